"""Write a general-motion set (uncaptioned, for VAE training) in the HumanML3D layout.

Layout written by :func:`build_general` (``<id>`` = ``G`` + 6 digits)::

    new_joint_vecs/<id>.npy   (N-1, 263) float32   joints_to_features of the generated joints
    new_joints/<id>.npy       (N-1, 22, 3) float32 features_to_joints of those features
    train.txt val.txt test.txt all.txt   splits 0.80 / 0.05 / 0.15
    Mean.npy Std.npy          statistics of this set's training split (for comparison; a mixture
                              normally uses the corpus's, see salad_core.data.general_dataset)
    general.json              generator, seed, size, modes, frame counts, round-trip error

There are no ``texts/``: the set only trains the VAE. Every motion comes from its own random
stream ``(seed, index)`` (:func:`~.general.generate_general`), so the files do not depend on the
number of workers and two builds with the same seed are byte-identical.
"""
from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

import numpy as np

from ...motion import compute_mean_std, features_to_joints, joints_to_features, process_joints
from ...skeleton import get_skeleton
from .corpus import npy_bytes, split_indices
from .general import GeneralConfig, generate_general
from .parallel import run_jobs

__all__ = ["build_general", "make_general_motion", "GENERAL_VERSION"]

#: Bump when the generator's output changes.
GENERAL_VERSION = "1.1"
_FILES = ("train.txt", "val.txt", "test.txt", "all.txt", "Mean.npy", "Std.npy", "general.json")


def make_general_motion(seed: int, index: int, config: GeneralConfig | None = None) -> dict:
    """Files of motion ``index``: ``{"name", "new_joint_vecs": bytes, "new_joints": bytes, "meta"}``.

    ``meta`` holds the mode, the frame count and the round-trip error (m): the largest joint
    distance between ``features_to_joints(joints_to_features(j))`` and the processed joints.
    """
    clip = generate_general(seed, index, config)
    feats = joints_to_features(clip.joints)
    rec = features_to_joints(feats).astype(np.float32)
    ref = process_joints(clip.joints)[:-1]
    err = float(np.linalg.norm(rec.astype(np.float64) - ref, axis=-1).max())
    return {"name": f"G{index:06d}", "new_joint_vecs": npy_bytes(feats), "new_joints": npy_bytes(rec),
            "meta": {"mode": clip.mode, "frames": int(feats.shape[0]), "roundtrip": err}}


def _job(args: tuple[int, int, str, GeneralConfig | None]) -> dict:
    seed, index, root, config = args
    m = make_general_motion(seed, index, config)
    root_p = Path(root)
    (root_p / "new_joint_vecs" / f"{m['name']}.npy").write_bytes(m["new_joint_vecs"])
    (root_p / "new_joints" / f"{m['name']}.npy").write_bytes(m["new_joints"])
    return m["meta"]


def _split_ids(n: int, seed: int) -> dict[str, list[str]]:
    # the corpus's split fractions, drawn independently of a corpus of the same seed
    return {name: [f"G{i:06d}" for i in ids] for name, ids in split_indices(n, seed, salt=104729).items()}


def build_general(out_dir: str | os.PathLike, n: int = 4000, seed: int = 0, workers: int | None = None,
                  overwrite: bool = False, progress: bool = True, config: GeneralConfig | None = None) -> dict:
    """Generate ``n`` general motions into ``out_dir`` (HumanML3D layout without texts).

    Parameters
    ----------
    out_dir : path
        Folder to write; must be empty or absent unless ``overwrite``.
    n : int
        Motions (>= 20, for the splits).
    seed : int
        Same seed, same files (byte for byte), whatever ``workers``.
    workers : int, optional
        Processes (default: 1 up to 200 motions, else up to 2 CPUs).
    overwrite : bool
        Replace a set already in ``out_dir``.
    progress : bool
        Show a progress bar.
    config : GeneralConfig, optional

    Returns
    -------
    dict: the summary also written to ``general.json``.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 20:
        raise ValueError(f"n={n!r} must be an int >= 20 (the splits need it)")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r} must be a non-negative int")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"out_dir {out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"out_dir {out} is not empty; pass overwrite=True (--force) to replace it")
        for d in ("new_joint_vecs", "new_joints"):
            for f in (out / d).glob("G*.npy"):
                f.unlink()
        for f in _FILES:
            (out / f).unlink(missing_ok=True)
    for d in ("new_joint_vecs", "new_joints"):
        (out / d).mkdir(parents=True, exist_ok=True)
    if workers is None:
        workers = 1 if n <= 200 else max(1, min(2, os.cpu_count() or 1))
    jobs = [(int(seed), i, str(out), config) for i in range(int(n))]
    metas: list[dict] = run_jobs(_job, jobs, workers, desc="general motion", chunksize=16, progress=progress)

    splits = _split_ids(int(n), int(seed))
    for name, ids in splits.items():
        (out / f"{name}.txt").write_text("\n".join(ids) + "\n", encoding="utf-8")
    (out / "all.txt").write_text("\n".join(sorted(i for v in splits.values() for i in v)) + "\n", encoding="utf-8")
    mean, std = compute_mean_std((np.load(out / "new_joint_vecs" / f"{i}.npy") for i in splits["train"]),
                                 get_skeleton("humanml3d"))
    np.save(out / "Mean.npy", mean)
    np.save(out / "Std.npy", std)
    frames = np.array([m["frames"] for m in metas])
    rt = np.array([m["roundtrip"] for m in metas])
    modes = Counter(m["mode"] for m in metas)
    summary = {
        "generator": "salad_core.data.procedural.general",
        "version": GENERAL_VERSION,
        "seed": int(seed),
        "motions": int(n),
        "splits": {k: len(v) for k, v in splits.items()},
        "modes": dict(sorted(modes.items())),
        "frames": {"total": int(frames.sum()), "mean": round(float(frames.mean()), 2), "min": int(frames.min()),
                   "max": int(frames.max())},
        "roundtrip_m": {"median": float(np.median(rt)), "p95": float(np.percentile(rt, 95)),
                        "max": float(rt.max()), "share_above_1cm": float((rt > 0.01).mean())},
    }
    (out / "general.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary
