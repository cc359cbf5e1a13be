//! Random keys and clips for the accuracy and property tests.
//!
//! A small deterministic generator (SplitMix64) rather than a crate: the
//! accuracy sweep must be reproducible run to run so that its measured
//! worst errors mean something, and it needs nothing proptest's shrinking
//! offers. Property tests build on the same helpers from proptest seeds.

use anim::{Channel, ClipSpec, Ends, Interpolation, JointSpec, Keys, Playback, SkeletonSpec, Speed};
use anim::{TrackSpec, Transform};
use glam::{Quat, Vec3, Vec4};

pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    pub fn vec3(&mut self, r: f64) -> Vec3 {
        Vec3::new(self.range(-r, r) as f32, self.range(-r, r) as f32, self.range(-r, r) as f32)
    }

    /// A uniformly random unit axis.
    pub fn axis(&mut self) -> Vec3 {
        loop {
            let v = self.vec3(1.0);
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

/// `n` strictly increasing key times, non-uniform (gaps in `[0.15, 1]`) or
/// uniform (to exercise the computed-index search) at random.
pub fn times(rng: &mut Rng, n: usize) -> Vec<f32> {
    let mut t = rng.range(-1.0, 1.0) as f32;
    let uniform = rng.chance(0.25);
    let h = rng.range(0.15, 1.0) as f32;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(t);
        t += if uniform { h } else { rng.range(0.15, 1.0) as f32 };
    }
    out
}

/// A random walk of rotations: each key turns the last by up to
/// `max_deg` degrees about a random axis. Keys are then given a random
/// sign and a random norm in `[0.5, 2]`, which the core must undo.
pub fn quats(rng: &mut Rng, n: usize, max_deg: f64) -> Vec<Vec4> {
    let mut q = Quat::from_axis_angle(rng.axis(), rng.range(0.0, std::f64::consts::TAU) as f32);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let sign = if rng.chance(0.3) { -1.0 } else { 1.0 };
        out.push(Vec4::from(q) * (sign * rng.range(0.5, 2.0) as f32));
        let step = Quat::from_axis_angle(rng.axis(), rng.range(0.0, max_deg).to_radians() as f32);
        q = (step * q).normalize();
    }
    out
}

/// What kind of track to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kind {
    pub channel: Channel,
    pub interpolation: Interpolation,
    pub ends: Option<Ends>,
    pub speed: Speed,
    /// Largest rotation between consecutive rotation keys, in degrees.
    pub max_deg: f64,
}

impl Kind {
    pub fn new(channel: Channel, interpolation: Interpolation) -> Self {
        Kind { channel, interpolation, ends: None, speed: Speed::Keyed, max_deg: 90.0 }
    }

    pub fn ends(self, ends: Ends) -> Self {
        Kind { ends: Some(ends), ..self }
    }

    pub fn constant_speed(self) -> Self {
        Kind { speed: Speed::Constant, ..self }
    }

    pub fn max_deg(self, max_deg: f64) -> Self {
        Kind { max_deg, ..self }
    }

    pub fn label(&self) -> String {
        let mut s = format!("{} {}", self.channel.as_str(), self.interpolation.as_str());
        if let Some(e) = self.ends {
            s += &format!(" {}", e.as_str());
        }
        if self.speed == Speed::Constant {
            s += " constant-speed";
        }
        if self.channel == Channel::Rotation {
            s += &format!(" (≤{}°/key)", self.max_deg);
        }
        s
    }
}

/// A random valid track of `kind` with `n` keys (`n >= 4` for phantom ends).
pub fn track(rng: &mut Rng, joint: &str, kind: Kind, n: usize) -> TrackSpec {
    let times = times(rng, n);
    let rotation = kind.channel == Channel::Rotation;
    let mut values = if rotation {
        Keys::Vec4(quats(rng, n, kind.max_deg))
    } else if kind.channel == Channel::Scale {
        Keys::Vec3((0..n).map(|_| rng.vec3(0.5) + Vec3::ONE).collect())
    } else {
        Keys::Vec3((0..n).map(|_| rng.vec3(2.0)).collect())
    };
    if kind.ends == Some(Ends::Wrap) {
        match &mut values {
            Keys::Vec3(v) => v[n - 1] = v[0],
            // The same rotation, possibly the other sign and another norm.
            Keys::Vec4(v) => v[n - 1] = v[0] * if rng.chance(0.5) { -1.5 } else { 0.75 },
        }
    }
    let mut spec = TrackSpec::new(joint, kind.channel, kind.interpolation, times, values);
    if kind.interpolation == Interpolation::BSpline {
        spec.ends = kind.ends;
    }
    if kind.interpolation == Interpolation::CatmullRom {
        spec.ends = kind.ends;
        if rng.chance(0.5) {
            spec.tension = Some(rng.range(0.0, 1.0) as f32);
        }
    }
    if kind.interpolation == Interpolation::CubicHermite {
        let tangents = |rng: &mut Rng| {
            if rotation {
                Keys::Vec4((0..n).map(|_| Vec4::from((rng.vec3(0.6), rng.range(-0.6, 0.6) as f32))).collect())
            } else {
                Keys::Vec3((0..n).map(|_| rng.vec3(2.0)).collect())
            }
        };
        spec.in_tangents = Some(tangents(rng));
        spec.out_tangents = Some(tangents(rng));
    }
    spec.speed = kind.speed;
    spec
}

/// A clip with a single joint and one track.
pub fn one_track_clip(track: TrackSpec) -> ClipSpec {
    ClipSpec {
        name: "t".into(),
        skeleton: None,
        tracks: vec![track],
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    }
}

/// A random hierarchy of `joints` joints (each parent earlier), random
/// rests with uniform scales, and a random track of a random kind on
/// about half of the channels.
pub fn skeleton_clip(rng: &mut Rng, joints: usize) -> ClipSpec {
    let mut skel = SkeletonSpec::default();
    let mut tracks = Vec::new();
    for j in 0..joints {
        let name = format!("j{j}");
        let parent = (j > 0 && rng.chance(0.85)).then(|| format!("j{}", rng.below(j)));
        let rest = Transform {
            translation: rng.vec3(1.0),
            rotation: Quat::from_axis_angle(rng.axis(), rng.range(0.0, 3.0) as f32),
            scale: Vec3::splat(rng.range(0.5, 1.5) as f32),
        };
        skel.joints.push(JointSpec { name: name.clone(), parent, rest, inverse_bind: None });
        for channel in Channel::ALL {
            if rng.chance(0.5) {
                continue;
            }
            let interpolation =
                [Interpolation::Step, Interpolation::Linear, Interpolation::CatmullRom, Interpolation::CubicHermite]
                    [rng.below(4)];
            let kind = Kind::new(channel, interpolation);
            let n = 1 + rng.below(6);
            let mut track = track(rng, &name, kind, n);
            if channel == Channel::Scale {
                // Uniform scales keep the composition of docs/clip-format.md, 2.8, exact.
                if let Keys::Vec3(v) = &mut track.values {
                    v.iter_mut().for_each(|s| *s = Vec3::splat(s.x));
                }
                if let Some(Keys::Vec3(v)) = &mut track.in_tangents {
                    v.iter_mut().for_each(|s| *s = Vec3::splat(s.x));
                }
                if let Some(Keys::Vec3(v)) = &mut track.out_tangents {
                    v.iter_mut().for_each(|s| *s = Vec3::splat(s.x));
                }
            }
            tracks.push(track);
        }
    }
    if tracks.is_empty() {
        tracks.push(track(rng, "j0", Kind::new(Channel::Translation, Interpolation::Linear), 3));
    }
    let playback = [Playback::Once, Playback::Loop, Playback::PingPong][rng.below(3)];
    ClipSpec { name: "random".into(), skeleton: Some(skel), tracks, events: vec![], playback, ..Default::default() }
}
