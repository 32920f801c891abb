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
  as RMS envelopes over the window (the models' with the test's noise power added, as the fit compares them,
  and the test's noise floor);
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
    lines += estimate_lines(res)
    lines += profile_lines(res)
    st = fit.stats
    lines += ["", f"{st['n_runs']} model runs ({short(st['cpu_s_runs'], '.3g')} s of CPU) on {st['where']} "
              f"({st['workers']} workers), {st['wall_s']:.1f} s wall for the fit.", ""]
    return "\n".join(lines)


def estimate_lines(res: Identified) -> list[str]:
    """identify.md's estimate section: where the reported values come from, and for each parameter whose profile
    the test cannot reject over a range wider than its local interval, why its point says no more than its interval.

    Parameters
    ----------
    res : Identified
    """
    fit = res.fit
    ps = fit.problem.parameters
    if not fit.probes:
        return []

    def where(th):
        return ", ".join(f"{p.key} = {p.value(float(t)):.4g}" for p, t in zip(ps, th, strict=True))

    lines = ["", "## Estimate", ""]
    if fit.from_profile:
        excess = min(pr.excess for pr in fit.probes)
        lines.append(f"The reported values are the profile's cheapest probe, {where(fit.theta)}: its cost is "
                     f"{-excess:.4g} below the least squares' end ({where(fit.optimum)}), where the Jacobian, the "
                     "correlations and the local intervals were taken. The least squares stopped where the trust "
                     "region saw no descent; the cheaper point is the better least-squares estimate, "
                     f"but a cost difference of {-excess:.4g} against the test's limit of {fit.profile_limit:.4g} is "
                     "no evidence for one point over the other.")
    else:
        lines.append("The reported values are the least squares' end: no probe of the profile is cheaper.")
    for j, p in enumerate(ps):
        own = [pr for pr in fit.probes if pr.index == j and pr.accepted]
        (a, b) = fit.local_ci.get(p.key, (math.nan, math.nan))
        if not own:
            continue
        # the accepted probes, the least squares' end (excess 0) and the estimate (the cheapest probe, or the end)
        end = fit.optimum if fit.optimum is not None else fit.theta
        vals = [p.value(float(pr.theta[j])) for pr in own] + [fit.values[p.key], p.value(float(end[j]))]
        lo, hi = min(vals), max(vals)
        if not (lo < a or hi > b):
            continue
        ex = [pr.excess for pr in own] + [0.0] + ([min(pr.excess for pr in fit.probes)] if fit.from_profile else [])
        # a cost that falls again farther out on a side: its differences are the chaos's, not the parameter's
        rough = any(any(b_.excess < a_.excess for a_, b_ in zip(line, line[1:], strict=False))
                    for line in (sorted((pr for pr in fit.probes if pr.index == j and pr.side == side),
                                        key=lambda pr: pr.multiple) for side in (-1, 1)))
        lines.append("")
        lines.append(f"- {p.key}: along its profile (the others on the valley floor) the cost stays within "
                     f"{min(ex):+.4g} to {max(ex):+.4g} of the end's from {lo:.4g} to {hi:.4g}, under the limit "
                     f"{fit.profile_limit:.4g} that the test's noise and chaos allow"
                     + (", and falls again farther out on a side: there the costs differ as new realisations of the "
                        "chaos do, not as the parameter moves them" if rough else "") + ". "
                     f"The point {fit.values[p.key]:.4g} is the cheapest the search found on that floor, not a value "
                     "the test prefers over the others there; it says no more than the interval "
                     f"[{fit.ci[p.key][0]:.4g}, {fit.ci[p.key][1]:.4g}].")
    return lines


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


def rms_envelope(t: np.ndarray, y: np.ndarray, per: int, window_s) -> tuple[np.ndarray, np.ndarray]:
    """(t_c, e): the RMS of ``y`` in consecutive windows of ``per`` samples inside ``window_s``, at their mean times.

    Parameters
    ----------
    t : (N,) ndarray of float
        s.
    y : (N,) ndarray of float
        A channel, its unit.
    per : int
        Samples a window.
    window_s : (float, float)
        s.

    Returns
    -------
    (t_c (n,) in s, e (n,) in y's unit)

    Examples
    --------
    >>> tc, e = rms_envelope(np.arange(4.0), np.array([3.0, -3.0, 4.0, 4.0]), 2, (0.0, 3.0))
    >>> tc.tolist(), e.tolist()
    ([0.5, 2.5], [3.0, 4.0])
    """
    inside = (t >= window_s[0]) & (t <= window_s[1])
    x, tt = y[inside], t[inside]
    n = x.size // per
    return tt[: n * per].reshape(n, per).mean(axis=1), np.sqrt(np.mean(x[: n * per].reshape(n, per) ** 2, axis=1))


def with_noise_power(e: np.ndarray, noise: float) -> np.ndarray:
    """The model's RMS envelope as a sensor of RMS noise ``noise`` would record it: sqrt(e^2 + noise^2), the
    form the envelope block compares with the test's (:mod:`bearingshaft.identify.residuals`; noise uncorrelated
    with the motion adds its power).

    Parameters
    ----------
    e : ndarray of float
        The model's RMS envelope, the channel's unit.
    noise : float
        The test channel's RMS before the blow, the same unit.

    Examples
    --------
    >>> with_noise_power(np.array([3.0, 0.0]), 4.0).tolist()
    [5.0, 4.0]
    """
    return np.sqrt(np.asarray(e, float) ** 2 + float(noise) ** 2)


def overlay_figure(res: Identified, path) -> None:
    """identified_overlay.png (:func:`draw_overlay`).

    Parameters
    ----------
    res : Identified
    path : str or Path
        The PNG written.
    """
    fig = draw_overlay(res)
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110)
    plt.close(fig)


def draw_overlay(res: Identified):
    """Test, first guess and identified model: the pointwise span (left) and RMS envelopes over the window (right).

    The test's envelope holds its sensor's noise, sqrt(e^2 + n^2) with n its RMS before the blow, so late in the
    record, where the motion has decayed under the noise, it levels off at n while the model's alone keeps falling.
    The right panels therefore draw the models' envelopes with the test's noise power added (:func:`with_noise_power`,
    as the fit compares them), the identified model's alone dashed, and the noise floor n dotted.

    Parameters
    ----------
    res : Identified

    Returns
    -------
    matplotlib Figure (the caller saves and closes it)
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
    # the test channels' RMS before the blow, as recorded (the overlay draws the channels unfiltered)
    noise = np.zeros(len(ov.names)) if tg.noise is None else np.asarray(tg.noise, float)
    for ax, ax2, i in zip(axes[:, 0], axes[:, 1], rows, strict=True):
        for data, label, style in ((ov.test, "test", dict(color="k", lw=1.0)),
                                   (ov.initial, "model, first guess", dict(color="tab:blue", lw=0.7, alpha=0.6)),
                                   (ov.identified, "model, identified", dict(color="tab:red", lw=0.8))):
            ax.plot(1e3 * ov.t[near], data[i][near], label=label, **style)
            tc, env = rms_envelope(ov.t, data[i], per, win)
            if data is ov.test:
                ax2.semilogy(tc, env, label=label, **style)
                continue
            ax2.semilogy(tc, with_noise_power(env, noise[i]), label=f"{label} + test's noise power", **style)
            if data is ov.identified and noise[i] > 0:
                ax2.semilogy(tc, env, label=f"{label}, alone", color="tab:red", lw=0.7, ls="--")
        if noise[i] > 0:
            ax2.axhline(noise[i], color="0.4", lw=0.8, ls=":", label="test's noise floor (RMS before the blow)")
        ax.axvspan(1e3 * a, 1e3 * b, color="0.9", zorder=0)
        ax.set_ylabel(f"{ov.names[i]} [{ov.units[i]}]")
        ax2.set_ylabel(f"RMS in {1e3 * tg.envelope_window_s:g} ms")
    axes[-1, 0].set_xlabel("t [ms] (shaded: the pointwise block, up to the horizon)")
    axes[-1, 1].set_xlabel("t [s] (models: sqrt(e^2 + n^2), n the test's noise RMS)")
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[0, 1].legend(fontsize=7, loc="upper right")
    vals = ", ".join(f"{k.split('.', 1)[1]} = {v:.4g}" for k, v in res.fit.values.items())
    fig.suptitle(f"{res.scene.name}: test and model, identified {vals}", fontsize=10)
    return fig


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


__all__ = ["write", "markdown", "profile_lines", "estimate_lines", "identified_rows", "correlation_rows", "weight_rows",
           "overlay_figure", "draw_overlay", "history_figure", "rms_envelope", "with_noise_power"]
