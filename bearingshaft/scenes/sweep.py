"""The [sweep] table (and ``--vary`` on the command line): which scene keys vary over which
values, and the design that combines them. Only the table is read here; the cases are
built and checked by :mod:`bearingshaft.sweep.plan`."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from bearingshaft.scenes.errors import SweepError, suggest
from bearingshaft.scenes.tables import SECTIONS

DESIGNS = ("grid", "zip", "random")
OVERLAYS = ("", "nnm_stability")
MAX_CASES = 100_000  # cases in one sweep (each is validated before any runs)
TABLES = ("model", "initial", "load", *(s for s in SECTIONS if s != "initial"))
KEY_PATTERN = re.compile(r"^(?P<table>[A-Za-z_]\w*)(?:\[(?P<ti>\d+)\])?\.(?P<name>[A-Za-z_]\w*)(?:\[(?P<i>\d+)\])?$")
INT_PATTERN = re.compile(r"^[+-]?\d+$")

# -- the design -------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Vary:
    """One varied key: its values (list or LO:HI:N range), or a range LO:HI for a random design.

    Parameters
    ----------
    key : str
        The scene key: ``model.gap``, ``initial.v0_m_s[1]``, ``load[0].peak_N``.
    values : tuple
        The values of a grid or zip design.
    low, high : float, optional
        A random design's range.
    log : bool
        The values (or the random draws) are spaced geometrically.
    integer : bool
        The range's ends are written as integers: values are rounded.
    text : str
        As written, for messages.
    """

    key: str  # "model.gap", "initial.v0_m_s[1]", "load[0].peak_N"
    values: tuple = ()  # the values of a grid or zip design
    low: float | None = None  # a random design's range
    high: float | None = None
    log: bool = False
    integer: bool = False  # the range's ends are written as integers: values are rounded
    text: str = ""  # as written, for messages

    @property
    def is_range(self) -> bool:
        return self.low is not None


@dataclass(frozen=True, slots=True)
class SweepSpec:
    """The ``[sweep]`` table (or ``--vary`` and its options).

    Parameters
    ----------
    vary : tuple of Vary
        The varied keys.
    design : {'grid', 'zip', 'random'}
        Every combination, the i-th values together, or random draws in the ranges.
    samples : int
        Random design: number of cases.
    seed : int
        Random design: seed.
    plots : tuple of str
        Metric columns drawn (default: the ``DEFAULT_PLOTS`` that exist).
    x : str
        Column drawn on the x axis instead of the varied key (one varied key).
    overlay : str
        "nnm_stability" or "".
    """

    vary: tuple[Vary, ...] = ()  # [sweep.vary]: the varied keys and their values
    design: str = "grid"  # grid (every combination) | zip (the i-th values together) | random
    samples: int = 0  # random design: number of cases
    seed: int = 0  # random design: seed
    plots: tuple[str, ...] = ()  # metric columns drawn (default: DEFAULT_PLOTS that exist)
    x: str = ""  # column drawn on the x axis instead of the varied key (one varied key)
    overlay: str = ""  # "nnm_stability": the Floquet stability of NNM 1 and 3 beside the plot


def _literal(text: str):
    """A value as written on the command line: integer, number, true/false, else a string."""
    s = text.strip()
    if INT_PATTERN.match(s):
        return int(s)
    if s in ("true", "false"):
        return s == "true"
    try:
        return float(s)
    except ValueError:
        return s.strip("\"'")


def _number(text: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise SweepError(f"{where}: {text.strip()!r} is not a number") from None
    if not math.isfinite(v):
        raise SweepError(f"{where}: {text.strip()!r} must be finite")
    return v


def parse_values(key: str, value, where: str) -> Vary:
    """A :class:`Vary` from a TOML value or a command-line string (``where`` names it in errors).

    Strings: ``a,b,c`` (a list), ``LO:HI:N`` (N values, linear), ``LO:HI:N:log`` (geometric),
    ``LO:HI`` or ``LO:HI:log`` (a range for the random design). TOML lists and numbers are
    values as they are.

    Parameters
    ----------
    key : str
        The scene key varied (checked by :func:`check_key`).
    value : list, number, bool or str
        The values, as above.
    where : str
        Where they were given, for the messages.

    Returns
    -------
    Vary

    Raises
    ------
    SweepError
        A bad key, an empty list, a nested value, a malformed range, a log range through 0, HI <= LO
        for a range, or a count that is not an integer in [1, ``MAX_CASES``].
    """
    check_key(key, where)
    if isinstance(value, list):
        if not value:
            raise SweepError(f"{where}: the list is empty; give at least one value")
        for v in value:
            if isinstance(v, (list, dict)):
                raise SweepError(f"{where}: values must be numbers, strings or booleans, got {v!r}")
        return Vary(key, tuple(value), text=repr(value))
    if isinstance(value, (bool, int, float)):
        return Vary(key, (value,), text=repr(value))
    if not isinstance(value, str):
        raise SweepError(f"{where}: expected a list or a string such as '1e-4:1e-3:9:log', got {value!r}")
    text = value.strip()
    if not text:
        raise SweepError(f"{where}: no values given")
    if ":" not in text:
        return Vary(key, tuple(_literal(p) for p in text.split(",")), text=text)
    parts = [p.strip() for p in text.split(":")]
    scale = "lin"
    if parts[-1] in ("log", "lin"):
        scale = parts.pop()
    if len(parts) not in (2, 3):
        raise SweepError(f"{where}: {text!r} is not LO:HI:N[:log] (grid, zip) or LO:HI[:log] (random)")
    lo, hi = _number(parts[0], where), _number(parts[1], where)
    integer = scale == "lin" and bool(INT_PATTERN.match(parts[0]) and INT_PATTERN.match(parts[1]))
    if scale == "log" and not (lo > 0 and hi > 0):
        raise SweepError(f"{where}: a log range needs LO > 0 and HI > 0, got {text!r}")
    if len(parts) == 2:
        if not hi > lo:
            raise SweepError(f"{where}: a range needs HI > LO, got {text!r}")
        return Vary(key, low=lo, high=hi, log=scale == "log", integer=integer, text=text)
    if not INT_PATTERN.match(parts[2]) or int(parts[2]) < 1:
        raise SweepError(f"{where}: the number of values must be an integer >= 1, got {parts[2]!r}")
    n = int(parts[2])
    if n > MAX_CASES:
        raise SweepError(f"{where}: {n} values is too many (at most {MAX_CASES})")
    if n == 1:
        vals = np.array([lo])
    elif scale == "log":
        vals = np.geomspace(lo, hi, n)
        vals[0], vals[-1] = lo, hi  # the ends exactly as written
    else:
        vals = np.linspace(lo, hi, n)
    out = tuple(int(round(v)) for v in vals) if integer else tuple(float(v) for v in vals)
    return Vary(key, out, log=scale == "log", integer=integer, text=text)


def parse_vary_option(text: str) -> Vary:
    """``--vary KEY=VALUES`` as a :class:`Vary`.

    Parameters
    ----------
    text : str
        ``KEY=VALUES``.

    Returns
    -------
    Vary

    Raises
    ------
    SweepError
        No ``=`` or no key, or values :func:`parse_values` refuses.
    """
    key, sep, values = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise SweepError(f"--vary {text!r}: expected KEY=VALUES, e.g. model.gap=1e-4:1e-3:9:log or model.k_g=1e7,1e8")
    return parse_values(key, values, f"--vary {key}")


def check_key(key: str, where: str) -> None:
    """``key`` is TABLE.KEY, TABLE.KEY[i] or load[i].KEY of a scene table.

    Parameters
    ----------
    key : str
        The key.
    where : str
        Where it was given, for the messages.

    Returns
    -------
    None

    Raises
    ------
    SweepError
        Not of that form, an unknown table, or an index on a table that is not [[load]] (or none on
        one that is).
    """
    m = KEY_PATTERN.match(key)
    if m is None:
        raise SweepError(f"{where}: {key!r} is not a scene key: write TABLE.KEY (e.g. model.gap), TABLE.KEY[i] "
                         "for an element of a list, or load[i].KEY")
    table = m["table"]
    if table not in TABLES:
        raise SweepError(f"{where}: unknown table {table!r}{suggest(table, TABLES)} (known: {', '.join(TABLES)})")
    if (table == "load") != (m["ti"] is not None):
        hint = ("[[load]] tables are numbered: load[0].KEY" if table == "load"
                else f"[{table}] is one table: {table}.KEY")
        raise SweepError(f"{where}: {key!r}: {hint}")


def parse_sweep_table(table, origin: str) -> SweepSpec:
    """The scene's ``[sweep]`` table, every key checked (the cases themselves: :func:`build_plan`).

    Parameters
    ----------
    table : dict
        The [sweep] table.
    origin : str
        The scene file, for the messages.

    Returns
    -------
    SweepSpec

    Raises
    ------
    SweepError
        Not a table, an unknown key, a value of the wrong type, or a design rule broken
        (:func:`check_spec`).
    """
    where = f"{origin} [sweep]"
    if not isinstance(table, dict):
        raise SweepError(f"{where}: expected a table, got {table!r}"[:200])
    known = ("vary", "design", "samples", "seed", "plots", "x", "overlay")
    for key in table:
        if key not in known:
            raise SweepError(f"{where}: unknown key {key!r}{suggest(key, known)} (known: {', '.join(known)})")
    vary = table.get("vary", {})
    if not isinstance(vary, dict):
        raise SweepError(f"{where} vary: expected a table of KEY = VALUES ([sweep.vary]), got {vary!r}"[:200])
    design = table.get("design", "grid")
    samples = table.get("samples", 0)
    seed = table.get("seed", 0)
    for name, v in (("samples", samples), ("seed", seed)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 0 or v > MAX_CASES * 1000:
            raise SweepError(f"{where} {name}: expected an integer >= 0, got {v!r}")
    plots = table.get("plots", [])
    if not isinstance(plots, list) or not all(isinstance(p, str) for p in plots):
        raise SweepError(f"{where} plots: expected a list of metric names, got {plots!r}"[:200])
    for name in ("x", "overlay"):
        if not isinstance(table.get(name, ""), str):
            raise SweepError(f"{where} {name}: expected a string, got {table[name]!r}")
    spec = SweepSpec(tuple(parse_values(k, v, f"{where} vary {k}") for k, v in vary.items()), design, samples,
                     seed, tuple(plots), table.get("x", ""), table.get("overlay", ""))
    return check_spec(spec, where)


def check_spec(spec: SweepSpec, where: str) -> SweepSpec:
    """The design's own rules (the values are checked case by case later).

    Parameters
    ----------
    spec : SweepSpec
        The sweep.
    where : str
        Where it was given, for the messages.

    Returns
    -------
    SweepSpec
        ``spec``.

    Raises
    ------
    SweepError
        An unknown design or overlay, a key varied twice, ranges in a grid or zip design (or values
        in a random one), a random design without samples, or zip values of unequal counts.
    """
    if not isinstance(spec.design, str) or spec.design not in DESIGNS:
        raise SweepError(f"{where} design: unknown design {spec.design!r}{suggest(str(spec.design), DESIGNS)} "
                         f"(known: {', '.join(DESIGNS)})")
    if spec.overlay not in OVERLAYS:
        raise SweepError(f"{where} overlay: unknown overlay {spec.overlay!r}{suggest(spec.overlay, OVERLAYS)} "
                         f"(known: {', '.join(o for o in OVERLAYS if o)})")
    keys = [v.key for v in spec.vary]
    for k in keys:
        if keys.count(k) > 1:
            raise SweepError(f"{where} vary {k}: the key is varied twice")
    if spec.design == "random":
        if spec.vary and spec.samples < 1:
            raise SweepError(f"{where} samples: the random design needs samples >= 1 (the number of cases)")
        for v in spec.vary:
            if not v.is_range:
                raise SweepError(f"{where} vary {v.key}: the random design samples a range: give LO:HI or "
                                 f"LO:HI:log, not {v.text!r}")
    else:
        for v in spec.vary:
            if v.is_range:
                raise SweepError(f"{where} vary {v.key}: the {spec.design} design needs the values: give LO:HI:N "
                                 f"or LO:HI:N:log or a list, not {v.text!r}")
        if spec.design == "zip" and len({len(v.values) for v in spec.vary}) > 1:
            sizes = ", ".join(f"{v.key}: {len(v.values)}" for v in spec.vary)
            raise SweepError(f"{where} vary: the zip design pairs the i-th values, so every key needs as many "
                             f"values ({sizes})")
    return spec

