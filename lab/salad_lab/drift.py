"""How far one model's score moves between the study's stages, against the gaps between rows.

A staged group evaluates every variant at each stage with the same protocol (same crops, captions and noise),
so two readings of one evaluation file series can be compared directly:

* the **gap** of a paper pair at a stage: the paired advantage of the first row over the second
  (:func:`salad_lab.orderings.paired_advantage`; positive: the first row is better);
* the **drift** of a row: how much its own mean moves from one evaluated stage to the next. The study's
  learning rate is constant after warm-up (``lab/configs/ablations_v2.json``), so late checkpoints keep moving;
  a gap smaller than the drift of the rows it compares is a property of the checkpoint the budget ends
  on, not of the variants.

Everything here is read from evaluation files (``<group>@<steps>.json``); nothing is measured.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from .orderings import BETTER, TABLE_METRICS, paired_advantage

__all__ = ["load_group_evaluations", "row_drift", "pair_gaps", "drift_markdown"]


def load_group_evaluations(root: str | os.PathLike | None, group: str) -> list[dict[str, Any]]:
    """Every evaluation file ``root/evaluations/<group>@*.json`` (default root: the shipped ablation folder),
    sorted by steps. An error names the folder when there are none."""
    from .study import ablations_dir

    folder = (Path(root) if root is not None else ablations_dir()) / "evaluations"
    docs = sorted((json.loads(p.read_text()) for p in folder.glob(f"{group}@*.json")), key=lambda d: d["steps"])
    if not docs:
        raise FileNotFoundError(f"no evaluation of group {group!r} in {folder}")
    return docs


def row_drift(evaluations: Sequence[Mapping[str, Any]], metric: str) -> dict[str, dict[str, Any]]:
    """Per row: its mean of ``metric`` at every stage and its change between consecutive stages.

    Values are in the evaluation files' units (MPJPE in metres).

    Returns
    -------
    dict
        ``{variant: {"steps": [s1, ...], "means": [m1, ...], "changes": [m2 - m1, ...], "last_change": float}}``
        for the rows present at every stage; ``last_change`` is the change into the final stage (0 with one
        stage).
    """
    if metric not in BETTER:
        raise ValueError(f"metric={metric!r} is not compared; allowed: {sorted(BETTER)}")
    variants = [v for v in evaluations[-1]["rows"] if all(v in doc["rows"] for doc in evaluations)]
    out: dict[str, dict[str, Any]] = {}
    for v in variants:
        means = [float(doc["rows"][v]["summary"][metric][0]) for doc in evaluations]
        changes = [b - a for a, b in zip(means, means[1:])]
        out[v] = {"steps": [int(doc["steps"]) for doc in evaluations], "means": means, "changes": changes,
                  "last_change": changes[-1] if changes else 0.0}
    return out


def pair_gaps(evaluations: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Every paper pair of the group's tables, per metric: its paired advantage at each stage and the drift of
    its two rows into the final stage.

    Returns
    -------
    list of dict
        ``{"table", "a", "b", "metric", "gaps": [(mean, half), ...] per stage, "drift_a", "drift_b",
        "within_drift": bool}``; ``within_drift`` is true when the final gap's size is smaller than the larger
        of the two rows' own changes into the final stage.
    """
    final = evaluations[-1]
    metrics = TABLE_METRICS[final["kind"]]
    drifts = {metric: row_drift(evaluations, metric) for metric in metrics}
    out = []
    for table, rows in final["tables"].items():
        variants = list(rows)
        first = variants[0]
        for b in variants[1:]:
            for metric in metrics:
                drift = drifts[metric]
                gaps = [paired_advantage(doc["rows"][first]["values"][metric], doc["rows"][b]["values"][metric],
                                         metric) for doc in evaluations]
                da, db = drift[first]["last_change"], drift[b]["last_change"]
                out.append({"table": table, "a": first, "b": b, "metric": metric, "gaps": gaps,
                            "drift_a": da, "drift_b": db,
                            "within_drift": abs(gaps[-1][0]) < max(abs(da), abs(db))})
    return out


def drift_markdown(root: str | os.PathLike | None = None, group: str = "denoisers") -> str:
    """Two markdown tables: each row's mean per stage (with its change into the final stage), and each paper
    pair's paired advantage per stage against its rows' drift. Read from ``root``'s evaluation files."""
    evaluations = load_group_evaluations(root, group)
    steps = [int(doc["steps"]) for doc in evaluations]
    metrics = TABLE_METRICS[evaluations[-1]["kind"]]
    if len(steps) < 2:
        raise ValueError(f"group {group!r} has one evaluated stage ({steps[0]:,} steps): no drift to read")
    lines = [f"**Each row per stage** (group `{group}`; the mean of the stage's replications; the last column is "
             f"the change from {steps[-2]:,} to {steps[-1]:,} steps)", ""]
    head = "| variant | metric | " + " | ".join(f"{s:,}" for s in steps) + " | change into the last stage |"
    lines += [head, "|" + "---|" * (len(steps) + 3)]
    for metric in metrics:
        for v, d in row_drift(evaluations, metric).items():
            lines.append(f"| `{v}` | {metric} | " + " | ".join(f"{m:.3f}" for m in d["means"])
                         + f" | {d['last_change']:+.3f} |")
    lines += ["", "**Each paper pair**: the first row's paired advantage over the second (positive: better, "
              "95 % half-width) per stage, and whether the final gap is smaller than what the last stage interval "
              "did to either row on its own", ""]
    lines += ["| pair | metric | " + " | ".join(f"{s:,}" for s in steps)
              + " | drift of the two rows | gap within drift |", "|" + "---|" * (len(steps) + 4)]
    for p in pair_gaps(evaluations):
        cells = " | ".join(f"{m:+.3f} ± {h:.3f}" for m, h in p["gaps"])
        lines.append(f"| `{p['a']}` vs `{p['b']}` | {p['metric']} | {cells} | "
                     f"{p['drift_a']:+.3f} / {p['drift_b']:+.3f} | "
                     f"{'yes' if p['within_drift'] else 'no'} |")
    return "\n".join(lines).strip() + "\n"
