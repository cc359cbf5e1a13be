//! `GET /viewer`: a browser page that lists clips, plays their WebSocket
//! stream as a 3D skeleton and plots their curves (issue 8), composes them
//! into motions with IK handles and broadcasts them (issue 20).
//!
//! The page is plain files embedded in the binary, so serving it
//! needs no build step and no download. Each answer carries a strong
//! `ETag` (a hash of the file, computed at compile time) and `no-cache`, so
//! a browser revalidates and gets `304` until the binary changes. The
//! Content-Security-Policy allows only this origin's script, style and
//! connections (`'self'` covers the same-origin `ws:` stream), and no inline
//! code at all.

use axum::Router;
use axum::http::header::{CACHE_CONTROL, CONTENT_TYPE, ETAG, IF_NONE_MATCH};
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;

/// One embedded file and how to serve it.
struct Asset {
    body: &'static str,
    content_type: &'static str,
    etag: &'static str,
}

/// A strong entity tag from the file's bytes: `"v-<fnv1a64 hex>"`.
macro_rules! asset {
    ($file:expr, $content_type:literal) => {{
        const BODY: &str = include_str!($file);
        const HASH: u64 = fnv1a(BODY.as_bytes());
        const TAG: [u8; 20] = etag_of(HASH);
        const ETAG_STR: &str = match std::str::from_utf8(&TAG) {
            Ok(s) => s,
            Err(_) => panic!("an entity tag is ASCII"),
        };
        Asset { body: BODY, content_type: $content_type, etag: ETAG_STR }
    }};
}

const INDEX: Asset = asset!("viewer/index.html", "text/html; charset=utf-8");
const STYLE: Asset = asset!("viewer/viewer.css", "text/css; charset=utf-8");
const PANEL_STYLE: Asset = asset!("viewer/panel.css", "text/css; charset=utf-8");

/// A script of the page: an ES module, by its file name in `viewer/`.
macro_rules! module {
    ($file:literal) => {
        (concat!("/viewer/", $file), &asset!(concat!("viewer/", $file), "text/javascript; charset=utf-8"))
    };
}

/// The page's entry module (it imports the others).
const SCRIPT: Asset = asset!("viewer/viewer.js", "text/javascript; charset=utf-8");

/// The page's files other than the page itself, by path. The scripts are
/// ES modules importing each other (`viewer.js` lists them); their unit
/// tests (`viewer/tests/`) and `viewer/package.json` are not served.
const FILES: [(&str, &Asset); 28] = [
    ("/viewer/viewer.js", &SCRIPT),
    ("/viewer/viewer.css", &STYLE),
    ("/viewer/panel.css", &PANEL_STYLE),
    module!("math.js"),
    module!("dom.js"),
    module!("events.js"),
    module!("status.js"), // what the header and status line say
    module!("state.js"),
    module!("render.js"), // the one animation-frame loop
    module!("api.js"),
    module!("settings.js"),
    module!("pose.js"),
    module!("scene.js"),
    module!("mesh.js"), // the clip's or character's skinned mesh
    module!("curves.js"),
    module!("player.js"),
    module!("controls.js"),
    module!("clips.js"),
    module!("thumbs.js"),  // a pose thumbnail per clip version
    module!("library.js"), // the clip list's rows and their actions
    module!("upload.js"),
    module!("composition.js"),
    module!("panel.js"),     // composition and IK handles
    module!("character.js"), // the character the motion plays on
    module!("graph.js"),     // the graph played and its parameters
    module!("springs.js"),   // spring chains on the motion
    module!("compact.js"), // compact frames: a link to the JavaScript client's decoder, examples/clients/js/compact.mjs
    module!("broadcast.js"), // creating and watching broadcasts
];

/// Same-origin script, style, images and connections only; no inline code,
/// no plugins, no framing. `data:` images are the empty favicon.
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'none'; script-src 'self'; style-src 'self'; \
    img-src 'self' data:; connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// `/viewer` (and `/viewer/`) with its scripts and stylesheets.
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    let page = Router::new().route("/viewer", get(viewer_page)).route("/viewer/", get(viewer_page));
    FILES.into_iter().fold(page, |router, (path, asset)| {
        router.route(path, get(move |headers: HeaderMap| async move { serve(asset, &headers) }))
    })
}

/// The viewer page: pick a clip, play its stream, see its curves.
#[utoipa::path(
    get, path = "/viewer", tag = "viewer",
    responses(
        (status = 200, description = "The viewer page (HTML; script and style at /viewer/viewer.js, /viewer/viewer.css)",
            content_type = "text/html"),
        (status = 304, description = "`If-None-Match` matched"),
    )
)]
pub async fn viewer_page(headers: HeaderMap) -> Response {
    serve(&INDEX, &headers)
}

fn serve(asset: &Asset, request: &HeaderMap) -> Response {
    let tag = HeaderValue::from_static(asset.etag);
    let common = [
        (ETAG, tag),
        (CACHE_CONTROL, HeaderValue::from_static("no-cache")),
        (HeaderName::from_static("x-content-type-options"), HeaderValue::from_static("nosniff")),
    ];
    if matches_etag(request, asset.etag) {
        return (StatusCode::NOT_MODIFIED, common).into_response();
    }
    let own = [
        (CONTENT_TYPE, HeaderValue::from_static(asset.content_type)),
        (HeaderName::from_static("content-security-policy"), HeaderValue::from_static(CONTENT_SECURITY_POLICY)),
        (HeaderName::from_static("referrer-policy"), HeaderValue::from_static("no-referrer")),
    ];
    (StatusCode::OK, common, own, asset.body).into_response()
}

/// Whether `If-None-Match` names `etag` (weak comparison, RFC 9110 §13.1.2).
pub(crate) fn matches_etag(request: &HeaderMap, etag: &str) -> bool {
    request
        .get_all(IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .any(|item| item == "*" || item.strip_prefix("W/").unwrap_or(item) == etag)
}

const fn fnv1a(bytes: &[u8]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325_u64;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0100_0000_01b3);
        i += 1;
    }
    hash
}

/// `"v-` + 16 hex digits + `"`.
const fn etag_of(hash: u64) -> [u8; 20] {
    const HEX: &[u8; 16] = b"0123456789abcdef";
    let mut out = *b"\"v-0000000000000000\"";
    let mut i = 0;
    while i < 16 {
        out[3 + i] = HEX[((hash >> (60 - 4 * i)) & 0xf) as usize];
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn etags_are_quoted_hex_of_the_content() {
        assert_eq!(INDEX.etag.len(), 20);
        assert!(INDEX.etag.starts_with("\"v-") && INDEX.etag.ends_with('"'));
        assert_ne!(INDEX.etag, SCRIPT.etag);
        let tags: std::collections::HashSet<_> = FILES.iter().map(|(_, a)| a.etag).collect();
        assert_eq!(tags.len(), FILES.len(), "each file its own tag");
        // FNV-1a 64 test vector: "a" → af63dc4c8601ec8c.
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(&etag_of(0xaf63_dc4c_8601_ec8c), b"\"v-af63dc4c8601ec8c\"");
    }

    #[test]
    fn if_none_match_compares_weakly_and_in_lists() {
        let mut h = HeaderMap::new();
        assert!(!matches_etag(&h, STYLE.etag));
        h.insert(IF_NONE_MATCH, HeaderValue::from_str(&format!("\"x\", W/{}", STYLE.etag)).unwrap());
        assert!(matches_etag(&h, STYLE.etag));
        assert!(!matches_etag(&h, SCRIPT.etag));
        h.insert(IF_NONE_MATCH, HeaderValue::from_static("*"));
        assert!(matches_etag(&h, SCRIPT.etag));
    }
}
