"""Robustness evaluation (sweeps, results, figures), one-episode analysis and rollout video."""
