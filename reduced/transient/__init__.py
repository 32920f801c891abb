"""Time integration of a :class:`~reduced.models.gaps.GapSystem` and what reads its output.

Free (ringdown) or forced: every integrator and the flow take ``loads`` (a
:class:`~reduced.models.loads.Loads`), M x'' + C x' + K x + B^T f(B x) = sum_l b_l p_l(t), and
report the loads' work int v^T f_ext dt (``external``) beside the dissipated work.

- :mod:`~reduced.transient.integrate`: :func:`ringdown`, one entry point for the three methods, in
  memory or streamed to disk (``out=``), :func:`ringdown_stream`, and the estimates
  :func:`ringdown_peak_bytes` and :func:`ringdown_disk_bytes`;
- :mod:`~reduced.transient.stepper`: the one driver of the three methods (each a
  :class:`~reduced.transient.stepper.Stepper` that supplies its step, with a frozen options dataclass);
- :mod:`~reduced.transient.exact`: event-driven closed form in each contact state (its tables in
  :mod:`~reduced.transient.exact_tables`, its numba kernels in ``_modal`` and ``_exact_kernels``);
- :mod:`~reduced.transient.explicit`: central difference in a numba kernel;
- :mod:`~reduced.transient.dop853`: SciPy's DOP853, the independent reference;
- :mod:`~reduced.transient.friction`: the three methods for a system with friction at its tips (the exact
  one on the stick/slip states' closed forms, :mod:`~reduced.transient.friction_tables`, its kernels in
  ``_friction_kernels``; central difference with a return mapping; DOP853 restarted at every state change);
- :mod:`~reduced.transient.flow`: the exact flow map and its Jacobian (for shooting);
- :mod:`~reduced.transient.result`: :class:`RingdownResult` (in memory), :class:`RingdownStream`
  (chunks as they are computed) and the sample grid;
- :mod:`~reduced.transient.store`: ``ringdown.npz`` written in one pass and read lazily
  (:class:`RingdownFile`);
- :mod:`~reduced.transient.spectrogram`: STFT of a response (from chunks) with curves overlaid;
- :mod:`~reduced.transient.compare`: the largest Lyapunov exponent of a motion and the comparison
  of two runs by what a chaotic motion keeps (energy envelope, dominant frequency, impacts).

Every public function checks its arguments before any work (``ValueError`` naming the argument,
the value and what is allowed; :mod:`~reduced._checks`).
"""
