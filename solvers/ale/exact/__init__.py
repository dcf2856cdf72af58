"""Exact reference solutions for the ALE solver: stiffened-gas Riemann problem (closed form), Riemann
problem of any EOS of the background (riemann_eos: Mie-Grueneisen, JWL, ...; imported on its own: it
loads numba and scipy.integrate), Sedov-Taylor blast wave and a shock reflecting from a wall.

The names load on first use (PEP 562): a Riemann check of a run then does not import scipy.integrate
for the Sedov solution (0.5 s of every such run's check, measured)."""
from importlib import import_module

_WHERE = {"ReflectedShock": ".reflected_shock", "RiemannSolution": ".riemann", "SedovSolution": ".sedov"}

__all__ = list(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(import_module(_WHERE[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
