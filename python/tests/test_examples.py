"""The Python examples of examples/python run, and what they print holds."""

import pathlib
import runpy
import sys

import numpy as np
import pytest

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python"


def run_example(name, argv):
    saved = sys.argv
    sys.argv = [name, *argv]
    try:
        return runpy.run_path(str(EXAMPLES / name), run_name="example")["main"]()
    finally:
        sys.argv = saved


def test_the_heap_fitted_in_numpy_agrees_with_the_scripts_angle(tmp_path):
    angle, run = run_example("heap_repose.py", ["--count", "200", "--out", str(tmp_path / "heap")])
    # Two measures of one slope: the numpy fit through the columns' tops and the script's
    # angle_of_repose (a fit of its own), within the script's spread along the heap.
    assert abs(angle - run.summary["angle_of_repose_deg"]) < max(run.summary["angle_std_deg"], 2.0)
    assert 5.0 < angle < 45.0


def test_the_triaxial_q_p_path(tmp_path):
    series, phi = run_example("triaxial_qp.py", ["--count", "150", "--axial-strain", "0.004",
                                                 "--out", str(tmp_path / "tri"), "--figure", str(tmp_path / "qp.png")])
    # Loaded from the isotropic 100 kPa state at constant lateral stress: p - q/3 stays the
    # lateral stress (the servo's 2 %), and the stress ratio climbs.
    p, q = np.asarray(series["p"], dtype=float), np.asarray(series["q"], dtype=float)
    np.testing.assert_allclose(p - q / 3.0, 1e5, rtol=0.02)
    assert q[-1] > q[0] and phi[-1] > 10.0
    assert (tmp_path / "qp.png").stat().st_size > 0


def test_the_runout_notebook_executes():
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    notebook = nbformat.read(EXAMPLES / "column_runout.ipynb", as_version=4)
    client = nbclient.NotebookClient(notebook, timeout=900, kernel_name="python3",
                                     resources={"metadata": {"path": str(EXAMPLES)}})
    client.execute()  # a failing cell (its assertions on the runout included) raises
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
