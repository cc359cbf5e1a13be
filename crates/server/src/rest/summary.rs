//! The clip summary every create, replace and list returns.

use serde::Serialize;
use utoipa::ToSchema;

use crate::store::ClipMeta;
use formats::wire::json::PlaybackDoc;

use super::extract::etag;

/// A clip's identity and shape, without its keys.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ClipSummary {
    /// Opaque, URL-safe, time-ordered id.
    pub id: String,
    pub name: String,
    /// 1 on create, +1 on each replace.
    pub version: u64,
    /// Joints in the skeleton.
    pub joints: u32,
    pub tracks: u32,
    /// Smallest first key time, seconds.
    pub start: f32,
    /// Largest last key time, seconds.
    pub end: f32,
    pub duration: f32,
    /// The clip's default playback mode.
    pub playback: PlaybackDoc,
    /// How many events the clip has.
    pub events: u32,
    /// The document's `tags`.
    pub tags: Vec<String>,
    /// RFC 3339, UTC.
    pub created_at: String,
    pub updated_at: String,
    /// The strong entity tag of this version (as in the `ETag` header).
    pub etag: String,
}

impl From<&ClipMeta> for ClipSummary {
    fn from(m: &ClipMeta) -> Self {
        let s = &m.stats;
        ClipSummary {
            id: m.id.clone(),
            name: m.name.clone(),
            version: m.version,
            joints: s.joints,
            tracks: s.tracks,
            start: s.start,
            end: s.end,
            duration: s.end - s.start,
            playback: s.playback.into(),
            events: s.events,
            tags: m.tags.clone(),
            created_at: rfc3339(m.created_at),
            updated_at: rfc3339(m.updated_at),
            etag: etag(m.version),
        }
    }
}

/// Unix milliseconds as RFC 3339 UTC (`2026-11-21T14:09:13.123Z`), by the
/// days-to-civil algorithm (H. Hinnant), so no date crate is needed.
pub fn rfc3339(ms: i64) -> String {
    let (secs, millis) = (ms.div_euclid(1000), ms.rem_euclid(1000));
    let (days, sod) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{millis:03}Z", sod / 3600, sod % 3600 / 60, sod % 60)
}

#[cfg(test)]
mod tests {
    #[test]
    fn rfc3339_matches_known_instants() {
        assert_eq!(super::rfc3339(0), "1970-01-01T00:00:00.000Z");
        // `date -u -d @951782400` → 2000-02-29 00:00:00 (a leap day).
        assert_eq!(super::rfc3339(951_782_400_123), "2000-02-29T00:00:00.123Z");
        assert_eq!(super::rfc3339(1_795_003_753_000), "2026-11-18T12:09:13.000Z");
    }
}
