"""One evaluation point of a staged ablation group: snapshot the runs, package them, score every row.

Folder layout under the study's ``work`` folder, for a stage named ``<group>@<steps>``::

    stages/<group>@<steps>/runs/<run>/      the run's ``latest`` checkpoint at exactly <steps> (float32
                                            "run view": latest.*, config.json, mean_std, latent_stats, log)
    stages/<group>@<steps>/models/<folder>/ what would ship: ``vae_<name>/`` (export_vae) or ``<name>/``
                                            (assemble_pipeline on the frozen VAE), fp16
    evaluations/<group>@<steps>.rows/<variant>.json   one scored row (``_real.json``: the real motions)
    evaluations/<group>@<steps>.json        the whole stage: rows, the real row, orderings, settings

The snapshot freezes the weights of the stage, so training on to the next stage never changes what
an evaluation scored, and the shipped folder is the snapshot of the final stage (the numbers in the
model card are those of the shipped fp16 weights). Every file is written atomically and skipped when
present, so an interrupted evaluation continues with the rows not yet scored.

Rows are scored with one protocol per group (its :class:`~salad_core.eval.settings.EvalSettings`):
denoisers with :func:`~salad_core.eval.protocol.evaluate_generator` (T2M protocol, replications, 95 %
intervals; generation in length groups, :class:`~salad_core.eval.length_buckets.LengthBucketed`),
VAEs with :func:`~salad_core.eval.reconstruction.evaluate_reconstruction` (FID and MPJPE of the
reconstructions of the same crops), both on the ``split`` of the study's corpus.
"""
from __future__ import annotations

import json
import logging
import math
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .orderings import PAPER_PAIRS, TABLE_METRICS, compare, pair_key, paper_ordering
from .staged import StagedRecipe, StudyGroup

__all__ = ["stage_dir", "evaluation_path", "latest_step", "snapshot_run", "package_stage", "evaluate_stage",
           "group_orderings", "load_evaluation", "REAL_ROW"]

log = logging.getLogger(__name__)

#: Row file name of the real motions in a denoiser stage.
REAL_ROW = "_real"
_VIEW_FILES = ("latest.safetensors", "latest.json", "config.json", "mean_std.safetensors",
               "latent_stats.safetensors", "log.jsonl")


def stage_dir(work: str | Path, group: StudyGroup, steps: int) -> Path:
    """``work/stages/<group>@<steps>``."""
    return Path(work) / "stages" / group.stage_name(steps)


def evaluation_path(work: str | Path, group: StudyGroup, steps: int) -> Path:
    """``work/evaluations/<group>@<steps>.json``."""
    return Path(work) / "evaluations" / f"{group.stage_name(steps)}.json"


def load_evaluation(work: str | Path, group: StudyGroup, steps: int) -> dict | None:
    """The stage's evaluation document, or None when it has not been written yet."""
    path = evaluation_path(work, group, steps)
    return json.loads(path.read_text()) if path.is_file() else None


def latest_step(run: str | Path) -> int | None:
    """The step of a run's ``latest`` checkpoint (None when it has none)."""
    meta_path = Path(run) / "latest.json"
    if not meta_path.is_file():
        return None
    meta = json.loads(meta_path.read_text())
    step = meta.get("step", meta.get("meta", {}).get("step"))
    return None if step is None else int(step)


def snapshot_run(run: str | Path, dest: str | Path, steps: int) -> Path:
    """Copy a run's ``latest`` checkpoint (and what loading it needs) to ``dest``, if it is at ``steps``.

    ``dest`` holds no ``best.*``, so :func:`~salad_core.train.assemble.run_checkpoint` and the denoiser
    trainer's ``--vae`` take its ``latest``: the weights of exactly that step. An existing snapshot is
    returned as it is.

    Raises
    ------
    RuntimeError
        When the run's latest checkpoint is not at ``steps`` (not trained that far, or trained past
        the stage without a snapshot of it: the stage's weights are gone).
    """
    run, dest = Path(run), Path(dest)
    if (dest / "latest.safetensors").is_file():
        return dest
    at = latest_step(run)
    if at != int(steps):
        raise RuntimeError(f"run {run} is at step {at}, not at the stage's {steps} steps, and {dest} holds no "
                           "snapshot of that step: " + ("train it first" if at is None or at < steps else
                                                        "its weights of that step are gone; move the run away and "
                                                        "train again"))
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for name in _VIEW_FILES:
        if (run / name).is_file():
            shutil.copy2(run / name, tmp / name)
    tmp.rename(dest)
    return dest


def package_stage(recipe: StagedRecipe, group: StudyGroup, steps: int, work: str | Path,
                  frozen_vaes: Mapping[str, Path] | None = None, text_encoder=None) -> Path:
    """Write ``stages/<stage>/models/``: every variant of the group in its shipping form (fp16).

    Needs the snapshots (``stages/<stage>/runs/``). Denoisers are assembled with their frozen VAE
    (``frozen_vaes``: VAE variant -> the VAE group's packaged model folder). Returns the models folder.
    """
    from salad_core.train.assemble import assemble_pipeline, export_vae

    root = stage_dir(work, group, steps)
    models = root / "models"
    for name in group.variants:
        v = recipe.base.variant(name)
        run_name = f"vae_{name}" if v.kind == "vae" else f"den_{name}"
        folder = models / (f"vae_{name}" if v.kind == "vae" else name)
        if (folder / ".packaged").is_file():
            continue
        view = root / "runs" / run_name
        if v.kind == "vae":
            export_vae(view, folder)
        else:
            if not frozen_vaes or v.vae not in frozen_vaes:
                raise ValueError(f"denoiser {name!r} needs its frozen VAE {v.vae!r}; frozen: {sorted(frozen_vaes or {})}")
            if text_encoder is None:
                from salad_core.text import load_text_encoder

                text_encoder = load_text_encoder(json.loads((view / "config.json").read_text())
                                                 .get("task", {}).get("text_encoder", "minilm"))
            assemble_pipeline(frozen_vaes[v.vae], view, folder, text_encoder=text_encoder)
        (folder / ".packaged").write_text(f"{group.stage_name(steps)}\n")
    return models


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(float(obj)) else None
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    return str(obj)


def _row_doc(result, variant: str, label: str, steps: int, parameters: int | None = None) -> dict:
    summary = result.summary()
    return _jsonable({"variant": variant, "label": label, "steps": steps, "values": dict(result.values),
                      "summary": {m: list(v) for m, v in summary.items()}, "parameters": parameters,
                      "settings": dict(result.settings)})


def _write_json(path: Path, doc: dict) -> None:
    from salad_core.io import atomic_write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(doc, indent=2) + "\n")


def group_orderings(summaries: Mapping[str, Mapping[str, tuple[float, float]]], group: StudyGroup,
                    mode: str = "intervals") -> dict[str, dict[str, Any]]:
    """Every paper pair of the group's tables, per metric: our ordering and the paper's.

    Parameters
    ----------
    summaries : dict
        Variant -> ``{metric: (mean, 95% half-width)}``.
    group : StudyGroup
    mode : {"intervals", "means"}
        How our ordering is read (the paper's is read the same way).

    Returns
    -------
    dict
        :func:`~salad_lab.orderings.pair_key` -> ``{"table", "a", "b", "metric", "ours",
        "paper", "agrees", "separated"}``; ``separated`` says whether our 95 % intervals do not
        overlap. Pairs whose paper rows are not both rows of the recipe's table are left out.
    """
    out: dict[str, dict[str, Any]] = {}
    for table, rows in group.tables.items():
        variant_of = {label: v for v, label in rows.items()}
        for a_row, b_row in PAPER_PAIRS[table]:
            if a_row not in variant_of or b_row not in variant_of:
                continue
            a, b = variant_of[a_row], variant_of[b_row]
            for metric in TABLE_METRICS[group.kind]:
                sa, sb = tuple(summaries[a][metric]), tuple(summaries[b][metric])
                ours = compare(sa, sb, metric, mode)
                paper = paper_ordering(table, a_row, b_row, metric, mode)
                out[pair_key(table, a, b, metric)] = {
                    "table": table, "a": a, "b": b, "metric": metric, "ours": ours, "paper": paper,
                    "agrees": ours == paper, "separated": compare(sa, sb, metric, "intervals") != "="}
    return out


def _score_vae(folder: Path, label: str, data, evaluator, settings, weights: str):
    from salad_core.eval.reconstruction import evaluate_reconstruction
    from salad_core.io import load_model, load_tensors

    vae, _, _ = load_model(folder / "vae")
    stats = load_tensors(folder / "stats.safetensors")
    res = evaluate_reconstruction(vae, stats["mean"].float().numpy(), stats["std"].float().numpy(), data, evaluator,
                                  settings, name=label, weights=weights)
    return res, res.parameters


def _score_denoiser(folder: Path, label: str, data, evaluator, settings, weights: str, text_encoder):
    from salad_core.eval.length_buckets import LengthBucketed
    from salad_core.eval.protocol import evaluate_generator
    from salad_core.pipeline import SaladPipeline

    pipe = SaladPipeline.from_pretrained(folder, text_encoder=text_encoder)
    return evaluate_generator(LengthBucketed(pipe), data, evaluator, settings, name=label, weights=weights), None


def evaluate_stage(recipe: StagedRecipe, group: StudyGroup, steps: int, work: str | Path, data: str | Path,
                   evaluator, text_encoder=None) -> dict:
    """Score every variant of ``group`` at ``steps`` (needs :func:`package_stage`) and write the stage file.

    Rows already written (``evaluations/<stage>.rows/``) are not scored again; an existing stage file
    is returned at once. ``evaluator`` None: the shipped procedural-corpus evaluator, loaded only when
    a row needs scoring.

    Returns
    -------
    dict
        The stage document: ``stage``, ``group``, ``kind``, ``steps``, ``tables``, ``settings``,
        ``rows`` (variant -> row document with per-replication ``values`` and ``summary``),
        ``real`` (denoiser groups: the real motions' row), ``orderings`` (:func:`group_orderings`,
        read with the recipe's stop-rule mode) and ``data``.
    """
    done = load_evaluation(work, group, steps)
    if done is not None:
        return done
    settings = group.evaluation
    models = stage_dir(work, group, steps) / "models"
    rows_dir = evaluation_path(work, group, steps).with_suffix(".rows")
    rows: dict[str, dict] = {}
    tables_of = {v: [t for t, r in group.tables.items() if v in r] for v in group.variants}

    def get_evaluator():
        if evaluator is not None:
            return evaluator
        from salad_core.eval.train_evaluator import load_packaged_evaluator

        return load_packaged_evaluator()[0]          # the shipped procedural-corpus evaluator

    ev = None
    for name in group.variants:
        path = rows_dir / f"{name}.json"
        if path.is_file():
            rows[name] = json.loads(path.read_text())
            continue
        ev = ev if ev is not None else get_evaluator()
        v = recipe.base.variant(name)
        label = v.label
        weights = f"ablation {name} at {steps} steps ({group.stage_name(steps)})"
        log.info("evaluating %s at %d steps", name, steps)
        if group.kind == "vae":
            res, params = _score_vae(models / f"vae_{name}", label, data, ev, settings, weights)
        else:
            if text_encoder is None:
                from salad_core.text import load_text_encoder

                text_encoder = load_text_encoder("minilm")
            res, params = _score_denoiser(models / name, label, data, ev, settings, weights, text_encoder)
        rows[name] = {**_row_doc(res, name, label, int(steps), params), "tables": tables_of[name]}
        _write_json(path, rows[name])
    real = None
    if group.kind == "denoiser":
        path = rows_dir / f"{REAL_ROW}.json"
        if path.is_file():
            real = json.loads(path.read_text())
        else:
            from salad_core.eval.protocol import evaluate_real

            ev = ev if ev is not None else get_evaluator()
            real = _row_doc(evaluate_real(data, ev, settings), REAL_ROW, "Real motion", int(steps))
            _write_json(path, real)
    summaries = {n: {m: tuple(s) for m, s in r["summary"].items()} for n, r in rows.items()}
    doc = _jsonable({"stage": group.stage_name(steps), "group": group.name, "kind": group.kind, "steps": int(steps),
                     "tables": group.tables, "settings": asdict(settings), "data": str(data),
                     "compare": recipe.stop.compare, "rows": rows, "real": real,
                     "orderings": group_orderings(summaries, group, recipe.stop.compare)})
    _write_json(evaluation_path(work, group, steps), doc)
    return doc
