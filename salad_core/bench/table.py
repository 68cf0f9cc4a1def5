"""The ``salad bench`` table as Markdown: the machine header, one table, then the notes."""
from __future__ import annotations

import datetime as _dt
import os
import platform
from typing import Any

import numpy as np
import torch

from salad_core.allocator import allocator_tuned
from salad_core.models.gemm import backend as gemm_backend

__all__ = ["machine_header", "format_cell", "format_table"]


def machine_header(threads: int, quick: bool) -> str:
    """One line: date, platform, CPUs, torch version and threads, and the load at the start."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    cpu = platform.processor() or platform.machine()
    return (f"salad bench{' --quick' if quick else ''}, {_dt.datetime.now().astimezone():%Y-%m-%d %H:%M %Z}: "
            f"{platform.platform()} ({cpu}), {os.cpu_count()} CPUs, Python {platform.python_version()}, "
            f"torch {torch.__version__}, {threads} torch thread{'s' * (threads != 1)}, dense layers on "
            f"{gemm_backend()}, allocator {'tuned' if allocator_tuned() else 'system default'}, load average "
            f"{load:.2f} at the start")


def format_cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    if isinstance(value, (int, float, np.floating)):
        v = float(value)
        if v == 0:
            return "0"
        if abs(v) >= 100:
            return f"{v:,.0f}"
        if abs(v) >= 0.01:
            return f"{v:.3g}" if abs(v) < 10 else f"{v:.1f}"
        return f"{v:.2e}"
    return str(value).replace("|", "\\|")


def format_table(df: Any) -> str:
    """The table as Markdown: the machine header, one table, then the notes."""
    cols = list(df.columns)
    lines = [f"**{df.attrs.get('header', 'salad bench')}**", "",
             "| " + " | ".join(cols) + " |",
             "|" + "|".join("---:" if c in ("value", "reference", "ratio") else "---" for c in cols) + "|"]
    for rec in df.itertuples(index=False):
        lines.append("| " + " | ".join(format_cell(getattr(rec, c)) for c in cols) + " |")
    notes = df.attrs.get("notes", [])
    if notes:
        lines += ["", "Notes:"] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"
