"""Live scenes: a script's simulations stepped, inspected and changed from Python."""

import numpy as np
import pytest

import granite

FALL = """
let sim = dem(#{ seed: 1 });
let glass = sim.material(#{ name: "glass", density: 2500.0 });
sim.contact_law("linear", #{ young: 1e8, friction: 25.0 });
let floor = sim.wall_plane(glass, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
let ball = sim.sphere(glass, [0.0, 0.0, 0.5], 0.01);
sim.gravity([0.0, 0.0, -9.81]);
sim.dt(2.0e-5);
"""


def test_a_falling_sphere_driven_from_python(tmp_path):
    script = tmp_path / "fall.rhai"
    script.write_text(FALL)
    sim = granite.load(script, out=tmp_path / "out", threads=1)
    assert set(sim.simulations) == {"sim"}
    assert sim.variables["floor"] == "DemWall"
    x0 = sim.array("position")
    assert x0.shape == (1, 3) and x0[0, 2] == 0.5
    # Free fall for 0.2 s: z = z0 - g t^2 / 2, v = -g t (the integrator's error: g t dt / 2 at most).
    sim.run_time(0.2)
    t = sim.time
    assert t == pytest.approx(0.2, abs=1e-9)
    z, vz = sim.array("position")[0, 2], sim.array("velocity")[0, 2]
    assert z == pytest.approx(0.5 - 0.5 * 9.81 * t ** 2, abs=9.81 * t * 2e-5)
    assert vz == pytest.approx(-9.81 * t, rel=1e-12)
    # Changed from Python with the script's own calls: no gravity, a sideways velocity.
    sim.call("gravity", [0.0, 0.0, 0.0])
    sim.call("set_body", sim["ball"], {"velocity": np.array([1.0, 0.0, 0.0])})
    sim.run_steps(1000)
    x = sim.array("position")[0]
    assert x[0] == pytest.approx(1000 * 2e-5, rel=1e-12) and x[2] == pytest.approx(z, abs=1e-15)
    # A value the scene holds (the wall) goes back into a call as it is.
    assert sim.call("wall_force", sim["floor"]) == [0.0, 0.0, 0.0]
    # The script's checks and errors, from Python.
    with pytest.raises(granite.GraniteError) as caught:
        sim.call("set_body", 99, {"velocity": [0.0, 0.0, 0.0]})
    assert "99" in str(caught.value)
    with pytest.raises(granite.GraniteError):
        sim.array("pressure")


def test_sphere_contacts_reach_numpy_without_a_file(tmp_path):
    script = tmp_path / "rest.rhai"
    script.write_text(FALL.replace("[0.0, 0.0, 0.5]", "[0.0, 0.0, 0.0099]") + "sim.damping(0.7);\n")
    sim = granite.load(script, out=tmp_path / "out", threads=1)
    sim.run_time(0.5)
    contacts = sim["sim"].contacts()
    assert len(contacts["normal_force"]) == 1
    # At rest on the floor: the contact carries the sphere's weight.
    mass = sim.array("mass")[0]
    assert contacts["normal_force"][0] == pytest.approx(mass * 9.81, rel=1e-6)
    # The sphere's force of the last step is the contact's (gravity apart): the floor's push.
    np.testing.assert_allclose(sim.array("force")[0], [0.0, 0.0, mass * 9.81], rtol=1e-6, atol=1e-12)


def test_an_error_in_the_loaded_script_names_its_line(tmp_path):
    script = tmp_path / "bad.rhai"
    script.write_text(FALL + "sim.gravity(1.0, 2.0);\n")
    with pytest.raises(granite.ScriptError) as caught:
        granite.load(script, out=tmp_path / "out")
    assert caught.value.file == "bad.rhai" and caught.value.line == FALL.count("\n") + 1


RVE_CELL = """
let rve = dem_load(rve_file);
let sim = mpm(#{ dim: 3, origin: [0.0, 0.0, 0.0], cell: 1.0, cells: [1, 1, 1] });
let sand = sim.material("dem_rve", #{ name: "sand_rve", density: 2650.0 / (1.0 + rve.void_ratio()), rve: rve });
sim.fill_box(sand, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], #{ per_cell: 2, layout: "regular", stress: rve.cell_stress() });
for face in ["x-", "x+", "y-", "y+", "z-", "z+"] { sim.fix(face, "x"); sim.fix(face, "y"); sim.fix(face, "z"); }
sim.dt(1.0e-4);
"""


def test_the_rve_stresses_of_mpmxdem_points_reach_numpy(scripts, tmp_path):
    # The RVE of 150 spheres prepared at 100 kPa, then one cell of 8 points held still.
    prepared = granite.run(scripts / "mpmxdem" / "prepare_rve.rhai", params={"count": 150},
                           out=tmp_path / "rve", threads=2)
    script = tmp_path / "cell.rhai"
    script.write_text('let rve_file = param("rve_file", "");\n' + RVE_CELL)
    scene = granite.load(script, params={"rve_file": str(prepared.out_dir / "rve.json")}, out=tmp_path / "cell")
    # Two simulations: the loaded RVE (a DEM one) and the MPM cell.
    assert scene.variables["rve"] == "DemSim" and scene.variables["sim"] == "MpmSim"
    sim = scene["sim"]
    sim.run_steps(2)
    stress = sim.array("stress")
    assert stress.shape == (8, 6)
    # Every point's stress is its RVE's: isotropic at the preparation's 100 kPa (compression
    # negative; the servo's tolerance is 2 %), the same in all 8 copies of the same RVE.
    np.testing.assert_allclose(stress[:, :3], -1e5, rtol=0.02)
    np.testing.assert_allclose(stress, np.broadcast_to(stress[0], stress.shape), rtol=1e-12, atol=1e-9)
    mean = sim.array("rve_mean_stress")
    np.testing.assert_allclose(mean, stress[:, :3].mean(axis=1), rtol=1e-12)
    assert "coordination" in sim.array_names


def test_velocities_set_from_numpy_with_the_consoles_checks(tmp_path):
    script = tmp_path / "spheres.rhai"
    script.write_text(FALL.replace("let ball = sim.sphere(glass, [0.0, 0.0, 0.5], 0.01);",
                                   "for k in 0..4 { sim.sphere(glass, [0.1 * k.to_float(), 0.0, 0.5], 0.01); }")
                      + "sim.gravity([0.0, 0.0, 0.0]);\n")
    sim = granite.load(script, out=tmp_path / "out", threads=1)
    v = np.zeros((4, 3))
    v[:, 0] = [1.0, 2.0, 3.0, 4.0]
    sim.set_array("velocity", v)
    x0 = sim.array("position")
    sim.run_steps(100)
    # No gravity, no contact: each sphere moves at the velocity numpy gave it.
    np.testing.assert_allclose(sim.array("position") - x0, v * 100 * 2e-5, rtol=1e-12, atol=1e-15)
    # Blocked degrees of freedom as flags (1: x), read back as set.
    fixed = np.array([1.0, 0.0, 0.0, 0.0])
    sim.set_array("fixed", fixed)
    np.testing.assert_array_equal(sim.array("fixed"), fixed)
    # Refused as the console refuses, before anything changes.
    bad = v.copy()
    bad[2, 1] = np.nan
    with pytest.raises(granite.GraniteError, match="row 2"):
        sim.set_array("velocity", bad)
    with pytest.raises(granite.GraniteError, match="shape"):
        sim.set_array("velocity", v[:3])
    np.testing.assert_array_equal(sim.array("velocity"), v)


def test_ctrl_c_pauses_a_session_run_and_keeps_its_state(tmp_path):
    import signal
    import threading

    script = tmp_path / "fall.rhai"
    script.write_text(FALL)
    sim = granite.load(script, out=tmp_path / "out", threads=1, progress=False)
    timer = threading.Timer(0.5, signal.raise_signal, args=(signal.SIGINT,))
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        sim.run_steps(10 ** 9)
    timer.join()
    # Paused between two steps, the state kept: it goes on from there.
    t, step = sim.time, sim.step
    assert 0.0 < t < 10 ** 9 * 2e-5 and step > 0
    sim.run_steps(10)
    assert sim.step == step + 10 and sim.time == pytest.approx(t + 10 * 2e-5, rel=1e-12)


def test_a_second_thread_waits_for_a_run_without_deadlock(tmp_path):
    # One thread runs the scene; another reads an array meanwhile: it waits for the scene
    # without holding the GIL (other Python threads, a notebook, go on), and both finish.
    import threading

    script = tmp_path / "fall.rhai"
    script.write_text(FALL)
    sim = granite.load(script, out=tmp_path / "out", threads=1, progress=False)
    runner = threading.Thread(target=sim.run_steps, args=(20000,), daemon=True)
    runner.start()
    read = {}
    reader = threading.Thread(target=lambda: read.setdefault("x", sim.array("position")), daemon=True)
    reader.start()
    runner.join(timeout=120)
    reader.join(timeout=120)
    assert not runner.is_alive() and not reader.is_alive()
    assert read["x"].shape == (1, 3) and sim.step == 20000


def test_a_loaded_script_finds_its_files_beside_it(scripts, tmp_path):
    # The STL walls of the silo, named by the script without a folder, found beside the script
    # (as `granite run` finds them) though the working directory is elsewhere.
    import shutil

    folder = tmp_path / "scene"
    folder.mkdir()
    shutil.copy(scripts / "dem" / "silo_outlet_15mm.stl", folder)
    (folder / "silo.rhai").write_text(
        'let sim = dem();\n'
        'let glass = sim.material(#{ name: "glass", density: 2500.0 });\n'
        'let silo = sim.wall_mesh(glass, "silo_outlet_15mm.stl", #{ scale: 0.001 });\n')
    scene = granite.load(folder / "silo.rhai", out=tmp_path / "out")
    # One wall a triangle of the file.
    stl = (folder / "silo_outlet_15mm.stl").read_bytes()
    triangles = stl.count(b"facet normal") if stl.lstrip().startswith(b"solid") else int.from_bytes(stl[80:84], "little")
    assert scene.eval("silo.len()") == triangles > 0
