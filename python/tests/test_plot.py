"""granite.plot: figures of a run's curves hold the run's numbers."""

import numpy as np
import pytest

import granite

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")


def test_series_and_energies_draw_the_runs_columns(scripts, tmp_path):
    run = granite.run(scripts / "mpm" / "vibrating_bar.rhai", out=tmp_path / "bar")
    series = run.series
    figure = granite.plot.series(run, "time", "kinetic_energy")
    (line,) = figure.axes[0].get_lines()
    np.testing.assert_array_equal(line.get_xdata(), np.asarray(series["time"], dtype=float))
    np.testing.assert_array_equal(line.get_ydata(), np.asarray(series["kinetic_energy"], dtype=float))
    lines = granite.plot.energies(run).axes[0].get_lines()
    assert [l.get_label() for l in lines] == ["kinetic_energy", "gravitational_energy", "elastic_energy", "total_energy"]
    with pytest.raises(KeyError, match="kinetic"):
        granite.plot.series(run, "time", "kinetc_energy")


def test_the_runout_figure_of_a_column(scripts, tmp_path):
    run = granite.run(scripts / "mpm" / "column_collapse.rhai", out=tmp_path / "column",
                      params={"cell_size": 0.2, "points_per_cell": 1, "a_tau": 0.05, "collapse_time": 1.0})
    figure = granite.plot.runout(run, experiments=1.2)
    lines = figure.axes[0].get_lines()
    assert len(lines) == 3
    runout = run.table("series_runout.csv")
    np.testing.assert_array_equal(lines[0].get_ydata(), np.asarray(runout["runout_normalised"], dtype=float))
    # The last row is the summary's final runout.
    assert lines[0].get_ydata()[-1] == pytest.approx(run.summary["final_normalised_runout"])


def test_stress_paths_from_a_table():
    pandas = pytest.importorskip("pandas")
    table = pandas.DataFrame({"p": [1e5, 1.2e5, 1.4e5], "q": [0.0, 6e4, 1.2e5], "void_ratio": [0.60, 0.59, 0.585]})
    (line,) = granite.plot.q_p(table).axes[0].get_lines()
    np.testing.assert_array_equal(line.get_ydata(), table["q"])
    ax = granite.plot.e_p(table).axes[0]
    assert ax.get_xscale() == "log"
