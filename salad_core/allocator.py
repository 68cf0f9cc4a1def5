"""Keep freed memory for reuse instead of returning it to the OS (glibc ``mallopt``).

PyTorch's CPU tensors come from the C library's ``malloc``. glibc serves every block above its
mmap threshold (128 KiB to 32 MiB, adaptive) with a fresh ``mmap`` and unmaps it on free, so each
new large activation is page-faulted in and zeroed by the kernel again. At batch 32 the paper
denoiser allocates tens of MB per operation; on this project's 2-core machine one denoiser forward
took 1.41-1.56 s with glibc's defaults and 1.20-1.21 s with large blocks served from the heap and
freed memory kept (the same figures as ``MALLOC_MMAP_MAX_=0 MALLOC_TRIM_THRESHOLD_=...`` in the
environment). The price: the process keeps its peak heap instead of shrinking after a big batch.

:func:`tune_allocator` applies that at run time (``mallopt(M_MMAP_MAX, 0)`` and a 2 GiB trim
threshold). The ``salad`` command calls it for its commands unless ``SALAD_ALLOCATOR=system``; a
library user may call it once (notebooks keep glibc's defaults unless they do). On other C
libraries (macOS, Windows, musl) it does nothing and says so.
"""
from __future__ import annotations

import ctypes
import logging
import os
import platform

__all__ = ["tune_allocator", "allocator_tuned", "ENV_VAR"]

log = logging.getLogger(__name__)

#: ``system`` keeps the C library's defaults in the ``salad`` command; anything else (or unset) tunes.
ENV_VAR = "SALAD_ALLOCATOR"

_M_TRIM_THRESHOLD = -1
_M_MMAP_MAX = -4
_TRIM_BYTES = 2**31 - 1          # mallopt takes an int: about 2 GiB
_state = {"tuned": False}


def allocator_tuned() -> bool:
    """Whether :func:`tune_allocator` has changed this process's allocator."""
    return _state["tuned"]


def tune_allocator() -> bool:
    """Serve large blocks from the heap and keep freed memory (glibc only); True if applied.

    Idempotent. Returns False, changing nothing, on a non-glibc platform or if ``mallopt`` fails.
    """
    if _state["tuned"]:
        return True
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        log.debug("allocator: not glibc (%s), left alone", platform.libc_ver())
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        ok = libc.mallopt(_M_MMAP_MAX, 0) == 1 and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_BYTES) == 1
    except (OSError, AttributeError) as exc:
        log.debug("allocator: mallopt unavailable (%s)", exc)
        return False
    _state["tuned"] = bool(ok)
    return _state["tuned"]


def tune_from_environment() -> bool:
    """The ``salad`` command's choice: tune unless ``SALAD_ALLOCATOR=system``."""
    value = os.environ.get(ENV_VAR, "tuned").strip().lower()
    if value == "system":
        return False
    if value not in ("", "tuned"):
        raise ValueError(f"{ENV_VAR} must be 'tuned' or 'system', got {value!r}")
    return tune_allocator()
