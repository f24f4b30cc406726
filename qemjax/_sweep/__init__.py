"""Sweeps: grids of runs, their configuration files, and Pareto fronts."""
