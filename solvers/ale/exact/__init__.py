"""Exact reference solutions for the ALE solver: stiffened-gas Riemann problem and Sedov-Taylor blast wave."""
from .riemann import RiemannSolution
from .sedov import SedovSolution

__all__ = ["RiemannSolution", "SedovSolution"]
