//! `inbetween import FILE`: glTF, GLB or BVH to clip documents, printed or
//! uploaded to a server.
//!
//! Without `--server` the result is `{"clips": [clip document...],
//! "warnings": [{"code", "pointer", "detail"}...]}` on stdout, ready for
//! `POST /v1/clips` or `inbetween sample`. With `--server URL` each clip is
//! POSTed to `URL/v1/clips` and the server's answers (summaries, each with
//! the server's warnings about that document) are printed in the same
//! shape. The top-level warnings point into the file (docs/warnings.md) and
//! are also written to stderr, one line each, so they are seen when stdout
//! goes to a file.
//!
//! `--fix hemisphere` flips glTF CUBICSPLINE rotation keys that alternate
//! hemispheres, like the import route's `?fix=hemisphere`.
//!
//! Unlike an upload, a local `.gltf` may name an external buffer file: it is
//! read if it is a plain file name in the same directory as the `.gltf`
//! (no path separators, no `..`, no scheme), and refused otherwise.
//!
//! Files are opened, not read whole: a GLB (or a `.bin` beside a `.gltf`) is
//! read only where its animations and skins point (`import::Source`), so a
//! character file of hundreds of megabytes costs the memory of its
//! animation data.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use serde::Serialize;

use crate::anim::Interpolation;
use crate::import::{Format, ImportLimits, ImportOptions, SNIFF_BYTES, Source, Warning, file_stem, import_from, sniff};
use crate::wire::json::ClipDoc;

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// A .gltf (embedded buffers, or a .bin beside it), .glb or .bvh file.
    file: PathBuf,
    /// gltf | glb | bvh; by default from the extension, else the content.
    #[arg(long)]
    format: Option<Format>,
    /// BVH keys: linear, catmull_rom, or b_spline (approximating: smooths
    /// capture jitter).
    #[arg(long, default_value = "linear", value_parser = ["linear", "catmull_rom", "b_spline"])]
    interpolation: String,
    /// Clip name (BVH; default: the file name), or a prefix NAME/<animation>
    /// for glTF files with several animations (an unnamed animation is
    /// named after the file).
    #[arg(long)]
    name: Option<String>,
    /// Upload each clip to this server (e.g. http://127.0.0.1:8080)
    /// instead of printing the documents.
    #[arg(long)]
    server: Option<String>,
    /// hemisphere: flip glTF CUBICSPLINE rotation keys (value and tangents)
    /// that lie in the opposite hemisphere to the key before, so they turn
    /// the short way (off by default: glTF says to use keys as given).
    #[arg(long, value_parser = ["hemisphere"])]
    fix: Option<String>,
    /// Bearer token for the server's write routes.
    #[arg(long, requires = "server", env = "INBETWEEN_API_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

#[derive(Serialize)]
struct Output<T: Serialize> {
    clips: Vec<T>,
    warnings: Vec<Warning>,
}

pub fn run(args: ImportArgs) -> anyhow::Result<()> {
    let limits = ImportLimits::default();
    let path = &args.file;
    let source = open(path, limits.max_bytes).map_err(anyhow::Error::msg)?;
    let format = match args.format {
        Some(f) => f,
        None => format_of(path, &source)?,
    };
    let options = ImportOptions {
        bvh_interpolation: match args.interpolation.as_str() {
            "catmull_rom" => Interpolation::CatmullRom,
            "b_spline" => Interpolation::BSpline,
            _ => Interpolation::Linear,
        },
        name: args.name.clone(),
        file_name: path.file_name().and_then(|n| file_stem(&n.to_string_lossy())),
        fix_hemispheres: args.fix.is_some(),
        limits,
    };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut resolve = |uri: &str| sibling(&dir, uri, limits.max_bytes);
    let imported = import_from(&source, format, &options, Some(&mut resolve))
        .map_err(|e| anyhow::anyhow!("{}: {e} ({})", path.display(), e.code()))?;
    let docs: Vec<ClipDoc> = imported.clips.iter().map(ClipDoc::from_spec).collect();
    for w in &imported.warnings {
        eprintln!("warning: {}: {} at {}: {}", path.display(), w.code, w.pointer, w.detail);
    }

    let mut out = super::Results::buffered();
    match &args.server {
        None => serde_json::to_writer(&mut out, &Output { clips: docs, warnings: imported.warnings })?,
        Some(server) => {
            let created = upload(server, args.token.as_deref(), &docs)?;
            serde_json::to_writer(&mut out, &Output { clips: created, warnings: imported.warnings })?;
        }
    }
    out.write_all(b"\n")?;
    out.flush()?;
    Ok(())
}

/// The file at `path` as a source read by range, if it is within `max_bytes`.
fn open(path: &Path, max_bytes: u64) -> Result<Source, String> {
    let file = std::fs::File::open(path).map_err(|e| format!("reading {}: {e}", path.display()))?;
    let source = Source::open_file(file).map_err(|e| format!("reading {}: {e}", path.display()))?;
    if source.len() > max_bytes {
        return Err(format!("{} is {} bytes; the import limit is {max_bytes}", path.display(), source.len()));
    }
    Ok(source)
}

/// The format from the file extension, else from the content.
fn format_of(path: &Path, source: &Source) -> anyhow::Result<Format> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if let Some(f) = ext.as_deref().and_then(|e| e.parse().ok()) {
        return Ok(f);
    }
    let head = source.head(SNIFF_BYTES).with_context(|| format!("reading {}", path.display()))?;
    match sniff(&head, None) {
        Some(f) => Ok(f),
        None => bail!("{}: cannot tell the format; pass --format gltf|glb|bvh", path.display()),
    }
}

/// Reads an external buffer named by `uri` if it is a plain file name in
/// `dir`: percent-decoded, no separators, no `..`, no scheme. The importer
/// asks once per URI and shares the opened file between buffers naming it.
fn sibling(dir: &Path, uri: &str, max_bytes: u64) -> Result<Source, String> {
    let name = percent_encoding::percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| "the URI is not valid percent-encoded UTF-8".to_owned())?;
    let plain = !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\', ':', '\0'])
        && Path::new(name.as_ref()).components().count() == 1;
    if !plain {
        return Err("only a plain file name in the same directory as the .gltf is read".into());
    }
    open(&dir.join(name.as_ref()), max_bytes)
}

/// POSTs each document to `server/v1/clips`, returning the created summaries.
fn upload(server: &str, token: Option<&str>, docs: &[ClipDoc]) -> anyhow::Result<Vec<serde_json::Value>> {
    let url = format!("{}/v1/clips", server.trim_end_matches('/'));
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(async {
        let client = reqwest::Client::new();
        let mut created = Vec::with_capacity(docs.len());
        for doc in docs {
            let mut request = client.post(&url).json(doc);
            if let Some(token) = token {
                request = request.bearer_auth(token);
            }
            let response = request.send().await.with_context(|| format!("POST {url}"))?;
            let status = response.status();
            let body = response.text().await.with_context(|| format!("POST {url}: reading the response"))?;
            if !status.is_success() {
                bail!("POST {url} for clip '{}': {status}: {body}", doc.name);
            }
            created.push(serde_json::from_str(&body).with_context(|| format!("POST {url}: the response is not JSON"))?);
        }
        Ok(created)
    })
}
