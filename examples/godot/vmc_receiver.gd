# Attach to any node; point `skeleton` at a humanoid Skeleton and `bone_names` at its bone names
# (humanoid bone -> your bone; empty: the VMC names themselves, as in `instrument skeleton`'s rest).
# Listens on 127.0.0.1:`port` and poses the skeleton every frame it receives.
extends Node

export(NodePath) var skeleton
export(int) var port := 39539
export(Dictionary) var bone_names := {}
export(float) var scale := 0.0

var driver
var socket := PacketPeerUDP.new()


func _ready() -> void:
	var target: Skeleton = get_node(skeleton)
	var names := bone_names
	if names.empty():
		for i in target.get_bone_count():
			names[target.get_bone_name(i)] = target.get_bone_name(i)
	driver = preload("res://vmc_skeleton.gd").new(target, names, scale)
	if socket.listen(port, "127.0.0.1") != OK:
		push_error("VMC receiver: cannot listen on 127.0.0.1:%d" % port)


func _process(_delta: float) -> void:
	while socket.get_available_packet_count() > 0:
		for message in driver.parse_osc(socket.get_packet()):
			driver.handle(message[0], message[1])


func _exit_tree() -> void:
	socket.close()
