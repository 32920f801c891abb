"""The virtual rig: a reduced model of the apparatus with the test's channels and the hammer.

A :class:`VirtualRig` is a reduced 3-D model (:class:`reduced.models.rom.ReducedModel`, built
with its rig outputs and mesh) with a hammer blow of unit force along ``direction`` at
``location`` on the beam (reduced load b = V^T b_full, :meth:`ReducedModel.point_load`):

    M q'' + C q' + K q + B^T f(B q) = b p(t),

and the channels of :mod:`fem.rig`, synthesised from the state (q, q') at each sample:

- accelerometers: a = R q'' with q'' = M^-1 (b p - C q' - K q - B^T f(B q) - Bt^T f_t), exact
  given the state (no differencing; f_t = k_t (Bt q - w) the sliders' forces when the tips have
  friction, w their positions);
- tip load cells: the stop's compression f_c >= 0 (upper stop of a gap: the top tip, lower
  stop: the bottom one) minus the seismic mass's inertia along the cell, F = f_c - m_a a_z
  (top), f_c + m_a a_z (bottom), a_z the seat's vertical acceleration;
- the hammer: p(t) itself (its load cell reads the force it applies).

Nothing here integrates: the solvers (:mod:`reduced.transient`) give (q, q'), this module
turns them into channels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fem.rig import HAMMER_NODE, TIP_CELLS, dominant_axis, sensor_node, tip_node, unit_direction
from reduced.models.gaps import GapSystem
from reduced.models.loads import Loads

# quantity of each channel kind (keys of fem.uff.QUANTITIES)
KIND_QUANTITY = {"accelerometer": "acceleration", "load_cell": "reaction_force", "hammer": "force"}
SEISMIC_MASS_KG = 0.04  # kg, tip + bolt + half the load cell above its gauge (half the tip assembly's 0.08 kg)


@dataclass(frozen=True, slots=True)
class Channel:
    """One channel as the rig names it, with its UFF node and direction code.

    Parameters
    ----------
    name : str
        ``<sensor>:<axis>``, a tip load cell (``TIP_CELLS``) or ``hammer``.
    node : int
        UFF node number.
    direction : int
        UFF code: 1, 2, 3 = +X, +Y, +Z; negative: the opposite sense.
    kind : {'accelerometer', 'load_cell', 'hammer'}
        Sets the quantity (``KIND_QUANTITY``) and unit (m/s^2 or N).
    """

    name: str
    node: int
    direction: int  # UFF code: 1, 2, 3 = +X, +Y, +Z; negative: the opposite sense
    kind: str  # accelerometer | load_cell | hammer

    @property
    def quantity(self) -> str:
        return KIND_QUANTITY[self.kind]

    @property
    def unit(self) -> str:
        return "m/s^2" if self.kind == "accelerometer" else "N"


@dataclass(frozen=True, eq=False)
class VirtualRig:
    """The reduced apparatus, its channels and the hammer's unit load vector.

    Attributes
    ----------
    system : GapSystem
        The reduced apparatus with its four stops x1+, x1-, x3+, x3-.
    channels : tuple of Channel
        Accelerometer axes, then the four tip load cells (``TIP_CELLS`` order), then the hammer.
    acc_rows : (n_acc, n) ndarray of float
        Reduced rows of the accelerometer axes, in channel order (displacement = row @ q, m).
    seat_rows : (4, n) ndarray of float
        Reduced rows of the tip seats' vertical displacement, ``TIP_CELLS`` order.
    b : (n,) ndarray of float
        Reduced load of a unit hammer force (per N).
    location : tuple of 3 float
        m, the point struck.
    direction : tuple of 3 float
        Unit vector of the blow.
    seismic_mass_kg : float
        kg, m_a, the mass above each load cell's gauge.
    """

    system: GapSystem
    channels: tuple[Channel, ...]
    acc_rows: np.ndarray  # (n_acc, n) reduced rows of the accelerometer axes, in channel order
    seat_rows: np.ndarray  # (4, n) the tip seats' vertical motion, in TIP_CELLS order
    b: np.ndarray  # (n,) reduced load of a unit hammer force
    location: tuple[float, float, float]  # m
    direction: tuple[float, float, float]  # unit vector
    seismic_mass_kg: float = SEISMIC_MASS_KG

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    def loads(self, signal) -> Loads:
        """The blow as a load on the model: f_ext = b p(t)."""
        return Loads(self.b[None, :], (signal,), ("hammer",))

    def channel_data(self, x: np.ndarray, v: np.ndarray, p: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        """(n_channels, N) every channel at N samples of the state x, v (N, n) under hammer force p (N,); with
        friction, the sliders' positions w (N, p) give their forces (the tips' tangential forces on the beam)."""
        s = self.system
        x, v, p = np.atleast_2d(x), np.atleast_2d(v), np.atleast_1d(p)
        W = np.linalg.solve(s.M, np.vstack([self.acc_rows, self.seat_rows]).T).T  # rows of R M^-1 (M symmetric)
        a = (np.outer(W @ self.b, p) - (W @ s.C) @ v.T - (W @ s.K) @ x.T  # R q'' for every row, (rows, N)
             - W @ s.contact_force(x).T)
        if s.friction is not None:
            if w is None:
                raise ValueError("a rig with friction needs the sliders' positions w for its channels")
            a -= (W @ s.friction.Bt.T) @ s.friction.force(x, np.atleast_2d(w)).T
        acc, seat = a[: len(self.acc_rows)], a[len(self.acc_rows):]
        stop = s.stop_force(x).T  # (4, N) compression of x1+, x1-, x3+, x3-: the tips in TIP_CELLS order
        sign = np.array([1.0 if c.endswith("top") else -1.0 for c in TIP_CELLS])[:, None]
        cells = stop - sign * self.seismic_mass_kg * seat
        return np.vstack([acc, cells, p[None, :]])


def virtual_rig(rom, location, direction, seismic_mass_kg: float = SEISMIC_MASS_KG) -> VirtualRig:
    """The rig of a reduced assembly model ``rom`` (built with its outputs) struck at ``location``.

    Parameters
    ----------
    rom : ReducedModel
        A reduced model of the whole assembly built with its rig outputs (sensor axes and
        ``seat:<cell>`` rows) and its mesh.
    location : array_like of 3 float
        m, the point struck, on the beam.
    direction : array_like of 3 float
        The blow's direction (normalised here).
    seismic_mass_kg : float
        kg, m_a, >= 0.

    Returns
    -------
    VirtualRig

    Raises
    ------
    ValueError
        A model without rig outputs (not the assembly), a negative or non-finite seismic mass, a
        zero direction, a location off the beam, a model without a mesh, or stops other than
        x1+, x1-, x3+, x3-.
    """
    if not rom.output_names or not any(n.startswith("seat:") for n in rom.output_names):
        raise ValueError("the virtual hammer test needs a reduced model of the whole assembly "
                         "([model] layout = \"assembly\") built with its rig outputs")
    if not (np.isfinite(seismic_mass_kg) and seismic_mass_kg >= 0):
        raise ValueError(f"seismic_mass_kg must be >= 0, got {seismic_mass_kg!r}")
    d = unit_direction(direction)
    b = rom.point_load(location, d)
    system = rom.system()
    if system.stop_names != ("x1+", "x1-", "x3+", "x3-"):
        raise ValueError(f"unexpected stops {system.stop_names}: the load cells follow x1+, x1-, x3+, x3-")
    acc_names = [n for n in rom.output_names if not n.startswith("seat:")]
    channels = [Channel(n, sensor_node(n.split(":")[0]), "xyz".index(n[-1]) + 1, "accelerometer")
                for n in acc_names]
    channels += [Channel(c, *tip_node(c), "load_cell") for c in TIP_CELLS]
    channels.append(Channel("hammer", HAMMER_NODE, dominant_axis(d), "hammer"))
    return VirtualRig(system=system, channels=tuple(channels),
                      acc_rows=np.vstack([rom.output(n) for n in acc_names]),
                      seat_rows=np.vstack([rom.output(f"seat:{c}") for c in TIP_CELLS]), b=b,
                      location=tuple(float(v) for v in location), direction=tuple(float(v) for v in d),
                      seismic_mass_kg=float(seismic_mass_kg))


__all__ = ["Channel", "VirtualRig", "virtual_rig", "SEISMIC_MASS_KG", "KIND_QUANTITY"]
