"""A staged ablation recipe: the study's variants trained in groups to shared evaluation points.

``lab/configs/ablations_v2.json`` extends the format of ``lab/configs/ablations.json`` (read by
:func:`~salad_lab.study.load_recipe`: base configs, variants) with

* ``groups``: each group has a ``kind`` (``"vae"`` or ``"denoiser"``), ``stages`` (the steps at
  which every variant of the group is evaluated, increasing; the last is the budget),
  ``evaluation`` (:class:`~salad_core.eval.settings.EvalSettings` fields, one protocol for every row)
  and ``tables``: ``{paper table: {variant: paper row label}}``. Every variant belongs to exactly one
  group; a variant may be a row of several tables of its group (the full denoiser is the reference
  row of Table 3 and supplement Tables 2-3), which is why tables that share a variant train and stop
  together: every row of a table then has exactly the same steps.
* ``stop``: :class:`~salad_lab.stop_rule.StopRule` fields.
* ``timing`` (optional): measured training speeds ``{"steps_per_s": {variant: s^-1}, "measured": "..."}``
  for the plan's CPU-time estimate.

The learning-rate schedule must not depend on where the study stops: every run is constant after
its warm-up (``milestones: []``, checked), so the model evaluated at a stage is the same whether the
study stops there or goes on, and stage ``k`` of a longer study is bit-identical to a study whose
budget is stage ``k`` (resumed training is exact: :mod:`salad_core.train.common`).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping

from .orderings import KIND_OF_TABLE, PAPER_PAIRS, check_table_rows
from .stop_rule import StopRule
from .study import KINDS, AblationRecipe, TrainJob, load_recipe, plan_jobs

__all__ = ["StudyGroup", "StagedRecipe", "load_staged_recipe", "stage_jobs", "SCHEDULE_FIELDS"]

#: Training fields a variant may not override: they set the budget or the schedule, which every row
#: of a table shares.
SCHEDULE_FIELDS = ("max_steps", "max_epochs", "lr", "warmup_steps", "milestones", "gamma")


@dataclass(frozen=True)
class StudyGroup:
    """Tables trained and stopped together, with their stages and evaluation protocol."""

    name: str
    kind: str                                   # "vae" or "denoiser"
    stages: tuple[int, ...]                     # evaluation points (steps), increasing; the last is the budget
    tables: Mapping[str, Mapping[str, str]]     # paper table -> {variant: paper row label}
    evaluation: Any                             # EvalSettings shared by every row of the group

    @property
    def variants(self) -> tuple[str, ...]:
        """The group's variants, in order of first appearance in its tables."""
        out: list[str] = []
        for rows in self.tables.values():
            out += [v for v in rows if v not in out]
        return tuple(out)

    def stage_name(self, steps: int) -> str:
        """``"<group>@<steps>"``: the name of an evaluation point (its file is ``evaluations/<name>.json``)."""
        return f"{self.name}@{int(steps)}"


@dataclass(frozen=True)
class StagedRecipe:
    """A whole staged study."""

    base: AblationRecipe                        # base configs and variants
    groups: tuple[StudyGroup, ...]              # VAE groups before the denoiser groups that need them
    stop: StopRule = StopRule()
    steps_per_s: Mapping[str, float] = field(default_factory=dict)   # measured training speed per variant
    timing_note: str = ""
    path: str = ""

    def group(self, name: str) -> StudyGroup:
        for g in self.groups:
            if g.name == name:
                return g
        raise KeyError(f"no group {name!r}; the recipe has {[g.name for g in self.groups]}")

    def group_of(self, variant: str) -> StudyGroup:
        for g in self.groups:
            if variant in g.variants:
                return g
        raise KeyError(f"variant {variant!r} is in no group")


def _fail(path: Path, where: str, msg: str) -> None:
    raise ValueError(f"staged ablation recipe {path}: {where}: {msg}")


def _stages(path: Path, where: str, stages: Any) -> tuple[int, ...]:
    ok = (isinstance(stages, list) and stages
          and all(isinstance(s, int) and not isinstance(s, bool) and s >= 1 for s in stages)
          and all(a < b for a, b in zip(stages, stages[1:])))
    if not ok:
        _fail(path, f"{where}.stages={stages!r}", "use a non-empty list of increasing integers >= 1 (steps)")
    return tuple(stages)


def _evaluation(path: Path, where: str, spec: Any):
    from salad_core.eval.settings import EvalSettings

    if not isinstance(spec, dict):
        _fail(path, f"{where}.evaluation={spec!r}", "use an object of EvalSettings fields")
    known = {f.name for f in fields(EvalSettings)}
    unknown = sorted(set(spec) - known)
    if unknown:
        _fail(path, f"{where}.evaluation", f"unknown fields {unknown}; allowed: {sorted(known)}")
    try:
        return EvalSettings(**spec)
    except ValueError as exc:
        _fail(path, f"{where}.evaluation", str(exc))


def _check_schedule(path: Path, recipe: AblationRecipe, group: StudyGroup) -> None:
    jobs = {j.variant.name: j for j in plan_jobs(recipe, "/nonexistent")}
    for name in group.variants:
        over = sorted(set(recipe.variant(name).train) & set(SCHEDULE_FIELDS))
        if over:
            _fail(path, f"variant {name!r}", f"its 'train' sets {over}, but every row of a table shares the budget "
                                             f"and schedule (the group's stages set max_steps)")
        train = jobs[name].config.get("train", {})
        if train.get("milestones", None) != []:
            _fail(path, f"variant {name!r}: train.milestones={train.get('milestones', '(missing)')!r}",
                  "use [] (constant learning rate after warm-up), so that a model evaluated at a stage does not "
                  "depend on where the study stops")
        warm = int(train.get("warmup_steps", 0))
        if warm >= group.stages[0]:
            _fail(path, f"variant {name!r}: train.warmup_steps={warm}",
                  f"must be below the group {group.name!r}'s first stage {group.stages[0]}")


def load_staged_recipe(path: str | os.PathLike) -> StagedRecipe:
    """Read and validate a staged recipe (see the module docstring).

    Raises ``ValueError`` naming the field, its value and what is allowed.
    """
    path = Path(path)
    base = load_recipe(path)
    doc = json.loads(path.read_text())
    if not isinstance(doc.get("groups"), dict) or not doc["groups"]:
        _fail(path, "groups", "missing or empty; a staged recipe needs groups of tables with stages")
    kinds = {v.name: v.kind for v in base.variants}
    seen: dict[str, str] = {}
    groups = []
    for gname, spec in doc["groups"].items():
        where = f"groups.{gname}"
        if not isinstance(spec, dict):
            _fail(path, where, "use an object with kind, stages, evaluation and tables")
        unknown = sorted(set(spec) - {"kind", "stages", "evaluation", "tables", "about"})
        if unknown:
            _fail(path, where, f"unknown keys {unknown}; allowed: ['about', 'evaluation', 'kind', 'stages', 'tables']")
        kind = spec.get("kind")
        if kind not in KINDS:
            _fail(path, f"{where}.kind={kind!r}", f"allowed: {list(KINDS)}")
        stages = _stages(path, where, spec.get("stages"))
        tables = spec.get("tables")
        if not isinstance(tables, dict) or not tables:
            _fail(path, f"{where}.tables", "use a non-empty object {paper table: {variant: paper row}}")
        for table, rows in tables.items():
            if table not in PAPER_PAIRS:
                _fail(path, f"{where}.tables.{table}", f"not a paper table; allowed: {sorted(PAPER_PAIRS)}")
            if KIND_OF_TABLE[table] != kind:
                _fail(path, f"{where}.tables.{table}", f"is a {KIND_OF_TABLE[table]} table in a {kind} group")
            if not isinstance(rows, dict) or not rows:
                _fail(path, f"{where}.tables.{table}", "use a non-empty object {variant: paper row label}")
            for variant in rows:
                if variant not in kinds:
                    _fail(path, f"{where}.tables.{table}", f"variant {variant!r} is not in the recipe's vaes/denoisers")
                if kinds[variant] != kind:
                    _fail(path, f"{where}.tables.{table}", f"variant {variant!r} is a {kinds[variant]} in a {kind} group")
                if seen.get(variant, gname) != gname:
                    _fail(path, f"{where}.tables.{table}", f"variant {variant!r} is already in group {seen[variant]!r}: "
                                                           "a variant trains in one group only")
                seen[variant] = gname
            try:
                check_table_rows(table, rows)
            except ValueError as exc:
                _fail(path, f"{where}.tables.{table}", str(exc))
            if len(set(rows.values())) != len(rows):
                _fail(path, f"{where}.tables.{table}", f"two variants map to the same paper row: {rows}")
        group = StudyGroup(gname, kind, stages, {t: dict(r) for t, r in tables.items()},
                           _evaluation(path, where, spec.get("evaluation", {})))
        _check_schedule(path, base, group)
        groups.append(group)
    missing = sorted(set(kinds) - set(seen))
    if missing:
        _fail(path, "groups", f"variants {missing} are in no group (they would never be trained or evaluated)")
    stop = doc.get("stop", {})
    try:
        stop_rule = StopRule(**stop)
    except TypeError:
        _fail(path, f"stop={stop!r}", "allowed keys: ['compare', 'consecutive']")
    except ValueError as exc:
        _fail(path, "stop", str(exc))
    timing = doc.get("timing", {})
    speeds = timing.get("steps_per_s", {}) if isinstance(timing, dict) else None
    if not isinstance(speeds, dict) or not all(isinstance(v, (int, float)) and v > 0 for v in speeds.values()):
        _fail(path, "timing.steps_per_s", "use an object {variant or kind: positive steps per second}")
    # VAE groups first: a denoiser group trains on the final VAEs of the groups before it
    groups.sort(key=lambda g: KINDS.index(g.kind))
    return StagedRecipe(base, tuple(groups), stop_rule, dict(speeds), str(timing.get("measured", "")), str(path))


def stage_jobs(recipe: StagedRecipe, group: StudyGroup, steps: int, work: str | os.PathLike,
               frozen_vaes: Mapping[str, Path] | None = None) -> list[TrainJob]:
    """The training jobs that take every variant of ``group`` to ``steps``.

    Parameters
    ----------
    recipe : StagedRecipe
    group : StudyGroup
    steps : int
        One of the group's stages: the jobs' ``max_steps``.
    work : path
        The study folder (runs go to ``work/vae_<name>`` and ``work/den_<name>``).
    frozen_vaes : dict, optional
        Denoiser groups: VAE variant name -> the frozen VAE run view the denoisers learn on
        (the VAE at its group's final stage). Required for a denoiser group.
    """
    if int(steps) not in group.stages:
        raise ValueError(f"steps={steps!r} is not a stage of group {group.name!r}: {list(group.stages)}")
    jobs = []
    for job in plan_jobs(recipe.base, work):
        if job.variant.name not in group.variants:
            continue
        config = json.loads(json.dumps(job.config))
        config["train"]["max_steps"] = int(steps)
        depends = job.depends_on
        if job.variant.kind == "denoiser":
            if not frozen_vaes or job.variant.vae not in frozen_vaes:
                raise ValueError(f"denoiser variant {job.variant.name!r} needs its VAE {job.variant.vae!r} frozen "
                                 f"(its group has not stopped yet); frozen: {sorted(frozen_vaes or {})}")
            depends = Path(frozen_vaes[job.variant.vae])
            # one latent cache per VAE, shared by its denoisers (the cache's signature hashes the VAE's weights
            # and the corpus; a lock lets one process build it while the others wait)
            config["train"].setdefault("latent_cache_dir", str(Path(work) / "latent_cache"))
        jobs.append(TrainJob(job.variant, job.run_dir, config, depends))
    return jobs
