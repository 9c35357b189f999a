"""A progress bar of a script's runs while they go on (tqdm: a widget in Jupyter, a line in a
terminal), fed by the native progress probe."""


class Bar:
    """The steps the script's runs have taken so far, their rate and the simulated time; while
    one run call (`run_steps(n)`, `run_until(t)`) takes more than a step, its own share too."""

    def __init__(self, probe, label):
        try:
            from tqdm.auto import tqdm
        except ImportError:  # no tqdm: no bar
            tqdm = None
        self._tqdm = tqdm
        self._probe = probe
        self._label = label
        self._bar = None
        self._calls = 0
        self._before = 0  # steps of the calls finished
        self._last = 0

    def update(self):
        if self._tqdm is None:
            return
        calls, done, total, time = self._probe.read()
        if calls == 0:
            return
        if calls != self._calls:
            self._before += self._last
            self._calls = calls
        self._last = done
        if self._bar is None:
            # Scripts that end within half a second draw nothing.
            self._bar = self._tqdm(desc=self._label, unit="step", delay=0.5, leave=False)
        self._bar.n = self._before + done
        share = f", run {calls}: {done}/{total}" if total > 1 else ""
        self._bar.set_postfix_str(f"t = {time:.4g} s{share}", refresh=False)
        self._bar.refresh()

    def close(self):
        if self._bar is not None:
            self._bar.close()
            self._bar = None
