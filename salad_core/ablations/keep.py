"""Keep a stopped VAE group of a staged study in the repository, and restore it on another machine.

A staged study takes longer than one working session, and its run folder (``work``) lives outside the
repository, where a new machine loses it. The denoiser groups need only what a stopped VAE group
*decided*: its evaluations and its VAEs at the final stage, in shipping form (fp16, the form the
denoisers learn on: :func:`~salad_core.ablations.runner.run_study` freezes the packaged models). So
when a VAE group stops, :func:`keep_group` copies exactly that into a folder of the repository
(``studies/<recipe name>/``)::

    vae_<name>/                     the stage's packaged VAE (vae.*, stats.safetensors, runs.json)
    evaluations/<group>@<steps>.json  every evaluated stage of the group (the stop rule's history)
    groups.json                     {group: {steps, reason, stages, fingerprint}}

and :func:`restore_group` puts it back into a fresh ``work`` folder, so the study goes on with the
denoisers instead of training the VAEs again. The files are byte-identical to what the final ship copies
into ``salad_core/weights/ablations`` (git stores them once).

The ``fingerprint`` (:func:`group_fingerprint`) hashes the group's training configs, stages, evaluation
protocol and stop rule: a kept group whose recipe has changed since is refused with an error that says
so, never restored silently.
"""
from __future__ import annotations

import hashlib
import json
import logging
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import Any

from .stage_eval import evaluation_path, load_evaluation, stage_dir
from .staged import StagedRecipe, StudyGroup
from .study import plan_jobs

__all__ = ["group_fingerprint", "keep_group", "restore_group", "kept_groups", "KEPT_INDEX"]

log = logging.getLogger(__name__)

#: The index file of a keep folder.
KEPT_INDEX = "groups.json"


def group_fingerprint(recipe: StagedRecipe, group: StudyGroup) -> str:
    """SHA-256 of what decides a group's models and evaluations: every variant's training config document
    (model, train, diffusion), the stages, the evaluation settings and the stop rule."""
    configs = {j.variant.name: j.config for j in plan_jobs(recipe.base, "/work")
               if j.variant.name in group.variants}
    doc = {"group": group.name, "kind": group.kind, "stages": list(group.stages), "tables": group.tables,
           "evaluation": asdict(group.evaluation), "stop": asdict(recipe.stop), "configs": configs}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def kept_groups(keep: str | Path) -> dict[str, dict[str, Any]]:
    """The groups kept in ``keep`` (``{}`` when the folder or its index does not exist)."""
    index = Path(keep) / KEPT_INDEX
    return json.loads(index.read_text()) if index.is_file() else {}


def keep_group(recipe: StagedRecipe, group: StudyGroup, steps: int, reason: str, evaluated: list[int],
               work: str | Path, keep: str | Path) -> Path:
    """Copy a stopped VAE group's final models and its evaluations from ``work`` into ``keep``.

    Parameters
    ----------
    recipe, group
        The study and the group (``kind == "vae"``).
    steps : int
        The stage where the group stopped (its models there are copied).
    reason : str
        The stop rule's reason (``"stable"`` or ``"budget"``).
    evaluated : list of int
        The stages evaluated up to the stop, in order (their evaluation files are copied).
    work, keep : path
        The study folder and the keep folder.
    """
    from salad_core.io import atomic_write_text

    if group.kind != "vae":
        raise ValueError(f"group {group.name!r} is a {group.kind} group; only VAE groups are kept (the denoiser "
                         "groups end in the shipped study)")
    work, keep = Path(work), Path(keep)
    models = stage_dir(work, group, steps) / "models"
    (keep / "evaluations").mkdir(parents=True, exist_ok=True)
    for name in group.variants:
        src = models / f"vae_{name}"
        if not (src / ".packaged").is_file():
            raise FileNotFoundError(f"{src} is not packaged: the stage {group.stage_name(steps)} has not been "
                                    "packaged yet")
        dest = keep / f"vae_{name}"
        shutil.rmtree(dest, ignore_errors=True)
        shutil.copytree(src, dest, ignore=shutil.ignore_patterns(".packaged"))
    for s in evaluated:
        shutil.copy2(evaluation_path(work, group, s), keep / "evaluations")
    index = kept_groups(keep)
    index[group.name] = {"steps": int(steps), "reason": reason, "stages": [int(s) for s in evaluated],
                         "variants": list(group.variants), "fingerprint": group_fingerprint(recipe, group)}
    atomic_write_text(keep / KEPT_INDEX, json.dumps(index, indent=2) + "\n")
    log.info("kept group %s (stopped at %d steps, %s) in %s", group.name, steps, reason, keep)
    return keep


def restore_group(recipe: StagedRecipe, group: StudyGroup, keep: str | Path, work: str | Path) -> bool:
    """Put a kept group back into ``work``; returns False when ``keep`` does not hold it.

    What ``work`` already has is left as it is (an evaluation file or a packaged model present is not
    overwritten). Raises ``ValueError`` when the kept group was made by another recipe (fingerprint).
    """
    keep, work = Path(keep), Path(work)
    entry = kept_groups(keep).get(group.name)
    if entry is None:
        return False
    want = group_fingerprint(recipe, group)
    if entry.get("fingerprint") != want:
        raise ValueError(f"the group {group.name!r} kept in {keep} was trained by another recipe than "
                         f"{recipe.path} (fingerprint {str(entry.get('fingerprint'))[:12]} against {want[:12]}): "
                         f"remove {keep / KEPT_INDEX}'s entry to train the group again")
    steps = int(entry["steps"])
    for s in entry["stages"]:
        dest = evaluation_path(work, group, s)
        if load_evaluation(work, group, s) is None:
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(keep / "evaluations" / dest.name, dest)
    models = stage_dir(work, group, steps) / "models"
    for name in group.variants:
        dest = models / f"vae_{name}"
        if (dest / ".packaged").is_file():
            continue
        shutil.rmtree(dest, ignore_errors=True)
        shutil.copytree(keep / f"vae_{name}", dest)
        (dest / ".packaged").write_text(f"{group.stage_name(steps)} (restored from {keep})\n")
    log.info("restored group %s (stopped at %d steps, %s) from %s", group.name, steps, entry["reason"], keep)
    return True
