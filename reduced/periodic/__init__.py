"""Periodic solutions: nonlinear normal modes by harmonic balance and shooting, and their stability.

- :mod:`~reduced.periodic.hb`: the HB residual with its analytic Jacobian (AFT) and Newton;
- :mod:`~reduced.periodic.continuation`: pseudo-arclength continuation of any residual;
- :mod:`~reduced.periodic.backbones`: NNM branches (frequency-energy) of a gap system;
- :mod:`~reduced.periodic.shooting`: periodic orbits of the exact flow, Floquet multipliers;
- :mod:`~reduced.periodic.stability`: Hill's method and its comparison with Floquet;
- :mod:`~reduced.periodic.nnm2`: the exact NNM 2 relation of the three-mass model (Eq. 12-14, corrected);
- :mod:`~reduced.periodic.exact_hb`: HB with the stop forces projected exactly over their contact intervals;
- :mod:`~reduced.periodic.frc`: forced-response curves under a harmonic load (HB condensed onto the
  contact coordinates, continued through folds), their stability and bifurcations, and the
  stepped-sine reference by the exact flow.
"""
