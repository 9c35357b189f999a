"""`granite.load`: a script's simulations kept alive in Python, to run, inspect and change."""

import pathlib

import numpy as np

from . import _native, _progress
from ._run import _on_a_thread, _overrides, _raised

# The script types of simulations (their arrays: spheres or material points).
_SIMULATIONS = ("DemSim", "MpmSim")


def load(script, params=None, out=None, threads=None, quiet=True, progress=True):
    """Runs a script in a live scene and returns it: its simulations stay, to be stepped,
    inspected and changed from Python (`Scene`).

    params, threads, quiet, progress: as for `granite.run` (the bar for the scene's runs);
    out: the scene's output folder (default out/<script stem>/), each simulation writing into
    its own simN/ folder of it. The script's own runs, if it has any, run here as they would in
    `granite run`.
    """
    script = pathlib.Path(script)
    folder = pathlib.Path(out) if out is not None else pathlib.Path("out") / script.stem
    probe = _native.Progress()
    # Files the script reads (meshes, STL walls) are also looked for beside it, as in `granite run`.
    native = _native.Session(_overrides(params), str(folder), threads, quiet, probe, str(script.resolve().parent))
    scene = Scene(native, _progress.Bar(probe, script.name) if progress else None)
    scene.eval(script.read_text(), name=script.name)
    try:
        scene._native.check_overrides()
    except _native.GraniteError as error:
        raise _raised(error) from None
    return scene


class Scene:
    """A live scene: the variables a script made, and code evaluated among them.

    With exactly one simulation, the scene stands for it: `run_steps`, `run_time`, `call`,
    `array`, `set_array`, `time` and `step` go to that simulation; `scene["name"]` is any
    variable of the scene (a simulation as a `Simulation`).
    """

    def __init__(self, native, bar=None):
        self._native = native
        self._bar = bar

    def __repr__(self):
        return "Scene(" + ", ".join(f"{name}: {kind}" for name, kind in self.variables.items()) + ")"

    def eval(self, code, name="<python>"):
        """Evaluates script code in the scene (variables and functions are kept), as a REPL
        input; returns its value. Errors raise ScriptError (the line within `code`)."""
        value = _interruptible(self._native, lambda: self._native.eval(code), name, self._bar)
        return _wrapped(self, value)

    @property
    def variables(self):
        """{name: script type} of the scene's variables."""
        return {name: kind for name, kind in self._native.variables() if not name.startswith("__python_")}

    @property
    def simulations(self):
        """{variable name: Simulation} of the scene's DEM and MPM simulations."""
        return {name: Simulation(self, name) for name, kind in self.variables.items() if kind in _SIMULATIONS}

    def __getitem__(self, name):
        if name not in self.variables:
            raise KeyError(f"the scene has no variable `{name}`; it has: {', '.join(self.variables)}")
        if self.variables[name] in _SIMULATIONS:
            return Simulation(self, name)
        return self.eval(name)

    def _only(self):
        sims = self.simulations
        if len(sims) != 1:
            raise _native.GraniteError(
                f"the scene has {len(sims)} simulations ({', '.join(sims) or 'none'}): pick one, scene[\"name\"]")
        return next(iter(sims.values()))

    def run_steps(self, n):
        return self._only().run_steps(n)

    def run_time(self, duration):
        return self._only().run_time(duration)

    def call(self, method, *args):
        return self._only().call(method, *args)

    def array(self, name):
        return self._only().array(name)

    def set_array(self, name, values):
        return self._only().set_array(name, values)

    @property
    def time(self):
        return self._only().time

    @property
    def step(self):
        return self._only().step

    def close(self):
        """Pauses any run still going in the background and waits for it."""
        self._native.finish()


class Simulation:
    """A DEM or MPM simulation of a scene, by its variable's name."""

    def __init__(self, scene, variable):
        self.scene = scene
        self.variable = variable

    def __repr__(self):
        return f"Simulation({self.variable!r}: {self.scene.eval(self.variable + '.to_string()')})"

    def call(self, method, *args):
        """Calls one of the simulation's script functions, `sim.method(args...)`, with Python
        values (numbers, strings, lists, dicts, numpy arrays, values the scene handed back):
        the same checks and errors as in a script. Returns its value."""
        names = []
        for k, arg in enumerate(args):
            name = f"__python_arg{k}"
            self.scene._native.set(name, arg._stored if isinstance(arg, Value) else arg)
            names.append(name)
        return self.scene.eval(f"{self.variable}.{method}({', '.join(names)})")

    def get(self, prop):
        """A property of the simulation (`time`, `step`, `dt`, ...)."""
        return self.scene.eval(f"{self.variable}.{prop}")

    def run_steps(self, n):
        """Runs n steps (Ctrl-C pauses at the next step, state kept, and raises KeyboardInterrupt)."""
        return self.call("run_steps", int(n))

    def run_time(self, duration):
        """Runs for `duration` seconds of simulated time."""
        return self.call("run_until", self.time + float(duration))

    @property
    def time(self):
        return self.get("time")

    @property
    def step(self):
        return self.get("step")

    @property
    def array_names(self):
        """The arrays `array` gives: the spheres' (DEM) or the material points' and their laws'
        state variables (MPM)."""
        return self.scene._native.array_names(self.variable)

    def array(self, name):
        """One array of the spheres (DEM: position, velocity, radius, force, ...) or material
        points (MPM: position, velocity, stress, strain, volume, a state variable, ...): a numpy
        array of one row per sphere or point, (n,) or (n, components); a copy."""
        data, columns = self.scene._native.array(self.variable, name)
        values = np.frombuffer(data, dtype=np.float64).copy()
        return values.reshape(-1, columns) if columns > 1 else values

    def set_array(self, name, values):
        """Sets one array from a numpy array of one row per sphere or point (the order of
        `array`), with the checks of the script calls that change them (`set_body`,
        `set_point_velocity`); every row is checked before any changes. DEM: `velocity`,
        `angular_velocity`, `fixed` (the flags `array("fixed")` gives); MPM: `velocity`."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        columns = 1 if values.ndim == 1 else values.shape[1]
        self.scene._native.set_array(self.variable, name, values.tobytes(), columns)

    def arrays(self):
        """Every array, {name: array}."""
        return {name: self.array(name) for name in self.array_names}

    def contacts(self):
        """The DEM simulation's contacts as {column: numpy array} (`sim.contacts()` of the script)."""
        rows = self.call("contacts")
        if not rows:
            return {}
        columns = {}
        for key in rows[0]:
            values = [row.get(key) for row in rows]
            try:
                columns[key] = np.array(values, dtype=float)
            except (TypeError, ValueError):
                columns[key] = np.array(values, dtype=object)
        return columns


class Value:
    """A value of the scene Python cannot hold itself (a material, a wall, a mesh...): passed
    back into calls as it is."""

    def __init__(self, scene, stored):
        self.scene = scene
        self._stored = stored

    @property
    def kind(self):
        return self._stored.kind

    def __repr__(self):
        return f"Value({self.kind}: {self.scene.eval(self._stored.variable + '.to_string()')})"


def _wrapped(scene, value):
    if isinstance(value, _native.Stored):
        if value.kind in _SIMULATIONS:
            return Simulation(scene, value.variable)
        return Value(scene, value)
    if isinstance(value, list):
        return [_wrapped(scene, v) for v in value]
    if isinstance(value, dict):
        return {k: _wrapped(scene, v) for k, v in value.items()}
    return value


def _interruptible(native, work, name, bar=None):
    """Runs `work` (native code, GIL released) so that Ctrl-C here pauses the scene's runs, the
    progress bar following them; errors become ScriptError naming `name`."""
    try:
        return _on_a_thread(work, native.interrupt, bar)
    except _native.GraniteError as error:
        if str(error).startswith("line "):
            error = _native.GraniteError(f"{name}: {error}")
        raise _raised(error) from None
