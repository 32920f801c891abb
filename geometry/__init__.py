"""The test apparatus as a gmsh model: the impact beam and the box tube, meshed with hexahedra.

The first stage of the pipeline (``geometry`` -> ``fem`` -> ``reduced``); it imports
nothing from the others.

- :mod:`geometry.params`: :class:`~geometry.params.AssemblyGeometry`, the dimensions and
  mesh controls of the beam and tube (SI units), validated before gmsh runs;
- :mod:`geometry.build`: the OCC model cut into axis-aligned blocks and meshed transfinite
  (hexahedra only, ``wall_layers`` through the tube wall), every seat, sensor and bungee
  point under a physical name; returns a gmsh-free :class:`~geometry.build.MeshData`.

Entry points: :func:`geometry.build.build_mesh` (``AssemblyGeometry`` -> ``MeshData``) and
:func:`geometry.build.gmsh_session`, the context manager that initialises and always
finalises gmsh. The dimensions themselves come from :meth:`fem.model.AssemblyModel.geometry`,
which derives them from the paper's parameters; a scene never builds a geometry directly.
Importing :mod:`geometry` imports neither gmsh nor NumPy.
"""
