"""What a test would see (part of stage ``frc``, issue 25): the response map's frequencies of each level and
sweep grouped into bands of one regime, each periodic band matched to the drawn orbit it lies on; no solver
runs here.

The response map (:mod:`bearingshaft.stages.frc_map`) classifies each frequency of a stepped sine up and
down by the exact flow: periodic (period k forcing periods), quasi-periodic or chaotic, with the largest
Lyapunov exponent and the envelope of the per-period max |x1|. A periodic response that closes no stop
is the orbit of the open-gap (linear, damped) system, its only periodic orbit there (``open_gap``, stable:
the sweep settled on it). One in contact is matched to the level's drawn curve
(:func:`bearingshaft.stages.frc_files.drawn_curves`: the exact families, the open-gap orbits that close no
stop, HB where no stop closes) by its amplitude, max |x1| over its period, against each drawn piece's
amplitude interpolated linearly at its frequency, among the pieces of its period; the nearest within
:data:`MATCH_TOL` (relative) is its orbit. A band is a run of consecutive frequencies of one sweep with the
same regime, period, contact and orbit.

``frc_regimes.csv``: level, direction, freq_from_hz, freq_to_hz (in sweep order), points, regime,
period_k, contact, orbit (``family N``, ``open_gap``, ``hb`` or ``none``), orbit_kind (the family's
symmetry: main, asymmetric, half_wave_broken, period_doubled, ...; ``linear``), orbit_stable,
match_rel_diff (largest over the band), lyapunov_max_per_s, x1_min_m, x1_mean_m, x1_max_m (the envelope
over the band).
"""

from __future__ import annotations

import numpy as np

from bearingshaft.digits import sig

MATCH_TOL = 2e-3  # relative: a settled stepped sine is on its orbit to ~1e-5 (stepped_sine_tol); a family's
# points are ~1e-3 of the band apart, so the linear interpolation between them errs by up to ~1e-3 near a peak
DIGITS = 10
EXP_DIGITS = 4
FIELDS = ["level", "direction", "freq_from_hz", "freq_to_hz", "points", "regime", "period_k", "contact", "orbit",
          "orbit_kind", "orbit_stable", "match_rel_diff", "lyapunov_max_per_s", "x1_min_m", "x1_mean_m", "x1_max_m"]


def orbit_pieces(result, P: float, curve, col: int) -> list[tuple]:
    """(label, kind, period_k, freq_hz (k,), amplitude (k,), stable (k,)) per drawn piece of level P: each
    exact family's pieces, the open-gap orbits', HB's where it is drawn (``curve``: the drawn curve).

    Parameters
    ----------
    result : FRCResult
    P : N, the level
    curve : the level's drawn curve (or an exception)
    col : the column of the output point x1

    Returns
    -------
    list of tuple (frequencies in Hz, amplitudes in m)
    """
    out = []
    cc = result.converged.get(P)
    ex = cc.exact if cc is not None else None
    if ex is not None:
        for k, fam in enumerate(ex.families):
            for s in np.unique(fam.segment):
                i = np.flatnonzero(fam.segment == s)
                out.append((f"family {k}", fam.kind, int(fam.periods), fam.freq_hz[i], fam.amplitude_m[i, col],
                            fam.stable[i]))
        og = cc.open_gap
        if og is not None:
            for s in np.unique(og.segment):
                i = np.flatnonzero(og.segment == s)
                out.append(("open_gap", "open_gap", 1, og.freq_hz[i], og.amplitude_m[i, col],
                            np.full(i.size, og.stable)))
    hb = curve.hb_pieces() if hasattr(curve, "hb_pieces") else \
        curve.pieces() if curve is not None and not isinstance(curve, Exception) else []
    for i in hb:
        out.append(("hb", "main", 1, curve.freq_hz[i], curve.amplitude_m[i, col], curve.stable[i]))
    return out


def match(f: float, amp: float, period_k: int, pieces: list[tuple]) -> tuple[str, str, bool | None, float]:
    """(orbit, kind, stable, relative difference) of the drawn piece of period ``period_k`` whose amplitude,
    interpolated linearly at f between two consecutive points that bracket it, is nearest ``amp``;
    ("none", "", None, nearest difference or inf) when none is within :data:`MATCH_TOL`.

    Parameters
    ----------
    f : Hz
    amp : m, the response's max abs x1
    period_k : forcing periods
    pieces : :func:`orbit_pieces`

    Returns
    -------
    tuple

    >>> pcs = [("family 0", "main", 1, np.array([1.0, 2.0]), np.array([1.0, 3.0]), np.array([True, True]))]
    >>> match(1.5, 2.0, 1, pcs)
    ('family 0', 'main', True, 0.0)
    >>> match(1.5, 2.5, 1, pcs)[0], match(1.5, 2.0, 2, pcs)[0], match(2.5, 3.0, 1, pcs)[0]
    ('none', 'none', 'none')
    """
    best = ("none", "", None, np.inf)
    for label, kind, pk, fr, a, st in pieces:
        if pk != period_k or fr.size < 2:
            continue
        lo, hi = np.minimum(fr[:-1], fr[1:]), np.maximum(fr[:-1], fr[1:])
        for j in np.flatnonzero((lo <= f) & (f <= hi)):
            w = 0.0 if hi[j] == lo[j] else (f - fr[j]) / (fr[j + 1] - fr[j])
            d = abs((a[j] + w * (a[j + 1] - a[j])) / amp - 1.0)
            if d < best[3]:
                best = (label, kind, bool(st[j] and st[j + 1]), float(d))
    return best if best[3] <= MATCH_TOL else ("none", "", None, best[3])


def regime_rows(result, drawn: dict, col: int) -> list[dict]:
    """frc_regimes.csv rows (module docstring): per level and sweep, the bands of one regime and orbit.

    Parameters
    ----------
    result : FRCResult
        The stage's result (its response maps and drawn curves).
    drawn : dict
        P -> the drawn curve (:func:`bearingshaft.stages.frc_files.drawn_curves`).
    col : int
        The output point (x1).

    Returns
    -------
    list of dict
    """
    rows = []
    for P, lvl in (getattr(result, "response_maps", {}) or {}).items():
        pieces = orbit_pieces(result, P, drawn.get(P), col)
        for d, rm in lvl.sweeps.items():
            band = None
            for f, pt in zip(rm.freq_hz, rm.points, strict=True):
                pk = pt.peak[:, col]
                periodic = pt.regime in ("periodic", "subharmonic")
                if not periodic:
                    orbit, kind, stable, diff = "", "", None, np.nan
                elif not pt.contact:  # closes no stop: the open-gap system's orbit, its only periodic one
                    orbit, kind, stable, diff = "open_gap", "linear", True, np.nan
                else:
                    orbit, kind, stable, diff = match(float(f), float(pk.max()), int(pt.period_k), pieces)
                key = (pt.regime, int(pt.period_k), bool(pt.contact), orbit)
                if band is None or band["key"] != key:
                    band = {"key": key, "f": [], "lam": [], "min": [], "mean": [], "max": [], "diff": [],
                            "kind": kind, "stable": stable}
                    rows.append(band)
                    band["meta"] = (P, d)
                band["f"].append(float(f))
                band["lam"].append(float(pt.lyapunov_per_s))
                band["min"].append(float(pk.min()))
                band["mean"].append(float(pk.mean()))
                band["max"].append(float(pk.max()))
                band["diff"].append(diff)
                if stable is False:
                    band["stable"] = False
    return [_row(b) for b in rows]


def _row(b: dict) -> dict:
    regime, period_k, contact, orbit = b["key"]
    P, d = b["meta"]
    diff = [x for x in b["diff"] if np.isfinite(x)]
    return {"level": P, "direction": d, "freq_from_hz": sig(b["f"][0], DIGITS), "freq_to_hz": sig(b["f"][-1], DIGITS),
            "points": len(b["f"]), "regime": regime, "period_k": period_k, "contact": "true" if contact else "false",
            "orbit": orbit, "orbit_kind": b["kind"],
            "orbit_stable": "" if b["stable"] is None else ("true" if b["stable"] else "false"),
            "match_rel_diff": sig(max(diff), EXP_DIGITS) if diff else "",
            "lyapunov_max_per_s": sig(max(b["lam"]), EXP_DIGITS), "x1_min_m": sig(min(b["min"]), DIGITS),
            "x1_mean_m": sig(float(np.mean(b["mean"])), DIGITS), "x1_max_m": sig(max(b["max"]), DIGITS)}


def markdown(rows: list[dict], P: float, limit: int = 24) -> list[str]:
    """frc.md: the level's bands as a table (at most ``limit`` per sweep, the widest; all in frc_regimes.csv).

    Parameters
    ----------
    rows : frc_regimes.csv rows (frequencies in Hz, envelopes in m)
    P : N, the level
    limit : bands per sweep

    Returns
    -------
    list of str
    """
    mine = [r for r in rows if r["level"] == P]
    if not mine:
        return []
    out = ["", f"What a test would see at {P:g} N (frc_regimes.csv: the response map's frequencies in bands of one "
           "regime, a periodic one matched to the drawn orbit it lies on, within "
           f"{MATCH_TOL:g} of its amplitude):", "",
           "| sweep | f [Hz] | points | regime | orbit | stable | Lyapunov max [1/s] "
           "| max abs x1 min / mean / max [m] |",
           "|---|---|---|---|---|---|---|---|"]
    for d in ("up", "down"):
        rs = [r for r in mine if r["direction"] == d]
        shown = sorted(sorted(rs, key=lambda r: -r["points"])[:limit], key=rs.index)
        for r in shown:
            regime = r["regime"] + (f" {r['period_k']} T" if r["regime"] in ("periodic", "subharmonic") else "") \
                + (", contact" if r["contact"] == "true" else ", no contact")
            orbit = "" if not r["orbit"] else r["orbit"] + (f" ({r['orbit_kind']})" if r["orbit_kind"] else "")
            out.append(f"| {d} | {r['freq_from_hz']}-{r['freq_to_hz']} | {r['points']} | {regime} | {orbit} | "
                       f"{r['orbit_stable']} | {r['lyapunov_max_per_s']} | {r['x1_min_m']:.4g} / {r['x1_mean_m']:.4g}"
                       f" / {r['x1_max_m']:.4g} |")
        if len(rs) > len(shown):
            out.append(f"| {d} | ... | | {len(rs) - len(shown)} narrower bands in frc_regimes.csv | | | | |")
    return out
