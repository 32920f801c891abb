"""Scenes: TOML cases turned into frozen dataclasses, in this one package.

A scene names a model and the stages to run on it; a table present in the file is a stage
to run, a table absent is a stage skipped (and so never built). Layout::

    name = "discrete-impulse"          # optional, defaults to the file name
    description = "..."
    [model]          kind = "discrete" (DiscreteParams), "rom" (reduced.models.rom.RomSpec: the 3-D
                     model reduced to its tips), "assembly" (fem.model.AssemblyModel) or
                     "discrete_friction" (DiscreteFrictionParams: + the axial motion u, friction mu, k_t)
    [initial]        x0_m, v0_m_s at the points x1, x2, x3
    [[load]]         external forces (half_sine, harmonic, tabulated) at named points: a
                     ringdown with loads is a forced transient (reduced.models.loads)
    [ringdown]       integrator and run length                      -> stage ringdown
    [spectrogram]    STFT of one DOF with the NNM curves overlaid  (with ringdown)
    [symmetry]       |x_a - x_b| against time                      (with ringdown)
    [nnm]            frequency-energy relations                     -> stage nnm
    [fep]            HB / shooting backbones and stability (issue 3)   -> stage nnm
    [work_precision] error against run time                         -> stage study
    [stiff_cases]    stiff and extreme parameter sweep              -> stage study
    [rom_convergence] reduced model against its mode count          -> stage study (kind "rom")
    [verify]         reduction against the discrete model           -> stage verify (kind "rom")
    [frc]            forced-response curves by HB, stepped sine, stability (issue 11) -> stage frc
    [hammer]         the virtual hammer test of the apparatus, channel for channel (issue 12)
                     -> stage hammer (kind "rom", layout "assembly"; uses [ringdown] for the
                     integrator and record, [spectrogram] for Fig. 11 with dof = a channel)

Unknown keys, wrong types and invalid values raise :class:`SceneError` with a one-line
message naming the table and key.

The package is the schema at the bottom of the application layer: it imports models from
:mod:`reduced` (and :mod:`fem` lazily, for 3-D scenes) and nothing of the stages, the
pipeline or Dask. Modules: ``errors`` (SceneError, SweepError, suggestions), ``checks`` and
``convert`` (values to fields), ``tables`` (one dataclass per table), ``loads`` ([[load]]),
``models`` ([model] kinds), ``sweep`` ([sweep]), ``scene`` (:class:`Scene`), ``parse``
(text and files to scenes). Which stages a scene runs is the registry's business
(:func:`bearingshaft.registry.stages_of`).
"""

from bearingshaft.scenes.convert import from_table
from bearingshaft.scenes.errors import SceneError, SweepError, suggest
from bearingshaft.scenes.loads import LOAD_KINDS, HalfSineLoadSpec, HarmonicLoadSpec, TabulatedLoadSpec
from bearingshaft.scenes.models import MODEL_KINDS, model_class
from bearingshaft.scenes.parse import builtin_names, load_scene, parse_scene
from bearingshaft.scenes.scene import Scene
from bearingshaft.scenes.sweep import SweepSpec, Vary
from bearingshaft.scenes.tables import (
    SECTIONS,
    FEPSpec,
    FRCSpec,
    FRFSpec,
    HammerSpec,
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

__all__ = ["Scene", "SceneError", "SweepError", "SweepSpec", "Vary", "load_scene", "parse_scene", "builtin_names",
           "from_table", "suggest", "SECTIONS", "MODEL_KINDS", "LOAD_KINDS", "model_class", "FEPSpec", "FRCSpec",
           "HammerSpec", "InitialSpec", "ModalSpec", "NNMSpec", "RingdownSpec", "RomConvergenceSpec",
           "SpectrogramSpec", "StiffCasesSpec", "SymmetrySpec", "VerifySpec", "WorkPrecisionSpec",
           "HalfSineLoadSpec", "HarmonicLoadSpec", "TabulatedLoadSpec", "FRFSpec"]
