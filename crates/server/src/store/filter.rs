//! The clip list as one SQL statement per request, built from the filters
//! the request actually gives, so each backend plans it with the indexes
//! that serve those filters (a catch-all `? IS NULL OR …` statement is
//! planned once for every combination, and uses none of them).
//!
//! The indexes (`migrations/*/0002_clip_index.sql`): a name prefix is a
//! range on `clips_by_name` (bytewise, code-point order), a tag a lookup in
//! `clip_tags_by_tag`, a duration range a range on `clips_by_duration`
//! (the expression `end_time - start_time`). Skeleton compatibility walks
//! the clips in id order (the page's order), skipping those with fewer
//! joints, and probes `clip_joints`'s primary key for the reference's joints
//! until one is missing: a page costs about its length times the joint count
//! when most clips match, one probe per clip of another rig when few do. A
//! substring cannot be served by a B-tree: it is tested on the name alone,
//! never on a document.

use sqlx::{Encode, QueryBuilder, Type};

use super::dialect::Dialect;
use super::document::DocQuery;
use super::{ListQuery, NameFilters};

/// `SELECT <columns> FROM clips c WHERE <filters> ORDER BY id LIMIT n`.
/// `reference_joints` is the joint count of `q.compatible_with`'s clip
/// (a clip with fewer joints cannot include all of its joints).
pub(crate) fn list_query<DB>(columns: &str, q: &ListQuery, reference_joints: Option<i64>) -> QueryBuilder<DB>
where
    DB: Dialect,
    DB::Arguments: Default,
    for<'t> String: Encode<'t, DB> + Type<DB>,
    for<'t> f64: Encode<'t, DB> + Type<DB>,
    for<'t> i64: Encode<'t, DB> + Type<DB>,
{
    let mut qb = filtered(format!("SELECT {columns} FROM clips c"), &q.names());
    if let Some(tag) = &q.tag {
        qb.push(" AND c.id IN (SELECT t.clip_id FROM clip_tags t WHERE t.tag = ").push_bind(tag.clone()).push(")");
    }
    if let Some(min) = q.min_duration {
        qb.push(" AND c.end_time - c.start_time >= ").push_bind(min);
    }
    if let Some(max) = q.max_duration {
        qb.push(" AND c.end_time - c.start_time <= ").push_bind(max);
    }
    if let (Some(reference), Some(joints)) = (&q.compatible_with, reference_joints) {
        // No joint of the reference is missing from the candidate.
        qb.push(" AND c.joints >= ").push_bind(joints);
        qb.push(" AND NOT EXISTS (SELECT 1 FROM clip_joints r WHERE r.clip_id = ").push_bind(reference.clone());
        qb.push(" AND NOT EXISTS (SELECT 1 FROM clip_joints j WHERE j.clip_id = c.id AND j.joint = r.joint))");
    }
    page(qb, q.limit)
}

/// `<select> WHERE <filters> ORDER BY id LIMIT n` over a table of
/// documents aliased `c` (`store::sql_document`): the name filters as the
/// clip list has them, on its `<table>_by_name` index.
pub(crate) fn document_query<DB>(select: &str, q: &DocQuery) -> QueryBuilder<DB>
where
    DB: Dialect,
    DB::Arguments: Default,
    for<'t> String: Encode<'t, DB> + Type<DB>,
    for<'t> i64: Encode<'t, DB> + Type<DB>,
{
    page(filtered(select.to_owned(), &q.names), q.limit)
}

/// `<select> WHERE` the cursor and name filters of a list over a table
/// aliased `c`, to which a list adds its own filters, then [`page`].
fn filtered<DB>(select: String, q: &NameFilters) -> QueryBuilder<DB>
where
    DB: Dialect,
    DB::Arguments: Default,
    for<'t> String: Encode<'t, DB> + Type<DB>,
{
    let mut qb = QueryBuilder::new(select + " WHERE TRUE");
    if let Some(after) = &q.after {
        qb.push(" AND c.id > ").push_bind(after.clone());
    }
    if let Some(name) = &q.name {
        qb.push(" AND c.name = ").push_bind(name.clone());
    }
    if let Some(prefix) = &q.name_prefix {
        qb.push(format_args!(" AND {} >= ", DB::BYTEWISE_NAME)).push_bind(prefix.clone());
        if let Some(end) = prefix_end(prefix) {
            qb.push(format_args!(" AND {} < ", DB::BYTEWISE_NAME)).push_bind(end);
        }
    }
    if let Some(part) = &q.name_contains {
        qb.push(format_args!(" AND {}(c.name, ", DB::POSITION_FN)).push_bind(part.clone()).push(") > 0");
    }
    qb
}

/// A list's end: its page of at most `limit` rows, in id order.
fn page<DB>(mut qb: QueryBuilder<DB>, limit: u32) -> QueryBuilder<DB>
where
    DB: Dialect,
    DB::Arguments: Default,
    for<'t> i64: Encode<'t, DB> + Type<DB>,
{
    qb.push(" ORDER BY c.id LIMIT ").push_bind(i64::from(limit));
    qb
}

/// The least string above every string that starts with `prefix`, in
/// code-point order (UTF-8 byte order): `prefix` with its last character
/// advanced by one, dropping trailing `U+10FFFF`s; `None` if nothing is above.
pub(crate) fn prefix_end(prefix: &str) -> Option<String> {
    let mut chars: Vec<char> = prefix.chars().collect();
    while let Some(last) = chars.pop() {
        let next = if last == '\u{D7FF}' { Some('\u{E000}') } else { char::from_u32(last as u32 + 1) };
        if let Some(next) = next {
            chars.push(next);
            return Some(chars.into_iter().collect());
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::prefix_end;

    #[test]
    fn prefix_end_bounds_exactly_the_strings_with_the_prefix() {
        assert_eq!(prefix_end("walk").as_deref(), Some("wall"));
        assert_eq!(prefix_end("a\u{D7FF}").as_deref(), Some("a\u{E000}"));
        assert_eq!(prefix_end("b\u{10FFFF}").as_deref(), Some("c"));
        assert_eq!(prefix_end("\u{10FFFF}"), None);
        assert_eq!(prefix_end(""), None);
        // Byte order of the UTF-8 agrees with code-point order on both sides of the bound.
        let end = prefix_end("é").unwrap();
        for inside in ["é", "é\u{10FFFF}", "éz"] {
            assert!(inside.as_bytes() >= "é".as_bytes() && inside.as_bytes() < end.as_bytes(), "{inside}");
        }
        assert!("ê".as_bytes() >= end.as_bytes());
    }
}
