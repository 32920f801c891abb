"""Time integration of a :class:`~reduced.models.gaps.GapSystem` and what reads its output.

- :mod:`~reduced.transient.integrate`: :func:`ringdown`, one entry point for the three methods;
- :mod:`~reduced.transient.exact`: event-driven closed form in each contact state;
- :mod:`~reduced.transient.explicit`: central difference in a numba kernel;
- :mod:`~reduced.transient.dop853`: SciPy's DOP853, the independent reference;
- :mod:`~reduced.transient.flow`: the exact flow map and its Jacobian (for shooting);
- :mod:`~reduced.transient.result`: :class:`RingdownResult` and the sample grid;
- :mod:`~reduced.transient.spectrogram`: STFT of a response with curves overlaid.
"""
