"""rimd_sim: digital twin of the RIMD vibro-impact test rig.

The package's folders are its layers, bottom to top (docs/architecture.md): ``settings``, ``model``,
``instruments`` and ``io``, ``runtime``, ``analysis`` and ``viz``, ``ros`` (the only one that imports ROS), ``cli``.
Importing ``rimd_sim`` itself imports nothing else.
"""

__version__ = "0.4.0"
