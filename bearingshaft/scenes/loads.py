"""The [[load]] tables: forces at named points (half-sine blows, harmonic shakers, tabulated
measured forces), turned into the time functions of :mod:`reduced.models.loads`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from bearingshaft.scenes.convert import from_table
from bearingshaft.scenes.errors import SceneError, show, suggest
from reduced.models.loads import HalfSine, Harmonic, LoadError, Tabulated

LOAD_DIRECTIONS = ("gap",)  # the models here move only along their gaps' direction


@dataclass(frozen=True, slots=True)
class HalfSineLoadSpec:
    """A hammer blow: peak_N sin(pi (t - start_s) / duration_s) on [start_s, start_s + duration_s].

    Parameters
    ----------
    kind : str
        "half_sine".
    point : str
        The model's point it acts at.
    direction : str
        "gap", the only direction of these models.
    peak_N : float
        N, peak force.
    duration_s : float
        s, length of the half-sine.
    start_s : float
        s, start of the blow.
    """

    kind: str = "half_sine"  # the kind of load
    point: str = "x2"  # where it acts (the model's point names)
    direction: str = "gap"  # the gap direction (the only one these models have)
    peak_N: float = 0.0  # N, peak force
    duration_s: float = 1e-3  # s, length of the half-sine
    start_s: float = 0.0  # s, start of the blow

    def signal(self, base: Path | None = None) -> HalfSine:
        return HalfSine(self.peak_N, self.duration_s, self.start_s)


@dataclass(frozen=True, slots=True)
class HarmonicLoadSpec:
    """A shaker: amplitude_N cos(2 pi freq_hz (t - start_s) + phase_deg) from start_s on.

    Parameters
    ----------
    kind : str
        "harmonic".
    point : str
        The model's point it acts at.
    direction : str
        "gap".
    amplitude_N : float
        N.
    freq_hz : float
        Hz.
    phase_deg : float
        degrees.
    start_s : float
        s, when the shaker starts.
    """

    kind: str = "harmonic"  # the kind of load
    point: str = "x2"  # where it acts (the model's point names)
    direction: str = "gap"  # the gap direction (the only one these models have)
    amplitude_N: float = 0.0  # N, force amplitude
    freq_hz: float = 100.0  # Hz, frequency
    phase_deg: float = 0.0  # degrees, phase at start_s
    start_s: float = 0.0  # s, when the shaker starts

    def signal(self, base: Path | None = None) -> Harmonic:
        return Harmonic(self.amplitude_N, self.freq_hz, self.phase_deg, self.start_s)


@dataclass(frozen=True, slots=True)
class TabulatedLoadSpec:
    """A measured force: CSV (time [s], force [N]) or UFF 58, piecewise linear, zero outside.

    Parameters
    ----------
    kind : str
        "tabulated".
    point : str
        The model's point it acts at.
    direction : str
        "gap".
    file : str
        CSV (time [s], force [N]) or UFF 58 file, path from the scene file's folder.
    start_s : float
        s, added to the file's times.
    """

    kind: str = "tabulated"  # the kind of load
    point: str = "x2"  # where it acts (the model's point names)
    direction: str = "gap"  # the gap direction (the only one these models have)
    file: str = ""  # CSV (time [s], force [N]) or UFF 58 file of the force history
    start_s: float = 0.0  # s, added to the file's times

    def signal(self, base: Path | None = None) -> Tabulated:
        if not self.file:
            raise LoadError("file must name a CSV or UFF 58 file of the force history")
        sig = Tabulated.from_file(self.file)
        if self.start_s:
            sig = Tabulated(sig.t_s + self.start_s, sig.force_N, source=sig.source)
        return sig


LOAD_KINDS: dict[str, type] = {"half_sine": HalfSineLoadSpec, "harmonic": HarmonicLoadSpec,
                               "tabulated": TabulatedLoadSpec}
LoadSpec = HalfSineLoadSpec | HarmonicLoadSpec | TabulatedLoadSpec
MAX_LOADS = 64  # loads in one scene


def parse_loads(value, where: str, point_names: tuple[str, ...], base: str | Path | None = None
                ) -> tuple[tuple, tuple]:
    """([[load]] specs, their signals), every key checked; ``where`` names the file.

    Parameters
    ----------
    value : object
        The scene's ``load`` value (an array of tables).
    where : str
        The scene file, for the messages.
    point_names : tuple of str
        The model's points.
    base : str or Path, optional
        The folder a tabulated load's ``file`` is relative to (the scene file's; None: the working directory).

    Returns
    -------
    specs : tuple
        One HalfSineLoadSpec, HarmonicLoadSpec or TabulatedLoadSpec per table.
    signals : tuple
        Their time functions (:mod:`reduced.models.loads`).

    Raises
    ------
    SceneError
        Not an array of tables, an empty one, more than ``MAX_LOADS``, an unknown kind, key, point
        or direction, or a load :mod:`reduced.models.loads` refuses.
    """
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise SceneError(f"{where} load: expected an array of tables ([[load]]), got {show(value)}")
    if not value:
        raise SceneError(f"{where} load: the array is empty; give at least one [[load]] or none")
    if len(value) > MAX_LOADS:
        raise SceneError(f"{where} load: {len(value)} loads is too many (at most {MAX_LOADS})")
    specs, signals = [], []
    for i, table in enumerate(value):
        at = f"{where} [[load]] {i + 1}"
        kind = table.get("kind")
        if not isinstance(kind, str):
            raise SceneError(f"{at} kind: expected a string (one of {', '.join(LOAD_KINDS)}), got {show(kind)}")
        if kind not in LOAD_KINDS:
            raise SceneError(f"{at} kind: unknown load {show(kind)}{suggest(kind, LOAD_KINDS)} "
                             f"(known: {', '.join(LOAD_KINDS)})")
        spec = from_table(LOAD_KINDS[kind], table, f"{at} ({kind})", base)
        if spec.point not in point_names:
            raise SceneError(f"{at} point: unknown point {spec.point!r}{suggest(spec.point, point_names)} "
                             f"(known: {', '.join(point_names)})")
        if spec.direction not in LOAD_DIRECTIONS:
            raise SceneError(f"{at} direction: {spec.direction!r} is not a direction of this model "
                             f"(known: {', '.join(LOAD_DIRECTIONS)})")
        try:
            signal = spec.signal()
        except LoadError as exc:
            text = str(exc)
            prefix = "file: " if kind == "tabulated" and not text.startswith("file") else ""
            raise SceneError(f"{at} {prefix}{text}") from None
        specs.append(spec)
        signals.append(signal)
    return tuple(specs), tuple(signals)

