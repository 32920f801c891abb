"""The tables of a scene other than [model], [[load]] and [sweep]: one frozen dataclass each,
with the unit first in every field's comment and the allowed values checked on construction.
``SECTIONS`` maps each table name to its class."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from bearingshaft.scenes.checks import check, each, positive, tolerance
from reduced.periodic import MAX_HARMONICS
from reduced.transient.methods import METHODS

EXPLICIT_OMEGA_DT_MAX = 1.6  # rad: 0.8 x the central-difference limit omega dt = 2 (reduced.transient.explicit)


@dataclass(frozen=True, slots=True)
class InitialSpec:
    """Initial state of the ringdown at the points x1, x2, x3 (see :mod:`reduced.models.initial`).

    For the discrete model the points are its DOFs. A reduced model takes the point values
    in its lowest three open-gap modes (heave, pitch, first bending), as the discrete model.

    Parameters
    ----------
    x0_m : tuple of float
        m, displacement of each point x1, x2, x3.
    v0_m_s : tuple of float
        m/s, velocity of each point.
    """

    x0_m: tuple[float, ...] = (0.0, 0.0, 0.0)  # m, displacement of each point
    v0_m_s: tuple[float, ...] = (0.0, 0.0, 0.0)  # m/s, velocity of each point



@dataclass(frozen=True, slots=True)
class RingdownSpec:
    """Free response from the initial state.

    Parameters
    ----------
    method : {'exact', 'explicit', 'dop853'}
        The integrator.
    duration_s : float
        s, > 0.
    sample_rate_hz : float
        Hz, output sampling, > 0.
    dt_s : float, optional
        s, explicit step (default: omega_dt / omega_ref).
    omega_dt : float
        rad, explicit step as omega_ref dt, in (0, ``EXPLICIT_OMEGA_DT_MAX``].
    step_basis : {'top', 'contact'}
        omega_ref: the top closed-gap frequency, or that of the three lowest modes that move the
        gaps (top mode capped at omega_max dt = 1).
    rtol : float
        DOP853 relative tolerance, in (0, 1).
    atol : float, optional
        m, DOP853 absolute tolerance (default rtol x max(largest stop offset, 1e-3 m)).

    Raises
    ------
    ValueError
        A value outside its range.
    """

    method: str = "exact"  # exact | explicit | dop853
    duration_s: float = 2.0  # s, length of the run
    sample_rate_hz: float = 20000.0  # Hz, output sampling
    dt_s: float | None = None  # s, explicit step (default: omega_dt / omega_ref)
    omega_dt: float = 0.05  # rad, explicit step: omega_ref dt
    step_basis: str = "top"  # omega_ref: "top" closed-gap frequency, or "contact" (the three lowest
    # modes that move the gaps, as the discrete model has; top mode capped at omega_max dt = 1)
    rtol: float = 1e-10  # dop853 relative tolerance
    atol: float | None = None  # m, dop853 absolute tolerance (default rtol x max(largest stop offset, 1 mm))

    def __post_init__(self) -> None:
        check(self.method in METHODS, f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        positive(self, "duration_s", "sample_rate_hz", "omega_dt", "rtol")
        tolerance(self, "rtol")
        check(self.omega_dt <= EXPLICIT_OMEGA_DT_MAX, f"omega_dt must be <= {EXPLICIT_OMEGA_DT_MAX} "
               f"(central difference is unstable past omega dt = 2), got {self.omega_dt!r}")
        check(self.step_basis in ("top", "contact"), f"step_basis must be top or contact, got {self.step_basis!r}")
        if self.dt_s is not None:
            positive(self, "dt_s")
        if self.atol is not None:
            positive(self, "atol")


@dataclass(frozen=True, slots=True)
class SpectrogramSpec:
    """Short-time Fourier transform (Hann window) of one DOF.

    Parameters
    ----------
    dof : str
        Which DOF to transform.
    window_s : float
        s, Hann window length, > 0.
    overlap : float
        Fraction of the window shared by neighbouring frames, in [0, 1).
    fmax_hz : float
        Hz, top of the plot, > 0.
    db_range : float
        dB shown below the peak, > 0.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    dof: str = "x1"  # which DOF to transform
    window_s: float = 0.05  # s, Hann window length
    overlap: float = 0.9  # fraction of the window shared by neighbouring frames
    fmax_hz: float = 1500.0  # Hz, top of the plot
    db_range: float = 120.0  # dB shown below the peak

    def __post_init__(self) -> None:
        positive(self, "window_s", "fmax_hz", "db_range")
        check(0.0 <= self.overlap < 1.0, f"overlap must be in [0, 1), got {self.overlap!r}")


@dataclass(frozen=True, slots=True)
class SymmetrySpec:
    """Symmetry-breaking plot: |x_a - x_b| against time (Fig. 4).

    Parameters
    ----------
    dofs : tuple of str
        The two DOFs a symmetric motion keeps equal.
    methods : tuple of str
        Integrators compared.

    Raises
    ------
    ValueError
        Not two different DOFs, or an unknown method.
    """

    dofs: tuple[str, ...] = ("x1", "x3")  # the pair that a symmetric motion keeps equal
    methods: tuple[str, ...] = ("exact", "explicit", "dop853")  # integrators compared

    def __post_init__(self) -> None:
        check(len(self.dofs) == 2, f"dofs must name two DOFs, got {self.dofs!r}")
        check(self.dofs[0] != self.dofs[1], f"dofs must name two different DOFs, got {self.dofs!r}")
        each(self, "methods", lambda m: m in METHODS, f"one of {', '.join(METHODS)}")


@dataclass(frozen=True, slots=True)
class NNMSpec:
    """Frequency-energy relations of the nonlinear normal modes.

    Parameters
    ----------
    n_energy : int
        Number of energies, log-spaced, >= 2.
    energy_min_J, energy_max_J : float
        J, the range, 0 < min < max.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    n_energy: int = 400  # number of energies, log-spaced
    energy_min_J: float = 1e-4  # J, lowest energy
    energy_max_J: float = 1e5  # J, highest energy

    def __post_init__(self) -> None:
        check(self.n_energy >= 2, f"n_energy must be >= 2, got {self.n_energy!r}")
        positive(self, "energy_min_J", "energy_max_J")
        check(self.energy_max_J > self.energy_min_J, "energy_max_J must exceed energy_min_J")


@dataclass(frozen=True, slots=True)
class FEPSpec:
    """Frequency-energy plots by HB, shooting and their stability (issue 3) -> stage nnm.

    Parameters
    ----------
    harmonics : tuple of int
        HB orders drawn in fep.png (1: the paper's Fig. 2), in [1, MAX_HARMONICS].
    convergence_harmonics : tuple of int
        H of the hb_convergence study.
    samples_study_harmonics : int
        H at which the AFT sample count N is varied.
    samples : tuple of int
        N values of that study, each > 2 samples_study_harmonics.
    energy_max_J : float
        J, every branch runs at least this far.
    n_shooting : int
        Shooting orbits per NNM (log-spaced in energy), >= 2.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    harmonics: tuple[int, ...] = (1, 15)  # HB orders drawn in fep.png (1: the paper's Fig. 2)
    convergence_harmonics: tuple[int, ...] = (1, 3, 5, 9, 15, 25, 50)  # hb_convergence study
    samples_study_harmonics: int = 15  # H at which the AFT sample count N is varied
    samples: tuple[int, ...] = (32, 64, 128, 256, 512, 1024, 2048)  # N values of that study
    energy_max_J: float = 1e5  # J, every branch runs at least this far
    n_shooting: int = 60  # shooting orbits per NNM (log-spaced in energy)

    def __post_init__(self) -> None:
        each(self, "harmonics", lambda h: 1 <= h <= MAX_HARMONICS, f"in [1, {MAX_HARMONICS}]")
        each(self, "convergence_harmonics", lambda h: 1 <= h <= MAX_HARMONICS, f"in [1, {MAX_HARMONICS}]")
        check(1 <= self.samples_study_harmonics <= MAX_HARMONICS,
               f"samples_study_harmonics must be in [1, {MAX_HARMONICS}], got {self.samples_study_harmonics!r}")
        each(self, "samples", lambda n: n > 2 * self.samples_study_harmonics,
              f"> 2 x samples_study_harmonics = {2 * self.samples_study_harmonics} (AFT sampling theorem)")
        positive(self, "energy_max_J")
        check(self.n_shooting >= 2, f"n_shooting must be >= 2, got {self.n_shooting!r}")


@dataclass(frozen=True, slots=True)
class WorkPrecisionSpec:
    """Error against run time of the three integrators over a short window.

    Parameters
    ----------
    window_s : float
        s, the window compared (before chaotic divergence dominates).
    sample_rate_hz : float
        Hz, grid on which errors are measured.
    explicit_omega_dt : tuple of float
        rad, explicit steps, at least 3, in (0, ``EXPLICIT_OMEGA_DT_MAX``].
    dop853_rtol : tuple of float
        DOP853 tolerances, in (0, 1).
    repeats : int
        Best-of timing, >= 1.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    window_s: float = 0.05  # s, before chaotic divergence dominates
    sample_rate_hz: float = 20000.0  # Hz, grid on which errors are measured
    explicit_omega_dt: tuple[float, ...] = (0.8, 0.4, 0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625, 0.003125)  # rad,
    # explicit steps as omega_max dt
    dop853_rtol: tuple[float, ...] = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-13)  # DOP853 relative tolerances
    repeats: int = 3  # best-of timing

    def __post_init__(self) -> None:
        positive(self, "window_s", "sample_rate_hz")
        check(len(self.explicit_omega_dt) >= 3, "explicit_omega_dt needs >= 3 values to fit an order")
        each(self, "explicit_omega_dt", lambda v: 0 < v <= EXPLICIT_OMEGA_DT_MAX,
              f"in (0, {EXPLICIT_OMEGA_DT_MAX}] (central difference is unstable past omega dt = 2)")
        each(self, "dop853_rtol", lambda v: 0 < v < 1, "in (0, 1)")
        check(self.repeats >= 1, f"repeats must be >= 1, got {self.repeats!r}")


@dataclass(frozen=True, slots=True)
class StiffCasesSpec:
    """Sweep over stiff and extreme parameters (every combination is run).

    Parameters
    ----------
    k_g : tuple of float
        N/m, > 0.
    gap : tuple of float
        m, >= 0.
    speed : tuple of float
        m/s, initial velocity of mass 3, nonzero.
    c : tuple of float
        N s/m, >= 0.
    duration_s : float
        s.
    sample_rate_hz : float
        Hz.
    methods : tuple of str
        Integrators run.
    long_duration_s : float
        s, also run the nominal case (first k_g, Table-1 gap, 200 m/s) this long for every c
        (0: no long runs).

    Raises
    ------
    ValueError
        A value outside its range.
    """

    k_g: tuple[float, ...] = (3.502e7, 1e9, 1e11)  # N/m, tip stiffnesses
    gap: tuple[float, ...] = (0.0, 2.54e-4, 1e-2)  # m, clearances
    speed: tuple[float, ...] = (0.01, 200.0, 2000.0)  # m/s, initial velocity of mass 3
    c: tuple[float, ...] = (0.0, 4.0, 400.0)  # N s/m, damping on every mass
    duration_s: float = 0.2  # s, length of each run
    sample_rate_hz: float = 5000.0  # Hz, output sampling
    methods: tuple[str, ...] = ("exact", "explicit")  # integrators run
    long_duration_s: float = 0.0  # s, also run the nominal case (first k_g, Table-1 gap, 200 m/s) this long
    # for every c (0: no long runs)

    def __post_init__(self) -> None:
        positive(self, "duration_s", "sample_rate_hz")
        each(self, "k_g", lambda v: v > 0, "> 0 N/m")
        each(self, "gap", lambda v: v >= 0, ">= 0 m")
        each(self, "c", lambda v: v >= 0, ">= 0 N s/m")
        each(self, "speed", lambda v: v != 0, "nonzero m/s (a run from rest has nothing to show)")
        check(self.long_duration_s >= 0, f"long_duration_s must be >= 0, got {self.long_duration_s!r}")
        each(self, "methods", lambda m: m in METHODS, f"one of {', '.join(METHODS)}")


@dataclass(frozen=True, slots=True)
class ModalSpec:
    """Modal analysis of a 3-D model (kind = "assembly"): correlation, MAC, pictures.

    Parameters
    ----------
    n_modes : int
        Modes computed, rigid-body ones included, >= 12.
    shift_hz : float
        Hz, the shift is sigma = -(2 pi shift_hz)^2.
    solver : {'pardiso', 'superlu'}
        Sparse factorization (superlu without pypardiso).
    test_shapes : str
        UFF (dataset 55) or CSV file of test mode shapes; "" for the FE auto-MAC.
    pictures : bool
        Mode-shape pictures rendered with pyvista off screen.
    vtu : bool
        modes.vtu of the labelled modes for ParaView.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    n_modes: int = 20  # modes computed, rigid-body ones included
    shift_hz: float = 1.0  # Hz, the shift is sigma = -(2 pi shift_hz)^2 (K - sigma M > 0)
    solver: str = "pardiso"  # pardiso | superlu (falls back to superlu without pypardiso)
    test_shapes: str = ""  # UFF (dataset 55) or CSV file of test mode shapes; "" -> FE auto-MAC
    pictures: bool = True  # mode-shape pictures rendered with pyvista off screen
    vtu: bool = True  # modes.vtu of the labelled modes for ParaView

    def __post_init__(self) -> None:
        check(self.n_modes >= 12, f"n_modes must be >= 12 (6 rigid + 6 pseudo-rigid), got {self.n_modes!r}")
        positive(self, "shift_hz")
        check(self.solver in ("pardiso", "superlu"), f"solver must be pardiso or superlu, got {self.solver!r}")


@dataclass(frozen=True, slots=True)
class RomConvergenceSpec:
    """Reduced model against its number of fixed-interface modes (kind = "rom").

    Parameters
    ----------
    modes : tuple of int
        Fixed-interface mode counts, at least two, >= 0; the largest is the reference.
    window_s : float
        s, ringdown window over which the error is measured.
    sample_rate_hz : float
        Hz, grid on which errors are measured.
    n_compare : int
        Contact-coupled frequencies compared (open and closed gap), >= 1.
    repeats : int
        Best-of timing, >= 1.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    modes: tuple[int, ...] = (1, 2, 5, 10, 20, 50)  # fixed-interface modes; the largest is the reference
    window_s: float = 0.05  # s, ringdown window over which the error is measured
    sample_rate_hz: float = 20000.0  # Hz, grid on which errors are measured
    n_compare: int = 4  # contact-coupled frequencies compared (open and closed gap)
    repeats: int = 3  # best-of timing

    def __post_init__(self) -> None:
        check(len(self.modes) >= 2, f"modes needs >= 2 counts, got {self.modes!r}")
        each(self, "modes", lambda m: m >= 0, ">= 0")
        positive(self, "window_s", "sample_rate_hz")
        check(self.n_compare >= 1, f"n_compare must be >= 1, got {self.n_compare!r}")
        check(self.repeats >= 1, f"repeats must be >= 1, got {self.repeats!r}")


@dataclass(frozen=True, slots=True)
class VerifySpec:
    """Reduction against the discrete model: identified parameters, frequencies, NNMs, ringdowns.

    Parameters
    ----------
    duration_s : float
        s, ringdown of each of the paper's three initial conditions.
    sample_rate_hz : float
        Hz.
    method : str
        Ringdown integrator.
    energy_max_J : float
        J, NNM backbones (HB, H = 1) up to this energy.
    window_s : float
        s, spectrogram window.
    fmax_hz : float
        Hz, top of the spectrograms.

    Raises
    ------
    ValueError
        A value outside its range.
    """

    duration_s: float = 2.0  # s, ringdown of each of the paper's three initial conditions
    sample_rate_hz: float = 20000.0  # Hz, output sampling of the ringdowns
    method: str = "exact"  # ringdown integrator
    energy_max_J: float = 1e5  # J, NNM backbones (HB, H = 1) up to this energy
    window_s: float = 0.05  # s, spectrogram window
    fmax_hz: float = 1500.0  # Hz, top of the spectrograms

    def __post_init__(self) -> None:
        check(self.method in METHODS, f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        positive(self, "duration_s", "sample_rate_hz", "energy_max_J", "window_s", "fmax_hz")


FRC_CURVES = ("auto", "hb", "shooting")  # [frc] curve: how the drawn curve of each level is computed


@dataclass(frozen=True, slots=True)
class FRCSpec:
    """Forced-response curves by HB under a harmonic load at one point, verified by a stepped
    sine of the exact integrator (issue 11) -> stage frc (reduced.periodic.frc).

    Parameters
    ----------
    point : str
        Where the load P cos(2 pi f t) acts (a point name).
    also_points : tuple of str
        Further points the same load acts at, in phase (a slanted load: e.g. ``["u"]``, the beam's axial motion,
        of the model with friction at the tips).
    also_weights : tuple of float
        The load at each of ``also_points``, a share of P (one a point; signed).
    levels_N : tuple of float
        N, load amplitudes P: one curve each.
    freq_min_hz, freq_max_hz : float
        Hz, the band.
    harmonics : int
        H of the curves in frc.csv and frc.png (odd with ``odd_harmonics``).
    odd_harmonics : bool
        Odd harmonics only (a half-wave symmetric response; stability sees all).
    convergence_harmonics : tuple of int
        H of the error-against-H study.
    convergence_level_N : float
        N, the level of that study.
    max_steps : int
        Continuation steps per curve at most.
    hill_points : int
        Hill's method on at most this many points per curve (0: none).
    shooting_points : int
        Floquet multipliers by shooting on the exact flow, points per curve (0: none).
    shooting_segments : int
        Segments of the multiple shooting.
    stepped_sine_points : int
        Frequencies per level, each swept up and down (0: no stepped sine).
    stepped_sine_tol : float
        Settled when the predicted distance to the periodic orbit is below this, in (0, 1).
    stepped_sine_max_s : float
        s, simulated time per frequency at most before "not settled".
    backbone_scales : tuple of float
        Damping and load scaled together (backbone check), in (0, 1].
    curve : {'auto', 'hb', 'shooting'}
        The drawn curve of each level: HB at ``harmonics``, the orbits of the exact flow continued
        by multiple shooting, or (auto) HB where its amplitudes no longer move with H (within
        ``hb_converged_tol`` of the next lower H of ``convergence_harmonics``), else shooting.
    hb_converged_tol : float
        Relative change of the amplitudes below which HB counts as converged, in (0, 1).
    branch_switching : bool
        Follow the families born at the exact curve's pitchforks and period doublings.
    max_families : int
        Families switched onto per level at most.
    family_steps : int
        Points of a switched family at most.
    period_doubling : bool
        Follow the period-doubled (2 T) families born where a Floquet multiplier passes -1 (with
        ``branch_switching``), on every family of the exact curve.
    period_doubling_families : int
        Period-doubled families per level at most (besides ``max_families``).
    period_doubling_depth : int
        Doublings of a cascade followed: 1 the 2 T families, 2 also the 4 T ones born on them.
    period_doubling_steps : int
        Points of a period-doubled family at most (each costs about twice a point of period 1).
    cover_families : int
        Families started from HB orbits of the contact band that no family covers, per level at most
        (kind ``isolated``: an isola or a piece of the curve the main family does not reach; 0: none).
    verdict_points : int
        HB points in contact judged per band no exact family covers (evenly spread; 0: none): multiple shooting
        from the HB orbit with 2 and 4 times the segments, an orbit starts an isolated family, else "no orbit
        near this HB point" with the best defect (:func:`reduced.periodic.uncovered.cover_verdicts`).
    close_return_families : int
        Families per level started from close returns of the response map's chaotic Poincare samples
        (unstable periodic orbits of period 1-4 T, :func:`reduced.periodic.uncovered.close_return_families`;
        0: none).
    close_return_tries : int
        Close returns shot per level at most.
    close_return_steps : int
        Points of such a family (and of a family started by a verdict, or switched onto from either) at most,
        each way.
    found_family_switches : int
        Families switched onto at the pitchforks and period doublings of each family started by a verdict or a
        close return (and of its children) at most: an allowance of its own, as ``max_families`` is mostly
        spent on the main curve's switches by then; 0: their branch points are listed, not followed.
    switching_max_s : float
        s of wall time per level after which no new family is started; 0 (the default): no such limit, so the
        families found do not depend on the machine or its load.
    shooting_steps : int
        Points of the main exact family at most.
    map_step_hz : float
        Hz, the response map's step over the contact band (issue 25; 0: no map).
    map_coarse_points : int
        Log-spaced frequencies of the response map over the band outside the contact band.
    map_periods : int
        Forcing periods recorded at each frequency of the response map (>= 32).

    Raises
    ------
    ValueError
        A value outside its range.
    """

    point: str = "x2"  # where the load P cos(2 pi f t) acts (a point name)
    also_points: tuple[str, ...] = ()  # further points the same load acts at, in phase (a slanted load)
    also_weights: tuple[float, ...] = ()  # the load at each of also_points, a share of P (signed)
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
    map_step_hz: float = 0.1  # Hz, step of the response map (stepped sine by the exact flow), contact band (0: no map)
    map_coarse_points: int = 24  # log-spaced frequencies over the band outside the contact band
    map_periods: int = 128  # forcing periods recorded at each frequency
    curve: str = "auto"  # the drawn curve: "hb", "shooting" (exact flow) or "auto" (HB where converged in H)
    hb_converged_tol: float = 1e-4  # HB converged: amplitudes within this of the next lower H's
    branch_switching: bool = True  # follow the families born at pitchforks and period doublings
    max_families: int = 12  # families switched onto per level at most
    family_steps: int = 3000  # points of a switched family at most
    period_doubling: bool = True  # follow the period-doubled (2 T) families born where a multiplier passes -1
    period_doubling_families: int = 4  # period-doubled families per level at most
    period_doubling_depth: int = 1  # doublings of a cascade followed (1: 2 T; 2: also 4 T)
    period_doubling_steps: int = 600  # points of a period-doubled family at most
    cover_families: int = 2  # families started from HB orbits of the contact band no family covers (0: none)
    verdict_points: int = 3  # uncovered HB points in contact judged by shooting per band (0: none)
    close_return_families: int = 2  # families from close returns of chaotic Poincare samples per level (0: none)
    close_return_tries: int = 6  # close returns shot per level at most
    close_return_steps: int = 200  # points of such a family (or one from a verdict) at most, each way
    found_family_switches: int = 1  # families switched onto from each family of a verdict or close return
    switching_max_s: float = 0.0  # s, wall time per level after which no new family is started (0: none, reproducible)
    shooting_steps: int = 30000  # points of the main exact family at most

    def __post_init__(self) -> None:
        each(self, "levels_N", lambda v: v > 0, "> 0 N")
        check(len(self.also_weights) == len(self.also_points),
              f"also_weights needs one share per point of also_points ({len(self.also_points)}), "
              f"got {len(self.also_weights)}")
        each(self, "also_weights", math.isfinite, "finite")
        positive(self, "freq_min_hz", "freq_max_hz", "convergence_level_N", "stepped_sine_max_s")
        check(self.freq_max_hz > self.freq_min_hz,
               f"freq_max_hz must exceed freq_min_hz = {self.freq_min_hz!r} Hz, got {self.freq_max_hz!r}")
        check(1 <= self.harmonics <= MAX_HARMONICS,
               f"harmonics must be in [1, {MAX_HARMONICS}], got {self.harmonics!r}")
        each(self, "convergence_harmonics", lambda h: 1 <= h <= MAX_HARMONICS, f"in [1, {MAX_HARMONICS}]")
        if self.odd_harmonics:
            check(self.harmonics % 2 == 1, f"harmonics must be odd with odd_harmonics = true, got {self.harmonics!r}")
            each(self, "convergence_harmonics", lambda h: h % 2 == 1, "odd with odd_harmonics = true")
        check(self.max_steps >= 1, f"max_steps must be >= 1, got {self.max_steps!r}")
        check(self.hill_points >= 0, f"hill_points must be >= 0, got {self.hill_points!r}")
        check(self.shooting_points >= 0, f"shooting_points must be >= 0, got {self.shooting_points!r}")
        check(self.shooting_segments >= 1, f"shooting_segments must be >= 1, got {self.shooting_segments!r}")
        check(self.stepped_sine_points >= 0, f"stepped_sine_points must be >= 0, got {self.stepped_sine_points!r}")
        tolerance(self, "stepped_sine_tol")
        each(self, "backbone_scales", lambda v: 0 < v <= 1, "in (0, 1] (damping and load scaled down together)")
        check(self.curve in FRC_CURVES, f"curve must be one of {', '.join(FRC_CURVES)}, got {self.curve!r}")
        tolerance(self, "hb_converged_tol")
        check(self.switching_max_s >= 0, f"switching_max_s must be >= 0 s, got {self.switching_max_s!r}")
        for key in ("period_doubling_families", "period_doubling_depth", "cover_families", "verdict_points",
                    "close_return_families", "close_return_tries", "found_family_switches"):
            check(getattr(self, key) >= 0, f"{key} must be >= 0, got {getattr(self, key)!r}")
        for key in ("max_families", "family_steps", "shooting_steps", "period_doubling_steps", "close_return_steps"):
            check(getattr(self, key) >= (0 if key == "max_families" else 1),
                  f"{key} must be >= {0 if key == 'max_families' else 1}, got {getattr(self, key)!r}")
        check(self.map_step_hz >= 0, f"map_step_hz must be >= 0 Hz, got {self.map_step_hz!r}")
        check(self.map_coarse_points >= 0, f"map_coarse_points must be >= 0, got {self.map_coarse_points!r}")
        check(self.map_periods >= 32, f"map_periods must be >= 32, got {self.map_periods!r}")


@dataclass(frozen=True, slots=True)
class HammerSpec:
    """A hammer blow on the beam of the reduced apparatus, recorded on every rig channel
    (issue 12) -> stage hammer (reduced.models.rig). The record's length, sampling and
    integrator are [ringdown]'s.

    Parameters
    ----------
    location_m : tuple of float
        m, point struck (default: the beam's top face at mid-span, under the tube's hole).
    direction : tuple of float
        The blow's direction, 3 numbers, not all zero.
    peak_N : float
        N, the nominal blow.
    duration_s : float
        s, length of the half-sine.
    start_s : float
        s, pre-trigger: the blow starts here.
    levels_N : tuple of float
        N, the level sweep.
    force_file : str
        A measured force history (CSV t_s,force_N or UFF 58) instead of the half-sine.
    seismic_mass_kg : float
        kg, tip assembly above each load cell's gauge.
    load_cell : str
        The load cell of fig10.png (one of ``fem.rig.TIP_CELLS``).
    compare : tuple of str
        Channels compared with a measured test (default: all but the hammer).
    compare_window_s : tuple of float
        s, (start, end) of the error measures (default: the record).
    linear_check : bool
        The open-gap response against the full 3-D model's modal superposition.
    linear_check_max_hz : float
        Hz, full-model modes up to this in that reference.
    backbone_modes : int
        NNM backbones overlaid on fig11.png (0: none).
    force_window : bool
        With --test, the measured hammer channel through a force window (zero outside the pulse
        and a margin) before it drives the model.
    force_window_margin_s : float
        s, the force window's margin on either side of the pulse (half-cosine tapered).

    Raises
    ------
    ValueError
        A value outside its range, or a force file that does not exist.
    """

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
    force_window: bool = True  # with --test, the measured hammer channel zeroed outside its pulse and a margin
    force_window_margin_s: float = 1e-3  # s, that margin on either side of the pulse (half-cosine tapered)

    def __post_init__(self) -> None:
        from fem.rig import TIP_CELLS

        if self.location_m:
            check(len(self.location_m) == 3, f"location_m must be 3 numbers (x, y, z), got {self.location_m!r}")
        check(len(self.direction) == 3, f"direction must be 3 numbers, got {self.direction!r}")
        check(any(d != 0 for d in self.direction), "direction must not be the zero vector")
        positive(self, "peak_N", "duration_s", "linear_check_max_hz")
        check(self.start_s >= 0, f"start_s must be >= 0, got {self.start_s!r}")
        each(self, "levels_N", lambda v: v > 0, "> 0 N")
        check(self.seismic_mass_kg >= 0, f"seismic_mass_kg must be >= 0, got {self.seismic_mass_kg!r}")
        check(self.load_cell in TIP_CELLS, f"load_cell must be one of {', '.join(TIP_CELLS)}, got {self.load_cell!r}")
        if self.force_file:
            check(Path(self.force_file).is_file(), f"force_file: no such file {self.force_file!r}")
        if self.compare_window_s:
            w = self.compare_window_s
            check(len(w) == 2 and 0 <= w[0] < w[1], f"compare_window_s must be (start, end), 0 <= start < end, "
                   f"got {w!r}")
        check(self.backbone_modes >= 0, f"backbone_modes must be >= 0, got {self.backbone_modes!r}")
        check(self.force_window_margin_s >= 0, f"force_window_margin_s must be >= 0 s, got "
              f"{self.force_window_margin_s!r}")



@dataclass(frozen=True, slots=True)
class FRFSpec:
    """FRFs and modal parameters of a hammer test (issue 26) -> stage frf. Without ``--test`` the
    blows are the virtual test's: the scene's reduced apparatus struck at each reference, at a
    level that leaves the gaps open, recorded as a DAQ does ([ringdown] sample_rate_hz and
    duration_s give the record); with ``--test`` they are a measured file's.

    Parameters
    ----------
    blows : int
        Blows averaged per reference.
    peak_N : float
        N, the virtual blows' nominal peak (must leave the gaps open).
    peak_spread : float
        The virtual blows' peaks vary by up to this fraction (uniform, seeded).
    noise : float
        Noise added to every virtual channel, a fraction of its RMS over the record.
    seed : int
        Seed of the spread and the noise.
    locations_m : tuple of tuple of float
        m, the virtual references' points on the beam (default: three, on the top, side and end faces).
    directions : tuple of tuple of float
        Their blow directions, one per location.
    force_window_s : float
        s, the force window's length after the trigger.
    exp_end : float
        The exponential window's value at the record's end, in (0, 1] (1: no window).
    band_hz : tuple of float
        Hz, (low, high): the band of the identification.
    max_order : int
        Highest model order of the stabilization diagram.
    min_share : float
        Share of the orders at which a pole must be stable to be a mode.
    modes_hz : tuple of float
        Hz, pick the stable poles nearest these instead (default: every persistent one).
    mac_reference : str
        ``fe``: the 3-D model's modes (as the modal stage solves them); ``rom``: the reduced rig's.
    fe_modes : int
        Modes of the 3-D model solved for the MAC.
    export_max_hz : float
        Hz, FRFs and coherences are written up to this (frf.uff, frf.npz).

    Raises
    ------
    ValueError
        A value outside its range.
    """

    blows: int = 5  # blows averaged per reference
    peak_N: float = 20.0  # N, the virtual blows' peak: the gaps stay open (they close near 120 N)
    peak_spread: float = 0.1  # the virtual peaks vary by up to +-10 %
    noise: float = 0.0  # noise on every virtual channel, a fraction of its RMS
    seed: int = 0  # seed of the spread and the noise
    locations_m: tuple[tuple[float, ...], ...] = ()  # m, the references (default: top, side, end faces)
    directions: tuple[tuple[float, ...], ...] = ()  # one per location
    force_window_s: float = 0.005  # s, force window after the trigger
    exp_end: float = 0.01  # exponential window's value at the record's end (1: none)
    band_hz: tuple[float, ...] = (5.0, 45.0)  # Hz, band of the identification (the six pseudo-rigid modes)
    max_order: int = 30  # highest model order of the stabilization diagram
    min_share: float = 0.3  # share of the orders at which a pole must be stable to be a mode
    modes_hz: tuple[float, ...] = ()  # Hz, pick the poles nearest these (default: automatic)
    mac_reference: str = "fe"  # fe (the 3-D model, as the modal stage) | rom (the reduced rig)
    fe_modes: int = 20  # modes of the 3-D model solved for the MAC
    export_max_hz: float = 200.0  # Hz, FRFs and coherences written up to this (frf.uff, frf.npz)

    def __post_init__(self) -> None:
        check(self.blows >= 1, f"blows must be >= 1, got {self.blows!r}")
        positive(self, "peak_N", "force_window_s", "export_max_hz")
        check(0 <= self.peak_spread < 1, f"peak_spread must lie in [0, 1), got {self.peak_spread!r}")
        check(self.noise >= 0, f"noise must be >= 0, got {self.noise!r}")
        check(len(self.locations_m) == len(self.directions), f"locations_m and directions must pair up, got "
              f"{len(self.locations_m)} and {len(self.directions)}")
        for name in ("locations_m", "directions"):
            check(all(len(v) == 3 for v in getattr(self, name)), f"{name}: every entry must be 3 numbers")
        check(all(any(d != 0 for d in v) for v in self.directions), "directions: a zero vector")
        check(0 < self.exp_end <= 1, f"exp_end must lie in (0, 1], got {self.exp_end!r}")
        check(len(self.band_hz) == 2 and 0 < self.band_hz[0] < self.band_hz[1],
              f"band_hz must be (low, high) with 0 < low < high, got {self.band_hz!r}")
        check(self.max_order >= 2, f"max_order must be >= 2, got {self.max_order!r}")
        check(0 < self.min_share <= 1, f"min_share must lie in (0, 1], got {self.min_share!r}")
        each(self, "modes_hz", lambda v: self.band_hz[0] <= v <= self.band_hz[1], "inside band_hz")
        check(self.mac_reference in ("fe", "rom"), f"mac_reference must be fe or rom, got {self.mac_reference!r}")
        check(self.fe_modes >= 12, f"fe_modes must be >= 12 (6 rigid + 6 pseudo-rigid), got {self.fe_modes!r}")


IDENTIFY_MEASURES = ("time", "envelope", "decay", "ridges", "impacts", "open", "first")  # residual blocks of [identify]


@dataclass(frozen=True, slots=True)
class IdentifySpec:
    """The uncertain parameters of the model fitted to a measured hammer test (issue 26) ->
    ``bearingshaft identify --scene S --test FILE.uff`` (:mod:`bearingshaft.identify`).

    Parameters
    ----------
    parameters : tuple of str
        The [model] keys fitted, as ``model.KEY`` (contact and damping keys: the reduction is kept).
    lower, upper : tuple of float
        Their bounds, one per parameter in its unit (default: the scene's value / 4 and x 4; a ``lin``
        parameter whose value is 0 needs its bounds).
    scales : tuple of str
        ``log`` (the fit varies ln p: a positive parameter over decades) or ``lin`` (p / (upper - lower):
        one that may be 0), one per parameter (default: log for a positive value, lin for 0).
    measures : tuple of str
        The residual blocks (``IDENTIFY_MEASURES``): ``first`` (each load cell's first impact: its time and
        peak), ``time`` (pointwise, up to the predictability horizon),
        ``envelope`` (log RMS envelope), ``decay`` (its shape after the last impact: the damping),
        ``ridges``, ``impacts``, ``open``.
    window_s : tuple of float
        s, (start, end) of the test fitted (default: the whole record).
    envelope_window_s : float
        s, the RMS envelope's windows.
    step : float
        The finite-difference step of the Jacobian in the scaled parameters (log: 0.01 is 1 %).
    max_iterations : int
        Least-squares iterations per pass at most.
    passes : int
        Fits in turn, each with the horizon and the weights of the previous one's optimum.
    scan : int
        Where the fit starts: each parameter in turn over this many evenly spaced (scaled) values across
        its bounds, the others at the best so far, the cheapest kept (0: at the scene's values).
    n_modes : int
        Fixed-interface modes kept in the fit, the lowest (0: all of the reduced model's).
    confidence : float
        The intervals' confidence level, in (0, 1).

    Raises
    ------
    ValueError
        A value outside its range, lists of different lengths, a key named twice.
    """

    parameters: tuple[str, ...] = ("model.gap", "model.k_g", "model.modal_damping[0]")  # [model] keys fitted
    lower: tuple[float, ...] = ()  # each parameter's unit: lower bounds (default: the scene's value / 4)
    upper: tuple[float, ...] = ()  # upper bounds (default: the scene's value x 4)
    scales: tuple[str, ...] = ()  # log | lin, per parameter (default: log, lin for a value of 0)
    measures: tuple[str, ...] = ("first", "envelope", "impacts")  # residual blocks: first, time, envelope, decay,
    # ridges, impacts, open
    window_s: tuple[float, ...] = ()  # s, (start, end) of the test fitted (default: the whole record)
    envelope_window_s: float = 0.05  # s, windows of the RMS envelope
    step: float = 0.01  # finite-difference step of the Jacobian, in the scaled parameters (log: 1 %)
    max_iterations: int = 15  # least-squares iterations per pass at most
    passes: int = 2  # fits in turn, each with the horizon and weights at the last one's optimum
    scan: int = 12  # the start: each parameter over this many values across its bounds in turn (0: the scene's)
    n_modes: int = 0  # fixed-interface modes kept in the fit, the lowest (0: all)
    confidence: float = 0.95  # the intervals' confidence level

    def __post_init__(self) -> None:
        n = len(self.parameters)
        check(n >= 1, "parameters must name at least one [model] key")
        each(self, "parameters", lambda k: isinstance(k, str) and k.startswith("model.") and len(k) > 6,
             "a [model] key written model.KEY")
        check(len(set(self.parameters)) == n, f"parameters: a key named twice in {list(self.parameters)}")
        for name in ("lower", "upper", "scales"):
            v = getattr(self, name)
            check(not v or len(v) == n, f"{name} must have one value per parameter ({n}), got {len(v)}")
        each(self, "scales", lambda s: s in ("log", "lin"), "log or lin")
        if self.lower and self.upper:
            for i, (lo, hi) in enumerate(zip(self.lower, self.upper, strict=True)):
                check(lo < hi, f"lower[{i}] = {lo!r} must be below upper[{i}] = {hi!r}")
        check(len(self.measures) >= 1, "measures must name at least one residual block")
        each(self, "measures", lambda m: m in IDENTIFY_MEASURES, f"one of {', '.join(IDENTIFY_MEASURES)}")
        check(len(set(self.measures)) == len(self.measures), "measures: a block named twice")
        if self.window_s:
            w = self.window_s
            check(len(w) == 2 and 0 <= w[0] < w[1], f"window_s must be (start, end), 0 <= start < end, got {w!r}")
        positive(self, "envelope_window_s")
        check(0 < self.step <= 0.5, f"step must lie in (0, 0.5], got {self.step!r}")
        check(self.max_iterations >= 1, f"max_iterations must be >= 1, got {self.max_iterations!r}")
        check(1 <= self.passes <= 5, f"passes must lie in [1, 5], got {self.passes!r}")
        check(self.scan == 0 or self.scan >= 3, f"scan must be 0 or >= 3, got {self.scan!r}")
        check(self.n_modes >= 0, f"n_modes must be >= 0, got {self.n_modes!r}")
        check(0 < self.confidence < 1, f"confidence must lie in (0, 1), got {self.confidence!r}")


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
    "frf": FRFSpec,
    "identify": IdentifySpec,
}
