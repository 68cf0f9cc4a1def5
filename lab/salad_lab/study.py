"""The ablation study's recipe, training runs, shipping and loading (paper Tables 2-3, supplement Tables 2-4).

A JSON recipe (``lab/configs/ablations.json``) names VAE variants (skeleton-aware vs pose-vector VAE,
the VAE loss terms) and denoiser variants (w/o ST-Latent, w/o cross-attention, both, the three
diffusion parametrisations, w/o FiLM), each as overrides of the default configs with one shared
step budget per kind, so that variants differ only in what the ablation changes.

* :func:`load_recipe` reads and validates the recipe; :func:`plan_jobs` turns it into
  :class:`TrainJob` s (a denoiser job depends on its VAE job); :func:`run_jobs` trains them with
  ``python -m salad_core.train ... --resume`` in subprocesses, at most ``max_parallel`` at a time
  (each resumable, so an interrupted study continues where it stopped);
* :func:`ship` assembles the runs into a folder (default ``salad_core/weights/ablations``, package
  data): ``vae_<name>/`` VAE-only folders, ``<name>/`` pipeline folders, and ``index.json``;
* :func:`list_ablations`, :func:`load_ablation_pipeline` and :func:`load_ablation_vae` load
  what was shipped (used by the ablation notebooks).

The denoisers learn on the latents of the ablation VAEs (trained with the same budget), not on the
shipped VAE, so "w/o ST-Latent" compares two VAEs trained alike.
"""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["AblationVariant", "AblationRecipe", "TrainJob", "load_recipe", "plan_jobs", "run_jobs", "ship",
           "ablations_dir", "list_ablations", "load_ablation_pipeline", "load_ablation_vae"]

log = logging.getLogger(__name__)

KINDS = ("vae", "denoiser")


@dataclass(frozen=True)
class AblationVariant:
    """One variant of the study."""

    name: str                       # identifier, also the run and shipped folder name
    kind: str                       # "vae" or "denoiser"
    label: str                      # row label in the tables
    table: str                      # which paper table the row belongs to
    model: dict[str, Any] = field(default_factory=dict)      # model-config overrides
    diffusion: dict[str, Any] = field(default_factory=dict)  # denoiser only: DiffusionConfig overrides
    vae: str | None = None          # denoiser only: name of the VAE variant it learns on
    train: dict[str, Any] = field(default_factory=dict)      # training overrides (a table with its own budget)


@dataclass(frozen=True)
class AblationRecipe:
    """The whole study: base configs (full documents ``{model, train}``), budgets and variants."""

    vae_doc: dict[str, Any]         # the VAE config document every VAE variant starts from
    denoiser_doc: dict[str, Any]    # the denoiser config document every denoiser variant starts from
    variants: tuple[AblationVariant, ...]

    def variant(self, name: str) -> AblationVariant:
        for v in self.variants:
            if v.name == name:
                return v
        raise KeyError(f"no ablation variant {name!r}; the recipe has {[v.name for v in self.variants]}")


@dataclass(frozen=True)
class TrainJob:
    """One training run of the study."""

    variant: AblationVariant
    run_dir: Path                   # the run folder (config.json, checkpoints, log.jsonl)
    config: dict[str, Any]          # the config document passed with --config
    depends_on: Path | None         # the VAE run a denoiser job needs finished first


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def load_recipe(path: str | os.PathLike) -> AblationRecipe:
    """Read ``lab/configs/ablations.json``-style recipes; base config paths are relative to the recipe.

    Raises ``ValueError`` naming the problem (unknown VAE of a denoiser variant, unknown keys).
    """
    path = Path(path)
    doc = json.loads(path.read_text())
    for key in ("vae_base", "denoiser_base", "vaes", "denoisers"):
        if key not in doc:
            raise ValueError(f"ablation recipe {path}: missing key {key!r}")
    vae_doc = json.loads((path.parent / doc["vae_base"]).read_text())
    den_doc = json.loads((path.parent / doc["denoiser_base"]).read_text())
    vae_doc = _merge(vae_doc, {"train": doc.get("vae_train", {})})
    den_doc = _merge(den_doc, {"train": doc.get("denoiser_train", {}), "model": doc.get("denoiser_model", {})})
    allowed = {"label", "table", "model", "diffusion", "vae", "train"}
    variants = []
    for kind, group in (("vae", doc["vaes"]), ("denoiser", doc["denoisers"])):
        for name, spec in group.items():
            unknown = set(spec) - allowed
            if unknown:
                raise ValueError(f"ablation recipe {path}: variant {name!r} has unknown keys {sorted(unknown)}; "
                                 f"allowed: {sorted(allowed)}")
            if kind == "denoiser" and spec.get("vae") not in doc["vaes"]:
                raise ValueError(f"ablation recipe {path}: denoiser variant {name!r} names VAE {spec.get('vae')!r}, "
                                 f"which is not one of the VAE variants {sorted(doc['vaes'])}")
            if kind == "vae" and ("diffusion" in spec or "vae" in spec):
                raise ValueError(f"ablation recipe {path}: VAE variant {name!r} cannot set 'diffusion' or 'vae'")
            variants.append(AblationVariant(name=name, kind=kind, label=spec.get("label", name),
                                            table=spec.get("table", ""), model=spec.get("model", {}),
                                            diffusion=spec.get("diffusion", {}), vae=spec.get("vae"),
                                            train=spec.get("train", {})))
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ValueError(f"ablation recipe {path}: variant names must be unique across VAEs and denoisers: {names}")
    return AblationRecipe(vae_doc=vae_doc, denoiser_doc=den_doc, variants=tuple(variants))


def _vae_latent(vae_model_doc: dict[str, Any]) -> tuple[int, int]:
    """``(num_parts, z_dim)`` of a VAE config document (what its denoiser must be sized to)."""
    from salad_core.io import config_from_dict
    from salad_core.models.vae import VAEConfig

    cfg = config_from_dict(VAEConfig, vae_model_doc)
    return cfg.num_parts, cfg.z_dim


def plan_jobs(recipe: AblationRecipe, work: str | os.PathLike) -> list[TrainJob]:
    """The study's runs, VAEs first: ``work/vae_<name>`` and ``work/den_<name>``."""
    work = Path(work)
    jobs: list[TrainJob] = []
    vae_models: dict[str, dict[str, Any]] = {}
    for v in recipe.variants:
        if v.kind == "vae":
            doc = _merge(recipe.vae_doc, {"model": v.model, "train": v.train})
            vae_models[v.name] = doc["model"]
            jobs.append(TrainJob(v, work / f"vae_{v.name}", doc, None))
    for v in recipe.variants:
        if v.kind == "denoiser":
            parts, z_dim = _vae_latent(vae_models[v.vae])
            doc = _merge(recipe.denoiser_doc, {"model": {**v.model, "num_parts": parts, "latent_dim": z_dim},
                                               "diffusion": v.diffusion, "train": v.train})
            jobs.append(TrainJob(v, work / f"den_{v.name}", doc, work / f"vae_{v.vae}"))
    return jobs


def _finished(run_dir: Path, max_steps: int) -> bool:
    latest = run_dir / "latest.json"
    if not latest.is_file():
        return False
    meta = json.loads(latest.read_text())
    step = meta.get("step", meta.get("meta", {}).get("step", -1))
    return int(step) >= max_steps


def _outside_dependencies(jobs: list[TrainJob]) -> dict[str, int]:
    """Exit codes to assume for VAE runs that denoiser jobs need but that are not in ``jobs``:
    0 when the VAE is there (a run with a checkpoint, or an exported VAE folder), else -1."""
    from salad_core.train.assemble import vae_source

    names = {j.run_dir.name for j in jobs}
    codes = {}
    for j in jobs:
        if j.depends_on is not None and j.depends_on.name not in names:
            try:
                has_ckpt = vae_source(j.depends_on).stem.with_suffix(".safetensors").is_file()
            except FileNotFoundError:
                has_ckpt = False
            codes[j.depends_on.name] = 0 if has_ckpt else -1
    return codes


def job_command(job: TrainJob, data: str | os.PathLike, python: str = sys.executable) -> list[str]:
    """The ``python -m salad_core.train`` command of a job (its config is written beside its run)."""
    cfg_path = job.run_dir.parent / "configs" / f"{job.run_dir.name}.json"
    cfg_path.parent.mkdir(parents=True, exist_ok=True)
    cfg_path.write_text(json.dumps(job.config, indent=2) + "\n")
    cmd = [python, "-m", "salad_core.train", job.variant.kind, "--data", str(data), "--out", str(job.run_dir),
           "--config", str(cfg_path), "--resume", "--no-progress"]
    if job.depends_on is not None:
        cmd += ["--vae", str(job.depends_on)]
    return cmd


def run_jobs(jobs: list[TrainJob], data: str | os.PathLike, *, max_parallel: int = 1,
             python: str = sys.executable, poll_s: float = 2.0, inline: bool = False) -> dict[str, int]:
    """Train the jobs (``--resume``: finished runs return at once), dependencies first.

    Each job runs as a subprocess (one torch thread each) whose output goes to ``<run_dir>.log``;
    with ``inline=True`` the jobs run one after the other in this process instead (no start-up
    cost; ``max_parallel`` is then ignored). Returns the exit code of each job by run name; a failed
    VAE job fails its denoiser jobs (code -1, not started).
    """
    if max_parallel < 1:
        raise ValueError(f"max_parallel={max_parallel!r} is invalid; use an integer >= 1")
    if inline:
        return _run_inline(jobs, data)
    pending = list(jobs)
    running: dict[str, tuple[subprocess.Popen, Any]] = {}
    codes: dict[str, int] = _outside_dependencies(jobs)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    while pending or running:
        for name, (proc, fh) in list(running.items()):
            if proc.poll() is not None:
                fh.close()
                codes[name] = proc.returncode
                log.info("%s finished with exit code %d", name, proc.returncode)
                del running[name]
        for job in list(pending):
            if len(running) >= max_parallel:
                break
            dep = job.depends_on.name if job.depends_on is not None else None
            if dep is not None and dep not in codes:
                continue                                  # its VAE is still training
            pending.remove(job)
            if dep is not None and codes[dep] != 0:
                codes[job.run_dir.name] = -1
                log.error("%s not started: its VAE run %s failed", job.run_dir.name, dep)
                continue
            job.run_dir.parent.mkdir(parents=True, exist_ok=True)
            fh = open(job.run_dir.parent / f"{job.run_dir.name}.log", "a")
            log.info("training %s", job.run_dir.name)
            running[job.run_dir.name] = (subprocess.Popen(job_command(job, data, python), stdout=fh,
                                                          stderr=subprocess.STDOUT, env=env), fh)
        if running:
            time.sleep(poll_s)
    return {j.run_dir.name: codes[j.run_dir.name] for j in jobs}


def _run_inline(jobs: list[TrainJob], data: str | os.PathLike) -> dict[str, int]:
    from salad_core.cli.train import main as train_main

    codes: dict[str, int] = _outside_dependencies(jobs)
    for job in jobs:
        dep = job.depends_on.name if job.depends_on is not None else None
        if dep is not None and codes.get(dep) != 0:
            codes[job.run_dir.name] = -1
            log.error("%s not started: its VAE run %s failed", job.run_dir.name, dep)
            continue
        argv = job_command(job, data)[3:]          # drop "python -m salad_core.train"
        try:
            codes[job.run_dir.name] = int(train_main(argv) or 0)
        except SystemExit as exc:                   # argparse / config errors
            codes[job.run_dir.name] = exc.code if isinstance(exc.code, int) else 1
    return {j.run_dir.name: codes[j.run_dir.name] for j in jobs}


def ship(jobs: list[TrainJob], out: str | os.PathLike, *, text_encoder=None) -> Path:
    """Assemble the trained runs into ``out`` (fp16): ``vae_<name>/``, ``<name>/`` and ``index.json``
    (merged with an existing index, so shipping a subset keeps the other entries)."""
    from salad_core.io import atomic_write_text
    from salad_core.train.assemble import assemble_pipeline, export_vae, last_log_line

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # shipping a subset (``--only``) keeps the entries of the models shipped before
    index: dict[str, Any] = json.loads((out / "index.json").read_text()) if (out / "index.json").is_file() else {}
    for job in jobs:
        v = job.variant
        if v.kind == "vae":
            folder = export_vae(job.run_dir, out / f"vae_{v.name}")
        else:
            folder = assemble_pipeline(job.depends_on, job.run_dir, out / v.name, text_encoder=text_encoder)
            _share_vae(folder, out / f"vae_{v.vae}")
        last = last_log_line(job.run_dir)
        index[folder.name] = {"variant": v.name, "kind": v.kind, "label": v.label, "table": v.table,
                              "vae": f"vae_{v.vae}" if v.vae else None, "steps": last.get("step"),
                              "model": v.model, "diffusion": v.diffusion}
    atomic_write_text(out / "index.json", json.dumps(index, indent=2) + "\n")
    return out


def _share_vae(pipeline_dir: Path, vae_dir: Path) -> None:
    """Point a shipped pipeline at its VAE variant's folder instead of a byte-identical copy.

    Several denoisers learn on the same VAE (and the pose-vector VAE alone is 5 MB), so the pipeline's
    ``vae.*`` files are removed and ``pipeline.json`` names ``../vae_<name>/vae``. A VAE folder that
    is missing or holds other weights leaves the pipeline's own copy in place.
    """
    from salad_core.io import atomic_write_text

    own, shared = pipeline_dir / "vae.safetensors", vae_dir / "vae.safetensors"
    if not (shared.is_file() and own.is_file() and shared.read_bytes() == own.read_bytes()
            and (vae_dir / "vae.json").read_bytes() == (pipeline_dir / "vae.json").read_bytes()):
        return
    doc = json.loads((pipeline_dir / "pipeline.json").read_text())
    doc["vae"] = f"../{vae_dir.name}/vae"
    atomic_write_text(pipeline_dir / "pipeline.json", json.dumps(doc, indent=2) + "\n")
    own.unlink()
    (pipeline_dir / "vae.json").unlink()


# ------------------------------------------------------------------------------ loading
# Loading what was shipped is the toolkit's (the notebooks use it): salad_core.ablation_models.
from salad_core.ablation_models import ablations_dir, list_ablations, load_ablation_pipeline, load_ablation_vae  # noqa: E402
