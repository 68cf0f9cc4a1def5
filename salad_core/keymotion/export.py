"""Export a KeyMotion training root (``kf_vae/``, ``pst/``, ``mmae/``) as a pipeline folder with its run records.

The folder is what :meth:`KeyMotionPipeline.from_pretrained` loads and what ships in
``salad_core/weights/keymotion``: the three models (each stage's ``best`` checkpoint, else ``latest``; fp16 by
default), ``keymotion.json`` (with the chosen default guidance) and ``runs.json``, which keeps for each stage the
checkpoint used, its step, the stage's training config and its last training and validation log lines, so that a
model card can say exactly what was shipped.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping

import torch

from salad_core.io import atomic_write_text
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.train import STAGES
from salad_core.sampling import Guidance
from salad_core.train.assemble import run_checkpoint

__all__ = ["run_record", "stage_records", "export_pipeline", "export_with_component", "export_with_components"]


def run_record(run: str | os.PathLike) -> dict[str, Any]:
    """One stage's entry of ``runs.json`` for the training run folder ``run``: ``checkpoint`` (the one an export
    loads, :func:`~salad_core.train.assemble.run_checkpoint`: "best" if the run has one, else "latest"),
    ``step``, ``config`` (the run's ``config.json``), ``last_log`` and ``last_val`` (its last training and
    validation lines of ``log.jsonl``, ``{}`` if none).

    Raises
    ------
    FileNotFoundError
        The run folder, its checkpoint record or its ``config.json`` is missing (the message names it).
    """
    run = Path(run)
    if not run.is_dir():
        raise FileNotFoundError(f"{run} does not exist")
    stem = run_checkpoint(run).name
    if not (run / f"{stem}.json").is_file():
        raise FileNotFoundError(f"{run} has no record of its {stem} checkpoint ({stem}.json)")
    if not (run / "config.json").is_file():
        raise FileNotFoundError(f"{run / 'config.json'} is missing")
    log_file = run / "log.jsonl"
    lines = [json.loads(line) for line in log_file.read_text().splitlines() if line.strip()] \
        if log_file.is_file() else []
    train_lines = [line for line in lines if "loss" in line]
    val_lines = [line for line in lines if "val_loss" in line]
    meta = json.loads((run / f"{stem}.json").read_text()).get("meta", {})
    return {"checkpoint": stem, "step": meta.get("step"),
            "config": json.loads((run / "config.json").read_text()),
            "last_log": train_lines[-1] if train_lines else {},
            "last_val": val_lines[-1] if val_lines else {}}


def stage_records(work: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """``runs.json``'s content for the training root ``work``: per stage :func:`run_record` of ``work/<stage>``.

    Raises
    ------
    FileNotFoundError
        A stage folder, its checkpoint record or its ``config.json`` is missing (the message names it).
    """
    root = Path(work)
    records = {}
    for stage in STAGES:
        if not (root / stage).is_dir():
            raise FileNotFoundError(f"{root / stage} does not exist: {root} is not a finished KeyMotion training "
                                    f"root (it needs {', '.join(STAGES)})")
        records[stage] = run_record(root / stage)
    return records


def export_pipeline(work: str | os.PathLike, dest: str | os.PathLike, *, guidance: Guidance | None = None,
                    dtype: torch.dtype | None = torch.float16) -> Path:
    """Write the training root ``work`` as a pipeline folder ``dest`` (created) and return it.

    Parameters
    ----------
    work : path
        A KeyMotion training root (``salad train keymotion --out``), or a pipeline folder (its ``runs.json``, if
        any, is copied).
    dest : path
        The pipeline folder; files of the same names are replaced.
    guidance : Guidance, optional
        The default guidance stored in ``keymotion.json`` (default: the pipeline's, ``Guidance(7.5)``).
    dtype : torch.dtype or None
        Storage type of the floating weights (fp16 by default; None keeps float32).
    """
    root = Path(work)
    if (root / "keymotion.json").is_file() and not any((root / stage).is_dir() for stage in STAGES):
        # a pipeline folder exported before (e.g. the shipped one): its own records travel with it
        records = json.loads((root / "runs.json").read_text()) if (root / "runs.json").is_file() else None
    else:
        records = stage_records(root)              # first: a missing stage fails before anything is written
    pipe = KeyMotionPipeline.from_pretrained(work)
    if guidance is not None:
        if not isinstance(guidance, Guidance):
            raise TypeError(f"guidance must be a salad_core.sampling.Guidance, got {type(guidance).__name__}")
        pipe.guidance = guidance
    out = pipe.save_pretrained(dest, dtype=dtype)
    if records is not None:
        atomic_write_text(out / "runs.json", json.dumps(records, indent=2) + "\n")
    return out


def export_with_component(source: str | os.PathLike, stage: str, run: str | os.PathLike, dest: str | os.PathLike, *,
                          text_encoder: Any = None) -> Path:
    """Write the KeyMotion pipeline folder ``source`` to ``dest`` (fp16) with its ``stage`` model ("kf_vae",
    "pst" or "mmae") replaced by the one of the run folder ``run`` (its ``best``, else ``latest``), the
    other two components, the guidance and the settings unchanged: how a fine-tuned stage is assembled for
    measuring (``lab/scripts/keymotion/finetune_keymotion.py``). ``dest/runs.json`` keeps ``source``'s run records (if it has
    them) with the ``stage`` entry replaced by :func:`run_record` of ``run``, so a shipped pipeline says which run
    each of its models came from. Returns ``dest``."""
    return export_with_components(source, {stage: run}, dest, text_encoder=text_encoder)


def export_with_components(source: str | os.PathLike, runs: Mapping[str, str | os.PathLike],
                           dest: str | os.PathLike, *, text_encoder: Any = None) -> Path:
    """:func:`export_with_component` for several stages at once, ``runs`` mapping each replaced stage to its run
    folder: how a PST trained on another keyframe VAE is assembled (``{"kf_vae": VAE_RUN, "pst": PST_RUN}``; one
    stage at a time could not be, since the source's PST does not fit the new VAE's latents). The assembled
    pipeline is checked as :class:`KeyMotionPipeline` checks any (latent shape, skeleton, text width) before
    anything is written.

    Raises
    ------
    ValueError
        ``runs`` is empty or names a stage that is not a KeyMotion component, a run holds another kind of model,
        or the assembled models do not fit each other (the message says how).
    """
    from salad_core.io import load_model
    from salad_core.keymotion.pipeline import COMPONENTS

    if not runs:
        raise ValueError("runs is empty: name at least one stage to replace")
    for stage in runs:
        if stage not in COMPONENTS:
            raise ValueError(f"stage={stage!r} is not a KeyMotion component; use one of {sorted(COMPONENTS)}")
    pipe = KeyMotionPipeline.from_pretrained(source, **({"text_encoder": text_encoder} if text_encoder else {}))
    # first: a run without its records fails before anything is written
    new_records = {stage: run_record(run) for stage, run in runs.items()}
    for stage, run in runs.items():
        checkpoint = run_checkpoint(run)
        kind = json.loads(checkpoint.with_suffix(".json").read_text()).get("type")
        if kind != COMPONENTS[stage]:
            raise ValueError(f"{run} holds a {kind!r} model, not the {stage} ({COMPONENTS[stage]!r})")
        model, _, _ = load_model(checkpoint)
        setattr(pipe, stage, model.eval())
    pipe._check_compatible()
    source_records = Path(source) / "runs.json"
    records = json.loads(source_records.read_text()) if source_records.is_file() else {}
    records.update(new_records)
    out = pipe.save_pretrained(dest, dtype=torch.float16)
    atomic_write_text(out / "runs.json", json.dumps(records, indent=2) + "\n")
    return out
