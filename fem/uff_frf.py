"""Frequency functions (FRFs, coherence) as UFF dataset 58, and test geometry as datasets 15, 2411 and 82.

A :class:`FrequencyFunction` is one evenly spaced function of frequency between a response
DOF (node, direction) and a reference DOF: an FRF (function type 4, complex, ordinate
numerator the response quantity, ordinate denominator the reference quantity, e.g.
acceleration / excitation force) or an ordinary coherence (function type 6, real,
dimensionless). :func:`write_uff58_functions` writes them with pyuff as dataset 58 records
(Universal Dataset Number 58, "Function at Nodal DOF", the layout quoted in
:mod:`fem.uff`): record 6 carries the response and reference node and direction (load case 0,
single point excitation, so the reference fields apply), record 7 the ordinate data type (6
complex double for an FRF, 4 real double for a coherence), record 8 the abscissa (specific
data type 18, frequency, Hz), record 9 the ordinate numerator and record 10 the ordinate
denominator, each with its specific data type and unit exponents from :data:`fem.uff.QUANTITIES`
(Addendum A: acceleration 12 with length exponent 1; excitation force 13 with force exponent
1; a coherence is "general", type 1, with all exponents 0, and has no denominator, type 0).
:func:`read_uff58_functions` reads them back, refusing in one line (:class:`fem.uff.UffError`)
a record that is not an FRF or a coherence.

The geometry of a test (:func:`write_geometry`): its nodes as dataset 15 (Format(4I10,1P3E13.5):
node label, definition and displacement coordinate systems 0 (global Cartesian), colour,
X, Y, Z) or dataset 2411 (Format(4I10) then Format(1P3D25.16)), and its trace lines as
dataset 82 (Format(3I10): trace line number, number of nodes, colour; Format(80A1): its
name; Format(8I10): the nodes, 0 = move without drawing), which test software draws as a
wireframe. ``tests/test_frf.py`` compares the records field by field with ones written by
hand from these layouts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.uff import DATA_TYPES, DIRECTIONS, QUANTITIES, UffError, _name10, _unit_ok

FRF = 4  # function type: frequency response function
COHERENCE = 6  # function type: coherence
FREQUENCY_DATA_TYPE = 18  # abscissa: frequency (Hz)
GENERAL_DATA_TYPE = 1  # a dimensionless ordinate (coherence): general, exponents 0 0 0


@dataclass(frozen=True, eq=False)
class FrequencyFunction:
    """One function of frequency between a response DOF and a reference DOF.

    Parameters
    ----------
    name : str
        Function description (record 1), e.g. ``beam_s1:z/hammer``.
    function_type : int
        4 (FRF) or 6 (coherence).
    response_node, response_direction : int
        The response DOF (UFF node and direction code).
    reference_node, reference_direction : int
        The reference DOF (the hammer's).
    numerator : str
        A key of ``QUANTITIES`` (the response's quantity); ignored for a coherence.
    denominator : str
        A key of ``QUANTITIES`` (the reference's quantity); ignored for a coherence.
    data : (nf,) array_like
        Complex for an FRF (SI units of numerator / denominator), real for a coherence.
    f0_hz, df_hz : float
        Hz, the first frequency and the spacing (> 0).
    """

    name: str
    function_type: int
    response_node: int
    response_direction: int
    reference_node: int
    reference_direction: int
    numerator: str
    denominator: str
    data: np.ndarray
    f0_hz: float
    df_hz: float

    def __post_init__(self) -> None:
        if self.function_type not in (FRF, COHERENCE):
            raise UffError(f"function {self.name!r}: function type must be {FRF} (FRF) or {COHERENCE} (coherence), "
                           f"got {self.function_type!r}")
        if self.function_type == FRF:
            for q in (self.numerator, self.denominator):
                if q not in QUANTITIES:
                    raise UffError(f"function {self.name!r}: unknown quantity {q!r} (known: {', '.join(QUANTITIES)})")
        for d in (self.response_direction, self.reference_direction):
            if d not in DIRECTIONS:
                raise UffError(f"function {self.name!r}: direction must be one of {DIRECTIONS}, got {d!r}")
        if not (math.isfinite(self.df_hz) and self.df_hz > 0 and math.isfinite(self.f0_hz)):
            raise UffError(f"function {self.name!r}: need a finite f0_hz and df_hz > 0, got {self.f0_hz!r}, "
                           f"{self.df_hz!r}")
        data = np.asarray(self.data)
        if data.ndim != 1 or data.size < 1:
            raise UffError(f"function {self.name!r}: data must be a non-empty 1-D series")
        object.__setattr__(self, "data", data.astype(complex if self.function_type == FRF else float))

    @property
    def freq_hz(self) -> np.ndarray:
        return self.f0_hz + np.arange(self.data.size) * self.df_hz

    @property
    def unit(self) -> str:
        """The ordinate's unit, e.g. ``m/s^2/N`` (``-`` for a coherence)."""
        if self.function_type == COHERENCE:
            return "-"
        return f"{QUANTITIES[self.numerator][1]}/{QUANTITIES[self.denominator][1]}"


def _characteristics(quantity: str) -> tuple[int, int, int, str]:
    code, unit, length, force = QUANTITIES[quantity]
    return code, length, force, unit


def write_uff58_functions(path: str | Path, functions, *, model: str = "bearingshaft") -> None:
    """Write ``functions`` (FrequencyFunction) to ``path`` as ASCII dataset 58 records (replacing the file).

    FRFs are complex double precision (ordinate data type 6, 4E20.12, real and imaginary parts
    alternating), coherences real double (type 4).

    Parameters
    ----------
    path : str or Path
        The file, replaced if it exists.
    functions : iterable of FrequencyFunction
        Written in order, one record each (function identification number = its position, from 1).
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
    for k, fn in enumerate(functions):
        if fn.function_type == FRF:
            num = _characteristics(fn.numerator)
            den = _characteristics(fn.denominator)
            ord_type, data = 6, np.asarray(fn.data, complex)
        else:
            num, den = (GENERAL_DATA_TYPE, 0, 0, "NONE"), (0, 0, 0, "NONE")
            ord_type, data = 4, np.asarray(fn.data, float)
        dset = pyuff.prepare_58(
            binary=0, id1=fn.name, id2=model, id3="NONE", id4="NONE", id5="NONE",
            func_type=fn.function_type, ver_num=0, load_case_id=0,
            rsp_ent_name=_name10(fn.name.split("/")[0]), rsp_node=int(fn.response_node),
            rsp_dir=int(fn.response_direction), ref_ent_name=_name10(fn.name.split("/")[-1]),
            ref_node=int(fn.reference_node), ref_dir=int(fn.reference_direction),
            ord_data_type=ord_type, num_pts=int(data.size), abscissa_spacing=1, abscissa_min=float(fn.f0_hz),
            abscissa_inc=float(fn.df_hz), z_axis_value=0.0, abscissa_spec_data_type=FREQUENCY_DATA_TYPE,
            abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0,
            abscissa_axis_units_lab="Hz",
            ordinate_spec_data_type=num[0], ordinate_len_unit_exp=num[1], ordinate_force_unit_exp=num[2],
            ordinate_temp_unit_exp=0, ordinate_axis_units_lab=num[3],
            orddenom_spec_data_type=den[0], orddenom_len_unit_exp=den[1], orddenom_force_unit_exp=den[2],
            orddenom_temp_unit_exp=0, orddenom_axis_units_lab=den[3],
            z_axis_spec_data_type=0, z_axis_len_unit_exp=0, z_axis_force_unit_exp=0, z_axis_temp_unit_exp=0,
            z_axis_axis_units_lab="NONE", data=data, x=fn.freq_hz,
        )
        dset["func_id"] = k + 1  # record 6 field 2 (pyuff's prepare_58 does not take it)
        sets.append(dset)
    pyuff.UFF(str(path)).write_sets(sets, mode="add")


def read_uff58_functions(path: str | Path) -> list[FrequencyFunction]:
    """Every dataset 58 FRF (type 4) and coherence (type 6) record of ``path``; one-line UffError on others.

    Parameters
    ----------
    path : str or Path
        A universal file.

    Returns
    -------
    list of FrequencyFunction, in file order

    Raises
    ------
    UffError
        No such file, an unreadable file, no dataset 58, a record of another function type,
        uneven spacing, an unknown numerator or denominator data type, or a unit label that is
        not the SI unit of its data type.
    """
    import pyuff

    path = Path(path)
    if not path.is_file():
        raise UffError(f"{str(path)!r}: no such file")
    try:
        uff = pyuff.UFF(str(path))
        idx = [i for i, t in enumerate(uff.get_set_types()) if int(t) == 58]
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
        ftype = rec.get("func_type")
        if ftype not in (FRF, COHERENCE):
            raise UffError(f"{where}: function type {ftype}, not an FRF ({FRF}) or a coherence ({COHERENCE})")
        if rec.get("abscissa_spacing", 1) != 1:
            raise UffError(f"{where}: uneven frequency spacing")
        quantities = []
        if ftype == FRF:
            for field, label in (("ordinate_spec_data_type", "ordinate_axis_units_lab"),
                                 ("orddenom_spec_data_type", "orddenom_axis_units_lab")):
                q = DATA_TYPES.get(rec.get(field))
                if q is None:
                    raise UffError(f"{where}: {field} {rec.get(field)} is none of "
                                   + ", ".join(f"{c} ({n})" for c, n in DATA_TYPES.items()))
                text = str(rec.get(label, "") or "").strip()
                if text and text.upper() != "NONE" and not _unit_ok(text, QUANTITIES[q][1]):
                    raise UffError(f"{where}: unit {text!r} is not {QUANTITIES[q][1]!r}, the SI unit of {q}")
                quantities.append(q)
        else:
            quantities = ["", ""]
        try:
            out.append(FrequencyFunction(name, int(ftype), int(rec.get("rsp_node", 0)), int(rec.get("rsp_dir", 0)),
                                         int(rec.get("ref_node", 0)), int(rec.get("ref_dir", 0)), quantities[0],
                                         quantities[1], np.asarray(rec["data"]), float(rec.get("abscissa_min", 0.0)),
                                         float(rec.get("abscissa_inc", 0.0))))
        except UffError as exc:
            raise UffError(f"{where}: {exc}") from None
    return out


@dataclass(frozen=True, eq=False)
class SensorGeometry:
    """Nodes of a test (sensors, load cells, hammer references) and the trace lines between them.

    Parameters
    ----------
    nodes : (n,) array_like of int
        UFF node labels.
    xyz : (n, 3) array_like of float
        m, their coordinates in the global Cartesian system.
    names : tuple of str
        A name per node (for the CSV beside the file).
    lines : tuple of (str, tuple of int)
        Trace lines: a name and the nodes drawn through (0: lift the pen).
    """

    nodes: np.ndarray
    xyz: np.ndarray
    names: tuple[str, ...]
    lines: tuple[tuple[str, tuple[int, ...]], ...]

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, int)
        xyz = np.asarray(self.xyz, float).reshape(-1, 3)
        if nodes.ndim != 1 or xyz.shape[0] != nodes.size or len(self.names) != nodes.size:
            raise ValueError(f"need n nodes, (n, 3) coordinates and n names, got {nodes.shape}, {xyz.shape}, "
                             f"{len(self.names)}")
        if len(set(nodes.tolist())) != nodes.size:
            raise ValueError("node labels must be unique")
        known = set(nodes.tolist()) | {0}
        for name, line in self.lines:
            bad = [n for n in line if n not in known]
            if bad:
                raise ValueError(f"trace line {name!r}: unknown nodes {bad}")
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "xyz", xyz)


def write_geometry(path: str | Path, geometry: SensorGeometry, dataset: int = 15) -> None:
    """Write the nodes (dataset 15 or 2411) and the trace lines (dataset 82) of ``geometry`` to ``path``.

    Parameters
    ----------
    path : str or Path
        The file, replaced if it exists.
    geometry : SensorGeometry
        Nodes and trace lines.
    dataset : {15, 2411}
        The nodes' dataset: 15 (single precision, the classic one) or 2411 (double precision).

    Returns
    -------
    None
    """
    import pyuff

    if dataset not in (15, 2411):
        raise ValueError(f"dataset must be 15 or 2411, got {dataset!r}")
    path = Path(path)
    if path.exists():
        path.unlink()
    n = geometry.nodes.size
    zeros = np.zeros(n, int)
    prepare = pyuff.prepare_15 if dataset == 15 else pyuff.prepare_2411
    sets = [prepare(node_nums=geometry.nodes, def_cs=zeros, disp_cs=zeros, color=zeros, x=geometry.xyz[:, 0],
                    y=geometry.xyz[:, 1], z=geometry.xyz[:, 2])]
    for k, (name, line) in enumerate(geometry.lines):
        sets.append(pyuff.prepare_82(trace_num=k + 1, n_nodes=len(line), color=0, id=name[:80],
                                     nodes=np.asarray(line, int)))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")


__all__ = ["FrequencyFunction", "write_uff58_functions", "read_uff58_functions", "SensorGeometry", "write_geometry",
           "FRF", "COHERENCE"]
