"""The [model] kinds: the 3-DOF model, the reduced 3-D model, the 3-D assembly, and the 3-DOF model with the
beam's axial motion and friction at the tips (``discrete_friction``: keys ``mu`` and ``k_t``, N/m, default
Mindlin's 0.82 k_g, see :class:`reduced.models.discrete.DiscreteFrictionParams`)."""

from __future__ import annotations

from reduced.models.discrete import DiscreteFrictionParams, DiscreteParams
from reduced.models.rom import RomSpec


def _assembly_model():
    from fem.model import AssemblyModel  # imported only for 3-D scenes: no scikit-fem otherwise

    return AssemblyModel


MODEL_KINDS: dict[str, object] = {"discrete": DiscreteParams, "assembly": _assembly_model, "rom": RomSpec,
                                  "discrete_friction": DiscreteFrictionParams}


def model_class(kind: str) -> type:
    """The dataclass of [model] ``kind`` (the 3-D model's is imported only when asked for).

    Parameters
    ----------
    kind : str
        A key of ``MODEL_KINDS``: "discrete", "rom", "assembly" or "discrete_friction".

    Returns
    -------
    type
        DiscreteParams, RomSpec, fem.model.AssemblyModel or DiscreteFrictionParams.

    Raises
    ------
    KeyError
        An unknown kind.
    """
    entry = MODEL_KINDS[kind]
    return entry if isinstance(entry, type) else entry()
