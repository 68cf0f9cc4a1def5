"""SaladPipeline: text -> motion, the thin orchestration of text encoder, denoiser, sampler and VAE.

Models know nothing of sampling, the sampler (:func:`salad_core.sampling.denoise`) knows nothing of
text or motion formats; this module joins them:

1. validate prompts and lengths; encode the prompts and the null text once;
2. draw per-sample initial noise ``(N'_max, P, Dz)`` from a per-sample seed, so a motion does not
   depend on what else is in the batch, and generate only the latent frames the longest motion of
   the batch needs (padded frames are masked, so the result is the same as padding to 196);
3. denoise with classifier-free guidance; decode with the VAE; de-normalise; recover joints.

Editing (:meth:`SaladPipeline.edit`, SALAD supplement B, Algorithm 1) samples a source and an
edited motion side by side from the same noise in one batched forward per step; given motions are
edited after :meth:`SaladPipeline.invert` (DDIM inversion, faithful under guidance), see
:mod:`salad_core.attention`.

A pretrained folder holds ``pipeline.json`` (text encoder, diffusion config, skeleton, solver and,
when not 50, the sampler steps), ``vae.{safetensors,json}``, ``denoiser.{safetensors,json}`` and
``stats.safetensors`` (Mean/Std). ``SaladPipeline.from_pretrained()`` with no path loads the shipped
default from ``salad_core/weights/salad``; ``preset="realtime"`` the few-step student distilled from it
(:mod:`salad_core.train.consistency`), ``salad_core/weights/salad_realtime``.
"""
from __future__ import annotations

import json
import logging
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import torch

from salad_core import limits
from salad_core.io import (CheckpointError, CheckpointTypeError, atomic_write_text, checkpoint_files, config_from_dict,
                           config_to_dict, load_model, load_tensors, save_checkpoint, save_tensors)
from salad_core.models.denoiser import Denoiser, TextContext
from salad_core.models.vae import MotionVAE
from salad_core.motion import MAX_FEATURE_MAGNITUDE, denormalize, features_to_joints, normalize
from salad_core.sampling import SOLVERS, DiffusionConfig, Guidance, denoise, make_scheduler, resolve_guidance
from salad_core.sampling import MAX_GUIDANCE  # noqa: F401  (salad_core.cli imports it from here)
from salad_core.skeleton import Skeleton
from salad_core.text import TextBatch, TextEncoder, load_text_encoder, validate_prompts
from salad_core.vocabulary import (UnknownWordsWarning, check_prompt, unknown_words_message, vocabulary_and_source,
                                   write_vocabulary)

if TYPE_CHECKING:  # pragma: no cover - annotations only: salad_core.attention is imported when used
    from salad_core.attention import AttentionMaps, CaptureConfig, EditController, EditSpec, Inversion
    from salad_core.attention.hooks import ActivationCache, HookFn, NameFilter

__all__ = ["SaladPipeline", "MotionOutput", "EditOutput", "default_weights_dir", "realtime_weights_dir",
           "validate_prompts", "validate_lengths", "PIPELINE_JSON_FIELDS", "PIPELINE_PRESETS", "DEFAULT_NUM_STEPS",
           "guidance_from_json"]

log = logging.getLogger(__name__)


def default_weights_dir() -> Path:
    """Folder of the shipped default SALAD weights (package data)."""
    return Path(__file__).resolve().parent / "weights" / "salad"


def realtime_weights_dir() -> Path:
    """Folder of the few-step ("realtime") SALAD weights, a consistency-distilled student of the default weights
    (:mod:`salad_core.train.consistency`); absent until they are distilled."""
    return Path(__file__).resolve().parent / "weights" / "salad_realtime"


#: Named weight folders of :meth:`SaladPipeline.from_pretrained` ``preset=``: the folder it loads (unless a path
#: is given) and the command that makes the folder when it is missing.
PIPELINE_PRESETS: dict[str, tuple[Any, str]] = {
    "realtime": (realtime_weights_dir,
                 "python lab/scripts/salad/distill_realtime.py --data CORPUS --out RUN --export "
                 "salad_core/weights/salad_realtime (in the salad repository; CORPUS: the teacher's corpus)"),
}

#: Sampler steps of a weight folder whose ``pipeline.json`` names none (the official DDIM-50 sampler).
DEFAULT_NUM_STEPS = 50


@dataclass
class MotionOutput:
    """Generated motions.

    Attributes
    ----------
    features : np.ndarray
        ``(B, N_max, D)`` de-normalised HumanML3D features, zero beyond each length.
    joints : list of np.ndarray
        Per sample ``(N_b, J, 3)`` joint positions (metres for HumanML3D), recovered from the
        features by the pipeline's :attr:`SaladPipeline.recovery` method (``settings["recovery"]``;
        by default a fixed-bone-length fit with the feet locked from the contact channels, see
        :mod:`salad_core.recovery`). The GIF, BVH and NPY files the command line writes show these.
    texts : list of str
    lengths : list of int
        Frames per sample (multiples of 4).
    latents : torch.Tensor
        ``(B, N'_max, P, Dz)`` final latents (padded frames zero).
    noise : torch.Tensor
        ``(B, N'_max, P, Dz)`` the initial noise, so the same start can be reused for edits.
    seeds : list of int
        Per-sample noise seeds.
    attention : AttentionMaps or None
        Captured attention maps (:class:`salad_core.attention.AttentionMaps`) when requested.
    settings : dict
        Guidance scale, steps, solver: everything needed to regenerate.
    unknown_words : list of list of str
        Per prompt, what of it the weights never saw in training (:attr:`SaladPipeline.vocabulary`):
        unknown words and pieces in another script or emoji, in prompt order; ``[]`` when all known.
    """

    features: np.ndarray
    joints: list[np.ndarray]
    texts: list[str]
    lengths: list[int]
    latents: torch.Tensor
    noise: torch.Tensor
    seeds: list[int]
    attention: AttentionMaps | None = None
    settings: dict = field(default_factory=dict)
    unknown_words: list[list[str]] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.texts)

    @property
    def raw_joints(self) -> list[np.ndarray]:
        """Per sample ``(N_b, J, 3)`` joints read from the position features as they are (HumanML3D's
        ``recover_from_ric``, no fit): what the metrics of the papers use."""
        skeleton = self.settings.get("skeleton", "humanml3d")
        return [features_to_joints(self.features[b, :n], skeleton).astype(np.float32)
                for b, n in enumerate(self.lengths)]


@dataclass
class EditOutput:
    """A source motion and its edit, with everything needed to regenerate both.

    Attributes
    ----------
    source : MotionOutput
        The source motion (for a given motion: its reconstruction from the inverted noise), with
        ``attention`` = the source maps ``M`` when capture was requested.
    edited : MotionOutput
        The edited motion; ``texts`` are the target prompts, ``attention`` the maps it used
        (``M_hat`` where the edit replaced them).
    noise : torch.Tensor
        ``(B, N', P, Dz)`` the initial noise both share (Algorithm 1, line 4).
    edits : tuple of EditSpec
        The edit specification, in order.
    settings : dict
        Guidance scale, steps, solver, weights, ``probe``, the inversion method if any, and the
        cost: ``forward_rows`` and ``cost_vs_generation`` (forward rows relative to one plain
        CFG generation of the source).
    prior : MotionOutput or None
        With ``Inpaint(prior="prompt")``: the target prompts sampled alone, whose latents were pasted into the
        region (its ``lengths`` are the prior clips' own; ``settings["inpaint_prior"]["windows"]`` says which of its
        latent frames went where, :meth:`Inpaint.prior_window
        <salad_core.attention.inpaint.Inpaint.prior_window>`); None otherwise.
    """

    source: MotionOutput
    edited: MotionOutput
    noise: torch.Tensor
    edits: tuple[EditSpec, ...]
    settings: dict = field(default_factory=dict)
    prior: MotionOutput | None = None


def validate_lengths(lengths: int | Sequence[int] | None, n: int, skeleton: Skeleton,
                     default: int = 120, stacklevel: int = 3) -> list[int]:
    """Per-sample lengths in frames: positive, at most ``skeleton.max_length``; lengths that are
    not multiples of ``unit_length`` are floored to one, with a warning saying so (attributed
    ``stacklevel`` frames up: 3 = the caller of the function that calls this one)."""
    unit, max_len = skeleton.unit_length, skeleton.max_length
    if lengths is None:
        lengths = [default] * n
    elif isinstance(lengths, (int, np.integer)) and not isinstance(lengths, bool):
        lengths = [int(lengths)] * n
    elif isinstance(lengths, (list, tuple, np.ndarray)):
        lengths = list(lengths)
        if len(lengths) != n:
            raise ValueError(f"got {len(lengths)} lengths for {n} prompts; give one length per prompt or a single int")
    else:
        raise TypeError(f"lengths must be an int or a list of ints, got {type(lengths).__name__}")
    out = []
    for i, length in enumerate(lengths):
        # "length 0" would read as "the length is 0": name the entry only when there are several
        which = "length" if len(lengths) == 1 else f"lengths[{i}]"
        if isinstance(length, bool) or not isinstance(length, (int, np.integer)):
            if isinstance(length, float) and math.isfinite(length) and float(length).is_integer():
                length = int(length)
            else:
                raise TypeError(f"{which} must be an integer number of frames, got {length!r}")
        length = int(length)
        if length < unit or length > max_len:
            raise ValueError(f"{which} = {length} frames is out of range; allowed: {unit}..{max_len} "
                             f"(at {skeleton.fps:g} fps, multiples of {unit})")
        if length % unit:
            floored = length - length % unit
            warnings.warn(f"{which} = {length} frames is not a multiple of {unit}; using {floored}",
                          stacklevel=stacklevel)
            length = floored
        out.append(length)
    return out


#: The keys of a SALAD weight folder's ``pipeline.json`` and their JSON types (checked by
#: :meth:`SaladPipeline.from_pretrained` with :func:`salad_core.limits.check_fields`).
PIPELINE_JSON_FIELDS: dict[str, Any] = {
    "vae": str, "denoiser": str, "stats": str, "text_encoder": str, "diffusion": dict, "solver": str,
    "guidance": dict | None, "recovery": str | None, "skeleton": str, "num_steps": int,
}


def guidance_from_json(entry: Any, source: str | Path) -> Guidance | None:
    """The :class:`~salad_core.sampling.Guidance` of a weight folder's ``"guidance"`` entry (``None``
    stays None): its keys and types checked, the weight within :data:`MAX_GUIDANCE`; a bad entry raises
    :class:`~salad_core.io.CheckpointError` ``<source>: bad "guidance" entry ...``."""
    if entry is None:
        return None
    try:
        guidance = config_from_dict(Guidance, entry, source="guidance")
        if abs(guidance.scale) > MAX_GUIDANCE:
            raise CheckpointError(f"scale {guidance.scale:g} is beyond {MAX_GUIDANCE:g}")
    except CheckpointError as err:
        cls = CheckpointTypeError if isinstance(err, TypeError) else CheckpointError
        raise cls(f'{source}: bad "guidance" entry {limits.short_json(entry)} ({err})') from None
    return guidance


class SaladPipeline:
    """Text-to-motion with SALAD: ``pipe(prompts, lengths=..., seed=...)``.

    Parameters
    ----------
    vae : MotionVAE
    denoiser : Denoiser
    text_encoder : TextEncoder
        An encoder following :class:`salad_core.text.TextEncoder`, e.g. from
        :func:`salad_core.text.load_text_encoder` (``dim`` must equal the
        denoiser's ``text_dim``).
    mean, std : np.ndarray
        ``(D,)`` feature statistics the models were trained with.
    diffusion : DiffusionConfig
    solver : str
        Default scheduler name (``"ddim"``; see :data:`salad_core.sampling.SOLVERS`).
    num_steps : int, optional
        Default sampler steps (``pipeline.json`` "num_steps"; :data:`DEFAULT_NUM_STEPS`, 50, when absent), e.g. 4
        for a consistency-distilled folder sampled with ``solver="lcm"``.
    """

    #: Motions denoised together in one forward by :meth:`__call__` (without attention capture);
    #: larger batches run in chunks of this size. ``None`` (default) picks by the allocator
    #: (:meth:`chunk_size`). On this project's 2-core CPU, 32 prompts through the pipeline took
    #: 1.14 s per motion in one batch and 0.82 s in chunks of 8 with glibc's default allocator (every
    #: large activation of the big batch is page-faulted in anew), but 0.62 s in one batch and
    #: 0.77 s in chunks of 8 with the tuned allocator of :mod:`salad_core.allocator`.
    max_batch: int | None = None
    #: Words of the captions these weights were trained on (``vocabulary.json`` of the weights folder,
    #: :func:`salad_core.vocabulary.load_vocabulary`); None: not recorded, so only text in another script,
    #: emoji and ``[UNK]`` tokens are reported. Prompts with other words warn (:class:`UnknownWordsWarning`).
    vocabulary: frozenset[str] | None = None
    #: Where the vocabulary comes from (e.g. "procedural corpus 2.4"), named in the warning.
    vocabulary_source: str | None = None
    #: Warn about unknown words (the command line turns it off and prints its own note instead).
    warn_unknown_words: bool = True

    def __init__(self, vae: MotionVAE, denoiser: Denoiser, text_encoder: TextEncoder, mean: np.ndarray,
                 std: np.ndarray, diffusion: DiffusionConfig | None = None, solver: str = "ddim",
                 source: str | None = None, guidance: Guidance | None = None, recovery: str | None = None,
                 latent_stats: tuple[Any, Any] | None = None, num_steps: int | None = None) -> None:
        if not isinstance(text_encoder, TextEncoder):
            raise TypeError(f"text_encoder must follow salad_core.text.TextEncoder (name, dim, max_tokens, encode, "
                            f"encode_null), e.g. load_text_encoder('minilm'); got {type(text_encoder).__name__}")
        self.vae = vae.eval()
        self.denoiser = denoiser.eval()
        self.text_encoder = text_encoder
        self.diffusion = diffusion or DiffusionConfig()
        self.solver = solver
        self.source = source
        #: Sampler steps of a call that gives none (``pipeline.json`` "num_steps"; 50 when absent).
        self.num_steps = _check_solver_steps(DEFAULT_NUM_STEPS if num_steps is None else num_steps, solver,
                                              self.diffusion)
        #: Default guidance of these weights (``pipeline.json`` "guidance"; the paper's w 7.5 when absent).
        #: A number passed as ``guidance_scale`` replaces only its weight; a Guidance replaces it all.
        self.skeleton: Skeleton = vae.skeleton
        self.guidance = guidance if guidance is not None else Guidance(7.5)
        if not isinstance(self.guidance, Guidance):
            raise TypeError(f"guidance must be a salad_core.sampling.Guidance, got {type(guidance).__name__}")
        #: How ``out.joints`` are recovered from the decoded features (:data:`salad_core.recovery.METHODS`):
        #: "fit" (fixed bone lengths, feet locked from the contact channels, nothing below the floor;
        #: the default where the skeleton has target bone lengths) or "positions" (the raw position
        #: features). Measured on the version 0.2 weights (``scripts/compare_recovery.py``, 20 motions): bone
        #: error p95 7.1 cm -> 0, foot skating 0.28 -> 0.07 m/s, floor penetration 10.9 cm -> 0.
        self.recovery = recovery if recovery is not None else (
            "fit" if self.skeleton.bone_lengths is not None else "positions")
        _check_recovery(self.recovery)
        check_compatible(vae, denoiser, text_encoder)
        d = self.skeleton.feature_dim
        self.mean = np.asarray(mean, dtype=np.float32).reshape(-1)
        self.std = np.asarray(std, dtype=np.float32).reshape(-1)
        if self.mean.shape != (d,) or self.std.shape != (d,):
            raise ValueError(f"mean/std must have shape ({d},) for {self.skeleton.name}, "
                             f"got {self.mean.shape} and {self.std.shape}")
        limits.check_stats(self.mean, self.std, "the feature statistics")      # finite, std > 0
        for p in [*self.vae.parameters(), *self.denoiser.parameters()]:
            p.requires_grad_(False)
        #: Latent normalisation of the diffusion (latent diffusion models' scale factor, per part and
        #: channel): the denoiser works on ``(z - mean) / std`` of the VAE latents ``z``; None = identity
        #: (the official models). Stored as ``latent_mean`` / ``latent_std`` ``(P, Dz)`` in the stats file.
        self.latent_stats = None
        if latent_stats is not None:
            shape = tuple(self.latent_shape)
            mean, std = (torch.as_tensor(np.asarray(t, dtype=np.float32)).reshape(shape) for t in latent_stats)
            if not bool(torch.isfinite(mean).all()) or not bool((std > 0).all()):
                raise ValueError("latent_stats need a finite mean and a positive std")
            self.latent_stats = (mean, std)

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_pretrained(cls, path: str | Path | None = None, *, text_encoder: TextEncoder | None = None,
                        allow_outside_paths: bool | str | Path = False, preset: str | None = None) -> "SaladPipeline":
        """Load a pipeline folder (``None``: the shipped default weights).

        ``preset="realtime"`` loads the few-step student (:data:`PIPELINE_PRESETS`:
        ``salad_core/weights/salad_realtime``, or ``path`` when given); a missing folder raises a
        :class:`~salad_core.io.CheckpointError` naming it and the command that makes it. The folder's
        ``pipeline.json`` names its solver, steps and guidance, so calls sample it correctly by default.

        ``pipeline.json`` is checked before anything loads (:data:`PIPELINE_JSON_FIELDS`: known keys
        only, a misspelt one named with the closest known key; JSON types; nesting and size limits of
        :mod:`salad_core.limits`), and so are the checkpoints (:func:`salad_core.io.load_model`) and the
        statistics (``mean`` and ``std`` present, finite, ``std > 0``).

        The paths it names (``vae``, ``denoiser``, ``stats``, a ``text_encoder`` folder) must resolve
        inside the folder (after ``..`` and symbolic links; folders of the shipped weights may share
        files with each other). ``allow_outside_paths=True`` accepts any path, a folder accepts paths
        inside that folder too. Relative paths are relative to the folder.

        Raises
        ------
        CheckpointError
            Naming the file, the key and the problem (:class:`~salad_core.io.CheckpointTypeError`, also a
            TypeError, for a value of the wrong JSON type).
        """
        if preset is not None:
            root = _preset_folder(preset, path)
        else:
            root = Path(path) if path is not None else default_weights_dir()
        cfg_path = root / "pipeline.json"
        if not cfg_path.is_file():
            hint = (" (the shipped weights are missing from this installation: reinstall salad, or train "
                    "them with scripts/reproduce_salad.sh)") if path is None else ""
            raise CheckpointError(f"no pipeline.json in {root}{hint}")
        cfg = limits.read_json(cfg_path, "file", expect=None, error=lambda msg: CheckpointError(
            f"{msg}; restore the file or re-run scripts/assemble_weights.py"))
        limits.check_fields(cfg, PIPELINE_JSON_FIELDS, str(cfg_path), CheckpointError, CheckpointTypeError)

        def inside(key: str, value: str) -> Path:
            return limits.resolve_inside(root, value, key, cfg_path, allow_outside_paths, CheckpointError,
                                         CheckpointTypeError)

        stems = {key: inside(key, cfg.get(key, key)) for key in ("vae", "denoiser")}
        for key, stem in stems.items():         # the very files load_model opens (a symbolic link may leave)
            for file in checkpoint_files(stem):
                limits.check_inside(root, file, key, cfg[key] if key in cfg else key, cfg_path, allow_outside_paths,
                                    CheckpointError)
        stats_path = inside("stats", cfg.get("stats", "stats.safetensors"))
        vae, _, _ = load_model(stems["vae"], expected_type="salad_vae")
        denoiser, _, _ = load_model(stems["denoiser"], expected_type="denoiser")
        stats = load_tensors(stats_path)
        for key in ("mean", "std", *(("latent_mean", "latent_std") if "latent_mean" in stats else ())):
            if key not in stats:
                raise CheckpointError(f"{stats_path} lacks the tensor {key!r} (it holds {sorted(stats)}); the "
                                      "statistics file needs 'mean' and 'std' (and 'latent_std' with 'latent_mean')")
        mean, std = stats["mean"].float().numpy(), stats["std"].float().numpy()
        limits.check_stats(mean, std, str(stats_path), CheckpointError)
        latent_stats = None
        if "latent_mean" in stats:
            limits.check_stats(stats["latent_mean"].float().numpy(), stats["latent_std"].float().numpy(),
                               str(stats_path), CheckpointError, names=("latent_mean", "latent_std"))
            latent_stats = (stats["latent_mean"], stats["latent_std"])
        if text_encoder is None:
            name = cfg.get("text_encoder", "minilm")
            where = name if name.lower() == "minilm" else inside("text_encoder", name)
            try:
                text_encoder = load_text_encoder(where)
            except (ValueError, OSError) as err:
                raise CheckpointError(f"{cfg_path}: 'text_encoder' {name!r} cannot be loaded: {err}") from None
        diffusion = config_from_dict(DiffusionConfig, cfg.get("diffusion", {}), source=f"{cfg_path}: 'diffusion'")
        solver = cfg.get("solver", "ddim")
        if solver not in SOLVERS:
            raise CheckpointError(f"{cfg_path}: 'solver' {solver!r} is unknown; known: {', '.join(SOLVERS)}")
        guidance = guidance_from_json(cfg.get("guidance"), cfg_path)
        num_steps = cfg.get("num_steps", DEFAULT_NUM_STEPS)
        try:
            _check_solver_steps(num_steps, solver, diffusion)
        except ValueError as err:
            raise CheckpointError(f"{cfg_path}: 'num_steps': {err}") from None
        try:
            recovery = _check_recovery(cfg.get("recovery")) if cfg.get("recovery") is not None else None
        except ValueError as err:
            raise CheckpointError(f"{cfg_path}: 'recovery': {err}") from None
        if "skeleton" in cfg and cfg["skeleton"] != vae.skeleton.name:
            raise CheckpointError(f"{cfg_path}: 'skeleton' is {cfg['skeleton']!r} but the VAE is built for "
                                  f"{vae.skeleton.name!r}")
        pipe = cls(vae, denoiser, text_encoder, mean, std, latent_stats=latent_stats, diffusion=diffusion,
                   solver=solver, source=str(root), guidance=guidance, recovery=recovery, num_steps=num_steps)
        pipe.vocabulary, pipe.vocabulary_source = vocabulary_and_source(root, allow_outside_paths)
        return pipe

    def save_pretrained(self, path: str | Path, *, dtype: torch.dtype | None = None, meta: dict | None = None) -> Path:
        """Write this pipeline as a folder that :meth:`from_pretrained` reads."""
        root = Path(path)
        root.mkdir(parents=True, exist_ok=True)
        save_checkpoint(root / "vae", self.vae, model_type="salad_vae", config=self.vae.config, dtype=dtype, meta=meta)
        save_checkpoint(root / "denoiser", self.denoiser, model_type="denoiser", config=self.denoiser.config,
                        dtype=dtype, meta=meta)
        stats = {"mean": torch.from_numpy(self.mean), "std": torch.from_numpy(self.std)}
        if self.latent_stats is not None:
            stats.update(latent_mean=self.latent_stats[0].clone(), latent_std=self.latent_stats[1].clone())
        save_tensors(root / "stats.safetensors", stats)
        doc = {"vae": "vae", "denoiser": "denoiser", "stats": "stats.safetensors",
               "text_encoder": getattr(self.text_encoder, "source", "minilm"),
               "diffusion": config_to_dict(self.diffusion), "solver": self.solver,
               "guidance": self.guidance.to_json_dict(), "recovery": self.recovery, "skeleton": self.skeleton.name}
        if self.num_steps != DEFAULT_NUM_STEPS:     # written only when set: folders read by versions without it
            doc["num_steps"] = self.num_steps
        atomic_write_text(root / "pipeline.json", json.dumps(doc, indent=2) + "\n")
        if self.vocabulary is not None:     # what the weights can read travels with them
            write_vocabulary(self.vocabulary, root, source=self.vocabulary_source)
        return root

    # ------------------------------------------------------------------ pieces
    @property
    def latent_shape(self) -> tuple[int, int]:
        """``(P, Dz)`` of one latent frame."""
        return self.vae.num_parts, self.vae.latent_dim

    def encode_text(self, prompts: list[str]) -> tuple[TextBatch, TextBatch]:
        """Token features of the prompts and of the null text "" (classifier-free guidance)."""
        batch = self.text_encoder.encode(prompts)
        null = self.text_encoder.encode([""], allow_empty=True)
        return batch, null

    def unknown_words(self, text: TextBatch | Sequence[str], *, warn: bool = False, stacklevel: int = 1
                      ) -> list[list[str]]:
        """Per prompt, its words outside :attr:`vocabulary` and its pieces in another script or emoji
        (:func:`salad_core.vocabulary.check_prompt`); with ``warn``, one :class:`UnknownWordsWarning`
        for the call naming them (and saying which prompts are mostly unknown, or hold ``[UNK]`` tokens)."""
        checks = self._prompt_checks(text)
        if warn:
            self._warn_unknown(checks, stacklevel + 1)
        return [c.terms for c in checks]

    def _prompt_checks(self, text: TextBatch | Sequence[str]) -> list:
        prompts = list(text.prompts) if isinstance(text, TextBatch) else validate_prompts(text)
        tokens = list(text.tokens) if isinstance(text, TextBatch) else [None] * len(prompts)
        return [check_prompt(p, self.vocabulary, t) for p, t in zip(prompts, tokens)]

    def _warn_unknown(self, checks: list, stacklevel: int, labels: Sequence[str] | None = None) -> None:
        """One :class:`UnknownWordsWarning` naming what ``checks`` found (nothing if all is known)."""
        if self.warn_unknown_words and any(checks):
            warnings.warn(unknown_words_message(checks, self.vocabulary_source, labels), UnknownWordsWarning,
                          stacklevel=stacklevel + 1)

    def make_noise(self, seeds: Sequence[int], latent_frames: int) -> torch.Tensor:
        """``(B, N', P, Dz)`` standard-normal noise; sample ``b`` from ``torch.Generator(seed_b)``.

        Each sample's noise is drawn at the maximum latent length and cropped, so it does not depend
        on the batch's longest motion.
        """
        p, dz = self.latent_shape
        full = self.skeleton.max_length // self.skeleton.unit_length
        out = []
        for s in seeds:
            g = torch.Generator().manual_seed(int(s))
            out.append(torch.randn(full, p, dz, generator=g)[:latent_frames])
        return torch.stack(out)

    def frame_mask(self, lengths: Sequence[int], latent_frames: int) -> torch.Tensor:
        """``(B, N')`` bool, True on the latent frames each motion uses."""
        n_lat = torch.tensor([length // self.skeleton.unit_length for length in lengths])
        return torch.arange(latent_frames)[None, :] < n_lat[:, None]

    def decode(self, latents: torch.Tensor, lengths: Sequence[int],
               recovery: str | None = None, *, progress: bool = False) -> tuple[np.ndarray, list[np.ndarray]]:
        """Latents ``(B, N', P, Dz)`` -> de-normalised features ``(B, 4N', D)`` (zero past each
        length) and per-sample joints ``(N_b, J, 3)`` recovered by ``recovery`` (default
        :attr:`recovery`); ``progress`` shows a bar over the motions."""
        from salad_core.sampling import progress_bar

        from salad_core.recovery import recover_joints

        method = _check_recovery(self.recovery if recovery is None else recovery)
        unit = self.skeleton.unit_length
        feats = np.zeros((latents.shape[0], latents.shape[1] * unit, self.skeleton.feature_dim), np.float32)
        joints = []
        with torch.inference_mode():
            for b, length in progress_bar(list(enumerate(lengths)), "decoding", progress):
                # decode each motion at its own length: the VAE's temporal convolutions would
                # otherwise see the batch's zero padding near the end of shorter motions
                z = self.from_diffusion(latents[b:b + 1, : length // unit].float())
                dec = self.vae.decode(z)[0].cpu().numpy()
                feats[b, :length] = denormalize(dec, self.mean, self.std)
                joints.append(recover_joints(feats[b, :length], method, self.skeleton).astype(np.float32))
        return feats, joints

    def encode_motion(self, features: np.ndarray, *, sample: bool = False) -> torch.Tensor:
        """Raw (de-normalised) features ``(N, D)`` or ``(B, N, D)`` -> latents ``(B, N/4, P, Dz)`` in the
        diffusion's space (:meth:`to_diffusion` of the VAE's).

        ``N`` must be a multiple of 4. ``sample=False`` uses the posterior mean.
        """
        x = np.asarray(features, dtype=np.float32)
        if x.ndim == 2:
            x = x[None]
        d = self.skeleton.feature_dim
        if x.ndim != 3 or x.shape[-1] != d:
            raise ValueError(f"features must be (N, {d}) or (B, N, {d}), got {x.shape}")
        if not np.isfinite(x).all():
            raise ValueError("features contain NaN or infinite values")
        unit = self.skeleton.unit_length
        if x.shape[1] % unit:
            raise ValueError(f"motion length {x.shape[1]} is not a multiple of {unit}; crop it first")
        with torch.inference_mode():
            enc = self.vae.encode(torch.from_numpy(normalize(x, self.mean, self.std)), sample=sample)
        return self.to_diffusion(enc.z if sample else enc.mu)

    def to_diffusion(self, z: torch.Tensor) -> torch.Tensor:
        """VAE latents ``(..., P, Dz)`` -> the denoiser's normalised latents (identity without stats)."""
        if self.latent_stats is None:
            return z
        mean, std = self.latent_stats
        return (z - mean.to(z)) / std.to(z)

    def from_diffusion(self, z: torch.Tensor) -> torch.Tensor:
        """The denoiser's latents ``(..., P, Dz)`` -> VAE latents (inverse of :meth:`to_diffusion`)."""
        if self.latent_stats is None:
            return z
        mean, std = self.latent_stats
        return z * std.to(z) + mean.to(z)

    # ------------------------------------------------------------------ generate
    def __call__(self, prompts: str | Sequence[str], lengths: int | Sequence[int] | None = None,
                 seed: int | Sequence[int] = 0, guidance_scale: "float | Guidance | None" = None,
                 num_steps: int | None = None, solver: str | None = None,
                 capture_attention: bool | CaptureConfig | dict = False,
                 noise: torch.Tensor | None = None, progress: bool = False,
                 hooks: Sequence[tuple[str, HookFn]] | None = None) -> MotionOutput:
        """Generate one motion per prompt.

        Parameters
        ----------
        prompts : str or list of str
        lengths : int or list of int, optional
            Frames per motion (default 120 = 6 s at 20 fps), multiples of 4, at most 196.
        seed : int or list of int
            Sample ``b`` uses noise seed ``seed + b`` (or ``seed[b]`` for a list); seeds must lie in
            :data:`SEED_RANGE` (what ``torch.Generator`` accepts). With the ``"lcm"`` solver the noise it
            adds between steps comes from the same seed.
        guidance_scale : float or Guidance, optional
            Classifier-free guidance (:func:`~salad_core.sampling.resolve_guidance`): None uses the
            weights' default (:attr:`guidance`); a number (not a string) in
            ``-MAX_GUIDANCE..MAX_GUIDANCE`` replaces its weight ``w`` only (paper default 7.5; 1
            disables guidance; a negative weight steers away from the prompt and is warned about); a
            :class:`~salad_core.sampling.Guidance` (weight, rescale, interval) is used as given
            (``Guidance(7.5)`` is the paper's sampler).
        num_steps : int, optional
            Sampler steps, at most the diffusion's training timesteps (None: the weights' :attr:`num_steps`, 50
            DDIM steps for the shipped weights).
        solver : str, optional
            Scheduler name of :data:`salad_core.sampling.SOLVERS` (default: the pipeline's, "ddim");
            e.g. "dpm++". Anything else (``""``, a number) is refused.
        capture_attention : bool or CaptureConfig
            Record the cross-attention maps (see :mod:`salad_core.attention`); never changes the
            motion.
        noise : torch.Tensor, optional
            ``(B, N', P, Dz)`` initial noise to reuse (overrides ``seed``).
        hooks : list of (name, fn), optional
            Read or replace activations at named hook points for this call only
            (:mod:`salad_core.attention.hooks`): ``name`` is a hook point or a glob
            (``"layers.3.cross"`` the probabilities, ``"layers.3.cross.out"`` the site's output,
            ``".q"``, ``".k"``, ``".v"`` read-only), ``fn(tensor, ctx)`` returns None (read) or a
            tensor of the same shape (replace). ``fn`` gets every row of the guided batch
            ``[uncond (B); cond (B)]``; ``ctx.cond`` / ``ctx.uncond`` slice it. Nothing stays
            installed afterwards, also after an error.
        """
        out, _ = self._generate(prompts, lengths, seed, guidance_scale, num_steps, solver, capture_attention, noise,
                                progress, hooks)
        return out

    def run_with_cache(self, prompts: str | Sequence[str], lengths: int | Sequence[int] | None = None, *,
                       names: NameFilter = None, layers: int | Sequence[int] | None = None,
                       steps: tuple[float, float] = (0.0, 1.0), store: str | Sequence[str] = "probs",
                       hooks: Sequence[tuple[str, HookFn]] | None = None, seed: int | Sequence[int] = 0,
                       guidance_scale: "float | Guidance | None" = None, num_steps: int | None = None,
                       solver: str | None = None, capture_attention: bool | CaptureConfig | dict = False,
                       noise: torch.Tensor | None = None, progress: bool = False
                       ) -> tuple[MotionOutput, ActivationCache]:
        """Generate and keep the activations of the chosen hook points (TransformerLens'
        ``run_with_cache``); the motion is bit for bit the one :meth:`__call__` gives.

        Parameters
        ----------
        prompts, lengths
            As :meth:`__call__`.
        names : str, callable or list of these, optional
            Hook points by exact name or glob (``"layers.*.cross"``; a site name also selects its
            outputs and inputs when ``store`` asks for them) or a predicate on the name; None: every
            site (:func:`salad_core.attention.hooks.select_hook_points`).
        layers : int or list of int, optional
            Only these layers (execution order).
        steps : (start, stop)
            Keep the steps whose fraction ``i / S`` lies in ``[start, stop)``.
        store : str or tuple of str
            ``"probs"`` (post-softmax probabilities), ``"inputs"`` (per-head q, k, v),
            ``"outputs"`` (the sites' outputs after ``Wo``), or several.
        hooks : list of (name, fn), optional
            As :meth:`__call__`; the cache keeps what the run used (after the hooks).
        seed, guidance_scale, num_steps, solver, capture_attention, noise, progress
            As :meth:`__call__`.

        Returns
        -------
        (MotionOutput, ActivationCache)
            The cache maps hook point names to CPU tensors ``(S, B, ...)`` of the conditional rows
            (:class:`salad_core.attention.hooks.ActivationCache` documents the axes).
        """
        from salad_core.attention.capture import TokenInfo
        from salad_core.attention.hooks import CacheRecorder, select_hook_points

        recorder = CacheRecorder(select_hook_points(self.denoiser, names, layers, store), steps)
        if not recorder.points:
            raise ValueError(f"names={names!r}, layers={layers!r} and store={store!r} select no hook point")
        # the recorder keeps the conditional rows only: without other hooks, only those are computed
        out, text = self._generate(prompts, lengths, seed, guidance_scale, num_steps, solver, capture_attention, noise,
                                   progress, [*(hooks or ()), *recorder.hooks], rows="all" if hooks else "cond")
        cache = recorder.result(TokenInfo.from_batch(text), out.lengths, self.skeleton.unit_length,
                                self.denoiser.config.layers)
        return out, cache

    def _generate(self, prompts: str | Sequence[str], lengths: int | Sequence[int] | None, seed: int | Sequence[int],
                  guidance_scale: "float | Guidance | None", num_steps: int | None, solver: str | None,
                  capture_attention: bool | CaptureConfig | dict, noise: torch.Tensor | None, progress: bool,
                  hooks: Sequence[tuple[str, HookFn]] | None, rows: str = "all", caller_depth: int = 1
                  ) -> tuple[MotionOutput, TextBatch]:
        """:meth:`__call__`, also returning the encoded prompts; ``rows``: what the hooks get;
        ``caller_depth``: frames between the user's call and this one (warnings point at the user)."""
        prompts = validate_prompts(prompts)
        lengths = validate_lengths(lengths, len(prompts), self.skeleton, stacklevel=3 + caller_depth)
        if len(prompts) > limits.PROMPT_CHUNK:
            log.info("generating %d motions in chunks of %d (progress=True shows a bar)", len(prompts),
                     self.chunk_size())
        guidance = self.resolve_guidance(guidance_scale)
        solver = _check_solver(solver)
        num_steps = _check_solver_steps(self.num_steps if num_steps is None else num_steps, solver or self.solver,
                                        self.diffusion)
        seeds = _seeds(seed, len(prompts))
        step_noise = _step_generators(seeds, solver or self.solver, self)
        n_lat = max(lengths) // self.skeleton.unit_length
        if noise is None:
            noise = self.make_noise(seeds, n_lat)
        else:
            noise = _check_noise(noise, (len(prompts), n_lat, *self.latent_shape))
        text, null = self.encode_text(prompts)
        unknown = self.unknown_words(text, warn=True, stacklevel=2 + caller_depth)
        uncond = self.denoiser.prepare_text(null.features, null.mask)
        settings = dict(_guidance_settings(guidance), num_steps=int(num_steps), solver=solver or self.solver,
                        weights=self.source, **self._output_settings())
        attention = None
        if hooks:
            latents, attention = self._denoise_hooked(text, uncond, noise, lengths, guidance, int(num_steps),
                                                      solver or self.solver, progress, capture_attention, hooks, rows,
                                                      step_noise)
        elif capture_attention:
            from salad_core.attention.capture import capture_cross_attention

            cond = self.denoiser.prepare_text(text.features, text.mask)
            mask = self.frame_mask(lengths, n_lat)
            with capture_cross_attention(self.denoiser, text, lengths, capture_attention) as store:
                latents = denoise(self.denoiser, make_scheduler(self.diffusion, solver or self.solver), cond, uncond,
                                  noise, mask, guidance_scale=guidance, num_steps=int(num_steps),
                                  controller_hooks=[store.on_step], progress=progress, generator=step_noise)
            attention = store.result()
        else:
            latents = self._denoise_in_chunks(text, uncond, noise, lengths, guidance, int(num_steps),
                                              solver or self.solver, progress, step_noise)
        feats, joints = self.decode(latents, lengths, progress=progress and len(lengths) > limits.PROMPT_CHUNK)
        return MotionOutput(feats, joints, prompts, lengths, latents, noise, seeds, attention, settings,
                            unknown_words=unknown), text

    def _denoise_hooked(self, text: TextBatch, uncond: TextContext, noise: torch.Tensor, lengths: Sequence[int],
                        guidance: Guidance, num_steps: int, solver: str, progress: bool,
                        capture: bool | CaptureConfig | dict, hooks: Sequence[tuple[str, HookFn]], rows: str,
                        step_noise: list[torch.Generator] | None = None) -> tuple[torch.Tensor, AttentionMaps | None]:
        """One batched denoising with the hooks installed (and the attention store, if capturing,
        served by the same processors after the hooks); the hooks are removed on exit."""
        from salad_core.attention.capture import attention_store, store_sites
        from salad_core.attention.hooks import use_hooks

        store = attention_store(self.denoiser, text, lengths, capture) if capture else None
        observed = store_sites(self.denoiser, store) if store is not None else ()
        cond = self.denoiser.prepare_text(text.features, text.mask)
        mask = self.frame_mask(lengths, noise.shape[1])
        with use_hooks(self.denoiser, hooks, rows=rows, observer=store, observer_sites=observed) as session:
            steps = [session.on_step] if store is None else [store.on_step, session.on_step]
            latents = denoise(self.denoiser, make_scheduler(self.diffusion, solver), cond, uncond, noise, mask,
                              guidance_scale=guidance, num_steps=num_steps, controller_hooks=steps, progress=progress,
                              generator=step_noise)
        return latents, None if store is None else store.result()

    def _output_settings(self) -> dict[str, str]:
        return {"recovery": self.recovery, "skeleton": self.skeleton.name}

    def resolve_guidance(self, guidance_scale: "float | Guidance | None" = None) -> Guidance:
        """The :class:`~salad_core.sampling.Guidance` a call uses: None -> :attr:`guidance`; a number ->
        :attr:`guidance` with that weight; a Guidance -> itself
        (:func:`~salad_core.sampling.resolve_guidance`, which checks the weight)."""
        return resolve_guidance(self.guidance, guidance_scale, stacklevel=2)

    def chunk_size(self) -> int:
        """Motions per denoising chunk: :attr:`max_batch` if set, else 32 when the allocator is tuned
        (:func:`salad_core.allocator.tune_allocator`, which the ``salad`` command applies) and 8 when
        it is not (see :attr:`max_batch` for the measurements)."""
        if self.max_batch is not None:
            if isinstance(self.max_batch, bool) or not isinstance(self.max_batch, int) or self.max_batch < 1:
                raise ValueError(f"max_batch must be a positive int or None, got {self.max_batch!r}")
            return self.max_batch
        from salad_core.allocator import allocator_tuned

        return 32 if allocator_tuned() else 8

    def _denoise_in_chunks(self, text: TextBatch, uncond: TextContext, noise: torch.Tensor, lengths: Sequence[int],
                           guidance: Guidance, num_steps: int, solver: str, progress: bool,
                           step_noise: list[torch.Generator] | None = None) -> torch.Tensor:
        """Denoise the ``B`` motions in consecutive chunks of at most :meth:`chunk_size` motions (one
        chunk when ``B`` is not larger), each at its own longest length; returns latents ``(B, N', P, Dz)`` as one
        call would (zero past each length).

        Every sample keeps its own noise, so the motions are those of one batched call up to float
        rounding (the GEMMs block differently at another batch size).
        """
        from salad_core.sampling import progress_bar

        unit = self.skeleton.unit_length
        latents = torch.zeros_like(noise)
        chunk = self.chunk_size()
        starts = range(0, len(lengths), chunk)
        many = progress and len(lengths) > limits.PROMPT_CHUNK      # a bar over the chunks too
        for start in progress_bar(starts, f"motions ({chunk} per chunk)", many, total=len(starts)):
            rows = slice(start, start + chunk)
            n_lat = max(lengths[rows]) // unit
            cond = self.denoiser.prepare_text(text.features[rows], text.mask[rows])
            latents[rows, :n_lat] = denoise(self.denoiser, make_scheduler(self.diffusion, solver), cond, uncond,
                                            noise[rows, :n_lat], self.frame_mask(lengths[rows], n_lat),
                                            guidance_scale=guidance, num_steps=num_steps, progress=progress,
                                            generator=None if step_noise is None else step_noise[rows])
        return latents

    # ------------------------------------------------------------------ edit
    @staticmethod
    def edit_namespace() -> dict[str, Any]:
        """The names a line of ``pipe.edit(...)`` code uses (``WordSwap``, ``Refine``, ``Reweight``, ``Mirror``,
        ``Erase``, ``Inpaint``, ``MirrorTake``, ``CaptureConfig``): what the Jupyter explorer's editing panel
        evaluates its printed line with (:func:`salad_viz.widgets.explore_attention` ``editor=pipe``)."""
        from salad_core import attention

        return {n: getattr(attention, n) for n in ("WordSwap", "Refine", "Reweight", "Mirror", "Erase", "Inpaint",
                                                   "MirrorTake", "CaptureConfig")}

    def edit(self, source: str | Sequence[str] | None = None, target: str | Sequence[str] | None = None,
             edits: EditSpec | Sequence[EditSpec] = (), lengths: int | Sequence[int] | None = None,
             seed: int | Sequence[int] = 0,
             guidance_scale: "float | Guidance | None" = None, num_steps: int | None = None,
             solver: str | None = None, noise: torch.Tensor | None = None, inversion: Inversion | None = None,
             capture_attention: bool | CaptureConfig | dict = False,
             probe: bool = False, progress: bool = False, ground: bool | None = None) -> EditOutput:
        """Zero-shot editing by attention modulation (SALAD supplement B, Algorithm 1).

        The source and the edited motion are sampled together from the same noise; per step one
        batched forward serves both branches (and, with ``probe=True``, Algorithm 1's probe).

        Parameters
        ----------
        source : str or list of str, optional
            Source prompts (omit when editing an ``inversion``).
        target : str or list of str, optional
            Target prompts, one per source (a single string is used for all); default: the
            source prompts (re-weighting and mirroring edit the source's own maps).
        edits : EditSpec or sequence of EditSpec
            :class:`~salad_core.attention.WordSwap`, :class:`~salad_core.attention.Refine`,
            :class:`~salad_core.attention.Reweight`, :class:`~salad_core.attention.Mirror`,
            :class:`~salad_core.attention.InjectSelfAttention`, composed in order (and
            :class:`~salad_core.attention.Inpaint`: regenerate chosen body parts / a frame span from the
            target, keep the rest of the source or the inverted motion); empty: the
            edited motion is a plain generation of the target from the same noise (with the
            source as target that is the source itself: warned). A word swap or a refinement
            needs a target that differs from the source (refused otherwise); a refinement whose
            target shares no word with the source keeps no source map (warned).
        lengths, seed, solver, noise
            As :meth:`__call__`.
        guidance_scale, num_steps : optional
            As :meth:`__call__` (default: :attr:`guidance` and 50), or the inversion's.
        inversion : Inversion, optional
            From :meth:`invert` (anything else is refused): edit a given motion. Its prompts, lengths, noise, guidance,
            steps and per-step null texts / corrections are used.
        capture_attention : bool or CaptureConfig
            Record the source maps and the maps the edited motion used.
        probe : bool
            Read the target's own maps from a separate probe row (Algorithm 1's line 7, official)
            instead of from the edited row itself (Prompt-to-Prompt); see
            :class:`~salad_core.attention.EditController`.
        ground : bool, optional
            Keep the edited motion's pelvis within 10 cm of the source's height range (and the corpus's) unless
            the target asks to leave the floor (:func:`salad_core.attention.grounding.ground_edit`: frames above
            are lowered, the pose kept). Default: on when editing an ``inversion`` (a given take), off for
            generated sources; ``settings["grounding"]`` records what was lowered.

        Returns
        -------
        EditOutput
        """
        from salad_core.attention.capture import TokenInfo
        from salad_core.attention.controller import EditController
        from salad_core.attention.editing import edit_latents
        from salad_core.attention.edits import validate_edits

        from salad_core.attention.edits import Refine, WordSwap
        from salad_core.attention.inversion import Inversion

        edits = validate_edits(edits)
        if inversion is not None and not isinstance(inversion, Inversion):
            raise TypeError(f"inversion must be the Inversion that pipe.invert(motion, prompt) returns, got "
                            f"{type(inversion).__name__} {inversion!r:.60}")
        from salad_core.attention.ranking import ranked_edit, ranked_inpaint

        inverted = inversion is not None
        motions = 1 if inversion is None else len(inversion.prompts)
        if ranked_inpaint(edits, inverted, motions) is not None:   # Inpaint.candidates: K edits, the best
            return ranked_edit(lambda specs: self.edit(source, target, specs, lengths, seed, guidance_scale, num_steps,
                                                       solver, noise, inversion, capture_attention, probe, progress,
                                                       ground), edits, inverted=inverted, motions=motions,
                               skeleton=self.skeleton.name)
        solver = _check_solver(solver)
        null_schedule = corrections = None
        if inversion is not None:
            prompts, lengths, noise, guidance, num_steps = self._from_inversion(
                inversion, source, lengths, noise, guidance_scale, num_steps, solver)
            seeds: list[int] = []
            solver = "ddim"
            corrections = inversion.corrections
        else:
            if source is None:
                raise ValueError("edit needs source prompts, or inversion=pipe.invert(motion, prompt) to edit a "
                                 "given motion")
            prompts = validate_prompts(source)
            lengths = validate_lengths(lengths, len(prompts), self.skeleton)
            guidance = self.resolve_guidance(guidance_scale)
            num_steps = _check_steps(50 if num_steps is None else num_steps)
            seeds = _seeds(seed, len(prompts))
            n_lat = max(lengths) // self.skeleton.unit_length
            noise = (self.make_noise(seeds, n_lat) if noise is None
                     else _check_noise(noise, (len(prompts), n_lat, *self.latent_shape)))
        _check_plain_guidance(guidance, "edit")
        targets = prompts if target is None else validate_prompts(target)
        if len(targets) == 1 and len(prompts) > 1:
            targets = targets * len(prompts)
        if len(targets) != len(prompts):
            raise ValueError(f"got {len(targets)} target prompts for {len(prompts)} source prompts; give one each "
                             "or a single target for all")
        _check_edit_does_something(edits, prompts, targets, WordSwap, Refine)
        text_src, null = self.encode_text(prompts)
        text_tgt = text_src if targets == prompts else self.text_encoder.encode(targets)
        checks = {"source": self._prompt_checks(text_src), "edited": self._prompt_checks(text_tgt)}
        self._warn_unknown(checks["source"] + checks["edited"] * (text_tgt is not text_src), 2,
                           [f"{kind} {b}" for kind in ("source", "target")[:1 + (text_tgt is not text_src)]
                            for b in range(len(prompts))])
        unknown = {branch: [c.terms for c in cs] for branch, cs in checks.items()}
        if inversion is not None and inversion.null_texts is not None:
            null_schedule = [self.denoiser.prepare_text(f, inversion.null_mask) for f in inversion.null_texts]
            null_width = inversion.null_mask.shape[1]
        else:
            null_schedule = self.denoiser.prepare_text(null.features, null.mask)
            null_width = null.features.shape[1]
        width = max(text_src.features.shape[1], text_tgt.features.shape[1], null_width)
        controller = EditController(edits, TokenInfo.from_batch(text_src), TokenInfo.from_batch(text_tgt), width,
                                    cfg=guidance.cfg, probe=probe)
        if capture_attention:
            self._record(controller, capture_attention, lengths)
        solver = solver or self.solver
        scheduler = make_scheduler(self.diffusion, solver)
        mask = self.frame_mask(lengths, noise.shape[1])
        target_ctx = self.denoiser.prepare_text(text_tgt.features, text_tgt.mask)
        inpaint = next((e for e in edits if e.role == "latent"), None)
        release = 0 if inpaint is None else inpaint.prior_release(int(num_steps), inverted)
        prior = alone = None
        if release > 0:       # a prior released at the first step would only be noise: not sampled
            prior, alone = self._inpaint_prior(inpaint, text_tgt, null, lengths, noise.shape[1], guidance,
                                               int(num_steps), solver)
        run = edit_latents(self.denoiser, scheduler, controller,
                           source=self.denoiser.prepare_text(text_src.features, text_src.mask),
                           target=target_ctx, null=null_schedule, noise=noise, frame_mask=mask,
                           guidance_scale=guidance, num_steps=int(num_steps), corrections=corrections,
                           progress=progress, region_prior=prior)
        generation_rows = (2 if guidance.cfg else 1) * len(prompts) * int(num_steps)
        settings = dict(_guidance_settings(guidance), num_steps=int(num_steps), solver=solver, weights=self.source,
                        **self._output_settings())
        if prior is not None:
            settings["inpaint_prior"] = {"mode": "prompt",
                                         "strength": inpaint.prior_strength_for(inverted),
                                         "release_step": release, "forward_rows": generation_rows,
                                         "windows": [list(w) for w in alone.settings["windows"]]}
        # an edit that gives the edited sample its own noise (ExampleBased) reports that noise and its seeds
        own_seed = next((e.edited_seed for e in edits if e.edited_seed is not None), None)
        edited_noise, edited_seeds = ((noise, seeds) if run.edited_noise is None else
                                      (run.edited_noise, [] if own_seed is None else
                                       [int(own_seed) + b for b in range(len(prompts))]))
        out = []
        for branch, latents, texts, z0, s0 in (("source", run.source, prompts, noise, seeds),
                                               ("edited", run.edited, targets, edited_noise, edited_seeds)):
            feats, joints = self.decode(latents, lengths)
            out.append(MotionOutput(feats, joints, list(texts), list(lengths), latents, z0, s0,
                                    controller.maps(branch), dict(settings), unknown_words=unknown[branch]))
        settings.update(probe=bool(probe), forward_rows=run.rows, probe_steps=run.probe_steps,
                        cost_vs_generation=run.rows / generation_rows,
                        inversion=None if inversion is None else inversion.method)
        result = EditOutput(out[0], out[1], noise, edits, settings, prior=alone)
        # edits that keep parts or frames (MirrorTake, Inpaint with composite=True) take them from the source's
        # decoded features: the decoder's convolutions would otherwise let the edited tokens move them
        from salad_core.attention.composite import composite_output

        result = composite_output(self, result)
        if inverted if ground is None else bool(ground):
            from salad_core.attention.grounding import ground_edit

            result = ground_edit(self, result)
        return result

    def _inpaint_prior(self, inpaint, target: TextBatch, null: TextBatch, lengths: Sequence[int], latent_frames: int,
                       guidance: Guidance, num_steps: int, solver: str) -> tuple[torch.Tensor, MotionOutput]:
        """``Inpaint(prior="prompt")``'s pasted latents ``(B, N', P, Dz)`` and the prior motions themselves: the
        target prompts sampled alone over :meth:`Inpaint.prior_window
        <salad_core.attention.inpaint.Inpaint.prior_window>` (noise of the in-painting's seed as :meth:`make_noise`
        draws it, the edited branch's guidance weight, the edit's solver and steps, the pipeline's null text), their
        latents placed at the region's latent frames and parts (zero elsewhere); the decoded prior
        (:class:`MotionOutput`, ``settings["windows"]``: each motion's ``(s, e, frames, c)``)."""
        import dataclasses

        from salad_core.skeleton import PART_NAMES

        scale = inpaint.edited_guidance
        prior_guidance = guidance if scale is None else dataclasses.replace(guidance, scale=float(scale))
        windows = [inpaint.prior_window(int(n), self.skeleton.min_length) for n in lengths]
        frames = [w[2] for w in windows]
        n_lat = max(frames) // self.skeleton.unit_length
        noise = self.make_noise([inpaint.seed + b for b in range(len(lengths))], n_lat)
        uncond = self.denoiser.prepare_text(null.features[:1], null.mask[:1])
        alone = self._denoise_in_chunks(target, uncond, noise, frames, prior_guidance, num_steps, solver, False)
        out = torch.zeros(len(lengths), latent_frames, *self.latent_shape)
        for b, (s, e, _, c) in enumerate(windows):
            out[b, s:e] = alone[b, c:c + (e - s)]
        chosen = inpaint.parts or PART_NAMES
        out[:, :, [i for i, part in enumerate(PART_NAMES) if part not in chosen]] = 0.0
        log.debug("in-painting prior: %s sampled from the target over latent frames %s", inpaint.describe(),
                  [w[:2] for w in windows])
        feats, joints = self.decode(alone, frames)
        seeds = [inpaint.seed + b for b in range(len(lengths))]
        prior = MotionOutput(feats, joints, list(target.prompts), list(frames), alone, noise, seeds, None,
                             {**_guidance_settings(prior_guidance), "num_steps": int(num_steps), "solver": solver,
                              "windows": [tuple(int(v) for v in w) for w in windows], **self._output_settings()})
        return out, prior

    def _from_inversion(self, inversion: Inversion, source: str | Sequence[str] | None,
                        lengths: int | Sequence[int] | None, noise: torch.Tensor | None,
                        guidance_scale: float | Guidance | None, num_steps: int | None, solver: str | None
                        ) -> tuple[list[str], list[int], torch.Tensor, Guidance, int]:
        """Prompts, lengths, noise, guidance and steps of an inversion; refuses settings that differ."""
        prompts = list(inversion.prompts)
        if source is not None and validate_prompts(source) != prompts:
            raise ValueError(f"source={source!r} differs from the inversion's prompts {prompts}; omit source when "
                             "editing an inversion")
        if lengths is not None and validate_lengths(lengths, len(prompts), self.skeleton) != list(inversion.lengths):
            raise ValueError(f"lengths={lengths!r} differ from the inverted motions' {inversion.lengths}; omit lengths")
        if noise is not None:
            raise ValueError("noise cannot be given with an inversion: the inversion is the noise")
        made_for = _inversion_guidance(inversion)
        if guidance_scale is not None and self.resolve_guidance(guidance_scale) != made_for:
            raise ValueError(f"guidance_scale={guidance_scale} but the inversion is faithful to "
                             f"{made_for.describe()}; invert again with that guidance")
        if num_steps is not None and int(num_steps) != inversion.num_steps:
            raise ValueError(f"num_steps={num_steps} but the inversion has {inversion.num_steps} steps")
        if solver is not None and solver.lower() != "ddim":
            raise ValueError(f"solver={solver!r}: an inversion is made for the deterministic 'ddim' sampler")
        return prompts, list(inversion.lengths), inversion.noise, made_for, inversion.num_steps

    # ------------------------------------------------------------------ inversion
    def invert(self, motions: Any, prompts: str | Sequence[str], *, method: str = "fixed_point",
               guidance_scale: "float | Guidance | None" = None, num_steps: int = 50,
               iterations: int | None = None, exact: bool = True, reconstruct: bool = True,
               progress: bool = False) -> Inversion:
        """Invert given motions to noise under their prompts, so that :meth:`edit` can edit them.

        Parameters
        ----------
        motions : array or list of arrays
            Raw (de-normalised) features ``(N, D)``, ``(B, N, D)`` or a list of ``(N_b, D)``, real
            numbers of magnitude at most :data:`salad_core.motion.MAX_FEATURE_MAGNITUDE`; each is
            cropped to a multiple of 4 frames (with a warning; at most ``skeleton.max_length``).
        prompts : str or list of str
            One source prompt per motion: what the motion shows.
        method : str
            ``"ddim"``, ``"fixed_point"`` (default) or ``"null_text"``: see
            :mod:`salad_core.attention.inversion`; chosen by the reconstruction errors measured by
            ``scripts/measure_editing.py``.
        guidance_scale, num_steps
            The sampling settings the inversion is made for (edits must use the same); guidance as
            in :meth:`__call__`.
        iterations : int, optional
            Fixed-point updates or null-text optimiser steps per sampling step.
        exact : bool
            Add per-step corrections so that the source reconstruction is exact (default). At the
            same cost it brought the error down to the VAE's own (1.5 cm vs 3.9 cm without, shipped
            weights) and the mirror edit acted more strongly on the inverted motion, not less;
            ``False`` keeps the plain method (the edited branch then carries no correction).
        reconstruct : bool
            Regenerate the motion from the inverted noise and measure the error
            (``inversion.errors``, metres: ``mpjpe`` root-aligned and ``mpjpe_global`` against
            the input; ``vae_mpjpe`` / ``vae_mpjpe_global``: the VAE's own encode/decode error,
            the floor of any inversion; ``inversion_mpjpe`` / ``inversion_mpjpe_global``: the
            reconstruction against that VAE decoding, i.e. the inversion's own error).

        Returns
        -------
        salad_core.attention.Inversion
        """
        from salad_core.attention.inversion import DEFAULT_ITERATIONS, Inversion, invert_latents

        prompts = validate_prompts(prompts)
        feats = _motion_list(motions, self.skeleton)
        if len(feats) != len(prompts):
            raise ValueError(f"got {len(feats)} motions and {len(prompts)} prompts; give one prompt per motion")
        guidance = self.resolve_guidance(guidance_scale)
        _check_plain_guidance(guidance, "invert")
        num_steps = _check_steps(num_steps)
        unit = self.skeleton.unit_length
        lengths = [f.shape[0] for f in feats]
        n_lat = max(lengths) // unit
        p, dz = self.latent_shape
        latents = torch.zeros(len(feats), n_lat, p, dz)
        for b, f in enumerate(feats):
            latents[b, : f.shape[0] // unit] = self.encode_motion(f)[0]
        mask = self.frame_mask(lengths, n_lat)
        text, null = self.encode_text(prompts)
        self.unknown_words(text, warn=True, stacklevel=2)
        res = invert_latents(self.denoiser, make_scheduler(self.diffusion, "ddim"), latents,
                             self.denoiser.prepare_text(text.features, text.mask),
                             self.denoiser.prepare_text(null.features, null.mask), mask, method=method,
                             guidance_scale=guidance, num_steps=num_steps, iterations=iterations,
                             exact=exact, progress=progress)
        inv = Inversion(prompts=prompts, lengths=lengths, features=feats, latents=latents, noise=res.noise,
                        trajectory=res.trajectory, method=method, guidance_scale=guidance.scale, guidance=guidance,
                        num_steps=num_steps, exact=bool(exact),
                        iterations=DEFAULT_ITERATIONS[method] if iterations is None else int(iterations),
                        null_texts=res.null_texts,
                        null_mask=None if res.null_texts is None else null.mask.expand(len(feats), -1).clone(),
                        corrections=res.corrections, residuals=res.residuals, forward_rows=res.forward_rows,
                        seconds=res.seconds)
        if reconstruct:
            from salad_core.eval.metrics import mpjpe

            rec = self.reconstruct(inv, progress=progress)
            # errors of the representation itself: raw position features on every side (no fit)
            vae_feats, vae_joints = self.decode(latents, lengths, recovery="positions")
            gt = [features_to_joints(f, self.skeleton).astype(np.float32) for f in feats]
            rec_joints = rec.raw_joints
            inv.reconstruction = rec
            inv.errors = {
                "mpjpe": float(np.mean([mpjpe(r, g) for r, g in zip(rec_joints, gt)])),
                "mpjpe_global": float(np.mean([mpjpe(r, g, root_aligned=False) for r, g in zip(rec_joints, gt)])),
                "vae_mpjpe": float(np.mean([mpjpe(r, g) for r, g in zip(vae_joints, gt)])),
                "vae_mpjpe_global": float(np.mean([mpjpe(r, g, root_aligned=False) for r, g in zip(vae_joints, gt)])),
                "inversion_mpjpe": float(np.mean([mpjpe(r, v) for r, v in zip(rec_joints, vae_joints)])),
                "inversion_mpjpe_global": float(np.mean([mpjpe(r, v, root_aligned=False)
                                                         for r, v in zip(rec_joints, vae_joints)])),
                "latent_rmse": float(((rec.latents - latents) ** 2).sum().div(
                    mask.sum() * p * dz).sqrt()),
            }
        return inv

    def reconstruct(self, inversion: Inversion, *, capture_attention: bool | CaptureConfig | dict = False,
                    progress: bool = False) -> MotionOutput:
        """Regenerate an inverted motion (no edit): the source branch of :meth:`edit` alone."""
        from salad_core.attention.capture import TokenInfo
        from salad_core.attention.controller import EditController
        from salad_core.attention.editing import edit_latents

        prompts, lengths = list(inversion.prompts), list(inversion.lengths)
        w, steps = _inversion_guidance(inversion), inversion.num_steps
        text, null = self.encode_text(prompts)
        if inversion.null_texts is not None:
            nulls = [self.denoiser.prepare_text(f, inversion.null_mask) for f in inversion.null_texts]
            null_width = inversion.null_mask.shape[1]
        else:
            nulls = self.denoiser.prepare_text(null.features, null.mask)
            null_width = null.features.shape[1]
        info = TokenInfo.from_batch(text)
        controller = EditController((), info, info, max(text.features.shape[1], null_width), cfg=w.cfg,
                                    edited=False)
        if capture_attention:
            self._record(controller, capture_attention, lengths)
        ctx = self.denoiser.prepare_text(text.features, text.mask)
        mask = self.frame_mask(lengths, inversion.noise.shape[1])
        run = edit_latents(self.denoiser, make_scheduler(self.diffusion, "ddim"), controller, source=ctx, target=None,
                           null=nulls, noise=inversion.noise, frame_mask=mask, guidance_scale=w, num_steps=steps,
                           corrections=inversion.corrections, progress=progress)
        feats, joints = self.decode(run.source, lengths)
        return MotionOutput(feats, joints, prompts, lengths, run.source, inversion.noise, [], controller.maps("source"),
                            dict(_guidance_settings(w), num_steps=steps, solver="ddim", weights=self.source,
                                 **self._output_settings(),
                                 inversion=inversion.method), unknown_words=self.unknown_words(text))


    def _record(self, controller: EditController, capture: bool | CaptureConfig | dict,
                lengths: Sequence[int]) -> None:
        """Have the controller record the attention of its branches at this denoiser's sites."""
        dc = self.denoiser.config
        controller.record_attention(capture, lengths, num_layers=dc.layers, num_heads=dc.heads,
                                    unit_length=self.skeleton.unit_length)


def _check_recovery(method: Any) -> str:
    from salad_core.recovery import check_method

    return check_method(method)


def _guidance_settings(guidance: Guidance) -> dict[str, Any]:
    """The guidance entries of an output's ``settings``: weight, rescale and interval, and the refinements
    (threshold, projection, ...) that differ from their defaults as ``guidance_<field>``."""
    refinements = {f"guidance_{k}": v for k, v in guidance.to_json_dict().items()
                   if k not in ("scale", "rescale", "interval")}
    return dict(guidance_scale=guidance.scale, guidance_rescale=guidance.rescale, guidance_interval=guidance.interval,
                **refinements)


def _check_plain_guidance(guidance: Guidance, what: str) -> None:
    """Raise ``ValueError`` if ``guidance`` uses a refinement on the clean-sample prediction (threshold,
    projection): the editing and inversion loops run the source and edited rows stacked and do not support them."""
    if guidance.on_clean_sample:
        raise ValueError(f"pipe.{what} does not support guidance threshold or projection ({guidance.describe()}); "
                         "give guidance_scale=Guidance(scale, rescale=..., interval=...) without them")


def _inversion_guidance(inversion: Inversion) -> Guidance:
    """The guidance an inversion is faithful to (older inversions carry only the weight)."""
    made = getattr(inversion, "guidance", None)
    return made if made is not None else Guidance(inversion.guidance_scale)


def check_compatible(vae: MotionVAE, denoiser: Denoiser, text_encoder: TextEncoder | None = None) -> None:
    """Raise if the VAE latent, the denoiser and the text encoder do not fit together."""
    dc = denoiser.config
    if dc.num_parts != vae.num_parts or dc.latent_dim != vae.latent_dim:
        raise ValueError(f"the VAE and the denoiser do not fit together: VAE latent (P={vae.num_parts}, "
                         f"Dz={vae.latent_dim}) vs denoiser (P={dc.num_parts}, Dz={dc.latent_dim})")
    if text_encoder is not None and getattr(text_encoder, "dim", dc.text_dim) != dc.text_dim:
        raise ValueError(f"the text encoder gives {text_encoder.dim}-d features; the denoiser expects "
                         f"{dc.text_dim}-d (it was trained with another encoder)")


def _check_solver(solver: Any) -> str | None:
    """None (the pipeline's default) or the name of a solver of :data:`salad_core.sampling.SOLVERS`."""
    from salad_core.sampling import SOLVERS

    if solver is None:
        return None
    if not isinstance(solver, str):
        raise TypeError(f"solver must be a solver name ({', '.join(SOLVERS)}) or None, got "
                        f"{type(solver).__name__} {solver!r}")
    if solver.lower() not in SOLVERS:
        raise ValueError(f"solver={solver!r} is unknown; allowed: {', '.join(SOLVERS)} (None: the pipeline's default)")
    return solver


def _preset_folder(preset: Any, path: str | Path | None) -> Path:
    """The folder of a :data:`PIPELINE_PRESETS` preset (``path`` when given); CheckpointError when it is missing."""
    if not isinstance(preset, str) or preset not in PIPELINE_PRESETS:
        raise ValueError(f"preset={preset!r} is unknown; known: {', '.join(PIPELINE_PRESETS)} (None: the folder "
                         "given, or the shipped weights)")
    folder_of, command = PIPELINE_PRESETS[preset]
    root = Path(path) if path is not None else folder_of()
    if not (root / "pipeline.json").is_file():
        raise CheckpointError(f"the {preset!r} weights are missing: no pipeline.json in {root}; make them with "
                              f"{command}")
    return root


#: Solvers whose steps draw fresh noise that :meth:`SaladPipeline.__call__` seeds per sample (multistep consistency
#: sampling re-noises its clean estimate between steps).
_SEEDED_STEP_NOISE = ("lcm",)


def _step_generators(seeds: Sequence[int], solver: str, pipe: "SaladPipeline") -> list[torch.Generator] | None:
    """Per sample, the generator of a stochastic solver's step noise (None for the other solvers): the generator of
    the sample's initial noise (seeded by its seed) continued after that noise, so a motion is a function of its
    seed. The noise of step 2 onwards is drawn at the batch's latent length (a diffusers draw per row), so it
    depends on the longest motion of the batch (chunk) too."""
    if solver.lower() not in _SEEDED_STEP_NOISE:
        return None
    p, dz = pipe.latent_shape
    full = pipe.skeleton.max_length // pipe.skeleton.unit_length
    out = []
    for s in seeds:
        g = torch.Generator().manual_seed(int(s))
        torch.randn(full, p, dz, generator=g)             # the initial noise (make_noise) comes first
        out.append(g)
    return out


def _check_solver_steps(num_steps: Any, solver: str, diffusion: DiffusionConfig) -> int:
    """Sampler steps for ``solver`` (a call's, or a weight folder's default): a positive int within the training
    timesteps and, for the ``"lcm"`` solver, within the grid it samples on (``ValueError`` naming the bound)."""
    steps = _check_steps(num_steps, diffusion.num_train_timesteps)
    if isinstance(solver, str) and solver.lower() == "lcm":
        grid = make_scheduler(diffusion, "lcm").config.original_inference_steps
        if steps > grid:
            raise ValueError(f"num_steps={steps} is more than the {grid}-step grid the 'lcm' solver samples on "
                             f"(consistency-distilled weights take 1-{grid}, typically 1-4)")
    return steps


def _check_steps(num_steps: Any, max_steps: int | None = None) -> int:
    """A positive integer number of sampler steps, at most ``max_steps`` (the training timesteps)."""
    if not isinstance(num_steps, (int, np.integer)) or isinstance(num_steps, bool) or num_steps < 1:
        raise ValueError(f"num_steps must be a positive integer, got {num_steps!r}")
    if max_steps is not None and num_steps > max_steps:
        raise ValueError(f"num_steps={num_steps} is more than the {max_steps} diffusion timesteps the model was "
                         f"trained with; allowed: 1..{max_steps} (default 50)")
    return int(num_steps)


def _motion_list(motions: Any, skeleton: Skeleton) -> list[np.ndarray]:
    """Raw features ``(N, D)``, ``(B, N, D)`` or a list of ``(N_b, D)`` -> float32 arrays cropped to
    multiples of ``unit_length`` frames."""
    d, unit, max_len = skeleton.feature_dim, skeleton.unit_length, skeleton.max_length
    if isinstance(motions, torch.Tensor):
        motions = motions.detach().cpu().numpy()
    if isinstance(motions, np.ndarray):
        motions = [motions] if motions.ndim == 2 else list(motions)
    if not isinstance(motions, (list, tuple)) or not motions:
        raise TypeError(f"motions must be a (N, {d}) array, a (B, N, {d}) array or a list of (N, {d}) arrays")
    out = []
    for i, m in enumerate(motions):
        m = m.detach().cpu().numpy() if isinstance(m, torch.Tensor) else np.asarray(m)
        # complex parts would be dropped with only a ComplexWarning, strings parsed as numbers
        if m.dtype == bool or not (np.issubdtype(m.dtype, np.integer) or np.issubdtype(m.dtype, np.floating)):
            raise TypeError(f"motion {i} must hold real numbers, got dtype {m.dtype}")
        m = m.astype(np.float32, copy=False)
        if m.ndim != 2 or m.shape[1] != d:
            raise ValueError(f"motion {i} must be ({'N'}, {d}) raw {skeleton.name} features, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise ValueError(f"motion {i} contains NaN or infinite values")
        top = float(np.abs(m).max(initial=0.0))
        if top > MAX_FEATURE_MAGNITUDE:
            raise ValueError(f"motion {i} reaches |value| = {top:.3g}, beyond {MAX_FEATURE_MAGNITUDE:g}: not raw "
                             f"{skeleton.name} features (metres, radians, metres per frame; of order 1)")
        n = m.shape[0] - m.shape[0] % unit
        if n < unit or n > max_len:
            raise ValueError(f"motion {i} has {m.shape[0]} frames; allowed: {unit}..{max_len} "
                             f"(crop longer motions first)")
        if n != m.shape[0]:
            warnings.warn(f"motion {i} has {m.shape[0]} frames, not a multiple of {unit}; using the first {n}",
                          stacklevel=3)
        out.append(np.ascontiguousarray(m[:n]))
    return out


#: Seeds torch.Generator.manual_seed accepts.
SEED_RANGE = (-(2 ** 63), 2 ** 64 - 1)


def _check_edit_does_something(edits: tuple, prompts: list[str], targets: list[str], word_swap: type,
                               refine: type) -> None:
    """Refuse edits that cannot change anything and warn about those that probably do not.

    A word swap or a refinement of a prompt into itself gives back the source (refused); no edit
    and the source as target is a plain regeneration (warned: documented, and a useful baseline);
    a refinement whose target shares no word with the source keeps no source map (warned).
    """
    same = targets == prompts
    kinds = [type(e).__name__ for e in edits if isinstance(e, (word_swap, refine))]
    if kinds and same:
        raise ValueError(f"{kinds[0]} needs a target prompt that differs from the source (target=None or the "
                         f"same text gives back the source motion); pass target='...'")
    if not edits and same:
        warnings.warn("edits is empty and the target is the source: the edited motion is the source motion "
                      "(nothing is edited)", stacklevel=3)
    if any(isinstance(e, refine) for e in edits):
        for i, (a, b) in enumerate(zip(prompts, targets)):
            if not set(a.lower().split()) & set(b.lower().split()):
                warnings.warn(f"Refine: target {i} {b!r} shares no word with the source {a!r}, so no source map is "
                              "kept (the edit is a plain generation of the target)", stacklevel=3)


def _seeds(seed: int | Sequence[int], n: int) -> list[int]:
    """Per-sample noise seeds: ``seed + b`` for an int, the list itself for a list (each an int in
    :data:`SEED_RANGE`)."""
    if isinstance(seed, (list, tuple)):
        if len(seed) != n:
            raise ValueError(f"got {len(seed)} seeds for {n} prompts")
        seeds = list(seed)
    elif isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int or a list of ints, got {seed!r}")
    else:
        seeds = [int(seed) + i for i in range(n)]
    lo, hi = SEED_RANGE
    for i, s in enumerate(seeds):
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)):
            raise TypeError(f"seed {i} must be an int, got {s!r}")
        if not lo <= int(s) <= hi:
            raise ValueError(f"seed {int(s)} is out of range; seeds are integers in -2**63..2**64-1"
                             + (f" (sample {i} uses seed + {i})" if i and not isinstance(seed, (list, tuple)) else ""))
    return [int(s) for s in seeds]


def _check_noise(noise: torch.Tensor, shape: tuple[int, ...]) -> torch.Tensor:
    if not isinstance(noise, torch.Tensor) or tuple(noise.shape) != shape:
        got = tuple(noise.shape) if isinstance(noise, torch.Tensor) else type(noise).__name__
        raise ValueError(f"noise must be a tensor of shape {shape}, got {got}")
    if not torch.isfinite(noise).all():
        raise ValueError("noise contains NaN or infinite values")
    return noise.float()
