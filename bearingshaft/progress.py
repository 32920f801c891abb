"""Progress of the stages: the one place bars are made.

On a terminal a computation draws a tqdm bar, redrawn in place. Without one (stderr captured
to a file, a pipe, a batch job's log) a redrawn bar is thousands of carriage-return updates, so
:func:`bar` gives a :class:`LineBar` instead: one line at each tenth of a long computation (one
expected to take ``LONG_S`` or more) and nothing for a short one, whose stage's summary line
says it finished. :func:`run_total` is the line that ends ``bearingshaft run``.
"""

from __future__ import annotations

import resource
import sys
import time

from tqdm import tqdm

LINE_STEPS = 10  # without a terminal: a line at each tenth of a long computation
LONG_S = 20.0  # s, a computation whose elapsed / fraction done reaches this prints those lines


def interactive() -> bool:
    """Whether stderr is a terminal (where a bar can be redrawn in place)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed stream
        return False


class LineBar:
    """The bar without a terminal: ``desc: 30 % after 12 s (about 28 s left)`` at each tenth, once the
    computation is expected to take ``LONG_S`` or more; tqdm's methods the stages use, no redrawing.

    Parameters
    ----------
    iterable : iterable, optional
        Items to iterate over (``total`` is then their number, if they have one).
    total : float, optional
        Steps of the whole computation.
    desc : str
        Label at the start of each line.
    unit : str
        Name of a step (unused in the lines; tqdm's signature).
    """

    def __init__(self, iterable=None, total: float | None = None, desc: str = "", unit: str = "it") -> None:
        self.iterable = iterable
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)
        self.total = total
        self.desc = desc
        self.n = 0.0
        self.postfix = ""
        self.lines = 0  # tenths passed so far
        self.long = False  # expected to take LONG_S or more: its tenths are reported
        self.t0 = time.monotonic()

    def update(self, n: float = 1) -> None:
        """Add ``n`` steps; print the line of each tenth passed, if the computation is long."""
        self.n += n
        if not self.total:
            return
        fraction = min(self.n / self.total, 1.0)
        tenth = int(fraction * LINE_STEPS + 1e-9)
        if tenth <= self.lines:
            return
        self.lines = tenth
        elapsed = time.monotonic() - self.t0
        if not self.long and (fraction <= 0 or elapsed / fraction < LONG_S):
            return
        self.long = True  # once reported, every tenth is: a log that stops mid-way looks like a stall
        left = elapsed * (1.0 / fraction - 1.0)
        more = f" (about {left:.0f} s left)" if tenth < LINE_STEPS else ""
        note = f"; {self.postfix}" if self.postfix else ""
        print(f"{self.desc}: {100 * fraction:.0f} % after {elapsed:.0f} s{more}{note}", file=sys.stderr,
              flush=True)

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        self.postfix = s

    def __iter__(self):
        for item in self.iterable:
            yield item
            self.update(1)

    def close(self) -> None:
        """Nothing to clear: the lines stay."""

    def __enter__(self) -> LineBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def bar(iterable=None, *, total: float | None = None, desc: str = "", enabled: bool = True, unit: str = "it",
        leave: bool = False, bar_format: str | None = None):
    """A progress bar: tqdm on a terminal, a :class:`LineBar` without one, silent when not ``enabled``.

    Parameters
    ----------
    iterable : iterable, optional
        Wrap these items (as ``tqdm(iterable)``).
    total : float, optional
        Steps of the computation.
    desc : str
        Label.
    enabled : bool
        Show progress at all (``--no-progress`` turns it off).
    unit : str
        Name of a step.
    leave : bool
        Keep tqdm's bar on the terminal when done.
    bar_format : str, optional
        tqdm's format (the terminal only).

    Returns
    -------
    tqdm.tqdm or LineBar
        Either offers ``update``, ``set_postfix_str``, ``close`` and iteration.
    """
    if enabled and not interactive():
        return LineBar(iterable, total=total, desc=desc, unit=unit)
    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=not enabled, leave=leave,
                **({"bar_format": bar_format} if bar_format else {}))


class ProgressBar:
    """A progress callback (fraction done, 0 to 1) drawing a bar of 1000 steps (:func:`bar`).

    Parameters
    ----------
    desc : str
        Label drawn before the bar.
    enabled : bool
        Draw it (False: a silent callback).

    Attributes
    ----------
    bar : tqdm.tqdm or LineBar
        The bar, 1000 steps.
    done : int
        Steps drawn so far (a fraction that goes back is ignored).
    """

    BAR_FORMAT = "{l_bar}{bar}| {elapsed}<{remaining}"

    def __init__(self, desc: str, enabled: bool) -> None:
        self.bar = bar(total=1000, desc=desc, enabled=enabled, bar_format=self.BAR_FORMAT)
        self.done = 0

    def __call__(self, fraction: float) -> None:
        new = int(round(1000 * min(max(fraction, 0.0), 1.0)))
        if new > self.done:
            self.bar.update(new - self.done)
            self.done = new

    def close(self) -> None:
        self.bar.close()


class CaseBar(ProgressBar):
    """A bar that names the case being run (long cases otherwise look like a stall).

    Parameters
    ----------
    desc, enabled
        As :class:`ProgressBar`.
    """

    BAR_FORMAT = "{l_bar}{bar}| {elapsed}<{remaining}{postfix}"

    def describe(self, text: str) -> None:
        self.bar.set_postfix_str(text, refresh=False)


def peak_memory_bytes() -> int:
    """Bytes, the largest resident memory this process has had (``getrusage``; Linux reports KiB)."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(rss if sys.platform == "darwin" else rss * 1024)


def run_total(n_stages: int, n_scenes: int, wall_s: float, peak_bytes: int | None = None, workers: str = "") -> str:
    """The line that ends ``bearingshaft run``: stages, scenes, wall time and the peak memory.

    Parameters
    ----------
    n_stages, n_scenes : int
        Stages run, and the scenes they belong to.
    wall_s : float
        s, from the first stage's start to the last one's end.
    peak_bytes : int, optional
        The job's peak memory when it ran on Dask workers (the sum of the workers' peaks); None: this process's.
    workers : str
        Where the stages ran (``LocalCluster(2)``), with ``peak_bytes``.

    Returns
    -------
    str

    Examples
    --------
    >>> run_total(31, 19, 774.0).split(", peak")[0]
    'run: 31 stages of 19 scenes in 774 s (12.9 min)'
    """
    from bearingshaft.digits import human

    minutes = f" ({wall_s / 60:.1f} min)" if wall_s >= 60 else ""
    where = f"{workers}, the sum of the workers' peaks" if peak_bytes is not None else "this process"
    peak = peak_memory_bytes() if peak_bytes is None else peak_bytes
    return (f"run: {n_stages} stage{'s' * (n_stages != 1)} of {n_scenes} scene{'s' * (n_scenes != 1)} in "
            f"{wall_s:.0f} s{minutes}, peak memory {human(peak)} ({where})")
