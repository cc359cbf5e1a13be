-- Characters (docs/characters.md): the same tables as
-- migrations/sqlite/0006_characters.sql (see there). `id` sorts bytewise
-- (COLLATE "C") so `ORDER BY id` is creation order whatever the locale;
-- `?name_prefix=` is a bytewise range on `characters_by_name_bytewise`.
CREATE TABLE characters (
    id          TEXT COLLATE "C" NOT NULL PRIMARY KEY,
    name        TEXT             NOT NULL,
    version     BIGINT           NOT NULL,
    doc         TEXT             NOT NULL,
    joints      BIGINT           NOT NULL,
    roles       TEXT             NOT NULL,
    created_at  BIGINT           NOT NULL,
    updated_at  BIGINT           NOT NULL
);
CREATE INDEX characters_by_name ON characters (name, id);
CREATE INDEX characters_by_name_bytewise ON characters ((name COLLATE "C"), id);

CREATE TABLE character_meshes (
    character_id TEXT COLLATE "C" NOT NULL PRIMARY KEY REFERENCES characters (id) ON DELETE CASCADE,
    etag         TEXT             NOT NULL,
    bytes        BYTEA            NOT NULL
);
