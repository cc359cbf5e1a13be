# Snapshot interpolation for an inbetween stream, as the three.js client's
# (examples/clients/three/buffer.mjs), in Godot 4 GDScript: the pose shown at a
# render time a little behind the newest frame (two ticks by default),
# interpolated between the two frames around it (translations and scales
# lerped, rotations slerped along the shorter arc); a late frame is
# extrapolated from the last two for at most one tick, then held.
#
# Stream time: frame `seq` of a stream at `fps` is due `seq / fps` seconds after
# the first (docs/api.md, Streams), whatever the clip does, so interpolation
# runs on `seq`, never on the clip time. Poses are flat PackedFloat64Arrays: 3
# translation, 4 rotation [x, y, z, w] and 3 scale values per joint.
class_name InbetweenSnapshotBuffer
extends RefCounted

## How far the clock estimate may rise per second of arrivals (a network that got slower for good).
const CLOCK_CREEP := 0.001

var fps: float
var tick: float
var delay: float
var capacity: int
var frames: Array = []  # snapshots, oldest first
var offset := 0.0  # arrival clock minus stream time, seconds: the smallest lateness seen
var has_clock := false
var last_arrival := 0.0


## `delay_ticks`: how far behind the newest frame the render time runs
## (2: one late frame still arrives in time); `keep`: frames kept.
func _init(stream_fps: float, delay_ticks := 2.0, keep := 8) -> void:
	assert(stream_fps > 0, "fps must be positive")
	fps = stream_fps
	tick = 1.0 / fps
	delay = delay_ticks / fps
	capacity = keep


## Writes `a + (b - a) t` for `n` values from `ao` and `bo` into `out` from `oo`.
static func lerp_into(
	out: PackedFloat64Array,
	oo: int,
	a: PackedFloat64Array,
	ao: int,
	b: PackedFloat64Array,
	bo: int,
	n: int,
	t: float
) -> void:
	for k in n:
		out[oo + k] = a[ao + k] + (b[bo + k] - a[ao + k]) * t


## Spherical interpolation of the unit quaternions at `a[ao..]` and `b[bo..]`
## along the shorter arc; `t` outside [0, 1] extrapolates along the same arc.
static func slerp_into(
	out: PackedFloat64Array,
	oo: int,
	a: PackedFloat64Array,
	ao: int,
	b: PackedFloat64Array,
	bo: int,
	t: float
) -> void:
	var dot := a[ao] * b[bo] + a[ao + 1] * b[bo + 1] + a[ao + 2] * b[bo + 2] + a[ao + 3] * b[bo + 3]
	var side := -1.0 if dot < 0 else 1.0
	dot *= side
	var wa := 1.0 - t
	var wb := t
	var near := dot > 1 - 1e-9
	if not near:
		# Not nearly the same rotation (there the arc is a line and sin θ would divide by ~0).
		var theta := acos(dot)
		var s := sin(theta)
		wa = sin((1 - t) * theta) / s
		wb = sin(t * theta) / s
	wb *= side
	for k in 4:
		out[oo + k] = wa * a[ao + k] + wb * b[bo + k]
	if near:
		var n := sqrt(
			(
				out[oo] * out[oo]
				+ out[oo + 1] * out[oo + 1]
				+ out[oo + 2] * out[oo + 2]
				+ out[oo + 3] * out[oo + 3]
			)
		)
		for k in 4:
			out[oo + k] /= n


## The pose a sample writes, for `joints` joints.
static func empty_pose(joints: int) -> Dictionary:
	var pose := {
		"translations": PackedFloat64Array(),
		"rotations": PackedFloat64Array(),
		"scales": PackedFloat64Array(),
		"root": PackedFloat64Array([0, 0, 0, 0]),
		"has_root": false,
	}
	pose["translations"].resize(joints * 3)
	pose["rotations"].resize(joints * 4)
	pose["scales"].resize(joints * 3)
	return pose


## Keeps `frame` (a decoded frame: seq, clip_time, pose arrays, optional root
## [x, y, z, yaw]), which arrived at `arrival_ms`.
func push(frame: Dictionary, arrival_ms: float) -> void:
	var shot := {
		"seq": frame["seq"],
		"time": frame["seq"] / fps,
		"clip_time": frame["clip_time"],
		"translations": _doubles(frame["translations"]),
		"rotations": _doubles(frame["rotations"]),
		"scales": _doubles(frame["scales"]),
		"root": null if typeof(frame.get("root")) == TYPE_NIL else _doubles(frame["root"]),
	}
	if not frames.is_empty() and shot["seq"] <= frames.back()["seq"]:
		# A new stream (seq starts again): forget the old one's frames and clock.
		frames.clear()
		has_clock = false
	frames.append(shot)
	if frames.size() > capacity:
		frames.pop_front()
	_observe(arrival_ms / 1000.0, shot["time"])


## A copy in doubles of a pose array (a decoder's PackedFloat32Array, a JSON frame's Array).
static func _doubles(values) -> PackedFloat64Array:
	var out := PackedFloat64Array()
	out.resize(values.size())
	for k in values.size():
		out[k] = values[k]
	return out


## The clock estimate: the least lateness seen, rising slowly so a lasting slow-down is followed.
func _observe(arrival: float, stream_time: float) -> void:
	var lateness := arrival - stream_time
	var crept := lateness if not has_clock else offset + CLOCK_CREEP * (arrival - last_arrival)
	offset = minf(lateness, crept)
	has_clock = true
	last_arrival = arrival


## The stream time to show at `now_ms` (the clock of `push`), or NAN before the first frame.
func render_time(now_ms: float) -> float:
	return now_ms / 1000.0 - offset - delay if has_clock else NAN


## Writes the pose at stream time `time` into `out` (`empty_pose`). Returns
## {mode, from, to, alpha}: mode "interpolate" (between from and to),
## "extrapolate" (past the newest, at most a tick) or "hold"; {} without frames.
func sample(time: float, out: Dictionary) -> Dictionary:
	if frames.is_empty():
		return {}
	var newest: Dictionary = frames.back()
	if frames.size() == 1 or time <= frames[0]["time"]:
		var only: Dictionary = frames[0] if time <= frames[0]["time"] else newest
		_blend(only, only, 0.0, out)
		return {"mode": "hold", "from": only, "to": only, "alpha": 0.0}
	if time <= newest["time"]:
		var i := frames.size() - 1
		while frames[i - 1]["time"] > time:
			i -= 1
		var from: Dictionary = frames[i - 1]
		var to: Dictionary = frames[i]
		var alpha: float = (time - from["time"]) / (to["time"] - from["time"])
		_blend(from, to, alpha, out)
		return {"mode": "interpolate", "from": from, "to": to, "alpha": alpha}
	var before: Dictionary = frames[frames.size() - 2]
	var limit: float = newest["time"] + tick
	var t: float = (minf(time, limit) - before["time"]) / (newest["time"] - before["time"])
	_blend(before, newest, t, out)
	var mode := "extrapolate" if time <= limit else "hold"
	return {"mode": mode, "from": before, "to": newest, "alpha": t}


func _blend(a: Dictionary, b: Dictionary, t: float, out: Dictionary) -> void:
	var joints: int = a["rotations"].size() / 4
	for j in joints:
		lerp_into(
			out["translations"], 3 * j, a["translations"], 3 * j, b["translations"], 3 * j, 3, t
		)
		slerp_into(out["rotations"], 4 * j, a["rotations"], 4 * j, b["rotations"], 4 * j, t)
		lerp_into(out["scales"], 3 * j, a["scales"], 3 * j, b["scales"], 3 * j, 3, t)
	out["has_root"] = typeof(a["root"]) != TYPE_NIL and typeof(b["root"]) != TYPE_NIL
	if out["has_root"]:
		lerp_into(out["root"], 0, a["root"], 0, b["root"], 0, 4, t)
