//! Listing clips a page at a time (`GET /v1/clips`, `ListClips`).

use super::raw::{Field, Locate, Raw, malformed, whole};
use crate::server::error::ApiError;
use crate::server::state::AppState;
use crate::store::{ClipMeta, ListQuery, is_clip_id};

/// The default and the largest page size.
pub const DEFAULT_PAGE: u32 = 100;
pub const MAX_PAGE: u32 = 1000;

/// A page request, as a transport decoded it.
#[derive(Debug, Clone, Copy)]
pub struct RawPage<'a> {
    /// `None`: [`DEFAULT_PAGE`].
    pub limit: Option<Raw<'a>>,
    /// The `next_cursor` of the previous page.
    pub cursor: Option<&'a str>,
    /// Only clips with exactly this name.
    pub name: Option<&'a str>,
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
    /// `bad_limit` (not a whole number in 1..=[`MAX_PAGE`]), `bad_cursor`.
    fn check(&self) -> Result<(u32, Option<String>), ApiError> {
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
        Ok((limit, after))
    }

    /// Checks the request and reads the page (one more than asked, to know
    /// whether another follows).
    ///
    /// # Errors
    /// As `check`, or the store's failure.
    pub async fn read(&self, state: &AppState) -> Result<Page, ApiError> {
        let (limit, after) = self.check()?;
        let name = self.name.map(str::to_owned);
        let mut clips = state.store.list(ListQuery { after, name, limit: limit + 1 }).await?;
        let more = clips.len() > limit as usize;
        clips.truncate(limit as usize);
        let next_cursor = if more { clips.last().map(|m| m.id.clone()) } else { None };
        Ok(Page { clips, next_cursor })
    }
}
