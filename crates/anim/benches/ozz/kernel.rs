//! An ozz-animation-style sampling job, written here because the Rust port
//! (`ozz-animation-rs` 0.11) does not build on stable Rust: it turns on
//! glam's `core-simd` feature, which needs the nightly `portable_simd`
//! (error E0554, BENCHMARKS.md). It follows ozz's `SamplingJob`
//! (animation.cc, sampling_job.cc of ozz 0.14) in what costs time:
//!
//! - keys of all tracks of a channel in one stream, ordered so that forward
//!   playback consumes them in order: first the first two keys of every
//!   track, then each further key ordered by the time of the key it replaces;
//! - a per-context cache of each track's (left, right) key and a cursor into
//!   the stream: moving forward only advances the cursor; moving backwards
//!   (or a random seek) rewinds it to the start and replays, as ozz does;
//! - structure of arrays, 4 joints per SIMD lane group (`glam::Vec4` is an
//!   SSE register here), refreshed only for groups whose keys changed;
//! - linear interpolation of translations and scales and normalised lerp
//!   (nlerp) of rotations, with rotation keys flipped into one hemisphere at
//!   build time so nlerp needs no sign test.
//!
//! It does not decompress: ozz stores half floats and 3-component quantised
//! quaternions, which costs it a few instructions per key more than the plain
//! f32 keys here, so this kernel is, if anything, faster than ozz.

use glam::Vec4;

/// One key of a channel's stream.
#[derive(Clone, Copy)]
struct Key<const N: usize> {
    /// The time of the key this one replaces in its track (sort order).
    prev_time: f32,
    time: f32,
    track: u32,
    value: [f32; N],
}

/// One channel (translation, rotation or scale) of all joints.
struct Channel<const N: usize> {
    keys: Vec<Key<N>>,
    tracks: usize,
}

impl<const N: usize> Channel<N> {
    /// `tracks[j]` = (times, values) of joint j.
    fn new(tracks: &[(Vec<f32>, Vec<[f32; N]>)]) -> Self {
        let mut first = Vec::new();
        let mut rest = Vec::new();
        for (j, (times, values)) in tracks.iter().enumerate() {
            for k in 0..times.len() {
                let key = Key {
                    prev_time: if k == 0 { f32::MIN } else { times[k - 1] },
                    time: times[k],
                    track: j as u32,
                    value: values[k],
                };
                if k < 2 { first.push(key) } else { rest.push(key) }
            }
        }
        // ozz: the first two keys of each track (pushed in track order), then
        // every other key by the time of the key it replaces.
        rest.sort_by(|a, b| a.prev_time.total_cmp(&b.prev_time).then(a.track.cmp(&b.track)));
        first.extend(rest);
        Channel { keys: first, tracks: tracks.len() }
    }
}

/// What a sampling context keeps between calls for one channel.
struct Cursor<const N: usize> {
    /// Per track: indices of its left and right keys in the stream.
    entries: Vec<[u32; 2]>,
    cursor: usize,
    /// Per group of 4 tracks: keys changed since the SoA copy.
    outdated: Vec<bool>,
    /// Per group: SoA left/right times and values.
    soa_t: Vec<[Vec4; 2]>,
    soa_v: Vec<[[Vec4; N]; 2]>,
}

impl<const N: usize> Cursor<N> {
    fn new(ch: &Channel<N>) -> Self {
        let groups = ch.tracks.div_ceil(4);
        let mut c = Cursor {
            entries: vec![[0, 0]; ch.tracks],
            cursor: 0,
            outdated: vec![true; groups],
            soa_t: vec![[Vec4::ZERO; 2]; groups],
            soa_v: vec![[[Vec4::ZERO; N]; 2]; groups],
        };
        c.rewind(ch);
        c
    }

    fn rewind(&mut self, ch: &Channel<N>) {
        for j in 0..ch.tracks {
            self.entries[j] = [(2 * j) as u32, (2 * j + 1) as u32];
        }
        self.cursor = 2 * ch.tracks;
        self.outdated.fill(true);
    }

    /// ozz's `UpdateCacheCursor`: consume keys whose predecessor is now behind.
    fn advance(&mut self, ch: &Channel<N>, t: f32) {
        while self.cursor < ch.keys.len() {
            let key = &ch.keys[self.cursor];
            let track = key.track as usize;
            if ch.keys[self.entries[track][1] as usize].time > t {
                break;
            }
            self.entries[track] = [self.entries[track][1], self.cursor as u32];
            self.outdated[track / 4] = true;
            self.cursor += 1;
        }
    }

    /// ozz's `UpdateInterpKeyframes`: SoA copies of outdated groups.
    fn refresh(&mut self, ch: &Channel<N>) {
        for g in 0..self.outdated.len() {
            if !self.outdated[g] {
                continue;
            }
            self.outdated[g] = false;
            let mut t = [[0.0f32; 4]; 2];
            let mut v = [[[0.0f32; 4]; N]; 2];
            for lane in 0..4 {
                let j = (g * 4 + lane).min(ch.tracks - 1);
                for side in 0..2 {
                    let key = &ch.keys[self.entries[j][side] as usize];
                    t[side][lane] = key.time;
                    for (component, value) in v[side].iter_mut().zip(key.value) {
                        component[lane] = value;
                    }
                }
            }
            self.soa_t[g] = [Vec4::from(t[0]), Vec4::from(t[1])];
            self.soa_v[g] = v.map(|side| side.map(Vec4::from));
        }
    }

    /// Lerp of every group; `alpha` clamped to [0, 1] like ozz's.
    fn lerp(&self, g: usize, t: f32) -> [Vec4; N] {
        let [t0, t1] = self.soa_t[g];
        let alpha = ((Vec4::splat(t) - t0) / (t1 - t0)).clamp(Vec4::ZERO, Vec4::ONE);
        let [a, b] = &self.soa_v[g];
        std::array::from_fn(|c| a[c] + (b[c] - a[c]) * alpha)
    }
}

/// A SoA transform of 4 joints.
#[derive(Clone, Copy, Default)]
pub struct SoaTransform {
    pub translation: [Vec4; 3],
    pub rotation: [Vec4; 4],
    pub scale: [Vec4; 3],
}

/// The compiled animation.
pub struct Animation {
    translations: Channel<3>,
    rotations: Channel<4>,
    scales: Channel<3>,
}

/// A sampling context (ozz `SamplingJob::Context`).
pub struct Context {
    time: f32,
    t: Cursor<3>,
    r: Cursor<4>,
    s: Cursor<3>,
}

pub type Track<const N: usize> = (Vec<f32>, Vec<[f32; N]>);

impl Animation {
    /// One track per joint per channel, each with at least two keys.
    pub fn new(translations: &[Track<3>], rotations: &[Track<4>], scales: &[Track<3>]) -> Self {
        // ozz's optimiser keeps consecutive rotation keys in one hemisphere.
        let rotations: Vec<Track<4>> = rotations
            .iter()
            .map(|(times, values)| {
                let mut prev = [0.0, 0.0, 0.0, 1.0];
                let flipped = values
                    .iter()
                    .map(|q| {
                        let dot: f32 = (0..4).map(|i| q[i] * prev[i]).sum();
                        let q = if dot < 0.0 { q.map(|x| -x) } else { *q };
                        prev = q;
                        q
                    })
                    .collect();
                (times.clone(), flipped)
            })
            .collect();
        Animation {
            translations: Channel::new(translations),
            rotations: Channel::new(&rotations),
            scales: Channel::new(scales),
        }
    }

    pub fn context(&self) -> Context {
        Context {
            time: f32::MIN,
            t: Cursor::new(&self.translations),
            r: Cursor::new(&self.rotations),
            s: Cursor::new(&self.scales),
        }
    }

    /// ozz's `SamplingJob::Run` at time `t` (seconds; within the keys' range).
    pub fn sample(&self, ctx: &mut Context, t: f32, out: &mut [SoaTransform]) {
        if t < ctx.time {
            ctx.t.rewind(&self.translations);
            ctx.r.rewind(&self.rotations);
            ctx.s.rewind(&self.scales);
        }
        ctx.time = t;
        ctx.t.advance(&self.translations, t);
        ctx.r.advance(&self.rotations, t);
        ctx.s.advance(&self.scales, t);
        ctx.t.refresh(&self.translations);
        ctx.r.refresh(&self.rotations);
        ctx.s.refresh(&self.scales);
        for (g, o) in out.iter_mut().enumerate() {
            o.translation = ctx.t.lerp(g, t);
            o.scale = ctx.s.lerp(g, t);
            // nlerp: lerp, then normalise the 4 lanes at once.
            let [x, y, z, w] = ctx.r.lerp(g, t);
            let inv = Vec4::ONE / (x * x + y * y + z * z + w * w).sqrt();
            o.rotation = [x * inv, y * inv, z * inv, w * inv];
        }
    }
}
