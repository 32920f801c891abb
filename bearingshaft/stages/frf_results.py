"""What the frf stage computes (:mod:`bearingshaft.stages.frf`), as its writers read it
(:mod:`bearingshaft.stages.frf_files`): the blows, the FRFs, the stabilization diagram, the
modes and their MAC against the model.

Data only: nothing here integrates, identifies, draws or writes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bearingshaft.scenes import Scene
from fem.frf import FRFEstimate
from fem.lscf import LSFDFit, OrderPoles, SelectedModes
from fem.uff_frf import SensorGeometry


@dataclass(frozen=True, slots=True)
class Dof:
    """A channel's place: its name, UFF node and direction code, and quantity.

    Attributes
    ----------
    name : str
        The channel's name.
    node, direction : int
        UFF node and direction code.
    quantity : str
        A key of ``fem.uff.QUANTITIES``.
    """

    name: str
    node: int
    direction: int
    quantity: str


@dataclass(frozen=True, eq=False)
class Blows:
    """Repeated blows, one record each: the hammer's force and every response, as recorded.

    Attributes
    ----------
    sample_rate_hz : float
        Hz, fs.
    force : (n_blows, N) ndarray of float
        N, the force of each blow (the hammer channel of its reference).
    responses : (n_blows, n_out, N) ndarray of float
        The responses, in ``outputs`` order.
    reference : (n_blows,) ndarray of int
        The reference (index into ``references``) of each blow.
    outputs : tuple of Dof
        The response channels.
    references : tuple of Dof
        The hammer's DOF at each reference.
    source : str
        Where the blows come from (the virtual test, or the file).
    info : dict
        How they were made or read (levels, noise, largest gap closure, acquisition), for provenance.
    """

    sample_rate_hz: float
    force: np.ndarray
    responses: np.ndarray
    reference: np.ndarray
    outputs: tuple[Dof, ...]
    references: tuple[Dof, ...]
    source: str
    info: dict

    @property
    def n_samples(self) -> int:
        return self.force.shape[1]


@dataclass(frozen=True, eq=False)
class Windows:
    """The windows applied before the transform.

    Attributes
    ----------
    trigger_s : (n_blows,) ndarray of float
        s, each blow's trigger (the force's first crossing of ``TRIGGER_SHARE`` of its peak).
    origin_s : (n_blows,) ndarray of float
        s, where the windows start (the trigger less the pre-trigger share of the force window).
    force_window_s : float
        s, the force window's length after the trigger.
    tau_s : float
        s, the exponential window's time constant (inf: none).
    sigma : float
        1/s, the decay rate it adds to every pole (1 / tau).
    """

    trigger_s: np.ndarray
    origin_s: np.ndarray
    force_window_s: float
    tau_s: float
    sigma: float


@dataclass(frozen=True, eq=False)
class ModelModes:
    """The model's modes: the reduced rig's open-gap complex poles, and the MAC reference shapes.

    Attributes
    ----------
    freq_hz, zeta : (k,) ndarray of float
        Hz and damping ratio of the rig's open-gap complex poles in the band (|lambda| / 2 pi, -Re / |lambda|).
    ref_names : tuple of str
        The MAC reference modes (Table 2 labels for the 3-D model, ``mode k`` for the reduced rig).
    ref_freq_hz : (r,) ndarray of float
        Hz, their frequencies.
    ref_shapes : (n_acc, r) ndarray of float
        Their shapes at the accelerometer axes of ``ref_dofs``.
    ref_dofs : tuple of str
        ``<sensor>:<axis>`` of the rows of ``ref_shapes``.
    source : str
        What the reference is ("3-D FE model, ..." or "reduced rig, ...").
    """

    freq_hz: np.ndarray
    zeta: np.ndarray
    ref_names: tuple[str, ...]
    ref_freq_hz: np.ndarray
    ref_shapes: np.ndarray
    ref_dofs: tuple[str, ...]
    source: str


@dataclass(frozen=True, eq=False)
class FRFResult:
    """FRFs of repeated blows and the modal parameters identified from them.

    Attributes
    ----------
    scene : Scene
        The scene.
    blows : Blows
        What was averaged.
    windows : Windows
        The windows.
    estimate : FRFEstimate
        H1, H2 and coherence of every output to every reference.
    band : slice
        The frequency lines of the identification.
    diagram : list of OrderPoles
        The stabilization diagram (windowed poles).
    selected : SelectedModes
        The modes picked from it (windowed poles).
    lam : (m,) ndarray of complex
        rad/s, their poles corrected for the exponential window.
    added_zeta : (m,) ndarray of float
        The damping ratio the window added to each.
    fit : LSFDFit
        Residues and residuals of the accelerometers (receptance form).
    acc_index : (n_acc,) ndarray of int
        The accelerometer outputs (rows of the FRFs) the shapes are at.
    shapes : (n_acc, m) ndarray of float
        Real mode shapes at those outputs, along +x, +y, +z.
    shape_dofs : tuple of str
        ``<sensor>:<axis>`` of each row of ``shapes``.
    complexity : (m,) ndarray of float
        Their complexity (0: a normal mode).
    model : ModelModes
        The model's modes.
    mac_beam, mac_assembly : (m, r) ndarray of float
        MAC of the identified shapes against the reference's, on the beam accelerometers and on
        all of them (the paper's Table 3 and Fig. 9).
    match : (m,) ndarray of int
        The model pole nearest each identified mode (index into ``model.freq_hz``).
    geometry : SensorGeometry
        Nodes and trace lines of the test.
    stats : dict
        For provenance.json.
    lines : tuple of str
        The stage's summary lines.
    """

    scene: Scene
    blows: Blows
    windows: Windows
    estimate: FRFEstimate
    band: slice
    diagram: list[OrderPoles]
    selected: SelectedModes
    lam: np.ndarray
    added_zeta: np.ndarray
    fit: LSFDFit
    acc_index: np.ndarray
    shapes: np.ndarray
    shape_dofs: tuple[str, ...]
    complexity: np.ndarray
    model: ModelModes
    mac_beam: np.ndarray
    mac_assembly: np.ndarray
    match: np.ndarray
    geometry: SensorGeometry
    stats: dict
    lines: tuple[str, ...]

    @property
    def freq_hz(self) -> np.ndarray:
        """Hz, the identified modes' natural frequencies |lambda| / 2 pi (window corrected)."""
        return np.abs(self.lam) / (2 * np.pi)

    @property
    def zeta(self) -> np.ndarray:
        """The identified damping ratios, window corrected."""
        return -self.lam.real / np.abs(self.lam)


__all__ = ["Dof", "Blows", "Windows", "ModelModes", "FRFResult"]
