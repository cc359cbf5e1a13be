-- Clips: one row per clip, the canonical document plus the few derived
-- figures a listing shows (so a list never reads or compiles documents).
-- Portable SQL on purpose: migrations/postgres will mirror this file.
-- Times are Unix milliseconds (BIGINT), ids are UUIDv7 text (time-ordered,
-- so `ORDER BY id` is creation order and cursor pagination is stable).
CREATE TABLE clips (
    id          TEXT             NOT NULL PRIMARY KEY,
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
