//! The compiled tracks of a clip, stored in one list per channel and curve
//! kind, so that sampling runs each list as a tight loop with no dispatch
//! per track. Constant tracks never reach these lists: `Clip::build` folds
//! them into the clip's base pose. Bezier tracks that share a timeline are
//! then gathered four at a time into the SIMD groups of `soa` ([`QuatTracks::group`]), and rotation
//! tracks with their own times four at a time as well.

use glam::{Quat, Vec3A, Vec4};

use super::curve::{
    ArcPiece, QuatCurve, QuatSegment, SlerpCurve, Vec3Curve, bezier3, bezier4, lerp_keys, slerp_bezier, step,
};
use super::heap::vec_bytes;
use super::soa::{Lanes, QuatGroup, QuatSegment4, Vec3Group};
use super::timeline::Span;

/// One track: the joint it writes, the timeline it reads and its curve.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Track<C> {
    pub joint: u32,
    pub timeline: u32,
    pub curve: C,
}

/// Bezier segments walked at constant speed (docs/clip-format.md, “Speed control”).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ArcCurve {
    segments: Box<[[Vec3A; 4]]>,
    pieces: Box<[ArcPiece]>,
}

/// Translation or scale tracks by kind.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Vec3Tracks {
    step: Vec<Track<Box<[Vec3A]>>>,
    linear: Vec<Track<Box<[Vec3A]>>>,
    bezier: Vec<Track<Box<[[Vec3A; 4]]>>>,
    arc: Vec<Track<ArcCurve>>,
    /// Bezier tracks sharing a timeline, four per group.
    groups: Vec<Vec3Group>,
}

/// Rotation tracks by kind.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct QuatTracks {
    step: Vec<Track<Box<[Quat]>>>,
    slerp: Vec<Track<SlerpCurve>>,
    bezier: Vec<Track<Box<[QuatSegment]>>>,
    hermite: Vec<Track<Box<[[Vec4; 4]]>>>,
    /// Slerp-Bezier tracks sharing a timeline, four per group.
    groups: Vec<QuatGroup>,
    /// Tracks at the front of `bezier` with different timelines, evaluated
    /// four at a time all the same.
    gathered: Vec<Gathered>,
    /// How many tracks at the front of `bezier` `gathered` covers.
    gathered_tracks: usize,
}

/// Two to four slerp-Bezier tracks with different timelines, by index in
/// `QuatTracks::bezier` (missing lanes repeat the last).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Gathered {
    lanes: Lanes,
    tracks: [u32; 4],
}

/// Bytes of a track list: the list, and each track's curve arrays.
fn list_bytes<C>(tracks: &Vec<Track<C>>, curve: impl Fn(&C) -> usize) -> usize {
    vec_bytes(tracks) + tracks.iter().map(|t| curve(&t.curve)).sum::<usize>()
}

fn slice_bytes<T>(s: &[T]) -> usize {
    std::mem::size_of_val(s)
}

/// Where each track's timeline stands, and which joints to write: a whole
/// pose reads spans located up front for every joint; a part of a pose
/// (`Clip::sample_joints_into`) locates a timeline only when a kept track
/// needs it.
pub(crate) trait Spans {
    fn keeps(&self, joint: u32) -> bool;
    fn span(&mut self, timeline: u32) -> Span;
}

/// Every joint, spans already located.
impl Spans for &[Span] {
    #[inline(always)]
    fn keeps(&self, _joint: u32) -> bool {
        true
    }
    #[inline(always)]
    fn span(&mut self, timeline: u32) -> Span {
        self[timeline as usize]
    }
}

/// Splits `tracks` into the ones left alone and runs of 2–4 tracks on one
/// timeline (in track order), which `make` turns into a group.
fn gather<C, G>(tracks: &mut Vec<Track<C>>, mut make: impl FnMut(u32, &[&Track<C>]) -> G) -> Vec<G> {
    let mut timelines: Vec<u32> = tracks.iter().map(|t| t.timeline).collect();
    timelines.sort_unstable();
    timelines.dedup();
    let mut grouped = vec![false; tracks.len()];
    let mut groups = Vec::new();
    for timeline in timelines {
        let on: Vec<usize> = (0..tracks.len()).filter(|&i| tracks[i].timeline == timeline).collect();
        for chunk in on.chunks(4).filter(|c| c.len() >= 2) {
            groups.push(make(timeline, &chunk.iter().map(|&i| &tracks[i]).collect::<Vec<_>>()));
            chunk.iter().for_each(|&i| grouped[i] = true);
        }
    }
    let mut keep = grouped.iter().map(|g| !g);
    tracks.retain(|_| keep.next().unwrap_or(true));
    tracks.shrink_to_fit();
    groups
}

/// Evaluates each group with a kept lane and writes its kept lanes.
#[inline(always)]
fn run_groups<G, T: Copy>(
    groups: &[G],
    spans: &mut impl Spans,
    out: &mut [T],
    of: impl Fn(&G) -> (&Lanes, u32),
    eval: impl Fn(&G, Span) -> [T; 4],
) {
    for g in groups {
        let (lanes, timeline) = of(g);
        if !lanes.iter().any(|(_, j)| spans.keeps(j)) {
            continue;
        }
        let values = eval(g, spans.span(timeline));
        for (k, j) in lanes.iter() {
            if spans.keeps(j) {
                out[j as usize] = values[k];
            }
        }
    }
}

#[inline(always)]
fn run<C, T>(tracks: &[Track<C>], spans: &mut impl Spans, out: &mut [T], eval: impl Fn(&C, Span) -> T) {
    for t in tracks {
        if spans.keeps(t.joint) {
            out[t.joint as usize] = eval(&t.curve, spans.span(t.timeline));
        }
    }
}

impl Vec3Tracks {
    /// Files `curve` under its kind; a constant curve is written to `base`
    /// (the joint's value in the clip's base pose) instead.
    pub fn push(&mut self, joint: u32, timeline: u32, curve: Vec3Curve, base: &mut Vec3A) {
        match curve {
            Vec3Curve::Constant(v) => *base = v,
            Vec3Curve::Step(curve) => self.step.push(Track { joint, timeline, curve }),
            Vec3Curve::Linear(curve) => self.linear.push(Track { joint, timeline, curve }),
            Vec3Curve::Bezier(curve) => self.bezier.push(Track { joint, timeline, curve }),
            Vec3Curve::ConstantSpeed { segments, pieces } => {
                self.arc.push(Track { joint, timeline, curve: ArcCurve { segments, pieces } })
            }
        }
    }

    /// Bytes of every list and curve.
    pub fn heap_bytes(&self) -> usize {
        list_bytes(&self.step, |c| slice_bytes(c))
            + list_bytes(&self.linear, |c| slice_bytes(c))
            + list_bytes(&self.bezier, |c| slice_bytes(c))
            + list_bytes(&self.arc, |c| slice_bytes(&c.segments) + slice_bytes(&c.pieces))
            + vec_bytes(&self.groups)
            + self.groups.iter().map(Vec3Group::heap_bytes).sum::<usize>()
    }

    /// Tracks evaluated in groups.
    pub fn simd_lanes(&self) -> usize {
        self.groups.iter().map(|g| g.lanes.count as usize).sum()
    }

    /// Gathers Bezier tracks that share a timeline into groups of four.
    pub fn group(&mut self) {
        self.groups = gather(&mut self.bezier, |timeline, tracks| {
            Vec3Group::new(timeline, &tracks.iter().map(|t| (t.joint, &*t.curve)).collect::<Vec<_>>())
        });
    }

    /// Evaluates every track `spans` keeps at its timeline's span into `out`.
    #[inline]
    pub fn apply(&self, spans: &mut impl Spans, out: &mut [Vec3A]) {
        run(&self.step, spans, out, |k, s| step(k, s));
        run(&self.linear, spans, out, |k, s| {
            let i = s.index as usize;
            lerp_keys(k[i], k[i + 1], s.u)
        });
        run(&self.bezier, spans, out, |segs, s| bezier3(&segs[s.index as usize], s.u));
        run_groups(&self.groups, spans, out, |g| (&g.lanes, g.timeline), Vec3Group::at);
        run(&self.arc, spans, out, |a, s| {
            let piece = a.pieces[s.index as usize];
            bezier3(&a.segments[piece.segment as usize], piece.u0 + s.u * piece.du)
        });
    }
}

impl QuatTracks {
    /// Files `curve` under its kind; a constant curve is written to `base`.
    pub fn push(&mut self, joint: u32, timeline: u32, curve: QuatCurve, base: &mut Quat) {
        match curve {
            QuatCurve::Constant(q) => *base = q,
            QuatCurve::Step(curve) => self.step.push(Track { joint, timeline, curve }),
            QuatCurve::Slerp(curve) => self.slerp.push(Track { joint, timeline, curve }),
            QuatCurve::SlerpBezier(curve) => self.bezier.push(Track { joint, timeline, curve }),
            QuatCurve::Hermite(curve) => self.hermite.push(Track { joint, timeline, curve }),
        }
    }

    /// The timeline of `joint`'s rotation track, unless it has none or a
    /// constant one.
    pub fn timeline_of(&self, joint: u32) -> Option<u32> {
        fn find<C>(tracks: &[Track<C>], joint: u32) -> Option<u32> {
            tracks.iter().find(|t| t.joint == joint).map(|t| t.timeline)
        }
        find(&self.step, joint)
            .or_else(|| find(&self.slerp, joint))
            .or_else(|| find(&self.bezier, joint))
            .or_else(|| find(&self.hermite, joint))
            .or_else(|| self.groups.iter().find(|g| g.lanes.iter().any(|(_, j)| j == joint)).map(|g| g.timeline))
    }

    /// Bytes of every list and curve.
    pub fn heap_bytes(&self) -> usize {
        list_bytes(&self.step, |c| slice_bytes(c))
            + list_bytes(&self.slerp, SlerpCurve::heap_bytes)
            + list_bytes(&self.bezier, |c| slice_bytes(c))
            + list_bytes(&self.hermite, |c| slice_bytes(c))
            + vec_bytes(&self.groups)
            + self.groups.iter().map(QuatGroup::heap_bytes).sum::<usize>()
            + vec_bytes(&self.gathered)
    }

    /// Tracks evaluated in groups (gathered ones included).
    pub fn simd_lanes(&self) -> usize {
        self.groups.iter().map(|g| g.lanes.count as usize).sum::<usize>() + self.gathered_tracks
    }

    /// Gathers slerp-Bezier tracks that share a timeline into groups of
    /// four, and the others four at a time (the last one alone stays scalar).
    pub fn group(&mut self) {
        self.groups = gather(&mut self.bezier, |timeline, tracks| {
            QuatGroup::new(timeline, &tracks.iter().map(|t| (t.joint, &*t.curve)).collect::<Vec<_>>())
        });
        let n = self.bezier.len();
        let covered = if n % 4 == 1 { n - 1 } else { n };
        self.gathered = (0..covered)
            .step_by(4)
            .map(|first| {
                let last = (first + 4).min(covered);
                let joints: Vec<u32> = self.bezier[first..last].iter().map(|t| t.joint).collect();
                let lanes = Lanes::new(&joints);
                Gathered { lanes, tracks: std::array::from_fn(|k| (first + k.min(last - first - 1)) as u32) }
            })
            .collect();
        self.gathered_tracks = covered;
    }

    /// The gathered groups: each kept lane's own span and segment,
    /// transposed, evaluated together; lanes left out repeat a kept one.
    #[inline(always)]
    fn run_gathered(&self, spans: &mut impl Spans, out: &mut [Quat]) {
        for g in &self.gathered {
            let Some((first, _)) = g.lanes.iter().find(|&(_, j)| spans.keeps(j)) else { continue };
            let mut u = [0.0; 4];
            let segs: [&QuatSegment; 4] = std::array::from_fn(|k| {
                let lane = if k < g.lanes.count as usize && spans.keeps(g.lanes.joints[k]) { k } else { first };
                let track = &self.bezier[g.tracks[lane] as usize];
                let span = spans.span(track.timeline);
                u[k] = span.u;
                &track.curve[span.index as usize]
            });
            let values = QuatSegment4::gather(segs).at(Vec4::from_array(u));
            for (k, j) in g.lanes.iter() {
                if spans.keeps(j) {
                    out[j as usize] = values[k];
                }
            }
        }
    }

    /// Evaluates every track `spans` keeps at its timeline's span into `out`.
    #[inline]
    pub fn apply(&self, spans: &mut impl Spans, out: &mut [Quat]) {
        run(&self.step, spans, out, |k, s| step(k, s));
        run(&self.slerp, spans, out, SlerpCurve::at);
        run(&self.bezier[self.gathered_tracks..], spans, out, |segs, s| slerp_bezier(&segs[s.index as usize], s.u));
        self.run_gathered(spans, out);
        run_groups(&self.groups, spans, out, |g| (&g.lanes, g.timeline), QuatGroup::at);
        run(&self.hermite, spans, out, |segs, s| {
            let seg = &segs[s.index as usize];
            // The cubic can pass through zero (a key and its negation with
            // zero tangents): no direction there, so hold the segment's key.
            Quat::from_vec4(bezier4(seg, s.u).normalize_or(seg[0].normalize()))
        });
    }
}
