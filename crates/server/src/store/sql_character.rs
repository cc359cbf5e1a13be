//! What characters have beyond being documents (`store::sql_document`):
//! a glTF import's clips and characters written in one transaction, and
//! their skinned meshes.

use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Type};

use super::dialect::Dialect;
use super::document::{DocKind, DocMeta, NewDoc};
use super::retry::Retry;
use super::sql::{SqlStore, Written, new_meta};
use super::sql_document::{CHARACTER_MESHES, new_doc_meta, table};
use super::{ClipMeta, ImportWritten, NewCharacter, NewClip, OnName, StoreError, StoredMesh, now_millis};

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
    /// A glTF import's clips and characters, in one transaction.
    pub(super) async fn create_import_now(
        &self,
        clips: Vec<NewClip>,
        characters: Vec<NewCharacter>,
        on_name: OnName,
    ) -> Result<ImportWritten, StoreError> {
        let (now, characters_table) = (now_millis(), table(DocKind::Character));
        let docs: Vec<NewDoc> = characters.into_iter().map(NewDoc::from).collect();
        let clip_metas: Vec<ClipMeta> = clips.iter().map(|c| new_meta(c, now)).collect();
        let metas: Vec<DocMeta> = docs.iter().map(|d| new_doc_meta(d, characters_table, now)).collect();
        let (clip_metas, clips, metas, docs) = (&clip_metas, &clips, &metas, &docs);
        let mode = if on_name == OnName::Replace { Retry::IfNotExecuted } else { Retry::Always };
        let (clips, characters) = self
            .run("create_import", mode, |n| {
                let earlier = || (clip_metas.clone(), metas.clone());
                self.in_write(n, earlier, async |db| {
                    let written = match Self::write_clips(db, clip_metas, clips, on_name).await? {
                        Written::Done(written) => written,
                        Written::Ours => return Ok(Written::Ours),
                        Written::Refused(refused) => return Ok(Written::Refused(refused)),
                    };
                    let characters = Self::write_docs(db, characters_table, metas, docs, on_name).await?;
                    Ok(characters.map(|c| (written, c)))
                })
            })
            .await??;
        Ok((clips, characters.into_iter().map(Into::into).collect()))
    }

    pub(super) async fn character_mesh_tag_now(&self, id: &str) -> Result<Option<Option<String>>, StoreError> {
        self.read_mesh_tag(&CHARACTER_MESHES, id).await
    }

    pub(super) async fn character_mesh_now(&self, id: &str) -> Result<Option<StoredMesh>, StoreError> {
        self.read_mesh(&CHARACTER_MESHES, id).await
    }
}
