"""Reduced-order model of the 3-D assembly: Craig-Bampton on the tips' gap coordinates.

The 3-D model (:mod:`fem.model`) is reduced onto its two gap coordinates ``x1``, ``x3``
(:mod:`fem.contact`) and ``n_modes`` fixed-interface modes,

    q = [x1, x3, eta_1 .. eta_n],      Mr q'' + Cr q' + Kr q + B^T f(B q) = 0,

with B picking x1 and x3 and f the two-sided penalty stops of the tips, so the reduced
model is a :class:`reduced.models.gaps.GapSystem` and every solver of the discrete model (exact,
explicit, DOP853 ringdowns, HB backbones) runs on it unchanged. Damping is what the
discrete model has: dashpots ``c_points`` at its three points x1, x2 (mid-span), x3, plus an
optional mass-proportional part ``alpha`` Mr, plus modal damping on every mode of the reduced
model with its gaps open (``modal_damping``, issue 25):

    C = c_points P^T P + alpha Mr + Mr Phi diag(2 zeta_r omega_r) Phi^T Mr,

Phi the mass-normalised modes of (Kr, Mr), omega_r their frequencies, zeta_r the ratio given for
mode r (the last one given for every higher mode). The dashpots alone leave the modes with nodes
at x1, x2 and x3 almost undamped (the 2029 Hz antisymmetric bending of the beam-grounded beam at
zeta = 1e-7, a decay time of 13 min; 731 Hz at 4e-4): a forced response then never settles and
their Floquet multipliers sit at |mu| = 0.99987-0.999999. The default, :data:`MODAL_DAMPING` on
every mode, is the low end of the structural damping of a bolted steel beam, and the smallest
round ratio that makes every elastic mode decay faster than the dashpot-damped heave mode
(2.4 1/s: at 731 Hz zeta omega = 4.6 1/s), so a stepped sine settles as fast as on the discrete
model, while it changes the dashpots' 1.8-2.1 % on the two pseudo-rigid modes by 5-6 %.

**Friction** (``mu`` > 0): the tangential coordinates of the contact faces (:func:`fem.contact.tangential_rows`:
per stop, since the upper tip rubs on the beam's top face and the lower one on its bottom face; along the
beam, and across it with ``friction_directions = "axial+lateral"``) join x1, x3 as Craig-Bampton boundary
coordinates, q = [x1, x3, t_1 .. t_r, eta_1 .. eta_n], so that the constraint modes carry the static
response to a tangential force exactly (a sticking tip is a stiff tangential spring k_t there). Each is a
slider of the :class:`reduced.models.gaps.Friction` of the reduced system, engaged by its own stop, with
the normal force k_g (penetration) of that stop: 4 sliders (axial) or 8 (both directions), 7 or 19
friction states a tip. With ``mu`` = 0 there are no tangential coordinates: the reduction is the
frictionless one, bit for bit. A model reduced with them can be run without friction (``mu`` = 0 in
:meth:`ReducedModel.with_contact`): the same basis, the frictionless system, the fairest comparison.

The matrices, the DOF map (the interface rows and point rows on the full DOFs, the
constraint and fixed-interface modes for expansion) and provenance go to ``rom.npz``
(:meth:`ReducedModel.save`), so a ringdown never rebuilds the 3-D model: a built model is
also kept in a cache folder keyed by the specification and the source of the code that
builds it (``$BEARINGSHAFT_CACHE``, default ``~/.cache/bearingshaft``): ``rom-<key>.npz``
with its manifest ``rom-<key>.npz.json`` (hash of the inputs, sha256 of the file), checked
on every read; a corrupt entry is reported in one line, removed and rebuilt
(:mod:`reduced.cache`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from reduced.cache import atomic_write, load_entry, write_entry
from reduced.models.discrete import MINDLIN_RATIO
from reduced.models.gaps import Friction, GapSystem, two_sided_stops

ROM_LAYOUTS = ("beam-grounded", "assembly")
POINTS = ("x1", "x2", "x3")  # the discrete model's three points: left tip, mid-span, right tip
RIGID_TOL = 1e-6  # relative error allowed on the in-plane rigid mass and inertia (see cb_check)
FRICTION_DIRECTIONS = ("axial", "lateral", "axial+lateral")  # where the tips rub: along the beam, across, both
STOPS = ("x1+", "x1-", "x3+", "x3-")  # the reduced system's stops (two_sided_stops of x1, x3)
MODAL_DAMPING = 1e-3  # damping ratio added to every mode by default (module docstring: why this value)


@dataclass(frozen=True, slots=True)
class RomSpec:
    """How to build a reduced model (scene ``[model] kind = "rom"``), SI units.

    Parameters
    ----------
    layout : {'beam-grounded', 'assembly'}
        Tips fixed, or tips bolted to the tube (whole assembly on its bungees).
    n_modes : int
        Fixed-interface modes kept (the coupled ones when ``planar``), >= 0.
    cutoff_hz : float
        Hz, keep only modes at or below this, at most ``n_modes`` of them (0: no cut-off).
    planar : bool
        Keep only modes the tips' in-plane contact can excite (symmetric in y and coupled).
    k_g : float
        N/m, tip contact stiffness, > 0.
    gap : float
        m, tip clearance, >= 0.
    c_points : float
        N s/m, dashpot at each of x1, x2, x3 (the discrete model's c), >= 0.
    alpha : float
        1/s, mass-proportional damping alpha Mr, >= 0.
    modal_damping : tuple of float
        Damping ratio zeta_r added to each mode of the reduced model with its gaps open, lowest
        first; the last applies to every higher mode; each in [0, 1) (module docstring).
    element_size : float
        m, 3-D mesh size, > 0.
    element : {'hex8', 'hex20', 'hex27'}
        Solid element.
    rom_file : str
        Load this rom.npz (in a scene: a path from the scene file's folder) instead of building; k_g, gap and
        damping still apply. '' to build or use the cache.
    mu : float
        Coulomb coefficient at the tips, >= 0; 0: no friction (and no tangential coordinates).
    k_t : float or None
        N/m, tangential stiffness of each contact face's slider, > 0; None: ``MINDLIN_RATIO`` k_g.
    friction_directions : {'axial', 'lateral', 'axial+lateral'}
        Where the tips rub (with mu > 0): along the beam, across it, or both ('lateral' needs planar = false).

    Raises
    ------
    ValueError
        An unknown layout or element, a value that is not a finite number or outside its range,
        or a ``rom_file`` that does not exist.
    """

    layout: str = "beam-grounded"  # beam-grounded (tips fixed) | assembly (tips on the tube)
    n_modes: int = 5  # fixed-interface modes kept (the coupled ones when planar)
    cutoff_hz: float = 0.0  # Hz, keep the modes below this, at most n_modes of them (0: no cut-off)
    planar: bool = True  # keep only modes the tips' in-plane contact can excite
    k_g: float = 3.502e7  # N/m, tip contact stiffness
    gap: float = 2.54e-4  # m, tip clearance
    c_points: float = 4.0  # N s/m, dashpot at each of x1, x2, x3 (the discrete model's c)
    alpha: float = 0.0  # 1/s, mass-proportional damping alpha Mr
    modal_damping: tuple[float, ...] = (MODAL_DAMPING,)  # ratio added to each open-gap mode (last: all higher)
    element_size: float = 0.3  # m, 3-D mesh size (the mesh study's default)
    element: str = "hex20"  # hex8 | hex20 | hex27
    rom_file: str = ""  # load this rom.npz instead of building (in a scene: a path from the scene file's
    # folder); k_g, gap and damping still apply
    mu: float = 0.0  # Coulomb coefficient at the tips (0: no friction, no tangential coordinates)
    k_t: float | None = None  # N/m, tangential stiffness of each contact face; None: Mindlin's 2 (1 - nu) /
    # (2 - nu) k_g = 0.82 k_g (an elastic contact of like materials, nu = 0.3: steel on steel)
    friction_directions: str = "axial"  # axial (along the beam) | lateral (across it) | axial+lateral

    def __post_init__(self) -> None:
        if self.layout not in ROM_LAYOUTS:
            raise ValueError(f"layout must be one of {', '.join(ROM_LAYOUTS)}, got {self.layout!r}")
        if isinstance(self.n_modes, bool) or not isinstance(self.n_modes, int) or self.n_modes < 0:
            raise ValueError(f"n_modes must be an integer >= 0, got {self.n_modes!r}")
        for name in ("cutoff_hz", "k_g", "gap", "c_points", "alpha", "element_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v!r}")
            if v < 0:
                raise ValueError(f"{name} must be >= 0, got {v!r}")
        if not self.k_g > 0:
            raise ValueError(f"k_g must be > 0, got {self.k_g!r}")
        if not self.element_size > 0:
            raise ValueError(f"element_size must be > 0, got {self.element_size!r}")
        if self.element not in ("hex8", "hex20", "hex27"):
            raise ValueError(f"element must be hex8, hex20 or hex27, got {self.element!r}")
        md = self.modal_damping
        if not isinstance(md, tuple) or not md or not all(
                isinstance(z, (int, float)) and not isinstance(z, bool) and math.isfinite(z) and 0.0 <= z < 1.0
                for z in md):
            raise ValueError(f"modal_damping must be a non-empty tuple of ratios in [0, 1), got {md!r}")
        if self.rom_file and not Path(self.rom_file).is_file():
            raise ValueError(f"rom_file: no such file {self.rom_file!r}")
        if isinstance(self.mu, bool) or not isinstance(self.mu, (int, float)) or not math.isfinite(self.mu):
            raise ValueError(f"mu must be a finite number, got {self.mu!r}")
        if self.mu < 0:
            raise ValueError(f"mu must be >= 0, got {self.mu!r}")
        if self.k_t is not None and (isinstance(self.k_t, bool) or not isinstance(self.k_t, (int, float))
                                     or not math.isfinite(self.k_t) or not self.k_t > 0):
            raise ValueError(f"k_t must be a finite number > 0 (or not given), got {self.k_t!r}")
        if self.friction_directions not in FRICTION_DIRECTIONS:
            raise ValueError(f"friction_directions must be one of {', '.join(FRICTION_DIRECTIONS)}, "
                             f"got {self.friction_directions!r}")
        if self.mu > 0 and self.planar and "lateral" in self.friction_directions:
            raise ValueError("friction_directions with 'lateral' drives the beam out of its plane: it needs "
                             "planar = false")

    @property
    def tangential_directions(self) -> tuple[str, ...]:
        """The tangential directions of the reduction's interface: () without friction (mu = 0)."""
        return tuple(self.friction_directions.split("+")) if self.mu > 0 else ()

    @property
    def tangential_stiffness(self) -> float:
        """N/m, k_t, or ``MINDLIN_RATIO`` k_g when not given (Mindlin: the tangential stiffness of an
        elastic contact of like materials is 2 (1 - nu) / (2 - nu) times its normal one)."""
        return MINDLIN_RATIO * self.k_g if self.k_t is None else float(self.k_t)

    # -- the interface a scene uses --------------------------------------------------------
    @property
    def point_names(self) -> tuple[str, ...]:
        return POINTS

    def reduced(self, progress: bool = False) -> ReducedModel:
        """The reduced model: from ``rom_file``, the cache, or built (and cached)."""
        if self.rom_file:  # the user's file: a bad one is refused, never silently rebuilt
            path = Path(self.rom_file)
            if not path.exists():
                raise ValueError(f"rom_file: no such file {self.rom_file!r}")
            try:
                rom = ReducedModel.load(path)
            except ValueError as exc:
                raise ValueError(f"rom_file: {exc}") from None
            return rom.with_contact(self)
        return cached_rom(self, progress)

    def system(self) -> GapSystem:
        return self.reduced().system()

    def fe_model(self):
        """The 3-D model this reduction starts from (:class:`fem.model.AssemblyModel`)."""
        from fem.model import AssemblyModel

        return AssemblyModel(layout=self.layout, gap=self.gap, k_g=self.k_g,
                             element_size=self.element_size, element=self.element)


@dataclass(frozen=True, eq=False)
class ReducedModel:
    """Reduced matrices on q = [x1, x3, (t_1..r,) eta_1..n] with the map back to the 3-D model.

    Attributes
    ----------
    M, K, C : (n, n) ndarray of float
        Reduced mass, stiffness and damping on q = [x1, x3, t_1..r, eta_1..n] (kg, N/m, N s/m on the
        gap and tangential coordinates).
    P : (3, n) ndarray of float
        Rows of the points x1, x2, x3 in q.
    omega_fixed : (n - nb,) ndarray of float
        rad/s, fixed-interface frequencies.
    k_g : float
        N/m, tip contact stiffness.
    gap : float
        m, tip clearance.
    dof_names : tuple of str
        ``x1``, ``x3``, the tangential coordinates (``x1+:axial`` ...), ``eta1`` ...
    checks : list of dict
        :func:`reduced.models.craig_bampton.cb_check` rows.
    info : dict
        Provenance: spec, sizes, timings, source hash.
    Psi : (N, nb) ndarray of float or None
        Constraint modes, for expansion to the 3-D mesh.
    Phi : (N, n - nb) ndarray of float or None
        Fixed-interface modes.
    dof_map : dict of str to ndarray
        Interface and point rows on the full DOFs: ``{interface,points}_{row,dof,weight}`` (row r
        of T is sum_k weight_k u[dof_k] over row == r).
    output_names : tuple of str
        The rig's measured motions (:mod:`fem.rig`): sensor axes, ``seat:<cell>``.
    output_rows : (len(output_names), n) ndarray of float or None
        Each output is row @ q (m).
    mesh : dict
        ``points``, ``hexes``, ``cell_part``, ``beam_part``, ``element``: a point load anywhere on
        the beam without meshing again (:meth:`point_load`).
    tangential : tuple of str
        The tangential boundary coordinates, q[2 : 2 + r] (``<stop>:<direction>``; empty without friction).
    mu : float
        Coulomb coefficient at the tips (0: the system has no friction).
    k_t : float
        N/m, tangential stiffness of each slider.
    """

    M: np.ndarray  # (n, n) kg
    K: np.ndarray  # (n, n) N/m
    C: np.ndarray  # (n, n) N s/m
    P: np.ndarray  # (3, n) rows of the points x1, x2, x3 in q
    omega_fixed: np.ndarray  # (n - 2,) rad/s, fixed-interface frequencies
    k_g: float  # N/m
    gap: float  # m
    dof_names: tuple[str, ...]
    checks: list[dict] = field(default_factory=list)  # cb_check rows
    info: dict = field(default_factory=dict)  # provenance: spec, sizes, timings, commit
    Psi: np.ndarray | None = None  # (N, 2) constraint modes (for expansion to the 3-D mesh)
    Phi: np.ndarray | None = None  # (N, n - 2) fixed-interface modes
    dof_map: dict = field(default_factory=dict)  # interface and point rows on the full DOFs:
    # {interface,points}_{row,dof,weight} arrays (row r of T is sum_k weight_k u[dof_k] over row == r)
    output_names: tuple[str, ...] = ()  # the rig's measured motions (fem.rig): sensor axes, tube seats
    output_rows: np.ndarray | None = None  # (len(output_names), n): each output is row @ q
    mesh: dict = field(default_factory=dict)  # points, hexes, cell_part, beam_part, element: a point
    # load anywhere on the beam without meshing again (point_load)
    tangential: tuple[str, ...] = ()  # the tangential boundary coordinates q[2 : 2 + r] (<stop>:<direction>)
    mu: float = 0.0  # Coulomb coefficient at the tips (0: no friction)
    k_t: float = 0.0  # N/m, tangential stiffness of each slider

    @property
    def n(self) -> int:
        return self.M.shape[0]

    @property
    def nb(self) -> int:
        """Boundary coordinates: x1, x3 and the tangential ones."""
        return 2 + len(self.tangential)

    @property
    def n_modes(self) -> int:
        return self.n - self.nb

    @property
    def friction_directions(self) -> tuple[str, ...]:
        """The directions of the tangential coordinates, in order ((): none)."""
        return tuple(dict.fromkeys(name.split(":")[1] for name in self.tangential))

    def friction(self) -> Friction | None:
        """The sliders at the tips (None when mu = 0): one a tangential coordinate, engaged by its stop."""
        if self.mu <= 0.0 or not self.tangential:
            return None
        r = len(self.tangential)
        Bt = np.zeros((r, self.n))
        Bt[np.arange(r), 2 + np.arange(r)] = 1.0
        stop = np.array([STOPS.index(name.split(":")[0]) for name in self.tangential])
        return Friction(Bt=Bt, tip=stop // 2, k_t=self.k_t, mu=self.mu, names=self.tangential, stop=stop)

    def system(self) -> GapSystem:
        """The reduced model with its two tip clearances, |x1| <= g and |x3| <= g, and friction at them
        when mu > 0 (:meth:`friction`)."""
        rows = np.zeros((2, self.n))
        rows[0, 0] = rows[1, 1] = 1.0
        stops = two_sided_stops(rows, self.k_g, self.gap, ("x1", "x3"))
        return GapSystem(M=self.M, C=self.C, K=self.K, dof_names=self.dof_names, **stops, friction=self.friction())

    @property
    def point_rows(self) -> np.ndarray:
        return self.P

    def with_contact(self, spec: RomSpec) -> ReducedModel:
        """The same reduction with the contact, friction and damping of ``spec`` (no rebuild).

        Raises ValueError when ``spec`` asks for friction in directions this reduction has no tangential
        coordinates for (it was reduced without them: build it again with mu > 0).
        """
        if spec.mu > 0 and set(spec.tangential_directions) != set(self.friction_directions):
            have = "+".join(self.friction_directions) or "none"
            raise ValueError(f"friction_directions = {spec.friction_directions!r} needs tangential coordinates this "
                             f"reduced model was built without (it has: {have}); reduce it again with that mu > 0")
        info = {**self.info, "spec": {**self.info.get("spec", {}), "k_g": spec.k_g, "gap": spec.gap,
                                      "c_points": spec.c_points, "alpha": spec.alpha,
                                      "modal_damping": list(spec.modal_damping), "mu": spec.mu, "k_t": spec.k_t}}
        return replace(self, C=damping_matrix(self.M, self.K, self.P, spec), k_g=spec.k_g, gap=spec.gap, info=info,
                       mu=float(spec.mu), k_t=spec.tangential_stiffness)

    def output(self, name: str) -> np.ndarray:
        """(n,) the reduced row of a rig output (see ``output_names``): its value is row @ q."""
        if name not in self.output_names:
            raise KeyError(f"the reduced model has no output {name!r} (it has {len(self.output_names)})")
        return self.output_rows[self.output_names.index(name)]

    def point_load(self, location, direction) -> np.ndarray:
        """(n,) reduced load of a unit force along ``direction`` at ``location`` (m) on the beam,
        V^T b with b the consistent nodal load (:func:`fem.rig.point_load_vector`)."""
        from fem.rig import point_load_vector

        if not self.mesh or self.Psi is None:
            raise ValueError("this reduced model keeps no mesh: rebuild it to apply a point load")
        m = self.mesh
        b = point_load_vector(m["points"], m["hexes"], str(m["element"]), m["cell_part"], int(m["beam_part"]),
                              location, direction, self.Psi.shape[0])
        return np.concatenate([np.asarray(b @ self.Psi).ravel(), np.asarray(b @ self.Phi).ravel()])

    def _write_npz(self, f) -> None:
        """The ``rom.npz`` content (matrices, DOF map, checks and provenance as JSON) into file f."""
        arrays = {"M": self.M, "K": self.K, "C": self.C, "P": self.P, "omega_fixed": self.omega_fixed,
                  "k_g": self.k_g, "gap": self.gap, "dof_names": np.array(self.dof_names),
                  "checks_json": json.dumps(self.checks), "info_json": json.dumps(self.info)}
        if self.Psi is not None:
            arrays["Psi"] = self.Psi
            arrays["Phi"] = self.Phi
        for key, val in self.dof_map.items():
            arrays[f"map_{key}"] = np.asarray(val)
        if self.output_names:
            arrays["output_names"] = np.array(self.output_names)
            arrays["output_rows"] = self.output_rows
        for key, val in self.mesh.items():
            arrays[f"mesh_{key}"] = np.asarray(val)
        if self.tangential:
            arrays.update(tangential=np.array(self.tangential), mu=self.mu, k_t=self.k_t)
        np.savez_compressed(f, **arrays)

    def save(self, path: str | Path) -> None:
        """``rom.npz``: matrices, DOF map, checks and provenance (JSON), written atomically."""
        atomic_write(path, self._write_npz)

    @classmethod
    def load(cls, path) -> ReducedModel:
        """The model saved by :meth:`save`, from a path or a binary file object.

        Raises ValueError (one line) whatever is wrong with the file: missing, truncated,
        not a zip, a bad CRC or deflate stream, a missing array, bad JSON.
        """
        try:
            with np.load(path, allow_pickle=False) as z:
                info = json.loads(str(z["info_json"]))
                return cls(M=z["M"], K=z["K"], C=z["C"], P=z["P"], omega_fixed=z["omega_fixed"],
                           k_g=float(z["k_g"]), gap=float(z["gap"]), dof_names=tuple(str(s) for s in z["dof_names"]),
                           checks=json.loads(str(z["checks_json"])), info=info,
                           Psi=z["Psi"] if "Psi" in z else None, Phi=z["Phi"] if "Phi" in z else None,
                           dof_map={k[4:]: z[k] for k in z.files if k.startswith("map_")},
                           output_names=tuple(str(s) for s in z["output_names"]) if "output_names" in z else (),
                           output_rows=z["output_rows"] if "output_rows" in z else None,
                           mesh={k[5:]: z[k] for k in z.files if k.startswith("mesh_")},
                           tangential=tuple(str(s) for s in z["tangential"]) if "tangential" in z else (),
                           mu=float(z["mu"]) if "mu" in z else 0.0, k_t=float(z["k_t"]) if "k_t" in z else 0.0)
        except Exception as exc:  # BadZipFile, zlib.error, EOFError, KeyError, ...: all mean a bad file
            name = getattr(path, "name", path)
            reason = " ".join(f"{type(exc).__name__}: {exc}".split())
            raise ValueError(f"{name}: not a reduced model file ({reason})") from None


def modal_ratios(modal_damping, count: int) -> np.ndarray:
    """(count,) the ratio of each mode, lowest first: the ratios given, the last repeated.

    Parameters
    ----------
    modal_damping : sequence of float
        The ratios given (``RomSpec.modal_damping``), at least one.
    count : int
        Modes.

    Returns
    -------
    ndarray
        (count,) float.

    Examples
    --------
    >>> modal_ratios((0.02, 0.001), 4).tolist(), modal_ratios((0.001,), 2).tolist()
    ([0.02, 0.001, 0.001, 0.001], [0.001, 0.001])
    """
    z = np.asarray(modal_damping, float)
    return np.concatenate([z[:count], np.full(max(count - z.size, 0), z[-1])])


def damping_matrix(M: np.ndarray, K: np.ndarray, P: np.ndarray, spec: RomSpec) -> np.ndarray:
    """N s/m, C = c_points P^T P + alpha M + M Phi diag(2 zeta_r omega_r) Phi^T M (module docstring).

    Parameters
    ----------
    M, K : (n, n) the reduced mass and stiffness (gaps open)
    P : (3, n) the rows of the points x1, x2, x3
    spec : the dashpots ``c_points``, ``alpha`` and ``modal_damping``

    Returns
    -------
    ndarray
        (n, n) symmetric. Mode r (mass-normalised, Phi^T M Phi = I) gets 2 zeta_r omega_r on top of
        what the dashpots give it; a rigid-body mode (omega = 0) gets none.
    """
    from scipy.linalg import eigh

    C = spec.c_points * P.T @ P + spec.alpha * M
    z = modal_ratios(spec.modal_damping, M.shape[0])
    if np.any(z > 0.0):
        w2, Phi = eigh(K, M)
        MPhi = M @ Phi
        C = C + (MPhi * (2.0 * z * np.sqrt(np.maximum(w2, 0.0)))) @ MPhi.T
    return 0.5 * (C + C.T)


def _sparse_rows(rows: np.ndarray) -> dict[str, np.ndarray]:
    """The nonzeros of rows as (row, dof, weight) arrays: the DOF map kept in rom.npz."""
    r, d = np.nonzero(rows)
    return {"row": r, "dof": d, "weight": rows[r, d]}


def build_rom(spec: RomSpec, fe=None, progress: bool = False) -> tuple[ReducedModel, object]:
    """Mesh and assemble the 3-D model (unless ``fe`` is given), reduce it; (rom, fe).

    Parameters
    ----------
    spec : RomSpec
        What to build (``rom_file`` is not read here).
    fe : FESystem, optional
        The 3-D model already assembled (default: built from ``spec.fe_model()``).
    progress : bool
        Print a line before meshing.

    Returns
    -------
    rom : ReducedModel
        With C = :func:`damping_matrix`, the Craig-Bampton checks, DOF map, rig outputs and
        mesh; with mu > 0, the tangential coordinates of the contact faces in its boundary and its friction.
    fe : FESystem
        The 3-D model it was reduced from.

    Raises
    ------
    ValueError
        As :func:`reduced.models.craig_bampton.craig_bampton` (too few coupled modes) or
        :func:`fem.contact.mirror_map` (a mesh not symmetric in y, when planar).
    """
    from fem._pardiso import fixed_threads

    with fixed_threads():  # OpenBLAS on a fixed thread count: the same matrices whatever the machine's cores
        return _build_rom(spec, fe, progress)


def _build_rom(spec: RomSpec, fe, progress: bool) -> tuple[ReducedModel, object]:
    from fem.contact import contact_pairs, contact_rows, mirror_map, point_rows, tangential_rows
    from fem.model import build_system
    from reduced.models.craig_bampton import cb_check, craig_bampton

    t0 = time.perf_counter()
    if fe is None:
        if progress:
            print(f"building the 3-D model ({spec.layout}, element size {spec.element_size} m)", flush=True)
        fe = build_system(spec.fe_model())
    t_fe = time.perf_counter() - t0
    pairs = contact_pairs(fe, gap=spec.gap, k_g=spec.k_g)
    tangential = tangential_rows(fe, spec.tangential_directions) if spec.tangential_directions else []
    T = np.vstack([contact_rows(pairs), *(t.row for t in tangential)])
    boundary = ("x1", "x3", *(t.name for t in tangential))
    symmetric = None
    if spec.planar:  # the tips act in the plane y = 0: only modes symmetric in y can couple
        perm, sign = mirror_map(fe)

        def symmetric(Phi):
            return np.einsum("ij,ij->j", Phi, fe.M @ (sign[:, None] * Phi[perm])) > 0.5

    cb = craig_bampton(fe.K, fe.M, T, n_modes=spec.n_modes, cutoff_hz=spec.cutoff_hz or None,
                       boundary_names=boundary, coupled_only=spec.planar, mode_filter=symmetric)
    prow = point_rows(fe)
    rows = np.vstack([prow[p] for p in POINTS])
    P = cb.reduce_rows(rows)
    # in-plane rigid motions of the whole model: heave (uz) and pitch (theta_y) about the origin
    R = fe.rigid_modes(np.arange(fe.n_dofs), (0.0, 0.0, 0.0))[:, [2, 4]]
    checks = cb_check(cb, rigid=R, M_rigid=fe.M, rigid_tol=RIGID_TOL)
    C = damping_matrix(cb.M, cb.K, P, spec)
    info = {
        "spec": asdict(spec),
        "n_full_dofs": int(fe.n_dofs),
        "n_boundary": len(boundary),
        "n_modes": int(cb.nq),
        "contact_centres_m": [list(p.centre) for p in pairs],
        "timing_s": {"fe": t_fe, "craig_bampton": cb.stats["wall_s"], "total": time.perf_counter() - t0},
        "cb_stats": cb.stats,
        "source_hash": source_hash(),
    }
    dof_map = {f"interface_{k}": v for k, v in _sparse_rows(T).items()} | {
        f"points_{k}": v for k, v in _sparse_rows(rows).items()}
    names = (*boundary, *(f"eta{i + 1}" for i in range(cb.nq)))
    out_names, out_rows = _rig_outputs(fe, cb)
    mesh = {"points": fe.mesh.points, "hexes": fe.mesh.hexes, "cell_part": fe.mesh.cell_part,
            "beam_part": fe.mesh.part_names.index("beam"), "element": fe.solid.element}
    rom = ReducedModel(cb.M, cb.K, C, P, cb.omega_fixed, spec.k_g, spec.gap, names, checks,
                       info, cb.Psi, cb.Phi, dof_map, out_names, out_rows, mesh, boundary[2:], float(spec.mu),
                       spec.tangential_stiffness if tangential else 0.0)
    return rom, fe


def _rig_outputs(fe, cb) -> tuple[tuple[str, ...], np.ndarray]:
    """The rig's measured motions as reduced rows: every accelerometer axis (``beam_s1:x`` ..) and,
    with the tube, each tip load cell's seat (``seat:tip_left_top`` ..): see :mod:`fem.rig`."""
    from fem.rig import seat_rows, sensor_rows

    parts = ("beam", "tube") if fe.model.layout == "assembly" else ("beam",)
    dofs = sensor_rows(fe, parts)
    names = list(dofs)
    rows = [np.concatenate([cb.Psi[d], cb.Phi[d]]) for d in dofs.values()]
    if fe.model.layout == "assembly":
        for cell, r in seat_rows(fe).items():
            names.append(f"seat:{cell}")
            rows.append(cb.reduce_rows(r)[0])
    return tuple(names), np.vstack(rows)


def source_hash() -> str:
    """sha256 of the code that builds a reduced model (geometry, fem, this reduction)."""
    here = Path(__file__).resolve().parent
    root = here.parent.parent
    h = hashlib.sha256()
    files = sorted([*root.glob("geometry/*.py"), *root.glob("fem/*.py"), here / "craig_bampton.py", here / "rom.py"])
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """Folder of the reduced-model cache: ``$BEARINGSHAFT_CACHE``, default ``~/.cache/bearingshaft``."""
    return Path(os.environ.get("BEARINGSHAFT_CACHE", Path.home() / ".cache" / "bearingshaft"))


def _cache_inputs(spec: RomSpec) -> dict:
    """What a cached reduction depends on: the spec without contact, friction, damping and rom_file, and the
    tangential coordinates of its interface when it has them (friction on)."""
    inputs = {f.name: getattr(spec, f.name) for f in fields(spec)
              if f.name not in ("k_g", "gap", "c_points", "alpha", "modal_damping", "rom_file", "mu", "k_t",
                                "friction_directions")}
    if spec.tangential_directions:
        inputs["tangential"] = list(spec.tangential_directions)
    return inputs


def _inputs_hash(spec: RomSpec) -> str:
    """sha256 (hex) of the cache inputs and the source hash: recorded in the entry's manifest."""
    h = hashlib.sha256(json.dumps(_cache_inputs(spec), sort_keys=True).encode() + source_hash().encode())
    return h.hexdigest()


def _cache_key(spec: RomSpec, inputs: str | None = None) -> str:
    """The cache file's key: the first 20 hex digits of :func:`_inputs_hash` (``inputs`` if given)."""
    return (inputs or _inputs_hash(spec))[:20]


def _cache_path(spec: RomSpec, inputs: str | None = None) -> Path:
    """``<cache_dir>/rom-<key>.npz`` (its manifest: the same name + ``.json``)."""
    return cache_dir() / f"rom-{_cache_key(spec, inputs)}.npz"


def cache_key(spec: RomSpec) -> str:
    """The key of the cache entry that holds the reduction of ``spec``.

    Parameters
    ----------
    spec : RomSpec
        The reduced model's specification.

    Returns
    -------
    str
        20 hex digits; two specs that differ only in contact or damping share one entry.
    """
    return _cache_key(spec)


def store_in_cache(rom: ReducedModel, spec: RomSpec) -> None:
    """Keep ``rom`` where :func:`cached_rom` looks for ``spec``, with its manifest (a read-only
    cache is skipped: the model is then rebuilt when next needed).

    Parameters
    ----------
    rom : ReducedModel
        The model built for ``spec``.
    spec : RomSpec
        Its specification (its reduction inputs key the entry).

    Returns
    -------
    None
    """
    inputs = _inputs_hash(spec)
    try:
        write_entry(_cache_path(spec, inputs), rom._write_npz, inputs,
                    info={"kind": "reduced model", "spec": _cache_inputs(spec), "source_hash": source_hash()})
    except OSError:
        pass


def from_cache(spec: RomSpec) -> ReducedModel | None:
    """The reduced model of ``spec`` if the cache holds it (with the contact, friction and damping of ``spec``),
    else None: an entry is made by the same code (:func:`source_hash`) from the same inputs, so it holds the
    bits a rebuild would give. A bad entry is reported in one line and removed (:mod:`reduced.cache`).

    Parameters
    ----------
    spec : RomSpec
        What is wanted.

    Returns
    -------
    ReducedModel or None
        The cached reduction, or None when there is none.
    """
    inputs = _inputs_hash(spec)
    rom = load_entry(_cache_path(spec, inputs), inputs, ReducedModel.load)
    return None if rom is None else rom.with_contact(spec)


def build_fe(spec: RomSpec):
    """The 3-D model :func:`build_rom` reduces (meshed and assembled, OpenBLAS on a fixed thread count).

    Parameters
    ----------
    spec : RomSpec
        Its ``fe_model()`` says what to mesh.

    Returns
    -------
    fem.model.FESystem
        The assembled model.
    """
    from fem._pardiso import fixed_threads
    from fem.model import build_system

    with fixed_threads():
        return build_system(spec.fe_model())


def reduction(spec: RomSpec, progress: bool = False) -> tuple[ReducedModel, object]:
    """(rom, fe): the reduced model of ``spec`` from the cache when it holds it, with the 3-D model it reduces
    built again (meshing and assembly only), else :func:`build_rom` (not stored: :func:`store_in_cache`).

    Parameters
    ----------
    spec : RomSpec
        What is wanted.
    progress : bool
        Print a line before meshing, when building.

    Returns
    -------
    rom : ReducedModel
        The same bits whichever way it came (:func:`from_cache`).
    fe : FESystem
        The 3-D model.
    """
    rom = from_cache(spec)
    if rom is None:
        return build_rom(spec, progress=progress)
    return rom, build_fe(spec)


def cached_rom(spec: RomSpec, progress: bool = False) -> ReducedModel:
    """The reduced model of ``spec`` from the cache, built and stored there if absent.

    An entry whose manifest is missing, names other inputs or another checksum, or whose
    file cannot be read, is reported in one line, removed and rebuilt (:mod:`reduced.cache`).
    The contact (k_g, gap), friction (mu, k_t) and damping do not enter the reduction (the
    interface is the gap coordinate itself, and the tangential ones with friction), so they are
    applied after loading.

    Parameters
    ----------
    spec : RomSpec
        What to build.
    progress : bool
        Print a line when the 3-D model is built.

    Returns
    -------
    ReducedModel
        With the contact and damping of ``spec``.
    """
    rom = from_cache(spec)
    if rom is not None:
        return rom
    rom, _ = build_rom(spec, progress=progress)
    store_in_cache(rom, spec)
    return rom


__all__ = ["RomSpec", "ReducedModel", "build_fe", "build_rom", "cache_key", "cached_rom", "damping_matrix",
           "from_cache", "modal_ratios", "reduction",
           "store_in_cache", "MODAL_DAMPING", "POINTS", "ROM_LAYOUTS", "FRICTION_DIRECTIONS", "STOPS"]
