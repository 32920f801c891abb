"""Modal assurance criterion and mode shapes in universal files (dataset 55) or CSV.

MAC_ij = |a_i^T b_j|^2 / ((a_i^T a_i)(b_j^T b_j)) (Allemang and Brown, 1982), a_i and b_j
mode shapes at the same sensor DOFs; 1 for parallel shapes, 0 for orthogonal ones.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def mac(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(m, n) MAC between the columns of A (p, m) and B (p, n).

    Parameters
    ----------
    A : (p, m) array_like of float
        Mode shapes at p DOFs.
    B : (p, n) array_like of float
        Mode shapes at the same p DOFs.

    Returns
    -------
    (m, n) ndarray of float
        MAC_ij of column i of A with column j of B, in [0, 1].

    Raises
    ------
    ValueError
        A and B with different numbers of rows.
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    if A.shape[0] != B.shape[0]:
        raise ValueError(f"shapes must share their DOFs: {A.shape[0]} != {B.shape[0]}")
    num = np.abs(A.T @ B) ** 2
    den = np.outer(np.einsum("ij,ij->j", A, A), np.einsum("ij,ij->j", B, B))
    return num / np.maximum(den, 1e-300)


def write_uff55(path: str | Path, node_ids: np.ndarray, freq_hz: np.ndarray, shapes: np.ndarray,
                name: str = "bearingshaft") -> None:
    """Write real normal modes as UFF dataset 55 (three DOFs per node).

    ``shapes`` is (3 n_nodes, n_modes) with x, y, z per node in ``node_ids`` order.

    Parameters
    ----------
    path : str or Path
        The file, replaced if it exists.
    node_ids : (n_nodes,) array_like of int
        UFF node numbers.
    freq_hz : (n_modes,) array_like of float
        Hz, one per mode.
    shapes : (3 n_nodes, n_modes) ndarray of float
        Mode shapes, x, y, z per node (written with modal mass 1).
    name : str
        The records' first ID line.

    Returns
    -------
    None
    """
    import pyuff

    path = Path(path)
    if path.exists():
        path.unlink()
    node_ids = np.asarray(node_ids, dtype=int)
    n = len(node_ids)
    uff = pyuff.UFF(str(path))
    sets = []
    for k, f in enumerate(freq_hz):
        s = np.asarray(shapes[:, k], float).reshape(n, 3)
        sets.append(pyuff.prepare_55(
            model_type=1, id1=name, id2=f"mode {k + 1}", id3="NONE", id4="NONE", id5="NONE",
            analysis_type=2, data_ch=2, spec_data_type=8, data_type=2, n_data_per_node=3,
            r1=s[:, 0], r2=s[:, 1], r3=s[:, 2], load_case=1, mode_n=k + 1, freq=float(f),
            modal_m=1.0, modal_damp_vis=0.0, modal_damp_his=0.0, node_nums=node_ids,
        ))
    uff.write_sets(sets, mode="add")


def read_uff55(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read real modes from UFF dataset 55: (node_ids, freq_hz (m,), shapes (3 n, m)).

    Parameters
    ----------
    path : str or Path
        A universal file holding dataset 55 records (other datasets are skipped).

    Returns
    -------
    node_ids : (n,) ndarray of int
        Node numbers of the first record.
    freq_hz : (m,) ndarray of float
        Hz, one per record.
    shapes : (3 n, m) ndarray of float
        Real parts of the shapes, x, y, z per node.

    Raises
    ------
    ValueError
        No dataset 55 in the file.
    """
    import pyuff

    uff = pyuff.UFF(str(path))
    types = uff.get_set_types()
    idx = [i for i, t in enumerate(types) if int(t) == 55]
    if not idx:
        raise ValueError(f"{path}: no dataset 55 (data at nodes) found")
    data = uff.read_sets(idx)
    if isinstance(data, dict):
        data = [data]
    nodes = np.asarray(data[0]["node_nums"], dtype=int)
    freq = np.array([float(d["freq"]) for d in data])
    shapes = np.column_stack([np.column_stack([d["r1"], d["r2"], d["r3"]]).ravel() for d in data])
    return nodes, freq, np.real(shapes)


def read_shapes_csv(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Test shapes from CSV: header ``dof,mode1,...``, one row per sensor DOF (e.g. beam_s1:x).

    Parameters
    ----------
    path : str or Path
        CSV file; the header line is skipped.

    Returns
    -------
    dofs : list of str
        The first column (sensor DOF names).
    shapes : (n_dofs, n_modes) ndarray of float
        The other columns.
    """
    rows = Path(path).read_text().strip().splitlines()
    dofs, vals = [], []
    for line in rows[1:]:
        parts = line.split(",")
        dofs.append(parts[0])
        vals.append([float(v) for v in parts[1:]])
    return dofs, np.array(vals)
