"""Arm carriage: how a performer holds an arm that no action drives (hand in a pocket, on the
hip, on the belly or chest, behind the back, carrying something, loosely in front).

Generator 2.0 let every free arm hang at the persona's rest pose, so the two arms of the corpus
moved together far more than real performers' do (the pose PCA needed 8 components for 90 % of
the variance, the real data 12 or more). Here each arm of a clip draws its own carriage, so left
and right arm poses vary independently across the corpus.

Wrist targets are in the chest frame measured from the shoulder (x outwards for either arm, y
up, z forward; metres), as in :mod:`.poses`; a negative x crosses towards the midline.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kinematics import BodyModel, Pose, arm_angles_for_target

__all__ = ["Carriage", "CARRIAGES", "FREE_ARM_KINDS", "sample_carriages", "apply_carriage"]


@dataclass(frozen=True)
class Carriage:
    """One way to hold a free arm: a box of wrist targets and an elbow pole."""

    name: str
    low: tuple[float, float, float]     # lower corner of the wrist target box (m, chest frame)
    high: tuple[float, float, float]    # upper corner
    pole: tuple[float, float, float]    # elbow pole (chest frame, x outwards)

    def __post_init__(self) -> None:
        if any(lo > hi for lo, hi in zip(self.low, self.high)):
            raise ValueError(f"Carriage {self.name!r}: low {self.low} must not exceed high {self.high}")
        if np.linalg.norm(self.pole) < 1e-6:
            raise ValueError(f"Carriage {self.name!r}: pole {self.pole} must not be zero")


#: The carriages an arm may take (the elbows point back or out, never forwards).
CARRIAGES: tuple[Carriage, ...] = (
    Carriage("pocket", (-0.02, -0.47, 0.03), (0.03, -0.42, 0.09), (1.0, 0.0, -0.8)),
    Carriage("hip", (-0.06, -0.42, -0.03), (-0.02, -0.37, 0.02), (1.0, 0.0, -0.6)),
    Carriage("belly", (-0.2, -0.36, 0.14), (-0.14, -0.3, 0.2), (1.0, -0.4, -0.3)),
    Carriage("chest", (-0.18, -0.17, 0.15), (-0.12, -0.1, 0.19), (1.0, -0.6, -0.2)),
    Carriage("behind", (-0.16, -0.43, -0.15), (-0.1, -0.37, -0.1), (0.8, 0.0, -1.0)),
    Carriage("carry", (-0.02, -0.31, 0.26), (0.06, -0.22, 0.34), (0.3, -0.2, -1.0)),
    Carriage("front", (-0.09, -0.5, 0.12), (-0.04, -0.44, 0.18), (0.5, 0.0, -1.0)),
)

#: Base actions during which a free arm may keep a carriage (they leave the arms to the
#: performer: walking with a hand in a pocket is common, jumping with one is not). Gesture
#: steps (the performer stands) also do.
FREE_ARM_KINDS = frozenset({"walk", "walk_backward", "sidestep", "circle", "turn", "pivot", "step_over",
                            "step_up", "climb_stairs", "descend_stairs", "shuffle"})

#: Chance that an arm of a clip that allows it takes a carriage, and that the second arm copies
#: the first's (both hands in the pockets, behind the back, ...).
CARRY_P, SAME_P = 0.6, 0.3


def sample_carriages(rng: np.random.Generator) -> list[tuple[Carriage, np.ndarray] | None]:
    """Per arm (left, right): ``(carriage, wrist target (3,))`` or None (the arm hangs)."""
    out: list[tuple[Carriage, np.ndarray] | None] = []
    for k in range(2):
        if k == 1 and out[0] is not None and rng.random() < SAME_P:
            c = out[0][0]
        elif rng.random() < CARRY_P:
            c = CARRIAGES[int(rng.integers(len(CARRIAGES)))]
        else:
            out.append(None)
            continue
        out.append((c, rng.uniform(c.low, c.high)))
    return out


def apply_carriage(pose: Pose, body: BodyModel, carriages: list[tuple[Carriage, np.ndarray] | None],
                   weight: np.ndarray | None = None) -> None:
    """Hold each carried arm of ``pose`` at its carriage (in place).

    ``weight`` ``(N,)`` in [0, 1] (default 1) blends the carriage over the arm controls already
    there; gestures laid on afterwards take the arm from it.
    """
    n = pose.num_frames
    w = np.ones(n) if weight is None else np.asarray(weight, dtype=np.float64)
    if w.shape != (n,):
        raise ValueError(f"weight must have shape ({n},), got {w.shape}")
    for k, ck in enumerate(carriages):
        if ck is None:
            continue
        c, target = ck
        angles = arm_angles_for_target(target, body.upper_arm[k], body.forearm[k])
        pose.arm[:, k] += w[:, None] * (angles[None] - pose.arm[:, k])
        pole = pose.arm_pole[:, k] + w[:, None] * (np.asarray(c.pole)[None] - pose.arm_pole[:, k])
        pose.arm_pole[:, k] = pole / np.maximum(np.linalg.norm(pole, axis=-1, keepdims=True), 1e-9)
