-- What the clip list filters on (issue 18): tags, joint names, durations.
-- The same tables as migrations/sqlite/0002_clip_index.sql.
--
-- `tags` holds the document's tags as a JSON array, so a listing renders
-- them without reading documents; `clip_tags` and `clip_joints` hold one
-- row per tag and per joint name, for `?tag=` and `?compatible_with=`.
-- Rows go with their clip (ON DELETE CASCADE). Both are rewritten with the
-- clip on every create and replace, in the same transaction; the NOTIFY
-- trigger stays on `clips` alone (one announcement per change, at commit).
ALTER TABLE clips ADD COLUMN tags TEXT NOT NULL DEFAULT '[]';

CREATE TABLE clip_tags (
    clip_id TEXT COLLATE "C" NOT NULL REFERENCES clips (id) ON DELETE CASCADE,
    tag     TEXT             NOT NULL,
    PRIMARY KEY (clip_id, tag)
);
CREATE INDEX clip_tags_by_tag ON clip_tags (tag, clip_id);

CREATE TABLE clip_joints (
    clip_id TEXT COLLATE "C" NOT NULL REFERENCES clips (id) ON DELETE CASCADE,
    joint   TEXT             NOT NULL,
    PRIMARY KEY (clip_id, joint)
);
CREATE INDEX clip_joints_by_joint ON clip_joints (joint, clip_id);

-- `?min_duration=` / `?max_duration=` compare this very expression.
CREATE INDEX clips_by_duration ON clips ((end_time - start_time), id);

-- `?name_prefix=` is a bytewise range (code-point order, as SQLite's
-- BINARY collation), whatever the database's locale.
CREATE INDEX clips_by_name_bytewise ON clips ((name COLLATE "C"), id);

-- Clips stored before this migration: their joint names, read once from
-- the stored documents (the only time the store reads one). A clip's joints
-- are its skeleton's, or without a skeleton the joints its tracks name
-- (anim::Clip::build); a skeleton names every joint its tracks do, so the
-- union of both is exact either way. No clip had tags before.
INSERT INTO clip_joints (clip_id, joint)
SELECT c.id, j ->> 'name' FROM clips c, jsonb_array_elements(COALESCE(c.doc::jsonb #> '{skeleton,joints}', '[]')) j
UNION
SELECT c.id, t ->> 'joint' FROM clips c, jsonb_array_elements(c.doc::jsonb -> 'tracks') t;
