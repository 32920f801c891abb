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

import inspect
import math
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bearingshaft.plots import wrap_title  # noqa: E402
from bearingshaft.scenes.sweep import KEY_PATTERN  # noqa: E402
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


# what a metric column is, and its unit ("" for a count or a ratio), for the axes and colour bars
METRICS = {
    "energy_balance_error": ("relative energy-balance error", ""),
    "energy_J_initial": ("initial energy", "J"),
    "contact_events": ("contact switches (events)", ""),
    "freq_early_hz": ("dominant frequency, first 1/8 of the record", "Hz"),
    "freq_middle_hz": ("dominant frequency, middle 1/8 of the record", "Hz"),
    "freq_late_hz": ("dominant frequency, last 1/8 of the record", "Hz"),
    "impacts": ("number of impacts", ""),
    "peak_tip_force_N": ("peak tip force", "N"),
    "gaps_open_after_s": ("time after which the gaps stay open", "s"),
    "decay_time_s": ("decay time (energy to 1 % of its peak)", "s"),
    "t_break_s": ("symmetry-break time", "s"),
    "t_break_min_s": ("symmetry-break time, earliest seed", "s"),
    "t_break_max_s": ("symmetry-break time, latest seed", "s"),
    "growth_rate_per_s": ("growth rate of the antisymmetric motion", "1/s"),
    "runs_broken": ("seeded runs that broke symmetry", ""),
    "symmetry_perturbation_m": ("seed perturbation", "m"),
    "energy_at_break_J": ("energy at the symmetry break", "J"),
    "hammer_work_J": ("work of the hammer", "J"),
    "run_time_s": ("run time of the case", "s"),
}
# a column's unit from its name's last word(s), for the columns METRICS does not list
SUFFIX_UNITS = (("_m_s", "m/s"), ("_per_s", "1/s"), ("_hz", "Hz"), ("_s", "s"), ("_N", "N"), ("_J", "J"),
                ("_m", "m"), ("_kg", "kg"))
LABEL_CHARS = 32  # a key's description longer than this loses its parentheses on an axis
UNIT_ATOMS = {"m", "mm", "s", "ms", "N", "kg", "Hz", "J", "rad", "Pa", "MPa", "GPa", "W", "dB", "K", "deg"}
FRC_PEAK = re.compile(r"^frc_peak_(?P<what>hz|m)_(?P<level>.+)N$")
MIN_SCALED_VALUES = 4  # a grid axis of fewer values is categorical: two or three values make no scale
EVEN_STEPS = 1.5  # a grid axis is drawn to scale when its largest step is at most this many times its smallest


def _unit_text(label: str, unit: str) -> str:
    """An axis label with its unit in brackets (none for a count or a ratio).

    >>> _unit_text("peak tip force", "N"), _unit_text("number of impacts", "")
    ('peak tip force [N]', 'number of impacts')
    """
    return f"{label} [{unit}]" if unit else label


def metric_label(name: str) -> str:
    """The axis label of a metric column: what it is and its unit.

    Parameters
    ----------
    name : a column of the sweep's rows (``freq_early_hz``, ``frc_peak_hz_1N``, ``nnm.n_orbits``)

    Returns
    -------
    str
        From :data:`METRICS`, else the name in words with the unit its suffix says.

    Examples
    --------
    >>> metric_label("peak_tip_force_N"), metric_label("frc_peak_m_10N"), metric_label("verify.max_error_s")
    ('peak tip force [N]', 'FRC peak amplitude at 10 N [m]', 'verify.max error [s]')
    """
    if name in METRICS:
        return _unit_text(*METRICS[name])
    m = FRC_PEAK.match(name)
    if m:
        what = "frequency" if m["what"] == "hz" else "amplitude"
        return _unit_text(f"FRC peak {what} at {m['level']} N", "Hz" if m["what"] == "hz" else "m")
    for suffix, unit in SUFFIX_UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return _unit_text(name[: -len(suffix)].replace("_", " "), unit)
    return name.replace("_", " ")


def _is_unit(text: str) -> bool:
    """Whether the first words of a field's description are a unit.

    >>> _is_unit("N m/rad"), _is_unit("m/s"), _is_unit("1/s"), _is_unit("the nominal blow"), _is_unit("")
    (True, True, True, False, False)
    """
    atoms = [a for a in re.split(r"[ /^*.()0-9-]+", text) if a]
    return bool(text) and all(a in UNIT_ATOMS for a in atoms)


def _field_doc(obj, name: str) -> tuple[str, str]:
    """(description, unit) of a scene table's field from its dataclass's numpydoc Parameters, whose
    entries read ``unit, what it is, range`` (``("", "")`` when the docstring does not say)."""
    doc = inspect.getdoc(type(obj)) or ""
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        names = [n.strip() for n in line.split(":")[0].split(",")] if ":" in line and not line.startswith(" ") else []
        if name in names and i + 1 < len(lines) and lines[i + 1].startswith(" "):
            text = lines[i + 1].strip().rstrip(".")
            parts = [t.strip() for t in text.split(",")]
            unit = parts[0] if parts and _is_unit(parts[0]) else ""
            what = ", ".join(t for t in parts[1 if unit else 0:] if t and t[0] not in "<>=").replace("`", "")
            if len(what) > LABEL_CHARS:  # an axis label: the asides go
                what = re.sub(r"\s*\([^)]*\)", "", what)
            return what, unit
    return "", ""


def key_label(scene, key: str) -> str:
    """The axis label of a varied scene key: what it is, the key, and its unit.

    Parameters
    ----------
    scene : the base scene (its tables' dataclasses document every key)
    key : ``TABLE.KEY``, ``TABLE.KEY[i]`` or ``load[i].KEY``; a metric column (``[sweep] x``) too

    Returns
    -------
    str
        Such as ``'radial clearance at each tip, model.gap [m]'``; a metric's label for a metric.
    """
    m = KEY_PATTERN.match(key)
    if m is None:
        return metric_label(key)
    table, name = m["table"], m["name"]
    ti = int(m["ti"]) if m["ti"] is not None else None
    obj = (scene.loads[ti] if ti is not None and ti < len(scene.loads) else None) if table == "load" \
        else getattr(scene, table, None)
    what, unit = _field_doc(obj, name) if obj is not None else ("", "")
    if m["i"] is not None and what.endswith("each point"):  # x0_m[1]: the point it is
        names = getattr(scene.model, "point_names", ())
        i = int(m["i"])
        what = what[: -len("each point")] + (names[i] if i < len(names) else f"point {i}")
    if not unit:
        unit = next((u for suffix, u in SUFFIX_UNITS if name.endswith(suffix)), "")
    return _unit_text(f"{what}, {key}" if what else key, unit)


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
        fig = draw_lines(rows, xkey, metrics, title, _is_log([r.get(xkey) for r in rows], log_hint),
                         None if spec.x else base[0], key_label(plan.scene, xkey))
        _save(fig, result.out / "sweep.png")
        files.append("sweep.png")
    elif metrics and len(keys) == 2:
        fig = draw_maps(rows, spec, metrics, title, base, tuple(key_label(plan.scene, k) for k in keys))
        _save(fig, result.out / "sweep.png")
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


def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=110)
    plt.close(fig)


def draw_lines(rows, xkey, metrics, title: str, logx: bool, base=None, xlabel: str | None = None):
    """Each metric against one varied key (or ``[sweep] x``), a panel each; returns the figure.

    Parameters
    ----------
    rows : the ok cases' rows
    xkey : the column on the x axis
    metrics : the columns drawn, a panel each
    title : the figure's title
    logx : a log x axis
    base : the scene's own value of ``xkey`` (a red dotted line), or None
    xlabel : the x axis's label (default: :func:`metric_label` of ``xkey``)
    """
    nr, nc = _grid(len(metrics))
    fig, axes = plt.subplots(nr, nc, figsize=(4.4 * nc, 3.4 * nr), squeeze=False, sharex=True)
    x = np.array([r.get(xkey, np.nan) for r in rows], float)
    order = np.argsort(x)
    for ax, m in zip(axes.flat, metrics, strict=False):
        y = np.array([r.get(m, np.nan) if isinstance(r.get(m), (int, float)) else np.nan for r in rows], float)
        ax.plot(x[order], y[order], ".-", ms=3, lw=0.8)
        if logx:
            ax.set_xscale("log")
        if _is_log(y):
            ax.set_yscale("log")
        ax.set_ylabel(metric_label(m), fontsize=8)
        ax.grid(True, alpha=0.3)
        if base is not None:
            ax.axvline(base, color="tab:red", lw=0.8, ls=":")
        missing = int(np.sum(~np.isfinite(y)))
        if missing:
            ax.set_title(f"{missing} cases without a value", fontsize=8)
        _thin_x(ax, logx)
        ax.tick_params(labelsize=8)
    for ax in axes[-1]:
        ax.set_xlabel(xlabel or metric_label(xkey), fontsize=8)
    for ax in list(axes.flat)[len(metrics):]:
        ax.set_visible(False)
    fig.suptitle(title + ("; red dotted: the scene's own value" if base is not None else ""), fontsize=10)
    fig.tight_layout()
    return fig


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


def _even(u: np.ndarray) -> bool:
    """Whether sorted values are (nearly) evenly spaced: largest step <= EVEN_STEPS x smallest.

    >>> _even(np.array([1.0, 2.0, 3.0])), _even(np.array([200.0, 800.0])), _even(np.array([20.0, 100, 200, 500]))
    (True, True, False)
    """
    d = np.diff(u)
    return bool(u.size >= 2 and np.all(d > 0) and d.max() <= EVEN_STEPS * d.min())


def grid_axis(values: np.ndarray, log_hint: bool = False) -> tuple[str, np.ndarray]:
    """How a grid design's axis is drawn: ``("linear" | "log", cell edges)`` when its values are evenly
    spaced on that scale (each cell then spans half a step either side of its value), else
    ``("categorical", edges at -0.5 .. n - 0.5)``: one equal cell per value, labelled with it. A cell
    never reaches past half a step beyond its value, so a 200 N row of 200, 500, 1000 N does not
    span -100 to 500 N.

    Parameters
    ----------
    values : the distinct values of the axis, sorted
    log_hint : the design asked for log spacing

    Returns
    -------
    (scale, edges), ``len(edges) = len(values) + 1``.

    Examples
    --------
    >>> grid_axis(np.array([1e-4, 1e-3, 1e-2, 1e-1]))[0], grid_axis(np.array([1.0, 2.0, 3.0, 4.0]))[0]
    ('log', 'linear')
    >>> scale, edges = grid_axis(np.array([20.0, 200.0, 500.0, 1000.0]))
    >>> scale, edges.tolist()
    ('categorical', [-0.5, 0.5, 1.5, 2.5, 3.5])
    >>> grid_axis(np.array([200.0, 800.0]))[0]  # midpoints would give the 200 N row -100 to 500 N
    'categorical'
    """
    v = np.asarray(values, float)
    categorical = "categorical", np.arange(v.size + 1) - 0.5
    if v.size < MIN_SCALED_VALUES:
        return categorical
    positive = bool(np.all(v > 0))
    log_even = positive and _even(np.log(v))
    if log_even and (log_hint or _is_log(v) or not _even(v)):
        return "log", _edges(v, True)
    if _even(v):
        edges = _edges(v, False)
        if not (positive and edges[0] <= 0):  # a cell of positive values must not reach zero or below
            return "linear", edges
    return categorical


def _tick_text(v: float) -> str:
    """A categorical tick: the value to 3 significant digits.

    >>> _tick_text(0.000254), _tick_text(1389495.49), _tick_text(200.0)
    ('0.000254', '1.39e+06', '200')
    """
    return f"{v:.3g}"


def _set_grid_axis(ax, which: str, scale: str, values: np.ndarray) -> None:
    """The axis's scale, and for a categorical one its ticks at the values' cells (at most 8 labelled)."""
    if scale == "log":
        (ax.set_xscale if which == "x" else ax.set_yscale)("log")
    if scale != "categorical":
        return
    step = max(1, math.ceil(values.size / 8))
    idx = np.arange(0, values.size, step)
    (ax.set_xticks if which == "x" else ax.set_yticks)(idx, [_tick_text(values[i]) for i in idx])
    if which == "x":
        ax.tick_params(axis="x", labelrotation=30)


def _position(v: np.ndarray, values: np.ndarray, scale: str) -> np.ndarray:
    """Where values sit on an axis drawn by :func:`grid_axis` (their index on a categorical one)."""
    return np.searchsorted(values, v).astype(float) if scale == "categorical" else v


def draw_maps(rows, spec, metrics, title: str, base=(None, None), labels: tuple[str, str] | None = None):
    """Each metric over two varied keys, a panel each with its colour bar; returns the figure. A grid
    design is drawn as cells (:func:`grid_axis`), a zip or random one as coloured points.

    Parameters
    ----------
    rows : the ok cases' rows
    spec : the sweep's design (its two varied keys, design)
    metrics : the columns drawn, a panel each
    title : the figure's title
    base : the scene's own values of the two keys (a red +), or None
    labels : the x and y axes' labels (default: the keys)
    """
    (vx, vy) = spec.vary
    nr, nc = _grid(len(metrics))
    fig, axes = plt.subplots(nr, nc, figsize=(5.0 * nc, 4.0 * nr), squeeze=False)
    x = np.array([r[vx.key] for r in rows], float)
    y = np.array([r[vy.key] for r in rows], float)
    grid = spec.design == "grid"
    xs, ys = np.unique(x), np.unique(y)
    if grid:
        (sx, ex), (sy, ey) = grid_axis(xs, vx.log), grid_axis(ys, vy.log)
    else:
        sx = "log" if _is_log(x, vx.log) else "linear"
        sy = "log" if _is_log(y, vy.log) else "linear"
    xlabel, ylabel = labels or (vx.key, vy.key)
    if grid:  # a categorical axis says so: its cells are equal whatever the values' steps
        xlabel += "\n(one column per value, not to scale)" if sx == "categorical" else ""
        ylabel += "\n(one row per value, not to scale)" if sy == "categorical" else ""
    show_base = None not in base and (not grid or ((sx != "categorical" or base[0] in xs)
                                                   and (sy != "categorical" or base[1] in ys)))
    for ax, m in zip(axes.flat, metrics, strict=False):
        z = np.array([r.get(m, np.nan) if isinstance(r.get(m), (int, float)) else np.nan for r in rows], float)
        logz = _is_log(z) and np.nanmin(z) > 0
        norm = matplotlib.colors.LogNorm() if logz else None
        ax.set_facecolor("0.85")
        if grid:
            Z = np.full((ys.size, xs.size), np.nan)
            Z[np.searchsorted(ys, y), np.searchsorted(xs, x)] = z
            im = ax.pcolormesh(ex, ey, np.ma.masked_invalid(Z), norm=norm, cmap="viridis", shading="flat")
        else:
            ok = np.isfinite(z)
            ax.scatter(x[~ok], y[~ok], c="0.6", s=8, marker="x")
            im = ax.scatter(x[ok], y[ok], c=z[ok], s=14, norm=norm, cmap="viridis")
        cb = fig.colorbar(im, ax=ax)
        cb.set_label(metric_label(m), fontsize=8)
        cb.ax.tick_params(labelsize=8)
        if show_base:
            bx = _position(np.array([base[0]], float), xs, sx) if grid else [base[0]]
            by = _position(np.array([base[1]], float), ys, sy) if grid else [base[1]]
            ax.plot(bx, by, "+", color="tab:red", ms=10, mew=1.5)
        if grid:
            _set_grid_axis(ax, "x", sx, xs)
            _set_grid_axis(ax, "y", sy, ys)
        else:
            if sx == "log":
                ax.set_xscale("log")
            if sy == "log":
                ax.set_yscale("log")
        if sx != "categorical":
            _thin_x(ax, sx == "log")
        ax.tick_params(labelsize=8)
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(ylabel, fontsize=8)
        missing = int(np.sum(~np.isfinite(z)))
        grey = f"\n(grey: {missing} case{'s' if missing > 1 else ''} without a value)" if missing else ""
        ax.set_title(metric_label(m) + grey, fontsize=9)
    for ax in list(axes.flat)[len(metrics):]:
        ax.set_visible(False)
    fig.suptitle(title + ("; red +: the scene's own values" if show_base else ""), fontsize=10)
    fig.tight_layout()
    return fig


def _thin_x(ax, log: bool) -> None:
    """At most 5 major x ticks, so that the labels of a small panel do not run together."""
    from matplotlib.ticker import LogLocator, MaxNLocator

    ax.xaxis.set_major_locator(LogLocator(numticks=5) if log else MaxNLocator(4))


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
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
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
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
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
    ax.set_ylabel("largest Floquet multiplier |mu|")
    ax.set_xlabel("initial energy [J] (shaded above: the energies where NNM 1 / NNM 3 are unstable)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
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
    fig, axes = plt.subplots(3, 1, figsize=(12.5, 9.5), sharex=True, gridspec_kw={"height_ratios": [3, 3, 2]})
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
                            150), fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "symmetry_break.png", dpi=110)
    plt.close(fig)
