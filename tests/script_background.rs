//! Background runs from a script: a callback pauses an open-ended `sim.run()` at a chosen step,
//! `sim.wait()` returns then, and a run of n steps left going at the end of the script is
//! waited for by `granite run` before the outputs close; free fall checks nothing was lost, and
//! a series column (a script function) is computed by the background thread.

use crate::common;

const G: f64 = 9.81;
const DT: f64 = 1e-5;
const PAUSE_AT: u64 = 1000;
const LAST_RUN: u64 = 300;

#[test]
fn callback_pause_wait_and_a_run_left_going() {
    let src = format!(
        r#"
let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [10, 40] }});
let soil = sim.material("linear_elastic", #{{ density: 1000.0, young: 1e6, poisson: 0.3 }});
sim.fill_box(soil, [0.3, 3.5], [0.7, 3.9], #{{ per_cell: 2 }});
sim.gravity([0.0, -{G:?}]);
sim.dt({DT:e});
sim.series_every(100);
sim.series_column("speed", |s| {{ let d = s.diagnostics(); (2.0 * d.kinetic_energy / d.mass).sqrt() }});
sim.every(100, |s| {{ if s.step == {PAUSE_AT} {{ s.pause(); }} }});
sim.run();
sim.wait();
summary("paused_step", sim.step);
summary("running_after_wait", sim.running);
sim.run({LAST_RUN});
"#
    );
    let out = common::run_text("script_background", &src);
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["paused_step"].as_i64(), Some(PAUSE_AT as i64), "{summary}");
    assert_eq!(summary["running_after_wait"].as_bool(), Some(false), "{summary}");

    let (h, rows) = common::read_csv(&out.join("series.csv"));
    let last = rows.last().expect("series rows");
    let (step, time, speed) = (common::column(&h, "step"), common::column(&h, "time"), common::column(&h, "speed"));
    assert_eq!(last[step] as u64, PAUSE_AT + LAST_RUN, "the run left going was finished");
    let v = last[speed];
    assert!((last[time] - last[step] * DT).abs() < 1e-9);
    assert!((v - G * last[time]).abs() < 1e-6 * G * last[time], "speed {v} after {} s of free fall", last[time]);
}
