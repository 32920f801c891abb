"""Checks of a table's values in its ``__post_init__``: each raises ValueError with one line
naming the key, which the parser turns into a :class:`~bearingshaft.scenes.errors.SceneError`."""

from __future__ import annotations

import math


def check(cond: bool, msg: str) -> None:
    """Raise ValueError(``msg``) unless ``cond``.

    Parameters
    ----------
    cond : bool
        The condition that must hold.
    msg : str
        The one-line message naming the key.

    Returns
    -------
    None

    Raises
    ------
    ValueError
        ``cond`` is false.
    """
    if not cond:
        raise ValueError(msg)


def positive(obj, *names: str) -> None:
    """Each field ``names`` of ``obj`` is a finite number > 0 (None is refused).

    Parameters
    ----------
    obj : object
        A table's dataclass.
    *names : str
        The fields checked, in order.

    Returns
    -------
    None

    Raises
    ------
    ValueError
        The first field that is not, named.
    """
    for name in names:
        v = getattr(obj, name)
        check(v is not None and v > 0 and math.isfinite(v), f"{name} must be > 0, got {v!r}")


def each(obj, name: str, ok, allowed: str) -> None:
    """Every value of the tuple field ``name`` satisfies ``ok``; else name the first that does not.

    Parameters
    ----------
    obj : object
        A table's dataclass.
    name : str
        A tuple field.
    ok : callable
        ``ok(value) -> bool``.
    allowed : str
        What is allowed, for the message.

    Returns
    -------
    None

    Raises
    ------
    ValueError
        ``name[i] must be <allowed>, got <value>`` for the first value refused.
    """
    for i, v in enumerate(getattr(obj, name)):
        check(ok(v), f"{name}[{i}] must be {allowed}, got {v!r}")


def tolerance(obj, *names: str) -> None:
    """Relative tolerances lie in (0, 1): at rtol >= 1 a solver controls no digit.

    Parameters
    ----------
    obj : object
        A table's dataclass.
    *names : str
        The fields checked.

    Returns
    -------
    None

    Raises
    ------
    ValueError
        A field outside (0, 1).
    """
    for name in names:
        v = getattr(obj, name)
        check(0.0 < v < 1.0, f"{name} must be in (0, 1), got {v!r}")

