"""The inlined modulus of the exact kernels (:func:`reduced.transient._cabs.cabs`) is the C library's hypot to the
bit: numba's ``abs(z)`` calls it, and the march's step bounds were written with it (a changed bit moves a
continuation's step path, whose files are compared digit for digit with the committed results)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from reduced.transient._cabs import cabs


@nb.njit(cache=True)
def _mismatches(z):
    """Indices where cabs(z) and abs(z) (the library's hypot) differ in any bit (two NaNs agree)."""
    out = []
    for i in range(z.shape[0]):
        a = abs(z[i])
        b = cabs(z[i])
        if a != b and not (a != a and b != b):
            out.append(i)
        elif a == 0.0 and math.copysign(1.0, a) != math.copysign(1.0, b):
            out.append(i)
    return out


def _pairs(rng, n, lo, hi, spread):
    """n complex numbers whose parts have decimal exponents in [lo, hi), the two parts up to ``spread``
    decades apart, random signs."""
    e1 = rng.uniform(lo, hi, n)
    e2 = np.clip(e1 + rng.uniform(-spread, spread, n), -323.0, 307.0)
    s = rng.choice([-1.0, 1.0], (2, n))
    return s[0] * 10.0**e1 * rng.uniform(1.0, 9.99, n) + 1j * s[1] * 10.0**e2 * rng.uniform(1.0, 9.99, n)


def test_cabs_is_the_library_hypot_to_the_bit():
    rng = np.random.default_rng(28)
    parts = [_pairs(rng, 150_000, lo, hi, spread)
             for lo, hi, spread in ((-3, 3, 3), (-30, 30, 20), (-320, 307, 40), (-170, -130, 5), (130, 170, 5))]
    g = rng.standard_normal((2, 150_000))
    near = g[0] + 1j * g[0] * (1.0 + 1e-15 * g[1])  # |Re| ~ |Im|: the kernel's other branch
    special = np.array([0j, complex(-0.0, 0.0), 1 + 0j, 1j, complex(3, 4), complex(np.inf, 1.0), complex(1.0, -np.inf),
                        complex(np.nan, 1.0), complex(np.inf, np.nan), complex(np.nan, np.nan), 5e-324 + 5e-324j,
                        complex(1e308, 1e308), complex(2.0**511, 2.0**-459), complex(2.0**-459, 2.0**-460),
                        complex(2.0**512, 1.0)])
    z = np.concatenate(parts + [near, g[0] + 1j * g[1], special])
    bad = _mismatches(z)
    assert not bad, f"{len(bad)} of {z.size} differ, e.g. {z[bad[:5]]}"
