//! Requests too big for the machine are refused with the numbers, never a panic or an abort in
//! the allocator: generators, meshes and fills estimate their memory first, and a script's own
//! arrays, strings and maps stop with an error before they take the memory the process has.

use crate::common;
use granite_script::{run_source, RunOptions};

fn fails(name: &str, source: &str) -> String {
    let options = RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
    match run_source(&format!("{name}.rhai"), source, granite::registry(), options) {
        Ok(_) => panic!("{name}: the script must fail"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn generators_meshes_and_fills_beyond_the_memory_are_refused_with_the_numbers() {
    let lattice = |spacing: &str, radius: &str| {
        format!(
            "let sim = dem();\nlet m = sim.material(#{{ name: \"g\", density: 2500.0 }});\n\
             sim.lattice(m, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], #{{ spacing: {spacing}, radius: {radius} }});\n"
        )
    };
    // 1e18 sites (a capacity overflow before) and 1e9 (an abort on a 32 GB allocation before).
    for (spacing, radius, sites) in [("1e-6", "4e-7", "1.000e18"), ("1e-3", "4e-4", "1.000e9")] {
        let e = fails("limits_lattice", &lattice(spacing, radius));
        assert!(e.contains("line 3") && e.contains(&format!("{sites} spheres")) && e.contains("GB"), "{e}");
    }
    let e = fails(
        "limits_cloud",
        "let sim = dem();\nlet m = sim.material(#{ name: \"g\", density: 2500.0 });\n\
         sim.cloud(m, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], #{ count: 100000000000, radius: 1e-4 });\n",
    );
    assert!(e.contains("line 3") && e.contains("1.000e11 spheres"), "{e}");
    let e = fails(
        "limits_mesh",
        "let sim = mpm(#{ dim: 3, origin: [0.0, 0.0, 0.0], cell: 1e-3, cells: [1200, 1200, 1200] });\n",
    );
    assert!(e.contains("line 1") && e.contains("nodes would take"), "{e}");
    let e = fails(
        "limits_fill",
        "let sim = mpm(#{ dim: 3, origin: [0.0, 0.0, 0.0], cell: 1e-3, cells: [300, 300, 300] });\n\
         let m = sim.material(\"linear_elastic\", #{ name: \"s\", density: 2000.0, young: 1e6, poisson: 0.3 });\n\
         sim.fill_box(m, [0.0, 0.0, 0.0], [0.3, 0.3, 0.3], #{ per_cell: 20 });\n",
    );
    assert!(e.contains("line 3") && e.contains("material points would take"), "{e}");
}

/// Under a 2 GB address-space limit, a script asking for 160 GB at once, one doubling a string
/// 40 times and one filling nested arrays in a map without end each stop at their line with an
/// error (exit 1), where each aborted the process in the allocator (exit 134) without a check.
#[cfg(unix)]
#[test]
fn a_script_cannot_abort_granite_through_its_own_arrays_and_strings() {
    let e = fails("limits_pad", "let a = [];\na.pad(10000000000, 0.0);\n");
    assert!(e.contains("line 2") && e.contains("160.00 GB"), "{e}");
    let dir = common::out_dir("limits_script_data");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, source) in [
        ("pad", "let a = [];\na.pad(10000000000, 0.0);\n"),
        ("doubling", "let s = \"ab\";\nfor i in 0..40 { s += s; }\n"),
        (
            "nested",
            "let m = #{ rows: [] };\nfor i in 0..1000000 { let row = []; row.pad(10000, 0.0); m.rows.push(row); }\n",
        ),
    ] {
        let script = dir.join(format!("{name}.rhai"));
        std::fs::write(&script, source).unwrap();
        let (code, stderr) = common::run_under_limit("ulimit -v 2000000", &script, &dir.join(name));
        assert_eq!(code, Some(1), "{name}: {stderr}");
        assert!(stderr.contains("line 2") && stderr.contains("GB"), "{name}: {stderr}");
    }
}

/// The memory check reads the process's own limits: under `ulimit -v` a lattice the machine could
/// hold but the limit cannot (4.9 million spheres, about 5 GB at the measured 1 029 bytes a
/// sphere, under 3 GB) is refused at once with the numbers, not aborted in the allocator.
#[cfg(unix)]
#[test]
fn an_address_space_limit_is_part_of_the_memory_check() {
    let dir = common::out_dir("limits_ulimit");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("lattice.rhai");
    std::fs::write(
        &script,
        "let sim = dem();\nlet m = sim.material(#{ name: \"g\", density: 2500.0 });\n\
         sim.lattice(m, [0.0, 0.0, 0.0], [1.7, 1.7, 1.7], #{ spacing: 0.01, radius: 0.004 });\n",
    )
    .unwrap();
    let (code, stderr) = common::run_under_limit("ulimit -v 3000000", &script, &dir.join("out"));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("line 3") && stderr.contains("4.913e6 spheres") && stderr.contains("ulimit -v"),
        "{stderr}"
    );
    let available: f64 =
        stderr.split("more than the ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    assert!(available < 3.1, "{available} GB reported under a 3 GB limit: {stderr}");
}
