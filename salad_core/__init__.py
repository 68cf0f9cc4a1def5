"""salad: text-driven human motion generation and attention-based editing (SALAD, KeyMotion).

The library part (no plotting imports). See README.md for the entry points.
"""
__version__ = "0.5.0"
