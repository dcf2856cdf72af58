"""Solver adapters: each solver group speaks the same small coupling contract (see adapters.base)
to the coupler over an MPI intercommunicator. Adapters register themselves by role name."""

from solvers.kernel_cache import configure as _configure_kernel_cache

_configure_kernel_cache()  # before any module imports numba (solvers/kernel_cache.py)
