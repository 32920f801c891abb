"""The 3-D finite element model of the test apparatus: matrices, modes, correlation, contact.

Takes the meshes of :mod:`geometry` and hands sparse K, M with their DOF maps to
:mod:`reduced` (``geometry`` -> ``fem`` -> ``reduced``; nothing here imports ``reduced``).

- :mod:`fem.model`: :class:`~fem.model.AssemblyModel`, every parameter of the model (the
  paper's and the open ones), and :func:`~fem.model.build_system` -> :class:`~fem.model.FESystem`
  (K, M, DOF maps, named node sets) in the layouts ``assembly``, ``beam-grounded``, ``beam-free``;
- :mod:`fem.solid`: 3-D elasticity of the meshed solids assembled with scikit-fem (hex8,
  hex20, hex27), element matrices computed once per distinct element shape;
- :mod:`fem.material`: isotropic materials and their weak forms (``stiffness_form``,
  ``mass_form``, ``lame_parameters``);
- :mod:`fem.springs`: the coil springs as Timoshenko columns, rigid maps and distributing
  (RBE3) couplings to their seats;
- :mod:`fem.modal`: K phi = omega^2 M phi by shift-invert Lanczos (PARDISO or SuperLU),
  safe with rigid-body modes;
- :mod:`fem.labels`: the six pseudo-rigid modes labelled automatically (bounce, pitch, ...),
  and the free beam's modes sorted into families;
- :mod:`fem.analysis`: one call from an ``AssemblyModel`` to labelled modes,
  :func:`~fem.analysis.analyse` -> :class:`~fem.analysis.ModalAnalysis` (Table 2 rows);
- :mod:`fem.mac`: the modal assurance criterion, mode shapes read and written as universal
  files (dataset 55) or CSV;
- :mod:`fem.uff`: test channels (time histories at a node and direction, with quantity and SI
  unit) written and read as universal file dataset 58, bit for bit in binary records;
- :mod:`fem.calibrate`: model updating of the open parameters against Table 2 (least
  squares in log parameters, with sensitivities);
- :mod:`fem.contact`: the impact tips as one gap coordinate per tip (RBE3 rows), the tied
  (closed-gap) stiffness, point rows at x1, x2, x3, gap modes and the y-mirror map;
- :mod:`fem.beam_theory`: Euler-Bernoulli, Timoshenko, torsion and axial frequencies of a
  free-free bar, the references of the ``beam-free`` scene;
- :mod:`fem.rig`: the instrumented rig: channel names, UFF node and direction codes, sensor and
  seat rows, and the hammer's consistent point load anywhere on the beam (from the mesh alone);
- :mod:`fem.modal_response`: a modal model with non-proportional damping, its pole-residue FRF
  and its exact half-sine response (the virtual hammer test's linear check);
- :mod:`fem.vtu`: displacement fields on the hex mesh as VTU files for ParaView.

Entry points: :func:`fem.analysis.analyse` (the ``modal`` stage) and
:func:`fem.model.build_system` with :mod:`fem.contact` (the ``reduce`` stage, through
:func:`reduced.models.rom.build_rom`). Importing :mod:`fem` loads none of its modules.
"""
