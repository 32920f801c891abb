"""The files and figures of an identification (:class:`bearingshaft.identify.results.Identified`); runs no model.

- ``identified.csv``: ``parameter, unit, initial, value, ci_low, ci_high`` (the interval at the
  [identify] confidence, 95 % by default, from the sandwich at the optimum: :mod:`bearingshaft.identify.fit`);
- ``correlation.csv``: the parameters' correlation matrix;
- ``weights.csv``: each residual block's size, effective size, RMS and weight at the optimum;
- ``misfit_history.csv``: every model run (pass, kind, the values, the weighted cost and each
  block's mean square, its wall and CPU time);
- ``identify.md``: what was fitted to what, how the residuals are weighted, the passes, the
  intervals, the identifiability notes;
- ``identified_overlay.png``: test, first guess and identified model, over the pointwise span and
  as RMS envelopes over the window;
- ``misfit_history.png``: the cost and the parameters run by run.

Numbers are written to 6 significant digits (``digits``): the fit stops at a relative step of 1e-3,
so the values are reproducible to about that on another machine; the intervals are written to as many
digits (a gap known to 0.1 % needs four to show its interval at all), reproducible to about two.
"""

from __future__ import annotations

import math

import numpy as np

from bearingshaft.digits import short
from bearingshaft.identify.results import Identified
from bearingshaft.output import StageWriter, write_rows

DIGITS = ".6g"
MAX_PANELS = 4  # channels drawn in the overlay
PREFERRED = ("beam_s3:z", "tip_left_top", "beam_s1:z", "tube_s1:z")  # drawn first when compared


def identified_rows(res: Identified) -> list[dict]:
    """The rows of identified.csv.

    Parameters
    ----------
    res : Identified
    """
    fit = res.fit
    return [{"parameter": p.key, "unit": p.unit, "initial": format(p.initial, DIGITS),
             "value": format(fit.values[p.key], DIGITS), "ci_low": format(fit.ci[p.key][0], DIGITS),
             "ci_high": format(fit.ci[p.key][1], DIGITS)} for p in fit.problem.parameters]


def correlation_rows(res: Identified) -> list[dict]:
    """The rows of correlation.csv: one per parameter, a column per parameter.

    Parameters
    ----------
    res : Identified
    """
    keys = [p.key for p in res.fit.problem.parameters]
    return [{"parameter": k, **{c: format(float(res.fit.correlation[i, j]), ".4f") for j, c in enumerate(keys)}}
            for i, k in enumerate(keys)]


def weight_rows(res: Identified) -> list[dict]:
    """The rows of weights.csv.

    Parameters
    ----------
    res : Identified
    """
    return [{"measure": w.measure, "n": w.n, "n_eff": format(w.n_eff, ".4g"), "rms": format(w.rms, ".4g"),
             "weight": format(w.weight, ".4g"), "share_of_information": format(w.n_eff / res.fit.n_eff, ".3f")}
            for w in res.fit.weights.values()]


def write(res: Identified, writer: StageWriter) -> None:
    """Every file of an identification into ``writer``'s folder, and its statistics.

    Parameters
    ----------
    res : Identified
    writer : StageWriter
    """
    fit = res.fit
    write_rows(writer.path("identified.csv"), identified_rows(res),
               ["parameter", "unit", "initial", "value", "ci_low", "ci_high"])
    write_rows(writer.path("correlation.csv"), correlation_rows(res))
    write_rows(writer.path("weights.csv"), weight_rows(res))
    hist = [{k: (format(v, DIGITS) if isinstance(v, float) else v) for k, v in row.items()} for row in fit.history]
    write_rows(writer.path("misfit_history.csv"), hist)
    writer.path("identify.md").write_text(markdown(res), encoding="utf-8")
    overlay_figure(res, writer.path("identified_overlay.png"))
    history_figure(res, writer.path("misfit_history.png"))
    writer.stats.update(res.stats)


def markdown(res: Identified) -> str:
    """identify.md.

    Parameters
    ----------
    res : Identified
    """
    fit = res.fit
    spec = res.scene.identify
    ps = fit.problem.parameters
    conf = round(100 * spec.confidence)
    lines = [f"# Identification: {res.scene.name} against {res.test_file}", "",
             f"Fitted: {', '.join(p.key for p in ps)} over {fit.problem.window_s[0]:g}-{fit.problem.window_s[1]:g} s "
             f"of the test, the model driven by {res.driven}, {fit.problem.n_keep - 2} fixed-interface modes; "
             f"residual blocks: {', '.join(fit.weights)}.", "",
             f"| parameter | unit | initial | identified | {conf} % interval |", "|---|---|---|---|---|"]
    for p in ps:
        lo, hi = fit.ci[p.key]
        lines.append(f"| {p.key} | {p.unit or '-'} | {p.initial:.4g} | {fit.values[p.key]:.4g} | "
                     f"[{lo:.3g}, {hi:.3g}] |")
    lines += ["", "## Identifiability", ""]
    lines += [f"- {n}" for n in fit.notes] or ["- Every parameter is identified: no pair correlated beyond "
                                               f"+-0.95, J^T J well conditioned ({fit.condition:.3g}), every "
                                               "interval inside its bounds."]
    keys = [p.key for p in ps]
    lines += ["", "Correlations (correlation.csv):", "", "| | " + " | ".join(keys) + " |",
              "|---|" + "---|" * len(keys)]
    for i, k in enumerate(keys):
        lines.append(f"| {k} | " + " | ".join(f"{fit.correlation[i, j]:+.3f}" for j in range(len(keys))) + " |")
    lines += ["", "## How the residuals are weighted", "",
              "Each residual is divided by its scatter at the optimum (bearingshaft.identify.scatter: the test's "
              "noise redrawn on the model's record, and the roughness about local planes over a cloud of runs with "
              "the hammer force redrawn within its noise: the chaos past the horizon), and each block by "
              "sqrt(n_eff / n), n_eff the independent residuals it holds (the integrated autocorrelation time along "
              "each series and the participation ratio across channels). The intervals are theta -+ t sqrt(C_ii), "
              "C = s^2 A^-1 B A^-1 (a sandwich: A = J^T J, J the planes' slopes; B from the scatter's realisations "
              f"projected on J), s^2 = {fit.s2:.3g}, N_eff = {fit.n_eff:.4g}, t = {fit.t_quantile:.3f}.", "",
              "| block | residuals | effective | RMS | weight |", "|---|---|---|---|---|"]
    for w in fit.weights.values():
        lines.append(f"| {w.measure} | {w.n} | {w.n_eff:.4g} | {w.rms:.4g} | {w.weight:.4g} |")
    lines += ["", "## Passes", "", "| pass | start | end | trial points | cost start | cost end | pointwise block |",
              "|---|---|---|---|---|---|---|"]
    for k, pa in enumerate(fit.passes):
        def show(th):
            return ", ".join(f"{p.value(t):.4g}" for p, t in zip(ps, th, strict=True))
        lines.append(f"| {k + 1} | {show(pa.start)} | {show(pa.end)} | {pa.n_iterations} | {pa.cost_start:.4g} | "
                     f"{pa.cost_end:.4g} | {pa.span} |")
    lines += profile_lines(res)
    st = fit.stats
    lines += ["", f"{st['n_runs']} model runs ({short(st['cpu_s_runs'], '.3g')} s of CPU) on {st['where']} "
              f"({st['workers']} workers), {st['wall_s']:.1f} s wall for the fit.", ""]
    return "\n".join(lines)


def profile_lines(res: Identified) -> list[str]:
    """identify.md's profile section: the local intervals and every probe (:mod:`bearingshaft.identify.profile`).

    Parameters
    ----------
    res : Identified
    """
    fit = res.fit
    ps = fit.problem.parameters
    if not fit.probes:
        return []
    lines = ["", "## Profile", "",
             "Each parameter probed at multiples of its local half-width on either side, the others moved onto the "
             "valley floor (the planes' regression, then one Gauss-Newton step); a probe whose cost exceeds the "
             f"optimum's by at most {fit.profile_limit:.4g} (the chi-square quantile of {len(ps)} degrees of freedom "
             "times s^2) is one the test cannot reject, and every interval reaches it.", "",
             "| parameter | local interval | reported |", "|---|---|---|"]
    for p in ps:
        (a, b), (lo, hi) = fit.local_ci.get(p.key, (math.nan, math.nan)), fit.ci[p.key]
        lines.append(f"| {p.key} | [{a:.4g}, {b:.4g}] | [{lo:.4g}, {hi:.4g}] |")
    lines += ["", "| profiled | side | half-widths | " + " | ".join(p.key for p in ps) + " | cost excess | accepted |",
              "|---|---|---|" + "---|" * len(ps) + "---|---|"]
    for pr in fit.probes:
        vals = " | ".join(f"{p.value(float(t)):.4g}" for p, t in zip(ps, pr.theta, strict=True))
        lines.append(f"| {ps[pr.index].key} | {'+' if pr.side > 0 else '-'} | {pr.multiple:g} | {vals} | "
                     f"{pr.excess:+.4g} | {'yes' if pr.accepted else 'no'} |")
    return lines


def _pick(names) -> list[int]:
    first = [names.index(n) for n in PREFERRED if n in names]
    rest = [i for i in range(len(names)) if i not in first]
    return (first + rest)[:MAX_PANELS]


def overlay_figure(res: Identified, path) -> None:
    """Test, first guess and identified model: the pointwise span (left) and RMS envelopes over the window (right).

    Parameters
    ----------
    res : Identified
    path : str or Path
        The PNG written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ov = res.overlay
    tg = res.fit.target
    rows = _pick(list(ov.names))
    fig, axes = plt.subplots(len(rows), 2, figsize=(12, 2.6 * len(rows)), squeeze=False,
                             constrained_layout=True)
    a, b = tg.time_span_s
    pad = max(0.2 * (b - a), 2e-3)
    near = (ov.t >= a - pad) & (ov.t <= b + 4 * pad)
    win = res.fit.problem.window_s
    per = max(1, int(round(tg.envelope_window_s / float(ov.t[1] - ov.t[0]))))
    for ax, ax2, i in zip(axes[:, 0], axes[:, 1], rows, strict=True):
        for data, label, style in ((ov.test, "test", dict(color="k", lw=1.0)),
                                   (ov.initial, "model, first guess", dict(color="tab:blue", lw=0.7, alpha=0.6)),
                                   (ov.identified, "model, identified", dict(color="tab:red", lw=0.8))):
            ax.plot(1e3 * ov.t[near], data[i][near], label=label, **style)
            inside = (ov.t >= win[0]) & (ov.t <= win[1])
            y = data[i][inside]
            n = y.size // per
            env = np.sqrt(np.mean(y[: n * per].reshape(n, per) ** 2, axis=1))
            tc = ov.t[inside][: n * per].reshape(n, per).mean(axis=1)
            ax2.semilogy(tc, env, label=label, **style)
        ax.axvspan(1e3 * a, 1e3 * b, color="0.9", zorder=0)
        ax.set_ylabel(f"{ov.names[i]} [{ov.units[i]}]")
        ax2.set_ylabel(f"RMS in {1e3 * tg.envelope_window_s:g} ms")
    axes[-1, 0].set_xlabel("t [ms] (shaded: the pointwise block, up to the horizon)")
    axes[-1, 1].set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=8, loc="upper right")
    vals = ", ".join(f"{k.split('.', 1)[1]} = {v:.4g}" for k, v in res.fit.values.items())
    fig.suptitle(f"{res.scene.name}: test and model, identified {vals}", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def history_figure(res: Identified, path) -> None:
    """The weighted cost of every trial point and each parameter against the run, by pass.

    Parameters
    ----------
    res : Identified
    path : str or Path
        The PNG written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fit = res.fit
    ps = fit.problem.parameters
    pts = [h for h in fit.history if h["kind"] == "point" and math.isfinite(h["cost"])]
    fig, axes = plt.subplots(1 + len(ps), 1, figsize=(7, 2.0 * (1 + len(ps))), sharex=True, constrained_layout=True)
    for k in sorted({h["pass"] for h in fit.history}):
        sel = [h for h in pts if h["pass"] == k]
        axes[0].semilogy([h["run"] for h in sel], [h["cost"] for h in sel], "o-", ms=3, label=f"pass {k}")
    axes[0].set_ylabel("weighted cost")
    axes[0].legend(fontsize=8)
    for ax, p in zip(axes[1:], ps, strict=True):
        run = [h["run"] for h in fit.history]
        ax.plot(run, [h[p.key] for h in fit.history], ".", color="0.6", ms=3, label="every run")
        ax.plot([h["run"] for h in pts], [h[p.key] for h in pts], "o-", ms=3, label="trial points")
        lo, hi = fit.ci[p.key]
        bounded = math.isfinite(lo) and math.isfinite(hi) and (lo > 0 or p.scale != "log")
        if bounded:  # an unbounded interval (a parameter the test does not see) draws no band
            ax.axhspan(lo, hi, color="tab:red", alpha=0.15, label="interval")
        if p.scale == "log":
            ax.set_yscale("log")
        ax.set_ylabel(f"{p.key.split('.', 1)[1]} [{p.unit or '-'}]")
    axes[1].legend(fontsize=7)
    axes[-1].set_xlabel("model run")
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["write", "markdown", "profile_lines", "identified_rows", "correlation_rows", "weight_rows", "overlay_figure",
           "history_figure"]
