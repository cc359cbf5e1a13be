//! `POST /v1/clips/import`: glTF, GLB and BVH files in, stored clips out.
//!
//! The file is imported and every clip it yields is admitted (the same
//! checks as an uploaded JSON clip) before the store is touched; then all of
//! them are stored in one transaction. A file is imported whole or not at
//! all, and parsing runs on the blocking pool, off the async workers.
//!
//! The body is the file itself, or `multipart/form-data` carrying a `.gltf`
//! and the buffer files it names (what a browser's file picker sends): the
//! part named `file`, else the first part whose file name ends in `.gltf`,
//! `.glb` or `.bvh`, is the document, and the other parts answer its buffer
//! URIs by plain file name only. Nothing else is ever fetched. Buffers that
//! name the same part share its bytes, and the bytes they declare count
//! against `max_import_resolved_bytes` (413 `resolved_bytes_too_large`).
//!
//! Files may be far over the JSON body limit: the body guard spools the
//! body to a temporary file under `max_import_bytes` (`server::spool`), a
//! multipart body's parts are spooled again one file each, and the importer
//! reads only the glTF JSON and the accessor ranges animations, skins and
//! the kept skinned mesh use. Each clip of a skin is stored with its mesh
//! (docs/mesh-format.md) in the same transaction. What is held in memory whole (a `.gltf` or `.bvh` file, a GLB's JSON
//! chunk) stays within `max_body_bytes` (413 `document_too_large`). Every
//! 413 names its limit and how to raise it.

use std::sync::Arc;

use axum::Json;
use axum::body::{Body, Bytes};
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::StatusCode;
use axum::http::header::CONTENT_TYPE;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use std::sync::atomic::AtomicBool;

use crate::auth::{CallerKey, WriteAccess};
use crate::cache::CachedClip;
use crate::config::Limits;
use crate::error::{ApiError, At, raise_hint};
use crate::limits::{Admitted, admit_doc};
use crate::spool::{SpooledBody, Spooler};
use crate::state::AppState;
use crate::store::{MeshWrite, NewCharacter, StoredMesh};
use anim::{ClipSpec, Interpolation, Playback};
use formats::import::{
    ErrorClass, Format, ImportError, ImportLimits, ImportOptions, Imported, ImportedCharacter, Resolver, SCALE_RANGE,
    SNIFF_BYTES, Source, UpAxis, Warning, detect, file_stem, import_from,
};
use formats::wire::character::CharacterDoc;
use formats::wire::json::{ClipDoc, InterpolationDoc, PlaybackDoc};
use formats::wire::mesh;

use super::characters::CharacterSummary;
use super::query::{Query, QueryParams};
use super::summary::ClipSummary;

/// What an import created, and what in the file looked wrong or was left out.
#[derive(Debug, Serialize, ToSchema)]
pub struct ImportResult {
    pub clips: Vec<ClipSummary>,
    /// One per skin of a glTF file (its bind pose, roles and mesh), named
    /// after the file, else the scene, plus `/<skin name>` when there are several.
    pub characters: Vec<CharacterSummary>,
    /// Valid but probably wrong, each with a pointer into the file: parts
    /// not imported (`not_imported`), suspicious keys (docs/warnings.md).
    #[schema(value_type = Vec<super::schemas::Warning>)]
    pub warnings: Vec<Warning>,
}

/// Import a glTF 2.0 (`.gltf` with embedded buffers, `.glb`) or BVH file.
#[utoipa::path(
    post, path = "/v1/clips/import", tag = "clips",
    params(
        ("format" = Option<String>, Query, pattern = "^(gltf|glb|bvh)$", description = "gltf | glb | bvh; inferred from Content-Type or the bytes when absent"),
        ("interpolation" = Option<String>, Query, pattern = "^(linear|catmull_rom|b_spline)$", description = "BVH keys: linear (default), catmull_rom, or b_spline (approximating: smooths capture jitter)"),
        ("name" = Option<String>, Query, min_length = 1, max_length = 256, description = "The clip's name (a BVH, or a glTF with one animation); with several animations, each is named NAME/<animation>"),
        ("name_prefix" = Option<String>, Query, min_length = 1, max_length = 256, description = "Prepended to every clip's name: a folder such as fox/"),
        ("up" = Option<String>, Query, pattern = "^(y|z)$", description = "The file's up axis: y (default) or z (turned into Y-up by -90 degrees about X at the roots: rest, keys, mesh)"),
        ("scale" = Option<f64>, Query, description = "Every length times this, 1e-6 to 1e6 (translations, mesh positions, inverse binds): 0.01 for a file in centimetres"),
        ("playback" = Option<String>, Query, pattern = "^(once|loop|ping_pong)$", description = "Every clip's playback: loop (default, as three.js plays actions), once or ping_pong"),
        ("replace" = Option<bool>, Query, description = "true: a clip whose name a stored clip has becomes that clip's new version (same id) instead of refusing the import (409 name_taken)"),
        ("fix" = Option<String>, Query, pattern = "^hemisphere$", description = "hemisphere: flip glTF CUBICSPLINE rotation keys that lie in the opposite hemisphere to the key before (value and tangents), so they turn the short way; off by default, as the glTF spec says to use keys as given (docs/warnings.md, rotation_hemisphere_flips)"),
    ),
    request_body(content = super::schemas::FileBytes, content_type = "application/octet-stream",
        description = "The file, up to max_import_bytes (256 MiB by default; only its glTF JSON and animation data are read); or multipart/form-data with the .gltf and the buffer files it names"),
    responses(
        (status = 201, description = "Every clip of the file, stored, with warnings about the file (valid but probably wrong)", body = ImportResult),
        (status = 400, description = "Not a well-formed glTF, GLB or BVH file", body = super::schemas::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::schemas::Problem),
        (status = 409, description = "A clip has the name of one the file yields (name_taken: import with replace=true, or name it otherwise), or several stored before names were unique do (ambiguous_name)", body = super::schemas::Problem),
        (status = 413, description = "The file over max_import_bytes, its JSON over max_body_bytes, or its content over another limit (the detail names the limit and how to raise it)", body = super::schemas::Problem),
        (status = 415, description = "An FBX file (fbx_not_supported: the detail says how to convert it to glTF)", body = super::schemas::Problem),
        (status = 422, description = "Well-formed but not importable (code says why)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn import_clips(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    Query(params): Query,
    request: Request,
) -> Result<Response, ApiError> {
    let on_name = params.on_name()?;
    let (format, bytes, (admitted, characters, warnings)) =
        import_request(&state, &caller.key(), &params, request, false, |imported, limits, cancel| {
            let mut admitted = (imported.clips.iter().zip(&imported.springs))
                .map(|(spec, chains)| admit_doc(with_springs(ClipDoc::from_spec(spec), chains), limits, cancel))
                .collect::<Result<Vec<Admitted>, ApiError>>()?;
            // Each clip of a skin keeps its mesh, stored in the clips' transaction.
            for (admitted, mesh) in admitted.iter_mut().zip(imported.meshes) {
                if let Some(bytes) = mesh {
                    admitted.new_clip.mesh = MeshWrite::Set(StoredMesh { etag: mesh::etag(&bytes), bytes });
                }
            }
            let characters = admit_characters(imported.characters, limits, cancel)?;
            // The importer's warnings point into the file; the documents' own are the same findings.
            let warnings = imported.warnings;
            Ok((admitted, characters, warnings))
        })
        .await?;
    let (new_clips, clips): (Vec<_>, Vec<_>) = admitted.into_iter().map(|a| (a.new_clip, (a.clip, a.springs))).unzip();
    let (metas, characters) = state.store.create_clips_and_characters(new_clips, characters, on_name).await?;
    characters.iter().for_each(|m| state.document_changed(crate::store::DocKind::Character, &m.id));
    tracing::info!(
        format = format.as_str(),
        bytes,
        clips = metas.len(),
        characters = characters.len(),
        warnings = warnings.len(),
        "file imported"
    );
    let summaries = metas.iter().map(ClipSummary::from).collect();
    for (meta, (clip, springs)) in metas.into_iter().zip(clips) {
        state.cache_written(Arc::new(CachedClip { meta, clip, springs }));
    }
    let characters = characters.iter().map(CharacterSummary::from).collect();
    Ok((StatusCode::CREATED, Json(ImportResult { clips: summaries, characters, warnings })).into_response())
}

/// Import the characters of a glTF 2.0 file (one per skin: its joints at the bind pose, with the skinned mesh) or a BVH hierarchy.
#[utoipa::path(
    post, path = "/v1/characters/import", tag = "characters",
    params(
        ("format" = Option<String>, Query, pattern = "^(gltf|glb|bvh)$", description = "gltf | glb | bvh; inferred from Content-Type or the bytes when absent"),
        ("name" = Option<String>, Query, min_length = 1, max_length = 256, description = "The character's name; with several skins, each is named NAME/<skin>. Default: the file's name, else the glTF scene's, else the skin's"),
        ("name_prefix" = Option<String>, Query, min_length = 1, max_length = 256, description = "Prepended to every character's name: a folder such as fox/"),
        ("up" = Option<String>, Query, pattern = "^(y|z)$", description = "The file's up axis: y (default) or z (turned into Y-up by -90 degrees about X at the roots: rest and mesh)"),
        ("scale" = Option<f64>, Query, description = "Every length times this, 1e-6 to 1e6 (translations, mesh positions, inverse binds): 0.01 for a file in centimetres"),
        ("replace" = Option<bool>, Query, description = "true: a character whose name a stored character has becomes its new version (same id) instead of refusing the import (409 name_taken)"),
    ),
    request_body(content = super::schemas::FileBytes, content_type = "application/octet-stream",
        description = "The file, up to max_import_bytes; or multipart/form-data with the .gltf and the buffer files it names"),
    responses(
        (status = 201, description = "Every character of the file, stored, with warnings about the file", body = CharacterImportResult),
        (status = 400, description = "Not a well-formed glTF, GLB or BVH file", body = super::schemas::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::schemas::Problem),
        (status = 409, description = "A character has the name of one the file yields (name_taken)", body = super::schemas::Problem),
        (status = 413, description = "The file or its content over a limit (the detail names it)", body = super::schemas::Problem),
        (status = 415, description = "An FBX file (fbx_not_supported)", body = super::schemas::Problem),
        (status = 422, description = "Well-formed but not importable: no skin (no_skins), or a skeleton a clip could not have", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn import_characters(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    Query(params): Query,
    request: Request,
) -> Result<Response, ApiError> {
    let on_name = params.on_name()?;
    let (format, bytes, (characters, warnings)) =
        import_request(&state, &caller.key(), &params, request, true, |imported, limits, cancel| {
            Ok((admit_characters(imported.characters, limits, cancel)?, imported.warnings))
        })
        .await?;
    let metas = crate::characters::create_all(&state, characters, on_name).await?;
    tracing::info!(format = format.as_str(), bytes, characters = metas.len(), "characters imported");
    let characters = metas.iter().map(CharacterSummary::from).collect();
    Ok((StatusCode::CREATED, Json(CharacterImportResult { characters, warnings })).into_response())
}

/// What a character import created, and what in the file looked wrong.
#[derive(Debug, Serialize, ToSchema)]
pub struct CharacterImportResult {
    pub characters: Vec<CharacterSummary>,
    #[schema(value_type = Vec<super::schemas::Warning>)]
    pub warnings: Vec<Warning>,
}

/// The imported characters, each checked as an uploaded one, with its mesh.
pub(crate) fn admit_characters(
    characters: Vec<ImportedCharacter>,
    limits: &Limits,
    cancel: &AtomicBool,
) -> Result<Vec<NewCharacter>, ApiError> {
    characters
        .into_iter()
        .map(|c| {
            let spec = ClipSpec { name: c.name.clone(), skeleton: Some(c.skeleton), ..Default::default() };
            let skeleton = crate::characters::skeleton_doc(&spec);
            let doc = CharacterDoc { name: c.name, skeleton, roles: c.roles };
            let mesh =
                c.mesh.map_or(MeshWrite::None, |bytes| MeshWrite::Set(StoredMesh { etag: mesh::etag(&bytes), bytes }));
            Ok(crate::characters::admit(doc, mesh, limits, cancel)?.new_character)
        })
        .collect()
}

/// Reads an import request's file (the body, or its multipart parts),
/// imports it on the work pool, priced by its size, and hands the result to
/// `admit` there: the format, the file's size and what `admit` made.
async fn import_request<T: Send + 'static>(
    state: &AppState,
    caller: &CallerKey,
    params: &QueryParams,
    request: Request,
    characters_only: bool,
    admit: impl FnOnce(Imported, &Limits, &AtomicBool) -> Result<T, ApiError> + Send + 'static,
) -> Result<(Format, u64, T), ApiError> {
    let content_type = request.headers().get(CONTENT_TYPE).and_then(|v| v.to_str().ok()).map(str::to_owned);
    // The guard spooled the body; a request without one has none to spool.
    let spooled = request.extensions().get::<SpooledBody>().cloned();
    let max_import_bytes = state.config.limits.max_import_bytes;
    let (document, siblings, file_name) =
        if content_type.as_deref().is_some_and(|c| c.starts_with("multipart/form-data")) {
            let body = match &spooled {
                Some(spooled) => spooled.body().await?,
                None => Body::empty(),
            };
            let (parts, _) = request.into_parts();
            let multipart = Multipart::from_request(Request::from_parts(parts, body), state)
                .await
                .map_err(|e| rejected(e.status(), e.body_text(), max_import_bytes))?;
            read_parts(multipart, max_import_bytes).await?
        } else {
            (spooled.map_or_else(|| Source::memory(Bytes::new()), |s| s.source()), Vec::new(), None)
        };
    let format = match params.get("format") {
        Some(f) => Some(f.parse::<Format>().map_err(|e| ApiError::parameter("bad_format", "format", e))?),
        None => None,
    };
    let mut options = import_options(params, &state.config.limits)?;
    options.file_name = file_name.as_deref().and_then(file_stem);
    options.characters_only = characters_only;
    let file = ImportFile { document, siblings, content_type, format };
    run_import(state, caller, file, options, admit).await
}

/// A file to import: its document, the parts its buffers may name, and
/// what says its format.
pub(crate) struct ImportFile {
    pub document: Source,
    pub siblings: Vec<(String, Source)>,
    pub content_type: Option<String>,
    /// Given; `None`: detected from the bytes and the content type.
    pub format: Option<Format>,
}

/// Imports `file` on the work pool, priced by its size, and hands the
/// result to `admit` there: the format, the file's size and what `admit` made.
pub(crate) async fn run_import<T: Send + 'static>(
    state: &AppState,
    caller: &CallerKey,
    file: ImportFile,
    options: ImportOptions,
    admit: impl FnOnce(Imported, &Limits, &AtomicBool) -> Result<T, ApiError> + Send + 'static,
) -> Result<(Format, u64, T), ApiError> {
    let ImportFile { document, siblings, content_type, format } = file;
    let limits = state.config.limits.clone();
    let bytes = document.len();
    let units = crate::work::price::import(bytes);
    let importing = crate::builds::run(&state.work, caller, &state.config.limits, units, "importing this file", {
        move |cancel| -> Result<_, ApiError> {
            let format = match format {
                Some(format) => format,
                None => detect(&document.head(SNIFF_BYTES).map_err(ApiError::internal)?, content_type.as_deref())
                    .map_err(refused)?,
            };
            // A shared handle on the part, never a copy: the importer asks once
            // per name and reads the ranges it needs.
            let mut resolve = |uri: &str| -> Result<Source, String> {
                siblings
                    .iter()
                    .find(|(name, _)| name == uri)
                    .map(|(_, part)| part.clone())
                    .ok_or_else(|| format!("no part named {uri:?} in the upload"))
            };
            let resolver: Option<Resolver<'_>> = if siblings.is_empty() { None } else { Some(&mut resolve) };
            let imported = import_from(&document, format, &options, resolver).map_err(refused)?;
            Ok((format, admit(imported, &limits, cancel)?))
        }
    });
    let (format, made) = importing.await?;
    Ok((format, bytes, made))
}

/// The import's options from its query (every one but `format` and
/// `replace`), each checked: 400 for a value that does not parse, 422 for a
/// `scale` out of range.
fn import_options(params: &QueryParams, limits: &Limits) -> Result<ImportOptions, ApiError> {
    let bvh_interpolation = match params.get("interpolation") {
        None => Interpolation::Linear,
        Some(text) => match text.parse::<InterpolationDoc>().map(Interpolation::from) {
            Ok(i @ (Interpolation::Linear | Interpolation::CatmullRom | Interpolation::BSpline)) => i,
            _ => {
                let detail = format!("`interpolation` must be linear, catmull_rom or b_spline, got `{text}`");
                return Err(ApiError::parameter("bad_interpolation", "interpolation", detail));
            }
        },
    };
    let fix_hemispheres = match params.get("fix") {
        None => false,
        Some("hemisphere") => true,
        Some(other) => {
            let detail = format!("`fix` must be hemisphere, got `{other}`");
            return Err(ApiError::parameter("bad_fix", "fix", detail));
        }
    };
    let up = match params.get("up") {
        None => UpAxis::Y,
        Some(text) => text.parse().map_err(|e| ApiError::parameter("bad_parameter", "up", e))?,
    };
    let playback = match params.get("playback") {
        None => Playback::Loop,
        Some(text) => text.parse::<PlaybackDoc>().map(Playback::from).map_err(|_| {
            let detail = format!("`playback` must be once, loop or ping_pong, got `{text}`");
            ApiError::parameter("bad_parameter", "playback", detail)
        })?,
    };
    Ok(ImportOptions {
        bvh_interpolation,
        name: name_parameter(params, "name")?,
        name_prefix: name_parameter(params, "name_prefix")?,
        file_name: None,
        fix_hemispheres,
        up,
        scale: scale_parameter(params)?,
        playback,
        characters_only: false,
        limits: import_limits(limits),
    })
}

/// `scale`: a finite number within [`SCALE_RANGE`] (default 1).
fn scale_parameter(params: &QueryParams) -> Result<f32, ApiError> {
    let Some(text) = params.get("scale") else { return Ok(1.0) };
    let value: f64 = text.trim().parse().ok().filter(|v: &f64| v.is_finite()).ok_or_else(|| {
        ApiError::parameter("bad_number", "scale", format!("`scale` must be a finite number, got `{text}`"))
    })?;
    checked_scale(value as f32, text)
}

/// `scale` within [`SCALE_RANGE`] (`text`: as the caller wrote it).
pub(crate) fn checked_scale(scale: f32, text: &str) -> Result<f32, ApiError> {
    if !SCALE_RANGE.contains(&scale) {
        let (lo, hi) = (SCALE_RANGE.start(), SCALE_RANGE.end());
        let detail = format!("`scale` must be within {lo}..={hi} (0.01 turns centimetres into metres), got {text}");
        return Err(ApiError::Invalid { code: "scale_out_of_range", at: At::Parameter("scale".into()), detail });
    }
    Ok(scale)
}

/// `name` or `name_prefix`: not blank, at most the core's name length.
fn name_parameter(params: &QueryParams, which: &str) -> Result<Option<String>, ApiError> {
    checked_name(params.get(which), which)
}

/// A name option (`which`: `name` or `name_prefix`): not blank, at most the core's name length.
pub(crate) fn checked_name(text: Option<&str>, which: &str) -> Result<Option<String>, ApiError> {
    let Some(text) = text else { return Ok(None) };
    if text.trim().is_empty() || text.chars().count() > anim::MAX_NAME_CHARS {
        let detail = format!("`{which}` must be 1 to {} characters, not blank", anim::MAX_NAME_CHARS);
        return Err(ApiError::parameter("bad_parameter", which, detail));
    }
    Ok(Some(text.to_owned()))
}

/// The document part, the named sibling parts (each spooled to a file of
/// its own) and the document's file name.
async fn read_parts(mut multipart: Multipart, max_bytes: usize) -> Result<Parts, ApiError> {
    let mut document: Option<Source> = None;
    let mut document_name = None;
    let mut siblings = Vec::new();
    let failed = |e: axum::extract::multipart::MultipartError| rejected(e.status(), e.body_text(), max_bytes);
    while let Some(mut field) = multipart.next_field().await.map_err(failed)? {
        let field_name = field.name().unwrap_or_default().to_owned();
        let file_name = field.file_name().map(str::to_owned);
        // The parts together are no larger than the spooled body, already within the limit.
        let mut part = Spooler::new(max_bytes as u64, "max_import_bytes").await?;
        while let Some(chunk) = field.chunk().await.map_err(failed)? {
            part.push(&chunk).await?;
        }
        let data = part.finish().await?.source();
        let is_document = |n: &str| [".gltf", ".glb", ".bvh"].iter().any(|ext| n.to_ascii_lowercase().ends_with(ext));
        if document.is_none() && (field_name == "file" || file_name.as_deref().is_some_and(is_document)) {
            document = Some(data);
            document_name = file_name;
        } else if let Some(name) = file_name.filter(|n| !n.is_empty() && !n.contains(['/', '\\']) && n != "..") {
            siblings.push((name, data));
        }
    }
    let document = document.ok_or_else(|| {
        bad_multipart("no document part: name it `file`, or give it a .gltf, .glb or .bvh file name".into())
    })?;
    Ok((document, siblings, document_name))
}

/// What [`read_parts`] returns.
type Parts = (Source, Vec<(String, Source)>, Option<String>);

/// A multipart body that could not be read: over the size limit (413; the
/// spooled body already passed it), else malformed (400).
fn rejected(status: StatusCode, detail: String, max_bytes: usize) -> ApiError {
    if status == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::PayloadTooLarge { limit: max_bytes, setting: "max_import_bytes" }
    } else {
        bad_multipart(detail)
    }
}

/// An import refusal as the API answers it: a limit's 413 says which server
/// setting it is and how to raise it; a source that cannot be read (the
/// server's own spool file) is an internal error, not the client's.
fn refused(e: ImportError) -> ApiError {
    let setting = match &e {
        ImportError::Read(_) => return ApiError::internal(e),
        ImportError::ResolvedTooLarge { .. } => Some("max_import_resolved_bytes"),
        ImportError::DocumentTooLarge { .. } => Some("max_body_bytes"),
        ImportError::TooLarge { what, .. } => setting_of(what),
        _ => None,
    };
    match (ApiError::from(e), setting) {
        (ApiError::Import { class, code, pointer, detail }, Some(setting)) => {
            ApiError::Import { class, code, pointer, detail: format!("{detail} ({})", raise_hint(setting)) }
        }
        (api, _) => api,
    }
}

fn bad_multipart(detail: String) -> ApiError {
    ApiError::Import { class: ErrorClass::Malformed, code: "bad_upload", pointer: None, detail }
}

/// The server setting behind an importer's `TooLarge { what }` (the bounds
/// `import_limits` sets from one); `None` for the importer's fixed bounds.
fn setting_of(what: &str) -> Option<&'static str> {
    match what {
        "the upload (bytes)" => Some("max_import_bytes"),
        "the tracks of one clip" => Some("max_tracks"),
        "the joints of one clip" => Some("max_joints"),
        "the keys of one accessor" | "Frames" => Some("max_keys_per_track"),
        _ => None,
    }
}

/// The importer's bounds, from the server's: a clip an import produces
/// obeys the same limits as one uploaded as JSON.
pub(crate) fn import_limits(limits: &Limits) -> ImportLimits {
    ImportLimits {
        max_bytes: limits.max_import_bytes as u64,
        max_document_bytes: limits.max_body_bytes as u64,
        max_joints: limits.max_joints,
        max_tracks: limits.max_tracks,
        max_keys_per_track: limits.max_keys_per_track,
        max_frames: limits.max_keys_per_track,
        max_resolved_bytes: limits.max_import_resolved_bytes as u64,
        max_build_work: limits.max_build_work,
        max_texture_pixels: limits.max_texture_pixels,
        ..ImportLimits::default()
    }
}

/// An imported clip's document with the file's spring chains for it
/// (docs/springs.md, “Import”): the importer kept those that fit its
/// skeleton, so the clip's admission checks them again and stores them.
fn with_springs(mut doc: ClipDoc, chains: &[anim::spring::ChainSpec]) -> ClipDoc {
    doc.springs = chains.iter().map(formats::wire::spring::SpringDoc::from_spec).collect();
    doc
}
