//! Potential particles against walls of bounded shapes: rectangles, disks, cylinders and the
//! triangles of a wall mesh.

use crate::common;
use crate::common::bodies::scene;
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::math::Vec3;
use nalgebra::{UnitQuaternion, Vector3};

/// A rounded box lying on an incline (walls `incline(material, down, normal)` through the origin)
/// slides down it at `g (sin theta - mu cos theta)`, its face on the wall; returns the distance
/// it slid and where it ended.
fn slides_down(incline: impl Fn(u16, Vec3, Vec3) -> Vec<Wall>) -> (f64, Vec3) {
    let (theta, mu_deg, g, kn) = (25f64.to_radians(), 15f64, 9.81, 1e5);
    let mut s = scene(2500.0, &[("kn", kn), ("kt_ratio", 1.0), ("friction", mu_deg)]);
    s.sim.world.gravity = [0.0, -g, 0.0];
    let (down, normal) = ([theta.cos(), -theta.sin(), 0.0], [theta.sin(), theta.cos(), 0.0]);
    for wall in incline(s.material, down, normal) {
        s.sim.world.add_wall(wall);
    }
    // A flat box, 3 x 1 x 3 cm about its axes (the short one along the incline's normal), on its
    // face at the equilibrium overlap.
    let (half, r) = ([0.015 - 0.002, 0.005 - 0.002, 0.015 - 0.002], 0.002);
    let shape = s.rounded_box(half, r, 0.04, 0.1);
    let mass = 2500.0 * shape.volume();
    let rest = face_below(shape.as_ref()) - mass * g * theta.cos() / kn;
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -theta);
    s.add(&shape, normal.map(|c| c * rest), turn);
    let dt = 0.05 * s.sim.world.critical_dt().unwrap();
    s.sim.world.set_dt(dt).unwrap();
    let steps = (0.25 / dt).round() as u64;
    for step in 0..steps {
        s.sim.step().unwrap();
        // One contact at every step (never two across a mesh's seams, nor none), its normal the
        // incline's.
        let c = s.sim.world.body_contacts_of(0);
        let tilt = c.iter().map(|c| 1.0 + (0..3).map(|a| c.normal[a] * normal[a]).sum::<f64>()).fold(0.0, f64::max);
        assert!(c.len() == 1 && tilt < 1e-9, "step {step}: {} contacts, normal off by {tilt:e}", c.len());
    }
    let (t, x) = (s.sim.world.time, s.sim.world.kinds.x[0]);
    let slid = (0..3).map(|a| (x[a] - normal[a] * rest) * down[a]).sum::<f64>();
    let expected = g * (theta.sin() - mu_deg.to_radians().tan() * theta.cos());
    let measured = 2.0 * slid / (t * t);
    eprintln!("sliding box: a = {measured:.6} m/s^2, expected {expected:.6} ({:+.3e})", measured / expected - 1.0);
    assert!((measured / expected - 1.0).abs() < 0.01, "a = {measured:.5} m/s^2, expected {expected:.5}");
    // It slides on its face: no turn beyond the incline's.
    let q = s.sim.world.kinds.q[0];
    assert!(q.angle_to(&turn) < 1e-3, "the box tipped by {} rad", q.angle_to(&turn));
    (slid, x)
}

/// How far below its centre a body's surface lies (along its -y axis), by bisection.
fn face_below(shape: &dyn granite_core::ext::BodyShape) -> f64 {
    let (mut inside, mut outside) = (0.0, shape.bounding_radius());
    for _ in 0..100 {
        let mid = 0.5 * (inside + outside);
        if shape.contains([0.0, -mid, 0.0]) {
            inside = mid;
        } else {
            outside = mid;
        }
    }
    inside
}

fn plane(m: u16, _: Vec3, normal: Vec3) -> Vec<Wall> {
    vec![Wall::new("incline", WallShape::Plane { normal }, [0.0; 3], m)]
}

#[test]
fn a_rounded_box_slides_down_a_rectangle_as_down_a_plane() {
    let (on_plane, x_plane) = slides_down(plane);
    let (on_rect, x_rect) = slides_down(|m, down, _| {
        let shape = WallShape::Rect { u: down, v: [0.0, 0.0, 1.0], half: [1.0, 1.0] };
        vec![Wall::new("incline", shape, [0.0; 3], m)]
    });
    // The same contact (the plane's) to the plane solve's tolerance.
    let apart = (0..3).map(|a| (x_plane[a] - x_rect[a]).abs()).fold(0.0, f64::max);
    eprintln!("rectangle against plane: {apart:e} m apart after {on_plane} m");
    assert!(apart < 1e-9, "plane {on_plane} m, rectangle {on_rect} m: {apart:e} apart");
}

/// The incline a wall mesh of 2 cm squares cut along a diagonal: the 3 cm box always lies over
/// several triangles and slides across seams and diagonals, meeting the surface once, as a plane.
#[test]
fn a_rounded_box_slides_down_a_wall_mesh_across_its_seams_as_down_a_plane() {
    let (on_plane, x_plane) = slides_down(plane);
    let (on_mesh, x_mesh) = slides_down(|m, down, _| {
        let at = |s: f64, z: f64| [s * down[0], s * down[1], z];
        let side = 0.02;
        let mut triangles = Vec::new();
        for i in -5..20 {
            for j in -4..4 {
                let (s0, z0) = (i as f64 * side, j as f64 * side + 0.007);
                let (s1, z1) = (s0 + side, z0 + side);
                triangles.push([at(s0, z0), at(s1, z0), at(s1, z1)]);
                triangles.push([at(s0, z0), at(s1, z1), at(s0, z1)]);
            }
        }
        granite_core::dem::mesh_walls::mesh_walls(&triangles, "incline", m).unwrap()
    });
    let apart = (0..3).map(|a| (x_plane[a] - x_mesh[a]).abs()).fold(0.0, f64::max);
    eprintln!("mesh against plane: {apart:e} m apart after {on_plane} m");
    assert!(apart < 1e-9, "plane {on_plane} m, mesh {on_mesh} m: {apart:e} apart");
}

/// A rounded box lying on a rectangle with its centre 4 mm past the rectangle's edge (its face
/// bearing on the edge) tips over it and falls off; one with its centre 4 mm inside stays.
#[test]
fn a_rounded_box_over_a_rectangles_edge_tips_off_only_past_its_middle() {
    let g = 9.81;
    for (overhang, falls) in [(0.004, true), (-0.004, false)] {
        let mut s = scene(2500.0, &[("kn", 1e5), ("kt_ratio", 1.0), ("friction", 30.0)]);
        s.sim.world.gravity = [0.0, 0.0, -g];
        // The rectangle's edge at x = 0, the rectangle over x < 0.
        let rect = WallShape::Rect { u: [1.0, 0.0, 0.0], v: [0.0, 1.0, 0.0], half: [0.05, 0.05] };
        s.sim.world.add_wall(Wall::new("table", rect, [-0.05, 0.0, 0.0], s.material));
        let shape = s.rounded_box([0.013, 0.013, 0.003], 0.002, 0.04, 0.1);
        s.add(&shape, [overhang, 0.0, 0.005], UnitQuaternion::identity());
        s.sim.world.set_damping(0.2).unwrap();
        let dt = 0.1 * s.sim.world.critical_dt().unwrap();
        s.sim.world.set_dt(dt).unwrap();
        while s.sim.world.time < 0.3 {
            s.sim.step().unwrap();
        }
        let z = s.sim.world.kinds.x[0][2];
        if falls {
            assert!(z < -0.01, "a box with its centre past the edge fell to z = {z}");
        } else {
            assert!((z - 0.005).abs() < 1e-3, "a box with its centre over the table rests at z = {z}");
        }
    }
}

/// Rounded boxes poured into a cylinder standing on a disk, and into the silo of
/// scripts/dem/silo_outlet_15mm.stl (four sides and a floor with a 15 mm hole, closed by a
/// rectangle under it): at rest the walls carry their weight, to 0.5 %, and none has passed
/// through a wall.
#[test]
fn rounded_boxes_settle_in_a_cylinder_on_a_disk_and_in_a_silo_of_triangles() {
    let cloud = r#"count: 12, shape: "potential_box", hx: 0.004, hy: 0.003, hz: 0.002, r: 0.0015, k: 0.2"#;
    for (name, s) in common::bodies::poured_into_containers("potential", cloud, 1.5) {
        let get = |k: &str| s[k].as_f64().unwrap();
        assert!((get("carried") / get("weight") - 1.0).abs() < 0.005, "{name}: walls carry {s}");
        assert!(get("lowest") > 0.0, "{name}: a box below the floor: {s}");
        assert!(get("wall_contacts") >= 3.0, "{name}: {s}");
    }
}
