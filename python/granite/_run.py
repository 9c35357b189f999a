"""`granite.run`: a script run to its end from Python, and what it left behind."""

import json
import pathlib
import re
import threading
import xml.etree.ElementTree as ElementTree

from . import _native, _progress, _tables, _vtk


class ScriptError(_native.GraniteError):
    """A script stopped with an error at one of its lines: `file`, `line` and `message`."""

    def __init__(self, text, file, line, message):
        super().__init__(text)
        self.file = file
        self.line = line
        self.message = message


# "column_study.rhai: line 172: at t = ..." (granite's script errors name the file and the line).
_AT_LINE = re.compile(r"^(?P<file>[^\n]*?\.rhai): line (?P<line>\d+): (?P<message>.*)$", re.DOTALL)


def _raised(error):
    """The exception a native error becomes: ScriptError where it names a script line."""
    text = str(error)
    match = _AT_LINE.match(text)
    if match:
        return ScriptError(text, match.group("file"), int(match.group("line")), match.group("message"))
    return error


def _literal(value):
    """A value as `--set` takes it: booleans and numbers as script literals, lists as arrays."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(json.dumps(v) if isinstance(v, str) else _literal(v) for v in value) + "]"
    return str(value)


def _overrides(params):
    """`--set` pairs from a dict (strings as they are)."""
    return [(str(name), _literal(value)) for name, value in (params or {}).items()]


def run(script, params=None, out=None, threads=None, quiet=True, progress=True):
    """Runs a Rhai script to its end, as `granite run` does, and returns its `Run`.

    params: {name: value} as `--set name=value` (checked as `--set` is: an unknown name is refused
    with the closest declared ones); out: the output folder (default out/<script stem>/);
    threads: worker threads (default every core); quiet: no progress lines on standard error;
    progress: a progress bar of each run call of the script while it goes on (tqdm, where
    installed: a widget in Jupyter), drawn once a call lasts half a second.
    Raises ScriptError (file, line, message) when the script stops at a line, GraniteError for
    any other failure. Ctrl-C stops the run cleanly at its next step (outputs and checkpoints
    written, as on the command line) and then raises KeyboardInterrupt.
    """
    probe = _native.Progress()

    def work():
        return _native.run(str(script), _overrides(params), None if out is None else str(out), threads, quiet, probe)

    bar = _progress.Bar(probe, pathlib.Path(script).name) if progress else None
    try:
        result = _on_a_thread(work, _native.request_stop, bar)
    except _native.GraniteError as error:
        raise _raised(error) from None
    out_dir, summary = result
    return Run(out_dir, json.loads(summary))


def _on_a_thread(work, stop, bar=None):
    """Runs `work` (native code that releases the GIL) on a thread of its own, so that this one
    takes Ctrl-C: `stop()` asks the native code to stop at its next step, and once it has, the
    KeyboardInterrupt goes on. Returns what `work` returns; raises what it raised."""
    result = {}
    finished = threading.Event()

    def target():
        try:
            result["value"] = work()
        except BaseException as error:  # handed to the calling thread
            result["error"] = error
        finally:
            finished.set()

    # An Event, not Thread.join: a join that Ctrl-C interrupts can take the thread for ended.
    threading.Thread(target=target, name="granite", daemon=True).start()
    try:
        while not finished.wait(0.1):
            if bar is not None:
                bar.update()
    except KeyboardInterrupt:
        stop()
        finished.wait()
        raise
    finally:
        if bar is not None:
            bar.close()
    if "error" in result:
        raise result["error"]
    return result["value"]


def params(script, **overrides):
    """The parameters a script declares before its first simulation, {name: {"value", "type",
    "allowed", "comment"}}; keyword arguments are checked as `--set` values are."""
    try:
        declared = _native.params(str(script), _overrides(overrides))
    except _native.GraniteError as error:
        raise _raised(error) from None
    return {
        name: {"value": value, "type": kind, "allowed": allowed, "comment": comment}
        for name, value, kind, allowed, comment in declared
    }


class Run:
    """What a finished run left in its output folder."""

    def __init__(self, out_dir, summary=None):
        self.out_dir = pathlib.Path(out_dir)
        self._summary = summary

    def __repr__(self):
        return f"Run({str(self.out_dir)!r}, status={self.summary.get('status')!r})"

    @property
    def summary(self):
        """summary.json: the script's `summary(...)` entries, status and wall time."""
        if self._summary is None:
            self._summary = json.loads((self.out_dir / "summary.json").read_text())
        return self._summary

    @property
    def provenance(self):
        """provenance.json: program and commit, script and its hash, parameters, plugins."""
        return json.loads((self.out_dir / "provenance.json").read_text())

    @property
    def series(self):
        """series.csv (a DataFrame with pandas, else a numpy structured array)."""
        return self.table("series.csv")

    def table(self, name):
        """Any CSV file of the run (`series_runout.csv`, `final_points.csv`, ...)."""
        return _tables.read_csv(self.out_dir / name)

    def files(self, pattern="*"):
        """The run's files matching a glob pattern, sorted."""
        return sorted(self.out_dir.glob(pattern))

    def frames(self, collection="points"):
        """[(time, path)] of a VTK collection (`points`: material points or spheres, `contacts`),
        from its .pvd file."""
        pvd = self.out_dir / "vtk" / f"{collection}.pvd"
        if pvd.exists():
            root = ElementTree.parse(pvd).getroot()
            return [(float(d.get("timestep")), self.out_dir / "vtk" / d.get("file")) for d in root.iter("DataSet")]
        return [(float("nan"), path) for path in _vtk.frame_files(self.out_dir / "vtk", collection)]

    @property
    def vtk_frames(self):
        """The paths of the material points' or spheres' frames, in order."""
        return [path for _, path in self.frames("points")]

    def points(self, frame=-1):
        """One frame of the material points (MPM) as {name: numpy array}: "position" (n, 3),
        "velocity" (n, 3), "stress" (n, 6: xx, yy, zz, xy, yz, xz, tension positive), ...;
        frame: its index (negative from the end)."""
        return self._frame("points", frame)

    def spheres(self, frame=-1):
        """One frame of a DEM run's spheres as {name: numpy array} ("position", "radius",
        "velocity", ...)."""
        return self._frame("points", frame)

    def contacts(self, frame=-1):
        """One frame of a DEM run's contacts as {name: numpy array}: the forces per contact, and
        "position" with each contact's two ends one after the other."""
        return self._frame("contacts", frame)

    def _frame(self, collection, frame):
        frames = self.frames(collection)
        if not frames:
            raise FileNotFoundError(f"{self.out_dir}: no `{collection}` frames in vtk/ (the script wrote none)")
        try:
            _, path = frames[frame]
        except IndexError:
            raise IndexError(f"frame {frame} of {len(frames)} `{collection}` frames") from None
        return _vtk.read_frame(path)
