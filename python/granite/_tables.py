"""CSV files of a run as pandas DataFrames, or numpy structured arrays where pandas is absent."""

import numpy as np

try:
    import pandas
except ImportError:  # pandas is optional
    pandas = None


def read_csv(path):
    """A CSV file with a header row: a DataFrame with pandas, else a structured array whose
    numeric columns are float (text columns stay text)."""
    if pandas is not None:
        return pandas.read_csv(path)
    return np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")


def frame(rows):
    """A list of dicts as a DataFrame with pandas, else as it is."""
    if pandas is not None:
        return pandas.DataFrame(rows)
    return rows
