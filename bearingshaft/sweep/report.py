"""Figures of a sweep (issue 13): a metric against one varied key, maps over two, and the
symmetry-break time against energy beside the NNM stability ranges. Draws only: every number
comes in the rows and the overlay (:mod:`bearingshaft.sweep.metrics`); no solver runs here.

``sweep.png``: one panel per plotted metric (``[sweep] plots``, default the DEFAULT_PLOTS a
stage wrote). With one varied key (or ``[sweep] x``, a metric column such as
``energy_J_initial``) each panel is the metric against it; with two keys of a grid design
each panel is a map over the grid (grey: no value, e.g. a decay not reached in the run);
with two keys of a zip or random design, the cases as coloured points. With
``overlay = "nnm_stability"`` the Floquet multipliers of NNM 1 and NNM 3 over the swept
energies (:func:`bearingshaft.sweep.metrics.nnm_stability`) are drawn in
``symmetry_break.png`` beside the break times.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bearingshaft.plots import wrap_title  # noqa: E402
from bearingshaft.sweep.plan import base_value  # noqa: E402

DEFAULT_PLOTS = ("freq_early_hz", "freq_middle_hz", "freq_late_hz", "decay_time_s", "gaps_open_after_s", "impacts",
                 "peak_tip_force_N", "t_break_s", "energy_at_break_J")
MAX_PANELS = 9
LOG_SPAN = 100.0  # an axis is drawn on a log scale when its positive values span more than this factor
# the NNM instability ranges: (NNM, eigenvector of the largest multiplier) -> colour
COLOURS = {(1, "antisymmetric"): "tab:red", (1, "symmetric"): "tab:orange",
           (3, "antisymmetric"): "tab:purple", (3, "symmetric"): "tab:pink"}


def _finite(values) -> np.ndarray:
    a = np.array([np.nan if v is None else v for v in values], float)
    return a[np.isfinite(a)]


def _is_log(values, hint: bool = False) -> bool:
    """Whether an axis of these values is drawn on a log scale.

    >>> _is_log([1.0, 1e3]), _is_log([1.0, 10.0]), _is_log([1.0, 10.0], hint=True), _is_log([-1.0, 1e3])
    (True, False, True, False)
    """
    a = _finite(values)
    return bool(a.size and np.all(a > 0) and (hint or a.max() / a.min() > LOG_SPAN))


def plotted_metrics(spec, rows: list[dict]) -> list[str]:
    """The metric columns to draw.

    Parameters
    ----------
    spec : the sweep's design (its ``plots`` and varied keys)
    rows : the ok cases' rows

    Returns
    -------
    ``[sweep] plots`` if given, else the DEFAULT_PLOTS that hold a number (else a stage's first
    numbers), at most MAX_PANELS.
    """
    names = list(spec.plots) or [m for m in DEFAULT_PLOTS if any(
        isinstance(r.get(m), (int, float)) and math.isfinite(r[m]) for r in rows)]
    if not names:  # stages without a default: their first numbers
        keys = {v.key for v in spec.vary}
        for r in rows:
            names += [k for k, v in r.items() if k not in keys and k not in names and k != "run_time_s"
                      and isinstance(v, (int, float)) and not isinstance(v, bool)]
    return names[:MAX_PANELS]


def _label(name: str) -> str:
    return name.replace("_", " ")


def write_plots(plan, result) -> list[str]:
    """The sweep's figures in ``result.out``.

    Parameters
    ----------
    plan : the :class:`~bearingshaft.sweep.plan.SweepPlan`
    result : the :class:`~bearingshaft.sweep.tables.SweepResult` (rows and overlay)

    Returns
    -------
    The names written: ``sweep.png`` (when a metric can be drawn against one key or over two),
    ``symmetry_break.png`` (with the NNM stability overlay).
    """
    rows = [r for r in result.rows if r.get("status") == "ok"]
    spec = plan.spec
    if not rows:
        return []
    files = []
    metrics = plotted_metrics(spec, rows)
    keys = [v.key for v in spec.vary]
    title = f"{plan.scene.name}: {len(rows)} cases ({spec.design} over {', '.join(keys)})"
    base = [base_value(plan.scene, k) for k in keys]  # the scene's own values: marked on the plots
    base = [b if isinstance(b, (int, float)) and not isinstance(b, bool) else None for b in base]
    if metrics and (len(keys) == 1 or spec.x):
        xkey = spec.x or keys[0]
        log_hint = spec.vary[0].log if not spec.x else False
        _lines(rows, xkey, metrics, result.out / "sweep.png", title, _is_log([r.get(xkey) for r in rows], log_hint),
               None if spec.x else base[0])
        files.append("sweep.png")
    elif metrics and len(keys) == 2:
        _maps(rows, spec, metrics, result.out / "sweep.png", title, base)
        files.append("sweep.png")
    if result.stability is not None:
        symmetry_break_figure(plan, rows, result.stability, result.out)
        files.append("symmetry_break.png")
    return files


def _grid(n: int) -> tuple[int, int]:
    """(rows, columns) of a figure of n panels, at most 3 columns.

    >>> _grid(1), _grid(4), _grid(9)
    ((1, 1), (2, 3), (3, 3))
    """
    cols = min(3, n)
    return -(-n // cols), cols


def _lines(rows, xkey, metrics, path: Path, title: str, logx: bool, base=None) -> None:
    nr, nc = _grid(len(metrics))
    fig, axes = plt.subplots(nr, nc, figsize=(4.2 * nc, 3.2 * nr), squeeze=False, sharex=True)
    x = np.array([r.get(xkey, np.nan) for r in rows], float)
    order = np.argsort(x)
    for ax, m in zip(axes.flat, metrics, strict=False):
        y = np.array([r.get(m, np.nan) if isinstance(r.get(m), (int, float)) else np.nan for r in rows], float)
        ax.plot(x[order], y[order], ".-", ms=3, lw=0.8)
        if logx:
            ax.set_xscale("log")
        if _is_log(y):
            ax.set_yscale("log")
        ax.set_ylabel(_label(m))
        ax.grid(True, alpha=0.3)
        if base is not None:
            ax.axvline(base, color="tab:red", lw=0.8, ls=":")
        missing = int(np.sum(~np.isfinite(y)))
        if missing:
            ax.set_title(f"{missing} cases without a value", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel(xkey)
    for ax in list(axes.flat)[len(metrics):]:
        ax.set_visible(False)
    fig.suptitle(title + ("; red dotted: the scene's own value" if base is not None else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _edges(v: np.ndarray, log: bool) -> np.ndarray:
    """Cell edges around sorted centres v (geometric midpoints on a log axis).

    >>> _edges(np.array([1.0, 2.0, 4.0]), False).tolist(), _edges(np.array([1.0, 100.0]), True).round(9).tolist()
    ([0.5, 1.5, 3.0, 5.0], [0.1, 10.0, 1000.0])
    """
    if v.size == 1:
        return np.array([v[0] * 0.9, v[0] * 1.1]) if log else np.array([v[0] - 0.5, v[0] + 0.5])
    u = np.log(v) if log else v
    mid = 0.5 * (u[1:] + u[:-1])
    e = np.concatenate([[u[0] - (mid[0] - u[0])], mid, [u[-1] + (u[-1] - mid[-1])]])
    return np.exp(e) if log else e


def _maps(rows, spec, metrics, path: Path, title: str, base=(None, None)) -> None:
    (vx, vy) = spec.vary
    nr, nc = _grid(len(metrics))
    fig, axes = plt.subplots(nr, nc, figsize=(4.6 * nc, 3.8 * nr), squeeze=False)
    x = np.array([r[vx.key] for r in rows], float)
    y = np.array([r[vy.key] for r in rows], float)
    logx, logy = _is_log(x, vx.log), _is_log(y, vy.log)
    grid = spec.design == "grid"
    xs, ys = np.unique(x), np.unique(y)
    for ax, m in zip(axes.flat, metrics, strict=False):
        z = np.array([r.get(m, np.nan) if isinstance(r.get(m), (int, float)) else np.nan for r in rows], float)
        logz = _is_log(z) and np.nanmin(z) > 0
        norm = matplotlib.colors.LogNorm() if logz else None
        ax.set_facecolor("0.85")
        if grid:
            Z = np.full((ys.size, xs.size), np.nan)
            Z[np.searchsorted(ys, y), np.searchsorted(xs, x)] = z
            im = ax.pcolormesh(_edges(xs, logx), _edges(ys, logy), np.ma.masked_invalid(Z), norm=norm,
                               cmap="viridis", shading="flat")
        else:
            ok = np.isfinite(z)
            ax.scatter(x[~ok], y[~ok], c="0.6", s=8, marker="x")
            im = ax.scatter(x[ok], y[ok], c=z[ok], s=14, norm=norm, cmap="viridis")
        fig.colorbar(im, ax=ax, label=_label(m))
        if None not in base:
            ax.plot(*base, "+", color="tab:red", ms=10, mew=1.5)
        if logx:
            ax.set_xscale("log")
        if logy:
            ax.set_yscale("log")
        ax.set_xlabel(vx.key)
        ax.set_ylabel(vy.key)
        missing = int(np.sum(~np.isfinite(z)))
        ax.set_title(_label(m) + (f" (grey: {missing} without a value)" if missing else ""), fontsize=9)
    for ax in list(axes.flat)[len(metrics):]:
        ax.set_visible(False)
    fig.suptitle(title + ("; red +: the scene's own values" if None not in base else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- symmetry break against energy, beside the NNM stability ranges ----------------------------
def _ranges(rows: list[dict], nnm: int, eigvec: str) -> list[tuple[float, float]]:
    """Energy intervals over which NNM ``nnm`` is unstable with an ``eigvec`` eigenvector: each such
    orbit stands for the energies up to the geometric midpoints with its neighbours on the grid
    (an energy where shooting found no orbit is not shaded).

    >>> rows = [{"nnm": 1, "energy_J": e, "found": 1, "unstable_eigvec": k}
    ...         for e, k in ((1.0, ""), (4.0, "antisymmetric"), (16.0, "antisymmetric"))]
    >>> [(float(a), float(b)) for a, b in _ranges(rows, 1, "antisymmetric")]
    [(2.0, 16.0)]
    """
    pts = [r for r in rows if r["nnm"] == nnm]
    E = np.array([r["energy_J"] for r in pts])
    flag = np.array([bool(r["found"]) and r["unstable_eigvec"] == eigvec for r in pts])
    out, start = [], None
    for i, f in enumerate(flag):
        lo = math.sqrt(E[i - 1] * E[i]) if i else E[i]
        hi = math.sqrt(E[i] * E[i + 1]) if i + 1 < E.size else E[i]
        if f and start is None:
            start = lo
        if f and (i + 1 == E.size or not flag[i + 1]):
            out.append((start, hi))
            start = None
    return out


def _break_time_panel(ax, E0, tb, lo, hi, duration: float) -> None:
    """The seeded break time against the initial energy, the NNM instability ranges shaded."""
    broke = np.isfinite(tb)
    ax.errorbar(E0[broke], tb[broke], yerr=[tb[broke] - lo[broke], hi[broke] - tb[broke]], fmt=".", ms=3, lw=0.6,
                color="k", label="seeded break time (median, min-max over the seeds)")
    ax.plot(E0[~broke], np.full(np.sum(~broke), duration), "v", color="0.5", ms=3,
            label=f"no break within the {duration:g} s run")
    ax.set_ylabel("break time [s]")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(True, alpha=0.3)


def _break_energy_panel(ax, stab, E0, tb, Eb) -> None:
    """The energy at the break against the initial energy, the instability ranges on both axes."""
    broke = np.isfinite(tb)
    ax.loglog(E0[broke], Eb[broke], ".", ms=3, color="k", label="energy when the symmetry breaks")
    ax.loglog(E0, E0, ":", color="0.5", lw=0.8, label="initial energy")
    for (nnm, kind), c in COLOURS.items():
        for a, b in _ranges(stab, nnm, kind):
            ax.axhspan(a, b, color=c, alpha=0.12, lw=0)
    ax.set_ylabel("energy at the break [J]")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, alpha=0.3, which="both")


def _multiplier_panel(ax, stab) -> None:
    """|mu|max of NNM 1 and NNM 3 against energy, coloured by the eigenvector of the unstable ones."""
    for nnm, marker in ((1, "o"), (3, "s")):
        pts = [r for r in stab if r["nnm"] == nnm and r["found"]]
        e = np.array([r["energy_J"] for r in pts])
        mu = np.array([r["max_abs_mu"] for r in pts])
        kind = [r["unstable_eigvec"] for r in pts]
        for k, c in (("antisymmetric", "tab:red" if nnm == 1 else "tab:purple"),
                     ("symmetric", "tab:orange" if nnm == 1 else "tab:pink"), ("", "tab:green")):
            sel = np.array([q == k for q in kind], bool)
            if np.any(sel):
                ax.loglog(e[sel], mu[sel], marker, ms=4, color=c, mfc="none" if nnm == 3 else c,
                          label=f"NNM {nnm} " + (f"unstable, {k} eigenvector" if k else "stable"))
    ax.set_ylabel("NNM |mu| max")
    ax.set_xlabel("initial energy [J] (shaded above: the energies where NNM 1 / NNM 3 are unstable)")
    ax.legend(fontsize=7, ncol=2, loc="upper left")
    ax.grid(True, alpha=0.3, which="both")


def symmetry_break_figure(plan, rows: list[dict], stability, out: Path) -> None:
    """``symmetry_break.png``: the seeded break time against the initial energy, the energy at the
    break, and the energies where NNM 1 and NNM 3 are unstable.

    Parameters
    ----------
    plan : the :class:`~bearingshaft.sweep.plan.SweepPlan` (its scene's name and run length)
    rows : the ok cases' rows
    stability : the :class:`~bearingshaft.sweep.metrics.NnmStability` overlay
    out : the sweep's folder
    """
    stab = stability.rows
    cols = [np.array([r.get(k, np.nan) for r in rows], float)
            for k in ("energy_J_initial", "t_break_s", "t_break_min_s", "t_break_max_s", "energy_at_break_J")]
    order = np.argsort(cols[0])
    E0, tb, lo, hi, Eb = (c[order] for c in cols)
    perturbation = next((r.get("symmetry_perturbation_m") for r in rows if r.get("symmetry_perturbation_m")), None)
    fig, axes = plt.subplots(3, 1, figsize=(9, 9.5), sharex=True, gridspec_kw={"height_ratios": [3, 3, 2]})
    for ax in axes[:2]:
        for (nnm, kind), c in COLOURS.items():
            for a, b in _ranges(stab, nnm, kind):
                ax.axvspan(a, b, color=c, alpha=0.12 if nnm == 1 else 0.08, lw=0)
    _break_time_panel(axes[0], E0, tb, lo, hi, plan.scene.ringdown.duration_s)
    _break_energy_panel(axes[1], stab, E0, tb, Eb)
    _multiplier_panel(axes[2], stab)
    axes[0].set_xscale("log")
    seed = (f"seeded with a {perturbation:g} m antisymmetric perturbation at x1, x3 ({stability.symmetry_seeds} "
            "seeds)" if perturbation else "")
    fig.suptitle(wrap_title(f"{plan.scene.name}: symmetry-break time against energy; {seed}; shaded red/purple: "
                            "NNM 1/3 unstable with an antisymmetric eigenvector, orange: NNM 1 with a symmetric one",
                            110), fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "symmetry_break.png", dpi=110)
    plt.close(fig)
