"""Scenes: TOML cases turned into frozen dataclasses, in this one place.

A scene names a model and the stages to run on it; a table present in the file is a stage
to run, a table absent is a stage skipped (and so never built). Layout::

    name = "discrete-impulse"          # optional, defaults to the file name
    description = "..."
    [model]          kind = "discrete" (DiscreteParams), "rom" (reduced.models.rom.RomSpec: the 3-D
                     model reduced to its tips) or "assembly" (fem.model.AssemblyModel)
    [initial]        x0_m, v0_m_s at the points x1, x2, x3
    [[load]]         external forces (half_sine, harmonic, tabulated) at named points: a
                     ringdown with loads is a forced transient (reduced.models.loads)
    [ringdown]       integrator and run length                      -> stage ringdown
    [spectrogram]    STFT of one DOF with the NNM curves overlaid  (with ringdown)
    [symmetry]       |x_a - x_b| against time                      (with ringdown)
    [nnm]            frequency-energy relations                     -> stage nnm
    [fep]            HB / shooting backbones and stability (issue 3)   -> stage nnm
    [work_precision] error against run time                         -> stage study
    [stiff_cases]    stiff and extreme parameter sweep              -> stage study
    [rom_convergence] reduced model against its mode count          -> stage study (kind "rom")
    [verify]         reduction against the discrete model           -> stage verify (kind "rom")
    [frc]            forced-response curves by HB, stepped sine, stability (issue 11) -> stage frc
    [hammer]         the virtual hammer test of the apparatus, channel for channel (issue 12)
                     -> stage hammer (kind "rom", layout "assembly"; uses [ringdown] for the
                     integrator and record, [spectrogram] for Fig. 11 with dof = a channel)

Unknown keys, wrong types and invalid values raise :class:`SceneError` with a one-line
message naming the table and key.
"""

from __future__ import annotations

import difflib
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path

from reduced.models.discrete import DiscreteParams
from reduced.models.loads import HalfSine, Harmonic, LoadError, Tabulated
from reduced.models.rom import RomSpec
from reduced.transient.integrate import METHODS


class SceneError(ValueError):
    """A scene that cannot be read or is invalid; the message is one line."""


MAX_COUNT = 100_000  # largest count (energies, orbits, repeats, modes) a scene may ask for
MAX_MAGNITUDE = 1e100  # no SI quantity here comes near; squares of larger values (energies) overflow


def suggest(word: str, known) -> str:
    """' (did you mean X?)' for the closest of ``known`` to a misspelled ``word``, else ''."""
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _show(value) -> str:
    """A value as the user wrote it, cut short: messages stay one line."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise ValueError(msg)


def _positive(obj, *names: str) -> None:
    for name in names:
        v = getattr(obj, name)
        _check(v is not None and v > 0 and math.isfinite(v), f"{name} must be > 0, got {v!r}")


def _each(obj, name: str, ok, allowed: str) -> None:
    """Every value of the tuple field ``name`` satisfies ``ok``; else name the first that does not."""
    for i, v in enumerate(getattr(obj, name)):
        _check(ok(v), f"{name}[{i}] must be {allowed}, got {v!r}")


def _tolerance(obj, *names: str) -> None:
    """Relative tolerances lie in (0, 1): at rtol >= 1 a solver controls no digit."""
    for name in names:
        v = getattr(obj, name)
        _check(0.0 < v < 1.0, f"{name} must be in (0, 1), got {v!r}")


MAX_HARMONICS = 1000  # HB orders beyond this resolve nothing a 20 kHz ringdown shows
EXPLICIT_OMEGA_DT_MAX = 1.6  # rad: 0.8 x the central-difference limit omega dt = 2 (reduced.transient.explicit)


@dataclass(frozen=True, slots=True)
class InitialSpec:
    """Initial state of the ringdown at the points x1, x2, x3 (see :mod:`reduced.models.initial`).

    For the discrete model the points are its DOFs. A reduced model takes the point values
    in its lowest three open-gap modes (heave, pitch, first bending), as the discrete model.
    """

    x0_m: tuple[float, ...] = (0.0, 0.0, 0.0)  # m, displacement of each point
    v0_m_s: tuple[float, ...] = (0.0, 0.0, 0.0)  # m/s, velocity of each point


LOAD_DIRECTIONS = ("gap",)  # the models here move only along their gaps' direction


@dataclass(frozen=True, slots=True)
class HalfSineLoadSpec:
    """A hammer blow: peak_N sin(pi (t - start_s) / duration_s) on [start_s, start_s + duration_s]."""

    kind: str = "half_sine"
    point: str = "x2"  # where it acts (the model's point names)
    direction: str = "gap"  # the gap direction (the only one these models have)
    peak_N: float = 0.0  # N
    duration_s: float = 1e-3  # s
    start_s: float = 0.0  # s

    def signal(self, base: Path | None = None) -> HalfSine:
        return HalfSine(self.peak_N, self.duration_s, self.start_s)


@dataclass(frozen=True, slots=True)
class HarmonicLoadSpec:
    """A shaker: amplitude_N cos(2 pi freq_hz (t - start_s) + phase_deg) from start_s on."""

    kind: str = "harmonic"
    point: str = "x2"
    direction: str = "gap"
    amplitude_N: float = 0.0  # N
    freq_hz: float = 100.0  # Hz
    phase_deg: float = 0.0  # degrees
    start_s: float = 0.0  # s

    def signal(self, base: Path | None = None) -> Harmonic:
        return Harmonic(self.amplitude_N, self.freq_hz, self.phase_deg, self.start_s)


@dataclass(frozen=True, slots=True)
class TabulatedLoadSpec:
    """A measured force: CSV (time [s], force [N]) or UFF 58, piecewise linear, zero outside."""

    kind: str = "tabulated"
    point: str = "x2"
    direction: str = "gap"
    file: str = ""  # path from the working directory
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


def parse_loads(value, where: str, point_names: tuple[str, ...]) -> tuple[tuple, tuple]:
    """([[load]] specs, their signals), every key checked; ``where`` names the file."""
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise SceneError(f"{where} load: expected an array of tables ([[load]]), got {_show(value)}")
    if not value:
        raise SceneError(f"{where} load: the array is empty; give at least one [[load]] or none")
    if len(value) > MAX_LOADS:
        raise SceneError(f"{where} load: {len(value)} loads is too many (at most {MAX_LOADS})")
    specs, signals = [], []
    for i, table in enumerate(value):
        at = f"{where} [[load]] {i + 1}"
        kind = table.get("kind")
        if not isinstance(kind, str):
            raise SceneError(f"{at} kind: expected a string (one of {', '.join(LOAD_KINDS)}), got {_show(kind)}")
        if kind not in LOAD_KINDS:
            raise SceneError(f"{at} kind: unknown load {_show(kind)}{suggest(kind, LOAD_KINDS)} "
                             f"(known: {', '.join(LOAD_KINDS)})")
        spec = from_table(LOAD_KINDS[kind], table, f"{at} ({kind})")
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


@dataclass(frozen=True, slots=True)
class RingdownSpec:
    """Free response from the initial state."""

    method: str = "exact"  # exact | explicit | dop853
    duration_s: float = 2.0  # s
    sample_rate_hz: float = 20000.0  # Hz, output sampling
    dt_s: float | None = None  # s, explicit step (default: omega_dt / omega_max)
    omega_dt: float = 0.05  # rad, explicit step: omega_ref dt
    step_basis: str = "top"  # omega_ref: "top" closed-gap frequency, or "contact" (the three lowest
    # modes that move the gaps, as the discrete model has; top mode capped at omega_max dt = 1)
    rtol: float = 1e-10  # dop853 relative tolerance
    atol: float | None = None  # m, dop853 absolute tolerance (default rtol x gap)

    def __post_init__(self) -> None:
        _check(self.method in METHODS, f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        _positive(self, "duration_s", "sample_rate_hz", "omega_dt", "rtol")
        _tolerance(self, "rtol")
        _check(self.omega_dt <= EXPLICIT_OMEGA_DT_MAX, f"omega_dt must be <= {EXPLICIT_OMEGA_DT_MAX} "
               f"(central difference is unstable past omega dt = 2), got {self.omega_dt!r}")
        _check(self.step_basis in ("top", "contact"), f"step_basis must be top or contact, got {self.step_basis!r}")
        if self.dt_s is not None:
            _positive(self, "dt_s")
        if self.atol is not None:
            _positive(self, "atol")


@dataclass(frozen=True, slots=True)
class SpectrogramSpec:
    """Short-time Fourier transform (Hann window) of one DOF."""

    dof: str = "x1"  # which DOF to transform
    window_s: float = 0.05  # s, Hann window length
    overlap: float = 0.9  # fraction of the window shared by neighbouring frames
    fmax_hz: float = 1500.0  # Hz, top of the plot
    db_range: float = 120.0  # dB shown below the peak

    def __post_init__(self) -> None:
        _positive(self, "window_s", "fmax_hz", "db_range")
        _check(0.0 <= self.overlap < 1.0, f"overlap must be in [0, 1), got {self.overlap!r}")


@dataclass(frozen=True, slots=True)
class SymmetrySpec:
    """Symmetry-breaking plot: |x_a - x_b| against time (Fig. 4)."""

    dofs: tuple[str, ...] = ("x1", "x3")  # the pair that a symmetric motion keeps equal
    methods: tuple[str, ...] = ("exact", "explicit", "dop853")  # integrators compared

    def __post_init__(self) -> None:
        _check(len(self.dofs) == 2, f"dofs must name two DOFs, got {self.dofs!r}")
        _check(self.dofs[0] != self.dofs[1], f"dofs must name two different DOFs, got {self.dofs!r}")
        _each(self, "methods", lambda m: m in METHODS, f"one of {', '.join(METHODS)}")


@dataclass(frozen=True, slots=True)
class NNMSpec:
    """Frequency-energy relations of the nonlinear normal modes."""

    n_energy: int = 400  # number of energies, log-spaced
    energy_min_J: float = 1e-4  # J
    energy_max_J: float = 1e5  # J

    def __post_init__(self) -> None:
        _check(self.n_energy >= 2, f"n_energy must be >= 2, got {self.n_energy!r}")
        _positive(self, "energy_min_J", "energy_max_J")
        _check(self.energy_max_J > self.energy_min_J, "energy_max_J must exceed energy_min_J")


@dataclass(frozen=True, slots=True)
class FEPSpec:
    """Frequency-energy plots by HB, shooting and their stability (issue 3) -> stage nnm."""

    harmonics: tuple[int, ...] = (1, 15)  # HB orders drawn in fep.png (1: the paper's Fig. 2)
    convergence_harmonics: tuple[int, ...] = (1, 3, 5, 9, 15, 25, 50)  # hb_convergence study
    samples_study_harmonics: int = 15  # H at which the AFT sample count N is varied
    samples: tuple[int, ...] = (32, 64, 128, 256, 512, 1024, 2048)  # N values of that study
    energy_max_J: float = 1e5  # J, every branch runs at least this far
    n_shooting: int = 60  # shooting orbits per NNM (log-spaced in energy)

    def __post_init__(self) -> None:
        _each(self, "harmonics", lambda h: 1 <= h <= MAX_HARMONICS, f"in [1, {MAX_HARMONICS}]")
        _each(self, "convergence_harmonics", lambda h: 1 <= h <= MAX_HARMONICS, f"in [1, {MAX_HARMONICS}]")
        _check(1 <= self.samples_study_harmonics <= MAX_HARMONICS,
               f"samples_study_harmonics must be in [1, {MAX_HARMONICS}], got {self.samples_study_harmonics!r}")
        _each(self, "samples", lambda n: n > 2 * self.samples_study_harmonics,
              f"> 2 x samples_study_harmonics = {2 * self.samples_study_harmonics} (AFT sampling theorem)")
        _positive(self, "energy_max_J")
        _check(self.n_shooting >= 2, f"n_shooting must be >= 2, got {self.n_shooting!r}")


@dataclass(frozen=True, slots=True)
class WorkPrecisionSpec:
    """Error against run time of the three integrators over a short window."""

    window_s: float = 0.05  # s, before chaotic divergence dominates
    sample_rate_hz: float = 20000.0  # Hz, grid on which errors are measured
    explicit_omega_dt: tuple[float, ...] = (0.8, 0.4, 0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625, 0.003125)
    dop853_rtol: tuple[float, ...] = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-13)
    repeats: int = 3  # best-of timing

    def __post_init__(self) -> None:
        _positive(self, "window_s", "sample_rate_hz")
        _check(len(self.explicit_omega_dt) >= 3, "explicit_omega_dt needs >= 3 values to fit an order")
        _each(self, "explicit_omega_dt", lambda v: 0 < v <= EXPLICIT_OMEGA_DT_MAX,
              f"in (0, {EXPLICIT_OMEGA_DT_MAX}] (central difference is unstable past omega dt = 2)")
        _each(self, "dop853_rtol", lambda v: 0 < v < 1, "in (0, 1)")
        _check(self.repeats >= 1, f"repeats must be >= 1, got {self.repeats!r}")


@dataclass(frozen=True, slots=True)
class StiffCasesSpec:
    """Sweep over stiff and extreme parameters (every combination is run)."""

    k_g: tuple[float, ...] = (3.502e7, 1e9, 1e11)  # N/m
    gap: tuple[float, ...] = (0.0, 2.54e-4, 1e-2)  # m
    speed: tuple[float, ...] = (0.01, 200.0, 2000.0)  # m/s, initial velocity of mass 3
    c: tuple[float, ...] = (0.0, 4.0, 400.0)  # N s/m
    duration_s: float = 0.2  # s
    sample_rate_hz: float = 5000.0  # Hz
    methods: tuple[str, ...] = ("exact", "explicit")
    long_duration_s: float = 0.0  # s, also run the nominal case (first k_g, Table-1 gap, 200 m/s) this long
    # for every c (0: no long runs)

    def __post_init__(self) -> None:
        _positive(self, "duration_s", "sample_rate_hz")
        _each(self, "k_g", lambda v: v > 0, "> 0 N/m")
        _each(self, "gap", lambda v: v >= 0, ">= 0 m")
        _each(self, "c", lambda v: v >= 0, ">= 0 N s/m")
        _each(self, "speed", lambda v: v != 0, "nonzero m/s (a run from rest has nothing to show)")
        _check(self.long_duration_s >= 0, f"long_duration_s must be >= 0, got {self.long_duration_s!r}")
        _each(self, "methods", lambda m: m in METHODS, f"one of {', '.join(METHODS)}")


@dataclass(frozen=True, slots=True)
class ModalSpec:
    """Modal analysis of a 3-D model (kind = "assembly"): correlation, MAC, pictures."""

    n_modes: int = 20  # modes computed, rigid-body ones included
    shift_hz: float = 1.0  # Hz, the shift is sigma = -(2 pi shift_hz)^2 (K - sigma M > 0)
    solver: str = "pardiso"  # pardiso | superlu (falls back to superlu without pypardiso)
    test_shapes: str = ""  # UFF (dataset 55) or CSV file of test mode shapes; "" -> FE auto-MAC
    pictures: bool = True  # mode-shape pictures rendered with pyvista off screen
    vtu: bool = True  # modes.vtu of the labelled modes for ParaView

    def __post_init__(self) -> None:
        _check(self.n_modes >= 12, f"n_modes must be >= 12 (6 rigid + 6 pseudo-rigid), got {self.n_modes!r}")
        _positive(self, "shift_hz")
        _check(self.solver in ("pardiso", "superlu"), f"solver must be pardiso or superlu, got {self.solver!r}")


@dataclass(frozen=True, slots=True)
class RomConvergenceSpec:
    """Reduced model against its number of fixed-interface modes (kind = "rom")."""

    modes: tuple[int, ...] = (1, 2, 5, 10, 20, 50)  # fixed-interface modes; the largest is the reference
    window_s: float = 0.05  # s, ringdown window over which the error is measured
    sample_rate_hz: float = 20000.0  # Hz, grid on which errors are measured
    n_compare: int = 4  # contact-coupled frequencies compared (open and closed gap)
    repeats: int = 3  # best-of timing

    def __post_init__(self) -> None:
        _check(len(self.modes) >= 2, f"modes needs >= 2 counts, got {self.modes!r}")
        _each(self, "modes", lambda m: m >= 0, ">= 0")
        _positive(self, "window_s", "sample_rate_hz")
        _check(self.n_compare >= 1, f"n_compare must be >= 1, got {self.n_compare!r}")
        _check(self.repeats >= 1, f"repeats must be >= 1, got {self.repeats!r}")


@dataclass(frozen=True, slots=True)
class VerifySpec:
    """Reduction against the discrete model: identified parameters, frequencies, NNMs, ringdowns."""

    duration_s: float = 2.0  # s, ringdown of each of the paper's three initial conditions
    sample_rate_hz: float = 20000.0  # Hz
    method: str = "exact"  # ringdown integrator
    energy_max_J: float = 1e5  # J, NNM backbones (HB, H = 1) up to this energy
    window_s: float = 0.05  # s, spectrogram window
    fmax_hz: float = 1500.0  # Hz, top of the spectrograms

    def __post_init__(self) -> None:
        _check(self.method in METHODS, f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        _positive(self, "duration_s", "sample_rate_hz", "energy_max_J", "window_s", "fmax_hz")


@dataclass(frozen=True, slots=True)
class FRCSpec:
    """Forced-response curves by HB under a harmonic load at one point, verified by a stepped
    sine of the exact integrator (issue 11) -> stage frc (reduced.periodic.frc)."""

    point: str = "x2"  # where the load P cos(2 pi f t) acts (a point name)
    levels_N: tuple[float, ...] = (0.1, 1.0, 10.0)  # N, load amplitudes P: one curve each
    freq_min_hz: float = 10.0  # Hz, each curve starts here (from rest at the lowest level)
    freq_max_hz: float = 900.0  # Hz, and ends where it leaves the band
    harmonics: int = 15  # H of the curves in frc.csv and frc.png
    odd_harmonics: bool = True  # odd harmonics only (a half-wave symmetric response; stability sees all)
    convergence_harmonics: tuple[int, ...] = (1, 3, 5, 9, 15, 21, 25, 31)  # H of the error-against-H study
    convergence_level_N: float = 1.0  # N, the level of that study
    max_steps: int = 3000  # continuation steps per curve at most
    hill_points: int = 40  # Hill's method on at most this many points per curve (0: none)
    shooting_points: int = 12  # Floquet multipliers by shooting on the exact flow, points per curve (0: none)
    shooting_segments: int = 8  # segments of the multiple shooting
    stepped_sine_points: int = 24  # frequencies per level, each swept up and down (0: no stepped sine)
    stepped_sine_tol: float = 1e-6  # settled when the predicted distance to the periodic orbit is below this
    stepped_sine_max_s: float = 10.0  # s, simulated time per frequency at most before "not settled"
    backbone_scales: tuple[float, ...] = (1.0, 0.1, 0.01)  # damping and load scaled together (backbone check)

    def __post_init__(self) -> None:
        _each(self, "levels_N", lambda v: v > 0, "> 0 N")
        _positive(self, "freq_min_hz", "freq_max_hz", "convergence_level_N", "stepped_sine_max_s")
        _check(self.freq_max_hz > self.freq_min_hz,
               f"freq_max_hz must exceed freq_min_hz = {self.freq_min_hz!r} Hz, got {self.freq_max_hz!r}")
        _check(1 <= self.harmonics <= MAX_HARMONICS,
               f"harmonics must be in [1, {MAX_HARMONICS}], got {self.harmonics!r}")
        _each(self, "convergence_harmonics", lambda h: 1 <= h <= MAX_HARMONICS, f"in [1, {MAX_HARMONICS}]")
        if self.odd_harmonics:
            _check(self.harmonics % 2 == 1, f"harmonics must be odd with odd_harmonics = true, got {self.harmonics!r}")
            _each(self, "convergence_harmonics", lambda h: h % 2 == 1, "odd with odd_harmonics = true")
        _check(self.max_steps >= 1, f"max_steps must be >= 1, got {self.max_steps!r}")
        _check(self.hill_points >= 0, f"hill_points must be >= 0, got {self.hill_points!r}")
        _check(self.shooting_points >= 0, f"shooting_points must be >= 0, got {self.shooting_points!r}")
        _check(self.shooting_segments >= 1, f"shooting_segments must be >= 1, got {self.shooting_segments!r}")
        _check(self.stepped_sine_points >= 0, f"stepped_sine_points must be >= 0, got {self.stepped_sine_points!r}")
        _tolerance(self, "stepped_sine_tol")
        _each(self, "backbone_scales", lambda v: 0 < v <= 1, "in (0, 1] (damping and load scaled down together)")


@dataclass(frozen=True, slots=True)
class HammerSpec:
    """A hammer blow on the beam of the reduced apparatus, recorded on every rig channel
    (issue 12) -> stage hammer (reduced.models.rig). The record's length, sampling and
    integrator are [ringdown]'s."""

    location_m: tuple[float, ...] = ()  # m, point struck (default: the beam's top face at mid-span,
    # under the tube's hole)
    direction: tuple[float, ...] = (0.0, 0.0, -1.0)  # the blow's direction (default: straight down)
    peak_N: float = 500.0  # N, the nominal blow: hammer.npz, hammer.uff, fig10.png, fig11.png
    duration_s: float = 1e-3  # s, length of the half-sine
    start_s: float = 0.01  # s, pre-trigger: the blow starts here
    levels_N: tuple[float, ...] = (20.0, 100.0, 200.0, 500.0, 1000.0, 2000.0)  # N, the level sweep
    force_file: str = ""  # a measured force history (CSV t_s,force_N or UFF 58) instead of the half-sine
    seismic_mass_kg: float = 0.04  # kg, tip assembly above each load cell's gauge (fem.rig)
    load_cell: str = "tip_left_top"  # the load cell of fig10.png
    compare: tuple[str, ...] = ()  # channels compared with a measured test (default: all but the hammer)
    compare_window_s: tuple[float, ...] = ()  # s, (start, end) of the error measures (default: the record)
    linear_check: bool = False  # the open-gap response against the full 3-D model's modal superposition
    linear_check_max_hz: float = 20000.0  # Hz, full-model modes up to this in that reference
    backbone_modes: int = 3  # NNM backbones overlaid on fig11.png (0: none)

    def __post_init__(self) -> None:
        from fem.rig import TIP_CELLS

        if self.location_m:
            _check(len(self.location_m) == 3, f"location_m must be 3 numbers (x, y, z), got {self.location_m!r}")
        _check(len(self.direction) == 3, f"direction must be 3 numbers, got {self.direction!r}")
        _check(any(d != 0 for d in self.direction), "direction must not be the zero vector")
        _positive(self, "peak_N", "duration_s", "linear_check_max_hz")
        _check(self.start_s >= 0, f"start_s must be >= 0, got {self.start_s!r}")
        _each(self, "levels_N", lambda v: v > 0, "> 0 N")
        _check(self.seismic_mass_kg >= 0, f"seismic_mass_kg must be >= 0, got {self.seismic_mass_kg!r}")
        _check(self.load_cell in TIP_CELLS, f"load_cell must be one of {', '.join(TIP_CELLS)}, got {self.load_cell!r}")
        if self.force_file:
            _check(Path(self.force_file).is_file(), f"force_file: no such file {self.force_file!r}")
        if self.compare_window_s:
            w = self.compare_window_s
            _check(len(w) == 2 and 0 <= w[0] < w[1], f"compare_window_s must be (start, end), 0 <= start < end, "
                   f"got {w!r}")
        _check(self.backbone_modes >= 0, f"backbone_modes must be >= 0, got {self.backbone_modes!r}")


def _assembly_model():
    from fem.model import AssemblyModel  # imported only for 3-D scenes: no scikit-fem otherwise

    return AssemblyModel


MODEL_KINDS: dict[str, object] = {"discrete": DiscreteParams, "assembly": _assembly_model, "rom": RomSpec}


def model_class(kind: str) -> type:
    entry = MODEL_KINDS[kind]
    return entry if isinstance(entry, type) else entry()

SECTIONS: dict[str, type] = {
    "modal": ModalSpec,
    "initial": InitialSpec,
    "ringdown": RingdownSpec,
    "spectrogram": SpectrogramSpec,
    "symmetry": SymmetrySpec,
    "nnm": NNMSpec,
    "fep": FEPSpec,
    "work_precision": WorkPrecisionSpec,
    "stiff_cases": StiffCasesSpec,
    "rom_convergence": RomConvergenceSpec,
    "verify": VerifySpec,
    "frc": FRCSpec,
    "hammer": HammerSpec,
}

STAGES = ("modal", "reduce", "ringdown", "hammer", "nnm", "study", "verify", "frc")


@dataclass(frozen=True, slots=True)
class Scene:
    """One case: a model and the stages to run on it."""

    name: str
    description: str
    model_kind: str
    model: object  # DiscreteParams | RomSpec | fem.model.AssemblyModel
    source: str = field(repr=False)  # the TOML text as read, kept with every result
    origin: str = field(default="", repr=False)  # where it was read from, for messages
    initial: InitialSpec = InitialSpec()
    loads: tuple = ()  # [[load]] specs (HalfSineLoadSpec | HarmonicLoadSpec | TabulatedLoadSpec)
    load_signals: tuple = field(default=(), repr=False)  # their time functions (reduced.models.loads)
    modal: ModalSpec | None = None
    ringdown: RingdownSpec | None = None
    spectrogram: SpectrogramSpec | None = None
    symmetry: SymmetrySpec | None = None
    nnm: NNMSpec | None = None
    fep: FEPSpec | None = None
    work_precision: WorkPrecisionSpec | None = None
    stiff_cases: StiffCasesSpec | None = None
    rom_convergence: RomConvergenceSpec | None = None
    verify: VerifySpec | None = None
    frc: FRCSpec | None = None
    hammer: HammerSpec | None = None
    sweep: object | None = None  # [sweep]: bearingshaft.sweep.SweepSpec (issue 13); run by `bearingshaft sweep`

    @property
    def stages(self) -> tuple[str, ...]:
        """The pipeline stages this scene asks for, in pipeline order."""
        wanted = {
            "modal": self.modal is not None,
            "reduce": self.model_kind == "rom",
            "ringdown": self.ringdown is not None and self.hammer is None,  # [hammer] records its own
            "hammer": self.hammer is not None,
            "nnm": self.nnm is not None or self.fep is not None,
            "study": self.work_precision is not None or self.stiff_cases is not None
            or self.rom_convergence is not None,
            "verify": self.verify is not None,
            "frc": self.frc is not None,
        }
        return tuple(s for s in STAGES if wanted[s])


# -- conversion --------------------------------------------------------------------------
def _coerce(value, typ, where: str):
    origin = typing.get_origin(typ)
    if origin in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(typ) if a is not type(None)]
        return _coerce(value, args[0], where)
    if origin is tuple:
        (inner, _) = typing.get_args(typ)
        if not isinstance(value, list):
            raise SceneError(f"{where}: expected a list, got {_show(value)}")
        if not value:
            raise SceneError(f"{where}: the list is empty; give at least one value")
        if len(value) > MAX_COUNT:
            raise SceneError(f"{where}: {len(value)} values is too many (at most {MAX_COUNT})")
        return tuple(_coerce(v, inner, f"{where}[{i}]") for i, v in enumerate(value))
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{where}: expected a number, got {_show(value)}")
        if isinstance(value, float) and not math.isfinite(value):
            raise SceneError(f"{where}: must be finite, got {_show(value)}")
        if abs(value) > MAX_MAGNITUDE:
            raise SceneError(f"{where}: {value!r} is out of range (|value| <= {MAX_MAGNITUDE:g})")
        return float(value)
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"{where}: expected an integer, got {_show(value)}")
        if abs(value) > MAX_COUNT:
            raise SceneError(f"{where}: {value} is too large (at most {MAX_COUNT})")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise SceneError(f"{where}: expected a string, got {_show(value)}")
        return value
    if typ is bool:
        if not isinstance(value, bool):
            raise SceneError(f"{where}: expected true or false, got {_show(value)}")
        return value
    raise TypeError(f"unsupported field type {typ!r} at {where}")  # a bug, not bad input


def from_table(cls: type, table: dict, where: str):
    """Build dataclass ``cls`` from a TOML table, naming ``where`` in every error."""
    if not isinstance(table, dict):
        raise SceneError(f"{where}: expected a table, got {_show(table)}")
    hints = typing.get_type_hints(cls)
    known = [f.name for f in fields(cls)]
    for key in table:
        if key not in known:
            raise SceneError(f"{where}: unknown key {key!r}{suggest(key, known)} (known: {', '.join(known)})")
    kwargs = {k: _coerce(v, hints[k], f"{where} {k}") for k, v in table.items()}
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:
        raise SceneError(f"{where}: {exc}") from None


def parse_scene(text: str, default_name: str, origin: str) -> Scene:
    """A :class:`Scene` from TOML text; ``origin`` names the file in error messages."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: invalid TOML: {exc}") from None
    top = {"name", "description", "model", "load", "sweep", *SECTIONS}
    for key in data:
        if key not in top:
            raise SceneError(f"{origin}: unknown key {key!r}{suggest(key, top)} (known: {', '.join(sorted(top))})")
    name = data.get("name", default_name)
    description = data.get("description", "")
    if not isinstance(name, str) or not name or "/" in name or name.startswith(".") or len(name) > 200:
        raise SceneError(f"{origin}: name must be a non-empty string without '/' or a leading '.', "
                         f"got {_show(name)}")
    if not isinstance(description, str):
        raise SceneError(f"{origin}: description must be a string, got {_show(description)}")
    model_table = data.get("model", {})
    if not isinstance(model_table, dict):
        raise SceneError(f"{origin} [model]: expected a table, got {_show(model_table)}")
    model_table = dict(model_table)
    kind = model_table.pop("kind", "discrete")
    if not isinstance(kind, str):
        raise SceneError(f"{origin} [model] kind: expected a string (one of {', '.join(MODEL_KINDS)}), "
                         f"got {_show(kind)}")
    if kind not in MODEL_KINDS:
        raise SceneError(f"{origin} [model] kind: unknown model {_show(kind)}{suggest(kind, MODEL_KINDS)} "
                         f"(known: {', '.join(MODEL_KINDS)})")
    try:
        model = from_table(model_class(kind), model_table, f"{origin} [model]")
    except SceneError as exc:
        if "kind" in data.get("model", {}):
            raise
        raise SceneError(f"{exc}; [model] kind is not given, so {kind!r} is assumed") from None
    sections = {
        key: from_table(cls, data[key], f"{origin} [{key}]") for key, cls in SECTIONS.items() if key in data
    }
    if "sweep" in data:  # issue 13: the table is read by bearingshaft.sweep, its cases checked by `sweep`
        from bearingshaft.sweep import parse_sweep_table

        sections["sweep"] = parse_sweep_table(data["sweep"], origin)
    if not hasattr(model, "system"):  # a 3-D model: only [modal] applies
        other = [k for k in sections if k not in ("modal", "sweep")] + (["[load]"] if "load" in data else [])
        if other:
            raise SceneError(f"{origin}: model kind {kind!r} takes only a [modal] table, got [{other[0]}]")
        return Scene(name=name, description=description, model_kind=kind, model=model, source=text, origin=origin,
                     **sections)
    if "modal" in sections:
        raise SceneError(f"{origin}: [modal] needs a 3-D model (kind = \"assembly\"), not {kind!r}")
    if kind == "rom":
        for key in ("work_precision",):  # [nnm] and [fep] run on a reduced model too (stages/fep.py)
            if key in sections:
                raise SceneError(f"{origin}: [{key}] is for the discrete model; a reduced model has "
                                 "[ringdown], [nnm], [fep], [stiff_cases], [rom_convergence] and [verify]")
    else:
        for key in ("rom_convergence", "verify"):
            if key in sections:
                raise SceneError(f"{origin}: [{key}] needs a reduced model (kind = \"rom\"), not {kind!r}")
    dof_names = model.point_names  # what [initial], [spectrogram] and [symmetry] refer to
    n = len(dof_names)
    init = sections.get("initial", InitialSpec())
    for key in ("x0_m", "v0_m_s"):
        if len(getattr(init, key)) != n:
            raise SceneError(f"{origin} [initial] {key}: needs {n} values ({', '.join(dof_names)}), "
                             f"got {len(getattr(init, key))}")
    hammer = sections.get("hammer")
    if hammer is not None:
        _check_hammer(sections, kind, model, origin, "load" in data)
        from fem.rig import channel_names

        dof_names = channel_names()  # [spectrogram] dof names a channel of the rig
    spec = sections.get("spectrogram")
    if spec is not None and spec.dof not in dof_names:
        raise SceneError(f"{origin} [spectrogram] dof: unknown DOF {spec.dof!r} (known: {', '.join(dof_names)})")
    sym = sections.get("symmetry")
    if sym is not None and any(d not in dof_names for d in sym.dofs):
        raise SceneError(f"{origin} [symmetry] dofs: unknown DOF in {sym.dofs!r}")
    if spec is not None and "ringdown" in sections and spec.window_s > sections["ringdown"].duration_s:
        raise SceneError(f"{origin} [spectrogram] window_s: {spec.window_s!r} s is longer than the run "
                         f"([ringdown] duration_s = {sections['ringdown'].duration_s!r} s)")
    loads, signals = (), ()
    if "load" in data:
        loads, signals = parse_loads(data["load"], origin, dof_names)
        if "ringdown" not in sections:
            raise SceneError(f"{origin} [[load]]: loads drive the ringdown stage; add a [ringdown] table")
        for key in ("work_precision", "stiff_cases", "rom_convergence", "verify"):
            if key in sections:
                raise SceneError(f"{origin} [[load]]: [{key}] runs free ringdowns; put the loads in a scene "
                                 "without it")
        duration = sections["ringdown"].duration_s
        for i, sig in enumerate(signals):
            if sig.start_s >= duration:
                raise SceneError(f"{origin} [[load]] {i + 1} start_s: the load starts at {sig.start_s!r} s, "
                                 f"at or after the end of the run ([ringdown] duration_s = {duration!r} s)")
    if "fep" in sections and "nnm" not in sections:
        raise SceneError(f"{origin}: [fep] needs an [nnm] table (its energy range and grid)")
    frc = sections.get("frc")
    if frc is not None:
        if frc.point not in dof_names:
            raise SceneError(f"{origin} [frc] point: unknown point {frc.point!r}{suggest(frc.point, dof_names)} "
                             f"(known: {', '.join(dof_names)})")
        damping = (model.c,) if kind == "discrete" else (model.c_points, model.alpha)
        if not any(d > 0 for d in damping):
            raise SceneError(f"{origin} [frc]: the model has no damping ([model] "
                             f"{'c' if kind == 'discrete' else 'c_points or alpha'} = 0), so no forced response "
                             "settles and the curves have no peak; give the model damping")
    if ("spectrogram" in sections or "symmetry" in sections) and "ringdown" not in sections:
        raise SceneError(f"{origin}: [spectrogram] and [symmetry] need a [ringdown] table")
    return Scene(name=name, description=description, model_kind=kind, model=model, source=text, origin=origin,
                 loads=loads, load_signals=signals, **sections)


def _check_hammer(sections: dict, kind: str, model, origin: str, has_loads: bool) -> None:
    """[hammer] needs a reduced model of the whole assembly, a [ringdown] and no other load or stage."""
    if kind != "rom" or model.layout != "assembly":
        raise SceneError(f"{origin} [hammer]: the virtual test needs the reduced apparatus ([model] kind = \"rom\", "
                         "layout = \"assembly\")")
    if "ringdown" not in sections:
        raise SceneError(f"{origin} [hammer]: add a [ringdown] table (the record's duration_s, sample_rate_hz, "
                         "method)")
    if has_loads:
        raise SceneError(f"{origin} [[load]]: [hammer] is the load of a virtual test; drop [[load]] or [hammer]")
    for key in ("symmetry", "work_precision", "stiff_cases", "rom_convergence", "verify", "frc"):
        if key in sections:
            raise SceneError(f"{origin}: [{key}] does not go with [hammer]; put it in another scene")
    h, rd = sections["hammer"], sections["ringdown"]
    if h.start_s + h.duration_s > rd.duration_s:
        raise SceneError(f"{origin} [hammer] start_s: the blow ends at {h.start_s + h.duration_s!r} s, after the "
                         f"record ([ringdown] duration_s = {rd.duration_s!r} s)")
    from fem.rig import channel_names

    names = channel_names()
    for c in h.compare:
        if c not in names:
            raise SceneError(f"{origin} [hammer] compare: unknown channel {c!r}{suggest(c, names)}")


# -- built-in scenes ---------------------------------------------------------------------
def builtin_names() -> list[str]:
    """Names of the scenes shipped with the package, sorted."""
    folder = resources.files("bearingshaft") / "scenes"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scene(name_or_path: str) -> Scene:
    """A built-in scene by name, or a scene from a TOML file path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise SceneError(f"{name_or_path}: cannot read scene file ({exc.strerror})") from None
        except UnicodeDecodeError:
            raise SceneError(f"{name_or_path}: not a text file (a scene is TOML in UTF-8)") from None
        return parse_scene(text, path.stem, str(path))
    if name_or_path not in builtin_names():
        hint = suggest(name_or_path, builtin_names())
        raise SceneError(
            f"unknown scene {name_or_path!r}{hint}: not a file, and no built-in scene has that name"
            + ("" if hint else f" (built-in: {', '.join(builtin_names())})")
        )
    text = (resources.files("bearingshaft") / "scenes" / f"{name_or_path}.toml").read_text(encoding="utf-8")
    return parse_scene(text, name_or_path, f"scene {name_or_path}")


__all__ = ["Scene", "SceneError", "FRCSpec", "HammerSpec", "load_scene", "parse_scene", "builtin_names", "from_table"]
