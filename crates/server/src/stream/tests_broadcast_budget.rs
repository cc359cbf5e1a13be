//! A broadcast's budgets on a paused tokio clock (docs/broadcasts.md, "Work"
//! and "Control"): its store queue is bounded and a control beyond it is
//! refused and never applied; a control the store refuses is withdrawn and
//! its sender told; a broadcast whose ticks overrun their price ends with
//! `too_much_work` while another goes on; crossfades and `ik` controls
//! re-price it.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use serde_json::Value::Null;

use super::tests::{clip, pinned};
use super::*;
use crate::error::ApiError;

/// A store that never answers (`stuck`), or refuses every control.
struct TestJournal {
    stuck: bool,
    ended: Arc<AtomicBool>,
}

impl Journal for TestJournal {
    fn record(
        &self,
        _: &str,
        _: u64,
        _: &str,
        _: serde_json::Value,
        _: Option<&StreamMotion>,
    ) -> BoxFuture<'static, Result<(), ControlError>> {
        match self.stuck {
            true => std::future::pending().boxed(),
            false => std::future::ready(Err(ApiError::Unavailable(None).to_control())).boxed(),
        }
    }

    fn touch(&self, _: &str) -> BoxFuture<'static, ()> {
        std::future::ready(()).boxed()
    }

    fn expire(&self, _: &str, _: Duration) -> BoxFuture<'static, bool> {
        std::future::ready(false).boxed()
    }

    fn ended(&self, _: &str) -> BoxFuture<'static, ()> {
        self.ended.store(true, Ordering::Relaxed);
        std::future::ready(()).boxed()
    }
}

fn engine() -> Engine {
    Engine::new(EngineConfig { max_streams: 100, max_streams_per_client: 100, max_broadcasts: 4, ..Default::default() })
}

fn spec(fps: u32) -> BroadcastSpec {
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps, ..Default::default() }).unwrap();
    BroadcastSpec { params, idle_timeout: Duration::from_secs(300), description: Null, work_per_sec: 0 }
}

fn viewer(e: &Engine, b: &Arc<Broadcast>) -> Subscription {
    b.watch(Encoding::Json, e.admit(None).unwrap(), None)
}

async fn frame(sub: &mut Subscription) -> Delivered {
    match sub.next().await {
        Next::Frame(f) => f,
        Next::End(r) => panic!("ended early: {r:?}"),
    }
}

fn time(f: &Delivered) -> f64 {
    let v: serde_json::Value = serde_json::from_slice(&f.bytes).unwrap();
    (v["pose"]["time"].as_f64().unwrap() * 1e9).round() / 1e9
}

#[tokio::test(start_paused = true)]
async fn a_control_beyond_the_store_queue_is_refused_and_never_applied() {
    let e = engine();
    e.broadcasts().set_journal(Arc::new(TestJournal { stuck: true, ended: Arc::default() }));
    let b = e.broadcasts().create(spec(10), BroadcastCharge::free()).unwrap();
    let mut v = viewer(&e, &b);
    for i in 0..STORE_QUEUE {
        let (_, storing) = b.control(Control::Seek(i as f64)).unwrap();
        assert!(storing.is_some(), "with a journal every control is stored");
        if i % 16 == 15 {
            frame(&mut v).await; // the task takes the controls filed so far
        }
    }
    let refused = b.control(Control::Pause).unwrap_err();
    assert_eq!(refused.code(), "unavailable", "{refused}");
    let ControlError::Refused { problem, .. } = &refused else { panic!("{refused:?}") };
    assert_eq!(problem["status"], 503);
    assert_eq!(b.control_ids().len(), STORE_QUEUE, "the refused control was never applied");
    for _ in 0..3 {
        frame(&mut v).await;
    }
    assert!(!b.status().paused);
}

#[tokio::test(start_paused = true)]
async fn a_control_the_store_refuses_is_withdrawn_and_its_sender_told() {
    let e = engine();
    e.broadcasts().set_journal(Arc::new(TestJournal { stuck: false, ended: Arc::default() }));
    let b = e.broadcasts().create(spec(10), BroadcastCharge::free()).unwrap();
    let mut v = viewer(&e, &b);
    frame(&mut v).await;
    let (seq, storing) = b.control(Control::Seek(7.0)).unwrap();
    let refusal = storing.expect("stored through the journal").await.expect("the store refused it");
    assert_eq!(refusal.code(), "unavailable");
    let mut shown = Vec::new();
    for _ in 0..4 {
        let f = frame(&mut v).await;
        shown.push((f.seq, time(&f)));
    }
    assert_eq!(seq, 1);
    assert_eq!(shown, [(1, 0.1), (2, 0.2), (3, 0.3), (4, 0.4)], "played as if never sought");
}

#[tokio::test(start_paused = true)]
async fn a_broadcast_whose_ticks_overrun_their_price_ends_alone_with_too_much_work() {
    let e = engine();
    let ended = Arc::new(AtomicBool::new(false));
    e.broadcasts().set_journal(Arc::new(TestJournal { stuck: true, ended: Arc::clone(&ended) }));
    // Priced as if a unit took a femtosecond: every real tick is far over.
    let underpriced = BroadcastCharge { per_tick: 10, limit_per_sec: u64::MAX, ns_per_unit: 1e-6, tickets: vec![] };
    let greedy = e.broadcasts().create(spec(10), underpriced).unwrap();
    let bystander = e.broadcasts().create(spec(10), BroadcastCharge::free()).unwrap();
    let (mut g, mut y) = (viewer(&e, &greedy), viewer(&e, &bystander));
    let mut greedy_frames = 0;
    let reason = loop {
        match g.next().await {
            Next::Frame(_) => greedy_frames += 1,
            Next::End(reason) => break reason,
        }
    };
    assert_eq!(reason, EndReason::TooMuchWork);
    assert!((9..=10).contains(&greedy_frames), "ended after one second of ticks, not before: {greedy_frames}");
    assert!(e.broadcasts().get(greedy.id()).is_none(), "unlisted");
    tokio::task::yield_now().await;
    assert!(ended.load(Ordering::Relaxed), "ended everywhere through the journal");
    let first = frame(&mut y).await.seq;
    for k in 1..30 {
        assert_eq!(frame(&mut y).await.seq, first + k, "the bystander keeps every tick");
    }
}

#[test]
fn a_crossfade_or_ik_control_re_prices_the_broadcast_and_one_over_the_limit_is_refused() {
    let s = spec(10);
    let motion = &s.params.motion;
    let one_pose = crate::work::price::motion_pose(motion);
    let charge =
        BroadcastCharge { per_tick: 100, limit_per_sec: 10 * (100 + one_pose), ns_per_unit: 10.0, tickets: vec![] };
    let mut budget = broadcast_budget::Budget::new(charge, motion, 10);
    assert_eq!(budget.per_tick(), 100);
    budget.reprice(&Control::Pause, motion).unwrap();
    assert_eq!(budget.per_tick(), 100, "a pause costs nothing more");
    let fade =
        Control::Crossfade(Crossfade { to: Arc::clone(motion), duration: 0.5, ease: anim::Ease::Linear, source: None });
    budget.reprice(&fade, motion).unwrap();
    assert_eq!(budget.per_tick(), 100 + one_pose, "while it fades both motions are evaluated");
    let refused = budget.reprice(&fade, motion).unwrap_err();
    assert_eq!(refused.code(), "too_much_work", "a fade begun while the first may still run evaluates three motions");
    assert_eq!(budget.per_tick(), 100 + one_pose, "nothing changed");
    let ik = Control::SetIk(Vec::new());
    budget.reprice(&ik, motion).unwrap();
    assert_eq!(budget.per_tick(), 100 + one_pose);
    let tight = BroadcastCharge { per_tick: 100, limit_per_sec: 1000, ns_per_unit: 10.0, tickets: vec![] };
    let mut budget = broadcast_budget::Budget::new(tight, motion, 10);
    let refused = budget.reprice(&fade, motion).unwrap_err();
    assert_eq!(refused.code(), "too_much_work");
    assert_eq!(budget.per_tick(), 100, "a refused control changes nothing");
}

#[tokio::test(start_paused = true)]
async fn a_broadcast_holds_its_charge_until_it_is_deleted() {
    let e = engine();
    let meter = crate::work::Meter::new(1000, 1.0);
    let caller = crate::auth::CallerKey::Addr([10, 0, 0, 1].into());
    let ticket = meter.charge(&caller, 300).unwrap();
    let charge = BroadcastCharge { per_tick: 30, limit_per_sec: u64::MAX, ns_per_unit: 0.0, tickets: vec![ticket] };
    let b = e.broadcasts().create(spec(10), charge).unwrap();
    let mut v = viewer(&e, &b);
    frame(&mut v).await;
    assert_eq!(meter.held(), 300, "held while it lives");
    assert!(e.broadcasts().delete(b.id()));
    assert_eq!(meter.held(), 0, "given back at the delete, while a viewer and this test still hold the broadcast");
    assert_eq!(v.next().await, Next::End(EndReason::Ended));
}
