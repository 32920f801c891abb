"""A scene: one case, a model and the tables that say which stages run on it
(:func:`bearingshaft.registry.stages_of`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from bearingshaft.scenes.sweep import SweepSpec
from bearingshaft.scenes.tables import (
    FEPSpec,
    FRCSpec,
    FRFSpec,
    HammerSpec,
    IdentifySpec,
    InitialSpec,
    ModalSpec,
    NNMSpec,
    RingdownSpec,
    RomConvergenceSpec,
    SpectrogramSpec,
    StiffCasesSpec,
    SymmetrySpec,
    VerifySpec,
    WorkPrecisionSpec,
)


@dataclass(frozen=True, slots=True)
class Scene:
    """One case: a model and the stages to run on it.

    Attributes
    ----------
    name : str
        The scene's name (file stem or built-in name).
    description : str
        One line from the file.
    model_kind : str
        "discrete", "rom" or "assembly".
    model : DiscreteParams, RomSpec or fem.model.AssemblyModel
        The [model] table.
    source : str
        The TOML text as read, kept with every result.
    origin : str
        Where it was read from, for messages.
    initial : InitialSpec
        [initial], the points' initial state.
    loads : tuple
        The [[load]] specs (HalfSineLoadSpec, HarmonicLoadSpec, TabulatedLoadSpec).
    load_signals : tuple
        Their time functions (:mod:`reduced.models.loads`).
    modal, ringdown, spectrogram, symmetry, nnm, fep : table dataclass or None
        The tables of the same names (:mod:`bearingshaft.scenes.tables`), None where the scene has none.
    work_precision, stiff_cases, rom_convergence, verify, frc, hammer : table dataclass or None
        Likewise.
    frf : FRFSpec or None
        [frf], FRFs and modal parameters of a hammer test (needs [hammer]).
    identify : IdentifySpec or None
        [identify], the parameters ``bearingshaft identify`` fits to a measured test (needs [hammer]).
    sweep : SweepSpec or None
        [sweep], run by ``bearingshaft sweep``.
    folder : str
        The folder its file paths are relative to (the scene file's; the package's for a built-in one).
    """

    name: str
    description: str
    model_kind: str
    model: object  # DiscreteParams | RomSpec | fem.model.AssemblyModel
    source: str = field(repr=False)  # the TOML text as read, kept with every result
    origin: str = field(default="", repr=False)  # where it was read from, for messages
    initial: InitialSpec = InitialSpec()
    loads: tuple = ()  # [[load]] specs (HalfSineLoadSpec | HarmonicLoadSpec | TabulatedLoadSpec)
    load_signals: tuple = field(default=(), repr=False)  # their time functions (reduced.models.loads)
    modal: ModalSpec | None = None
    ringdown: RingdownSpec | None = None
    spectrogram: SpectrogramSpec | None = None
    symmetry: SymmetrySpec | None = None
    nnm: NNMSpec | None = None
    fep: FEPSpec | None = None
    work_precision: WorkPrecisionSpec | None = None
    stiff_cases: StiffCasesSpec | None = None
    rom_convergence: RomConvergenceSpec | None = None
    verify: VerifySpec | None = None
    frc: FRCSpec | None = None
    hammer: HammerSpec | None = None
    frf: FRFSpec | None = None  # [frf]: FRFs and modal parameters of a hammer test (issue 26)
    identify: IdentifySpec | None = None  # [identify]: fitted to a test by `bearingshaft identify` (issue 26)
    sweep: SweepSpec | None = None  # [sweep]: run by `bearingshaft sweep`
    folder: str = field(default="", repr=False)  # the folder its file paths are relative to (issue 24)

