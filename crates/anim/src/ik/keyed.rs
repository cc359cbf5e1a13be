//! IK keyed in a clip (docs/ik.md, “Keyed targets in clips”): constraints whose targets
//! and weights are keyed tracks, solved at every sample after the joint
//! tracks, so an animator keys a foot's path and the computer solves the
//! leg.
//!
//! [`KeyedIk::build`] compiles each target and weight track as a
//! translation curve would be (the same rules, errors and ends) and
//! validates the constraints once; [`KeyedIk::solve`] evaluates the curves
//! at the clip time into a [`KeyedIkState`] the caller's cursor owns, then
//! solves. Clip IK always starts cold: a clip's pose is a function of time.

use std::sync::atomic::{AtomicU64, Ordering};

use super::constraint::{IkConstraint, IkLimits};
use super::error::{IkError, IkErrorKind};
use super::spec::{IkSpec, build_constraints};
use super::{ChainStart, IkReport, IkSolver};
use crate::arc::Meter;
use crate::compile::{self, Compiled};
use crate::curve::Vec3Curve;
use crate::error::{ClipError, ClipErrorKind};
use crate::spec::{IkTarget, KeyedIkSpec, Keys, TrackSpec};
use crate::timeline::Timeline;
use crate::{Path, Pose, Skeleton};

/// What a keyed curve drives.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    Target(usize),
    Weight,
}

#[derive(Debug, Clone, PartialEq)]
struct KeyedCurve {
    constraint: usize,
    slot: Slot,
    timeline: Timeline,
    curve: Vec3Curve,
}

/// A clip's compiled IK: the constraints (targets still to be filled) and
/// the curves that fill them.
#[derive(Debug, Clone)]
pub(crate) struct KeyedIk {
    /// Tells a cursor's state which clip's constraints it holds.
    id: u64,
    constraints: Vec<IkConstraint>,
    curves: Vec<KeyedCurve>,
}

/// Two builds of the same document are equal, whatever their ids.
impl PartialEq for KeyedIk {
    fn eq(&self, other: &Self) -> bool {
        self.constraints == other.constraints && self.curves == other.curves
    }
}

/// A sampler's working copy of a clip's constraints, the solver's buffers
/// and the last sample's reports.
#[derive(Debug, Clone, Default)]
pub struct KeyedIkState {
    owner: u64,
    constraints: Vec<IkConstraint>,
    hints: Vec<u32>,
    solver: IkSolver,
    reports: Vec<IkReport>,
}

impl KeyedIkState {
    /// One report per constraint of the clip last sampled.
    pub fn reports(&self) -> &[IkReport] {
        &self.reports
    }

    /// The last sample was of a clip without constraints.
    pub(crate) fn forget_reports(&mut self) {
        self.reports.clear();
    }
}

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// A compiled list and the clip-time range its keys cover (`None`: all fixed).
type Built = (KeyedIk, Option<(f32, f32)>);

impl KeyedIk {
    /// Compiles `specs` against `skeleton`; returns `None` for an empty
    /// list, else the IK and the time range its tracks cover.
    ///
    /// # Errors
    /// The first rule broken, at its path under `ik`.
    pub(crate) fn build(
        specs: &[KeyedIkSpec],
        skeleton: &Skeleton,
        limits: &IkLimits,
        meter: &mut Meter<'_>,
    ) -> Result<Option<Built>, ClipError> {
        if specs.is_empty() {
            return Ok(None);
        }
        let base = Path::root().field("ik");
        let mut plain = Vec::with_capacity(specs.len());
        for (i, spec) in specs.iter().enumerate() {
            let expected = spec.constraint.target_count();
            if spec.targets.len() != expected {
                let kind = ClipErrorKind::LengthMismatch { expected, provided: spec.targets.len() };
                return Err(ClipError::new(base.clone().index(i).field("targets"), kind));
            }
            let mut constraint = spec.constraint.clone();
            for (slot, target) in spec.targets.iter().enumerate() {
                if let IkTarget::Fixed(point) = target {
                    constraint.set_target(slot, *point);
                }
            }
            plain.push(constraint);
        }
        let constraints = build_constraints(&plain, skeleton, limits).map_err(|e| clip_error(e, &base))?;
        let (mut curves, mut domain) = (Vec::new(), (f32::INFINITY, f32::NEG_INFINITY));
        for (i, spec) in specs.iter().enumerate() {
            let at = base.clone().index(i);
            for (slot, target) in spec.targets.iter().enumerate() {
                let IkTarget::Keyed(track) = target else { continue };
                let path = target_path(&spec.constraint, at.clone(), slot);
                curves.push(keyed_curve(i, Slot::Target(slot), track, &path, meter, &mut domain)?);
            }
            if let Some(track) = &spec.weight {
                let path = at.field("weight");
                check_weights(track, &path)?;
                curves.push(keyed_curve(i, Slot::Weight, track, &path, meter, &mut domain)?);
            }
        }
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        let domain = (domain.0 <= domain.1).then_some(domain);
        Ok(Some((KeyedIk { id, constraints, curves }, domain)))
    }

    pub(crate) fn len(&self) -> usize {
        self.constraints.len()
    }

    /// The constraints as built (keyed targets still unset): what a solve
    /// walks and iterates, for pricing it before it runs.
    pub(crate) fn constraints(&self) -> &[IkConstraint] {
        &self.constraints
    }

    /// Bytes held on the heap (curves, timelines, constraint lists), roughly.
    pub(crate) fn heap_bytes(&self) -> usize {
        let curve = |c: &KeyedCurve| {
            c.timeline.heap_bytes()
                + match &c.curve {
                    Vec3Curve::Constant(_) => 0,
                    Vec3Curve::Step(k) | Vec3Curve::Linear(k) => std::mem::size_of_val(&**k),
                    Vec3Curve::Bezier(s) => std::mem::size_of_val(&**s),
                    Vec3Curve::ConstantSpeed { segments, pieces } => {
                        std::mem::size_of_val(&**segments) + std::mem::size_of_val(&**pieces)
                    }
                }
        };
        crate::heap::vec_bytes(&self.constraints)
            + crate::heap::vec_bytes(&self.curves)
            + self.curves.iter().map(curve).sum::<usize>()
    }

    /// Fills the constraints' targets and weights at clip time `t` and
    /// solves them on `pose` (this clip's local pose).
    pub(crate) fn solve(&self, t: f32, skeleton: &Skeleton, state: &mut KeyedIkState, pose: &mut Pose) {
        if state.owner != self.id {
            state.owner = self.id;
            state.constraints.clone_from(&self.constraints);
            state.hints.clear();
            state.hints.resize(self.curves.len(), 0);
        }
        for (curve, hint) in self.curves.iter().zip(&mut state.hints) {
            let value = curve.curve.at(curve.timeline.locate(t, hint));
            let constraint = &mut state.constraints[curve.constraint];
            match curve.slot {
                Slot::Target(slot) => constraint.set_target(slot, value),
                // A smooth weight curve may overshoot its keys.
                Slot::Weight => constraint.set_weight(value.x.clamp(0.0, 1.0)),
            }
        }
        state.solver.solve(skeleton, pose, &state.constraints, ChainStart::Cold, &mut state.reports);
    }
}

/// Where target `slot` of `constraint` sits in the document.
fn target_path(constraint: &IkSpec, at: Path, slot: usize) -> Path {
    match constraint {
        IkSpec::Chain(_) => at.field("effectors").index(slot).field("target"),
        _ => at.field("target"),
    }
}

fn clip_error(e: IkError, base: &Path) -> ClipError {
    let e = e.under(base.clone());
    ClipError::new(e.path, ClipErrorKind::Ik(e.kind))
}

/// Compiles one keyed track (its rules and errors are a translation
/// track's) and widens `domain` by its keys.
fn keyed_curve(
    constraint: usize,
    slot: Slot,
    track: &TrackSpec,
    path: &Path,
    meter: &mut Meter<'_>,
    domain: &mut (f32, f32),
) -> Result<KeyedCurve, ClipError> {
    let Compiled { times, curve, domain: (start, end) } = compile::vec3_track(track, path, meter)?;
    *domain = (domain.0.min(start), domain.1.max(end));
    Ok(KeyedCurve { constraint, slot, timeline: Timeline::new(&times), curve })
}

/// Weight keys lie in [0, 1].
fn check_weights(track: &TrackSpec, path: &Path) -> Result<(), ClipError> {
    let Keys::Vec3(values) = &track.values else { return Ok(()) };
    match values.iter().position(|w| !(0.0..=1.0).contains(&w.x)) {
        Some(k) => {
            let kind = ClipErrorKind::Ik(IkErrorKind::WeightOutOfRange { weight: values[k].x });
            Err(ClipError::new(path.clone().field("values").index(k), kind))
        }
        None => Ok(()),
    }
}
