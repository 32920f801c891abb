"""TOML values to dataclass fields: types checked (a number given as a string or a boolean is
refused, not coerced), NaN, infinities and absurd magnitudes refused, unknown keys named."""

from __future__ import annotations

import functools
import math
import types
import typing
from dataclasses import fields
from pathlib import Path

from bearingshaft.scenes.errors import SceneError, show, suggest

MAX_COUNT = 100_000  # largest count (energies, orbits, repeats, modes) a scene may ask for
MAX_MAGNITUDE = 1e100  # no SI quantity here comes near; squares of larger values (energies) overflow
PATH_KEYS = ("file", "force_file", "test_shapes", "rom_file")  # keys naming a file: relative to the scene's folder
RENAMED = {"g": "gap"}  # old key -> its name now (issue 24: one name for the gap in every model); refused with a hint


# -- conversion --------------------------------------------------------------------------
def _coerce(value, typ, where: str):
    origin = typing.get_origin(typ)
    if origin in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(typ) if a is not type(None)]
        return _coerce(value, args[0], where)
    if origin is tuple:
        (inner, _) = typing.get_args(typ)
        if not isinstance(value, list):
            raise SceneError(f"{where}: expected a list, got {show(value)}")
        if not value:
            raise SceneError(f"{where}: the list is empty; give at least one value")
        if len(value) > MAX_COUNT:
            raise SceneError(f"{where}: {len(value)} values is too many (at most {MAX_COUNT})")
        return tuple(_coerce(v, inner, f"{where}[{i}]") for i, v in enumerate(value))
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{where}: expected a number, got {show(value)}")
        if isinstance(value, float) and not math.isfinite(value):
            raise SceneError(f"{where}: must be finite, got {show(value)}")
        if abs(value) > MAX_MAGNITUDE:
            raise SceneError(f"{where}: {value!r} is out of range (|value| <= {MAX_MAGNITUDE:g})")
        return float(value)
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"{where}: expected an integer, got {show(value)}")
        if abs(value) > MAX_COUNT:
            raise SceneError(f"{where}: {value} is too large (at most {MAX_COUNT})")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise SceneError(f"{where}: expected a string, got {show(value)}")
        return value
    if typ is bool:
        if not isinstance(value, bool):
            raise SceneError(f"{where}: expected true or false, got {show(value)}")
        return value
    raise TypeError(f"unsupported field type {typ!r} at {where}")  # a bug, not bad input


def resolve_path(value: str, base: str | Path | None, where: str) -> str:
    """The file a scene's path names: relative paths from ``base`` (the scene file's folder); it must exist.

    Parameters
    ----------
    value : str
        The path as the scene writes it ("" stays "").
    base : str or Path, optional
        The folder relative paths start from (None: the working directory).
    where : str
        File, table and key, for the message.

    Returns
    -------
    str
        The absolute path.

    Raises
    ------
    SceneError
        No such file, naming the folder looked in.
    """
    if not value:
        return value
    folder = Path(base if base is not None else ".").absolute()
    path = Path(value).expanduser()
    full = path if path.is_absolute() else folder / path
    if not full.is_file():
        looked = ("" if path.is_absolute() else
                  f" in {str(folder)!r} (a path in a scene is relative to its file's folder)")
        raise SceneError(f"{where}: no such file {value!r}{looked}")
    return str(full)


def absolute_paths(data: dict, base: str | Path | None) -> dict:
    """Scene TOML data with every existing file of ``PATH_KEYS`` made absolute from ``base``, so the
    scene reads the same from any folder (a sweep writes its cases elsewhere); a copy, others untouched.

    Parameters
    ----------
    data : dict
        The scene's TOML data.
    base : str or Path, optional
        The scene file's folder (None: the working directory).

    Returns
    -------
    dict
    """
    folder = Path(base if base is not None else ".").absolute()

    def fix(table):
        if not isinstance(table, dict):
            return table
        out = dict(table)
        for key in PATH_KEYS:
            v = out.get(key)
            if isinstance(v, str) and v and not Path(v).expanduser().is_absolute() and (folder / v).is_file():
                out[key] = str(folder / v)
        return out

    return {k: [fix(t) for t in v] if isinstance(v, list) else fix(v) for k, v in data.items()}


@functools.cache
def type_hints(cls: type) -> dict:
    """``typing.get_type_hints(cls)``, worked out once per class (a scene check asks for it per table, and
    it evaluates every annotation's string each time).

    Parameters
    ----------
    cls : type
        A dataclass.

    Returns
    -------
    dict
        Field name -> type; shared between callers, so read only.
    """
    return typing.get_type_hints(cls)


def from_table(cls: type, table: dict, where: str, base: str | Path | None = None):
    """Build dataclass ``cls`` from a TOML table, naming ``where`` in every error.

    Parameters
    ----------
    cls : type
        A dataclass whose field types are float, int, str, bool, tuples of them, or optional ones.
    table : dict
        The TOML table.
    where : str
        Where the table is (file and table), for the messages.
    base : str or Path, optional
        The folder the keys of ``PATH_KEYS`` are relative to (the scene file's; None: the working
        directory); they are passed on as absolute paths of existing files.

    Returns
    -------
    object
        ``cls(**table)`` with the values converted.

    Raises
    ------
    SceneError
        Not a table, an unknown key (with the nearest known one), a value of the wrong type, not
        finite or out of range, or one ``cls`` refuses.
    """
    if not isinstance(table, dict):
        raise SceneError(f"{where}: expected a table, got {show(table)}")
    hints = type_hints(cls)
    known = [f.name for f in fields(cls)]
    for key in table:
        if key not in known:
            hint = (f" (did you mean {RENAMED[key]!r}? the key was renamed)" if RENAMED.get(key) in known
                    else suggest(key, known))
            raise SceneError(f"{where}: unknown key {key!r}{hint} (known: {', '.join(known)})")
    kwargs = {k: _coerce(v, hints[k], f"{where} {k}") for k, v in table.items()}
    for k in PATH_KEYS:
        if isinstance(kwargs.get(k), str):
            kwargs[k] = resolve_path(kwargs[k], base, f"{where} {k}")
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:
        raise SceneError(f"{where}: {exc}") from None

