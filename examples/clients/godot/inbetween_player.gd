# A Godot 4 player of an inbetween stream: attach to a Node3D, point
# `skeleton_path` at a Skeleton3D imported from the same glTF or BVH the clip
# came from, set `clip_id`, and the skeleton moves with the stream.
#
# - Compact frames by default (docs/compact-frames.md; compact.gd decodes them),
#   `encoding = "json"` for JSON frames; both carry clip events and root motion.
# - Smooth at any frame rate: a snapshot interpolation buffer
#   (snapshot_buffer.gd) shows the pose two ticks behind the newest frame,
#   interpolated between frames, extrapolated at most one tick when one is late.
# - Joints bind to bones by name as Godot's importer renames them
#   (`mixamorig:Hips` -> `mixamorig_Hips`: names.gd).
# - A server with tokens: set `token`, or run with `-- --token T` (arguments
#   after `--` are the game's), or set INBETWEEN_TOKEN; it goes in the
#   WebSocket handshake as `Authorization: Bearer T`.
#
# Local space: each joint's translation, rotation ([x, y, z, w], Godot's
# Quaternion(x, y, z, w) order) and scale are the bone's pose relative to its
# parent, as Skeleton3D.set_bone_pose_* expects. Both use Y up and right-handed
# axes, as glTF does, so nothing is converted.
extends Node3D

## A clip event (a footstep, a sound cue) crossed since the previous frame.
signal event_crossed(name: String, time: float)

const Compact = preload("compact.gd")
const SnapshotBuffer = preload("snapshot_buffer.gd")
const Names = preload("names.gd")

@export var server := "ws://127.0.0.1:8080"
@export var clip_id := ""
@export var fps := 30
@export_enum("compact", "json") var encoding := "compact"
@export var delay_ticks := 2.0
@export var token := ""
@export var skeleton_path: NodePath

var missing := PackedStringArray()  # joints the skeleton has no bone for
var shown := {}  # the last sample: {mode, from, to, alpha}

var _socket := WebSocketPeer.new()
var _skeleton: Skeleton3D
var _decoder: Compact
var _buffer: SnapshotBuffer
var _pose := {}
var _bones := PackedInt32Array()  # bone index per joint, -1 for none
var _origin: Transform3D


func _ready() -> void:
	_skeleton = get_node(skeleton_path) as Skeleton3D
	_buffer = SnapshotBuffer.new(fps, delay_ticks)
	_origin = transform
	var url := (
		"%s/v1/clips/%s/stream?fps=%d&encoding=%s" % [server, clip_id.uri_encode(), fps, encoding]
	)
	var bearer := Names.token_from(
		token, OS.get_cmdline_user_args(), OS.get_environment("INBETWEEN_TOKEN")
	)
	if bearer != "":
		_socket.handshake_headers = PackedStringArray(["Authorization: Bearer %s" % bearer])
	var err := _socket.connect_to_url(url)
	if err != OK:
		push_error("inbetween: cannot connect to %s (%s)" % [url, error_string(err)])


func _process(_delta: float) -> void:
	_socket.poll()
	match _socket.get_ready_state():
		WebSocketPeer.STATE_OPEN:
			var now := Time.get_ticks_usec() / 1000.0
			while _socket.get_available_packet_count() > 0:
				var packet := _socket.get_packet()
				if _socket.was_string_packet():
					_receive_text(packet.get_string_from_utf8(), now)
				elif _decoder != null:
					_take(_compact_frame(_decoder.decode(packet)), now)
			_show(now)
		WebSocketPeer.STATE_CLOSED:
			if _socket.get_close_code() != 1000:
				push_warning(
					(
						"inbetween: stream closed %d %s"
						% [_socket.get_close_code(), _socket.get_close_reason()]
					)
				)
			set_process(false)


func _receive_text(text: String, now: float) -> void:
	var message = JSON.parse_string(text)
	if not message is Dictionary:
		return
	if message.has("error"):
		push_error("inbetween: %s" % message["error"])
	elif message.has("opened"):
		var opened: Dictionary = message["opened"]
		if opened.has("compact"):
			_decoder = Compact.new(opened["compact"])
			_bind(_decoder.names)
	elif message.has("layout") and _decoder != null:
		# A new layout mid-stream: the skeleton and the buffered frames stay, so the pose interpolates on.
		_decoder.relayout(message["layout"])
	elif message.has("pose"):
		_take(_json_frame(message), now)


func _take(frame: Dictionary, now: float) -> void:
	if frame.has("error"):
		push_error("inbetween: %s: %s" % [frame["error"], frame["detail"]])
		return
	_buffer.push(frame, now)


func _bind(names: PackedStringArray) -> void:
	var bone_names := PackedStringArray()
	for b in _skeleton.get_bone_count():
		bone_names.append(_skeleton.get_bone_name(b))
	_bones = Names.match_names(names, bone_names)
	missing = PackedStringArray()
	for j in names.size():
		if _bones[j] < 0:
			missing.append(names[j])
	if not missing.is_empty():
		push_warning("inbetween: no bone for %s" % ", ".join(missing))
	_pose = SnapshotBuffer.empty_pose(names.size())


## Puts the pose at the render time for `now` on the skeleton (and root motion on this node).
func _show(now: float) -> void:
	var time := _buffer.render_time(now)
	if is_nan(time) or _pose.is_empty():
		return
	shown = _buffer.sample(time, _pose)
	var t: PackedFloat64Array = _pose["translations"]
	var r: PackedFloat64Array = _pose["rotations"]
	var s: PackedFloat64Array = _pose["scales"]
	for j in _bones.size():
		var bone := _bones[j]
		if bone < 0:
			continue
		_skeleton.set_bone_pose_position(bone, Vector3(t[3 * j], t[3 * j + 1], t[3 * j + 2]))
		var q := Quaternion(r[4 * j], r[4 * j + 1], r[4 * j + 2], r[4 * j + 3])
		_skeleton.set_bone_pose_rotation(bone, q)
		_skeleton.set_bone_pose_scale(bone, Vector3(s[3 * j], s[3 * j + 1], s[3 * j + 2]))
	if _pose["has_root"]:
		var root: PackedFloat64Array = _pose["root"]
		var moved := Transform3D(Basis(Vector3.UP, root[3]), Vector3(root[0], root[1], root[2]))
		transform = _origin * moved


## A decoded compact frame, its root motion's total as the buffer takes it; its
## events emitted as they arrive.
func _compact_frame(frame: Dictionary) -> Dictionary:
	if frame.has("error"):
		return frame
	var root_motion = frame["root_motion"]
	frame["root"] = root_motion["total"] if root_motion is Dictionary else null
	for event in frame["events"]:
		event_crossed.emit(event["name"], event["time"])
	return frame


## A JSON frame as flat arrays (the decoder's shape); its events re-emitted as they arrive.
func _json_frame(message: Dictionary) -> Dictionary:
	var joints: Array = message["pose"]["joints"]
	if _pose.is_empty():
		var names := PackedStringArray()
		for joint in joints:
			names.append(joint["name"])
		_bind(names)
	var frame := {
		"seq": int(message["seq"]),
		"clip_time": message["clip_time"],
		"translations": [],
		"rotations": [],
		"scales": [],
		"root": null,
	}
	for joint in joints:
		frame["translations"].append_array(joint["translation"])
		frame["rotations"].append_array(joint["rotation"])
		frame["scales"].append_array(joint["scale"])
	var root_motion = message["pose"].get("root_motion")
	if root_motion is Dictionary:
		var total: Dictionary = root_motion["total"]
		frame["root"] = total["translation"] + [total["yaw"]]
	for event in message.get("events", []):
		event_crossed.emit(event["name"], event["time"])
	return frame


## Controls act on the server's next tick (docs/api.md, streaming).
func seek(time: float) -> void:
	_socket.send_text(JSON.stringify({"op": "seek", "time": time}))


func set_speed(speed: float) -> void:
	_socket.send_text(JSON.stringify({"op": "speed", "speed": speed}))


func pause() -> void:
	_socket.send_text(JSON.stringify({"op": "pause"}))


func play() -> void:
	_socket.send_text(JSON.stringify({"op": "play"}))
