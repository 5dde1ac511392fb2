"""The rig model (no ROS): integrator kernel, contact laws, rigid and structural models, RigModel, ensemble."""
