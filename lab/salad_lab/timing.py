"""How long a staged study will train: CPU seconds per step of its variants, measured in a short run.

:func:`time_variants` trains a copy of each chosen variant's run for a few steps in this process, on one
torch thread, and reads the process's CPU clock (``time.process_time``) after every optimiser step.
CPU time per step does not depend much on what else loads the machine (wall time does: a shared 2-core
VM may give a low-priority run a seventh of a core), so the plan's estimate is "CPU time of one core";
the wall time is that divided by the cores the study gets. Set-up (text features, latent cache) and the
first ``skip`` steps (allocator warm-up) are left out.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Sequence

__all__ = ["time_variants", "TIMING_FILE"]

#: Where :func:`time_variants` writes its result in the study folder (read by the dry run).
TIMING_FILE = "timing.json"


def _train(job, data: str, out: Path, steps: int, vae_path: Path | None, on_step) -> None:
    import torch

    from salad_core.io import config_from_dict

    doc = job.config
    train = {**doc["train"], "max_steps": int(steps), "val_every": 0, "ckpt_every": 0, "num_threads": 1,
             "progress": False}
    torch.set_num_threads(1)
    if job.variant.kind == "vae":
        from salad_core.models.vae import VAEConfig
        from salad_core.train.config import VAETrainConfig
        from salad_core.train.vae_trainer import train_vae

        train_vae(data, out, config_from_dict(VAEConfig, doc["model"]), config_from_dict(VAETrainConfig, train),
                  on_step=on_step)
    else:
        from salad_core.models.denoiser import DenoiserConfig
        from salad_core.sampling import DiffusionConfig
        from salad_core.train.config import DenoiserTrainConfig
        from salad_core.train.denoiser_trainer import train_denoiser

        train_denoiser(data, out, vae_path, config_from_dict(DenoiserConfig, doc["model"]),
                       config_from_dict(DenoiserTrainConfig, train), doc.get("text_encoder", "minilm"),
                       diffusion_config=config_from_dict(DiffusionConfig, doc.get("diffusion") or {}), on_step=on_step)


def time_variants(recipe, names: Sequence[str], data: str | os.PathLike, work: str | os.PathLike, *,
                  steps: int = 30, skip: int = 5) -> dict[str, Any]:
    """CPU seconds per training step of the named variants (VAEs first: the denoisers train on them).

    Parameters
    ----------
    recipe : StagedRecipe
    names : sequence of str
        Variants to time; a denoiser's VAE is timed (and trained for ``steps``) too when not named.
    data : path
        A corpus (the per-step cost does not depend on its size: batches are random crops).
    work : path
        Scratch folder (``work/timing/<run>``, replaced); the result also goes to ``work/timing.json``.
    steps, skip : int
        Steps trained, and first steps left out of the measurement.

    Returns
    -------
    dict
        ``{"steps_per_cpu_s": {variant: float}, "cpu_s_per_step": {...}, "wall_s_per_step": {...},
        "steps": steps, "skip": skip, "measured": "<date>, <load average>"}``.
    """
    import shutil

    from salad_core.io import atomic_write_text

    from .study import plan_jobs

    if steps <= skip:
        raise ValueError(f"steps={steps} must exceed skip={skip}")
    work = Path(work)
    jobs = {j.variant.name: j for j in plan_jobs(recipe.base, work / "timing")}
    unknown = sorted(set(names) - set(jobs))
    if unknown:
        raise ValueError(f"variants {unknown} are not in the recipe; it has {sorted(jobs)}")
    wanted = list(dict.fromkeys([*(jobs[n].variant.vae for n in names if jobs[n].variant.kind == "denoiser"), *names]))
    wanted.sort(key=lambda n: jobs[n].variant.kind != "vae")
    cpu, wall = {}, {}
    for name in wanted:
        job = jobs[name]
        shutil.rmtree(job.run_dir, ignore_errors=True)
        marks: list[tuple[float, float]] = []
        _train(job, str(data), job.run_dir, steps, job.depends_on,
               lambda step: marks.append((time.process_time(), time.perf_counter())))
        (c0, w0), (c1, w1) = marks[skip - 1], marks[-1]
        cpu[name] = (c1 - c0) / (len(marks) - skip)
        wall[name] = (w1 - w0) / (len(marks) - skip)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    result = {"steps_per_cpu_s": {n: round(1.0 / s, 4) for n, s in cpu.items()},
              "cpu_s_per_step": {n: round(s, 4) for n, s in cpu.items()},
              "wall_s_per_step": {n: round(s, 4) for n, s in wall.items()}, "steps": steps, "skip": skip,
              "measured": f"{time.strftime('%Y-%m-%d %H:%M')}, {steps} steps ({skip} skipped), one torch thread, "
                          f"load average {load:.1f}, corpus {data}"}
    atomic_write_text(work / TIMING_FILE, json.dumps(result, indent=2) + "\n")
    return result
