"""Time histories in and out as Universal File Format dataset 58 (function at nodal DOF).

One :class:`TimeHistory` is one channel of a test (an accelerometer axis, a load cell, the
hammer): a uniformly sampled real signal at a node and direction, with its quantity and
unit. :func:`write_uff58` writes channels with pyuff as dataset 58 records, function type 1
(time response), even abscissa spacing, abscissa type 17 (time, s), the ordinate's specific
data type and unit exponents from :data:`QUANTITIES` (SI: m, N, s); binary records (58b)
by default, so a round trip reproduces every sample bit for bit. :func:`read_uff58`
reads them back, refusing in one line (:class:`UffError`) what a channel cannot be: a
record that is not a real time response, uneven sampling, an unknown quantity or a unit
that is not the SI unit of its quantity (an acceleration in g, a force in kN).

Direction codes are UFF's: 1, 2, 3 for +X, +Y, +Z, negative for the opposite sense, 0 for
a scalar.

The layout is SDRC's Universal Dataset Number 58, "Function at Nodal DOF" (I-DEAS "Universal
File Datasets Summary"; text at UC-SDRL, https://www.ceas3.uc.edu/sdrluff/files/58.asc) and
UC-SDRL's binary 58b; ``tests/test_uff_spec.py`` compares the writer's records field by field
with one written by hand from it. Record 7 keeps the abscissa minimum and increment as E13.5,
6 significant digits (exact for 20 kHz, dt = 5e-5 s; 51.2 kHz's 1.953125e-5 s is written
1.95313e-05, 2.6e-6 long).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# quantity -> (UFF specific data type, SI unit label, length exponent, force exponent)
QUANTITIES: dict[str, tuple[int, str, int, int]] = {
    "displacement": (8, "m", 1, 0),
    "velocity": (11, "m/s", 1, 0),
    "acceleration": (12, "m/s^2", 1, 0),
    "force": (13, "N", 0, 1),  # excitation force (the hammer, a shaker)
    "reaction_force": (9, "N", 0, 1),  # a load cell's force
}
DATA_TYPES = {code: q for q, (code, *_rest) in QUANTITIES.items()}
UNIT_SPELLINGS = {"m/s^2": {"m/s^2", "m/s2", "m/s**2", "m s^-2", "m/s/s"}, "m/s": {"m/s", "m s^-1"},
                  "m": {"m"}, "N": {"n", "N"}}
DIRECTIONS = (-3, -2, -1, 0, 1, 2, 3)
TIME_DATA_TYPE = 17  # abscissa: time
TIME_RESPONSE = 1  # function type


class UffError(ValueError):
    """A UFF file or record that cannot be used as a channel; the message is one line."""


@dataclass(frozen=True, eq=False)
class TimeHistory:
    """One channel: ``data[k]`` at t = t0_s + k dt_s, at ``node`` along ``direction``.

    Parameters
    ----------
    name : str
        Channel name (e.g. ``beam_s1:z``).
    node : int
        UFF node number.
    direction : int
        UFF code: 1, 2, 3 = +X, +Y, +Z; negative: opposite; 0: scalar.
    quantity : str
        A key of ``QUANTITIES`` (displacement, velocity, acceleration, force, reaction_force).
    data : (n,) array_like of float
        The samples, in the SI unit of ``quantity`` (stored as float).
    dt_s : float
        s, sampling step, > 0.
    t0_s : float
        s, time of the first sample.

    Raises
    ------
    UffError
        An unknown quantity or direction, a step that is not finite and > 0, or data that is not
        a real non-empty 1-D series.
    """

    name: str
    node: int
    direction: int  # UFF code: 1, 2, 3 = +X, +Y, +Z; negative: opposite; 0: scalar
    quantity: str  # a key of QUANTITIES
    data: np.ndarray
    dt_s: float
    t0_s: float = 0.0

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise UffError(f"channel {self.name!r}: unknown quantity {self.quantity!r} "
                           f"(known: {', '.join(QUANTITIES)})")
        if self.direction not in DIRECTIONS:
            raise UffError(f"channel {self.name!r}: direction must be one of {DIRECTIONS}, got {self.direction!r}")
        if not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise UffError(f"channel {self.name!r}: dt_s must be > 0, got {self.dt_s!r}")
        data = np.asarray(self.data)
        if data.ndim != 1 or data.size < 1 or np.iscomplexobj(data):
            raise UffError(f"channel {self.name!r}: data must be a real 1-D series")
        object.__setattr__(self, "data", data.astype(float))

    @property
    def unit(self) -> str:
        return QUANTITIES[self.quantity][1]

    @property
    def t(self) -> np.ndarray:
        """s, the sample times."""
        return self.t0_s + np.arange(self.data.size) * self.dt_s


def _name10(name: str) -> str:
    """Record 6's entity name, Format 10A1: the first 10 characters from column 1, blank-padded
    (as Fortran stores a CHARACTER*10; pyuff's %10s would right-justify a shorter one), "NONE"
    if unused."""
    return (name[:10] or "NONE").ljust(10)


def write_uff58(path: str | Path, channels, *, binary: bool = True, model: str = "bearingshaft") -> None:
    """Write ``channels`` (TimeHistory) to ``path`` as dataset 58 records (replacing the file).

    Parameters
    ----------
    path : str or Path
        The file, replaced if it exists.
    channels : iterable of TimeHistory
        Written in order, one record each.
    binary : bool
        Binary 58b records (exact samples) rather than ASCII 58.
    model : str
        The records' second ID line.

    Returns
    -------
    None
    """
    import pyuff

    path = Path(path)
    if path.exists():
        path.unlink()
    sets = []
    for ch in channels:
        code, unit, len_exp, force_exp = QUANTITIES[ch.quantity]
        sets.append(pyuff.prepare_58(
            binary=1 if binary else 0, id1=ch.name, id2=model, id3="NONE", id4="NONE", id5="NONE",
            func_type=TIME_RESPONSE, ver_num=0, load_case_id=0, rsp_ent_name=_name10(ch.name),
            rsp_node=int(ch.node), rsp_dir=int(ch.direction), ref_ent_name=_name10(""), ref_node=0, ref_dir=0,
            ord_data_type=4, num_pts=int(ch.data.size), abscissa_spacing=1, abscissa_min=float(ch.t0_s),
            abscissa_inc=float(ch.dt_s), z_axis_value=0.0, abscissa_spec_data_type=TIME_DATA_TYPE,
            abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0,
            abscissa_axis_units_lab="s", ordinate_spec_data_type=code, ordinate_len_unit_exp=len_exp,
            ordinate_force_unit_exp=force_exp, ordinate_temp_unit_exp=0, ordinate_axis_units_lab=unit,
            orddenom_spec_data_type=0, orddenom_len_unit_exp=0, orddenom_force_unit_exp=0,
            orddenom_temp_unit_exp=0, orddenom_axis_units_lab="NONE", z_axis_spec_data_type=0,
            z_axis_len_unit_exp=0, z_axis_force_unit_exp=0, z_axis_temp_unit_exp=0, z_axis_axis_units_lab="NONE",
            data=np.asarray(ch.data, float), x=ch.t,
        ))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")


def _unit_ok(label: str, unit: str) -> bool:
    text = (label or "").strip()
    return text in UNIT_SPELLINGS[unit] or text.lower() in {u.lower() for u in UNIT_SPELLINGS[unit]}


def read_uff58(path: str | Path) -> list[TimeHistory]:
    """Every dataset 58 record of ``path`` as a TimeHistory; one-line UffError on anything else.

    A record is refused unless it is a real, evenly sampled time response (function type 1)
    of a quantity in :data:`QUANTITIES` whose unit label (if given) is that quantity's SI
    unit; records of other dataset types (units, geometry) are skipped.

    Parameters
    ----------
    path : str or Path
        A universal file.

    Returns
    -------
    list of TimeHistory
        One per dataset 58 record, in file order.

    Raises
    ------
    UffError
        No such file, an unreadable file, no dataset 58, or a record refused as above.
    """
    import pyuff

    path = Path(path)
    if not path.is_file():
        raise UffError(f"{str(path)!r}: no such file")
    try:
        uff = pyuff.UFF(str(path))
        types = [int(t) for t in uff.get_set_types()]
        idx = [i for i, t in enumerate(types) if t == 58]
        sets = uff.read_sets(idx) if idx else []
    except Exception as exc:  # pyuff raises many types on a damaged file
        raise UffError(f"{str(path)!r}: not a readable UFF file ({type(exc).__name__}: {str(exc)[:60]})") from None
    if not idx:
        raise UffError(f"{str(path)!r}: no dataset 58 (function) record")
    sets = [sets] if isinstance(sets, dict) else list(sets)
    out = []
    for k, rec in enumerate(sets):
        name = str(rec.get("id1", "")).strip() or f"record {k + 1}"
        where = f"{str(path)!r} record {k + 1} ({name})"
        if rec.get("func_type") != TIME_RESPONSE:
            raise UffError(f"{where}: function type {rec.get('func_type')}, not a time response (1)")
        data = np.asarray(rec["data"])
        if np.iscomplexobj(data):
            raise UffError(f"{where}: complex data; a time history is real")
        code = rec.get("ordinate_spec_data_type")
        quantity = DATA_TYPES.get(code)
        if quantity is None:
            raise UffError(f"{where}: ordinate data type {code} is none of "
                           + ", ".join(f"{c} ({q})" for c, q in DATA_TYPES.items()))
        unit = QUANTITIES[quantity][1]
        label = str(rec.get("ordinate_axis_units_lab", "") or "").strip()
        if label and label.upper() != "NONE" and not _unit_ok(label, unit):
            raise UffError(f"{where}: unit {label!r} is not {unit!r}, the SI unit of {quantity}; convert it")
        x = np.asarray(rec.get("x", []), float)
        dt = float(rec.get("abscissa_inc", 0.0) or 0.0)
        if rec.get("abscissa_spacing", 1) != 1 or not dt > 0:
            if x.size >= 2 and np.allclose(np.diff(x), x[1] - x[0], rtol=1e-9, atol=0.0):
                dt = float(x[1] - x[0])
            else:
                raise UffError(f"{where}: uneven or missing sampling; a channel needs a fixed time step")
        t0 = float(rec.get("abscissa_min", x[0] if x.size else 0.0))
        try:
            out.append(TimeHistory(name, int(rec.get("rsp_node", 0)), int(rec.get("rsp_dir", 0)), quantity,
                                   data.astype(float), dt, t0))
        except UffError as exc:
            raise UffError(f"{where}: {exc}") from None
    return out


__all__ = ["TimeHistory", "UffError", "QUANTITIES", "write_uff58", "read_uff58"]
