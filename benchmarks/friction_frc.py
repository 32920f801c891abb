"""Forced-response curves with friction by harmonic balance (issue 27): the Jenkins element by AFT.

    PYTHONPATH=. python benchmarks/friction_frc.py [--out results/friction-frc] [--H 31] [--samples 2048]

The system: the Coulomb oscillator of tests/test_friction.py, a mass m = 1 kg on a spring k = 1e4 N/m
(15.9 Hz, c = 2 N s/m) rubbing on a contact pressed into its stop (N = 9.90 N held by the stop, mu = 0.3,
F = mu N = 2.97 N, k_t = 1e6 N/m), driven along x by P cos(2 pi f t). At P = 4 N the mass sticks for part of
each period (stick-slip). Den Hartog's regime (continuous slip) is checked apart: P = 10 N on the undamped
oscillator with k_t = 1e3 k (near Coulomb's law), HB at fixed frequencies against his closed form.

Each curve is :func:`reduced.periodic.friction_aft.friction_frc` (condensed HB, the stop projected exactly,
the slider by AFT over two periods, its stability by Hill's method on the consistent Jacobian). It is checked
against the exact integrator's settled orbit (from rest, ``SETTLE_PERIODS`` periods, the amplitude of the
last) at a few frequencies.

Writes friction_frc.csv (level_N, freq_hz, amplitude_m, stick_fraction, slip_fraction, max_multiplier,
stable), friction_frc_checks.csv (level_N, freq_hz, hb_m, exact_m, rel_error, settled_change),
friction_frc_den_hartog.csv (level_N, freq_hz, hb_m, den_hartog_m, rel_error, no_friction_m),
friction_frc_machine.csv and friction_frc.png.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import machine_rows, write_rows  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.models.gaps import Friction, GapSystem  # noqa: E402
from reduced.models.loads import Harmonic, Loads  # noqa: E402
from reduced.periodic.exact_hb import default_root_samples  # noqa: E402
from reduced.periodic.frc import linear_frf, max_abs_over_period, solution_at_frequency  # noqa: E402
from reduced.periodic.friction_aft import FrictionBalance, den_hartog_amplitude, friction_frc  # noqa: E402
from reduced.periodic.hb import newton  # noqa: E402
from reduced.transient.friction import integrate_exact_friction  # noqa: E402

M_X, K_X, C_X, M_Z, K_Z, K_G, DELTA = 1.0, 1.0e4, 2.0, 0.5, 1.0e5, 1.0e7, 1.0e-4  # the oscillator (SI)
MU, K_T = 0.3, 1.0e6  # Coulomb coefficient, N/m tangential stiffness
Z_REST = -K_G * DELTA / (K_G + K_Z)  # m, the normal coordinate at rest
N_REST = K_G * (Z_REST + DELTA)  # N, 9.90
LEVELS_N = (4.0,)  # stick-slip (F / P = 0.74)
DEN_HARTOG_N = 10.0  # continuous slip (F / P = 0.30), undamped, k_t = 1e3 k: Den Hartog's closed form
DEN_HARTOG_HZ = (8.0, 11.0, 20.0, 25.0, 30.0)
BAND_HZ = (10.0, 40.0)
CHECK_HZ = (11.0, 13.0, 15.0, 18.0, 25.0)
SETTLE_PERIODS = 60  # from rest; the last period's amplitude is read
SAMPLES_PER_PERIOD = 2000  # of the exact run's output


def oscillator() -> GapSystem:
    """The Coulomb oscillator (module docstring): x tangential, z normal, pressed into its stop."""
    return GapSystem(M=np.diag([M_X, M_Z]), C=np.diag([C_X, 0.0]), K=np.diag([K_X, K_Z]), B=np.array([[0.0, 1.0]]),
                     k=np.array([K_G]), offset=np.array([-DELTA]), side=np.array([1.0]), tip=np.array([0]),
                     dof_names=("x", "z"), stop_names=("n",),
                     friction=Friction(Bt=np.array([[1.0, 0.0]]), tip=[0], k_t=K_T, mu=MU, names=("t",)))


def settled(system: GapSystem, P: float, f: float) -> tuple[float, float]:
    """(m, relative change over the last period) of the exact orbit's amplitude of x after SETTLE_PERIODS."""
    spp = SAMPLES_PER_PERIOD
    run = integrate_exact_friction(system, np.array([0.0, Z_REST]), np.zeros(2), SETTLE_PERIODS / f, spp * f,
                                   loads=Loads(np.array([[1.0, 0.0]]), (Harmonic(P, f),)))
    last = float(np.abs(run.x[-spp - 1:, 0]).max())
    before = float(np.abs(run.x[-2 * spp - 1:-spp, 0]).max())
    return last, abs(last / before - 1.0)


def den_hartog_rows(H: int, samples: int) -> list[dict]:
    """HB of the undamped oscillator with k_t = 1e3 k at DEN_HARTOG_N, by Newton at fixed frequencies from the
    linear response, against Den Hartog's closed form (continuous slip)."""
    s = replace(oscillator(), C=np.zeros((2, 2)),
                friction=Friction(Bt=np.array([[1.0, 0.0]]), tip=[0], k_t=1e3 * K_X, mu=MU, names=("t",)))
    fb = FrictionBalance(s, np.array([1.0, 0.0]), DEN_HARTOG_N, 0.0, H, default_root_samples(H), False, None, samples)
    out = []
    for f in DEN_HARTOG_HZ:
        w = 2 * np.pi * f
        z = fb.linear_z(w)
        z[1] = Z_REST
        x_ref = float(np.max(np.abs(z)))

        def fun(v, w=w, x_ref=x_ref):
            R, J, _ = fb.residual(v * x_ref, w)
            return R / x_ref, J

        with single_thread_blas():
            zs = newton(fun, z / x_ref, tol=1e-12, max_iter=100).y * x_ref
        hb = float(max_abs_over_period(fb.response(zs, w), np.eye(2))[0])
        dh = den_hartog_amplitude(M_X, K_X, DEN_HARTOG_N, MU * N_REST, w)
        out.append({"level_N": DEN_HARTOG_N, "freq_hz": f, "hb_m": hb, "den_hartog_m": dh, "rel_error": hb / dh - 1,
                    "no_friction_m": DEN_HARTOG_N / abs(K_X - M_X * w * w)})
        print(f"   Den Hartog {f:5.1f} Hz: HB {hb:.6e} m, closed form {dh:.6e} m ({hb / dh - 1:+.2e})")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(ROOT / "results" / "friction-frc"))
    ap.add_argument("--H", type=int, default=31)
    ap.add_argument("--samples", type=int, default=2048)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    s = oscillator()
    rows, checks, curves = [], [], {}
    t_all = time.perf_counter()
    for P in LEVELS_N:
        t0 = time.perf_counter()
        with single_thread_blas():
            br = friction_frc(s, [1.0, 0.0], P, *BAND_HZ, args.H, samples=args.samples, x_ref=1e-4, max_steps=2000)
        wall = time.perf_counter() - t0
        curves[P] = br
        fb = br.balance
        print(f"P = {P:g} N: {len(br.freq_hz)} points, {wall:.1f} s ({br.stability_wall_s:.1f} s Hill), "
              f"status {br.status}, bifurcations {br.bifurcations}")
        for i in range(len(br.freq_hz)):
            st = fb.slider_state(br.z[i])[0]
            rows.append({"level_N": P, "freq_hz": br.freq_hz[i], "amplitude_m": br.amplitude_m[i, 0],
                         "stick_fraction": st[1], "slip_fraction": st[2],
                         "max_multiplier": float(np.abs(br.multipliers[i, 0])), "stable": bool(br.stable[i])})
        for f in CHECK_HZ:
            with single_thread_blas():
                amp, _, _ = solution_at_frequency(br, f, stable_only=False)
            exact, change = settled(s, P, f)
            hb = float(amp[0]) if amp is not None else float("nan")
            checks.append({"level_N": P, "freq_hz": f, "hb_m": hb, "exact_m": exact, "rel_error": hb / exact - 1.0,
                           "settled_change": change})
            print(f"   {f:5.1f} Hz: HB {hb:.6e} m, exact {exact:.6e} m ({hb / exact - 1:+.2e})")
    dh_rows = den_hartog_rows(args.H, args.samples)
    write_rows(out / "friction_frc.csv", rows)
    write_rows(out / "friction_frc_checks.csv", checks)
    write_rows(out / "friction_frc_den_hartog.csv", dh_rows)
    write_rows(out / "friction_frc_machine.csv", machine_rows(H=args.H, samples=args.samples))
    _plot(out / "friction_frc.png", s, curves, checks)
    print(f"total {time.perf_counter() - t_all:.1f} s; wrote {out}")
    return 0


def _plot(path: Path, s: GapSystem, curves: dict, checks: list) -> None:
    """The curves (stable solid, unstable dotted), the frictionless FRF, the exact points and Den Hartog."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    f = np.linspace(*BAND_HZ, 600)
    for k, (P, br) in enumerate(curves.items()):
        color = f"C{k}"
        a = br.amplitude_m[:, 0] * 1e3
        ax.plot(br.freq_hz, np.where(br.stable, a, np.nan), "-", color=color, label=f"HB, P = {P:g} N")
        ax.plot(br.freq_hz, np.where(br.stable, np.nan, a), ":", color=color)
        ax.plot(f, linear_frf(s.with_friction(None), [1.0, 0.0], P, f)[:, 0] * 1e3, "--", color=color, lw=0.7,
                label=f"no friction, P = {P:g} N")
        pts = [c for c in checks if c["level_N"] == P]
        ax.plot([c["freq_hz"] for c in pts], [c["exact_m"] * 1e3 for c in pts], "o", color=color, mfc="none",
                label=f"exact settled orbit, P = {P:g} N")
    ax.set_xlabel("excitation frequency (Hz)")
    ax.set_ylabel("max |x| (mm)")
    ax.set_yscale("log")
    ax.set_title(f"Coulomb oscillator with a Jenkins slider (mu N = {MU * N_REST:.2f} N): HB by AFT")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
