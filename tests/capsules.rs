//! Capsules, a body kind of the built-in plugins, against analytic cases: the overlap and force of
//! two crossed capsules and of a capsule and a sphere; a capsule rolling without slip down an
//! incline at `a = g sin(theta) / (1 + I_axis / (m r^2))`; the energy of capsules bouncing in a
//! frictionless elastic box.

use crate::common;

use common::bodies::{along, scene};
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::dem::DemSim;
use granite_core::math::Vec3;
use nalgebra::UnitQuaternion;

#[test]
fn crossed_capsules_and_a_capsule_and_a_sphere_overlap_and_push_as_the_law_says() {
    let (r, kn, overlap) = (0.01, 1e5, 1e-4);
    let mut s = scene(2500.0, &[("kn", kn)]);
    let shape = s.capsule(r, 0.1);
    // Along x at the origin, and along y above it, their axes 2r - overlap apart.
    s.add_moving(&shape, [0.0; 3], along([1.0, 0.0, 0.0]), [0.0; 3], [0.0; 3]);
    s.add_moving(&shape, [0.03, 0.02, 2.0 * r - overlap], along([0.0, 1.0, 0.0]), [0.0; 3], [0.0; 3]);
    // A sphere resting on the first capsule's side, further along x.
    let ball = 0.005;
    s.sim.world.add_sphere(s.material, [-0.04, 0.0, -(r + ball - overlap)], ball, [0.0; 3]).unwrap();
    s.sim.world.set_dt(1e-8).unwrap();
    s.sim.step().unwrap();
    let k = &s.sim.world.kinds;
    assert_eq!(s.sim.world.contacts.body_touching_count(), 2);
    let push = kn * overlap;
    // The first capsule: pushed down by the second, up by the sphere: its two forces cancel along z.
    let expect = |got: Vec3, want: Vec3, what: &str| {
        let err = (0..3).map(|a| (got[a] - want[a]).abs()).fold(0.0, f64::max);
        assert!(err < 1e-9 * push, "{what}: {got:?}, expected {want:?}");
    };
    expect(k.force[1], [0.0, 0.0, push], "force on the upper capsule");
    expect(k.force[0], [0.0, 0.0, 0.0], "force on the lower capsule");
    expect(s.sim.world.spheres.force[0], [0.0, 0.0, -push], "force on the sphere");
    // Each force acts at its contact point (on the axes' common perpendicular, and under the
    // sphere's centre): torques by the lever arms from the centres of mass.
    let lever = |point: Vec3, centre: Vec3, f: f64| {
        let d = [point[0] - centre[0], point[1] - centre[1], point[2] - centre[2]];
        [d[1] * f, -d[0] * f, 0.0]
    };
    let depth = r - overlap / 2.0;
    let upper = [0.03, 0.02, 2.0 * r - overlap];
    expect(k.torque[1], lever([0.03, 0.0, depth], upper, push), "torque on the upper capsule");
    let from_upper = lever([0.03, 0.0, depth], [0.0; 3], -push);
    let from_sphere = lever([-0.04, 0.0, -depth], [0.0; 3], push);
    expect(k.torque[0], [0.0, from_upper[1] + from_sphere[1], 0.0], "torque on the lower capsule");
}

#[test]
fn a_capsule_rolls_down_an_incline_without_slip_at_the_rate_of_its_own_inertia() {
    rolls_down(|m, _, normal| vec![Wall::new("incline", WallShape::Plane { normal }, [0.0; 3], m)]);
}

#[test]
fn a_capsule_rolls_down_a_rectangle_as_down_a_plane() {
    rolls_down(|m, down, _| {
        let shape = WallShape::Rect { u: down, v: [0.0, 0.0, 1.0], half: [1.0, 1.0] };
        vec![Wall::new("incline", shape, [0.0; 3], m)]
    });
}

/// The incline a wall mesh: squares of 2 cm (the capsule's radius is 1 cm, its cylinder 4 cm
/// long) each cut along a diagonal, one row of seams under the capsule's middle along the slope:
/// the capsule rolls across some ten seams and diagonals, always over several triangles.
#[test]
fn a_capsule_rolls_down_a_wall_mesh_across_its_seams_as_down_a_plane() {
    rolls_down(|m, down, _| {
        let at = |s: f64, z: f64| [s * down[0], s * down[1], z];
        let side = 0.02;
        let mut triangles = Vec::new();
        for i in -5..16 {
            for j in -3..3 {
                let (s0, z0) = (i as f64 * side, j as f64 * side);
                let (s1, z1) = (s0 + side, z0 + side);
                triangles.push([at(s0, z0), at(s1, z0), at(s1, z1)]);
                triangles.push([at(s0, z0), at(s1, z1), at(s0, z1)]);
            }
        }
        granite_core::dem::mesh_walls::mesh_walls(&triangles, "incline", m).unwrap()
    });
}

/// A capsule lying across an incline (walls `incline(material, down, normal)` through the origin)
/// rolls without slip at `g sin(theta) / (1 + I_axis / (m r^2))`.
fn rolls_down(incline: impl Fn(u16, Vec3, Vec3) -> Vec<Wall>) {
    let (r, length, theta) = (0.01, 0.04, 15f64.to_radians());
    let g = 9.81;
    let kn = 1e5;
    let mut s = scene(2500.0, &[("kn", kn), ("kt_ratio", 1.0), ("friction", 30.0)]);
    s.sim.world.gravity = [0.0, -g, 0.0];
    // The incline through the origin, going down towards +x; the capsule's axis along z, across
    // the slope, resting at its equilibrium overlap.
    let (down, normal) = ([theta.cos(), -theta.sin(), 0.0], [theta.sin(), theta.cos(), 0.0]);
    for wall in incline(s.material, down, normal) {
        s.sim.world.add_wall(wall);
    }
    let shape = s.capsule(r, length);
    let mass = 2500.0 * shape.volume();
    let i_axis = 2500.0 * shape.inertia_per_density()[2];
    let rest = r - mass * g * theta.cos() / kn;
    s.add_moving(&shape, normal.map(|c| c * rest), UnitQuaternion::identity(), [0.0; 3], [0.0; 3]);
    let dt = 0.05 * s.sim.world.critical_dt().unwrap();
    s.sim.world.set_dt(dt).unwrap();
    let duration = 0.3;
    let steps = (duration / dt).round() as u64;
    for _ in 0..steps {
        s.sim.step().unwrap();
    }
    let t = s.sim.world.time;
    let k = &s.sim.world.kinds;
    let travelled = (0..3).map(|a| (k.x[0][a] - normal[a] * rest) * down[a]).sum::<f64>();
    let expected = g * theta.sin() / (1.0 + i_axis / (mass * r * r));
    let measured = 2.0 * travelled / (t * t);
    eprintln!("rolling capsule: a = {measured:.6} m/s^2, expected {expected:.6} ({:+.3e})", measured / expected - 1.0);
    assert!((measured / expected - 1.0).abs() < 0.01, "a = {measured:.5} m/s^2, expected {expected:.5}");
    // Rolling without slip: the spin about the axis carries the centre's speed.
    let speed = (0..3).map(|a| k.v[0][a] * down[a]).sum::<f64>();
    let spin = -k.w[0][2];
    assert!((spin * r / speed - 1.0).abs() < 0.01, "w r = {:.5} m/s, v = {speed:.5} m/s", spin * r);
    // A sliding capsule would go at g sin(theta): well above.
    assert!(measured < 0.8 * g * theta.sin());
}

#[test]
fn capsules_bouncing_in_a_frictionless_elastic_box_keep_their_energy() {
    let kn = 1e4;
    let mut s = scene(1000.0, &[("kn", kn)]);
    let size = 0.2;
    for (normal, at) in [
        ([1.0, 0.0, 0.0], [0.0; 3]),
        ([-1.0, 0.0, 0.0], [size, 0.0, 0.0]),
        ([0.0, 1.0, 0.0], [0.0; 3]),
        ([0.0, -1.0, 0.0], [0.0, size, 0.0]),
        ([0.0, 0.0, 1.0], [0.0; 3]),
        ([0.0, 0.0, -1.0], [0.0, 0.0, size]),
    ] {
        s.sim.world.add_wall(Wall::new("box", WallShape::Plane { normal }, at, s.material));
    }
    let shape = s.capsule(0.01, 0.03);
    // Eight capsules on a lattice, turned and thrown every way, spinning.
    let mut n = 0;
    for i in 0..2 {
        for j in 0..2 {
            for k in 0..2 {
                let x = [0.05 + 0.1 * i as f64, 0.05 + 0.1 * j as f64, 0.05 + 0.1 * k as f64];
                let f = n as f64;
                let axis = [1.0 + f, 2.0 - 0.3 * f, 0.5 * f - 1.0];
                let v = [0.3 * (f - 3.5), 0.2 * (2.0 - f), 0.25 * (f * f / 10.0 - 1.0)];
                let w = [3.0 - f, 0.5 * f, 2.0];
                s.add_moving(&shape, x, along(axis), v, w);
                n += 1;
            }
        }
    }
    let dt = 0.02 * s.sim.world.critical_dt().unwrap();
    s.sim.world.set_dt(dt).unwrap();
    let energy = |sim: &DemSim| sim.world.kinds.kinetic_energy();
    let e0 = energy(&s.sim);
    let (mut worst, mut free_checks, mut collisions) = (0.0f64, 0, 0);
    let mut touching_before = false;
    for _ in 0..(1.0 / dt) as u64 {
        s.sim.step().unwrap();
        let touching = s.sim.world.contacts.body_touching_count() > 0;
        if touching_before && !touching {
            collisions += 1;
        }
        if !touching {
            worst = worst.max((energy(&s.sim) / e0 - 1.0).abs());
            free_checks += 1;
        }
        touching_before = touching;
    }
    eprintln!(
        "capsules in a box: {collisions} collisions, kinetic energy between them within {worst:.3e} of {e0:.4e} J"
    );
    assert!(collisions >= 20, "only {collisions} collisions");
    assert!(free_checks > 1000);
    assert!(worst < 1e-4, "kinetic energy between collisions drifted by {worst:.3e} of {e0:.4e} J");
}

#[test]
fn capsules_and_spheres_settled_in_a_box_rest_their_weight_on_the_walls() {
    let report = common::run("dem/capsules_in_a_box.rhai", "capsules_in_a_box", &[], 2).unwrap();
    let (weight, carried) = (common::summary_f64(&report, "weight"), common::summary_f64(&report, "walls_carry"));
    assert_eq!(common::summary_f64(&report, "bodies"), 40.0);
    assert!(common::summary_f64(&report, "contacts") > 100.0, "a packing has contacts between its grains");
    // At rest (the unbalanced force ratio, YADE's static criterion, below 1 %: a kinetic energy
    // bound would also count a sphere rolling or spinning on in a pocket, which Cundall damping,
    // acting on accelerations, slows only through friction) the walls' vertical reactions
    // balance the weight.
    let unbalanced = common::summary_f64(&report, "unbalanced_force");
    assert!(unbalanced < 1e-2, "unbalanced force ratio {unbalanced}");
    assert!((carried / weight - 1.0).abs() < 5e-3, "the walls carry {carried} N of a weight of {weight} N");
    assert!(report.out_dir.join("vtk/bodies.pvd").exists());
}

/// The same box with rounded boxes (potential particles) poured in first: the capsules settle on
/// and between them (contacts of the two families, `capsule_potential`), and the walls carry the
/// weight of all of it.
#[test]
fn capsules_settled_on_rounded_boxes_rest_their_weight_on_the_walls() {
    let sets = [("blocks", "8"), ("capsules", "10"), ("spheres", "30"), ("duration", "2.5"), ("half_width", "0.05")];
    let report = common::run("dem/capsules_in_a_box.rhai", "capsules_on_blocks", &sets, 2).unwrap();
    let (weight, carried) = (common::summary_f64(&report, "weight"), common::summary_f64(&report, "walls_carry"));
    assert_eq!(common::summary_f64(&report, "bodies"), 18.0);
    let meetings = common::summary_f64(&report, "capsule_block_contacts");
    assert!(meetings >= 5.0, "capsules rest on the blocks: {meetings} capsule-block contacts");
    // Nearly at rest (below 1e-5 J of about 0.7 J released by the fall): the walls' reactions
    // balance the weight.
    assert!(common::summary_f64(&report, "kinetic_energy") < 1e-5);
    assert!((carried / weight - 1.0).abs() < 5e-3, "the walls carry {carried} N of a weight of {weight} N");
}

/// `granite plugins` lists the capsule kind with its parameters.
#[test]
fn the_plugins_command_lists_the_capsule_body_kind() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_granite")).arg("plugins").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let at = text.lines().position(|l| l.trim_start().starts_with("capsule:")).expect("the capsule kind");
    let params: Vec<&str> =
        text.lines().skip(at + 1).take(2).map(|l| l.split_whitespace().next().unwrap_or("")).collect();
    assert_eq!(params, ["radius", "length"], "{text}");
}

/// A saved state holds the bodies with their contacts' history: a run resumed from it goes on
/// bit for bit as the run that wrote it.
#[test]
fn a_saved_state_with_capsules_resumes_bit_for_bit() {
    let build = || {
        let mut s = scene(2500.0, &[("kn", 1e5), ("kt_ratio", 0.5), ("friction", 25.0)]);
        s.sim.world.gravity = [0.0, 0.0, -9.81];
        s.sim.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], s.material));
        let shape = s.capsule(0.01, 0.03);
        // Four capsules side by side on the floor, each pressing on the next, and a sphere in
        // each groove between two of them: every kind of pair touches from the start.
        // Overlaps about the weight's (m g / k_n = 3e-6 m): the packing starts nearly at rest.
        let (r, ball, overlap) = (0.01, 0.008, 3e-6);
        let gap = 2.0 * r - overlap;
        for k in 0..4 {
            let f = k as f64;
            s.add_moving(&shape, [f * gap, 0.002 * f, r - overlap], along([0.0, 1.0, 0.0]), [0.0; 3], [0.0; 3]);
        }
        let height = r - overlap + ((r + ball - overlap).powi(2) - (gap / 2.0).powi(2)).sqrt();
        for k in 0..3 {
            s.sim.world.add_sphere(s.material, [(k as f64 + 0.5) * gap, 0.0, height], ball, [0.0; 3]).unwrap();
        }
        s.sim.world.set_damping(0.2).unwrap();
        let dt = 0.2 * s.sim.world.critical_dt().unwrap();
        s.sim.world.set_dt(dt).unwrap();
        s
    };
    let (straight, written, resumed) = common::straight_and_resumed(|| build().sim, 2000, "capsules_state");
    let contacts = written.world.contacts.body_touching_count();
    assert!(contacts >= 10, "the saved state has {contacts} contacts");
    let (a, b) = (&straight.world.kinds, &resumed.world.kinds);
    assert!(a.x == b.x && a.v == b.v && a.w == b.w && a.q == b.q, "the resumed bodies parted from the straight run");
    assert!(straight.world.spheres.x == resumed.world.spheres.x && straight.world.spheres.v == resumed.world.spheres.v);
    assert_eq!(straight.world.contacts.body_touching_count(), resumed.world.contacts.body_touching_count());
}

/// A fixed capsule is a moving container part: it keeps the velocity and spin a script gives it,
/// whatever pushes on it, and pushes the grains in its way.
#[test]
fn a_fixed_capsule_moves_as_the_script_drives_it_and_sweeps_a_sphere() {
    let out = common::run_text(
        "capsule_blade",
        r#"
let sim = dem();
let m = sim.material(#{ density: 2500.0 });
sim.contact_law("linear", #{ kn: 1e4 });
let blade = sim.capsule(m, [0.0, 0.0, 0.0], #{ radius: 0.01, length: 0.1, axis: [0.0, 1.0, 0.0], fixed: true });
let ball = sim.sphere(m, [0.05, 0.0, 0.0], 0.01);
sim.body_velocity(blade, [0.5, 0.0, 0.0]);
sim.body_spin(blade, [0.0, 2.0, 0.0]);
sim.dt(0.05 * sim.critical_dt());
sim.run_until(0.1);
let b = sim.body_state(blade);
summary("blade_x", b.position[0]);
summary("blade_spin", b.spin[1]);
summary("time", sim.time);
summary("sphere_x", sim.body(ball).position[0]);
summary("sphere_vx", sim.body(ball).velocity[0]);
"#,
    );
    let summary: serde_json::Value = common::summary_of(&out);
    let get = |k: &str| summary[k].as_f64().unwrap();
    // The blade moved at its own velocity (sums of steps: to rounding), spinning as told.
    assert!((get("blade_x") - 0.5 * get("time")).abs() < 1e-12, "blade at {}", get("blade_x"));
    assert_eq!(get("blade_spin"), 2.0);
    // The sphere, met after 0.06 s, was swept ahead of it: a light elastic ball off a heavy paddle
    // leaves at about twice the paddle's speed.
    assert!(get("sphere_x") > get("blade_x") + 0.019, "sphere at {}, blade at {}", get("sphere_x"), get("blade_x"));
    assert!(get("sphere_vx") > 0.5, "sphere at {} m/s", get("sphere_vx"));
}

/// A change of contact parameters reaches the bodies' contacts: a capsule and a sphere sliding
/// at 1 m/s on a frictionless plane start to roll once friction is set, the sphere at 5/7 of
/// its speed and the capsule (lying across its motion) at `v0 / (1 + I_axis / (m r²))`. A switch
/// to another law with bodies in contact then runs on (it stopped the run with a panic before).
#[test]
fn a_contact_change_reaches_capsules_and_a_law_switch_runs_on() {
    let (radius, length, rho) = (0.01f64, 0.04f64, 1000.0f64);
    // At rest on its two ends, each carrying half its weight (started deeper, it would bounce
    // on the undamped springs and rock from end to end).
    let mass = rho * std::f64::consts::PI * radius * radius * (length + 4.0 / 3.0 * radius);
    let rest = radius - 0.5 * mass * 9.81 / 1e6;
    let source = format!(
        r#"
        let sim = dem();
        let m = sim.material(#{{ density: {rho} }});
        sim.contact_law("linear", #{{ kn: 1e6, kt_ratio: 0.5, friction: 0.0 }});
        sim.wall_plane(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
        let cap = sim.capsule(m, [0.0, 0.0, {rest}], #{{ radius: {radius}, length: {length}, axis: [0.0, 1.0, 0.0] }});
        let sp = sim.sphere(m, [0.0, 0.2, 0.00999], {radius});
        sim.body_velocity(cap, [1.0, 0.0, 0.0]);
        sim.set_body(sp, #{{ velocity: [1.0, 0.0, 0.0] }});
        sim.gravity([0.0, 0.0, -9.81]);
        sim.dt(0.2 * sim.critical_dt());
        sim.run_until(0.05);
        summary("sliding", sim.body_state(cap).velocity[0]);
        sim.set_contact_params(#{{ friction: 45.0 }});
        sim.run_until(0.5);
        summary("capsule_v", sim.body_state(cap).velocity[0]);
        summary("capsule_spin", sim.body_state(cap).spin[1]);
        summary("sphere_v", sim.body(sp).velocity[0]);
        sim.contact_law("visco_elastic", #{{ kn: 1e5, kt_ratio: 0.5, friction: 30.0, restitution: 0.5 }});
        sim.run_steps(100);
        summary("after_switch", sim.body_state(cap).velocity[0]);
        "#
    );
    let out = common::run_text("capsule_contact_change", &source);
    let s: serde_json::Value = common::summary_of(&out);
    let get = |k: &str| s[k].as_f64().unwrap();
    assert!((get("sliding") - 1.0).abs() < 1e-9, "frictionless: it slides at {}", get("sliding"));
    // A cylinder of the length and two half-spheres: I_axis = m_c r²/2 + 2 m_s r²/5.
    let (m_cyl, m_sph) = (
        rho * std::f64::consts::PI * radius * radius * length,
        rho * 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3),
    );
    let ratio = (0.5 * m_cyl + 0.4 * m_sph) / (m_cyl + m_sph);
    let rolling = 1.0 / (1.0 + ratio);
    assert!((get("capsule_v") - rolling).abs() < 0.005 * rolling, "capsule at {}, rolling {rolling}", get("capsule_v"));
    assert!((get("capsule_spin") * radius - get("capsule_v")).abs() < 0.005 * rolling, "rolls without slip: {s}");
    assert!((get("sphere_v") - 5.0 / 7.0).abs() < 0.005, "sphere at {}", get("sphere_v"));
    assert!(get("after_switch").is_finite());
}

/// Capsules poured into a cylinder standing on a disk, and into the silo of
/// scripts/dem/silo_outlet_15mm.stl (a wall mesh: four sides and a floor with a 15 mm hole,
/// closed by a rectangle just under it, into which the 16 mm capsules dip): at rest the walls
/// carry their weight, to 0.5 %, and no capsule has passed through a wall.
#[test]
fn capsules_settle_in_a_cylinder_on_a_disk_and_in_a_silo_of_triangles() {
    let cloud = r#"count: 15, shape: "capsule", radius: 0.004, length: 0.008"#;
    for (name, s) in common::bodies::poured_into_containers("capsules", cloud, 2.0) {
        let get = |k: &str| s[k].as_f64().unwrap();
        assert!((get("carried") / get("weight") - 1.0).abs() < 0.005, "{name}: walls carry {s}");
        assert!(get("lowest") > 0.0, "{name}: a capsule below the floor: {s}");
    }
}

/// A capsule dropped nearly flat (tilted by 0.003 to 0.2 rad) on a plane, in a frictionless
/// elastic law: each end bears on the plane as a sphere would (a two-point contact), so the
/// impact keeps the energy to the time step's error (1e-4 asked, 2-3e-5 measured at a fiftieth of
/// the critical step; one contact at the ends' weighed point, whose force is no energy's gradient,
/// lost 1.3 % of it in such impacts). Then, damped, it rests with its weight shared by its two
/// ends.
#[test]
fn a_capsule_dropped_flat_keeps_its_energy_and_rests_on_both_ends() {
    use granite_core::dem::inspect::Member;
    let floor = |s: &mut common::bodies::Scene| {
        s.sim.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], s.material));
        Member::Wall(0)
    };
    dropped_flat(floor, 0.05, "plane");
}

/// A capsule dropped nearly flat (tilted by 0.003 to 0.2 rad) along a fixed capsule of its size
/// lying beneath it, in a frictionless elastic law: the two bear on each other at both ends of
/// their overlap (a two-point contact, as on a plane), so the impact keeps the energy to 1e-4
/// (1.4e-5 to 2.8e-5 measured; with the stretch's ends taken as points moving along the axis
/// instead of the capsules' end spheres, +4e-4); damped, it rests on the other with its weight
/// shared by the two points by the lever rule.
#[test]
fn a_capsule_dropped_flat_on_another_keeps_its_energy_and_rests_on_both_ends() {
    use granite_core::dem::inspect::Member;
    let floor = |s: &mut common::bodies::Scene| {
        let shape = s.capsule(0.01, 0.04);
        s.add_as(&shape, [0.0, 0.0, -0.01], along([1.0, 0.0, 0.0]), [[0.0; 3]; 2], true);
        Member::Body(0)
    };
    dropped_flat(floor, 0.06, "capsule");
}

/// A capsule (radius 1 cm, cylinder 4 cm) dropped from `height` onto what `floor` adds (a member
/// whose top is at z = 0), along x, tilted about y: see the two tests above.
fn dropped_flat(
    floor: impl Fn(&mut common::bodies::Scene) -> granite_core::dem::inspect::Member,
    height: f64,
    on: &str,
) {
    let (r, length, g) = (0.01, 0.04, 9.81);
    for tilt in [0.003, 0.01, 0.05, 0.2] {
        let mut s = scene(1000.0, &[("kn", 1e5), ("kt_ratio", 0.5), ("friction", 0.0)]);
        s.sim.world.gravity = [0.0, 0.0, -g];
        floor(&mut s);
        let shape = s.capsule(r, length);
        let q = UnitQuaternion::from_scaled_axis(nalgebra::Vector3::new(0.0, tilt, 0.0)) * along([1.0, 0.0, 0.0]);
        let i = s.add(&shape, [0.0, 0.0, height], q);
        let dt = 0.02 * s.sim.world.critical_dt().unwrap();
        s.sim.world.set_dt(dt).unwrap();
        // Leapfrog keeps velocities half a step behind positions: in flight the velocity at
        // the position is `v - g dt / 2` (none before the first step).
        let energy = |s: &common::bodies::Scene, lag: f64| {
            let k = &s.sim.world.kinds;
            let (m, v) = (k.mass[i], k.v[i]);
            let vz = v[2] - g * lag;
            let translation = 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            k.kinetic_energy() - translation + 0.5 * m * (v[0] * v[0] + v[1] * v[1] + vz * vz) + m * g * k.x[i][2]
        };
        let e0 = energy(&s, 0.0);
        let (mut touched, mut most) = (false, 0usize);
        loop {
            s.sim.step().unwrap();
            let n = s.sim.world.contacts.body_touching_count();
            most = most.max(n);
            touched |= n > 0;
            if touched && n == 0 {
                break;
            }
            assert!(s.sim.world.time < 1.0, "tilt {tilt}: still in contact after 1 s");
        }
        let e1 = energy(&s, 0.5 * dt);
        eprintln!(
            "capsule dropped on a {on} at tilt {tilt}: energy {e1:.9e} after the bounce, {e0:.9e} before ({:+.2e})",
            e1 / e0 - 1.0
        );
        assert!((e1 / e0 - 1.0).abs() < 1e-4, "on a {on}, tilt {tilt}: energy {e1} after the bounce, {e0} before");
        if tilt <= 0.01 {
            assert_eq!(most, 2, "on a {on}, tilt {tilt}: both ends struck at once");
        }
    }
    // At rest, damped: each end carries half the weight.
    let mut s = scene(1000.0, &[("kn", 1e5), ("kt_ratio", 0.5), ("friction", 30.0)]);
    s.sim.world.gravity = [0.0, 0.0, -g];
    let under = floor(&mut s);
    let shape = s.capsule(r, length);
    let q = UnitQuaternion::from_scaled_axis(nalgebra::Vector3::new(0.0, 0.05, 0.0)) * along([1.0, 0.0, 0.0]);
    let i = s.add(&shape, [0.0, 0.0, r + 0.01], q);
    s.sim.world.set_damping(0.3).unwrap();
    let dt = 0.1 * s.sim.world.critical_dt().unwrap();
    s.sim.world.set_dt(dt).unwrap();
    while s.sim.world.time < 1.0 {
        s.sim.step().unwrap();
    }
    // Each end carries the share of the weight the lever rule gives it about the other (half
    // where the centre lies midway between them).
    let (weight, centre) = (s.sim.world.kinds.mass[i] * g, s.sim.world.kinds.x[i][0]);
    let ends: Vec<(f64, f64)> = s
        .sim
        .world
        .body_contacts_of(i)
        .into_iter()
        .filter(|c| c.other == under)
        .map(|c| (c.point[0], c.force[2]))
        .collect();
    assert_eq!(ends.len(), 2, "on a {on}: two contacts at rest: {ends:?}");
    let span = ends[1].0 - ends[0].0;
    for (k, &(x, f)) in ends.iter().enumerate() {
        let share = (ends[1 - k].0 - centre) / (ends[1 - k].0 - x);
        eprintln!("on a {on}: an end at x = {x:.6e} carries {f:.9e} N of {weight:.9e} N, its lever share {share:.9}");
        assert!((f / (share * weight) - 1.0).abs() < 1e-6, "on a {on}: an end carries {f} N of {weight} N: {ends:?}");
    }
    assert!(span.abs() > 0.9 * length, "on a {on}: the ends {span} m apart");
}

/// A contact change that keeps the law keeps the bodies' contacts' history, as the spheres':
/// a capsule and a rounded box held on a 10° slope by static friction (their tangential springs
/// carrying `m g sin 10°`) stay where they are when the friction is raised; contacts starting
/// again would slide each by about that load over the tangential stiffness before holding again.
#[test]
fn a_contact_change_keeps_the_tangential_springs_of_bodies_at_rest() {
    let (kt, rho, g, theta) = (0.5e6f64, 1000.0f64, 9.81f64, 10f64.to_radians());
    let source = format!(
        r#"
        let sim = dem();
        let m = sim.material(#{{ density: {rho} }});
        sim.contact_law("linear", #{{ kn: 1e6, kt_ratio: 0.5, friction: 30.0 }});
        sim.wall_plane(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
        let cap = sim.capsule(m, [0.0, 0.0, 0.00999], #{{ radius: 0.01, length: 0.04, axis: [1.0, 0.0, 0.0] }});
        let block = sim.potential(m, [0.0, 0.2, 0.00599], #{{ shape: "potential_box", hx: 0.01, hy: 0.01, hz: 0.004, r: 0.002 }});
        sim.gravity([{gx}, 0.0, {gz}]);
        sim.damping(0.5);
        sim.dt(0.2 * sim.critical_dt());
        sim.run_until(0.3);
        let x0 = [sim.body_state(cap).position[0], sim.body_state(block).position[0]];
        summary("capsule_mass", sim.body_state(cap).mass);
        summary("block_mass", sim.body_state(block).mass);
        summary("capsule_speed", sim.body_state(cap).velocity[0]);
        sim.set_contact_params(#{{ friction: 35.0 }});
        sim.run_until(0.35);
        summary("capsule_moved", sim.body_state(cap).position[0] - x0[0]);
        summary("block_moved", sim.body_state(block).position[0] - x0[1]);
        "#,
        gx = g * theta.sin(),
        gz = -g * theta.cos()
    );
    let out = common::run_text("body_history_kept", &source);
    let s: serde_json::Value = common::summary_of(&out);
    let get = |k: &str| s[k].as_f64().unwrap();
    for body in ["capsule", "block"] {
        let slip = get(&format!("{body}_mass")) * g * theta.sin() / kt;
        let moved = get(&format!("{body}_moved"));
        assert!(moved.abs() < 0.01 * slip, "{body} moved {moved:e} m after the change (a reloading spring: {slip:e})");
    }
    assert!(get("capsule_speed").abs() < 1e-6, "at rest before the change: {s}");
}

/// Capsules placed into the floor, into one another and onto a sphere are said at the start of
/// the run as deep overlaps, as spheres are: each overlap over the smaller radius (a capsule's
/// is the radius of the sphere of its volume), deepest first.
#[test]
fn capsules_placed_into_the_floor_one_another_and_a_sphere_are_said() {
    let (r, l) = (0.01f64, 0.04f64);
    let source = format!(
        r#"
        let sim = dem();
        let m = sim.material(#{{ name: "g", density: 2500.0 }});
        sim.contact_law("linear", #{{ kn: 1e5, kt_ratio: 0.5, friction: 30.0 }});
        sim.wall_plane(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
        sim.capsule(m, [0.0, 0.0, 0.007], #{{ radius: {r}, length: {l}, axis: [1.0, 0.0, 0.0] }});
        sim.capsule(m, [0.2, 0.0, 0.05], #{{ radius: {r}, length: {l}, axis: [1.0, 0.0, 0.0] }});
        sim.capsule(m, [0.2, 0.0, 0.065], #{{ radius: {r}, length: {l}, axis: [0.0, 1.0, 0.0] }});
        sim.sphere(m, [0.4, 0.0, 0.05], {r});
        sim.capsule(m, [0.4, 0.0, 0.08], #{{ radius: {r}, length: {l}, axis: [0.0, 0.0, 1.0] }});
        sim.dt(0.1 * sim.critical_dt());
        sim.run_steps(1);
        "#
    );
    let out = common::run_text("capsule_overlaps", &source);
    let summary = common::summary_of(&out);
    let warnings: Vec<&str> = summary["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap()).collect();
    let said = warnings.iter().find(|w| w.contains("overlap by more than 10 %")).expect("the deep overlaps");
    let volume = std::f64::consts::PI * r * r * l + 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
    let r_eq = (3.0 * volume / (4.0 * std::f64::consts::PI)).cbrt();
    let percent = |overlap: f64, radius: f64| format!("{:.0} %", 100.0 * overlap / radius);
    // Into the floor by 3 mm; crossed capsules with axes 15 mm apart; the upright capsule's axis
    // ending 10 mm above the sphere's centre (its lower cap reaches the centre).
    let floor = format!("capsule 0 and wall 0 (\"plane\") by {}", percent(r - 0.007, r_eq));
    let crossed = format!("capsule 2 and capsule 1 by {}", percent(2.0 * r - 0.015, r_eq));
    let sphere = format!("capsule 4 and sphere 3 by {}", percent(2.0 * r - (0.08 - 0.5 * l - 0.05), r));
    for expected in [&floor, &crossed, &sphere] {
        assert!(said.contains(expected.as_str()), "expected {expected} in: {said}");
    }
}
