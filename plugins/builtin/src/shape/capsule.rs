//! Capsules (spherocylinders): the points within `radius` of a segment of `length`, a body kind
//! of its own. In the body frame the segment runs along z, from `-length/2` to `length/2`,
//! through the centre of mass.
//!
//! Contacts are those of the swept spheres: between two capsules, along the line joining the
//! closest points of their segments; against a sphere, from the segment's point nearest the
//! centre; against a plane, one contact whose depth is the deeper end's and whose point is the
//! ends' points weighed by their depths (a capsule lying flat bears at its middle, one tilting
//! shifts its bearing continuously towards the end going down).

use super::golden_least;
use granite_core::dem::mesh_walls::closest_on_triangle;
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::error::{GraniteError, Result};
use granite_core::ext::body::{
    Ball, BodyGeometry, BodyKindFactory, BodyShape, KindBodies, PairFailure, PlacedBodies, Plane, Touch, WarmStarts,
};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use std::f64::consts::PI;
use std::sync::Arc;

pub struct CapsuleKind;

const SPECS: &[ParamSpec] = &[
    ParamSpec::required("radius", "radius of the capsule (of its cylinder and end caps) in m, > 0"),
    ParamSpec::required("length", "length of its cylinder (between the centres of the end caps) in m, >= 0"),
];

impl BodyKindFactory for CapsuleKind {
    fn name(&self) -> &str {
        "capsule"
    }
    fn description(&self) -> &str {
        "spherocylinders: a cylinder of `length` with hemispherical caps of `radius`"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn build(&self, params: Params) -> Result<Arc<dyn BodyShape>> {
        let radius = params.positive("radius")?;
        let length = params.get("length");
        if !(length >= 0.0 && length.is_finite()) {
            return Err(GraniteError::param_in(format!("`length` of {}", params.owner()), length, "must be >= 0"));
        }
        Ok(Arc::new(Capsule { radius, half: 0.5 * length }))
    }
    fn values_per_shape(&self) -> usize {
        2
    }
    fn geometry(&self) -> Arc<dyn BodyGeometry> {
        Arc::new(CapsuleGeometry)
    }
}

/// A capsule of `radius` around the segment from `-half` to `half` along z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    pub radius: f64,
    pub half: f64,
}

impl Capsule {
    /// Volumes of the cylinder and of the two caps together (a sphere).
    fn parts(&self) -> (f64, f64) {
        let r = self.radius;
        (PI * r * r * 2.0 * self.half, 4.0 / 3.0 * PI * r * r * r)
    }
}

impl BodyShape for Capsule {
    fn kind(&self) -> &str {
        "capsule"
    }
    fn params(&self) -> granite_core::params::ParamMap {
        [("radius".to_string(), self.radius), ("length".to_string(), 2.0 * self.half)].into_iter().collect()
    }
    fn values(&self) -> Vec<f64> {
        vec![self.radius, self.half]
    }
    fn bounding_radius(&self) -> f64 {
        self.radius + self.half
    }
    fn volume(&self) -> f64 {
        let (cylinder, caps) = self.parts();
        cylinder + caps
    }
    fn inertia_per_density(&self) -> Vec3 {
        let (r, h) = (self.radius, self.half);
        let (cylinder, caps) = self.parts();
        let axial = cylinder * r * r / 2.0 + caps * 2.0 / 5.0 * r * r;
        // Each cap about a diameter through the capsule's centre: its own 2/5 m r^2 about its base,
        // moved to its centroid (3r/8 from the base), then to the centre (h + 3r/8 away).
        let across =
            cylinder * (r * r / 4.0 + (2.0 * h) * (2.0 * h) / 12.0) + caps * (0.4 * r * r + h * h + 0.75 * h * r);
        [across, across, axial]
    }
    fn surface(&self) -> (Vec<Vec3>, Vec<[usize; 3]>) {
        const AROUND: usize = 16;
        const CAP_RINGS: usize = 4;
        let (r, h) = (self.radius, self.half);
        // Rings from the bottom pole to the top one: the lower cap's, then the upper cap's.
        let mut rings: Vec<(f64, f64)> = Vec::new();
        for k in 1..=CAP_RINGS {
            let a = -PI / 2.0 + PI / 2.0 * k as f64 / CAP_RINGS as f64;
            rings.push((r * a.cos(), -h + r * a.sin()));
        }
        for k in 0..CAP_RINGS {
            let a = PI / 2.0 * k as f64 / CAP_RINGS as f64;
            rings.push((r * a.cos(), h + r * a.sin()));
        }
        let mut points = vec![[0.0, 0.0, -h - r]];
        for &(rho, z) in &rings {
            for j in 0..AROUND {
                let t = 2.0 * PI * j as f64 / AROUND as f64;
                points.push([rho * t.cos(), rho * t.sin(), z]);
            }
        }
        points.push([0.0, 0.0, h + r]);
        let top = points.len() - 1;
        let at = |ring: usize, j: usize| 1 + ring * AROUND + j % AROUND;
        let mut triangles = Vec::new();
        for j in 0..AROUND {
            triangles.push([0, at(0, j + 1), at(0, j)]);
            for ring in 0..rings.len() - 1 {
                triangles.push([at(ring, j), at(ring, j + 1), at(ring + 1, j + 1)]);
                triangles.push([at(ring, j), at(ring + 1, j + 1), at(ring + 1, j)]);
            }
            triangles.push([at(rings.len() - 1, j), at(rings.len() - 1, j + 1), top]);
        }
        (points, triangles)
    }
    fn contains(&self, p: Vec3) -> bool {
        let z = p[2].clamp(-self.half, self.half);
        p[0] * p[0] + p[1] * p[1] + (p[2] - z) * (p[2] - z) <= self.radius * self.radius
    }
    /// The centres of the end caps: a heap's surface follows both ends.
    fn monitor_points(&self) -> Vec<Vec3> {
        vec![[0.0, 0.0, -self.half], [0.0, 0.0, self.half]]
    }
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

struct CapsuleGeometry;

impl BodyGeometry for CapsuleGeometry {
    fn meets_bounded_walls(&self) -> bool {
        true
    }
    /// Two contact points with a wall: a capsule lying on it bears on both ends.
    fn body_points(&self) -> usize {
        2
    }

    fn wall_points(&self) -> usize {
        2
    }
    fn place<'a>(&'a self, bodies: KindBodies<'a>) -> Result<Box<dyn PlacedBodies + 'a>> {
        // Each capsule's axis turned into the world once a step, not once per pair.
        let segments = (0..bodies.x.len())
            .map(|i| if bodies.owns(i) { segment(&bodies, i) } else { ([0.0; 3], [0.0; 3], 0.0) })
            .collect();
        Ok(Box::new(PlacedCapsules { bodies, segments }))
    }
}

/// Capsules at a step's start: their segments are found per pair from the poses (a segment costs
/// a rotation, less than keeping it).
struct PlacedCapsules<'a> {
    bodies: KindBodies<'a>,
    /// Each body's segment (ends and radius, world frame), zeros for another family's.
    segments: Vec<(Vec3, Vec3, f64)>,
}

/// The segment of capsule `i`: its ends and radius, in the world frame.
pub(crate) fn segment(bodies: &KindBodies<'_>, i: usize) -> (Vec3, Vec3, f64) {
    let v = bodies.values_of(i);
    let (r, half) = (v[0], v[1]);
    let axis = bodies.q[i] * nalgebra::Vector3::z();
    let x = bodies.x[i];
    let end = |s: f64| [x[0] + s * half * axis[0], x[1] + s * half * axis[1], x[2] + s * half * axis[2]];
    (end(-1.0), end(1.0), r)
}

pub(crate) fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn along(a: Vec3, d: Vec3, t: f64) -> Vec3 {
    [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]]
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The point of segment `[a, b]` nearest `p`.
pub(crate) fn nearest_on(a: Vec3, b: Vec3, p: Vec3) -> Vec3 {
    let d = sub(b, a);
    let dd = dot(d, d);
    let t = if dd > 0.0 { (dot(sub(p, a), d) / dd).clamp(0.0, 1.0) } else { 0.0 };
    along(a, d, t)
}

/// The closest points of segments `[p0, p1]` and `[q0, q1]`.
pub fn closest_points(p0: Vec3, p1: Vec3, q0: Vec3, q1: Vec3) -> (Vec3, Vec3) {
    let (d1, d2, r) = (sub(p1, p0), sub(q1, q0), sub(p0, q0));
    let (a, e, f) = (dot(d1, d1), dot(d2, d2), dot(d2, r));
    let tiny = f64::EPSILON * (a + e).max(f64::MIN_POSITIVE);
    let (s, t) = if a <= tiny && e <= tiny {
        (0.0, 0.0)
    } else if a <= tiny {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = dot(d1, r);
        if e <= tiny {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            // Parallel segments: any s; the first end's.
            let mut s = if denom > tiny * (a + e) { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (along(p0, d1, s), along(q0, d2, t))
}

/// The touch of two swept spheres whose centres are `a` and `b` (radii `ra`, `rb`), the normal
/// from `a` to `b`; `fallback` is the normal to use when the centres coincide.
fn swept_touch(a: Vec3, ra: f64, b: Vec3, rb: f64, fallback: Vec3) -> Option<Touch> {
    let d = sub(b, a);
    let distance = dot(d, d).sqrt();
    let overlap = ra + rb - distance;
    if !(overlap > 0.0) {
        return None;
    }
    let normal = if distance > 0.0 { d.map(|c| c / distance) } else { fallback };
    Some(Touch { normal, overlap, point: along(a, normal, ra - 0.5 * overlap) })
}

/// A unit vector, or `z` for a zero one.
fn unit_or_z(v: Vec3) -> Vec3 {
    let n = dot(v, v).sqrt();
    if n > 0.0 {
        v.map(|c| c / n)
    } else {
        [0.0, 0.0, 1.0]
    }
}

impl PlacedBodies for PlacedCapsules<'_> {
    fn pairs(
        &self,
        pairs: &[(u32, u32, u8)],
        _: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        let bodies = &self.bodies;
        // A pair's contact points are consecutive entries: both are found at its first.
        let mut last: Option<((u32, u32), PairTouches)> = None;
        for (slot, &(i, j, part)) in out.iter_mut().zip(pairs) {
            let touches = match last {
                Some((pair, touches)) if pair == (i, j) => touches,
                _ => {
                    let (a, b) = (self.segments[i as usize], self.segments[j as usize]);
                    // Segments crossing each other: across both axes, towards the second body.
                    let across = cross(sub(a.1, a.0), sub(b.1, b.0));
                    let towards = sub(bodies.x[j as usize], bodies.x[i as usize]);
                    let fallback = unit_or_z(if dot(across, towards) < 0.0 { across.map(|c| -c) } else { across });
                    let touches = pair_touches(a, b, fallback);
                    last = Some(((i, j), touches));
                    touches
                }
            };
            *slot = touches.get(part as usize).copied().flatten();
        }
        Ok(())
    }

    fn planes(
        &self,
        pairs: &[(u32, Plane)],
        _: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        for (slot, &(i, plane)) in out.iter_mut().zip(pairs) {
            let (e0, e1, r) = self.segments[i as usize];
            // Part 0 bears on the first end, part 1 on the second: the spheres of the axis that
            // go deepest into a plane are at its ends (the depth is linear along it). A capsule
            // of no length is a sphere: one contact.
            let end = match plane.part {
                0 => e0,
                _ if e0 == e1 => {
                    *slot = None;
                    continue;
                }
                _ => e1,
            };
            let n = plane.normal;
            let overlap = r - dot(sub(end, plane.point), n);
            let inward = n.map(|c| -c);
            *slot = (overlap > 0.0).then(|| Touch {
                normal: inward,
                overlap,
                point: along(end, inward, r - 0.5 * overlap),
            });
        }
        Ok(())
    }

    fn spheres(
        &self,
        pairs: &[(u32, Ball)],
        _: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        for (slot, &(i, ball)) in out.iter_mut().zip(pairs) {
            let (e0, e1, r) = self.segments[i as usize];
            let p = nearest_on(e0, e1, ball.centre);
            let fallback = unit_or_z(cross(sub(e1, e0), [1.0, 0.0, 0.0]));
            *slot = swept_touch(p, r, ball.centre, ball.radius, fallback);
        }
        Ok(())
    }

    fn bounded_walls(
        &self,
        pairs: &[(u32, &Wall, u8)],
        _: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        for (slot, &(i, wall, part)) in out.iter_mut().zip(pairs) {
            *slot = wall_touch(self.segments[i as usize], wall, part);
        }
        Ok(())
    }
}

/// A capsule pair's touches at its two contact points (parts 0 and 1).
type PairTouches = [Option<Touch>; 2];

/// The touches of capsules `a` and `b` (segment ends and radius each) at their two contact points
/// (parts 0 and 1), the same whichever capsule is first (a capsule and its periodic image are found under
/// one order, the same two in a larger cell under either). One contact is the deepest: at the
/// closest points of the two axes, or, for parallel axes, at the deeper end of their overlap.
/// The other is the end of the overlap farthest from it, where it presses: an end sphere of one
/// capsule that lies along the other's axis (its foot on the other's segment), against the other
/// capsule. So two capsules lying along each other bear at both ends of their overlap, each force
/// that of a point of one body (the pair's forces derive from an energy), and crossed capsules
/// meet at their closest points. Part 0 is the contact lower along `a`'s axis, part 1 the upper,
/// so that each keeps its history as the capsules move. `fallback` is the normal where the axes
/// meet.
fn pair_touches(a: (Vec3, Vec3, f64), b: (Vec3, Vec3, f64), fallback: Vec3) -> PairTouches {
    let ((a0, a1, ra), (b0, b1, rb)) = (a, b);
    let (da, db) = (sub(a1, a0), sub(b1, b0));
    let (aa, bb) = (dot(da, da), dot(db, db));
    // A contact as a point of `a`'s axis and one of `b`'s; its touch where it is chosen.
    let touch = |(pa, pb): (Vec3, Vec3)| swept_touch(pa, ra, pb, rb, fallback);
    let closest = closest_points(a0, a1, b0, b1);
    if aa == 0.0 || bb == 0.0 {
        // A capsule of no length is a sphere: one contact.
        return [touch(closest), None];
    }
    // The end spheres lying along the other capsule's axis, against it.
    let foot = |p: Vec3, (e0, d, dd): (Vec3, Vec3, f64)| (0.0..=1.0).contains(&(dot(sub(p, e0), d) / dd));
    let candidates = [
        (foot(a0, (b0, db, bb)), (a0, nearest_on(b0, b1, a0))),
        (foot(a1, (b0, db, bb)), (a1, nearest_on(b0, b1, a1))),
        (foot(b0, (a0, da, aa)), (nearest_on(a0, a1, b0), b0)),
        (foot(b1, (a0, da, aa)), (nearest_on(a0, a1, b1), b1)),
    ];
    let ends = || candidates.iter().filter(|(on, _)| *on).map(|&(_, c)| c);
    let gap = |(pa, pb): &(Vec3, Vec3)| {
        let d = sub(*pb, *pa);
        dot(d, d)
    };
    let across = cross(da, db);
    let parallel = dot(across, across) <= 1e-24 * aa * bb;
    let deepest = match ends().min_by(|x, y| gap(x).total_cmp(&gap(y))) {
        Some(end) if parallel => end,
        _ => closest,
    };
    let middle = |(pa, pb): &(Vec3, Vec3)| along(*pa, sub(*pb, *pa), 0.5);
    let apart = |c: &(Vec3, Vec3)| {
        let d = sub(middle(c), middle(&deepest));
        dot(d, d)
    };
    // The other end of the overlap: the end sphere farthest from the deepest contact (an end
    // found twice, where the two capsules' ends meet, counts once).
    let reach = 1e-12 * (aa + bb);
    let Some(other) = ends().filter(|c| apart(c) > reach).max_by(|x, y| apart(x).total_cmp(&apart(y))) else {
        return [touch(deepest), None];
    };
    if dot(da, deepest.0) <= dot(da, other.0) {
        [touch(deepest), touch(other)]
    } else {
        [touch(other), touch(deepest)]
    }
}

/// Steps of the golden-section search along a capsule's axis: its bracket shrinks to 0.618^40,
/// about 4e-9 of the axis.
const GOLDEN_STEPS: usize = 40;

/// The touch of the capsule of segment `[e0, e1]` and radius `r` with a wall of a bounded shape,
/// for its contact point `part`, from the spheres of its axis (the gap `g(t)` of the sphere at
/// `c(t)`, as `Wall::contact` gives a sphere's). Where the gap rises or stays level inwards from
/// both ends, the least is at an end: part 0 bears on the first end, part 1 on the second, each
/// where it presses, as on a plane (a capsule lying on a face, or over two triangles of a flat
/// mesh, bears on each with the end over it). Where the gap falls inwards (the axis across an
/// edge), the sphere that meets the wall most is found by a golden-section search (the distance
/// to a flat convex shape is convex along the axis) and is the part of its half of the axis; the
/// other part is its end, where that presses. A triangle of a wall mesh meets the spheres by its
/// own rules for shared edges and corners (a sphere a neighbour counts has no gap with it).
fn wall_touch((e0, e1, r): (Vec3, Vec3, f64), wall: &Wall, part: u8) -> Option<Touch> {
    let d = sub(e1, e0);
    let gap = |t: f64| wall.contact(along(e0, d, t), r, f64::INFINITY).map_or(f64::INFINITY, |c| c.gap);
    // No sphere of the axis is nearer the wall than the middle's by more than half the axis
    // (a triangle's distance taken to the whole triangle: the gap leaves out the edges and
    // corners its neighbours count).
    let half = 0.5 * dot(d, d).sqrt();
    let middle = along(e0, d, 0.5);
    let middle_gap = match &wall.shape {
        WallShape::Triangle { b, c, .. } => {
            let (q, _) = closest_on_triangle(sub(middle, wall.position), [0.0; 3], *b, *c);
            let off = sub(sub(middle, wall.position), q);
            dot(off, off).sqrt() - r
        }
        _ => gap(0.5),
    };
    if middle_gap.is_finite() && middle_gap > half {
        return None;
    }
    if part > 0 && d == [0.0; 3] {
        // A capsule of no length is a sphere: one contact.
        return None;
    }
    let (g0, g1) = (gap(0.0), gap(1.0));
    // The gap rising (or level) inwards from both ends: least at the ends (convex or, for a
    // cylinder's inner face, concave along the axis, or level along a face).
    let (step, level) = (1e-6, 1e-12 * r);
    let ends_least = gap(step) >= g0 - level && gap(1.0 - step) >= g1 - level;
    let end = if part == 0 { (0.0, g0) } else { (1.0, g1) };
    let (t, least) = if ends_least {
        end
    } else {
        let (inner, g_inner) = golden_least(&gap, (0.0, 1.0), GOLDEN_STEPS);
        if (inner < 0.5) == (part == 0) {
            (inner, g_inner)
        } else {
            end
        }
    };
    if !(least < 0.0) {
        return None;
    }
    let centre = along(e0, d, t);
    let contact = wall.contact(centre, r, f64::INFINITY)?;
    let (n, overlap) = (contact.normal, -contact.gap);
    Some(Touch { normal: n, overlap, point: along(centre, n, r - 0.5 * overlap) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_points_of_crossed_skew_and_parallel_segments() {
        let near = |a: Vec3, b: Vec3| dot(sub(a, b), sub(a, b)).sqrt() < 1e-15;
        // Crossed at right angles, 0.3 apart along z.
        let (p, q) = closest_points([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.2, -1.0, 0.3], [0.2, 1.0, 0.3]);
        assert!(near(p, [0.2, 0.0, 0.0]) && near(q, [0.2, 0.0, 0.3]), "{p:?} {q:?}");
        // One ends short of the other: its end is nearest.
        let (p, q) = closest_points([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [2.0, 3.0, 0.0]);
        assert!(near(p, [1.0, 0.0, 0.0]) && near(q, [2.0, 1.0, 0.0]), "{p:?} {q:?}");
        // Parallel, overlapping along x, 0.5 apart: any pair of facing points, 0.5 apart.
        let (p, q) = closest_points([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.5, 0.0], [3.0, 0.5, 0.0]);
        let d = sub(q, p);
        assert!((dot(d, d).sqrt() - 0.5).abs() < 1e-15, "{p:?} {q:?}");
    }

    #[test]
    fn mass_properties_tend_to_a_sphere_and_to_a_long_rod() {
        let r = 0.1;
        let ball = Capsule { radius: r, half: 0.0 };
        let sphere_i = 2.0 / 5.0 * ball.volume() * r * r;
        for i in ball.inertia_per_density() {
            assert!((i - sphere_i).abs() < 1e-15 * sphere_i);
        }
        // A long thin capsule: about m L^2 / 12 across, m r^2 / 2 along its axis.
        let rod = Capsule { radius: 1e-3, half: 0.5 };
        let m = rod.volume();
        let [across, _, axial] = rod.inertia_per_density();
        assert!((across / (m * 1.0 / 12.0) - 1.0).abs() < 1e-2, "{across}");
        assert!((axial / (m * 1e-6 / 2.0) - 1.0).abs() < 0.01, "{axial}");
    }
}
