"""Models: what the solvers integrate, never a solver itself.

- :mod:`~reduced.models.gaps`: :class:`GapSystem`, M x'' + C x' + K x + B^T f(B x) = 0 with
  penalty stops, the one system every solver takes, and its optional :class:`Friction` at the tips;
- :mod:`~reduced.models.discrete`: the paper's three-mass model (Eq. 9, Table 1), and the same with
  the beam's axial motion and friction at the tips (:class:`DiscreteFrictionParams`);
- :mod:`~reduced.models.modes`: open- and closed-gap linear modes, modes that move given rows;
- :mod:`~reduced.models.craig_bampton`, :mod:`~reduced.models.rom`: the 3-D model reduced
  onto its tips, saved as ``rom.npz`` and cached;
- :mod:`~reduced.models.rig`: the virtual rig: a reduced apparatus struck by a hammer, its
  channels (accelerometers, tip load cells, the hammer) synthesised from the state;
- :mod:`~reduced.models.loads`: external forces (half-sine, harmonic, tabulated);
- :mod:`~reduced.models.identify`: a reduced model read back as the three-mass model;
- :mod:`~reduced.models.initial`: initial states given at the points x1, x2, x3.
"""
