//! Import uploads spooled to a temporary file as they arrive.
//!
//! `POST /v1/clips/import` takes character files far over the JSON body
//! limit (`max_import_bytes`, 256 MiB by default), most of whose bytes are
//! textures and meshes that an animation import never reads. So its body is
//! not held in memory: the body guard writes it, chunk by chunk, to an
//! anonymous temporary file (in `$TMPDIR`, unlinked from the start, so not
//! even a crash leaves it behind), checking the limit on every chunk, and
//! hands the handler a [`SpooledBody`] in the request's extensions. The
//! importer then reads only the ranges it needs (`import::Source`). Memory
//! holds one write buffer per upload, never the file.
//!
//! Spooling happens where other bodies are buffered, before admission, so a
//! slow upload holds no in-flight slot; at most `max_concurrent_builds`
//! uploads spool at once (the rest are shed with 503 `overloaded`), which
//! bounds the disk they take to that many times `max_import_bytes`.

use std::fs::File;
use std::io::SeekFrom;
use std::sync::Arc;

use axum::body::{Body, HttpBody};
use axum::extract::Request;
use axum::http::Method;
use tokio::io::{AsyncSeekExt, AsyncWriteExt, BufWriter};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::error::ApiError;
use formats::import::Source;

/// Bytes gathered before each write to the file.
const WRITE_BUFFER: usize = 256 * 1024;

/// Seconds a client shed for want of a spool slot is told to wait.
const RETRY_AFTER_SECS: u64 = 1;

/// The route whose bodies are spooled, its limit, and the spool slots.
#[derive(Debug, Clone)]
pub struct SpoolRoute {
    /// The `POST` path spooled.
    pub path: &'static str,
    pub max_bytes: usize,
    /// The setting `max_bytes` comes from, named in a 413.
    pub setting: &'static str,
    slots: Arc<Semaphore>,
}

impl SpoolRoute {
    pub fn new(path: &'static str, max_bytes: usize, setting: &'static str, concurrent: usize) -> SpoolRoute {
        SpoolRoute { path, max_bytes, setting, slots: Arc::new(Semaphore::new(concurrent.max(1))) }
    }

    /// Whether `request` is one this route spools.
    pub fn matches(&self, request: &Request) -> bool {
        request.method() == Method::POST && request.uri().path() == self.path
    }

    /// A spool slot, held until the request ends, or 503 at once.
    ///
    /// # Errors
    /// [`ApiError::Overloaded`] when every slot is taken.
    pub fn slot(&self) -> Result<OwnedSemaphorePermit, ApiError> {
        Arc::clone(&self.slots).try_acquire_owned().map_err(|_| {
            metrics::counter!("inbetween_requests_shed_total", "protocol" => "import_spool").increment(1);
            ApiError::Overloaded { retry_after: RETRY_AFTER_SECS }
        })
    }

    /// The whole body into a temporary file, 413 once it passes the limit
    /// (400 if the client breaks the stream off).
    ///
    /// # Errors
    /// As above; a temporary file that cannot be written is a 500.
    pub async fn receive(&self, mut body: Body) -> Result<SpooledBody, ApiError> {
        let mut spooler = Spooler::new(self.max_bytes as u64, self.setting).await?;
        while let Some(frame) = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)).await {
            let frame = frame.map_err(|e| ApiError::parameter("body_incomplete", "body", format!("{e}")))?;
            if let Ok(data) = frame.into_data() {
                spooler.push(&data).await?;
            }
        }
        spooler.finish().await
    }
}

/// A body spooled to a temporary file: the import handler's request
/// extension. Clones share the file, which is deleted when the last goes.
#[derive(Debug, Clone)]
pub struct SpooledBody {
    file: Arc<File>,
    len: u64,
}

impl SpooledBody {
    /// The bytes, for the importer to read by range.
    pub fn source(&self) -> Source {
        Source::file(Arc::clone(&self.file), self.len)
    }

    /// The bytes again as a streamed body (to parse a multipart upload
    /// without holding it).
    ///
    /// # Errors
    /// The file cannot be reopened (500).
    pub async fn body(&self) -> Result<Body, ApiError> {
        let handle = self.file.try_clone().map_err(ApiError::internal)?;
        let mut file = tokio::fs::File::from_std(handle);
        file.seek(SeekFrom::Start(0)).await.map_err(ApiError::internal)?;
        Ok(Body::from_stream(tokio_util::io::ReaderStream::new(file)))
    }
}

/// Writes chunks to a fresh temporary file, refusing more than `max` bytes.
pub struct Spooler {
    file: BufWriter<tokio::fs::File>,
    len: u64,
    max: u64,
    setting: &'static str,
}

impl Spooler {
    /// A spooler on a new anonymous temporary file.
    ///
    /// # Errors
    /// The file cannot be created (500).
    pub async fn new(max: u64, setting: &'static str) -> Result<Spooler, ApiError> {
        let file = tokio::task::spawn_blocking(tempfile::tempfile)
            .await
            .map_err(ApiError::internal)?
            .map_err(|e| ApiError::internal(anyhow::Error::new(e).context("creating an import spool file")))?;
        let file = BufWriter::with_capacity(WRITE_BUFFER, tokio::fs::File::from_std(file));
        Ok(Spooler { file, len: 0, max, setting })
    }

    /// Appends `chunk`, or refuses (413) once the total passes the limit.
    ///
    /// # Errors
    /// Over the limit; a failed write (500).
    pub async fn push(&mut self, chunk: &[u8]) -> Result<(), ApiError> {
        self.len += chunk.len() as u64;
        if self.len > self.max {
            return Err(ApiError::PayloadTooLarge { limit: self.max as usize, setting: self.setting });
        }
        self.file.write_all(chunk).await.map_err(write_failed)
    }

    /// The spooled bytes, flushed to the file.
    ///
    /// # Errors
    /// A failed write (500).
    pub async fn finish(mut self) -> Result<SpooledBody, ApiError> {
        self.file.flush().await.map_err(write_failed)?;
        let file = self.file.into_inner().into_std().await;
        Ok(SpooledBody { file: Arc::new(file), len: self.len })
    }
}

fn write_failed(e: std::io::Error) -> ApiError {
    ApiError::internal(anyhow::Error::new(e).context("writing an import spool file"))
}
