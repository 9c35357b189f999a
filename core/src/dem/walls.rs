//! Walls: kinematic boundaries that move at a prescribed velocity and measure the force they take.

use crate::math::{cross3, dot3, norm3, Vec3};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum WallShape {
    /// Infinite plane through `position`; particles live on the side `normal` points to.
    Plane { normal: Vec3 },
    /// Rectangle centred on `position`, spanned by unit vectors `u` and `v` with half-sizes `half`;
    /// touched from both sides, edges and corners included.
    Rect { u: Vec3, v: Vec3, half: [f64; 2] },
    /// Disk centred on `position` with unit `normal` and `radius`, touched from both sides.
    Disk { normal: Vec3, radius: f64 },
    /// Cylindrical shell (both sides, rims included): axis through `position` along unit `axis`,
    /// from 0 to `length`.
    Cylinder { axis: Vec3, radius: f64, length: f64 },
    /// Triangle of a wall mesh (both sides, edges and corners included) with corners
    /// `position`, `position + b`, `position + c`, and the triangles around it, which decide
    /// who counts a shared edge or corner (see `mesh_walls`).
    Triangle { b: Vec3, c: Vec3, ring: crate::dem::mesh_walls::FacetRing },
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Wall {
    pub name: String,
    pub shape: WallShape,
    pub position: Vec3,
    pub velocity: Vec3,
    pub material: u16,
    /// Angular velocity (rad/s) about `pivot` (a triangle of a wall mesh; zero for the others).
    #[serde(default)]
    pub spin: Vec3,
    /// The point the wall turns about; it moves with the wall's velocity.
    #[serde(default)]
    pub pivot: Vec3,
}

/// The walls' motion: each wall moves by its velocity over the step, and a spinning triangle
/// turns about its pivot by `spin dt`. Reads the time step and where the walls were when the
/// lists were built; writes their positions and shapes, and the angle each has turned since.
/// Returns the largest distance a point of a wall moved since the lists were built (a bound:
/// its reference point's displacement plus the angle turned times its reach from that point).
pub(crate) struct WallMotion;

impl WallMotion {
    pub(crate) fn run(walls: &mut [Wall], (at_build, turned): (&[Vec3], &mut Vec<f64>), dt: f64) -> f64 {
        turned.resize(walls.len(), 0.0);
        let mut moved: f64 = 0.0;
        for ((w, at), turn) in walls.iter_mut().zip(at_build).zip(turned.iter_mut()) {
            for a in 0..3 {
                w.position[a] += w.velocity[a] * dt;
                w.pivot[a] += w.velocity[a] * dt;
            }
            let mut reach = 0.0;
            if w.spin != [0.0; 3] {
                let rotation = nalgebra::Rotation3::new(nalgebra::Vector3::from(w.spin) * dt);
                let turn_vec = |v: &mut Vec3| {
                    let r = rotation * nalgebra::Vector3::from(*v);
                    *v = [r[0], r[1], r[2]];
                };
                let mut arm = [0, 1, 2].map(|a| w.position[a] - w.pivot[a]);
                turn_vec(&mut arm);
                w.position = [0, 1, 2].map(|a| w.pivot[a] + arm[a]);
                if let WallShape::Triangle { b, c, ring } = &mut w.shape {
                    turn_vec(b);
                    turn_vec(c);
                    for (corners, _) in ring.others.iter_mut() {
                        corners.iter_mut().for_each(turn_vec);
                    }
                    reach = dot3(*b, *b).max(dot3(*c, *c)).sqrt();
                }
                *turn += dot3(w.spin, w.spin).sqrt() * dt;
            }
            let d = [0, 1, 2].map(|a| w.position[a] - at[a]);
            moved = moved.max((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() + *turn * reach);
        }
        moved
    }
}

impl Wall {
    /// What is wrong with a wall read from a saved state, if anything: its geometry must be one a
    /// contact can use (unit normals and axes, sizes finite and > 0, a triangle with an area) and
    /// its motion finite.
    pub(crate) fn check_loaded(&self) -> std::result::Result<(), String> {
        let finite = |v: &Vec3| v.iter().all(|c| c.is_finite());
        let unit = |v: &Vec3| (norm3(*v) - 1.0).abs() <= 1e-9;
        let size = |x: f64| x.is_finite() && x > 0.0;
        if !(finite(&self.position) && finite(&self.velocity) && finite(&self.spin) && finite(&self.pivot)) {
            return Err("a non-finite position, velocity, spin or pivot".into());
        }
        let shape = match &self.shape {
            WallShape::Plane { normal } if !unit(normal) => format!("plane normal {normal:?} (a unit vector)"),
            WallShape::Rect { u, v, half } if !(unit(u) && unit(v) && dot3(*u, *v).abs() <= 1e-9) => {
                format!("rectangle sides {u:?}, {v:?} (unit vectors at right angles; half sizes {half:?})")
            }
            WallShape::Rect { half, .. } if !(size(half[0]) && size(half[1])) => {
                format!("rectangle half sizes {half:?} (finite and > 0)")
            }
            WallShape::Disk { normal, radius } if !(unit(normal) && size(*radius)) => {
                format!("disk normal {normal:?}, radius {radius} (a unit normal, a radius > 0)")
            }
            WallShape::Cylinder { axis, radius, length } if !(unit(axis) && size(*radius) && size(*length)) => {
                format!("cylinder axis {axis:?}, radius {radius}, length {length} (a unit axis, sizes > 0)")
            }
            WallShape::Triangle { b, c, .. } if !(finite(b) && finite(c) && size(norm3(cross3(*b, *c)))) => {
                format!("triangle edges {b:?}, {c:?} (finite, spanning an area)")
            }
            _ => return Ok(()),
        };
        Err(shape)
    }

    /// Whether `other` is the same surface (a plane given through another of its points included):
    /// spheres would touch both, with twice the stiffness.
    pub fn same_surface(&self, other: &Wall) -> bool {
        let offset: Vec3 = [0, 1, 2].map(|a| self.position[a] - other.position[a]);
        let scale = 1e-12 * (1.0 + dot3(self.position, self.position).sqrt());
        match (&self.shape, &other.shape) {
            (WallShape::Plane { normal: a }, WallShape::Plane { normal: b }) => {
                a == b && dot3(offset, *a).abs() <= scale
            }
            (a, b) => a == b && dot3(offset, offset).sqrt() <= scale,
        }
    }
}

/// Contact of a sphere with a wall: unit normal from the sphere's centre towards the wall, the gap
/// `distance - radius` (negative = overlap) and the contact point.
#[derive(Debug, Clone, Copy)]
pub struct WallContact {
    pub normal: Vec3,
    pub gap: f64,
    pub point: Vec3,
}

impl Wall {
    /// A wall at rest.
    pub fn new(name: &str, shape: WallShape, position: Vec3, material: u16) -> Wall {
        Wall { name: name.to_string(), shape, position, velocity: [0.0; 3], material, spin: [0.0; 3], pivot: position }
    }

    /// The velocity of the wall's surface at `point`: its velocity, and its spin about the pivot.
    #[inline(always)]
    pub fn point_velocity(&self, point: Vec3) -> Vec3 {
        if self.spin == [0.0; 3] {
            return self.velocity;
        }
        let arm = [point[0] - self.pivot[0], point[1] - self.pivot[1], point[2] - self.pivot[2]];
        let w = self.spin;
        [
            self.velocity[0] + w[1] * arm[2] - w[2] * arm[1],
            self.velocity[1] + w[2] * arm[0] - w[0] * arm[2],
            self.velocity[2] + w[0] * arm[1] - w[1] * arm[0],
        ]
    }

    /// Geometry against a sphere, or None when the sphere is out of the wall's reach
    /// (beyond its extent, or farther than `reach` from it). Planes, the common container
    /// walls, are worked out in line (in the contact loop, and in the candidate search, where
    /// only `is_some` is used and the geometry is never built); other shapes in a call.
    #[inline(always)]
    pub fn contact(&self, x: Vec3, radius: f64, reach: f64) -> Option<WallContact> {
        match &self.shape {
            WallShape::Plane { normal } => {
                let d = [x[0] - self.position[0], x[1] - self.position[1], x[2] - self.position[2]];
                let dist = dot3(d, *normal);
                let gap = dist - radius;
                if gap > reach {
                    return None;
                }
                let n = [-normal[0], -normal[1], -normal[2]];
                let point = [x[0] - normal[0] * dist, x[1] - normal[1] * dist, x[2] - normal[2] * dist];
                Some(WallContact { normal: n, gap, point })
            }
            _ => self.bounded_contact(x, radius, reach),
        }
    }

    /// [`Wall::contact`] of the shapes with edges or curvature: the wall's point closest to the
    /// sphere's centre, whose distance gives the gap and whose direction the normal.
    fn bounded_contact(&self, x: Vec3, radius: f64, reach: f64) -> Option<WallContact> {
        let point = self.closest_point(x)?;
        let to = [point[0] - x[0], point[1] - x[1], point[2] - x[2]];
        let dist = dot3(to, to).sqrt();
        let gap = dist - radius;
        if gap > reach || dist == 0.0 {
            return None;
        }
        Some(WallContact { normal: [to[0] / dist, to[1] / dist, to[2] / dist], gap, point })
    }

    /// The point of a bounded wall closest to `x`. None on a cylinder's axis, where every
    /// direction is as close, and for a plane: its contact is one-sided (a sphere behind it
    /// overlaps it), which [`Wall::contact`] works out itself.
    fn closest_point(&self, x: Vec3) -> Option<Vec3> {
        let d = [x[0] - self.position[0], x[1] - self.position[1], x[2] - self.position[2]];
        let p = self.position;
        match &self.shape {
            WallShape::Plane { .. } => None,
            WallShape::Triangle { b, c, ring } => crate::dem::mesh_walls::facet_contact_point(d, *b, *c, ring)
                .map(|q| [p[0] + q[0], p[1] + q[1], p[2] + q[2]]),
            WallShape::Rect { u, v, half } => {
                let su = dot3(d, *u).clamp(-half[0], half[0]);
                let sv = dot3(d, *v).clamp(-half[1], half[1]);
                Some([p[0] + su * u[0] + sv * v[0], p[1] + su * u[1] + sv * v[1], p[2] + su * u[2] + sv * v[2]])
            }
            WallShape::Disk { normal, radius: big_r } => {
                let h = dot3(d, *normal);
                let inplane = [d[0] - h * normal[0], d[1] - h * normal[1], d[2] - h * normal[2]];
                let rho = dot3(inplane, inplane).sqrt();
                let scale = if rho > *big_r { big_r / rho } else { 1.0 };
                Some([p[0] + inplane[0] * scale, p[1] + inplane[1] * scale, p[2] + inplane[2] * scale])
            }
            WallShape::Cylinder { axis, radius: big_r, length } => {
                // Closest point of the finite shell (either side, rims included): a grain that
                // flows over the rim of a lowered cylinder meets its edge, not its inner face.
                let along = dot3(d, *axis);
                let radial = [d[0] - along * axis[0], d[1] - along * axis[1], d[2] - along * axis[2]];
                let rho = dot3(radial, radial).sqrt();
                if rho == 0.0 {
                    return None;
                }
                let on_axis = along.clamp(0.0, *length);
                let out = big_r / rho;
                Some([
                    p[0] + on_axis * axis[0] + radial[0] * out,
                    p[1] + on_axis * axis[1] + radial[1] * out,
                    p[2] + on_axis * axis[2] + radial[2] * out,
                ])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_rect_and_cylinder_gaps() {
        let floor = Wall {
            name: "floor".into(),
            shape: WallShape::Plane { normal: [0.0, 0.0, 1.0] },
            position: [0.0; 3],
            velocity: [0.0; 3],
            material: 0,
            spin: [0.0; 3],
            pivot: [0.0; 3],
        };
        let c = floor.contact([1.0, 2.0, 0.09], 0.1, 0.0).unwrap();
        assert!((c.gap + 0.01).abs() < 1e-15 && c.normal == [0.0, 0.0, -1.0]);
        assert!(floor.contact([0.0, 0.0, 0.5], 0.1, 0.1).is_none());
        let rect = Wall {
            shape: WallShape::Rect { u: [1.0, 0.0, 0.0], v: [0.0, 1.0, 0.0], half: [1.0, 1.0] },
            ..floor.clone()
        };
        // Beyond the edge: the closest point is on the edge.
        let c = rect.contact([1.05, 0.0, 0.05], 0.1, 0.0).unwrap();
        assert!((c.gap - (0.05f64.hypot(0.05) - 0.1)).abs() < 1e-12);
        let cyl = Wall { shape: WallShape::Cylinder { axis: [0.0, 0.0, 1.0], radius: 1.0, length: 2.0 }, ..floor };
        let c = cyl.contact([0.95, 0.0, 1.0], 0.1, 0.0).unwrap();
        assert!((c.gap + 0.05).abs() < 1e-12 && (c.normal[0] - 1.0).abs() < 1e-15);
        assert!(cyl.contact([0.95, 0.0, 3.0], 0.1, 0.0).is_none());
        // Outside the shell the contact pushes outwards, and past the rim the rim edge is met
        // (a grain flowing over a lowered cylinder is not pulled back through it).
        let c = cyl.contact([1.05, 0.0, 1.0], 0.1, 0.0).unwrap();
        assert!((c.gap + 0.05).abs() < 1e-12 && (c.normal[0] + 1.0).abs() < 1e-15);
        let c = cyl.contact([1.05, 0.0, 2.05], 0.1, 0.0).unwrap();
        assert!((c.gap - (0.05f64.hypot(0.05) - 0.1)).abs() < 1e-12);
        assert!(c.normal[0] < 0.0 && c.normal[2] < 0.0, "towards the rim edge: {:?}", c.normal);
    }
}
