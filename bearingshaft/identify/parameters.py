"""The parameters a scene's [identify] table fits: their keys, units, bounds and scales.

A parameter is a key of the scene's reduced model (``model.gap``, ``model.k_g``, ``model.c_points``,
``model.alpha``; ``model.modal_damping[i]``, an element of a list key, once the model has one):
the keys that :meth:`reduced.models.rom.ReducedModel.with_contact` applies to a reduction
without rebuilding it (contact and damping). Keys that change the reduction itself (the mode
count, the mesh) are refused; the bungee and spring stiffnesses are keys of the 3-D model
(``kind = "assembly"``), not of a reduced one, so a reduced scene cannot name them (each fit would
remesh and reduce the apparatus: about 60 s a model run instead of 3).

The least-squares fit works on scaled, dimensionless variables theta:

    log scale:  theta = ln(p / p0)            (p0 the scene's value: theta = 0 there; steps relative)
    lin scale:  theta = (p - p0) / (upper - lower)

so that one finite-difference step and one trust region suit parameters of any unit and size.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

from bearingshaft.scenes import Scene, SceneError

FITTABLE = ("gap", "k_g", "c_points", "alpha", "modal_damping")  # keys with_contact applies without a new reduction
DEFAULT_SPAN = 4.0  # default bounds: the scene's value / 4 and x 4
_KEY = re.compile(r"^model\.(?P<name>\w+)(?:\[(?P<index>\d+)\])?$")


@dataclass(frozen=True, slots=True)
class Parameter:
    """One fitted parameter.

    Attributes
    ----------
    key : str
        As the scene writes it, ``model.KEY`` or ``model.KEY[i]``.
    unit : str
        Its SI unit ("" for a ratio).
    initial : float
        The scene's value, where the fit starts.
    lower, upper : float
        Its bounds, in its unit.
    scale : str
        ``log`` or ``lin`` (module docstring).
    """

    key: str
    unit: str
    initial: float
    lower: float
    upper: float
    scale: str

    @property
    def name(self) -> str:
        """The model field (``gap`` for ``model.gap``, ``modal_damping`` for ``model.modal_damping[0]``)."""
        return _KEY.match(self.key)["name"]

    @property
    def index(self) -> int | None:
        m = _KEY.match(self.key)["index"]
        return None if m is None else int(m)

    def theta(self, value: float) -> float:
        """The scaled variable of ``value`` (module docstring)."""
        if self.scale == "log":
            return math.log(value / self.initial)
        return (value - self.initial) / (self.upper - self.lower)

    def value(self, theta: float) -> float:
        """The parameter's value at scaled ``theta``."""
        if self.scale == "log":
            return self.initial * math.exp(theta)
        return self.initial + theta * (self.upper - self.lower)

    @property
    def theta_bounds(self) -> tuple[float, float]:
        return self.theta(self.lower), self.theta(self.upper)


def _unit(model_cls: type, name: str) -> str:
    from bearingshaft.scenes.keys import field_comments, unit_and_meaning

    return unit_and_meaning(field_comments(model_cls).get(name, ""))[0]


def parameters_of(scene: Scene) -> tuple[Parameter, ...]:
    """The parameters of ``scene``'s [identify] table, with their units, values, bounds and scales.

    Parameters
    ----------
    scene : Scene
        A scene with [identify] and a reduced model.

    Returns
    -------
    tuple of Parameter

    Raises
    ------
    SceneError
        One line naming the key: not a key of the model, one that needs a new reduction, a value
        outside its bounds, a log scale on a value of 0, bounds a model value may not take.
    """
    spec = scene.identify
    where = f"{scene.origin or scene.name} [identify]"
    model = scene.model
    if scene.model_kind != "rom":
        raise SceneError(f"{where}: fits the reduced apparatus ([model] kind = \"rom\"), not {scene.model_kind!r}")
    fields = {f.name for f in dataclasses.fields(model)}
    out = []
    for i, key in enumerate(spec.parameters):
        m = _KEY.match(key)
        if m is None:
            raise SceneError(f"{where} parameters[{i}]: {key!r} is not a [model] key written model.KEY or "
                             f"model.KEY[i]")
        name, index = m["name"], m["index"]
        if name not in fields:
            hint = (" (the bungee and spring stiffnesses are keys of the 3-D model, kind = \"assembly\": a reduced "
                    "model cannot vary them without a new reduction per run)" if name.startswith(("bungee", "k_s"))
                    else "")
            raise SceneError(f"{where} parameters[{i}]: the reduced model has no key {name!r}{hint}; fittable: "
                             f"{', '.join(f for f in FITTABLE if f in fields)}")
        if name not in FITTABLE:
            raise SceneError(f"{where} parameters[{i}]: {key!r} changes the reduction itself (each run would rebuild "
                             f"it); fittable: {', '.join(f for f in FITTABLE if f in fields)}")
        current = getattr(model, name)
        if isinstance(current, tuple):
            if index is None:
                raise SceneError(f"{where} parameters[{i}]: {key!r} is a list; name one element, {key}[0]")
            k = int(index)
            if k >= len(current):
                raise SceneError(f"{where} parameters[{i}]: {key!r}: the model gives {len(current)} values "
                                 f"(give [model] {name} at least {k + 1})")
            value = float(current[k])
        elif index is not None:
            raise SceneError(f"{where} parameters[{i}]: {name!r} is not a list")
        else:
            value = float(current)
        scale = spec.scales[i] if spec.scales else ("log" if value > 0 else "lin")
        if scale == "log" and not value > 0:
            raise SceneError(f"{where} scales[{i}]: {key} = {value!r} in the scene: a log scale needs a value > 0 "
                             f"(give it one, or scale = \"lin\" with its bounds)")
        lo = spec.lower[i] if spec.lower else (value / DEFAULT_SPAN if value > 0 else None)
        hi = spec.upper[i] if spec.upper else (value * DEFAULT_SPAN if value > 0 else None)
        if lo is None or hi is None:
            raise SceneError(f"{where}: {key} = 0 in the scene: give its bounds (lower, upper)")
        if not lo <= value <= hi:
            raise SceneError(f"{where} lower[{i}], upper[{i}]: {key} = {value!r} in the scene lies outside "
                             f"[{lo!r}, {hi!r}]")
        if scale == "log" and not lo > 0:
            raise SceneError(f"{where} lower[{i}]: a log scale needs a lower bound > 0, got {lo!r}")
        for bound in (lo, hi):  # the model must accept every value the fit may try
            try:
                with_values(model, {key: bound})
            except ValueError as exc:
                raise SceneError(f"{where}: the bound {bound!r} of {key}: {exc}") from None
        out.append(Parameter(key, _unit(type(model), name), value, float(lo), float(hi), scale))
    return tuple(out)


def with_values(model, values: dict):
    """``model`` (a frozen dataclass) with ``{"model.KEY" or "model.KEY[i]": value}`` set (its checks run).

    Parameters
    ----------
    model : RomSpec or another model dataclass
    values : dict

    Returns
    -------
    The replaced dataclass (ValueError from its checks for a value it refuses).

    Examples
    --------
    >>> from reduced.models.rom import RomSpec
    >>> with_values(RomSpec(), {"model.gap": 1e-4}).gap
    0.0001
    """
    changes: dict = {}
    for key, v in values.items():
        m = _KEY.match(key)
        name, index = m["name"], m["index"]
        if index is None:
            changes[name] = float(v)
        else:
            seq = list(changes.get(name, getattr(model, name)))
            seq[int(index)] = float(v)
            changes[name] = tuple(seq)
    return dataclasses.replace(model, **changes)


__all__ = ["Parameter", "parameters_of", "with_values", "FITTABLE"]
