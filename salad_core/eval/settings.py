"""What an evaluation run is and what it returns: :class:`EvalSettings`, :class:`EvalResult` and the
metric names and table columns every evaluation module shares.

``EvalSettings`` is recorded with every result, so a table can always say how its numbers were
made (quick mode, replications, samples, steps, guidance, solver, seed). Nothing here runs a model.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np

from . import metrics as M

__all__ = [
    "METRICS",
    "CI_SUFFIX",
    "REAL_NAME",
    "DEFAULT_CFG_SCALES",
    "SETTING_COLUMNS",
    "PROTOCOL_REPLICATIONS",
    "EvalSettings",
    "EvalResult",
    "protocol_deviations",
]

#: Metric columns, in table order.
METRICS = ("R-precision top-1", "R-precision top-2", "R-precision top-3", "FID", "MM-Dist", "Diversity",
           "MultiModality")
#: Suffix of the confidence half-width column of a metric.
CI_SUFFIX = " ±"
#: Row name of the real-motion reference.
REAL_NAME = "Real motion"
#: The CFG weights of SALAD Fig. 5 / supplement Table 1: 1.5, 2.5, ..., 12.5.
DEFAULT_CFG_SCALES = tuple(float(w) for w in np.arange(1.5, 13.0, 1.0))
#: Settings columns of :func:`~salad_core.eval.tables.results_frame`, in order.
SETTING_COLUMNS = ("kind", "split", "batch_size", "replications", "samples", "mm", "mm_prompts", "mm_repeats",
                   "diversity_pairs", "num_steps", "guidance_scale", "solver", "seed", "max_samples", "quick",
                   "weights", "evaluator", "data")
#: Replications of the T2M protocol.
PROTOCOL_REPLICATIONS = 20


@dataclass(frozen=True)
class EvalSettings:
    """How one evaluation is run; recorded with every result."""

    split: str = "test"                 # split file stem of the dataset
    batch_size: int = 32                # R-precision batch (32 in every published table)
    replications: int = 20              # repetitions of the whole protocol (mean ± 95% CI over them)
    mm: bool = True                     # compute MultiModality (extra mm_prompts x mm_repeats generations)
    mm_prompts: int = 100               # captions used for MultiModality (T2M: 100; MoMask/SALAD: 96)
    mm_repeats: int = 30                # generations per MultiModality caption
    mm_pairs: int = 10                  # pairs of generations compared per caption
    diversity_pairs: int = 300          # Diversity pairs (100 when there are at most this many samples)
    num_steps: int = 50                 # sampler steps given to the generator
    guidance_scale: float = 7.5         # CFG weight w given to the generator (paper default 7.5)
    solver: str | None = None           # scheduler name given to the generator (None: its default, not passed)
    seed: int = 0                       # seeds crops, captions, batch order, noise and metric draws
    max_samples: int | None = None      # cap on samples per replication (quick mode); None: whole split
    quick: bool = False                 # marks a quick (non-protocol) run in every output

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ValueError(f"EvalSettings.{name}={getattr(self, name)!r} is invalid; {allowed}")

        def is_int(v: Any) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        need(isinstance(self.split, str) and bool(self.split.strip()), "split", "use a split name such as 'test'")
        need(is_int(self.batch_size) and self.batch_size >= 2, "batch_size", "use an int >= 2 (32 for the protocol)")
        for name in ("replications", "mm_prompts", "mm_pairs", "diversity_pairs", "num_steps"):
            need(is_int(getattr(self, name)) and getattr(self, name) >= 1, name, "use an int >= 1")
        need(is_int(self.mm_repeats) and self.mm_repeats > self.mm_pairs, "mm_repeats",
             f"use an int > mm_pairs={self.mm_pairs}")
        need(isinstance(self.mm, bool), "mm", "use True or False")
        need(isinstance(self.quick, bool), "quick", "use True or False")
        need(isinstance(self.guidance_scale, (int, float)) and not isinstance(self.guidance_scale, bool)
             and math.isfinite(self.guidance_scale), "guidance_scale", "use a finite float")
        need(self.solver is None or (isinstance(self.solver, str) and bool(self.solver)), "solver",
             "use None or a scheduler name")
        need(is_int(self.seed) and self.seed >= 0, "seed", "use an int >= 0")
        need(self.max_samples is None or (is_int(self.max_samples) and self.max_samples >= self.batch_size),
             "max_samples", f"use None or an int >= batch_size={self.batch_size}")

    @classmethod
    def quick_mode(cls, **changes: Any) -> "EvalSettings":
        """Quick settings: 2 replications of at most 64 samples, MultiModality off (if switched on:
        32 prompts x 12 repeats), ``quick=True``.

        Numbers from quick runs are not comparable with the protocol's (fewer samples make FID
        larger and the CIs wider); every output says so.
        """
        base = dict(replications=2, max_samples=64, mm=False, mm_prompts=32, mm_repeats=12, quick=True)
        return cls(**{**base, **changes})

    def replace(self, **changes: Any) -> "EvalSettings":
        """A validated copy with some fields changed."""
        return replace(self, **changes)

    def protocol_deviations(self) -> list[str]:
        """How these settings fall short of the T2M protocol (20 replications of the whole split,
        MultiModality on); empty for the protocol itself. Generation settings (steps, w, solver)
        are choices within the protocol and are not listed."""
        return protocol_deviations(self.replications, self.max_samples, self.mm)

    def describe(self) -> str:
        """One line for humans, starting with the mode."""
        short = self.protocol_deviations()
        mode = ("QUICK MODE (not the full protocol)" if self.quick else
                f"reduced protocol ({', '.join(short)})" if short else "full protocol")
        mm = f"on ({self.mm_prompts} prompts x {self.mm_repeats})" if self.mm else "off"
        cap = f", at most {self.max_samples} samples per replication" if self.max_samples else ""
        return (f"{mode}: split={self.split}, batch {self.batch_size}, {self.replications} replications{cap}, "
                f"MultiModality {mm}, steps {self.num_steps}, w {self.guidance_scale:g}, "
                f"solver {self.solver or 'default'}, seed {self.seed}")


def protocol_deviations(replications: Any, max_samples: Any, mm: Any) -> list[str]:
    """How a run (its recorded ``replications``, ``max_samples`` and ``mm``) falls short of the protocol.

    Takes the raw values of a result's settings or of a results-frame row (where a missing value
    may be None or NaN); ``mm=None`` means "not applicable" (the real row generates nothing).
    """
    out = []
    if replications is not None and int(replications) < PROTOCOL_REPLICATIONS:
        out.append(f"{int(replications)} replications instead of {PROTOCOL_REPLICATIONS}")
    if max_samples is not None and not (isinstance(max_samples, float) and math.isnan(max_samples)):
        out.append(f"at most {int(max_samples)} samples per replication instead of the whole split")
    if mm is False:
        out.append("no MultiModality")
    return out


@dataclass(frozen=True)
class EvalResult:
    """Per-replication metric values of one evaluated model, and the settings that produced them."""

    name: str                                        # table row label
    values: Mapping[str, tuple[float, ...]]          # metric (from METRICS) -> one value per replication
    settings: Mapping[str, Any] = field(default_factory=dict)  # EvalSettings fields + kind, samples, weights, evaluator, data

    def summary(self) -> dict[str, tuple[float, float]]:
        """``metric -> (mean, 95% half-width)`` over the replications (only metrics computed)."""
        out = {}
        for m in METRICS:
            if m in self.values:
                mean, half = M.mean_ci(np.asarray(self.values[m], dtype=np.float64))
                out[m] = (float(mean), float(half))
        return out
