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

/// A checkpoint edited by hand or truncated is refused with what is wrong in it, instead of
/// panicking at the first step.
#[test]
fn inconsistent_checkpoints_are_refused_with_the_reason() {
    let sim = granite::bench::mohr_coulomb_column(0.1).unwrap();
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/mpm_checkpoint_bad");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("checkpoint.json");
    sim.save(&path).unwrap();
    let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let good = file["state"].clone();
    let nodes = sim.mesh.node_count();
    type Edit = fn(&mut serde_json::Value);
    let max_step = i64::MAX;
    let id_1 = sim.points.id[1];
    let edits: [(&str, Edit, String); 7] = [
        ("short stress", |s| drop(s["points"]["stress"].as_array_mut().unwrap().pop()), "`stress` has".into()),
        // Scripts read the step as a signed integer: u64::MAX would show as -1.
        ("step", |s| s["step"] = u64::MAX.into(), format!("a step up to {max_step}")),
        ("repeated id", |s| s["points"]["id"][1] = s["points"]["id"][0].clone(), "two points have id".into()),
        ("volume", |s| s["points"]["volume"][1] = (-1.0).into(), format!("point id {id_1}: mass")),
        ("point count", |s| s["materials"][0]["count"] = 1_000_000.into(), "counts 1000000 points".into()),
        (
            "node",
            |s| s["boundary"]["velocity"][0]["nodes"][0] = 99_999_999.into(),
            format!("node 99999999 of the mesh's {nodes}"),
        ),
        ("mesh", |s| s["mesh"]["cells"][0] = 0.into(), "every axis needs at least one cell".into()),
    ];
    for (what, edit, says) in edits {
        let mut state = good.clone();
        edit(&mut state);
        // Sealed as granite seals a file: what is checked here is the content, not the checksum.
        let version = file["version"].as_u64().unwrap() as u32;
        let sealed =
            granite_core::io::checkpoint_file::seal("granite-mpm-checkpoint", version, "test", &state.to_string());
        std::fs::write(&path, sealed).unwrap();
        let e = granite_core::mpm::MpmSim::load(&path, &granite::registry()).err().expect(what).to_string();
        assert!(e.contains("not a usable MPM checkpoint") && e.contains(&says), "{what}: {e}");
    }
}
