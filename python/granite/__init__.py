"""granite from Python: run Rhai simulation scripts and read their results as numpy arrays and
pandas DataFrames.

    import granite
    run = granite.run("scripts/mpm/column_collapse.rhai", params={"a_tau": 0.05}, out="out/col")
    run.summary["final_normalised_runout"]
    run.series            # series.csv as a DataFrame (a numpy structured array without pandas)

The scripts stay granite's way of setting a simulation up; docs/python.md is the reference.
"""

from ._native import GraniteError, __version__
from ._run import Run, ScriptError, params, run

__all__ = ["GraniteError", "Run", "ScriptError", "__version__", "params", "run"]
