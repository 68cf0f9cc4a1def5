"""Edits that stay human: an edit of a take does not lift the pelvis above the source's height range.

A re-weight test saw ``Reweight("turns", -1)`` of an inverted walk-and-turn lift the pelvis from 0.98 to 1.45 m and keep it
above 1.25 m for 1.1 s, the lower foot 0.55 m off the floor: a figure floating, not a person turning less. The
denoiser has no notion of the floor; the edited branch's root token simply leaves the region the take's own
latents occupy. What is done here is a projection of the edited branch's output, not a guidance of its sampling:

* the ceiling of a motion is the source's highest pelvis plus ``margin`` (10 cm), but not above the corpus's range
  (``mean + 3 std`` of the pipeline's pelvis-height statistics, 1.39 m with the shipped weights) unless the source
  itself is; a target prompt that asks the body to leave the floor (:func:`asks_to_leave_floor`: jump, hop, leap,
  flip, climb, stairs ...) has no ceiling;
* frames whose pelvis (the recovered joints', what the user sees) is above the ceiling have the whole body
  lowered by the excess (:func:`lower_body`: the root height, every joint's height and the vertical joint
  velocities of the features), which keeps the pose and the horizontal motion exactly and puts the pelvis at the
  ceiling; the joints are recovered again with the pipeline's recovery (repeated while the recovery leaves some
  excess) and the latents re-encoded from the lowered features.

A projection and not a latent guidance because it is exact (the ceiling holds by construction, it touches only the
frames above it and nothing else of the edit) and costs one decode; a guidance toward the source's pelvis would
need the VAE decoder's gradient at every step and still only approach the range.

:func:`ground_edit` applies it to an :class:`~salad_core.pipeline.EditOutput`; ``pipe.edit(inversion=...)`` is meant
to apply it by default (off switch ``ground=False``).
"""
from __future__ import annotations

import dataclasses
import re
from typing import Sequence

import numpy as np

from salad_core.skeleton import get_skeleton

__all__ = ["GROUND_MARGIN", "LIFT_WORDS", "asks_to_leave_floor", "corpus_pelvis_max", "pelvis_ceiling",
           "lower_body", "ground_features", "ground_edit"]

#: How far (metres) an edit's pelvis may rise above the source's highest pelvis.
GROUND_MARGIN: float = 0.10
#: Word stems of prompts that ask the body to leave the floor or go up (no ceiling then).
LIFT_WORDS: tuple[str, ...] = ("jump", "hop", "leap", "bounc", "flip", "backflip", "somersault", "vault", "climb", "stair",
                               "ladder", "cartwheel", "skip", "ascend", "steps up", "step up")


def asks_to_leave_floor(prompt: str) -> bool:
    """Whether ``prompt`` asks the body to leave the floor or go up (a word starting with one of
    :data:`LIFT_WORDS`)."""
    text = " ".join(re.findall(r"[a-z]+", str(prompt).lower()))
    return any(re.search(r"\b" + re.escape(stem), text) for stem in LIFT_WORDS)


def corpus_pelvis_max(mean: np.ndarray, std: np.ndarray, skeleton="humanml3d", k: float = 3.0) -> float:
    """The corpus's pelvis-height range top, ``mean + k std`` of the root-height feature channel."""
    sl = get_skeleton(skeleton).feature_slices["root_y"]
    return float(np.asarray(mean)[sl][0] + k * np.asarray(std)[sl][0])


def pelvis_ceiling(source_heights: np.ndarray, *, margin: float = GROUND_MARGIN,
                   corpus_max: float | None = None) -> float:
    """``min(source max + margin, max(corpus_max, source max))``: at most ``margin`` above the source's range, and
    not above the corpus's unless the source is."""
    top = float(np.max(source_heights))
    ceiling = top + float(margin)
    if corpus_max is not None:
        ceiling = min(ceiling, max(float(corpus_max), top))
    return ceiling


def lower_body(features: np.ndarray, drop: np.ndarray, skeleton="humanml3d") -> np.ndarray:
    """Features ``(N, D)`` with the whole body lowered by ``drop`` ``(N,)`` metres per frame (a new array): the root
    height and every joint's height (``ric``) minus ``drop``, the vertical joint velocities minus its change."""
    sk = get_skeleton(skeleton)
    f = np.array(features, dtype=np.float64, copy=True)
    d = np.asarray(drop, np.float64)
    if d.shape != (len(f),):
        raise ValueError(f"drop must have one value per frame ({len(f)}), got shape {d.shape}")
    f[:, sk.feature_slices["root_y"]] -= d[:, None]
    ric = sk.feature_slices["ric"]
    f[:, ric.start + 1:ric.stop:3] -= d[:, None]
    vel = sk.feature_slices["local_vel"]
    if len(f) > 1:
        f[:-1, vel.start + 1:vel.stop:3] -= (d[1:] - d[:-1])[:, None]
    return f.astype(np.asarray(features).dtype, copy=False)


def ground_features(features: np.ndarray, ceiling: float, skeleton="humanml3d") -> tuple[np.ndarray, np.ndarray]:
    """Lower the frames whose pelvis is above ``ceiling`` by the excess: ``(features, drop per frame)``."""
    sk = get_skeleton(skeleton)
    heights = np.asarray(features, np.float64)[:, sk.feature_slices["root_y"]][:, 0]
    drop = np.maximum(heights - float(ceiling), 0.0)
    if not drop.any():
        return np.asarray(features).copy(), drop
    return lower_body(features, drop, sk), drop


def ground_edit(pipe, output, *, margin: float = GROUND_MARGIN, corpus_k: float = 3.0,
                lift_words: bool = True, reencode: bool = True, iterations: int = 3):
    """The edit with each edited motion's pelvis kept within ``margin`` of its source's height range
    (:func:`pelvis_ceiling`); an :class:`~salad_core.pipeline.EditOutput` (a copy; ``output`` is not changed).

    Heights are those of the joints the user sees (the pipeline's recovery, ``out.joints``): the source's highest
    pelvis sets the ceiling, and the edited motion is lowered (:func:`lower_body`) by its recovered pelvis's excess,
    again up to ``iterations`` times while the recovery (which fits bones and keeps the feet above the floor) leaves
    some above. ``lift_words``: a target prompt that asks to leave the floor (:func:`asks_to_leave_floor`) is left
    alone. ``reencode``: the edited latents of a lowered motion are re-encoded from its lowered features (else kept).
    ``settings["grounding"]`` records per motion the ceiling, the largest drop (m) and the frames lowered.
    """
    import torch

    from salad_core.recovery import recover_joints

    sk = pipe.skeleton
    corpus_max = corpus_pelvis_max(pipe.mean, pipe.std, sk, corpus_k)
    src, ed = output.source, output.edited
    feats = np.array(ed.features, copy=True)
    joints = list(ed.joints)
    latents = ed.latents.clone() if isinstance(ed.latents, torch.Tensor) else ed.latents
    record = []
    unit = sk.unit_length
    for b, n in enumerate(ed.lengths):
        prompt = ed.texts[b]
        if lift_words and asks_to_leave_floor(prompt):
            record.append({"prompt": prompt, "ceiling": None, "max_drop": 0.0, "frames": 0, "reason": "lift words"})
            continue
        ceiling = pelvis_ceiling(np.asarray(src.joints[b])[:, 0, 1], margin=margin, corpus_max=corpus_max)
        f, j = feats[b, :n], np.asarray(joints[b])
        total = np.zeros(n)
        for _ in range(max(int(iterations), 1)):
            excess = np.maximum(j[:n, 0, 1].astype(np.float64) - ceiling, 0.0)
            if excess.max(initial=0.0) <= 1e-4:
                break
            f = lower_body(f, excess, sk)
            total += excess
            j = recover_joints(f, pipe.recovery, sk).astype(np.float32)
        record.append({"prompt": prompt, "ceiling": ceiling, "max_drop": float(total.max(initial=0.0)),
                       "frames": int((total > 0).sum())})
        if not total.any():
            continue
        feats[b, :n], joints[b] = f, j
        if reencode and isinstance(latents, torch.Tensor):
            latents[b, : n // unit] = pipe.encode_motion(np.asarray(f, np.float32))[0].to(latents)
    settings = dict(ed.settings)
    settings["grounding"] = {"margin": float(margin), "corpus_max": corpus_max, "motions": record}
    grounded = dataclasses.replace(ed, features=feats, joints=joints, latents=latents, settings=settings)
    out_settings = dict(output.settings)
    out_settings["grounding"] = settings["grounding"]
    return dataclasses.replace(output, edited=grounded, settings=out_settings)


def pelvis_excess(source_heights: Sequence[float], edited_heights: Sequence[float]) -> float:
    """How far (metres) the edited pelvis rises above the source's highest (0 when it does not)."""
    return max(0.0, float(np.max(edited_heights)) - float(np.max(source_heights)))
