"""`granite.batch`: a parameter sweep run in parallel processes, one table of summaries."""

import concurrent.futures
import itertools
import multiprocessing
import os
import pathlib

from . import _tables
from ._run import run


def _grid_rows(grid):
    """The runs of a grid: {name: [values]} as their Cartesian product, or a list of dicts."""
    if isinstance(grid, dict):
        names = list(grid)
        for name in names:
            if isinstance(grid[name], (str, bytes)) or not hasattr(grid[name], "__iter__"):
                raise TypeError(f"grid[{name!r}] must be a list of values (got {grid[name]!r})")
        return [dict(zip(names, values)) for values in itertools.product(*(list(grid[n]) for n in names))]
    rows = [dict(row) for row in grid]
    if not rows:
        raise ValueError("the grid holds no run")
    return rows


def _one(script, params, out, threads):
    """One run of the sweep, in a worker process: its row (failures recorded, not raised)."""
    row = dict(params)
    try:
        result = run(script, params=params, out=out, threads=threads, progress=False)
        row.update(result.summary)
        provenance = result.provenance
        row["program"] = provenance.get("program")
        row["script_hash"] = provenance.get("script_hash")
    except Exception as error:  # one failed run does not end the sweep
        row["status"] = "failed"
        row["error"] = str(error)
    row["out_dir"] = str(out)
    return row


def batch(script, grid, jobs=None, out=None, threads=None, progress=True):
    """Runs a script once per point of `grid` in `jobs` parallel processes and returns one table
    (a DataFrame with pandas, else a list of dicts): the parameters, the summary, `status`,
    `error` (a failed run's message), `program` and `script_hash` (its provenance) and `out_dir`.

    grid: {name: [values, ...]} (every combination) or a list of {name: value} dicts.
    jobs: processes at once (default: every core); threads: threads per run (default: the cores
    shared among the jobs); out: the folder of the runs' folders, run_000, run_001, ... (default
    out/<script stem>_batch/); progress: a progress bar over the runs where tqdm is installed.
    """
    script = pathlib.Path(script)
    rows = _grid_rows(grid)
    folder = pathlib.Path(out) if out is not None else pathlib.Path("out") / f"{script.stem}_batch"
    cores = os.cpu_count() or 1
    jobs = max(1, min(jobs or cores, len(rows)))
    threads = threads or max(1, cores // jobs)
    width = max(3, len(str(len(rows) - 1)))
    outs = [folder / f"run_{k:0{width}d}" for k in range(len(rows))]
    # Fresh processes: a forked copy of a process whose native thread pools are running is unsafe.
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        futures = [pool.submit(_one, str(script), params, str(o), threads) for params, o in zip(rows, outs)]
        done = concurrent.futures.as_completed(futures)
        if progress:
            try:
                from tqdm.auto import tqdm

                done = tqdm(done, total=len(futures), desc=script.name, unit="run")
            except ImportError:
                pass
        for _ in done:
            pass
        results = [f.result() for f in futures]
    return _tables.frame(results)
