//! What a DEM frame shows in ParaView besides the spheres: the walls as surfaces and the contact
//! network (force chains) as lines.

use crate::dem::inspect::Member;
use crate::dem::sim::DemWorld;
use crate::dem::walls::WallShape;
use crate::io::vtk::{Field, PolyData};
use crate::math::Vec3;

/// Sides of the polygon of a disk and of the prism of a cylinder.
const ROUND: usize = 48;

/// Two unit vectors spanning the plane normal to `n`.
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let cross = |a: Vec3, b: Vec3| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let u = cross(n, helper);
    let len = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = u.map(|c| c / len);
    (u, cross(n, u))
}

fn at(p: Vec3, u: Vec3, a: f64, v: Vec3, b: f64) -> Vec3 {
    [0, 1, 2].map(|k| p[k] + a * u[k] + b * v[k])
}

impl DemWorld {
    /// The walls as polygons: a rectangle, a disk (48-gon) and a cylinder (48 quads) as they are;
    /// an infinite plane as a square around the spheres (their bounding box's diagonal wide, 1 m
    /// without spheres). Cell data: `wall` (index), `force` (the spheres' force on it in the last
    /// step), `velocity`.
    pub fn walls_picture(&self) -> PolyData {
        let mut p = PolyData::default();
        let (lo, hi) = crate::math::point_bounds(&self.spheres.x);
        let size = if self.spheres.is_empty() {
            1.0
        } else {
            let d = [0, 1, 2].map(|a| hi[a] - lo[a] + 2.0 * self.spheres.largest_radius());
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        };
        let centre = if self.spheres.is_empty() { [0.0; 3] } else { [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a])) };
        let (mut index, mut force, mut velocity) = (Vec::new(), Vec::new(), Vec::new());
        let forces = self.wall_forces();
        for (w, wall) in self.walls.iter().enumerate() {
            let x = wall.position;
            let mut add = |p: &mut PolyData, corners: Vec<Vec3>| {
                let first = p.points.len() as u32;
                p.polygons.push((first..first + corners.len() as u32).collect());
                p.points.extend(corners);
                index.push(w as i64);
                force.extend(forces[w]);
                velocity.extend(wall.velocity);
            };
            match &wall.shape {
                WallShape::Plane { normal } => {
                    let (u, v) = basis(*normal);
                    // The square's centre: the spheres' centre brought onto the plane.
                    let d: f64 = (0..3).map(|k| (centre[k] - x[k]) * normal[k]).sum();
                    let c = [0, 1, 2].map(|k| centre[k] - d * normal[k]);
                    let h = 0.5 * size;
                    add(&mut p, vec![at(c, u, -h, v, -h), at(c, u, h, v, -h), at(c, u, h, v, h), at(c, u, -h, v, h)]);
                }
                WallShape::Triangle { b, c, .. } => {
                    add(&mut p, vec![x, [0, 1, 2].map(|k| x[k] + b[k]), [0, 1, 2].map(|k| x[k] + c[k])]);
                }
                WallShape::Rect { u, v, half } => {
                    let (a, b) = (half[0], half[1]);
                    add(
                        &mut p,
                        vec![at(x, *u, -a, *v, -b), at(x, *u, a, *v, -b), at(x, *u, a, *v, b), at(x, *u, -a, *v, b)],
                    );
                }
                WallShape::Disk { normal, radius } => {
                    let (u, v) = basis(*normal);
                    let ring = (0..ROUND)
                        .map(|k| {
                            let t = 2.0 * std::f64::consts::PI * k as f64 / ROUND as f64;
                            at(x, u, radius * t.cos(), v, radius * t.sin())
                        })
                        .collect();
                    add(&mut p, ring);
                }
                WallShape::Cylinder { axis, radius, length } => {
                    let (u, v) = basis(*axis);
                    let top = [0, 1, 2].map(|k| x[k] + length * axis[k]);
                    for k in 0..ROUND {
                        let angle = |k: usize| 2.0 * std::f64::consts::PI * k as f64 / ROUND as f64;
                        let (t0, t1) = (angle(k), angle(k + 1));
                        add(
                            &mut p,
                            vec![
                                at(x, u, radius * t0.cos(), v, radius * t0.sin()),
                                at(x, u, radius * t1.cos(), v, radius * t1.sin()),
                                at(top, u, radius * t1.cos(), v, radius * t1.sin()),
                                at(top, u, radius * t0.cos(), v, radius * t0.sin()),
                            ],
                        );
                    }
                }
            }
        }
        p.cell_fields =
            vec![Field::int("wall", index), Field::float("force", 3, force), Field::float("velocity", 3, velocity)];
        p
    }

    /// The contacts touching in the last step as lines: between the two centres (a sphere's or
    /// a body's of a plugin kind; the other one's periodic image where the pair crosses the
    /// cell), or from a centre to its contact point on a wall. Cell data: `normal_force`
    /// (compression positive), `shear_force` (its magnitude), `force` (on the first member),
    /// `id1`, `id2` (-1 for a wall), `wall` (-1 for a pair of grains), `overlap`.
    pub fn contacts_picture(&self) -> PolyData {
        let mut p = PolyData::default();
        let contacts = self.touching_contacts();
        let n = contacts.len();
        let (mut fn_, mut ft, mut force, mut overlap) =
            (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(3 * n), Vec::with_capacity(n));
        let (mut id1, mut id2, mut wall) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
        let (s, k) = (&self.spheres, &self.kinds);
        // A grain's centre and id.
        let grain = |m: Member| match m {
            Member::Sphere(i) => Some((s.x[i], s.id[i] as i64)),
            Member::Body(i) => Some((k.x[i], k.id[i] as i64)),
            Member::Wall(_) => None,
        };
        for c in &contacts {
            let Some((from, first_id)) = grain(c.first) else { continue };
            let to = match (c.other, grain(c.other)) {
                (_, Some((centre, id))) => {
                    let image = match (&self.cell, c.shift) {
                        (Some(cell), shift) if shift != [0; 3] => cell.shift_vector(shift),
                        _ => [0.0; 3],
                    };
                    id2.push(id);
                    wall.push(-1);
                    [0, 1, 2].map(|a| centre[a] + image[a])
                }
                (Member::Wall(w), None) => {
                    id2.push(-1);
                    wall.push(w as i64);
                    c.point
                }
                _ => continue,
            };
            let first = p.points.len() as u32;
            p.points.push(from);
            p.points.push(to);
            p.lines.push([first, first + 1]);
            fn_.push(c.normal_force);
            ft.push((c.shear_force.iter().map(|f| f * f).sum::<f64>()).sqrt());
            force.extend(c.force);
            overlap.push(c.overlap);
            id1.push(first_id);
        }
        p.cell_fields = vec![
            Field::float("normal_force", 1, fn_),
            Field::float("shear_force", 1, ft),
            Field::float("force", 3, force),
            Field::float("overlap", 1, overlap),
            Field::int("id1", id1),
            Field::int("id2", id2),
            Field::int("wall", wall),
        ];
        p
    }
}

/// Rigid bodies of shapes of their own, as a picture shows them.
pub(crate) struct RigidBodies<'a> {
    pub shape: &'a [u32],
    pub x: &'a [Vec3],
    pub q: &'a [nalgebra::UnitQuaternion<f64>],
    pub id: &'a [u64],
    pub material: &'a [u16],
    pub fixed: &'a [bool],
    pub v: &'a [Vec3],
    pub force: &'a [Vec3],
}

/// Each body's shape surface (`surfaces`, in the body frame, by shape) placed at its pose, with
/// id, material, fixed, velocity and force on each triangle.
pub(crate) fn rigid_picture(surfaces: &[(Vec<Vec3>, Vec<[usize; 3]>)], b: RigidBodies<'_>) -> PolyData {
    let mut picture = PolyData::default();
    let (mut id, mut material, mut fixed, mut velocity, mut force) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for i in 0..b.x.len() {
        let (points, triangles) = &surfaces[b.shape[i] as usize];
        let first = picture.points.len() as u32;
        let rot = b.q[i].to_rotation_matrix();
        picture.points.extend(points.iter().map(|p| {
            let w = rot * nalgebra::Vector3::new(p[0], p[1], p[2]);
            [b.x[i][0] + w[0], b.x[i][1] + w[1], b.x[i][2] + w[2]]
        }));
        for t in triangles {
            picture.polygons.push(t.iter().map(|&k| first + k as u32).collect());
            id.push(b.id[i] as i64);
            material.push(b.material[i] as i64);
            fixed.push(b.fixed[i] as i64);
            velocity.extend(b.v[i]);
            force.extend(b.force[i]);
        }
    }
    picture.cell_fields = vec![
        Field::int("id", id),
        Field::int("material", material),
        Field::int("fixed", fixed),
        Field::float("velocity", 3, velocity),
        Field::float("force", 3, force),
    ];
    picture
}
