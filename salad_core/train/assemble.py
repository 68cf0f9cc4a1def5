"""Assemble a :class:`~salad_core.pipeline.SaladPipeline` folder from a VAE run and a denoiser run.

Used for the shipped default weights (``scripts/assemble_weights.py``) and for the small ablation
models (``lab/scripts/ablations/train_ablations.py``). Each run's ``best`` checkpoint is taken (else ``latest``),
the VAE run's Mean/Std, the denoiser run's text encoder and diffusion config; the folder gets
``pipeline.json``, ``vae.*``, ``denoiser.*``, ``stats.safetensors`` and ``runs.json`` (the runs'
configs and last log lines, for model cards).

When a run's numerics differ from the release-0.5 trainers (length-bucketed batches with their loss
normaliser, cached VAE posteriors: recorded by the trainers in the run's ``config.json``), the
folder's ``MODEL_CARD.md`` gets a "Training numerics" section saying so (:func:`numerics_note`),
added to an existing card or starting a new one; the section is replaced when assembling again.
"""
from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import NamedTuple

import torch

from salad_core.io import atomic_write_text, config_from_dict, load_model, load_tensors, save_checkpoint, save_tensors

__all__ = ["run_checkpoint", "last_log_line", "assemble_pipeline", "export_vae", "numerics_note", "VaeSource", "vae_source",
           "write_numerics_section", "denoiser_vae", "check_denoiser_vae"]

log = logging.getLogger(__name__)

_BEGIN, _END = "<!-- training-numerics: begin -->", "<!-- training-numerics: end -->"


def run_checkpoint(run: str | Path) -> Path:
    """The checkpoint stem of a run folder: ``best`` if it was validated, else ``latest``."""
    run = Path(run)
    for name in ("best", "latest"):
        if (run / f"{name}.safetensors").is_file():
            return run / name
    raise FileNotFoundError(f"run folder {run} has no best/latest checkpoint (was it trained?)")


def last_log_line(run: str | Path) -> dict:
    """The last line of a run's ``log.jsonl`` (``{}`` when there is none)."""
    path = Path(run) / "log.jsonl"
    lines = path.read_text().splitlines() if path.is_file() else []
    return json.loads(lines[-1]) if lines else {}


def _run_record(run: Path) -> dict:
    return {"checkpoint": run_checkpoint(run).name, "config": json.loads((run / "config.json").read_text()),
            "last_log": last_log_line(run)}


class VaeSource(NamedTuple):
    """Where a VAE's weights, statistics and training record are (:func:`vae_source`)."""

    stem: Path
    """checkpoint stem (``<stem>.json`` + ``<stem>.safetensors``)"""
    stats: Path
    """the Mean/Std file it was trained with (``mean_std.safetensors`` of a run, ``stats.safetensors`` of an
    exported VAE or pipeline folder); it may be missing for very old runs (:attr:`has_stats`)"""
    record: dict
    """the run record (``checkpoint``, ``config``, ``last_log``) as ``runs.json`` keeps it (``{}`` if unknown)"""
    run: Path | None
    """the training run folder, or None for an exported VAE or a pipeline folder"""

    @property
    def has_stats(self) -> bool:
        return self.stats.is_file()

    @property
    def numerics(self) -> Path | dict:
        """The argument :func:`numerics_note` takes for this VAE: its run folder, else its recorded config."""
        return self.run if self.run is not None else self.record.get("config", {})


def vae_source(vae: str | Path) -> VaeSource:
    """The one resolver of a VAE location, used by the assembler, the denoiser trainer and the measuring
    scripts. ``vae`` may be

    - a training run folder (``best``/``latest`` checkpoint, ``mean_std.safetensors``, ``config.json``),
    - an exported VAE folder (:func:`export_vae`: ``vae.*``, ``stats.safetensors``, ``runs.json``) such as
      ``salad_core/weights/general_vae``, or a pipeline folder (same files beside the denoiser's),
    - a checkpoint stem or file inside either (``run/best``, ``run/latest.safetensors``, ``folder/vae``).
    """
    vae = Path(vae)
    if vae.suffix in (".json", ".safetensors"):
        vae = vae.with_suffix("")
    if not vae.is_dir():                                   # a checkpoint stem
        if not vae.with_suffix(".safetensors").is_file():
            raise FileNotFoundError(f"VAE {vae}: no such folder and no {vae.name}.safetensors checkpoint")
        stem, folder = vae, vae.parent
    elif (vae / "vae.safetensors").is_file() and not (vae / "config.json").is_file():
        stem, folder = vae / "vae", vae
    else:
        stem, folder = run_checkpoint(vae), vae
    if (folder / "config.json").is_file():                 # a training run
        record = _run_record(folder)
        record["checkpoint"] = stem.name
        return VaeSource(stem, folder / "mean_std.safetensors", record, folder)
    runs = folder / "runs.json"
    record = json.loads(runs.read_text()).get("vae", {}) if runs.is_file() else {}
    return VaeSource(stem, folder / "stats.safetensors", record, None)


def numerics_note(runs: dict[str, str | Path | dict]) -> str | None:
    """A Markdown paragraph on how the runs' numerics differ from release 0.5, or None if they do not.

    Parameters
    ----------
    runs : dict
        Name (e.g. ``"denoiser"``) -> run folder holding the ``config.json`` its trainer wrote, or that
        ``config.json`` already read (an exported VAE's ``runs.json`` record keeps it).
    """
    lines = []
    for name, run in runs.items():
        if isinstance(run, dict):
            doc = run
        else:
            path = Path(run) / "config.json"
            doc = json.loads(path.read_text()) if path.is_file() else {}
        runtime, numerics = doc.get("runtime", {}), dict(doc.get("task", {}).get("numerics", {}))
        changes = []
        batching = runtime.get("batching", "random")
        if batching != "random":
            changes.append(f"batches: {batching}")
        if int(runtime.get("micro_batches", 1)) > 1:
            changes.append(f"each batch in {runtime['micro_batches']} length-sorted micro-batches "
                           "(the same gradient, summed in another order)")
        if numerics.get("loss_normaliser") and batching != "random":
            changes.append(f"loss normaliser: {numerics['loss_normaliser']}")
        if numerics.get("latents", "").startswith("cached"):
            changes.append(f"latents: {numerics['latents']}")
        if runtime.get("autocast"):
            changes.append(f"forward passes under {runtime['autocast']} autocast (float32 weights, optimiser and "
                           "validation)")
        if changes:
            threads = runtime.get("torch_threads")
            where = "as recorded with the exported weights" if isinstance(run, dict) else Path(run).name
            lines.append(f"- **{name}** ({where}): " + "; ".join(changes)
                         + (f"; {threads} torch thread(s)" if threads else ""))
    if not lines:
        return None
    return ("## Training numerics\n\n"
            "These weights were trained with the issue-19 trainers, whose numerics differ from release 0.5 "
            "(random batches, VAE encoder at every step): the runs are not bit-comparable with older runs of the same "
            "config, while the objective is the same in expectation. Set `batching: \"random\"`, `micro_batches: 1`, "
            "`latent_cache: false` and `autocast: null` in the training config to train as release 0.5 did.\n\n" + "\n".join(lines) + "\n")


def write_numerics_section(card: str | Path, note: str | None) -> Path | None:
    """Put ``note`` into ``card`` (a ``MODEL_CARD.md``) between markers, replacing an earlier section;
    ``None`` removes it. Creates the card when it does not exist (and there is a note)."""
    card = Path(card)
    text = card.read_text() if card.is_file() else ""
    if _BEGIN in text and _END in text:
        head, rest = text.split(_BEGIN, 1)
        text = head.rstrip("\n") + rest.split(_END, 1)[1]
    if note is None:
        if card.is_file():
            atomic_write_text(card, text)
        return card if card.is_file() else None
    section = f"{_BEGIN}\n{note.rstrip()}\n{_END}\n"
    text = (text.rstrip("\n") + "\n\n" + section) if text.strip() else "# Model card\n\n" + section
    atomic_write_text(card, text)
    return card


def denoiser_vae(denoiser_run: str | Path) -> Path | None:
    """The VAE checkpoint stem a denoiser run trained on, as its ``config.json`` records it (``task.vae``), or
    None when the run does not say."""
    path = Path(denoiser_run) / "config.json"
    recorded = json.loads(path.read_text()).get("task", {}).get("vae") if path.is_file() else None
    return Path(recorded) if recorded else None


def check_denoiser_vae(source: VaeSource, denoiser_run: str | Path, *, rtol: float = 2e-3, atol: float = 1e-4) -> str:
    """Check that ``source`` is the VAE the denoiser run trained on: a denoiser diffuses in its VAE's latent space,
    so pairing it with another VAE gives a pipeline that loads and samples but decodes nonsense.

    The weights and Mean/Std are compared with the VAE the run recorded (``task.vae``) within float16 storage
    rounding (``rtol``, ``atol``), so an exported or float16 copy of the same VAE passes.

    Returns
    -------
    str
        ``"same"`` when they match, ``"unchecked: ..."`` when the recorded VAE is not recorded or no longer exists
        (a run folder from another machine).

    Raises
    ------
    ValueError
        When they differ, naming both VAEs and the first tensor that differs.
    """
    recorded = denoiser_vae(denoiser_run)
    if recorded is None:
        return "unchecked: the denoiser run does not record its VAE"
    if not recorded.with_suffix(".safetensors").is_file():
        return f"unchecked: the denoiser's VAE {recorded} is gone"
    theirs_src = vae_source(recorded)
    if theirs_src.stem.resolve() == source.stem.resolve():
        return "same"
    ours = load_tensors(source.stem.with_suffix(".safetensors"))
    theirs = load_tensors(theirs_src.stem.with_suffix(".safetensors"))
    pairs = [(f"weight {k!r}", ours.get(k), theirs[k]) for k in sorted(theirs)]
    if source.has_stats and theirs_src.has_stats:
        a, b = load_tensors(source.stats), load_tensors(theirs_src.stats)
        pairs += [(f"statistic {k!r}", a.get(k), b[k]) for k in ("mean", "std")]
    if set(ours) != set(theirs):
        raise ValueError(f"VAE {source.stem} is not the VAE denoiser run {denoiser_run} trained on ({recorded}): "
                         f"their weights have different names")
    for what, a, b in pairs:
        if a is None or a.shape != b.shape or not torch.allclose(a.float(), b.float(), rtol=rtol, atol=atol):
            raise ValueError(f"VAE {source.stem} is not the VAE denoiser run {denoiser_run} trained on ({recorded}): "
                             f"{what} differs; assemble with that VAE (or a copy of it)")
    return "same"


def assemble_pipeline(vae_run: str | Path | None, denoiser_run: str | Path, out: str | Path, *,
                      dtype: torch.dtype | None = torch.float16, text_encoder=None) -> Path:
    """Write a pipeline folder that ``SaladPipeline.from_pretrained(out)`` loads.

    Parameters
    ----------
    vae_run, denoiser_run : path
        Run folders written by ``salad train vae`` / ``salad train denoiser``; the VAE may also be an
        exported VAE folder (:func:`vae_source`). ``vae_run=None`` takes the VAE the denoiser run records.
        A VAE other than the one the denoiser trained on is refused (:func:`check_denoiser_vae`).
    out : path
        Pipeline folder (created; existing files of the same names are replaced atomically).
    dtype : torch.dtype or None
        Storage dtype of the weights (float16 by default; ``None`` keeps float32).
    text_encoder : optional
        An already loaded text encoder (default: the one the denoiser run names).
    """
    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import DiffusionConfig
    from salad_core.text import load_text_encoder

    denoiser_run, out = Path(denoiser_run), Path(out)
    if vae_run is None:
        vae_run = denoiser_vae(denoiser_run)
        if vae_run is None:
            raise ValueError(f"denoiser run {denoiser_run} does not record its VAE: give the VAE it trained on")
    source = vae_source(vae_run)
    if not source.has_stats:
        raise FileNotFoundError(f"VAE {vae_run}: no {source.stats.name} beside it (the Mean/Std it was trained with)")
    vae_check = check_denoiser_vae(source, denoiser_run)
    if vae_check != "same":
        log.warning("assembling %s with VAE %s: %s", denoiser_run, source.stem, vae_check)
    vae, _, _ = load_model(source.stem)
    den, _, _ = load_model(run_checkpoint(denoiser_run))
    stats = load_tensors(source.stats)
    task = json.loads((denoiser_run / "config.json").read_text()).get("task", {})
    diffusion = config_from_dict(DiffusionConfig, task["diffusion"]) if task.get("diffusion") else DiffusionConfig()
    encoder = text_encoder if text_encoder is not None else load_text_encoder(task.get("text_encoder", "minilm"))
    latent = denoiser_run / "latent_stats.safetensors"       # runs with latent_norm (absent: identity)
    latent_stats = None
    if latent.is_file():
        lat = load_tensors(latent)
        latent_stats = (lat["latent_mean"], lat["latent_std"])
    pipe = SaladPipeline(vae, den, encoder, stats["mean"].numpy(), stats["std"].numpy(), diffusion=diffusion,
                         latent_stats=latent_stats)
    pipe.save_pretrained(out, dtype=dtype)
    runs = {"vae": source.record, "denoiser": _run_record(denoiser_run), "vae_check": vae_check}
    atomic_write_text(out / "runs.json", json.dumps(runs, indent=2) + "\n")
    write_numerics_section(out / "MODEL_CARD.md",
                           numerics_note({"vae": source.numerics, "denoiser": denoiser_run}))
    return out


def export_vae(vae_run: str | Path, out: str | Path, *, dtype: torch.dtype | None = torch.float16) -> Path:
    """Write a VAE-only folder: ``vae.*`` (loadable with :func:`salad_core.io.load_model`), ``stats.safetensors``
    and ``runs.json``; for the VAE ablations, which have no denoiser."""
    out = Path(out)
    source = vae_source(vae_run)
    if not source.has_stats:
        raise FileNotFoundError(f"VAE {vae_run}: no {source.stats.name} beside it (the Mean/Std it was trained with)")
    out.mkdir(parents=True, exist_ok=True)
    vae, _, _ = load_model(source.stem)
    save_checkpoint(out / "vae", vae, model_type="salad_vae", config=vae.config, dtype=dtype)
    stats = load_tensors(source.stats)
    save_tensors(out / "stats.safetensors", {"mean": stats["mean"], "std": stats["std"]})
    atomic_write_text(out / "runs.json", json.dumps({"vae": source.record}, indent=2) + "\n")
    return out
