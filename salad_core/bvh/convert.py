"""BVH files to joints (the take's own and HumanML3D's) and features; one loader for every motion file.

:func:`import_bvh` runs the whole conversion:

1. read the file and run its forward kinematics (:mod:`salad_core.bvh.reader`);
2. map the rig to the 22 HumanML3D joints (:mod:`salad_core.bvh.rigs`);
3. turn the up axis to +Y: detected as the axis the spine (pelvis -> head) and the legs (ankles ->
   pelvis) point along in the rest pose (BVH rest poses stand: a T- or A-pose in the file's axes),
   or, when the rest pose is not upright, on average over the motion; ``up=`` overrides. The turn
   is a proper rotation, so left stays left;
4. convert lengths to metres: the unit (m, cm, mm, inch, foot) whose conversion gives the rig's
   legs + spine (hip -> knee -> ankle plus pelvis -> head along the spine) the length closest to
   HumanML3D's target skeleton (1.48 m, a person of about 1.7 m); when even the closest unit is off
   by more than a factor 1.6 (unusual units such as the CMU conversion's 1/0.45 inch), the rig is
   scaled to that target length and the unit is reported as ``"fit"``; ``units=`` overrides;
5. resample to ``fps`` (20, HumanML3D's rate) from the file's Frame Time, linearly in joint
   positions (when the rates divide, every output frame is a source frame; a file already at
   ``fps`` keeps every frame);
6. put the lowest joint of the clip (the lowest foot, in any upright motion) on the floor,
   ``y = 0``, as HumanML3D does.

The result, :attr:`BvhImport.joints`, is **the take itself**: its own bone lengths, its horizontal
position and heading, on its floor. Beside it, :attr:`BvhImport.retargeted` is the copy on
HumanML3D's target skeleton that the models see (:func:`salad_core.motion.process_joints`: bone
directions kept, lengths replaced, the root path scaled by the leg-length ratio, first frame at the
origin facing +Z), and :attr:`BvhImport.retarget_error` says how far that copy is from the take
(per-frame root-aligned, after the same heading alignment). :meth:`BvhImport.features` are the
retargeted copy's HumanML3D features (one fewer frame than the joints: they hold velocities).
"""
from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Mapping

import numpy as np

from salad_core import limits
from salad_core.motion import (MAX_FEATURE_MAGNITUDE, _check_magnitude, check_features, check_joints,
                               features_to_joints, joints_to_features, process_joints)
from salad_core.skeleton import get_skeleton

from .reader import BvhError, BvhMotion, read_bvh
from .rigs import HML_NAMES, RigMapping, map_rig

__all__ = ["BvhImportOptions", "BvhImport", "import_bvh", "bvh_to_joints", "bvh_to_features", "LoadedMotion",
           "load_motion", "JointsConversionError", "UNITS", "UP_AXES", "TARGET_STATURE", "stature",
           "retargeted_joints", "take_in_features_frame", "retarget_error", "RetargetError", "load_motion_array",
           "resampled_frames"]

#: Metres per file unit of the length units :func:`import_bvh` knows.
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "ft": 0.3048}
_UNIT_ALIASES = {"metre": "m", "meter": "m", "metres": "m", "meters": "m", "centimetre": "cm", "centimeter": "cm",
                 "millimetre": "mm", "millimeter": "mm", "in": "inch", "inches": "inch", "foot": "ft", "feet": "ft"}
#: Up axes :func:`import_bvh` accepts, as rotations taking that axis to +Y (rows: new x, y, z).
UP_AXES: dict[str, np.ndarray] = {
    "y": np.eye(3),
    "-y": np.diag([1.0, -1.0, -1.0]),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "-z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "x": np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
    "-x": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}
log = logging.getLogger(__name__)
_SK = get_skeleton("humanml3d")
_IDX = {n: i for i, n in enumerate(HML_NAMES)}
_LEG = (("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle"))
_SPINE = ("pelvis", "spine1", "spine2", "spine3", "neck", "head")


def _chain_length(joints: np.ndarray, chain) -> np.ndarray:
    idx = [_IDX[n] for n in chain]
    return np.linalg.norm(np.diff(joints[..., idx, :], axis=-2), axis=-1).sum(-1)


def stature(joints: np.ndarray) -> float:
    """Median over frames of the mean leg length plus the spine length (pelvis -> head).

    ``joints`` ``(T, 22, 3)`` in HumanML3D's joint order, any length unit; the result is in that
    unit (compare :data:`TARGET_STATURE`, metres).
    """
    legs = 0.5 * (_chain_length(joints, _LEG[0]) + _chain_length(joints, _LEG[1]))
    return float(np.median(legs + _chain_length(joints, _SPINE)))


#: Legs + spine of HumanML3D's target skeleton, metres (the reference for unit detection).
TARGET_STATURE = float(0.5 * sum(_SK.bone_lengths[_IDX[n]] for leg in _LEG for n in leg[1:])
                       + sum(_SK.bone_lengths[_IDX[n]] for n in _SPINE[1:]))
_FIT_FACTOR = 1.6


@dataclass(frozen=True)
class BvhImportOptions:
    """How :func:`import_bvh` converts a file (validated on construction).

    Attributes
    ----------
    fps : float
        Output frame rate (HumanML3D: 20).
    units : str, float or None
        Length unit of the file: a key of :data:`UNITS` (``"m", "cm", "mm", "inch", "ft"``), metres
        per file unit as a positive number, or ``None`` to detect from the skeleton's size.
    up : str or None
        The file's up axis, a key of :data:`UP_AXES` (``"y", "z", "-y", "-z", "x", "-x"``), or
        ``None`` to detect.
    rig : str or None
        Force a rig style (``"smpl", "mixamo", "cmu", "generic"``); ``None`` detects.
    name_map : tuple of (humanml3d_joint, rig_joint) pairs, or a JSON path
        User overrides of the rig mapping (a dict is accepted and stored as sorted pairs).
    """

    fps: float = 20.0
    units: str | float | None = None
    up: str | None = None
    rig: str | None = None
    name_map: tuple[tuple[str, str], ...] | str | None = field(default=None)

    def __post_init__(self) -> None:
        fps = self.fps
        if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not math.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps must be a positive number of frames per second, got {fps!r}")
        units = self.units
        if isinstance(units, str):
            key = _UNIT_ALIASES.get(units.lower(), units.lower())
            if key not in UNITS:
                raise ValueError(f"units {units!r} is not known; allowed: {', '.join(UNITS)}, metres per unit as "
                                 "a number, or None to detect")
            object.__setattr__(self, "units", key)
        elif units is not None and (isinstance(units, bool) or not isinstance(units, (int, float))
                                    or not math.isfinite(units) or units <= 0):
            raise ValueError(f"units must be a unit name ({', '.join(UNITS)}), a positive number of metres per "
                             f"file unit, or None; got {units!r}")
        if self.up is not None:
            up = str(self.up).lower().replace("+", "")
            if up not in UP_AXES:
                raise ValueError(f"up {self.up!r} is not an axis; allowed: {', '.join(UP_AXES)} or None to detect")
            object.__setattr__(self, "up", up)
        if isinstance(self.name_map, Mapping):
            object.__setattr__(self, "name_map", tuple(sorted(self.name_map.items())))
        elif isinstance(self.name_map, os.PathLike):
            object.__setattr__(self, "name_map", os.fspath(self.name_map))


@dataclass(frozen=True)
class RetargetError:
    """How far the HumanML3D-retargeted copy of a take is from the take, in centimetres.

    Per frame, both are root-aligned (each pose's pelvis subtracted) after the same heading
    alignment (first frame facing +Z); ``mean_cm`` averages over joints and frames, ``max_cm`` is
    the largest joint distance.
    """

    mean_cm: float
    max_cm: float

    def __str__(self) -> str:
        return f"{self.mean_cm:.1f} cm mean, {self.max_cm:.1f} cm max"


def retargeted_joints(joints: np.ndarray, skeleton="humanml3d") -> np.ndarray:
    """The HumanML3D-retargeted copy ``(N, 22, 3)`` float32 of a take's joints: target bone lengths,
    on the floor, first frame's root at the origin facing +Z (:func:`salad_core.motion.process_joints`;
    what :func:`~salad_core.motion.joints_to_features` encodes, one frame more)."""
    return process_joints(np.asarray(joints, dtype=np.float64), skeleton)


def _aligned(joints: np.ndarray, skeleton="humanml3d") -> np.ndarray:
    """The take's joints in the retargeted copy's frame (floor, origin, facing +Z), bones unchanged."""
    return process_joints(np.asarray(joints, dtype=np.float64), skeleton, retarget=False).astype(np.float64)


def retarget_error(joints: np.ndarray, skeleton="humanml3d") -> RetargetError:
    """:class:`RetargetError` of the retargeted copy (:func:`retargeted_joints`) of ``joints`` ``(N, J, 3)``."""
    take = _aligned(joints, skeleton)
    ret = retargeted_joints(joints, skeleton).astype(np.float64)
    d = np.linalg.norm((ret - ret[:, :1]) - (take - take[:, :1]), axis=-1)
    return RetargetError(float(d.mean() * 100.0), float(d.max() * 100.0))


def _yaw(src: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The rotation ``(3, 3)`` about +Y that best turns the horizontal spread of ``src`` onto ``ref``
    (same shape ``(..., 3)``; least squares over every point after centring)."""
    a = src[..., [0, 2]].reshape(-1, 2)
    b = ref[..., [0, 2]].reshape(-1, 2)
    a = a - a.mean(0)
    b = b - b.mean(0)
    # rotation about y by t: x' = cos t x + sin t z, z' = -sin t x + cos t z
    sin = float((a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1]).sum())
    cos = float((a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]).sum())
    t = math.atan2(sin, cos)
    c, s_ = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]])


def take_in_features_frame(joints: np.ndarray, features: np.ndarray, start: int = 0,
                           skeleton="humanml3d") -> np.ndarray:
    """A take's own joints placed where ``features_to_joints(features)`` puts its retargeted copy.

    ``features`` ``(n, 263)`` are (a crop starting at joint frame ``start`` of) the take's features,
    ``joints_to_features(joints)[start:start + n]``. The result ``(n, 22, 3)`` float64 is
    ``joints[start:start + n]`` with the take's own bone lengths, on its floor, turned about the
    vertical as the features' joints are and with its first root on theirs (horizontally): the
    reference for errors "against the take" of anything made from the features.
    """
    feats = np.asarray(features)
    n = int(feats.shape[0])
    if not (0 <= start and start + n <= len(joints)):
        raise ValueError(f"features of {n} frames from frame {start} do not fit a take of {len(joints)} frames")
    ref = np.asarray(features_to_joints(feats, skeleton), dtype=np.float64)
    ret = retargeted_joints(joints, skeleton).astype(np.float64)[start:start + n]
    take = _aligned(joints, skeleton)[start:start + n]
    rot = _yaw(ret, ref)                        # the features' heading (exact: a rigid turn of ret)
    out = take @ rot.T
    shift = ref[0, 0] - out[0, 0]
    out[..., 0] += shift[0]
    out[..., 2] += shift[2]
    return out


@dataclass(frozen=True, eq=False)
class BvhImport:
    """A BVH take converted to the 22 HumanML3D joints.

    Attributes
    ----------
    joints : ndarray (N, 22, 3) float32
        The take itself: its own bone lengths, metres, +Y up, lowest joint of the clip on y = 0, at
        ``fps``; the take's own horizontal position and heading. (``salad import`` writes these as
        ``<take>_joints.npy``.)
    fps : float
    source_fps : float
        The file's frame rate (1 / Frame Time).
    source_frames : int
    units : str
        The length unit used (a key of :data:`UNITS`, ``"fit"`` or ``"custom"``).
    metres_per_unit : float
    up : str
        The file's up axis (a key of :data:`UP_AXES`).
    detected : tuple of str
        Which of ``"units"``, ``"up"``, ``"rig"`` were detected rather than given.
    rig : RigMapping
    path : str

    Derived: :attr:`retargeted` (the copy on HumanML3D's skeleton, ``N`` frames), :attr:`retarget_error`
    (its distance from the take), :meth:`features` (``N - 1`` frames).
    """

    joints: np.ndarray
    fps: float
    source_fps: float
    source_frames: int
    units: str
    metres_per_unit: float
    up: str
    detected: tuple[str, ...]
    rig: RigMapping
    path: str

    @property
    def num_frames(self) -> int:
        return int(self.joints.shape[0])

    @cached_property
    def retargeted(self) -> np.ndarray:
        """``(N, 22, 3)`` float32: the take on HumanML3D's target skeleton (:func:`retargeted_joints`):
        what the features hold (``features_to_joints(self.features()) == self.retargeted[:-1]``)."""
        return retargeted_joints(self.joints)

    @cached_property
    def retarget_error(self) -> RetargetError:
        """How far :attr:`retargeted` is from the take (:func:`retarget_error`)."""
        return retarget_error(self.joints)

    def features(self) -> np.ndarray:
        """``(N-1, 263)`` HumanML3D features of the retargeted take
        (:func:`salad_core.motion.joints_to_features`; one fewer than the joints: velocities)."""
        if self.num_frames < 2:
            raise ValueError(f"{self.path}: the take has {self.num_frames} frame at {self.fps:g} fps; features "
                             "need at least 2")
        return joints_to_features(self.joints.astype(np.float64), _SK)

    def summary(self) -> str:
        """One line: frames, rates, unit, up axis and rig style, marking what was detected."""
        def mark(key):
            return " (detected)" if key in self.detected else ""

        return (f"{self.path}: {self.source_frames} frames at {self.source_fps:.4g} fps -> {self.num_frames} at "
                f"{self.fps:g} fps; units {self.units}{mark('units')} ({self.metres_per_unit:.4g} m per unit), "
                f"up {self.up}{mark('up')}, rig {self.rig.style}{mark('rig')}")


def _detect_up(joints: np.ndarray) -> str | None:
    """The axis (of the file) the spine and legs point along on average, if clear."""
    pelvis, head = joints[:, _IDX["pelvis"]], joints[:, _IDX["head"]]
    ankles = 0.5 * (joints[:, _IDX["left_ankle"]] + joints[:, _IDX["right_ankle"]])

    def unit(v):
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        return np.where(n > 1e-9, v / np.maximum(n, 1e-12), 0.0)

    v = (unit(head - pelvis) + unit(pelvis - ankles)).mean(0) / 2.0
    k = int(np.argmax(np.abs(v)))
    # clear: the mean direction is long (the body mostly upright) and mostly along one axis
    if np.linalg.norm(v) < 0.5 or abs(v[k]) < 0.8 * np.linalg.norm(v):
        return None
    return ("-" if v[k] < 0 else "") + "xyz"[k]


def _choose_up(rest: str | None, moving: str | None, path: str) -> str:
    """The rest pose decides (BVH rest poses stand: a T- or A-pose in the file's axes), the motion
    when the rest pose is not upright; a disagreement is logged."""
    if rest is None and moving is None:
        raise ValueError(f"{path}: cannot tell the up axis (the spine points along no single axis in the rest "
                         f"pose or on average in the motion); pass up= one of {', '.join(UP_AXES)}")
    if rest is not None and moving is not None and rest != moving:
        log.warning("%s: the rest pose stands along %s but the body's spine points along %s on average in the "
                    "motion (a take spent lying down?); using %s (pass up= to choose)", path, rest, moving, rest)
    return rest or moving


def _detect_units(size: float) -> tuple[str, float]:
    """Closest known unit by the legs + spine length ``size`` (file units); ``("fit", scale)`` when
    none is close."""
    if not size > 0:
        raise ValueError("the rig has zero size (legs and spine of length 0); cannot detect its units")
    name, per = min(UNITS.items(), key=lambda kv: abs(math.log(size * kv[1] / TARGET_STATURE)))
    if abs(math.log(size * per / TARGET_STATURE)) > math.log(_FIT_FACTOR):
        return "fit", TARGET_STATURE / size
    return name, per


#: Frame Times are written with few decimals (``0.033333`` for 30 fps, ``0.049999`` for 20), so a take
#: may look a little shorter or longer than it is: rates within this relative difference of the output
#: rate count as that rate (the frames are kept as they are), and an output frame at most this fraction
#: of the take's duration (or 0.01 frame) past its last frame is kept (it is the last frame).
_RATE_SLACK = 1e-4


def resampled_frames(n: int, src_fps: float, fps: float) -> int:
    """How many frames :func:`_resample` makes of ``n`` frames at ``src_fps`` for ``fps`` (no array made).

    Output frame ``k`` is at source position ``k * src_fps / fps``; there are as many as fit in the
    take, up to the rounding slack :data:`_RATE_SLACK`. A take already at ``fps`` (up to that rounding)
    keeps its ``n`` frames. May be a float ``inf`` for absurd rates (refused by the caller).
    """
    ratio = src_fps / fps                       # source frames per output frame
    if n == 1 or abs(ratio - 1.0) <= _RATE_SLACK:
        return n
    span = (n - 1) / ratio if ratio > 0 else math.inf      # the take's duration in output frames
    count = span * (1.0 + _RATE_SLACK) + 0.01
    return int(math.floor(count)) + 1 if math.isfinite(count) else math.inf


def _check_resample(n: int, src_fps: float, fps: float, path: str) -> int:
    """:func:`resampled_frames`, if within :func:`salad_core.limits.resample_problem` (else BvhError)."""
    n_out = resampled_frames(n, src_fps, fps)
    if (problem := limits.resample_problem(n, src_fps, n_out, fps, len(HML_NAMES))) is not None:
        raise BvhError(path, None, problem)
    return n_out


def _resample(joints: np.ndarray, src_fps: float, fps: float, path: str = "<array>") -> np.ndarray:
    """Linear resampling over time of ``(N, J, 3)`` from ``src_fps`` to ``fps`` (first frame kept).

    :func:`resampled_frames` output frames (checked against :mod:`salad_core.limits` before any array
    is made); a take already at ``fps`` (up to rounding) keeps every frame as it is: a 20 fps file
    neither loses nor gains a frame.
    """
    n = joints.shape[0]
    ratio = src_fps / fps                       # source frames per output frame
    n_out = _check_resample(n, src_fps, fps, path)
    if n_out == n and (n == 1 or abs(ratio - 1.0) <= _RATE_SLACK):
        return joints
    pos = np.minimum(np.arange(n_out) * ratio, n - 1)
    k = np.minimum(np.floor(pos + 1e-9).astype(int), n - 1)
    k1 = np.minimum(k + 1, n - 1)
    w = np.clip(pos - k, 0.0, 1.0)[:, None, None]
    return joints[k] * (1.0 - w) + joints[k1] * w


def import_bvh(source: str | os.PathLike | BvhMotion, options: BvhImportOptions | None = None, **kwargs) -> BvhImport:
    """Convert a BVH take to the 22 HumanML3D joints (see the module docstring for the steps).

    Parameters
    ----------
    source : path or BvhMotion
        The ``.bvh`` file, or an already parsed motion.
    options : BvhImportOptions, optional
        Or its fields as keyword arguments: ``fps=20``, ``units=None``, ``up=None``, ``rig=None``,
        ``name_map=None``.

    Returns
    -------
    BvhImport
        ``.joints``: the take itself (its bone lengths, on its floor, at ``fps``);
        ``.retargeted``: its copy on HumanML3D's skeleton, ``.retarget_error`` how far that is;
        ``.features()``: the copy's HumanML3D features.

    Raises
    ------
    BvhError
        For a malformed file (message with the line), or one whose resampled take would exceed
        :data:`salad_core.limits.IMPORT_MAX_FRAMES` frames (checked before any work).
    RigError
        When the rig's joints cannot be mapped (message lists the missing joints).
    ValueError
        For bad options, or an up axis that cannot be detected.
    """
    if options is None:
        options = BvhImportOptions(**kwargs)
    elif kwargs:
        raise TypeError("give either options or keyword arguments, not both")
    motion = source if isinstance(source, BvhMotion) else read_bvh(source)
    # the output's size, before any work: forward kinematics and resampling scale with it
    _check_resample(motion.num_frames, motion.fps, float(options.fps), motion.path)
    name_map = dict(options.name_map) if isinstance(options.name_map, tuple) else options.name_map
    mapping = map_rig(motion.joint_names, motion.point_names(), motion.point_parents(),
                      rest=motion.world_positions(rest=True)[0], name_map=name_map, style=options.rig,
                      source=motion.path)
    joints = mapping.apply(motion.world_positions())               # (N, 22, 3) file units and axes
    detected = []
    up = options.up
    if up is None:
        up = _choose_up(_detect_up(mapping.apply(motion.world_positions(rest=True))), _detect_up(joints),
                        motion.path)
        detected.append("up")
    joints = joints @ UP_AXES[up].T
    if options.units is None:
        units, per = _detect_units(stature(joints))
        detected.append("units")
    elif isinstance(options.units, str):
        units, per = options.units, UNITS[options.units]
    else:
        units, per = "custom", float(options.units)
    joints = _resample(joints * per, motion.fps, float(options.fps), motion.path)
    joints[..., 1] -= joints[..., 1].min()
    if options.rig is None:
        detected.append("rig")
    return BvhImport(joints.astype(np.float32), float(options.fps), motion.fps, motion.num_frames, units, per, up,
                     tuple(detected), mapping, motion.path)


def bvh_to_joints(source: str | os.PathLike | BvhMotion, *, name_map=None, rig: str | None = None,
                  fps: float = 20.0, units: str | float | None = None, up: str | None = None) -> np.ndarray:
    """The take's own joints ``(N, 22, 3)`` (HumanML3D's joints of its rig: float32, metres, +Y up, on the
    floor, its own bone lengths) of a BVH take.

    See :func:`import_bvh` for the arguments; this returns only ``import_bvh(...).joints``.
    """
    return import_bvh(source, name_map=name_map, rig=rig, fps=fps, units=units, up=up).joints


def bvh_to_features(source: str | os.PathLike | BvhMotion, **kwargs) -> np.ndarray:
    """HumanML3D features ``(N-1, 263)`` of a BVH take (keyword arguments as :func:`bvh_to_joints`)."""
    return import_bvh(source, **kwargs).features()


class JointsConversionError(ValueError):
    """A joints file whose joints cannot be turned into HumanML3D features (e.g. all zeros)."""


@dataclass(frozen=True, eq=False)
class LoadedMotion:
    """A motion file read for the models.

    Attributes
    ----------
    features : ndarray (N, D) float32
        HumanML3D features (for BVH and joints input: of the retargeted copy of ``N + 1`` joint
        frames).
    joints : ndarray (M, J, 3) float32
        The joints as given: for a BVH file the take itself (:attr:`BvhImport.joints`: its own bone
        lengths, on its floor; ``M = N + 1``); for a joints .npy as stored (``M = N + 1``); for a
        features .npy the position features' joints (``features_to_joints``, ``M = N``).
    kind : {"bvh", "features", "joints"}
    path : Path
    bvh : BvhImport or None
        The import details for a BVH file.
    """

    features: np.ndarray
    joints: np.ndarray
    kind: str
    path: Path
    bvh: BvhImport | None = None


def load_motion(path: str | os.PathLike, skeleton: str = "humanml3d", **bvh_options) -> LoadedMotion:
    """Read a motion file: a ``.bvh`` take, or a ``.npy`` of features ``(N, D)`` or joints ``(N, J, 3)``.

    Parameters
    ----------
    path : str or PathLike
    skeleton : str
        The skeleton of ``.npy`` files (BVH files are imported to HumanML3D).
    **bvh_options
        For BVH files: ``fps, units, up, rig, name_map`` (:class:`BvhImportOptions`).

    Returns
    -------
    LoadedMotion

    Raises
    ------
    FileNotFoundError
        ``"motion file not found: <path>"``.
    JointsConversionError
        Joints that ``joints_to_features`` refuses (a ValueError).
    ValueError
        A file that cannot be read or has the wrong shape or non-finite values; BVH errors
        (:class:`~salad_core.bvh.reader.BvhError`, :class:`~salad_core.bvh.rigs.RigError`) name
        the problem and, for malformed files, the line.
    """
    sk = get_skeleton(skeleton)
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"motion file not found: {p}")
    if p.suffix.lower() == ".bvh":
        if sk.name != "humanml3d":
            raise ValueError(f"{p}: BVH files are imported to the humanml3d skeleton, not {sk.name!r}")
        if bvh_options.get("fps") is None:
            bvh_options["fps"] = sk.fps
        imp = import_bvh(p, **bvh_options)
        return LoadedMotion(imp.features(), imp.joints, "bvh", p, imp)
    if bvh_options and any(v is not None for v in bvh_options.values()):
        given = ", ".join(k for k, v in bvh_options.items() if v is not None)
        raise ValueError(f"{p}: {given} appl{'ies' if ',' not in given else 'y'} to BVH files only")
    arr = load_motion_array(p, sk)
    if arr.ndim == 2:
        return LoadedMotion(arr, np.asarray(features_to_joints(arr, sk), np.float32), "features", p)
    check_joints(arr, sk, name=str(p), min_frames=2)
    try:
        feats = joints_to_features(arr.astype(np.float64), sk)
    except ValueError as exc:
        raise JointsConversionError(f"{p} holds joints {arr.shape} that cannot be converted to HumanML3D "
                                    f"features: {exc}") from None
    return LoadedMotion(feats, arr, "joints", p)


def load_motion_array(path: str | os.PathLike, skeleton: str = "humanml3d") -> np.ndarray:
    """A motion ``.npy`` from outside, checked: features ``(N, D)`` or joints ``(N, J, 3)``, float32.

    The header is read first (:func:`salad_core.limits.read_npy`: never unpickles, refuses a header
    that does not parse, a non-numeric dtype, a claimed size over 1 GiB or more than the file holds),
    then the shape against ``skeleton``, then the values: finite, features within
    :data:`salad_core.motion.MAX_FEATURE_MAGNITUDE` and joints within
    :data:`salad_core.limits.MAX_JOINT_MAGNITUDE` metres.

    Raises
    ------
    FileNotFoundError
        ``"motion file not found: <path>"``.
    ValueError
        Naming the file and the problem.
    """
    sk = get_skeleton(skeleton)
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"motion file not found: {p}")
    arr = limits.read_npy(p, kinds="iuf")
    if arr.ndim == 2:
        check_features(arr, sk, name=str(p))
        _check_magnitude(arr, f"{p}: the features", MAX_FEATURE_MAGNITUDE)
        return arr.astype(np.float32, copy=False)
    if arr.ndim == 3 and arr.shape[1:] == (sk.num_joints, 3):
        check_joints(arr, sk, name=str(p))
        limits.check_array_values(arr, f"{p}: the joints", max_abs=limits.MAX_JOINT_MAGNITUDE,
                                  hint="joints are positions in metres; check the array's units")
        return arr.astype(np.float32, copy=False)
    raise ValueError(f"{p} has shape {arr.shape}; expected features (N, {sk.feature_dim}), joints "
                     f"(N, {sk.num_joints}, 3) or a .bvh file")
