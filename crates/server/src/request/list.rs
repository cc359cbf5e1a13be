//! Listing clips a page at a time (`GET /v1/clips`, `ListClips`), filtered
//! by name (exact, prefix, substring), tag, duration range and skeleton
//! compatibility. Every filter is a store query (`store::filter`): nothing
//! here reads a document.

use super::raw::{Field, Locate, Raw, finite, malformed, unprocessable, whole};
use crate::error::ApiError;
use crate::state::AppState;
use crate::store::{ClipMeta, ListQuery, StoreError, is_clip_id};

/// The default and the largest page size.
pub const DEFAULT_PAGE: u32 = 100;
pub const MAX_PAGE: u32 = 1000;
/// The longest text filter, in characters (a clip name's limit).
pub const MAX_FILTER_CHARS: usize = anim::MAX_NAME_CHARS;

/// A page request, as a transport decoded it. `None` (or, from protobuf, an
/// empty string) is no filter; the filters combine with AND.
#[derive(Debug, Clone, Copy)]
pub struct RawPage<'a> {
    /// `None`: [`DEFAULT_PAGE`].
    pub limit: Option<Raw<'a>>,
    /// The `next_cursor` of the previous page.
    pub cursor: Option<&'a str>,
    /// Only clips with exactly this name.
    pub name: Option<&'a str>,
    /// Names that start with this (case-sensitive).
    pub name_prefix: Option<&'a str>,
    /// Names that contain this (case-sensitive).
    pub name_contains: Option<&'a str>,
    /// Clips carrying this tag.
    pub tag: Option<&'a str>,
    /// Duration (`end - start`, seconds) at least / at most this, inclusive.
    pub min_duration: Option<Raw<'a>>,
    pub max_duration: Option<Raw<'a>>,
    /// Clips whose joints include every joint of this clip.
    pub compatible_with: Option<&'a str>,
    pub at: Locate,
}

/// One page, in creation order, and the cursor of the next if there is one.
#[derive(Debug)]
pub struct Page {
    pub clips: Vec<ClipMeta>,
    pub next_cursor: Option<String>,
}

impl RawPage<'_> {
    /// # Errors
    /// `bad_limit` (not a whole number in 1..=[`MAX_PAGE`]), `bad_cursor`,
    /// `bad_filter` (an empty, over-long or NUL-carrying text filter),
    /// `bad_number` (a duration that is not a finite number), and, 422,
    /// `bad_duration_range` (a negative bound, or min above max).
    pub fn check(&self) -> Result<ListQuery, ApiError> {
        let limit = match self.limit {
            None => DEFAULT_PAGE,
            Some(raw) => whole(raw, Field::Limit, self.at)
                .ok()
                .filter(|n| (1.0..=f64::from(MAX_PAGE)).contains(n))
                .map(|n| n as u32)
                .ok_or_else(|| {
                    let detail = format!("`limit` must be a whole number in 1..={MAX_PAGE}");
                    malformed("bad_limit", Field::Limit, self.at, detail)
                })?,
        };
        let after = self.cursor.map(str::to_owned);
        if after.as_deref().is_some_and(|c| !is_clip_id(c)) {
            let detail = "`cursor` must be a next_cursor from a previous page".to_owned();
            return Err(malformed("bad_cursor", Field::Cursor, self.at, detail));
        }
        let min_duration = self.duration(self.min_duration, Field::MinDuration)?;
        let max_duration = self.duration(self.max_duration, Field::MaxDuration)?;
        if let (Some(min), Some(max)) = (min_duration, max_duration)
            && min > max
        {
            let detail = format!("`min_duration` ({min}) is above `max_duration` ({max})");
            return Err(unprocessable("bad_duration_range", Field::MinDuration, self.at, detail));
        }
        Ok(ListQuery {
            after,
            name: self.text(self.name, Field::Name)?,
            name_prefix: self.text(self.name_prefix, Field::NamePrefix)?,
            name_contains: self.text(self.name_contains, Field::NameContains)?,
            tag: self.text(self.tag, Field::Tag)?,
            min_duration,
            max_duration,
            compatible_with: self.compatible_with.map(str::to_owned),
            limit,
        })
    }

    /// A text filter: 1..=[`MAX_FILTER_CHARS`] characters, no NUL (which no
    /// stored name or tag can hold).
    fn text(&self, value: Option<&str>, field: Field) -> Result<Option<String>, ApiError> {
        let Some(value) = value else { return Ok(None) };
        let chars = value.chars().count();
        if chars == 0 || chars > MAX_FILTER_CHARS || value.contains('\0') {
            let detail = format!("`{}` must have 1..={MAX_FILTER_CHARS} characters and no NUL", field.name());
            return Err(malformed("bad_filter", field, self.at, detail));
        }
        Ok(Some(value.to_owned()))
    }

    fn duration(&self, raw: Option<Raw<'_>>, field: Field) -> Result<Option<f64>, ApiError> {
        let Some(raw) = raw else { return Ok(None) };
        let value = finite(raw, field, self.at)?;
        if value < 0.0 {
            let detail = format!("`{}` must be at least 0 seconds, got {value}", field.name());
            return Err(unprocessable("bad_duration_range", field, self.at, detail));
        }
        Ok(Some(value))
    }

    /// Checks the request and reads the page (one more than asked, to know
    /// whether another follows).
    ///
    /// # Errors
    /// As `check`; `clip_not_found` (404) at `compatible_with` when it names
    /// no clip; or the store's failure.
    pub async fn read(&self, state: &AppState) -> Result<Page, ApiError> {
        let mut query = self.check()?;
        let limit = query.limit;
        query.limit = limit + 1;
        let not_found = || {
            let id = self.compatible_with.unwrap_or_default();
            ApiError::ClipNotFoundAt {
                at: (self.at)(Field::CompatibleWith),
                detail: format!("no clip has the id {id:?}"),
            }
        };
        if query.compatible_with.as_deref().is_some_and(|id| !is_clip_id(id)) {
            return Err(not_found());
        }
        let mut clips = match state.store.list(query).await {
            Err(StoreError::NotFound) => return Err(not_found()),
            other => other?,
        };
        let more = clips.len() > limit as usize;
        clips.truncate(limit as usize);
        let next_cursor = if more { clips.last().map(|m| m.id.clone()) } else { None };
        Ok(Page { clips, next_cursor })
    }
}
