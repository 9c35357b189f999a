"""A DEM heap's angle of repose fitted in numpy (thesis 2.3.2).

examples/tutorial_dem.rhai pours glass beads into a box and then takes one side away: the beads
that stay form a heap. This script runs it, reads the heap's spheres from the last VTK frame,
fits the free surface with numpy and compares the slope with the script's own measure.

    python examples/python/heap_repose.py                   # 500 beads, about a minute
    python examples/python/heap_repose.py --count 200 --out out/heap_small
"""

import argparse
import pathlib

import numpy as np

import granite

ROOT = pathlib.Path(__file__).resolve().parents[2]


def surface_angle(position, radius, width, bins=12):
    """The heap's slope in degrees: the top of each column of beads across x (a bead's top,
    z + r), a straight line fitted through the columns on the slope (their top neither at the
    wall's plateau nor at the floor)."""
    x, top = position[:, 0], position[:, 2] + radius
    edges = np.linspace(0.0, width, bins + 1)
    centres, heights = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = (x >= lo) & (x < hi)
        if inside.any():
            centres.append(0.5 * (lo + hi))
            heights.append(top[inside].max())
    centres, heights = np.array(centres), np.array(heights)
    floor = 2.0 * radius.max()
    slope = (heights > floor) & (heights < heights.max() - 0.5 * floor)
    if slope.sum() < 3:
        slope = heights > floor
    gradient, _ = np.polyfit(centres[slope], heights[slope], 1)
    return np.degrees(np.arctan(abs(gradient)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=500, help="beads poured")
    parser.add_argument("--out", default="out/heap_repose", help="output folder")
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args()
    run = granite.run(ROOT / "examples" / "tutorial_dem.rhai", params={"count": args.count}, out=args.out,
                      threads=args.threads)
    heap = run.spheres(-1)
    angle = surface_angle(heap["position"], heap["radius"], width=0.1)
    print(f"{len(heap['radius'])} beads in the heap; surface fitted in numpy: {angle:.1f} deg; "
          f"the script's angle_of_repose: {run.summary['angle_of_repose_deg']:.1f} "
          f"+- {run.summary['angle_std_deg']:.1f} deg")
    return angle, run


if __name__ == "__main__":
    main()
