"""Keep a staged study's groups in the repository, stopped or in progress, and restore them on another machine.

A staged study takes longer than one working session, and its run folder (``work``) lives outside the
repository, where a new machine loses it. The later groups need only what a stopped group *decided*: its
evaluations and its models at the final stage, in shipping form (fp16; the denoisers learn on the packaged
VAEs: :func:`~salad_lab.runner.run_study` freezes them). So when a group stops,
:func:`keep_group` copies exactly that into a folder of the repository (``lab/records/<recipe name>/``)::

    vae_<name>/ or <name>/          the final stage's packaged model (a VAE group's or a denoiser group's)
    evaluations/<group>@<steps>.json  every evaluated stage of the group (the stop rule's history)
    groups.json                     {group: {steps, reason, stopped, stages, variants, fingerprint}}

and :func:`restore_group` puts it back into a fresh ``work`` folder, so the study goes on with the next
group instead of training this one again. The model files are byte-identical to what the final ship copies
into ``salad_core/weights/ablations``, so once the study has shipped the keep folder
(``lab/records/<recipe name>/``) holds only ``groups.json`` and the probe records, and :func:`restore_group`
takes a stopped group's models and evaluations from the shipped folder (each pipeline with its own copy of its
VAE, as the study packaged it): the repository stores every weight file once.

A group that has *not* stopped yet can take several sessions, and a new machine would train it from step
0 again. So after every evaluated stage :func:`keep_progress` keeps, for each of its runs, the weights of
that stage in float16 (a warm start, :mod:`salad_core.train.warm_start`: a sixth of the float32 train state
with its AdamW moments) beside the group's evaluations::

    progress/<group>/<run>.safetensors, .json   the run's weights at the last evaluated stage (fp16)

and :func:`restore_group` puts the evaluations back and each run's weights as its ``warm_start``: the
group goes on from the kept stage (new AdamW moments, the learning rate warmed up again), not from 0.
When the group stops, :func:`keep_group` replaces its progress.

A stage of the denoiser group takes longer than a working session, so a session also keeps its runs *as they
are* before it ends (``keep_progress(..., current=True)``, what ``lab/scripts/ablations/train_ablations.py --keep-now``
does): each run's weights at its latest checkpoint, wherever it is inside a stage, and the snapshots of
stages trained but not evaluated yet (their weights in float16, which is also what packaging makes of them)::

    progress/<group>/<run>.safetensors, .json           the run's weights at its latest step (fp16)
    progress/<group>/snapshots/<steps>/<run>/           a stage's snapshot, not evaluated yet (fp16 weights)

with ``runs`` ({run: kept step}) and ``snapshots`` ({steps: [runs]}) in the index. A run that had not started
is not kept (it starts from 0 again, as it would have). A run continued this way warm-starts inside the
stage, so it re-warms its learning rate at another step than a run that did not stop there; its
``log.jsonl`` records where (the stage's snapshot carries it into the evaluation's folder).

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

from .stage_eval import _VIEW_FILES, evaluation_path, load_evaluation, stage_dir
from .staged import StagedRecipe, StudyGroup
from .study import plan_jobs

__all__ = ["group_fingerprint", "keep_group", "keep_progress", "restore_group", "kept_groups", "KEPT_INDEX"]

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
        The study and the group (a VAE group: the denoisers learn on its models; a denoiser group: what ships).
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

    work, keep = Path(work), Path(keep)
    models = stage_dir(work, group, steps) / "models"
    (keep / "evaluations").mkdir(parents=True, exist_ok=True)
    for name in group.variants:
        src = models / _model_folder(group, name)
        if not (src / ".packaged").is_file():
            raise FileNotFoundError(f"{src} is not packaged: the stage {group.stage_name(steps)} has not been "
                                    "packaged yet")
        dest = keep / _model_folder(group, name)
        shutil.rmtree(dest, ignore_errors=True)
        shutil.copytree(src, dest, ignore=shutil.ignore_patterns(".packaged"))
    for s in evaluated:
        shutil.copy2(evaluation_path(work, group, s), keep / "evaluations")
    index = kept_groups(keep)
    index[group.name] = {"steps": int(steps), "reason": reason, "stopped": True, "stages": [int(s) for s in evaluated],
                         "variants": list(group.variants), "fingerprint": group_fingerprint(recipe, group)}
    atomic_write_text(keep / KEPT_INDEX, json.dumps(index, indent=2) + "\n")
    shutil.rmtree(keep / "progress" / group.name, ignore_errors=True)
    if (keep / "progress").is_dir() and not any((keep / "progress").iterdir()):
        (keep / "progress").rmdir()
    log.info("kept group %s (stopped at %d steps, %s) in %s", group.name, steps, reason, keep)
    return keep


def _model_folder(group: StudyGroup, name: str) -> str:
    """The packaged model's folder name of a variant (as in ``stages/<stage>/models/`` and the shipped study)."""
    return f"vae_{name}" if group.kind == "vae" else name


def _run_name(recipe: StagedRecipe, name: str) -> str:
    return f"vae_{name}" if recipe.base.variant(name).kind == "vae" else f"den_{name}"


def keep_progress(recipe: StagedRecipe, group: StudyGroup, evaluated: list[int], work: str | Path,
                  keep: str | Path, *, current: bool = False) -> Path:
    """Keep a group that has not stopped: its evaluations so far and each run's weights (fp16).

    By default the weights are those of the last evaluated stage, ``evaluated[-1]`` (taken from the stage's
    snapshot ``stages/<group>@<steps>/runs/<run>/latest``). With ``current=True`` (the end of a working
    session) each run is kept at its latest checkpoint in ``work`` when that is beyond the last evaluated
    stage (a run not started yet is left out), and the snapshots of stages not evaluated yet are kept too;
    ``evaluated`` may then be empty.

    Raises ``FileNotFoundError`` when a snapshot or an evaluation of those stages is missing, and
    ``ValueError`` when ``keep`` holds the group as stopped already or there is nothing to keep.
    """
    from salad_core.io import atomic_write_text
    from salad_core.train.warm_start import write_warm_start

    from .stage_eval import latest_step

    work, keep = Path(work), Path(keep)
    if not evaluated and not current:
        raise ValueError(f"group {group.name!r} has no evaluated stage to keep")
    index = kept_groups(keep)
    if index.get(group.name, {}).get("stopped", group.name in index):
        raise ValueError(f"{keep} holds the group {group.name!r} as stopped already; its progress is not kept")
    steps = int(evaluated[-1]) if evaluated else 0
    runs = stage_dir(work, group, steps) / "runs" if evaluated else None
    tmp = keep / "progress" / f".{group.name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    kept_runs: dict[str, int] = {}
    snapshots: dict[str, list[str]] = {}
    for name in group.variants:
        run = _run_name(recipe, name)
        at = latest_step(work / run) if current else None
        if at is not None and at > steps:
            write_warm_start(work / run / "latest", tmp / run)
            kept_runs[run] = at
        elif runs is not None:
            if not (runs / run / "latest.json").is_file():
                raise FileNotFoundError(f"{runs / run} holds no snapshot of the stage {group.stage_name(steps)}")
            write_warm_start(runs / run / "latest", tmp / run)
            kept_runs[run] = steps
        if current:
            for later in (s for s in group.stages if s > steps):
                snap = stage_dir(work, group, later) / "runs" / run
                if not (snap / "latest.json").is_file():
                    # a run stopped exactly at a stage before its snapshot was taken: its latest is the snapshot
                    # (and a run warm-started at its stage's end would train no step to write one)
                    snap = work / run if at == later else None
                if snap is not None:
                    _keep_snapshot(snap, tmp / "snapshots" / str(later) / run)
                    snapshots.setdefault(str(later), []).append(run)
    if not kept_runs:
        shutil.rmtree(tmp, ignore_errors=True)
        raise ValueError(f"group {group.name!r}: no run has trained a step yet in {work}; nothing to keep")
    (keep / "evaluations").mkdir(parents=True, exist_ok=True)
    for s in evaluated:
        shutil.copy2(evaluation_path(work, group, s), keep / "evaluations")
    dest = keep / "progress" / group.name
    shutil.rmtree(dest, ignore_errors=True)
    tmp.rename(dest)
    index[group.name] = {"steps": steps, "reason": "in progress", "stopped": False,
                         "stages": [int(s) for s in evaluated], "variants": list(group.variants),
                         "fingerprint": group_fingerprint(recipe, group), "runs": kept_runs, "snapshots": snapshots}
    atomic_write_text(keep / KEPT_INDEX, json.dumps(index, indent=2) + "\n")
    log.info("kept the progress of group %s (evaluated up to %d steps; runs at %s; snapshots %s) in %s",
             group.name, steps, kept_runs, snapshots, dest)
    return dest


def _keep_snapshot(snap: Path, dest: Path) -> None:
    """Copy a stage snapshot (``snapshot_run``'s folder) with its weights in float16."""
    from salad_core.train.warm_start import write_warm_start

    write_warm_start(snap / "latest", dest / "latest")
    for name in _VIEW_FILES:                  # the snapshot's other files: configs, statistics, the run's log
        if not name.startswith("latest.") and (snap / name).is_file():
            shutil.copy2(snap / name, dest / name)


def restore_group(recipe: StagedRecipe, group: StudyGroup, keep: str | Path, work: str | Path, *,
                  shipped: str | Path | None = None) -> bool:
    """Put a kept group back into ``work``; returns False when ``keep`` does not hold it.

    A stopped group's model folder or evaluation file that ``keep`` does not hold is taken from ``shipped``
    (default: the shipped ablation folder, :func:`salad_core.ablation_models.ablations_dir`), where the study's
    final ship put the same files.

    A stopped group gets its evaluations and final packaged models back; a group in progress gets its
    evaluations back and, for each run that has no train state in ``work``, the kept weights as the run's
    warm start. What ``work`` already has is left as it is (an evaluation file, a packaged model or a
    run's train state present is not overwritten). Raises ``ValueError`` when the kept group was made by
    another recipe (fingerprint).
    """
    from salad_core.ablation_models import ablations_dir

    keep, work = Path(keep), Path(work)
    shipped = Path(shipped) if shipped is not None else ablations_dir()
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
            src = keep / "evaluations" / dest.name
            shutil.copy2(src if src.is_file() or not entry.get("stopped", True) else shipped / "evaluations" / dest.name,
                         dest)
    if not entry.get("stopped", True):
        from salad_core.train.warm_start import WARM_START

        progress = keep / "progress" / group.name
        for name in group.variants:
            run = work / _run_name(recipe, name)
            if (run / "train_state.safetensors").is_file() or (run / f"{WARM_START}.json").is_file():
                continue
            if not (progress / f"{run.name}.json").is_file():
                continue                          # kept mid-stage before it started: it starts from 0
            run.mkdir(parents=True, exist_ok=True)
            for suffix in (".safetensors", ".json"):
                shutil.copy2(progress / f"{run.name}{suffix}", run / f"{WARM_START}{suffix}")
        for later, names in entry.get("snapshots", {}).items():
            for run_name in names:
                dest = stage_dir(work, group, int(later)) / "runs" / run_name
                if (dest / "latest.safetensors").is_file():
                    continue
                shutil.rmtree(dest, ignore_errors=True)
                dest.parent.mkdir(parents=True, exist_ok=True)
                shutil.copytree(progress / "snapshots" / later / run_name, dest)
        log.info("restored group %s in progress (evaluated up to %d steps; runs at %s) from %s: its runs continue "
                 "from the kept weights", group.name, steps, entry.get("runs", "that stage"), keep)
        return True
    models = stage_dir(work, group, steps) / "models"
    for name in group.variants:
        dest = models / _model_folder(group, name)
        if (dest / ".packaged").is_file():
            continue
        shutil.rmtree(dest, ignore_errors=True)
        if (keep / _model_folder(group, name)).is_dir():
            shutil.copytree(keep / _model_folder(group, name), dest)
        else:
            _copy_shipped_model(shipped, _model_folder(group, name), dest)
        (dest / ".packaged").write_text(f"{group.stage_name(steps)} (restored from {keep})\n")
    log.info("restored group %s (stopped at %d steps, %s) from %s", group.name, steps, entry["reason"], keep)
    return True


def _copy_shipped_model(shipped: Path, folder: str, dest: Path) -> None:
    """Copy a shipped model folder to ``dest`` as the study packaged it: a pipeline whose ``pipeline.json`` names
    its VAE variant's folder (``../vae_<name>/vae``) or another folder's statistics gets those files beside it, and
    a folder whose statistics are shared (:func:`salad_lab.shipping.share_statistics`) gets its own copy back."""
    src = shipped / folder
    if not src.is_dir():
        raise FileNotFoundError(f"{src}: the kept group's model {folder!r} is neither kept nor shipped")
    shutil.copytree(src, dest)
    entry = json.loads((shipped / "index.json").read_text()).get(folder, {}) if (shipped / "index.json").is_file() else {}
    if not (dest / "stats.safetensors").is_file() and entry.get("stats"):     # statistics shared in the shipped folder
        shutil.copy2(shipped / entry["stats"], dest / "stats.safetensors")
    pipeline = dest / "pipeline.json"
    if pipeline.is_file():
        doc = json.loads(pipeline.read_text())
        vae, stats = str(doc.get("vae", "vae")), str(doc.get("stats", "stats.safetensors"))
        if vae != "vae":
            for suffix in (".json", ".safetensors"):
                shutil.copy2((src / vae).with_name(Path(vae).name + suffix), dest / f"vae{suffix}")
            doc["vae"] = "vae"
        if stats != "stats.safetensors":
            shutil.copy2(src / stats, dest / "stats.safetensors")
            doc["stats"] = "stats.safetensors"
        pipeline.write_text(json.dumps(doc, indent=2) + "\n")
