//! Parameters (docs/clip-format.md, “Parameters”): named keyed values that are not joints — morph
//! weights, a camera's field of view, a light's intensity.
//!
//! A parameter of width `W` is compiled as `⌈W/3⌉` translation-like curves
//! (components `3c..3c+3`, the last one padded with zeros), so it is checked by
//! the same rules, its control points computed by the same `f64` code, and it
//! samples through the same track lists as translations: per component exactly
//! as docs/clip-format.md, “Evaluation math”, at the same cost per three
//! numbers. The pose holds them as `Vec3A` entries ([`Pose::parameters`]);
//! [`ParameterLayout`] says which entries and lanes are whose.

use std::collections::HashMap;

use glam::{Vec3, Vec3A};

use super::arc::Meter;
use super::compile::{self, Compiled};
use super::error::{ClipError, ClipErrorKind as K};
use super::heap::vec_bytes;
use super::path::Path;
use super::skeleton::Pose;
use super::spec::{Channel, Keys, MAX_NAME_CHARS, ParameterSpec, TrackSpec};
use super::tracks::{Spans, Vec3Tracks};

/// The widest parameter key (glTF meshes rarely have more morph targets).
pub const MAX_PARAMETER_WIDTH: usize = 256;

/// Names, widths and places of a clip's parameters in [`Pose::parameters`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ParameterLayout {
    names: Vec<String>,
    widths: Vec<u32>,
    /// Per parameter, its first entry in the pose; one more at the end.
    first: Vec<u32>,
}

impl ParameterLayout {
    /// The number of parameters.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Their names, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Their widths (numbers per key), in order.
    pub fn widths(&self) -> &[u32] {
        &self.widths
    }

    /// The index of the parameter called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Entries of [`Pose::parameters`] a pose of this clip holds.
    pub fn entries(&self) -> usize {
        self.first.last().map_or(0, |&e| e as usize)
    }

    /// The entries of parameter `p`.
    ///
    /// # Panics
    /// If there is no parameter `p`.
    pub fn range(&self, p: usize) -> std::ops::Range<usize> {
        self.first[p] as usize..self.first[p + 1] as usize
    }

    /// The numbers of every parameter together.
    pub fn total_width(&self) -> usize {
        self.widths.iter().map(|&w| w as usize).sum()
    }

    /// Parameter `p`'s values in `pose`, component by component.
    pub fn values<'a>(&self, pose: &'a Pose, p: usize) -> impl Iterator<Item = f32> + 'a {
        let (first, width) = (self.first[p] as usize, self.widths[p] as usize);
        (0..width).map(move |c| pose.parameters[first + c / 3][c % 3])
    }

    pub(crate) fn heap_bytes(&self) -> usize {
        vec_bytes(&self.names)
            + self.names.iter().map(String::capacity).sum::<usize>()
            + vec_bytes(&self.widths)
            + vec_bytes(&self.first)
    }

    fn push(&mut self, name: &str, width: usize) {
        if self.first.is_empty() {
            self.first.push(0);
        }
        self.names.push(name.to_owned());
        self.widths.push(width as u32);
        let end = self.entries() + width.div_ceil(3);
        self.first.push(end as u32);
    }
}

/// A clip's compiled parameters: their layout and their curves (one per
/// entry that is not constant; constants live in the clip's base pose).
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Parameters {
    pub layout: ParameterLayout,
    tracks: Vec3Tracks,
}

/// What building the parameters adds to a clip's build.
pub(crate) struct Built {
    pub parameters: Parameters,
    /// The base values (constant entries filled, the rest 0).
    pub base: Vec<Vec3A>,
    /// The smallest first and largest last key, if there is any parameter.
    pub domain: Option<(f32, f32)>,
}

impl Parameters {
    /// Checks and compiles `specs` (paths `/parameters/i/...`), interning
    /// their key times with `intern`.
    ///
    /// # Errors
    /// The first rule a parameter breaks, at its path under `parameters`.
    pub fn build(
        specs: &[ParameterSpec],
        meter: &mut Meter<'_>,
        mut intern: impl FnMut(Vec<f32>) -> u32,
    ) -> Result<Built, ClipError> {
        let mut layout = ParameterLayout::default();
        let mut seen: HashMap<&str, ()> = HashMap::with_capacity(specs.len());
        let mut tracks = Vec3Tracks::default();
        let mut base = Vec::new();
        let mut domain: Option<(f32, f32)> = None;
        for (p, spec) in specs.iter().enumerate() {
            let path = Path::root().field("parameters").index(p);
            let width = check(spec, &path)?;
            if seen.insert(spec.name.as_str(), ()).is_some() {
                let kind = K::DuplicateParameter { name: spec.name.clone() };
                return Err(ClipError::new(path.field("name"), kind));
            }
            let entry = layout.entries();
            layout.push(&spec.name, width);
            base.resize(layout.entries(), Vec3A::ZERO);
            for c in 0..width.div_ceil(3) {
                let track = chunk(spec, c);
                let Compiled { times, curve, domain: (first, last) } = compile::vec3_track(&track, &path, meter)?;
                tracks.push((entry + c) as u32, intern(times), curve, &mut base[entry + c]);
                domain = Some(domain.map_or((first, last), |(a, b)| (a.min(first), b.max(last))));
            }
        }
        Ok(Built { parameters: Parameters { layout, tracks }, base, domain })
    }

    pub fn heap_bytes(&self) -> usize {
        self.layout.heap_bytes() + self.tracks.heap_bytes()
    }

    /// Evaluates every curve at its timeline's span into `out` (the pose's
    /// parameter entries, already holding the base values).
    #[inline]
    pub fn apply(&self, spans: &mut impl Spans, out: &mut [Vec3A]) {
        self.tracks.apply(spans, out);
    }
}

/// The rules only parameters have (name, widths, finite numbers per
/// component); the rest — times, tangents' presence, ends, tension — are
/// the translation tracks' own, checked when the chunks compile. Returns
/// the width.
fn check(spec: &ParameterSpec, path: &Path) -> Result<usize, ClipError> {
    let chars = spec.name.chars().count();
    if chars == 0 || chars > MAX_NAME_CHARS {
        return Err(ClipError::new(path.clone().field("name"), K::BadParameterName { max: MAX_NAME_CHARS }));
    }
    if spec.times.is_empty() {
        return Err(ClipError::new(path.clone().field("times"), K::NoKeys));
    }
    if spec.values.len() != spec.times.len() {
        let kind = K::LengthMismatch { expected: spec.times.len(), provided: spec.values.len() };
        return Err(ClipError::new(path.clone().field("values"), kind));
    }
    let width = spec.values[0].len();
    if width == 0 || width > MAX_PARAMETER_WIDTH {
        let kind = K::ParameterWidth { max: MAX_PARAMETER_WIDTH, provided: width };
        return Err(ClipError::new(path.clone().field("values").index(0), kind));
    }
    rows(&spec.values, width, &path.clone().field("values"))?;
    for (field, tangents) in [("in_tangents", &spec.in_tangents), ("out_tangents", &spec.out_tangents)] {
        if let Some(t) = tangents {
            rows(t, width, &path.clone().field(field))?;
        }
    }
    Ok(width)
}

/// Every row `width` wide and every number finite.
fn rows(rows: &[Vec<f32>], width: usize, path: &Path) -> Result<(), ClipError> {
    for (i, row) in rows.iter().enumerate() {
        if row.len() != width {
            let kind = K::WrongWidth { channel: "parameter", expected: width, provided: row.len() };
            return Err(ClipError::new(path.clone().index(i), kind));
        }
        if let Some(c) = row.iter().position(|x| !x.is_finite()) {
            return Err(ClipError::new(path.clone().index(i).index(c), K::NonFinite));
        }
    }
    Ok(())
}

/// Components `3c..3c+3` of `spec` as a translation track (zeros past the
/// width), with the parameter's times, mode, ends and tension.
fn chunk(spec: &ParameterSpec, c: usize) -> TrackSpec {
    let take = |rows: &[Vec<f32>]| -> Keys {
        Keys::Vec3(
            rows.iter()
                .map(|r| {
                    let at = |k: usize| r.get(3 * c + k).copied().unwrap_or(0.0);
                    Vec3::new(at(0), at(1), at(2))
                })
                .collect(),
        )
    };
    let mut track =
        TrackSpec::new(&spec.name, Channel::Translation, spec.interpolation, spec.times.clone(), take(&spec.values));
    track.in_tangents = spec.in_tangents.as_deref().map(take);
    track.out_tangents = spec.out_tangents.as_deref().map(take);
    track.ends = spec.ends;
    track.tension = spec.tension;
    track
}
