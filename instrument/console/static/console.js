// The instrument's console: a mixer of the style space and the character drawn live.
// One WebSocket to the instrument: the page sends control events ({set, value}, {preset},
// {store}, {save}) and receives, each frame, every control value and the joints' positions
// (and the presets' names when they change).
// The page holds no state of its own: every slider shows what the instrument says, so all
// pages and all controllers (MIDI, HID, OSC, a replayed log) move the same parameters.
"use strict";

const token = new URLSearchParams(location.search).get("token");
const $ = (id) => document.getElementById(id);
let hello = null;  // the instrument's description: styles, skeleton, ranges
let socket = null;
let latest = null;  // the newest frame message
const controls = new Map();  // target -> {row, range, box}
let held = null;  // the target this page's performer is dragging right now (not overwritten meanwhile)

// ---- connection --------------------------------------------------------------------------

function connect() {
  const scheme = location.protocol === "https:" ? "wss://" : "ws://";
  socket = new WebSocket(scheme + location.host + "/ws" + (token ? "?token=" + encodeURIComponent(token) : ""));
  socket.onopen = () => say("connected");
  socket.onclose = () => { say("not connected: trying again…"); setTimeout(connect, 1000); };
  socket.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === "hello") build(message);
    else if (message.type === "frame") onFrame(message);
    else if (message.type === "refused") say("refused: " + message.reason);
    else if (message.type === "saved") $("saved").textContent = message.error || message.text;
    else if (message.type === "presets") showPresets(message.presets);  // when a preset is stored
  };
}

function send(item) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(item));
}

const sent = new Map();  // target -> {value, until}: a value this page sent, not yet seen back
function setTarget(target, value) {
  send({ set: target, value: Number(value) });
  sent.set(target, { value: Number(value), until: performance.now() + 500 });
}
const say = (text) => { $("status").textContent = text; };
const fmt = (value) => (value === null || value === undefined ? "–" : Number(value).toFixed(2));

// ---- the mixer ---------------------------------------------------------------------------

function labelled(target, label, kind) {
  // a mixer row for `target`, its label first: [row, label]
  const row = document.createElement("div");
  row.className = kind ? "row " + kind : "row";
  row.dataset.target = target;
  const name = document.createElement("label");
  name.textContent = label;
  name.title = target;
  return [row, name];
}

function slider(parent, target, label, range, travel, marks) {
  const [low, high] = travel || range;
  const [row, name] = labelled(target, label);
  const track = document.createElement("div");
  track.className = "track";
  const input = document.createElement("input");
  Object.assign(input, { type: "range", min: low, max: high, step: 0.01, value: 0 });
  input.setAttribute("aria-label", target);
  const box = document.createElement("input");
  Object.assign(box, { type: "number", min: range[0], max: range[1], step: 0.01 });
  box.setAttribute("aria-label", target + " value");
  track.append(input);
  if (marks) track.append(zones(low, high));
  row.append(name, track, box);
  parent.append(row);
  input.addEventListener("pointerdown", () => { held = target; });
  input.addEventListener("input", () => { box.value = fmt(input.value); setTarget(target, input.value); });
  box.addEventListener("change", () => { if (box.value !== "") setTarget(target, box.value); });
  controls.set(target, { row, input, box });
}

function choice(parent, target, label, names) {
  // one button a named value (gait: stand, walk, run), pressed while the instrument's value is nearest it
  const [row, name] = labelled(target, label, "choice");
  const buttons = document.createElement("div");
  buttons.className = "choices";
  buttons.setAttribute("role", "group");
  buttons.setAttribute("aria-label", target);
  names.forEach((text, k) => {
    const button = document.createElement("button");
    button.textContent = text;
    button.dataset.value = k;
    button.setAttribute("aria-pressed", "false");
    button.addEventListener("click", () => setTarget(target, k));
    buttons.append(button);
  });
  row.append(name, buttons);
  parent.append(row);
  const show = (value) => {
    for (const button of buttons.children) {
      button.setAttribute("aria-pressed", String(Math.floor(value + 0.5) === Number(button.dataset.value)));
    }
  };
  controls.set(target, { row, show });
}

function press(parent, target, label) {
  // a gesture's button: held down, the target is 1 (the gesture repeats), let go, 0 (it lowers)
  const [row, name] = labelled(target, label, "choice");
  const button = document.createElement("button");
  button.textContent = label;
  button.setAttribute("aria-label", target);
  button.setAttribute("aria-pressed", "false");
  let down = false;
  const set = (on) => { if (on !== down) { down = on; setTarget(target, on ? 1 : 0); } };
  button.addEventListener("pointerdown", (event) => { event.preventDefault(); set(true); });
  for (const kind of ["pointerup", "pointerleave", "pointercancel"]) button.addEventListener(kind, () => set(false));
  button.addEventListener("keydown", (event) => { if (event.key === " " || event.key === "Enter") set(true); });
  button.addEventListener("keyup", () => set(false));
  row.append(name, button);
  parent.append(row);
  const show = (value) => button.setAttribute("aria-pressed", String(value > 0));
  controls.set(target, { row, show });
}

function zones(low, high) {
  // where inversion begins (below 0: absent), the style itself (1; inhibited between) and exaggeration
  const where = (v) => ((v - low) / (high - low)) * 100 + "%";
  const div = document.createElement("div");
  div.className = "zones";
  const labels = [["◂ invert", low / 2, "invert"], ["0", 0], ["1", 1], ["exaggerate ▸", (1 + high) / 2, "exaggerate"]];
  for (const [text, at, kind] of labels) {
    const span = document.createElement("span");
    span.textContent = text;
    span.style.left = where(at);
    if (kind) span.className = kind;
    div.append(span);
  }
  for (const at of [0, 1]) {
    const tick = document.createElement("i");
    tick.style.left = where(at);
    div.append(tick);
  }
  return div;
}

// The sliders are the instrument's table of targets (control/spec.py), as the hello message
// carries it: one row a kind of target, with its range, the slider's travel and its section.
function expand(row) {
  // [target, label, group title or null] of each target a row stands for, for this model
  if (row.kind === "style") return hello.styles.map((s) => ["style/" + s, s, null]);
  if (row.kind === "part") return hello.styles.flatMap((s) => hello.groups.map((g, k) => [`part/${s}/${g}`, g, k === 0 ? s : null]));
  if (row.kind === "gesture") return (hello.gestures || []).map((g) => ["gesture/" + g, g, null]);
  if (row.kind === "phase") return Array.from({ length: hello.states }, (_, k) => ["phase/" + (k + 1), "state " + (k + 1), null]);
  return [[row.pattern, row.units === "s" ? row.kind + " s" : row.kind, null]];
}

function build(message) {
  hello = message;
  controls.clear();
  for (const id of ["styles", "walk", "gestures", "parts", "phases", "morph", "pad-styles"]) $(id).replaceChildren();
  $("gestures-title").hidden = !(hello.gestures || []).length;
  for (const row of hello.rows) {
    for (const [target, label, title] of expand(row)) {
      if (title) {
        const div = document.createElement("div");
        div.className = "group";
        div.textContent = title;
        $(row.section).append(div);
      }
      if (row.kind === "gesture") press($(row.section), target, label);
      else if (row.choices && row.choices.length) choice($(row.section), target, label, row.choices);
      else slider($(row.section), target, label, row.range, row.travel, row.kind === "style");
      controls.get(target).row.title = row.help;
    }
  }
  $("save").disabled = !hello.save;
  $("save").title = hello.save ? "write every preset to " + hello.save : "start the instrument with --presets FILE to save";
  buildPad();
  showPresets(hello.presets);
  figure.setup(hello);
}

let presetNames = [];  // as the instrument last said: the number keys recall the first nine
function showPresets(names) {
  presetNames = names;
  $("presets").replaceChildren(...names.map((name, k) => {
    const button = document.createElement("button");
    button.dataset.preset = name;
    button.innerHTML = k < 9 ? `<small>${k + 1}</small>` : "";
    button.append(name);
    button.addEventListener("click", () => send({ preset: name }));
    return button;
  }));
}

function onFrame(message) {
  latest = message;
  for (const [target, { row, input, box, show }] of controls) {
    let value = message.v[target];
    const follows = value === null;  // a part weight following its style
    if (follows) value = message.v["style/" + target.split("/")[1]];
    row.classList.toggle("follows", follows);
    if (target === held || value === undefined) continue;
    const mine = sent.get(target);
    if (mine) {  // until the instrument shows this page's own move, an older frame does not undo it
      if (Math.abs(value - mine.value) > 1e-4 && performance.now() < mine.until) continue;
      sent.delete(target);
    }
    if (show) { show(value); continue; }  // buttons of named values
    if (Number(input.value) !== value) input.value = value;
    if (document.activeElement !== box) box.value = fmt(value);
  }
  $("frame").textContent = "frame " + message.frame;
  $("late").textContent = `late ${message.late}` + (message.dropped ? ` (dropped ${message.dropped})` : "");
  $("pages").textContent = message.pages + (message.pages === 1 ? " page" : " pages");
  $("sources").textContent = "controls: " + message.sources;
  rate.count++;
  figure.push(message.p, message.crowd || []);
}

const rate = { count: 0, since: performance.now() };
setInterval(() => {
  const now = performance.now();
  $("rate").textContent = ((rate.count * 1000) / (now - rate.since)).toFixed(0) + " fps";
  rate.count = 0;
  rate.since = now;
}, 1000);

window.addEventListener("pointerup", () => { held = null; });
window.addEventListener("pointercancel", () => { held = null; });
$("reset").addEventListener("click", () => setTarget("reset", 1));
$("store").addEventListener("submit", (event) => {
  event.preventDefault();
  const name = $("store-name").value.trim();
  if (name) send({ store: name });
  $("store-name").value = "";
});
$("save").addEventListener("click", () => send({ save: true }));

// ---- keyboard: arrows steer and change speed, digits recall presets ---------------------

let steering = false;  // an arrow key is held: the page set a turn it must take back
const typing = (event) => ["INPUT", "SELECT", "TEXTAREA"].includes(event.target.tagName);
window.addEventListener("keydown", (event) => {
  if (typing(event) || !latest || event.ctrlKey || event.metaKey || event.altKey) return;
  const key = event.key;
  if (key === "ArrowLeft" || key === "ArrowRight") {
    if (!event.repeat) setTarget("turn", key === "ArrowLeft" ? 1.0 : -1.0);  // positive turns left
    steering = true;
  } else if (key === "ArrowUp" || key === "ArrowDown") {
    const [low, high] = hello.rows.find((row) => row.kind === "speed").range;  // past the range is refused: stop at its ends
    setTarget("speed", Math.min(Math.max(Math.round((latest.v.speed + (key === "ArrowUp" ? 0.1 : -0.1)) * 100) / 100, low), high));
  } else if (/^[1-9]$/.test(key)) {
    const name = presetNames[Number(key) - 1];
    if (name !== undefined) send({ preset: name });
  } else return;
  event.preventDefault();
});
window.addEventListener("keyup", (event) => {
  if (!typing(event) && (event.key === "ArrowLeft" || event.key === "ArrowRight")) { steering = false; setTarget("turn", 0); }
});
window.addEventListener("blur", () => { if (steering) { steering = false; setTarget("turn", 0); } });  // a key released elsewhere

// ---- the XY pad: two styles (blend across, amount up) or three (a triangle) -------------

const pad = { canvas: $("pad"), chosen: [], point: null, pending: null };

function buildPad() {
  const names = hello.styles;
  const defaults = [names[0], names[1 % names.length], names.length > 2 ? names[2] : ""];
  pad.selects = defaults.map((name, k) => {
    const select = document.createElement("select");
    select.setAttribute("aria-label", "pad style " + (k + 1));
    const options = (k === 2 ? ["—"] : []).concat(names);
    for (const option of options) select.append(new Option(option, option === "—" ? "" : option));
    select.value = name;
    select.addEventListener("change", choosePad);
    $("pad-styles").append(select);
    return select;
  });
  choosePad();
}

function choosePad() {
  pad.chosen = [...new Set(pad.selects.map((s) => s.value).filter(Boolean))];
  pad.point = null;
  drawPad();
}

function padAnchors(w, h) {
  if (pad.chosen.length === 3) return [[w / 2, 18], [18, h - 18], [w - 18, h - 18]];
  return [[18, h / 2], [w - 18, h / 2]];
}

function padWeights(x, y, w, h) {
  // weights of the chosen styles at pad point (x, y), in pad pixels
  if (pad.chosen.length === 3) {
    const [[ax, ay], [bx, by], [cx, cy]] = padAnchors(w, h);
    const det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy);
    let a = ((by - cy) * (x - cx) + (cx - bx) * (y - cy)) / det;
    let b = ((cy - ay) * (x - cx) + (ax - cx) * (y - cy)) / det;
    let c = 1 - a - b;
    [a, b, c] = [a, b, c].map((v) => Math.max(v, 0));
    const sum = a + b + c || 1;
    return [a / sum, b / sum, c / sum];
  }
  const blend = Math.min(Math.max((x - 18) / (w - 36), 0), 1);
  const amount = Math.min(Math.max(2 * (1 - y / h), 0), 2);  // bottom: absent, middle: the styles, top: exaggerated
  return pad.chosen.length === 2 ? [(1 - blend) * amount, blend * amount] : [amount];
}

function drawPad() {
  const { canvas } = pad;
  const g = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height;
  g.clearRect(0, 0, w, h);
  g.strokeStyle = "#333846";
  g.fillStyle = "#8a8f99";
  g.font = "12px system-ui";
  const anchors = padAnchors(w, h);
  if (pad.chosen.length === 3) {
    g.beginPath();
    anchors.forEach(([x, y], k) => (k ? g.lineTo(x, y) : g.moveTo(x, y)));
    g.closePath();
    g.stroke();
  } else {
    g.beginPath(); g.moveTo(0, h / 2); g.lineTo(w, h / 2); g.stroke();
    g.fillText("exaggerate ↑", w / 2 - 36, 14);
    g.fillText("absent ↓", w / 2 - 24, h - 6);
  }
  pad.chosen.forEach((name, k) => {
    const [x, y] = anchors[k] || anchors[0];
    g.fillText(name, Math.min(Math.max(x - 20, 2), w - 70), y + (y < h / 2 ? 16 : -6));
  });
  if (pad.point) {
    g.fillStyle = "#e0a040";
    g.beginPath(); g.arc(pad.point[0], pad.point[1], 8, 0, 2 * Math.PI); g.fill();
  }
}

function padAt(event) {
  const box = pad.canvas.getBoundingClientRect();
  const x = ((event.clientX - box.left) / box.width) * pad.canvas.width;
  const y = ((event.clientY - box.top) / box.height) * pad.canvas.height;
  pad.point = [x, y];
  pad.pending = padWeights(x, y, pad.canvas.width, pad.canvas.height);
  drawPad();
}

setInterval(() => {  // at most 30 sends a second from the pad, however fast the pointer moves
  if (!pad.pending) return;
  pad.pending.forEach((weight, k) => setTarget("style/" + pad.chosen[k], Math.round(weight * 1000) / 1000));
  pad.pending = null;
}, 33);
pad.canvas.addEventListener("pointerdown", (event) => { pad.canvas.setPointerCapture(event.pointerId); padAt(event); });
pad.canvas.addEventListener("pointermove", (event) => { if (event.buttons) padAt(event); });

// ---- the character in 3D: own projection on a 2D canvas (no library, no GPU needed) ----

const figure = {
  canvas: $("view"),
  camera: { yaw: 0.7, pitch: 0.28, distance: 520, target: [0, 90, 0], follow: true },
  joints: [], parents: [], first: 0,
  positions: null, others: [], floor: Infinity, prints: [], feet: [], frames: 0, dirty: true, size: "",

  setup(hello) {
    this.parents = hello.parents;
    this.joints = hello.joints;
    this.first = hello.root;  // segments above the body root (a ground marker) are not drawn
    this.side = hello.joints.map((name) => (/(^|[_.\s])(l|left)([_.\s]|$)|^left|left$|_l$/i.test(name) ? -1
      : /(^|[_.\s])(r|right)([_.\s]|$)|^right|right$|_r$/i.test(name) ? 1 : 0));
    this.radius = hello.joints.map((name) => (/head/i.test(name) ? 11 : /spine|chest|hips|pelvis/i.test(name) ? 9
      : /up|thigh|leg/i.test(name) ? 7 : /neck/i.test(name) ? 5 : /foot|toe/i.test(name) ? 4.5 : 4.5));
    const leaf = (k) => !hello.parents.includes(k);
    this.feet = hello.joints.map((name, k) => k).filter((k) => /foot|toe|ankle/i.test(hello.joints[k]) && leaf(k));
    if (this.feet.length === 0) this.feet = hello.joints.map((n, k) => k).filter((k) => /foot|ankle/i.test(hello.joints[k]));
    this.planted = this.feet.map(() => false);
    this.prints = [];
    this.floor = Infinity;
  },

  push(flat, crowd) {  // the followed character's joints, and a crowd's others one after the other
    const n = flat.length / 3;
    const joints = (values, from) => {
      const out = [];
      for (let k = from; k < from + n; k++) out.push([values[3 * k], values[3 * k + 1], values[3 * k + 2]]);
      return out;
    };
    const positions = joints(flat, 0);
    this.others = [];
    for (let c = 0; c < crowd.length / flat.length; c++) this.others.push(joints(crowd, c * n));
    const previous = this.positions;
    this.positions = positions;
    if (!previous) {  // the first frame: the camera starts on the character, not at the origin far from it
      const root = positions[Math.max(this.first, 0)];
      this.camera.target = [root[0], this.camera.target[1], root[2]];
    }
    this.dirty = true;
    this.frames++;
    let lowest = Infinity;
    for (const p of positions) lowest = Math.min(lowest, p[1]);
    this.floor = Math.min(this.floor, lowest);
    // footprints: a foot near the floor that has stopped moving leaves one print per contact
    this.feet.forEach((k, i) => {
      const p = positions[k];
      const moved = previous ? Math.hypot(p[0] - previous[k][0], p[2] - previous[k][2]) : 0;
      const down = p[1] < this.floor + 5 && moved < 1.2;
      if (down && !this.planted[i]) this.prints.push({ at: [p[0], this.floor, p[2]], side: this.side[k], born: this.frames });
      this.planted[i] = down;
    });
    if (this.prints.length > 40) this.prints.splice(0, this.prints.length - 40);
  },

  basis() {
    const c = this.camera;
    const eye = [c.target[0] + c.distance * Math.cos(c.pitch) * Math.sin(c.yaw),
                 c.target[1] + c.distance * Math.sin(c.pitch),
                 c.target[2] + c.distance * Math.cos(c.pitch) * Math.cos(c.yaw)];
    const f = norm(sub(c.target, eye));
    const r = norm(cross(f, [0, 1, 0]));
    const u = cross(r, f);
    return { eye, f, r, u };
  },

  draw() {
    const canvas = this.canvas;
    const width = canvas.clientWidth, height = canvas.clientHeight;
    const scale = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(width * scale) || canvas.height !== Math.round(height * scale)) {
      canvas.width = Math.round(width * scale);
      canvas.height = Math.round(height * scale);
    }
    const g = canvas.getContext("2d");
    g.setTransform(scale, 0, 0, scale, 0, 0);
    const sky = g.createLinearGradient(0, 0, 0, height);
    sky.addColorStop(0, "#2a2f3a");
    sky.addColorStop(1, "#101216");
    g.fillStyle = sky;
    g.fillRect(0, 0, width, height);
    if (!this.positions) return;
    const root = this.positions[Math.max(this.first, 0)];
    const floor = Number.isFinite(this.floor) ? this.floor : 0;
    if (this.camera.follow) {  // ease towards the character so the view does not jitter with each step
      const t = this.camera.target;
      t[0] += (root[0] - t[0]) * 0.15;
      t[1] += (floor + 90 - t[1]) * 0.15;
      t[2] += (root[2] - t[2]) * 0.15;
    }
    const { eye, f, r, u } = this.basis();
    const focal = height * 1.1;
    const view = (p) => { const d = sub(p, eye); return [dot(d, r), dot(d, u), dot(d, f)]; };
    const screen = (v) => [width / 2 + (v[0] * focal) / v[2], height / 2 - (v[1] * focal) / v[2]];
    const near = 10;
    const line = (a, b) => {  // a world segment, clipped to the near plane
      let va = view(a), vb = view(b);
      if (va[2] < near && vb[2] < near) return;
      if (va[2] < near || vb[2] < near) {
        const t = (near - va[2]) / (vb[2] - va[2]);
        const cut = va.map((x, k) => x + (vb[k] - x) * t);
        if (va[2] < near) va = cut; else vb = cut;
      }
      const [x0, y0] = screen(va), [x1, y1] = screen(vb);
      g.moveTo(x0, y0);
      g.lineTo(x1, y1);
    };

    // floor grid, 50 units a cell, fixed to the world so the walk is seen to travel
    const cell = 50, reach = 12;
    const cx = Math.round(this.camera.target[0] / cell) * cell, cz = Math.round(this.camera.target[2] / cell) * cell;
    g.lineWidth = 1;
    g.strokeStyle = "rgba(150, 160, 180, 0.22)";
    g.beginPath();
    for (let k = -reach; k <= reach; k++) {
      line([cx + k * cell, floor, cz - reach * cell], [cx + k * cell, floor, cz + reach * cell]);
      line([cx - reach * cell, floor, cz + k * cell], [cx + reach * cell, floor, cz + k * cell]);
    }
    g.stroke();

    // footprints, fading with age
    for (const print of this.prints) {
      const age = (this.frames - print.born) / 300;
      if (age > 1) continue;
      const ring = [];
      for (let k = 0; k < 10; k++) {
        const a = (k / 10) * 2 * Math.PI;
        const v = view([print.at[0] + 6 * Math.cos(a), print.at[1], print.at[2] + 9 * Math.sin(a)]);
        if (v[2] < near) { ring.length = 0; break; }
        ring.push(screen(v));
      }
      if (!ring.length) continue;
      g.fillStyle = print.side < 0 ? `rgba(110, 160, 230, ${0.55 * (1 - age)})` : `rgba(230, 150, 90, ${0.55 * (1 - age)})`;
      g.beginPath();
      ring.forEach(([x, y], k) => (k ? g.lineTo(x, y) : g.moveTo(x, y)));
      g.fill();
    }

    // the rest of a crowd: slim figures, the nearest drawn last (the followed character is drawn whole)
    const others = this.others.map((positions) => ({ positions, depth: view(positions[Math.max(this.first, 0)])[2] }))
      .filter((o) => o.depth > near).sort((a, b) => b.depth - a.depth);
    g.lineCap = "round";
    for (const { positions } of others) {
      g.strokeStyle = "rgba(175, 182, 198, 0.75)";
      g.lineWidth = Math.max(1.5, (6 * focal) / Math.max(view(positions[Math.max(this.first, 0)])[2], near));
      g.beginPath();
      this.parents.forEach((parent, k) => { if (parent >= this.first) line(positions[parent], positions[k]); });
      g.stroke();
    }

    // the shadow: the skeleton flattened onto the floor
    g.strokeStyle = "rgba(0, 0, 0, 0.35)";
    g.lineCap = "round";
    g.lineWidth = 8;
    g.beginPath();
    this.parents.forEach((parent, k) => {
      if (parent < this.first) return;
      const a = this.positions[parent], b = this.positions[k];
      line([a[0], floor, a[2]], [b[0], floor, b[2]]);
    });
    g.stroke();

    // limbs as shaded cylinders, far ones first
    const light = norm([-0.4, 0.8, -0.45]);  // in view space: from above, left, behind the viewer
    const segments = [];
    this.parents.forEach((parent, k) => {
      if (parent < this.first) return;
      const a = view(this.positions[parent]), b = view(this.positions[k]);
      if (a[2] < near || b[2] < near) return;
      segments.push({ a, b, k, depth: (a[2] + b[2]) / 2 });
    });
    segments.sort((s, t) => t.depth - s.depth);
    for (const { a, b, k, depth } of segments) {
      const [x0, y0] = screen(a), [x1, y1] = screen(b);
      const radius = this.radius[k] * focal / depth;
      const axis = norm(sub(b, a));
      const across = norm([-(y1 - y0), x1 - x0]);  // on screen, perpendicular to the limb
      const lit = Math.max(0.25, 1 - Math.abs(dot(axis, light)));  // a cylinder is brightest side-on to the light
      const base = this.side[k] < 0 ? [110, 160, 230] : this.side[k] > 0 ? [230, 150, 90] : [200, 200, 205];
      const shade = (s) => `rgb(${base.map((c) => Math.round(c * s)).join(",")})`;
      const mx = (x0 + x1) / 2, my = (y0 + y1) / 2;
      const gradient = g.createLinearGradient(mx - across[0] * radius, my - across[1] * radius,
                                              mx + across[0] * radius, my + across[1] * radius);
      gradient.addColorStop(0, shade(0.35 * lit));
      gradient.addColorStop(0.35, shade(lit));
      gradient.addColorStop(1, shade(0.3 * lit));
      g.strokeStyle = gradient;
      g.lineWidth = Math.max(2 * radius, 1.5);
      g.beginPath();
      g.moveTo(x0, y0);
      g.lineTo(x1, y1);
      g.stroke();
    }
    // the head as a lit sphere
    const head = this.joints.findIndex((name) => /head/i.test(name));
    if (head >= 0) {
      const v = view(this.positions[head]);
      if (v[2] > near) {
        const [x, y] = screen([v[0], v[1] + 6, v[2]]);
        const radius = (11 * focal) / v[2];
        const ball = g.createRadialGradient(x - radius * 0.35, y - radius * 0.4, radius * 0.1, x, y, radius);
        ball.addColorStop(0, "#f4f4f6");
        ball.addColorStop(1, "#6c6f78");
        g.fillStyle = ball;
        g.beginPath(); g.arc(x, y, radius, 0, 2 * Math.PI); g.fill();
      }
    }
  },
};

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + (a.length > 2 ? a[2] * b[2] : 0);
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => { const n = Math.hypot(...a) || 1; return a.map((x) => x / n); };

function animate() {  // draws only when there is something new: a frame, a camera move, a resize
  const size = figure.canvas.clientWidth + "x" + figure.canvas.clientHeight;
  if (figure.dirty || size !== figure.size) figure.draw();
  figure.dirty = false;
  figure.size = size;
  requestAnimationFrame(animate);
}
requestAnimationFrame(animate);

// orbit with a drag (mouse or one finger), zoom with the wheel or two fingers
const pointers = new Map();
let pinch = null;
figure.canvas.addEventListener("pointerdown", (event) => {
  figure.canvas.setPointerCapture(event.pointerId);
  pointers.set(event.pointerId, [event.clientX, event.clientY]);
});
figure.canvas.addEventListener("pointermove", (event) => {
  const before = pointers.get(event.pointerId);
  if (!before) return;
  pointers.set(event.pointerId, [event.clientX, event.clientY]);
  const c = figure.camera;
  figure.dirty = true;
  if (pointers.size === 1) {
    c.yaw -= (event.clientX - before[0]) * 0.008;
    c.pitch = Math.min(Math.max(c.pitch + (event.clientY - before[1]) * 0.006, 0.02), 1.45);
  } else if (pointers.size === 2) {
    const [p, q] = [...pointers.values()];
    const spread = Math.hypot(p[0] - q[0], p[1] - q[1]);
    if (pinch) c.distance = Math.min(Math.max(c.distance * (pinch / spread), 120), 3000);
    pinch = spread;
  }
});
const release = (event) => { pointers.delete(event.pointerId); if (pointers.size < 2) pinch = null; };
figure.canvas.addEventListener("pointerup", release);
figure.canvas.addEventListener("pointercancel", release);
figure.canvas.addEventListener("wheel", (event) => {
  event.preventDefault();
  figure.camera.distance = Math.min(Math.max(figure.camera.distance * Math.exp(event.deltaY * 0.001), 120), 3000);
  figure.dirty = true;
}, { passive: false });
$("follow").addEventListener("click", () => {
  figure.camera.follow = !figure.camera.follow;
  figure.dirty = true;
  $("follow").setAttribute("aria-pressed", String(figure.camera.follow));
});
$("home").addEventListener("click", () => {
  Object.assign(figure.camera, { yaw: 0.7, pitch: 0.28, distance: 520 });
  figure.dirty = true;
});

connect();
