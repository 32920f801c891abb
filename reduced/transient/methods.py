"""The names of the transient integrators, in a module that loads none of them (the scene schema
checks a ``method`` key against it without importing numba kernels or SciPy's integrators)."""

METHODS = ("exact", "explicit", "dop853")  # reduced.transient.integrate.ringdown's ``method``
