-- Characters (docs/characters.md): a skeleton with its humanoid roles and,
-- when imported from a glTF skin, its skinned mesh. Stored and versioned
-- like clips. The same tables as migrations/postgres/0006_characters.sql.
--
-- `doc` is the canonical character document (name, skeleton, given
-- roles); `joints` and `roles` are what a listing shows, derived from it
-- when it is written (`roles`: the role map as JSON, role → joint and how
-- it was found), so a list never reads documents. Names identify
-- characters as they do clips: the check runs in the write's transaction,
-- so `characters_by_name` needs no uniqueness (it could not have it for
-- clips stored before names were unique, and stays alike here).
CREATE TABLE characters (
    id          TEXT   NOT NULL PRIMARY KEY,
    name        TEXT   NOT NULL,
    version     BIGINT NOT NULL,
    doc         TEXT   NOT NULL,
    joints      BIGINT NOT NULL,
    roles       TEXT   NOT NULL,
    created_at  BIGINT NOT NULL,
    updated_at  BIGINT NOT NULL
);
CREATE INDEX characters_by_name ON characters (name, id);

-- The skinned mesh an import keeps with a character, as `clip_meshes`
-- keeps a clip's: written in the character's transaction, dropped by a
-- replace from JSON, gone with its character.
CREATE TABLE character_meshes (
    character_id TEXT NOT NULL PRIMARY KEY REFERENCES characters (id) ON DELETE CASCADE,
    etag         TEXT NOT NULL,
    bytes        BLOB NOT NULL
) WITHOUT ROWID;
