//! IK constraints in JSON (docs/ik.md): one object per constraint with its
//! `kind`, parsed strictly into the core's [`IkSpec`] (requests, stream
//! controls) or [`KeyedIkSpec`] (clips, whose targets and weights may be
//! keyed tracks), with the JSON pointer of any field at fault; and the
//! `{kind, residual, iterations, converged}` reports poses carry.

use std::collections::BTreeMap;
use std::fmt;

use bytes::BufMut;
use glam::Vec3;
use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use super::doc::{DocError, EndsDoc, InterpolationDoc, SpeedDoc, keys_doc};
use super::float::write_float;
use anim::ik::{AimSpec, ChainSpec, EffectorSpec, IkReport, IkSpec, LimitSpec, TwoBoneSpec};
use anim::{Channel, IkTarget, KeyedIkSpec, Keys, TrackSpec};

/// One constraint. Which fields apply depends on `kind` (`docs/ik.md`):
/// `two_bone` {joints: [upper, middle, end], target, pole?, weight?};
/// `aim` {joint, target, forward?, up?, up_direction?, weight?};
/// `chain` {effectors, joints?, limits?, max_iterations?, tolerance?, weight?}.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct IkDoc {
    pub kind: IkKindDoc,
    /// `two_bone`: `[upper, middle, end]`, each a descendant of the one
    /// before. `chain`: the movable joints (default: every ancestor of an
    /// effector, and the effector itself when its tip is not the origin).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints: Option<Vec<String>>,
    /// `aim`: the joint that turns.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<String>,
    /// `two_bone`, `aim`: a model-space point; in a clip, a keyed track of points too.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<TargetDoc>,
    /// `two_bone`: a model-space point the middle joint bends toward.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub pole: Option<[f32; 3]>,
    /// `aim`: the joint-local axis that points at the target (default `[0, 0, 1]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub forward: Option<[f32; 3]>,
    /// `aim`: a joint-local axis whose roll `up_direction` fixes (both or neither).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub up: Option<[f32; 3]>,
    /// `aim`: a model-space direction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub up_direction: Option<[f32; 3]>,
    /// `chain`: the points that should reach their targets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effectors: Option<Vec<EffectorDoc>>,
    /// `chain`: per joint, bounds of its three angles (`Rx`, `Ry`, `Rz`) in radians.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<BTreeMap<String, LimitDoc>>,
    /// `chain`: the iteration budget (default 100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<u32>,
    /// `chain`: stop when `√E` is at most this (default `1e-4` × the chain's length).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f32>,
    /// In [0, 1] (default 1): the solved rotations are slerped from the
    /// unsolved ones by it. In a clip, a keyed track of `[w]` too.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight: Option<WeightDoc>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum IkKindDoc {
    TwoBone,
    Aim,
    Chain,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EffectorDoc {
    pub joint: String,
    pub target: TargetDoc,
    /// The bone tip in the joint's local frame (default the origin).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub tip: Option<[f32; 3]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LimitDoc {
    #[schema(min_items = 3, max_items = 3)]
    pub min: [f32; 3],
    #[schema(min_items = 3, max_items = 3)]
    pub max: [f32; 3],
}

keys_doc!(
    /// Keys of a target or weight, as a joint track's (`docs/clip-format.md`),
    /// without its joint and channel: targets have 3-number values, weights
    /// 1-number ones.
    KeysDoc {}
);

/// A point `[x, y, z]`, or (in clips) keys of points.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
#[serde(untagged)]
pub enum TargetDoc {
    #[schema(value_type = Vec<f32>)]
    Point([f32; 3]),
    Keys(KeysDoc),
}

/// A number in [0, 1], or (in clips) keys of `[w]`.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
#[serde(untagged)]
pub enum WeightDoc {
    Fixed(f32),
    Keys(KeysDoc),
}

/// Reads an array as the fixed form and an object as keys, so an error
/// inside either keeps its exact JSON pointer (an untagged enum would say
/// only that nothing matched).
struct FixedOrKeys<F>(std::marker::PhantomData<F>, &'static str);

impl<'de, F: Deserialize<'de>> Visitor<'de> for FixedOrKeys<F> {
    type Value = Result<F, KeysDoc>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(self.1)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        F::deserialize(SeqAccessDeserializer::new(seq)).map(Ok)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        KeysDoc::deserialize(MapAccessDeserializer::new(map)).map(Err)
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
        F::deserialize(de::value::F64Deserializer::new(v)).map(Ok)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
        F::deserialize(de::value::U64Deserializer::new(v)).map(Ok)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
        F::deserialize(de::value::I64Deserializer::new(v)).map(Ok)
    }
}

impl<'de> Deserialize<'de> for TargetDoc {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let visitor = FixedOrKeys::<[f32; 3]>(std::marker::PhantomData, "a point [x, y, z] or keys {times, values}");
        Ok(d.deserialize_any(visitor)?.map_or_else(TargetDoc::Keys, TargetDoc::Point))
    }
}

impl<'de> Deserialize<'de> for WeightDoc {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let visitor = FixedOrKeys::<f32>(std::marker::PhantomData, "a number in [0, 1] or keys {times, values}");
        Ok(d.deserialize_any(visitor)?.map_or_else(WeightDoc::Keys, WeightDoc::Fixed))
    }
}

impl IkDoc {
    /// A request's or stream control's constraint; `pointer` is its place
    /// in the body (`/motion/ik/0`).
    ///
    /// # Errors
    /// A field the kind needs missing, one it does not take, or a keyed
    /// target or weight (those belong in clips).
    pub fn to_spec(&self, pointer: &str) -> Result<IkSpec, DocError> {
        self.shape(pointer)?;
        let point = |t: &TargetDoc, at: String| match t {
            TargetDoc::Point(p) => Ok(Vec3::from(*p)),
            TargetDoc::Keys(_) => Err(keyed_in_request(at)),
        };
        let weight = match &self.weight {
            None => None,
            Some(WeightDoc::Fixed(w)) => Some(*w),
            Some(WeightDoc::Keys(_)) => return Err(keyed_in_request(format!("{pointer}/weight"))),
        };
        let mut spec = self.untargeted(weight);
        for (slot, (target, at)) in self.targets(pointer).into_iter().enumerate() {
            spec.set_target(slot, point(target, at)?);
        }
        Ok(spec)
    }

    /// A clip's constraint, its targets and weight fixed or keyed;
    /// `pointer` is its place in the clip (`/ik/0`).
    ///
    /// # Errors
    /// As [`IkDoc::to_spec`] but for keys, and key rows of the wrong width.
    pub fn to_keyed_spec(&self, pointer: &str) -> Result<KeyedIkSpec, DocError> {
        self.shape(pointer)?;
        let (weight, keyed_weight) = match &self.weight {
            None => (None, None),
            Some(WeightDoc::Fixed(w)) => (Some(*w), None),
            Some(WeightDoc::Keys(k)) => (None, Some(k.to_track(1, &format!("{pointer}/weight"))?)),
        };
        let constraint = self.untargeted(weight);
        let targets = self
            .targets(pointer)
            .into_iter()
            .map(|(target, at)| match target {
                TargetDoc::Point(p) => Ok(IkTarget::Fixed(Vec3::from(*p))),
                TargetDoc::Keys(k) => k.to_track(3, &at).map(IkTarget::Keyed),
            })
            .collect::<Result<_, _>>()?;
        Ok(KeyedIkSpec { constraint, targets, weight: keyed_weight })
    }

    /// The document of a clip's constraint (`GET /v1/clips/{id}`).
    pub fn from_keyed_spec(spec: &KeyedIkSpec) -> IkDoc {
        let target = |t: &IkTarget| match t {
            IkTarget::Fixed(p) => TargetDoc::Point(p.to_array()),
            IkTarget::Keyed(track) => TargetDoc::Keys(KeysDoc::from_track(track, 3)),
        };
        let mut doc = IkDoc::from_spec(&spec.constraint);
        match &mut doc.effectors {
            Some(effectors) => {
                for (e, t) in effectors.iter_mut().zip(&spec.targets) {
                    e.target = target(t);
                }
            }
            None => doc.target = spec.targets.first().map(target),
        }
        if let Some(track) = &spec.weight {
            doc.weight = Some(WeightDoc::Keys(KeysDoc::from_track(track, 1)));
        }
        doc
    }

    /// The document of a constraint (`{kind, …}` with what it names).
    pub fn from_spec(spec: &IkSpec) -> IkDoc {
        let mut doc = IkDoc::empty(match spec {
            IkSpec::TwoBone(_) => IkKindDoc::TwoBone,
            IkSpec::Aim(_) => IkKindDoc::Aim,
            IkSpec::Chain(_) => IkKindDoc::Chain,
        });
        let fixed = |w: Option<f32>| w.map(WeightDoc::Fixed);
        match spec {
            IkSpec::TwoBone(c) => {
                doc.joints = Some(c.joints.to_vec());
                doc.target = Some(TargetDoc::Point(c.target.to_array()));
                doc.pole = c.pole.map(|v| v.to_array());
                doc.weight = fixed(c.weight);
            }
            IkSpec::Aim(c) => {
                doc.joint = Some(c.joint.clone());
                doc.target = Some(TargetDoc::Point(c.target.to_array()));
                (doc.forward, doc.up, doc.up_direction) =
                    (c.forward.map(|v| v.to_array()), c.up.map(|v| v.to_array()), c.up_direction.map(|v| v.to_array()));
                doc.weight = fixed(c.weight);
            }
            IkSpec::Chain(c) => {
                doc.effectors = Some(
                    c.effectors
                        .iter()
                        .map(|e| EffectorDoc {
                            joint: e.joint.clone(),
                            target: TargetDoc::Point(e.target.to_array()),
                            tip: e.tip.map(|v| v.to_array()),
                        })
                        .collect(),
                );
                doc.joints.clone_from(&c.joints);
                let limits = c.limits.iter().map(|l| (l.joint.clone(), LimitDoc { min: l.min, max: l.max }));
                doc.limits = (!c.limits.is_empty()).then(|| limits.collect());
                (doc.max_iterations, doc.tolerance, doc.weight) = (c.max_iterations, c.tolerance, fixed(c.weight));
            }
        }
        doc
    }

    /// A constraint of `kind` with no field set (each wire fills its own).
    pub fn empty(kind: IkKindDoc) -> IkDoc {
        IkDoc {
            kind,
            joints: None,
            joint: None,
            target: None,
            pole: None,
            forward: None,
            up: None,
            up_direction: None,
            effectors: None,
            limits: None,
            max_iterations: None,
            tolerance: None,
            weight: None,
        }
    }

    /// Each target of the constraint with its pointer, in slot order.
    fn targets(&self, pointer: &str) -> Vec<(&TargetDoc, String)> {
        match (&self.target, &self.effectors) {
            (Some(t), _) => vec![(t, format!("{pointer}/target"))],
            (None, Some(effectors)) => effectors
                .iter()
                .enumerate()
                .map(|(i, e)| (&e.target, format!("{pointer}/effectors/{i}/target")))
                .collect(),
            (None, None) => Vec::new(),
        }
    }

    /// The constraint with its targets at the origin (filled by the caller).
    fn untargeted(&self, weight: Option<f32>) -> IkSpec {
        let v = |a: Option<[f32; 3]>| a.map(Vec3::from);
        match self.kind {
            IkKindDoc::TwoBone => {
                let joints = self.joints.clone().unwrap_or_default();
                let joints: [String; 3] = joints.try_into().unwrap_or_default();
                IkSpec::TwoBone(TwoBoneSpec { joints, target: Vec3::ZERO, pole: v(self.pole), weight })
            }
            IkKindDoc::Aim => IkSpec::Aim(AimSpec {
                joint: self.joint.clone().unwrap_or_default(),
                target: Vec3::ZERO,
                forward: v(self.forward),
                up: v(self.up),
                up_direction: v(self.up_direction),
                weight,
            }),
            IkKindDoc::Chain => IkSpec::Chain(ChainSpec {
                effectors: (self.effectors.iter().flatten())
                    .map(|e| EffectorSpec { joint: e.joint.clone(), target: Vec3::ZERO, tip: v(e.tip) })
                    .collect(),
                joints: self.joints.clone(),
                limits: (self.limits.iter().flatten())
                    .map(|(joint, l)| LimitSpec { joint: joint.clone(), min: l.min, max: l.max })
                    .collect(),
                max_iterations: self.max_iterations,
                tolerance: self.tolerance,
                weight,
            }),
        }
    }

    /// Checks that the fields present are the ones `kind` takes.
    fn shape(&self, pointer: &str) -> Result<(), DocError> {
        let present = [
            ("joints", self.joints.is_some()),
            ("joint", self.joint.is_some()),
            ("target", self.target.is_some()),
            ("pole", self.pole.is_some()),
            ("forward", self.forward.is_some()),
            ("up", self.up.is_some()),
            ("up_direction", self.up_direction.is_some()),
            ("effectors", self.effectors.is_some()),
            ("limits", self.limits.is_some()),
            ("max_iterations", self.max_iterations.is_some()),
            ("tolerance", self.tolerance.is_some()),
        ];
        let (kind, required, allowed): (&str, &[&str], &[&str]) = match self.kind {
            IkKindDoc::TwoBone => ("two_bone", &["joints", "target"], &["pole"]),
            IkKindDoc::Aim => ("aim", &["joint", "target"], &["forward", "up", "up_direction"]),
            IkKindDoc::Chain => ("chain", &["effectors"], &["joints", "limits", "max_iterations", "tolerance"]),
        };
        for (field, here) in present {
            if here && !required.contains(&field) && !allowed.contains(&field) {
                let detail = format!("`{field}` does not apply to a {kind} constraint");
                return Err(DocError { code: "field_not_applicable", pointer: format!("{pointer}/{field}"), detail });
            }
            if !here && required.contains(&field) {
                let detail = format!("a {kind} constraint needs `{field}`");
                return Err(DocError { code: "missing_field", pointer: format!("{pointer}/{field}"), detail });
            }
        }
        if let (IkKindDoc::TwoBone, Some(joints)) = (self.kind, &self.joints)
            && joints.len() != 3
        {
            let detail = format!("two_bone joints are [upper, middle, end], got {} names", joints.len());
            return Err(DocError { code: "wrong_width", pointer: format!("{pointer}/joints"), detail });
        }
        Ok(())
    }
}

fn keyed_in_request(pointer: String) -> DocError {
    let detail = "keyed targets and weights belong in clips; a request's are fixed: a point [x, y, z], a number";
    DocError { code: "keys_not_allowed", pointer, detail: detail.into() }
}

impl KeysDoc {
    /// A translation-like track of rows of `width` numbers (a weight's
    /// single number becomes `[w, 0, 0]`).
    fn to_track(&self, width: usize, pointer: &str) -> Result<TrackSpec, DocError> {
        let rows = |rows: &[Vec<f32>], field: &str| -> Result<Keys, DocError> {
            if let Some((i, row)) = rows.iter().enumerate().find(|(_, r)| r.len() != width) {
                let detail = format!("a key here has {width} numbers, got {}", row.len());
                return Err(DocError { code: "wrong_width", pointer: format!("{pointer}/{field}/{i}"), detail });
            }
            let pad = |r: &Vec<f32>| if width == 1 { Vec3::new(r[0], 0.0, 0.0) } else { Vec3::from_slice(r) };
            Ok(Keys::Vec3(rows.iter().map(pad).collect()))
        };
        self.keys_to_track((String::new(), Channel::Translation), rows)
    }

    /// The keys of a target (3 numbers a row) or weight (`[w, 0, 0]` → `[w]`) track.
    fn from_track(track: &TrackSpec, width: usize) -> KeysDoc {
        let rows = |k: &Keys| -> Vec<Vec<f32>> {
            match k {
                Keys::Vec3(v) => v.iter().map(|x| x.to_array()[..width].to_vec()).collect(),
                Keys::Vec4(v) => v.iter().map(|x| x.to_array().to_vec()).collect(),
            }
        };
        KeysDoc::keys_of_track(track, rows)
    }
}

/// One solve's report in a pose (`docs/ik.md`, "Reports").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct IkReportDoc {
    pub kind: IkKindDoc,
    /// The end joint's distance to its target (`two_bone`), the aim angle
    /// in radians (`aim`), `√E` (`chain`).
    pub residual: f32,
    pub iterations: u32,
    pub converged: bool,
}

/// `,"ik":[{…},…]` when there are reports (the pose writer's fast path).
pub fn write_reports(out: &mut impl BufMut, reports: &[IkReport]) {
    if reports.is_empty() {
        return;
    }
    out.put_slice(b",\"ik\":[");
    for (i, r) in reports.iter().enumerate() {
        if i > 0 {
            out.put_u8(b',');
        }
        out.put_slice(b"{\"kind\":\"");
        out.put_slice(r.kind.name().as_bytes());
        out.put_slice(b"\",\"residual\":");
        write_float(out, r.residual);
        out.put_slice(b",\"iterations\":");
        write_u32(out, r.iterations);
        out.put_slice(if r.converged { b",\"converged\":true}" } else { b",\"converged\":false}" });
    }
    out.put_u8(b']');
}

fn write_u32(out: &mut impl BufMut, n: u32) {
    let mut digits = [0u8; 10];
    let (mut n, mut i) = (n, digits.len());
    loop {
        i -= 1;
        digits[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.put_slice(&digits[i..]);
}
