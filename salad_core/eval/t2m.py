"""The T2M text-motion matching evaluator (Guo et al., CVPR 2022) used by every HumanML3D table.

Three networks map a caption and a motion into one 512-d space (``humanml3d_eval_facts`` §4.2):

- :class:`MovementConvEncoder`: normalised features without the 4 foot contacts ``(B, N, D-4)``
  -> movement codes ``(B, N // 4, 512)`` (two stride-2 convolutions);
- :class:`MotionEncoderBiGRUCo`: movement codes -> motion embedding ``(B, 512)`` (BiGRU);
- :class:`TextEncoderBiGRUCo`: word vectors + POS one-hots ``(B, L, 300)``, ``(B, L, 15)`` ->
  text embedding ``(B, 512)`` (BiGRU).

Module and parameter names equal the official ones, so the official ``finest.tar`` loads into
them unchanged (:meth:`T2MEvaluator.from_official`). :class:`EvaluatorConfig` holds the sizes;
a small evaluator for the procedural corpus uses the same classes with smaller widths.

:class:`T2MEvaluator` bundles the three networks with the evaluator's own normalisation
statistics and (optionally) its word vectors, so one safetensors checkpoint (``salad_core.io``,
model type ``"t2m_evaluator"``) carries everything. Unlike the official wrapper it returns
embeddings in the input order.

:func:`matching_loss` is the contrastive objective the evaluator was trained with.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence

from salad_core.io import (
    load_state_into,
    read_checkpoint,
    register_model,
    save_checkpoint,
    CheckpointError,
)
from salad_core.skeleton import Skeleton, get_skeleton

from .word_vectorizer import NUM_POS, WordVectorizer

__all__ = [
    "EvaluatorConfig",
    "MovementConvEncoder",
    "TextEncoderBiGRUCo",
    "MotionEncoderBiGRUCo",
    "T2MEvaluator",
    "MatchingLoss",
    "matching_loss",
    "save_evaluator",
    "load_evaluator",
    "official_paths",
    "MODEL_TYPE",
]

logger = logging.getLogger(__name__)

MODEL_TYPE = "t2m_evaluator"
#: Folder names of the official checkpoints per skeleton (``checkpoints/<t2m|kit>/...``).
_OFFICIAL_DATASET_DIR = {"humanml3d": "t2m", "kit": "kit"}
#: Option folders whose ``meta/{mean,std}.npy`` are the evaluator's statistics, in search order
#: (SALAD/MoMask use Comp_v6_KLD005, T2M's own scripts Comp_v6_KLD01).
_OFFICIAL_META_DIRS = ("Comp_v6_KLD005", "Comp_v6_KLD01", "text_mot_match")
#: Time down-sampling of the movement encoder: two stride-2 convolutions.
_MOVEMENT_STRIDE = 4
#: The default (official) evaluator is HumanML3D's.
_DEFAULT_SKELETON = get_skeleton("humanml3d")


@dataclass(frozen=True)
class EvaluatorConfig:
    """Sizes of the T2M evaluator; the defaults are the official HumanML3D ones."""

    dim_pose: int = _DEFAULT_SKELETON.feature_dim                  # feature width D incl. contacts (263; KIT 251)
    num_contacts: int = len(_DEFAULT_SKELETON.contact_joints)      # trailing contact channels, ignored (4)
    dim_word: int = 300                 # word-vector width (GloVe 300)
    dim_pos_ohot: int = NUM_POS         # POS one-hot width (15, fixed by the POS enumerator)
    dim_text_hidden: int = 512          # text BiGRU hidden size per direction
    dim_coemb: int = 512                # width of the shared text/motion embedding space
    dim_movement_enc_hidden: int = 512  # movement conv encoder hidden channels
    dim_movement_latent: int = 512      # movement code width
    dim_motion_hidden: int = 1024       # motion BiGRU hidden size per direction
    unit_length: int = _MOVEMENT_STRIDE  # frames per movement code (fixed by the two convs)
    max_text_len: int = 20              # caption tokens kept before sos/eos are added
    vocab: tuple[str, ...] = ()         # word list of the bundled word vectors (empty: none bundled)

    def __post_init__(self) -> None:
        for name in ("dim_pose", "dim_word", "dim_text_hidden", "dim_coemb", "dim_movement_enc_hidden",
                     "dim_movement_latent", "dim_motion_hidden", "max_text_len"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"EvaluatorConfig.{name} must be a positive int, got {v!r}")
        if not isinstance(self.num_contacts, int) or not 0 <= self.num_contacts < self.dim_pose:
            raise ValueError(f"EvaluatorConfig.num_contacts must be an int in [0, dim_pose={self.dim_pose}), "
                             f"got {self.num_contacts!r}")
        if self.dim_pos_ohot != NUM_POS:
            raise ValueError(f"EvaluatorConfig.dim_pos_ohot must be {NUM_POS} (the POS enumerator), "
                             f"got {self.dim_pos_ohot!r}")
        if self.unit_length != _MOVEMENT_STRIDE:
            raise ValueError(f"EvaluatorConfig.unit_length must be {_MOVEMENT_STRIDE} (two stride-2 "
                             f"convolutions), got {self.unit_length!r}")
        if not isinstance(self.vocab, tuple) or not all(isinstance(w, str) for w in self.vocab):
            raise ValueError("EvaluatorConfig.vocab must be a tuple of str")

    @property
    def movement_input_dim(self) -> int:
        """Width the movement encoder sees: ``dim_pose - num_contacts`` (259 / 247)."""
        return self.dim_pose - self.num_contacts

    @classmethod
    def for_skeleton(cls, skeleton: str | Skeleton = "humanml3d", **overrides) -> "EvaluatorConfig":
        """Official sizes with the feature width and contact count of ``skeleton``; ``overrides``
        change any field (e.g. smaller widths for our own evaluator)."""
        skel = get_skeleton(skeleton)
        base = cls(dim_pose=skel.feature_dim, num_contacts=len(skel.contact_joints))
        return replace(base, **overrides)


def _init_weights(module: nn.Module) -> None:
    # T2M's init_weight: Xavier-normal weights and zero biases for convs and linears
    if isinstance(module, (nn.Conv1d, nn.Linear)):
        nn.init.xavier_normal_(module.weight)
        if module.bias is not None:
            nn.init.zeros_(module.bias)


class MovementConvEncoder(nn.Module):
    """Normalised motion without contacts ``(B, N, D_in)`` -> movement codes ``(B, N // 4, D_out)``.

    Conv1d(k4, s2, p1) -> Dropout 0.2 -> LeakyReLU 0.2, twice, then a Linear. Official key
    names: ``main.0.*``, ``main.3.*``, ``out_net.*``.
    """

    def __init__(self, input_size: int, hidden_size: int, output_size: int) -> None:
        super().__init__()
        self.main = nn.Sequential(
            nn.Conv1d(input_size, hidden_size, 4, 2, 1),
            nn.Dropout(0.2),
            nn.LeakyReLU(0.2),
            nn.Conv1d(hidden_size, output_size, 4, 2, 1),
            nn.Dropout(0.2),
            nn.LeakyReLU(0.2),
        )
        self.out_net = nn.Linear(output_size, output_size)
        self.apply(_init_weights)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """``inputs (B, N, D_in)`` -> ``(B, N // 4, D_out)``."""
        x = self.main(inputs.transpose(1, 2))         # (B, D_out, N // 4)
        return self.out_net(x.transpose(1, 2))


class _BiGRUCo(nn.Module):
    """Shared body of the text and motion encoders: input Linear -> BiGRU with a learned initial
    state -> concatenated final states -> Linear, LayerNorm, LeakyReLU, Linear."""

    def __init__(self, input_size: int, hidden_size: int, output_size: int) -> None:
        super().__init__()
        self.hidden_size = hidden_size
        self.input_emb = nn.Linear(input_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = nn.Sequential(
            nn.Linear(hidden_size * 2, hidden_size),
            nn.LayerNorm(hidden_size),
            nn.LeakyReLU(0.2),
            nn.Linear(hidden_size, output_size),
        )
        self.input_emb.apply(_init_weights)
        self.output_net.apply(_init_weights)
        self.hidden = nn.Parameter(torch.randn(2, 1, hidden_size))  # (directions, 1, H)

    def _encode(self, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """``x (B, L, H)`` valid for ``lengths (B,)`` steps -> ``(B, C)`` in input order.

        ``enforce_sorted=False`` lets PyTorch sort by length for packing and restore the batch
        order of the final states, so callers need not sort (the official code sorts by hand).
        """
        b = x.shape[0]
        packed = pack_padded_sequence(x, lengths.to("cpu", torch.int64), batch_first=True, enforce_sorted=False)
        _, last = self.gru(packed, self.hidden.expand(2, b, self.hidden_size).contiguous())  # (2, B, H)
        return self.output_net(torch.cat([last[0], last[1]], dim=-1))


class TextEncoderBiGRUCo(_BiGRUCo):
    """Word vectors + POS one-hots -> text embedding.

    Official key names: ``hidden``, ``pos_emb.*``, ``input_emb.*``, ``gru.*``, ``output_net.{0,1,3}.*``.
    """

    def __init__(self, word_size: int, pos_size: int, hidden_size: int, output_size: int) -> None:
        super().__init__(word_size, hidden_size, output_size)
        self.pos_emb = nn.Linear(pos_size, word_size)
        self.pos_emb.apply(_init_weights)

    def forward(self, word_embs: torch.Tensor, pos_onehot: torch.Tensor, cap_lens: torch.Tensor) -> torch.Tensor:
        """``word_embs (B, L, d)``, ``pos_onehot (B, L, 15)``, ``cap_lens (B,)`` -> ``(B, C)``, input order."""
        return self._encode(self.input_emb(word_embs + self.pos_emb(pos_onehot)), cap_lens)


class MotionEncoderBiGRUCo(_BiGRUCo):
    """Movement codes ``(B, N', D_mov)`` valid for ``m_lens (B,)`` codes -> motion embedding ``(B, C)``.

    Official key names as the text encoder's, without ``pos_emb``.
    """

    def forward(self, inputs: torch.Tensor, m_lens: torch.Tensor) -> torch.Tensor:
        return self._encode(self.input_emb(inputs), m_lens)


class T2MEvaluator(nn.Module):
    """The three evaluator networks, the evaluator's normalisation and optional word vectors.

    State dict: ``movement_encoder.*``, ``text_encoder.*``, ``motion_encoder.*`` (official names
    under these prefixes), ``mean`` and ``std`` ``(D,)`` (the evaluator's own statistics; identity
    by default) and, when ``config.vocab`` is set, ``word_vectors`` ``(V, dim_word)``.

    Parameters
    ----------
    config : EvaluatorConfig
    vectorizer : WordVectorizer, optional
        Bundled as ``word_vectors`` (its words must equal ``config.vocab``).
    """

    def __init__(self, config: EvaluatorConfig, vectorizer: WordVectorizer | None = None) -> None:
        super().__init__()
        self.config = config
        c = config
        self.movement_encoder = MovementConvEncoder(c.movement_input_dim, c.dim_movement_enc_hidden,
                                                    c.dim_movement_latent)
        self.text_encoder = TextEncoderBiGRUCo(c.dim_word, c.dim_pos_ohot, c.dim_text_hidden, c.dim_coemb)
        self.motion_encoder = MotionEncoderBiGRUCo(c.dim_movement_latent, c.dim_motion_hidden, c.dim_coemb)
        self.register_buffer("mean", torch.zeros(c.dim_pose))
        self.register_buffer("std", torch.ones(c.dim_pose))
        if c.vocab:
            self.register_buffer("word_vectors", torch.zeros(len(c.vocab), c.dim_word))
        if vectorizer is not None:
            self.set_vectorizer(vectorizer)

    # --------------------------------------------------------------- text side
    def set_vectorizer(self, vectorizer: WordVectorizer) -> None:
        """Copy ``vectorizer``'s vectors into ``word_vectors`` (its words must be ``config.vocab``)."""
        if tuple(vectorizer.words) != self.config.vocab:
            raise ValueError(f"vectorizer words ({len(vectorizer)}) differ from config.vocab "
                             f"({len(self.config.vocab)}); build the config with vocab=vectorizer.words")
        if vectorizer.dim != self.config.dim_word or vectorizer.max_text_len != self.config.max_text_len:
            raise ValueError(f"vectorizer (dim {vectorizer.dim}, max_text_len {vectorizer.max_text_len}) does "
                             f"not fit config (dim_word {self.config.dim_word}, max_text_len "
                             f"{self.config.max_text_len})")
        with torch.no_grad():
            self.word_vectors.copy_(torch.from_numpy(vectorizer.vectors))

    @property
    def vectorizer(self) -> WordVectorizer:
        """A :class:`WordVectorizer` over the bundled vocabulary and current ``word_vectors``."""
        if not self.config.vocab:
            raise RuntimeError("this evaluator bundles no word vectors (config.vocab is empty); build "
                               "word_embs/pos_ohot with a WordVectorizer and call text_embeddings")
        vectors = self.word_vectors.detach().to("cpu", torch.float32).numpy()
        return WordVectorizer(self.config.vocab, vectors, max_text_len=self.config.max_text_len)

    @torch.no_grad()
    def text_embeddings(self, word_embs, pos_ohot, sent_lens) -> torch.Tensor:
        """Caption embeddings, in input order.

        Parameters
        ----------
        word_embs : ``(B, L, dim_word)``
        pos_ohot : ``(B, L, 15)``
        sent_lens : ``(B,)`` int, in ``[1, L]`` (``sos`` + tokens + ``eos``)
            Tensors or arrays (:meth:`WordVectorizer.process_batch` output).

        Returns
        -------
        torch.Tensor ``(B, dim_coemb)`` float32 on the module's device.
        """
        dev = self.mean.device
        w = torch.as_tensor(word_embs, dtype=torch.float32, device=dev)
        p = torch.as_tensor(pos_ohot, dtype=torch.float32, device=dev)
        n = torch.as_tensor(sent_lens).to(torch.int64)
        if w.ndim != 3 or w.shape[-1] != self.config.dim_word:
            raise ValueError(f"word_embs must be (B, L, {self.config.dim_word}), got {tuple(w.shape)}")
        if p.shape != (*w.shape[:2], self.config.dim_pos_ohot):
            raise ValueError(f"pos_ohot must be {(*w.shape[:2], self.config.dim_pos_ohot)}, got {tuple(p.shape)}")
        if n.shape != (w.shape[0],) or (n < 1).any() or (n > w.shape[1]).any():
            raise ValueError(f"sent_lens must be ({w.shape[0]},) ints in [1, {w.shape[1]}], got {n.tolist()}")
        return self.text_encoder(w, p, n)

    def caption_embeddings(self, captions: Sequence[Sequence[str]]) -> torch.Tensor:
        """``word/POS`` token lists of B captions -> ``(B, dim_coemb)`` via the bundled vectors."""
        return self.text_embeddings(*self.vectorizer.process_batch(captions))

    # ------------------------------------------------------------- motion side
    def normalize(self, features):
        """Raw features ``(..., D)`` -> the evaluator's normalisation ``(x - mean) / std`` (a tensor)."""
        x = torch.as_tensor(features, dtype=torch.float32, device=self.mean.device)
        if x.shape[-1] != self.config.dim_pose:
            raise ValueError(f"features must end in dim_pose={self.config.dim_pose}, got {tuple(x.shape)}")
        return (x - self.mean) / self.std

    @torch.no_grad()
    def motion_embeddings(self, motions, lengths, mask_padding: bool = True) -> torch.Tensor:
        """Motion embeddings, in input order.

        The official wrapper sorts the batch by length and returns embeddings in that sorted order;
        this returns row ``i`` for ``motions[i]`` (the sort for packing happens inside).

        Parameters
        ----------
        motions : ``(B, N, D)``
            Features normalised with THIS evaluator's ``mean``/``std`` (see :meth:`normalize`), not
            with the generator's statistics. The last ``num_contacts`` dims are dropped here.
        lengths : ``(B,)`` int, in ``[unit_length, N]``
            Valid frames; the motion GRU runs for ``lengths // unit_length`` codes.
        mask_padding : bool
            Zero frames at and after each length first, as SALAD does for generated motions (the
            convolutions see a few frames past the length; real loader motions are already zero
            there, so this changes nothing for them).

        Returns
        -------
        torch.Tensor ``(B, dim_coemb)`` float32 on the module's device.
        """
        c = self.config
        x = torch.as_tensor(motions, dtype=torch.float32, device=self.mean.device)
        m = torch.as_tensor(lengths).to(torch.int64).cpu()
        if x.ndim != 3 or x.shape[-1] != c.dim_pose:
            raise ValueError(f"motions must be (B, N, {c.dim_pose}), got {tuple(x.shape)}")
        if m.shape != (x.shape[0],) or (m < c.unit_length).any() or (m > x.shape[1]).any():
            raise ValueError(f"lengths must be ({x.shape[0]},) ints in [{c.unit_length}, N={x.shape[1]}], "
                             f"got {m.tolist()}")
        if mask_padding:
            valid = torch.arange(x.shape[1])[None, :] < m[:, None]       # (B, N)
            x = x * valid.to(x.device)[..., None]
        movements = self.movement_encoder(x[..., : c.movement_input_dim])   # (B, N // 4, D_mov)
        return self.motion_encoder(movements, m // c.unit_length)

    def forward(self, word_embs: torch.Tensor, pos_ohot: torch.Tensor, sent_lens: torch.Tensor,
                motions: torch.Tensor, lengths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Differentiable text and motion embeddings ``(B, C)`` each, for training with
        :func:`matching_loss` (motions normalised and contact dims included, as above)."""
        text = self.text_encoder(word_embs, pos_ohot, sent_lens)
        movements = self.movement_encoder(motions[..., : self.config.movement_input_dim])
        return text, self.motion_encoder(movements, lengths // self.config.unit_length)

    # ------------------------------------------------------------ official
    @classmethod
    def from_official(cls, checkpoints_dir: str | PathLike, dataset: str = "humanml3d",
                      glove_dir: str | PathLike | None = None, meta_dir: str | PathLike | None = None,
                      config: EvaluatorConfig | None = None) -> "T2MEvaluator":
        """Load the official evaluator of the T2M / MoMask / SALAD release.

        Parameters
        ----------
        checkpoints_dir : path
            The release's ``checkpoints`` folder, holding
            ``<t2m|kit>/text_mot_match/model/finest.tar`` (read with ``weights_only=True``).
        dataset : ``"humanml3d"`` (folder ``t2m``) or ``"kit"``
        glove_dir : path, optional
            Folder with ``our_vab_{data.npy,words.pkl,idx.pkl}``; default: the first of
            ``checkpoints_dir/../glove`` and ``checkpoints_dir/glove`` that exists.
        meta_dir : path, optional
            Folder with the evaluator's ``mean.npy`` and ``std.npy``; default: the first existing
            ``<t2m|kit>/{Comp_v6_KLD005,Comp_v6_KLD01,text_mot_match}/meta``.
        config : EvaluatorConfig, optional
            Sizes; default: :meth:`EvaluatorConfig.for_skeleton` (official sizes).

        Returns
        -------
        T2MEvaluator in eval mode, with the GloVe vectors bundled.
        """
        paths = official_paths(checkpoints_dir, dataset, glove_dir=glove_dir, meta_dir=meta_dir)
        vectorizer = WordVectorizer.from_glove(paths["glove"])
        base = config or EvaluatorConfig.for_skeleton(dataset)
        cfg = replace(base, vocab=tuple(vectorizer.words), dim_word=vectorizer.dim)
        model = cls(cfg, vectorizer)
        try:
            ckpt = torch.load(paths["weights"], map_location="cpu", weights_only=True)
        except Exception as exc:
            raise CheckpointError(f"cannot read {paths['weights']} as a weights-only torch file: {exc}") from exc
        if not isinstance(ckpt, dict):
            raise CheckpointError(f"{paths['weights']} holds a {type(ckpt).__name__}, expected a dict")
        for key in ("movement_encoder", "text_encoder", "motion_encoder"):
            if key not in ckpt:
                raise CheckpointError(f"{paths['weights']} lacks the key {key!r} (has {sorted(ckpt)})")
            load_state_into(getattr(model, key), ckpt[key], source=f"{paths['weights']}[{key!r}]")
        from salad_core import limits

        mean = limits.read_npy(paths["mean"], error=CheckpointError)
        std = limits.read_npy(paths["std"], error=CheckpointError)
        for name, arr in (("mean", mean), ("std", std)):
            if arr.shape != (cfg.dim_pose,):
                raise CheckpointError(f"{paths[name]} has shape {arr.shape}, expected ({cfg.dim_pose},)")
        limits.check_stats(mean, std, f"{paths['mean']} and std.npy", CheckpointError)
        with torch.no_grad():
            model.mean.copy_(torch.from_numpy(mean.astype(np.float32)))
            model.std.copy_(torch.from_numpy(std.astype(np.float32)))
        logger.info("loaded the official %s evaluator (epoch %s) from %s", dataset, ckpt.get("epoch"),
                    paths["weights"])
        return model.eval()


def official_paths(checkpoints_dir: str | PathLike, dataset: str = "humanml3d",
                   glove_dir: str | PathLike | None = None,
                   meta_dir: str | PathLike | None = None) -> dict[str, Path]:
    """Resolve the official evaluator files: keys ``weights``, ``mean``, ``std``, ``glove``.

    Raises ``FileNotFoundError`` naming every place searched.
    """
    name = get_skeleton(dataset).name
    if name not in _OFFICIAL_DATASET_DIR:
        raise ValueError(f"no official evaluator for skeleton {name!r}; known: {sorted(_OFFICIAL_DATASET_DIR)}")
    root = Path(checkpoints_dir)
    ds = root / _OFFICIAL_DATASET_DIR[name]
    weights = ds / "text_mot_match" / "model" / "finest.tar"
    if not weights.is_file():
        raise FileNotFoundError(f"official evaluator weights not found: {weights}")
    if meta_dir is None:
        tried = [ds / d / "meta" for d in _OFFICIAL_META_DIRS]
        found = [d for d in tried if (d / "mean.npy").is_file() and (d / "std.npy").is_file()]
        if not found:
            raise FileNotFoundError("evaluator mean.npy/std.npy not found in any of "
                                    + ", ".join(map(str, tried)) + "; pass meta_dir")
        meta = found[0]
    else:
        meta = Path(meta_dir)
        for f in ("mean.npy", "std.npy"):
            if not (meta / f).is_file():
                raise FileNotFoundError(f"evaluator statistics not found: {meta / f}")
    if glove_dir is None:
        tried = [root.parent / "glove", root / "glove"]
        found = [d for d in tried if (d / "our_vab_data.npy").is_file()]
        if not found:
            raise FileNotFoundError("GloVe folder (our_vab_data.npy) not found in any of "
                                    + ", ".join(map(str, tried)) + "; pass glove_dir")
        glove = found[0]
    else:
        glove = Path(glove_dir)
    return {"weights": weights, "mean": meta / "mean.npy", "std": meta / "std.npy", "glove": glove}


# ------------------------------------------------------------------ checkpoints (ours)
def save_evaluator(stem: str | PathLike, evaluator: T2MEvaluator, meta: dict | None = None, **kwargs) -> Path:
    """Write ``<stem>.safetensors`` + ``<stem>.json`` (model type ``"t2m_evaluator"``); ``kwargs``
    go to :func:`salad_core.io.save_checkpoint` (e.g. ``dtype``, ``overwrite``)."""
    return save_checkpoint(stem, evaluator, model_type=MODEL_TYPE, config=evaluator.config, meta=meta, **kwargs)


def load_evaluator(stem_or_path: str | PathLike) -> tuple[T2MEvaluator, dict]:
    """Rebuild an evaluator from our checkpoint; returns ``(evaluator in eval mode, meta)``."""
    from salad_core.io import build_model

    doc, state = read_checkpoint(stem_or_path)       # the checks of salad_core.io.load_model
    from salad_core.io import checkpoint_files

    model, _ = build_model(doc, state, str(stem_or_path), MODEL_TYPE, str(checkpoint_files(stem_or_path)[0]))
    return model, doc.get("meta", {})


register_model(MODEL_TYPE, EvaluatorConfig, T2MEvaluator)


# ------------------------------------------------------------------ training objective
class MatchingLoss(NamedTuple):
    """Contrastive matching loss and its two parts (scalars)."""

    total: torch.Tensor     # positive + negative
    positive: torch.Tensor  # mean squared distance of matched pairs
    negative: torch.Tensor  # mean squared hinge max(0, margin - d) of shifted pairs


def matching_loss(text_emb: torch.Tensor, motion_emb: torch.Tensor, margin: float = 10.0,
                  shift: int | None = None, generator: torch.Generator | None = None) -> MatchingLoss:
    """The T2M evaluator's contrastive loss (Guo et al. 2022; ``humanml3d_eval_facts`` §4.2).

    Matched pairs are pulled together (``d^2``); mismatched pairs, made by cyclically shifting the
    motion embeddings within the batch (text ``i`` with motion ``(i + shift) % B``), are pushed
    beyond ``margin`` (``max(0, margin - d)^2``). Both terms are batch means.

    Parameters
    ----------
    text_emb, motion_emb : ``(B, C)``, row ``i`` matched, ``B >= 2``
    margin : float
        10 in T2M.
    shift : int, optional
        Shift in ``[1, B-1]``; default: uniform in that range (from ``generator``). T2M draws from
        ``[0, B-2]``, where 0 pairs every text with its own motion as a "negative"; we exclude 0.
    generator : torch.Generator, optional
    """
    if text_emb.ndim != 2 or text_emb.shape != motion_emb.shape:
        raise ValueError(f"text_emb {tuple(text_emb.shape)} and motion_emb {tuple(motion_emb.shape)} must "
                         f"both be (B, C)")
    b = text_emb.shape[0]
    if b < 2:
        raise ValueError(f"matching_loss needs a batch of at least 2 pairs for negatives, got {b}")
    if shift is None:
        shift = int(torch.randint(1, b, (1,), generator=generator))
    if not isinstance(shift, int) or not 1 <= shift <= b - 1:
        raise ValueError(f"shift must be an int in [1, B-1={b - 1}], got {shift!r}")
    # F.pairwise_distance as in T2M's ContrastiveLoss (it adds eps=1e-6 to the difference)
    d_pos = F.pairwise_distance(text_emb, motion_emb)
    d_neg = F.pairwise_distance(text_emb, torch.roll(motion_emb, -shift, dims=0))
    pos = d_pos.pow(2).mean()
    neg = torch.clamp(margin - d_neg, min=0.0).pow(2).mean()
    return MatchingLoss(pos + neg, pos, neg)
