//! A potential particle against a wall of bounded shape: a rectangle, a disk, a cylinder's shell
//! or a triangle of a wall mesh.
//!
//! The particle meets such a wall at the wall's point deepest in its potential,
//! `w* = argmin f(w)` over the wall: they touch when `f(w*) < 0` (a point of the wall lies inside
//! the particle). `f` is convex, so on a flat wall (triangle, rectangle, disk: convex regions of a
//! plane) the problem is convex: the least of `f` over the wall's whole plane (Newton's method in
//! the plane: `f` is piecewise quadratic and strongly convex through its shadow sphere) is the
//! answer when it lies in the region; otherwise the answer lies on the region's boundary, found
//! edge by edge (a golden-section search on each segment, along which `f` is convex) or along a
//! disk's rim.
//!
//! - **Inside the region** the particle meets the wall as it meets the wall's plane (the plane
//!   contact of `detect_plane`: its deepest point below the plane), so that a particle on a
//!   rectangle steps as on a plane.
//! - **On the boundary** (an edge or a corner presses into the particle) the normal is the
//!   particle's `grad f` at `w*`, and the overlap the length from `w*` to the particle's surface
//!   along it.
//! - A **triangle of a wall mesh** counts a shared edge or corner as the mesh's rules do for a
//!   sphere (`mesh_walls`): once, by the triangle owning it, and only where every neighbour
//!   sharing it finds its own least there too (on its boundary, no lower); a neighbour holding
//!   its least inside makes the contact itself. So across a flat seam only the triangle holding
//!   the plane's least counts, over a ridge the owner of the ridge, in a valley each face.
//! - A **cylinder's shell** is curved: Newton's method on its angle and height from the point
//!   nearest the particle's centre, then, where that leaves the shell's length, a search along
//!   the rim it crossed; the touch is that of a boundary point.

use super::super::golden_least;
use super::contact::{along_ray, detect_plane, Placed};
use granite_core::dem::mesh_walls::{closest_on_triangle, feature, FacetRing};
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::ext::body::Touch;
use granite_core::math::{cross3, dot3, sub3, Vec3};
use nalgebra::{Matrix2, Vector2};

/// Steps of a golden-section search: its bracket shrinks to 0.618^50, about 4e-11 of it.
const GOLDEN_STEPS: usize = 50;
/// How near a region's boundary, relative to the particle's bounding radius, the least of the
/// plane lies on it: well above the Newton solve's error (1e-13).
const BOUNDARY_REACH: f64 = 1e-9;
/// Most Newton steps of a search over a wall's plane or shell.
const NEWTON_STEPS: usize = 50;

fn at(o: Vec3, d: Vec3, t: f64) -> Vec3 {
    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
}

fn unit(v: Vec3) -> Vec3 {
    let n = dot3(v, v).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

/// Two unit vectors spanning the plane normal to unit `n`.
fn basis(n: Vec3) -> [Vec3; 2] {
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let u = unit(cross3(n, helper));
    [u, cross3(n, u)]
}

/// The least of `g` on `[lo, hi]` by a golden-section search, its ends included (the least of a
/// convex function on a segment may be at one of them): `(t, g(t))`.
fn least_on(g: impl Fn(f64) -> f64, (lo, hi): (f64, f64)) -> (f64, f64) {
    let inner = golden_least(&g, (lo, hi), GOLDEN_STEPS);
    [(lo, g(lo)), (hi, g(hi)), inner].into_iter().min_by(|x, y| x.1.total_cmp(&y.1)).unwrap_or(inner)
}

/// Newton's method with backtracking on a function of two variables given with its gradient and
/// Hessian, from `start`; a step along the gradient where the Hessian is not positive. Stops when
/// a step is below `tolerance`.
fn newton_least(
    value: impl Fn(Vector2<f64>) -> (f64, Vector2<f64>, Matrix2<f64>),
    start: Vector2<f64>,
    tolerance: f64,
) -> Vector2<f64> {
    let mut u = start;
    for _ in 0..NEWTON_STEPS {
        let (f, g, h) = value(u);
        let step = match h.cholesky() {
            Some(c) => -c.solve(&g),
            None => -g * (tolerance / g.norm().max(f64::MIN_POSITIVE)),
        };
        let mut t = 1.0;
        while t > 1e-8 && value(u + step * t).0 > f {
            t *= 0.5;
        }
        u += step * t;
        if (step * t).norm() <= tolerance {
            break;
        }
    }
    u
}

/// The touch where wall point `w` (inside the particle) presses into it: along the particle's
/// gradient at `w`, up to its surface.
fn boundary_touch(p: &Placed, w: Vec3) -> Option<Touch> {
    let (f, g) = p.value_gradient(w);
    if !(f < 0.0) || g.norm() == 0.0 {
        return None;
    }
    let normal = unit([g[0], g[1], g[2]]);
    let depth = along_ray(p, w, normal, 2.0 * p.bounding_radius, 0.0);
    Some(Touch { normal, overlap: depth, point: at(w, normal, 0.5 * depth) })
}

/// A flat wall's region: a convex polygon (corners counter-clockwise about the normal, world
/// frame) or a disk about the plane's origin.
enum Region {
    /// Up to four corners, the first `count` of the array (no allocation per contact).
    Polygon([Vec3; 4], usize),
    Disk(f64),
}

/// A flat region of a plane through `origin` with unit `normal`, spanned by `e`.
struct Flat {
    origin: Vec3,
    normal: Vec3,
    e: [Vec3; 2],
    region: Region,
}

/// The least of a particle's potential over a flat region.
struct Least {
    /// Where it is, and its value.
    point: Vec3,
    value: f64,
    /// How far inside the region the least of the whole plane lies (negative: outside, the
    /// least then on the region's boundary).
    margin: f64,
}

impl Flat {
    /// A triangle of corners `a`, `b`, `c` (world frame).
    fn triangle(a: Vec3, b: Vec3, c: Vec3) -> Flat {
        let (ab, ac) = (sub3(b, a), sub3(c, a));
        let normal = unit(cross3(ab, ac));
        Flat { origin: a, normal, e: [unit(ab), unit(cross3(normal, ab))], region: Region::Polygon([a, b, c, c], 3) }
    }

    fn point_of(&self, u: Vector2<f64>) -> Vec3 {
        at(at(self.origin, self.e[0], u[0]), self.e[1], u[1])
    }

    fn in_plane(&self, w: Vec3) -> Vector2<f64> {
        let d = sub3(w, self.origin);
        Vector2::new(dot3(d, self.e[0]), dot3(d, self.e[1]))
    }

    /// The least of `p`'s potential over the region: the least over the whole plane (Newton's
    /// method from the centre's foot) where it lies inside, else the least over the boundary.
    fn least(&self, p: &Placed) -> Least {
        let e = self.e.map(|v| nalgebra::Vector3::new(v[0], v[1], v[2]));
        let value = |u: Vector2<f64>| {
            let (f, g, h) = p.value_gradient_hessian(self.point_of(u));
            let grad = Vector2::new(g.dot(&e[0]), g.dot(&e[1]));
            let hess = Matrix2::new(
                e[0].dot(&(h * e[0])),
                e[0].dot(&(h * e[1])),
                e[1].dot(&(h * e[0])),
                e[1].dot(&(h * e[1])),
            );
            (f, grad, hess)
        };
        let least = newton_least(value, self.in_plane(p.position), 1e-13 * p.bounding_radius);
        let margin = match &self.region {
            Region::Polygon(corners, count) => (0..*count)
                .map(|k| {
                    let (a, b) = (self.in_plane(corners[k]), self.in_plane(corners[(k + 1) % count]));
                    let (edge, to) = (b - a, least - a);
                    (edge[0] * to[1] - edge[1] * to[0]) / edge.norm()
                })
                .fold(f64::INFINITY, f64::min),
            Region::Disk(r) => r - least.norm(),
        };
        if margin >= 0.0 {
            let point = self.point_of(least);
            return Least { point, value: p.value(point), margin };
        }
        let f = |w: Vec3| p.value(w);
        let (point, value) = match &self.region {
            Region::Polygon(corners, count) => (0..*count)
                .map(|k| {
                    let (a, b) = (corners[k], corners[(k + 1) % count]);
                    let d = sub3(b, a);
                    let (t, value) = least_on(|t| f(at(a, d, t)), (0.0, 1.0));
                    (at(a, d, t), value)
                })
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .unwrap_or((self.origin, f64::INFINITY)),
            Region::Disk(r) => {
                // The least lies within a right angle of the plane's least, seen from the centre.
                let towards = least[1].atan2(least[0]);
                let rim = |phi: f64| self.point_of(Vector2::new(r * phi.cos(), r * phi.sin()));
                let quarter = 0.5 * std::f64::consts::PI;
                let (phi, value) = least_on(|phi| f(rim(phi)), (towards - quarter, towards + quarter));
                (rim(phi), value)
            }
        };
        Least { point, value, margin }
    }
}

/// The contact of particle `p` with `wall`, a wall of bounded shape (a plane is met by
/// `detect_plane`); None when apart. Fails only where `detect_plane` does (its message).
pub fn bounded_wall_touch(p: &Placed, wall: &Wall) -> std::result::Result<Option<Touch>, String> {
    let o = wall.position;
    let size = p.bounding_radius;
    // Out of reach: the wall's closest point to the centre beyond the bounding radius (a mesh
    // triangle's whole face taken: what its neighbours count is decided below).
    let nearest = match &wall.shape {
        WallShape::Triangle { b, c, .. } => {
            let (q, _) = closest_on_triangle(sub3(p.position, o), [0.0; 3], *b, *c);
            let d = sub3(sub3(p.position, o), q);
            dot3(d, d).sqrt()
        }
        _ => match wall.contact(p.position, 0.0, f64::INFINITY) {
            Some(c) => c.gap,
            None => return Ok(None),
        },
    };
    if nearest > size {
        return Ok(None);
    }
    let flat = match &wall.shape {
        WallShape::Plane { .. } => return Ok(None),
        WallShape::Cylinder { axis, radius, length } => return Ok(shell_touch(p, o, (*axis, *radius, *length))),
        WallShape::Triangle { b, c, .. } => Flat::triangle(o, at(o, *b, 1.0), at(o, *c, 1.0)),
        WallShape::Rect { u, v, half } => {
            let corner = |su: f64, sv: f64| at(at(o, *u, su * half[0]), *v, sv * half[1]);
            let corners = [corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)];
            Flat { origin: o, normal: unit(cross3(*u, *v)), e: [*u, *v], region: Region::Polygon(corners, 4) }
        }
        WallShape::Disk { normal, radius } => {
            Flat { origin: o, normal: *normal, e: basis(*normal), region: Region::Disk(*radius) }
        }
    };
    let least = flat.least(p);
    if !(least.value < 0.0) {
        return Ok(None);
    }
    // The plane's least within the solve's reach of the boundary: on it.
    let on_boundary = least.margin.abs() <= BOUNDARY_REACH * size;
    if let WallShape::Triangle { ring, .. } = &wall.shape {
        if (least.margin < 0.0 || on_boundary) && !counts_here(p, &flat, ring, &least) {
            return Ok(None);
        }
    }
    if least.margin >= 0.0 || on_boundary {
        // The particle meets the wall as its plane, from the side its centre is on.
        let n = flat.normal;
        let side = if dot3(sub3(p.position, o), n) >= 0.0 { n } else { n.map(|c| -c) };
        return detect_plane(p, o, side, None).map(|(_, touch)| touch).map_err(|e| e.to_string());
    }
    Ok(boundary_touch(p, least.point))
}

/// Whether mesh triangle `flat` (neighbours `ring`) makes the contact whose least of `p`'s
/// potential lies on its boundary, by the mesh's rules: a feature it shares counts once, by its
/// owner, and only where no neighbour sharing it holds a lower value of the potential (as a
/// sphere meets a shared feature only where no neighbour is closer).
fn counts_here(p: &Placed, flat: &Flat, ring: &FacetRing, least: &Least) -> bool {
    let Region::Polygon(corners, _) = &flat.region else { return true };
    // The edges the least lies on, within the solve's reach of their lines; two: their corner.
    let reach = BOUNDARY_REACH * p.bounding_radius;
    let on_edge = |k: usize| {
        let (a, b) = (corners[k], corners[(k + 1) % 3]);
        let (edge, to) = (sub3(b, a), sub3(least.point, a));
        dot3(cross3(edge, to), flat.normal).abs() / dot3(edge, edge).sqrt() <= reach
    };
    let [ab, bc, ca] = [0, 1, 2].map(on_edge);
    let on = match (ab, bc, ca) {
        (true, _, true) => feature::CORNER_A,
        (true, true, _) => feature::CORNER_B,
        (_, true, true) => feature::CORNER_C,
        (true, _, _) => feature::EDGE_AB,
        (_, true, _) => feature::EDGE_BC,
        (_, _, true) => feature::EDGE_CA,
        _ => return true,
    };
    if !ring.others.iter().any(|(_, mask)| mask & on != 0) {
        return true;
    }
    if ring.owns & on == 0 {
        return false;
    }
    // Each neighbour sharing the feature finds its own least on its boundary too, no lower (a
    // ridge, or the least of the plane on the seam itself): a neighbour holding its least
    // inside (across a flat seam, in a valley) or a lower one makes the contact itself.
    let o = corners[0];
    let slack = 1e-12 * least.value.abs().max(1.0);
    ring.others.iter().filter(|(_, mask)| mask & on != 0).all(|(c, _)| {
        let theirs = Flat::triangle(at(o, c[0], 1.0), at(o, c[1], 1.0), at(o, c[2], 1.0)).least(p);
        theirs.margin <= reach && theirs.value >= least.value - slack
    })
}

/// The touch of particle `p` with the shell of a cylinder about `axis` from `base`, of `radius`
/// and `length` (both faces, rims included).
fn shell_touch(p: &Placed, base: Vec3, (axis, radius, length): (Vec3, f64, f64)) -> Option<Touch> {
    let e = basis(axis);
    let shell = |theta: f64, z: f64| {
        let (s, c) = theta.sin_cos();
        at(at(at(base, axis, z), e[0], radius * c), e[1], radius * s)
    };
    let d = sub3(p.position, base);
    let start = Vector2::new(dot3(d, e[1]).atan2(dot3(d, e[0])), dot3(d, axis));
    let value = |u: Vector2<f64>| {
        let (s, c) = u[0].sin_cos();
        let (f, g, h) = p.value_gradient_hessian(shell(u[0], u[1]));
        let v3 = |v: Vec3| nalgebra::Vector3::new(v[0], v[1], v[2]);
        let around = v3(e[0]) * (-radius * s) + v3(e[1]) * (radius * c);
        let out = v3(e[0]) * (radius * c) + v3(e[1]) * (radius * s);
        let a = v3(axis);
        let grad = Vector2::new(g.dot(&around), g.dot(&a));
        // The shell's curvature adds `grad f . d2w/dtheta2 = -grad f . (w - axis point)`.
        let hess = Matrix2::new(
            around.dot(&(h * around)) - g.dot(&out),
            around.dot(&(h * a)),
            a.dot(&(h * around)),
            a.dot(&(h * a)),
        );
        (f, grad, hess)
    };
    let least = newton_least(value, start, 1e-13 * p.bounding_radius);
    let w = if (0.0..=length).contains(&least[1]) {
        shell(least[0], least[1])
    } else {
        let z = least[1].clamp(0.0, length);
        // Along the rim it crossed, within the particle's angular reach of where it crossed.
        let reach = (2.0 * p.bounding_radius / radius).min(std::f64::consts::PI);
        let (theta, _) = least_on(|t| p.value(shell(t, z)), (least[0] - reach, least[0] + reach));
        shell(theta, z)
    };
    boundary_touch(p, w)
}
