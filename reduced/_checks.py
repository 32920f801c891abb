"""Argument checks shared by the public functions of :mod:`reduced` (transient, periodic).

Every check runs before any work and raises :class:`InvalidArgument` (a ``ValueError``)
with a one-line message naming the argument, the value given and what is allowed, e.g.
``atol must be a finite number > 0 (m), got nan``. Booleans are refused where a number
is expected (``True`` is an int to Python, never a tolerance to a user).
"""

from __future__ import annotations

import math
import numbers

import numpy as np


class InvalidArgument(ValueError):
    """An argument of a public function that cannot be used; the message is one line."""


def show(value) -> str:
    """``repr`` of a value cut to one short line for a message.

    Parameters
    ----------
    value : object
        Anything.

    Returns
    -------
    str
        ``repr(value)`` with newlines as spaces, cut to 60 characters (57 and '...').
    """
    text = repr(value).replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def one_line(exc: BaseException, typed: bool | None = None) -> str:
    """An exception's message on one line, ``Type: message`` when ``typed`` (by default, for
    anything but a ValueError, whose message says what is wrong by itself); its type's name
    when it has no message.

    Parameters
    ----------
    exc : BaseException
        The exception.
    typed : bool, optional
        Prefix the type's name; None: for anything but a ValueError.

    Returns
    -------
    str
        The message with its whitespace runs collapsed to single spaces.

    Examples
    --------
    >>> one_line(ValueError("gap must be\\n >= 0")), one_line(KeyError("x"), typed=True), one_line(OSError())
    ('gap must be >= 0', "KeyError: 'x'", 'OSError')
    """
    text = " ".join(str(exc).split())
    if not text:
        return type(exc).__name__
    if typed is None:
        typed = not isinstance(exc, ValueError)
    return f"{type(exc).__name__}: {text}" if typed else text


def _is_number(value) -> bool:
    """A real number, NumPy scalars and 0-d arrays included; booleans are not numbers."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return value.dtype.kind in "iuf"
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def number(name: str, value, *, lo: float | None = None, hi: float | None = None, lo_open: bool = True,
           hi_open: bool = True, unit: str = "") -> float:
    """``value`` as a float, refused unless a finite real number in the interval (lo, hi)
    (``lo_open`` / ``hi_open`` say whether each end is excluded; None: unbounded).

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : object
        What was given: a real number (NumPy scalars and 0-d arrays too), not a bool.
    lo, hi : float, optional
        Bounds of the interval.
    lo_open, hi_open : bool
        Whether each bound is excluded (the default) or allowed.
    unit : str
        Unit named in the message.

    Returns
    -------
    float

    Raises
    ------
    InvalidArgument
        Not a real number, not finite, or outside the interval.
    """
    ok = _is_number(value)
    if ok:
        v = float(value)
        ok = math.isfinite(v)
        if ok and lo is not None:
            ok = v > lo if lo_open else v >= lo
        if ok and hi is not None:
            ok = v < hi if hi_open else v <= hi
    if not ok:  # the message is made only here: the checks run on every call of hot paths (Flow.__call__)
        parts = []
        if lo is not None:
            parts.append(f"{'>' if lo_open else '>='} {lo:g}")
        if hi is not None:
            parts.append(f"{'<' if hi_open else '<='} {hi:g}")
        allowed = "a finite number" + (" " + " and ".join(parts) if parts else "") + (f" ({unit})" if unit else "")
        raise InvalidArgument(f"{name} must be {allowed}, got {show(value)}")
    return v


def positive(name: str, value, unit: str = "") -> float:
    """A finite number > 0.

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : object
        What was given.
    unit : str
        Unit named in the message.

    Returns
    -------
    float

    Raises
    ------
    InvalidArgument
        Not a finite real number > 0.
    """
    return number(name, value, lo=0.0, unit=unit)


def integer(name: str, value, *, lo: int = 1, hi: int | None = None) -> int:
    """An int (not a bool) in [lo, hi].

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : object
        What was given: an integral number (NumPy integers and 0-d integer arrays too).
    lo : int
        Smallest value allowed.
    hi : int, optional
        Largest value allowed.

    Returns
    -------
    int

    Raises
    ------
    InvalidArgument
        Not an integer (a float or a bool), or outside [lo, hi].
    """
    allowed = f"an integer >= {lo}" + (f" and <= {hi}" if hi is not None else "")
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iu":
        value = value.item()
    if not isinstance(value, (numbers.Integral,)) or isinstance(value, (bool, np.bool_)):
        raise InvalidArgument(f"{name} must be {allowed}, got {show(value)}")
    v = int(value)
    if v < lo or (hi is not None and v > hi):
        raise InvalidArgument(f"{name} must be {allowed}, got {show(value)}")
    return v


def choice(name: str, value, options: tuple[str, ...]) -> str:
    """One of ``options``.

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : object
        What was given.
    options : tuple of str
        The values allowed.

    Returns
    -------
    str
        ``value``.

    Raises
    ------
    InvalidArgument
        Not one of ``options``.
    """
    if not isinstance(value, str) or value not in options:
        raise InvalidArgument(f"{name} must be one of {', '.join(options)}, got {show(value)}")
    return value


def flag(name: str, value) -> bool:
    """True or False (not a number or a string).

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : object
        What was given: a bool or a NumPy bool.

    Returns
    -------
    bool

    Raises
    ------
    InvalidArgument
        Anything else (1 and 'yes' included).
    """
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidArgument(f"{name} must be True or False, got {show(value)}")
    return bool(value)


def callback(name: str, value):
    """None or a callable.

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : callable or None
        What was given.

    Returns
    -------
    callable or None
        ``value``.

    Raises
    ------
    InvalidArgument
        Neither None nor callable.
    """
    if value is not None and not callable(value):
        raise InvalidArgument(f"{name} must be None or a callable taking the fraction done, got {show(value)}")
    return value


def vector(name: str, value, n: int) -> np.ndarray:
    """A finite float vector of n values (a copy).

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : array_like
        What was given.
    n : int
        Length required.

    Returns
    -------
    (n,) ndarray of float
        A new array.

    Raises
    ------
    InvalidArgument
        Not numbers, not of shape (n,), or not finite.
    """
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidArgument(f"{name} must be {n} finite numbers, got {show(value)}") from None
    if a.shape != (n,):
        raise InvalidArgument(f"{name} must have {n} values, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidArgument(f"{name} must be finite, got {a.tolist()}")
    return a


def series(name: str, value, ndim: int = 1, min_len: int = 1) -> np.ndarray:
    """A finite float array of ``ndim`` dimensions with at least ``min_len`` rows.

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : array_like
        What was given.
    ndim : int
        Dimensions required.
    min_len : int
        Fewest rows (entries along the first axis).

    Returns
    -------
    ndarray of float
        ``np.asarray(value, float)``: no copy when it already is one.

    Raises
    ------
    InvalidArgument
        Not numbers, the wrong number of dimensions, too short, or not finite.
    """
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidArgument(f"{name} must be an array of numbers, got {show(value)}") from None
    if a.ndim != ndim:
        raise InvalidArgument(f"{name} must be a {ndim}-D array, got shape {a.shape}")
    if a.shape[0] < min_len:
        raise InvalidArgument(f"{name} must have at least {min_len} samples, got {a.shape[0]}")
    if not np.all(np.isfinite(a)):
        raise InvalidArgument(f"{name} must be finite (it holds NaN or inf)")
    return a


def run_args(system, x0, v0, duration_s, sample_rate_hz):
    """(n, x0, v0, duration_s, sample_rate_hz) of a run, checked: what every integrator takes.

    Parameters
    ----------
    system : GapSystem
        The system integrated.
    x0 : (n,) array_like of float
        m, initial displacements.
    v0 : (n,) array_like of float
        m/s, initial velocities.
    duration_s : float
        s, > 0.
    sample_rate_hz : float
        Hz, > 0.

    Returns
    -------
    tuple
        (n, x0, v0, duration_s, sample_rate_hz), the vectors as new float arrays.

    Raises
    ------
    InvalidArgument
        Any of them refused by :func:`gap_system`, :func:`vector` or :func:`positive`.
    """
    gap_system(system)
    n = system.n
    return (n, vector("x0", x0, n), vector("v0", v0, n), positive("duration_s", duration_s, "s"),
            positive("sample_rate_hz", sample_rate_hz, "Hz"))


def gap_system(value, name: str = "system"):
    """A :class:`~reduced.models.gaps.GapSystem`.

    Parameters
    ----------
    value : object
        What was given.
    name : str
        The argument's name, for the message.

    Returns
    -------
    GapSystem
        ``value``.

    Raises
    ------
    InvalidArgument
        Not a GapSystem.
    """
    from reduced.models.gaps import GapSystem

    if not isinstance(value, GapSystem):
        raise InvalidArgument(f"{name} must be a reduced.GapSystem, got {type(value).__name__}")
    return value


def frictionless(system, what: str):
    """``system``, refused if it has friction, which ``what`` does not treat (it would drop it silently).

    Parameters
    ----------
    system : GapSystem
        The system.
    what : str
        The solver, for the message.

    Returns
    -------
    GapSystem
        ``system``.

    Raises
    ------
    InvalidArgument
        The system has friction.
    """
    if getattr(system, "friction", None) is not None:
        raise InvalidArgument(f"the system has friction at its tips, which {what} does not treat yet; run its "
                              "ringdown (reduced.transient.integrate.ringdown), or drop the friction "
                              "(system.with_friction(None))")
    return system


def loads(value, n: int, name: str = "loads"):
    """None or a :class:`~reduced.models.loads.Loads` of at least one load on the system's n coordinates.

    Parameters
    ----------
    value : Loads or None
        What was given.
    n : int
        Coordinates of the system the loads act on.
    name : str
        The argument's name, for the message.

    Returns
    -------
    Loads or None
        ``value``.

    Raises
    ------
    InvalidArgument
        Not a Loads, a Loads without loads, or one whose ``b`` is not (L, n).
    """
    if value is None:
        return None
    from reduced.models.loads import Loads

    if not isinstance(value, Loads):
        raise InvalidArgument(f"{name} must be None or a reduced.models.loads.Loads, got {type(value).__name__}")
    if value.n_loads == 0:
        raise InvalidArgument(f"{name} must hold at least one load (None for a free response), got none")
    if value.n != n:
        raise InvalidArgument(f"{name} must act on the system's {n} coordinates (b of shape (L, {n})), "
                              f"got b of shape {value.b.shape}")
    return value
