"""A base segment (one leg/root action from standing to standing) and the neutral standing pose.

Every base action of the corpus starts and ends in a relaxed stand (or, for sitting, ends
seated), so segments can be chained in any order: the next one starts where the feet are.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .curves import envelope, frame_times
from .footwork import Persona, Plant, Stance, max_pelvis_height, plant_pose, standing_height
from .kinematics import FPS, BodyModel, Pose, heading_vectors, ypr_matrix

__all__ = ["Segment", "standing_pose", "knee_poles", "num_frames"]


def num_frames(duration: float) -> int:
    """Frames covering ``duration`` seconds at the corpus frame rate (at least 2)."""
    return max(2, int(round(duration * FPS)) + 1)


@dataclass
class Segment:
    """A stretch of motion produced by one base action (or by standing still)."""

    pose: Pose                              # the controls, N frames
    end: Stance | None                      # where the feet are at the last frame (None: seated)
    core: tuple[int, int]                   # frames [f0, f1) of the action itself
    arms_free: bool = True                  # may an arm gesture be layered on top?
    seated: bool = False                    # ends seated (nothing standing can follow)
    info: dict = field(default_factory=dict)  # measured facts (speed, jump height, ...)
    #: hands held at world points: ``(weights (N, 2) in [0, 1], wrist targets (N, 2, 3) world)``
    #: per arm (left, right), or None. The composer re-solves these arms after it has laid the
    #: performer's posture and wander on the trunk, so a hand on the floor stays on it.
    hands: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def num_frames(self) -> int:
        return self.pose.num_frames


def knee_poles(foot_yaw: np.ndarray, out: float = 0.15) -> np.ndarray:
    """``(N, 2, 3)`` knee pole directions: along each foot, slightly outwards."""
    poles = []
    for k, sign in enumerate((1.0, -1.0)):
        fwd, left = heading_vectors(foot_yaw[:, k])
        poles.append(fwd + left * (sign * out))
    return np.stack(poles, 1)


def standing_pose(stance: Stance, persona: Persona, n: int, body: BodyModel,
                  rng: np.random.Generator | None = None, idle: bool = True) -> Pose:
    """A relaxed stand over ``stance`` for ``n`` frames, with a faint sway and breathing.

    The idle motion fades in and out so that the first and last frames are the exact neutral
    pose every segment starts and ends with.
    """
    t = frame_times(n, FPS)
    h = standing_height(stance, body, pitch=0.03)
    ground = stance.ground
    fwd, left = heading_vectors(stance.yaw)
    pelvis = np.tile(ground + np.array([0.0, h, 0.0]), (n, 1))
    ypr = np.tile(np.array([stance.yaw, 0.03, 0.0]), (n, 1))
    spine = np.tile(np.array([0.0, 0.03, 0.0]), (n, 1))
    neck = np.tile(np.array([0.0, persona.head_pitch, 0.0]), (n, 1))
    arm = np.tile(np.asarray(persona.arm_rest, dtype=np.float64), (n, 2, 1))
    pole = np.tile(np.asarray(persona.arm_pole, dtype=np.float64), (n, 2, 1))
    if idle and rng is not None and n > 8:
        # weight shifts from foot to foot (a slow and a slower wave), breathing, a wandering gaze
        w = envelope(t, 0.0, t[-1], min(0.4, t[-1] / 3))
        f_sway, f_breath = rng.uniform(0.15, 0.35), rng.uniform(0.2, 0.3)
        ph = rng.uniform(0, 2 * np.pi, size=5)
        shift = np.sin(2 * np.pi * f_sway * t + ph[0]) + 0.5 * np.sin(2 * np.pi * 0.45 * f_sway * t + ph[3])
        sway = persona.sway * shift * w
        pelvis += left[None] * sway[:, None] + fwd[None] * (0.3 * persona.sway * np.sin(2 * np.pi * 0.7 * f_sway * t + ph[4]) * w)[:, None]
        ypr[:, 2] += -1.5 * sway                                   # the hips drop on the unloaded side
        breath = 0.015 * np.sin(2 * np.pi * f_breath * t + ph[1]) * w
        spine[:, 1] += breath
        spine[:, 2] += 0.8 * sway                                  # the trunk stays over the feet
        neck[:, 1] -= 0.6 * breath
        neck[:, 0] += 0.12 * np.sin(2 * np.pi * 0.6 * f_sway * t + ph[2]) * w
        arm[:, :, 0] += (0.012 * np.sin(2 * np.pi * f_breath * t + ph[2]) * w)[:, None]
    ankle = np.zeros((n, 2, 3))
    toe = np.zeros((n, 2, 3))
    for k in range(2):
        p = Plant(-np.inf, np.inf, stance.ankles[k], float(stance.foot_yaw[k]))
        ankle[:, k], toe[:, k] = plant_pose(p, t, body, k)
    poles = knee_poles(np.tile(stance.foot_yaw, (n, 1)))
    if idle and rng is not None and n > 8:
        bound = max_pelvis_height(pelvis, ypr_matrix(ypr), ankle, body) - 0.004
        pelvis[:, 1] = np.minimum(pelvis[:, 1], bound)
    return Pose(pelvis, ypr, spine, neck, ankle, toe, poles, arm, pole)
