"""Frequency intervals of the frc stage with friction (:mod:`bearingshaft.stages.frc_friction`): the HB curve's
contact band, what the continued exact orbits cover of it and what they leave (frc.md's coverage; the grid of
exact orbits :func:`bearingshaft.stages.frc_friction._swept` shoots there)."""

from __future__ import annotations

import numpy as np


def intervals(pairs) -> list[tuple[float, float]]:
    """The union of closed intervals [a, b] (a <= b or not), merged where they touch or overlap, in order.

    Examples
    --------
    >>> intervals([(3.0, 4.0), (1.0, 2.0), (2.0, 1.5), (3.5, 5.0)])
    [(1.0, 2.0), (3.0, 5.0)]

    Parameters
    ----------
    pairs : iterable of (a, b) Hz, in any order
    """
    out: list = []
    for a, b in sorted(tuple(sorted((float(a), float(b)))) for a, b in pairs):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def clip(ivs, band) -> list[tuple[float, float]]:
    """The intervals ``ivs`` (merged, :func:`intervals`) intersected with the union ``band``.

    Examples
    --------
    >>> clip([(1.0, 3.0), (5.0, 6.0)], [(2.0, 5.5)])
    [(2.0, 3.0), (5.0, 5.5)]

    Parameters
    ----------
    ivs : list of (a, b) Hz
    band : list of (c, d) Hz, merged
    """
    out = []
    for a, b in intervals(ivs):
        for c, d in band:
            lo, hi = max(a, c), min(b, d)
            if lo < hi:
                out.append((lo, hi))
    return intervals(out)


def complement(ivs, band) -> list[tuple[float, float]]:
    """The parts of the union ``band`` not in the intervals ``ivs``.

    Examples
    --------
    >>> complement([(2.0, 3.0)], [(1.0, 4.0)])
    [(1.0, 2.0), (3.0, 4.0)]

    Parameters
    ----------
    ivs : list of (a, b) Hz
    band : list of (c, d) Hz, merged
    """
    out = []
    for c, d in band:
        lo = c
        for a, b in clip(ivs, [(c, d)]):
            if a > lo:
                out.append((lo, a))
            lo = max(lo, b)
        if lo < d:
            out.append((lo, d))
    return out


def contact_band(br) -> list[tuple[float, float]]:
    """The frequency intervals of the HB curve ``br`` where a slider's tip touches over part of the period at two
    consecutive points (open fraction below 1: AFT's slider states), merged.

    Parameters
    ----------
    br : the HB curve with friction (its balance's slider states)
    """
    touch = [bool(np.any(br.balance.slider_state(z)[:, 0] < 1.0)) for z in br.z]
    return intervals((br.freq_hz[i - 1], br.freq_hz[i]) for i in range(1, len(touch)) if touch[i] and touch[i - 1])


__all__ = ["clip", "complement", "contact_band", "intervals"]
