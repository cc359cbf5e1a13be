# A Godot 4 player of an inbetween stream: attach to a Node3D, point
# `skeleton_path` at a Skeleton3D whose bone names are the clip's joint names
# (a character imported from the same glTF or BVH the clip came from), set
# `clip_id`, and the skeleton moves with the frames the server streams.
#
# Local space is asked for: each joint's translation, rotation ([x, y, z, w],
# which is Godot's Quaternion(x, y, z, w) order) and scale are the bone's
# pose relative to its parent, as Skeleton3D.set_bone_pose_* expects. Both
# use Y up and right-handed axes, as glTF does, so nothing is converted.
extends Node3D

@export var server := "ws://127.0.0.1:8080"
@export var clip_id := ""
@export var fps := 60
@export var skeleton_path: NodePath

var _socket := WebSocketPeer.new()
var _skeleton: Skeleton3D
var _bones := {}  # joint name -> bone index, filled from the first frame

func _ready() -> void:
	_skeleton = get_node(skeleton_path) as Skeleton3D
	var url := "%s/v1/clips/%s/stream?fps=%d&space=local" % [server, clip_id, fps]
	var err := _socket.connect_to_url(url)
	if err != OK:
		push_error("inbetween: cannot connect to %s (%s)" % [url, error_string(err)])

func _process(_delta: float) -> void:
	_socket.poll()
	match _socket.get_ready_state():
		WebSocketPeer.STATE_OPEN:
			# Apply only the newest frame: a game renders at its own rate.
			var newest = null
			while _socket.get_available_packet_count() > 0:
				newest = JSON.parse_string(_socket.get_packet().get_string_from_utf8())
			if newest is Dictionary:
				_apply(newest)
		WebSocketPeer.STATE_CLOSED:
			if _socket.get_close_code() != 1000:
				push_warning("inbetween: stream closed %d %s" % [_socket.get_close_code(), _socket.get_close_reason()])
			set_process(false)

func _apply(frame: Dictionary) -> void:
	if frame.has("error"):
		push_error("inbetween: %s" % frame["error"])
		return
	for joint in frame["pose"]["joints"]:
		var bone: int = _bones.get(joint["name"], -2)
		if bone == -2:
			bone = _skeleton.find_bone(joint["name"])
			_bones[joint["name"]] = bone
		if bone < 0:
			continue  # a joint the model does not have
		var t: Array = joint["translation"]
		var r: Array = joint["rotation"]
		var s: Array = joint["scale"]
		_skeleton.set_bone_pose_position(bone, Vector3(t[0], t[1], t[2]))
		_skeleton.set_bone_pose_rotation(bone, Quaternion(r[0], r[1], r[2], r[3]))
		_skeleton.set_bone_pose_scale(bone, Vector3(s[0], s[1], s[2]))
	for event in frame["events"]:
		event_crossed.emit(event["name"], event["time"])

## A clip event (a footstep, a sound cue) crossed since the previous frame.
signal event_crossed(name: String, time: float)

## Controls act on the server's next tick (docs/api.md, streaming).
func seek(time: float) -> void:
	_socket.send_text(JSON.stringify({"op": "seek", "time": time}))

func set_speed(speed: float) -> void:
	_socket.send_text(JSON.stringify({"op": "speed", "speed": speed}))

func pause() -> void:
	_socket.send_text(JSON.stringify({"op": "pause"}))

func play() -> void:
	_socket.send_text(JSON.stringify({"op": "play"}))
