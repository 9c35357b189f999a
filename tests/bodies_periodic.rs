#![allow(clippy::needless_range_loop)]
//! Bodies of plugin kinds (capsules, potential particles) in a periodic cell: a thin cell, whose
//! capsules touch their own images and each other's across its faces, steps as the same packing
//! in a cell four times as thick; capsules of no length step as spheres in a sheared and stretched
//! cell; a free capsule keeps zero fluctuation under stretching wherever it sits (SLLOD).

use crate::common;

use common::bodies::{scene, Scene};
use granite_core::dem::cell::PeriodicCell;
use granite_core::math::Vec3;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// A few capsules and spheres in a cell `copies` times as thick along y as a capsule's radius
/// times 1.6: the capsules lie along x, slightly tilted, rows of them along x and z.
fn packing(copies: usize, l: Matrix3<f64>) -> (Scene, usize) {
    let (r, length, kn) = (0.01, 0.01, 1e5);
    let mut s = scene(2500.0, &[("kn", kn), ("kt_ratio", 0.5), ("friction", 20.0)]);
    let shape = s.capsule(r, length);
    let (dx, dz, thick) = (1.9 * (r + 0.5 * length), 1.9 * r, 1.6 * r);
    let (nx, nz) = (3, 4);
    let mut next = common::uniform_stream(7);
    let mut capsules: Vec<(Vec3, UnitQuaternion<f64>)> = Vec::new();
    for i in 0..nx {
        for k in 0..nz {
            let x = [(i as f64 + 0.5 + 0.05 * next()) * dx, next() * thick, (k as f64 + 0.5 + 0.05 * next()) * dz];
            let tilt = Vector3::new(0.0, 0.2 * (next() - 0.5), 0.2 * (next() - 0.5));
            let q = UnitQuaternion::from_scaled_axis(tilt) * common::bodies::along([1.0, 0.0, 0.0]);
            capsules.push((x, q));
        }
    }
    // Spheres between the rows of capsules, in the space a capsule end leaves.
    let balls: Vec<(Vec3, f64)> =
        (0..nz).map(|k| ([nx as f64 * dx - 0.2 * r, next() * thick, (k as f64 + 0.5) * dz], 0.9 * r)).collect();
    let size = [nx as f64 * dx + 1.2 * r, copies as f64 * thick, nz as f64 * dz];
    s.sim.world.set_cell(Some(PeriodicCell::new_box(size)));
    for c in 0..copies {
        let up = |x: Vec3| [x[0], x[1] + c as f64 * thick, x[2]];
        for (x, q) in &capsules {
            s.add(&shape, up(*x), *q);
        }
        for (x, radius) in &balls {
            s.sim.world.add_sphere(s.material, up(*x), *radius, [0.0; 3]).unwrap();
        }
    }
    s.sim.skin = 0.1 * r;
    s.sim.world.set_dt(2e-6).unwrap();
    s.sim.world.cell.as_mut().unwrap().velocity_gradient = l;
    (s, capsules.len())
}

/// The thin cell and the four times thicker one after 400 steps under `l`: the same Love-Weber
/// stress to 1e-6, four copies of each contact, and each capsule's velocity and spin alike in
/// every copy.
fn thin_and_thick_cells_agree(l: Matrix3<f64>) {
    let ((mut thin, n), (mut thick, _)) = (packing(1, l), packing(4, l));
    for step in 0..400 {
        thin.sim.step().unwrap();
        thick.sim.step().unwrap();
        if step == 0 {
            let p = &thin.sim.world.contacts.bodies;
            assert!(
                (0..p.len()).any(|k| p.touching[k] && p.a[k] == p.b[k]),
                "no capsule touches its own image: the test checks nothing there"
            );
            let sp = &thin.sim.world.contacts.body_spheres;
            assert!(
                (0..sp.len()).any(|k| sp.touching[k] && sp.shift[k] != [0; 3]),
                "no capsule touches a sphere's image: the test checks nothing there"
            );
        }
    }
    let stress = |s: &Scene| s.sim.world.love_weber_stress(s.sim.world.cell_volume().unwrap());
    let (st, sk) = (stress(&thin), stress(&thick));
    assert!(st[0] < 0.0 && st[1] < 0.0 && st[2] < 0.0, "the packing is compressed: {st:?}");
    let scale = st.iter().map(|v| v.abs()).fold(0.0, f64::max);
    for a in 0..6 {
        assert!((st[a] - sk[a]).abs() < 1e-6 * scale, "sigma[{a}]: thin cell {}, thick cell {}", st[a], sk[a]);
    }
    let (kt, kk) = (&thin.sim.world.kinds, &thick.sim.world.kinds);
    assert_eq!(4 * thin.sim.world.contacts.body_touching_count(), thick.sim.world.contacts.body_touching_count());
    let close = |a: Vec3, b: Vec3, what: &str| {
        let d = (0..3).map(|q| (a[q] - b[q]).abs()).fold(0.0, f64::max);
        let size = a.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(d < 1e-6 * (1e-3 + size), "{what}: {a:?} against {b:?}");
    };
    for i in 0..n {
        for c in 0..4 {
            close(kt.v[i], kk.v[c * n + i], &format!("capsule {i} copy {c} velocity"));
            close(kt.w[i], kk.w[c * n + i], &format!("capsule {i} copy {c} spin"));
        }
    }
}

#[test]
fn capsules_in_a_thin_cell_step_as_in_a_thicker_one_when_sheared() {
    let mut l = Matrix3::zeros();
    l[(0, 1)] = 50.0;
    thin_and_thick_cells_agree(l);
}

#[test]
fn capsules_in_a_thin_cell_step_as_in_a_thicker_one_when_stretched() {
    // Stretched along x, squeezed across the thin axis and sheared: SLLOD's update keeps each
    // capsule and its images together.
    thin_and_thick_cells_agree(Matrix3::new(25.0, 10.0, 0.0, 0.0, -25.0, 0.0, 0.0, 0.0, 0.0));
}

#[test]
fn a_free_capsule_keeps_no_fluctuation_in_a_stretched_cell_wherever_it_sits() {
    let l = Matrix3::new(20.0, 5.0, 0.0, 0.0, -10.0, 0.0, 0.0, 0.0, -10.0);
    for at in [[0.05, 0.05, 0.05], [0.9, 0.1, 0.5], [0.3, 0.95, 0.9]] {
        let mut s = scene(2500.0, &[("kn", 1e5)]);
        s.sim.world.set_cell(Some(PeriodicCell::new_box([1.0; 3])));
        let shape = s.capsule(0.01, 0.02);
        s.add(&shape, at, common::bodies::along([0.3, 0.4, 0.5]));
        s.sim.world.set_dt(1e-4).unwrap();
        s.sim.world.cell.as_mut().unwrap().velocity_gradient = l;
        for _ in 0..1000 {
            s.sim.step().unwrap();
        }
        let v = s.sim.world.kinds.v[0];
        assert!(v.iter().all(|c| c.abs() < 1e-12), "capsule set at {at:?}: fluctuation {v:?}");
        // It went with the field: still inside the cell after the rebuilds wrapped it.
        let cell = s.sim.world.cell.as_ref().unwrap();
        let reduced = cell.reduced(&cell.inverse(), s.sim.world.kinds.x[0]);
        assert!(reduced.iter().all(|c| (-0.5..1.5).contains(c)), "capsule at reduced {reduced:?}");
    }
}

#[test]
fn capsules_of_no_length_step_as_spheres_in_a_sheared_and_stretched_cell() {
    // A capsule of length 0 is a sphere (the same mass and moments): a packing of them meets its
    // images through the bodies' stages as one of spheres does through the spheres'.
    let r = 0.01;
    let l = Matrix3::new(20.0, 30.0, 0.0, 0.0, -10.0, 5.0, 0.0, 0.0, -10.0);
    let mut next = common::uniform_stream(3);
    let (n, spacing) = (3usize, 1.85 * r);
    let grains: Vec<(Vec3, f64)> = (0..n * n * n)
        .map(|c| {
            let at = [c % n, c / n % n, c / (n * n)].map(|k| (k as f64 + 0.5 + 0.05 * next()) * spacing);
            (at, r * (0.9 + 0.1 * next()))
        })
        .collect();
    let run = |as_capsules: bool| {
        let mut s = scene(2500.0, &[("kn", 1e5), ("kt_ratio", 0.5), ("friction", 20.0)]);
        s.sim.world.set_cell(Some(PeriodicCell::new_box([n as f64 * spacing; 3])));
        for (x, radius) in &grains {
            if as_capsules {
                let shape = s.capsule(*radius, 0.0);
                s.add(&shape, *x, UnitQuaternion::identity());
            } else {
                s.sim.world.add_sphere(s.material, *x, *radius, [0.0; 3]).unwrap();
            }
        }
        s.sim.skin = 0.1 * r;
        s.sim.world.set_dt(2e-6).unwrap();
        s.sim.world.cell.as_mut().unwrap().velocity_gradient = l;
        for _ in 0..300 {
            s.sim.step().unwrap();
        }
        let w = &s.sim.world;
        let (v, spin) = if as_capsules {
            (w.kinds.v.clone(), w.kinds.w.clone())
        } else {
            (w.spheres.v.clone(), w.spheres.w.clone())
        };
        (w.love_weber_stress(w.cell_volume().unwrap()), v, spin)
    };
    let (spheres, capsules) = (run(false), run(true));
    let scale = spheres.0.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(spheres.0[3].abs() > 1e-3 * scale, "no shear stress: {:?}", spheres.0);
    for a in 0..6 {
        let (s, c) = (spheres.0[a], capsules.0[a]);
        assert!((s - c).abs() < 1e-9 * scale, "sigma[{a}]: spheres {s}, capsules {c}");
    }
    let vmax = spheres.1.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(vmax > 0.0, "nothing moves: the test checks nothing");
    for i in 0..grains.len() {
        for q in 0..3 {
            assert!((spheres.1[i][q] - capsules.1[i][q]).abs() < 1e-9 * vmax, "grain {i} velocity");
            assert!((spheres.2[i][q] - capsules.2[i][q]).abs() < 1e-9 * vmax / r, "grain {i} spin");
        }
    }
}

/// Rounded boxes (potential particles) compacted isotropically in a periodic cell by the stress
/// servo: bodies cross the faces and are wrapped back while in contact, their contact problems
/// starting from the last step's solutions (kept relative to the body, so a wrapped pair starts
/// where it left off), until the contacts' Love-Weber stress holds the goal in equilibrium.
#[test]
fn rounded_boxes_compact_to_a_stress_in_a_periodic_cell() {
    let out = common::run_text(
        "potential_periodic",
        r#"
        let sim = dem(#{ seed: 3 });
        let m = sim.material(#{ name: "g", density: 2650.0 });
        let h = 1e-3;
        let w = 0.0297;
        sim.periodic([w, w, w]);
        sim.clump_cloud(m, [0.0, 0.0, 0.0], [w, w, w], #{ count: 200, shape: "potential_box", hx: h, hy: h, hz: 0.6 * h, r: 0.25 * h });
        sim.contact_law("linear", #{ kn: 1e4, kt_ratio: 0.5, friction: 0.3 });
        sim.dt(0.2 * sim.critical_dt());
        sim.damping(0.4);
        let goal = #{ stress: -1e4, max_rate: 20.0 };
        sim.cell_control(#{ x: goal, y: goal, z: goal, relax_steps: 20 });
        let rounds = 0;
        loop {
            sim.run_steps(1000);
            rounds += 1;
            if sim.stress_reached(0.01) && sim.diagnostics().unbalanced_force < 0.01 { break; }
            if rounds > 100 { throw "no equilibrium in 1e5 steps"; }
        }
        let s = sim.cell_stress();
        summary("mean_stress", (s[0] + s[1] + s[2]) / 3.0);
        summary("contacts", sim.diagnostics().contacts);
        summary("void_ratio", sim.void_ratio());
        "#,
    );
    let summary = common::summary_of(&out);
    let p = summary["mean_stress"].as_f64().unwrap();
    assert!((p + 1e4).abs() < 0.01e4, "mean stress {p}");
    // 200 boxes held by their contacts, each in several.
    assert!(summary["contacts"].as_f64().unwrap() > 2.0 * 200.0, "{summary}");
    let e = summary["void_ratio"].as_f64().unwrap();
    assert!(e > 0.2 && e < 1.0, "void ratio {e}");
}

/// A sheared thin cell of capsules and spheres saved half way and resumed from its file goes on
/// bit for bit: the pairs' images (shifts), the cell and its field come back with the bodies.
#[test]
fn capsules_in_a_sheared_cell_resume_from_a_saved_state_bit_for_bit() {
    let mut l = Matrix3::zeros();
    l[(0, 1)] = 50.0;
    let (straight, written, resumed) = common::straight_and_resumed(|| packing(1, l).0.sim, 200, "capsules_cell_state");
    let crossing = written.world.contacts.bodies.shift.iter().filter(|s| **s != [0; 3]).count();
    assert!(crossing > 0, "no pair across the cell's faces when saved: the test checks nothing there");
    let (a, b) = (&straight.world.kinds, &resumed.world.kinds);
    assert_eq!(a.x, b.x);
    assert_eq!(a.v, b.v);
    assert_eq!(a.w, b.w);
    assert_eq!(straight.world.spheres.x, resumed.world.spheres.x);
    assert_eq!(straight.world.cell, resumed.world.cell);
}

/// Rounded boxes (potential particles) in a cell thinner than one box, touching their own images
/// and each other's across its faces, step as the same packing in a cell four times as thick
/// under shear: their contact problems with images are solved from warm starts kept relative to
/// the body, as any pair's.
#[test]
fn rounded_boxes_in_a_thin_cell_step_as_in_a_thicker_one_when_sheared() {
    let (half, kn) = (0.01, 1e5);
    let (nx, nz, gap, thick) = (3, 3, 1.9 * half, 1.7 * half);
    let mut next = common::uniform_stream(11);
    let mut boxes: Vec<(Vec3, UnitQuaternion<f64>)> = Vec::new();
    for i in 0..nx {
        for k in 0..nz {
            let x = [(i as f64 + 0.5) * gap, next() * thick, (k as f64 + 0.5) * gap];
            let tilt = Vector3::new(0.2 * (next() - 0.5), 0.2 * (next() - 0.5), 0.2 * (next() - 0.5));
            boxes.push((x, UnitQuaternion::from_scaled_axis(tilt)));
        }
    }
    let mut l = Matrix3::zeros();
    l[(0, 1)] = 50.0;
    let build = |copies: usize| {
        let mut s = scene(2500.0, &[("kn", kn), ("kt_ratio", 0.5), ("friction", 20.0)]);
        let shape = s.rounded_box([0.6 * half; 3], 0.4 * half, 4.0 * half, 0.3);
        s.sim.world.set_cell(Some(PeriodicCell::new_box([nx as f64 * gap, copies as f64 * thick, nz as f64 * gap])));
        for c in 0..copies {
            for (x, q) in &boxes {
                s.add(&shape, [x[0], x[1] + c as f64 * thick, x[2]], *q);
            }
        }
        s.sim.skin = 0.1 * half;
        s.sim.world.set_dt(2e-6).unwrap();
        s.sim.world.cell.as_mut().unwrap().velocity_gradient = l;
        s
    };
    let (mut thin, mut thick_cell) = (build(1), build(4));
    for step in 0..300 {
        thin.sim.step().unwrap();
        thick_cell.sim.step().unwrap();
        if step == 0 {
            let p = &thin.sim.world.contacts.bodies;
            assert!(
                (0..p.len()).any(|k| p.touching[k] && p.a[k] == p.b[k]),
                "no box touches its own image: the test checks nothing there"
            );
        }
    }
    let stress = |s: &Scene| s.sim.world.love_weber_stress(s.sim.world.cell_volume().unwrap());
    let (st, sk) = (stress(&thin), stress(&thick_cell));
    assert!(st[1] < 0.0, "the packing is compressed: {st:?}");
    let scale = st.iter().map(|v| v.abs()).fold(0.0, f64::max);
    for a in 0..6 {
        assert!((st[a] - sk[a]).abs() < 1e-6 * scale, "sigma[{a}]: thin cell {}, thick cell {}", st[a], sk[a]);
    }
    // Each contact problem is solved to a tolerance (1e-8 of the potential's value), from the
    // pair's own last solution, and a copy in the thick cell may meet its neighbour from the other
    // side: the two agree to what that tolerance leaves (1.5e-6 of a spin after 300 steps).
    let n = boxes.len();
    let (kt, kk) = (&thin.sim.world.kinds, &thick_cell.sim.world.kinds);
    for i in 0..n {
        for c in 0..4 {
            for (a, b) in [(kt.v[i], kk.v[c * n + i]), (kt.w[i], kk.w[c * n + i])] {
                let d = (0..3).map(|q| (a[q] - b[q]).abs()).fold(0.0, f64::max);
                let size = a.iter().map(|v| v.abs()).fold(0.0, f64::max);
                assert!(d < 1e-5 * (1e-3 + size), "box {i} copy {c}: {a:?} against {b:?}");
            }
        }
    }
}
