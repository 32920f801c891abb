"""Every key of a scene, generated from the dataclasses that read it (``bearingshaft keys``).

The dataclasses are the single source; nothing here restates them:

- the **unit** and **meaning** of a key are its field's comment, unit first
  (``gap: float = 2.54e-4  # m, radial clearance at each tip``), read from the class's source with
  :mod:`tokenize` (a comment continued on the lines below the field belongs to it);
- its **type** and **default** are the field's;
- its **allowed values** are what the class's own checks say when they refuse a value: each key is
  given a few values of its type that a check may refuse (negative, zero, huge, empty, an unknown
  word), and the refusals that name the key (``n_energy must be >= 2, got -1``) are collected. The
  listing can so never promise what the checks do not hold, nor miss a check added later. Checks
  between tables (a [spectrogram] window longer than the run, ...) are the parser's, not listed.

:func:`scene_tables` lists the tables, :func:`table_keys` one table's keys as :class:`Key` rows,
:func:`format_keys` prints them.
"""

from __future__ import annotations

import dataclasses
import inspect
import io
import re
import textwrap
import tokenize
import typing
from dataclasses import dataclass
from functools import cache

from bearingshaft.scenes.convert import PATH_KEYS, type_hints
from bearingshaft.scenes.loads import LOAD_KINDS
from bearingshaft.scenes.models import MODEL_KINDS, model_class
from bearingshaft.scenes.sweep import SweepSpec
from bearingshaft.scenes.tables import SECTIONS

_UNIT_ATOMS = {"m", "s", "Hz", "N", "J", "kg", "rad", "Pa", "dB", "W", "degrees", "1", "-"}
_PROBES: dict[type, tuple] = {  # values a check may refuse, by field type
    float: (-1.0, 0.0, 1e-99, 1e99),
    int: (-1, 0, 100_000),
    str: ("\x01",),
}
_REFUSAL = re.compile(r"^(?P<key>\w+)(?P<index>\[\d+\])?:? (?P<rule>.*?)(?:, got .*)?$")
_IMPLIED = {">= 0": ("> 0", "in (0,"), "> 0": ("in (0,",)}  # a rule dropped when one of these is listed too
COUPLED = "within limits the other keys set"  # e.g. a beam too short for its spring seats; the refusal says which
_HUGE = ("1e+99", "1e-99", "100000")  # a rule quoting the huge probes restates the value, not the rule


@dataclass(frozen=True, slots=True)
class Key:
    """One key of a scene table, as ``bearingshaft keys`` lists it.

    Parameters
    ----------
    table : str
        The table as a scene writes it: ``ringdown``, ``model`` (with its kind), ``[[load]]`` (with its kind).
    key : str
        The key.
    type : str
        TOML type: float, int, string, bool, list of float, ...
    unit : str
        SI unit from the field's comment ("" where it has none: a count, a name, a ratio).
    default : str
        The default, as TOML would write it ("not set" for an optional key left out).
    allowed : str
        What the class's checks allow ("any" where they check nothing beyond the type).
    meaning : str
        The field's comment after the unit.
    """

    table: str
    key: str
    type: str
    unit: str
    default: str
    allowed: str
    meaning: str


def scene_tables() -> dict[str, type]:
    """Every table of a scene and its dataclass, in the order a scene is usually written.

    Returns
    -------
    dict of str to type
        ``model.discrete``, ``model.rom``, ``model.assembly``, the tables of
        :data:`~bearingshaft.scenes.tables.SECTIONS`, ``load.half_sine``, ``load.harmonic``,
        ``load.tabulated`` and ``sweep``. A name with a dot is a table of that kind.
    """
    tables: dict[str, type] = {f"model.{kind}": model_class(kind) for kind in MODEL_KINDS}
    tables.update({"initial": SECTIONS["initial"]})
    tables.update({k: v for k, v in SECTIONS.items() if k != "initial"})
    tables.update({f"load.{kind}": cls for kind, cls in LOAD_KINDS.items()})
    tables["sweep"] = SweepSpec
    return tables


def select_tables(name: str | None) -> dict[str, type]:
    """The tables ``bearingshaft keys NAME`` shows: all, one, or every kind of ``model`` or ``load``.

    Parameters
    ----------
    name : str, optional
        ``ringdown``, ``model``, ``model.rom``, ``load``, ``[ringdown]``, ``[[load]]``, ... (None: all).

    Returns
    -------
    dict of str to type

    Raises
    ------
    KeyError
        An unknown table, the message naming the nearest one and the known ones.
    """
    from bearingshaft.scenes.errors import suggest

    tables = scene_tables()
    if name is None:
        return tables
    name = name.strip("[]")
    chosen = {k: v for k, v in tables.items() if k == name or k.split(".")[0] == name}
    if not chosen:
        known = sorted({k.split(".")[0] for k in tables} | set(tables))
        raise KeyError(f"unknown table {name!r}{suggest(name, known)} (known: {', '.join(known)})")
    return chosen


# -- the field comments ----------------------------------------------------------------------
@cache
def field_comments(cls: type) -> dict[str, str]:
    """The comment of each field of dataclass ``cls``: on its line and the comment lines just below.

    Parameters
    ----------
    cls : type
        A dataclass defined in a Python source file.

    Returns
    -------
    dict of str to str
        Field name -> its comment, without ``#``, lines joined by a space ("" where there is none).
    """
    names = {f.name for f in dataclasses.fields(cls)}
    source = textwrap.dedent(inspect.getsource(cls))
    out: dict[str, str] = {}
    current = None  # the field whose comment may continue on the next line
    line_start = True
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NAME and line_start and tok.start[1] == 4:
            current = tok.string if tok.string in names else None
            if current is not None:
                out.setdefault(current, "")
        elif tok.type == tokenize.COMMENT and current is not None:
            text = tok.string.lstrip("#").strip()
            if text.startswith("--"):  # "# -- materials ---": a heading over the next fields
                current = None
                continue
            out[current] = f"{out[current]} {text}".strip()
        elif tok.type == tokenize.NL and line_start:  # a blank line ends a comment
            current = None
        line_start = tok.type in (tokenize.NEWLINE, tokenize.NL, tokenize.INDENT, tokenize.DEDENT)
        if tok.type == tokenize.NAME and tok.start[1] == 4 and tok.string in ("def", "class", "@"):
            current = None
    return {name: out.get(name, "") for name in names}


def _is_unit(text: str) -> bool:
    """Whether ``text`` is a unit (``m``, ``N s/m``, ``kg/m^3``, ``1/s``, ``N m/rad``).

    >>> [_is_unit(t) for t in ("m", "N s/m", "kg/m^3", "1/s", "N m/rad", "the integrator", "Hz")]
    [True, True, True, True, True, False, True]
    """
    atoms = [a for a in re.split(r"[ /]", re.sub(r"\^-?\d+", "", text)) if a]
    return bool(atoms) and all(a in _UNIT_ATOMS for a in atoms)


def unit_and_meaning(comment: str) -> tuple[str, str]:
    """(unit, meaning) of a field comment written unit first.

    Parameters
    ----------
    comment : str
        The comment (``"m, radial clearance at each tip"``).

    Returns
    -------
    tuple of str
        ``("m", "radial clearance at each tip")``; ``("", comment)`` when it starts with no unit.

    Examples
    --------
    >>> unit_and_meaning("m, radial clearance at each tip")
    ('m', 'radial clearance at each tip')
    >>> unit_and_meaning("s")
    ('s', '')
    >>> unit_and_meaning("which DOF to transform")
    ('', 'which DOF to transform')
    """
    head, _, rest = comment.partition(",")
    if _is_unit(head.strip()):
        return head.strip(), rest.strip()
    return "", comment


# -- types, defaults, checks -----------------------------------------------------------------
def _base_type(hint):
    """(the type, optional?) of a field's hint, ``float | None`` -> (float, True)."""
    if typing.get_origin(hint) in (typing.Union, __import__("types").UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return args[0], True
    return hint, False


def _type_name(hint) -> str:
    """TOML's name of a field's type.

    >>> _type_name(tuple[float, ...]), _type_name(float | None), _type_name(str)
    ('list of float', 'float (optional)', 'string')
    """
    base, optional = _base_type(hint)
    names = {float: "float", int: "int", str: "string", bool: "bool"}
    if typing.get_origin(base) is tuple:
        inner = typing.get_args(base)[0]
        text = f"list of {names.get(inner, getattr(inner, '__name__', str(inner)))}"
    else:
        text = names.get(base, getattr(base, "__name__", str(base)))
    return text + (" (optional)" if optional else "")


def toml_value(value) -> str:
    """A default as a scene writes it.

    Parameters
    ----------
    value : object
        A field's default.

    Returns
    -------
    str

    Examples
    --------
    >>> toml_value((1.0, 15)), toml_value("exact"), toml_value(True), toml_value(None), toml_value(2.54e-4)
    ('[1.0, 15]', '"exact"', 'true', 'not set', '0.000254')
    """
    if value is None:
        return "not set"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def _probes(hint) -> list:
    base, _ = _base_type(hint)
    if typing.get_origin(base) is tuple:
        inner = typing.get_args(base)[0]
        return [()] + [(v,) for v in _PROBES.get(inner, ())]
    return list(_PROBES.get(base, ()))


def allowed_values(cls: type, name: str) -> str:
    """What ``cls``'s checks allow for field ``name``: the rules of the refusals that name it.

    Parameters
    ----------
    cls : type
        A table's dataclass (constructible with its defaults).
    name : str
        One of its fields.

    Returns
    -------
    str
        The rules, "; "-separated (``"> 0"``, ``"one of exact, explicit, dop853"``, ``"each > 0 N"``),
        ``"true or false"`` for a bool, ``"an existing file ..."`` for a path, ``"any"`` where no
        check refuses a probe; ``COUPLED`` is added where a probe was refused by a check that ties the key
        to others (``freq_max_hz must exceed freq_min_hz``, a geometry that no longer fits).
    """
    hint = type_hints(cls)[name]
    if name in PATH_KEYS:
        return 'an existing file, relative to the scene file\'s folder ("" for none)'
    if _base_type(hint)[0] is bool:
        return "true or false"
    rules: list[str] = []
    coupled = False  # a probe refused by a check of another key, or of several together
    for value in _probes(hint):
        try:
            obj = cls(**{name: value})
            if hasattr(obj, "signal") and name != "file":  # a [[load]]: its time function checks the values
                obj.signal()
        except (ValueError, TypeError) as exc:
            m = _REFUSAL.match(str(exc).strip())
            if m is None or m["key"] != name:
                coupled = True
                continue
            rule = m["rule"]
            rule = rule[len("must be "):] if rule.startswith("must be ") else rule
            if m["index"]:
                rule = f"each {rule}"
            if any(h in rule for h in _HUGE):
                coupled = True
                continue
            if rule not in rules:
                rules.append(rule)
    rules = [r for r in rules if not any(o.startswith(_IMPLIED.get(r, ())) for o in rules if o != r)]
    coupled = coupled or not all(_ends_accepted(cls, name, hint, r) for r in rules)
    if coupled:
        rules.append(COUPLED)
    return "; ".join(rules) or _PARSER_RULES.get(name, "any")


def rule_bounds(rule: str) -> tuple[float, bool, float | None, bool] | None:
    """(lo, lo_open, hi, hi_open) of a simple rule, None for any other.

    Parameters
    ----------
    rule : str
        A rule of :func:`allowed_values`.

    Returns
    -------
    tuple or None

    Examples
    --------
    >>> rule_bounds("> 0"), rule_bounds(">= 2"), rule_bounds("in [1, 50]"), rule_bounds("one of a, b")
    ((0.0, True, None, False), (2.0, False, None, False), (1.0, False, 50.0, False), None)
    """
    if m := re.fullmatch(r"(>=?) (-?[\d.e+-]+)", rule):
        return float(m[2]), m[1] == ">", None, False
    if m := re.fullmatch(r"in ([(\[])(-?[\d.e+-]+), (-?[\d.e+-]+)([)\]])", rule):
        return float(m[2]), m[1] == "(", float(m[3]), m[4] == ")"
    return None


def _ends_accepted(cls: type, name: str, hint, rule: str) -> bool:
    """Whether the closed ends of a simple rule are accepted with the other keys at their defaults (an end
    refused there is a limit another key sets: FEPSpec's samples_study_harmonics = MAX_HARMONICS with its
    samples)."""
    b = rule_bounds(rule)
    base = _base_type(hint)[0]
    if b is None or base not in (int, float):
        return True
    lo, lo_open, hi, hi_open = b
    for end, is_open in ((lo, lo_open), (hi, hi_open)):
        if end is None or is_open:
            continue
        try:
            obj = cls(**{name: base(end)})
            if hasattr(obj, "signal") and name != "file":
                obj.signal()
        except (ValueError, TypeError):
            return False
    return True


def _parser_rules() -> dict[str, str]:
    """Rules of keys the scene parser checks against the model, not the table's dataclass."""
    from bearingshaft.scenes.loads import LOAD_DIRECTIONS

    points = "a point of the model (x1, x2, x3)"
    return {"point": points, "dof": points + "; with [hammer], a channel of the rig",
            "dofs": points + "s, two different ones", "direction": "one of " + ", ".join(LOAD_DIRECTIONS),
            "compare": "channels of the rig (fem.rig)"}


_PARSER_RULES = _parser_rules()


def table_keys(table: str, cls: type) -> list[Key]:
    """The keys of one table, in the order of its fields.

    Parameters
    ----------
    table : str
        A name of :func:`scene_tables` (``model.rom``, ``ringdown``, ``load.tabulated``, ...).
    cls : type
        Its dataclass.

    Returns
    -------
    list of Key
    """
    hints = type_hints(cls)
    comments = field_comments(cls)
    shown = _shown_table(table)
    rows = []
    if table.startswith("model."):  # the key that picks the dataclass
        rows.append(Key(shown, "kind", "string", "", '"discrete"', "one of " + ", ".join(MODEL_KINDS),
                        "the model: 3-DOF (discrete), reduced 3-D (rom) or the 3-D assembly"))
    for f in dataclasses.fields(cls):
        unit, meaning = unit_and_meaning(comments[f.name])
        default = f.default if f.default is not dataclasses.MISSING else None
        if table == "sweep":
            allowed = _sweep_allowed(f.name)
        elif f.name == "kind" and table.startswith("load."):
            allowed = "one of " + ", ".join(LOAD_KINDS)
        else:
            allowed = allowed_values(cls, f.name)
        kind = "table" if (table, f.name) == ("sweep", "vary") else _type_name(hints[f.name])
        rows.append(Key(shown, f.name, kind, unit, toml_value(default), allowed, meaning))
    return rows


def _shown_table(table: str) -> str:
    """``model.rom`` -> ``[model] kind = "rom"``; ``load.harmonic`` -> ``[[load]] kind = "harmonic"``."""
    head, _, kind = table.partition(".")
    if not kind:
        return f"[{head}]"
    return f'[model] kind = "{kind}"' if head == "model" else f'[[load]] kind = "{kind}"'


def _sweep_allowed(name: str) -> str:
    """[sweep] is read by its own parser (:func:`bearingshaft.scenes.sweep.parse_sweep_table`), not by checks
    of its dataclass: its rules, from that module's constants."""
    from bearingshaft.scenes import sweep

    return {"design": "one of " + ", ".join(sweep.DESIGNS), "samples": ">= 1 for a random design",
            "overlay": "one of " + ", ".join(f'"{o}"' for o in sweep.OVERLAYS),
            "vary": '"TABLE.KEY" = LO:HI:N[:log] or a list; a random design LO:HI[:log]'}.get(name, "any")


def keys_csv(keys: list[Key]) -> str:
    """The keys as CSV, one row per key, the columns of :class:`Key`.

    Parameters
    ----------
    keys : list of Key

    Returns
    -------
    str
    """
    import csv

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([f.name for f in dataclasses.fields(Key)])
    w.writerows(dataclasses.astuple(k) for k in keys)
    return buf.getvalue()


def format_keys(keys: list[Key]) -> str:
    """The keys as text: a heading per table, then one row per key in aligned columns.

    Parameters
    ----------
    keys : list of Key
        Rows of one or more tables.

    Returns
    -------
    str
    """
    header = ("key", "type", "unit", "default", "allowed", "meaning")
    out: list[str] = []
    tables = list(dict.fromkeys(k.table for k in keys))
    for table in tables:
        rows = [(k.key, k.type, k.unit or "-", k.default, k.allowed, k.meaning or "-")
                for k in keys if k.table == table]
        widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header) - 1)]
        out.append(table)
        for r in [header, *rows]:
            out.append("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=False)) + "  " + r[-1])
        out.append("")
    return "\n".join(out).rstrip() + "\n"
