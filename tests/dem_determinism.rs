//! The same DEM scene gives bit-identical results on 1, 2 and 3 threads (per-contact forces, then
//! per-particle gathers in a fixed order), and with the kernels' AVX2 twins or without them.

use crate::common;

fn deposit(threads: usize) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, usize) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let mut sim = granite::bench::gravity_deposition(3000).unwrap();
        for _ in 0..1500 {
            sim.step().unwrap();
        }
        (sim.world.spheres.x.clone(), sim.world.spheres.w.clone(), sim.world.contacts.spheres.touching_count())
    })
}

#[test]
fn gravity_deposition_is_thread_count_independent() {
    let one = deposit(1);
    let two = deposit(2);
    assert!(one.2 > 1000, "the scene must have contacts by then ({} contacts)", one.2);
    assert!(one.0 == two.0 && one.1 == two.1, "1 and 2 threads differ");
    // Three workers (more than this machine's cores): runs of pieces and merge pieces shared unevenly.
    let three = deposit(3);
    assert!(one.0 == three.0 && one.1 == three.1, "1 and 3 threads differ");
}

/// An empty simulation of "grains" of `density` with the linear law (`young`, kt/kn 0.5, 30°).
fn frictional(density: f64, young: f64) -> (granite_core::dem::DemSim, u16) {
    let mut sim = granite_core::dem::DemSim::new();
    let m = sim.world.add_material("grains", density).unwrap();
    let params = [("young", young), ("kt_ratio", 0.5), ("friction", 30.0)];
    let params = params.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    sim.world.set_contact_law(granite::registry().build_contact_law("linear", &params).unwrap(), None).unwrap();
    (sim, m)
}

/// A dense, sheared periodic packing (image contacts, friction, spins), stepped `threads`-wide
/// or sequentially (the RVE path: forces summed pair by pair as the contacts are computed);
/// with `servo`, a stress servo then unloads it to half its mean stress for 100 more steps.
fn sheared_periodic(threads: usize, sequential: bool, servo: bool) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, usize) {
    use granite_core::dem::cell::{AxisGoal, CellControl, PeriodicCell};
    use granite_core::dem::generate::lattice;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let (r, side) = (1e-3, 12);
        let spacing = 1.9 * r;
        let width = side as f64 * spacing;
        let (mut sim, m) = frictional(2650.0, 1e8);
        sim.world.set_cell(Some(PeriodicCell::new_box([width; 3])));
        let hi = [width - 0.5 * spacing + r; 3];
        for (x, radius) in lattice([0.5 * spacing - r; 3], hi, spacing, r * 0.93, 0.01 * r, 7).unwrap() {
            sim.world.add_sphere(m, x, radius, [0.0; 3]).unwrap();
        }
        sim.set_sequential(sequential);
        sim.world.set_dt(0.2 * sim.world.critical_dt().unwrap()).unwrap();
        // Squeezed 5 % on every axis while sheared: the lattice neighbours come into contact.
        let l = &mut sim.world.cell.as_mut().unwrap().velocity_gradient;
        for a in 0..3 {
            l[(a, a)] = -0.05 / (300.0 * sim.world.dt);
        }
        l[(0, 2)] = 0.1 / (300.0 * sim.world.dt);
        for _ in 0..300 {
            sim.step().unwrap();
        }
        if servo {
            // Half the present mean stress, and no rate limit: the servo's rate follows the
            // stress it sums to the last bit.
            let stress = sim.world.love_weber_stress(sim.world.cell_volume().unwrap());
            let target = 0.5 * (stress[0] + stress[1] + stress[2]) / 3.0;
            assert!(target < 0.0, "the packing must be compressed ({stress:?})");
            let goal = AxisGoal::Stress { target, max_rate: f64::INFINITY };
            sim.world.cell_control = Some(CellControl::new([goal; 3], vec![], 200.0));
            for _ in 0..100 {
                sim.step().unwrap();
            }
            let l = sim.world.cell.as_ref().unwrap().velocity_gradient;
            assert!((0..3).all(|a| l[(a, a)] != 0.0), "the servo does not move the cell: {l}");
        }
        (sim.world.spheres.x.clone(), sim.world.spheres.w.clone(), sim.world.contacts.spheres.touching_count())
    })
}

#[test]
fn sequential_and_parallel_stepping_agree_bit_for_bit() {
    let sequential = sheared_periodic(1, true, false);
    let parallel = sheared_periodic(2, false, false);
    assert_eq!(sequential.0.len(), 12 * 12 * 12);
    assert!(sequential.2 > 2000, "the packing must be in contact ({} contacts)", sequential.2);
    assert!(sequential.1.iter().any(|w| w.iter().any(|c| c.abs() > 0.0)), "no sphere spins");
    assert!(sequential.0 == parallel.0 && sequential.1 == parallel.1, "sequential and 2-thread stepping differ");
}

/// The servo sums the Love-Weber stress over its pairs every step, in parallel when the
/// simulation steps in parallel: over more pairs than one block of that sum, the result must
/// not depend on it.
#[test]
fn a_stress_servo_steps_the_same_on_any_thread_count() {
    let sequential = sheared_periodic(1, true, true);
    assert!(sequential.2 > 2000, "the packing must be in contact ({} contacts)", sequential.2);
    assert!(sequential == sheared_periodic(2, false, true), "sequential and 2-thread stepping differ");
}

/// The series of a script run by the `granite` command, with the AVX2 kernels on or off.
fn series(script: &str, sets: &[&str], avx2: bool, name: &str) -> Vec<u8> {
    let dir = common::out_dir(name);
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_granite"));
    cmd.args(["run", script, "--quiet", "--threads", "2", "--out"]).arg(&dir).current_dir(common::root());
    for s in sets {
        cmd.args(["--set", s]);
    }
    if !avx2 {
        cmd.env("GRANITE_NO_AVX2", "1");
    }
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::read(dir.join("series.csv")).unwrap()
}

#[test]
fn avx2_and_plain_kernels_agree_bit_for_bit() {
    if !granite_core::simd::avx2() {
        eprintln!("this CPU has no AVX2: both runs below take the plain kernels");
    }
    // Walls, the linear law, parallel stepping; then a periodic cell under stress control with
    // the visco-elastic law. The series are printed at full precision.
    let cases: [(&str, &[&str]); 2] = [
        ("scripts/dem/gravity_deposition.rhai", &["count=1500", "steps=3000"]),
        ("scripts/dem/triaxial_periodic.rhai", &["count=200", "axial_strain=0.01", "inertial_number=1e-3"]),
    ];
    for (k, (script, sets)) in cases.into_iter().enumerate() {
        let wide = series(script, sets, true, &format!("simd_wide_{k}"));
        let plain = series(script, sets, false, &format!("simd_plain_{k}"));
        assert!(wide.len() > 1000, "{script}: too short a series to compare");
        assert!(wide == plain, "{script}: the AVX2 and plain kernels gave different series");
    }
}

/// 300 tetrahedral clumps (1200 member spheres, enough to step in parallel) dropped into a box
/// with a little sideways velocity, stepped `threads`-wide or sequentially.
fn falling_clumps(threads: usize, sequential: bool) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, usize) {
    use granite_core::dem::clump::tetrahedral_members;
    use granite_core::dem::walls::{Wall, WallShape};
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let (r_sphere, r_clump) = (3.1e-3, 5e-3);
        let spacing = 2.3 * r_clump;
        let nx = 6;
        let side = nx as f64 * spacing;
        let (mut sim, m) = frictional(1111.0, 1e6);
        for (a, upper) in [(0, false), (0, true), (1, false), (1, true), (2, false)] {
            let mut n = [0.0; 3];
            n[a] = if upper { -1.0 } else { 1.0 };
            let position = if upper { [side; 3] } else { [0.0; 3] };
            sim.world.add_wall(Wall::new("", WallShape::Plane { normal: n }, position, m));
        }
        // Layer by layer, nx by nx clumps a layer.
        for (i, j, k) in (0..300).map(|n| (n % nx, n / nx % nx, n / (nx * nx))) {
            let centre = [(i as f64 + 0.5) * spacing, (j as f64 + 0.5) * spacing, (k as f64 + 0.5) * spacing];
            let members = tetrahedral_members(centre, r_sphere, r_clump).unwrap();
            // Alternating sideways velocities: the clumps collide and spin on their way down.
            let v = if (i + j + k) % 2 == 0 { [0.05, -0.03, 0.0] } else { [-0.04, 0.02, 0.0] };
            sim.world.add_clump(m, &members, v, 16).unwrap();
        }
        sim.set_sequential(sequential);
        sim.world.gravity = [0.0, 0.0, -9.81];
        sim.world.damping = 0.2;
        sim.world.set_dt(0.3 * sim.world.critical_dt().unwrap()).unwrap();
        for _ in 0..1500 {
            sim.step().unwrap();
        }
        (sim.world.spheres.x.clone(), sim.world.spheres.w.clone(), sim.world.contacts.spheres.touching_count())
    })
}

#[test]
fn clumps_step_the_same_in_parallel_and_sequentially() {
    let sequential = falling_clumps(1, true);
    assert_eq!(sequential.0.len(), 1200);
    assert!(sequential.2 > 100, "the clumps must be in contact ({} contacts)", sequential.2);
    assert!(sequential.1.iter().any(|w| w.iter().any(|c| c.abs() > 0.0)), "no clump spins");
    assert!(sequential == falling_clumps(2, false), "sequential and 2-thread stepping differ");
}
