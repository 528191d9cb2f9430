// The Khronos glTF-Validator on one file: prints its issues as JSON (numErrors, messages, ...).
//   NODE_PATH=.../node_modules node validate.js FILE.glb
const fs = require("fs");
const validator = require("gltf-validator");

validator.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))
  .then((report) => console.log(JSON.stringify(report.issues)))
  .catch((error) => { console.error(String(error)); process.exit(2); });
