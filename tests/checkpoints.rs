//! What a checkpoint guarantees: a damaged file is refused naming it, a file says which granite
//! wrote it, a newer format is refused with a clear message, and the formats granite released
//! before (kept in tests/checkpoints/) still load and run.

use crate::common;
use granite_script::{run_source, RunOptions};
use std::path::{Path, PathBuf};

/// Runs script text; Err carries the script error.
fn run(name: &str, source: &str) -> Result<PathBuf, String> {
    let out = common::out_dir(name);
    let options = RunOptions { out_dir: out.clone(), quiet: true, ..Default::default() };
    run_source(&format!("{name}.rhai"), source, granite::registry(), options)
        .map(|r| r.out_dir)
        .map_err(|e| e.to_string())
}

const MPM_RUN: &str = r#"
let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [3, 3] });
let soil = sim.material("mohr_coulomb", #{ name: "soil", density: 1800.0, young: 1e6, poisson: 0.3, friction: 30.0, cohesion: 0.0 });
sim.fill_box(soil, [0.0, 0.0], [0.2, 0.2], #{ per_cell: 2 });
sim.fix("x-", "x"); sim.fix("y-", "y");
sim.gravity([0.0, -9.81]);
sim.dt(1e-4);
sim.run_steps(40);
sim.save("state.json");
"#;

const DEM_RUN: &str = r#"
let sim = dem(#{ seed: 3 });
let glass = sim.material(#{ name: "glass", density: 2500.0 });
sim.contact_law("hertz_mindlin", #{ young: 1e7, poisson: 0.3, friction: 20.0 });
sim.box_walls(glass, [0.0, 0.0, 0.0], [0.05, 0.05, 0.05]);
sim.sphere(glass, [0.025, 0.025, 0.006], 0.005);
sim.sphere(glass, [0.025, 0.025, 0.0165], 0.005);
sim.gravity([0.0, 0.0, -9.81]);
sim.dt(0.2 * sim.critical_dt());
sim.run_steps(200);
sim.save("state.json");
"#;

/// Changes one digit in the middle of the file (a 3 becomes a 4, or the reverse).
fn change_one_digit(path: &Path) {
    let mut bytes = std::fs::read(path).unwrap();
    let middle = bytes.len() / 2;
    let at = (middle..bytes.len()).find(|&i| bytes[i] == b'3' || bytes[i] == b'4').expect("a digit 3 or 4");
    bytes[at] = if bytes[at] == b'3' { b'4' } else { b'3' };
    std::fs::write(path, bytes).unwrap();
}

fn load_script(function: &str, path: &Path) -> String {
    format!("let sim = {function}({:?});\nsim.run_steps(5);\n", path.to_str().unwrap())
}

#[test]
fn a_checkpoint_with_one_digit_changed_is_refused_naming_the_file() {
    for (name, writer, loader) in [("ckpt_mpm", MPM_RUN, "mpm_load"), ("ckpt_dem", DEM_RUN, "dem_load")] {
        let dir = run(name, writer).unwrap();
        let file = dir.join("state.json");
        // Intact, it loads and runs.
        run(&format!("{name}_intact"), &load_script(loader, &file)).unwrap();
        change_one_digit(&file);
        let e = run(&format!("{name}_damaged"), &load_script(loader, &file)).unwrap_err();
        assert!(e.contains("state.json is damaged") && e.contains("crc32") && e.contains("line 1"), "{loader}: {e}");
    }
}

#[test]
fn a_checkpoint_says_which_granite_wrote_it_and_a_newer_format_is_refused() {
    let dir = common::out_dir("ckpt_cli");
    let script = dir.with_extension("rhai");
    std::fs::create_dir_all(dir.parent().unwrap()).unwrap();
    std::fs::write(&script, MPM_RUN).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_granite"))
        .args(["run", "--quiet", "--out"])
        .arg(&dir)
        .arg(&script)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(dir.join("state.json")).unwrap();
    let header: serde_json::Value = serde_json::from_str(&text).unwrap();
    let writer = header["written_by"].as_str().unwrap();
    assert!(
        writer.contains(env!("CARGO_PKG_VERSION")) && writer.contains(env!("GRANITE_GIT_COMMIT")),
        "written by {writer}"
    );
    assert_eq!(header["version"], 4);
    // The same file as a future granite would write it.
    let newer = text.replacen("\"version\":4", "\"version\":5", 1).replacen(writer, "granite 9.9.9 (future)", 1);
    let future = dir.join("future.json");
    std::fs::write(&future, newer).unwrap();
    let e = run("ckpt_future", &load_script("mpm_load", &future)).unwrap_err();
    assert!(e.contains("granite 9.9.9 (future)") && e.contains("version 5") && e.contains("versions 1 to 4"), "{e}");
}

/// Formats released before load through their upgrade path and run on: a DEM state of version 2
/// and an MPM checkpoint of version 1, written before checkpoints carried a checksum; a DEM state
/// of version 3 (a periodic cell whose stress servo had no integral part yet, saved
/// mid-compaction) and an MPM checkpoint of version 2 (before shape functions and stress rates),
/// both written by granite 5416ea0; a DEM state of version 5 (bodies of one family, before a
/// scene could hold several), written by granite 46b9482; an MPM checkpoint of version 3 (before
/// loads carried by points), written by granite 262568d.
#[test]
fn checkpoints_of_every_released_format_load_and_run() {
    // Each file, how to load it, and what summary.json must then say.
    let cases = [
        ("dem_state_v2.json", "dem_load", "particles", "\"particles\": 3", "\"steps\": 100"),
        ("dem_state_v3.json", "dem_load", "particles", "\"particles\": 60", "\"step\": 3100"),
        // Written at step 37613 by granite 46b9482: five capsules (one body family) and eight
        // spheres settled in a box.
        ("dem_state_v5.json", "dem_load", "bodies", "\"bodies\": 5", "\"step\": 37713"),
        // Written at step 50 with 4 points (2 x 2 cells, one point each).
        ("mpm_checkpoint_v1.json", "mpm_load", "points", "\"points\": 4", "\"step\": 150"),
        // Written at step 50 with 16 points (2 x 2 cells, four points each).
        ("mpm_checkpoint_v2.json", "mpm_load", "points", "\"points\": 16", "\"step\": 150"),
        // Written at step 50 by granite 262568d (before loads carried by points): the same
        // block on quadratic B-splines with a Jaumann rate and a traction on its top.
        ("mpm_checkpoint_v3.json", "mpm_load", "points", "\"points\": 16", "\"step\": 150"),
    ];
    for (file, load, count, has_count, has_steps) in cases {
        let path = common::root().join("tests").join("checkpoints").join(file);
        let source = format!(
            "let sim = {load}({:?});\nlet before = sim.step;\nsim.run_steps(100);\n\
             summary(\"steps\", sim.step - before);\nsummary(\"step\", sim.step);\nsummary(\"{count}\", sim.{count});\n",
            path.to_str().unwrap()
        );
        let dir = run(&format!("ckpt_{load}_released"), &source).unwrap();
        let summary = std::fs::read_to_string(dir.join("summary.json")).unwrap();
        assert!(summary.contains(has_count) && summary.contains(has_steps), "{file}: {summary}");
    }
}

/// Writes `path`'s checkpoint again with its state changed by `edit` and a checksum that fits,
/// as a program crafting a file would: the checksum is then no defence.
fn crafted(path: &Path, name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
    let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut state = file["state"].clone();
    edit(&mut state);
    let text = granite_core::io::checkpoint_file::seal(
        file["format"].as_str().unwrap(),
        file["version"].as_u64().unwrap() as u32,
        file["written_by"].as_str().unwrap(),
        &serde_json::to_string(&state).unwrap(),
    );
    let out = path.with_file_name(name);
    std::fs::write(&out, text).unwrap();
    out
}

/// Values a step cannot use are refused even under a valid checksum, naming the value: a time so
/// large that a step no longer moves it on, a next point id no new point can take, a plane wall
/// without a normal. A sphere moved in the file is taken where it was put (the contact lists are
/// built again), instead of stopping the run as if it had flown there.
#[test]
fn crafted_checkpoints_with_a_valid_checksum_are_refused_naming_the_value() {
    let mpm = run("ckpt_crafted_mpm", MPM_RUN).unwrap().join("state.json");
    let dem = run("ckpt_crafted_dem", DEM_RUN).unwrap().join("state.json");
    // The file, how to load it, the crafted file's name, the edit, and what the refusal says.
    type Case<'a> = (&'a Path, &'a str, &'a str, Box<dyn FnOnce(&mut serde_json::Value)>, &'a [&'a str]);
    let cases: [Case; 3] = [
        (&mpm, "mpm_load", "late.json", Box::new(|s| s["time"] = 1e308.into()), &["time 1e308", "leaves it unchanged"]),
        (
            &mpm,
            "mpm_load",
            "ids.json",
            Box::new(|s| s["next_id"] = u64::MAX.into()),
            &["next id of new points is 18446744073709551615", "above every id held"],
        ),
        (
            &dem,
            "dem_load",
            "flat.json",
            Box::new(|s| s["walls"][0]["shape"]["Plane"]["normal"] = serde_json::json!([0.0, 0.0, 0.0])),
            &["wall 0 (\"x-\")", "plane normal [0.0, 0.0, 0.0] (a unit vector)"],
        ),
    ];
    for (source, load, name, edit, expected) in cases {
        let file = crafted(source, name, edit);
        let e = run("ckpt_crafted_load", &load_script(load, &file)).unwrap_err();
        assert!(e.contains("not a usable") && expected.iter().all(|x| e.contains(x)), "{name}: {e}");
    }
    // The first sphere moved 15 mm sideways in the box, three times what half the skin and the
    // smallest radius allow between two builds of the lists.
    let x0 = {
        let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&dem).unwrap()).unwrap();
        file["state"]["spheres"]["x"][0][0].as_f64().unwrap()
    };
    let moved = crafted(&dem, "moved.json", |s| s["spheres"]["x"][0][0] = (x0 + 0.015).into());
    let source = format!(
        "let sim = dem_load({:?});\nsim.run_steps(5);\nsummary(\"x\", sim.body(sim.ids()[0]).position[0]);\n",
        moved.to_str().unwrap()
    );
    let dir = run("ckpt_crafted_moved", &source).unwrap();
    let summary: serde_json::Value = common::summary_of(&dir);
    // Five steps of a sphere settling under gravity move it by far less than a millimetre.
    assert!((summary["x"].as_f64().unwrap() - (x0 + 0.015)).abs() < 1e-3, "{summary}");
}

/// `dem_load` and `mpm_load` of a FIFO or a device are refused at once, naming what the file
/// is: opening a FIFO would block the run where no stop request is seen, a device would be read
/// until memory runs out.
#[test]
fn a_fifo_or_a_device_is_not_loaded() {
    let dir = common::out_dir("ckpt_fifo");
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("pipe.json");
    let _ = std::fs::remove_file(&fifo);
    assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    for (load, file, kind) in
        [("dem_load", fifo.as_path(), "a FIFO"), ("mpm_load", Path::new("/dev/urandom"), "a device")]
    {
        let e = run("ckpt_fifo_load", &load_script(load, file)).unwrap_err();
        assert!(e.contains(kind) && e.contains("not a regular file") && e.contains("line 1"), "{load}: {e}");
    }
}

/// A DEM state of version 6 (the bodies' contact lists in a record of their own, before the one
/// contact set), written by granite f762650: a capsule and a rounded box held on a 10° slope by
/// static friction, a sphere resting against the box's uphill face (the scene of
/// `a_contact_change_keeps_the_tangential_springs_of_bodies_at_rest`, run 0.5 s to rest).
/// Loaded, they stay where they are: their contacts' tangential springs came through; contacts
/// starting afresh would slide each body by about `m g sin 10° / k_t` first.
#[test]
fn a_state_of_version_6_keeps_its_bodies_contacts() {
    let (kt, g, theta) = (0.5e6f64, 9.81f64, 10f64.to_radians());
    let path = common::root().join("tests").join("checkpoints").join("dem_state_v6.json");
    let source = format!(
        r#"
        let sim = dem_load({:?});
        let cap = 0;
        let block = 1;
        let x0 = [sim.body_state(cap).position[0], sim.body_state(block).position[0]];
        summary("contacts", sim.contacts().filter(|c| c.kind1 != "sphere").len());
        summary("with_sphere", sim.contacts().filter(|c| c.kind1 != "sphere" && c.kind2 == "sphere").len());
        sim.run_until(sim.time + 0.05);
        summary("capsule_moved", sim.body_state(cap).position[0] - x0[0]);
        summary("block_moved", sim.body_state(block).position[0] - x0[1]);
        summary("capsule_mass", sim.body_state(cap).mass);
        summary("block_mass", sim.body_state(block).mass);
        "#,
        path.to_str().unwrap()
    );
    let dir = run("ckpt_dem_v6_bodies", &source).unwrap();
    let s = common::summary_of(&dir);
    let get = |k: &str| s[k].as_f64().unwrap();
    // The capsule on its two ends, the box on its face and against the sphere.
    assert!(get("contacts") >= 4.0 && get("with_sphere") == 1.0, "{s}");
    for body in ["capsule", "block"] {
        let slip = get(&format!("{body}_mass")) * g * theta.sin() / kt;
        let moved = get(&format!("{body}_moved"));
        assert!(moved.abs() < 0.01 * slip, "{body} moved {moved:e} m after loading (a reloading spring: {slip:e})");
    }
}
