"""granite.batch: a sweep of runs in parallel processes, one table."""

import numpy as np
import pytest

import granite


def test_a_sweep_of_eight_bars_returns_one_table(scripts, tmp_path):
    # The vibrating bar's period 4 L / c with c = sqrt(E / rho): 10 s at every resolution; the
    # sweep crosses 4 resolutions with 2 shape functions.
    table = granite.batch(scripts / "mpm" / "vibrating_bar.rhai",
                          {"cells": [10, 15, 20, 25], "shape_functions": ["linear", "bspline2"]},
                          jobs=2, out=tmp_path / "sweep", progress=False)
    pandas = pytest.importorskip("pandas")
    assert isinstance(table, pandas.DataFrame) and len(table) == 8
    assert list(table["status"]) == ["ok"] * 8
    assert sorted(zip(table["cells"], table["shape_functions"])) == sorted(
        (c, s) for c in [10, 15, 20, 25] for s in ["linear", "bspline2"])
    np.testing.assert_allclose(table["period"], table["period_exact"], rtol=0.02)
    # B-splines converge (docs/mpm.md): at 25 cells closer to the exact period than at 10.
    bspline = table[table["shape_functions"] == "bspline2"].set_index("cells")
    assert bspline.loc[25, "period_error"] < bspline.loc[10, "period_error"]
    assert table["script_hash"].nunique() == 1 and table["out_dir"].nunique() == 8


def test_a_failed_run_is_a_row_not_an_exception(scripts, tmp_path):
    table = granite.batch(scripts / "mpm" / "vibrating_bar.rhai", [{"cells": 10}, {"cells": 2}],
                          jobs=2, out=tmp_path / "sweep", progress=False)
    rows = table.to_dict("records") if hasattr(table, "to_dict") else table
    assert [r["status"] for r in rows] == ["ok", "failed"]
    assert "cells" in rows[1]["error"]
