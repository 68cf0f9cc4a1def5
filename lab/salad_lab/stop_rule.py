"""When a staged ablation group stops: its orderings are stable, or its budget is spent.

A group (tables that share variants, trained together) is evaluated at each of its stages. At each
evaluation every paper pair of every table of the group gets an ordering per metric
(:func:`~salad_lab.orderings.compare`). The group stops at the first stage where the
orderings of the last ``consecutive`` evaluations are all identical (``"stable"``), or at its last
stage (``"budget"``); otherwise it trains on to the next stage (``"continue"``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

from .orderings import COMPARE_MODES

__all__ = ["StopRule", "StopDecision", "decide"]


@dataclass(frozen=True)
class StopRule:
    """How stability is judged."""

    consecutive: int = 2            # evaluations in a row whose orderings must be identical
    compare: str = "intervals"      # "intervals": level when the 95 % intervals overlap; "means": signs of the means

    def __post_init__(self) -> None:
        if isinstance(self.consecutive, bool) or not isinstance(self.consecutive, int) or self.consecutive < 2:
            raise ValueError(f"StopRule.consecutive={self.consecutive!r} is invalid; use an integer >= 2 "
                             "(one evaluation alone cannot show a stable ordering)")
        if self.compare not in COMPARE_MODES:
            raise ValueError(f"StopRule.compare={self.compare!r} is invalid; allowed: {COMPARE_MODES}")


@dataclass(frozen=True)
class StopDecision:
    """What the rule says after the evaluations so far."""

    stop: bool
    reason: str                     # "stable", "budget" or "continue"
    steps: int                      # the stage of the last evaluation
    next_steps: int | None          # the stage to train to next (None when stopping)


def decide(history: Sequence[Mapping[str, str]], stages: Sequence[int], rule: StopRule = StopRule()) -> StopDecision:
    """Apply the stop rule to a group's evaluations so far.

    Parameters
    ----------
    history : sequence of dict
        One ``{pair key: ordering}`` per evaluated stage, in stage order (``history[i]`` belongs to
        ``stages[i]``); every dict has the same keys.
    stages : sequence of int
        The group's evaluation points (steps), increasing.
    rule : StopRule

    Returns
    -------
    StopDecision
    """
    stages = [int(s) for s in stages]
    if not history:
        raise ValueError("history is empty: evaluate the first stage before asking whether to stop")
    if len(history) > len(stages):
        raise ValueError(f"{len(history)} evaluations for {len(stages)} stages {stages}")
    keys = set(history[0])
    for i, h in enumerate(history):
        if set(h) != keys:
            raise ValueError(f"evaluation {i} (step {stages[i]}) orders {sorted(h)}, the first orders {sorted(keys)}: "
                             "every evaluation of a group must order the same pairs")
    steps = stages[len(history) - 1]
    last = history[-rule.consecutive:]
    if len(last) == rule.consecutive and all(dict(h) == dict(last[0]) for h in last):
        return StopDecision(True, "stable", steps, None)
    if len(history) == len(stages):
        return StopDecision(True, "budget", steps, None)
    return StopDecision(False, "continue", steps, stages[len(history)])
