"""Reduced and discrete models: gap systems, ringdown integrators, nonlinear normal modes."""
