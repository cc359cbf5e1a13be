-- Broadcast checkpoints (docs/broadcasts.md, "Checkpoints"): a broadcast's
-- state after tick `seq`, written by the nodes that run it every checkpoint
-- interval, so that a restarted or late node steps on from the newest one
-- instead of from tick 0. The same table as
-- migrations/postgres/0005_broadcast_checkpoints.sql.
--
-- `state` is the JSON the server reads back (numbers as their bits, the
-- motions named by the controls that made them); every node writes the
-- same text for the same tick, so a second write of a row replaces it with
-- itself. Only the newest row of a broadcast is kept, and the controls
-- stamped at or before its `seq` are deleted, except those it names.
CREATE TABLE broadcast_checkpoints (
    broadcast_id  TEXT   NOT NULL REFERENCES broadcasts (id) ON DELETE CASCADE,
    seq           BIGINT NOT NULL,
    state         TEXT   NOT NULL,
    PRIMARY KEY (broadcast_id, seq)
);
