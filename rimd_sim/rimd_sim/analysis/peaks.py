"""The largest value of a sampled curve, refined between its samples.

Shared by the analyses of the model and of recordings (a branch's largest relative displacement, a contact pulse's
peak force).
"""

from __future__ import annotations

import numpy as np

__all__ = ["sampled_peak"]


def sampled_peak(values: np.ndarray) -> float:
    """The largest of ``values``, refined by the parabola through it and its two neighbours.

    The vertex is taken only where that parabola opens downwards; at either end of the samples, or on a flat or
    convex triple, the largest sample itself.
    """
    j = int(np.argmax(values))
    peak = float(values[j])
    if 0 < j < values.size - 1:
        a, b, c = values[j - 1], values[j], values[j + 1]
        den = a - 2.0 * b + c
        if den < 0:
            peak = float(b - 0.125 * (c - a) ** 2 / den)
    return peak
