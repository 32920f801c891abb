"""The results of the nnm stage: what its compute returns and its writers read (no drawing here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# -- what the stage computed ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class NNM2Exact:
    """The exact NNM 2 relation of the symmetric 3-DOF model on an energy grid, and its check
    against periods integrated by DOP853 (``checks``: one dict per amplitude x0 / g, raw numbers;
    ``checked`` False for a model without a gap, which has nothing to check).

    Attributes
    ----------
    energy_J : (k,) ndarray of float
        J, the energy grid.
    freq_hz : (k,) ndarray of float
        Hz, the exact relation.
    freq_paper_hz : (k,) ndarray of float
        Hz, the paper's Eq. 12-14 as printed.
    checks : list of dict
        One per amplitude x0 / g: the integrated period against the closed form (raw numbers).
    checked : bool
        False for a model without a gap.
    """

    energy_J: np.ndarray  # (k,)
    freq_hz: np.ndarray  # (k,) exact
    freq_paper_hz: np.ndarray  # (k,) the paper's Eq. 12-14 as printed
    checks: list
    checked: bool


@dataclass(frozen=True, eq=False)
class FEPSummary:
    """The numbers of fep.md (a model without a closed form): the converged H and why.

    ``max_err``: H -> ({nnm: max error against the shooting orbits on the backbone}, whether
    every branch of that H reached ``[fep] energy_max_J``); ``off``: (nnm, orbit, best HB error)
    of the shooting orbits off the HB backbone.

    Attributes
    ----------
    converged_H : int or None
        Smallest H of the study within ``converged_tol`` of shooting, or None.
    max_err : dict
        H -> ({nnm: max error against the shooting orbits on the backbone}, every branch reached
        energy_max_J).
    off : list of tuple
        (nnm, orbit, best HB error) of the shooting orbits off the HB backbone.
    open_hz : ndarray of float
        Hz, every open-gap linear frequency.
    closed_hz : ndarray of float
        Hz, every closed-gap linear frequency.
    closed_idx : list of int
        The closed-gap modes that move the gaps, one per NNM followed.
    converged_tol : float
        Relative frequency error of a converged H.
    off_backbone_tol : float
        An orbit no H of the study comes within this of is off the backbone.
    """

    converged_H: int | None  # smallest H of the study within converged_tol of shooting, or None
    max_err: dict
    off: list
    open_hz: np.ndarray  # every open-gap linear frequency
    closed_hz: np.ndarray  # every closed-gap linear frequency
    closed_idx: list  # the closed-gap modes that move the gaps, one per NNM followed
    converged_tol: float  # relative frequency error of a converged H
    off_backbone_tol: float  # an orbit no H of the study comes within this of is off the backbone

    @property
    def n_off(self) -> int:
        """Shooting orbits off the HB backbone."""
        return len(self.off)


@dataclass(frozen=True, eq=False)
class FEPResult:
    """What the [fep] part of the nnm stage computed (:func:`bearingshaft.stages.nnm_fep.compute_fep`).

    Keys: ``nnm`` the 0-based position of a followed NNM, ``H`` the harmonics, ``N`` the AFT
    samples of the N study (None: the default of that H).

    Attributes
    ----------
    scene_name : str
        The scene's name.
    spec : FEPSpec
        The [fep] table.
    model : FEPModel
        System, modes followed, kind, exact reference, study NNM.
    open_hz : ndarray of float
        Hz, the followed NNMs' open-gap linear frequencies.
    closed_hz : ndarray of float
        Hz, the gap-moving closed-gap linear frequencies.
    branches : dict
        (nnm, H, N) -> NNMBranch.
    shots : dict
        nnm -> (energies (k,) in J, PeriodicOrbit or None per energy, wall_s).
    hill_stable : dict
        (nnm, H) -> per HB point of the drawn branch, stable by Hill's method.
    stability : list of dict
        stability.csv rows: Hill against Floquet at the shooting energies.
    disagreements : dict
        "NNM k H=h" -> points where Hill and Floquet disagree.
    errors : dict
        (nnm, H, N) -> (shooting energies, |f_HB / f_shooting - 1| there).
    exact_err : dict
        (nnm, H, N) -> |f_HB / f_exact - 1| at each point (NNMs with a closed form).
    convergence : list of dict
        hb_convergence.csv rows.
    shooting_vs_exact : float or None
        max |f / f_exact - 1| of the shooting orbits (with a closed form).
    summary : FEPSummary or None
        fep.md's numbers (a reduced model).
    """

    scene_name: str
    spec: object  # the [fep] table
    model: object  # the FEPModel: system, modes followed, kind, exact reference, study NNM
    open_hz: np.ndarray  # the followed NNMs' open-gap linear frequencies
    closed_hz: np.ndarray  # the gap-moving closed-gap linear frequencies
    branches: dict  # (nnm, H, N) -> NNMBranch
    shots: dict  # nnm -> (energies (k,), PeriodicOrbit or None per energy, wall_s)
    hill_stable: dict  # (nnm, H) -> per HB point of the drawn branch, stable by Hill's method
    stability: list  # stability.csv rows: Hill against Floquet at the shooting energies
    disagreements: dict  # "NNM k H=h" -> points where Hill and Floquet disagree
    errors: dict  # (nnm, H, N) -> (shooting energies, |f_HB / f_shooting - 1| there)
    exact_err: dict  # (nnm, H, N) -> |f_HB / f_exact - 1| at each point (NNMs with a closed form)
    convergence: list  # hb_convergence.csv rows
    shooting_vs_exact: float | None  # max |f / f_exact - 1| of the shooting orbits (with a closed form)
    summary: FEPSummary | None  # fep.md's numbers (a reduced model)


@dataclass(frozen=True, eq=False)
class NNMResult:
    """What the nnm stage computed (:func:`bearingshaft.stages.nnm.compute`).

    Attributes
    ----------
    scene_name : str
        The scene's name.
    dof_names : tuple of str
        The model's coordinates.
    linear : dict
        "open", "closed" -> LinearModes.
    nnm2 : NNM2Exact or None
        The exact NNM 2 relation (a symmetric discrete model).
    nnm2_skipped : str
        Why the exact NNM 2 relation was not computed ("" if it was).
    fep : FEPResult or None
        The [fep] study.
    """

    scene_name: str
    dof_names: tuple[str, ...]
    linear: dict  # "open", "closed" -> LinearModes
    nnm2: NNM2Exact | None
    nnm2_skipped: str  # why the exact NNM 2 relation was not computed ("" if it was)
    fep: FEPResult | None
