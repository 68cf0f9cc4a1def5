"""KeyMotion text-to-motion generation: keyframe latents -> keyframes -> in-filled motion.

The pipeline only orchestrates (models know nothing of sampling, the loop is
:func:`~salad_core.keymotion.pst.sample_latents`)::

    prompts --text encoder--> token features (B, W, C)
    noise (B, Lz, Dz) --PST + scheduler, CFG--> keyframe latents z0 (B, Lz, Dz)
        (a PST with PSTConfig.side_cue also gets the tokens' left/right ids (B, W): keymotion.sides)
    z0 --keyframe VAE decoder--> keyframes (B, K, D), positions (B, K) --> frame indices (B, K)
    keyframes at their frames --MMAE (text-conditioned)--> motion (B, N, D) normalised
    --de-normalise (MMAE's statistics)--> features --recovery--> joints (N_b, J, 3)

:class:`KeyMotionPipeline` has the interface of ``SaladPipeline``: ``from_pretrained(path=None)``
and ``pipe(prompts, lengths=None, seed=0, guidance_scale=None, num_steps=50)`` returning an output
with ``features``, ``joints``, ``texts``, ``lengths`` (and here ``keyframes``).

Choices: motion lengths are given by the caller (as in the T2M protocol, where the evaluation
uses the ground-truth lengths) and may be any ``num_keyframes <= L <= max_length``; without them
every motion gets ``default_length`` (120) frames. The empty prompt ``""`` is the unconditional
text of classifier-free guidance. The default guidance of a set of weights is stored with them
(``keymotion.json`` "guidance", a :class:`~salad_core.sampling.Guidance`: weight, rescale,
interval), as SALAD's ``pipeline.json``; without the entry it is ``Guidance(7.5)`` as SALAD's (the
KeyMotion paper's value was lost in our copy). ``docs/keymotion_recipe.md`` says why the weight
matters so much here: strong guidance pushes the keyframe latents off the data and the seeds
collapse. The MMAE output is the motion (it may correct the decoded
keyframes); ``keep_keyframes=True`` pastes the decoded keyframes back. Padded rows of
``features`` (``t >= length``) are zero. ``joints`` are recovered from the features as SALAD's pipeline
recovers them (:attr:`KeyMotionPipeline.recovery`: by default the skeleton fit with fixed bone lengths,
feet locked from the contact channels and nothing below the floor, :mod:`salad_core.recovery`), so the
two generators' GIFs, BVHs and joints are made the same way; ``raw_joints`` are the position features
read as they are (what the papers' metrics and the physics benchmark's default measure).

A pretrained folder holds::

    keymotion.json                      {"format": "keymotion_pipeline", "text_encoder", "diffusion",
                                         "default_length", optional "guidance": {"scale", "rescale", "interval"}}
    kf_vae.safetensors / kf_vae.json    the keyframe VAE (salad_core.io checkpoint)
    pst.safetensors / pst.json          the PST denoiser
    mmae.safetensors / mmae.json        the MMAE

A training root written by :func:`salad_core.keymotion.train.train_keymotion` (run folders
``kf_vae/``, ``pst/``, ``mmae/``, each with ``best.*`` or ``latest.*``) loads the same way.
"""
from __future__ import annotations

import json
import logging
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

from salad_core.io import atomic_write_text, config_from_dict, config_to_dict, load_model, save_checkpoint
from salad_core.motion import features_to_joints
from salad_core.sampling import DiffusionConfig, Guidance, make_scheduler, resolve_guidance
from salad_core.text import TextEncoder

from .kf_vae import KeyframeVAE
from .mmae import MotionMaskedAutoencoder
from .models import NORMALISATION_TOLERANCE, normalisation_gap
from .pst import PST_DIFFUSION, ParallelSkipTransformer, sample_latents
from .sides import mirror_side_words, names_left_first, side_ids_of

__all__ = ["KeyMotionPipeline", "KeyMotionOutput", "decode_keyframes", "DEFAULT_WEIGHTS_DIR", "COMPONENTS",
           "KEYMOTION_JSON_FIELDS"]

log = logging.getLogger(__name__)

#: Where the shipped KeyMotion weights live (package data).
DEFAULT_WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights" / "keymotion"
#: Component stems of a pretrained folder, and their model types.
COMPONENTS: dict[str, str] = {"kf_vae": "keymotion_kf_vae", "pst": "keymotion_pst", "mmae": "keymotion_mmae"}
_FORMAT = "keymotion_pipeline"


@dataclass
class KeyMotionOutput:
    """Generated motions (numpy, de-normalised); sample ``b`` has ``lengths[b]`` frames."""

    features: np.ndarray              # (B, N, D) features, N = max(lengths); rows t >= lengths[b] are 0
    joints: list[np.ndarray]          # per sample (N_b, J, 3) joint positions, recovered by ``settings["recovery"]``
    texts: list[str]                  # the prompts
    lengths: list[int]                # N_b, frames per sample
    keyframes: list[np.ndarray]       # per sample (K,) int64 frame indices of the keyframes, increasing
    keyframe_features: np.ndarray     # (B, K, D) decoded keyframes (de-normalised), in keyframe order
    latents: np.ndarray               # (B, Lz, Dz) denoised keyframe latents
    settings: dict = field(default_factory=dict)   # "recovery", "skeleton"
    #: per prompt: words the weights never saw in training, pieces in another script or emoji (as SALAD's)
    unknown_words: list[list[str]] = field(default_factory=list)
    #: per sample: replaced by its mirror image by the side check (``KeyMotionPipeline.side_check``)
    mirrored: list[bool] = field(default_factory=list)
    #: per sample: generated from the prompt's mirror image and mirrored back (a side-canonical PST,
    #: ``PSTConfig.side_canonical``, for prompts naming the left kind first); ``latents`` are the sampled ones
    canonical_mirrored: list[bool] = field(default_factory=list)

    @property
    def raw_joints(self) -> list[np.ndarray]:
        """Per sample ``(N_b, J, 3)`` joints read from the position features as they are (HumanML3D's
        ``recover_from_ric``, no fit), as SALAD's ``raw_joints``."""
        skeleton = self.settings.get("skeleton", "humanml3d")
        return [features_to_joints(self.features[b, :n], skeleton).astype(np.float32)
                for b, n in enumerate(self.lengths)]


def decode_keyframes(vae: KeyframeVAE, z: torch.Tensor, lengths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Decode latents into time-ordered keyframes and their frames.

    Parameters
    ----------
    vae : KeyframeVAE
    z : Tensor ``(B, Lz, Dz)``
    lengths : Tensor ``(B,)``
        Motion lengths (``>= K``).

    Returns
    -------
    keyframes : Tensor ``(B, K, D)`` normalised, sorted by decoded position
    indices : Tensor ``(B, K)`` long, strictly increasing, first 0 and last ``L - 1``
    """
    dec = vae.decode(z)
    order = torch.argsort(dec.positions, dim=1, stable=True)          # keep features with their positions
    keyframes = torch.gather(dec.keyframes, 1, order[..., None].expand(-1, -1, dec.keyframes.shape[-1]))
    positions = torch.gather(dec.positions, 1, order)
    return keyframes, vae.indices_of(positions, lengths)


def _join_chunks(parts: Sequence[tuple[torch.Tensor, ...]], n: int) -> tuple[torch.Tensor, ...]:
    """The chunks of :meth:`KeyMotionPipeline._generate_rows` as one batch: ``z``, keyframes and indices
    concatenated, the motions ``(b, n_chunk, D)`` zero-padded to ``n`` frames first (``(B, n, D)``)."""
    z, keyframes, indices, motions = zip(*parts)
    padded = [torch.nn.functional.pad(m, (0, 0, 0, n - m.shape[1])) for m in motions]
    return torch.cat(z), torch.cat(keyframes), torch.cat(indices), torch.cat(padded)


def _resolve_component(root: Path, name: str, allow_outside_paths: bool | str | os.PathLike = False) -> Path:
    """Checkpoint stem of component ``name`` in a pretrained folder or a training root; its files must
    lie inside ``root`` after symbolic links are resolved (:func:`salad_core.limits.resolve_inside`)."""
    from salad_core import limits
    from salad_core.io import CheckpointError, checkpoint_files

    if (root / f"{name}.json").is_file():
        stem = root / name
    else:
        stem = next((root / name / s for s in ("best", "latest") if (root / name / f"{s}.json").is_file()), None)
        if stem is None:
            raise FileNotFoundError(f"{root} holds no {name}.json / {name}.safetensors and no run folder "
                                    f"{root / name} with best.* or latest.*")
    for file in checkpoint_files(stem):
        limits.check_inside(root, file, name, str(file.relative_to(root)), root, allow_outside_paths, CheckpointError)
    return stem


#: The keys of ``keymotion.json`` and their JSON types (checked by :meth:`KeyMotionPipeline.from_pretrained`
#: with :func:`salad_core.limits.check_fields`).
KEYMOTION_JSON_FIELDS: dict[str, Any] = {
    "format": str, "version": int, "text_encoder": str, "diffusion": dict | None, "default_length": int,
    "guidance": dict | None, "recovery": str | None, "side_check": bool,
}


class KeyMotionPipeline:
    """Text -> motion with KeyMotion (keyframe VAE, PST denoiser, MMAE).

    Prompts with words outside :attr:`vocabulary` (the training captions' words, ``vocabulary.json``
    of the weights folder) warn with :class:`salad_core.vocabulary.UnknownWordsWarning`, as SALAD's.

    Parameters
    ----------
    kf_vae : KeyframeVAE
    pst : ParallelSkipTransformer
    mmae : MotionMaskedAutoencoder
    text_encoder : TextEncoder
        ``encode(prompts, allow_empty=...) -> TextBatch`` and ``dim``.
    diffusion : DiffusionConfig, optional
        The PST's schedule (default :data:`~salad_core.keymotion.pst.PST_DIFFUSION`).
    solver : str
        Sampler name for :func:`salad_core.sampling.make_scheduler` (``"ddim"``).
    default_length : int
        Frames generated when ``lengths`` is None.
    text_encoder_name : str, optional
        Recorded by :meth:`save_pretrained` (default: the encoder's ``name``).
    guidance : Guidance, optional
        Default classifier-free guidance of these weights (default ``Guidance(7.5)``).
    recovery : str, optional
        How ``out.joints`` are recovered from the features (:data:`salad_core.recovery.METHODS`; default
        ``"fit"`` where the skeleton has target bone lengths, else ``"positions"``), as SALAD's pipeline.
    """

    #: Sampling-time side check (:mod:`salad_core.side_check`): a motion that uses the other side than
    #: its prompt names (and none that it names) is replaced by its exact mirror image. KeyMotion 0.2
    #: takes the side from its noise, not its text; ``keymotion.json`` "side_check" (default true).
    side_check: bool = True
    #: Training vocabulary (``vocabulary.json``; None: not recorded), its corpus, and whether to warn.
    vocabulary: frozenset[str] | None = None
    vocabulary_source: str | None = None
    warn_unknown_words: bool = True
    #: Motions denoised and in-filled together by :meth:`__call__`; larger batches run in consecutive chunks of
    #: this size (:meth:`chunk_size`). None (default): :data:`salad_core.limits.PROMPT_CHUNK`.
    max_batch: int | None = None

    def __init__(self, kf_vae: KeyframeVAE, pst: ParallelSkipTransformer, mmae: MotionMaskedAutoencoder,
                 text_encoder: TextEncoder, *, diffusion: DiffusionConfig | None = None, solver: str = "ddim",
                 default_length: int = 120, text_encoder_name: str | None = None,
                 guidance: Guidance | None = None, recovery: str | None = None) -> None:
        self.kf_vae = kf_vae.eval()
        self.pst = pst.eval()
        self.mmae = mmae.eval()
        self.text_encoder = text_encoder
        self.diffusion = diffusion or PST_DIFFUSION
        if self.diffusion.prediction_type != "epsilon":
            log.warning("KeyMotion's PST predicts epsilon; diffusion.prediction_type=%r", self.diffusion.prediction_type)
        self.solver = solver
        self.text_encoder_name = text_encoder_name or getattr(text_encoder, "name", type(text_encoder).__name__)
        self._check_compatible()
        self.default_length = self._check_length(default_length, "default_length")
        #: Default guidance (``keymotion.json`` "guidance"); a number passed as ``guidance_scale``
        #: replaces only its weight, a Guidance replaces it all.
        self.guidance = Guidance(7.5) if guidance is None else guidance
        if not isinstance(self.guidance, Guidance):
            raise TypeError(f"guidance must be a salad_core.sampling.Guidance, got {type(guidance).__name__}")
        #: How ``out.joints`` are recovered (:data:`salad_core.recovery.METHODS`), as SALAD's pipeline.
        from salad_core.recovery import check_method

        self.recovery = check_method(recovery if recovery is not None else (
            "fit" if self.skeleton.bone_lengths is not None else "positions"))

    # ------------------------------------------------------------------------ checks
    def _check_compatible(self) -> None:
        vc, pc, mc = self.kf_vae.config, self.pst.config, self.mmae.config
        if (vc.latent_size, vc.latent_dim) != (pc.latent_size, pc.latent_dim):
            raise ValueError(f"the PST denoises latents ({pc.latent_size}, {pc.latent_dim}) but the keyframe VAE's "
                             f"are ({vc.latent_size}, {vc.latent_dim})")
        if vc.skeleton != mc.skeleton:
            raise ValueError(f"the keyframe VAE is for skeleton {vc.skeleton!r} but the MMAE for {mc.skeleton!r}")
        dim = getattr(self.text_encoder, "dim", None)
        for name, cfg in (("PST", pc), ("MMAE", mc)):
            if dim is not None and cfg.text_dim != dim:
                raise ValueError(f"the {name} expects {cfg.text_dim}-d text features but the text encoder "
                                 f"gives {dim}-d; use the encoder it was trained with")
        gap = normalisation_gap(self.kf_vae.norm.mean, self.kf_vae.norm.std, self.mmae.norm.mean, self.mmae.norm.std)
        if gap > NORMALISATION_TOLERANCE:
            log.warning("the keyframe VAE and the MMAE were trained with different normalisation statistics "
                        "(up to %.3g of a channel's std apart); the MMAE's are used", gap)

    @property
    def skeleton(self):
        return self.mmae.skeleton

    @property
    def num_keyframes(self) -> int:
        return self.kf_vae.config.num_keyframes

    @property
    def max_length(self) -> int:
        """Longest motion all three models support."""
        return min(self.kf_vae.config.max_length, self.mmae.config.max_length, self.pst.config.max_length)

    def _check_length(self, value: Any, name: str) -> int:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an int number of frames, got {value!r}")
        if not self.num_keyframes <= int(value) <= self.max_length:
            raise ValueError(f"{name}={int(value)} is out of range: use {self.num_keyframes} (the number of keyframes) "
                             f"to {self.max_length} frames")
        return int(value)

    @property
    def device(self) -> torch.device:
        return next(self.pst.parameters()).device

    def to(self, device: str | torch.device) -> "KeyMotionPipeline":
        """Move the three models (the text encoder stays where it was built)."""
        for m in (self.kf_vae, self.pst, self.mmae):
            m.to(device)
        return self

    # -------------------------------------------------------------------------- loading
    @classmethod
    def from_pretrained(cls, path: str | os.PathLike | None = None, *,
                        text_encoder: str | TextEncoder | None = None, device: str | torch.device = "cpu",
                        solver: str = "ddim", default_length: int | None = None,
                        recovery: str | None = None, allow_outside_paths: bool | str | os.PathLike = False
                        ) -> "KeyMotionPipeline":
        """Load a pretrained folder or a training root; ``path=None`` loads the shipped weights.

        Parameters
        ----------
        path : path, optional
            Folder described in the module docstring (default :data:`DEFAULT_WEIGHTS_DIR`).
        text_encoder : str or encoder, optional
            Overrides the encoder named in ``keymotion.json`` (``"minilm"`` or a CLIP folder) with a
            name or an already built encoder.
        device : str or torch.device
        solver : str
            Sampler name (:data:`salad_core.sampling.SOLVERS`).
        default_length : int, optional
            Overrides the stored default length.
        recovery : str, optional
            Overrides the stored recovery of ``out.joints`` (``keymotion.json`` "recovery"; default "fit").
        allow_outside_paths : bool or path
            The checkpoints, ``vocabulary.json`` and a ``text_encoder`` folder named in ``keymotion.json`` must
            lie inside the folder (after symbolic links are resolved); True accepts any place, a folder that
            folder too.

        ``keymotion.json`` is checked before anything loads (:data:`KEYMOTION_JSON_FIELDS`: known keys,
        a misspelt one named with the closest known key, JSON types, the nesting and size limits of
        :mod:`salad_core.limits`), and so are the checkpoints (:func:`salad_core.io.load_model`); problems
        raise :class:`~salad_core.io.CheckpointError` (a ValueError) naming the file and the key.
        """
        root = Path(path) if path is not None else DEFAULT_WEIGHTS_DIR
        if path is None and not (root / "keymotion.json").is_file():
            raise FileNotFoundError(
                f"no shipped KeyMotion weights at {root} (missing from this installation: reinstall salad, or "
                "train them with scripts/reproduce_keymotion.sh, or `salad train keymotion --data DIR --out RUN` "
                "and pass RUN as path)")
        if not root.is_dir():
            raise FileNotFoundError(f"KeyMotion folder {root} does not exist")
        from salad_core import limits
        from salad_core.io import CheckpointError, CheckpointTypeError
        from salad_core.pipeline import guidance_from_json

        doc_path = root / "keymotion.json"
        doc: dict[str, Any] = {}
        if doc_path.is_file():
            doc = limits.read_json(doc_path, "file", error=CheckpointError, expect=None)
            if not isinstance(doc, dict) or doc.get("format") != _FORMAT:
                found = doc.get("format") if isinstance(doc, dict) else limits.short_json(doc)
                raise CheckpointError(f"{doc_path} is not a KeyMotion pipeline description "
                                      f"(format {found!r}, expected {_FORMAT!r})")
            limits.check_fields(doc, KEYMOTION_JSON_FIELDS, str(doc_path), CheckpointError, CheckpointTypeError)
        models = {}
        metas = {}
        for name, model_type in COMPONENTS.items():
            stem = _resolve_component(root, name, allow_outside_paths)
            model, _, meta = load_model(stem, expected_type=model_type)
            models[name] = model.to(device).eval()
            metas[name] = meta
        where = doc_path if doc.get("diffusion") else f"{_resolve_component(root, 'pst')}.json: meta"
        diffusion = doc.get("diffusion") or metas["pst"].get("diffusion")
        diffusion = (config_from_dict(DiffusionConfig, diffusion, source=f"{where}: 'diffusion'") if diffusion
                     else PST_DIFFUSION)
        enc_name = doc.get("text_encoder") or metas["pst"].get("text_encoder") or "minilm"
        if text_encoder is None or isinstance(text_encoder, (str, os.PathLike)):
            from salad_core.text import load_text_encoder

            if text_encoder is not None:            # the caller's choice: taken as given
                enc_name = str(text_encoder)
                encoder = load_text_encoder(enc_name, device=device)
            else:
                if not isinstance(enc_name, str):
                    raise CheckpointTypeError(f"{where}: 'text_encoder' must be a string, got {enc_name!r}")
                path = (enc_name if enc_name.lower() == "minilm" else
                        limits.resolve_inside(root, enc_name, "text_encoder", doc_path, allow_outside_paths,
                                              CheckpointError, CheckpointTypeError))
                encoder = load_text_encoder(path, device=device)
        else:
            encoder = text_encoder
            enc_name = getattr(encoder, "name", type(encoder).__name__)
        length = default_length if default_length is not None else doc.get("default_length", 120)
        guidance = guidance_from_json(doc.get("guidance"), doc_path)
        pipe = cls(models["kf_vae"], models["pst"], models["mmae"], encoder, diffusion=diffusion, solver=solver,
                   default_length=length, text_encoder_name=enc_name, guidance=guidance,
                   recovery=recovery if recovery is not None else doc.get("recovery"))
        from salad_core.vocabulary import vocabulary_and_source

        pipe.vocabulary, pipe.vocabulary_source = vocabulary_and_source(root, allow_outside_paths)
        pipe.side_check = doc.get("side_check", True)          # a bool: checked with the fields above
        return pipe

    def save_pretrained(self, path: str | os.PathLike, *, dtype: torch.dtype | None = None) -> Path:
        """Write the three checkpoints and ``keymotion.json`` into ``path`` (created); returns it.

        ``dtype`` (e.g. ``torch.float16``) stores floating weights compactly.
        """
        root = Path(path)
        root.mkdir(parents=True, exist_ok=True)
        for name, model in (("kf_vae", self.kf_vae), ("pst", self.pst), ("mmae", self.mmae)):
            save_checkpoint(root / name, model, model_type=COMPONENTS[name], config=model.config, dtype=dtype)
        doc = {"format": _FORMAT, "version": 1, "text_encoder": self.text_encoder_name,
               "diffusion": config_to_dict(self.diffusion), "default_length": self.default_length,
               "guidance": self.guidance.to_json_dict(), "recovery": self.recovery, "side_check": self.side_check}
        atomic_write_text(root / "keymotion.json", json.dumps(doc, indent=2) + "\n")
        if self.vocabulary is not None:     # what the weights can read travels with them
            from salad_core.vocabulary import write_vocabulary

            write_vocabulary(self.vocabulary, root, source=self.vocabulary_source)
        return root

    # ---------------------------------------------------------------------- generation
    def _lengths(self, lengths: int | Sequence[int] | None, b: int) -> list[int]:
        if lengths is None:
            return [self.default_length] * b
        if isinstance(lengths, (int, np.integer)) and not isinstance(lengths, bool):
            return [self._check_length(lengths, "lengths")] * b
        out = [self._check_length(v, f"lengths[{i}]") for i, v in enumerate(lengths)]
        if len(out) != b:
            raise ValueError(f"lengths has {len(out)} entries for {b} prompts")
        return out

    def resolve_guidance(self, guidance_scale: "float | Guidance | None" = None) -> Guidance:
        """The :class:`~salad_core.sampling.Guidance` a call uses: None -> :attr:`guidance`; a number ->
        :attr:`guidance` with that weight; a Guidance -> itself
        (:func:`~salad_core.sampling.resolve_guidance`, as SALAD's pipeline, which checks the weight)."""
        return resolve_guidance(self.guidance, guidance_scale, stacklevel=2)

    def __call__(self, prompts: str | Sequence[str], lengths: int | Sequence[int] | None = None, seed: int = 0,
                 guidance_scale: "float | Guidance | None" = None, num_steps: int = 50, *,
                 keep_keyframes: bool = False, recovery: str | None = None,
                 side_check: bool | None = None, progress: bool = False) -> KeyMotionOutput:
        """Generate one motion per prompt.

        Parameters
        ----------
        prompts : str or list of str
        lengths : int or list of int, optional
            Frames per motion (``num_keyframes .. max_length``; default :attr:`default_length`).
        seed : int
            Seeds the initial noise; the same call with the same seed returns the same motions.
        guidance_scale : float or Guidance, optional
            Classifier-free guidance (eq. 8): None uses the weights' default (:attr:`guidance`), a
            number in ``-MAX_GUIDANCE..MAX_GUIDANCE`` replaces its weight (1 disables guidance; a
            negative weight is warned about), a Guidance replaces it all.
        num_steps : int
            Denoising steps.
        keep_keyframes : bool
            Paste the decoded keyframes over the MMAE's output at their frames (by default the MMAE
            may correct them, as in the paper).
        recovery : str, optional
            How ``joints`` are recovered from the features (default :attr:`recovery`).
        side_check : bool, optional
            Mirror a motion whose measured side contradicts its prompt (default :attr:`side_check`;
            ``out.mirrored`` says which were; their ``latents`` stay the sampled, unmirrored ones).
            With a side-canonical PST (``PSTConfig.side_canonical``) a prompt naming the left kind first is
            generated as its mirror image (side words swapped) and the motion mirrored back before the check
            (``out.canonical_mirrored``), so "left" and "right" give each other's exact mirror images.
        progress : bool
            Show a progress bar over the denoising steps (and, for more than
            :data:`salad_core.limits.PROMPT_CHUNK` prompts, over the chunks and the motions' joint recovery).

        Prompts are checked and normalised as SALAD's are (:func:`salad_core.text.validate_prompts`).
        A batch of more than :meth:`chunk_size` motions is denoised and in-filled in consecutive chunks of
        that size (memory bounded, progress shown). The initial noise of *all* motions is drawn first, from
        the one generator seeded by ``seed``, in the order one piece draws it, so with a deterministic
        solver (the default DDIM) every motion equals the one of an unchunked call up to float rounding
        (the products block differently at another batch size), and a prompt's motion does not depend on
        the chunk it falls in. Stochastic solvers (``"ddpm"``, ``"euler_ancestral"``) also draw fresh noise
        from that generator at every step: chunk after chunk, so a batch larger than the chunk size gives
        other (equally distributed) motions than one piece would, still the same ones for the same call,
        seed and chunk size.

        Returns
        -------
        KeyMotionOutput
        """
        from salad_core import limits
        from salad_core.sampling import progress_bar
        from salad_core.text import validate_prompts

        texts = validate_prompts(prompts)        # the prompt checks SALAD's pipeline makes (salad_core.text)
        b = len(texts)
        many = b > limits.PROMPT_CHUNK
        chunk = self.chunk_size()
        if many:
            log.info("generating %d motions in chunks of %d (denoising, then %d joint recoveries)", b, chunk, b)
        lens = self._lengths(lengths, b)
        dev = self.device
        len_t = torch.tensor(lens, dtype=torch.long, device=dev)
        tb = self.text_encoder.encode(texts)
        unknown = self.unknown_words(tb, warn=True, stacklevel=2)
        # a side-canonical PST learnt sides from right-first captions only: mirror the others, and the motions back
        canonical = [self.pst.config.side_canonical and names_left_first(t) for t in texts]
        if any(canonical):
            tb = self.text_encoder.encode([mirror_side_words(t) if c else t for t, c in zip(texts, canonical)])
        guidance = self.resolve_guidance(guidance_scale)
        null = None
        if guidance.cfg:
            nb = self.text_encoder.encode([""], allow_empty=True)
            null = (nb.features.to(dev), nb.mask.to(dev))
        gen = torch.Generator().manual_seed(int(seed))
        lz, dz = self.pst.config.latent_size, self.pst.config.latent_dim
        dtype = next(self.pst.parameters()).dtype
        noise = torch.randn((b, lz, dz), generator=gen).to(device=dev, dtype=dtype)   # every motion's, up front
        # a side-cue PST reads which tokens say left/right (salad_core.keymotion.sides)
        sides = side_ids_of(tb).to(dev) if self.pst.config.side_cue else None
        text, text_mask = tb.features.to(dev), tb.mask.to(dev)
        starts = range(0, b, chunk)
        parts = [self._generate_rows(slice(i, i + chunk), text, text_mask, sides, null, noise, len_t, guidance,
                                     num_steps, gen, keep_keyframes, progress)
                 for i in progress_bar(starts, f"motions ({chunk} per chunk)", progress and many, total=len(starts))]
        with torch.inference_mode():
            z, keyframes, indices, motion = _join_chunks(parts, max(lens))
            feats = self.mmae.norm.denormalize(motion)
            valid = (torch.arange(feats.shape[1], device=dev)[None] < len_t[:, None])[..., None]
            feats = (feats * valid.to(feats.dtype)).float().cpu().numpy()
            kf_feats = self.mmae.norm.denormalize(keyframes).float().cpu().numpy()
        if any(canonical):
            from salad_core.motion import mirror_features

            for i, n in enumerate(lens):
                if canonical[i]:
                    feats[i, :n] = mirror_features(feats[i, :n], self.skeleton)
                    kf_feats[i] = mirror_features(kf_feats[i], self.skeleton)
        from salad_core.recovery import check_method, recover_joints

        method = check_method(self.recovery if recovery is None else recovery)

        joints = [recover_joints(feats[i, :n], method, self.skeleton).astype(np.float32)
                  for i, n in progress_bar(list(enumerate(lens)), "recovering joints", progress and many)]
        mirrored = [False] * b
        if self.side_check if side_check is None else side_check:
            from salad_core.motion import mirror_features
            from salad_core.side_check import should_mirror

            for i, n in enumerate(lens):
                if should_mirror(texts[i], joints[i], self.skeleton):
                    mirrored[i] = True
                    feats[i, :n] = mirror_features(feats[i, :n], self.skeleton)
                    kf_feats[i] = mirror_features(kf_feats[i], self.skeleton)
                    joints[i] = recover_joints(feats[i, :n], method, self.skeleton).astype(np.float32)
        return KeyMotionOutput(features=feats, joints=joints, texts=texts, lengths=lens,
                               keyframes=[row for row in indices.cpu().numpy().astype(np.int64)],
                               keyframe_features=kf_feats, latents=z.float().cpu().numpy(),
                               settings={"recovery": method, "skeleton": self.skeleton.name,
                                         "side_check": bool(self.side_check if side_check is None else side_check)},
                               unknown_words=unknown, mirrored=mirrored, canonical_mirrored=canonical)

    def chunk_size(self) -> int:
        """Motions per chunk of :meth:`__call__`: :attr:`max_batch` if set, else
        :data:`salad_core.limits.PROMPT_CHUNK` (read at call time)."""
        from salad_core import limits

        if self.max_batch is None:
            return limits.PROMPT_CHUNK
        if isinstance(self.max_batch, bool) or not isinstance(self.max_batch, int) or self.max_batch < 1:
            raise ValueError(f"max_batch must be a positive int or None, got {self.max_batch!r}")
        return self.max_batch

    def _generate_rows(self, rows: slice, text: torch.Tensor, text_mask: torch.Tensor, sides: torch.Tensor | None,
                       null: tuple[torch.Tensor, torch.Tensor] | None, noise: torch.Tensor, len_t: torch.Tensor,
                       guidance: Guidance, num_steps: int, gen: torch.Generator, keep_keyframes: bool,
                       progress: bool) -> tuple[torch.Tensor, ...]:
        """One chunk of :meth:`__call__`, the motions ``rows`` of the batch: the PST denoises their noise
        ``(b, Lz, Dz)`` (a fresh scheduler: multistep solvers keep state), the keyframe VAE decodes, the MMAE
        in-fills. Returns ``(z (b, Lz, Dz), keyframes (b, K, D) normalised, indices (b, K), motion
        (b, n, D) normalised)`` with ``n`` the chunk's longest length."""
        null_text, null_mask = null if null is not None else (None, None)
        lens = len_t[rows]
        z = sample_latents(self.pst, make_scheduler(self.diffusion, self.solver), text[rows], text_mask[rows],
                           null_text, null_mask, noise[rows], lengths=lens, guidance_scale=guidance,
                           num_steps=num_steps, progress=progress, generator=gen,
                           text_sides=None if sides is None else sides[rows])
        with torch.inference_mode():
            keyframes, indices = decode_keyframes(self.kf_vae, z, lens)
            motion = self.mmae.infill(keyframes, indices, lens, text[rows], text_mask[rows],
                                      keep_keyframes=keep_keyframes)
        return z, keyframes, indices, motion

    def unknown_words(self, text, *, warn: bool = False, stacklevel: int = 1) -> list[list[str]]:
        """Per prompt (a list of prompts or a ``TextBatch``): its words outside :attr:`vocabulary` and its
        pieces in another script or emoji; with ``warn``, one ``UnknownWordsWarning`` naming them."""
        from salad_core.vocabulary import UnknownWordsWarning, check_prompt, unknown_words_message

        prompts = [text] if isinstance(text, str) else list(getattr(text, "prompts", text))
        tokens = list(getattr(text, "tokens", [None] * len(prompts)))
        checks = [check_prompt(p, self.vocabulary, t) for p, t in zip(prompts, tokens)]
        if warn and self.warn_unknown_words and any(checks):
            warnings.warn(unknown_words_message(checks, self.vocabulary_source), UnknownWordsWarning,
                          stacklevel=stacklevel + 1)
        return [c.terms for c in checks]
