"""Feet on the floor: stances, planted feet with heel/toe roll, swing trajectories, leg reach.

A foot is either *planted* (a :class:`Plant`: its flat position is fixed in the world, so it
cannot slide; it may roll about the ankle (toe up) or about the toe (heel up)) or *in the air*
between two plants (a :class:`Swing` arc, or any custom trajectory). :func:`foot_track`
evaluates a foot's ankle and toe targets over time; the leg IK then reaches for them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Union

import numpy as np

from .curves import min_jerk, smoothstep, wrap_angle
from .kinematics import BodyModel, foot_vector, heading_vectors, ypr_matrix

__all__ = [
    "ANKLE_HEIGHT",
    "TOE_HEIGHT",
    "PELVIS_AHEAD",
    "Persona",
    "trunk_curvature",
    "spine_shares",
    "Stance",
    "Plant",
    "Swing",
    "flat_pitch",
    "plant_pose",
    "foot_track",
    "max_pelvis_height",
    "standing_height",
]

#: Ankle height of a flat foot (HumanML3D stance frames: 0.05-0.06 m).
ANKLE_HEIGHT = 0.058
#: Toe joint height of a flat foot (HumanML3D: about 0.01 m).
TOE_HEIGHT = 0.012
#: The pelvis stands this far ahead of the midpoint of the ankles (m).
PELVIS_AHEAD = 0.03
#: Shortest pivot (s) on the ball of a planted foot.
PIVOT_MIN = 0.12
#: Hip-to-ankle distance of a standing leg, as a fraction of the straight leg (knees soft).
STAND_REACH = 0.975


@dataclass(frozen=True)
class Persona:
    """Per-clip style of the performer: how they stand and hold their arms."""

    width: float            # half distance between the ankles when standing (m)
    toe_out: float          # outward rotation of each foot (rad)
    arm_rest: tuple         # (flex, abd, elbow) of the hanging arms (rad)
    arm_pole: tuple         # elbow pole of the hanging arms (chest frame, x outwards)
    sway: float             # idle sway amplitude of the pelvis (m)
    head_pitch: float       # resting head pitch (rad, + looks down)
    tempo: float            # global speed factor of this performer (1 = average)
    slouch: float = 0.0     # extra spine pitch of the posture (rad, + hunched forward)
    tilt: float = 0.0       # sideways lean of the posture (rad, + towards the left): asymmetry
    liveliness: float = 1.0  # scale of the low-frequency wander on the joint angles (0 = frozen)
    arm_asym: float = 0.0   # the left arm is carried this much further forward than the right (rad)
    twist: float = 0.0      # spine yaw of the posture (rad, + the chest turned to the left)
    #: per-arm (flex, abd, elbow) offsets (rad) of the resting carriage beyond ``arm_rest``, each arm
    #: its own (2.2: the arms of one performer do not hang alike; gestures override them)
    arm_offsets: tuple = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    #: per trunk joint (spine1, spine2, spine3, neck base, head) (yaw, pitch, roll) offsets (rad) of the
    #: posture's curvature (2.3: lumbar lordosis, thoracic kyphosis, a forward head, a lateral curve,
    #: each performer their own; see :func:`trunk_curvature`); the chest's orientation keeps ``slouch``
    trunk_posture: tuple = ((0.0, 0.0, 0.0),) * 5
    #: shares of the spine's bend (yaw, pitch, roll) taken by spine1, spine2 and spine3, per axis
    #: (None: :data:`.kinematics.SPINE_SHARE` on every axis); 2.3: one performer bends more from
    #: the lower back, another from the upper back
    spine_share: tuple | None = None
    #: per-arm (left, right) scale of the walking arm swing (2.4: one arm swings more than the
    #: other, as with most people; 1 = the gait's amplitude)
    swing_scale: tuple = (1.0, 1.0)

    def __post_init__(self) -> None:
        if not 0.03 <= self.width <= 0.3:
            raise ValueError(f"Persona.width={self.width} m must lie in [0.03, 0.3]")
        if not 0.5 <= self.tempo <= 2.0:
            raise ValueError(f"Persona.tempo={self.tempo} must lie in [0.5, 2]")
        if not 0.0 <= self.liveliness <= 3.0:
            raise ValueError(f"Persona.liveliness={self.liveliness} must lie in [0, 3]")
        if np.shape(self.arm_offsets) != (2, 3):
            raise ValueError(f"Persona.arm_offsets must be 2 arms x (flex, abd, elbow), got {self.arm_offsets!r}")
        if abs(self.twist) > 0.5:
            raise ValueError(f"Persona.twist={self.twist} rad must lie in [-0.5, 0.5]")
        if np.shape(self.trunk_posture) != (5, 3):
            raise ValueError(f"Persona.trunk_posture must be 5 trunk joints x (yaw, pitch, roll), "
                             f"got {self.trunk_posture!r}")
        if self.spine_share is not None:
            sh = np.asarray(self.spine_share, dtype=np.float64)
            if sh.shape != (3, 3) or (sh < 0).any() or not np.allclose(sh.sum(0), 1.0):
                raise ValueError(f"Persona.spine_share must be 3 spine joints x 3 axes of non-negative shares "
                                 f"summing to 1 per axis, got {self.spine_share!r}")
        if np.shape(self.swing_scale) != (2,) or not all(0.0 <= x <= 2.0 for x in self.swing_scale):
            raise ValueError(f"Persona.swing_scale must be 2 arms' scales in [0, 2], got {self.swing_scale!r}")
        if np.abs(self.trunk_posture).max() > 0.5:
            raise ValueError(f"Persona.trunk_posture holds {np.abs(self.trunk_posture).max():.2f} rad; "
                             f"each offset must lie in [-0.5, 0.5]")

    @staticmethod
    def sample(rng: np.random.Generator) -> "Persona":
        # ranges wide enough that posture and arm carriage differ visibly between performers
        # (generator 1.0 drew a near-identical stance: the corpus's pose std was 0.66x the real one)
        return Persona(
            width=float(rng.uniform(0.05, 0.2)),
            toe_out=float(rng.uniform(0.0, 0.45)),
            arm_rest=(float(rng.uniform(-0.1, 0.3)), float(rng.uniform(0.04, 0.4)), float(rng.uniform(0.1, 1.0))),
            arm_pole=(0.3, 0.0, -1.0),
            sway=float(rng.uniform(0.015, 0.04)),
            head_pitch=float(rng.uniform(-0.2, 0.45)),
            tempo=float(rng.uniform(0.85, 1.15)),
            slouch=float(rng.uniform(-0.15, 0.5)),
            tilt=float(rng.uniform(-0.25, 0.25)),
            liveliness=float(rng.uniform(0.6, 1.4)),
            arm_asym=float(rng.uniform(-0.3, 0.3)),
            # 2.2: a twisted posture and arms carried each their own way vary pose dimensions that
            # nothing else does (the corpus needed 9 principal components for 90 % of its variance);
            # 2.5 widens stance width, tilt, twist and the per-arm flexion/abduction offsets
            twist=float(rng.uniform(-0.4, 0.4)),
            arm_offsets=tuple(tuple(float(x) for x in rng.uniform([-0.3, -0.12, -0.3], [0.3, 0.4, 0.5]))
                              for _ in range(2)),
            trunk_posture=trunk_curvature(rng),
            spine_share=spine_shares(rng),
            swing_scale=tuple(float(x) for x in rng.uniform(0.7, 1.3, size=2)),
        )


def spine_shares(rng: np.random.Generator, concentration: float = 12.0) -> tuple:
    """A performer's shares ``(3, 3)`` (rows spine1-3, columns yaw, pitch, roll) of the spine's bend.

    Drawn per axis around :data:`.kinematics.SPINE_SHARE` (Dirichlet, ``concentration`` 12: the
    lumbar share of a bow has a std of about 0.14 between performers, mostly 0.2-0.7).
    """
    from .kinematics import SPINE_SHARE

    base = np.asarray(SPINE_SHARE, dtype=np.float64)
    sh = np.stack([rng.dirichlet(concentration * base) for _ in range(3)], 1)
    return tuple(tuple(float(x) for x in r) for r in sh)


def trunk_curvature(rng: np.random.Generator) -> tuple:
    """A performer's spinal curvature: ``(5, 3)`` (yaw, pitch, roll) offsets (rad) of spine1,
    spine2, spine3, the neck base and the head (:attr:`Persona.trunk_posture`).

    The three spine joints' offsets sum to zero on every axis, so the chest keeps the orientation
    the rest of the posture gives it (hands that touch something stay within reach) while the
    lumbar, lower and upper thoracic segments bend each their own way: a hollow or flat lower back
    under a rounder or straighter upper back (about +-10 deg), a slight sideways S and a twist
    shared unevenly. The neck leans forward or back and the head turns the other way by most of
    it (a forward head keeps a level gaze), with a habitual tilt and turn of its own.
    """
    u = rng.uniform
    spine = rng.normal(0.0, 1.0, size=(3, 3)) * np.array([0.08, 0.15, 0.08])   # rows spine1-3; (yaw, pitch, roll)
    spine -= spine.mean(0, keepdims=True)
    fwd = u(-0.15, 0.3)                                           # + the neck leans forward
    neck = np.array([u(-0.08, 0.08), fwd, u(-0.08, 0.08)])
    head = np.array([u(-0.1, 0.1), -u(0.6, 1.0) * fwd, u(-0.1, 0.1)])
    rows = np.clip(np.concatenate([spine, neck[None], head[None]]), -0.5, 0.5)
    return tuple(tuple(float(x) for x in r) for r in rows)


def flat_pitch(body: BodyModel) -> np.ndarray:
    """``(2,)`` downward pitch of a flat foot's ankle-to-toe bone (left, right)."""
    return np.arcsin((ANKLE_HEIGHT - TOE_HEIGHT) / body.foot)


@dataclass(frozen=True)
class Stance:
    """A standing body: both feet flat on the floor and a heading."""

    ankles: np.ndarray      # (2, 3) flat ankle positions (left, right), world
    foot_yaw: np.ndarray    # (2,) yaw of each foot
    yaw: float              # heading of the body

    @staticmethod
    def at(origin, yaw: float, persona: Persona) -> "Stance":
        """Feet side by side around ``origin`` (x, z) facing ``yaw``."""
        fwd, left = heading_vectors(yaw)
        base = np.array([origin[0], ANKLE_HEIGHT, origin[1]]) - fwd * PELVIS_AHEAD
        ankles = np.stack([base + left * persona.width, base - left * persona.width])
        return Stance(ankles, np.array([yaw + persona.toe_out, yaw - persona.toe_out]), float(yaw))

    @property
    def ground(self) -> np.ndarray:
        """``(3,)`` floor point under the pelvis of this stance."""
        fwd, _ = heading_vectors(self.yaw)
        g = self.ankles.mean(0) + fwd * PELVIS_AHEAD
        g[1] = 0.0
        return g

    def turned(self, yaw: float) -> "Stance":
        return Stance(self.ankles, self.foot_yaw, float(yaw))


@dataclass(frozen=True)
class Plant:
    """A foot planted flat at ``ankle`` from ``t_on`` to ``t_off``, with optional roll.

    Roll angles: > 0 lifts the toe (the foot pivots about the ankle, e.g. a heel strike), < 0
    lifts the heel (the foot pivots about the toe, e.g. a toe-off). ``roll_in`` decays to 0 over
    ``roll_in_time`` after ``t_on``; ``roll_out`` builds up over ``roll_out_time`` before ``t_off``.
    """

    t_on: float
    t_off: float
    ankle: np.ndarray           # (3,) flat ankle position
    yaw: float                  # foot yaw
    roll_in: float = 0.0
    roll_in_time: float = 0.0
    roll_out: float = 0.0
    roll_out_time: float = 0.0
    #: a pivot on the ball of the foot in mid-stance: the heel rises by ``pivot_lift`` rad about
    #: the toe while the foot turns by ``yaw_turn`` rad about it (finite stances only)
    yaw_turn: float = 0.0
    pivot_lift: float = 0.25

    def __post_init__(self) -> None:
        if not self.t_off >= self.t_on:
            raise ValueError(f"Plant: t_off={self.t_off} must not precede t_on={self.t_on}")
        if self.roll_in_time < 0 or self.roll_out_time < 0:
            raise ValueError(f"Plant: roll times must be >= 0, got {self.roll_in_time}, {self.roll_out_time}")
        if self.yaw_turn and not self.pivot_window():
            raise ValueError(f"Plant: yaw_turn={self.yaw_turn} needs a finite stance with at least "
                             f"{PIVOT_MIN} s between the rolls, got t_on={self.t_on}, t_off={self.t_off}")

    def pivot_window(self) -> tuple[float, float] | None:
        """(start, end) times of the mid-stance pivot, or None when the stance is too short."""
        if not (np.isfinite(self.t_on) and np.isfinite(self.t_off)):
            return None
        a, b = self.t_on + self.roll_in_time + 0.03, self.t_off - self.roll_out_time - 0.02
        return (a, b) if b - a >= PIVOT_MIN else None

    @property
    def yaw_end(self) -> float:
        """Foot yaw at lift-off (after any pivot)."""
        return self.yaw + self.yaw_turn


@dataclass(frozen=True)
class Swing:
    """An arc between two plants."""

    height: float = 0.1         # extra ankle lift at the peak (m)
    peak: float = 0.5           # where in the swing the lift peaks (0..1)
    pitch_mid: float = 0.0      # extra foot pitch in mid-swing (rad, + toe up)
    lead: float = 0.0           # extra forward reach of the ankle in mid-swing (m, knee-up marching)

    def __post_init__(self) -> None:
        if self.height < 0:
            raise ValueError(f"Swing.height={self.height} must be >= 0")
        if not 0.0 < self.peak < 1.0:
            raise ValueError(f"Swing.peak={self.peak} must lie in (0, 1)")


Air = Union[Swing, Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]]


def plant_pose(p: Plant, t: np.ndarray, body: BodyModel, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Ankle and toe ``(N, 3)`` of planted foot ``k`` (0 left, 1 right) at times ``t``."""
    phi0 = flat_pitch(body)[k]
    length = body.foot[k]
    t = np.asarray(t, dtype=np.float64)
    d = np.zeros_like(t)
    if p.roll_in and p.roll_in_time > 0:
        d = d + p.roll_in * (1.0 - min_jerk((t - p.t_on) / p.roll_in_time))
    if p.roll_out and p.roll_out_time > 0:
        d = d + p.roll_out * min_jerk((t - (p.t_off - p.roll_out_time)) / p.roll_out_time)
    flat_toe = p.ankle + foot_vector(p.yaw, phi0, length)
    yaw = np.full_like(t, p.yaw)
    win = p.pivot_window() if p.yaw_turn else None
    if win is not None:         # turn about the toe with the heel up (ball of the foot)
        tau = np.clip((t - win[0]) / (win[1] - win[0]), 0.0, 1.0)
        yaw = yaw + p.yaw_turn * min_jerk(np.clip((tau - 0.15) / 0.7, 0.0, 1.0))   # inside the heel's rise
        d = d - p.pivot_lift * np.sin(np.pi * tau)
    vec = foot_vector(yaw, phi0 - d, np.full_like(t, length))
    flat = flat_toe[None, :] - foot_vector(yaw, np.full_like(t, phi0), np.full_like(t, length))
    ankle = np.where((d >= 0)[:, None], flat, flat_toe[None, :] - vec)
    return ankle, ankle + vec


def _bump(tau: np.ndarray, peak: float) -> np.ndarray:
    peak = float(np.clip(peak, 0.15, 0.85))
    gamma = np.log(0.5) / np.log(peak)
    return np.sin(np.pi * np.clip(tau, 0.0, 1.0) ** gamma)


def _swing_pose(a: Plant, b: Plant, s: Swing, t: np.ndarray, body: BodyModel, k: int):
    phi0 = flat_pitch(body)[k]
    a0, _ = plant_pose(a, np.array([a.t_off]), body, k)
    b0, _ = plant_pose(b, np.array([b.t_on]), body, k)
    tau = np.clip((t - a.t_off) / max(b.t_on - a.t_off, 1e-9), 0.0, 1.0)
    m = min_jerk(tau)[:, None]
    ankle = a0 + (b0 - a0) * m
    bump = _bump(tau, s.peak)
    ankle[:, 1] += s.height * bump
    yaw = a.yaw_end + wrap_angle(b.yaw - a.yaw_end) * m[:, 0]
    if s.lead:
        fwd, _ = heading_vectors(yaw)
        ankle += fwd * (s.lead * bump)[:, None]
    delta = a.roll_out + (b.roll_in - a.roll_out) * smoothstep(tau) + s.pitch_mid * np.sin(np.pi * tau)
    toe = ankle + foot_vector(yaw, phi0 - delta, np.full_like(tau, body.foot[k]))
    return ankle, toe


def foot_track(t: np.ndarray, plants: list[Plant], airs: list[Air], body: BodyModel, k: int,
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ankle ``(N, 3)``, toe ``(N, 3)`` and planted flag ``(N,)`` of foot ``k`` over times ``t``.

    ``airs[i]`` is the flight between ``plants[i]`` and ``plants[i+1]``: a :class:`Swing` or a
    callable ``f(t) -> (ankle, toe)``. The first plant holds before its ``t_off`` and the last
    after its ``t_on``.
    """
    if len(airs) != len(plants) - 1:
        raise ValueError(f"foot_track: {len(plants)} plants need {len(plants) - 1} airs, got {len(airs)}")
    n = len(t)
    ankle = np.zeros((n, 3))
    toe = np.zeros((n, 3))
    planted = np.zeros(n, dtype=bool)
    for i, p in enumerate(plants):
        lo = -np.inf if i == 0 else p.t_on
        hi = np.inf if i == len(plants) - 1 else p.t_off
        sel = (t >= lo) & (t <= hi)
        if sel.any():
            ankle[sel], toe[sel] = plant_pose(p, t[sel], body, k)
            planted[sel] = True
        if i < len(plants) - 1:
            q = plants[i + 1]
            sel = (t > p.t_off) & (t < q.t_on)
            if sel.any():
                air = airs[i]
                if isinstance(air, Swing):
                    ankle[sel], toe[sel] = _swing_pose(p, q, air, t[sel], body, k)
                else:
                    ankle[sel], toe[sel] = air(t[sel])
    return ankle, toe, planted


def max_pelvis_height(pelvis: np.ndarray, g0: np.ndarray, ankle: np.ndarray, body: BodyModel,
                      reach: float = 0.995, planted: np.ndarray | None = None) -> np.ndarray:
    """``(N,)`` highest pelvis height at which the hips reach their planted ankle targets.

    Parameters
    ----------
    pelvis : ``(N, 3)`` pelvis positions (only x and z are used)
    g0 : ``(N, 3, 3)`` pelvis orientation
    ankle : ``(N, 2, 3)`` ankle targets
    reach : float
        Largest hip-to-ankle distance as a fraction of the straight leg.
    planted : ``(N, 2)`` bool, optional
        Which feet bear weight (default: both). A foot in the air does not hold the pelvis
        down; its leg simply stretches towards it. Frames with no planted foot get ``inf``.
    """
    bound = np.full(len(pelvis), np.inf)
    for k in range(2):
        off = g0 @ body.hip_offsets[k]                                  # (N, 3)
        dxz = np.hypot(pelvis[:, 0] + off[:, 0] - ankle[:, k, 0], pelvis[:, 2] + off[:, 2] - ankle[:, k, 2])
        length = reach * body.leg[k]
        vert = np.sqrt(np.maximum(length ** 2 - dxz ** 2, 0.0))
        leg_bound = ankle[:, k, 1] + vert - off[:, 1]
        if planted is not None:
            leg_bound = np.where(planted[:, k], leg_bound, np.inf)
        bound = np.minimum(bound, leg_bound)
    return bound


def standing_height(stance: Stance, body: BodyModel, pitch: float = 0.0) -> float:
    """Pelvis height of a relaxed stand (knees soft) over ``stance``."""
    g0 = ypr_matrix(np.array([[stance.yaw, pitch, 0.0]]))
    pelvis = stance.ground[None]
    return float(max_pelvis_height(pelvis, g0, stance.ankles[None], body, STAND_REACH)[0])
