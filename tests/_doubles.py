"""Test doubles shared by several test modules: a hashing text encoder, a fake corpus folder, a tiny
random evaluator and a recording stand-in python for the
resumable shell scripts."""
from __future__ import annotations

import os
import subprocess
import zlib
from pathlib import Path

import numpy as np
import torch

from salad_core.data.texts import split_words
from salad_core.skeleton import get_skeleton
from salad_core.text import TextBatch

#: Verbs of the fake corpus's captions (one per clip, cycled).
WORDS = ("walks", "jumps", "runs", "waves", "kicks", "turns")


class HashTextEncoder:
    """Deterministic stand-in text encoder: ``[CLS] words [SEP]``, each token a fixed random
    ``(dim,)`` vector seeded by its crc32. Records every ``encode`` call in ``calls``."""

    name = "hash"
    max_tokens = 32

    def __init__(self, dim: int = 16) -> None:
        self.dim = dim
        self.calls: list[list[str]] = []

    def _vec(self, token: str) -> torch.Tensor:
        return torch.randn(self.dim, generator=torch.Generator().manual_seed(zlib.crc32(token.encode())))

    def encode(self, prompts, allow_empty: bool = False) -> TextBatch:
        self.calls.append(list(prompts))
        words = [split_words(p) for p in prompts]
        toks = [["[CLS]", *w, "[SEP]"] for w in words]
        width = max(len(t) for t in toks)
        feats = torch.zeros(len(prompts), width, self.dim)
        mask = torch.zeros(len(prompts), width, dtype=torch.bool)
        for b, t in enumerate(toks):
            for j, tok in enumerate(t):
                feats[b, j] = self._vec(tok)
            mask[b, : len(t)] = True
        return TextBatch(feats, mask, toks, [[None, *range(len(w)), None] for w in words], words, list(prompts))

    def encode_null(self, n: int = 1) -> TextBatch:
        return self.encode([""] * n, allow_empty=True)


def rest_pose(skeleton: str = "humanml3d") -> np.ndarray:
    """``(J, 3)`` the skeleton's reference offsets standing (legs straight, arms hanging), lowest joint at y = 0,
    facing +Z (left = +X), metres."""
    sk = get_skeleton(skeleton)
    pos = np.zeros((sk.num_joints, 3))
    for j, parent in enumerate(sk.parents):
        if parent >= 0:
            pos[j] = pos[parent] + sk.target_offsets[j]
    pos[:, 1] -= pos[:, 1].min()
    return pos


def make_fake_corpus(root: Path, n_train: int = 8, n_val: int = 3, lengths=(64, 72), seed: int = 0) -> Path:
    """A HumanML3D-layout folder with random smooth features (width from the skeleton), two captions
    per clip, train/val/test splits and Mean/Std."""
    rng = np.random.default_rng(seed)
    d = get_skeleton("humanml3d").feature_dim
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    ids = [f"{i:06d}" for i in range(n_train + n_val)]
    feats = []
    for i, mid in enumerate(ids):
        n = int(rng.integers(*lengths))
        t = np.linspace(0.0, 1.0, n)[:, None]
        x = np.sin(2 * np.pi * (t * rng.uniform(0.5, 2.0, d) + rng.uniform(0.0, 1.0, d)))
        x = (x + 0.1 * rng.standard_normal((n, d))).astype(np.float32)
        np.save(root / "new_joint_vecs" / f"{mid}.npy", x)
        feats.append(x)
        w = WORDS[i % len(WORDS)]
        (root / "texts" / f"{mid}.txt").write_text(
            f"a person {w}#a/DET person/NOUN {w}/VERB#0.0#0.0\n"
            f"someone {w} slowly#someone/PRON {w}/VERB slowly/ADV#0.0#0.0\n")
    (root / "train.txt").write_text("\n".join(ids[:n_train]) + "\n")
    (root / "val.txt").write_text("\n".join(ids[n_train:]) + "\n")
    (root / "test.txt").write_text("\n".join(ids[n_train:]) + "\n")
    cat = np.concatenate(feats)
    np.save(root / "Mean.npy", cat.mean(0).astype(np.float32))
    np.save(root / "Std.npy", (cat.std(0) + 1e-3).astype(np.float32))
    return root


def make_tiny_evaluator(corpus_root, seed: int = 0, **dims):
    """A random (untrained) T2M evaluator of the given ``dims`` with random word vectors over the
    corpus vocabulary and the corpus's Mean/Std; ``source = "tiny-random-evaluator"``."""
    from salad_core.data.dataset import load_mean_std
    from salad_core.eval.t2m import EvaluatorConfig, T2MEvaluator
    from salad_core.eval.vocab import corpus_vocabulary
    from salad_core.eval.word_vectorizer import WordVectorizer

    words = corpus_vocabulary(corpus_root)
    vec = WordVectorizer(words, np.random.default_rng(seed).standard_normal((len(words), dims["dim_word"])))
    torch.manual_seed(seed)
    ev = T2MEvaluator(EvaluatorConfig.for_skeleton("humanml3d", **dims, vocab=tuple(words)), vec)
    mean, std = load_mean_std(corpus_root)
    with torch.no_grad():
        ev.mean.copy_(torch.from_numpy(mean))
        ev.std.copy_(torch.from_numpy(std))
    ev.source = "tiny-random-evaluator"
    return ev.eval()


def recording_python(folder: Path) -> tuple[Path, Path]:
    """``(fake, log)``: an executable stand-in for python in ``folder`` that appends its arguments to
    ``log`` (one line per call) and succeeds, so a shell script's commands can be checked without running."""
    log = folder / "calls.txt"
    fake = folder / "fake_python"
    fake.write_text(f'#!/usr/bin/env bash\necho "$*" >> {log}\n')
    fake.chmod(0o755)
    return fake, log


def run_stage_script(script: Path, out: Path, *stages: str, python: str, timeout: float = 60,
                     **env: str) -> subprocess.CompletedProcess:
    """``bash script OUT STAGE...`` with ``PYTHON=python`` and ``env`` added to the environment."""
    full = {**os.environ, "PYTHON": python, **env}
    return subprocess.run(["bash", str(script), str(out), *stages], capture_output=True, text=True, env=full,
                          timeout=timeout)


def tiny_keymotion(seed: int = 0, **pipeline_kwargs):
    """A seeded KeyMotion pipeline of tiny random models (8 keyframes, 2 x 16 latent, 16-d :class:`HashTextEncoder`,
    default length 40) for tests of the sampling and the command line; ``pipeline_kwargs`` go to
    :class:`~salad_core.keymotion.pipeline.KeyMotionPipeline` (``solver``, ``recovery``, ...)."""
    from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig
    from salad_core.keymotion.mmae import MMAEConfig, MotionMaskedAutoencoder
    from salad_core.keymotion.pipeline import KeyMotionPipeline
    from salad_core.keymotion.pst import ParallelSkipTransformer, PSTConfig

    torch.manual_seed(seed)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, frame_dim=56, index_dim=8, latent_size=2, latent_dim=16,
                                        num_layers=1, num_heads=4, ff_dim=64, dropout=0.0))
    pst = ParallelSkipTransformer(PSTConfig(latent_size=2, latent_dim=16, text_dim=16, width=32, num_heads=4,
                                            ff_dim=64, num_cond_layers=1, num_cross_layers=2, dropout=0.0))
    mmae = MotionMaskedAutoencoder(MMAEConfig(text_dim=16, width=32, num_layers=1, num_heads=4, ff_dim=64,
                                              dropout=0.0))
    return KeyMotionPipeline(vae, pst, mmae, HashTextEncoder(16), default_length=40, **pipeline_kwargs)
