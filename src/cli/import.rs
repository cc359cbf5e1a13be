//! `inbetween import FILE`: glTF, GLB or BVH to clip documents, printed or
//! uploaded to a server.
//!
//! Without `--server` the result is `{"clips": [clip document...],
//! "warnings": [{"code", "pointer", "detail"}...]}` on stdout, ready for
//! `POST /v1/clips` or `inbetween sample`. With `--server URL` the file is
//! checked here the same way, then sent as it is (with the `.bin` files a
//! `.gltf` names beside it, as parts of one multipart upload) to
//! `URL/v1/clips/import`, which keeps what a clip document cannot carry (the
//! skinned mesh the viewer draws); its answer — the created clips' summaries
//! and its warnings — is printed in the same shape. The warnings point into
//! the file (docs/warnings.md) and are also written to stderr, one line each,
//! so they are seen when stdout goes to a file.
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

use anim::{Interpolation, Playback};
use formats::import::{
    Format, ImportError, ImportLimits, ImportOptions, SCALE_RANGE, SNIFF_BYTES, Source, UpAxis, Warning, detect,
    file_stem, import_from,
};
use formats::wire::json::ClipDoc;

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
    /// Prepended to every clip's name: a folder such as `fox/`.
    #[arg(long)]
    name_prefix: Option<String>,
    /// The file's up axis: y (glTF's), or z to turn Z-up data into Y-up
    /// (−90° about X at the roots: rest, keys, mesh).
    #[arg(long, default_value = "y", value_parser = ["y", "z"])]
    up: String,
    /// Every length times this (translations, mesh positions, inverse
    /// binds): 0.01 for a file in centimetres.
    #[arg(long, default_value_t = 1.0, value_parser = parse_scale)]
    scale: f32,
    /// Every clip's playback: loop (as three.js plays actions), once or
    /// ping_pong.
    #[arg(long, default_value = "loop", value_parser = ["once", "loop", "ping_pong"])]
    playback: String,
    /// With --server: a clip whose name a stored clip has becomes its new
    /// version (same id), so the command can be run again; without it such
    /// an import is refused (409 name_taken).
    #[arg(long, requires = "server")]
    replace: bool,
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
        name_prefix: args.name_prefix.clone(),
        up: if args.up == "z" { UpAxis::Z } else { UpAxis::Y },
        scale: args.scale,
        playback: match args.playback.as_str() {
            "once" => Playback::Once,
            "ping_pong" => Playback::PingPong,
            _ => Playback::Loop,
        },
        characters_only: false,
        limits,
    };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut buffers = Vec::new();
    let mut resolve = |uri: &str| {
        let opened = sibling(&dir, uri, limits.max_bytes)?;
        buffers.push(uri.to_owned());
        Ok(opened)
    };
    let imported = import_from(&source, format, &options, Some(&mut resolve))
        .map_err(|e| anyhow::anyhow!("{}: {e} ({})", path.display(), e.code()))?;
    for w in &imported.warnings {
        eprintln!("warning: {}: {} at {}: {}", path.display(), w.code, w.pointer, w.detail);
    }

    let mut out = super::results::Results::buffered();
    match &args.server {
        None => {
            let docs: Vec<ClipDoc> = imported.clips.iter().map(ClipDoc::from_spec).collect();
            serde_json::to_writer(&mut out, &Output { clips: docs, warnings: imported.warnings })?
        }
        Some(server) => {
            let upload = Upload { path, buffers: &buffers, format, args: &args };
            serde_json::to_writer(&mut out, &upload.send(server)?)?;
        }
    }
    out.write_all(b"\n")?;
    out.flush()?;
    Ok(())
}

/// `--scale`: a finite factor within the importer's range.
fn parse_scale(text: &str) -> Result<f32, String> {
    let scale: f32 = text.parse().map_err(|_| format!("`{text}` is not a number"))?;
    if SCALE_RANGE.contains(&scale) {
        Ok(scale)
    } else {
        Err(format!("must be within {:?} (0.01 turns centimetres into metres)", SCALE_RANGE))
    }
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
    match detect(&head, None) {
        Ok(f) => Ok(f),
        // An FBX file needs converting, not another --format.
        Err(e @ ImportError::Fbx) => bail!("{}: {e} ({})", path.display(), e.code()),
        Err(_) if ext.as_deref() == Some("fbx") => {
            bail!("{}: {} ({})", path.display(), ImportError::Fbx, ImportError::Fbx.code())
        }
        Err(_) => bail!("{}: cannot tell the format; pass --format gltf|glb|bvh", path.display()),
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

/// A file checked here, to send to a server's import route.
struct Upload<'a> {
    path: &'a Path,
    /// The external buffers the file names (plain file names beside it).
    buffers: &'a [String],
    format: Format,
    args: &'a ImportArgs,
}

impl Upload<'_> {
    /// POSTs the file and its buffers to `server/v1/clips/import`; returns
    /// the server's answer (`{clips, characters, warnings}`: a glTF file's skins become characters).
    fn send(&self, server: &str) -> anyhow::Result<serde_json::Value> {
        let url = format!("{}/v1/clips/import", server.trim_end_matches('/'));
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
        runtime.block_on(async {
            let mut request = reqwest::Client::new().post(&url).query(&self.query()).multipart(self.form().await?);
            if let Some(token) = &self.args.token {
                request = request.bearer_auth(token);
            }
            let response = request.send().await.map_err(|e| send_failed(e, &url))?;
            let status = response.status();
            let body = response.text().await.with_context(|| format!("POST {url}: reading the response"))?;
            if !status.is_success() {
                bail!("POST {url} for {}: {status}: {body}", self.path.display());
            }
            serde_json::from_str(&body).with_context(|| format!("POST {url}: the response is not JSON"))
        })
    }

    /// The command's options as the route's query.
    fn query(&self) -> Vec<(&'static str, String)> {
        let mut query = Vec::new();
        if self.format == Format::Bvh {
            query.push(("interpolation", self.args.interpolation.clone()));
        }
        if let Some(name) = &self.args.name {
            query.push(("name", name.clone()));
        }
        if let Some(fix) = &self.args.fix {
            query.push(("fix", fix.clone()));
        }
        if let Some(prefix) = &self.args.name_prefix {
            query.push(("name_prefix", prefix.clone()));
        }
        query.push(("up", self.args.up.clone()));
        query.push(("scale", self.args.scale.to_string()));
        query.push(("playback", self.args.playback.clone()));
        if self.args.replace {
            query.push(("replace", "true".into()));
        }
        query
    }

    /// The file as the `file` part (streamed, never read whole), then each
    /// buffer as a part named by its URI, as the route matches them.
    async fn form(&self) -> anyhow::Result<reqwest::multipart::Form> {
        let name = self.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let mut form = reqwest::multipart::Form::new().part("file", file_part(self.path, name).await?);
        let dir = self.path.parent().map(Path::to_path_buf).unwrap_or_default();
        for uri in self.buffers {
            let file = percent_encoding::percent_decode_str(uri).decode_utf8_lossy().into_owned();
            form = form.part("buffer", file_part(&dir.join(file), uri.clone()).await?);
        }
        Ok(form)
    }
}

/// A failed upload, with what a connection closed mid-file usually means.
fn send_failed(e: reqwest::Error, url: &str) -> anyhow::Error {
    let reset = std::iter::successors(Some(&e as &(dyn std::error::Error + 'static)), |e| e.source())
        .filter_map(|e| e.downcast_ref::<std::io::Error>())
        .any(|e| matches!(e.kind(), std::io::ErrorKind::BrokenPipe | std::io::ErrorKind::ConnectionReset));
    let e = anyhow::Error::new(e).context(format!("POST {url}"));
    match reset {
        true => e.context(
            "the server closed the connection before it had the whole file: it refuses, unread, files over its \
             max_import_bytes and big ones from a caller who may not write (see --token)",
        ),
        false => e,
    }
}

/// A multipart part streaming the file at `path`, named `file_name`.
async fn file_part(path: &Path, file_name: String) -> anyhow::Result<reqwest::multipart::Part> {
    let file = tokio::fs::File::open(path).await.with_context(|| format!("reading {}", path.display()))?;
    let len = file.metadata().await.with_context(|| format!("reading {}", path.display()))?.len();
    let body = reqwest::Body::from(file);
    Ok(reqwest::multipart::Part::stream_with_length(body, len).file_name(file_name))
}
