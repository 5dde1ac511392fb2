"""Library functions of the hot loop replaced by cheaper polynomial forms: ``(sin, cos)`` and ``x ** -0.2``.

Both are inlined into their callers (the models' physics, the event search, the step control).
"""

from __future__ import annotations

import math

from rimd_sim.model.jit import kernel_jit


@kernel_jit(inline=True)
def sincos(x):
    """``(sin x, cos x)``, fast for the pendulum's small angles.

    For ``|x| < 0.25`` by Taylor polynomials of degree 11 and 12, accurate to about one ulp and several
    times faster than the library calls.
    """
    if abs(x) < 0.25:
        x2 = x * x
        s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (
            1.0 / 362880.0 + x2 * (-1.0 / 39916800.0))))))
        c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (
            -1.0 / 3628800.0 + x2 * (1.0 / 479001600.0))))))
        return s, c
    return math.sin(x), math.cos(x)


#: ``2^(-r/5)`` for r = 0..4: the fractional part of ``2^(-e/5)`` in :func:`inv_fifth_root`.
_TWO_POW_MINUS_FIFTHS = (1.0, 2.0 ** -0.2, 2.0 ** -0.4, 2.0 ** -0.6, 2.0 ** -0.8)


@kernel_jit(inline=True)
def inv_fifth_root(x):
    """``x ** -0.2`` to 1e-5 relative for ``x > 0``: the step control's factor, which needs two digits.

    ``x = m 2^e`` with ``m`` in [0.5, 1) (``frexp``); ``2^(-e/5) = 2^-q 2^(-r/5)`` for ``e = 5 q + r`` from a table
    and an exact ``ldexp``; ``m^(-1/5)`` from a quadratic fit on [0.5, 1] (within 2e-3) and one Newton step on
    ``y^5 m = 1``. The step control needs one such factor per step, and a library ``pow`` costs far more than
    these few multiplications. An infinite ``x`` (a step that overflowed) gives 0, as ``pow`` does: the step is
    then cut by the most allowed.
    """
    if not x < math.inf:
        return 0.0
    m, e = math.frexp(x)
    q = e // 5
    r = e - 5 * q
    y = (0.2395284269767007 * m - 0.6505206630934096) * m + 1.4122927588697187
    y2 = y * y
    y = y + 0.2 * y * (1.0 - m * (y2 * y2 * y))
    return math.ldexp(y * _TWO_POW_MINUS_FIFTHS[r], -q)
