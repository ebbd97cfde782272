"""Optimisation on top of the studies: assembly-phase allocation, tolerance budgets and costs, profile modifications."""
