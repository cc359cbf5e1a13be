//! Named, versioned documents in [`SqlStore`] (`store::document`): one set
//! of statements per table, made by one macro from its table and column
//! names, and one implementation of create, get, list, replace and delete
//! for every kind, with the name rule, retries and (for characters) meshes
//! that clips have (`store::sql`).

use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Row, Type};

use super::dialect::Dialect;
use super::document::{DocKind, DocMeta, DocQuery, NewDoc, StoredDoc, name_reference};
use super::filter::document_query;
use super::retry::Retry;
use super::sql::{Meshes, NameCheck, Named, SqlStore, Written, at_version, named};
use super::{MeshWrite, OnName, StoreError, new_clip_id, now_millis};

/// The statements of one table of documents (aliased `c`): its figure and
/// report columns read as `figure` and `report`, and `mesh` as 0 or 1.
pub(super) struct DocTable {
    pub named: Named,
    /// `SELECT <columns> FROM <table> c`, for the list.
    pub select: &'static str,
    /// `$1` id, `$2` name, `$3` doc, `$4` figure, `$5` report, `$6` now.
    pub insert: &'static str,
    /// `$1` id: the row and `doc`.
    pub get: &'static str,
    /// `$1` name: the rows (at most a few) and `doc`.
    pub get_named: &'static str,
    /// `$1` id, `$2` expected version or NULL, `$3` name, `$4` doc, `$5`
    /// figure, `$6` report, `$7` now: `version, created_at`.
    pub replace: &'static str,
    /// `$1` id, `$2` expected version or NULL.
    pub delete: &'static str,
    pub meshes: Option<Meshes>,
}

/// The columns of a [`DocTable`]'s rows as [`DocMeta`] reads them.
macro_rules! doc_columns {
    ($figure:literal, $report:literal, $mesh:literal) => {
        concat!(
            "SELECT c.id, c.name, c.version, c.",
            $figure,
            " AS figure, c.",
            $report,
            " AS report, c.created_at, c.updated_at, CAST(",
            $mesh,
            " AS BIGINT) AS mesh"
        )
    };
}

/// The [`DocTable`] of `$table`, its figure in column `$figure`, its report
/// in `$report`, whether a mesh is kept as the SQL expression `$mesh`.
macro_rules! doc_table {
    ($table:literal, $what:literal, $figure:literal, $report:literal, $mesh:literal, $meshes:expr) => {
        DocTable {
            named: named!($table, $what),
            select: concat!(doc_columns!($figure, $report, $mesh), " FROM ", $table, " c"),
            insert: concat!(
                "INSERT INTO ",
                $table,
                " (id, name, version, doc, ",
                $figure,
                ", ",
                $report,
                ", created_at, updated_at) VALUES ($1, $2, 1, $3, $4, $5, $6, $6)"
            ),
            get: concat!(doc_columns!($figure, $report, $mesh), ", c.doc FROM ", $table, " c WHERE c.id = $1"),
            get_named: concat!(
                doc_columns!($figure, $report, $mesh),
                ", c.doc FROM ",
                $table,
                " c WHERE c.name = $1 ORDER BY c.id LIMIT 8"
            ),
            replace: concat!(
                "UPDATE ",
                $table,
                " SET name = $3, doc = $4, ",
                $figure,
                " = $5, ",
                $report,
                " = $6, updated_at = $7, version = version + 1 ",
                at_version!(),
                " RETURNING version, created_at"
            ),
            delete: concat!("DELETE FROM ", $table, " ", at_version!()),
            meshes: $meshes,
        }
    };
}

/// The characters' skinned meshes, one per character.
pub(super) const CHARACTER_MESHES: Meshes = Meshes {
    tag: "SELECT m.etag FROM characters c LEFT JOIN character_meshes m ON m.character_id = c.id WHERE c.id = $1",
    get: "SELECT etag, bytes FROM character_meshes WHERE character_id = $1",
    insert: "INSERT INTO character_meshes (character_id, etag, bytes) VALUES ($1, $2, $3)",
    delete: "DELETE FROM character_meshes WHERE character_id = $1",
};

/// Characters (`migrations/*/0006_characters.sql`) and their meshes.
const CHARACTERS: DocTable = doc_table!(
    "characters",
    "character",
    "joints",
    "roles",
    "CASE WHEN EXISTS (SELECT 1 FROM character_meshes m WHERE m.character_id = c.id) THEN 1 ELSE 0 END",
    Some(CHARACTER_MESHES)
);

/// Graphs (`migrations/*/0007_graphs.sql`): no meshes.
const GRAPHS: DocTable = doc_table!("graphs", "graph", "nodes", "summary", "0", None);

/// The table of `kind`.
pub(super) fn table(kind: DocKind) -> &'static DocTable {
    match kind {
        DocKind::Character => &CHARACTERS,
        DocKind::Graph => &GRAPHS,
    }
}

/// A document row as [`DocMeta`], for both backends.
fn doc_from_row<'r, R>(row: &'r R) -> Result<DocMeta, sqlx::Error>
where
    R: Row,
    &'static str: ColumnIndex<R>,
    String: Decode<'r, R::Database> + Type<R::Database>,
    i64: Decode<'r, R::Database> + Type<R::Database>,
{
    Ok(DocMeta {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        version: row.try_get::<i64, _>("version")? as u64,
        figure: row.try_get::<i64, _>("figure")? as u32,
        report_json: row.try_get("report")?,
        mesh: row.try_get::<i64, _>("mesh")? != 0,
        created_at: row.try_get("created_at")?,
        updated_at: row.try_get("updated_at")?,
    })
}

fn stored_from_row<'r, R>(row: &'r R) -> Result<StoredDoc, sqlx::Error>
where
    R: Row,
    &'static str: ColumnIndex<R>,
    String: Decode<'r, R::Database> + Type<R::Database>,
    i64: Decode<'r, R::Database> + Type<R::Database>,
{
    Ok(StoredDoc { meta: doc_from_row(row)?, doc_json: row.try_get("doc")? })
}

/// The row a new document will have.
pub(super) fn new_doc_meta(doc: &NewDoc, table: &DocTable, now: i64) -> DocMeta {
    DocMeta {
        id: new_clip_id(),
        name: doc.name.clone(),
        version: 1,
        figure: doc.figure,
        report_json: doc.report_json.clone(),
        mesh: table.meshes.is_some() && matches!(doc.mesh, MeshWrite::Set(_)),
        created_at: now,
        updated_at: now,
    }
}

impl<DB: Dialect> SqlStore<DB>
where
    for<'c> &'c mut DB::Connection: Executor<'c, Database = DB>,
    DB::Arguments: IntoArguments<DB>,
    for<'q> String: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> &'q str: Encode<'q, DB> + Type<DB>,
    for<'q> i64: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> Option<i64>: Encode<'q, DB>,
    for<'q> f64: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> &'q [u8]: Encode<'q, DB> + Type<DB>,
    for<'q> Vec<u8>: Decode<'q, DB> + Type<DB>,
    &'static str: ColumnIndex<DB::Row>,
    usize: ColumnIndex<DB::Row>,
{
    /// Writes `docs` in the caller's transaction, each a new one, or the
    /// new version of the one holding its name as `on_name` allows.
    pub(super) async fn write_docs(
        db: &mut DB::Connection,
        table: &DocTable,
        metas: &[DocMeta],
        docs: &[NewDoc],
        on_name: OnName,
    ) -> Result<Written<Vec<DocMeta>>, sqlx::Error> {
        let mut written = Vec::with_capacity(docs.len());
        for (meta, doc) in metas.iter().zip(docs) {
            let ids = Self::holders(db, &table.named, &doc.name).await?;
            match NameCheck::of(&table.named, &ids, &meta.id, &doc.name, on_name) {
                NameCheck::Free => {
                    sqlx::query(table.insert)
                        .bind(&meta.id)
                        .bind(&meta.name)
                        .bind(&doc.doc_json)
                        .bind(i64::from(meta.figure))
                        .bind(&meta.report_json)
                        .bind(meta.created_at)
                        .execute(&mut *db)
                        .await?;
                    Self::write_doc_mesh(db, table, &meta.id, &doc.mesh, false).await?;
                    written.push(meta.clone());
                }
                NameCheck::Ours => return Ok(Written::Ours),
                NameCheck::Replace(id) => {
                    let row = Self::update_doc(db, table, &id, doc, None, meta.updated_at).await?;
                    written.push(row.ok_or(sqlx::Error::RowNotFound)?);
                }
                NameCheck::Refused(refused) => return Ok(Written::Refused(refused)),
            }
        }
        Ok(Written::Done(written))
    }

    /// A document's mesh, written whole, for a kind that keeps meshes.
    async fn write_doc_mesh(
        db: &mut DB::Connection,
        table: &DocTable,
        id: &str,
        mesh: &MeshWrite,
        replace: bool,
    ) -> Result<(), sqlx::Error> {
        let Some(meshes) = &table.meshes else { return Ok(()) };
        let whole = if *mesh == MeshWrite::Keep { MeshWrite::None } else { mesh.clone() };
        Self::write_mesh(db, meshes, id, &whole, replace).await
    }

    /// The replace statement and the mesh, in the caller's transaction;
    /// `None` when no row matched (no such id, or another version).
    async fn update_doc(
        db: &mut DB::Connection,
        table: &DocTable,
        id: &str,
        doc: &NewDoc,
        expected_version: Option<u64>,
        now: i64,
    ) -> Result<Option<DocMeta>, sqlx::Error> {
        let row = sqlx::query(table.replace)
            .bind(id)
            .bind(expected_version.map(|v| v as i64))
            .bind(&doc.name)
            .bind(&doc.doc_json)
            .bind(i64::from(doc.figure))
            .bind(&doc.report_json)
            .bind(now)
            .fetch_optional(&mut *db)
            .await?;
        let Some(row) = row else { return Ok(None) };
        let mut meta = new_doc_meta(doc, table, now);
        meta.id = id.to_owned();
        meta.version = row.try_get::<i64, _>("version")? as u64;
        meta.created_at = row.try_get("created_at")?;
        Self::write_doc_mesh(db, table, id, &doc.mesh, true).await?;
        Ok(Some(meta))
    }

    pub(super) async fn create_docs_now(
        &self,
        kind: DocKind,
        docs: Vec<NewDoc>,
        on_name: OnName,
    ) -> Result<Vec<DocMeta>, StoreError> {
        let (table, now) = (table(kind), now_millis());
        let metas: Vec<DocMeta> = docs.iter().map(|d| new_doc_meta(d, table, now)).collect();
        let (metas, docs) = (&metas, &docs);
        let mode = if on_name == OnName::Replace { Retry::IfNotExecuted } else { Retry::Always };
        self.run("create_documents", mode, |n| {
            self.in_write(n, || metas.clone(), async |db| Self::write_docs(db, table, metas, docs, on_name).await)
        })
        .await?
    }

    pub(super) async fn doc_now(&self, kind: DocKind, id: &str) -> Result<Option<StoredDoc>, StoreError> {
        let table = table(kind);
        self.run("document", Retry::Always, |_| async move {
            let row = sqlx::query(table.get).bind(id).fetch_optional(&self.pool).await?;
            row.as_ref().map(stored_from_row).transpose()
        })
        .await
    }

    pub(super) async fn doc_by_ref_now(&self, kind: DocKind, reference: &str) -> Result<Option<StoredDoc>, StoreError> {
        let Some(name) = name_reference(reference) else { return self.doc_now(kind, reference).await };
        let table = table(kind);
        let rows = self
            .run("document_by_name", Retry::Always, |_| async move {
                let rows = sqlx::query(table.get_named).bind(name).fetch_all(&self.pool).await?;
                rows.iter().map(stored_from_row).collect::<Result<Vec<_>, sqlx::Error>>()
            })
            .await?;
        match <[StoredDoc; 1]>::try_from(rows) {
            Ok([one]) => Ok(Some(one)),
            Err(rows) if rows.is_empty() => Ok(None),
            Err(rows) => {
                let ids = rows.into_iter().map(|r| r.meta.id).collect();
                Err(StoreError::AmbiguousName { name: name.to_owned(), ids, what: table.named.what })
            }
        }
    }

    pub(super) async fn list_docs_now(&self, kind: DocKind, query: DocQuery) -> Result<Vec<DocMeta>, StoreError> {
        let (table, query) = (table(kind), &query);
        self.run("list_documents", Retry::Always, |_| async move {
            let mut qb = document_query::<DB>(table.select, query);
            let rows = qb.build().fetch_all(&self.pool).await?;
            rows.iter().map(doc_from_row).collect::<Result<Vec<_>, _>>()
        })
        .await
    }

    pub(super) async fn replace_doc_now(
        &self,
        kind: DocKind,
        id: &str,
        doc: NewDoc,
        expected_version: Option<u64>,
    ) -> Result<DocMeta, StoreError> {
        let (table, doc, now) = (table(kind), &doc, now_millis());
        self.run("replace_document", Retry::IfNotExecuted, |_| async move {
            let mut tx = self.pool.begin_with(DB::BEGIN_WRITE).await?;
            if let Some(refused) = Self::rename_refused(&mut tx, &table.named, id, &doc.name).await? {
                tx.rollback().await?;
                return Ok(Err(refused));
            }
            let Some(meta) = Self::update_doc(&mut tx, table, id, doc, expected_version, now).await? else {
                tx.rollback().await?;
                return self.missed(&table.named, id).await.map(Err);
            };
            tx.commit().await?;
            Ok(Ok(meta))
        })
        .await?
    }

    pub(super) async fn delete_doc_now(
        &self,
        kind: DocKind,
        id: &str,
        expected_version: Option<u64>,
    ) -> Result<(), StoreError> {
        let table = table(kind);
        self.run("delete_document", Retry::IfNotExecuted, |_| async move {
            let done =
                sqlx::query(table.delete).bind(id).bind(expected_version.map(|v| v as i64)).execute(&self.pool).await?;
            if DB::rows_affected(&done) == 1 { Ok(Ok(())) } else { self.missed(&table.named, id).await.map(Err) }
        })
        .await?
    }
}
