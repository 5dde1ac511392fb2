"""rimd_sim: digital twin of the RIMD vibro-impact test rig.

Sub-packages: ``core`` (physics, without ROS), ``verbs`` (subcommands of the ``rimd`` command), and later
``nodes`` (thin ROS 2 adapters over the core).
"""

__version__ = "0.1.0"
