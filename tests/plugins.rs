//! Native constitutive-law plugins: the example crate (examples/custom_law, a Drucker-Prager law)
//! is built as a cdylib, loaded by a script and used in a simulation whose stresses are checked
//! against the same law computed here; a library with another ABI version is refused.

use crate::common;
use granite_plugin_abi::NativeLaw;
use std::path::PathBuf;
use std::process::Command;

/// Builds the example plugin into its own target folder and returns the library path.
fn build_plugin(features: &[&str], dir: &str) -> PathBuf {
    let target = common::root().join("target").join(dir);
    let mut cmd = Command::new(env!("CARGO"));
    cmd.args(["build", "--quiet", "-p", "custom_law", "--target-dir"]).arg(&target).current_dir(common::root());
    if !features.is_empty() {
        cmd.args(["--features", &features.join(",")]);
    }
    let status = cmd.status().expect("cargo runs");
    assert!(status.success(), "building the example plugin failed");
    let name = format!("{}custom_law{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX);
    target.join("debug").join(name)
}

#[test]
fn example_plugin_runs_a_simulation_and_matches_the_law() {
    let lib = build_plugin(&[], "plugin-test");
    let (e, nu, alpha, k) = (1e7, 0.25, 0.2, 2e3);
    // One cell, one point, every node's velocity prescribed: a homogeneous shear with
    // compression, so the point's strain increment is the same known value every step.
    let src = format!(
        r#"
let name = load_plugin("{lib}");
let sim = mpm(#{{ dim: 2, cell: 1.0, cells: [1, 1] }});
let m = sim.material(name, #{{ density: 2000.0, young: {e}, poisson: {nu}, alpha: {alpha}, k: {k} }});
sim.add_points(m, [[0.5, 0.5]], 1.0);
// v = L x with L = [[0, 1e-2], [0, -5e-3]]
sim.fix(|x| true, "x", 0.0);
sim.fix(|x| x[1] > 0.5, "x", 1e-2);
sim.fix(|x| true, "y", 0.0);
sim.fix(|x| x[1] > 0.5, "y", -5e-3);
sim.scheme("USL");
sim.dt(1e-3);
sim.run_steps(300);
sim.write_points("points.csv");
summary("gamma_p", sim.point_state(0, "gamma_p"));
"#,
        lib = lib.display()
    );
    let out = common::run_text("plugin_run", &src);
    let (h, rows) = common::read_csv(&out.join("points.csv"));
    let got: Vec<f64> =
        ["sxx", "syy", "szz", "sxy", "syz", "sxz"].iter().map(|c| rows[0][common::column(&h, c)]).collect();
    // The same law, here: 300 increments of de = L dt with engineering shear gamma_xy = 1e-5.
    let law = custom_law::DruckerPrager::new(&[e, nu, alpha, k]).unwrap();
    let de = [0.0, -5e-6, 0.0, 1e-5, 0.0, 0.0];
    let mut s = [[0.0; 6]];
    let mut st = [0.0];
    for _ in 0..300 {
        law.update(&mut s, &[de], &mut st).unwrap();
    }
    for c in 0..6 {
        assert!((got[c] - s[0][c]).abs() <= 1e-9 * s[0][1].abs().max(1.0), "component {c}: {} vs {}", got[c], s[0][c]);
    }
    assert!(st[0] > 0.0, "the path must reach the yield surface");
    let summary: serde_json::Value = common::summary_of(&out);
    assert!((summary["gamma_p"].as_f64().unwrap() - st[0]).abs() <= 1e-12 * st[0]);
    let prov: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("provenance.json")).unwrap()).unwrap();
    assert_eq!(prov["plugins"]["loaded"][0]["law"], "drucker_prager");
}

/// The plugin tutorial as a user runs it: its element test reaches the Drucker–Prager strength
/// of a drained triaxial, q_f = (k - 3 alpha sigma_3) / (1/sqrt(3) - alpha), to 1e-9, and its
/// cohesionless block cannot keep a vertical face: it slumps beyond its 0.4 m base.
#[test]
fn the_plugin_tutorial_checks_the_law_and_slumps() {
    let lib = build_plugin(&[], "plugin-test");
    let sets = common::sets(&[("plugin", &lib.display().to_string()), ("duration", "0.3")]);
    let report = granite::run(
        &common::root().join("examples/tutorial_plugin.rhai"),
        sets,
        Some(common::out_dir("tutorial_plugin")),
        true,
        Some(1),
    )
    .unwrap();
    let get = |k: &str| common::summary_f64(&report, k);
    let (q, q_f) = (get("q_end"), get("q_failure"));
    let (k, alpha, s3) = (2e3, 0.2, -1e5);
    assert!((q_f - (k - 3.0 * alpha * s3) / (1.0 / 3f64.sqrt() - alpha)).abs() < 1e-9 * q_f);
    assert!((q - q_f).abs() < 1e-9 * q_f, "q = {q} Pa at 5 % axial strain, strength {q_f} Pa");
    assert!(get("gamma_p_end") > 0.0);
    assert!(get("front_position") > 0.6, "front at {} m", get("front_position"));
}

#[test]
fn bad_plugins_are_refused_with_the_library_named() {
    let good = build_plugin(&[], "plugin-test");
    let wrong = build_plugin(&["wrong_abi"], "plugin-test-wrong-abi");
    let run = |src: String, name: &str| -> String {
        let options = granite_script::RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
        match granite_script::run_source("plugin.rhai", &src, granite::registry(), options) {
            Ok(_) => panic!("{name}: should fail"),
            Err(e) => e.to_string(),
        }
    };
    let e = run(format!("load_plugin(\"{}\");", wrong.display()), "plugin_wrong_abi");
    assert!(e.contains("ABI version") && e.contains(&wrong.display().to_string()), "{e}");
    let e = run("load_plugin(\"/nonexistent/libnothing.so\");".into(), "plugin_missing");
    assert!(e.contains("/nonexistent/libnothing.so") && e.contains("line 1"), "{e}");
    // An error raised inside the plugin (a bad parameter) names the library and the law.
    let e = run(
        format!(
            "let n = load_plugin(\"{}\");\nlet sim = mpm(#{{ dim: 2, cell: 1.0, cells: [1, 1] }});\nsim.material(n, #{{ density: 1.0, young: 1e6, poisson: 0.7, alpha: 0.1, k: 1.0 }});",
            good.display()
        ),
        "plugin_bad_param",
    );
    assert!(e.contains("drucker_prager") && e.contains("poisson = 0.7") && e.contains("line 3"), "{e}");
}

/// A plugin law reports its P-wave speed (ABI version 2), so `critical_dt()` gives the cell
/// crossing time cell / c_p, c_p = sqrt((lambda + 2G) / rho); a plugin of ABI version 1 still
/// loads and runs, and `critical_dt()` then says that no law reports a wave speed.
#[test]
fn plugin_laws_give_the_time_step_limit() {
    let (e, nu, rho, cell): (f64, f64, f64, f64) = (1e7, 0.25, 2000.0, 0.5);
    let src = |lib: &PathBuf| {
        format!(
            r#"
let name = load_plugin("{lib}");
let sim = mpm(#{{ dim: 2, cell: {cell:?}, cells: [2, 2] }});
let m = sim.material(name, #{{ density: {rho:?}, young: {e:?}, poisson: {nu:?}, alpha: 0.2, k: 2e3 }});
sim.fill_box(m, [0.0, 0.0], [0.5, 0.5]);
let limit = "";
try {{ summary("critical_dt", sim.critical_dt()); }} catch (e) {{ limit = e; }}
summary("refused", limit);
sim.dt(1e-5);
sim.run_steps(3);
"#,
            lib = lib.display()
        )
    };
    let lib = build_plugin(&[], "plugin-test");
    let out = common::run_text("plugin_dt", &src(&lib));
    let summary: serde_json::Value = common::summary_of(&out);
    let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let g = e / (2.0 * (1.0 + nu));
    let expected = cell / ((lambda + 2.0 * g) / rho).sqrt();
    let got = summary["critical_dt"].as_f64().unwrap();
    assert!((got - expected).abs() < 1e-12 * expected, "critical_dt {got}, cell / c_p = {expected}");

    let old = build_plugin(&["abi_v1"], "plugin-test-abi-v1");
    let out = common::run_text("plugin_dt_v1", &src(&old));
    let summary: serde_json::Value = common::summary_of(&out);
    let refused = summary["refused"].as_str().unwrap();
    assert!(refused.contains("reports a wave speed") && refused.contains("drucker_prager"), "{refused}");
    assert_eq!(summary["status"], "ok");
}

/// `granite plugins --plugin LIB` lists the library's law and its parameters.
#[test]
fn plugins_command_lists_a_library() {
    let lib = build_plugin(&[], "plugin-test");
    let out = Command::new(env!("CARGO_BIN_EXE_granite")).args(["plugins", "--plugin"]).arg(&lib).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let law = text.lines().position(|l| l.trim_start().starts_with("drucker_prager:")).expect("the plugin's law");
    let params: Vec<&str> =
        text.lines().skip(law + 1).take(4).map(|l| l.split_whitespace().next().unwrap_or("")).collect();
    assert_eq!(params, ["young", "poisson", "alpha", "k"], "{text}");
}

/// A plugin law does not silently take the name of a law already registered (a built-in one, or
/// one of another library loaded before): refused unless asked for with `replace: true`. The
/// same library loaded again, by the same path or another one, is a no-op.
#[test]
fn a_plugin_law_replaces_a_registered_name_only_when_asked() {
    let lib = build_plugin(&[], "plugin-test");
    // The same file by a second path: a link beside it.
    let link = lib.with_file_name("same_library_linked.so");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&lib, &link).unwrap();
    let twice = format!(
        "let a = load_plugin(\"{0}\");\nlet b = load_plugin(\"{0}\");\nlet c = load_plugin(\"{1}\");\n\
         summary(\"laws\", [a, b, c]);",
        lib.display(),
        link.display()
    );
    let out = common::run_text("plugin_twice", &twice);
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["laws"], serde_json::json!(["drucker_prager", "drucker_prager", "drucker_prager"]));
    // Another library file with a law of the same name.
    let other = lib.with_file_name("another_library.so");
    std::fs::copy(&lib, &other).unwrap();
    let clash = format!("load_plugin(\"{}\");\nload_plugin(\"{}\");", lib.display(), other.display());
    let e = common::run_text_err("plugin_clash", &clash);
    assert!(
        e.contains("a law named `drucker_prager` is already registered")
            && e.contains("another_library.so")
            && e.contains("replace: true")
            && e.contains("line 2"),
        "{e}"
    );
    let replaced = format!(
        "load_plugin(\"{0}\");\nlet n = load_plugin(\"{1}\", #{{ replace: true }});\nsummary(\"law\", n);",
        lib.display(),
        other.display()
    );
    let out = common::run_text("plugin_replace", &replaced);
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["law"], "drucker_prager");
}

/// A table whose declared parameter count does not match its list of names is refused before
/// any name past the list is read (a hand-written table; `export_law!` cannot get it wrong).
#[test]
fn a_plugin_table_declaring_more_parameters_than_it_names_is_refused() {
    use granite_plugin_abi::{CStrPtr, ErrorBuffer, LawTable, LawTableV1, ABI_VERSION};
    use std::ffi::c_void;
    unsafe extern "C" fn create(_: *const f64, _: usize, _: *mut ErrorBuffer) -> *mut c_void {
        std::ptr::null_mut()
    }
    unsafe extern "C" fn update(
        _: *const c_void,
        _: usize,
        _: *mut f64,
        _: *const f64,
        _: *mut f64,
        _: *mut ErrorBuffer,
    ) -> i32 {
        1
    }
    unsafe extern "C" fn destroy(_: *mut c_void) {}
    unsafe extern "C" fn wave_speed(_: *const c_void, _: f64) -> f64 {
        f64::NAN
    }
    static NAMES: [CStrPtr; 3] = [CStrPtr(c"young".as_ptr()), CStrPtr(c"poisson".as_ptr()), CStrPtr(std::ptr::null())];
    static NONE: [CStrPtr; 1] = [CStrPtr(std::ptr::null())];
    let table = |param_count: usize| LawTable {
        head: LawTableV1 {
            abi_version: ABI_VERSION,
            table_size: std::mem::size_of::<LawTable>() as u32,
            name: CStrPtr(c"lying".as_ptr()),
            version: CStrPtr(c"1".as_ptr()),
            param_count,
            param_names: NAMES.as_ptr(),
            state_count: 0,
            state_names: NONE.as_ptr(),
            create,
            update,
            destroy,
        },
        wave_speed,
    };
    for (count, says) in [(7, "declares 7 parameters and names 2"), (1, "declares 1 parameters and names more than 1")]
    {
        let lying: &'static LawTable = Box::leak(Box::new(table(count)));
        let mut registry = granite::registry();
        let e = unsafe { granite_loader::register_table(lying, "liar.so".into(), &mut registry, false) };
        let e = e.expect_err("refused").to_string();
        assert!(e.contains("liar.so") && e.contains(says), "{e}");
        assert!(registry.law_factory("lying").is_err());
    }
    let honest: &'static LawTable = Box::leak(Box::new(table(2)));
    let mut registry = granite::registry();
    unsafe { granite_loader::register_table(honest, "honest.so".into(), &mut registry, false) }.unwrap();
    assert_eq!(registry.law_factory("lying").unwrap().param_specs().len(), 2);
}
