//! `inbetween import FILE`: glTF, GLB or BVH to clip documents, printed or
//! uploaded to a server.
//!
//! Without `--server` the result is `{"clips": [clip document...],
//! "skipped": [{"what", "why"}...]}` on stdout, ready for `POST /v1/clips`
//! or `inbetween sample`. With `--server URL` each clip is POSTed to
//! `URL/v1/clips` and the server's summaries are printed in the same shape.
//!
//! Unlike an upload, a local `.gltf` may name an external buffer file: it is
//! read if it is a plain file name in the same directory as the `.gltf`
//! (no path separators, no `..`, no scheme), and refused otherwise.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use serde::Serialize;

use crate::anim::Interpolation;
use crate::import::{Format, ImportLimits, ImportOptions, Skipped, import_with, sniff};
use crate::wire::json::ClipDoc;

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// A .gltf (embedded buffers, or a .bin beside it), .glb or .bvh file.
    file: PathBuf,
    /// gltf | glb | bvh; by default from the extension, else the content.
    #[arg(long)]
    format: Option<Format>,
    /// BVH keys: linear or catmull_rom.
    #[arg(long, default_value = "linear", value_parser = ["linear", "catmull_rom"])]
    interpolation: String,
    /// Clip name (BVH; default: the file name), or a prefix NAME/<animation>
    /// for glTF files with several animations.
    #[arg(long)]
    name: Option<String>,
    /// Upload each clip to this server (e.g. http://127.0.0.1:8080)
    /// instead of printing the documents.
    #[arg(long)]
    server: Option<String>,
    /// Bearer token for the server's write routes.
    #[arg(long, requires = "server", env = "INBETWEEN_API_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

#[derive(Serialize)]
struct Output<T: Serialize> {
    clips: Vec<T>,
    skipped: Vec<Skipped>,
}

pub fn run(args: ImportArgs) -> anyhow::Result<()> {
    let limits = ImportLimits::default();
    let path = &args.file;
    let size = std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?.len();
    if size > limits.max_bytes {
        bail!("{} is {size} bytes; the import limit is {}", path.display(), limits.max_bytes);
    }
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let format = match args.format {
        Some(f) => f,
        None => format_of(path, &bytes)?,
    };
    let name = match (&args.name, format) {
        (Some(n), _) => Some(n.clone()),
        (None, Format::Bvh) => path.file_stem().map(|s| s.to_string_lossy().into_owned()),
        (None, _) => None,
    };
    let options = ImportOptions {
        bvh_interpolation: if args.interpolation == "catmull_rom" {
            Interpolation::CatmullRom
        } else {
            Interpolation::Linear
        },
        name,
        limits,
    };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut resolve = |uri: &str| sibling(&dir, uri, limits.max_bytes);
    let imported = import_with(&bytes, format, &options, Some(&mut resolve))
        .map_err(|e| anyhow::anyhow!("{}: {e} ({})", path.display(), e.code()))?;
    let docs: Vec<ClipDoc> = imported.clips.iter().map(ClipDoc::from_spec).collect();

    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    match &args.server {
        None => serde_json::to_writer(&mut out, &Output { clips: docs, skipped: imported.skipped })?,
        Some(server) => {
            let created = upload(server, args.token.as_deref(), &docs)?;
            serde_json::to_writer(&mut out, &Output { clips: created, skipped: imported.skipped })?;
        }
    }
    out.write_all(b"\n")?;
    out.flush()?;
    Ok(())
}

/// The format from the file extension, else from the content.
fn format_of(path: &Path, bytes: &[u8]) -> anyhow::Result<Format> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if let Some(f) = ext.as_deref().and_then(|e| e.parse().ok()) {
        return Ok(f);
    }
    match sniff(bytes, None) {
        Some(f) => Ok(f),
        None => bail!("{}: cannot tell the format; pass --format gltf|glb|bvh", path.display()),
    }
}

/// Reads an external buffer named by `uri` if it is a plain file name in
/// `dir`: percent-decoded, no separators, no `..`, no scheme. The importer
/// asks once per URI and shares the bytes between buffers naming it.
fn sibling(dir: &Path, uri: &str, max_bytes: u64) -> Result<bytes::Bytes, String> {
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
    let path = dir.join(name.as_ref());
    let size = std::fs::metadata(&path).map_err(|e| format!("{}: {e}", path.display()))?.len();
    if size > max_bytes {
        return Err(format!("{} is {size} bytes; the limit is {max_bytes}", path.display()));
    }
    std::fs::read(&path).map(bytes::Bytes::from).map_err(|e| format!("{}: {e}", path.display()))
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
