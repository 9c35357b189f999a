//! A saved DEM state resumes exactly: save, load and continue gives the same bits as continuing.

#[test]
fn saved_state_resumes_bit_for_bit() {
    let mut sim = granite::bench::gravity_deposition(2000).unwrap();
    for _ in 0..4000 {
        sim.step().unwrap();
    }
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/dem_checkpoint");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("state.json");
    sim.save(&path).unwrap();
    let mut resumed = granite_core::dem::DemSim::load(&path, &granite::registry()).unwrap();
    assert!(sim.pairs.touching_count() > 500, "the checkpoint must hold contacts with history");
    for _ in 0..400 {
        sim.step().unwrap();
        resumed.step().unwrap();
    }
    assert!(
        sim.spheres.x == resumed.spheres.x && sim.spheres.v == resumed.spheres.v && sim.spheres.w == resumed.spheres.w
    );
    assert_eq!(sim.pairs.history, resumed.pairs.history);
    assert_eq!(sim.time.to_bits(), resumed.time.to_bits());
}
