"""Exact reference solutions for the ALE solver: stiffened-gas Riemann problem (closed form), Riemann
problem of any EOS of the background (riemann_eos: Mie-Grueneisen, JWL, ...; imported on its own: it
loads numba and scipy.integrate), Sedov-Taylor blast wave and a shock reflecting from a wall."""
from .reflected_shock import ReflectedShock
from .riemann import RiemannSolution
from .sedov import SedovSolution

__all__ = ["ReflectedShock", "RiemannSolution", "SedovSolution"]
