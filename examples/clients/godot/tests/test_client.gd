# The Godot client's checks, with no scene and no server: every frame of every
# test vector in docs/compact-frames/ decodes to exactly the pose it states
# (the vectors the JavaScript, Python, C# and Rust decoders are tested on); a
# frame the decoder must refuse is refused with its code; the snapshot buffer
# and its slerp give the hand-computed poses of the three.js client's tests
# (examples/clients/three/tests/buffer.test.mjs); names and the token are
# found as Godot renames bones and as a game passes arguments.
#
#   godot --headless --path examples/clients/godot --script tests/test_client.gd
#   godot --headless --path examples/clients/godot --script tests/test_client.gd -- --vectors DIR
#
# Prints one line per check and "N passed, N failed"; exits 1 when any failed.
extends SceneTree

const Compact = preload("../compact.gd")
const SnapshotBuffer = preload("../snapshot_buffer.gd")
const Names = preload("../names.gd")

var passed := 0
var failed := 0


func _init() -> void:
	var vectors := _vectors_dir()
	var files := DirAccess.get_files_at(vectors)
	var loaded := []
	for file in files:
		if file.ends_with(".json"):
			loaded.append(JSON.parse_string(FileAccess.get_file_as_string(vectors.path_join(file))))
	_check(loaded.size() >= 5, "%d vectors in %s" % [loaded.size(), vectors])
	for vector in loaded:
		_check_vector(vector)
	_check_refusals(loaded)
	_check_graph(loaded)
	_check_relayout(loaded)
	_check_slerp()
	_check_buffer()
	_check_names()
	print("%d passed, %d failed" % [passed, failed])
	quit(1 if failed > 0 else 0)


func _vectors_dir() -> String:
	var args := OS.get_cmdline_user_args()
	var at := args.find("--vectors")
	if at >= 0 and at + 1 < args.size():
		return args[at + 1]
	return (
		ProjectSettings
		. globalize_path("res://")
		. path_join("../../../docs/compact-frames")
		. simplify_path()
	)


func _check(ok: bool, what: String) -> void:
	if ok:
		passed += 1
	else:
		failed += 1
		printerr("FAILED: %s" % what)


## Rows of numbers as f32 values, flat: the vector's pose as the decoder stores it.
static func _f32(rows: Array) -> PackedFloat32Array:
	var out := PackedFloat32Array()
	for row in rows:
		for x in row:
			out.append(x)
	return out


func _check_vector(vector: Dictionary) -> void:
	var decoder := Compact.new(vector["layout"])
	for frame in vector["frames"]:
		var what := "%s seq %d" % [vector["name"], int(frame["seq"])]
		if frame.has("layout"):  # a new layout mid-stream
			decoder.relayout(frame["layout"])
		var got := decoder.decode(Compact.from_hex(frame["hex"]))
		if got.has("error"):
			_check(false, "%s: %s %s" % [what, got["error"], got["detail"]])
			continue
		_check(got["key"] == frame["key"], what + ": key")
		_check(got["seq"] == int(frame["seq"]), what + ": seq")
		_check(got["dropped"] == int(frame["dropped"]), what + ": dropped")
		_check(
			got["sent_at_unix_nanos"] == String(frame["sent_at_unix_nanos"]).to_int(),
			what + ": sent_at"
		)
		_check(got["clip_time"] == _f32([[frame["clip_time"]]])[0], what + ": clip_time")
		_check(got["rotations"] == _f32(frame["pose"]["rotations"]), what + ": rotations")
		_check(got["translations"] == _f32(frame["pose"]["translations"]), what + ": translations")
		_check(got["scales"] == _f32(frame["pose"]["scales"]), what + ": scales")
		var indices := []
		for e in got["events"]:
			indices.append(e["index"])
		_check(indices == frame.get("events", []).map(func(i): return int(i)), what + ": events")
		var root = frame.get("root_motion")
		var want = null
		if root != null:
			want = {
				"delta": Array(_f32([root["delta"]])).map(func(x): return float(x)),
				"total": Array(_f32([root["total"]])).map(func(x): return float(x)),
			}
		_check(got["root_motion"] == want, what + ": root motion")
		var report = null
		if frame.has("graph"):
			report = _named(vector["layout"]["graph"], frame["graph"])
		_check(got["graph"] == report, what + ": graph report")


## Numbers as f32 values, in an Array as the decoder returns them.
static func _f32_list(numbers: Array) -> Array:
	return Array(_f32([numbers])).map(func(x): return float(x))


## A vector's graph report (indices into the layout's `graph`) as the decoder
## names it (the JavaScript test's `named`), numbers as f32s.
static func _named(graph: Dictionary, report: Dictionary) -> Dictionary:
	var states: Array = graph["states"]
	var out := {"state": states[int(report["state"])]}
	var t = report["transition"]
	if t != null:
		out["transition"] = {
			"from": states[int(t["from"])],
			"to": states[int(t["to"])],
			"alpha": _f32_list([t["alpha"]])[0],
		}
	var weights := {}
	for w in report["weights"]:
		weights[graph["nodes"][int(w["node"])]["name"]] = _f32_list(w["weights"])
	out["weights"] = weights
	return out


func _check_relayout(vectors: Array) -> void:
	var vector: Dictionary = vectors.filter(func(v): return v["name"] == "relayout")[0]
	var frames: Array = vector["frames"]
	var decoder := Compact.new(vector["layout"])
	decoder.decode(Compact.from_hex(frames[0]["hex"]))
	decoder.decode(Compact.from_hex(frames[1]["hex"]))
	decoder.relayout(frames[2]["layout"])
	var early := decoder.decode(Compact.from_hex(frames[3]["hex"]))
	_check(early.get("error") == "compact_missing_key_frame", "a new layout forgets the old key frame")
	_check(decoder.decode(Compact.from_hex(frames[2]["hex"]))["key"], "the new layout's key frame")
	_check(not decoder.decode(Compact.from_hex(frames[3]["hex"])).has("error"), "its delta frame")


func _check_refusals(vectors: Array) -> void:
	var bench: Dictionary = vectors.filter(func(v): return v["name"] == "bench20")[0]
	var decoder := Compact.new(bench["layout"])
	var delta := Compact.from_hex(bench["frames"][1]["hex"])
	_check(
		decoder.decode(delta).get("error") == "compact_missing_key_frame",
		"a delta frame without its key frame"
	)
	var key := Compact.from_hex(bench["frames"][0]["hex"])
	var cut := key.slice(0, key.size() - 1)
	_check(decoder.decode(cut).get("error") == "compact_truncated", "a key frame cut short")
	var longer := key.duplicate()
	longer.append(0)
	_check(
		decoder.decode(longer).get("error") == "compact_trailing_bytes", "a byte after the frame"
	)
	var flagged := key.duplicate()
	flagged[0] = 16
	_check(decoder.decode(flagged).get("error") == "compact_unknown_flags", "an unknown flag")
	_check(not decoder.decode(key).has("error"), "the key frame itself decodes")
	_check(not decoder.decode(delta).has("error"), "and then its delta frame")
	var stepping: Dictionary = vectors.filter(func(v): return v["name"] == "stepping")[0]
	var unknown := Compact.from_hex(stepping["frames"][0]["hex"])  # events [0], then root motion
	unknown[unknown.size() - 33] = stepping["layout"]["events"].size()
	_check(
		Compact.new(stepping["layout"]).decode(unknown).get("error") == "compact_unknown_event",
		"an event past the layout's list"
	)


## The graph-report vector's last report written out (move; walkrun halved, aim
## at 1/8, 3/8, 1/2: exact in f32), and the JavaScript test's refusals: the
## state, transition from and to, and node index past the layout's three states
## or two nodes, a report cut short, and a report against a layout without graph.
func _check_graph(vectors: Array) -> void:
	var vector: Dictionary = vectors.filter(func(v): return v["name"] == "graph-report")[0]
	var frames: Array = vector["frames"]
	var decoder := Compact.new(vector["layout"])
	var key := Compact.from_hex(frames[0]["hex"])
	_check(
		decoder.decode(key)["graph"] == {"state": "idle", "weights": {}}, "the key frame's report"
	)
	var delta := Compact.from_hex(frames[1]["hex"])
	var last := decoder.decode(Compact.from_hex(frames[2]["hex"]))
	var want := {"state": "move", "weights": {"walkrun": [0.5, 0.5], "aim": [0.125, 0.375, 0.5]}}
	_check(last["graph"] == want, "the last frame's report: %s" % last["graph"])
	decoder.decode(key)
	var at := delta.size() - 4 - 4 - 1 - 1 - 4 - 1 - 1 - 1  # the state
	_check(delta[at] == 2, "the delta frame's state byte")
	for case in [[0, 3], [1, 4], [2, 3], [8, 2]]:
		var bad := delta.duplicate()
		bad[at + case[0]] = case[1]
		_check(
			decoder.decode(bad).get("error") == "compact_unknown_graph_index",
			"graph report byte %d = %d" % case
		)
	var cut := delta.slice(0, delta.size() - 1)
	_check(decoder.decode(cut).get("error") == "compact_truncated", "a graph report cut short")
	var plain: Dictionary = vector["layout"].duplicate()
	plain.erase("graph")
	_check(
		Compact.new(plain).decode(key).get("error") == "compact_unknown_graph_index",
		"a graph report against a layout without graph"
	)


## The unit quaternion of `deg` degrees about +Z, [x, y, z, w].
static func _about_z(deg: float) -> PackedFloat64Array:
	return PackedFloat64Array([0, 0, sin(deg * PI / 360), cos(deg * PI / 360)])


func _close(got: PackedFloat64Array, want: PackedFloat64Array, what: String, eps := 1e-12) -> void:
	var ok := got.size() >= want.size()
	for k in want.size():
		ok = ok and absf(got[k] - want[k]) <= eps
	_check(ok, "%s: %s against %s" % [what, got, want])


func _check_slerp() -> void:
	var out := PackedFloat64Array([0, 0, 0, 0])
	for case in [
		[0.0, 0.0], [1.0 / 3, 30.0], [0.5, 45.0], [1.0, 90.0], [1.5, 135.0], [-0.5, -45.0]
	]:
		SnapshotBuffer.slerp_into(out, 0, _about_z(0), 0, _about_z(90), 0, case[0])
		_close(out, _about_z(case[1]), "slerp at t = %s" % case[0])
	var negated := _about_z(90)
	for k in 4:
		negated[k] = -negated[k]
	SnapshotBuffer.slerp_into(out, 0, _about_z(0), 0, negated, 0, 0.5)
	_close(out, _about_z(45), "slerp to a negated end")


## A one-joint frame: translation x = 10 seq, rotation 30 seq degrees about Z, scale 1 + seq.
static func _frame(seq: int) -> Dictionary:
	return {
		"seq": seq,
		"clip_time": seq / 20.0,
		"translations": [10.0 * seq, 0.0, 0.0],
		"rotations": _about_z(30.0 * seq),
		"scales": [1.0 + seq, 1.0, 1.0],
	}


func _check_buffer() -> void:
	var buffer := SnapshotBuffer.new(20.0)
	var arrivals := [1012.0, 1065.0, 1105.0, 1170.0]
	for seq in 4:
		buffer.push(_frame(seq), arrivals[seq])
	# Least lateness 1005 ms, crept by 1 ms a second over the 65 ms to the next
	# arrival; two ticks behind.
	_check(absf(buffer.render_time(1230) - (0.125 - 0.000065)) < 1e-12, "render time")
	var pose := SnapshotBuffer.empty_pose(1)
	var shown := buffer.sample(0.125, pose)
	_check(shown["mode"] == "interpolate" and shown["from"]["seq"] == 2, "interpolates from seq 2")
	_check(absf(shown["alpha"] - 0.5) < 1e-12, "halfway")
	_close(pose["translations"], PackedFloat64Array([25, 0, 0]), "translation")
	_close(pose["rotations"], _about_z(75), "rotation")
	_close(pose["scales"], PackedFloat64Array([3.5, 1, 1]), "scale")

	var late := SnapshotBuffer.new(20.0)
	for seq in 3:
		late.push(_frame(seq), 50.0 * seq)
	shown = late.sample(0.125, pose)
	_check(shown["mode"] == "extrapolate", "half a tick past the newest: extrapolated")
	_close(pose["rotations"], _about_z(75), "extrapolated rotation")
	shown = late.sample(10.0, pose)
	_check(shown["mode"] == "hold", "far past the newest: held")
	_close(pose["translations"], PackedFloat64Array([30, 0, 0]), "held one tick past the newest")
	_close(pose["rotations"], _about_z(90), "held rotation")
	late.push(_frame(4), 260.0)
	shown = late.sample(0.15, pose)
	_check(
		shown["mode"] == "interpolate" and shown["to"]["seq"] == 4, "interpolated across the gap"
	)


func _check_names() -> void:
	_check(
		Names.godot_name("mixamorig:Hips") == "mixamorig_Hips", "mixamorig:Hips as Godot names it"
	)
	var joints := PackedStringArray(["mixamorig:Hips", "mixamorig:Spine", "Tail"])
	var bones := PackedStringArray(["mixamorig_Hips", "mixamorig:Spine", "mixamorig_Spine"])
	_check(
		Names.match_names(joints, bones) == PackedInt32Array([0, 1, -1]),
		"exact name first, then Godot's"
	)
	var none := PackedStringArray()
	_check(Names.token_from("", PackedStringArray(["--token", "T"]), "E") == "T", "--token T")
	_check(Names.token_from("", PackedStringArray(["--token=U"]), "E") == "U", "--token=U")
	_check(Names.token_from("", none, "E") == "E", "INBETWEEN_TOKEN")
	_check(
		Names.token_from("P", PackedStringArray(["--token", "T"]), "E") == "P", "the property first"
	)
