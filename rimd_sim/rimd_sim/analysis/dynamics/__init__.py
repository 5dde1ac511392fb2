"""Analyses of the model's dynamics: sweeps, bifurcation, Peterka map, Lyapunov exponent, one impact."""
