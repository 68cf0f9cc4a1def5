"""What the attention measurement scripts share (``measure_editing.py``, ``measure_new_edits.py``,
``measure_real_edits.py``): the procedural corpus's annotated clips, the mirror edits they measure, a mean
that skips missing values, the summary tables they print and the start and end of a run (torch threads,
settings, total time, JSON).

The scripts import it as a sibling module (``python scripts/NAME.py`` puts ``scripts/`` first on
``sys.path``); it is not part of the ``salad_core`` package.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

#: Motion frames per latent frame (HumanML3D): clips are cut to a multiple of it.
UNIT_LENGTH = 4


def annotated_clips(root: Path, split: str, *, max_frames: int, min_frames: int,
                    mirrors: bool = True) -> Iterator[tuple[str, dict, np.ndarray]]:
    """The annotated clips of a procedural corpus split, in the split file's order.

    Parameters
    ----------
    root : Path
        A folder written by :func:`salad_core.data.procedural.build_corpus` (HumanML3D layout with
        ``annotations/``).
    split : str
        Split name (``root/{split}.txt`` lists the clip ids).
    max_frames, min_frames : int
        Each clip's features are cut to a multiple of :data:`UNIT_LENGTH` frames and to at most
        ``max_frames``; a clip left with fewer than ``min_frames`` is skipped.
    mirrors : bool
        Include the mirrored clips (ids ``M...``).

    Yields
    ------
    (id, annotation, features)
        The clip id, its ``annotations/{id}.json`` document and its features ``(N, D)`` float32.

    Raises
    ------
    SystemExit
        When the split holds no annotated clip long enough (not a procedural corpus?).
    """
    ids = [i for i in (root / f"{split}.txt").read_text().split() if i and (mirrors or not i.startswith("M"))]
    found = False
    for cid in ids:
        ann = root / "annotations" / f"{cid}.json"
        if not ann.is_file():
            continue
        doc = json.loads(ann.read_text())
        feats = np.load(root / "new_joint_vecs" / f"{cid}.npy").astype(np.float32)
        n_frames = min(len(feats) - len(feats) % UNIT_LENGTH, max_frames)
        if n_frames < min_frames:
            continue
        found = True
        yield cid, doc, feats[:n_frames]
    if not found:
        raise SystemExit(f"no annotated clips in {root}/{split}.txt; is {root} a procedural corpus?")


def deepmimic_items(skeleton, max_clips: int) -> list[dict]:
    """pybullet's DeepMimic takes as inversion inputs: ``{"id", "features" (N, D) float32, "prompt"}``.

    A loop shorter than ``skeleton.min_length`` is repeated past it; every take is cut to a multiple of
    :data:`UNIT_LENGTH` frames and at most ``skeleton.max_length``; takes left with fewer than two latent
    frames are dropped (the kick, 31 frames and no loop, stays: inversion takes it). Needs pybullet
    (``salad_core.data.deepmimic.pybullet_available``).
    """
    from salad_core.data import deepmimic

    items = []
    for name in deepmimic.available_clips()[:max_clips]:
        probe = deepmimic.load_clip(name)
        cycles = 1
        if probe.loop and probe.num_frames - 1 < skeleton.min_length:
            cycles = int(math.ceil(skeleton.min_length / max(probe.num_frames - 1, 1))) + 1
        clip = deepmimic.load_clip(name, cycles=cycles) if cycles > 1 else probe
        feats = clip.features()
        n = min(len(feats) - len(feats) % UNIT_LENGTH, skeleton.max_length)
        if n < 2 * UNIT_LENGTH:
            continue
        items.append({"id": name, "features": np.asarray(feats[:n], np.float32), "prompt": clip.prompt})
    return items


def mean(xs: Iterable) -> float:
    """The mean of the finite values of ``xs`` (None and NaN skipped); NaN when none is left."""
    kept = [float(x) for x in xs if x is not None and math.isfinite(float(x))]
    return float(np.mean(kept)) if kept else float("nan")


def print_summary(title: str, summary: dict, *, width: int, nested_digits: int) -> None:
    """Print ``== title`` and one line per entry of ``summary``: a number with 4 significant digits,
    a dict (one setting's figures) as ``key=value`` pairs with ``nested_digits``, anything else as
    it is; keys padded to ``width`` characters."""
    print(f"\n== {title}")
    for key, value in summary.items():
        if isinstance(value, dict):
            print(f"  {key:{width}s} " + "  ".join(f"{k}={v:.{nested_digits}g}" for k, v in value.items()))
        else:
            print(f"  {key:{width}s} {value:.4g}" if isinstance(value, float) else f"  {key:{width}s} {value}")


def start_run(threads: int | None) -> float:
    """Set torch's thread count when ``threads`` is given; the run's start (``time.perf_counter``)."""
    if threads:
        import torch

        torch.set_num_threads(threads)
    return time.perf_counter()


def run_settings(args, skip: tuple[str, ...] = ()) -> dict:
    """The parsed arguments as JSON-ready settings (paths as strings), without the names in ``skip``."""
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k not in skip}


def finish_run(results: dict, start: float, json_path: Path | None) -> dict:
    """Record and print the run's total seconds; write ``results`` to ``json_path`` when given."""
    results["seconds"] = time.perf_counter() - start
    print(f"\ntotal {results['seconds']:.1f} s")
    if json_path:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps(results, indent=2, default=float) + "\n")
        print(f"wrote {json_path}")
    return results


def mirror_edits(parts: str, self_attention: tuple[str, ...] = (), window: tuple[float, float] = (0.0, 1.0)) -> list:
    """``Mirror(parts)``, plus ``MirrorSelfAttention`` of the same parts over ``window`` when
    ``self_attention`` names kinds (temporal, skeletal)."""
    from salad_core.attention import Mirror, MirrorSelfAttention

    edits = [Mirror(parts)]
    if self_attention:
        edits.append(MirrorSelfAttention(parts, steps=tuple(window), kinds=tuple(self_attention)))
    return edits
