"""Figures of the discrete-model stages (matplotlib, no screen needed)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bearingshaft.envelopes import N_COLUMNS, Envelope  # noqa: E402, F401 (Envelope: figures draw it)
from reduced.transient.spectrogram import Spectrogram, curve_in_time  # noqa: E402

CURVE_STYLES = ("-", "--", "-.", ":")
TITLE_CHARS = 95  # a title line of a 9 in wide figure at 10 pt
ENERGY_FLOOR = 1e-6  # the energy panel shows down to this fraction of the initial energy


def wrap_title(title: str, width: int = TITLE_CHARS) -> str:
    """The title broken into lines that fit the figure's width.

    Parameters
    ----------
    title : str
        The title.
    width : int
        Characters a line.

    Returns
    -------
    str
        Lines joined by newlines (words are not broken).
    """
    return "\n".join(textwrap.wrap(title, width=width, break_long_words=False, break_on_hyphens=False)) or title


def ringdown_envelopes(res, chunk_samples: int | None = None, also=None, loads=None) -> dict[str, Envelope]:
    """Envelopes of x (every DOF), E, W, the work of the loads W_ext and the energy-balance defect
    |E0 + W_ext - E - W| [J] from one pass over a run's chunks (a RingdownResult, a RingdownFile or
    anything with ``chunks``, ``n_samples``, ``sample_rate_hz``); with ``loads``
    (:class:`reduced.models.loads.Loads`) also each load's force p_l(t). ``also(chunk)`` is
    called on every chunk of that pass. ``env["scale"]`` is what the defect is divided by:
    max(E0, max E, max |W_ext|), so a run from rest has a relative balance too.

    Parameters
    ----------
    res : RingdownResult or RingdownFile
        The run (``system``, ``n_samples``, ``sample_rate_hz`` and ``chunks(chunk_samples)``).
    chunk_samples : int, optional
        Samples a chunk read.
    also : callable, optional
        ``also(chunk)`` called on every chunk.
    loads : Loads, optional
        The run's loads.

    Returns
    -------
    dict
        :class:`Envelope` per key: ``x`` (m, every DOF), ``E``, ``W``, ``balance`` (J), with
        loads ``Wext`` (J) and ``p`` (N, each load), with friction ``Wf`` (J, its part of W); plus
        ``E0`` (J, the first energy) and ``scale`` (J).
    """
    n, N, fs = res.system.n, res.n_samples, res.sample_rate_hz
    env = {"x": Envelope(N, fs, n), "E": Envelope(N, fs, 1), "W": Envelope(N, fs, 1), "balance": Envelope(N, fs, 1)}
    if loads is not None:
        env["Wext"] = Envelope(N, fs, 1)
        env["p"] = Envelope(N, fs, loads.n_loads)
    E0 = None
    scale = 0.0
    for c in res.chunks(chunk_samples):
        E = c.energy
        if E0 is None:
            E0 = float(E[0])
        ext = getattr(c, "external", None)
        ext = np.zeros_like(E) if ext is None else ext
        env["x"].add(c.start, c.x)
        env["E"].add(c.start, E)
        env["W"].add(c.start, c.dissipated)
        if getattr(c, "friction", None) is not None:  # a run with friction: its part of W
            env.setdefault("Wf", Envelope(N, fs, 1)).add(c.start, c.friction)
        env["balance"].add(c.start, np.abs(E0 + ext - E - c.dissipated))
        scale = max(scale, float(np.max(E)), float(np.max(np.abs(ext))))
        if loads is not None:
            env["Wext"].add(c.start, ext)
            env["p"].add(c.start, loads.values(c.t))
        if also is not None:
            also(c)
    env["E0"] = E0
    env["scale"] = max(scale, E0 or 0.0)
    return env


def ringdown_figure(res, path: Path, title: str, envelopes: dict | None = None, loads=None) -> None:
    """Displacements, energy and energy-balance error against time (min/max envelopes per pixel
    column, so a run of any length is drawn in bounded memory); with ``loads`` (a forced run) a
    first panel of the load forces and the work of the loads in the energy panel.

    Parameters
    ----------
    res : RingdownResult or RingdownFile
        The run (its system's DOF names label the lines).
    path : Path
        The image file.
    title : str
        The figure's title.
    envelopes : dict, optional
        :func:`ringdown_envelopes` of the run, if already made.
    loads : Loads, optional
        The run's loads (labels of the load panel).

    Returns
    -------
    None
    """
    env = envelopes or ringdown_envelopes(res, loads=loads)
    forced = "p" in env
    fig, axes = plt.subplots(3 + forced, 1, figsize=(9, 8 + 2 * forced), sharex=True, constrained_layout=True)
    if forced:
        t, y = env["p"].lines()
        for i, name in enumerate(loads.points if loads is not None else range(y.shape[1])):
            axes[0].plot(t, y[:, i], lw=0.8, label=f"load {i + 1} at {name}")
        axes[0].set_ylabel("load [N]")
        axes[0].legend(loc="upper right", fontsize=8)
    ax = axes[forced:]
    t, y = env["x"].lines()
    for i, name in enumerate(res.system.dof_names):
        ax[0].plot(t, y[:, i] * 1e3, lw=0.6, label=name)
    gap = float(np.max(res.system.offset, initial=0.0))
    if gap > 0:
        for s in (1, -1):
            ax[0].axhline(s * gap * 1e3, color="k", lw=0.5, ls=":")
    ax[0].set_ylabel("displacement [mm]")
    ax[0].legend(loc="upper right", ncol=min(len(res.system.dof_names), 6), fontsize=8)
    top = env["scale"] or 1.0
    floor = ENERGY_FLOOR * top
    curves = (("E", "E(t)"), ("W", "dissipated W(t)")) + ((("Wext", "work of the loads W_ext(t)"),) if forced else ())
    if "Wf" in env:
        curves += (("Wf", "friction W_f(t), part of W"),)
    for key, label in curves:
        t, y = env[key].lines()
        ax[1].semilogy(t, np.maximum(y[:, 0], 0.1 * floor), label=label)
    ax[1].set_ylim(floor, 2.0 * top)
    ax[1].set_ylabel("energy [J]")
    ax[1].legend(loc="center right")
    t, y = env["balance"].upper()
    ax[2].semilogy(t, y[:, 0] / top + 1e-18)
    ax[2].set_ylabel("|E0 + W_ext - E - W| / E_max" if forced else "|E0 - E - W| / E0")
    ax[2].set_xlabel("time [s]")
    axes[0].set_title(wrap_title(title), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def spectrogram_figure(
    spec: Spectrogram,
    energy_t: tuple[np.ndarray, np.ndarray],
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    path: Path,
    title: str,
    fmax_hz: float,
    db_range: float,
) -> None:
    """Spectrogram in dB with the NNM frequency-energy curves mapped onto time, f(E(t)).

    Parameters
    ----------
    spec : Spectrogram
        The spectrogram (power in m^2/Hz).
    energy_t : (ndarray, ndarray)
        s and J, the ringdown's energy against time.
    curves : dict of str to (ndarray, ndarray)
        Label -> (J, Hz), a frequency-energy curve.
    path : Path
        The image file.
    title : str
        The figure's title.
    fmax_hz : float
        Hz, top of the frequency axis.
    db_range : float
        dB drawn below the largest power.

    Returns
    -------
    None
    """
    fig, ax = plt.subplots(figsize=(9, 5.5), constrained_layout=True)
    keep = spec.freq_hz <= fmax_hz
    db = 10.0 * np.log10(np.maximum(spec.power[keep], 1e-300))
    top = float(np.max(db))
    mesh = ax.pcolormesh(spec.t, spec.freq_hz[keep], db, shading="nearest", cmap="viridis",
                         vmin=top - db_range, vmax=top, rasterized=True)
    fig.colorbar(mesh, ax=ax, label="PSD [dB re 1 m^2/Hz]")
    t_E, E = energy_t
    colors = ("w", "r", "orange", "magenta", "cyan", "yellow")
    for i, (label, (E_curve, f_curve)) in enumerate(curves.items()):
        f_t = curve_in_time(E, E_curve, f_curve)
        ax.plot(t_E, f_t, color=colors[i % len(colors)], ls=CURVE_STYLES[i % len(CURVE_STYLES)], lw=1.2,
                label=label)
    ax.set_ylim(0, fmax_hz)
    if spec.t.size > 1:
        ax.set_xlim(spec.t[0], spec.t[-1])
    ax.set_xlabel("time [s]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title(wrap_title(title), fontsize=10)
    if curves:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.6)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def symmetry_figure(points: Envelope, names: tuple[str, str], primary: str,
                    runs: dict[str, tuple[Envelope, float, float | None]], seeded: list[Envelope],
                    threshold_m: float, path: Path, title: str) -> None:
    """Top: the two points (envelopes) of the ``primary`` run. Bottom: |x_a - x_b| of each run
    (upper envelope), its solver tolerance (dotted) and break time (dashed), the seeded runs
    (grey) and the break threshold (black).

    Parameters
    ----------
    points : Envelope
        The two points of the ``primary`` run, m.
    names : (str, str)
        Names of the two points.
    primary : str
        The method of the run drawn on top.
    runs : dict of str to (Envelope, float, float or None)
        Method -> (|x_a - x_b| envelope in m, solver tolerance in m, break time in s or None).
    seeded : list of Envelope
        |x_a - x_b| of the seeded runs, m.
    threshold_m : float
        m, the break threshold.
    path : Path
        The image file.
    title : str
        The figure's title.

    Returns
    -------
    None
    """
    fig, ax = plt.subplots(2, 1, figsize=(9, 7), sharex=True, constrained_layout=True)
    t, y = points.lines()
    ax[0].plot(t, y[:, 0] * 1e3, lw=0.6, label=names[0])
    ax[0].plot(t, y[:, 1] * 1e3, lw=0.6, ls="--", label=names[1])
    ax[0].set_ylabel(f"displacement [mm] ({primary})")
    ax[0].legend(loc="upper right")
    for k, env in enumerate(seeded):
        t, y = env.upper()
        ax[1].semilogy(t, y[:, 0] + 1e-30, color="0.6", lw=0.6, label="seeded (exact)" if k == 0 else None)
    for i, (method, (env, tolerance, t_break)) in enumerate(runs.items()):
        color = f"C{i}"
        t, y = env.upper()
        ax[1].semilogy(t, y[:, 0] + 1e-30, color=color, lw=0.8, label=f"{method} (round-off)")
        ax[1].axhline(tolerance, color=color, lw=0.8, ls=":")
        if t_break is not None:
            for axis in ax:
                axis.axvline(t_break, color=color, ls="--", lw=1.0)
    ax[1].axhline(threshold_m, color="k", lw=0.8)
    ax[1].set_ylim(1e-22, None)
    ax[1].set_ylabel(f"|{names[0]} - {names[1]}| [m]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="lower right", fontsize=8,
                 title=f"dotted: solver tolerance; black: break at {threshold_m:g} m; dashed: break", title_fontsize=8)
    ax[0].set_title(wrap_title(title), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def nnm2_figure(E: np.ndarray, f_exact: np.ndarray, f_paper: np.ndarray, checks: list[dict],
                f_open: np.ndarray, f_closed: np.ndarray, path: Path) -> None:
    """Frequency-energy curve of NNM 2: exact, the paper's Eq. 13, integrated periods.

    Parameters
    ----------
    E : (k,) ndarray of float
        J, the energies of the curves.
    f_exact, f_paper : (k,) ndarray of float
        Hz, the exact relation and the paper's printed one at E.
    checks : list of dict
        ``energy_J`` and ``freq_integrated_hz`` of each integrated period.
    f_open, f_closed : ndarray of float
        Hz, the linear open- and closed-gap frequencies (dotted lines).
    path : Path
        The image file.

    Returns
    -------
    None
    """
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    ax.semilogx(E, f_exact, "k-", label="exact (this work)")
    ax.semilogx(E, f_paper, "r--", label="paper's Eq. 12-14 as printed")
    if checks:
        ax.semilogx([c["energy_J"] for c in checks], [c["freq_integrated_hz"] for c in checks], "o",
                    mfc="none", color="C0", label="DOP853 on Eq. 9 (period)")
    for f in f_open:
        ax.axhline(f, color="k", ls=":", lw=0.6)
    for f in f_closed:
        ax.axhline(f, color="r", ls=":", lw=0.6)
    ax.set_ylim(0, 1.1 * max(f_exact.max(), f_closed[1] if len(f_closed) > 1 else 0))
    ax.set_xlabel("energy [J]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title("NNM 2 frequency-energy relation (dotted: open (black) / closed (red) linear modes)")
    ax.legend(loc="upper left")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def work_precision_figure(rows: list[dict], order: float, path: Path, window_s: float) -> None:
    """Error against run time for each method.

    Parameters
    ----------
    rows : list of dict
        :func:`reduced.studies.work_precision` rows.
    order : float
        The explicit method's fitted order.
    path : Path
        The image file.
    window_s : float
        s, the run's window (in the title).

    Returns
    -------
    None
    """
    fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    markers = {"exact": "*", "explicit": "o", "dop853": "s"}
    for i, method in enumerate(("exact", "explicit", "dop853")):
        pts = [r for r in rows if r["method"] == method]
        if not pts:
            continue
        label = method + (f" (observed order {order:.2f})" if method == "explicit" else "")
        ax.loglog([r["runtime_s"] for r in pts], [max(r["error"], 1e-17) for r in pts],
                  marker=markers[method], ms=9 if method == "exact" else 6, color=f"C{i}", label=label)
        for r in pts:
            ax.annotate(str(r["setting"]), (r["runtime_s"], max(r["error"], 1e-17)), fontsize=6,
                        xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("run time [s] (best of repeats)")
    ax.set_ylabel("max |x - x_ref| / max |x_ref|")
    ax.set_title(f"Work-precision, discrete-impulse, window 0-{window_s:g} s")
    ax.legend()
    ax.grid(True, which="both", lw=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def rom_convergence_figure(rows: list[dict], path: Path, window_s: float) -> None:
    """Reduced model against its mode count: errors vs modes, and ringdown error vs run time.

    Parameters
    ----------
    rows : list of dict
        :func:`reduced.studies.rom_convergence` rows, mode counts ascending (the last the reference).
    path : Path
        The image file.
    window_s : float
        s, the ringdown's window (in a label).

    Returns
    -------
    None
    """
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    n = [r["n_modes"] for r in rows]
    floor = 1e-17  # the reference's own ringdown error is zero: draw it at the floor
    for key, label, style in (("open_freq_error", "open-gap frequencies", "o-"),
                              ("closed_freq_error", "closed-gap frequencies", "s-"),
                              ("ringdown_error", f"ringdown at x1, x2, x3 (vs {n[-1]} modes)", "*-")):
        a.loglog(n[:-1] if key == "ringdown_error" else n,
                 [max(r[key], floor) for r in (rows[:-1] if key == "ringdown_error" else rows)], style, label=label)
    a.set_xlabel("fixed-interface modes")
    a.set_ylabel("relative error")
    a.set_title("Reduced model against its number of modes")
    a.legend()
    a.grid(True, which="both", lw=0.3)
    for key, label, marker in (("exact_s", "exact integrator", "*"), ("explicit_s", "explicit (omega_max dt = 0.05)",
                                                                        "o")):
        err = "ringdown_error" if key == "exact_s" else "explicit_ringdown_error"
        b.loglog([r[key] for r in rows[:-1]], [max(r[err], floor) for r in rows[:-1]], marker=marker, label=label)
        for r in rows[:-1]:
            b.annotate(str(r["n_modes"]), (r[key], max(r[err], floor)), fontsize=7, xytext=(3, 3),
                       textcoords="offset points")
    b.set_xlabel(f"ringdown run time over 0-{window_s:g} s [s] (best of repeats)")
    b.set_ylabel(f"ringdown error against {n[-1]} modes")
    b.set_title("Error against run time (labels: modes)")
    b.legend()
    b.grid(True, which="both", lw=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)
