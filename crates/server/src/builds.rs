//! Where clips are built and what a build costs: every `Clip::build` the
//! server does (uploads, replaces, patches, imports, gRPC `PutClip`, cache
//! misses) is priced from what its document says (`work::price`: key
//! values, names, the bound on constant-speed tables), checked against
//! `max_request_work` and charged to its caller like a pose request, then
//! run on the work pool (`server::work`), never on the async workers.
//!
//! A build is CPU work of up to a fraction of a second; on the async
//! workers it would stall everything they serve (`/healthz`, gRPC `Ping`,
//! pose requests). On the pool the probes keep answering, and a caller
//! uploading many clips at once holds its share of the node and no more.
//! A build whose caller leaves (or whose request times out) is skipped if
//! it has not started, or stops within a few units of work: the pool's
//! cancel flag is the one `Clip::build_limited` watches.
//!
//! An upload pays twice, each priced before it runs: reading its body
//! (priced by its bytes), then building what the body turned out to hold.

use anim::spring::SpringsSpec;
use std::sync::atomic::AtomicBool;

use anim::ClipSpec;
use anim::ik::IkLimits;
use axum::body::Bytes;
use formats::wire::json::{ClipDoc, DocError, parse_clip, parse_clip_doc};

use crate::auth::CallerKey;
use crate::cache::CachedClip;
use crate::config::Limits;
use crate::error::ApiError;
use crate::limits::{Admitted, admit_spec, checked_spec};
use crate::store::{ClipMeta, StoredClip};
use crate::work::{Work, price};

/// Parses, checks and builds an uploaded clip document, each step priced
/// and run on the pool.
///
/// # Errors
/// `too_much_work` (422) over `max_request_work`; `caller_work_limit`
/// (429) and `overloaded` (503) as the work meter answers; then what
/// `malformed_json` (400), or what `limits::admit_doc` refuses.
pub async fn upload(work: &Work, caller: &CallerKey, limits: &Limits, body: Bytes) -> Result<Admitted, ApiError> {
    let units = price::parse(body.len() as u64);
    let checking = limits.clone();
    let parsed = run(work, caller, limits, units, "reading this clip document", move |_| {
        let doc = parse_clip_doc(&body)?;
        let spec = checked_spec(&doc, &checking)?;
        Ok((doc, spec))
    });
    let (doc, spec) = parsed.await?;
    build_spec(work, caller, limits, doc, spec).await
}

/// Checks and builds a parsed document (gRPC `PutClip`), priced and on
/// the pool.
///
/// # Errors
/// As [`upload`], less the JSON syntax.
pub async fn document(work: &Work, caller: &CallerKey, limits: &Limits, doc: ClipDoc) -> Result<Admitted, ApiError> {
    let spec = checked_spec(&doc, limits)?;
    build_spec(work, caller, limits, doc, spec).await
}

async fn build_spec(
    work: &Work,
    caller: &CallerKey,
    limits: &Limits,
    doc: ClipDoc,
    spec: ClipSpec,
) -> Result<Admitted, ApiError> {
    let units = price::clip_build(&spec, limits.max_build_work);
    let building = limits.clone();
    run(work, caller, limits, units, "building this clip", move |cancel| admit_spec(doc, &spec, &building, cancel))
        .await
}

/// Builds a stored clip (a cache miss), on the pool: reading its document
/// priced by its bytes, then its build by what the document holds, both
/// charged to the node ([`CallerKey::Node`]: every request that missed on
/// the clip waits on the one build) and not held to `max_request_work`
/// (the clip was admitted once).
///
/// # Errors
/// `overloaded` (503) when the node's capacity is taken; `request_timeout`;
/// `build_budget_exceeded` under a lowered `max_build_work`; `internal`
/// if the store holds a document that no longer reads or builds.
pub async fn stored(work: &Work, max_work: u64, stored: StoredClip) -> Result<CachedClip, ApiError> {
    let units = price::parse(stored.doc_json.len() as u64);
    let (meta, spec, springs) = work.spend(&CallerKey::Node, units, move |_| parse_stored(stored)).await??;
    let units = price::clip_build(&spec, max_work);
    let compile = move |cancel: &crate::work::Cancel| compile_stored((meta, springs), &spec, max_work, cancel.flag());
    work.spend(&CallerKey::Node, units, compile).await?
}

/// A stored document's spec. It was accepted once, so failure here means
/// the store was corrupted or the rules changed: an internal error.
fn parse_stored(stored: StoredClip) -> Result<(ClipMeta, ClipSpec, SpringsSpec), ApiError> {
    let no_longer =
        |e: DocError| ApiError::internal(anyhow::anyhow!("stored clip {} no longer parses: {e}", stored.meta.id));
    let (doc, spec) = parse_clip(stored.doc_json.as_bytes()).map_err(no_longer)?;
    let springs = doc.springs().map_err(no_longer)?;
    Ok((stored.meta, spec, springs))
}

/// Compiles a stored clip's spec within `max_work`: an internal error if it
/// no longer builds, unless the build budget was lowered since (422).
fn compile_stored(
    (meta, springs): (ClipMeta, SpringsSpec),
    spec: &ClipSpec,
    max_work: u64,
    cancel: &AtomicBool,
) -> Result<CachedClip, ApiError> {
    // A stored clip's constraints were admitted under the limits of their
    // day: IK ceilings apply to what comes in, not to what is kept.
    let ik = IkLimits { max_constraints: usize::MAX, max_iterations: u32::MAX, max_effectors: usize::MAX };
    let clip = crate::limits::build(spec, max_work, &ik, cancel).map_err(|e| match e {
        e @ ApiError::TooMany { .. } => e,
        e => ApiError::internal(anyhow::anyhow!("stored clip {} no longer builds: {e:?}", meta.id)),
    })?;
    Ok(CachedClip { meta, clip, springs })
}

/// Checks `units` of `what` against `max_request_work`, charges them to
/// `caller` and runs `job` on the pool with its cancel flag.
///
/// # Errors
/// `too_much_work` (422) over the limit; as `Work::spend`; what `job`
/// returns.
pub async fn run<T, F>(
    work: &Work,
    caller: &CallerKey,
    limits: &Limits,
    units: u64,
    what: &str,
    job: F,
) -> Result<T, ApiError>
where
    F: FnOnce(&AtomicBool) -> Result<T, ApiError> + Send + 'static,
    T: Send + 'static,
{
    check(units, limits, what)?;
    work.spend(caller, units, move |cancel| job(cancel.flag())).await?
}

/// # Errors
/// `too_much_work` (422) when `units` are over `max_request_work`.
pub fn check(units: u64, limits: &Limits, what: &str) -> Result<(), ApiError> {
    if units <= limits.max_request_work {
        return Ok(());
    }
    Err(ApiError::TooMany {
        code: "too_much_work",
        pointer: String::new(),
        detail: format!(
            "{what} costs {units} work units; the limit (max_request_work, --max-request-work) is {}",
            limits.max_request_work
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    fn limits(threads: usize) -> Limits {
        let mut limits = crate::config::RawConfig::default().validate().unwrap().limits;
        limits.work_threads = threads;
        limits.node_work_per_sec = 1_000_000_000;
        limits
    }

    fn caller(n: u8) -> CallerKey {
        CallerKey::Addr(std::net::IpAddr::from([10, 0, 0, n]))
    }

    #[tokio::test]
    async fn builds_run_on_the_pool_no_more_at_once_than_its_threads() {
        let limits = limits(2);
        let work = Arc::new(Work::new(&limits));
        let (running, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let here = std::thread::current().id();
        let tasks: Vec<_> = (0..6)
            .map(|n| {
                let (work, limits, running, peak) = (work.clone(), limits.clone(), running.clone(), peak.clone());
                tokio::spawn(async move {
                    run(&work, &caller(n), &limits, 1_000_000, "a test build", move |_| {
                        assert_ne!(std::thread::current().id(), here, "a build on the async worker");
                        let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                        peak.fetch_max(now, Ordering::SeqCst);
                        std::thread::sleep(Duration::from_millis(20));
                        running.fetch_sub(1, Ordering::SeqCst);
                        Ok(())
                    })
                    .await
                })
            })
            .collect();
        for task in tasks {
            task.await.unwrap().unwrap();
        }
        assert_eq!(peak.load(Ordering::SeqCst), 2, "both threads were used, and never more");
        assert_eq!(work.meter().held(), 0, "every build gave its price back");
    }

    #[tokio::test]
    async fn a_build_over_the_request_limit_is_refused_before_it_runs() {
        let limits = limits(1);
        let work = Work::new(&limits);
        let (over, me) = (limits.max_request_work + 1, caller(1));
        let refused = run(&work, &me, &limits, over, "building this clip", |_| -> Result<(), _> {
            panic!("a refused build ran")
        });
        let e = refused.await.unwrap_err();
        assert_eq!((e.code(), e.status().as_u16()), ("too_much_work", 422));
        assert!(format!("{e:?}").contains(&over.to_string()), "the price in the detail: {e:?}");
    }

    #[tokio::test]
    async fn a_build_whose_caller_stops_waiting_sees_its_flag_raised() {
        let limits = limits(1);
        let work = Arc::new(Work::new(&limits));
        let (seen_tx, seen_rx) = std::sync::mpsc::channel();
        let (started_tx, started_rx) = tokio::sync::oneshot::channel();
        let me = caller(1);
        let waiting = run(&work, &me, &limits, 1_000_000, "a test build", move |cancel| {
            started_tx.send(()).unwrap();
            let since = std::time::Instant::now();
            while !cancel.load(Ordering::Relaxed) && since.elapsed().as_secs() < 10 {
                std::thread::yield_now();
            }
            seen_tx.send(cancel.load(Ordering::Relaxed)).unwrap();
            Ok(())
        });
        tokio::select! {
            _ = waiting => panic!("the build ended on its own"),
            _ = started_rx => {}
        }
        let seen = tokio::task::spawn_blocking(move || seen_rx.recv().unwrap()).await.unwrap();
        assert!(seen, "the flag was raised");
        let ok = run(&work, &me, &limits, 1_000_000, "a test build", |_| Ok(7)).await.unwrap();
        assert_eq!((ok, work.meter().held()), (7, 0), "the price came back once the thread was done");
    }
}
