"""granite from Python: run Rhai simulation scripts and read their results as numpy arrays and
pandas DataFrames.

    import granite
    run = granite.run("scripts/mpm/column_collapse.rhai", params={"a_tau": 0.05}, out="out/col")
    run.summary["final_normalised_runout"]
    run.series            # series.csv as a DataFrame (a numpy structured array without pandas)

    sim = granite.load("scene.rhai")          # a live scene: step, inspect, change
    sim.run_steps(100)
    sim.array("position")                     # (n, 3) numpy array

The scripts stay granite's way of setting a simulation up; docs/python.md is the reference.
"""

from ._native import GraniteError, __version__
from . import plot
from ._batch import batch
from ._run import Run, ScriptError, params, run
from ._scene import Scene, Simulation, Value, load

__all__ = [
    "GraniteError", "Run", "ScriptError", "Scene", "Simulation", "Value", "__version__", "batch", "load", "params",
    "plot", "run",
]
