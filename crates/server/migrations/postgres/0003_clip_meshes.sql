-- The skinned mesh a glTF import keeps with a clip, for the viewer (issue 20).
-- The same table as migrations/sqlite/0003_clip_meshes.sql.
--
-- At most one per clip, written in the clip's own transaction: an import
-- stores it with the clip row; a replace by PUT drops it (a new document may
-- move or rename joints); a PATCH keeps it (it cannot touch the skeleton).
-- It goes with its clip (ON DELETE CASCADE); the NOTIFY trigger stays on
-- `clips`, whose row changes in the same transaction. `bytes` is the binary
-- form of docs/mesh-format.md as the import wrote it; `etag` the entity tag
-- it is served with, a hash of those bytes.
CREATE TABLE clip_meshes (
    clip_id TEXT COLLATE "C" NOT NULL PRIMARY KEY REFERENCES clips (id) ON DELETE CASCADE,
    etag    TEXT             NOT NULL,
    bytes   BYTEA            NOT NULL
);
