"""The lab's ablation study of paper Tables 2-3 and supplement Tables 2-4: small models, trained, scored, shipped.

Not installed: ``import salad_lab`` needs ``lab/`` on ``sys.path`` (the lab's scripts and ``lab/conftest.py`` put
it there). It imports the toolkit; the toolkit never imports it. Loading what was shipped is the toolkit's
(:mod:`salad_core.ablation_models`, re-exported here).

A JSON recipe names VAE variants (skeleton-aware vs pose-vector VAE, the VAE loss terms) and
denoiser variants (w/o ST-Latent, w/o cross-attention, both, the three diffusion parametrisations,
w/o FiLM), each as overrides of base configs, so that variants differ only in what the ablation changes.

* :mod:`~salad_lab.study`: the recipe (:func:`load_recipe`), its training runs
  (:func:`plan_jobs`, :func:`run_jobs`: resumable subprocesses), shipping a set of runs
  (:func:`ship`) and loading what was shipped (:func:`list_ablations`, :func:`load_ablation_pipeline`,
  :func:`load_ablation_vae`: :mod:`salad_core.ablation_models`, which notebooks 06 and 07 use);
* the staged study (``lab/configs/ablations_v2.json``, ``lab/scripts/ablations/train_ablations.py``):
  :mod:`~salad_lab.staged` (groups of tables, stages, one evaluation protocol per group:
  :func:`load_staged_recipe`), :mod:`~salad_lab.orderings` (which paper pairs are
  reproduced, read against :mod:`salad_core.eval.paper_tables`), :mod:`~salad_lab.stop_rule`
  (stable orderings or budget spent), :mod:`~salad_lab.stage_eval` (snapshots and scores of
  one stage), :mod:`~salad_lab.runner` (:func:`run_study`, resumable),
  :mod:`~salad_lab.keep` (a stopped group kept in ``lab/records``, restored on a new machine),
  :mod:`~salad_lab.probes` (a changed variant scored with a stage's protocol, to measure why an
  ordering differs), :mod:`~salad_lab.shipping` (:func:`ship_study`) and :mod:`~salad_lab.card`
  (the model card from the evaluations).

The denoisers learn on the latents of the ablation VAEs (trained with the same budget), not on the
shipped VAE, so "w/o ST-Latent" compares two VAEs trained alike.
"""
from __future__ import annotations

from .card import model_card, shipped_tables
from .keep import group_fingerprint, keep_group, keep_progress, kept_groups, restore_group
from .orderings import PAPER_PAIRS, TABLE_METRICS, compare, paper_ordering
from .runner import GroupOutcome, keep_study, run_study, study_plan
from .shipping import ship_study
from .stage_eval import evaluate_stage, group_orderings
from .staged import StagedRecipe, StudyGroup, load_staged_recipe, stage_jobs
from .stop_rule import StopDecision, StopRule, decide
from .study import (AblationRecipe, AblationVariant, TrainJob, ablations_dir, job_command, list_ablations,
                    load_ablation_pipeline, load_ablation_vae, load_recipe, plan_jobs, run_jobs, ship)

__all__ = ["AblationVariant", "AblationRecipe", "TrainJob", "load_recipe", "plan_jobs", "run_jobs", "ship",
           "job_command", "ablations_dir", "list_ablations", "load_ablation_pipeline", "load_ablation_vae",
           "StagedRecipe", "StudyGroup", "load_staged_recipe", "stage_jobs", "StopRule", "StopDecision", "decide",
           "PAPER_PAIRS", "TABLE_METRICS", "compare", "paper_ordering", "evaluate_stage", "group_orderings",
           "GroupOutcome", "run_study", "study_plan", "keep_study", "ship_study", "model_card", "shipped_tables",
           "group_fingerprint", "keep_group", "keep_progress", "kept_groups", "restore_group"]
