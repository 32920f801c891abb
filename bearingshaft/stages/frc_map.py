"""Part of stage ``frc``: the response map (issue 25), what a stepped-sine test sees at each frequency.

For each load level a stepped sine up and down by the exact flow, each frequency classified as
periodic (with its period), subharmonic, quasi-periodic or chaotic by its Poincare samples, its
largest Lyapunov exponent (the tangent of the exact flow, saltation = I: :mod:`reduced.transient.lyapunov`)
and its spectrum (:mod:`reduced.periodic.response_map`). The frequencies: ``[frc] map_step_hz``
steps over the contact band, ``map_coarse_points`` log-spaced elsewhere. The contact band is where
the linear response reaches a stop or the HB curve at that level is in contact
(:func:`contact_bands`), widened by :data:`BAND_MARGIN_HZ`; each sweep also keeps the fine step
beyond it while its own response stays in contact. :func:`compute_maps` is called by
:func:`bearingshaft.stages.frc.compute`; :mod:`bearingshaft.stages.frc_map_files` writes
``response_map.csv``, ``response_map_jumps.csv``, ``response_map.png`` and ``response_map_spectra.png``.
"""

from __future__ import annotations

import time

import numpy as np

from bearingshaft.stages.frc_results import MapLevel
from reduced.models.gaps import GapSystem
from reduced.periodic.frc import max_abs_over_period
from reduced.periodic.response_map import (
    MapOptions,
    linear_contact_bands,
    map_frequencies,
    merge_bands,
    response_map,
)

BAND_MARGIN_HZ = 1.0  # Hz, each contact band widened by this on both sides (the sweeps' jumps lie just outside)


def curve_contact_bands(system: GapSystem, curve) -> list[tuple[float, float]]:
    """Hz: the frequency spans of the runs of consecutive points of an HB curve whose orbit closes a
    stop (max |B x| over a period above the stop's offset); none for a curve that failed.

    Parameters
    ----------
    system : the gap system
    curve : an FRCBranch, or the exception of a curve that could not start

    Returns
    -------
    list of (lo, hi)
        Hz, in curve order (may overlap).
    """
    if isinstance(curve, Exception):
        return []
    touch = np.array([bool(np.any(max_abs_over_period(X, system.B) > np.abs(system.offset))) for X in curve.X])
    out, i = [], 0
    while i < touch.size:
        if touch[i]:
            j = i
            while j + 1 < touch.size and touch[j + 1]:
                j += 1
            f = curve.freq_hz[i:j + 1]
            out.append((float(f.min()), float(f.max())))
            i = j + 1
        else:
            i += 1
    return out


def contact_bands(system: GapSystem, b: np.ndarray, P: float, spec, curve) -> list[tuple[float, float]]:
    """Hz: the union of the linear response's contact band and the HB curve's, widened by
    :data:`BAND_MARGIN_HZ` and clipped to the scene's band.

    Parameters
    ----------
    system : the gap system
    b : (n,) the load direction
    P : N, the level
    spec : the [frc] table
    curve : the HB curve at P (or its exception)

    Returns
    -------
    list of (lo, hi)
        Hz, disjoint, increasing.
    """
    raw = linear_contact_bands(system, b, P, spec.freq_min_hz, spec.freq_max_hz) + curve_contact_bands(system, curve)
    return [(max(lo, spec.freq_min_hz), min(hi, spec.freq_max_hz)) for lo, hi in merge_bands(raw, BAND_MARGIN_HZ)]


def compute_maps(system: GapSystem, b: np.ndarray, rows: np.ndarray, names: tuple, spec, curves: dict,
                 bar=None, levels=None) -> dict:
    """P -> MapLevel for every level of ``[frc] levels_N`` (empty with ``map_step_hz = 0``).

    Parameters
    ----------
    system : the gap system
    b : (n,) the load direction
    rows, names : the output points (x1 first is what the map reads: its envelope, spectrum, jumps)
    spec : the [frc] table
    curves : P -> FRCBranch (or its exception), for the contact bands
    bar : a tqdm bar to describe the work on (or None)
    levels : the levels (N) to map, default every level of ``[frc] levels_N``

    Returns
    -------
    dict
        P -> :class:`bearingshaft.stages.frc_results.MapLevel`.
    """
    if spec.map_step_hz <= 0.0:
        return {}
    opts = MapOptions(n_record=spec.map_periods)
    out = {}
    for P in spec.levels_N if levels is None else levels:
        t0 = time.perf_counter()
        bands = contact_bands(system, b, P, spec, curves.get(P, ValueError("no curve")))
        freqs = map_frequencies(spec.freq_min_hz, spec.freq_max_hz, bands, spec.map_step_hz, spec.map_coarse_points)
        sweeps = {}
        for direction, fr in (("up", freqs), ("down", freqs[::-1])):
            if bar is not None:
                bar.set_postfix_str(f"response map {P:g} N {direction}")
            sweeps[direction] = response_map(system, b, P, fr, direction=direction, point_rows=rows, point_names=names,
                                             options=opts, extend_step_hz=spec.map_step_hz)
        out[P] = MapLevel(float(P), bands, sweeps, time.perf_counter() - t0)
        if bar is not None:
            bar.update()
    return out


__all__ = ["BAND_MARGIN_HZ", "compute_maps", "contact_bands", "curve_contact_bands"]
