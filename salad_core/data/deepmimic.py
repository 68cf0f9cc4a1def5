"""DeepMimic motion-capture clips on the HumanML3D skeleton (optional extra ``deepmimic``: pybullet).

The PyPI ``pybullet`` wheel ships DeepMimic's motion-capture clips (Peng et al. 2018) in
``pybullet_data/data/motions``: 15 ``humanoid3d_*`` clips (walk, run, jump, kick, punch, spin,
spin-kick, two dances, cartwheel, backflip, crawl, roll, two get-ups) and 5 ``walker/*`` clips
(walking, turning), all retargeted to DeepMimic's humanoid; ``laikago_walk`` is a quadruped and is
not offered. They are real capture that nobody in this project wrote, so they are the given
motions that inversion and editing are tried on.

A clip is JSON ``{"Loop": "wrap"|"none", "Frames": [[dt, root xyz, root quat, chest, neck,
right hip, right knee, right ankle, right shoulder, right elbow, left hip, left knee, left ankle,
left shoulder, left elbow], ...]}`` with quaternions stored ``w, x, y, z`` and the knees and elbows
as 1-DoF angles (``pybullet_envs/deep_mimic/env/humanoid_pose_interpolator.py``). Conversion:

1. resample to the skeleton's 20 fps: root position and 1-DoF angles linearly, quaternions by
   slerp (looping clips can be repeated, the root advancing by one cycle's displacement each time,
   as DeepMimic does);
2. pybullet's own forward kinematics in DIRECT mode on ``humanoid/humanoid.urdf`` (scale 0.25, as
   DeepMimic loads it) gives the joint frames;
3. the HumanML3D joints the humanoid lacks are placed in its link frames: spine1 halfway up the
   root link, spine3 just above the chest joint, the collars between spine3 and the shoulders,
   the head above the neck joint, the toes at the front bottom of the foot boxes;
4. DeepMimic's axes (Y up, facing +X, right +Z) are rotated to HumanML3D's (Y up, facing +Z, left
   +X);
5. by default (``rig="smpl"``) the motion is re-posed on HumanML3D's own rigid torso geometry
   (:func:`salad_core.retarget.rerig`): HumanML3D's joints are SMPL's, whose hips hang about 58 degrees
   below the line between them and whose spine and collars keep SMPL's rest angles in every clip, while
   DeepMimic's humanoid has level hips and a straight spine. The torso segments' rotations and every limb
   bone's direction are kept per frame; ``rig="deepmimic"`` keeps the humanoid's own geometry (the
   conversion before this step existed). Measured with the general VAE (``lab/docs/vae_real_motion.md``):
   the humanoid's geometry alone cost about 4 cm of its 7 cm reconstruction error;
6. :func:`salad_core.motion.joints_to_features` then retargets the bone lengths, puts the floor at 0
   and faces frame 0 to +Z as for any HumanML3D clip.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from salad_core.motion import joints_to_features
from salad_core.retarget import rerig, rest_directions, smpl_rest_directions
from salad_core.skeleton import get_skeleton

__all__ = ["DeepMimicClip", "CLIP_PROMPTS", "RIGS", "available_clips", "clip_path", "load_clip", "clip_features",
           "humanoid_rest_directions", "pybullet_available", "EXTRA"]

#: Torso geometries :func:`load_clip` can give a clip: HumanML3D's (SMPL's; the default) or the humanoid's own.
RIGS = ("smpl", "deepmimic")

log = logging.getLogger(__name__)

#: Name of the optional dependency group that provides pybullet.
EXTRA = "deepmimic"
_INSTALL_HINT = (f"DeepMimic clips need the optional extra '{EXTRA}': pip install 'salad[{EXTRA}]' "
                 "(or pip install pybullet==3.2.7, a binary wheel)")

#: A plain description of every humanoid clip (what the clip shows), usable as its source prompt.
CLIP_PROMPTS: dict[str, str] = {
    "backflip": "a person does a backflip",
    "cartwheel": "a person does a cartwheel",
    "crawl": "a person crawls forward on hands and knees",
    "dance_a": "a person dances",
    "dance_b": "a person dances energetically",
    "getup_facedown": "a person gets up from lying face down",
    "getup_faceup": "a person gets up from lying on their back",
    "jump": "a person jumps forward",
    "kick": "a person kicks",
    "punch": "a person punches",
    "roll": "a person rolls forward on the ground",
    "run": "a person runs forward",
    "spin": "a person spins around",
    "spinkick": "a person spins and kicks",
    "walk": "a person walks forward",
    "walker/0walk_forward": "a person walks forward",
    "walker/turn_left0": "a person walks and turns left",
    "walker/turn_left1": "a person walks and turns left",
    "walker/turn_right0": "a person walks and turns right",
    "walker/turn_right1": "a person walks and turns right",
}

# pybullet joint indices of humanoid.urdf (URDF_MAINTAIN_LINK_ORDER); the 44 values of a frame
# after [dt, root pos (3), root quat (4)] fill these joints in this order
_LINKS = ("root", "chest", "neck", "right_hip", "right_knee", "right_ankle", "right_shoulder", "right_elbow",
          "right_wrist", "left_hip", "left_knee", "left_ankle", "left_shoulder", "left_elbow", "left_wrist")
_FRAME_JOINTS = (("chest", 4), ("neck", 4), ("right_hip", 4), ("right_knee", 1), ("right_ankle", 4),
                 ("right_shoulder", 4), ("right_elbow", 1), ("left_hip", 4), ("left_knee", 1), ("left_ankle", 4),
                 ("left_shoulder", 4), ("left_elbow", 1))
_FRAME_WIDTH = 1 + 3 + 4 + sum(n for _, n in _FRAME_JOINTS)
#: DeepMimic loads the humanoid at a quarter of its URDF size (metres after scaling).
_URDF_SCALE = 0.25

# HumanML3D joint -> (DeepMimic link, offset in that link's frame, metres at scale 0.25).
# Offsets come from humanoid.urdf: chest joint 0.236 m above the root, neck 0.224 m above the
# chest, shoulders 0.244 m above the chest and 0.183 m to the side, head sphere centred 0.175 m
# above the neck, foot boxes 0.177 m long centred 0.045 m ahead of the ankle, 0.055 m high.
_JOINT_SOURCES: dict[str, tuple[str, tuple[float, float, float]]] = {
    "pelvis": ("root", (0.0, 0.0, 0.0)),
    "left_hip": ("left_hip", (0.0, 0.0, 0.0)),
    "right_hip": ("right_hip", (0.0, 0.0, 0.0)),
    "spine1": ("root", (0.0, 0.118, 0.0)),
    "left_knee": ("left_knee", (0.0, 0.0, 0.0)),
    "right_knee": ("right_knee", (0.0, 0.0, 0.0)),
    "spine2": ("chest", (0.0, 0.0, 0.0)),
    "left_ankle": ("left_ankle", (0.0, 0.0, 0.0)),
    "right_ankle": ("right_ankle", (0.0, 0.0, 0.0)),
    "spine3": ("chest", (0.0, 0.06, 0.0)),
    "left_foot": ("left_ankle", (0.12, -0.045, 0.0)),
    "right_foot": ("right_ankle", (0.12, -0.045, 0.0)),
    "neck": ("neck", (0.0, 0.0, 0.0)),
    "left_collar": ("chest", (-0.012, 0.17, -0.075)),     # DeepMimic's left is -Z
    "right_collar": ("chest", (-0.012, 0.17, 0.075)),
    "head": ("neck", (0.0, 0.1, 0.0)),
    "left_shoulder": ("left_shoulder", (0.0, 0.0, 0.0)),
    "right_shoulder": ("right_shoulder", (0.0, 0.0, 0.0)),
    "left_elbow": ("left_elbow", (0.0, 0.0, 0.0)),
    "right_elbow": ("right_elbow", (0.0, 0.0, 0.0)),
    "left_wrist": ("left_wrist", (0.0, 0.0, 0.0)),
    "right_wrist": ("right_wrist", (0.0, 0.0, 0.0)),
}
# DeepMimic (forward +X, up +Y, right +Z) -> HumanML3D (left +X, up +Y, forward +Z): a rotation
# about Y (both frames are right-handed), rows = HumanML3D axes in DeepMimic coordinates
_TO_HML = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


@dataclass
class DeepMimicClip:
    """A DeepMimic clip converted to HumanML3D joints."""

    name: str            # clip name, e.g. "walk" or "walker/turn_left0"
    joints: np.ndarray   # (N, 22, 3) float32 HumanML3D joints, Y up, metres, at `fps`
    fps: float           # frames per second of `joints` (the skeleton's 20)
    source_fps: float    # the clip's own frame rate
    loop: bool           # the clip is a cycle ("wrap")
    cycles: int          # how many times the cycle was played
    prompt: str          # a plain description (CLIP_PROMPTS)
    rig: str = "smpl"    # torso geometry (RIGS): HumanML3D's ("smpl") or the humanoid's own ("deepmimic")

    @property
    def num_frames(self) -> int:
        return int(self.joints.shape[0])

    def features(self) -> np.ndarray:
        """``(N-1, 263)`` HumanML3D features (:func:`clip_features`)."""
        return clip_features(self)


def pybullet_available() -> bool:
    """Whether the optional pybullet dependency can be imported."""
    try:
        import pybullet  # noqa: F401
        import pybullet_data  # noqa: F401
    except ImportError:
        return False
    return True


def _require():
    try:
        import pybullet
        import pybullet_data
    except ImportError as err:
        raise ImportError(_INSTALL_HINT) from err
    return pybullet, pybullet_data


def _motions_dir() -> Path:
    _, data = _require()
    return Path(data.getDataPath()) / "data" / "motions"


def available_clips() -> list[str]:
    """Names of the humanoid clips shipped with pybullet (``walker/...`` for the walker set)."""
    root = _motions_dir()
    names = sorted(p.stem[len("humanoid3d_"):] for p in root.glob("humanoid3d_*.txt"))
    names += sorted(f"walker/{p.stem}" for p in (root / "walker").glob("*.txt"))
    return names


def clip_path(name: str) -> Path:
    """The file of clip ``name`` (see :func:`available_clips`)."""
    root = _motions_dir()
    path = root / (f"{name}.txt" if name.startswith("walker/") else f"humanoid3d_{name}.txt")
    if not path.is_file():
        raise ValueError(f"unknown DeepMimic clip {name!r}; available: {available_clips()}")
    return path


def _read_frames(path: Path) -> tuple[np.ndarray, bool]:
    doc = json.loads(Path(path).read_text())
    frames = np.asarray(doc.get("Frames", []), dtype=np.float64)
    if frames.ndim != 2 or frames.shape[1] != _FRAME_WIDTH or len(frames) < 2:
        raise ValueError(f"{path} is not a DeepMimic humanoid clip: expected frames of {_FRAME_WIDTH} values, "
                         f"got shape {frames.shape}")
    return frames, str(doc.get("Loop", "none")).lower() == "wrap"


def _repeat(frames: np.ndarray, cycles: int) -> np.ndarray:
    """Play a cycle ``cycles`` times; each repetition starts where the last ended (root X/Z)."""
    if cycles == 1:
        return frames
    shift = np.zeros(frames.shape[1])
    shift[[1, 3]] = frames[-1, [1, 3]] - frames[0, [1, 3]]
    # a cycle's last frame is the next cycle's first (shifted), so every cycle but the last
    # drops it (its pose is a few degrees of heading off the first in some clips; the next cycle's
    # first frame wins) and its zero duration never enters the sequence
    parts = [frames[:-1] + c * shift for c in range(cycles - 1)] + [frames + (cycles - 1) * shift]
    return np.concatenate(parts)


def _slerp(q0: np.ndarray, q1: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Row-wise slerp of unit quaternions ``(N, 4)`` with fractions ``(N,)`` (shortest arc)."""
    dot = (q0 * q1).sum(-1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-6
    s = np.sin(theta)
    w0 = np.where(small, 1.0 - f, np.sin((1.0 - f) * theta) / np.where(small, 1.0, s))
    w1 = np.where(small, f, np.sin(f * theta) / np.where(small, 1.0, s))
    out = w0[:, None] * q0 + w1[:, None] * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _resample(frames: np.ndarray, fps: float) -> np.ndarray:
    """Frames at their own durations -> frames at ``fps`` (same layout, duration column = 1/fps)."""
    dt = frames[:-1, 0]
    if (dt <= 0).any():
        raise ValueError("DeepMimic clip has non-positive frame durations")
    times = np.concatenate([[0.0], np.cumsum(dt)])
    t = np.arange(0.0, times[-1] + 1e-9, 1.0 / fps)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(frames) - 2)
    f = (t - times[k]) / dt[k]
    a, b = frames[k], frames[k + 1]
    out = a + (b - a) * f[:, None]                    # root position and 1-DoF angles
    out[:, 0] = 1.0 / fps
    col = 4
    quats = [(4, 4)] + [(None, n) for _, n in _FRAME_JOINTS]
    for _, n in quats:
        if n == 4:
            out[:, col:col + 4] = _slerp(a[:, col:col + 4], b[:, col:col + 4], f)
        col += n
    return out


def _forward_kinematics(frames: np.ndarray) -> np.ndarray:
    """pybullet forward kinematics: frames ``(N, 44)`` -> HumanML3D joints ``(N, 22, 3)`` in
    DeepMimic axes."""
    p, data = _require()
    sk = get_skeleton("humanml3d")
    cid = p.connect(p.DIRECT)
    try:
        p.setAdditionalSearchPath(data.getDataPath(), physicsClientId=cid)
        body = p.loadURDF("humanoid/humanoid.urdf", [0, 0, 0], globalScaling=_URDF_SCALE, useFixedBase=True,
                          flags=p.URDF_MAINTAIN_LINK_ORDER, physicsClientId=cid)
        names = [p.getJointInfo(body, j, physicsClientId=cid)[1].decode() for j in range(
            p.getNumJoints(body, physicsClientId=cid))]
        if tuple(names) != _LINKS:
            raise RuntimeError(f"unexpected humanoid.urdf joints {names}; expected {_LINKS}")
        idx = [names.index(n) for n, _ in _FRAME_JOINTS]
        links = list(range(len(names)))
        out = np.zeros((len(frames), sk.num_joints, 3))
        sources = [(sk.joint_names.index(j), names.index(link), np.asarray(off))
                   for j, (link, off) in _JOINT_SOURCES.items()]
        for i, fr in enumerate(frames):
            w, x, y, z = fr[4:8]
            p.resetBasePositionAndOrientation(body, fr[1:4].tolist(), [x, y, z, w], physicsClientId=cid)
            positions, col = [], 8
            for _, n in _FRAME_JOINTS:
                v = fr[col:col + n]
                positions.append([v[1], v[2], v[3], v[0]] if n == 4 else [v[0]])
                col += n
            p.resetJointStatesMultiDof(body, idx, positions, physicsClientId=cid)
            states = p.getLinkStates(body, links, computeForwardKinematics=1, physicsClientId=cid)
            for j, link, off in sources:
                pos, orn = states[link][4], states[link][5]
                rot = np.asarray(p.getMatrixFromQuaternion(orn, physicsClientId=cid)).reshape(3, 3)
                out[i, j] = np.asarray(pos) + rot @ off
    finally:
        p.disconnect(physicsClientId=cid)
    return out


@lru_cache(maxsize=1)
def _humanoid_rest() -> np.ndarray:
    frame = [0.05, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0]                 # dt, root xyz, root quat (w, x, y, z)
    for _, n in _FRAME_JOINTS:
        frame += [1.0, 0.0, 0.0, 0.0] if n == 4 else [0.0]
    pose = _forward_kinematics(np.asarray([frame]))[0] @ _TO_HML.T
    out = rest_directions(pose, "humanml3d")
    out.setflags(write=False)
    return out


def humanoid_rest_directions() -> np.ndarray:
    """Rest directions ``(22, 3)`` (:mod:`salad_core.retarget`) of DeepMimic's humanoid as this converter maps it
    to the HumanML3D joints: the rest pose (identity root and joint rotations) through steps 2-4 of the module
    docstring. Its hips are level with the pelvis and its spine, neck and head straight up (needs pybullet)."""
    _require()
    return _humanoid_rest().copy()


def load_clip(name: str | Path, *, fps: float | None = None, cycles: int = 1, rig: str = "smpl") -> DeepMimicClip:
    """Load a DeepMimic clip as HumanML3D joints.

    Parameters
    ----------
    name : str or Path
        A name from :func:`available_clips` or the path of a clip file.
    fps : float, optional
        Output frame rate (default: the HumanML3D skeleton's 20).
    cycles : int
        Play a looping clip this many times (e.g. to reach the 40 frames HumanML3D motions have
        at least); must be 1 for non-looping clips.
    rig : str
        ``"smpl"`` (default): re-posed on HumanML3D's torso geometry, limbs kept (step 5 of the module
        docstring); ``"deepmimic"``: the humanoid's own level hips and straight spine.

    Raises
    ------
    ImportError
        If pybullet (the ``deepmimic`` extra) is not installed.
    """
    _require()
    sk = get_skeleton("humanml3d")
    fps = float(sk.fps if fps is None else fps)
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles must be a positive int, got {cycles!r}")
    if rig not in RIGS:
        raise ValueError(f"rig={rig!r} is unknown; use one of {RIGS}")
    path = Path(name) if Path(str(name)).suffix == ".txt" else clip_path(str(name))
    frames, loop = _read_frames(path)
    if cycles > 1 and not loop:
        raise ValueError(f"clip {str(name)!r} does not loop (Loop: none); it cannot be played {cycles} times")
    source_fps = 1.0 / float(np.median(frames[:-1, 0]))
    frames = _resample(_repeat(frames, cycles), fps)
    joints = _forward_kinematics(frames) @ _TO_HML.T
    if rig == "smpl":
        joints = rerig(joints, _humanoid_rest(), smpl_rest_directions("humanml3d"), "humanml3d")
    key = str(name) if not isinstance(name, Path) and Path(str(name)).suffix != ".txt" else path.stem
    log.info("DeepMimic clip %s: %d frames at %g fps (source %.1f fps, %d cycle(s), %s torso)", key, len(joints), fps,
             source_fps, cycles, rig)
    return DeepMimicClip(key, joints.astype(np.float32), fps, source_fps, loop, cycles,
                         CLIP_PROMPTS.get(key, "a person moves"), rig)


def clip_features(clip: DeepMimicClip) -> np.ndarray:
    """``(N-1, 263)`` HumanML3D features of a clip (retargeted, floored, facing +Z)."""
    if clip.num_frames < 2:
        raise ValueError(f"clip {clip.name!r} has {clip.num_frames} frame(s); features need at least 2")
    return joints_to_features(clip.joints.astype(np.float64), "humanml3d").astype(np.float32)
