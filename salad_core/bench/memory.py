"""The ``memory`` section: peak resident memory of one generation with streaming attention capture.

On Linux the kernel's high-water mark ``VmHWM`` is reset before each call (``/proc/self/clear_refs``);
elsewhere the process peak ``ru_maxrss`` is used (a delta then only shows growth beyond earlier peaks).
"""
from __future__ import annotations

import gc
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

from .plan import SOURCE, Row

__all__ = ["rss_kib", "reset_peak", "peak_rss_delta", "memory_rows"]


def rss_kib() -> tuple[int, int] | None:
    """``(current, peak)`` RSS in KiB from ``/proc/self/status`` (Linux), else None."""
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return None
    vals = {}
    for line in text.splitlines():
        key, _, rest = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            vals[key] = int(rest.split()[0])
    return (vals["VmRSS"], vals["VmHWM"]) if len(vals) == 2 else None


def reset_peak() -> bool:
    """Reset the kernel's RSS high-water mark of this process (Linux >= 4.0)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_rss_delta(fn: Callable[[], Any]) -> tuple[float, str]:
    """``(MiB, method)``: peak RSS while ``fn`` runs minus the RSS before it."""
    import resource

    gc.collect()
    if reset_peak() and rss_kib() is not None:
        before, _ = rss_kib()
        fn()
        _, peak = rss_kib()
        return max(peak - before, 0) / 1024, "resource RSS: VmHWM (reset) - VmRSS before"
    # ru_maxrss is KiB on Linux, bytes on macOS; it cannot be reset
    scale = 1 / 1024 if sys.platform != "darwin" else 1 / 2**20
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    fn()
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return (after - before) * scale, "resource RSS: ru_maxrss delta (process peak, not resettable)"


def memory_rows(pipe, frames: int, steps: Sequence[int] = (50, 200)) -> list[Row]:
    """Peak RSS growth of one generation with streaming capture, per number of steps; the ratio
    is against the first (the streaming store should not grow with the steps)."""
    pipe(SOURCE, lengths=frames, num_steps=2, capture_attention=True)  # first-call allocations out of the way
    rows, first = [], None
    for s in steps:
        mib, method = peak_rss_delta(lambda: pipe(SOURCE, lengths=frames, num_steps=s, capture_attention=True))
        first = mib if first is None else first
        rows.append(Row("memory", "peak memory, generation with streaming capture", f"{frames} frames, {s} steps",
                        mib, "MiB", reference=None if s == steps[0] else first,
                        ratio=None if s == steps[0] or first <= 0 else mib / first, note=method))
    return rows
