"""Backbones (frequency-energy curves) of the nonlinear normal modes of a gap system by HB.

:func:`nnm_branch` continues one NNM from its open-gap linear mode, below the energy at
which the mode first touches a stop, up to ``energy_max_J``; :func:`hb_backbones` gives
the paper's Fig. 2 curves (one harmonic) for every mode, for the spectrogram overlays.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from reduced._blas import single_thread_blas
from reduced.models.gaps import GapSystem
from reduced.models.modes import linear_modes
from reduced.periodic.continuation import continue_branch
from reduced.periodic.hb import HarmonicBalance, NewtonError, NNMResidual, default_samples, newton

START_FRACTION = 0.3  # start amplitude as a fraction of the grazing amplitude (open gap)


def grazing_amplitude(system: GapSystem, phi: np.ndarray) -> float:
    """Modal amplitude a (phi mass-normalised) at which mode phi first reaches a stop."""
    s = np.abs(system.B @ phi)
    with np.errstate(divide="ignore"):
        a = np.where(s > 1e-12 * np.max(s), np.abs(system.offset) / s, np.inf)
    return float(np.min(a))


@dataclass(eq=False)
class NNMBranch:
    """One HB backbone: energy [J] and frequency [Hz] per point, with the continuation data.

    ``segment`` numbers the continued pieces: a new piece starts after an internal
    resonance tongue was stepped over (``tongues`` says where); points of different pieces
    are not joined by a computed path.
    """

    mode: int  # 0-based index of the linear mode it starts from
    H: int
    N: int
    energy_J: np.ndarray
    freq_hz: np.ndarray
    X: np.ndarray  # (n_points, n (2H+1)) HB coefficients [m]
    omega: np.ndarray  # rad/s
    segment: np.ndarray  # (n_points,) int
    branches: list  # the Branch of each piece
    residual: NNMResidual
    wall_s: float
    tongues: list = field(default_factory=list)  # dicts: harmonic, energy_J, freq_hz, action
    notes: list = field(default_factory=list)

    @property
    def status(self) -> str:
        return self.branches[-1].status

    @property
    def n_steps(self) -> int:
        return sum(len(b.y) for b in self.branches)


def harmonic_ratio(hb: HarmonicBalance, X: np.ndarray) -> tuple[float, int]:
    """Largest mass-norm amplitude of a harmonic k >= 2 over that of the fundamental, and k."""
    Xm = hb.unpack(X)
    amp = np.array(
        [
            math.sqrt(Xm[2 * k - 1] @ hb.M @ Xm[2 * k - 1] + Xm[2 * k] @ hb.M @ Xm[2 * k])
            for k in range(1, hb.H + 1)
        ]
    )
    if hb.H < 2 or amp[0] == 0.0:
        return 0.0, 1
    k = int(np.argmax(amp[1:])) + 2
    return float(amp[k - 1] / amp[0]), k


TONGUE_RATIO = 1.0  # a harmonic k >= 2 larger than the fundamental: an internal resonance
STEP_OVER_DW = (0.01, 0.02, 0.05, 0.1, 0.2, 0.35)  # tried relative frequency jumps past a tongue


def _nnm_branch(
    system: GapSystem,
    mode: int,
    *,
    H: int = 1,
    N: int | None = None,
    energy_max_J: float = 1e5,
    energy_start_J: float | None = None,
    ds: float = 0.05,
    ds_max: float = 0.3,
    max_steps: int = 3000,
    max_angle_deg: float = 15.0,
    tongue_ratio: float = TONGUE_RATIO,
    max_tongues: int = 60,
    follow_steps: int = 100,
    progress=None,
) -> NNMBranch:
    """Continue NNM ``mode`` (0-based) by HB with H harmonics until energy >= energy_max_J.

    The branch starts at START_FRACTION of the amplitude at which the linear mode first
    touches a stop (or lower, at ``energy_start_J``), continued in log10 of the modal
    amplitude (:class:`reduced.periodic.hb.NNMResidual`).

    Internal resonances (tongues, H > 1): when a harmonic k >= 2 outgrows the fundamental
    (``tongue_ratio``), or the frequency falls while the energy rises and does not come back
    within ``follow_steps`` points (a tongue that does come back is "followed"), the branch
    has left the backbone for a k:1 resonance with another
    mode (for the 3-DOF model, NNM 1 meets NNM 3 wherever k f_1 = f_3; followed, such a
    tongue runs all the way along NNM 3). The tongue is *stepped over*: from the last
    backbone point before it (ratio < tongue_ratio / 3, frequency at its running
    maximum) the frequency is raised in jumps (STEP_OVER_DW), the amplitude predicted from
    the one-harmonic backbone, until a solution with a small ratio, a larger amplitude and
    a higher energy is found; continuation restarts there. Each tongue is reported in
    ``tongues`` with action "stepped over" (or "followed"); if no jump
    lands, the run ends with action "stopped" (never a silent jump).
    """
    t0 = time.perf_counter()
    lin = linear_modes(system, "open")
    phi = lin.phi[:, mode]
    omega0 = float(lin.omega[mode])
    hb = HarmonicBalance.for_system(system, H, N or default_samples(H))
    ref = int(np.argmax(np.abs(phi)))
    res = NNMResidual(hb, omega0, ref)
    a_g = grazing_amplitude(system, phi)
    if not math.isfinite(a_g):  # the mode never touches a stop: any amplitude will do
        a_g = 1.0
    a0 = START_FRACTION * a_g
    if energy_start_J is not None:  # linear energy 1/2 omega0^2 a^2
        a0 = min(a0, math.sqrt(2.0 * energy_start_J) / omega0)
    y0 = res.start(phi, omega0, math.log10(a0))
    nX = hb.size
    i_w, i_a = nX, nX + 2
    in_tongue = {"flag": False}
    tongues, notes = [], []

    def ratio(y):
        return harmonic_ratio(hb, y[:nX])

    st = {}

    def reset():
        st.update(w_max=-np.inf, E_prev=-np.inf, count=0, bend_at=None, bend=None)

    def stop(y):
        st["count"] += 1
        E = res.energy(y)
        if E >= energy_max_J:
            return True
        if H > 1:
            r, k = ratio(y)
            if r > tongue_ratio:
                in_tongue["flag"] = True
                return True
            # on the backbone of a hardening gap system the frequency rises with the energy;
            # a frequency that falls while the energy rises is the bend into a tongue: follow
            # it for up to follow_steps points, hoping it returns above its highest frequency
            if st["bend_at"] is None:
                if y[i_w] < st["w_max"] * (1.0 - 1e-6) and E > st["E_prev"]:
                    st["bend_at"] = st["count"]
                    st["bend"] = (k, E, st["w_max"])
            elif y[i_w] > st["bend"][2] and r < tongue_ratio / 3.0:
                k0, E0, w0 = st["bend"]
                tongues.append(
                    {
                        "harmonic": k0,
                        "energy_J": E0,
                        "freq_hz": w0 * omega0 / (2 * np.pi),
                        "action": "followed",
                        "energy_after_J": E,
                    }
                )
                notes.append(
                    f"{k0}:1 internal resonance at E = {E0:.4g} J: followed (the branch "
                    f"returned at E = {E:.4g} J)"
                )
                st["bend_at"] = None
            elif st["count"] - st["bend_at"] > follow_steps:
                in_tongue["flag"] = True
                return True
        st["w_max"] = max(st["w_max"], y[i_w])
        st["E_prev"] = E
        return False

    backbone1 = None
    pieces = []
    steps_left = max_steps
    ystart = y0
    for _ in range(max_tongues + 1):
        in_tongue["flag"] = False
        reset()
        br = continue_branch(
            res,
            ystart,
            param=i_a,
            direction=1.0,
            ds=ds,
            ds_max=ds_max,
            max_steps=steps_left,
            max_angle_deg=max_angle_deg,
            stop=stop,
            monitor=(i_w,),
            callback=res.energy,
            progress=progress,
        )
        steps_left -= len(br.y)
        if not in_tongue["flag"]:
            pieces.append((br, np.arange(len(br.y))))
            break
        # keep the backbone up to the last point clearly off the tongue
        r = np.array([ratio(y)[0] for y in br.y])
        w_max = np.maximum.accumulate(br.y[:, i_w])
        keep = np.flatnonzero((r < tongue_ratio / 3.0) & (br.y[:, i_w] >= w_max))
        if keep.size == 0:
            keep = np.array([0])
        last = int(keep[-1])
        k = ratio(br.y[-1])[1]
        pieces.append((br, np.arange(last + 1)))
        anchor = br.y[last]
        E_a = float(br.data[last])
        f_a = anchor[i_w] * omega0 / (2 * np.pi)
        if backbone1 is None:
            backbone1 = (
                _nnm_branch(system, mode, H=1, energy_max_J=energy_max_J, energy_start_J=energy_start_J)
                .branches[0]
                .y
            )
        n1 = system.n * 3  # size of an H = 1 coefficient vector
        la1 = backbone1[:, n1 + 2]
        bias = anchor[i_w] / float(np.interp(anchor[i_a], la1, backbone1[:, n1]))
        landed = None
        w1 = backbone1[:, n1]
        mono = np.maximum.accumulate(w1)  # the one-harmonic backbone, made monotone for inversion
        for jump, kind in [(j, g) for j in STEP_OVER_DW for g in ("anchor", "one-harmonic")]:
            # fix the frequency a little above the anchor's: the resonance sits at one
            # frequency (k omega = omega of the other mode), so a solve at fixed frequency
            # past it stays well conditioned, where one at fixed amplitude may not
            w_t = anchor[i_w] * (1.0 + jump)
            la = float(np.interp(w_t / bias, mono, la1))
            if kind == "anchor":  # the anchor's shape at the predicted amplitude
                guess = anchor.copy()
            else:  # the one-harmonic solution at that amplitude, higher harmonics zero
                guess = np.zeros_like(anchor)
                for c in range(n1):
                    guess[c] = np.interp(la, la1, backbone1[:, c])
            guess[i_w] = w_t
            guess[i_a] = la

            def fixed(z, w_t=w_t):
                R, J = res(z)
                e = np.zeros(z.size)
                e[i_w] = 1.0
                return np.concatenate([R, [z[i_w] - w_t]]), np.vstack([J, e])

            try:
                sol = newton(fixed, guess, max_iter=40, max_step=5.0)
            except NewtonError:
                continue
            # accept only a point on this backbone: amplitude near the prediction and above
            # the anchor's, more energy, a dominant fundamental
            if (
                abs(sol.y[i_a] - la) < 0.5
                and ratio(sol.y)[0] < tongue_ratio / 3.0
                and sol.y[i_a] > anchor[i_a]
                and res.energy(sol.y) > E_a
            ):
                landed = sol.y
                break
        if landed is None or steps_left <= 0:
            tongues.append({"harmonic": k, "energy_J": E_a, "freq_hz": f_a, "action": "stopped"})
            notes.append(f"{k}:1 internal resonance at E = {E_a:.4g} J, {f_a:.2f} Hz: could not step over")
            break
        E_b = res.energy(landed)
        tongues.append(
            {"harmonic": k, "energy_J": E_a, "freq_hz": f_a, "action": "stepped over", "energy_after_J": E_b}
        )
        notes.append(
            f"{k}:1 internal resonance at E = {E_a:.4g} J, {f_a:.2f} Hz: stepped over to E = {E_b:.4g} J"
        )
        ystart = landed
    Y = np.concatenate([b.y[idx] for b, idx in pieces])
    E = np.concatenate([np.asarray(b.data)[idx] for b, idx in pieces])
    seg = np.concatenate([np.full(idx.size, i) for i, (_, idx) in enumerate(pieces)])
    X = np.array([res.X_omega(y)[0] for y in Y])
    omega = Y[:, i_w] * omega0
    if pieces[-1][0].status != "stop" or E[-1] < energy_max_J:
        notes.append(f"stopped early ({pieces[-1][0].status}) at E = {E[-1]:.3g} J")
    return NNMBranch(
        mode,
        H,
        hb.N,
        E,
        omega / (2 * np.pi),
        X,
        omega,
        seg,
        [b for b, _ in pieces],
        res,
        time.perf_counter() - t0,
        tongues,
        notes,
    )


def nnm_branch(system: GapSystem, mode: int, **options) -> NNMBranch:
    """Continue NNM ``mode`` (0-based) by HB; see :func:`_nnm_branch` for the options.

    Runs with single-threaded BLAS (:mod:`reduced._blas`): the matrices are small.
    """
    with single_thread_blas():
        return _nnm_branch(system, mode, **options)


def hb_backbones(
    system: GapSystem, harmonics: int = 1, energy_max_J: float = 1e5, modes=None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{"NNM 1": (energy_J, freq_hz), ...} of the NNMs ``modes`` (0-based; default every one)
    by HB, sorted by energy.

    The paper's Fig. 2 curves with ``harmonics = 1``. Where a branch folds back in energy
    (an internal resonance at H > 1) the points are still returned sorted by energy, so
    use a one-harmonic branch for overlays.
    """
    out = {}
    for mode in range(system.n) if modes is None else modes:
        b = nnm_branch(system, int(mode), H=harmonics, energy_max_J=energy_max_J)
        order = np.argsort(b.energy_J, kind="stable")
        out[f"NNM {int(mode) + 1}"] = (b.energy_J[order], b.freq_hz[order])
    return out


__all__ = [
    "NNMBranch",
    "nnm_branch",
    "hb_backbones",
    "grazing_amplitude",
    "harmonic_ratio",
    "hb_point_at_energy",
]


def hb_point_at_energy(
    res: NNMResidual, y_guess: np.ndarray, energy_J: float, *, tol: float = 1e-11
) -> np.ndarray:
    """The HB solution of ``res`` whose (mean) energy is ``energy_J``, from a nearby point.

    Newton on [R(y); (E(y) - E*) / E*] (square: the arclength row replaced by the energy),
    with the analytic dE/dy of :meth:`reduced.periodic.hb.NNMResidual.energy_gradient`.
    Raises :class:`reduced.periodic.hb.NewtonError` on failure. Used to compare HB with exact
    orbits at exactly the same energy, with no interpolation along the branch.
    """

    def fun(y):
        R, J = res(y)
        E = res.energy(y)
        return (
            np.concatenate([R, [(E - energy_J) / energy_J]]),
            np.vstack([J, res.energy_gradient(y) / energy_J]),
        )

    with single_thread_blas():
        return newton(fun, y_guess, tol=tol, max_iter=30).y
