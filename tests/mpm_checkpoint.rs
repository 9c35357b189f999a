//! An MPM checkpoint resumes exactly: save, load and continue gives the same bits.

#[test]
fn mohr_coulomb_column_resumes_bit_for_bit() {
    let mut sim = granite::bench::mohr_coulomb_column(0.05).unwrap();
    sim.velocity_update = granite::registry()
        .build_velocity_update("FLIPX", &[("flip_ratio".to_string(), 0.95)].into_iter().collect())
        .unwrap();
    for _ in 0..200 {
        sim.step().unwrap();
    }
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/mpm_checkpoint");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("checkpoint.json");
    sim.save(&path).unwrap();
    let mut resumed = granite_core::mpm::MpmSim::load(&path, &granite::registry()).unwrap();
    for _ in 0..200 {
        sim.step().unwrap();
        resumed.step().unwrap();
    }
    assert!(
        sim.points.x == resumed.points.x
            && sim.points.v == resumed.points.v
            && sim.points.stress == resumed.points.stress
    );
    assert_eq!(sim.materials[0].state, resumed.materials[0].state);
}
