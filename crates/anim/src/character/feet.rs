//! Planted feet: a retargeted foot that stays still while its source foot
//! is in contact.
//!
//! A retarget copies rotations, so on a rig of other proportions a foot the
//! take holds still slides. Per foot, the source foot is *in contact* when
//! its model height (`+Y`) above its lowest in the clip, times `k`, is
//! within `contact_height`, and its speed times `k` is below `contact_speed`
//! (both in the target's units; speed is known from the second frame of a
//! run). When contact begins, the target foot's model position is its
//! anchor; while contact lasts, a two-bone solve (docs/ik.md, `two_bone`) of
//! that leg (upper leg, lower leg, foot) puts the foot back on the anchor,
//! and the report says how far it still is (the remaining slide: 0 unless
//! the anchor is out of the leg's reach).

use glam::Vec3A;

use super::map::RoleMap;
use super::retarget::Retargeter;
use super::roles::{Role, Side};
use crate::ik::{ChainStart, IkConstraint, IkReport, IkSolver, TwoBone};
use crate::{Clip, Cursor, Pose, Skeleton};

/// Contact thresholds, in the target's units (metres for glTF).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeetOptions {
    /// Height above the foot's lowest, scaled by `k` (default 2 cm).
    pub contact_height: f32,
    /// Speed, scaled by `k` (default 0.1 per second).
    pub contact_speed: f32,
}

impl Default for FeetOptions {
    fn default() -> Self {
        FeetOptions { contact_height: 0.02, contact_speed: 0.1 }
    }
}

/// One foot's state after a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FootReport {
    pub side: Side,
    /// Whether the source foot is in contact, so the foot was planted.
    pub planted: bool,
    /// The planted foot's distance from its anchor after the solve.
    pub slide: f32,
}

/// One leg both rigs map.
#[derive(Debug, Clone)]
struct Foot {
    side: Side,
    source: usize,
    /// Target upper leg, lower leg, foot.
    joints: [usize; 3],
    /// The source foot's lowest model height in the clip.
    lowest: f32,
    last: Option<Vec3A>,
    anchor: Option<Vec3A>,
}

/// Keeps a stream's retargeted feet planted, frame after frame.
#[derive(Debug, Clone)]
pub struct FootPlanter {
    feet: Vec<Foot>,
    options: FeetOptions,
    solver: IkSolver,
    constraints: Vec<IkConstraint>,
    solves: Vec<IkReport>,
    reports: Vec<FootReport>,
}

/// Each source foot's lowest model height over `clip`, sampled 60 times a
/// second (at most 4096 samples) and at both ends; `f32::INFINITY` for a
/// foot the roles lack.
pub fn lowest_feet(clip: &Clip, roles: &RoleMap) -> [f32; 2] {
    let feet = [Role::LeftFoot, Role::RightFoot].map(|r| roles.joint(r));
    let samples = ((clip.duration() * 60.0).ceil() as usize).clamp(1, 4096);
    let (mut cursor, mut local, mut model) = (Cursor::default(), Pose::default(), Pose::default());
    let mut lowest = [f32::INFINITY; 2];
    for k in 0..=samples {
        clip.sample_into(clip.start() + clip.duration() * k as f32 / samples as f32, &mut cursor, &mut local);
        clip.skeleton().to_model(&local, &mut model);
        for (low, foot) in lowest.iter_mut().zip(feet) {
            if let Some(f) = foot {
                *low = low.min(model.translations[f].y);
            }
        }
    }
    lowest
}

impl FootPlanter {
    /// A planter for the legs both maps have (foot on the source; upper
    /// leg, lower leg and foot on the target); `lowest` as [`lowest_feet`]
    /// gives it, left then right.
    pub fn new(source: &RoleMap, target: &RoleMap, lowest: [f32; 2], options: FeetOptions) -> FootPlanter {
        let feet = [Side::Left, Side::Right]
            .into_iter()
            .zip(lowest)
            .filter_map(|(side, lowest)| {
                let leg = [Role::LeftUpperLeg, Role::LeftLowerLeg, Role::LeftFoot].map(|r| target.joint(r.on(side)));
                let [Some(upper), Some(lower), Some(foot)] = leg else { return None };
                let source = source.joint(Role::LeftFoot.on(side))?;
                let joints = [upper, lower, foot];
                Some(Foot { side, source, joints, lowest, last: None, anchor: None })
            })
            .collect::<Vec<_>>();
        let n = feet.len();
        FootPlanter {
            feet,
            options,
            solver: IkSolver::new(),
            constraints: Vec::with_capacity(n),
            solves: Vec::with_capacity(n),
            reports: Vec::with_capacity(n),
        }
    }

    /// Bytes it holds: its record and, per foot, its leg, a constraint, a
    /// solve and a report.
    pub fn heap_bytes(&self) -> usize {
        let per_foot = size_of::<Foot>() + size_of::<IkConstraint>() + size_of::<IkReport>() + size_of::<FootReport>();
        size_of::<FootPlanter>() + self.feet.len() * per_foot
    }

    /// How many feet it plants (the legs both maps have), 0 to 2.
    pub fn feet(&self) -> usize {
        self.feet.len()
    }

    /// Each planted leg's target upper leg, lower leg and foot: the joints
    /// its two-bone solve turns.
    pub(crate) fn legs(&self) -> impl Iterator<Item = [usize; 3]> + '_ {
        self.feet.iter().map(|f| f.joints)
    }

    /// Forgets the last frame (after a seek): the next contact is new.
    pub fn reset(&mut self) {
        for foot in &mut self.feet {
            (foot.last, foot.anchor) = (None, None);
        }
    }

    /// Plants the feet of `target_local`, the pose `retargeter` just made,
    /// `dt` seconds after the previous frame (`None` for a first frame or
    /// a single pose: contact by height alone).
    pub fn plant(&mut self, retargeter: &Retargeter, dt: Option<f32>, target: &Skeleton, target_local: &mut Pose) {
        let (k, options) = (retargeter.k(), self.options);
        let (source_model, target_model) = (retargeter.source_model(), retargeter.target_model());
        self.constraints.clear();
        self.reports.clear();
        for foot in &mut self.feet {
            let now = source_model.translations[foot.source];
            let height = (now.y - foot.lowest) * k;
            let speed = match (foot.last, dt) {
                (Some(last), Some(dt)) if dt > 0.0 => Some(now.distance(last) / dt * k),
                _ => None,
            };
            foot.last = Some(now);
            let contact = height <= options.contact_height && speed.is_none_or(|s| s <= options.contact_speed);
            if !contact {
                foot.anchor = None;
                self.reports.push(FootReport { side: foot.side, planted: false, slide: 0.0 });
                continue;
            }
            let anchor = *foot.anchor.get_or_insert(target_model.translations[foot.joints[2]]);
            self.constraints.push(IkConstraint::TwoBone(TwoBone::new(foot.joints, anchor)));
            self.reports.push(FootReport { side: foot.side, planted: true, slide: 0.0 });
        }
        self.solver.solve(target, target_local, &self.constraints, ChainStart::Cold, &mut self.solves);
        let planted = self.reports.iter_mut().filter(|r| r.planted);
        for (report, solve) in planted.zip(&self.solves) {
            report.slide = solve.residual;
        }
    }

    /// One report per planted-capable foot (left first) for the last frame.
    pub fn reports(&self) -> &[FootReport] {
        &self.reports
    }
}
