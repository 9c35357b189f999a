"""A DEM run's spheres and contact forces as numpy arrays."""

import numpy as np
import pytest

import granite


def test_the_walls_carry_the_weight_of_settled_beads(examples, tmp_path):
    # examples/tutorial_dem.rhai: glass beads (2500 kg/m^3) poured into a box settle under gravity.
    run = granite.run(examples / "tutorial_dem.rhai", params={"count": 60, "repose_time": 0.0},
                      out=tmp_path / "beads", threads=2)
    spheres, contacts = run.spheres(), run.contacts()
    n = len(spheres["radius"])
    assert n == 60 and spheres["position"].shape == (n, 3)
    weight = np.sum(2500.0 * 4.0 / 3.0 * np.pi * spheres["radius"] ** 3) * 9.81
    # At rest (kinetic energy ~1e-29 J), the walls' contact forces hold the beads' weight.
    on_walls = contacts["wall"] >= 0
    assert np.any(on_walls) and np.any(~on_walls)
    assert abs(np.sum(contacts["force"][on_walls, 2])) == pytest.approx(weight, rel=1e-6)
    # Every contact has its two ends, and each sphere counts its own contacts.
    assert contacts["position"].shape == (2 * len(contacts["normal_force"]), 3)
    assert np.sum(spheres["contacts"]) == 2 * np.sum(~on_walls) + np.sum(on_walls)
