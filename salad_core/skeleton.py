"""Skeletons of the HumanML3D (22 joints) and KIT-ML (21 joints) motion formats.

Everything downstream takes joint sets, left/right pairs, feature slices and the body-part
pooling hierarchy from here, never from literals.

The pooling hierarchy is SALAD's (paper §3.1, official ``utils/paramUtil.py``): joints are
pooled to 12 intermediate nodes and then to the 7 latent body parts, in the paper's order
``root, left leg, right leg, spine, left arm, right arm, head``.

KIT-ML left/right follow Guo et al.'s processing convention (joints 11-15 and 5-7 are called
"right"), which is what the KIT feature files and evaluators use.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

__all__ = [
    "Skeleton",
    "get_skeleton",
    "available_skeletons",
    "PART_NAMES",
    "PART_MIRROR",
    "NUM_PARTS",
]

#: The 7 latent body parts, in the paper's plotting order (Fig. 6: root, left lower, ...).
PART_NAMES: tuple[str, ...] = ("root", "left leg", "right leg", "spine", "left arm", "right arm", "head")
NUM_PARTS = len(PART_NAMES)
#: Left/right counterpart of each body part (root, spine and head map to themselves).
PART_MIRROR: tuple[int, ...] = (0, 2, 1, 3, 5, 4, 6)
#: Edges of the 7-part latent graph (official ``paramUtil``).
PART_EDGES: tuple[tuple[int, int], ...] = ((0, 1), (0, 2), (0, 3), (3, 4), (3, 5), (3, 6))

#: Names of the 12 intermediate pooled nodes (shared by HumanML3D and KIT).
MID_NAMES: tuple[str, ...] = (
    "root", "left hip", "left leg", "right hip", "right leg", "spine",
    "chest", "left shoulder", "left arm", "right shoulder", "right arm", "head",
)
#: Edges of the 12-node intermediate graph.
MID_EDGES: tuple[tuple[int, int], ...] = (
    (0, 1), (0, 3), (0, 5), (1, 2), (3, 4), (5, 6), (6, 7), (6, 9), (6, 11), (7, 8), (9, 10),
)
#: 12 -> 7 pooling groups (members are intermediate nodes), for both datasets.
MID_TO_PART: tuple[tuple[int, ...], ...] = (
    (0, 1, 3, 5), (0, 1, 2), (0, 3, 4), (0, 5, 6), (6, 7, 8), (6, 9, 10), (6, 11),
)


@dataclass(frozen=True)
class Skeleton:
    """A joint set with everything the feature format, the VAE and the editing code need.

    Attributes are plain tuples so that the object is hashable and immutable; array views are
    offered as properties.
    """

    name: str                                   # "humanml3d" or "kit"
    joint_names: tuple[str, ...]                # J names
    parents: tuple[int, ...]                    # parent index per joint, -1 for the root
    kinematic_chains: tuple[tuple[int, ...], ...]  # chains used by IK/FK and plotting
    raw_offsets: tuple[tuple[float, float, float], ...]  # unit rest direction per joint
    bone_lengths: tuple[float, ...] | None      # target length of bone parent->joint (root 0)
    fid_l: tuple[int, int]                      # left ankle, left toe
    fid_r: tuple[int, int]                      # right ankle, right toe
    face_joint_indx: tuple[int, int, int, int]  # r_hip, l_hip, r_shoulder, l_shoulder
    leg_bones: tuple[int, int]                  # l_idx1, l_idx2: bones used for the scale ratio
    mirror_pairs: tuple[tuple[int, int], ...]   # (left, right) joint pairs
    joint_to_mid: tuple[tuple[int, ...], ...]   # 12 groups of joints (J -> 12 pooling)
    joint_to_part: tuple[int, ...]              # body part (of the 7) each joint is drawn in
    fps: float                                  # frame rate of the feature files
    min_length: int                             # shortest clip the loaders keep (frames)
    max_length: int = 196                       # longest motion the models handle (frames)
    foot_threshold: float = 0.002               # squared displacement per frame for contact
    unit_length: int = 4                        # temporal down-sampling of the latent
    feature_scale: float = 1.0                  # length unit in metres (KIT is ~mm)

    def __post_init__(self) -> None:
        j = len(self.joint_names)
        if len(self.parents) != j or len(self.raw_offsets) != j:
            raise ValueError(f"skeleton {self.name!r}: names, parents and offsets differ in length")
        if self.bone_lengths is not None and len(self.bone_lengths) != j:
            raise ValueError(f"skeleton {self.name!r}: bone_lengths must have {j} entries")
        if self.parents[0] != -1 or any(p >= i for i, p in enumerate(self.parents) if i > 0):
            raise ValueError(f"skeleton {self.name!r}: parents must be topologically ordered")
        if len(self.joint_to_part) != j:
            raise ValueError(f"skeleton {self.name!r}: joint_to_part must have {j} entries")
        if len(self.joint_to_mid) != len(MID_NAMES):
            raise ValueError(f"skeleton {self.name!r}: joint_to_mid must have {len(MID_NAMES)} groups")

    # ----------------------------------------------------------------- sizes
    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def feature_dim(self) -> int:
        """Width of the HumanML3D-style feature vector: 4 + 9(J-1) + 3J + 4 (263 / 251)."""
        j = self.num_joints
        return 4 + 9 * (j - 1) + 3 * j + 4

    @property
    def contact_joints(self) -> tuple[int, int, int, int]:
        """Joints of the 4 contact channels in feature order: left pair, then right pair."""
        return (*self.fid_l, *self.fid_r)

    @property
    def num_parts(self) -> int:
        return NUM_PARTS

    @property
    def part_names(self) -> tuple[str, ...]:
        return PART_NAMES

    @property
    def part_mirror(self) -> tuple[int, ...]:
        return PART_MIRROR

    # -------------------------------------------------------- feature layout
    @cached_property
    def feature_slices(self) -> dict[str, slice]:
        """Slices of the feature vector, in HumanML3D order (see ``humanml3d_eval_facts`` §2.1)."""
        j = self.num_joints
        ric0 = 4
        rot0 = ric0 + 3 * (j - 1)
        vel0 = rot0 + 6 * (j - 1)
        con0 = vel0 + 3 * j
        return {
            "root_rot_vel": slice(0, 1),
            "root_lin_vel": slice(1, 3),
            "root_y": slice(3, 4),
            "root": slice(0, 4),
            "ric": slice(ric0, rot0),
            "rot": slice(rot0, vel0),
            "local_vel": slice(vel0, con0),
            "contacts": slice(con0, con0 + 4),
        }

    @cached_property
    def joint_feature_index(self) -> tuple[tuple[int, ...], ...]:
        """Feature columns gathered into one token per joint (the SALAD VAE's joint split).

        Root: the 4 root dims then its local velocity (7). Joint j>=1: ric (3), rot6d (6),
        local velocity (3), and the contact channel last for the 4 contact joints (13).
        The union over joints is every column exactly once.
        """
        s = self.feature_slices
        cols: list[tuple[int, ...]] = []
        for jnt in range(self.num_joints):
            vel = tuple(range(s["local_vel"].start + 3 * jnt, s["local_vel"].start + 3 * jnt + 3))
            if jnt == 0:
                idx = tuple(range(0, 4)) + vel
            else:
                ric = tuple(range(s["ric"].start + 3 * (jnt - 1), s["ric"].start + 3 * jnt))
                rot = tuple(range(s["rot"].start + 6 * (jnt - 1), s["rot"].start + 6 * jnt))
                idx = ric + rot + vel
                if jnt in self.contact_joints:
                    idx = idx + (s["contacts"].start + self.contact_joints.index(jnt),)
            cols.append(idx)
        return tuple(cols)

    # --------------------------------------------------------------- graphs
    @cached_property
    def edges(self) -> tuple[tuple[int, int], ...]:
        """Undirected bone edges (parent, child)."""
        return tuple((p, c) for c, p in enumerate(self.parents) if p >= 0)

    @cached_property
    def neighbors(self) -> tuple[tuple[int, ...], ...]:
        """Graph-distance-1 neighbours of each joint (self excluded), sorted."""
        nb: list[set[int]] = [set() for _ in range(self.num_joints)]
        for a, b in self.edges:
            nb[a].add(b)
            nb[b].add(a)
        return tuple(tuple(sorted(s)) for s in nb)

    @property
    def adjacency(self) -> np.ndarray:
        """``(J, J)`` boolean adjacency without self loops."""
        return edges_to_adjacency(self.edges, self.num_joints)

    @cached_property
    def mirror_map(self) -> tuple[int, ...]:
        """Index of each joint's left/right counterpart (itself on the mid-line)."""
        m = list(range(self.num_joints))
        for a, b in self.mirror_pairs:
            m[a], m[b] = b, a
        return tuple(m)

    @property
    def pooling_levels(self) -> tuple[tuple[tuple[int, ...], ...], ...]:
        """Pooling groups per level: J -> 12 (joint groups), then 12 -> 7 (node groups)."""
        return (self.joint_to_mid, MID_TO_PART)

    @property
    def level_edges(self) -> tuple[tuple[tuple[int, int], ...], ...]:
        """Graph edges at each resolution: joints, 12 intermediate nodes, 7 parts."""
        return (self.edges, MID_EDGES, PART_EDGES)

    @property
    def target_offsets(self) -> np.ndarray:
        """``(J, 3)`` rest offsets of the target skeleton: raw direction x bone length."""
        if self.bone_lengths is None:
            raise ValueError(f"skeleton {self.name!r} has no target bone lengths")
        return np.asarray(self.raw_offsets, dtype=np.float64) * np.asarray(self.bone_lengths)[:, None]

    def pool_matrix(self, level: int) -> np.ndarray:
        """``(J_out, J_in)`` mean-pooling matrix of a level (rows sum to 1)."""
        groups = self.pooling_levels[level]
        n_in = self.num_joints if level == 0 else len(MID_NAMES)
        mat = np.zeros((len(groups), n_in), dtype=np.float32)
        for i, g in enumerate(groups):
            mat[i, list(g)] = 1.0 / len(g)
        return mat

    def unpool_matrix(self, level: int) -> np.ndarray:
        """``(J_in, J_out)`` binary membership (transpose of the pooling pattern)."""
        return (self.pool_matrix(level) > 0).astype(np.float32).T


def edges_to_adjacency(edges, n: int) -> np.ndarray:
    """``(n, n)`` symmetric boolean adjacency from undirected edges, no self loops."""
    adj = np.zeros((n, n), dtype=bool)
    for a, b in edges:
        adj[a, b] = adj[b, a] = True
    return adj


_HML_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
    "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist",
)

HUMANML3D = Skeleton(
    name="humanml3d",
    joint_names=_HML_NAMES,
    parents=(-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19),
    kinematic_chains=(
        (0, 2, 5, 8, 11), (0, 1, 4, 7, 10), (0, 3, 6, 9, 12, 15),
        (9, 14, 17, 19, 21), (9, 13, 16, 18, 20),
    ),
    raw_offsets=(
        (0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, -1, 0), (0, 1, 0),
        (0, -1, 0), (0, -1, 0), (0, 1, 0), (0, 0, 1), (0, 0, 1), (0, 1, 0), (1, 0, 0),
        (-1, 0, 0), (0, 0, 1), (0, -1, 0), (0, -1, 0), (0, -1, 0), (0, -1, 0), (0, -1, 0),
        (0, -1, 0),
    ),
    # Target skeleton "000021": every processed HumanML3D clip has exactly these bone lengths.
    bone_lengths=(
        0.0, 0.10307, 0.10988, 0.13157, 0.39362, 0.39019, 0.14319, 0.43243, 0.42564, 0.05736,
        0.14338, 0.14942, 0.21936, 0.13749, 0.14338, 0.10304, 0.13161, 0.12298, 0.25684,
        0.26309, 0.26601, 0.26988,
    ),
    fid_l=(7, 10),
    fid_r=(8, 11),
    face_joint_indx=(2, 1, 17, 16),
    leg_bones=(5, 8),
    mirror_pairs=((1, 2), (4, 5), (7, 8), (10, 11), (13, 14), (16, 17), (18, 19), (20, 21)),
    joint_to_mid=(
        (0, 1, 2, 3), (0, 1, 4), (4, 7, 10), (0, 2, 5), (5, 8, 11), (0, 3, 6, 9),
        (9, 6, 12, 13, 14), (9, 13, 16), (16, 18, 20), (9, 14, 17), (17, 19, 21), (9, 12, 15),
    ),
    joint_to_part=(0, 1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2, 6, 4, 5, 6, 4, 5, 4, 5, 4, 5),
    fps=20.0,
    min_length=40,
)

_KIT_NAMES = (
    "root", "BP", "BT", "BLN", "BUN", "RS", "RE", "RW", "LS", "LE", "LW",
    "RH", "RK", "RA", "RMrot", "RF", "LH", "LK", "LA", "LMrot", "LF",
)
# Names follow Guo et al.'s left/right convention (11 and 5 are "right"), see module docstring.

KIT = Skeleton(
    name="kit",
    joint_names=_KIT_NAMES,
    parents=(-1, 0, 1, 2, 3, 3, 5, 6, 3, 8, 9, 0, 11, 12, 13, 14, 0, 16, 17, 18, 19),
    kinematic_chains=(
        (0, 11, 12, 13, 14, 15), (0, 16, 17, 18, 19, 20), (0, 1, 2, 3, 4), (3, 5, 6, 7), (3, 8, 9, 10),
    ),
    raw_offsets=(
        (0, 0, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (1, 0, 0), (0, -1, 0), (0, -1, 0),
        (-1, 0, 0), (0, -1, 0), (0, -1, 0), (1, 0, 0), (0, -1, 0), (0, -1, 0), (0, 0, 1),
        (0, 0, 1), (-1, 0, 0), (0, -1, 0), (0, -1, 0), (0, 0, 1), (0, 0, 1),
    ),
    bone_lengths=None,  # KIT's target skeleton ("03950") is not embedded; retargeting is skipped
    fid_l=(19, 20),
    fid_r=(14, 15),
    face_joint_indx=(11, 16, 5, 8),
    leg_bones=(17, 18),
    mirror_pairs=((16, 11), (17, 12), (18, 13), (19, 14), (20, 15), (8, 5), (9, 6), (10, 7)),
    joint_to_mid=(
        (0, 1, 11, 16), (0, 16, 17, 18), (17, 18, 19, 20), (0, 11, 12, 13), (12, 13, 14, 15),
        (0, 1, 2, 3), (2, 3, 5, 8, 4), (3, 8, 9), (8, 9, 10), (3, 5, 6), (5, 6, 7), (3, 4),
    ),
    # the official KIT colouring sends both arms to part 4; here each arm goes to its own part
    joint_to_part=(0, 3, 3, 3, 6, 5, 5, 5, 4, 4, 4, 2, 2, 2, 2, 2, 1, 1, 1, 1, 1),
    fps=12.5,
    min_length=24,
    foot_threshold=0.05,
    feature_scale=1e-3,
)

_SKELETONS = {"humanml3d": HUMANML3D, "kit": KIT}
_ALIASES = {"t2m": "humanml3d", "hml3d": "humanml3d", "humanml": "humanml3d", "kit-ml": "kit", "kitml": "kit"}


def available_skeletons() -> tuple[str, ...]:
    return tuple(_SKELETONS)


def get_skeleton(name: str | Skeleton = "humanml3d") -> Skeleton:
    """Return a skeleton by name (``"humanml3d"`` or ``"kit"``; aliases ``t2m``, ``kit-ml``).

    A :class:`Skeleton` passes through unchanged, so functions can accept either.
    """
    if isinstance(name, Skeleton):
        return name
    if not isinstance(name, str):
        raise TypeError(f"skeleton must be a name or a Skeleton, got {type(name).__name__}")
    key = _ALIASES.get(name.lower(), name.lower())
    if key not in _SKELETONS:
        raise ValueError(f"unknown skeleton {name!r}; known skeletons: {', '.join(_SKELETONS)}")
    return _SKELETONS[key]
