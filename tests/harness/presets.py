"""Parameter sets the tests pin by value, apart from the presets the product ships.

``FORMER_DEFAULT``: the single-mass set (m 0.15 kg, zeta 0.08, A0 1 mm, f_n 1.82 Hz) that tests of the analyses'
mechanics (maps, caps, classes at chosen points) were written on. Those tests check how an analysis reads a motion,
not what the default rig does, so they keep the motions they were written for whatever the default becomes.
"""

from __future__ import annotations

FORMER_DEFAULT = {"mass": 0.15, "damping_ratio": 0.08, "amplitude": 1e-3, "natural_frequency": 1.82}
#: The same as ``rimd`` options (``--set NAME=VALUE`` of the analysis verbs).
FORMER_DEFAULT_ARGS = [arg for name, value in FORMER_DEFAULT.items() for arg in ("--set", f"{name}={value}")]
