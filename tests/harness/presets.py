"""Parameter sets the tests pin by value, apart from the presets the product ships.

``SINGLE_MASS_SET``: the single-mass mechanics of config/structural.yaml (m 0.15 kg, zeta 0.08, A0 1 mm, f_n
1.82 Hz), on which tests of the analyses' mechanics (maps, caps, classes at chosen points) pin their motions. Those
tests check how an analysis reads a motion, not what the default rig does, so they keep their motions whatever the
default configuration is.
"""

from __future__ import annotations

SINGLE_MASS_SET = {"mass": 0.15, "damping_ratio": 0.08, "amplitude": 1e-3, "natural_frequency": 1.82}
#: The same as ``rimd`` options (``--set NAME=VALUE`` of the analysis verbs).
SINGLE_MASS_ARGS = [arg for name, value in SINGLE_MASS_SET.items() for arg in ("--set", f"{name}={value}")]
