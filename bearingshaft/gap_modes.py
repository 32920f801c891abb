"""Which of the full 3-D model's modes a reduced model holds: the full model's open- and
closed-gap (tied) modes, each paired by mass-weighted MAC with the reduced mode it matches.

Shared by the stages that read a Craig-Bampton model against the full one: ``reduce``
(``gap_modes.csv``), ``verify`` (``verify.csv``, ``verify.md``) and ``study``
(``[rom_convergence]``'s reference frequencies). See :func:`compare_gap_modes` for the pairing
rule and why it does not depend on where its threshold sits.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass

import numpy as np

from reduced.models.modes import LinearModes, linear_modes
from reduced.models.rom import ReducedModel

N_FULL_MODES = 24  # full-model modes computed per contact state (all of them, coupled or not)
MAC_PAIR = 0.9  # a full mode is in the reduced basis, and a reduced mode its partner, above this (see below)
STATES = ("open", "closed")


def full_gap_modes(fe, spec, n_modes: int = N_FULL_MODES, Psi: np.ndarray | None = None) -> dict:
    """The full model's lowest modes with the scene's contact, open and tied.

    Parameters
    ----------
    fe : fem.model.FESystem
        The assembled 3-D model.
    spec : reduced.models.rom.RomSpec
        The scene's reduced-model table: its ``gap`` [m] and ``k_g`` [N/m] set the contact pairs.
    n_modes : int
        Modes computed per contact state.
    Psi : (N, 2) array, optional
        The constraint modes of the tips (see :func:`fem.contact.gap_modes`).

    Returns
    -------
    dict
        ``{state: fem.contact.GapModes}`` for ``state`` in :data:`STATES`.
    """
    from fem.contact import contact_pairs

    pairs = contact_pairs(fe, gap=spec.gap, k_g=spec.k_g)
    return {s: _state_modes(fe, pairs, s, n_modes, Psi) for s in STATES}


def _modes_key(fe, pairs, state: str, n_modes: int) -> str:
    """sha256 (hex) of what one state's eigensolution depends on: K, M, the tips' rows and k_g (closed only),
    the state, the number of modes, the code that builds and solves the model
    (:func:`reduced.models.rom.source_hash`) and the thread count asked for (``BEARINGSHAFT_THREADS``)."""
    from fem.contact import contact_rows
    from reduced.cache import hash_sparse
    from reduced.models.rom import source_hash

    h = hashlib.sha256(f"{state} {n_modes} {source_hash()} {os.environ.get('BEARINGSHAFT_THREADS', '')}".encode())
    hash_sparse(h, fe.K, fe.M)
    if state == "closed":  # the tied tips' stiffness k_g r r^T; the open state's K holds no contact
        h.update(np.ascontiguousarray(contact_rows(pairs)).tobytes())
        h.update(np.array([p.k_g for p in pairs], float).tobytes())
    return h.hexdigest()


def _state_modes(fe, pairs, state: str, n_modes: int, Psi):
    """:func:`fem.contact.gap_modes` of one state, its eigensolution kept in the reduced-model cache
    (``gapmodes-<key>.npz``, :func:`reduced.cache.cached_arrays`): the scenes of one 3-D model (four reductions
    of the apparatus) share it, and the result is built from the stored frequencies and shapes on a miss as on
    a hit, so both give the same bits (the factorization is single-threaded, :func:`_modes_key`)."""
    from fem.contact import gap_modes
    from reduced.cache import cached_arrays
    from reduced.models.rom import cache_dir

    def solve() -> dict:
        gm = gap_modes(fe, pairs, state, n_modes, Psi=Psi)
        return {"freq_hz": gm.freq_hz, "phi": gm.phi}

    key = _modes_key(fe, pairs, state, n_modes)
    z = cached_arrays(cache_dir() / f"gapmodes-{key[:20]}.npz", key, solve,
                      info={"kind": "full model's gap modes", "state": state, "n_modes": n_modes})
    return gap_modes(fe, pairs, state, n_modes, Psi=Psi, modes=(z["freq_hz"], z["phi"]))


def expand(rom: ReducedModel, q: np.ndarray) -> np.ndarray:
    """Full displacements u = Psi q_b + Phi eta of reduced coordinates q = [x1, x3, (tangential,) eta].

    Parameters
    ----------
    rom : ReducedModel
        The reduced model (its Psi (N, nb) and Phi (N, n - nb), nb = 2 or, with friction, more).
    q : (n, ...) array
        Reduced coordinates, one column per state or mode.

    Returns
    -------
    (N, ...) array
        The displacements of the full model's DOFs.
    """
    return rom.Psi @ q[:rom.nb] + rom.Phi @ q[rom.nb:]


@dataclass(frozen=True, eq=False)
class GapModeComparison:
    """The full model's modes of one contact state against the reduced model's, by mass-weighted MAC.

    Attributes
    ----------
    state : {'open', 'closed'}
        The contact state.
    full_hz : (m,) ndarray of float
        Hz, the full model's lowest modes.
    reduced : LinearModes
        The reduced model's modes (n of them).
    mac : (m, n) ndarray of float
        MAC_ij = (v_i^T M u_j)^2 / ((v_i^T M v_i)(u_j^T M u_j)), mass-weighted.
    basis_fraction : (m,) ndarray of float
        Share of full mode i in span[Psi, Phi] (M-norm); = sum_j MAC_ij.
    rows : list of dict
        One per full mode in the basis: its reduced partner, error, MAC.
    left_out : list of dict
        One per full mode not in the basis: why.
    unpaired : (k,) ndarray of int
        Reduced modes that are no full mode's partner (indices into ``reduced``).
    """

    state: str
    full_hz: np.ndarray  # (m,) Hz, the full model's lowest modes
    reduced: LinearModes  # the reduced model's modes (n of them)
    mac: np.ndarray  # (m, n) MAC_ij = (v_i^T M u_j)^2 / ((v_i^T M v_i)(u_j^T M u_j))
    basis_fraction: np.ndarray  # (m,) share of full mode i in span[Psi, Phi] (M-norm); = sum_j MAC_ij
    rows: list[dict]  # one per full mode in the basis: its reduced partner, error, MAC
    left_out: list[dict]  # one per full mode not in the basis: why
    unpaired: np.ndarray  # (k,) reduced modes that are no full mode's partner (index into ``reduced``)


def compare_gap_modes(rom: ReducedModel, fe, gm, planar: bool) -> GapModeComparison:
    """Pair the reduced model's modes with the full model's ``gm`` (a fem.contact.GapModes) by MAC.

    The reduced modes, expanded to the full DOFs (u = Psi q_b + Phi eta), are M-orthonormal
    and span the reduction basis V = [Psi, Phi]. With the mass-weighted MAC (the kinetic-energy
    inner product: independent of how finely the mesh samples a region, and exactly 0 between
    two distinct full modes), a full mode v_i splits as

        sum_j MAC_ij = v_i^T M V (V^T M V)^-1 V^T M v_i / (v_i^T M v_i) = basis_fraction_i <= 1.

    A full mode is one the reduced model is meant to keep when the basis holds at least
    ``MAC_PAIR`` = 0.9 of it; its partner is the reduced mode of largest MAC. Above 0.5 a
    partner is unique both ways (by Bessel's inequality at most one reduced mode can hold more
    than half of a full mode, and at most one full mode more than half of a reduced mode); 0.9,
    the usual test-analysis correlation threshold, asks that the pair share 90 % of their
    kinetic energy. On the impact beam the pairs measure >= 0.998 and every other full mode
    <= 1e-3 of the basis, so nothing depends on where between the threshold sits.

    Full modes outside the basis are listed with the reason: antisymmetric in y (out of
    plane: the tips act in y = 0 and ``planar`` keeps no such mode), symmetric but not moved by
    the tips (no coupling M_bq: surge, axial, z-antisymmetric modes), or moved by the tips but
    beyond the fixed-interface modes kept. Reduced modes that are no full mode's partner (those
    above the highest full mode computed, which cannot be checked) are in ``unpaired``.

    Parameters
    ----------
    rom : ReducedModel
        The reduced model.
    fe : fem.model.FESystem
        The full model it reduces (its mass matrix M weights the MAC).
    gm : fem.contact.GapModes
        The full model's modes of one contact state (:func:`full_gap_modes`).
    planar : bool
        Whether the reduction kept only modes symmetric in y (it names the reason of a left-out mode).

    Returns
    -------
    GapModeComparison
        The pairs, the full modes left out with their reason, and the reduced modes without partner.
    """
    red = linear_modes(rom.system(), gm.state)
    U = expand(rom, red.phi)
    MU = fe.M @ U
    Mv = fe.M @ gm.phi
    vv = np.einsum("ij,ij->j", gm.phi, Mv)
    uu = np.einsum("ij,ij->j", U, MU)
    mac = (gm.phi.T @ MU) ** 2 / np.outer(vv, uu)
    V = np.hstack([rom.Psi, rom.Phi])
    p = V.T @ Mv  # (n, m)
    fraction = np.einsum("ij,ij->j", p, np.linalg.solve(rom.M, p)) / vv
    f_fixed_max = float(rom.omega_fixed.max() / (2 * np.pi)) if rom.n_modes else 0.0
    rows, left_out = [], []
    for i, f in enumerate(gm.freq_hz):
        if fraction[i] >= MAC_PAIR:
            j = int(np.argmax(mac[i]))
            rows.append({"state": gm.state, "full_mode": i + 1, "full_hz": float(f), "reduced_mode": j + 1,
                         "reduced_hz": float(red.freq_hz[j]), "error_pct": float(100 * (red.freq_hz[j] - f) / f),
                         "mac": float(mac[i, j]), "basis_fraction": float(fraction[i])})
            continue
        if gm.symmetric[i] < 0:
            kind, why = "out of plane", "antisymmetric in y (out of plane): the tips cannot excite it" + (
                "; planar keeps no such mode" if planar else "")
        elif not gm.coupled[i]:
            kind, why = "not moved by the tips", "symmetric in y but not moved by the tips (no coupling to x1, x3)"
        else:
            kind, why = "beyond the basis", (f"moved by the tips, beyond the {rom.n_modes} fixed-interface "
                                             f"mode(s) kept (highest {f_fixed_max:.6g} Hz)")
        left_out.append({"state": gm.state, "full_mode": i + 1, "full_hz": float(f), "kind": kind, "reason": why,
                         "basis_fraction": float(fraction[i])})
    paired = {r["reduced_mode"] - 1 for r in rows}
    unpaired = np.array([j for j in range(len(red.freq_hz)) if j not in paired], dtype=int)
    return GapModeComparison(gm.state, gm.freq_hz, red, mac, fraction, rows, left_out, unpaired)


def compare_all(rom: ReducedModel, fe, spec, full: dict | None = None) -> dict[str, GapModeComparison]:
    """The reduced model against the full one in both contact states.

    Parameters
    ----------
    rom : ReducedModel
        The reduced model.
    fe : fem.model.FESystem
        The full model it reduces.
    spec : reduced.models.rom.RomSpec
        The scene's reduced-model table (contact and ``planar``).
    full : dict, optional
        ``{state: fem.contact.GapModes}`` already computed; by default :func:`full_gap_modes`
        with the reduced model's constraint modes.

    Returns
    -------
    dict
        ``{state: GapModeComparison}`` for ``state`` in :data:`STATES`.
    """
    full = full_gap_modes(fe, spec, Psi=rom.Psi) if full is None else full
    return {s: compare_gap_modes(rom, fe, full[s], spec.planar) for s in STATES}


def left_out_summary(comp: GapModeComparison) -> list[tuple[str, list[float]]]:
    """The full modes outside the basis, grouped by reason in the order they first appear.

    Parameters
    ----------
    comp : GapModeComparison
        One contact state's comparison.

    Returns
    -------
    list of (str, list of float)
        ``[(reason, [full_hz, ...])]``.
    """
    groups: dict[str, list[float]] = {}
    for r in comp.left_out:
        groups.setdefault(r["reason"], []).append(r["full_hz"])
    return list(groups.items())
