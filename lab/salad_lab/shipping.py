"""Ship a finished staged study: the final stage's models, their evaluations, ``index.json`` and the card.

The shipped folder (default ``salad_core/weights/ablations``) gets, for every group at the stage where
it stopped, the packaged fp16 models of that stage (``vae_<name>/`` and ``<name>/``; the pipelines
point at their VAE's folder instead of a copy), every evaluation document of the study
(``evaluations/<group>@<steps>.json``, the per-replication values the card and the notebooks read),
``index.json`` and ``MODEL_CARD.md`` (:func:`~salad_lab.card.model_card`, which prints the kept study's probes,
:mod:`~salad_lab.probes`; their records stay in the lab, ``lab/records/<recipe name>/probes.json``). The entries of
the previous ``index.json`` are removed first, so no model of an older study stays behind.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any, Mapping

from .card import model_card
from .stage_eval import evaluation_path, stage_dir
from .staged import StagedRecipe
from .study import _share_vae

__all__ = ["ship_study", "folder_size_mb", "share_statistics"]


def folder_size_mb(folder: str | os.PathLike) -> float:
    """Size of every file under ``folder``, in MB (10^6 bytes)."""
    return sum(p.stat().st_size for p in Path(folder).rglob("*") if p.is_file()) / 1e6


def ship_study(recipe: StagedRecipe, outcomes: Mapping[str, Any], out: str | os.PathLike, work: str | os.PathLike, *,
               command: str, data: str = "", probes: Mapping[str, Any] | None = None) -> Path:
    """Write the shipped folder (see the module docstring); every group must have stopped.

    Parameters
    ----------
    recipe : StagedRecipe
    outcomes : dict
        Group name -> :class:`~salad_lab.runner.GroupOutcome`, for every group of the recipe.
    out : path
        The shipped folder.
    work : path
        The study folder (stage snapshots and evaluations).
    command : str
        Quoted in the card as the command that regenerates it all.
    data : str
        The corpus, named in the card.
    probes : dict, optional
        Probe records (:mod:`~salad_lab.probes`, the kept study's ``probes.json``): printed in the card.
    """
    from salad_core.io import atomic_write_text

    out, work = Path(out), Path(work)
    missing = [g.name for g in recipe.groups if g.name not in outcomes]
    open_groups = [n for n, o in outcomes.items() if not o.decision.stop]
    if missing or open_groups:
        raise ValueError(f"cannot ship: groups {missing + open_groups} have not stopped")
    out.mkdir(parents=True, exist_ok=True)
    index_path = out / "index.json"
    if index_path.is_file():
        for name in json.loads(index_path.read_text()):
            shutil.rmtree(out / name, ignore_errors=True)
    shutil.rmtree(out / "evaluations", ignore_errors=True)
    index: dict[str, Any] = {}
    for group in recipe.groups:
        outcome = outcomes[group.name]
        steps = outcome.decision.steps
        models = stage_dir(work, group, steps) / "models"
        for name in group.variants:               # VAEs (earlier groups) are in place before the pipelines
            v = recipe.base.variant(name)
            folder = f"vae_{name}" if v.kind == "vae" else name
            shutil.copytree(models / folder, out / folder, ignore=shutil.ignore_patterns(".packaged"),
                            dirs_exist_ok=True)
            if v.kind == "denoiser":
                _share_vae(out / folder, out / f"vae_{v.vae}")
            index[folder] = {"variant": name, "kind": v.kind, "label": v.label,
                             "table": ", ".join(t for t, rows in group.tables.items() if name in rows),
                             "tables": [t for t, rows in group.tables.items() if name in rows],
                             "vae": f"vae_{v.vae}" if v.vae else None, "steps": steps, "group": group.name,
                             "stop": outcome.decision.reason, "stage": group.stage_name(steps),
                             "evaluation": f"evaluations/{group.stage_name(steps)}.json",
                             "model": v.model, "diffusion": v.diffusion,
                             "paper_rows": {t: rows[name] for t, rows in group.tables.items() if name in rows}}
        (out / "evaluations").mkdir(exist_ok=True)
        for doc in outcome.evaluations:
            shutil.copy2(evaluation_path(work, group, doc["steps"]), out / "evaluations")
    share_statistics(out, index)
    atomic_write_text(index_path, json.dumps(index, indent=2) + "\n")
    if (out / "probes.json").is_file():      # the probe records are the lab's (one store); the card prints them
        (out / "probes.json").unlink()
    size = folder_size_mb(out) - ((out / "MODEL_CARD.md").stat().st_size / 1e6 if (out / "MODEL_CARD.md").is_file() else 0)
    card = model_card(outcomes, command=command, recipe_path=recipe.path, data=data, size_mb=size,
                      date=time.strftime("%Y-%m-%d"), probes=probes)
    atomic_write_text(out / "MODEL_CARD.md", card)
    return out


def share_statistics(out: Path, index: dict[str, Any]) -> int:
    """Store byte-identical ``stats.safetensors`` files of the shipped folders once (the first folder in ``index``
    order keeps its own): a pipeline's ``pipeline.json`` then names the kept file (``../<folder>/stats.safetensors``),
    a VAE folder's ``index`` entry does (``"stats": "<folder>/stats.safetensors"``, read by
    :func:`salad_core.ablation_models.load_ablation_vae`). Updates ``index`` in place; returns the files removed."""
    from salad_core.io import atomic_write_text

    kept: dict[bytes, str] = {}
    removed = 0
    for folder, entry in index.items():
        path = out / folder / "stats.safetensors"
        if not path.is_file():
            continue
        data = path.read_bytes()
        owner = kept.setdefault(data, folder)
        if owner == folder:
            continue
        pipeline = out / folder / "pipeline.json"
        if entry.get("kind") == "denoiser" and pipeline.is_file():
            doc = json.loads(pipeline.read_text())
            doc["stats"] = f"../{owner}/stats.safetensors"
            atomic_write_text(pipeline, json.dumps(doc, indent=2) + "\n")
        elif entry.get("kind") == "vae":
            entry["stats"] = f"{owner}/stats.safetensors"
        else:
            continue
        path.unlink()
        removed += 1
    return removed
