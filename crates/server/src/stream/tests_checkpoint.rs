//! Broadcast checkpoints (docs/broadcasts.md "Checkpoints"): a program
//! restored from the stored text of any checkpoint makes the very bytes of
//! the program that stepped from tick 0 — through seeks, pauses, speed
//! changes, layer ramps, sync-group phases, root motion and crossfades
//! nested in crossfades — two programs write the same text for the same
//! tick, a control heard late goes back to the latest checkpoint before it
//! (never before the one a program started from), and the controls before
//! that are let go. The clips have events, so a frame also shows the
//! events crossed since the tick before the checkpoint.

use std::sync::Arc;

use anim::motion::{LayerSpec, MotionSpec, RootMotionSpec};
use anim::{Channel, Clip, ClipSpec, EventSpec, Interpolation, Keys, Motion, Playback, TrackSpec};
use glam::Vec3;

use super::broadcast_program::CHECKPOINTS;
use super::tests::pinned;
use super::*;

/// `root` and `tip` moving from `from` to `to` over `duration` (looping).
fn line(duration: f32, from: Vec3, to: Vec3) -> Arc<Clip> {
    let track = |joint: &str| {
        TrackSpec::new(
            joint,
            Channel::Translation,
            Interpolation::Linear,
            vec![0.0, duration],
            Keys::Vec3(vec![from, to]),
        )
    };
    let spec = ClipSpec {
        name: "line".into(),
        tracks: vec![track("root"), track("tip")],
        events: vec![
            EventSpec { time: duration * 0.25, name: "step".into() },
            EventSpec { time: duration * 0.75, name: "step".into() },
        ],
        playback: Playback::Loop,
        ..Default::default()
    };
    Arc::new(Clip::build(&spec).unwrap())
}

/// Two synced layers with root motion: phases, ramps and the root total
/// all carry from tick to tick.
fn gait(a: &Arc<dyn PinnedClip>, b: &Arc<dyn PinnedClip>, weight: f32) -> Arc<StreamMotion> {
    let layer = |clip: &Arc<dyn PinnedClip>, weight| LayerSpec {
        sync: Some("gait".into()),
        weight,
        ..LayerSpec::new(Arc::clone(clip))
    };
    let spec = MotionSpec {
        layers: vec![layer(a, 1.0), layer(b, weight)],
        root_motion: Some(RootMotionSpec::default()),
        ..Default::default()
    };
    Arc::new(Motion::build(spec).unwrap())
}

struct Case {
    params: StreamParams,
    log: ControlLog,
}

fn case() -> Case {
    let walk = pinned("walk", line(1.0, Vec3::ZERO, Vec3::new(1.0, 0.0, 0.5)));
    let run = pinned("run", line(0.6, Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.3, 0.0, 1.5)));
    let req = StreamRequest { fps: 30, ..Default::default() };
    let params = StreamParams::of_motion(gait(&walk, &run, 0.4), "gait".into(), req).unwrap();
    let fade =
        |to: Arc<StreamMotion>, duration, ease| Control::Crossfade(Crossfade { to, duration, ease, source: None });
    let schedule = [
        (7, Control::Layer { index: 1, weight: 0.9, duration: 0.5 }),
        (20, fade(gait(&run, &walk, 0.2), 0.8, anim::Ease::EaseInOut)),
        (29, fade(gait(&walk, &walk, 1.0), 0.5, anim::Ease::Linear)),
        (41, Control::Seek(0.35)),
        (55, Control::Pause),
        (70, Control::Layer { index: 0, weight: 0.5, duration: 0.3 }),
        (80, Control::Play),
        (90, Control::Speed(-0.5)),
        (130, fade(gait(&run, &run, 0.5), 1.0, anim::Ease::EaseOut)),
        (133, Control::Speed(2.0)),
        (170, Control::Seek(2.0)),
    ];
    let mut log = ControlLog::default();
    for (seq, control) in schedule {
        log.insert(StampedControl { seq, id: new_control_id(), control });
    }
    Case { params, log }
}

const TICKS: u64 = 240;
const EVERY: u64 = 16;

/// Tick `k`'s JSON frame (`sent_at` fixed, so equal frames are equal bytes).
fn bytes_at(p: &mut Program, k: u64, log: &ControlLog) -> bytes::Bytes {
    p.step_to(k, log);
    p.encode(Encoding::Json, 0).bytes
}

#[test]
fn a_program_restored_from_any_checkpoint_makes_the_same_bytes_as_one_stepped_from_tick_0() {
    let Case { params, log } = case();
    let mut reference = Program::new(&params).checkpointing(EVERY);
    let mut frames = Vec::new();
    let mut texts = Vec::new();
    for k in 0..TICKS {
        frames.push(bytes_at(&mut reference, k, &log));
        if (k + 1) % EVERY == 0 {
            texts.push(reference.checkpoint().unwrap().to_text());
        }
    }
    assert_ne!(frames[40], frames[41], "the seek shows");
    for (i, text) in texts.iter().enumerate() {
        let checkpoint = Checkpoint::from_text(text).unwrap();
        let c = (i as u64 + 1) * EVERY - 1;
        assert_eq!(checkpoint.tick, c);
        let mut restored = Program::from_checkpoint(&params, &checkpoint, &log).unwrap().checkpointing(EVERY);
        assert_eq!(restored.next(), c + 1);
        for k in c + 1..TICKS {
            assert_eq!(bytes_at(&mut restored, k, &log), frames[k as usize], "tick {k} from the checkpoint of {c}");
        }
        // Another node's program at the same tick writes the same text.
        let mut other = Program::new(&params);
        other.step_to(c, &log);
        assert_eq!(other.checkpoint().unwrap().to_text(), *text, "the checkpoint of tick {c} on another node");
    }
    // The last crossfade's checkpoint names the controls on the player and
    // the motions the broadcast played (its compact layouts hold them), and only those.
    let last = Checkpoint::from_text(texts.last().unwrap()).unwrap();
    let mut fade_ids: Vec<String> = [20, 29, 130].iter().map(|&k| log.at(k)[0].id.to_string()).collect();
    fade_ids.sort();
    assert_eq!(last.controls(), fade_ids, "the three crossfades' motions");
}

#[test]
fn a_control_heard_late_goes_back_to_the_latest_checkpoint_before_it_and_never_before_the_start() {
    let Case { params, log } = case();
    let mut reference = Program::new(&params).checkpointing(EVERY);
    let frames: Vec<_> = (0..TICKS).map(|k| bytes_at(&mut reference, k, &log)).collect();
    // A node that started from the checkpoint of tick 15 and has not heard the control stamped 130.
    let mut start = Program::new(&params);
    start.step_to(15, &log);
    let checkpoint = start.checkpoint().unwrap();
    let late_id = Arc::clone(&log.at(130)[0].id);
    let mut partial = log.clone();
    partial.remove(&late_id);
    let mut node = Program::from_checkpoint(&params, &checkpoint, &log).unwrap().checkpointing(EVERY);
    assert_eq!(node.floor(), 16);
    for k in 16..160 {
        bytes_at(&mut node, k, &partial);
    }
    // Checkpoints every 16 ticks, the last CHECKPOINTS kept: the floor moved up to the oldest let go.
    let newest = (160 / EVERY) * EVERY - 1;
    assert_eq!(node.newest_checkpoint(), newest + 1);
    assert_eq!(node.floor(), newest + 1 - CHECKPOINTS as u64 * EVERY);
    assert!(node.checkpoint_of(newest - EVERY).is_some() && node.checkpoint_of(15).is_none());
    let again = node.rewind_before(130).expect("130 is after the floor");
    assert_eq!(node.next(), 128, "the latest kept state before 130 is the checkpoint of 127");
    assert_eq!(again, 160 - 128);
    for k in 160..TICKS {
        assert_eq!(bytes_at(&mut node, k, &log), frames[k as usize], "tick {k} after the rewind");
    }
    // Before the floor, nothing changes.
    let next = node.next();
    assert_eq!(node.rewind_before(node.floor() - 1), None);
    assert_eq!(node.next(), next);
}

#[test]
fn the_log_forgets_controls_before_a_tick_and_counts_those_since() {
    let Case { log, .. } = case();
    let mut log = log;
    assert_eq!(log.since(0), 11);
    assert_eq!(log.since(80), 5);
    log.forget_before(80);
    assert_eq!(log.len(), 5);
    assert!(log.at(70).is_empty() && log.at(80).len() == 1);
}

#[test]
fn a_checkpoint_that_names_a_missing_control_or_another_format_is_refused() {
    let Case { params, log } = case();
    let mut p = Program::new(&params);
    p.step_to(40, &log);
    let checkpoint = p.checkpoint().unwrap();
    let named = checkpoint.controls();
    assert!(!named.is_empty(), "a crossfade's motion is named");
    let mut without = log.clone();
    without.remove(&named[0]);
    assert!(matches!(
        Program::from_checkpoint(&params, &checkpoint, &without),
        Err(CheckpointError::MissingControl(_))
    ));
    let other = checkpoint.to_text().replacen("\"format\":1", "\"format\":99", 1);
    assert!(matches!(
        Checkpoint::from_text(&other).map(|c| Program::from_checkpoint(&params, &c, &log)),
        Ok(Err(CheckpointError::Unreadable(_)))
    ));
    assert!(Checkpoint::from_text("{}").is_err());
}

/// A one-layer motion of `clip`, as a crossfade's target.
fn alone(clip: &Arc<dyn PinnedClip>) -> Arc<StreamMotion> {
    let spec = MotionSpec { layers: vec![anim::motion::LayerSpec::new(Arc::clone(clip))], ..Default::default() };
    Arc::new(Motion::build(spec).unwrap())
}

/// The compact layouts a broadcast chooses follow what it has played (a
/// layer ramp on its clip, crossfades, an `ik` control), and a program
/// restored from a checkpoint, or stepped by another node, chooses the
/// very same documents at every tick after it.
#[test]
fn a_restored_program_chooses_the_compact_layouts_of_the_one_stepped_from_tick_0() {
    let walk = pinned("walk", line(1.0, Vec3::ZERO, Vec3::new(1.0, 0.0, 0.5)));
    let run = pinned("run", line(0.6, Vec3::ZERO, Vec3::new(0.3, 0.0, 1.5)));
    let params = StreamParams::new(Arc::clone(&walk), StreamRequest { fps: 30, ..Default::default() }).unwrap();
    let fade = |to: &Arc<dyn PinnedClip>| {
        Control::Crossfade(Crossfade { to: alone(to), duration: 0.3, ease: anim::Ease::Linear, source: None })
    };
    let aim = anim::ik::IkConstraint::Aim(anim::ik::Aim::new(1, glam::Vec3A::new(0.0, 1.0, 1.0)));
    let schedule = [
        (10, Control::Layer { index: 0, weight: 0.5, duration: 0.2 }),
        (30, fade(&run)),
        (50, Control::SetIk(vec![aim])),
        (70, fade(&walk)),
    ];
    let mut log = ControlLog::default();
    for (seq, control) in schedule {
        log.insert(StampedControl { seq, id: new_control_id(), control });
    }
    let document = |p: &Program| Arc::clone(&p.reach().layout(&params, 1e-4, None).unwrap().document);
    let mut reference = Program::new(&params).checkpointing(EVERY);
    let mut docs = Vec::new();
    let mut texts = Vec::new();
    for k in 0..100 {
        reference.step_to(k, &log);
        docs.push(document(&reference));
        if (k + 1) % EVERY == 0 {
            texts.push(reference.checkpoint().unwrap().to_text());
        }
    }
    let changes: Vec<u64> = (1..100).filter(|&k| docs[k] != docs[k - 1]).map(|k| k as u64).collect();
    assert_eq!(changes, [10, 30, 50, 70], "a new layout at each control that widens it, none else");
    let ik_doc: serde_json::Value = serde_json::from_str(&docs[50]).unwrap();
    assert!(ik_doc["joints"][1]["rotation"]["smallest_three"]["largest"].is_null(), "the aimed joint is free");
    for (i, text) in texts.iter().enumerate() {
        let c = (i as u64 + 1) * EVERY - 1;
        let checkpoint = Checkpoint::from_text(text).unwrap();
        let mut restored = Program::from_checkpoint(&params, &checkpoint, &log).unwrap();
        for k in c + 1..100 {
            restored.step_to(k, &log);
            assert_eq!(document(&restored), docs[k as usize], "tick {k} from the checkpoint of {c}");
        }
        // Its played motions are named, so the store keeps their controls.
        if c >= 30 {
            assert!(checkpoint.controls().contains(&log.at(30)[0].id.to_string()), "tick {c}");
        }
    }
}
