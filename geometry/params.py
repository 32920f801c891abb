"""Parameters of the test apparatus geometry (Section 4, Fig. 5-8), validated before gmsh runs.

Coordinates: x along the impact beam, y across it (lateral), z up (bounce); origin at the
beam's centre. The beam is a steel bar ``beam_length x beam_width x beam_height``; the
suspension springs stand on the beam's top and bottom faces at x = +-L, y = 0 and reach
the inner faces of the box tube's top and bottom walls, so the tube's inner height is
``beam_height + 2 spring_length``. The impact tips are coaxial with the springs (the bolt
and tip pass through the coil), so a spring seat and a contact patch share the same place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

PARTS = ("beam", "tube")


@dataclass(frozen=True, slots=True, kw_only=True)
class AssemblyGeometry:
    """Dimensions and mesh controls of the beam and box tube (SI units).

    The dimensions have no defaults on purpose: the one source of truth is the model that
    asks for the mesh, :meth:`fem.model.AssemblyModel.geometry`, which derives the beam's
    section from its mass and bending stiffness (kappa) and takes its length, seat and spring
    sizes from the calibration against Table 2. A second set of defaults here would describe a
    beam that no stage analyses. Only the meshing controls the model does not set have defaults.

    Parameters
    ----------
    L : float
        m, half-distance between the spring/tip axes (Table 1); the seats are at x = +-L.
    beam_length, beam_width, beam_height : float
        m, the beam's extent along x, y and z.
    seat_diameter : float
        m, side of the square spring seat / contact patch (the coil diameter).
    spring_length : float
        m, installed length of a suspension spring (beam face to tube inner wall).
    tube_clearance_y : float
        m, lateral gap between a beam side and the tube's inner wall.
    tube_overhang : float
        m, tube length beyond each beam end.
    tube_wall : float
        m, wall thickness of the box tube.
    element_size : float
        m, target element edge along the long directions.
    wall_layers : int
        Elements through the tube wall (the paper: at least three).
    section_layers : int
        Minimum elements across each beam sub-block in y and z.
    parts : tuple of str
        Which solids to build, a non-empty subset of ``PARTS`` ('beam', 'tube'); the tube needs
        the beam.

    Raises
    ------
    ValueError
        A dimension that is not a finite number > 0, unknown or inconsistent ``parts``, a layer
        count below 1, seats off the beam or overlapping (L <= seat_diameter / 2), a seat wider
        than the beam or the tube, or a tube wall too thick for the section.
    """

    L: float  # m, half-distance between the spring/tip axes (Table 1)
    beam_length: float  # m, overall length of the impact beam
    beam_width: float  # m, along y
    beam_height: float  # m, along z (the bounce direction)
    seat_diameter: float  # m, side of the square seat/contact patch (coil diameter)
    spring_length: float  # m, installed length of a suspension spring
    tube_clearance_y: float  # m, lateral gap between beam side and tube inner wall
    tube_overhang: float  # m, tube length beyond each beam end
    tube_wall: float  # m, wall thickness of the box tube
    element_size: float  # m, target element edge along the long directions
    wall_layers: int  # elements through the tube wall (the paper: at least three)
    section_layers: int = 2  # minimum elements across each beam sub-block in y and z
    parts: tuple[str, ...] = PARTS  # which solids to build

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "parts":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{f.name} must be a finite number, got {v!r}")
            if not v > 0:
                why = {"tube_clearance_y": " (the tube must be larger than the beam)",
                       "tube_wall": " (a box tube needs a wall)"}.get(f.name, "")
                raise ValueError(f"{f.name} must be > 0, got {v!r}{why}")
        unknown = [p for p in self.parts if p not in PARTS]
        if unknown or not self.parts:
            raise ValueError(f"parts must be a non-empty subset of {PARTS}, got {self.parts!r}")
        if "tube" in self.parts and "beam" not in self.parts:
            raise ValueError("the tube is only built around the beam: parts must include 'beam'")
        if self.wall_layers < 1 or self.section_layers < 1:
            raise ValueError("wall_layers and section_layers must be >= 1")
        half = self.beam_length / 2
        if not self.L + self.seat_diameter / 2 < half:
            raise ValueError(
                f"the spring seats at x = +-(L + seat_diameter/2) = "
                f"+-{self.L + self.seat_diameter / 2:.4g} m "
                f"must lie on the beam (half-length {half:.4g} m)"
            )
        if not self.seat_diameter < self.beam_width:
            raise ValueError(
                f"seat_diameter {self.seat_diameter:.4g} m must be smaller than "
                f"beam_width {self.beam_width:.4g} m"
            )
        if not self.L > self.seat_diameter / 2:
            raise ValueError("the two seats overlap: L must exceed seat_diameter / 2")
        if not self.seat_diameter < self.tube_inner_width:
            raise ValueError("seat_diameter must be smaller than the tube's inner width")
        if not self.tube_wall * 2 < min(self.tube_outer_width, self.tube_outer_height) / 2:
            raise ValueError(f"tube_wall {self.tube_wall:.4g} m is too thick for the tube section")

    # -- derived dimensions ------------------------------------------------------------
    @property
    def tube_inner_width(self) -> float:
        """m, y extent inside the tube: beam width plus two lateral clearances."""
        return self.beam_width + 2 * self.tube_clearance_y

    @property
    def tube_inner_height(self) -> float:
        """m, z extent inside the tube: beam height plus two spring lengths."""
        return self.beam_height + 2 * self.spring_length

    @property
    def tube_outer_width(self) -> float:
        return self.tube_inner_width + 2 * self.tube_wall

    @property
    def tube_outer_height(self) -> float:
        return self.tube_inner_height + 2 * self.tube_wall

    @property
    def tube_length(self) -> float:
        return self.beam_length + 2 * self.tube_overhang

    @property
    def beam_volume(self) -> float:
        """m^3, b h l."""
        return self.beam_width * self.beam_height * self.beam_length

    @property
    def tube_volume(self) -> float:
        """m^3, (W H - w h) l_t."""
        return (
            self.tube_outer_width * self.tube_outer_height - self.tube_inner_width * self.tube_inner_height
        ) * self.tube_length

    # -- named points --------------------------------------------------------------------
    def seat_centres(self, part: str) -> dict[str, tuple[float, float, float]]:
        """Centres of the four spring seats on ``part`` ('beam' faces or 'tube' inner walls)."""
        z = self.beam_height / 2 if part == "beam" else self.beam_height / 2 + self.spring_length
        return {
            f"{side}_{level}": (sx * self.L, 0.0, sz * z)
            for side, sx in (("left", -1.0), ("right", 1.0))
            for level, sz in (("top", 1.0), ("bottom", -1.0))
        }

    def beam_sensors(self) -> dict[str, tuple[float, float, float]]:
        """Six triaxial accelerometers on the beam's top edges (Fig. 7): ends and middle, both sides."""
        h, b, l2 = self.beam_height / 2, self.beam_width / 2, self.beam_length / 2
        pts = {}
        for i, x in enumerate((-l2, 0.0, l2)):
            pts[f"beam_s{2 * i + 1}"] = (x, b, h)
            pts[f"beam_s{2 * i + 2}"] = (x, -b, h)
        return pts

    def tube_sensors(self) -> dict[str, tuple[float, float, float]]:
        """Four triaxial sensors on the tube's outer corners around its centreline (Fig. 8), at x = +-L."""
        w, h, L = self.tube_outer_width / 2, self.tube_outer_height / 2, self.L
        return {"tube_s1": (-L, w, h), "tube_s2": (L, -w, h), "tube_s3": (-L, -w, -h), "tube_s4": (L, w, -h)}
