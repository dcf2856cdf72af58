"""Exact reference solutions for the ALE solver: stiffened-gas Riemann problem, Sedov-Taylor blast wave
and a shock reflecting from a wall."""
from .reflected_shock import ReflectedShock
from .riemann import RiemannSolution
from .sedov import SedovSolution

__all__ = ["ReflectedShock", "RiemannSolution", "SedovSolution"]
