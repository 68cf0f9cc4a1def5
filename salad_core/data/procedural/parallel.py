"""Run per-motion generation jobs in order, in one process or a worker pool, with a progress bar.

Every job carries its own random stream ``(seed, index)``, so the results do not depend on the
number of workers; :func:`run_jobs` only keeps them in job order.
"""
from __future__ import annotations

import multiprocessing as mp
from typing import Any, Callable, Sequence

__all__ = ["run_jobs"]


def run_jobs(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int, *, desc: str, unit: str = "motion",
             chunksize: int = 8, progress: bool = True) -> list[Any]:
    """``[fn(job) for job in jobs]``, with ``workers`` processes (fork where available) when > 1."""
    from tqdm.auto import tqdm

    out: list[Any] = []
    bar = tqdm(total=len(jobs), desc=desc, unit=unit, disable=not progress)
    try:
        if workers == 1:
            for job in jobs:
                out.append(fn(job))
                bar.update()
        else:
            ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
            with ctx.Pool(workers) as pool:
                for result in pool.imap(fn, jobs, chunksize=chunksize):
                    out.append(result)
                    bar.update()
    finally:
        bar.close()
    return out
