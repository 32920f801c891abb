"""The [model] kinds: the 3-DOF model, the reduced 3-D model and the 3-D assembly."""

from __future__ import annotations

from reduced.models.discrete import DiscreteParams
from reduced.models.rom import RomSpec


def _assembly_model():
    from fem.model import AssemblyModel  # imported only for 3-D scenes: no scikit-fem otherwise

    return AssemblyModel


MODEL_KINDS: dict[str, object] = {"discrete": DiscreteParams, "assembly": _assembly_model, "rom": RomSpec}


def model_class(kind: str) -> type:
    """The dataclass of [model] ``kind`` (the 3-D model's is imported only when asked for).

    Parameters
    ----------
    kind : str
        A key of ``MODEL_KINDS``: "discrete", "rom" or "assembly".

    Returns
    -------
    type
        DiscreteParams, RomSpec or fem.model.AssemblyModel.

    Raises
    ------
    KeyError
        An unknown kind.
    """
    entry = MODEL_KINDS[kind]
    return entry if isinstance(entry, type) else entry()
