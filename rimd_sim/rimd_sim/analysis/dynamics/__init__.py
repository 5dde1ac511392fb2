"""Analyses of the model's dynamics: sweeps, bifurcation, continuation, maps and basins, Lyapunov, one impact."""
