"""Run a staged ablation study to its end: train each group stage by stage until its orderings are stable.

For every group of a :class:`~salad_lab.staged.StagedRecipe` (VAE groups first), stage by
stage:

1. if ``evaluations/<group>@<steps>.json`` exists, read it (nothing is trained or scored again);
2. else train every variant of the group to ``steps`` (:func:`~salad_lab.study.run_jobs`,
   resumable: a half-trained run continues), snapshot each run's checkpoint of that step, package the
   snapshots (fp16) and score every row (:mod:`~salad_lab.stage_eval`);
3. apply the stop rule (:func:`~salad_lab.stop_rule.decide`) to the group's evaluations so far.

When a VAE group stops, its variants' packaged models at the final stage (fp16, the form that ships) are
*frozen*: the denoiser groups learn on them and ship with them. Rerunning :func:`run_study` after a kill
continues where it stopped. With ``keep`` (a folder of the repository, :mod:`~salad_lab.keep`),
a stopped group is also copied there, a group in progress keeps its runs' fp16 weights after every new
evaluation, and a group the ``work`` folder lacks is restored from there: a new machine goes on with the
next group, or with the group in progress from its last evaluated stage (a warm start), instead of training
from step 0 again.
"""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from .keep import _run_name, group_fingerprint, keep_group, keep_progress, kept_groups, restore_group
from .stage_eval import evaluate_stage, load_evaluation, package_stage, snapshot_run, stage_dir
from .staged import StagedRecipe, StudyGroup, stage_jobs
from .stop_rule import StopDecision, decide
from .study import TrainJob, job_command, run_jobs

__all__ = ["GroupOutcome", "run_study", "study_plan", "keep_study", "final_denoiser_jobs"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GroupOutcome:
    """Where a group stopped and its evaluations (one document per evaluated stage, in order)."""

    group: StudyGroup
    decision: StopDecision
    evaluations: tuple[dict, ...]


def _history(evaluations) -> list[dict[str, str]]:
    return [{k: o["ours"] for k, o in doc["orderings"].items()} for doc in evaluations]


def _check_vae_of_runs(jobs, frozen: Mapping[str, Path]) -> None:
    """A denoiser run that exists must have learned on the frozen VAE it would resume with."""
    from salad_core.train.assemble import vae_source

    for job in jobs:
        cfg = job.run_dir / "config.json"
        if job.variant.kind != "denoiser" or not cfg.is_file():
            continue
        used = json.loads(cfg.read_text()).get("task", {}).get("vae")
        want = str(vae_source(frozen[job.variant.vae]).stem)
        if used is not None and used != want:
            raise RuntimeError(f"{job.run_dir} learned on the VAE {used}, but the study's {job.variant.vae!r} is "
                               f"now {want} (its VAE group stopped elsewhere): move the denoiser run away to retrain it")


def _train_stage(recipe: StagedRecipe, group: StudyGroup, steps: int, work: Path, data, frozen, max_parallel: int,
                 inline: bool, python: str) -> None:
    runs = stage_dir(work, group, steps) / "runs"
    jobs = [j for j in stage_jobs(recipe, group, steps, work, frozen)
            if not (runs / j.run_dir.name / "latest.safetensors").is_file()]
    if jobs:
        _check_vae_of_runs(jobs, frozen)
        log.info("%s: training %s to %d steps", group.name, [j.run_dir.name for j in jobs], steps)
        codes = run_jobs(jobs, data, max_parallel=max_parallel, python=python, inline=inline)
        failed = {n: c for n, c in codes.items() if c}
        if failed:
            raise RuntimeError(f"training failed for {failed} (exit codes); see their logs "
                               f"{[str(work / f'{n}.log') for n in failed]}")
    for job in stage_jobs(recipe, group, steps, work, frozen):
        snapshot_run(job.run_dir, runs / job.run_dir.name, steps)


def _stage_done(work: Path, group: StudyGroup, steps: int, run_name: str) -> bool:
    return (stage_dir(work, group, steps) / "runs" / run_name / "latest.safetensors").is_file()


def _run_group_pipelined(recipe: StagedRecipe, group: StudyGroup, work: Path, data, frozen, max_parallel: int,
                         python: str, evaluator: Any, text_encoder: Any, evaluations: list[dict],
                         on_progress=None) -> StopDecision | None:
    """Train and evaluate a group's remaining stages without idle cores at the stage boundaries.

    The work is a set of tasks ``(stage, variant)``: train the variant's run to the stage, then snapshot it.
    Free slots take the pending task of the lowest stage whose previous stage is snapshotted, up to one
    stage beyond the evaluation in progress; a stage is packaged and scored in a thread as soon as all its
    snapshots exist, while the next stage trains. When the stop rule stops the group, the runs trained
    beyond the stopping stage are interrupted (SIGINT: they write a checkpoint) and their extra steps are
    not used: the models of a stage are its snapshots, and with a constant learning rate after warm-up a
    run's weights at a step do not depend on how far it goes on (:mod:`~salad_lab.staged`).
    ``evaluations`` holds the stages evaluated before (in order) and is extended; ``on_progress`` is called
    with it after each new evaluation that does not stop the group. Returns the decision after the last
    evaluation (None when there is none).
    """
    import signal
    import threading

    stages = list(group.stages)
    names = list(group.variants)
    run_of = {v: (f"vae_{v}" if recipe.base.variant(v).kind == "vae" else f"den_{v}") for v in names}
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    running: dict[tuple[int, str], tuple[subprocess.Popen, Any]] = {}
    evaluating: dict[str, Any] = {}           # "thread", "index", "result", "error"
    decision = None
    for steps in stages[len(evaluations):]:   # stages evaluated before (also those restored from a keep folder)
        doc = load_evaluation(work, group, steps)
        if doc is None:
            break
        evaluations.append(doc)
        decision = decide(_history(evaluations), stages, recipe.stop)
        log.info("%s at %d steps: %s", group.name, steps, decision.reason)
        if decision.stop:
            return decision

    def done(i: int, v: str) -> bool:
        """Stage ``i`` of variant ``v`` is trained: snapshotted, or evaluated already."""
        return i < len(evaluations) or _stage_done(work, group, stages[i], run_of[v])

    def evaluate(i: int) -> None:
        import torch

        torch.set_num_threads(1)              # the trainings have the other cores
        try:
            package_stage(recipe, group, stages[i], work, frozen, text_encoder)
            evaluating["result"] = evaluate_stage(recipe, group, stages[i], work, data, evaluator, text_encoder)
        except BaseException as exc:           # re-raised by the scheduler
            evaluating["error"] = exc

    def stop_all() -> None:
        for (i, v), (proc, _) in running.items():
            if proc.poll() is None:
                log.info("%s: interrupting %s (training towards %d steps, beyond the stop)", group.name, run_of[v],
                         stages[i])
                proc.send_signal(signal.SIGINT)
        for proc, fh in running.values():
            try:
                proc.wait(timeout=600)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            fh.close()
        running.clear()

    try:
        while True:
            # finished trainings: snapshot their stage
            for (i, v), (proc, fh) in list(running.items()):
                code = proc.poll()
                if code is None:
                    continue
                fh.close()
                del running[(i, v)]
                if code != 0:
                    raise RuntimeError(f"training {run_of[v]} to {stages[i]} steps failed (exit code {code}); see "
                                       f"{work / (run_of[v] + '.log')}")
                snapshot_run(work / run_of[v], stage_dir(work, group, stages[i]) / "runs" / run_of[v], stages[i])
                log.info("%s: %s reached %d steps", group.name, run_of[v], stages[i])
            # a finished evaluation: the stop rule
            if evaluating and not evaluating["thread"].is_alive():
                if "error" in evaluating:
                    raise evaluating["error"]
                evaluations.append(evaluating["result"])
                evaluating.clear()
                decision = decide(_history(evaluations), stages, recipe.stop)
                log.info("%s at %d steps: %s", group.name, decision.steps, decision.reason)
                if decision.stop:
                    return decision
                if on_progress is not None:
                    on_progress(evaluations)
            # the next stage to evaluate, once every variant has its snapshot
            nxt = len(evaluations)
            if not evaluating and nxt < len(stages) and all(done(nxt, v) for v in names):
                thread = threading.Thread(target=evaluate, args=(nxt,), name=f"evaluate {group.stage_name(stages[nxt])}",
                                          daemon=True)
                evaluating.update(thread=thread, index=nxt)
                thread.start()
            # free slots: the lowest pending stage first, at most one stage beyond the one being evaluated
            limit = min(len(stages) - 1, len(evaluations) + 1)
            busy = {v for _, v in running}
            for i in range(len(evaluations), limit + 1):
                for v in names:
                    if len(running) >= max_parallel:
                        break
                    if v in busy or done(i, v) or (i > 0 and not done(i - 1, v)):
                        continue
                    job = next(j for j in stage_jobs(recipe, group, stages[i], work, frozen) if j.variant.name == v)
                    _check_vae_of_runs([job], frozen)
                    job.run_dir.parent.mkdir(parents=True, exist_ok=True)
                    fh = open(job.run_dir.parent / f"{job.run_dir.name}.log", "a")
                    log.info("%s: training %s to %d steps", group.name, job.run_dir.name, stages[i])
                    running[(i, v)] = (subprocess.Popen(job_command(job, data, python), stdout=fh,
                                                        stderr=subprocess.STDOUT, env=env), fh)
                    busy.add(v)
            if not running and not evaluating:
                if len(evaluations) == len(stages):
                    return decision
                if all(done(len(evaluations), v) for v in names):
                    continue                      # its evaluation starts at the next turn
                raise RuntimeError(f"{group.name}: nothing runs and stage {stages[len(evaluations)]} cannot start "
                                   "(a bug in the scheduler)")
            time.sleep(2.0)
    finally:
        stop_all()


def run_study(recipe: StagedRecipe, data: str | os.PathLike, work: str | os.PathLike, *, evaluator: Any = None,
              text_encoder: Any = None, max_parallel: int = 1, inline: bool = False,
              python: str = sys.executable, groups: list[str] | None = None,
              keep: str | os.PathLike | None = None, pipelined: bool = True) -> dict[str, GroupOutcome]:
    """Train and evaluate every group until it stops (see the module docstring); resumable.

    Parameters
    ----------
    recipe : StagedRecipe
    data : path
        The training corpus (HumanML3D layout); rows are scored on its ``evaluation.split``.
    work : path
        The study folder: runs, snapshots, evaluations.
    evaluator : T2MEvaluator, optional
        Default: the shipped procedural-corpus evaluator (loaded only when a row is scored).
    text_encoder : optional
        Shared by the denoiser pipelines (default: MiniLM, loaded when needed).
    max_parallel : int
        Runs trained at the same time (one torch thread each).
    inline : bool
        Train in this process, one run after the other (tests).
    groups : list of str, optional
        Only these groups (their VAE groups must have stopped already: their evaluations are in ``work``,
        or in ``keep``).
    pipelined : bool
        With subprocesses (``inline=False``): stages overlap, so no core idles at a stage boundary or during an
        evaluation (:func:`_run_group_pipelined`); False trains, evaluates and decides one stage at a time.
        The models and scores are the same either way.
    keep : path, optional
        Where stopped groups and the progress of running ones are kept (:func:`~salad_lab.keep.keep_group`,
        :func:`~salad_lab.keep.keep_progress`) and restored from
        (:func:`~salad_lab.keep.restore_group`) when ``work`` lacks them.

    Returns
    -------
    dict
        Group name -> :class:`GroupOutcome`.
    """
    work = Path(work)
    wanted = set(groups) if groups else None
    if wanted:
        unknown = sorted(wanted - {g.name for g in recipe.groups})
        if unknown:
            raise ValueError(f"groups={unknown} are not groups of the recipe: {[g.name for g in recipe.groups]}")
    frozen: dict[str, Path] = {}
    outcomes: dict[str, GroupOutcome] = {}
    chosen = [g for g in recipe.groups if wanted is None or g.name in wanted]
    needed_vaes = {recipe.base.variant(v).vae for g in chosen for v in g.variants
                   if recipe.base.variant(v).kind == "denoiser"}
    for group in recipe.groups:
        if keep is not None and (group in chosen or (group.kind == "vae" and needed_vaes & set(group.variants))):
            restore_group(recipe, group, keep, work)
        if group not in chosen:
            if group.kind == "vae" and needed_vaes & set(group.variants):
                frozen.update(_frozen_of(group, _replay(recipe, group, work), work))   # must have stopped
            continue
        needs = {recipe.base.variant(v).vae for v in group.variants if recipe.base.variant(v).kind == "denoiser"}
        missing = sorted(needs - set(frozen))
        if missing:
            raise RuntimeError(f"group {group.name!r} needs the VAEs {missing}, whose group has not stopped")
        evaluations: list[dict] = []
        decision = None

        def progress(evaluations: list[dict], group: StudyGroup = group) -> None:
            if keep is not None:
                keep_progress(recipe, group, [int(d["steps"]) for d in evaluations], work, keep)

        if not inline and pipelined:
            decision = _run_group_pipelined(recipe, group, work, data, frozen, max_parallel, python, evaluator,
                                            text_encoder, evaluations, on_progress=progress)
        for steps in (() if not inline and pipelined else group.stages):
            doc = load_evaluation(work, group, steps)
            new = doc is None
            if new:
                _train_stage(recipe, group, steps, work, data, frozen, max_parallel, inline, python)
                package_stage(recipe, group, steps, work, frozen, text_encoder)
                doc = evaluate_stage(recipe, group, steps, work, data, evaluator, text_encoder)
            evaluations.append(doc)
            decision = decide(_history(evaluations), group.stages, recipe.stop)
            log.info("%s at %d steps: %s", group.name, steps, decision.reason)
            if decision.stop:
                break
            if new:
                progress(evaluations)
        outcomes[group.name] = GroupOutcome(group, decision, tuple(evaluations))
        if group.kind == "vae":
            frozen.update(_frozen_of(group, outcomes[group.name], work))
        if keep is not None:
            _keep_stopped(recipe, outcomes[group.name], work, keep)
    return outcomes


def _keep_stopped(recipe: StagedRecipe, outcome: GroupOutcome, work: Path, keep: str | os.PathLike) -> None:
    """Keep a stopped group in ``keep`` unless it holds it already (same recipe, same final stage)."""
    group, decision = outcome.group, outcome.decision
    kept = kept_groups(keep).get(group.name, {})
    if (kept.get("fingerprint") != group_fingerprint(recipe, group) or kept.get("steps") != decision.steps
            or not kept.get("stopped", True)):
        keep_group(recipe, group, decision.steps, decision.reason, [int(d["steps"]) for d in outcome.evaluations],
                   work, keep)


def keep_study(recipe: StagedRecipe, work: str | os.PathLike, keep: str | os.PathLike) -> dict[str, str]:
    """Keep what ``work`` holds of every group, without training or scoring: a stopped group as
    :func:`~salad_lab.keep.keep_group`, a group in progress as
    :func:`~salad_lab.keep.keep_progress` with ``current=True`` (each run at its latest step,
    inside a stage too, and the snapshots of stages not evaluated yet): what a working session does before it
    ends, so that a new machine loses no trained step. Returns ``{group: what was kept}``.
    """
    from .stage_eval import latest_step

    work = Path(work)
    done: dict[str, str] = {}
    for group in recipe.groups:
        evaluations, decision = _evaluated(recipe, group, work)
        if decision is not None and decision.stop:
            _keep_stopped(recipe, GroupOutcome(group, decision, tuple(evaluations)), work, keep)
            done[group.name] = f"stopped at {decision.steps} steps ({decision.reason})"
            continue
        evaluated = [int(d["steps"]) for d in evaluations]
        if not evaluated and all(latest_step(work / _run_name(recipe, v)) is None for v in group.variants):
            done[group.name] = "nothing trained"
            continue
        keep_progress(recipe, group, evaluated, work, keep, current=True)
        kept = kept_groups(keep)[group.name]["runs"]
        done[group.name] = (f"in progress, evaluated up to {evaluated[-1]} steps" if evaluated else
                            "in progress, nothing evaluated yet") + f"; runs kept at {kept}"
    return done


def final_denoiser_jobs(recipe: StagedRecipe, work: str | os.PathLike) -> list[TrainJob]:
    """The training jobs of every denoiser variant at its group's final (stopped) stage, with the frozen VAE each
    learned on as ``depends_on``, read from ``work``'s evaluation files alone (no run folder is needed).

    This is what a probe beside the study needs on a machine where only the study's kept groups were restored
    (``run_study`` with ``keep``): the variants' training configs and their VAEs. Raises ``RuntimeError`` when a
    group has not stopped (its final stage is not known yet)."""
    work = Path(work)
    frozen: dict[str, Path] = {}
    jobs: list[TrainJob] = []
    for group in recipe.groups:
        outcome = _replay(recipe, group, work)
        if group.kind == "vae":
            frozen.update(_frozen_of(group, outcome, work))
        else:
            jobs += stage_jobs(recipe, group, outcome.decision.steps, work, frozen)
    return jobs


def _frozen_of(group: StudyGroup, outcome: GroupOutcome, work: Path) -> dict[str, Path]:
    """The VAE group's packaged fp16 models at its final stage: what the denoisers learn on and ship with
    (so a group restored from a keep folder gives the denoisers exactly the same VAEs)."""
    models = stage_dir(work, group, outcome.decision.steps) / "models"
    return {v: models / f"vae_{v}" for v in group.variants}


def _evaluated(recipe: StagedRecipe, group: StudyGroup, work: Path) -> tuple[list[dict], StopDecision | None]:
    """A group's evaluation files in stage order, up to the first missing one or the stop, and the stop rule's
    decision after the last of them (None when there is none)."""
    evaluations: list[dict] = []
    decision = None
    for steps in group.stages:
        doc = load_evaluation(work, group, steps)
        if doc is None:
            break
        evaluations.append(doc)
        decision = decide(_history(evaluations), group.stages, recipe.stop)
        if decision.stop:
            break
    return evaluations, decision


def _replay(recipe: StagedRecipe, group: StudyGroup, work: Path) -> GroupOutcome:
    """The outcome of a group from its evaluation files alone (it must have stopped)."""
    evaluations, decision = _evaluated(recipe, group, work)
    if decision is not None and decision.stop:
        return GroupOutcome(group, decision, tuple(evaluations))
    raise RuntimeError(f"group {group.name!r} has not stopped yet ({len(evaluations)} of its stages evaluated in "
                       f"{work / 'evaluations'}): run it first")


def _alike(recipe: StagedRecipe, name: str) -> tuple[str, str]:
    """What a variant's speed is taken to equal when it was not timed: VAEs of the same latent kind
    ("st" or "pose"), denoisers on the same VAE (the latent's token count sets the cost)."""
    v = recipe.base.variant(name)
    if v.kind == "vae":
        return "vae", str(v.model.get("kind", recipe.base.vae_doc.get("model", {}).get("kind", "st")))
    return "denoiser", str(v.vae)


def study_plan(recipe: StagedRecipe, speeds: Mapping[str, float] | None = None) -> list[dict[str, Any]]:
    """The study's stages, for a dry run: one entry per group and stage, with the steps each variant
    trains in that stage and the CPU seconds (one core) the measured speeds give.

    ``speeds``: steps per CPU second by variant (default: the recipe's ``timing``). A variant not
    timed takes the speed of a timed one alike (VAEs of the same latent kind, denoisers on the same
    VAE); ``cpu_seconds`` is None when none is.
    """
    speeds = dict(recipe.steps_per_s if speeds is None else speeds)
    for name in list(speeds):
        if name in {v.name for v in recipe.base.variants}:
            speeds.setdefault(_alike(recipe, name), speeds[name])
    plan = []
    for group in recipe.groups:
        before = 0
        for steps in group.stages:
            new = steps - before
            seconds: float | None = 0.0
            for v in group.variants:
                rate = speeds.get(v, speeds.get(_alike(recipe, v)))
                seconds = None if (seconds is None or not rate) else seconds + new / rate
            plan.append({"group": group.name, "kind": group.kind, "stage": group.stage_name(steps), "steps": steps,
                         "new_steps_per_variant": new, "variants": list(group.variants),
                         "tables": list(group.tables), "cpu_seconds": seconds})
            before = steps
    return plan
