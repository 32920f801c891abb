"""|z| of a complex number inside numba kernels, inlined: the bits of the C library's ``hypot`` (which numba's
``abs(z)`` calls), without the call.

The march of the exact flow takes |z| of every term of a stop's series at every step (the step bound
Q2 = sum_i |c_i e^{lam_i tau}| |lam_i|^2 and the scale of q'): a profile of the shooting residual of rom-frc
(24 exponents a series) spends 31 % of its march in the library's ``hypot`` (a call that the compiler can
neither inline nor overlap with the loop). :func:`cabs` is the same algorithm inlined (Borges 2019, "An improved
algorithm for hypot(a, b)", arXiv:1904.09481, the correction without a fused multiply-add, as glibc >= 2.35
builds it for x86-64): with a = max(|x|, |y|) >= b = min(|x|, |y|),

    h = sqrt(a^2 + b^2),   h <- h - (t1 + t2) / (2 h),
    t1 = a (2 d - a), t2 = (d - 2 (a - b)) d, d = h - b          if h <= 2 b,
    t1 = 2 d (a - 2 b), t2 = (4 d - b) b + d^2, d = h - a        otherwise,

the residual a^2 + b^2 - h^2 made exactly enough to round h correctly in almost every case; inputs scaled by
2^-600 above 2^511 and by 2^600 below 2^-459 (no overflow or underflow in the squares), a + b returned when
b <= 2^-54 a (b does not change the sum's rounding), infinities and NaNs as the library returns them. Each
operation rounds as the library's (no fused multiply-add: numba does not contract without fastmath), so the
result is the library's to the bit (tests/test_cabs.py: equality on ~900k pairs over the whole exponent
range, and the special values); where this machine's library differs, the test says so.
"""

from __future__ import annotations

import math

import numba as nb

_SCALE = 2.0**-600  # scaling of huge or tiny inputs (a power of two: exact)
_LARGE = 2.0**511  # a above this: scaled down
_TINY = 2.0**-459  # b below this: scaled up
_EPS = 2.0**-54  # b <= a _EPS: a + b is the rounded result
_FINITE = 1.7976931348623157e308  # the largest double


@nb.njit(cache=True, inline="always")
def _corrected(a, b):
    """sqrt(a^2 + b^2) for a >= b >= 0 whose squares neither overflow nor underflow, corrected by the exact
    residual of its square (module docstring)."""
    h = math.sqrt(a * a + b * b)
    if h <= 2.0 * b:
        d = h - b
        t1 = a * (2.0 * d - a)
        t2 = (d - 2.0 * (a - b)) * d
    else:
        d = h - a
        t1 = 2.0 * d * (a - 2.0 * b)
        t2 = (4.0 * d - b) * b + d * d
    return h - (t1 + t2) / (2.0 * h)


@nb.njit(cache=True, inline="always")
def cabs(z):
    """|z| = sqrt(Re(z)^2 + Im(z)^2) of a complex z, to the bit of ``abs(z)`` (the library's hypot; module
    docstring).

    Parameters
    ----------
    z : complex
        The number.

    Returns
    -------
    float
        Its modulus: inf if a part is infinite, NaN if a part is NaN and none is infinite.
    """
    x = abs(z.real)
    y = abs(z.imag)
    if not (x <= _FINITE and y <= _FINITE):  # an infinity or a NaN
        if x == math.inf or y == math.inf:
            return math.inf
        return x + y
    a = y if x < y else x
    b = x if x < y else y
    if a > _LARGE:
        if b <= a * _EPS:
            return a + b
        return _corrected(a * _SCALE, b * _SCALE) / _SCALE
    if b < _TINY:
        if a >= b / _EPS:
            return a + b
        return _corrected(a / _SCALE, b / _SCALE) * _SCALE
    if b <= a * _EPS:
        return a + b
    return _corrected(a, b)


__all__ = ["cabs"]
