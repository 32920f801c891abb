"""Numbers as the science files write them: to the digits a rerun reproduces, and no more.

A deterministic quantity is written to the digits it converges to (``sig``); a round-off-level
one has no reproducible digit, only an order of magnitude (``decade_bound``, ``roundoff_bound``);
an error below what its reference resolves is written as 0 (``to_resolution``). The text
helpers (``text``, ``short``, ``cells``) are the one way a stage turns such numbers into CSV or
Markdown cells, and ``human`` writes byte counts. Every helper keeps what is not a number as it is.
"""

from __future__ import annotations

import math

import numpy as np

ROUNDOFF_FLOOR = 1e-10  # the exact integrator's energy balance and its distance to DOP853 with events:
# written as the power of ten that bounds them, at least this (below it, their size moved by up to
# 6x on another CPU)


def _is_number(value) -> bool:
    return isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)


def sig(value, digits: int):
    """``value`` rounded to ``digits`` significant digits (non-numbers and non-finite values kept).

    Parameters
    ----------
    value : object
        A number, or anything else (kept).
    digits : int
        Significant digits.

    Returns
    -------
    float, int or object
        A float rounded (through its decimal text), an int unchanged, anything else as given.

    Examples
    --------
    >>> sig(3.14159, 3), sig(12345, 2), sig("x", 3), sig(float("nan"), 3)
    (3.14, 12345, 'x', nan)
    """
    if not _is_number(value) or not math.isfinite(value):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(f"{float(value):.{digits}g}")


def decade_bound(value):
    """The smallest power of ten >= |value| (0 stays 0): a round-off-level quantity has no
    reproducible digit, only its order of magnitude (non-numbers kept).

    Parameters
    ----------
    value : object
        A number, or anything else (kept).

    Returns
    -------
    float or object
        10^ceil(log10 |value|), 0.0 for zero; non-finite values and non-numbers as given.

    Examples
    --------
    >>> decade_bound(3.2e-13), decade_bound(-1e-9), decade_bound(0.0)
    (1e-12, 1e-09, 0.0)
    """
    if not _is_number(value) or not math.isfinite(value):
        return value
    v = abs(float(value))
    return 0.0 if v == 0 else float(f"1e{math.ceil(math.log10(v) - 1e-12)}")


def roundoff_bound(value):
    """A round-off-level quantity as written: its :func:`decade_bound`, at least :data:`ROUNDOFF_FLOOR`.

    Parameters
    ----------
    value : object
        A number, or anything else (kept).

    Returns
    -------
    float or object
        max(:func:`decade_bound`, ``ROUNDOFF_FLOOR``) (0 becomes ``ROUNDOFF_FLOOR``).

    Examples
    --------
    >>> roundoff_bound(3.2e-13), roundoff_bound(4e-8)
    (1e-10, 1e-07)
    """
    bound = decade_bound(value)
    return max(bound, ROUNDOFF_FLOOR) if isinstance(bound, float) else bound


def to_resolution(value, resolution: float, digits: int):
    """``value`` rounded to a multiple of ``resolution`` when smaller than it in magnitude (0),
    else to ``digits`` significant digits: an error below what the reference resolves is 0.

    Parameters
    ----------
    value : object
        A number, or anything else (kept).
    resolution : float
        The smallest magnitude the reference resolves.
    digits : int
        Significant digits above it.

    Returns
    -------
    float or object

    Examples
    --------
    >>> to_resolution(3e-12, 1e-10, 3), to_resolution(1.23456e-6, 1e-10, 3)
    (0.0, 1.23e-06)
    """
    if not _is_number(value) or not math.isfinite(value):
        return value
    return 0.0 if abs(value) < resolution else sig(value, digits)


def short(value, spec: str = ".3g") -> str:
    """A number formatted by ``spec`` for Markdown text; anything else as ``str``.

    Parameters
    ----------
    value : object
        An int or float (not a bool) is formatted; anything else goes through ``str``.
    spec : str
        A format specification.

    Returns
    -------
    str

    Examples
    --------
    >>> short(0.000123456), short(2, ".2f"), short("n/a"), short(True)
    ('0.000123', '2.00', 'n/a', 'True')
    """
    return format(value, spec) if isinstance(value, (int, float)) and not isinstance(value, bool) else str(value)


def text(value, digits: int = 4):
    """A number to ``digits`` significant digits for a science file ('' for None or NaN, 'inf' and
    '-inf' for infinities); integers and non-numbers kept.

    Parameters
    ----------
    value : object
        A float (formatted), None, or anything else (kept, ints included).
    digits : int
        Significant digits.

    Returns
    -------
    str or object

    Examples
    --------
    >>> text(1 / 3), text(float("nan")), text(float("-inf")), text(None), text(7)
    ('0.3333', '', '-inf', '', 7)
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return format(float(value), f".{digits}g") if isinstance(value, float) else value


def dash(value: float, digits: int = 2) -> str:
    """A number to ``digits`` significant digits for a Markdown table, '-' where it is not finite.

    Parameters
    ----------
    value : float
        The number.
    digits : int
        Significant digits.

    Returns
    -------
    str

    Examples
    --------
    >>> dash(0.012345), dash(float("nan"))
    ('0.012', '-')
    """
    return "-" if not np.isfinite(value) else f"{value:.{digits}g}"


def cells(rows: list[dict], formats: dict[str, str], default: str = ".6g") -> list[dict]:
    """Rows with floats as text to their converged digits: ``formats[key]`` or ``default``.

    Parameters
    ----------
    rows : list of dict
        Rows of a table.
    formats : dict of str to str
        Format specification per key.
    default : str
        Format specification of the other float cells.

    Returns
    -------
    list of dict
        New rows: float cells as text, the others as given.

    Examples
    --------
    >>> cells([{"f": 1.23456789, "e": 1.5e-9, "n": 3}], {"e": ".1e"})
    [{'f': '1.23457', 'e': '1.5e-09', 'n': 3}]
    """
    return [{k: format(v, formats.get(k, default)) if isinstance(v, float) else v for k, v in r.items()}
            for r in rows]


def human(n: float) -> str:
    """Bytes in B, KiB, MiB, GiB or TiB.

    Parameters
    ----------
    n : float
        bytes.

    Returns
    -------
    str
        Three significant digits and a binary unit, from B to PiB; four digits from 999.5 to 1023 of a unit
        (``.3g`` would write them with an exponent, 1.01e+03).

    Examples
    --------
    >>> human(512), human(3 * 2**20), human(1.5 * 2**40), human(1010 * 2**20), human(999.4)
    ('512 B', '3 MiB', '1.5 TiB', '1010 MiB', '999 B')
    """
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            break
        n /= 1024
    return f"{n:.3g} {unit}" if abs(n) < 999.5 else f"{n:.0f} {unit}"
