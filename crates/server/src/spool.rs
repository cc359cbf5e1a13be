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
//! slow upload holds no in-flight slot. It holds an upload slot instead
//! ([`UploadSlots`]): at most `max_import_uploads_per_caller` per caller (its
//! token's name, or its address) and `max_import_uploads` in all, which bounds
//! the disk they take to that many times `max_import_bytes`. An import that
//! finds no slot waits up to `import_slot_wait_secs` in a queue as long as
//! the node's slots, then is shed with 503 `overloaded`. And an upload must
//! keep arriving: one that brings fewer than `min_upload_bytes_per_sec` over
//! the last `upload_rate_window_secs` ([`Pace`]) is cut off with 408
//! `body_timeout`, which frees its slot. So one caller trickling uploads holds
//! its own slots only, and for a few seconds.

use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::io::SeekFrom;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::{Body, HttpBody};
use axum::extract::Request;
use axum::http::Method;
use tokio::io::{AsyncSeekExt, AsyncWriteExt, BufWriter};
use tokio::sync::Notify;
use tokio::time::Instant;

use super::auth::CallerKey;
use super::error::ApiError;
use crate::sync::lock;
use formats::import::Source;

/// Bytes gathered before each write to the file.
const WRITE_BUFFER: usize = 256 * 1024;

/// Seconds a client shed for want of an upload slot is told to wait.
const RETRY_AFTER_SECS: u64 = 1;

/// How often an upload's arrival rate is checked.
const PACE_CHECK: Duration = Duration::from_secs(1);

/// The route whose bodies are spooled, its limit, and the upload slots.
#[derive(Debug, Clone)]
pub struct SpoolRoute {
    /// The `POST` paths spooled (the import routes).
    pub paths: Vec<&'static str>,
    pub max_bytes: usize,
    /// The setting `max_bytes` comes from, named in a 413.
    pub setting: &'static str,
    slots: Arc<UploadSlots>,
    pace: PaceLimit,
}

/// How many uploads spool at once, and how long one waits for a slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UploadLimits {
    pub node: usize,
    pub per_caller: usize,
    pub wait: Duration,
}

/// The slowest an upload may arrive: `min_per_sec` over every `window`
/// once it has been sending that long (0: no floor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaceLimit {
    pub min_per_sec: u64,
    pub window: Duration,
}

impl SpoolRoute {
    pub fn new(
        paths: Vec<&'static str>,
        (max_bytes, setting): (usize, &'static str),
        limits: UploadLimits,
        pace: PaceLimit,
    ) -> SpoolRoute {
        SpoolRoute { paths, max_bytes, setting, slots: UploadSlots::new(limits), pace }
    }

    /// Whether `request` is one this route spools.
    pub fn matches(&self, request: &Request) -> bool {
        request.method() == Method::POST && self.paths.contains(&request.uri().path())
    }

    /// An upload slot for `caller`, held until the request ends.
    ///
    /// # Errors
    /// [`ApiError::Overloaded`] when none comes free within the wait, or the
    /// queue is full.
    pub async fn slot(&self, caller: CallerKey) -> Result<UploadSlot, ApiError> {
        self.slots.acquire(caller).await
    }

    /// The whole body into a temporary file, 413 once it passes the limit,
    /// 408 once it arrives slower than the pace limit (400 if the client
    /// breaks the stream off).
    ///
    /// # Errors
    /// As above; a temporary file that cannot be written is a 500.
    pub async fn receive(&self, mut body: Body) -> Result<SpooledBody, ApiError> {
        let mut spooler = Spooler::new(self.max_bytes as u64, self.setting).await?;
        let mut pace = Pace::new(self.pace, Instant::now());
        loop {
            let next = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx));
            match tokio::time::timeout_at(pace.next_check(), next).await {
                Ok(None) => break,
                Ok(Some(frame)) => {
                    let frame = frame.map_err(|e| ApiError::parameter("body_incomplete", "body", format!("{e}")))?;
                    if let Ok(data) = frame.into_data() {
                        spooler.push(&data).await?;
                        pace.arrived(data.len());
                    }
                }
                Err(_) => {}
            }
            pace.check(Instant::now())?;
        }
        spooler.finish().await
    }
}

/// The upload slots of the import route: per caller and in all, with a short
/// queue for either (see the module doc).
#[derive(Debug)]
pub struct UploadSlots {
    limits: UploadLimits,
    held: Mutex<Held>,
    /// Told whenever a slot is given back.
    freed: Notify,
}

#[derive(Debug, Default)]
struct Held {
    total: usize,
    waiting: usize,
    callers: HashMap<CallerKey, usize>,
}

impl UploadSlots {
    pub fn new(limits: UploadLimits) -> Arc<UploadSlots> {
        let limits = UploadLimits { node: limits.node.max(1), per_caller: limits.per_caller.max(1), ..limits };
        Arc::new(UploadSlots { limits, held: Mutex::default(), freed: Notify::new() })
    }

    /// A slot for `caller`: at once if both its share and the node have one,
    /// else the first to come free within the wait.
    ///
    /// # Errors
    /// [`ApiError::Overloaded`] past the wait, or when as many imports as the
    /// node has slots are already waiting.
    pub async fn acquire(self: &Arc<Self>, caller: CallerKey) -> Result<UploadSlot, ApiError> {
        if let Some(slot) = self.try_take(&caller) {
            return Ok(slot);
        }
        let _queued = self.enqueue()?;
        let deadline = Instant::now() + self.limits.wait;
        loop {
            let freed = self.freed.notified();
            tokio::pin!(freed);
            freed.as_mut().enable();
            if let Some(slot) = self.try_take(&caller) {
                return Ok(slot);
            }
            if tokio::time::timeout_at(deadline, freed).await.is_err() {
                return Err(shed());
            }
        }
    }

    fn try_take(self: &Arc<Self>, caller: &CallerKey) -> Option<UploadSlot> {
        let mut held = lock(&self.held);
        let mine = held.callers.get(caller).copied().unwrap_or(0);
        if held.total >= self.limits.node || mine >= self.limits.per_caller {
            return None;
        }
        held.total += 1;
        held.callers.insert(caller.clone(), mine + 1);
        metrics::gauge!("inbetween_import_uploads").increment(1.0);
        Some(UploadSlot { slots: Arc::clone(self), caller: caller.clone() })
    }

    /// A place in the queue, or 503 when it is full.
    fn enqueue(self: &Arc<Self>) -> Result<Queued, ApiError> {
        let mut held = lock(&self.held);
        if held.waiting >= self.limits.node {
            return Err(shed());
        }
        held.waiting += 1;
        Ok(Queued(Arc::clone(self)))
    }
}

fn shed() -> ApiError {
    metrics::counter!("inbetween_requests_shed_total", "protocol" => "import_spool").increment(1);
    ApiError::Overloaded { retry_after: RETRY_AFTER_SECS }
}

/// An import's upload slot, given back when dropped.
#[derive(Debug)]
pub struct UploadSlot {
    slots: Arc<UploadSlots>,
    caller: CallerKey,
}

impl Drop for UploadSlot {
    fn drop(&mut self) {
        let mut held = lock(&self.slots.held);
        held.total -= 1;
        metrics::gauge!("inbetween_import_uploads").decrement(1.0);
        if let Some(mine) = held.callers.get_mut(&self.caller) {
            *mine -= 1;
            if *mine == 0 {
                held.callers.remove(&self.caller);
            }
        }
        drop(held);
        self.slots.freed.notify_waiters();
    }
}

/// A place in the queue for a slot, left when dropped.
struct Queued(Arc<UploadSlots>);

impl Drop for Queued {
    fn drop(&mut self) {
        lock(&self.0.held).waiting -= 1;
    }
}

/// An upload's arrival measured against its [`PaceLimit`]: every second,
/// from one window after it began, the bytes of the last window (or a
/// little more) must reach `min_per_sec` per second.
#[derive(Debug)]
pub struct Pace {
    limit: PaceLimit,
    received: u64,
    /// `(time, bytes received by then)` at each check, the oldest at or
    /// before a window ago.
    marks: VecDeque<(Instant, u64)>,
    next: Instant,
}

impl Pace {
    pub fn new(limit: PaceLimit, start: Instant) -> Pace {
        Pace { limit, received: 0, marks: VecDeque::from([(start, 0)]), next: start + PACE_CHECK }
    }

    /// When the next check is due.
    pub fn next_check(&self) -> Instant {
        self.next
    }

    pub fn arrived(&mut self, bytes: usize) {
        self.received += bytes as u64;
    }

    /// Checks the last window once a check is due.
    ///
    /// # Errors
    /// [`ApiError::UploadTooSlow`] when it brought too little.
    pub fn check(&mut self, now: Instant) -> Result<(), ApiError> {
        if now < self.next || self.limit.min_per_sec == 0 {
            return Ok(());
        }
        self.next = now + PACE_CHECK;
        self.marks.push_back((now, self.received));
        let Some(window_start) = now.checked_sub(self.limit.window) else { return Ok(()) };
        while self.marks.get(1).is_some_and(|m| m.0 <= window_start) {
            self.marks.pop_front();
        }
        let (then, before) = self.marks[0];
        if then > window_start {
            // Not sending for a whole window yet: the grace.
            return Ok(());
        }
        let (received, secs) = (self.received - before, now.duration_since(then).as_secs_f64());
        if (received as f64) < self.limit.min_per_sec as f64 * secs {
            metrics::counter!("inbetween_uploads_too_slow_total").increment(1);
            let window_secs = secs.round() as u64;
            return Err(ApiError::UploadTooSlow { received, window_secs, min_per_sec: self.limit.min_per_sec });
        }
        Ok(())
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

#[cfg(test)]
mod tests {
    use std::net::IpAddr;

    use super::*;

    fn caller(last: u8) -> CallerKey {
        CallerKey::Addr(IpAddr::from([10, 0, 0, last]))
    }

    fn slots(node: usize, per_caller: usize) -> Arc<UploadSlots> {
        UploadSlots::new(UploadLimits { node, per_caller, wait: Duration::from_secs(2) })
    }

    #[tokio::test(start_paused = true)]
    async fn a_caller_at_its_share_leaves_the_node_to_the_others() {
        let slots = slots(4, 2);
        let (a1, _a2) = (slots.acquire(caller(1)).await.unwrap(), slots.acquire(caller(1)).await.unwrap());
        // A third of its own waits, then is shed; another caller gets one at once.
        let started = Instant::now();
        assert!(matches!(slots.acquire(caller(1)).await, Err(ApiError::Overloaded { retry_after: 1 })));
        assert_eq!(started.elapsed(), Duration::from_secs(2), "it waited import_slot_wait_secs");
        let _b = slots.acquire(caller(2)).await.unwrap();
        // One freed within the wait goes to the caller waiting for it.
        let waiting = tokio::spawn({
            let slots = Arc::clone(&slots);
            async move { slots.acquire(caller(1)).await.map(|_| ()) }
        });
        tokio::time::sleep(Duration::from_millis(500)).await;
        drop(a1);
        assert!(waiting.await.unwrap().is_ok());
        // Nothing is left counted once every slot is given back.
        drop((_a2, _b));
        let held = lock(&slots.held);
        assert_eq!((held.total, held.waiting, held.callers.len()), (0, 0, 0));
    }

    #[tokio::test(start_paused = true)]
    async fn the_node_cap_holds_and_the_queue_is_as_long_as_the_node_has_slots() {
        let slots = slots(2, 2);
        let _held = [slots.acquire(caller(1)).await.unwrap(), slots.acquire(caller(2)).await.unwrap()];
        let queued: Vec<_> = (3..5)
            .map(|c| {
                let slots = Arc::clone(&slots);
                tokio::spawn(async move { slots.acquire(caller(c)).await.map(|_| ()) })
            })
            .collect();
        tokio::task::yield_now().await;
        // Two wait; a third is refused at once.
        assert_eq!(lock(&slots.held).waiting, 2);
        let started = Instant::now();
        assert!(slots.acquire(caller(9)).await.is_err());
        assert_eq!(started.elapsed(), Duration::ZERO, "refused without waiting");
        for q in queued {
            assert!(q.await.unwrap().is_err(), "no slot came free");
        }
    }

    #[test]
    fn an_upload_below_the_floor_is_cut_after_one_window() {
        let limit = PaceLimit { min_per_sec: 1000, window: Duration::from_secs(3) };
        let start = Instant::now();
        let at = |ms: u64| start + Duration::from_millis(ms);
        // A trickle of 1 byte a second: passes its grace, cut at the end of the first window.
        let mut trickle = Pace::new(limit, start);
        for s in 1..3 {
            trickle.arrived(1);
            assert!(trickle.check(at(s * 1000)).is_ok(), "within the grace at {s} s");
        }
        trickle.arrived(1);
        let cut = trickle.check(at(3000)).unwrap_err();
        assert!(matches!(cut, ApiError::UploadTooSlow { received: 3, window_secs: 3, min_per_sec: 1000 }), "{cut:?}");
        // A steady 4000 bytes a second passes every check, and so does a stall
        // the last window still covers; a whole window without a byte is cut.
        let mut steady = Pace::new(limit, start);
        for s in 1..=10 {
            steady.arrived(4000);
            assert!(steady.check(at(s * 1000)).is_ok(), "steady at {s} s");
        }
        for s in 11..13 {
            assert!(steady.check(at(s * 1000)).is_ok(), "a stall the window still covers, at {s} s");
        }
        assert!(steady.check(at(13_000)).is_err(), "a whole window without a byte");
        // No floor: never cut.
        let mut free = Pace::new(PaceLimit { min_per_sec: 0, ..limit }, start);
        assert!(free.check(at(60_000)).is_ok());
    }
}
