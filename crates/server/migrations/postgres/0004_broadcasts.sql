-- Broadcasts (SPEC §9): the same tables as migrations/sqlite/0004_broadcasts.sql
-- (see there), announced to every node on the schema's channel as clips are
-- (0001_clips.sql): `broadcast 0 <id>` when one is created, `unbroadcast 0
-- <id>` when it is deleted, `control 0 <broadcast id>` for each control.
-- The nodes read the rows back; the payload only says where to look.
CREATE TABLE broadcasts (
    id          TEXT COLLATE "C" NOT NULL PRIMARY KEY,
    definition  TEXT             NOT NULL,
    created_at  BIGINT           NOT NULL,
    active_at   BIGINT           NOT NULL
);

CREATE TABLE broadcast_controls (
    id            TEXT COLLATE "C" NOT NULL PRIMARY KEY,
    broadcast_id  TEXT COLLATE "C" NOT NULL REFERENCES broadcasts (id) ON DELETE CASCADE,
    seq           BIGINT           NOT NULL,
    control       TEXT             NOT NULL
);
CREATE INDEX broadcast_controls_by_broadcast ON broadcast_controls (broadcast_id, seq, id);

CREATE FUNCTION inbetween_broadcasts_notify() RETURNS trigger AS $$
BEGIN
    IF TG_TABLE_NAME = 'broadcast_controls' THEN
        PERFORM pg_notify('inbetween_clips_' || TG_TABLE_SCHEMA, 'control 0 ' || NEW.broadcast_id);
    ELSIF TG_OP = 'DELETE' THEN
        PERFORM pg_notify('inbetween_clips_' || TG_TABLE_SCHEMA, 'unbroadcast 0 ' || OLD.id);
    ELSE
        PERFORM pg_notify('inbetween_clips_' || TG_TABLE_SCHEMA, 'broadcast 0 ' || NEW.id);
    END IF;
    RETURN NULL;
END;
$$ LANGUAGE plpgsql;

CREATE TRIGGER broadcasts_notify
    AFTER INSERT OR DELETE ON broadcasts
    FOR EACH ROW EXECUTE FUNCTION inbetween_broadcasts_notify();

CREATE TRIGGER broadcast_controls_notify
    AFTER INSERT ON broadcast_controls
    FOR EACH ROW EXECUTE FUNCTION inbetween_broadcasts_notify();
