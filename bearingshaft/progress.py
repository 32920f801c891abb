"""Progress bars of the stages: one tqdm bar per long computation, fed the fraction done."""

from __future__ import annotations

from tqdm import tqdm


class ProgressBar:
    """A progress callback (fraction done, 0 to 1) drawing a tqdm bar of 1000 steps.

    Parameters
    ----------
    desc : str
        Label drawn before the bar.
    enabled : bool
        Draw it (False: a silent callback).

    Attributes
    ----------
    bar : tqdm.tqdm
        The bar, 1000 steps.
    done : int
        Steps drawn so far (a fraction that goes back is ignored).
    """

    def __init__(self, desc: str, enabled: bool) -> None:
        self.bar = tqdm(total=1000, desc=desc, disable=not enabled, leave=False,
                        bar_format="{l_bar}{bar}| {elapsed}<{remaining}")
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

    def __init__(self, desc: str, enabled: bool) -> None:
        super().__init__(desc, enabled)
        self.bar.bar_format = "{l_bar}{bar}| {elapsed}<{remaining}{postfix}"

    def describe(self, text: str) -> None:
        self.bar.set_postfix_str(text, refresh=False)
