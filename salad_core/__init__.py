"""salad: text-driven human motion generation and attention-based editing (SALAD, KeyMotion).

The library part (no plotting imports). See README.md for the entry points.
"""
from salad_core import openmp as _openmp

# before anything imports torch: OpenMP workers sleep instead of spinning between parallel regions
# (see salad_core.openmp for the measurement; SALAD_OMP_WAIT=keep leaves the runtime's default)
_openmp.configure()

__version__ = "0.6.0"
