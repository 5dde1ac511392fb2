"""The settings: parameter declarations, SimConfig, lockstep, capture and recording settings, YAML, paths."""
