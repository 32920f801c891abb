"""Part of stage ``frc`` with friction at the tips: the response map (issues 25 and 27), what a stepped-sine test
sees at each frequency.

For each level a stepped sine up and down by the exact friction flow, each frequency classified as periodic (with
its period), subharmonic, quasi-periodic or chaotic by its Poincare samples and its largest Lyapunov exponent (the
exact tangent: state transition matrices between events, the saltation matrix at every gap, stick and slip event,
the sliders that are not stuck slaved to x; :mod:`reduced.periodic.friction_map`, classified by
:func:`reduced.periodic.response_map.classify` as without friction). The frequencies: ``[frc] map_step_hz`` steps
over the contact band (the HB curve's, :func:`bearingshaft.stages.frc_friction_bands.contact_band`, and the linear
response's, widened by :data:`bearingshaft.stages.frc_map.BAND_MARGIN_HZ`), ``map_coarse_points`` log-spaced
elsewhere, plus the frequencies the stage checks HB at (:func:`bearingshaft.stages.frc_friction._checks` reads the
map's state there instead of a stepped sine of its own); each sweep keeps the fine step beyond the band while its
own response stays in contact. Each frequency runs MAP_TRANSIENT periods, then ``[frc] map_periods`` recorded.

:func:`write` writes ``response_map.csv`` and ``response_map_jumps.csv`` (the columns of the frictionless map,
:mod:`bearingshaft.stages.frc_map_files`), ``response_map.png``; :func:`markdown` the frc.md section.
"""

from __future__ import annotations

import time

import numpy as np

from bearingshaft.stages.frc_friction_bands import contact_band
from bearingshaft.stages.frc_map import BAND_MARGIN_HZ
from bearingshaft.stages.frc_map_files import REGIME_COLORS, _label, write_tables, x1_column
from bearingshaft.stages.frc_results import MapLevel
from reduced.periodic.friction_map import friction_response_map
from reduced.periodic.response_map import MapOptions, linear_contact_bands, map_frequencies, merge_bands

MAP_TRANSIENT = 8  # periods run at each frequency before the record: a friction period in contact costs ~1.3 ms of
# CPU (its ~10 stick, slip and gap events), so the map of the scene's level (2 x ~170 frequencies) takes ~25 s at 8 +
# 32 periods (the frictionless map's 32 + 128 would take ~100 s); a contracting response is finished by Newton anyway


def bands(system, b: np.ndarray, P: float, spec, br) -> list[tuple[float, float]]:
    """Hz: the union of the HB curve's contact band and the linear (open-gap, frictionless) response's, widened by
    BAND_MARGIN_HZ and clipped to the scene's band.

    Parameters
    ----------
    system : the gap system with friction
    b : (n,) the load direction
    P : N, the level
    spec : the [frc] table
    br : the HB curve with friction at P, or its exception
    """
    raw = linear_contact_bands(system.with_friction(None), b, P, spec.freq_min_hz, spec.freq_max_hz)
    if not isinstance(br, Exception):
        raw += contact_band(br)
    return [(max(lo, spec.freq_min_hz), min(hi, spec.freq_max_hz)) for lo, hi in merge_bands(raw, BAND_MARGIN_HZ)]


def compute_map(system, b: np.ndarray, P: float, spec, br, rows: np.ndarray, names: tuple,
                extra_hz=()) -> MapLevel | None:
    """The response map at level P (module docstring), or None with ``[frc] map_step_hz = 0``.

    Parameters
    ----------
    system : the gap system with friction
    b : (n,) the load direction
    P : N
    spec : the [frc] table
    br : the HB curve at P (or its exception), for the contact band
    rows, names : the output points (x1 first: the map's envelope, spectrum and jumps are read there)
    extra_hz : Hz, frequencies added to the grid (the stage's check frequencies)

    Returns
    -------
    MapLevel or None
    """
    if spec.map_step_hz <= 0.0:
        return None
    t0 = time.perf_counter()
    bd = bands(system, b, P, spec, br)
    freqs = map_frequencies(spec.freq_min_hz, spec.freq_max_hz, bd, spec.map_step_hz, spec.map_coarse_points)
    freqs = np.unique(np.round(np.concatenate([freqs, np.asarray(extra_hz, float)]), 9))
    opts = MapOptions(n_transient=MAP_TRANSIENT, n_record=spec.map_periods)
    sweeps = {d: friction_response_map(system, b, P, fr, direction=d, point_rows=rows, point_names=names,
                                       options=opts, extend_step_hz=spec.map_step_hz, jump_step_hz=spec.map_step_hz)
              for d, fr in (("up", freqs), ("down", freqs[::-1]))}
    return MapLevel(float(P), bd, sweeps, time.perf_counter() - t0)


def state_at(level: MapLevel | None, freq_hz: float, direction: str = "up"):
    """(the point's PointResponse, its end state [x; v; w]) of a sweep at ``freq_hz`` (within 1e-9 Hz), or None.

    Parameters
    ----------
    level : the level's map (or None: none)
    freq_hz : Hz
    direction : the sweep, ``up`` or ``down``
    """
    if level is None:
        return None
    rm = level.sweeps[direction]
    k = np.flatnonzero(np.abs(rm.freq_hz - freq_hz) <= 1e-9 * max(freq_hz, 1.0))
    if not k.size:
        return None
    pt = rm.points[int(k[0])]
    return pt, pt.state


def write(result, writer) -> None:
    """response_map.csv, response_map_jumps.csv and response_map.png (nothing without a map); the statistics in
    ``writer.stats["frc"]["response_map"]``.

    Parameters
    ----------
    result : FrictionFRCResult
    writer : StageWriter
    """
    maps = {P: lvl for P, lvl in (getattr(result, "response_maps", {}) or {}).items() if lvl is not None}
    if not maps:
        return
    col = x1_column(result)
    writer.stats.setdefault("frc", {})["response_map"] = write_tables(maps, writer, col)
    _plot(writer.path("response_map.png"), result, maps, col)


def stretches(rm, col: int) -> list[tuple[float, float, str, np.ndarray, np.ndarray]]:
    """[(f_from, f_to, label, exponents (k,), per-period max |x1| min and max (k, 2))]: the runs of consecutive
    frequencies of a sweep (in sweep order) with the same regime (and period).

    Parameters
    ----------
    rm : the sweep (ResponseMap)
    col : the column of x1 among the monitored points
    """
    out, cur = [], None
    for f, pt in zip(rm.freq_hz, rm.points, strict=True):
        lab = _label(pt) if pt.settled else f"{_label(pt)} (not settled)"
        pk = pt.peak[:, col]
        if cur is None or cur[2] != lab:
            cur = [f, f, lab, [], []]
            out.append(cur)
        cur[1] = f
        cur[3].append(pt.lyapunov_per_s)
        cur[4].append((pk.min(), pk.max()))
    return [(a, b, lab, np.array(lam), np.array(env)) for a, b, lab, lam, env in out]


def markdown(result) -> list[str]:
    """frc.md's section on the response map (empty without one).

    Parameters
    ----------
    result : FrictionFRCResult
    """
    maps = {P: lvl for P, lvl in (getattr(result, "response_maps", {}) or {}).items() if lvl is not None}
    if not maps:
        return []
    col = x1_column(result)
    spec = result.scene.frc
    lines = ["## The response map: what a stepped-sine test sees (response_map.csv, response_map.png)", "",
             f"A stepped sine up and down by the exact friction flow (stick, slip and gaps as events), "
             f"{spec.map_step_hz:g} Hz steps over the contact band (the HB curve's and the linear response's, "
             f"+-{BAND_MARGIN_HZ:g} Hz; further while the sweep's own response stays in contact), "
             f"{spec.map_coarse_points} log-spaced frequencies elsewhere; the state (the sliders' positions included) "
             f"carried from one frequency to the next; at each, {MAP_TRANSIENT} periods run, then "
             f"{spec.map_periods} recorded (more, up to 4 blocks, while undecided). Each frequency classified "
             "(reduced.periodic.response_map.classify, as without friction) by its Poincare samples once a forcing "
             "period (a return within 1e-6 in p periods: periodic, p > 1 subharmonic; a contracting response finished "
             "by Newton on the p-period map with its exact Jacobian, its exponent then ln max |mu| / (p T)) and the "
             "largest Lyapunov exponent of the exact tangent (reduced.periodic.friction_map: the state transition "
             "matrices between events and the saltation matrix at every gap, stick and slip event; a slider open or "
             "slipping has its w slaved to x and is projected onto that at every period start, so it adds a multiplier "
             "0: the state has 2n + (sliders stuck) dimensions, changing at the events): chaotic where it is above "
             "its tolerance (lyapunov_tol_per_s: the spread of the record's quarters, at least 0.1 of the slowest "
             "linear decay rate). The envelope: the per-period max |x1| over the recorded periods (x1_min_m, "
             "x1_mean_m, x1_max_m), read on 64 uniform samples a period; asymmetry max |x1 - x3| / max(|x1|, |x3|).",
             ""]
    for P, lvl in maps.items():
        for d, rm in lvl.sweeps.items():
            counts = {r: sum(p.regime == r for p in rm.points) for r in REGIME_COLORS}
            jumps = ", ".join(f"{f:.4g}" for f in rm.jump_hz) or "none"
            lines.append(f"- {P:g} N, sweep {d}: {rm.freq_hz.size} frequencies, "
                         + ", ".join(f"{v} {k}" for k, v in counts.items() if v)
                         + f"; jumps at {jumps} Hz.")  # run times: provenance.json (frc.md is compared digit by digit)
            for a, b, lab, lam, env in stretches(rm, col):
                span = f"{a:.4g} Hz" if a == b else f"{a:.4g} -> {b:.4g} Hz"
                lines.append(f"  - {span}: {lab}, exponent {lam.min():.3g} .. {lam.max():.3g} 1/s, per-period max "
                             f"|x1| {env[:, 0].min():.3g} .. {env[:, 1].max():.3g} m")
    lines += ["", "Where the map is chaotic the sweep's state after it is set by round-off (response_map.csv's "
              "after_chaos): the reproduction report does not require those rows to reproduce, only their regimes "
              "and the amplitudes of the periodic rows before them.", ""]
    return lines


def _plot(path, result, maps: dict, col: int) -> None:
    """response_map.png: per level, top the HB curve (faint: not converged in contact), the exact orbits continued
    by shooting and the envelope of each sweep (min to max of the per-period max |x1|, the mean coloured by
    regime); bottom the Poincare samples of x1 (the brute-force bifurcation diagram)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(2, len(maps), figsize=(5.6 * len(maps) + 2.4, 8.0), squeeze=False, sharex="col")
    for c, (P, lvl) in enumerate(maps.items()):
        top, bot = axs[0][c], axs[1][c]
        br = result.curves.get(P)
        if br is not None and not isinstance(br, Exception):
            top.plot(br.freq_hz, br.amplitude_m[:, col], "-", color="0.6", lw=0.7, label=f"HB (H = {br.balance.H})")
        scs = result.shooting.get(P)
        for sc in (scs if isinstance(scs, list) else []):
            brn = sc.branch
            top.plot(brn.freq_hz, brn.amplitude_m[:, col], "-", color="k", lw=1.2,
                     label="exact orbits (shooting, all unstable)" if not np.any(brn.stable) else "exact orbits")
        for d, rm in lvl.sweeps.items():
            stt = rm.peak_stats(col)
            order = np.argsort(rm.freq_hz)
            shade = "C1" if d == "up" else "C9"
            top.fill_between(rm.freq_hz[order], stt[order, 0], stt[order, 2], color=shade, alpha=0.25, lw=0,
                             label=f"envelope {d} (per-period max |x1|, min to max)")
            for reg, colr in REGIME_COLORS.items():
                m = np.array([p.regime == reg for p in rm.points])
                if not m.any():
                    continue
                top.plot(rm.freq_hz[m], stt[m, 1], "^" if d == "up" else "v", ms=3, color=colr, mew=0,
                         label=f"{reg} (mean)")
                pts = [p for p in rm.points if p.regime == reg]
                f = np.concatenate([np.full(len(p.poincare), fk) for fk, p in zip(rm.freq_hz[m], pts, strict=True)])
                x = np.concatenate([p.poincare[:, col] for p in pts])
                bot.plot(f, x, "." if d == "up" else "x", ms=1.5, color=colr, alpha=0.6, mew=0.4,
                         label=f"{reg} ({d})")
            bot.plot(rm.jump_hz, np.zeros(rm.jump_hz.size), "|", ms=14, color=shade, label=f"jump ({d})")
        top.set_ylabel("max |x1| over a period [m]")
        bot.set_ylabel("x1 at t = k T (Poincare) [m]")
        bot.set_xlabel("excitation frequency [Hz]")
        top.set_title(f"{P:g} N", fontsize=9)
        for ax in (top, bot):
            ax.grid(True, alpha=0.2)
    for row in axs:
        uniq = {}
        for ax in row:
            handles, labels = ax.get_legend_handles_labels()
            uniq.update(zip(labels, handles, strict=True))
        row[-1].legend(uniq.values(), uniq.keys(), fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                       borderaxespad=0.0, markerscale=2)
    fig.suptitle(f"{result.scene.name}: response map with friction at the tips (stepped sine by the exact friction "
                 "flow, up and down; regimes by Poincare samples and the largest Lyapunov exponent)", fontsize=9,
                 wrap=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


__all__ = ["MAP_TRANSIENT", "bands", "compute_map", "markdown", "state_at", "stretches", "write"]
