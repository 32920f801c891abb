"""The plan of a sweep: its design points, its cases and their checks, before anything runs.

Every case's scene is the base scene's TOML with the case's values set (:func:`apply_values`),
written out and read back by the scene parser, its memory checked against one worker's share
(:mod:`bearingshaft.budget`) and the disk all cases will fill against the free space; the
first refusal is a :class:`~bearingshaft.scenes.SweepError` of one line naming the key and
value. A case's id is the first ID_DIGITS hex digits of the sha256 of its values.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bearingshaft.budget import HEADROOM, available_bytes, check_budget, free_disk_bytes
from bearingshaft.digits import human
from bearingshaft.registry import stages_of
from bearingshaft.scenes import Scene, parse_scene
from bearingshaft.scenes.convert import absolute_paths
from bearingshaft.scenes.sweep import KEY_PATTERN, MAX_CASES, SweepError, SweepSpec

ID_DIGITS = 12  # hex digits of a case id: 48 bits, a collision among 1e5 cases has odds ~1e-5
DESCRIPTION_CHARS = 500  # a case scene's description is cut to this


def design_points(spec: SweepSpec) -> list[tuple]:
    """The cases' values in design order.

    Parameters
    ----------
    spec : the sweep's design

    Returns
    -------
    One tuple of values per case, in the order of ``spec.vary``: the grid's product (last key
    fastest), the zip's i-th values, or the random design's Latin hypercube (one stratum per case
    and key, uniform inside it, on a log scale for log ranges; ``numpy.random.default_rng(seed)``).
    """
    if not spec.vary:
        return []
    if spec.design == "grid":
        n = math.prod(len(v.values) for v in spec.vary)
        if n > MAX_CASES:
            raise SweepError(f"the grid has {n} cases, more than {MAX_CASES}: give fewer values")
        return list(itertools.product(*(v.values for v in spec.vary)))
    if spec.design == "zip":
        return list(zip(*(v.values for v in spec.vary), strict=True))
    if spec.samples > MAX_CASES:
        raise SweepError(f"samples = {spec.samples} is more than {MAX_CASES} cases")
    rng = np.random.default_rng(spec.seed)
    n = spec.samples
    columns = []
    for v in spec.vary:
        u = (rng.permutation(n) + rng.random(n)) / n
        if v.log:
            col = np.exp(np.log(v.low) + u * (np.log(v.high) - np.log(v.low)))
        else:
            col = v.low + u * (v.high - v.low)
        columns.append([int(round(c)) for c in col] if v.integer else [float(c) for c in col])
    return list(zip(*columns, strict=True))


# -- the cases --------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Case:
    """One case of a sweep: its values, its scene's TOML text and the stages it runs.

    Attributes
    ----------
    case_id : str
        Short hash of its values (:func:`case_id`), its folder's name.
    values : tuple
        ((key, value), ...) in the order of the design's keys.
    text : str
        The case's scene (TOML), as its folder's scene.toml.
    name : str
        The case scene's name.
    origin : str
        Where it came from, for messages.
    stages : tuple of str
        The stages it runs, in pipeline order.
    shared_key : str
        The reduction a reduced-model case needs (see ``_reduction_key``), "" for none.
    """

    case_id: str
    values: tuple  # ((key, value), ...) in the order of the design's keys
    text: str = field(repr=False)  # the case's scene (TOML), as its folder's scene.toml
    name: str = ""
    origin: str = ""
    stages: tuple[str, ...] = ()
    shared_key: str = ""  # the reduction a reduced-model case needs (see _reduction_key), "" for none


@dataclass(frozen=True, eq=False)
class SweepPlan:
    """A validated sweep: the base scene, its design and every case.

    Attributes
    ----------
    scene : Scene
        The base scene.
    spec : SweepSpec
        The design.
    cases : tuple of Case
        Every case, in design order.
    source : str
        Where the design came from: "--vary" or "<scene> [sweep]".
    shared : dict
        Reduction key -> RomSpec to build once.
    """

    scene: Scene
    spec: SweepSpec
    cases: tuple[Case, ...]
    source: str  # where the design came from: "--vary" or "<scene> [sweep]"
    shared: dict = field(default_factory=dict)  # reduction key -> RomSpec to build once


def case_id(values) -> str:
    """Short hash of a case's values: sha256 of their JSON (floats as Python writes them).

    Parameters
    ----------
    values : iterable of (str, object)
        (key, value) pairs, JSON-serialisable.

    Returns
    -------
    str
        The first ``ID_DIGITS`` hex digits.

    Examples
    --------
    >>> case_id((("model.gap", 1e-4),)), case_id((("model.gap", 0.0001),)) == case_id((("model.gap", 1e-4),))
    ('5a2bdd9199f0', True)
    """
    blob = json.dumps([[k, v] for k, v in values], sort_keys=False, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:ID_DIGITS]


def show_values(values) -> str:
    """A case's values as refusals and summaries write them.

    Parameters
    ----------
    values : iterable of (str, object)
        (key, value) pairs.

    Returns
    -------
    str

    Examples
    --------
    >>> show_values((("model.gap", 0.0001), ("ringdown.method", "exact")))
    "model.gap = 0.0001, ringdown.method = 'exact'"
    """
    return ", ".join(f"{k} = {v!r}" for k, v in values)


def _default(scene: Scene, table: str, ti: int | None, name: str):
    """The current value of a key the scene's TOML does not write (the dataclass default)."""
    if table == "load":
        obj = scene.loads[ti] if ti is not None and ti < len(scene.loads) else None
    else:
        obj = getattr(scene, table, None)
    if obj is None or not hasattr(obj, name):
        return None
    value = getattr(obj, name)
    return list(value) if isinstance(value, tuple) else value


def _table_of(data: dict, table: str, ti: int | None, key: str, where: str) -> dict:
    """The TOML table of ``data`` that ``key`` sets (created for [model] and [initial])."""
    if table == "load":
        loads = data.get("load", [])
        if ti >= len(loads):
            raise SweepError(f"{where} {key}: the scene has {len(loads)} [[load]] table(s); load[{ti}] is not one")
        return loads[ti]
    if table in ("model", "initial"):  # present in every scene, if only as defaults
        return data.setdefault(table, {})
    if table not in data:
        raise SweepError(f"{where} {key}: the scene has no [{table}] table, so nothing reads {key} "
                         f"(its tables: {', '.join(k for k in data if isinstance(data[k], dict)) or 'none'})")
    return data[table]


def apply_values(scene: Scene, data: dict, values, where: str) -> dict:
    """A copy of the scene's TOML data with each (key, value) set.

    Parameters
    ----------
    scene : the base scene (for the defaults of list keys its TOML does not write)
    data : its TOML data (``tomllib.loads(scene.source)``), not changed
    values : ((key, value), ...), keys TABLE.KEY, TABLE.KEY[i] or load[i].KEY
    where : the case, as a refusal names it

    Returns
    -------
    The case's TOML data; :class:`SweepError` for a key the scene has no place for.
    """
    data = json.loads(json.dumps(data))  # a deep copy of plain TOML data
    for key, value in values:
        m = KEY_PATTERN.match(key)
        table, name = m["table"], m["name"]
        ti = int(m["ti"]) if m["ti"] is not None else None
        tab = _table_of(data, table, ti, key, where)
        if m["i"] is None:
            tab[name] = value
            continue
        i = int(m["i"])
        current = tab.get(name, _default(scene, table, ti, name))
        if not isinstance(current, list):
            raise SweepError(f"{where} {key}: [{table}] {name} is not a list, so it has no element [{i}]")
        if i >= len(current):
            raise SweepError(f"{where} {key}: [{table}] {name} has {len(current)} values; [{i}] is not one")
        current = list(current)
        current[i] = value
        tab[name] = current
    return data


def base_value(scene: Scene, key: str):
    """The value the scene itself gives a key (the sweep's figures mark it).

    Parameters
    ----------
    scene : the base scene
    key : TABLE.KEY, TABLE.KEY[i] or load[i].KEY

    Returns
    -------
    Its value in the scene's TOML, else the default; None if the scene has none.
    """
    m = KEY_PATTERN.match(key)
    if m is None:
        return None
    table, name = m["table"], m["name"]
    ti = int(m["ti"]) if m["ti"] is not None else None
    data = tomllib.loads(scene.source)
    try:
        tab = data["load"][ti] if table == "load" else data.get(table, {})
    except (KeyError, IndexError, TypeError):
        return None
    value = tab.get(name, _default(scene, table, ti, name)) if isinstance(tab, dict) else None
    if m["i"] is not None:
        i = int(m["i"])
        value = value[i] if isinstance(value, list) and i < len(value) else None
    return value


def _reduction_key(model) -> str:
    """What a reduced model's reduction depends on: the spec with contact and damping at their
    defaults (they are applied after the reduction, reduced.models.rom.RomSpec.reduced)."""
    from reduced.models.rom import RomSpec

    d = RomSpec()
    spec = dataclasses.replace(model, k_g=d.k_g, gap=d.gap, c_points=d.c_points, alpha=d.alpha,
                               modal_damping=d.modal_damping)
    return hashlib.sha256(repr(spec).encode()).hexdigest()[:ID_DIGITS]


def case_stages(scene: Scene) -> tuple[str, ...]:
    """The stages a case runs.

    Parameters
    ----------
    scene : the case's (or the base) scene

    Returns
    -------
    The scene's stages in pipeline order, less ``reduce`` (the reduction is built once per sweep).
    """
    return tuple(s for s in stages_of(scene) if s != "reduce")


def _case_text(scene: Scene, data: dict, values, cid: str, where: str) -> str:
    """The TOML of a case's scene: named ``<scene>-<id>``, described by its values."""
    import tomli_w

    case_data = apply_values(scene, data, values, where)
    case_data = {"name": f"{scene.name}-{cid}",
                 "description": f"{scene.name} sweep case: {show_values(values)}"[:DESCRIPTION_CHARS],
                 **{k: v for k, v in case_data.items() if k != "description"}}
    try:
        return tomli_w.dumps(case_data)
    except (TypeError, ValueError) as exc:
        raise SweepError(f"{where}: cannot be written as TOML ({exc})") from None


def build_plan(scene: Scene, spec: SweepSpec, source: str, out: Path | None = None,
               n_workers: int | None = None) -> SweepPlan:
    """Every case's scene written and parsed, its memory and the sweep's disk checked.

    Parameters
    ----------
    scene : the base scene
    spec : the design (the scene's [sweep] or --vary)
    source : where the design came from, as refusals name it ("--vary", "<scene> [sweep]")
    out : the sweep's folder, for the disk check (None: not checked)
    n_workers : workers sharing the machine's memory (each case gets its share)

    Returns
    -------
    The :class:`SweepPlan`; :class:`SweepError` (one line, naming the key and value) at the first
    case that would be refused, before anything runs.
    """
    if not spec.vary:
        raise SweepError(f"{source}: nothing is varied; give --vary KEY=VALUES or a [sweep.vary] table")
    if not case_stages(scene):
        raise SweepError(f"{scene.origin or scene.name}: the scene has no stage to run in each case "
                         f"(its stages: {', '.join(stages_of(scene)) or 'none'})")
    data = absolute_paths(tomllib.loads(scene.source), scene.folder or None)  # the cases are read elsewhere
    data.pop("sweep", None)
    data.pop("name", None)
    keys = [v.key for v in spec.vary]
    avail = available_bytes() // max(1, n_workers or 1)
    cases, seen, disk, shared = [], {}, 0.0, {}
    for point in design_points(spec):
        values = tuple(zip(keys, point, strict=True))
        cid = case_id(values)
        if cid in seen:
            raise SweepError(f"{source}: two cases have the same values ({show_values(values)}); give each "
                             "value once")
        seen[cid] = values
        where = f"{source} case {show_values(values)}"
        text = _case_text(scene, data, values, cid, where)
        case_scene = parse_scene(text, f"{scene.name}-{cid}", where)
        disk += sum(e.disk for e in check_budget(case_scene, None, available=avail))
        shared_key = ""
        if case_scene.model_kind == "rom" and not case_scene.model.rom_file:
            shared_key = _reduction_key(case_scene.model)
            shared.setdefault(shared_key, case_scene.model)
        cases.append(Case(cid, values, text, case_scene.name, where, case_stages(case_scene), shared_key))
    if out is not None and disk > HEADROOM * free_disk_bytes(out):
        raise SweepError(f"{source}: the {len(cases)} cases would write {human(disk)} into {out}, more than the "
                         f"{human(free_disk_bytes(out))} free; lower [ringdown] duration_s or sample_rate_hz, or "
                         "the number of cases")
    return SweepPlan(scene, spec, tuple(cases), source, shared)
