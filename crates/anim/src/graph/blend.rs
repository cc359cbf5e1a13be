//! Blend spaces (docs/graphs.md, “blend1d”, “blend2d”): parameter values to
//! one weight per point, summing to 1.
//!
//! A 1D blend interpolates linearly between the two neighbouring points
//! and clamps at the ends. A 2D blend normalises each axis to `[0, 1]` by
//! its parameter's `min`/`max` and triangulates the points once, when the
//! graph is built: the Delaunay triangulation, found by brute force (a
//! blend has at most [`MAX_LAYERS`](crate::motion::MAX_LAYERS) points, so
//! every triple with an empty circumcircle is a cell). A cell with more
//! than three cocircular points (every square of a grid) is split by the
//! fan from its lowest-index point, so the triangulation, and so the
//! weights, depend on the points' order and nothing else. Inside the hull
//! a value's weights are its barycentric coordinates in the first triangle
//! that contains it; outside, those of the nearest point on the hull (two
//! weights on an edge, one at a corner).

use super::error::Degeneracy;

/// Relative tolerance of the empty-circle and containment tests.
const EPSILON: f64 = 1e-9;

/// A 1D blend: points sorted by position, each with its index in the node.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Line {
    sorted: Vec<(f64, usize)>,
}

impl Line {
    /// Sorts the points; two at the same place make it degenerate.
    pub fn new(at: &[f64]) -> Result<Line, Degeneracy> {
        if at.is_empty() {
            return Err(Degeneracy::Empty);
        }
        let mut sorted: Vec<(f64, usize)> = at.iter().copied().zip(0..).collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        if let Some(w) = sorted.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(Degeneracy::Coincident(w[0].1.min(w[1].1), w[0].1.max(w[1].1)));
        }
        Ok(Line { sorted })
    }

    /// One weight per point (in the node's order) at value `v`.
    pub fn weights(&self, v: f64, out: &mut [f64]) {
        out.fill(0.0);
        let s = &self.sorted;
        let last = s.len() - 1;
        if v <= s[0].0 {
            out[s[0].1] = 1.0;
        } else if v >= s[last].0 {
            out[s[last].1] = 1.0;
        } else {
            let i = s.partition_point(|p| p.0 <= v) - 1;
            let u = (v - s[i].0) / (s[i + 1].0 - s[i].0);
            out[s[i].1] = 1.0 - u;
            out[s[i + 1].1] = u;
        }
    }
}

/// A triangle of a 2D blend: its corners and what turns a point into its
/// barycentric coordinates (`a` and the inverse of `[b − a, c − a]`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Triangle {
    corners: [usize; 3],
    a: [f64; 2],
    inverse: [[f64; 2]; 2],
}

/// A 2D blend: the normalised points, the triangles and the hull's edges.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Plane {
    points: Vec<[f64; 2]>,
    triangles: Vec<Triangle>,
    hull: Vec<[usize; 2]>,
}

impl Plane {
    /// Triangulates `points` (already normalised).
    pub fn new(points: &[[f64; 2]]) -> Result<Plane, Degeneracy> {
        check_points(points)?;
        let triangles: Vec<Triangle> = triangulate(points).into_iter().map(|t| triangle(points, t)).collect();
        let hull = hull_edges(&triangles);
        Ok(Plane { points: points.to_vec(), triangles, hull })
    }

    /// The triangles' corners, in the order they are searched.
    pub fn triangles(&self) -> impl Iterator<Item = [usize; 3]> + '_ {
        self.triangles.iter().map(|t| t.corners)
    }

    /// One weight per point (in the node's order) at the normalised `p`.
    pub fn weights(&self, p: [f64; 2], out: &mut [f64]) {
        out.fill(0.0);
        for t in &self.triangles {
            let (u, v) = barycentric(t, p);
            let w = 1.0 - u - v;
            if u >= -EPSILON && v >= -EPSILON && w >= -EPSILON {
                let (u, v, w) = (u.max(0.0), v.max(0.0), w.max(0.0));
                let sum = u + v + w;
                out[t.corners[0]] = w / sum;
                out[t.corners[1]] = u / sum;
                out[t.corners[2]] = v / sum;
                return;
            }
        }
        let (edge, s) = self.nearest_on_hull(p);
        out[edge[0]] = 1.0 - s;
        out[edge[1]] += s;
    }

    /// The hull edge nearest `p` and where along it (0 at its first end).
    fn nearest_on_hull(&self, p: [f64; 2]) -> ([usize; 2], f64) {
        let mut best = (self.hull[0], 0.0, f64::INFINITY);
        for &edge in &self.hull {
            let (a, b) = (self.points[edge[0]], self.points[edge[1]]);
            let d = sub(b, a);
            let s = (dot(sub(p, a), d) / dot(d, d)).clamp(0.0, 1.0);
            let q = [a[0] + s * d[0], a[1] + s * d[1]];
            let e = sub(p, q);
            let distance = dot(e, e);
            if distance < best.2 {
                best = (edge, s, distance);
            }
        }
        (best.0, best.1)
    }
}

fn check_points(points: &[[f64; 2]]) -> Result<(), Degeneracy> {
    if points.is_empty() {
        return Err(Degeneracy::Empty);
    }
    for i in 0..points.len() {
        if let Some(j) = (i + 1..points.len()).find(|&j| points[i] == points[j]) {
            return Err(Degeneracy::Coincident(i, j));
        }
    }
    let spread = (0..points.len())
        .any(|i| (i + 1..points.len()).any(|j| (j + 1..points.len()).any(|k| orient(points, i, j, k).abs() > EPSILON)));
    if spread { Ok(()) } else { Err(Degeneracy::Collinear) }
}

/// Twice the signed area of `(i, j, k)`: positive counter-clockwise.
fn orient(p: &[[f64; 2]], i: usize, j: usize, k: usize) -> f64 {
    let (a, b) = (sub(p[j], p[i]), sub(p[k], p[i]));
    a[0] * b[1] - a[1] * b[0]
}

/// The Delaunay cells (point sets on an empty circle), each split into
/// counter-clockwise triangles by the fan from its lowest index.
fn triangulate(p: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let n = p.len();
    let mut cells: Vec<Vec<usize>> = Vec::new();
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let Some(cell) = empty_circle(p, [i, j, k]) else { continue };
                if cells.contains(&cell) {
                    continue;
                }
                triangles.extend(fan(p, &cell));
                cells.push(cell);
            }
        }
    }
    triangles
}

/// Every point on the circle through `t` (sorted), if no point is inside it.
fn empty_circle(p: &[[f64; 2]], t: [usize; 3]) -> Option<Vec<usize>> {
    if orient(p, t[0], t[1], t[2]).abs() <= EPSILON {
        return None;
    }
    let (center, r2) = circumcircle(p[t[0]], p[t[1]], p[t[2]]);
    let tolerance = EPSILON * r2.max(1.0);
    let mut on = Vec::new();
    for (m, &q) in p.iter().enumerate() {
        let e = sub(q, center);
        let d = dot(e, e) - r2;
        if d < -tolerance {
            return None;
        }
        if d <= tolerance {
            on.push(m);
        }
    }
    Some(on)
}

/// The fan from the cell's lowest index (its first) over its points in
/// counter-clockwise order around the circle.
fn fan(p: &[[f64; 2]], cell: &[usize]) -> Vec<[usize; 3]> {
    let first = cell[0];
    let (center, _) = circumcircle(p[cell[0]], p[cell[1]], p[cell[2]]);
    let angle = |m: usize| {
        let e = sub(p[m], center);
        e[1].atan2(e[0])
    };
    let mut around: Vec<usize> = cell.to_vec();
    around.sort_by(|&a, &b| angle(a).total_cmp(&angle(b)));
    let start = around.iter().position(|&m| m == first).unwrap_or(0);
    around.rotate_left(start);
    around.windows(2).skip(1).map(|w| [first, w[0], w[1]]).collect()
}

fn circumcircle(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> ([f64; 2], f64) {
    let (b, c) = (sub(b, a), sub(c, a));
    let d = 2.0 * (b[0] * c[1] - b[1] * c[0]);
    let (bb, cc) = (dot(b, b), dot(c, c));
    let ux = (c[1] * bb - b[1] * cc) / d;
    let uy = (b[0] * cc - c[0] * bb) / d;
    ([a[0] + ux, a[1] + uy], ux * ux + uy * uy)
}

fn triangle(p: &[[f64; 2]], corners: [usize; 3]) -> Triangle {
    let a = p[corners[0]];
    let (b, c) = (sub(p[corners[1]], a), sub(p[corners[2]], a));
    let det = b[0] * c[1] - b[1] * c[0];
    let inverse = [[c[1] / det, -c[0] / det], [-b[1] / det, b[0] / det]];
    Triangle { corners, a, inverse }
}

/// `(u, v)`: the weights of the second and third corners.
fn barycentric(t: &Triangle, p: [f64; 2]) -> (f64, f64) {
    let e = sub(p, t.a);
    (t.inverse[0][0] * e[0] + t.inverse[0][1] * e[1], t.inverse[1][0] * e[0] + t.inverse[1][1] * e[1])
}

/// Edges that belong to one triangle only.
fn hull_edges(triangles: &[Triangle]) -> Vec<[usize; 2]> {
    let edges: Vec<[usize; 2]> = triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.corners;
            [[a, b], [b, c], [c, a]]
        })
        .collect();
    let key = |e: [usize; 2]| (e[0].min(e[1]), e[0].max(e[1]));
    edges.iter().copied().filter(|&e| edges.iter().filter(|&&f| key(f) == key(e)).count() == 1).collect()
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sorted(mut t: Vec<[usize; 3]>) -> Vec<[usize; 3]> {
        for c in &mut t {
            c.sort_unstable();
        }
        t.sort_unstable();
        t
    }

    #[test]
    fn a_square_is_split_by_the_fan_from_its_lowest_index() {
        // Corners 0..3 around a unit square: the diagonal from 0.
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let plane = Plane::new(&square).unwrap();
        assert_eq!(sorted(plane.triangles().collect()), vec![[0, 1, 2], [0, 2, 3]]);
        // The same square listed from another corner: the diagonal from point 0 again.
        let turned = [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]];
        let plane = Plane::new(&turned).unwrap();
        assert_eq!(sorted(plane.triangles().collect()), vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn a_point_inside_a_circle_takes_the_delaunay_diagonal() {
        // A kite whose short diagonal is the Delaunay one.
        let kite = [[0.0, 0.0], [1.0, 0.4], [2.0, 0.0], [1.0, -0.4]];
        let plane = Plane::new(&kite).unwrap();
        assert_eq!(sorted(plane.triangles().collect()), vec![[0, 1, 3], [1, 2, 3]]);
    }

    #[test]
    fn outside_the_hull_the_nearest_edge_or_corner_wins() {
        let triangle = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let plane = Plane::new(&triangle).unwrap();
        let mut w = [0.0; 3];
        plane.weights([0.25, -1.0], &mut w);
        assert_eq!(w, [0.75, 0.25, 0.0]);
        plane.weights([-1.0, -1.0], &mut w);
        assert_eq!(w, [1.0, 0.0, 0.0]);
        plane.weights([0.2, 0.3], &mut w);
        assert!((w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.2).abs() < 1e-12 && (w[2] - 0.3).abs() < 1e-12);
    }

    #[test]
    fn degenerate_spaces_are_refused() {
        assert_eq!(Plane::new(&[[0.0, 0.0], [0.5, 0.5], [1.0, 1.0]]), Err(Degeneracy::Collinear));
        assert_eq!(Plane::new(&[[0.0, 0.0], [1.0, 0.0]]), Err(Degeneracy::Collinear));
        assert_eq!(Plane::new(&[[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]]), Err(Degeneracy::Coincident(0, 2)));
        assert_eq!(Line::new(&[1.0, 0.0, 1.0]), Err(Degeneracy::Coincident(0, 2)));
        assert_eq!(Line::new(&[]), Err(Degeneracy::Empty));
    }

    #[test]
    fn a_line_interpolates_its_neighbours_and_clamps() {
        let line = Line::new(&[5.0, 0.0, 1.5]).unwrap();
        let mut w = [0.0; 3];
        line.weights(3.25, &mut w);
        assert_eq!(w, [0.5, 0.0, 0.5]);
        line.weights(-1.0, &mut w);
        assert_eq!(w, [0.0, 1.0, 0.0]);
        line.weights(9.0, &mut w);
        assert_eq!(w, [1.0, 0.0, 0.0]);
    }
}
