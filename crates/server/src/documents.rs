//! Named, versioned documents at the service's edge (characters, graphs;
//! `store::document`): what REST and gRPC share for every kind — a page of
//! summaries under the name filters, the store's refusals as answers, the
//! version a conditional write must find — so a kind adds only its
//! document's checks and its summary.

use crate::error::{ApiError, At};
use crate::request::{Field, Raw, RawPage};
use crate::store::{ClipStore, DocKind, DocMeta, DocQuery, ListQuery, StoreError};

/// A store refusal of a write or read of `kind`: as a clip's, but a
/// missing row is a missing document of that kind (`character_not_found`,
/// `graph_not_found`).
pub fn store_error(kind: DocKind, e: StoreError) -> ApiError {
    match e {
        StoreError::NotFound => ApiError::NotFound { what: kind.what() },
        other => ApiError::from(other),
    }
}

/// The raw list parameters of documents: the page and the name filters
/// (documents have no tags, durations or joints to filter on).
pub fn raw_page<'a>(
    limit: Option<Raw<'a>>,
    cursor: Option<&'a str>,
    names: [Option<&'a str>; 3],
    at: fn(Field) -> At,
) -> RawPage<'a> {
    let [name, name_prefix, name_contains] = names;
    RawPage {
        limit,
        cursor,
        name,
        name_prefix,
        name_contains,
        tag: None,
        min_duration: None,
        max_duration: None,
        compatible_with: None,
        at,
    }
}

/// One page of `kind` as the store has them under `query`'s filters: at
/// most its limit, and the cursor of the next page if any.
///
/// # Errors
/// The store's failure.
pub async fn page(
    store: &dyn ClipStore,
    kind: DocKind,
    query: ListQuery,
) -> Result<(Vec<DocMeta>, Option<String>), ApiError> {
    let limit = query.limit;
    let store_query = DocQuery { names: query.names(), limit: limit + 1 };
    let mut metas = store.list_docs(kind, store_query).await.map_err(|e| store_error(kind, e))?;
    let more = metas.len() > limit as usize;
    metas.truncate(limit as usize);
    let next_cursor = if more { metas.last().map(|m| m.id.clone()) } else { None };
    Ok((metas, next_cursor))
}
