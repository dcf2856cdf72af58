"""immerse package."""

from solvers.kernel_cache import configure as _configure_kernel_cache

_configure_kernel_cache()  # before any module imports numba (solvers/kernel_cache.py)
