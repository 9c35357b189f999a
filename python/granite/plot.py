"""Figures of the usual curves (matplotlib): series against time, the column's runout, energies,
q-p and e-p paths. Each returns the matplotlib Figure; `ax=` draws into an existing Axes instead."""

import numpy as np

from ._run import Run


def _columns(source, table):
    """{column: array} of a Run's CSV file, a DataFrame, a structured array or such a dict."""
    if isinstance(source, dict):
        return source
    if isinstance(source, Run):
        source = source.table(table)
    if hasattr(source, "columns"):  # a DataFrame
        return {name: np.asarray(source[name], dtype=float) for name in source.columns
                if np.issubdtype(np.asarray(source[name]).dtype, np.number)}
    return {name: np.asarray(source[name], dtype=float) for name in source.dtype.names}


def _axes(ax):
    import matplotlib.pyplot as plt

    if ax is not None:
        return ax.figure, ax
    figure, ax = plt.subplots(figsize=(7, 4.5))
    return figure, ax


def _need(columns, names, table):
    missing = [n for n in names if n not in columns]
    if missing:
        raise KeyError(f"{table} has no column {', '.join(map(repr, missing))}; it has: {', '.join(columns)}")


def series(source, x, y, table="series.csv", ax=None, **style):
    """Columns `y` (a name or a list) against column `x` of a run's table."""
    columns = _columns(source, table)
    ys = [y] if isinstance(y, str) else list(y)
    _need(columns, [x, *ys], table)
    figure, ax = _axes(ax)
    for name in ys:
        ax.plot(columns[x], columns[name], label=name, **style)
    ax.set_xlabel(x)
    ax.set_ylabel(ys[0] if len(ys) == 1 else "")
    if len(ys) > 1:
        ax.legend()
    ax.grid(True, alpha=0.3)
    return figure


def runout(source, table="series_runout.csv", experiments=None, ax=None):
    """The column's normalised runout L~ (eq. 5.8, from L_x and of the body front) against the
    normalised time t~ (eq. 5.9). experiments: a final L~ to draw as a line (e.g. Lajeunesse et
    al. 2005: 1.2 a for an aspect ratio a below about 2.3)."""
    columns = _columns(source, table)
    _need(columns, ["time_normalised", "runout_normalised"], table)
    figure, ax = _axes(ax)
    ax.plot(columns["time_normalised"], columns["runout_normalised"], label="L~ from L_x (eq. 5.8)")
    if "front_runout_normalised" in columns:
        ax.plot(columns["time_normalised"], columns["front_runout_normalised"], label="body front")
    if experiments is not None:
        ax.axhline(experiments, color="k", linestyle="--", label=f"experiments: {experiments:g}")
    ax.set_xlabel("t~ (eq. 5.9)")
    ax.set_ylabel("L~")
    ax.legend()
    ax.grid(True, alpha=0.3)
    return figure


def energies(source, table="series.csv", ax=None):
    """Kinetic, gravitational, elastic and total energy against time (the columns a run has)."""
    columns = _columns(source, table)
    names = [n for n in ("kinetic_energy", "gravitational_energy", "elastic_energy", "total_energy") if n in columns]
    if not names:
        raise KeyError(f"{table} has no energy column; it has: {', '.join(columns)}")
    return series(columns, "time", names, table, ax=ax)


def q_p(source, table="series.csv", p="p", q="q", ax=None):
    """The stress path q against p (compression positive, as the triaxial scripts write them)."""
    return _path(source, table, p, q, f"{p} [Pa]", f"{q} [Pa]", False, ax)


def e_p(source, table="series.csv", p="p", e="void_ratio", ax=None):
    """The void ratio against p on a logarithmic axis (compression positive)."""
    return _path(source, table, p, e, f"{p} [Pa]", e, True, ax)


def _path(source, table, x, y, x_label, y_label, log_x, ax):
    columns = _columns(source, table)
    _need(columns, [x, y], table)
    figure, ax = _axes(ax)
    (ax.semilogx if log_x else ax.plot)(columns[x], columns[y])
    ax.set_xlabel(x_label)
    ax.set_ylabel(y_label)
    ax.grid(True, which="both", alpha=0.3)
    return figure
