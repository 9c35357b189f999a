#![allow(clippy::needless_range_loop)]
//! Periodic cell: affine motion of a sheared gas, flips that keep every particle and contact,
//! and the Love-Weber stress of a hand-built packing.

use granite_core::dem::cell::{CellUpdate, PeriodicCell};
use granite_core::dem::DemSim;
use granite_core::registry::ParamMap;

fn params(pairs: &[(&str, f64)]) -> ParamMap {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

fn sim_with_law(kn: f64) -> (DemSim, u16) {
    let mut sim = DemSim::new();
    let m = sim.world.add_material("m", 2500.0).unwrap();
    let law = granite::registry()
        .build_contact_law("linear", &params(&[("kn", kn), ("kt_ratio", 0.5), ("friction", 20.0)]))
        .unwrap();
    sim.world.set_contact_law(law, None).unwrap();
    (sim, m)
}

#[test]
fn sheared_gas_moves_affinely_through_flips() {
    let (mut sim, m) = sim_with_law(1e4);
    let size = 1.0;
    sim.world.set_cell(Some(PeriodicCell::new_box([size; 3])));
    // A dilute gas: 5 x 5 x 5 small spheres at rest, far from each other.
    let mut x0 = Vec::new();
    for i in 0..5 {
        for j in 0..5 {
            for k in 0..5 {
                let x = [0.1 + 0.2 * i as f64, 0.1 + 0.2 * j as f64, 0.1 + 0.2 * k as f64];
                sim.world.add_sphere(m, x, 0.01, [0.0; 3]).unwrap();
                x0.push(x);
            }
        }
    }
    sim.skin = 0.005;
    let rate = 2.0;
    sim.world.cell.as_mut().unwrap().velocity_gradient[(0, 2)] = rate;
    sim.world.set_dt(1e-3).unwrap();
    let steps = 800; // total shear strain 1.6: flips at 0.5 and 1.5
    for _ in 0..steps {
        sim.step().unwrap();
    }
    let cell = sim.world.cell.as_ref().unwrap();
    assert!(cell.flips >= 2, "expected flips, got {}", cell.flips);
    assert_eq!(sim.world.spheres.len(), 125, "no particle may be lost");
    let gamma = rate * sim.world.time;
    let inv = cell.inverse();
    for (i, x) in sim.world.spheres.x.iter().enumerate() {
        // Affine image of the start position, compared modulo the (flipped) lattice.
        let expect = [x0[i][0] + gamma * x0[i][2], x0[i][1], x0[i][2]];
        let d = [x[0] - expect[0], x[1] - expect[1], x[2] - expect[2]];
        let s = cell.reduced(&inv, d);
        let frac: f64 = s.iter().map(|c| (c - c.round()).abs()).fold(0.0, f64::max);
        assert!(frac < 1e-9, "sphere {i} left the affine field: reduced offset {s:?}");
        assert!(sim.world.spheres.v[i].iter().all(|c| c.abs() < 1e-12), "fluctuation velocity appeared");
    }
}

/// Newton's first law in a deforming cell, under `cell_update("newton")`: a sphere that touches
/// nothing keeps its whole velocity (fluctuation plus the field `L x`) and moves in a straight
/// line, whatever the cell does around it, as in YADE's `homoDeform` 1. The fluctuation alone
/// changes: the field differs where the sphere goes.
#[test]
fn under_newton_a_free_sphere_keeps_its_velocity_in_a_deforming_cell() {
    let (mut sim, m) = sim_with_law(1e4);
    sim.world.set_cell(Some(PeriodicCell::new_box([1.0; 3])));
    sim.world.cell.as_mut().unwrap().update = CellUpdate::Newton;
    let (x0, v0) = ([0.5, 0.4, 0.3], [0.01, -0.02, 0.03]);
    sim.world.add_sphere(m, x0, 0.01, v0).unwrap();
    // Shear, stretch and compression together.
    let l = nalgebra::Matrix3::new(0.1, 0.0, 0.5, 0.0, 0.05, 0.0, 0.2, 0.0, -0.15);
    sim.world.cell.as_mut().unwrap().velocity_gradient = l;
    sim.world.set_dt(1e-3).unwrap();
    let whole = |sim: &DemSim| {
        let (x, v) = (sim.world.spheres.x[0], sim.world.spheres.v[0]);
        let lx = l * nalgebra::Vector3::new(x[0], x[1], x[2]);
        [v[0] + lx[0], v[1] + lx[1], v[2] + lx[2]]
    };
    let v_start = whole(&sim);
    let steps = 200;
    for _ in 0..steps {
        sim.step().unwrap();
    }
    let t = steps as f64 * 1e-3;
    let (v_end, x) = (whole(&sim), sim.world.spheres.x[0]);
    for a in 0..3 {
        assert!((v_end[a] - v_start[a]).abs() < 1e-14, "velocity {v_end:?}, started at {v_start:?}");
        // Well inside the cell: no wrapping to undo.
        let straight = x0[a] + v_start[a] * t;
        assert!((x[a] - straight).abs() < 1e-12, "at {x:?}, a straight line gives {straight}");
    }
    // The fluctuation did change, by -L (x - x0): the test is not one of a sphere at rest in the field.
    let moved = l * nalgebra::Vector3::new(x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]);
    for a in 0..3 {
        assert!((sim.world.spheres.v[0][a] - (v0[a] - moved[a])).abs() < 1e-12);
    }
    assert!(moved.norm() > 1e-3);
}

/// SLLOD (the default): a free sphere's fluctuation follows `v <- (I - L dt) v` whatever its
/// place, so one with none keeps none, to rounding, in a cell stretched, compressed and sheared
/// at once, wherever it sits; one with a fluctuation ends at `(I - L dt)^N v0`. Under Newton's
/// law for the whole velocity the same spheres gain fluctuations in proportion to their distance
/// from the cell's origin (`-L L x dt` a step): the test tells the two apart.
#[test]
fn under_sllod_a_free_spheres_fluctuation_does_not_depend_on_where_it_sits() {
    let l = nalgebra::Matrix3::new(20.0, 0.0, 5.0, 0.0, 8.0, 0.0, 3.0, 0.0, -15.0);
    let (dt, steps) = (1e-4, 1000);
    let places = [[0.1, 0.1, 0.1], [0.5, 0.5, 0.5], [0.9, 0.2, 0.7], [0.3, 0.8, 0.95]];
    let run = |update: CellUpdate, v0: [f64; 3]| {
        let (mut sim, m) = sim_with_law(1e4);
        sim.world.set_cell(Some(PeriodicCell::new_box([1.0; 3])));
        for x in places {
            sim.world.add_sphere(m, x, 0.01, v0).unwrap();
        }
        let cell = sim.world.cell.as_mut().unwrap();
        cell.velocity_gradient = l;
        cell.update = update;
        sim.world.set_dt(dt).unwrap();
        for _ in 0..steps {
            sim.step().unwrap();
        }
        sim.world.spheres.v.clone()
    };
    let largest = |v: &[[f64; 3]]| v.iter().flatten().map(|c| c.abs()).fold(0.0, f64::max);
    assert!(largest(&run(CellUpdate::Sllod, [0.0; 3])) < 1e-12, "a fluctuation appeared");
    assert!(largest(&run(CellUpdate::Newton, [0.0; 3])) > 1e-3, "Newton's update left the spheres in the field");
    let v0 = [0.01, -0.02, 0.03];
    let step = nalgebra::Matrix3::identity() - l * dt;
    let expect = step.pow(steps) * nalgebra::Vector3::from(v0);
    for v in run(CellUpdate::Sllod, v0) {
        for a in 0..3 {
            assert!((v[a] - expect[a]).abs() < 1e-12, "fluctuation {v:?}, (I - L dt)^N v0 = {expect:?}");
        }
    }
}

/// A simple cubic packing of equal spheres of radius r, overlap delta, spacing d = 2r - delta.
fn cubic_packing(n: usize, r: f64, delta: f64, kn: f64) -> DemSim {
    let (mut sim, m) = sim_with_law(kn);
    let d = 2.0 * r - delta;
    sim.world.set_cell(Some(PeriodicCell::new_box([n as f64 * d; 3])));
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                sim.world
                    .add_sphere(m, [(i as f64 + 0.5) * d, (j as f64 + 0.5) * d, (k as f64 + 0.5) * d], r, [0.0; 3])
                    .unwrap();
            }
        }
    }
    sim.skin = 0.1 * r;
    sim.world.set_dt(1e-7).unwrap();
    sim
}

/// The same infinite packing in cells of 4, 2 and 1 spheres a side: the last two are thinner than
/// twice the interaction reach (a sphere meets two images of its neighbour, or its own images).
#[test]
fn love_weber_stress_of_a_cubic_packing() {
    let (r, delta, kn) = (0.01, 1e-4, 1e5);
    for n in [4, 2, 1] {
        let mut sim = cubic_packing(n, r, delta, kn);
        sim.step().unwrap();
        let d = 2.0 * r - delta;
        // Each sphere has one contact per axis direction and sign; per sphere and axis one pair
        // pushes with kn delta over the branch d: sigma_xx = -kn delta d / d^3 (compression
        // negative).
        let expected = -kn * delta / (d * d);
        assert_eq!(sim.world.contacts.spheres.touching_count(), 3 * n * n * n, "{n} spheres a side");
        let s = sim.world.love_weber_stress(sim.world.cell_volume().unwrap());
        for a in 0..3 {
            assert!(
                (s[a] - expected).abs() < 1e-9 * expected.abs(),
                "n = {n}: sigma[{a}] = {}, expected {expected}",
                s[a]
            );
        }
        for a in 3..6 {
            assert!(s[a].abs() < 1e-9 * expected.abs());
        }
        assert!(sim.world.spheres.v.iter().flatten().all(|c| c.abs() < 1e-12), "n = {n}: the balanced lattice moved");
    }
}

/// A cell thinner than a sphere's diameter along y, sheared, with its spheres in contact with
/// images of each other and of themselves, steps as the same packing in a cell three times as
/// thick, whose search needs no more than the nearest images: both are one infinite packing, so
/// stress and motion agree.
/// A thin cell sheared across its thin axis and the same packing in a cell three times as thick
/// (`l` the velocity gradient, `update` the cell update): their stresses after 400 steps, and
/// their sphere velocities, copy by copy, agree to 1e-6.
fn thin_and_thick_cells_agree(l: nalgebra::Matrix3<f64>, update: CellUpdate) {
    let (r0, kn) = (0.01, 1e5);
    let spacing = 1.9 * r0;
    let (nx, nz, thick) = (4, 4, 1.6 * r0);
    let mut next = crate::common::uniform_stream(99);
    let mut spheres = Vec::new();
    for i in 0..nx {
        for k in 0..nz {
            let x = [
                (i as f64 + 0.5 + 0.05 * next()) * spacing,
                next() * thick,
                (k as f64 + 0.5 + 0.05 * next()) * spacing,
            ];
            spheres.push((x, r0 * (0.85 + 0.15 * next())));
        }
    }
    let size = [nx as f64 * spacing, thick, nz as f64 * spacing];
    let build = |copies: usize| {
        let (mut sim, m) = sim_with_law(kn);
        sim.world.set_cell(Some(PeriodicCell::new_box([size[0], copies as f64 * thick, size[2]])));
        for c in 0..copies {
            for (x, r) in &spheres {
                sim.world.add_sphere(m, [x[0], x[1] + c as f64 * thick, x[2]], *r, [0.0; 3]).unwrap();
            }
        }
        sim.skin = 0.1 * r0;
        sim.world.set_dt(2e-6).unwrap();
        let cell = sim.world.cell.as_mut().unwrap();
        cell.velocity_gradient = l;
        cell.update = update;
        sim
    };
    let (mut thin, mut thick_sim) = (build(1), build(3));
    let reach = 2.0 * r0 + thin.skin;
    assert!(thin.world.cell.as_ref().unwrap().widths()[1] < reach && 3.0 * thick >= 2.0 * reach);
    for step in 0..400 {
        thin.step().unwrap();
        thick_sim.step().unwrap();
        if step == 0 {
            assert!(
                (0..thin.world.contacts.spheres.len()).any(|k| thin.world.contacts.spheres.touching[k]
                    && thin.world.contacts.spheres.a[k] == thin.world.contacts.spheres.b[k]),
                "no sphere touches its own image: the test checks nothing there"
            );
        }
    }
    let st = thin.world.love_weber_stress(thin.world.cell_volume().unwrap());
    let sk = thick_sim.world.love_weber_stress(thick_sim.world.cell_volume().unwrap());
    assert!(st[1] < 0.0, "the packing is compressed: {st:?}");
    let scale = st.iter().map(|v| v.abs()).fold(0.0, f64::max);
    for a in 0..6 {
        assert!((st[a] - sk[a]).abs() < 1e-6 * scale, "sigma[{a}]: thin cell {}, thick cell {}", st[a], sk[a]);
    }
    // Contacts: three copies of each in the thick cell.
    assert_eq!(3 * thin.world.contacts.spheres.touching_count(), thick_sim.world.contacts.spheres.touching_count());
    let n = spheres.len();
    for i in 0..n {
        for c in 0..3 {
            let (a, b) = (thin.world.spheres.v[i], thick_sim.world.spheres.v[c * n + i]);
            let dv = (0..3).map(|q| (a[q] - b[q]).abs()).fold(0.0, f64::max);
            assert!(
                dv < 1e-6 * (1e-3 + a.iter().map(|v| v.abs()).fold(0.0, f64::max)),
                "sphere {i} copy {c}: {a:?} {b:?}"
            );
        }
    }
}

#[test]
fn a_thin_cell_steps_as_the_same_packing_in_a_thicker_one_when_sheared() {
    // Simple shear across the thin axis (L L = 0): every update keeps the images together.
    let mut l = nalgebra::Matrix3::zeros();
    l[(0, 1)] = 50.0;
    thin_and_thick_cells_agree(l, CellUpdate::Sllod);
}

#[test]
fn a_thin_cell_steps_as_the_same_packing_in_a_thicker_one_when_stretched() {
    // Stretched along x, squeezed across the thin axis, sheared: under SLLOD a sphere's
    // fluctuation changes alike in every image.
    let l = nalgebra::Matrix3::new(25.0, 10.0, 0.0, 0.0, -25.0, 0.0, 0.0, 0.0, 0.0);
    thin_and_thick_cells_agree(l, CellUpdate::Sllod);
}

#[test]
fn simple_shear_steps_alike_under_sllod_and_newton_to_the_last_bit() {
    // Where L L = 0 the two updates are the same arithmetic: a sheared packing with contacts
    // ends with the same bits under both.
    let run = |update: CellUpdate| {
        let mut sim = cubic_packing(3, 0.01, 2e-4, 1e5);
        let cell = sim.world.cell.as_mut().unwrap();
        cell.velocity_gradient[(0, 2)] = 20.0;
        cell.update = update;
        for _ in 0..300 {
            sim.step().unwrap();
        }
        (sim.world.spheres.x.clone(), sim.world.spheres.v.clone(), sim.world.love_weber_stress(1.0))
    };
    let (sllod, newton) = (run(CellUpdate::Sllod), run(CellUpdate::Newton));
    assert!(sllod.2[4] != 0.0 || sllod.2[5] != 0.0 || sllod.2[3] != 0.0, "no shear stress: {:?}", sllod.2);
    assert!(sllod == newton, "the updates differ under simple shear");
}

#[test]
fn flipping_keeps_every_contact() {
    let (n, r, delta, kn) = (4, 0.01, 1e-4, 1e5);
    let mut sim = cubic_packing(n, r, delta, kn);
    // Shear the cell alone (a huge rate over one step) to just below the flip threshold, then step
    // across it with a tiny rate: the packing is sheared affinely, every contact must survive.
    let size = n as f64 * (2.0 * r - delta);
    {
        let cell = sim.world.cell.as_mut().unwrap();
        cell.h[(0, 2)] = 0.5 * size - 1e-12;
    }
    // Move the particles with the cell: x += gamma z.
    for x in sim.world.spheres.x.iter_mut() {
        x[0] += (0.5 - 1e-12 / size) * x[2];
    }
    sim.world.needs_rebuild_for_tests();
    sim.step().unwrap();
    let before = sim.world.contacts.spheres.touching_count();
    let volume = sim.world.cell_volume().unwrap();
    let stress_before = sim.world.love_weber_stress(volume);
    assert!(before > 0);
    sim.world.cell.as_mut().unwrap().velocity_gradient[(0, 2)] = 1e-3;
    let flips = sim.world.cell.as_ref().unwrap().flips;
    for _ in 0..3 {
        sim.step().unwrap();
    }
    assert_eq!(sim.world.cell.as_ref().unwrap().flips, flips + 1, "the cell should have flipped once");
    assert_eq!(sim.world.spheres.len(), n * n * n);
    assert_eq!(sim.world.contacts.spheres.touching_count(), before, "contacts lost or created by the flip");
    let stress_after = sim.world.love_weber_stress(sim.world.cell_volume().unwrap());
    for a in 0..6 {
        assert!(
            (stress_after[a] - stress_before[a]).abs() <= 1e-6 * stress_before[0].abs(),
            "stress jumped at the flip"
        );
    }
}
