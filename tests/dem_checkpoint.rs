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
    assert!(sim.world.contacts.spheres.touching_count() > 500, "the checkpoint must hold contacts with history");
    for _ in 0..400 {
        sim.step().unwrap();
        resumed.step().unwrap();
    }
    assert!(
        sim.world.spheres.x == resumed.world.spheres.x
            && sim.world.spheres.v == resumed.world.spheres.v
            && sim.world.spheres.w == resumed.world.spheres.w
    );
    assert_eq!(sim.world.contacts.spheres.history, resumed.world.contacts.spheres.history);
    assert_eq!(sim.world.time.to_bits(), resumed.world.time.to_bits());
}

/// A state file edited by hand, truncated or written by another program is refused with what is
/// wrong in it; before, an index out of range or a short array panicked at the first step.
#[test]
fn inconsistent_state_files_are_refused_with_the_reason() {
    let mut sim = granite::bench::gravity_deposition(300).unwrap();
    for _ in 0..500 {
        sim.step().unwrap();
    }
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/dem_checkpoint_bad");
    std::fs::create_dir_all(&dir).unwrap();
    let good = sim.to_json().unwrap();
    assert!(!good["contacts"]["spheres"]["a"].as_array().unwrap().is_empty(), "the state must hold pairs");
    let (n, laws, materials) = (sim.world.spheres.len(), sim.world.contacts.laws.len(), sim.world.materials.len());
    type Edit = fn(&mut serde_json::Value);
    let (id_3, id_5, id_7) = (sim.world.spheres.id[3], sim.world.spheres.id[5], sim.world.spheres.id[7]);
    let edits: [(&str, Edit, String); 12] = [
        // Scripts read the step as a signed integer: u64::MAX would show as -1.
        ("step", |s| s["step"] = u64::MAX.into(), format!("a step up to {}", i64::MAX)),
        // A radius without a finite volume.
        ("huge radius", |s| s["spheres"]["radius"][7] = 1e300.into(), format!("sphere id {id_7}: radius 1")),
        (
            "density",
            |s| s["materials"][0]["density"] = (-2600.0).into(),
            "density -2600 (must be finite and > 0)".into(),
        ),
        // Two spheres under one id: one would be reported, moved or erased as the other.
        ("repeated id", |s| s["spheres"]["id"][1] = s["spheres"]["id"][0].clone(), "two spheres have id".into()),
        (
            "pair index",
            |s| s["contacts"]["spheres"]["b"][0] = 99_999.into(),
            format!("an index beyond the {n} spheres"),
        ),
        (
            // The force sums' order rests on pairs stored under their larger index.
            "pair orientation",
            |s| {
                let (a, b) = (s["contacts"]["spheres"]["a"][0].clone(), s["contacts"]["spheres"]["b"][0].clone());
                (s["contacts"]["spheres"]["a"][0], s["contacts"]["spheres"]["b"][0]) = (b, a);
            },
            "pair 0 has a first sphere below its second".into(),
        ),
        (
            // A sphere meets only its own images (a thin cell), never itself.
            "sphere with itself",
            |s| {
                s["contacts"]["spheres"]["b"][0] = s["contacts"]["spheres"]["a"][0].clone();
                s["contacts"]["spheres"]["shift"][0] = serde_json::json!([0, 0, 0]);
            },
            "or is a sphere with itself".into(),
        ),
        (
            "short radii",
            |s| drop(s["spheres"]["radius"].as_array_mut().unwrap().pop()),
            format!("`radius` has {} entries, `x` {n}", n - 1),
        ),
        (
            "short history",
            |s| drop(s["contacts"]["spheres"]["history"].as_array_mut().unwrap().pop()),
            "history values for".into(),
        ),
        ("contact law", |s| s["contacts"]["spheres"]["law"][0] = 7.into(), format!("contact law 7 of {laws}")),
        (
            "material",
            |s| s["spheres"]["material"][3] = 2.into(),
            format!("sphere id {id_3}: material 2 of {materials}"),
        ),
        ("mass", |s| s["spheres"]["mass"][5] = 0.0.into(), format!("sphere id {id_5}: radius")),
    ];
    for (what, edit, says) in edits {
        let mut state = good.clone();
        edit(&mut state);
        let path = dir.join("state.json");
        // Sealed as granite seals a file: what is checked here is the content, not the checksum.
        let version = state["version"].as_u64().unwrap() as u32;
        let sealed = granite_core::io::checkpoint_file::seal("granite-dem-state", version, "test", &state.to_string());
        std::fs::write(&path, sealed).unwrap();
        let e = granite_core::dem::DemSim::load(&path, &granite::registry()).err().expect(what).to_string();
        assert!(e.contains("not a usable DEM state") && e.contains(&says), "{what}: {e}");
    }
}

/// A state written when `hertz_mindlin` kept four values a pair (before its dashpot) loads: its
/// pairs are laid out for five and their values set again from the law, keeping their tangential
/// forces, and the run continues bit for bit as the state it was saved from.
#[test]
fn a_state_with_fewer_values_a_pair_is_widened() {
    let mut sim = granite::bench::gravity_deposition(300).unwrap();
    let params: granite_core::registry::ParamMap =
        [("young", 1e8), ("poisson", 0.25), ("friction", 30.0)].iter().map(|(k, v)| (k.to_string(), *v)).collect();
    sim.world.set_contact_law(granite::registry().build_contact_law("hertz_mindlin", &params).unwrap(), None).unwrap();
    for _ in 0..1500 {
        sim.step().unwrap();
    }
    assert!(sim.world.contacts.spheres.touching_count() > 50, "the state must hold touching contacts");
    let mut json = sim.to_json().unwrap();
    for list in ["spheres", "sphere_walls"] {
        let l = &mut json["contacts"][list];
        assert_eq!(l["param_stride"], 5);
        // The layout of the earlier law: e_star, g_star, r_star, mu (no damping).
        let old: Vec<serde_json::Value> =
            l["params"].as_array().unwrap().chunks(5).flat_map(|c| c[..4].to_vec()).collect();
        l["params"] = serde_json::Value::from(old);
        l["param_stride"] = serde_json::Value::from(4);
    }
    let mut resumed = granite_core::dem::DemSim::from_json(json, &granite::registry()).unwrap();
    assert_eq!(resumed.world.contacts.spheres.param_stride, 5);
    for _ in 0..300 {
        sim.step().unwrap();
        resumed.step().unwrap();
    }
    assert!(sim.world.spheres.x == resumed.world.spheres.x && sim.world.spheres.v == resumed.world.spheres.v);
}
