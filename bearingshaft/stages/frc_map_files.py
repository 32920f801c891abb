"""The response map's files (part of stage ``frc``), from :attr:`FRCResult.response_maps`; no solver runs here.

``response_map.csv``: one row per level, direction and frequency (in sweep order): the regime
(periodic, subharmonic, quasi_periodic, chaotic), its period in forcing periods (0 when not
periodic), the largest Lyapunov exponent (1/s: log max |mu| / (p T) of the orbit when periodic,
the tangent's time average otherwise) with the tolerance it was judged against, the statistics of
the per-period max |x1| over the recorded periods (min, mean, max: the envelope a test measures),
the asymmetry max |x1 - x3| / max(|x1|, |x3|), whether the sweep jumped on arriving there, and the
diagnostics (max |mu|, settled, contact, broadband, periods run), and ``after_chaos``: whether an earlier
frequency of the sweep was chaotic, quasi-periodic or unsettled (the sweep then arrives with a state
round-off sets: the reproduction report does not require what follows to reproduce).
``response_map_jumps.csv``: the jumps, each with the regimes and mean amplitudes on both sides (and
``after_chaos``). ``response_map.png``: per level, the
brute-force bifurcation diagram (Poincare samples of x1 against frequency, up and down) under the
level's drawn curve (:func:`bearingshaft.stages.frc_files.drawn_curves`: HB where it no longer moves with H,
else the exact flow's families; stable solid, unstable dashed; never an unconverged HB curve in contact)
with the shooting orbits and the measured envelope.
``response_map_spectra.png``: the order spectrum of x1 at every frequency of each sweep (response
frequency over excitation frequency, power fraction in dB): lines at the integers for a periodic
response, at multiples of 1/p for a subharmonic of period p, a continuum for chaos.
"""

from __future__ import annotations

import textwrap

import numpy as np

from bearingshaft.digits import sig
from bearingshaft.output import write_rows
from bearingshaft.stages.frc_plot import draw_curve
from bearingshaft.stages.frc_results import FRCResult

DIGITS = 10  # significant digits of frequencies and amplitudes
EXP_DIGITS = 4  # exponents, tolerances, ratios
MAP_FIELDS = ["level", "direction", "freq_hz", "regime", "period_k", "lyapunov_per_s", "x1_min_m", "x1_mean_m",
              "x1_max_m", "asymmetry", "jump", "lyapunov_tol_per_s", "max_abs_mu", "settled", "contact", "broadband",
              "n_periods", "after_chaos"]
JUMP_FIELDS = ["level", "direction", "from_hz", "freq_hz", "from_regime", "to_regime", "x1_mean_before_m",
               "x1_mean_after_m", "after_chaos"]
UNPREDICTABLE = ("chaotic", "quasi_periodic")  # regimes after which a sweep's state is set by round-off
REGIME_COLORS = {"periodic": "C0", "subharmonic": "C2", "quasi_periodic": "C4", "chaotic": "C3"}


def write(result: FRCResult, writer, stats: dict, drawn: dict) -> None:
    """Write the response map's files and put its statistics in ``stats["response_map"]`` (nothing
    without a map).

    Parameters
    ----------
    result : FRCResult
        What :func:`bearingshaft.stages.frc.compute` returned.
    writer : StageWriter
        Where the files go.
    stats : dict
        The frc stage's statistics (for provenance.json).
    drawn : dict
        P -> the level's drawn curve (:func:`bearingshaft.stages.frc_files.drawn_curves`), drawn over the map.
    """
    maps = getattr(result, "response_maps", {}) or {}
    if not maps:
        return
    col = x1_column(result)
    stats["response_map"] = write_tables(maps, writer, col)
    _plot_map(writer.path("response_map.png"), result, col, drawn)
    _plot_spectra(writer.path("response_map_spectra.png"), result)


def write_tables(maps: dict, writer, col: int) -> dict:
    """response_map.csv and response_map_jumps.csv of every level's sweeps; their statistics (for
    provenance.json), keyed "<P> N <direction>".

    Parameters
    ----------
    maps : dict
        P -> the level's MapLevel (its ``sweeps``: direction -> ResponseMap).
    writer : StageWriter
        Where the files go.
    col : int
        The column of x1 among the monitored points.

    Returns
    -------
    dict
    """
    rows, jumps, st = [], [], {}
    for P, lvl in maps.items():
        for d, rm in lvl.sweeps.items():
            r, j = _sweep_rows(P, d, rm, col)
            rows += r
            jumps += j
            st[f"{P:g} N {d}"] = _sweep_stats(rm, lvl)
    write_rows(writer.path("response_map.csv"), rows, fields=MAP_FIELDS)
    write_rows(writer.path("response_map_jumps.csv"), jumps, fields=JUMP_FIELDS)
    return st


def x1_column(result: FRCResult) -> int:
    """The column of x1 among the output points (the response map's point), else the first; of any stage result
    with ``names`` (the friction stage's too).

    Parameters
    ----------
    result : FRCResult
        The stage's result.

    Returns
    -------
    int
    """
    return result.names.index("x1") if "x1" in result.names else 0


def _bool(v) -> str:
    return "true" if v else "false"


def _sweep_rows(P: float, direction: str, rm, col: int) -> tuple[list[dict], list[dict]]:
    """(response_map.csv rows, response_map_jumps.csv rows) of one sweep."""
    rows, jumps = [], []
    after = False  # an earlier frequency of this sweep was chaotic, quasi-periodic or unsettled
    for k, (f, pt) in enumerate(zip(rm.freq_hz, rm.points, strict=True)):
        pk = pt.peak[:, col]
        rows.append({"level": P, "direction": direction, "freq_hz": sig(f, DIGITS), "regime": pt.regime,
                     "period_k": pt.period_k, "lyapunov_per_s": sig(pt.lyapunov_per_s, EXP_DIGITS),
                     "x1_min_m": sig(pk.min(), DIGITS), "x1_mean_m": sig(pk.mean(), DIGITS),
                     "x1_max_m": sig(pk.max(), DIGITS), "asymmetry": sig(pt.asymmetry, EXP_DIGITS),
                     "jump": _bool(rm.jump[k]), "lyapunov_tol_per_s": sig(pt.lyapunov_tol, EXP_DIGITS),
                     "max_abs_mu": "" if not np.isfinite(pt.max_abs_mu) else sig(pt.max_abs_mu, DIGITS),
                     "settled": _bool(pt.settled), "contact": _bool(pt.contact),
                     "broadband": sig(pt.broadband, EXP_DIGITS), "n_periods": pt.n_periods,
                     "after_chaos": _bool(after)})
        if rm.jump[k]:
            before = rm.points[k - 1]
            jumps.append({"level": P, "direction": direction, "from_hz": sig(rm.freq_hz[k - 1], DIGITS),
                          "freq_hz": sig(f, DIGITS), "from_regime": _label(before), "to_regime": _label(pt),
                          "x1_mean_before_m": sig(before.peak[:, col].mean(), DIGITS),
                          "x1_mean_after_m": sig(pk.mean(), DIGITS), "after_chaos": _bool(after)})
        after = after or pt.regime in UNPREDICTABLE or not pt.settled
    return rows, jumps


def _label(pt) -> str:
    """``periodic``, ``subharmonic 3``, ``chaotic`` ...

    >>> from types import SimpleNamespace as N
    >>> _label(N(regime="subharmonic", period_k=3)), _label(N(regime="chaotic", period_k=0))
    ('subharmonic 3', 'chaotic')
    """
    return f"{pt.regime} {pt.period_k}" if pt.regime == "subharmonic" else pt.regime


def _sweep_stats(rm, lvl) -> dict:
    """Counts per regime, the jump frequencies, the exponent range, unsettled points, the bands and wall time."""
    regimes = [p.regime for p in rm.points]
    lam = rm.lyapunov_per_s
    return {"frequencies": int(rm.freq_hz.size), **{r: regimes.count(r) for r in REGIME_COLORS},
            "unsettled": int(sum(not p.settled for p in rm.points)),
            "jump_hz": [round(float(f), 6) for f in rm.jump_hz],
            "max_lyapunov_per_s": round(float(np.max(lam)), 4),
            "bands_hz": [[round(a, 4), round(b, 4)] for a, b in lvl.bands],
            "wall_s": round(float(np.sum(rm.wall_s)), 3)}


# -- the figure ---------------------------------------------------------------------------------------
def _zoom(lvl, spec) -> tuple[float, float] | None:
    """Hz, the span shown: the bands and every frequency a sweep found in contact, +-5 %; None without."""
    fs = [f for a, b in lvl.bands for f in (a, b)]
    for rm in lvl.sweeps.values():
        fs += [f for f, p in zip(rm.freq_hz, rm.points, strict=True) if p.contact]
    if not fs:
        return None
    return max(min(fs) / 1.05, spec.freq_min_hz), min(max(fs) * 1.05, spec.freq_max_hz)


def _plot_curves(ax, result: FRCResult, P: float, col: int, curve) -> None:
    """The level's drawn curve (stable solid, unstable dashed) and the shooting orbits (open: unstable)."""
    if curve is not None and not isinstance(curve, Exception):
        draw_curve(ax, curve, col, "k", 0.8, label="periodic orbits (the drawn curve)")
    for r in result.checks.get(P, []):
        if r.shoot_amp is not None:
            ax.plot(r.freq_hz, r.shoot_amp[col], "s", ms=5, mec="k", mfc="k" if r.shoot_stable else "none",
                    label="exact orbit (shooting)")


def _plot_families(axs, result: FRCResult, P: float, col: int) -> None:
    """The level's exact families over the bifurcation diagram (bottom): their Poincare samples, x at t = j T for
    j < k of a k T orbit (the nodes at those times), stable solid black, unstable thin grey; and the families of
    unstable periodic orbits found from the chaotic stepped sine's close returns (kind ``close_return``,
    :mod:`reduced.periodic.uncovered`) in magenta, their amplitude on the top panel too."""
    cc = result.converged.get(P)
    ex = cc.exact if cc is not None else None
    for fam in (ex.families if ex is not None else ()):
        S = fam.nodes.shape[1] // fam.periods
        n = fam.nodes.shape[2] // 2
        if fam.kind != "close_return":  # every other family's Poincare samples, stable ones solid
            for piece in fam.pieces():
                for j in range(fam.periods):
                    x = fam.nodes[piece, j * S, :n] @ ex.point_rows[col]
                    for keep, style in ((~fam.stable[piece], dict(color="0.35", lw=0.6,
                                                                  label="unstable periodic orbits (families)")),
                                        (fam.stable[piece], dict(color="k", lw=1.4,
                                                                 label="stable periodic orbits (families)"))):
                        if keep.any():
                            axs[1].plot(fam.freq_hz[piece], np.where(keep, x, np.nan), "-", zorder=5, **style)
            continue
        lab = f"unstable {fam.periods} T orbits (close returns)"
        axs[0].plot(fam.freq_hz, fam.amplitude_m[:, col], "-", color="m", lw=1.8, label=lab, zorder=6)
        for j in range(fam.periods):  # on top of the chaotic samples they are embedded in
            axs[1].plot(fam.freq_hz, fam.nodes[:, j * S, :n] @ ex.point_rows[col], "-", color="m", lw=1.8,
                        label=lab, zorder=6)


def _plot_level(axs, result: FRCResult, P: float, lvl, col: int, curve) -> None:
    """Top: the drawn curve, the shooting orbits and the measured envelope of each sweep; bottom: the Poincare
    samples."""
    top, bot = axs
    _plot_curves(top, result, P, col, curve)
    _plot_families(axs, result, P, col)
    for d, rm in lvl.sweeps.items():
        st = rm.peak_stats(col)
        order = np.argsort(rm.freq_hz)
        shade = "C1" if d == "up" else "C9"
        top.fill_between(rm.freq_hz[order], st[order, 0], st[order, 2], color=shade, alpha=0.25, lw=0,
                         label=f"envelope {d} (per-period max |x1|, min to max)")
        for reg, c in REGIME_COLORS.items():
            m = np.array([p.regime == reg for p in rm.points])
            if m.any():
                top.plot(rm.freq_hz[m], st[m, 1], "^" if d == "up" else "v", ms=3, color=c, mew=0,
                         label=f"{reg} (mean)")
                f = np.concatenate([np.full(len(p.poincare), fk) for fk, p in zip(rm.freq_hz[m],
                                    [p for p in rm.points if p.regime == reg], strict=True)])
                x = np.concatenate([p.poincare[:, col] for p in rm.points if p.regime == reg])
                bot.plot(f, x, "." if d == "up" else "x", ms=1.5, color=c, alpha=0.6, mew=0.4, label=f"{reg} ({d})")
        bot.plot(rm.jump_hz, np.zeros(rm.jump_hz.size), "|", ms=14, color=shade, label=f"jump ({d})")
    top.set_ylabel("max |x1| over a period [m]")
    bot.set_ylabel("x1 at t = k T (Poincare) [m]")
    bot.set_xlabel("excitation frequency [Hz]")
    curve_label = "" if curve is None or isinstance(curve, Exception) else \
        f": {getattr(curve, 'label', None) or f'HB H={curve.H}'}"
    top.set_title(textwrap.fill(f"{P:g} N{curve_label}", 64), fontsize=8)
    for ax in axs:
        ax.grid(True, alpha=0.2)


def _plot_map(path, result: FRCResult, col: int, drawn: dict) -> None:
    """response_map.png: one column per level (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = result.response_maps
    fig, axs = plt.subplots(2, len(maps), figsize=(5.6 * len(maps) + 2.4, 8.0), squeeze=False, sharex="col")
    for c, (P, lvl) in enumerate(maps.items()):
        _plot_level((axs[0][c], axs[1][c]), result, P, lvl, col, drawn.get(P))
        zoom = _zoom(lvl, result.spec)
        if zoom is None:
            axs[0][c].set_xscale("log")
            axs[0][c].set_yscale("log")
        else:
            axs[0][c].set_xlim(*zoom)
    for row in axs:  # one legend per row, from every level's entries
        uniq = {}
        for ax in row:
            handles, labels = ax.get_legend_handles_labels()
            uniq.update(zip(labels, handles, strict=True))
        # beside the last panel, not over it: in contact the data fill every corner of the panels
        row[-1].legend(uniq.values(), uniq.keys(), fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                       borderaxespad=0.0, markerscale=2)
    fig.suptitle(_title(f"{result.scene_name}: response map under a load at {result.spec.point} (stepped sine by "
                        "the exact flow, up and down; regimes by Poincare samples and the largest Lyapunov exponent)",
                        len(maps)), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _title(text: str, columns: int) -> str:
    """The title in lines of about 60 characters per column of panels."""
    return "\n".join(textwrap.wrap(text, width=60 * columns + 20))


def _edges(f: np.ndarray) -> np.ndarray:
    """Cell edges around increasing centres f (midpoints; the ends mirrored).

    >>> _edges(np.array([1.0, 2.0, 4.0])).tolist()
    [0.5, 1.5, 3.0, 5.0]
    """
    mid = 0.5 * (f[1:] + f[:-1])
    return np.concatenate([[f[0] - (mid[0] - f[0])], mid, [f[-1] + (f[-1] - mid[-1])]])


def _plot_spectra(path, result: FRCResult) -> None:
    """response_map_spectra.png: per level (columns) and sweep (rows), the order spectrum of x1 against the
    excitation frequency, in dB of the power fraction (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = result.response_maps
    fig, axs = plt.subplots(2, len(maps), figsize=(5.6 * len(maps) + 1.0, 7.0), squeeze=False, layout="constrained")
    im = None
    for c, (P, lvl) in enumerate(maps.items()):
        zoom = _zoom(lvl, result.spec)
        for r, d in enumerate(("up", "down")):
            ax = axs[r][c]
            rm = lvl.sweeps.get(d)
            if rm is None:
                continue
            order = np.argsort(rm.freq_hz)
            f = rm.freq_hz[order]
            S = np.array([rm.points[i].spectrum for i in order], float)
            orders = rm.spectrum_orders
            db = 10.0 * np.log10(np.maximum(S, 1e-12)).T
            im = ax.pcolormesh(_edges(f), _edges(orders), db, vmin=-80.0, vmax=0.0, cmap="magma", shading="flat")
            if zoom is None:
                ax.set_xscale("log")
            else:
                ax.set_xlim(*zoom)
            ax.set_title(f"{P:g} N, sweep {d}", fontsize=9)
            ax.set_xlabel("excitation frequency [Hz]")
            ax.set_ylabel("response frequency / excitation frequency")
    if im is not None:
        fig.colorbar(im, ax=axs, shrink=0.6, label="power fraction of x1 [dB]")
    fig.suptitle(_title(f"{result.scene_name}: order spectra of x1 over the recorded periods (lines: periodic or "
                        "subharmonic; a continuum: chaos)", len(maps)), fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)

