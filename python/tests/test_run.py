"""granite.run from Python: summaries, series and frames reach numpy; errors become exceptions."""

import math

import numpy as np
import pytest

import granite


def test_the_vibrating_bar_keeps_its_period_and_energy(scripts, tmp_path):
    # An elastic bar in its first mode: period 4 L / c = 10 s (scripts/mpm/vibrating_bar.rhai).
    run = granite.run(scripts / "mpm" / "vibrating_bar.rhai", params={"shape_functions": "bspline2", "cells": 25},
                      out=tmp_path / "bar", threads=2)
    assert run.summary["status"] == "ok"
    # B-splines at 25 cells: 1.1e-3 measured (they converge at second order, tests/mpm_fidelity.rs).
    assert math.isclose(run.summary["period"], run.summary["period_exact"], rel_tol=3e-3)
    series = run.series
    time = np.asarray(series["time"], dtype=float)
    total = np.asarray(series["total_energy"], dtype=float)
    assert time[-1] == pytest.approx(2 * run.summary["period_exact"], rel=0.02)
    # Energy kept over two periods: the summary's end value (B-splines at 50 cells: 1.3e-5), and
    # every row of the series within the points' quadrature of the strain energy, O((pi h / 2L)^2)
    # = 4e-3 at 25 cells.
    assert abs(run.summary["energy_change_ratio"]) < 1e-3
    assert np.max(np.abs(total - total[0])) < 1e-2 * total[0]
    assert run.provenance["parameters"]["cells"] == 25


def test_frames_of_points_follow_the_bars_mode(scripts, tmp_path):
    run = granite.run(scripts / "mpm" / "vibrating_bar.rhai", params={"periods": 1.0, "shape_functions": "bspline2"},
                      out=tmp_path / "bar")
    first = run.points(0)
    n = len(first["position"])
    assert first["position"].shape == (n, 3) and first["stress"].shape == (n, 6)
    # u(x, t) = (v0 / w) sin(k x) sin(w t), k = pi / 2L, w = c k: L = 25 m, c = 10 m/s, v0 = 0.1 m/s,
    # E = 100 Pa, so stress E v0 / c cos(k x) sin(w t) (tension positive) and velocity
    # v0 sin(k x) cos(w t).
    k, w, v0, sigma0 = np.pi / 50.0, np.pi * 10.0 / 50.0, 0.1, 100.0 * 0.1 / 10.0
    x = first["position"][:, 0]
    np.testing.assert_allclose(first["velocity"][:, 0], v0 * np.sin(k * x), atol=1e-12)
    assert np.all(first["stress"] == 0.0)
    # The frame nearest a quarter period: the velocity has gone into strain.
    times = np.array([t for t, _ in run.frames()])
    quarter = int(np.argmin(np.abs(times - 2.5)))
    frame = run.points(quarter)
    x = frame["position"][:, 0]
    t = times[quarter]
    # 25 cells: the points' stress carries the transfer's noise, largest at the fixed end (4 %).
    stress_error = frame["stress"][:, 0] - sigma0 * np.cos(k * x) * np.sin(w * t)
    velocity_error = frame["velocity"][:, 0] - v0 * np.sin(k * x) * np.cos(w * t)
    assert np.sqrt(np.mean(stress_error ** 2)) < 0.02 * sigma0 and np.max(np.abs(stress_error)) < 0.05 * sigma0
    assert np.sqrt(np.mean(velocity_error ** 2)) < 0.02 * v0 and np.max(np.abs(velocity_error)) < 0.05 * v0
    assert len(run.vtk_frames) == len(times)


def test_a_script_error_names_its_line(tmp_path):
    script = tmp_path / "broken.rhai"
    script.write_text("let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 1.0, cells: [4, 4] });\n"
                      "let x = 1;\n"
                      "sim.no_such_call(x);\n")
    with pytest.raises(granite.ScriptError) as caught:
        granite.run(script, out=tmp_path / "out")
    assert caught.value.file == "broken.rhai"
    assert caught.value.line == 3
    assert "no_such_call" in caught.value.message


def test_an_unknown_parameter_is_refused_with_the_closest_names(scripts, tmp_path):
    with pytest.raises(granite.GraniteError) as caught:
        granite.run(scripts / "mpm" / "vibrating_bar.rhai", params={"cels": 10}, out=tmp_path / "out")
    assert "cels" in str(caught.value) and "cells" in str(caught.value)


def test_params_lists_what_a_script_declares(scripts):
    declared = granite.params(scripts / "mpm" / "vibrating_bar.rhai", cells=50)
    assert declared["cells"]["value"] == "50"
    assert declared["cells"]["allowed"] == ">= 4"
    assert declared["shape_functions"]["value"] == "linear"
    with pytest.raises(granite.GraniteError):
        granite.params(scripts / "mpm" / "vibrating_bar.rhai", cells=2)


def test_the_progress_probe_follows_the_runs(scripts, tmp_path):
    # The column's two runs (settling, collapse), each to its end: the probe the progress bar
    # reads counts both and ends at the last run's last step and the script's end time.
    probe = granite._native.Progress()
    params = [("cell_size", "0.2"), ("points_per_cell", "1"), ("a_tau", "0.05"), ("settle_time", "0.1"),
              ("collapse_time", "0.1")]
    out_dir, _ = granite._native.run(str(scripts / "mpm" / "column_collapse.rhai"), params, str(tmp_path / "col"), 1,
                                     True, probe)
    calls, done, total, time = probe.read()
    run = granite.Run(out_dir)
    assert calls >= 2 and done == total > 0
    assert time == pytest.approx(float(run.table("series_runout.csv")["time"].iloc[-1]), rel=1e-12)


def test_ctrl_c_stops_the_run_cleanly(scripts, tmp_path):
    # Ctrl-C one second in (SIGINT to this process): the run stops at its next step with its
    # outputs written and says so, then KeyboardInterrupt reaches the caller.
    import json
    import signal
    import threading

    timer = threading.Timer(1.0, signal.raise_signal, args=(signal.SIGINT,))
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        granite.run(scripts / "mpm" / "column_collapse.rhai", out=tmp_path / "col", threads=1, progress=False)
    timer.join()
    summary = json.loads((tmp_path / "col" / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["signal"] == "SIGINT"
    assert (tmp_path / "col" / "series.csv").exists()
