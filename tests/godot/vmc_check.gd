# Run by tests/test_godot_vmc.py inside headless Godot 3 (godot3-server):
#   VMC_RIG=rig.json VMC_PORT=N VMC_FRAMES=N VMC_REPORT=out.json VMC_SCALE=s \
#   godot3-server --path examples/godot -s tests/godot/vmc_check.gd
# Builds the Skeleton the rig file describes, drives it with the example's receiver node until
# VMC_FRAMES frames came in, and reports the last frame's messages and every bone's position.
extends SceneTree


func _init() -> void:
	var file := File.new()
	file.open(OS.get_environment("VMC_RIG"), File.READ)
	var rig: Dictionary = parse_json(file.get_as_text())
	file.close()
	var skeleton := Skeleton.new()
	for bone in rig["bones"]:
		var index := skeleton.get_bone_count()
		skeleton.add_bone(bone["name"])
		skeleton.set_bone_parent(index, int(bone["parent"]))
		var r: Array = bone["rest"]
		skeleton.set_bone_rest(index, Transform(Vector3(r[0], r[1], r[2]), Vector3(r[3], r[4], r[5]), Vector3(r[6], r[7], r[8]),
				Vector3(r[9], r[10], r[11])))
	get_root().add_child(skeleton)
	# the example's receiver node, as a user would add it, pointed at the skeleton
	var receiver := Node.new()
	receiver.set_script(load("res://vmc_receiver.gd"))
	receiver.skeleton = skeleton.get_path()
	receiver.port = int(OS.get_environment("VMC_PORT"))
	receiver.bone_names = rig["names"]
	receiver.scale = float(OS.get_environment("VMC_SCALE"))
	get_root().add_child(receiver)  # _ready: listens
	print("listening on 127.0.0.1:%d" % receiver.port)
	var frames := int(OS.get_environment("VMC_FRAMES"))
	var deadline := OS.get_ticks_msec() + 120000
	while receiver.driver.count < frames and OS.get_ticks_msec() < deadline:
		receiver._process(0.0)  # the main loop does not run inside _init: call what it would
		OS.delay_msec(1)
	var driver = receiver.driver
	var last: Array = driver.last_frame
	receiver.socket.close()
	var positions := {}
	for i in skeleton.get_bone_count():
		var origin: Vector3 = skeleton.get_bone_global_pose(i).origin
		positions[skeleton.get_bone_name(i)] = [origin.x, origin.y, origin.z]
	var out := File.new()
	out.open(OS.get_environment("VMC_REPORT"), File.WRITE)
	out.store_string(to_json({"count": driver.count, "messages": last, "positions": positions}))
	out.close()
	print("applied %d frames" % driver.count)
	quit(0)
