-- Animation graphs (docs/graphs.md): the same table as
-- migrations/sqlite/0007_graphs.sql (see there). `id` sorts bytewise
-- (COLLATE "C") so `ORDER BY id` is creation order whatever the locale;
-- `?name_prefix=` is a bytewise range on `graphs_by_name_bytewise`.
CREATE TABLE graphs (
    id          TEXT COLLATE "C" NOT NULL PRIMARY KEY,
    name        TEXT             NOT NULL,
    version     BIGINT           NOT NULL,
    doc         TEXT             NOT NULL,
    nodes       BIGINT           NOT NULL,
    summary     TEXT             NOT NULL,
    created_at  BIGINT           NOT NULL,
    updated_at  BIGINT           NOT NULL
);
CREATE INDEX graphs_by_name ON graphs (name, id);
CREATE INDEX graphs_by_name_bytewise ON graphs ((name COLLATE "C"), id);

-- Every node caches built graphs and characters by id and version
-- (`server::documents`), so their changes are announced as clips' are
-- (migrations/postgres/0001_clips.sql): `<op> <version> <id>` on the
-- schema's channel. Ids are UUIDs, unique across the tables, so a
-- listener tells nothing more than the id apart.
CREATE TRIGGER graphs_notify
    AFTER INSERT OR UPDATE OR DELETE ON graphs
    FOR EACH ROW EXECUTE FUNCTION inbetween_clips_notify();
CREATE TRIGGER characters_notify
    AFTER INSERT OR UPDATE OR DELETE ON characters
    FOR EACH ROW EXECUTE FUNCTION inbetween_clips_notify();
