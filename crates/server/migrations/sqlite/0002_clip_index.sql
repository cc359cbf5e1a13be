-- What the clip list filters on (issue 18): tags, joint names, durations.
-- The same tables as migrations/postgres/0002_clip_index.sql.
--
-- `tags` holds the document's tags as a JSON array, so a listing renders
-- them without reading documents; `clip_tags` and `clip_joints` hold one
-- row per tag and per joint name, for `?tag=` and `?compatible_with=`.
-- Rows go with their clip (ON DELETE CASCADE; foreign_keys is ON on every
-- connection). Both are rewritten with the clip on every create and
-- replace, in the same transaction.
ALTER TABLE clips ADD COLUMN tags TEXT NOT NULL DEFAULT '[]';

CREATE TABLE clip_tags (
    clip_id TEXT NOT NULL REFERENCES clips (id) ON DELETE CASCADE,
    tag     TEXT NOT NULL,
    PRIMARY KEY (clip_id, tag)
) WITHOUT ROWID;
CREATE INDEX clip_tags_by_tag ON clip_tags (tag, clip_id);

CREATE TABLE clip_joints (
    clip_id TEXT NOT NULL REFERENCES clips (id) ON DELETE CASCADE,
    joint   TEXT NOT NULL,
    PRIMARY KEY (clip_id, joint)
) WITHOUT ROWID;
CREATE INDEX clip_joints_by_joint ON clip_joints (joint, clip_id);

-- `?min_duration=` / `?max_duration=` compare this very expression.
CREATE INDEX clips_by_duration ON clips ((end_time - start_time), id);

-- Clips stored before this migration: their joint names, read once from
-- the stored documents (the only time the store reads one). A clip's joints
-- are its skeleton's, or without a skeleton the joints its tracks name
-- (anim::Clip::build); a skeleton names every joint its tracks do, so the
-- union of both is exact either way. No clip had tags before.
INSERT OR IGNORE INTO clip_joints (clip_id, joint)
SELECT c.id, json_extract(j.value, '$.name') FROM clips c, json_each(c.doc, '$.skeleton.joints') j;
INSERT OR IGNORE INTO clip_joints (clip_id, joint)
SELECT c.id, json_extract(t.value, '$.joint') FROM clips c, json_each(c.doc, '$.tracks') t;
