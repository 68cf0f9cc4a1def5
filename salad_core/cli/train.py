"""``salad train vae|denoiser|keymotion ...``: the command line of the trainers (also ``python -m salad_core.train``).

Under ``torchrun --nproc_per_node=N -m salad_core.train ...`` the same command trains with DDP.

The ``--config`` file is JSON, either a bare training config (the fields of
:class:`~salad_core.train.config.VAETrainConfig` / ``DenoiserTrainConfig``) or a document with any
of the keys ``"train"``, ``"model"`` (the model config), ``"diffusion"`` and ``"text_encoder"``,
which is the shape of a run's own ``config.json``. With ``--resume`` and no ``--config`` the run's
``config.json`` is used.

The file is read as the weight folders' JSON files are (:func:`salad_core.limits.read_json`: size, UTF-8 and
nesting checked before parsing) and checked against :func:`config_schema` before anything is built: a
misspelt key (``"lrr"``) is named with the closest known one (``'lr'``), a value of the wrong JSON type or a
model size beyond :data:`salad_core.limits.CONFIG_MAX_INT` is refused. Such a file is a :class:`ConfigError`:
one line ``salad train: error: ...`` and exit status 2, before ``--out`` is created.

``keymotion`` trains the keyframe VAE, the PST and the MMAE one after the other into
``--out/{kf_vae,pst,mmae}`` (:func:`salad_core.keymotion.train.train_keymotion`). Its ``--config``
is a :class:`~salad_core.keymotion.train.KeyMotionRecipe` document (``configs/keymotion-0.2.json``:
``text_encoder``, shared ``train`` fields, and ``kf_vae``/``pst``/``mmae`` sections with ``model`` and
``train``); the resolved recipe is written to ``--out/config.json``, which ``--resume`` reads when
no ``--config`` is given. ``--steps`` and ``--batch-size`` apply to every stage,
``--steps-per-stage KF_VAE PST MMAE`` to each stage. With ``--resume`` finished stages are skipped
and an interrupted one continues exactly.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Any, Sequence

from salad_core import limits
from salad_core.io import config_from_dict

from salad_core.train.config import DenoiserTrainConfig, VAETrainConfig

log = logging.getLogger(__name__)

__all__ = ["main", "build_parser", "TRAIN_TARGETS", "ConfigError", "config_schema", "check_config_doc"]


class ConfigError(ValueError):
    """A ``--config`` file (or a run's ``config.json``) ``salad train`` does not read: one line, exit status 2."""

#: What ``salad train`` can train (the single source of the ``what`` choices).
TRAIN_TARGETS: tuple[str, ...] = ("vae", "denoiser", "keymotion")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="salad train", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Train the SALAD VAE or denoiser, or the three KeyMotion models.",
        epilog="example:\n  salad train vae --data data/procedural --out runs/vae --config configs/salad-0.3/vae.json\n"
               "  salad train vae --data data/procedural --out runs/vae_dec --config lab/configs/v2_vae_decoder.json "
               "--init-from runs/vae --train-parts decoder\n"
               "  salad train denoiser --data data/procedural --out runs/denoiser --vae runs/vae\n"
               "  salad train keymotion --data data/procedural --out runs/keymotion --config configs/keymotion-0.2.json")
    parser.add_argument("what", choices=TRAIN_TARGETS, help="which model to train")
    parser.add_argument("--data", required=True, help="HumanML3D-layout data folder")
    parser.add_argument("--out", required=True, help="run folder (checkpoints, logs)")
    parser.add_argument("--config", help="JSON file: a training config or {train, model, diffusion, text_encoder}")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out exactly where it stopped")
    parser.add_argument("--steps", type=int, help="max optimiser steps (overrides the config; keymotion: every stage)")
    parser.add_argument("--steps-per-stage", type=int, nargs=3, metavar=("KF_VAE", "PST", "MMAE"),
                        help="keymotion only: max optimiser steps of each stage (overrides the config)")
    parser.add_argument("--batch-size", type=int, help="global batch size (overrides the config)")
    parser.add_argument("--vae", help="denoiser only: VAE run folder or checkpoint")
    parser.add_argument("--general", metavar="DIR",
                        help="vae only: uncaptioned general-motion folder mixed into training "
                             "(scripts/build_general_motion.py; overrides the config's general_data)")
    parser.add_argument("--general-ratio", type=float, metavar="R",
                        help="vae only: share of windows drawn from --general (default 0.5)")
    parser.add_argument("--init-from", metavar="DIR",
                        help="vae only: start from this VAE run or pipeline folder (its weights and normalisation; "
                             "overrides the config's init_from)")
    parser.add_argument("--train-parts", choices=("all", "decoder"),
                        help="vae only: 'decoder' freezes the encoder so its posteriors stay bit-identical "
                             "(needs --init-from or the config's init_from); default 'all'")
    parser.add_argument("--text-encoder", help="denoiser, keymotion: 'minilm' (default) or a local CLIP folder")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    return parser


#: What a run folder's config written before 0.6 (no batching/latent-cache fields) trained with.
_LEGACY_FIELDS = {"batching": "random", "latent_cache": False}


def _keep_legacy_numerics(doc: dict[str, Any], what: str) -> dict[str, Any]:
    """A run started before 0.6 continues with the numerics it started with (random batches, VAE encoder
    per step): the fields its config.json lacks get their 0.5 values instead of today's defaults."""
    fields = dict(_LEGACY_FIELDS) if what != "vae" else {"batching": "random"}
    if what == "keymotion":
        doc = dict(doc)
        for stage in ("kf_vae", "pst", "mmae"):
            section = dict(doc.get(stage) or {})
            section["train"] = {**fields, **(section.get("train") or {})}
            doc[stage] = section
        return doc
    if "runtime" in doc:              # written by a 0.6+ trainer: its train section is complete
        return doc
    if "train" in doc:
        return {**doc, "train": {**fields, **doc["train"]}}
    return {**fields, **doc}


def _has_train_field(doc: dict[str, Any], name: str) -> bool:
    """Whether any train section of a run's config (the shared one or a KeyMotion stage's) sets ``name``."""
    trains = [doc.get("train")] + [(doc.get(stage) or {}).get("train") for stage in ("kf_vae", "pst", "mmae")]
    return any(isinstance(t, dict) and name in t for t in trains)


def _keep_own_optimizer(doc: dict[str, Any], what: str) -> dict[str, Any]:
    """A run whose config.json predates ``TrainConfig.adamw`` trained with PyTorch's per-tensor AdamW loop
    and resumes with it (the fused default computes the same update, but not bit for bit)."""
    if _has_train_field(doc, "adamw"):
        return doc
    if "train" in doc or what == "keymotion":
        return {**doc, "train": {**(doc.get("train") or {}), "adamw": "loop"}}
    return {**doc, "adamw": "loop"}


#: The sections of a ``vae`` / ``denoiser`` config document and their JSON types (a run's ``config.json`` also
#: records ``model_type``, ``task`` and ``runtime``); a bare training config holds the training fields at the
#: top level instead of a ``"train"`` section.
DOC_FIELDS: dict[str, Any] = {"train": dict, "model": dict, "diffusion": dict | None, "text_encoder": str,
                              "model_type": str, "task": dict, "runtime": dict}
#: The entries of a run's ``task`` record that ``salad train denoiser`` reads (the rest is not read).
TASK_FIELDS: dict[str, Any] = {"vae": str, "diffusion": dict | None, "text_encoder": str}
#: The sections of a ``keymotion`` recipe (:class:`~salad_core.keymotion.train.KeyMotionRecipe`), and of each
#: of its stages.
KEYMOTION_FIELDS: dict[str, Any] = {"text_encoder": str, "train": dict | None, "kf_vae": dict | None,
                                    "pst": dict | None, "mmae": dict | None}
KEYMOTION_STAGE_FIELDS: dict[str, Any] = {"model": dict | None, "train": dict | None}


def config_schema(what: str) -> dict[str, tuple[type, type | None]]:
    """``{section: (training config class, model config class or None)}`` of ``salad train what``'s config
    document; the keymotion stages by their names, ``"train"`` is the training fields every stage shares."""
    if what == "keymotion":
        from salad_core.keymotion.train import _MODEL_CONFIGS, STAGES, KeyMotionTrainConfig

        return {"train": (KeyMotionTrainConfig, None),
                **{stage: (KeyMotionTrainConfig, _MODEL_CONFIGS[stage]) for stage in STAGES}}
    if what == "vae":
        from salad_core.models.vae import VAEConfig

        return {"train": (VAETrainConfig, VAEConfig)}
    from salad_core.models.denoiser import DenoiserConfig

    return {"train": (DenoiserTrainConfig, DenoiserConfig)}


def _check_section(data: Any, config_cls: type, where: str, *, model: bool) -> None:
    """One section against its config dataclass: known keys, JSON types; a model's integers within
    :data:`~salad_core.limits.CONFIG_MAX_INT` (a training config's seeds and step counts may be larger)."""
    if model:
        limits.check_config_values(config_cls, data, where, ConfigError, ConfigError)
    else:
        limits.check_fields(data, limits.config_fields(config_cls), where, ConfigError, ConfigError)


def check_config_doc(doc: dict[str, Any], what: str, source: str) -> None:
    """Check a ``salad train what`` config document (a JSON object) against :func:`config_schema` before
    anything is built; raises :class:`ConfigError` naming ``source``, the section and the key (a misspelt
    key with the closest known one). Top-level keys starting with ``_`` are comments (``"_note"``,
    ``"_command"`` of the shipped configs) and are not read."""
    doc = {k: v for k, v in doc.items() if not str(k).startswith("_")}
    if what == "keymotion":
        _check_keymotion_doc(doc, source)
    else:
        _check_model_doc(doc, what, source)


def _check_model_doc(doc: dict[str, Any], what: str, source: str) -> None:
    """:func:`check_config_doc` of a ``vae`` / ``denoiser`` document: :data:`DOC_FIELDS` or a bare training
    config, the model and diffusion sections, and what ``task`` holds that the trainer reads."""
    from salad_core.sampling import DiffusionConfig

    train_cls, model_cls = config_schema(what)["train"]
    if "train" in doc:
        limits.check_fields(doc, DOC_FIELDS, source, ConfigError, ConfigError)
        _check_section(doc["train"], train_cls, f"{source}: 'train'", model=False)
    else:       # a bare training config, perhaps beside the model's sections ("train" named for a misspelt one)
        limits.check_fields(doc, {**limits.config_fields(train_cls), **DOC_FIELDS}, source, ConfigError, ConfigError)
    if "model" in doc:
        _check_section(doc["model"], model_cls, f"{source}: 'model'", model=True)
    task = doc.get("task") or {}
    limits.check_fields({k: v for k, v in task.items() if k in TASK_FIELDS}, TASK_FIELDS, f"{source}: 'task'",
                        ConfigError, ConfigError)
    for where, diffusion in ((f"{source}: 'diffusion'", doc.get("diffusion")),
                             (f"{source}: 'task': 'diffusion'", task.get("diffusion"))):
        if diffusion:
            _check_section(diffusion, DiffusionConfig, where, model=True)


def _check_keymotion_doc(doc: dict[str, Any], source: str) -> None:
    """:func:`check_config_doc` of a KeyMotion recipe: :data:`KEYMOTION_FIELDS`, the shared training fields and
    each stage's ``model`` and ``train``."""
    schema = config_schema("keymotion")
    limits.check_fields(doc, KEYMOTION_FIELDS, source, ConfigError, ConfigError)
    if doc.get("train") is not None:
        _check_section(doc["train"], schema["train"][0], f"{source}: 'train'", model=False)
    for stage, (train_cls, model_cls) in schema.items():
        section = doc.get(stage) if stage != "train" else None
        if section is None:
            continue
        where = f"{source}: {stage!r}"
        limits.check_fields(section, KEYMOTION_STAGE_FIELDS, where, ConfigError, ConfigError)
        if section.get("train") is not None:
            _check_section(section["train"], train_cls, f"{where}: 'train'", model=False)
        if section.get("model"):
            _check_section(section["model"], model_cls, f"{where}: 'model'", model=True)


#: Where each ``salad train`` target's config format is shown.
_EXAMPLE_CONFIG = {"vae": "configs/salad-0.3/vae.json", "denoiser": "configs/salad-0.3/denoiser.json",
                   "keymotion": "configs/keymotion-0.2.json"}


def _read_config_json(path: Path, label: str, what: str) -> dict[str, Any]:
    """The JSON object of a config file, read with :func:`salad_core.limits.read_json` (size, UTF-8 and nesting
    before parsing); ``label`` names the file in the :class:`ConfigError` (``"--config FILE"``)."""
    if not path.is_file():
        raise ConfigError(f"{label}: no such file")
    try:
        return limits.read_json(path, "training config", error=ConfigError)
    except ConfigError as exc:
        reason = getattr(exc, "reason", str(exc))
        raise ConfigError(f"{label} is not a JSON document ({reason}); see {_EXAMPLE_CONFIG[what]} for the "
                          "format") from None


def _read_doc(args: argparse.Namespace) -> dict[str, Any]:
    path = Path(args.config) if args.config else None
    own = False
    if path is None and args.resume and (Path(args.out) / "config.json").is_file():
        path, own = Path(args.out) / "config.json", True
    if path is None:
        return {}
    label = f"--config {path}" if not own else f"{path} (the run's own config, read by --resume)"
    doc = _read_config_json(path, label, args.what)
    check_config_doc(doc, args.what, label)
    if own and not _has_train_field(doc, "batching"):
        log.info("%s predates length buckets and the latent cache: resuming with the numerics it started with", path)
        doc = _keep_legacy_numerics(doc, args.what)
    if own:
        doc = _keep_own_optimizer(doc, args.what)
    return {**doc, "_path": str(path)}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the trainer; returns the process exit code (130 when stopped by a signal; 2 with one line
    ``salad train: error: ...`` on stderr for a config file it does not read, :class:`ConfigError`)."""
    try:
        return _run(argv)
    except ConfigError as exc:
        print(f"salad train: error: {exc}", file=sys.stderr)
        return 2


def _run(argv: Sequence[str] | None) -> int:
    """:func:`main` itself."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.steps_per_stage is not None and args.what != "keymotion":
        parser.error("--steps-per-stage is for keymotion only (use --steps)")
    if args.steps_per_stage is not None and args.steps is not None:
        parser.error("give --steps (every stage) or --steps-per-stage, not both")
    if args.steps_per_stage is not None and min(args.steps_per_stage) < 0:
        parser.error(f"--steps-per-stage {args.steps_per_stage} must be integers >= 0")
    if args.vae is not None and args.what == "keymotion":
        parser.error("--vae is for the denoiser only (keymotion trains its own keyframe VAE)")
    if (args.general is not None or args.general_ratio is not None) and args.what != "vae":
        parser.error("--general/--general-ratio are for 'salad train vae' only")
    if (args.init_from is not None or args.train_parts is not None) and args.what != "vae":
        parser.error(f"--init-from/--train-parts are for 'salad train vae' only (fine-tuning a VAE), not {args.what!r}")
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    from salad_core.allocator import tune_from_environment

    tune_from_environment()   # as the salad command does; also under torchrun -m salad_core.train (whose
    # __main__ chose the OpenMP wait policy before torch loaded: salad_core.cli.tune_process)
    doc = _read_doc(args)
    if args.what == "keymotion":
        return _main_keymotion(args, doc)
    cls = VAETrainConfig if args.what == "vae" else DenoiserTrainConfig
    train_doc = doc.get("train", {k: v for k, v in doc.items() if k not in DOC_FIELDS and not k.startswith("_")})
    overrides = {"max_steps": args.steps, "batch_size": args.batch_size}
    if args.what == "vae":
        overrides.update(general_data=args.general, general_ratio=args.general_ratio,
                         init_from=args.init_from, train_parts=args.train_parts)
    if args.no_progress:
        overrides["progress"] = False
    train_config = config_from_dict(cls, {**train_doc, **{k: v for k, v in overrides.items() if v is not None}})

    from salad_core.train.distributed import init_distributed, shutdown_distributed

    env = init_distributed(train_config.device)
    if not env.is_main:
        logging.getLogger().setLevel(logging.WARNING)
    try:
        if args.what == "vae":
            from salad_core.models.vae import VAEConfig

            from salad_core.train.vae_trainer import train_vae

            model_config = config_from_dict(VAEConfig, doc["model"]) if "model" in doc else None
            result = train_vae(args.data, args.out, model_config, train_config, resume=args.resume, env=env)
        else:
            from salad_core.models.denoiser import DenoiserConfig
            from salad_core.sampling import DiffusionConfig

            from salad_core.train.denoiser_trainer import train_denoiser

            task_doc = doc.get("task", {})
            vae_path = args.vae or task_doc.get("vae")
            if not vae_path:
                raise SystemExit("salad train denoiser needs --vae (a VAE run folder or checkpoint)")
            model_config = config_from_dict(DenoiserConfig, doc["model"]) if "model" in doc else None
            diff = doc.get("diffusion", task_doc.get("diffusion"))
            diffusion_config = config_from_dict(DiffusionConfig, diff) if diff else None
            text_encoder = args.text_encoder or doc.get("text_encoder", task_doc.get("text_encoder", "minilm"))
            result = train_denoiser(args.data, args.out, vae_path, model_config, train_config, text_encoder,
                                    resume=args.resume, diffusion_config=diffusion_config, env=env)
    finally:
        shutdown_distributed()
    if env.is_main:
        print(f"{args.what}: step {result.step}, last loss {result.last_loss}, best val {result.best_val} "
              f"(step {result.best_step}), {result.steps_per_s:.3f} steps/s, {result.frames_per_s:.0f} frames/s on "
              f"{result.threads} torch thread(s) -> {result.out_dir}")
    return 130 if result.interrupted else 0


def _main_keymotion(args: argparse.Namespace, doc: dict[str, Any]) -> int:
    """``salad train keymotion``: the three stages into ``args.out``."""
    from salad_core.io import atomic_write_text
    from salad_core.keymotion.train import STAGES, KeyMotionRecipe, train_keymotion

    overrides: dict[str, Any] = {"max_steps": args.steps, "batch_size": args.batch_size}
    if args.no_progress:
        overrides["progress"] = False
    per_stage = dict(zip(STAGES, ({"max_steps": n} for n in args.steps_per_stage))) if args.steps_per_stage else None
    if args.text_encoder:
        doc = {**doc, "text_encoder": args.text_encoder}
    try:
        recipe = KeyMotionRecipe.from_doc(doc, train_overrides=overrides, stage_overrides=per_stage)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"--config {doc.get('_path', '(defaults)')}: {exc}") from None
    out = Path(args.out)
    if not args.resume and any((out / stage / "train_state.safetensors").exists() for stage in STAGES):
        raise SystemExit(f"{out} already holds a KeyMotion training run; pass --resume to continue it "
                         "or choose another --out folder")

    from salad_core.train.distributed import init_distributed, shutdown_distributed

    env = init_distributed(recipe.kf_vae_train.device)
    if not env.is_main:
        logging.getLogger().setLevel(logging.WARNING)
    try:
        if env.is_main:
            out.mkdir(parents=True, exist_ok=True)
            # the resolved recipe: what --resume without --config continues
            atomic_write_text(out / "config.json", json.dumps(recipe.to_doc(), indent=2) + "\n")
        results = train_keymotion(args.data, args.out, **recipe.train_kwargs(), resume=args.resume, env=env)
    finally:
        shutdown_distributed()
    if env.is_main:
        for stage, result in results.items():
            print(f"keymotion {stage}: step {result.step}, last loss {result.last_loss}, best val {result.best_val} "
                  f"(step {result.best_step}), {result.steps_per_s:.3f} steps/s, {result.frames_per_s:.0f} frames/s "
                  f"on {result.threads} torch thread(s) -> {result.out_dir}")
    return 130 if any(r.interrupted for r in results.values()) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
