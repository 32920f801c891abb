"""Reduced and discrete models of the assembly and the solvers that run on them.

Subpackages, imported one way (``models`` imports no solver):

- :mod:`reduced.models`: gap systems, the three-mass model, Craig-Bampton reduced models,
  linear modes, initial states;
- :mod:`reduced.transient`: ringdowns by the exact, explicit and DOP853 integrators,
  spectrograms;
- :mod:`reduced.periodic`: harmonic balance, continuation, NNM backbones, shooting, stability;
- :mod:`reduced.studies`: work-precision, stiff and extreme cases, mode-count convergence.

The names most used are importable from here (``from reduced import GapSystem, ringdown``);
each is loaded on first use, so importing :mod:`reduced` costs almost nothing: it only checks
that numba's disk cache of the package's kernels was compiled against these sources
(:func:`reduced._kernel_cache.refresh`, ~4 ms; numba alone checks only the file that defines a kernel,
not the files of the kernels it calls).
"""

from importlib import import_module

from reduced._kernel_cache import refresh as _refresh_kernel_cache

_refresh_kernel_cache()

_PUBLIC = {
    "GapSystem": "reduced.models.gaps",
    "DiscreteParams": "reduced.models.discrete",
    "DiscreteFrictionParams": "reduced.models.discrete",
    "Friction": "reduced.models.gaps",
    "linear_modes": "reduced.models.modes",
    "RomSpec": "reduced.models.rom",
    "ReducedModel": "reduced.models.rom",
    "build_rom": "reduced.models.rom",
    "initial_state": "reduced.models.initial",
    "ringdown": "reduced.transient.integrate",
    "RingdownResult": "reduced.transient.result",
    "integrate_exact": "reduced.transient.exact",
    "integrate_explicit": "reduced.transient.explicit",
    "integrate_dop853": "reduced.transient.dop853",
    "HarmonicBalance": "reduced.periodic.hb",
    "nnm_branch": "reduced.periodic.backbones",
    "hb_backbones": "reduced.periodic.backbones",
    "shoot": "reduced.periodic.shooting",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        return getattr(import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'reduced' has no attribute {name!r}")
