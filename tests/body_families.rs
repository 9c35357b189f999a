//! Bodies of two families in one simulation: capsules meeting potential particles through the
//! geometry the built-in plugins register for that pair (`capsule_potential`). Checked against a
//! sphere (a `k = 1` particle is one: the capsule must meet it as it meets a sphere), a capsule
//! resting across a rounded box (its weight in the spring), energy over many collisions, and a
//! saved state resumed bit for bit.

use crate::common;

use common::bodies::{along, scene};
use granite_core::dem::kinds::NewBody;
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::dem::DemSim;
use granite_core::math::Vec3;
use nalgebra::{UnitQuaternion, Vector3};

/// A `k = 1` potential particle is a sphere of radius `R`: a capsule meets it as it meets a sphere
/// there, with the same force and the same torques, wherever along its axis the two touch (its
/// side, the start of a cap, the end of a cap, obliquely).
#[test]
fn a_capsule_meets_a_k_one_particle_as_it_meets_a_sphere() {
    let (r, length, ball, kn) = (0.01, 0.06, 0.008, 1e5);
    let axis: Vec3 = [1.0, 0.4, -0.3];
    let norm = axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2];
    let u = axis.map(|c| c / norm.sqrt());
    // Centres of the ball: beside the axis at a tenth of its length, beside its end, beyond its
    // end on the axis, and off the end at 45 degrees; each overlapping by 0.1 to 1 mm.
    let side = [0.0, 0.3, 1.0];
    let s_norm = side.iter().map(|c| c * c).sum::<f64>().sqrt();
    let off = side.map(|c| c / s_norm);
    // Perpendicular to the axis: off minus its part along u.
    let along_u = off.iter().zip(&u).map(|(a, b)| a * b).sum::<f64>();
    let perp = [0, 1, 2].map(|a| off[a] - along_u * u[a]);
    let p_norm = perp.iter().map(|c| c * c).sum::<f64>().sqrt();
    let perp = perp.map(|c| c / p_norm);
    let reach = r + ball;
    let at = |s: f64, d: Vec3, depth: f64| [0, 1, 2].map(|a| s * u[a] + (reach - depth) * d[a]);
    let diagonal = [0, 1, 2].map(|a| (u[a] + perp[a]) / 2f64.sqrt());
    let cases = [
        at(0.1 * length, perp, 1e-4),
        at(0.5 * length, perp, 5e-4),
        at(0.5 * length, u, 1e-3),
        at(0.5 * length, diagonal, 2e-4),
        at(-0.5 * length, [-diagonal[0], -diagonal[1], -diagonal[2]], 3e-4),
    ];
    for centre in cases {
        let forces = |with_particle: bool| {
            let mut s = scene(2500.0, &[("kn", kn)]);
            let capsule = s.capsule(r, length);
            s.add(&capsule, [0.0; 3], along(u));
            if with_particle {
                let sphere = s.rounded_box([0.3 * ball; 3], 0.3 * ball, ball, 1.0);
                s.add(&sphere, centre, UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.7));
            } else {
                s.sim.world.add_sphere(s.material, centre, ball, [0.0; 3]).unwrap();
            }
            s.sim.world.set_dt(1e-9).unwrap();
            s.sim.step().unwrap();
            let k = &s.sim.world.kinds;
            assert_eq!(s.sim.world.contacts.body_touching_count(), 1, "ball at {centre:?}");
            (k.force[0], k.torque[0])
        };
        let ((f, t), (f_sphere, t_sphere)) = (forces(true), forces(false));
        let push = f_sphere.iter().map(|c| c * c).sum::<f64>().sqrt();
        let depth = push / kn;
        let force_error = (0..3).map(|a| (f[a] - f_sphere[a]).abs()).fold(0.0, f64::max);
        let torque_error = (0..3).map(|a| (t[a] - t_sphere[a]).abs()).fold(0.0, f64::max);
        eprintln!(
            "ball at {centre:?}: overlap {depth:.3e} m, force differs by {:.2e}, torque by {:.2e} of the sphere's",
            force_error / push,
            torque_error / (push * (length / 2.0 + r))
        );
        // A k = 1 particle meets a sphere exactly as a sphere does (its solve lands on the
        // optimum in one Newton step), and the search along the axis ends within 1e-7 r, which
        // moves the overlap by the square of that: both forces agree to rounding.
        let doubt = 1e-9;
        assert!(force_error < doubt * push, "force {f:?} against the sphere's {f_sphere:?}");
        assert!(torque_error < doubt * push * (length / 2.0 + r), "torque {t:?} against the sphere's {t_sphere:?}");
    }
}

/// A capsule lying across the top face of a fixed rounded box settles on it and carries its weight
/// in the spring, `k_n u_n = m g` (to 1e-5, at rest after damping), and stays level: its one
/// contact bears under its centre of mass (a bearing point off it would tip the capsule over the
/// face, which is slightly convex for `k > 0`).
#[test]
fn a_capsule_lying_across_a_rounded_box_carries_its_weight_in_the_spring() {
    let (r, length, kn, g) = (0.004, 0.03, 2000.0, 9.81);
    let mut s = scene(1200.0, &[("kn", kn), ("kt_ratio", 0.5), ("friction", 30.0)]);
    s.sim.world.gravity = [0.0, 0.0, -g];
    let (half, rounding) = (0.01, 0.002);
    let block = s.rounded_box([half; 3], rounding, 10.0 * half, 0.05);
    s.add_as(&block, [0.0; 3], UnitQuaternion::identity(), [[0.0; 3]; 2], true);
    let capsule = s.capsule(r, length);
    // Across the face, its axis nearly along x, a little off the middle, dropped from 1 mm.
    let face = half + rounding;
    s.add(&capsule, [0.002, -0.001, face + r + 1e-3], along([1.0, 0.1, 0.0]));
    s.sim.world.set_damping(0.3).unwrap();
    s.sim.world.set_dt(0.1 * s.sim.world.critical_dt().unwrap()).unwrap();
    for _ in 0..30_000 {
        s.sim.step().unwrap();
    }
    let k = &s.sim.world.kinds;
    let weight = k.mass[1] * g;
    let lift = k.force[1][2];
    eprintln!("capsule on a rounded box: lift {lift:.6e} N, weight {weight:.6e} N, at {:?}", k.x[1]);
    assert_eq!(s.sim.world.contacts.body_touching_count(), 1);
    assert!((lift / weight - 1.0).abs() < 1e-5, "the box lifts {lift} N of a weight of {weight} N");
    let level = (k.q[1] * Vector3::z())[2];
    assert!(level.abs() < 1e-3, "the capsule lies level: its axis rises by {level}");
}

/// A spinning capsule struck off-centre by a `k = 1` particle (a sphere to the geometry), in free
/// space, frictionless and elastic: the contact point slides along the capsule's axis as it
/// turns, and the search follows it. The collision keeps the kinetic energy (the geometry is that
/// of two spheres at every instant, so the contact force is conservative) and ends with the
/// velocities the same collision with a sphere of the engine's gives.
#[test]
fn a_spinning_capsule_struck_by_a_particle_rebounds_as_from_a_sphere() {
    let (r, length, ball) = (0.01, 0.06, 0.008);
    for (offset, spin, speed) in [(0.0, 0.0, 0.5), (0.015, 20.0, 0.5), (-0.02, -40.0, 0.8), (0.028, 60.0, 0.3)] {
        let collide = |with_particle: bool| {
            let mut s = scene(1000.0, &[("kn", 1e4)]);
            let capsule = s.capsule(r, length);
            // The capsule along x, turning about z; the ball coming down y towards it, `offset`
            // along its axis.
            s.add_as(&capsule, [0.0; 3], along([1.0, 0.0, 0.0]), [[0.0; 3], [0.0, 0.0, spin]], false);
            let (start, v) = ([offset, r + ball + 0.002, 0.001], [0.0, -speed, 0.0]);
            if with_particle {
                let sphere = s.rounded_box([0.3 * ball; 3], 0.3 * ball, ball, 1.0);
                s.add_as(&sphere, start, UnitQuaternion::identity(), [v, [0.0; 3]], false);
            } else {
                s.sim.world.add_sphere(s.material, start, ball, v).unwrap();
            }
            // One time step for both scenes (a fiftieth of the ball's critical step).
            let dt = 1e-5;
            s.sim.world.set_dt(dt).unwrap();
            let energy = |sim: &DemSim| {
                let sp = &sim.world.spheres;
                let spheres = (0..sp.len()).map(|i| 0.5 * sp.mass[i] * sp.v[i].iter().map(|c| c * c).sum::<f64>());
                sim.world.kinds.kinetic_energy() + spheres.sum::<f64>()
            };
            let e0 = energy(&s.sim);
            let (mut touched, mut steps) = (0, 0);
            while steps < 200_000 {
                s.sim.step().unwrap();
                steps += 1;
                let touching = s.sim.world.contacts.body_touching_count() > 0;
                touched += touching as usize;
                if touched > 0 && !touching {
                    break;
                }
            }
            assert!(touched > 10, "offset {offset}: the ball hit the capsule ({touched} steps in contact)");
            let k = &s.sim.world.kinds;
            let ball_v = if with_particle { k.v[1] } else { s.sim.world.spheres.v[0] };
            (energy(&s.sim) / e0 - 1.0, k.v[0], k.w[0], ball_v)
        };
        let (drift, v, w, ball_v) = collide(true);
        let (drift_s, v_s, w_s, ball_v_s) = collide(false);
        let differ = |a: Vec3, b: Vec3| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max);
        let (dv, dw, db) = (differ(v, v_s) / speed, differ(w, w_s) * r / speed, differ(ball_v, ball_v_s) / speed);
        eprintln!(
            "offset {offset}, spin {spin}: energy {drift:+.2e} (with a sphere {drift_s:+.2e}); velocities differ from \
             the sphere's by {dv:.1e}, {dw:.1e}, {db:.1e} of the speed"
        );
        // Leapfrog over the contact's start and end leaves some 1e-5 either way. The particle's
        // mass and inertia come from its shape's volume integral (`MASS_RESOLUTION`), 2e-4 above
        // the sphere's: the velocities after the collision agree to that order, not to rounding.
        assert!(drift.abs() < 1e-4, "offset {offset}: the kinetic energy changed by {drift:.3e}");
        assert!(
            dv.max(dw).max(db) < 1e-3,
            "offset {offset}: {v:?} {w:?} {ball_v:?} against {v_s:?} {w_s:?} {ball_v_s:?}"
        );
    }
}

/// Capsules resting on rounded boxes and spheres between them, saved half way and resumed: the
/// resumed run goes on bit for bit (both families, each body's family and the pairs' warm starts
/// are in the state).
#[test]
fn a_saved_state_with_capsules_and_potential_particles_resumes_bit_for_bit() {
    let build = || {
        let mut s = scene(1500.0, &[("kn", 2e3), ("kt_ratio", 0.5), ("friction", 25.0)]);
        s.sim.world.gravity = [0.0, 0.0, -9.81];
        s.sim.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], s.material));
        let block = s.rounded_box([0.006, 0.006, 0.004], 0.001, 0.05, 0.1);
        let capsule = s.capsule(0.003, 0.02);
        // Dropped from a few tenths of a millimetre: each block onto the floor, a capsule across
        // it, a sphere onto the first capsule.
        for k in 0..3 {
            let x = 0.016 * k as f64;
            s.add(&block, [x, 0.0, 0.0055], UnitQuaternion::identity());
            s.add(&capsule, [x + 0.002, 0.001 * k as f64, 0.0055 + 0.0051 + 0.0035], along([0.2, 1.0, 0.05]));
        }
        s.sim.world.add_sphere(s.material, [0.002, 0.0, 0.0141 + 0.0065], 0.003, [0.0; 3]).unwrap();
        s.sim.world.set_damping(0.3).unwrap();
        let dt = 0.2 * s.sim.world.critical_dt().unwrap();
        s.sim.world.set_dt(dt).unwrap();
        s.sim
    };
    let (straight, written, resumed) = common::straight_and_resumed(build, 3000, "families_state");
    let (k, p) = (&written.world.kinds, &written.world.contacts.bodies);
    let touching = (0..p.len()).filter(|&c| p.touching[c]).map(|c| (p.a[c] as usize, p.b[c] as usize));
    let mixed = touching.filter(|&(a, b)| k.family[a] != k.family[b]).count();
    assert!(mixed >= 3, "every capsule rests on its block when the state is written ({mixed} capsule-block contacts)");
    let (a, b) = (&straight.world.kinds, &resumed.world.kinds);
    assert!(a.x == b.x && a.v == b.v && a.w == b.w && a.q == b.q, "the resumed bodies parted from the straight run");
    assert!(straight.world.spheres.x == resumed.world.spheres.x);
    assert_eq!(straight.world.contacts.body_touching_count(), resumed.world.contacts.body_touching_count());
}

/// Bodies of a family join a scene of another only where a geometry of their pair is registered:
/// without one, the second family is refused, naming both and the pairs that are known.
#[test]
fn a_family_without_a_geometry_for_the_scene_s_family_is_refused() {
    let mut s = scene(1000.0, &[("kn", 1e4)]);
    let capsule = s.capsule(0.01, 0.02);
    s.add(&capsule, [0.0; 3], UnitQuaternion::identity());
    let block = s.rounded_box([0.01; 3], 0.002, 0.1, 0.1);
    let kind = s.registry.body_kind("potential").unwrap().clone();
    let body = NewBody {
        kind: kind.as_ref(),
        meetings: &[],
        shape: block,
        material: s.material,
        x: [0.1, 0.0, 0.0],
        q: UnitQuaternion::identity(),
        v: [0.0; 3],
        w: [0.0; 3],
        fixed: false,
    };
    let e = s.sim.world.add_body(body).unwrap_err().to_string();
    assert!(e.contains("potential bodies cannot join capsule bodies") && e.contains("known: none"), "{e}");
}

/// A scene keeps a family whose bodies were all removed while others remain: its saved state
/// names that family by the kind it joined with, and loads.
#[test]
fn a_state_keeping_a_family_without_bodies_loads() {
    let mut s = scene(1000.0, &[("kn", 1e4)]);
    let capsule = s.capsule(0.01, 0.02);
    let block = s.rounded_box([0.01; 3], 0.002, 0.1, 0.1);
    s.add(&capsule, [0.0; 3], UnitQuaternion::identity());
    s.add(&block, [0.1, 0.0, 0.0], UnitQuaternion::identity());
    s.sim.world.remove_bodies(&[false, true]);
    s.sim.world.set_dt(1e-5).unwrap();
    s.sim.step().unwrap();
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("family_without_bodies.json");
    s.sim.save(&path).unwrap();
    let loaded = DemSim::load(&path, &granite::registry()).unwrap();
    assert_eq!(loaded.world.kinds.families.len(), 2);
    assert_eq!(loaded.world.kinds.kind_name(0), "potential");
}
