-- Broadcast checkpoints: the same table as
-- migrations/sqlite/0005_broadcast_checkpoints.sql (see there). Not
-- announced: a node reads the newest checkpoint when it adopts a broadcast.
CREATE TABLE broadcast_checkpoints (
    broadcast_id  TEXT COLLATE "C" NOT NULL REFERENCES broadcasts (id) ON DELETE CASCADE,
    seq           BIGINT           NOT NULL,
    state         TEXT             NOT NULL,
    PRIMARY KEY (broadcast_id, seq)
);
