"""Draws the slip surface of a failed embankment: the points of failure.csv (written by
embankment.rhai after its first failed stage) coloured by their deviatoric strain, with a circle
of Bishop's method if given.

    python3 picture.py out/embankment/failure.csv picture.png [xc yc r]

Needs matplotlib (pip install matplotlib)."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

rows = list(csv.DictReader(open(sys.argv[1])))
x = np.array([float(r["x"]) for r in rows])
y = np.array([float(r["y"]) for r in rows])
strain = np.array([float(r["deviatoric_strain"]) for r in rows])
fig, ax = plt.subplots(figsize=(9, 3.6))
points = ax.scatter(x, y, c=strain, s=6, cmap="inferno", vmin=0, vmax=np.percentile(strain, 99))
fig.colorbar(points, ax=ax, label="deviatoric strain")
if len(sys.argv) > 3:
    xc, yc, r = map(float, sys.argv[3:6])
    t = np.linspace(0, 2 * np.pi, 500)
    ax.plot(xc + r * np.cos(t), yc + r * np.sin(t), "c--", lw=1, label="Bishop's critical circle")
    ax.legend(loc="upper right")
ax.set_xlim(x.min() - 0.5, x.max() + 0.5)
ax.set_ylim(y.min() - 0.5, y.max() + 1.0)
ax.set_aspect("equal")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=90)
