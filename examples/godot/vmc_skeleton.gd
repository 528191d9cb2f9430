# Poses a Godot 3 Skeleton from VMC messages (the instrument's VMC profile, or any VMC sender).
#
# VMC sends each humanoid bone's rotation relative to a normalised T-pose, in Unity's axes. This
# rebuilds each bone's rotation from the T-pose in Godot's axes (the character facing +Z, its
# left along +X, Y up, right-handed: Unity's X mirrored), and retargets it to the skeleton's own
# rest: the rest bone swung by the smallest rotation onto the T-pose direction (arms out, legs
# down, spine up; feet and toes only turned to point ahead) is where that rotation is applied,
# so any rest pose and any bone frames work. A bone points at its first child; an end bone
# along its parent. Bones the map leaves out follow their parents.
extends Reference

const FINGERS = ["Thumb", "Index", "Middle", "Ring", "Little"]
const PHALANGES = ["Proximal", "Intermediate", "Distal"]

var skeleton: Skeleton
var bone_map := {}  # humanoid bone -> skeleton bone index
var human_of := {}  # skeleton bone index -> humanoid bone
var human_parent := {}  # humanoid bone -> its humanoid parent ("" for the hips)
var human_order := []
var tpose := {}  # humanoid bone -> skeleton-space basis in the T-pose
var rest_global := []
var scale := 0.0  # sent metres -> skeleton units (0: from the hips' height)
var received := {}  # humanoid bone -> [position, basis] (Unity axes)
var root_position := Vector3()
var root_basis := Basis()
var count := 0
var last_frame := []  # the messages of the last frame applied, as [address, args]
var _pending := []


func _init(target: Skeleton, names: Dictionary, units: float = 0.0) -> void:
	skeleton = target
	scale = units
	_humanoid()
	for human in names:
		var index := skeleton.find_bone(names[human])
		if index >= 0:
			bone_map[human] = index
			human_of[index] = human
	for i in skeleton.get_bone_count():
		var parent := skeleton.get_bone_parent(i)
		var above: Transform = rest_global[parent] if parent >= 0 else Transform()
		rest_global.append(above * skeleton.get_bone_rest(i))
	_tpose()


func _humanoid() -> void:
	var pairs := [["Hips", ""], ["Spine", "Hips"], ["Chest", "Spine"], ["UpperChest", "Chest"], ["Neck", "UpperChest"], ["Head", "Neck"]]
	for side in ["Left", "Right"]:
		pairs += [[side + "Shoulder", "UpperChest"], [side + "UpperArm", side + "Shoulder"], [side + "LowerArm", side + "UpperArm"],
				[side + "Hand", side + "LowerArm"], [side + "UpperLeg", "Hips"], [side + "LowerLeg", side + "UpperLeg"],
				[side + "Foot", side + "LowerLeg"], [side + "Toes", side + "Foot"]]
		for finger in FINGERS:
			for k in 3:
				pairs.append([side + finger + PHALANGES[k], side + "Hand" if k == 0 else side + finger + PHALANGES[k - 1]])
	for pair in pairs:
		human_parent[pair[0]] = pair[1]
		human_order.append(pair[0])


static func direction_of(human: String):
	if human in ["Hips", "Spine", "Chest", "UpperChest", "Neck", "Head"]:
		return Vector3(0, 1, 0)
	for side in ["Left", "Right"]:
		var x := 1.0 if side == "Left" else -1.0
		if human in [side + "Shoulder", side + "UpperArm", side + "LowerArm", side + "Hand"]:
			return Vector3(x, 0, 0)
		if human in [side + "UpperLeg", side + "LowerLeg"]:
			return Vector3(0, -1, 0)
		if human in [side + "Foot", side + "Toes"]:
			return "ahead"
	return null


static func swing(from: Vector3, to: Vector3) -> Basis:
	var a := from.normalized()
	var b := to.normalized()
	var axis := a.cross(b)
	if axis.length() < 1e-9:
		if a.dot(b) > 0:
			return Basis()
		axis = a.cross(Vector3(1, 0, 0) if abs(a.x) < 0.9 else Vector3(0, 1, 0))
	return Basis(axis.normalized(), acos(clamp(a.dot(b), -1.0, 1.0)))


func _along(index: int) -> Vector3:
	"""Where a bone points in skeleton space at rest: at its first child, else along its parent."""
	for child in skeleton.get_bone_count():
		if skeleton.get_bone_parent(child) == index:
			return rest_global[child].origin - rest_global[index].origin
	var parent := skeleton.get_bone_parent(index)
	return rest_global[index].origin - rest_global[parent].origin if parent >= 0 else Vector3(0, 1, 0)


func _tpose() -> void:
	var swings := {}
	for human in human_order:
		var parent: String = human_parent[human]
		var carried: Basis = swings[parent] if parent != "" else Basis()
		if not bone_map.has(human):
			swings[human] = carried
			continue
		var index: int = bone_map[human]
		var along := _along(index)
		var target = direction_of(human)
		if target is Vector3:
			swings[human] = swing(along, target)
		elif target == "ahead" and Vector2(along.x, along.z).length() > 1e-6:  # feet and toes: only turned
			swings[human] = Basis(Vector3(0, 1, 0), -atan2(along.x, along.z))
		else:
			swings[human] = carried
		tpose[human] = swings[human] * rest_global[index].basis


static func to_godot(basis: Basis) -> Basis:
	"""A Unity-axes rotation in Godot's axes (X mirrored)."""
	var mirror := Basis(Vector3(-1, 0, 0), Vector3(0, 1, 0), Vector3(0, 0, 1))
	return mirror * basis * mirror


func handle(address: String, args: Array) -> bool:
	"""Take one message; true when a frame was applied (on /VMC/Ext/T, which the instrument sends last)."""
	_pending.append([address, args])
	if address == "/VMC/Ext/Bone/Pos" and args.size() >= 8:
		received[args[0]] = [Vector3(args[1], args[2], args[3]), Basis(Quat(args[4], args[5], args[6], args[7]).normalized())]
	elif address == "/VMC/Ext/Root/Pos" and args.size() >= 8:
		root_position = Vector3(args[1], args[2], args[3])
		root_basis = Basis(Quat(args[4], args[5], args[6], args[7]).normalized())
	elif address == "/VMC/Ext/T":
		apply()
		last_frame = _pending
		_pending = []
		return true
	return false


func apply() -> void:
	var world := {}
	for human in human_order:
		var parent: String = human_parent[human]
		var above: Basis = world[parent] if parent != "" else to_godot(root_basis)
		var local: Basis = to_godot(received[human][1]) if received.has(human) else Basis()
		world[human] = above * local
	var hips_unity := root_position + root_basis.xform(received["Hips"][0] if received.has("Hips") else Vector3())
	if scale <= 0.0 and bone_map.has("Hips"):
		scale = rest_global[bone_map["Hips"]].origin.y / max(hips_unity.y, 1e-6)
	var hips := Vector3(-hips_unity.x, hips_unity.y, hips_unity.z) * scale
	var posed := []
	for i in skeleton.get_bone_count():
		var parent := skeleton.get_bone_parent(i)
		var follow: Transform = (posed[parent] if parent >= 0 else Transform()) * skeleton.get_bone_rest(i)
		var desired := follow
		if human_of.has(i):
			var human: String = human_of[i]
			desired = Transform(world[human] * tpose[human], hips if human == "Hips" else follow.origin)
		posed.append(desired)
		skeleton.set_bone_pose(i, follow.affine_inverse() * desired)
	count += 1


static func parse_osc(packet: PoolByteArray) -> Array:
	"""[[address, args], ...] of an OSC packet, bundles unpacked; f, i, s and d arguments."""
	var out := []
	var buffer := StreamPeerBuffer.new()
	buffer.big_endian = true
	buffer.data_array = packet
	if packet.size() >= 8 and _string(buffer) == "#bundle":
		buffer.seek(16)
		while buffer.get_position() + 4 <= packet.size():
			var size := buffer.get_32()
			var start := buffer.get_position()
			out += parse_osc(packet.subarray(start, start + size - 1))
			buffer.seek(start + size)
		return out
	buffer.seek(0)
	var address := _string(buffer)
	var tags := _string(buffer)
	var args := []
	for k in range(1, tags.length()):
		var tag := tags[k]
		if tag == "f":
			args.append(buffer.get_float())
		elif tag == "i":
			args.append(buffer.get_32())
		elif tag == "d":
			args.append(buffer.get_double())
		elif tag == "s":
			args.append(_string(buffer))
	out.append([address, args])
	return out


static func _string(buffer: StreamPeerBuffer) -> String:
	var start := buffer.get_position()
	var bytes := PoolByteArray()
	while buffer.get_position() < buffer.get_size():
		var b := buffer.get_u8()
		if b == 0:
			break
		bytes.append(b)
	buffer.seek(start + (bytes.size() / 4 + 1) * 4)
	return bytes.get_string_from_utf8()
