//! VTKHDF output read back with VTK's own reader (`vtkHDFReader`, Python `vtk` package): every
//! frame of a run in one file holds exactly what the XML frames of the same run hold, and a run
//! resumed from a checkpoint continues the file as if it had not stopped.
//!
//! `cargo test --features vtkhdf --test integration vtkhdf::`; needs the HDF5 library (Debian: libhdf5-dev)
//! and Python 3 with `vtk` (`pip install vtk`).
#![cfg(feature = "vtkhdf")]

use crate::common;
use std::path::Path;
use std::process::Command;

fn run_in(out: &Path, source: &str, pairs: &[(&str, &str)]) -> granite_script::RunReport {
    common::run_source_in(out, "scene.rhai", source, pairs)
}

/// What tests/vtkhdf/compare_frames.py found: frames, pictures, arrays and values compared,
/// all equal (it fails the test otherwise, saying where the series differ).
fn compare(a: &Path, b: &Path) -> [usize; 4] {
    let script = common::root().join("tests/vtkhdf/compare_frames.py");
    let output = Command::new("python3")
        .arg(&script)
        .args([a, b])
        .output()
        .unwrap_or_else(|e| panic!("python3 could not be started ({e}): the VTKHDF tests need Python 3 with vtk"));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "{} and {} differ, or could not be read (`pip install vtk` if vtkmodules is missing):\n{stdout}\n{stderr}",
        a.display(),
        b.display()
    );
    let words: Vec<&str> = stdout.split_whitespace().collect();
    let count = |name: &str| -> usize {
        let k = words.iter().position(|w| *w == name).unwrap_or_else(|| panic!("no `{name}` in {stdout}"));
        words[k + 1].parse().unwrap()
    };
    [count("frames"), count("pictures"), count("arrays"), count("values")]
}

/// A run written once as XML frames and once as VTKHDF: the same frames, value for value.
fn xml_and_vtkhdf_agree(name: &str, source: &str) -> [usize; 4] {
    let xml = common::out_dir(&format!("{name}_xml"));
    let hdf = common::out_dir(&format!("{name}_vtkhdf"));
    run_in(&xml, source, &[("format", "binary")]);
    run_in(&hdf, source, &[("format", "vtkhdf")]);
    assert!(!hdf.join("vtk/points.pvd").exists(), "a VTKHDF run writes no XML frames");
    compare(&hdf.join("vtk/run.vtkhdf"), &xml.join("vtk"))
}

/// Spheres poured into a box: the spheres, the contact network (none in the first frames, a
/// few hundred at the end) and the walls.
const DEM_BOX: &str = r#"
let format = param("format", "binary");
let sim = dem(#{ seed: 3 });
let glass = sim.material(#{ name: "glass", density: 2500.0 });
sim.contact_law("linear", #{ young: 1e6, friction: 25.0 });
sim.box_walls(glass, [0.0, 0.0, 0.0], [0.04, 0.04, 0.2], #{ open_top: true });
sim.cloud(glass, [0.0, 0.0, 0.0], [0.04, 0.04, 0.08], #{ count: 150, radius: [0.003, 0.004] });
sim.gravity([0.0, 0.0, -9.81]);
sim.dt(0.2 * sim.critical_dt());
sim.vtk_format(format);
sim.vtk_every(300);
sim.run_steps(6000);
"#;

#[test]
fn dem_frames_in_one_vtkhdf_file_equal_the_xml_frames() {
    let [frames, pictures, arrays, values] = xml_and_vtkhdf_agree("vtkhdf_dem", DEM_BOX);
    assert_eq!(frames, 21);
    assert_eq!(pictures, 3, "spheres, contacts and walls");
    // Spheres: id, radius, material, velocity, angular velocity, force, contacts in each frame.
    assert!(arrays >= 7 * frames, "{arrays} arrays");
    assert!(values > 150 * 13 * frames, "{values} values");
}

/// A Mohr-Coulomb column beside an elastic block, collapsing: stress and strain tensors, the
/// plastic state of one law (zero on the other's points).
const MPM_COLUMN: &str = r#"
let format = param("format", "binary");
let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.05, cells: [16, 8] });
let sand = sim.material("mohr_coulomb", #{ density: 1800.0, young: 1e6, poisson: 0.3, friction: 30.0, dilation: 0.0, cohesion: 10.0 });
let block = sim.material("linear_elastic", #{ density: 2000.0, young: 5e6, poisson: 0.25 });
sim.fill_box(sand, [0.0, 0.0], [0.2, 0.3], #{ per_cell: 2 });
sim.fill_box(block, [0.5, 0.0], [0.6, 0.1], #{ per_cell: 2 });
sim.fix("x-", "x"); sim.fix("y-", "y"); sim.fix("x+", "x");
sim.gravity([0.0, -9.81]);
sim.dt(2e-4);
sim.vtk_format(format);
sim.vtk_every(100);
sim.run_steps(1000);
"#;

#[test]
fn mpm_frames_with_tensors_and_state_variables_equal_the_xml_frames() {
    let [frames, pictures, arrays, values] = xml_and_vtkhdf_agree("vtkhdf_mpm", MPM_COLUMN);
    assert_eq!((frames, pictures), (11, 1));
    // id, material, velocity, stress, strain, p, q, deviatoric strain, volume and the
    // Mohr-Coulomb state.
    assert!(arrays > 9 * frames, "{arrays} arrays");
    let points = (4 * 6 + 2 * 2) * 4;
    assert!(values >= points * (2 + 3 + 6 + 6 + 4) * frames, "{values} values");
}

/// A block settling under gravity (tests/common), its frames into VTKHDF every `every` steps, a
/// checkpoint every `checkpoint`.
fn block(cells: usize, every: u64, checkpoint: u64) -> String {
    let outputs = format!(
        "sim.vtk_format(\"vtkhdf\");\nsim.vtk_every({every});\nif !resume {{ sim.checkpoint_every({checkpoint}, \"ck.json\"); }}"
    );
    common::settling_block(cells, &outputs)
}

/// Stopped at step 300 with a checkpoint at step 200 and resumed to step 400: the file holds the
/// frames of steps 0 to 400 once each, as a run straight to step 400 writes them.
#[test]
fn a_resumed_run_continues_the_vtkhdf_file_of_the_run_it_resumes() {
    let source = block(8, 100, 200);
    let straight = common::out_dir("vtkhdf_straight");
    run_in(&straight, &source, &[("steps", "400")]);
    let resumed = common::out_dir("vtkhdf_resumed");
    run_in(&resumed, &source, &[("steps", "300")]);
    run_in(&resumed, &source, &[("resume", "true"), ("steps", "200")]);
    let [frames, ..] = compare(&straight.join("vtk/run.vtkhdf"), &resumed.join("vtk/run.vtkhdf"));
    assert_eq!(frames, 5, "steps 0, 100, 200, 300, 400");
}

/// A format of another name is refused, naming the ones there are.
#[test]
fn an_unknown_format_is_refused_naming_the_allowed_ones() {
    let e = common::run_text_err("vtkhdf_bad", "let sim = dem(); sim.vtk_format(\"hdf\");");
    assert!(e.contains("vtkhdf") && e.contains("\"hdf\"") && e.contains("line 1"), "{e}");
}

/// Runs writing a frame every step, killed (SIGKILL) at moments spread over 0.3 s after their
/// first checkpoint (most kills fall inside a frame's write), then resumed from their checkpoint
/// for 5 steps: each file holds, value for value, the frames a run straight to the same step
/// writes. The frame a kill cut short and the frames after the checkpoint are written again.
#[cfg(unix)]
#[test]
fn a_run_killed_while_writing_frames_resumes_its_file_whole() {
    let base = common::out_dir("vtkhdf_kill");
    std::fs::create_dir_all(&base).unwrap();
    let source = block(40, 1, 10);
    let script = base.join("block.rhai");
    std::fs::write(&script, &source).unwrap();
    let (killed, straight) = (base.join("killed"), base.join("straight"));
    let ck = killed.join("ck.json");
    let mut lcg: u64 = 0x2545_f491_4f6c_dd1d;
    for trial in 0..6 {
        lcg = lcg.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        let delay = std::time::Duration::from_micros((lcg >> 33) % 300_000);
        let _ = std::fs::remove_dir_all(&killed);
        common::kill_after_first_checkpoint(&script, &killed, &ck, delay, trial);
        let resumed_from = granite_core::mpm::MpmSim::load_newest(&ck, &granite::registry()).unwrap().0.step;
        run_in(&killed, &source, &[("resume", "true"), ("steps", "5")]);
        let _ = std::fs::remove_dir_all(&straight);
        let end = (resumed_from + 5).to_string();
        run_in(&straight, &source, &[("steps", end.as_str())]);
        let [frames, ..] = compare(&straight.join("vtk/run.vtkhdf"), &killed.join("vtk/run.vtkhdf"));
        assert_eq!(frames as u64, resumed_from + 6, "trial {trial}, killed {delay:?} after the first checkpoint");
    }
}

/// A disk that fills up while frames go into the VTKHDF file (a 2 MB tmpfs, a frame of 400
/// points every step): the run stops at the step whose frame could not be written, naming the
/// file and the cause, and every frame the file lists reads back equal to a run's on a disk with
/// room (HDF5 1.10 lost such a frame's data without an error: it was listed whole and read as
/// zeros, and the run went on until series.csv failed).
#[cfg(unix)]
#[test]
fn a_full_disk_stops_the_run_at_the_first_lost_vtkhdf_frame_with_every_listed_frame_whole() {
    if !common::can_mount_tmpfs() {
        return;
    }
    let base = common::out_dir("vtkhdf_disk_full");
    std::fs::create_dir_all(&base).unwrap();
    // Rows rarely: the frames are what fills the disk.
    let source = block(20, 1, 1_000_000).replace("sim.vtk_every(1);", "sim.vtk_every(1);\nsim.series_every(100000);");
    let script = base.join("block.rhai");
    std::fs::write(&script, &source).unwrap();
    let _ = std::fs::remove_dir_all(base.join("out"));
    Command::new("unshare")
        .args([
            "-rm",
            "sh",
            "-c",
            "d=$(mktemp -d) && mount -t tmpfs -o size=2m none \"$d\" && \
             \"$0\" run --quiet --threads 1 --set steps=2000 --out \"$d/out\" \"$1\" 2>\"$2/stderr.txt\"; \
             echo $? >\"$2/code.txt\"; cp -a \"$d/out\" \"$2/out\"",
        ])
        .arg(env!("CARGO_BIN_EXE_granite"))
        .arg(&script)
        .arg(&base)
        .status()
        .unwrap();
    let code = std::fs::read_to_string(base.join("code.txt")).unwrap();
    let stderr = std::fs::read_to_string(base.join("stderr.txt")).unwrap();
    assert_eq!(code.trim(), "1", "{stderr}");
    assert!(stderr.contains("run.vtkhdf") && stderr.contains("No space left on device"), "{stderr}");
    let step = common::stopped_at_step(&stderr);
    assert!(step > 5, "the disk held a few frames: {stderr}");
    // Frames of steps 0 to step - 1 are listed, and hold what a run with room writes.
    let straight = common::out_dir("vtkhdf_disk_full_straight");
    run_in(&straight, &source, &[("steps", &(step - 1).to_string())]);
    let [frames, ..] = compare(&straight.join("vtk/run.vtkhdf"), &base.join("out/vtk/run.vtkhdf"));
    assert_eq!(frames as u64, step, "the frame of step {step} is the first one lost");
}
