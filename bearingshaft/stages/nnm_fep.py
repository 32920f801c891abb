"""The [fep] part of the nnm stage: frequency-energy plots of the NNMs by HB and shooting, their
stability, HB convergence.

Computed by the nnm stage when the scene has an [fep] table (:func:`compute_fep`), written by
:func:`bearingshaft.stages.nnm_files.write_fep`. Runs on any gap
system: the 3-DOF model, or a reduced 3-D model (scene ``[model] kind = "rom"``), whose
NNMs followed are those of the lowest open-gap modes that move the gaps (heave, pitch,
first coupled bending: :func:`reduced.models.modes.gap_moving_modes`), numbered 1, 2, 3 as
the 3-DOF model's. Its files:

- ``fep.csv`` (nnm, method, harmonics, energy_J, freq_hz, stable) and ``fep.png``:
  HB backbones for each H of ``[fep] harmonics`` (stability by Hill's method) and the
  shooting orbits on the exact flow (stability by Floquet multipliers);
- ``stability.csv``: Hill against Floquet at each shooting energy, disagreements flagged;
- ``tongues.csv``: internal resonances met by the HB branches and what was done;
- ``hb_convergence.csv`` and ``hb_convergence.png``: HB frequency error against shooting
  for each H (and AFT samples N at one H) and, for the symmetric 3-DOF model, against the
  exact NNM 2 relation (:mod:`reduced.periodic.nnm2`). A reduced model has no closed form:
  its reference is shooting on the exact flow alone, and the ``max_err_vs_exact`` columns
  are empty;
- ``hb_convergence_timing.csv`` (run time of each branch and of shooting) and
  ``hb_convergence_timing.png`` (error against run time): wall-clock times, which change
  with machine load, live only in files whose name ends in ``_timing`` (the project's
  convention, tests/test_reproducible.py), so a rerun reproduces every other file;
- for a reduced model, ``fep.md``: the converged H and why, HB against shooting, the
  tongues met and the shooting failures, in words (the 3-DOF model's ``fep.md`` in
  results/discrete-fep is written by hand and not touched).

On another machine (other SIMD kernels in NumPy and OpenBLAS, so other last bits) the
continuation takes other steps: measured with OpenBLAS's Sandy Bridge kernels and NumPy's
AVX2/FMA paths disabled, fep.csv had 902 points instead of 905, one more shooting orbit
near NNM 1's tongues failed, tongue energies moved by up to 0.3 %, ``energy_reached_J``
(where the last step landed past ``energy_max_J``) by 2x and the maxima against shooting
over the tongue region by 30 %; the converged numbers agreed: HB against the exact NNM 2
relation to 5e-12 and against shooting above the last tongue to 4e-10 (relative). Writing
the backbones on a fixed energy grid would make the point sets machine-independent; the
path-dependent columns are reported as computed.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bearingshaft.fanout import fan_out
from bearingshaft.output import StageWriter
from bearingshaft.progress import bar as progress_bar
from bearingshaft.scenes import Scene
from bearingshaft.stages.nnm_results import FEPResult, FEPSummary
from bearingshaft.systems import model_system
from reduced._blas import single_thread_blas
from reduced.models.discrete import DiscreteParams
from reduced.models.gaps import GapSystem
from reduced.models.modes import gap_moving_modes, linear_modes
from reduced.periodic import nnm2
from reduced.periodic.backbones import START_FRACTION, hb_point_at_energy, nnm_branch
from reduced.periodic.hb import NewtonError, default_samples
from reduced.periodic.shooting import conservative, shooting_branch
from reduced.periodic.stability import compare, hill, hill_screened
from reduced.transient.flow import Flow

N_FOLLOWED = 3  # NNMs followed: the lowest open-gap modes that move the gaps (the 3-DOF model's three)
ALL_NNMS_MAX_H = 15  # every followed NNM runs each H of the study up to this; above it, only the study NNM
# A reduced model's shooting (measured on rom-fep, 10 modes): near grazing the orbits are very
# unstable and most guesses fail; a failing guess whose iterates chatter (hundreds to thousands
# of contact events a period, ~1 ms each) cost up to 17 s, and NNM 1 took 15 min. An NNM orbit
# has 6-16 events a period, so iterates past ROM_MAX_EVENTS are refused, and a guess that does
# not halve its residual in ROM_STALL iterations is dropped: NNM 1 then takes ~20 s with the
# same orbits found. The 3-DOF model keeps the defaults (its results are unchanged).
ROM_MAX_EVENTS = 40
ROM_STALL = 3
ROM_SHOOTING = {"stall": ROM_STALL, "max_events": ROM_MAX_EVENTS, "max_substeps": 1, "pick": "nearest",
                "guide_at_energy": True}
CONVERGED_TOL = 1e-3  # fep.md: H is converged when HB is within this of shooting (relative frequency)
OFF_BACKBONE_TOL = 1e-3  # fep.md: a shooting orbit that no H of the study comes within this of is off the backbone


@dataclass(frozen=True)
class ExactReference:
    """A closed-form frequency-energy relation of one followed NNM: the HB study's reference.

    Attributes
    ----------
    nnm : int
        0-based position among the followed NNMs.
    freq_hz : callable
        Energy [J] -> frequency [Hz], on arrays.
    grazing_energy_J : float
        J, where the NNM first touches a stop.
    label : str
        Legend label.
    """

    nnm: int  # 0-based position among the followed NNMs
    freq_hz: Callable[[np.ndarray], np.ndarray]  # energy [J] -> frequency [Hz]
    grazing_energy_J: float  # J, where the NNM first touches a stop
    label: str = "exact"


@dataclass(frozen=True)
class FEPModel:
    """What the fep study needs of a scene's model: the conservative gap system and the NNMs.

    ``modes`` are the 0-based open-gap linear modes followed (NNM k + 1 starts from
    ``modes[k]``); ``study`` the position of the NNM on which every H and every N of the
    convergence study runs; ``exact`` the closed-form reference if the model has one.

    Attributes
    ----------
    system : GapSystem
        The conservative gap system.
    modes : tuple of int
        0-based open-gap linear modes followed.
    kind : {'discrete', 'rom'}
        The model's kind.
    exact : ExactReference or None
        The closed-form reference, if any.
    study : int
        Position of the NNM of the convergence study.
    shooting : dict
        Options of :func:`reduced.periodic.shooting.shooting_branch`.
    hill : dict
        Options of :func:`reduced.periodic.stability.hill`.
    branch : dict
        Options of :func:`reduced.periodic.backbones.nnm_branch`.
    """

    system: GapSystem
    modes: tuple[int, ...]
    kind: str  # "discrete" | "rom"
    exact: ExactReference | None = None
    study: int = 1
    shooting: dict = field(default_factory=dict)  # options of shooting_branch
    hill: dict = field(default_factory=dict)  # options of reduced.periodic.stability.hill
    branch: dict = field(default_factory=dict)  # options of nnm_branch


def fep_model(scene: Scene, progress: bool = False) -> FEPModel:
    """The :class:`FEPModel` of a scene: the 3-DOF model (with its exact NNM 2 relation when
    m1 == m3) or a reduced model (reference: shooting alone).

    Parameters
    ----------
    scene : a scene whose model is the 3-DOF model or a reduced model
    progress : draw a progress bar if the reduced model must be built

    Returns
    -------
    FEPModel
        The conservative system, the NNMs followed and the options of each method for it.
    """
    model = scene.model
    system, _ = model_system(model, progress)
    system = conservative(system)
    modes = tuple(int(m) for m in gap_moving_modes(system, "open", N_FOLLOWED))
    if isinstance(model, DiscreteParams):
        exact = None
        if model.m1 == model.m3:
            exact = ExactReference(1, lambda E: nnm2.frequency_from_energy(model, E), model.grazing_energy_nnm2,
                                   "exact NNM 2 relation")
        return FEPModel(system, modes, "discrete", exact)
    # a reduced model: more DOFs, so Hill's eigenproblem by shift-invert Arnoldi (the eigenvalues near
    # the first zone only; dense where that is not certified), and only the first zone's exponents
    # (its local modes lie above H omega); tongues with the local modes are watched by their energy
    # too (reduced.periodic.backbones)
    return FEPModel(system, modes, "rom", None, 1, dict(ROM_SHOOTING), {"solver": "shift-invert", "strict_zone": True},
                    {"tongue_measure": "velocity"})


GRAZING_BAND = 10.0  # "near grazing": energies below this many times the grazing energy



def _hb_at(b, E_q):
    """HB frequency at exactly the energies E_q (nan where no piece of the branch covers
    E_q or Newton fails): from the nearest point of a covering piece, corrected onto the
    energy by :func:`reduced.periodic.backbones.hb_point_at_energy`."""
    out = np.full(np.shape(E_q), np.nan)
    i_w = b.residual.hb.size
    for k, E in enumerate(E_q):
        if not np.isfinite(E):
            continue
        for seg in np.unique(b.segment):
            idx = np.flatnonzero(b.segment == seg)
            Es = b.energy_J[idx]
            if not Es.min() <= E <= Es.max():
                continue
            y0 = b.branches[seg].y[np.argmin(np.abs(np.log(Es / E)))]
            try:
                y = hb_point_at_energy(b.residual, y0, float(E))
            except NewtonError:
                continue
            if abs(y[i_w] / y0[i_w] - 1.0) < 0.05:  # stayed on this piece
                out[k] = y[i_w] * b.residual.omega_ref / (2 * np.pi)
                break
    return out


def fep_stage(scene: Scene, writer: StageWriter, progress: bool) -> None:
    """Compute and write the [fep] files alone (module docstring; the nnm stage does both with the
    rest of its files).

    Parameters
    ----------
    scene : Scene
        A scene with an [fep] table.
    writer : StageWriter
        Where the files go.
    progress : bool
        Show progress bars.

    Returns
    -------
    None
    """
    from bearingshaft.stages.nnm_files import write_fep  # matplotlib: loaded only when files are written

    write_fep(compute_fep(scene, progress), writer)


def compute_fep(scene: Scene, progress: bool) -> FEPResult:
    """The HB branches, shooting orbits, Hill's multipliers and their comparisons of ``[fep]``.

    Parameters
    ----------
    scene : a scene with an [fep] table
    progress : draw a progress bar

    Returns
    -------
    FEPResult
        Dense algebra on one BLAS thread (the same sums whatever the machine's core count).
    """
    with single_thread_blas():
        return _compute_fep(scene, progress)


def _compute_fep(scene: Scene, progress: bool) -> FEPResult:
    spec = scene.fep
    fm = fep_model(scene, progress)
    system = fm.system
    n = len(fm.modes)  # NNMs followed, keyed 0..n-1 below (NNM k + 1 starts from linear mode fm.modes[k])
    open_hz = linear_modes(system, "open").freq_hz[list(fm.modes)]
    closed_hz = linear_modes(system, "closed").freq_hz[list(gap_moving_modes(system, "closed", N_FOLLOWED))]
    jobs = _jobs(spec, fm)
    bar = progress_bar(total=len(jobs) + 3 * n, desc=f"{scene.name}: NNM backbones", enabled=progress, unit="branch")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected steps
        branches = _branches(fm, spec, jobs, bar)
        shots, hills = _shooting_and_hills(fm, spec, branches, bar)
    bar.close()
    srows, n_dis = _stability(spec, n, branches, shots, hills)
    exact_err = _exact_errors(fm, branches)
    crow, errors = _convergence(fm, branches, shots, exact_err)
    shooting_vs_exact = None
    if fm.exact is not None:
        o2 = [o for o in shots[fm.exact.nnm][1] if o is not None]
        shooting_vs_exact = float(max(abs(o.freq_hz / float(fm.exact.freq_hz(o.energy_J)) - 1.0) for o in o2))
    summary = fep_summary(scene, fm, shots, branches, errors) if fm.kind == "rom" else None
    hill_stable = {key: [h.stable for h in hs] for key, hs in hills.items()}
    return FEPResult(scene.name, spec, fm, open_hz, closed_hz, branches, shots, hill_stable, srows, n_dis, errors,
                     exact_err, crow, shooting_vs_exact, summary)


def _jobs(spec, fm: FEPModel) -> list[tuple[int, int, int | None]]:
    """The work list: (nnm, H, N) branches; the study NNM (NNM 2) for every H, all NNMs for the H
    drawn in fep.png and for the convergence study up to H = ALL_NNMS_MAX_H, then the N study."""
    jobs = []
    for H in sorted(set(spec.harmonics) | set(spec.convergence_harmonics)):
        for mode in range(len(fm.modes)):
            if mode == fm.study or H in spec.harmonics or H <= ALL_NNMS_MAX_H:
                jobs.append((mode, H, None))
    for N in spec.samples:
        jobs.append((fm.study, spec.samples_study_harmonics, N))
    return jobs


def _branches(fm: FEPModel, spec, jobs: list, bar) -> dict:
    """{(nnm, H, N): NNMBranch} of the work list (a study branch at the default N is the branch
    already computed); the distinct branches are independent pieces (:func:`bearingshaft.fanout.fan_out`)."""
    first = {}  # (nnm, H, N or its default) -> the first job that asks for it: the one computed
    for mode, H, N in jobs:
        first.setdefault((mode, H, N or default_samples(H)), (mode, H, N))
    bar.set_postfix_str(f"{len(first)} HB branches")
    # the one-harmonic branches first: the others' step-overs past a tongue predict from them (nnm_branch's
    # backbone1: the points it would otherwise continue again at each branch's first tongue)
    ones = [k for k in first if k[1] == 1 and k[2] == default_samples(1)]
    done = dict(zip(ones, fan_out(_piece, [("branch", fm, spec, *first[k], None) for k in ones]), strict=True))
    backbone1 = {k[0]: done[k].branches[0].y for k in ones}
    keys = sorted((k for k in first if k not in done), key=lambda k: -k[1])  # the highest H first: the longest
    pieces = [("branch", fm, spec, *first[k], backbone1.get(k[0])) for k in keys]  # pieces start first
    done.update(zip(keys, fan_out(_piece, pieces), strict=True))
    bar.update(len(jobs))
    return {(mode, H, N): done[(mode, H, N or default_samples(H))] for mode, H, N in jobs}


def _piece(job: tuple):
    """One independent piece of the study: ``("branch", fm, spec, nnm, H, N, backbone1)`` an HB branch (the
    points of its one-harmonic branch, or None),
    ``("shooting", fm, spec, nnm, guides)`` the shooting orbits of one NNM (energies, orbits, wall_s), or
    ``("hill", fm, spec, nnm, branch, shooting energies)`` Hill's method at every point of one branch."""
    kind, fm, spec, mode = job[:4]
    if kind == "branch":
        H, N, backbone1 = job[4:]
        return nnm_branch(fm.system, fm.modes[mode], H=H, N=N, energy_max_J=spec.energy_max_J, backbone1=backbone1,
                          **fm.branch)
    if kind == "shooting":
        guides = job[4]
        energies = _shooting_energies(spec, guides)
        t0 = time.perf_counter()
        return energies, shooting_branch(Flow(fm.system), energies, guides, **fm.shooting), time.perf_counter() - t0
    if kind == "hill":
        b, energies = job[4:]
        if fm.hill.get("solver", "qz") != "qz":
            return [hill(b.residual.hb, b.X[i], b.omega[i], **fm.hill) for i in range(len(b.energy_J))]
        # QZ's multipliers where stability.csv writes them (the points nearest the shooting energies); elsewhere
        # only the verdict is used (fep.csv), screened by the faster shift-invert solve (stability.hill_screened)
        exact = set(_nearest_points(b, energies))
        return [hill(b.residual.hb, b.X[i], b.omega[i], **fm.hill) if i in exact
                else hill_screened(b.residual.hb, b.X[i], b.omega[i], **fm.hill) for i in range(len(b.energy_J))]
    raise ValueError(f"unknown piece {kind!r}")


def _shooting_energies(spec, guides: list) -> np.ndarray:
    """J, the energies of the shooting orbits of one NNM: ``[fep] n_shooting`` log-spaced from the first
    point of its last guide (its one-harmonic branch) to ``[fep] energy_max_J``."""
    E0 = guides[-1].energy_J[0]
    return np.logspace(np.log10(E0), np.log10(spec.energy_max_J), spec.n_shooting)


def _nearest_points(b, energies: np.ndarray) -> list[int]:
    """Index of the point of branch ``b`` nearest in log energy to each of ``energies`` (:func:`_stability`)."""
    return [int(np.argmin(np.abs(np.log(b.energy_J / E)))) for E in energies]


def _guides(fm: FEPModel, spec, branches: dict, mode: int) -> list:
    """The HB branches that guide the shooting along one NNM: the best complete ones (H = 1 last)."""
    guides = [branches[(mode, 1, None)]]
    hi = max(spec.harmonics)
    if branches[(mode, hi, None)].energy_J[-1] >= spec.energy_max_J:
        guides.insert(0, branches[(mode, hi, None)])
    return guides


def _shooting_and_hills(fm: FEPModel, spec, branches: dict, bar) -> tuple[dict, dict]:
    """({nnm: (energies, orbits, wall_s)}, {(nnm, H): [HillResult per point]}): shooting along each NNM, guided
    by the best complete HB branches, and Hill's method on every HB point of the drawn branches; independent
    pieces (:func:`bearingshaft.fanout.fan_out`)."""
    n = len(fm.modes)
    bar.set_postfix_str("shooting and Hill")
    hill_keys = [(mode, H) for mode in range(n) for H in spec.harmonics]
    pieces = [("shooting", fm, spec, mode, _guides(fm, spec, branches, mode)) for mode in range(n)]
    pieces += [("hill", fm, spec, mode, branches[(mode, H, None)],
                _shooting_energies(spec, _guides(fm, spec, branches, mode))) for mode, H in hill_keys]
    out = fan_out(_piece, pieces)
    bar.update(2 * n)
    return dict(zip(range(n), out[:n], strict=True)), dict(zip(hill_keys, out[n:], strict=True))


def _stability(spec, n: int, branches: dict, shots: dict, hills: dict) -> tuple[list[dict], dict]:
    """(stability.csv rows, disagreements per NNM and H): Hill (each drawn H) against Floquet at
    the shooting energies, at the HB point nearest in log energy (on the same piece of branch)."""
    srows = []
    n_dis = {}
    for mode in range(n):
        energies, orbits, _ = shots[mode]
        fl_max = np.array([o.max_multiplier if o else np.nan for o in orbits])
        fl_st = np.array([o.stable if o else False for o in orbits])
        for H in spec.harmonics:
            b = branches[(mode, H, None)]
            hm = np.array([h.max_multiplier for h in hills[(mode, H)]])
            hs = np.array([h.stable for h in hills[(mode, H)]])
            idx = _nearest_points(b, energies)
            near = np.array([abs(np.log(b.energy_J[i] / E)) < 0.05 for i, E in zip(idx, energies, strict=True)])
            cmp = compare(energies, np.where(near, fl_max, np.nan), fl_st, hm[idx], hs[idx])
            n_dis[f"NNM {mode + 1} H={H}"] = cmp.n_disagree
            for k, E in enumerate(energies):
                if not near[k] or orbits[k] is None:
                    continue
                srows.append({"nnm": mode + 1, "harmonics": H, "energy_J": E, "floquet_max_abs_mu": fl_max[k],
                              "hill_max_abs_mu": hm[idx[k]], "floquet_stable": int(fl_st[k]),
                              "hill_stable": int(hs[idx[k]]), "agree": int(cmp.agree[k])})
    return srows, n_dis


def _exact_errors(fm: FEPModel, branches: dict) -> dict:
    """{(nnm, H, N): |f_HB / f_exact - 1| at each point} of the branches of the NNM with a closed
    form (and of the study NNM, which hb_convergence.png draws); {} without one."""
    exact = fm.exact
    if exact is None:
        return {}
    return {key: np.abs(b.freq_hz / exact.freq_hz(b.energy_J) - 1.0) for key, b in branches.items()
            if key[0] in (exact.nnm, fm.study)}


def _convergence(fm: FEPModel, branches: dict, shots: dict, exact_err: dict) -> tuple[list[dict], dict]:
    """(hb_convergence.csv rows, {(nnm, H, N): (shooting energies, |f_HB / f_shooting - 1| there)}).

    Against shooting: at every exact orbit of the reference branch, the HB frequency at exactly
    its energy within the piece of branch that covers it (:func:`_hb_at`). NNM 1's exact
    backbone has its own internal-resonance tongues, on which shooting orbits are not the HB
    backbone's: the error above the last tongue is reported separately.
    """
    n = len(fm.modes)
    last_tongue = {m: max([t.get("energy_after_J") or t["energy_J"] for (mm, _, _), bb in branches.items() if mm == m
                           for t in bb.tongues], default=0.0) for m in range(n)}
    crow, errors = [], {}
    f_hb_of = {}  # id(branch): HB frequencies at the shooting energies (a shared branch once)
    for (mode, H, N), b in branches.items():
        orbits = shots[mode][1]
        E_sh = np.array([o.energy_J if o else np.nan for o in orbits])
        f_sh = np.array([o.freq_hz if o else np.nan for o in orbits])
        if id(b) not in f_hb_of:
            f_hb_of[id(b)] = _hb_at(b, E_sh)
        e = np.abs(f_hb_of[id(b)] / f_sh - 1.0)
        errors[(mode, H, N)] = (E_sh, e)
        crow.append(_convergence_row(fm, mode, H, N, b, E_sh, e, last_tongue[mode], exact_err.get((mode, H, N))))
    return crow, errors


def _convergence_row(fm: FEPModel, mode: int, H: int, N, b, E_sh: np.ndarray, e: np.ndarray, last_tongue: float,
                     err_x: np.ndarray | None) -> dict:
    """hb_convergence.csv row of one branch: its errors against shooting (overall, near grazing, above
    ten times the grazing energy, above the last tongue) and against the exact relation."""
    ok = np.isfinite(e)
    E_gr = b.energy_J[0] / START_FRACTION**2  # the linear mode starts at START_FRACTION a_g
    near_s = ok & (E_sh < GRAZING_BAND * E_gr) & (E_sh > E_gr)
    far_s = ok & (E_sh >= GRAZING_BAND * E_gr)
    row = {
        "nnm": mode + 1,
        "harmonics": H,
        "samples": b.N,
        "samples_study": int(N is not None),
        "n_points": len(b.energy_J),
        "energy_reached_J": b.energy_J[-1],
        "n_compared": int(ok.sum()),
        "max_err_vs_shooting": float(np.max(e[ok])) if ok.any() else np.nan,
        "median_err_vs_shooting": float(np.median(e[ok])) if ok.any() else np.nan,
        "max_err_vs_shooting_near_grazing": float(np.max(e[near_s])) if near_s.any() else np.nan,
        "max_err_vs_shooting_above_10x_grazing": float(np.max(e[far_s])) if far_s.any() else np.nan,
    }
    above = ok & (E_sh > last_tongue)
    row["max_err_vs_shooting_above_last_tongue"] = float(np.max(e[above])) if above.any() else np.nan
    row["n_folds"] = sum(len(br.folds) for br in b.branches)  # turning points of log10 a or omega
    row["n_corner_steps"] = sum(len(br.corners) for br in b.branches)  # grazing corners
    row["n_rejected_steps"] = sum(br.n_rejected for br in b.branches)
    row["last_tongue_energy_J"] = last_tongue
    if fm.exact is not None and mode == fm.exact.nnm:
        E_graze = fm.exact.grazing_energy_J
        near = (b.energy_J > E_graze) & (b.energy_J < GRAZING_BAND * E_graze)
        far = b.energy_J >= GRAZING_BAND * E_graze
        row.update({"max_err_vs_exact": float(err_x.max()),
                    "max_err_vs_exact_near_grazing": float(err_x[near].max()) if near.any() else np.nan,
                    "max_err_vs_exact_above_10x_grazing": float(err_x[far].max()) if far.any() else np.nan})
    else:
        row.update({"max_err_vs_exact": "", "max_err_vs_exact_near_grazing": "",
                    "max_err_vs_exact_above_10x_grazing": ""})
    row["tongues"] = "; ".join(f"{t['harmonic']}:1 at {t['energy_J']:.3g} J {t['action']}" for t in b.tongues)
    return row


def fep_summary(scene: Scene, fm: FEPModel, shots: dict, branches: dict, errors: dict) -> FEPSummary:
    """The numbers of fep.md (:func:`bearingshaft.stages.nnm_files.fep_markdown`) of a model
    without a closed form: the converged H and the orbits off the backbone.

    An H is *converged* when, on every followed NNM, its branch reaches ``[fep] energy_max_J``
    and its frequency is within :data:`CONVERGED_TOL` of every shooting orbit *on the
    backbone*, at every energy where both exist. An orbit is on the backbone when some H of
    the study comes within :data:`OFF_BACKBONE_TOL` of it; the others (multi-impact orbits
    near grazing, orbits shifted by a resonance of higher order than any H of the study)
    are listed, not compared.

    Parameters
    ----------
    scene : the scene (its [fep] table)
    fm : its model
    shots : {nnm: (energies, orbits, wall_s)}
    branches : {(nnm, H, N): NNMBranch}
    errors : {(nnm, H, N): (shooting energies, |f_HB / f_shooting - 1| there)}

    Returns
    -------
    FEPSummary
        The converged H (or None), the errors per H and NNM, the orbits off the backbone.
    """
    spec = scene.fep
    n = len(fm.modes)
    Hs = sorted({H for (_, H, N) in errors if N is None})
    # orbits on the backbone: some H of the study within OFF_BACKBONE_TOL
    best, off = {}, []
    for m in range(n):
        stack = np.array([errors[(m, H, None)][1] for H in Hs if (m, H, None) in errors])
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-nan columns: no HB there
            best[m] = np.nanmin(stack, axis=0)
        for i, o in enumerate(shots[m][1]):
            if o is not None and np.isfinite(best[m][i]) and best[m][i] >= OFF_BACKBONE_TOL:
                off.append((m, o, best[m][i]))
    max_err = {}  # H: ({nnm: max error over its orbits on the backbone}, every branch run reached energy_max_J)
    for H in Hs:
        errs, ok = {}, True
        for m in range(n):
            if (m, H, None) not in errors:  # H > ALL_NNMS_MAX_H: the study NNM only
                continue
            e = errors[(m, H, None)][1]
            on = np.isfinite(e) & (best[m] < OFF_BACKBONE_TOL)
            errs[m] = float(np.max(e[on])) if on.any() else np.nan
            ok = ok and branches[(m, H, None)].energy_J[-1] >= spec.energy_max_J
        max_err[H] = (errs, ok)
    converged = next((H for H in Hs if max_err[H][1] and len(max_err[H][0]) == n
                      and all(np.isfinite(x) and x <= CONVERGED_TOL for x in max_err[H][0].values())), None)
    closed_idx = list(gap_moving_modes(fm.system, "closed", N_FOLLOWED))
    return FEPSummary(converged, max_err, off, linear_modes(fm.system, "open").freq_hz,
                      linear_modes(fm.system, "closed").freq_hz, closed_idx, CONVERGED_TOL, OFF_BACKBONE_TOL)


__all__ = ["ExactReference", "FEPModel", "compute_fep", "fep_model", "fep_stage", "fep_summary"]
