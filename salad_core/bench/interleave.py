"""Two settings timed side by side: rounds that alternate which goes first, medians of each.

A ratio of two timings means something on a shared machine only when both met the same load, so the
bench scripts that compare two ways of doing one step run them in one process, in rounds, the order
flipped every round (A, B then B, A), after one warm-up call of each.
"""
from __future__ import annotations

import statistics
from typing import Callable

__all__ = ["interleaved_medians"]


def interleaved_medians(first: Callable[[], float], second: Callable[[], float], rounds: int,
                        warmup: bool = True) -> tuple[float, float]:
    """Median of what ``first`` and ``second`` return (seconds of one call each) over ``rounds`` rounds.

    Round ``r`` calls ``first`` then ``second`` when ``r`` is even, ``second`` then ``first`` when odd;
    with ``warmup`` both are called once before (results dropped). Each callable times itself and
    returns its seconds, so set-up outside the timed part stays out of the figures.
    """
    if rounds < 1:
        raise ValueError(f"rounds must be at least 1, got {rounds}")
    if warmup:
        first(), second()
    times: tuple[list[float], list[float]] = ([], [])
    for r in range(rounds):
        for which in ((0, 1) if r % 2 == 0 else (1, 0)):
            times[which].append((first, second)[which]())
    return statistics.median(times[0]), statistics.median(times[1])
