-- Broadcasts (SPEC §9): what a broadcast is and the controls stamped on it,
-- so that every node computes the same frames from them and a restarted
-- node resumes them. The same tables as migrations/postgres/0004_broadcasts.sql.
--
-- `definition` is the JSON the server needs to build the broadcast again
-- (the creation request as sent, and the versions its clips were pinned
-- at); `created_at` is the Unix nanosecond of its tick 0 (tick k is due
-- at created_at + k/fps); `active_at` the Unix millisecond a node last had
-- viewers of it or accepted a control (the idle end is decided on it).
CREATE TABLE broadcasts (
    id          TEXT   NOT NULL PRIMARY KEY,
    definition  TEXT   NOT NULL,
    created_at  BIGINT NOT NULL,
    active_at   BIGINT NOT NULL
);

-- One row per accepted control: `seq` is the tick it applies from, `id` a
-- UUIDv7 that orders the controls of one tick the same way on every node.
-- `control` is the JSON the server parses again (a stream control message,
-- and a crossfade's pinned clip versions).
CREATE TABLE broadcast_controls (
    id            TEXT   NOT NULL PRIMARY KEY,
    broadcast_id  TEXT   NOT NULL REFERENCES broadcasts (id) ON DELETE CASCADE,
    seq           BIGINT NOT NULL,
    control       TEXT   NOT NULL
);
CREATE INDEX broadcast_controls_by_broadcast ON broadcast_controls (broadcast_id, seq, id);
