"""Periodic solutions: nonlinear normal modes by harmonic balance and shooting, and their stability.

- :mod:`~reduced.periodic.hb`: the HB residual with its analytic Jacobian (AFT) and Newton;
- :mod:`~reduced.periodic.continuation`: pseudo-arclength continuation of any residual;
- :mod:`~reduced.periodic.backbones`: NNM branches (frequency-energy) of a gap system;
- :mod:`~reduced.periodic.shooting`: periodic orbits of the exact flow, Floquet multipliers;
- :mod:`~reduced.periodic.stability`: Hill's method and its comparison with Floquet;
- :mod:`~reduced.periodic.nnm2`: the exact NNM 2 relation of the three-mass model (Eq. 12-14, corrected);
- :mod:`~reduced.periodic.exact_hb`: HB with the stop forces projected exactly over their contact intervals;
- :mod:`~reduced.periodic.forced_balance`: HB under a harmonic load, condensed onto the contact
  coordinates (the residual of the forced-response curves);
- :mod:`~reduced.periodic.frc`: forced-response curves, continued through folds, with amplitudes;
- :mod:`~reduced.periodic.forced_stability`: their stability (monodromy, Hill, shooting on the
  forced exact flow) and bifurcations;
- :mod:`~reduced.periodic.stepped_sine`: the reference of the forced-response curves, a stepped
  sine by the exact flow.
- :mod:`~reduced.periodic.friction_aft`: friction (Jenkins elements) in the forced balance by AFT, its
  forced-response curves with Hill's stability;
- :mod:`~reduced.periodic.friction_shooting`: forced periodic orbits of the exact flow with friction (multiple
  shooting on [x; v; w]), their Floquet multipliers: the reference of the friction HB in contact.

Every continued curve takes one set of step options,
:class:`~reduced.periodic.continuation.ContinuationOptions`; every shooting failure is one
:class:`~reduced.periodic.shooting.ShootingError`.
"""

MAX_HARMONICS = 1000  # HB orders beyond this resolve nothing a 20 kHz ringdown shows (every solver here and
# the scene schema refuse more)
