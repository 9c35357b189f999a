"""The thesis's one-cell MPMxDEM triaxial (4.4.1) post-processed in Python: the q-p path and the
mobilised friction angle.

An RVE is prepared at the lateral stress (scripts/mpmxdem/prepare_rve.rhai), then one MPM cell of
8 points, each with its own copy of it, is compressed at constant lateral stress
(scripts/mpmxdem/triaxial_one_cell.rhai). The script's series (p, q, axial and volumetric strain)
comes back as a DataFrame; the stress ratio gives the friction angle sin(phi) = 3 M / (6 + M),
M = q / p, of a triaxial compression.

    python examples/python/triaxial_qp.py                        # 1000 spheres, 5 % axial strain
    python examples/python/triaxial_qp.py --count 150 --axial-strain 0.01
"""

import argparse
import pathlib

import numpy as np

import granite

ROOT = pathlib.Path(__file__).resolve().parents[2]


def friction_angle(p, q):
    """The mobilised friction angle (degrees) of a triaxial compression at stress ratio q / p."""
    m = np.asarray(q) / np.asarray(p)
    return np.degrees(np.arcsin(3.0 * m / (6.0 + m)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000, help="spheres of the RVE")
    parser.add_argument("--axial-strain", type=float, default=0.05)
    parser.add_argument("--out", default="out/triaxial_qp")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--figure", default=None, help="a PNG of the q-p path (matplotlib)")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    rve = granite.run(ROOT / "scripts" / "mpmxdem" / "prepare_rve.rhai", params={"count": args.count},
                      out=out / "rve", threads=args.threads)
    test = granite.run(ROOT / "scripts" / "mpmxdem" / "triaxial_one_cell.rhai",
                       params={"rve": str(rve.out_dir / "rve.json"), "axial_strain": args.axial_strain},
                       out=out / "triaxial", threads=args.threads)
    series = test.series
    p, q = np.asarray(series["p"], dtype=float), np.asarray(series["q"], dtype=float)
    phi = friction_angle(p, q)
    peak = int(np.argmax(q / p))
    print(f"RVE: {args.count} spheres, e0 = {rve.summary['void_ratio']:.3f}; "
          f"peak q/p = {q[peak] / p[peak]:.3f} at axial strain {series['axial_strain'][peak]:.4f}: "
          f"friction angle {phi[peak]:.1f} deg; last q = {q[-1]:.4g} Pa at p = {p[-1]:.4g} Pa")
    if args.figure:
        granite.plot.q_p(series).savefig(args.figure, dpi=120)
    return series, phi


if __name__ == "__main__":
    main()
