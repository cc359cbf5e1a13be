-- Animation graphs (docs/graphs.md): named, versioned documents stored as
-- characters are (`store::document`). The same table as
-- migrations/postgres/0007_graphs.sql.
--
-- `doc` is the canonical graph document; `nodes` and `summary` are what a
-- listing shows, derived from it when it is written (`summary`: the
-- graph's parameters, states and clips as JSON), so a list never reads
-- documents. Names identify graphs as they do clips and characters: the
-- check runs in the write's transaction.
CREATE TABLE graphs (
    id          TEXT   NOT NULL PRIMARY KEY,
    name        TEXT   NOT NULL,
    version     BIGINT NOT NULL,
    doc         TEXT   NOT NULL,
    nodes       BIGINT NOT NULL,
    summary     TEXT   NOT NULL,
    created_at  BIGINT NOT NULL,
    updated_at  BIGINT NOT NULL
);
CREATE INDEX graphs_by_name ON graphs (name, id);
