"""Optimisers with the ask/tell interface: Bayesian optimisation, random search,
particle swarms and CMA-ES."""
