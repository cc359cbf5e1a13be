# Joint names against the bone names Godot gave them, and the token to send.
# A stream names joints as the clip's source file did (`mixamorig:Hips`);
# Godot's scene importer does not allow `:` or `/` in a bone name and turns
# them into `_` (`mixamorig_Hips`). A joint binds to the bone of its exact name,
# else to the bone of its rewritten name, as the three.js client's names.mjs
# does with three.js's own rule.
class_name InbetweenNames
extends RefCounted


## The name Godot's importer gives a bone named `name` in the source file.
static func godot_name(name: String) -> String:
	return name.replace(":", "_").replace("/", "_")


## For each of `joints` (the stream's names), the index in `bones` (the
## skeleton's names) it binds to, or -1. The first bone of a repeated name wins.
static func match_names(joints: PackedStringArray, bones: PackedStringArray) -> PackedInt32Array:
	var index := {}
	for i in bones.size():
		if not index.has(bones[i]):
			index[bones[i]] = i
	var out := PackedInt32Array()
	for name in joints:
		out.append(index.get(name, index.get(godot_name(name), -1)))
	return out


## The bearer token: `property` when set, else `--token T` or `--token=T` among
## `args` (the game's own arguments, after `--`), else `env`; "" for none.
static func token_from(property: String, args: PackedStringArray, env: String) -> String:
	if property != "":
		return property
	for i in args.size():
		if args[i] == "--token" and i + 1 < args.size():
			return args[i + 1]
		if args[i].begins_with("--token="):
			return args[i].trim_prefix("--token=")
	return env
