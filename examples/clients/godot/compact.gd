# Compact frames (docs/compact-frames.md): a decoder for the binary frames of
# `encoding=compact` streams, in Godot 4 GDScript. It follows the JavaScript
# decoder (examples/clients/js/compact.mjs) step for step, in the same double
# precision, so both produce the same f32 values.
#
#   const Compact = preload("compact.gd")
#   var decoder = Compact.new(opened["compact"])          # the stream's `opened` message
#   var frame: Dictionary = decoder.decode(packet)         # frame["rotations"], ...
#   if frame.has("error"): push_error(frame["error"])
#
# A decoder keeps the last key frame's values, so feed it every frame of one
# stream in order. GDScript has no exceptions: a frame it refuses answers
# {"error": code, "detail": text}, with the codes of the JavaScript decoder.
# The pose arrays it returns are reused by the next decode: duplicate() them to
# keep them.
class_name InbetweenCompact
extends RefCounted

const KEY_FRAME := 1
const EVENTS := 2  # an events section follows the body
const ROOT_MOTION := 4  # a root motion section follows the body (and the events)
const GRAPH := 8  # a graph report section follows (after the root motion)
const KNOWN_FLAGS := KEY_FRAME | EVENTS | ROOT_MOTION | GRAPH
# Per joint in the value store: largest index, three rotation components,
# translation x y z, scale x y z.
const STRIDE := 10

var layout: Dictionary
var names := PackedStringArray()
var events: Array = []  # the clip's events ({time, name}), which frames index
var graph: Dictionary = {}  # a graph stream's {states, nodes}, which reports index
var joints: Array = []
var key := PackedInt64Array()
var values := PackedInt64Array()
var key_seq := -1
var has_key := false
var translations := PackedFloat32Array()
var rotations := PackedFloat32Array()
var scales := PackedFloat32Array()

# The frame being read: its bytes, the next bit, the bit past its end, and the first refusal.
var _bytes := PackedByteArray()
var _bit := 0
var _end := 0
var _at := 0
var _error := ""
var _detail := ""


func _init(compact_layout: Dictionary) -> void:
	relayout(compact_layout)


## Decodes frames of `compact_layout` from now on (docs/compact-frames.md, "A
## new layout": a `{"layout", "seq"}` message mid-stream): the last key frame is
## forgotten, so a delta frame before the new layout's first key frame is refused.
func relayout(compact_layout: Dictionary) -> void:
	layout = compact_layout
	joints = []
	names = PackedStringArray()
	key_seq = -1
	has_key = false
	if int(layout.get("version", 0)) != 1:
		push_error("inbetween: compact layout version %s" % layout.get("version"))
	events = layout.get("events", [])
	graph = layout.get("graph", {"states": [], "nodes": []})
	for joint in layout["joints"]:
		joints.append(_compile_joint(joint))
		names.append(joint["name"])
	var n := joints.size()
	key.resize(n * STRIDE)
	values.resize(n * STRIDE)
	translations.resize(n * 3)
	rotations.resize(n * 4)
	scales.resize(n * 3)


## One quantised value: `min + (u * (max - min)) / n` in doubles.
static func _field(bits: int, lo: float, hi: float) -> Dictionary:
	return {"bits": bits, "min": lo, "span": hi - lo, "levels": float((1 << bits) - 1)}


static func _value_of(f: Dictionary, u: int) -> float:
	return f["min"] if f["bits"] == 0 else f["min"] + (u * f["span"]) / f["levels"]


static func _axes(a: Dictionary) -> Array:
	var out := []
	for k in 3:
		out.append(_field(int(a["bits"][k]), a["min"][k], a["max"][k]))
	return out


static func _compile_joint(joint: Dictionary) -> Dictionary:
	var r: Dictionary = joint["rotation"]
	var compiled := {"translation": _axes(joint["translation"]), "scale": _axes(joint["scale"])}
	if r.has("constant"):
		compiled["constant"] = r["constant"]
	else:
		var s: Dictionary = r["smallest_three"]
		compiled["largest"] = s["largest"]  # null: sent per frame
		var components := []
		for k in 4:
			components.append(_field(int(s["bits"][k]), s["min"][k], s["max"][k]))
		compiled["components"] = components
	var animated := not compiled.has("constant")
	for f in compiled["translation"] + compiled["scale"]:
		animated = animated or f["bits"] > 0
	compiled["animated"] = animated
	return compiled


func _fail(code: String, detail: String) -> void:
	if _error == "":
		_error = code
		_detail = detail


## Reads a bit field packed least significant bit first (0 on a refusal).
func _read(bits: int) -> int:
	if bits == 0:
		return 0
	if _bit + bits > _end:
		_fail("compact_truncated", "the frame ends before its joint values")
		return 0
	var i := _bit >> 3
	var word := 0
	for k in 4:
		if i + k < _bytes.size():
			word |= _bytes[i + k] << (8 * k)
	word = word >> (_bit & 7)
	_bit += bits
	# Widths are at most 24 bits and the shift at most 7: one 32-bit word holds them.
	return word & ((1 << bits) - 1)


## A LEB128 varint (GDScript's int has 64 bits).
func _read_varint(what: String) -> int:
	var value := 0
	for n in 10:
		if _at >= _bytes.size():
			_fail("compact_truncated", "the frame ends before its %s" % what)
			return 0
		var byte := _bytes[_at]
		_at += 1
		value |= (byte & 0x7f) << (7 * n)
		if (byte & 0x80) == 0:
			return value
	_fail("compact_varint_overflow", "a varint is longer than 64 bits")
	return 0


## A zigzag varint: `(v << 1) ^ (v >> 63)` undone, with a logical shift.
func _read_zigzag() -> int:
	var zz := _read_varint("sent_at")
	return ((zz >> 1) & 0x7FFFFFFFFFFFFFFF) ^ -(zz & 1)


## Decodes one frame (a PackedByteArray). Returns the header and the pose:
## {seq, dropped, sent_at_unix_nanos, clip_time, key, key_seq, translations,
## rotations, scales} (flat PackedFloat32Arrays, 3/4/3 per joint), events
## (crossed since the previous frame, in order: {index, time, name}, index into
## the layout's `events`), root_motion ({delta, total}, each [x, y, z, yaw],
## or null) and graph (a graph stream's report as a JSON frame's `graph` member
## states it, {state, transition?: {from, to, alpha}, weights: {node: [w…]}},
## its numbers f32s; or null); or {error, detail}.
func decode(bytes: PackedByteArray) -> Dictionary:
	var frame := _read_header(bytes)
	if frame.has("error"):
		return frame
	if frame["key"]:
		_read_key()
	elif not has_key or key_seq != frame["key_seq"]:
		var seen: String = str(key_seq) if has_key else "none"
		return _refusal(
			"compact_missing_key_frame",
			(
				"a delta frame refers to key frame %d, and the last key frame seen is %s"
				% [frame["key_seq"], seen]
			)
		)
	else:
		_read_delta()
	_at += 4 + ceili((_bit - (_at + 4) * 8) / 8.0)
	var flags := bytes[0]
	frame["events"] = _read_events() if flags & EVENTS else []
	frame["root_motion"] = _read_root_motion() if flags & ROOT_MOTION else null
	frame["graph"] = _read_graph() if flags & GRAPH else null
	if _error == "" and _at != bytes.size():
		_fail(
			"compact_trailing_bytes",
			"%d bytes follow the frame's last field" % (bytes.size() - _at)
		)
	if _error != "":
		return _refusal(_error, _detail)
	if frame["key"]:
		key = values.duplicate()
		key_seq = frame["seq"]
		has_key = true
	_dequantise()
	frame["translations"] = translations
	frame["rotations"] = rotations
	frame["scales"] = scales
	return frame


## The events section: a count, then indices into the layout's `events`.
func _read_events() -> Array:
	var out := []
	var count := _read_varint("events")
	for n in count:
		if _error != "":
			break
		var index := _read_varint("events")
		if _error == "" and index >= events.size():
			_fail(
				"compact_unknown_event",
				"event %d is not in the layout's %d events" % [index, events.size()]
			)
		elif _error == "":
			out.append(
				{"index": index, "time": events[index]["time"], "name": events[index]["name"]}
			)
	return out


## The root motion section: delta then total, each x, y, z, yaw as little-endian f32s.
func _read_root_motion() -> Variant:
	if _error != "":
		return null
	if _at + 32 > _bytes.size():
		_fail("compact_truncated", "the frame ends before its root motion")
		return null
	var values := []
	for k in 8:
		values.append(_bytes.decode_float(_at + 4 * k))
	_at += 32
	return {"delta": values.slice(0, 4), "total": values.slice(4)}


## The graph report section: the state, the transition (0, or from + 1, to
## and alpha), then each evaluated blend node's index and weights.
func _read_graph() -> Variant:
	var states: Array = graph["states"]
	var nodes: Array = graph["nodes"]
	var state := _graph_index(_read_varint("graph report"), states.size(), "state")
	var from := _read_varint("graph report")
	var report := {}
	if _error == "":
		report["state"] = states[state]
	if _error == "" and from != 0:
		var source := _graph_index(from - 1, states.size(), "state")
		var target := _graph_index(_read_varint("graph report"), states.size(), "state")
		var alpha := _read_f32s(1)
		if _error == "":
			report["transition"] = {"from": states[source], "to": states[target], "alpha": alpha[0]}
	var weights := {}
	var count := _read_varint("graph report")
	var n := 0
	# `count` is unsigned: past 2^63 it reads as negative, and is cut short as the JS decoder's is.
	while _error == "" and (count < 0 or n < count):
		var index := _graph_index(_read_varint("graph report"), nodes.size(), "node")
		if _error == "":
			var node: Dictionary = nodes[index]
			weights[node["name"]] = _read_f32s(int(node["points"]))
		n += 1
	report["weights"] = weights
	if _error != "":
		return null
	return report


## `index` when it is below `known` (an unsigned varint: past 2^63 it reads as
## negative); else a refusal, and 0.
func _graph_index(index: int, known: int, what: String) -> int:
	if _error != "":
		return 0
	if index < 0 or index >= known:
		_fail(
			"compact_unknown_graph_index",
			"graph %s %d is not in the layout's %d" % [what, index, known]
		)
		return 0
	return index


## `count` little-endian f32s of the graph report section.
func _read_f32s(count: int) -> Array:
	var out := []
	if _error != "" or count < 0:
		return out
	if _at + 4 * count > _bytes.size():
		_fail("compact_truncated", "the frame ends before its graph report")
		return out
	for k in count:
		out.append(_bytes.decode_float(_at + 4 * k))
	_at += 4 * count
	return out


static func _refusal(code: String, detail: String) -> Dictionary:
	return {"error": code, "detail": detail}


## The header fields, with the bit reader set on the body that follows.
func _read_header(bytes: PackedByteArray) -> Dictionary:
	_bytes = bytes
	_error = ""
	_at = 1
	if bytes.size() == 0:
		return _refusal("compact_truncated", "the frame ends before its flags")
	var flags := bytes[0]
	if (flags & ~KNOWN_FLAGS) != 0:
		return _refusal(
			"compact_unknown_flags",
			"flags %d use bits other than key frame, events, root motion and graph" % flags
		)
	var seq := _read_varint("seq")
	var dropped := _read_varint("dropped")
	var frame_key_seq := seq - _read_varint("key offset")
	var sent_at := _read_zigzag()
	if _error == "" and _at + 4 > bytes.size():
		_fail("compact_truncated", "the frame ends before its clip time")
	if _error != "":
		return _refusal(_error, _detail)
	_bit = (_at + 4) * 8
	_end = bytes.size() * 8
	return {
		"seq": seq,
		"dropped": dropped,
		"sent_at_unix_nanos": sent_at,
		"clip_time": bytes.decode_float(_at),  # little-endian f32
		"key": (flags & KEY_FRAME) != 0,
		"key_seq": frame_key_seq,
	}


func _read_key() -> void:
	for j in joints.size():
		_read_joint(j)


func _read_delta() -> void:
	values = key.duplicate()
	for j in joints.size():
		if joints[j]["animated"] and _read(1) == 1:
			_read_joint(j)


func _read_joint(j: int) -> void:
	var joint: Dictionary = joints[j]
	var o := j * STRIDE
	if joint.has("components"):
		var sent := typeof(joint["largest"]) == TYPE_NIL
		var largest: int = _read(2) if sent else int(joint["largest"])
		values[o] = largest
		var slot := 1
		for k in 4:
			if k != largest:
				values[o + slot] = _read(joint["components"][k]["bits"])
				slot += 1
	for a in 3:
		values[o + 4 + a] = _read(joint["translation"][a]["bits"])
	for a in 3:
		values[o + 7 + a] = _read(joint["scale"][a]["bits"])


func _dequantise() -> void:
	var small := [0.0, 0.0, 0.0]
	for j in joints.size():
		var joint: Dictionary = joints[j]
		var o := j * STRIDE
		var r := j * 4
		if joint.has("constant"):
			for k in 4:
				rotations[r + k] = joint["constant"][k]
		else:
			var largest := values[o]
			var slot := 0
			for k in 4:
				if k != largest:
					small[slot] = _value_of(joint["components"][k], values[o + 1 + slot])
					slot += 1
			var sum: float = small[0] * small[0] + small[1] * small[1] + small[2] * small[2]
			var big := 0.0
			if sum < 1:
				big = sqrt(1 - sum)
			else:
				var norm := sqrt(sum)
				for s in 3:
					small[s] = small[s] / norm
			slot = 0
			for k in 4:
				if k == largest:
					rotations[r + k] = big
				else:
					rotations[r + k] = small[slot]
					slot += 1
		for a in 3:
			translations[j * 3 + a] = _value_of(joint["translation"][a], values[o + 4 + a])
			scales[j * 3 + a] = _value_of(joint["scale"][a], values[o + 7 + a])


## "0a1b..." -> PackedByteArray, for test vectors.
static func from_hex(hex: String) -> PackedByteArray:
	var out := PackedByteArray()
	out.resize(hex.length() >> 1)
	for i in out.size():
		out[i] = hex.substr(2 * i, 2).hex_to_int()
	return out
