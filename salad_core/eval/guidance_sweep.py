"""Choosing a model's default guidance from one sweep over the T2M metrics and the physical measures.

A model's default guidance weight (and its options, rescale and interval) is chosen from
a sweep over FID, R-precision and the physical-plausibility benchmark, not taken from the paper (whose
w = 7.5 was chosen for its own model). This module runs that sweep and applies one fixed, documented
rule (:func:`choose`), so the choice is reproducible and printed with its reasons:

* :func:`guidance_grid` spells the candidates (every combination of weights, rescales, intervals,
  thresholds and projections);
* :func:`run_sweep` evaluates each candidate with the T2M protocol (:mod:`.protocol`: R-precision,
  FID with their 95 % intervals over replications) and the physics benchmark (:mod:`.physics_prompts`:
  bone error, foot skating, floor penetration, the jump checks, seed diversity) on the same weights;
* :func:`choose` picks the default; :func:`sweep_markdown` is the table the CLI prints.

``salad eval --guidance-sweep --data CORPUS [--weights DIR] --scales 1.5,2.5,4 --rescales 0,0.7`` runs it.
Everything here is measured on a procedural corpus's test split and the benchmark prompts: never on the
real evaluation clips.
"""
from __future__ import annotations

import itertools
import json
import math
import re
import time
from dataclasses import asdict
from os import PathLike
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from salad_core.io import atomic_write_text
from salad_core.sampling import Guidance

from .physics_prompts import BenchSettings, run_benchmark, targets
from .protocol import evaluate_generator, evaluate_real
from .settings import EvalSettings

__all__ = ["guidance_grid", "guidance_label", "FixedGuidance", "run_sweep", "sweep_fingerprint", "choose", "sweep_markdown",
           "sweep_frame",
           "R_PRECISION_TOLERANCE", "PHYSICS_TARGETS"]

#: A candidate stays eligible while its R-precision top-3 is within this of the sweep's best (the
#: protocol's 95 % intervals at 20 replications are about +-0.005 on the procedural corpus; 0.01 keeps
#: candidates the metric cannot tell apart).
R_PRECISION_TOLERANCE = 0.01

#: The issue-20 targets (texts of :func:`~salad_core.eval.physics_prompts.targets`) counted by the rule.
PHYSICS_TARGETS = ("bone error p95", "bone error max", "foot skating <=", "ground penetration", "jump heights")


def guidance_grid(scales: Iterable[float], rescales: Iterable[float] = (0.0,),
                  intervals: Iterable[tuple[float, float] | None] = (None,),
                  thresholds: Iterable[tuple[float, float] | None] = (None,),
                  projections: Iterable[tuple[float, float | None] | None] = (None,)) -> list[Guidance]:
    """Every combination of weight ``w``, rescale ``phi``, interval, threshold ``(p, bound)`` and
    projection ``(eta, norm_cap)`` (None: that refinement off), in that nesting order.

    Returns
    -------
    list of Guidance, the product of the lengths long (each validated).
    """
    grid = [Guidance(float(w), float(phi), iv, **_threshold_kwargs(th), **_projection_kwargs(pr))
            for w, phi, iv, th, pr in itertools.product(scales, rescales, intervals, thresholds, projections)]
    if not grid:
        raise ValueError("the guidance grid is empty: give at least one scale, rescale and interval")
    if len({guidance_label(g) for g in grid}) != len(grid):
        raise ValueError("the guidance grid repeats a candidate; give distinct scales, rescales, intervals, "
                         "thresholds and projections")
    return grid


def _threshold_kwargs(item: tuple[float, float] | None) -> dict[str, float]:
    return {} if item is None else {"threshold": float(item[0]), "threshold_bound": float(item[1])}


def _projection_kwargs(item: tuple[float, float | None] | None) -> dict[str, float | None]:
    return {} if item is None else {"projection": float(item[0]),
                                    "norm_cap": None if item[1] is None else float(item[1])}


def guidance_label(g: Guidance) -> str:
    """Short row label, e.g. ``"w=4"``, ``"w=7.5 phi=0.7"``, ``"w=4 t/T in [0,0.5]"``,
    ``"w=7.5 thr=0.995 b=4"``, ``"w=7.5 eta=0 cap=5"``."""
    label = f"w={g.scale:g}"
    if g.rescale:
        label += f" phi={g.rescale:g}"
    if g.interval is not None:
        label += f" t/T in [{g.interval[0]:g},{g.interval[1]:g}]"
    if g.threshold is not None:
        label += f" thr={g.threshold:g}" + (f" b={g.threshold_bound:g}" if g.threshold_bound != 1.0 else "")
    if g.projection is not None:
        label += f" eta={g.projection:g}" + (f" cap={g.norm_cap:g}" if g.norm_cap is not None else "")
        label += f" beta={g.momentum:g}" if g.momentum else ""
    return label


class FixedGuidance:
    """A generator that samples ``pipe`` with one :class:`Guidance`, whatever weight it is asked for.

    The T2M protocol passes a float ``guidance_scale``; the sweep needs the whole Guidance (rescale,
    interval), so this wrapper replaces it. Calls go to ``pipe(prompts, lengths=, seed=,
    guidance_scale=self.guidance, num_steps=, [solver=])``.
    """

    def __init__(self, pipe: Callable[..., Any], guidance: Guidance) -> None:
        if not isinstance(guidance, Guidance):
            raise TypeError(f"guidance must be a salad_core.sampling.Guidance, got {type(guidance).__name__}")
        self.pipe, self.guidance = pipe, guidance
        self.source = getattr(pipe, "source", None)

    def __call__(self, prompts: Sequence[str], lengths: Sequence[int] | None = None, seed: Any = 0,
                 guidance_scale: float | None = None, num_steps: int = 50, **kwargs: Any) -> Any:
        return self.pipe(prompts, lengths=lengths, seed=seed, guidance_scale=self.guidance, num_steps=num_steps,
                         **kwargs)


def _t2m_row(result) -> dict[str, Any]:
    summary = result.summary()
    row = {}
    for key, name in (("r_precision_top3", "R-precision top-3"), ("r_precision_top1", "R-precision top-1"),
                      ("fid", "FID"), ("diversity", "Diversity"), ("mm_dist", "MM-Dist")):
        if name in summary:
            mean, ci = summary[name]
            row[key] = {"mean": float(mean), "ci": float(ci)}
    return row


def _physics_row(result: Mapping, name: str) -> dict[str, Any]:
    agg = result["generators"][name]["aggregate"]
    passed = {}
    for t in targets(result):
        key = next((k for k in PHYSICS_TARGETS if t["target"].startswith(k)), None)
        if key is not None and name in t["cells"]:
            passed[key] = t["cells"][name][1]
    gen = result["generators"][name]
    return {"bone_p95_cm": agg.get("bone_ref_p95_pooled_cm"), "bone_max_cm": agg.get("bone_ref_max_cm"),
            "skate_ms": agg.get("skate_mean_ms"), "penetration_max_cm": agg.get("penetration_max_cm"),
            "seed_diversity_cm": agg.get("seed_diversity_cm"), "checks_passed": gen["checks_passed"],
            "checks_total": gen["checks_total"], "targets": passed,
            "targets_passed": sum(1 for v in passed.values() if v)}


def run_sweep(pipe: Callable[..., Any], guidances: Sequence[Guidance], dataset_root: str | PathLike, evaluator,
              eval_settings: EvalSettings, bench_settings: BenchSettings, *, joints_of: Callable[[Any], list],
              sample_dir: str | PathLike | None = None, log: Callable[[str], None] | None = None,
              store: str | PathLike | None = None, identity: Mapping[str, Any] | None = None) -> dict:
    """Evaluate every candidate guidance with the T2M protocol and the physics benchmark.

    Parameters
    ----------
    pipe : a SALAD (or KeyMotion) pipeline: ``pipe(prompts, lengths=, seed=, guidance_scale=Guidance,
        num_steps=)`` returning an output with ``features`` ``(B, N, D)`` and ``lengths``.
    guidances : the candidates (:func:`guidance_grid`).
    dataset_root : procedural corpus (HumanML3D layout) whose split the protocol reads.
    evaluator : the T2M evaluator of that corpus.
    eval_settings : T2M protocol settings (their ``guidance_scale`` is ignored: each candidate's is used).
    bench_settings : physics benchmark settings (their ``guidance`` is ignored likewise).
    joints_of : ``output -> list of (N_b, J, 3)`` joints the benchmark measures
        (:func:`~salad_core.eval.physics.joints_reader`).
    sample_dir : real clips for the benchmark's reference row (reported, never used by the rule).
    store : folder that keeps each finished candidate (and the real row) as JSON, so that a sweep that was
        stopped (a sweep of a dozen candidates takes hours on a CPU) continues where it stopped when run
        again: a kept result is reused only if it was measured with the same settings, data, candidate and
        ``identity`` (:func:`sweep_fingerprint`); otherwise it is measured again and replaced.
    identity : what else a kept result must match, e.g. ``{"weights": <digest of the weight files>}``.

    Returns
    -------
    dict (JSON-ready): ``real`` (the protocol's real row), ``rows`` (one per candidate: ``label``,
    ``guidance``, ``t2m``, ``physics``, ``seconds``, ``reused``), ``settings``, ``references`` (the benchmark's
    real rows).
    """
    say = log or (lambda s: None)
    if not guidances:
        raise ValueError("guidances is empty; build candidates with guidance_grid(...)")
    keep = _SweepStore(store, eval_settings, bench_settings, dataset_root, identity)
    real = keep.load("real", None)
    if real is None:
        real = keep.save("real", None, _t2m_row(evaluate_real(dataset_root, evaluator, eval_settings)))
    rows, references = [], None

    def physics_gen(gen):
        return lambda texts, lengths, seed: joints_of(gen(texts, lengths=lengths, seed=[seed] * len(texts),
                                                          num_steps=bench_settings.steps))

    for g in guidances:
        label = guidance_label(g)
        kept = keep.load(label, g)
        if kept is not None:
            rows.append(dict(kept["row"], reused=True))
            references = kept["references"]
            say(f"{label}: measured before with the same settings ({keep.path(label)}): reused")
            continue
        gen = FixedGuidance(pipe, g)
        t0 = time.perf_counter()
        t2m = evaluate_generator(gen, dataset_root, evaluator, eval_settings, name=label)
        seconds = time.perf_counter() - t0
        say(f"{label}: T2M protocol done ({seconds:.0f} s)")
        bench = run_benchmark({label: physics_gen(gen)}, bench_settings, data_root=dataset_root,
                              sample_dir=sample_dir, log=say)
        row = {"label": label, "guidance": g.to_json_dict(), "t2m": _t2m_row(t2m), "physics": _physics_row(bench, label),
               "seconds": round(seconds + bench["generators"][label]["seconds"], 1)}
        references = bench["references"]
        keep.save(label, g, {"row": row, "references": references})
        rows.append(dict(row, reused=False))
    return {"real": real, "rows": rows, "references": references,
            "settings": {"t2m": eval_settings.describe(), "bench": asdict(bench_settings), "rule": rule_text()}}


def sweep_fingerprint(eval_settings: EvalSettings, bench_settings: BenchSettings, dataset_root: str | PathLike,
                      guidance: Guidance | None, identity: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """What a kept sweep result must have been measured with to be reused (JSON-ready)."""
    doc = {"t2m": eval_settings.describe(), "bench": asdict(bench_settings), "data": str(Path(dataset_root).resolve()),
           "guidance": None if guidance is None else guidance.to_json_dict(), "identity": dict(identity or {})}
    return json.loads(json.dumps(doc, default=str))                 # as kept on disk (tuples become lists)


class _SweepStore:
    """Per-candidate JSON files of :func:`run_sweep` (no-op without a folder)."""

    def __init__(self, folder, eval_settings, bench_settings, dataset_root, identity) -> None:
        self.folder = None if folder is None else Path(folder)
        self.args = (eval_settings, bench_settings, dataset_root)
        self.identity = identity

    def path(self, label: str) -> Path:
        slug = re.sub(r"[^A-Za-z0-9.=-]+", "_", label).strip("_")
        return self.folder / f"{slug}.json"

    def load(self, label: str, guidance: Guidance | None) -> Any:
        if self.folder is None or not self.path(label).is_file():
            return None
        doc = json.loads(self.path(label).read_text(encoding="utf-8"))
        want = sweep_fingerprint(*self.args, guidance, self.identity)
        return doc["result"] if doc.get("fingerprint") == want else None

    def save(self, label: str, guidance: Guidance | None, result: Any) -> Any:
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            doc = {"fingerprint": sweep_fingerprint(*self.args, guidance, self.identity), "result": result}
            atomic_write_text(self.path(label), json.dumps(doc, indent=1) + "\n")
        return result


def rule_text() -> str:
    """The selection rule of :func:`choose`, in words (printed with every sweep)."""
    return (f"eligible: R-precision top-3 within {R_PRECISION_TOLERANCE:g} of the sweep's best; among them the "
            f"most physics targets passed ({', '.join(PHYSICS_TARGETS)}), then the lowest FID, then the lowest "
            "bone error p95")


def choose(rows: Sequence[Mapping[str, Any]]) -> tuple[int, str]:
    """The index of the default guidance among ``rows`` (of :func:`run_sweep`) and why.

    The rule (:func:`rule_text`): text faithfulness first (R-precision top-3 within
    :data:`R_PRECISION_TOLERANCE` of the best candidate), then physical plausibility (number of
    issue-20 targets passed), then distribution quality (FID), then the bone-length error.
    """
    if not rows:
        raise ValueError("no sweep rows to choose from")

    def num(v: Any, default: float) -> float:
        return default if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)

    r3 = [num(r["t2m"].get("r_precision_top3", {}).get("mean"), -math.inf) for r in rows]
    best = max(r3)
    eligible = [i for i, v in enumerate(r3) if v >= best - R_PRECISION_TOLERANCE]
    key = (lambda i: (-rows[i]["physics"]["targets_passed"], num(rows[i]["t2m"].get("fid", {}).get("mean"), math.inf),
                      num(rows[i]["physics"]["bone_p95_cm"], math.inf)))
    pick = min(eligible, key=key)
    r = rows[pick]
    why = (f"{r['label']}: R-precision top-3 {r3[pick]:.3f} (best {best:.3f}; {len(eligible)} of {len(rows)} "
           f"candidates within {R_PRECISION_TOLERANCE:g}), {r['physics']['targets_passed']} of "
           f"{len(PHYSICS_TARGETS)} physics targets, FID {num(r['t2m'].get('fid', {}).get('mean'), math.nan):.3f}")
    return pick, why


def _cell(v: Any, fmt: str) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return fmt.format(v)


def sweep_markdown(result: Mapping[str, Any], chosen: int | None = None) -> str:
    """A Markdown table of a :func:`run_sweep` result (one row per candidate; ``chosen`` marked)."""
    head = ("| guidance | R-prec. top-3 | FID | bone p95 / max (cm) | skating (m/s) | penetration (cm) | "
            "checks | targets | diversity (cm) |")
    lines = [head, "|" + "---|" * 9]
    real = result.get("real", {})
    if real:
        lines.append(f"| real motion | {_ci(real.get('r_precision_top3'))} | {_ci(real.get('fid'))} | | | | | | |")
    for i, r in enumerate(result["rows"]):
        p = r["physics"]
        mark = " **(chosen)**" if i == chosen else ""
        lines.append(
            f"| {r['label']}{mark} | {_ci(r['t2m'].get('r_precision_top3'))} | {_ci(r['t2m'].get('fid'))} | "
            f"{_cell(p['bone_p95_cm'], '{:.1f}')} / {_cell(p['bone_max_cm'], '{:.1f}')} | "
            f"{_cell(p['skate_ms'], '{:.3f}')} | {_cell(p['penetration_max_cm'], '{:.1f}')} | "
            f"{p['checks_passed']}/{p['checks_total']} | {p['targets_passed']}/{len(PHYSICS_TARGETS)} | "
            f"{_cell(p['seed_diversity_cm'], '{:.1f}')} |")
    lines.append("")
    lines.append(f"Rule: {rule_text()}.")
    return "\n".join(lines)


def sweep_frame(result: Mapping[str, Any], name: str = "SALAD"):
    """A :func:`run_sweep` result (or its saved ``guidance_sweep.json``) as a pandas DataFrame that
    :func:`salad_viz.plots.plot_cfg_sweep` draws.

    One row per candidate: ``name`` (``"<name> w=<scale>"``, with ``" rescale <phi>"`` / ``" interval"`` /
    ``" threshold <p>"`` / ``" projection <eta>"`` in the stem when set, so that each such setting is its own
    line), ``kind``
    ("generated"), ``guidance_scale``, ``rescale``, the T2M means with their half-widths in
    ``"<column> ±"`` (``R-precision top-1``, ``R-precision top-3``, ``FID``, ``MM-Dist``, ``Diversity``),
    the physics columns ``bone p95 (cm)``, ``bone max (cm)``, ``skating (m/s)``, ``penetration (cm)``,
    ``checks``, and ``chosen`` (bool). Then the real row (``kind`` "real", no guidance) when present.
    """
    import pandas as pd

    t2m_cols = (("r_precision_top1", "R-precision top-1"), ("r_precision_top3", "R-precision top-3"),
                ("fid", "FID"), ("mm_dist", "MM-Dist"), ("diversity", "Diversity"))
    chosen = (result.get("chosen") or {}).get("index")

    def t2m(cells: Mapping[str, Any]) -> dict[str, float]:
        out = {}
        for key, col in t2m_cols:
            if cells.get(key):
                out[col], out[col + " ±"] = float(cells[key]["mean"]), float(cells[key]["ci"])
        return out

    rows = []
    for i, r in enumerate(result["rows"]):
        g, p = r["guidance"], r["physics"]
        stem = name + (f" rescale {g['rescale']:g}" if g.get("rescale") else "") + (
            " interval" if g.get("interval") else "") + (
            f" threshold {g['threshold']:g}" if g.get("threshold") is not None else "") + (
            f" projection {g['projection']:g}" if g.get("projection") is not None else "")
        rows.append({"name": f"{stem} w={g['scale']:g}", "kind": "generated", "guidance_scale": float(g["scale"]),
                     "rescale": float(g.get("rescale") or 0.0), **t2m(r["t2m"]),
                     "bone p95 (cm)": p.get("bone_p95_cm"), "bone max (cm)": p.get("bone_max_cm"),
                     "skating (m/s)": p.get("skate_ms"), "penetration (cm)": p.get("penetration_max_cm"),
                     "checks": f"{p['checks_passed']}/{p['checks_total']}", "chosen": i == chosen})
    if result.get("real"):
        rows.append({"name": "Real motion", "kind": "real", **t2m(result["real"]), "chosen": False})
    return pd.DataFrame(rows)


def _ci(cell: Mapping[str, float] | None) -> str:
    if not cell:
        return "-"
    return f"{cell['mean']:.3f} ± {cell['ci']:.3f}"
