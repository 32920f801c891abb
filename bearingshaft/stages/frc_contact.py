"""frc.md: one statement per level about the contact band (part of stage ``frc``, issue 25): which exact
family covers which of its HB points, and for each band no family from the HB curve reaches what the
verdicts of shooting at its HB points found (exact orbits that start a family, or no orbit of the exact flow
near them, with the best defect), whether the open-gap orbit closes no stop there, and what the response
map's stepped sine shows there. Text only: no solver runs here.

The contact band is the HB curve's points in contact (``ExactFRC.cover_freqs_hz``). A point is credited to
the lowest-numbered family whose frequency range (a continuous piece of it) holds it
(:func:`reduced.periodic.exact_frc.covered`); the bands are those the verdicts were judged in
(``Verdict.band_hz``, frc_cover.csv), else the runs no family covers (``ExactFRC.uncovered_bands``).
"""

from __future__ import annotations

import numpy as np

from reduced.periodic.exact_frc import covered

TOL_HZ = 1e-9  # Hz: a band's ends are HB frequencies written to full precision; this only absorbs round-off


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the runs of True in ``mask`` (1-D bool)."""
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def owners(families: list, freq_hz: np.ndarray) -> np.ndarray:
    """(k,) int: the lowest-numbered family whose range holds each frequency, -1 where none does.

    Parameters
    ----------
    families : list of reduced.periodic.exact_frc.OrbitFamily
    freq_hz : (k,) Hz

    Returns
    -------
    ndarray
    """
    f = np.asarray(freq_hz, float)
    out = np.full(f.shape, -1)
    for k, fam in enumerate(families):
        out[(out < 0) & covered([fam], f)] = k
    return out


def map_regimes(lvl, lo: float, hi: float) -> str:
    """'chaotic at 40, periodic 1 T with contact at 3 (up); ...': the response map's regimes over [lo, hi] Hz per
    sweep ('' without a response map).

    Parameters
    ----------
    lvl : bearingshaft.stages.frc_results.MapLevel or None
    lo, hi : Hz, the band's ends

    Returns
    -------
    str
    """
    if lvl is None:
        return ""
    out = []
    for d, rm in lvl.sweeps.items():
        n = {}
        for f, p in zip(rm.freq_hz, rm.points, strict=True):
            if lo - TOL_HZ <= f <= hi + TOL_HZ:
                key = p.regime + ("" if p.regime not in ("periodic", "subharmonic") else
                                  f" {p.period_k} T{' with contact' if p.contact else ' without contact'}")
                n[key] = n.get(key, 0) + 1
        if n:
            out.append(", ".join(f"{k} at {v}" for k, v in sorted(n.items(), key=lambda kv: -kv[1])) + f" ({d})")
    return "; ".join(out)


def _range(f: np.ndarray) -> str:
    """'a-b Hz' (or 'a Hz') of the frequencies ``f`` (Hz)."""
    return f"{f.min():.5g} Hz" if f.min() == f.max() else f"{f.min():.5g}-{f.max():.5g} Hz"


def _family(ex, k: int) -> str:
    """'family 3 (asymmetric, 17.04-17.118 Hz, unstable)'."""
    fam = ex.families[k]
    return (f"family {k} ({fam.kind}, {_range(fam.freq_hz)}, "
            + (f"stable at {int(np.sum(fam.stable))} points)" if np.any(fam.stable) else "unstable)"))


def _band(ex, lo: float, hi: float, f: np.ndarray, own: np.ndarray, verdicts: list, lvl, open_gap,
          verdict_points: int) -> str:
    """The statement about one band [lo, hi] Hz of HB points in contact no family from the HB curve reached."""
    inb = (f >= lo - TOL_HZ) & (f <= hi + TOL_HZ)
    n = int(inb.sum())
    head = f"{lo:.5g}-{hi:.5g} Hz ({n} HB point{'' if n == 1 else 's'})"
    judged = [v for v in verdicts if v.verdict not in ("covered", "not_judged") or v.segments]
    said = []
    if not verdicts:
        said.append("not judged (`[frc] verdict_points = 0`)" if not verdict_points else "not judged")
    else:
        said.append(f"judged by shooting at {len(judged)}")
        orbits = [v for v in judged if v.verdict == "orbit" and v.family >= 0]
        if orbits:
            said.append("exact orbits that start " + ", ".join(
                f"{_family(ex, v.family)} at {v.freq_hz:.5g} Hz" for v in orbits))
        known = [v for v in judged if v.verdict == "known" and v.family >= 0]
        if known:
            said.append("orbits of known families " + ", ".join(
                f"{v.family} at {v.freq_hz:.5g} Hz" for v in known))
        none = [v for v in judged if v.verdict == "no_orbit"]
        if none:
            said.append("no orbit of the exact flow near the HB point" + ("s" if len(none) > 1 else "")
                        + " judged at " + ", ".join(f"{v.freq_hz:.5g}" for v in none)
                        + f" Hz (best defect {min(v.defect for v in none):.2g})")
        rest = [v for v in judged if v not in orbits + known + none]
        said += [f"{v.verdict} at {v.freq_hz:.5g} Hz (defect {v.defect:.2g})" for v in rest]
    now = inb & (own >= 0)
    left = inb & (own < 0)
    cover = (f"covered now by a family: {int(now.sum())} of {n}"
             + ("" if not left.any() else "; by none: "
                + ", ".join(_range(f[r]) for r in _runs(left))))
    free = 0 if open_gap is None else int(np.sum(np.isin(f[inb], open_gap.freq_hz)))
    text = head + ": " + ", ".join(said[:1]) + ("; " + "; ".join(said[1:]) if said[1:] else "") + "; " + cover
    if free:
        text += f"; the open-gap orbit closes no stop at {free} of them (an exact orbit beside the HB one, drawn)"
    regimes = map_regimes(lvl, lo, hi)
    return text + (f"; the stepped sine there (response_map.csv): {regimes}" if regimes else "")


def contact_statement(ex, lvl, open_gap=None, verdict_points: int = 1) -> str:
    """frc.md: the level's statement about its contact band, one paragraph.

    Parameters
    ----------
    ex : reduced.periodic.exact_frc.ExactFRC
        The level's exact families, with ``cover_freqs_hz`` (Hz, the HB points in contact) and ``verdicts``.
    lvl : bearingshaft.stages.frc_results.MapLevel or None
        The level's response map.
    open_gap : bearingshaft.stages.frc_results.OpenGapOrbits or None
        The open-gap orbits drawn (their ``freq_hz``, Hz).
    verdict_points : int
        ``[frc] verdict_points`` (0: the bands were not judged).

    Returns
    -------
    str
        '' when the HB curve has no point in contact.
    """
    f = np.sort(np.asarray(ex.cover_freqs_hz, float))
    if not f.size:
        return ""
    own = owners(ex.families, f)
    bands = {}
    for v in ex.verdicts:
        bands.setdefault(tuple(v.band_hz), []).append(v)
    if not bands:
        bands = {(a, c): [] for a, c, _ in ex.uncovered_bands()}
    in_band = np.zeros(f.shape, bool)
    for lo, hi in bands:
        in_band |= (f >= lo - TOL_HZ) & (f <= hi + TOL_HZ)
    by = {}
    for k in np.unique(own[~in_band & (own >= 0)]):
        by[int(k)] = f[~in_band & (own == k)]
    text = f"Contact band ({f.size} HB points in contact, {_range(f)}): "
    if by:
        text += "covered by " + "; ".join(
            f"family {k} ({ex.families[k].kind}) at {fk.size} point{'' if fk.size == 1 else 's'}, {_range(fk)}"
            for k, fk in sorted(by.items(), key=lambda kv: kv[1].min()))
    stray = ~in_band & (own < 0)  # not reached and in no judged band: only when the verdicts ran before a change
    if stray.any():
        text += ("; " if by else "") + "by no family (not judged): " + ", ".join(_range(f[r]) for r in _runs(stray))
    if bands:
        said = [_band(ex, lo, hi, f, own, vs, lvl, open_gap, verdict_points) for (lo, hi), vs in sorted(bands.items())]
        text += (". " if by or stray.any() else "") + "No family from the HB curve reaches " + (
            said[0] + "." if len(said) == 1 else
            f"{len(said)} bands: " + " ".join(f"({i + 1}) {t}." for i, t in enumerate(said)))
        return text
    if not stray.any():
        text += "; every point is covered"
    return text + "."
