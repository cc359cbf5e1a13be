//! Animation graphs (docs/graphs.md) against references written here.
//!
//! Blend weights are held to an `f64` reference that finds the Delaunay
//! triangle by its empty circumcircle (general position) or by the grid's
//! known cells (ties), solves the 2×2 barycentric system, and projects onto
//! the hull's edges outside it. The state machine is held to a schedule
//! written by hand from the tick order. A blend's pose is held to the
//! layering of the same clips at the reported weights, bit for bit, and a
//! tick to allocating nothing.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;

use glam::Vec3;
use inbetween_anim::graph::{
    Blend1dSpec, Blend2dSpec, ClipNodeSpec, Comparison, Condition, EntrySource, EntrySpec, Graph, GraphPlayer,
    GraphSpec, Inputs, MachineSpec, NodeKind, NodeSpec, ParameterKind, ParameterSpec, SetError, StateSpec, TickRange,
    TopSpec, TransitionSpec, Value, due_tick,
};
use inbetween_anim::motion::{LayerMode, LayerSpec, MotionOptions, MotionSpec, Player};
use inbetween_anim::{Channel, Clip, ClipSpec, Ease, Interpolation, Keys, Motion, Playback, Space, TrackSpec};

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to `System` unchanged; counting touches
// only a const-initialised thread-local without a destructor.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// A looping clip of `duration` seconds moving `hips` from `from` to `to`
/// and turning it about y by `turn` radians.
fn clip(name: &str, duration: f32, from: [f32; 3], to: [f32; 3], turn: f32) -> Clip {
    let times = vec![0.0, duration];
    let t = TrackSpec::new(
        "hips",
        Channel::Translation,
        Interpolation::Linear,
        times.clone(),
        Keys::Vec3(vec![from.into(), to.into()]),
    );
    let q = |a: f32| glam::Quat::from_rotation_y(a);
    let r = TrackSpec::new(
        "hips",
        Channel::Rotation,
        Interpolation::Linear,
        times,
        Keys::Vec4(vec![q(0.0).into(), q(turn).into()]),
    );
    let spec = ClipSpec { name: name.into(), tracks: vec![t, r], playback: Playback::Loop, ..Default::default() };
    Clip::build(&spec).expect("a valid clip")
}

fn four_clips() -> Vec<Clip> {
    vec![
        clip("idle", 1.0, [0.0, 0.0, 0.0], [0.0, 0.1, 0.0], 0.1),
        clip("walk", 0.8, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], -0.4),
        clip("left", 1.2, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.9),
        clip("right", 0.6, [0.5, 0.0, 0.0], [0.0, 0.0, -1.0], -1.3),
    ]
}

fn float(name: &str, min: f64, max: f64) -> ParameterSpec {
    ParameterSpec { name: name.into(), kind: ParameterKind::Float { default: min.max(0.0).min(max), min, max } }
}

fn output(parameters: Vec<ParameterSpec>, kind: NodeKind) -> GraphSpec {
    GraphSpec { parameters, nodes: vec![NodeSpec { name: "blend".into(), kind }], top: TopSpec::Output(0) }
}

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.unit()
    }
}

// ---- the f64 reference of blend weights -------------------------------------------------

/// `(u, v)` with `p = a + u·(b − a) + v·(c − a)`, solving the 2×2 system by Cramer's rule.
fn solve(a: [f64; 2], b: [f64; 2], c: [f64; 2], p: [f64; 2]) -> (f64, f64) {
    let (m00, m01, m10, m11) = (b[0] - a[0], c[0] - a[0], b[1] - a[1], c[1] - a[1]);
    let (r0, r1) = (p[0] - a[0], p[1] - a[1]);
    let det = m00 * m11 - m01 * m10;
    ((r0 * m11 - m01 * r1) / det, (m00 * r1 - r0 * m10) / det)
}

/// Weights of `p` in triangle `t`, if it contains `p`.
fn inside(points: &[[f64; 2]], t: [usize; 3], p: [f64; 2]) -> Option<Vec<f64>> {
    let (u, v) = solve(points[t[0]], points[t[1]], points[t[2]], p);
    let w = 1.0 - u - v;
    if u < -1e-12 || v < -1e-12 || w < -1e-12 {
        return None;
    }
    let mut out = vec![0.0; points.len()];
    (out[t[0]], out[t[1]], out[t[2]]) = (w, u, v);
    Some(out)
}

/// Delaunay triangles of points in general position: every triple whose
/// circumcircle has no other point inside or on it.
fn delaunay(points: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let n = points.len();
    let mut out = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let (a, b, c) = (points[i], points[j], points[k]);
                // Circumcentre from the perpendicular bisectors, as its own 2×2 system.
                let (bx, by, cx, cy) = (b[0] - a[0], b[1] - a[1], c[0] - a[0], c[1] - a[1]);
                let det = bx * cy - by * cx;
                if det.abs() < 1e-12 {
                    continue;
                }
                let (hb, hc) = ((bx * bx + by * by) / 2.0, (cx * cx + cy * cy) / 2.0);
                let centre = [a[0] + (hb * cy - by * hc) / det, a[1] + (bx * hc - hb * cx) / det];
                let r2 = (a[0] - centre[0]).powi(2) + (a[1] - centre[1]).powi(2);
                let empty = (0..n).filter(|m| ![i, j, k].contains(m)).all(|m| {
                    (points[m][0] - centre[0]).powi(2) + (points[m][1] - centre[1]).powi(2) > r2 * (1.0 + 1e-9)
                });
                if empty {
                    out.push([i, j, k]);
                }
            }
        }
    }
    out
}

/// Edges between consecutive hull points: every other point strictly on one side, none on it between.
fn hull(points: &[[f64; 2]]) -> Vec<[usize; 2]> {
    let n = points.len();
    let mut edges = Vec::new();
    for i in 0..n {
        for j in 0..n {
            if i == j {
                continue;
            }
            let (a, b) = (points[i], points[j]);
            let side = |p: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
            let left = (0..n).filter(|&m| m != i && m != j).all(|m| {
                side(points[m]) > 1e-12 || {
                    // On the line: outside the segment.
                    let t = ((points[m][0] - a[0]) * (b[0] - a[0]) + (points[m][1] - a[1]) * (b[1] - a[1]))
                        / ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2));
                    side(points[m]).abs() <= 1e-12 && !(0.0..=1.0).contains(&t)
                }
            });
            if left {
                edges.push([i, j]);
            }
        }
    }
    edges
}

/// The nearest hull point's weights (on the segment between two hull neighbours).
fn nearest_on_hull(points: &[[f64; 2]], p: [f64; 2]) -> Vec<f64> {
    let mut best = (f64::INFINITY, vec![]);
    for [i, j] in hull(points) {
        let (a, b) = (points[i], points[j]);
        let d = [b[0] - a[0], b[1] - a[1]];
        let s = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / (d[0] * d[0] + d[1] * d[1])).clamp(0.0, 1.0);
        let q = [a[0] + s * d[0], a[1] + s * d[1]];
        let distance = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
        if distance < best.0 - 1e-15 {
            let mut w = vec![0.0; points.len()];
            (w[i], w[j]) = (1.0 - s, s);
            best = (distance, w);
        }
    }
    best.1
}

fn reference_2d(points: &[[f64; 2]], triangles: &[[usize; 3]], p: [f64; 2]) -> Vec<f64> {
    triangles.iter().find_map(|&t| inside(points, t, p)).unwrap_or_else(|| nearest_on_hull(points, p))
}

/// The graph's weights at `(x, y)` for a blend2d of `points` on axes
/// `x ∈ [-180, 180]`, `y ∈ [0, 6]`.
fn graph_2d<'a>(clips: &'a [Clip], points: &[[f64; 2]]) -> GraphPlayer<&'a Clip> {
    let spec = output(
        vec![float("direction", -180.0, 180.0), float("speed", 0.0, 6.0)],
        NodeKind::Blend2d(Blend2dSpec {
            x: 0,
            y: 1,
            points: points.iter().enumerate().map(|(i, &at)| (i % clips.len(), at)).collect(),
            sync: true,
        }),
    );
    let clips: Vec<&Clip> = clips.iter().collect();
    GraphPlayer::new(Arc::new(Graph::build(spec, &clips).expect("a valid graph")))
}

fn weights_at(player: &mut GraphPlayer<&Clip>, x: f64, y: f64) -> Vec<f64> {
    player.set(0, Value::Float(x)).unwrap();
    player.set(1, Value::Float(y)).unwrap();
    player.tick(1.0 / 60.0);
    let report = player.report();
    let (name, weights) = report.weights().next().expect("the blend was evaluated");
    assert_eq!(name, "blend");
    weights.to_vec()
}

fn normalised(p: [f64; 2]) -> [f64; 2] {
    [(p[0] + 180.0) / 360.0, p[1] / 6.0]
}

fn assert_close(got: &[f64], expected: &[f64], what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}");
    for (g, e) in got.iter().zip(expected) {
        assert!((g - e).abs() < 1e-9, "{what}: got {got:?}, expected {expected:?}");
    }
    assert!((got.iter().sum::<f64>() - 1.0).abs() < 1e-9, "{what}: weights sum to 1");
}

#[test]
fn blend2d_weights_match_the_reference_in_general_position_inside_and_outside() {
    let clips = four_clips();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for layout in 0..20 {
        let n = 4 + layout % 5;
        let points: Vec<[f64; 2]> = (0..n).map(|_| [rng.range(-150.0, 150.0), rng.range(0.5, 5.5)]).collect();
        let unit: Vec<[f64; 2]> = points.iter().map(|&p| normalised(p)).collect();
        let triangles = delaunay(&unit);
        let mut player = graph_2d(&clips, &points);
        for _ in 0..50 {
            // Some draws land outside the points' hull (and outside the axes' range, which clamps).
            let (x, y) = (rng.range(-180.0, 180.0), rng.range(0.0, 6.0));
            let got = weights_at(&mut player, x, y);
            let expected = reference_2d(&unit, &triangles, normalised([x, y]));
            assert_close(&got, &expected, &format!("layout {layout} at ({x}, {y})"));
        }
    }
}

#[test]
fn blend2d_splits_each_grid_cell_by_the_fan_from_its_lowest_index() {
    let clips = four_clips();
    // A 3×3 grid whose points are listed in a scrambled order.
    let order = [4usize, 7, 0, 2, 8, 5, 1, 6, 3];
    let cell = |g: usize| [-90.0 + 90.0 * (g % 3) as f64, 1.5 * (g / 3) as f64 + 1.5];
    let points: Vec<[f64; 2]> = order.iter().map(|&g| cell(g)).collect();
    let unit: Vec<[f64; 2]> = points.iter().map(|&p| normalised(p)).collect();
    // Each square's diagonal runs from its lowest-index corner (hand-derived from `order`).
    let index = |g: usize| order.iter().position(|&o| o == g).unwrap();
    let mut triangles = Vec::new();
    for (r, c) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
        let corners = [3 * r + c, 3 * r + c + 1, 3 * (r + 1) + c + 1, 3 * (r + 1) + c].map(index);
        let low = (0..4).min_by_key(|&k| corners[k]).unwrap();
        let (a, b, opposite, d) =
            (corners[low], corners[(low + 1) % 4], corners[(low + 2) % 4], corners[(low + 3) % 4]);
        triangles.push([a, b, opposite]);
        triangles.push([a, opposite, d]);
    }
    let mut player = graph_2d(&clips, &points);
    let mut rng = Rng(7);
    let mut draws: Vec<[f64; 2]> = (0..200).map(|_| [rng.range(-180.0, 180.0), rng.range(0.0, 6.0)]).collect();
    // On the grid's lines and at its points: the ties.
    draws.extend((0..9).map(cell));
    draws.extend([[-45.0, 2.25], [45.0, 3.75], [0.0, 2.25], [-45.0, 3.0]]);
    for [x, y] in draws {
        let got = weights_at(&mut player, x, y);
        let expected = reference_2d(&unit, &triangles, normalised([x, y]));
        assert_close(&got, &expected, &format!("at ({x}, {y})"));
    }
    // Inside a cell off its diagonal, three weights are non-zero; outside, at most two.
    let got = weights_at(&mut player, -60.0, 2.5);
    assert_eq!(got.iter().filter(|w| **w > 0.0).count(), 3, "{got:?}");
    let got = weights_at(&mut player, -170.0, 5.9);
    assert!(got.iter().filter(|w| **w > 0.0).count() <= 2, "{got:?}");
}

#[test]
fn blend1d_weights_are_the_neighbours_interpolated_and_clamped() {
    let clips = four_clips();
    let at = [5.0, 0.0, 1.5];
    let spec = output(
        vec![float("speed", -1.0, 6.0)],
        NodeKind::Blend1d(Blend1dSpec { parameter: 0, points: (0..3).map(|i| (i, at[i])).collect(), sync: true }),
    );
    let clips: Vec<&Clip> = clips.iter().collect();
    let mut player = GraphPlayer::new(Arc::new(Graph::build(spec, &clips).unwrap()));
    let mut rng = Rng(11);
    for _ in 0..200 {
        let v = rng.range(-1.0, 6.0);
        player.set(0, Value::Float(v)).unwrap();
        player.tick(0.01);
        let report = player.report();
        let got = report.weights().next().unwrap().1.to_vec();
        let mut expected = vec![0.0; 3];
        if v <= 0.0 {
            expected[1] = 1.0;
        } else if v < 1.5 {
            (expected[1], expected[2]) = (1.0 - v / 1.5, v / 1.5);
        } else if v < 5.0 {
            (expected[2], expected[0]) = (1.0 - (v - 1.5) / 3.5, (v - 1.5) / 3.5);
        } else {
            expected[0] = 1.0;
        }
        assert_close(&got, &expected, &format!("at {v}"));
    }
}

#[test]
fn a_blend_is_the_layering_of_its_clips_at_the_computed_weights() {
    let clips = four_clips();
    let points = [[0.0, 0.0], [0.0, 1.5], [-90.0, 1.5], [90.0, 1.5]];
    let mut graph = graph_2d(&clips, &points);
    graph.set(0, Value::Float(-30.0)).unwrap();
    graph.set(1, Value::Float(1.0)).unwrap();
    graph.tick(0.0);
    let weights = graph.report().weights().next().unwrap().1.to_vec();
    assert_eq!(weights.iter().filter(|w| **w > 0.0).count(), 3, "{weights:?}");
    // The same clips as a motion: one sync group, layer k at w_k / Σ_{j≤k} w_j.
    let mut sum = 0.0;
    let layers = clips
        .iter()
        .zip(&weights)
        .map(|(c, w)| {
            sum += w;
            let weight = if sum > 0.0 { (w / sum) as f32 } else { 0.0 };
            LayerSpec { weight, sync: Some("g".into()), ..LayerSpec::new(c) }
        })
        .collect();
    let motion = Arc::new(Motion::build(MotionSpec { layers, ..Default::default() }).unwrap());
    let mut player = Player::new(motion);
    let options = MotionOptions { ease: Ease::Linear, space: Space::Local };
    for k in 0..40 {
        if k > 0 {
            graph.tick(0.125);
        }
        player.sample(k as f64 * 0.125, &options);
        assert_eq!(graph.pose(), player.pose(), "tick {k}");
    }
}

// ---- the state machine ------------------------------------------------------------------

fn transition(from: Option<usize>, to: usize, when: Condition, duration: f64) -> TransitionSpec {
    TransitionSpec { from, to, when, duration, ease: Ease::Linear, interruptible: true }
}

/// move (a 1 s loop), jump (a 0.5 s clip played once), crouch: the
/// machine of the schedule below.
fn machine(clips: &[Clip]) -> GraphPlayer<&Clip> {
    let clips: Vec<&Clip> = clips.iter().collect();
    GraphPlayer::new(Arc::new(Graph::build(machine_spec(), &clips).unwrap()))
}

fn machine_spec() -> GraphSpec {
    let parameters = vec![
        ParameterSpec { name: "jump".into(), kind: ParameterKind::Trigger },
        ParameterSpec { name: "crouch".into(), kind: ParameterKind::Bool { default: false } },
    ];
    let node = |name: &str, clip, playback| NodeSpec {
        name: name.into(),
        kind: NodeKind::Clip(ClipNodeSpec { clip, playback, speed: 1.0 }),
    };
    let nodes = vec![node("walk", 0, None), node("hop", 1, Some(Playback::Once)), node("low", 2, None)];
    let crouch = |v| Condition::Compare { parameter: 1, op: Comparison::Eq, value: Value::Bool(v) };
    let transitions = vec![
        transition(Some(0), 1, Condition::Trigger(0), 0.25),
        transition(Some(1), 0, Condition::ExitTime(0.75), 0.25),
        TransitionSpec { interruptible: false, ..transition(None, 2, crouch(true), 0.5) },
        transition(Some(2), 0, crouch(false), 0.25),
    ];
    let state = |name: &str, node| StateSpec { name: name.into(), node };
    let states = vec![state("move", 0), state("jump", 1), state("crouch", 2)];
    let top = TopSpec::Machine(MachineSpec { initial: 0, states, transitions });
    GraphSpec { parameters, nodes, top }
}

fn machine_clips() -> Vec<Clip> {
    vec![
        clip("walk", 1.0, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.3),
        clip("hop", 0.5, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], -0.2),
        clip("low", 1.0, [0.0, -0.5, 0.0], [0.0, -0.4, 0.0], 0.1),
    ]
}

/// Tick `k`'s parameter changes in the schedule.
fn inputs(player: &mut GraphPlayer<&Clip>, k: usize) {
    match k {
        2 | 6 | 8 => player.set(0, Value::Bool(true)).unwrap(),
        7 => player.set(1, Value::Bool(true)).unwrap(),
        12 => player.set(1, Value::Bool(false)).unwrap(),
        _ => {}
    }
}

/// A tick's expected state and transition `(from, to, α)`.
type Tick = (&'static str, Option<(&'static str, &'static str, f32)>);

/// The schedule of [`inputs`], tick by tick.
fn schedule() -> [Tick; 16] {
    // Ticks of 1/8 s. Hand-derived from the tick order:
    //  2: jump fires (α 0); 4: it completes (elapsed 0.25);
    //  5: the hop has played 0.375/0.5 = 0.75 cycles: back to move;
    //  6: jump again, interrupting it; 7: that first transition completes
    //     (0.25), crouch fires from jump (any state) and cannot be interrupted;
    //  8: the jump trigger finds no transition from crouch and is cleared;
    //     crouch → move cannot interrupt; 11: crouch completes (0.5), and
    //     `* → crouch` does not fire into crouch; 12: crouch off → move.
    [
        ("move", None),
        ("move", None),
        ("jump", Some(("move", "jump", 0.0))),
        ("jump", Some(("move", "jump", 0.5))),
        ("jump", None),
        ("move", Some(("jump", "move", 0.0))),
        ("jump", Some(("move", "jump", 0.0))),
        ("crouch", Some(("jump", "crouch", 0.0))),
        ("crouch", Some(("jump", "crouch", 0.25))),
        ("crouch", Some(("jump", "crouch", 0.5))),
        ("crouch", Some(("jump", "crouch", 0.75))),
        ("crouch", None),
        ("move", Some(("crouch", "move", 0.0))),
        ("move", Some(("crouch", "move", 0.5))),
        ("move", None),
        ("move", None),
    ]
}

#[test]
fn the_machine_follows_the_hand_written_schedule() {
    let clips = machine_clips();
    let mut player = machine(&clips);
    for (k, (state, transition)) in schedule().into_iter().enumerate() {
        inputs(&mut player, k);
        player.tick(0.125);
        let report = player.report();
        let got = report.transition().map(|t| (t.from, t.to, t.alpha));
        assert_eq!((report.state(), got), (state, transition), "tick {k}");
    }
}

#[test]
fn a_fired_transition_shows_the_old_pose_and_a_state_resumes_exactly() {
    let clips = machine_clips();
    let (mut fired, mut still) = (machine(&clips), machine(&clips));
    for k in 0..3 {
        inputs(&mut fired, k);
        fired.tick(0.125);
        still.tick(0.125);
    }
    assert_eq!(fired.report().state(), "jump");
    assert_eq!(fired.pose(), still.pose(), "α is 0 on the tick it fires");

    // A player made from another's state steps on as that one does, through fades.
    let mut a = machine(&clips);
    for k in 0..7 {
        inputs(&mut a, k);
        a.tick(0.125);
    }
    let mut b = GraphPlayer::from_state(Arc::clone(a.graph()), a.state()).unwrap();
    for k in 7..16 {
        inputs(&mut a, k);
        inputs(&mut b, k);
        a.tick(0.125);
        b.tick(0.125);
        assert_eq!(a.pose(), b.pose(), "tick {k}");
        assert_eq!(a.state(), b.state(), "tick {k}");
    }
}

#[test]
fn a_tick_allocates_nothing() {
    let clips = four_clips();
    let machine_clips = machine_clips();
    let points = [[0.0, 0.0], [0.0, 1.5], [-90.0, 1.5], [90.0, 1.5]];
    let mut blend = graph_2d(&clips, &points);
    let mut states = machine(&machine_clips);
    let mut rng = Rng(3);
    blend.tick(0.0);
    states.tick(0.0);
    let before = allocations();
    for k in 1..400 {
        blend.set(0, Value::Float(rng.range(-200.0, 200.0))).unwrap();
        blend.set(1, Value::Float(rng.range(0.0, 6.0))).unwrap();
        blend.tick(1.0 / 60.0);
        inputs(&mut states, k % 16);
        states.tick(0.125);
        let report = blend.report();
        assert!(report.weights().count() == 1 && report.transition().is_none());
    }
    assert_eq!(allocations() - before, 0, "allocations during ticks");
    // Timed inputs played over a range (their list built beforehand) allocate nothing either.
    let (inputs, range) = (timed_inputs(), TickRange::new(0.5, 15.0 / 8.0, 8.0).unwrap());
    let mut timed = machine(&machine_clips);
    let before = allocations();
    timed.play(&range, &inputs, |_, p| assert!(!p.report().state().is_empty())).unwrap();
    assert_eq!(allocations() - before, 0, "allocations while playing timed inputs");
}

// ---- refusals ---------------------------------------------------------------------------

fn refusal(spec: GraphSpec, clips: &[Clip]) -> (String, &'static str) {
    let clips: Vec<&Clip> = clips.iter().collect();
    let e = Graph::build(spec, &clips).unwrap_err();
    (e.path.to_string(), e.kind.code())
}

#[test]
fn refusals_name_the_rule_and_the_place() {
    let clips = four_clips();
    let collinear = output(
        vec![float("direction", -180.0, 180.0), float("speed", 0.0, 6.0)],
        NodeKind::Blend2d(Blend2dSpec {
            x: 0,
            y: 1,
            points: vec![(0, [0.0, 0.0]), (1, [0.0, 1.0]), (2, [0.0, 3.0])],
            sync: true,
        }),
    );
    assert_eq!(refusal(collinear, &clips), ("/nodes/blend/blend2d/points".into(), "degenerate_blend_space"));

    let unbounded = output(
        vec![float("direction", f64::NEG_INFINITY, 180.0), float("speed", 0.0, 6.0)],
        NodeKind::Blend2d(Blend2dSpec {
            x: 0,
            y: 1,
            points: vec![(0, [0.0, 0.0]), (1, [0.0, 1.0]), (2, [1.0, 3.0])],
            sync: true,
        }),
    );
    assert_eq!(refusal(unbounded, &clips), ("/nodes/blend/blend2d/x".into(), "unbounded_axis"));

    let entry = |node| EntrySpec { source: EntrySource::Node(node), weight: 1.0, mode: LayerMode::Blend, mask: None };
    let cycle = GraphSpec {
        parameters: vec![],
        nodes: vec![
            NodeSpec { name: "a".into(), kind: NodeKind::Layers(vec![entry(1)]) },
            NodeSpec { name: "b".into(), kind: NodeKind::Layers(vec![entry(0)]) },
        ],
        top: TopSpec::Output(0),
    };
    assert_eq!(refusal(cycle, &clips), ("/nodes/a".into(), "node_cycle"));

    let clip_entry =
        EntrySpec { source: EntrySource::Clip(ClipNodeSpec::new(0)), weight: 1.0, mode: LayerMode::Blend, mask: None };
    let late = GraphSpec {
        parameters: vec![float("speed", 0.0, 6.0)],
        nodes: vec![
            NodeSpec {
                name: "walkrun".into(),
                kind: NodeKind::Blend1d(Blend1dSpec { parameter: 0, points: vec![(0, 0.0), (1, 1.0)], sync: true }),
            },
            NodeSpec { name: "stack".into(), kind: NodeKind::Layers(vec![clip_entry, entry(0)]) },
        ],
        top: TopSpec::Output(1),
    };
    assert_eq!(refusal(late, &clips), ("/nodes/stack/layers/1/node".into(), "entry_not_stackable"));

    let mut bad_default = output(vec![float("speed", 0.0, 6.0)], NodeKind::Clip(ClipNodeSpec::new(0)));
    bad_default.parameters[0].kind = ParameterKind::Float { default: 7.0, min: 0.0, max: 6.0 };
    assert_eq!(refusal(bad_default, &clips), ("/parameters/speed".into(), "parameter_range"));

    let one = |kind| GraphSpec {
        parameters: vec![ParameterSpec { name: "crouch".into(), kind: ParameterKind::Bool { default: false } }],
        nodes: vec![NodeSpec { name: "n".into(), kind: NodeKind::Clip(ClipNodeSpec::new(0)) }],
        top: TopSpec::Machine(MachineSpec {
            initial: 0,
            states: vec![StateSpec { name: "s".into(), node: 0 }, StateSpec { name: "t".into(), node: 0 }],
            transitions: vec![transition(None, 1, kind, 0.1)],
        }),
    };
    let gt_bool = Condition::Compare { parameter: 0, op: Comparison::Gt, value: Value::Bool(true) };
    assert_eq!(refusal(one(gt_bool), &clips), ("/machine/transitions/0/when/gt".into(), "parameter_type"));
    let not_trigger = Condition::Any(vec![Condition::ExitTime(1.0), Condition::Trigger(0)]);
    assert_eq!(
        refusal(one(not_trigger), &clips),
        ("/machine/transitions/0/when/any/1/trigger".into(), "parameter_type")
    );

    let mut masked = output(
        vec![],
        NodeKind::Layers(vec![EntrySpec {
            mask: Some(inbetween_anim::motion::MaskSpec { joints: vec![("spine".into(), 1.0)], ..Default::default() }),
            ..clip_entry_of(0)
        }]),
    );
    masked.top = TopSpec::Output(0);
    assert_eq!(refusal(masked, &clips), ("/nodes/blend/layers/0/mask/joints/spine".into(), "unknown_joint"));

    // A state whose clip has other joints cannot be crossfaded into.
    let mut clips = machine_clips();
    let keys = Keys::Vec3(vec![Vec3::ZERO]);
    let spine = TrackSpec::new("spine", Channel::Translation, Interpolation::Linear, vec![0.0], keys);
    clips[2] = Clip::build(&ClipSpec { name: "spine".into(), tracks: vec![spine], ..Default::default() }).unwrap();
    let refs: Vec<&Clip> = clips.iter().collect();
    let spec = machine_spec();
    let e = Graph::build(spec, &refs).unwrap_err();
    assert_eq!((e.path.to_string(), e.kind.code()), ("/machine/states/crouch/node".into(), "skeleton_mismatch"));
}

fn clip_entry_of(clip: usize) -> EntrySpec {
    EntrySpec { source: EntrySource::Clip(ClipNodeSpec::new(clip)), weight: 1.0, mode: LayerMode::Blend, mask: None }
}

#[test]
fn parameters_are_typed_and_floats_clamped_to_their_range() {
    let clips = machine_clips();
    let mut player = machine(&clips);
    assert_eq!(player.set(1, Value::Float(1.0)), Err(SetError::WrongType { expected: "boolean" }));
    assert_eq!(player.set(0, Value::Float(1.0)), Err(SetError::WrongType { expected: "boolean" }));
    assert_eq!(player.set(2, Value::Bool(true)), Err(SetError::UnknownParameter(2)));
    let clips = four_clips();
    let mut blend = graph_2d(&clips, &[[0.0, 0.0], [0.0, 1.5], [-90.0, 1.5], [90.0, 1.5]]);
    assert_eq!(blend.set(1, Value::Bool(true)), Err(SetError::WrongType { expected: "float" }));
    assert_eq!(blend.set(1, Value::Float(f64::NAN)), Err(SetError::NonFinite));
    blend.set(1, Value::Float(9.0)).unwrap();
    blend.set(0, Value::Float(-400.0)).unwrap();
    assert_eq!(blend.values(), [-180.0, 6.0]);
}

#[test]
fn an_input_is_due_at_the_first_tick_at_or_after_its_time() {
    assert_eq!(due_tick(0.1, 60.0), 6, "0.1 · 60 is 6.000000000000001 in f64, still tick 6");
    assert_eq!(due_tick(0.1001, 60.0), 7);
    assert_eq!(due_tick(0.0, 60.0), 0);
    assert_eq!(due_tick(-3.0, 60.0), 0);
    assert_eq!(due_tick(0.7, 8.0), 6, "5.6 ticks: the next one");
    let range = TickRange::new(0.5, 1.0, 60.0).unwrap();
    assert_eq!((range.first, range.last, range.answered()), (30, 60, 31));
    let range = TickRange::new(0.505, 0.51, 60.0);
    assert_eq!(range, None, "no tick between 30.3 and 30.6");
    assert_eq!(TickRange::new(1.0, 0.5, 60.0), None);
    assert_eq!(TickRange::new(0.0, 1.0, 0.0), None);
    assert_eq!(TickRange::new(-1.0, 1.0, 60.0), None);
}

/// The schedule's parameter changes as timed inputs at 8 fps: each time is
/// chosen so its first tick at or after it is the schedule's tick.
fn timed_inputs() -> Inputs {
    let (jump, crouch) = (0, 1);
    Inputs::new(
        8.0,
        [
            (1.4, crouch, Value::Bool(false)), // 11.2 → tick 12
            (0.25, jump, Value::Bool(true)),   // tick 2 exactly
            (0.7, jump, Value::Bool(true)),    // 5.6 → 6
            (0.8, crouch, Value::Bool(true)),  // 6.4 → 7
            (1.0, jump, Value::Bool(true)),    // 8
        ],
    )
}

#[test]
fn a_timed_sample_plays_the_schedule_and_equals_the_player_ticked_by_hand() {
    let clips = machine_clips();
    let mut by_hand = machine(&clips);
    let mut hand_poses = Vec::new();
    for k in 0..16 {
        inputs(&mut by_hand, k);
        by_hand.tick(0.125);
        hand_poses.push(by_hand.pose().clone());
    }
    let expected = schedule();
    for start in [0.0, 0.6] {
        // From 0.6 s the ticks 5.. are answered; 0..=4 are stepped without a pose.
        let range = TickRange::new(start, 15.0 / 8.0, 8.0).unwrap();
        let mut player = machine(&clips);
        let mut answered = Vec::new();
        player
            .play(&range, &timed_inputs(), |k, p| {
                let report = p.report();
                let transition = report.transition().map(|t| (t.from, t.to, t.alpha));
                assert_eq!((report.state(), transition), expected[k as usize], "tick {k} from {start}");
                assert_eq!(p.pose(), &hand_poses[k as usize], "tick {k} from {start}");
                answered.push(k);
            })
            .unwrap();
        let first = if start == 0.0 { 0 } else { 5 };
        assert_eq!(answered, (first..16).collect::<Vec<u64>>());
    }
}

#[test]
fn a_value_a_client_sends_is_checked_not_clamped() {
    let clips = four_clips();
    let player = graph_2d(&clips, &[[0.0, 0.0], [0.0, 1.5], [-90.0, 1.5], [90.0, 1.5]]);
    let graph = player.graph();
    assert_eq!(graph.check_value(1, Value::Float(6.5)), Err(SetError::OutOfRange { min: 0.0, max: 6.0 }));
    assert_eq!(graph.check_value(0, Value::Float(-180.5)), Err(SetError::OutOfRange { min: -180.0, max: 180.0 }));
    assert_eq!(graph.check_value(1, Value::Float(6.0)), Ok(Value::Float(6.0)), "the bounds are in range");
    assert_eq!(graph.check_value(1, Value::Bool(true)), Err(SetError::WrongType { expected: "float" }));
    assert_eq!(graph.check_value(1, Value::Float(f64::INFINITY)), Err(SetError::NonFinite));
    assert_eq!(graph.check_value(2, Value::Float(1.0)), Err(SetError::UnknownParameter(2)));
    let clips = machine_clips();
    let machine = machine(&clips);
    assert_eq!(machine.graph().check_value(0, Value::Bool(true)), Ok(Value::Bool(true)));
    assert_eq!(machine.graph().check_value(1, Value::Float(1.0)), Err(SetError::WrongType { expected: "boolean" }));
}

#[test]
fn a_tick_is_priced_by_its_costliest_chain() {
    // Every test clip has one joint (hips). The machine's transitions last:
    // nine slots of one one-joint state, and eight mixes of one joint.
    let clips = machine_clips();
    let machine = machine(&clips);
    assert_eq!((machine.graph().max_slots(), machine.graph().tick_joint_samples()), (9, 9 + 8));
    // An output blend of four points: one slot, four layers of one joint.
    let clips = four_clips();
    let blend = graph_2d(&clips, &[[0.0, 0.0], [0.0, 1.5], [-90.0, 1.5], [90.0, 1.5]]);
    assert_eq!((blend.graph().max_slots(), blend.graph().tick_joint_samples()), (1, 4));
    // Transitions of no duration: the tick one fires shows the old state beneath the new.
    let mut spec = machine_spec();
    if let TopSpec::Machine(m) = &mut spec.top {
        m.transitions.iter_mut().for_each(|t| t.duration = 0.0);
    }
    let clips = machine_clips();
    let refs: Vec<&Clip> = clips.iter().collect();
    let graph = Graph::build(spec, &refs).unwrap();
    assert_eq!((graph.max_slots(), graph.tick_joint_samples()), (2, 2 + 1));
}
