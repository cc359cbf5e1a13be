-- Clips: the same table as migrations/sqlite/0001_clips.sql (one row per
-- clip, the canonical document plus the figures a listing shows).
-- `id` sorts bytewise (COLLATE "C") so `ORDER BY id` is creation order
-- whatever the database's locale.
CREATE TABLE clips (
    id          TEXT COLLATE "C" NOT NULL PRIMARY KEY,
    name        TEXT             NOT NULL,
    version     BIGINT           NOT NULL,
    doc         TEXT             NOT NULL,
    joints      BIGINT           NOT NULL,
    tracks      BIGINT           NOT NULL,
    events      BIGINT           NOT NULL,
    start_time  DOUBLE PRECISION NOT NULL,
    end_time    DOUBLE PRECISION NOT NULL,
    playback    TEXT             NOT NULL,
    created_at  BIGINT           NOT NULL,
    updated_at  BIGINT           NOT NULL
);

CREATE INDEX clips_by_name ON clips (name, id);

-- Cross-node cache invalidation: every committed change to a clip is
-- announced on the channel `inbetween_clips_<schema>` (one channel per
-- schema, so several deployments or test schemas in one database do not
-- hear each other). NOTIFY is transactional: listeners hear of a change
-- only once it is committed, and never of a rolled-back one.
-- Payload: `<op> <version> <id>`, op one of create | replace | delete.
CREATE FUNCTION inbetween_clips_notify() RETURNS trigger AS $$
BEGIN
    IF TG_OP = 'DELETE' THEN
        PERFORM pg_notify('inbetween_clips_' || TG_TABLE_SCHEMA, 'delete ' || OLD.version || ' ' || OLD.id);
    ELSIF TG_OP = 'INSERT' THEN
        PERFORM pg_notify('inbetween_clips_' || TG_TABLE_SCHEMA, 'create ' || NEW.version || ' ' || NEW.id);
    ELSE
        PERFORM pg_notify('inbetween_clips_' || TG_TABLE_SCHEMA, 'replace ' || NEW.version || ' ' || NEW.id);
    END IF;
    RETURN NULL;
END;
$$ LANGUAGE plpgsql;

CREATE TRIGGER clips_notify
    AFTER INSERT OR UPDATE OR DELETE ON clips
    FOR EACH ROW EXECUTE FUNCTION inbetween_clips_notify();
