"""Mapping the joints of a BVH rig to the 22 HumanML3D joints.

Rig styles recognised by name (:data:`RIG_STYLES`):

``smpl``
    SMPL / HumanML3D names: ``pelvis, left_hip, left_knee, left_ankle, left_foot, spine1, spine2,
    spine3, neck, left_collar, head, left_shoulder, left_elbow, left_wrist``, ... and the ``Pelvis,
    L_Hip, L_Knee, ...`` variants (also with the ``m_avg_`` prefix of SMPL's FBX files). This
    project's own BVH export (:func:`salad_viz.export.export_bvh`) writes these names.
``mixamo``
    ``Hips, Spine, Spine1, Spine2, Neck, Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand,
    LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase``, ..., with or without the ``mixamorig:`` prefix.
``cmu``
    The CMU motion-capture BVH conversion: ``Hips, LHipJoint, LeftUpLeg, LeftLeg, LeftFoot,
    LeftToeBase, LowerBack, Spine, Spine1, Neck, Neck1, Head, LeftShoulder, LeftArm, LeftForeArm,
    LeftHand``, ...
``generic``
    Common synonyms of other tools (Unity ``UpperLeg/LowerLeg/UpperArm/LowerArm/Toes/Chest``,
    Unreal ``thigh_l/calf_l/ball_l/clavicle_l/upperarm_l/lowerarm_l``, 3ds Max Biped
    ``Bip01 L Thigh/Calf/Toe0/Clavicle``).

Names are compared after normalisation (:func:`normalize_name`): the part after the last ``:``
(namespaces such as ``mixamorig:``), lower case, letters and digits only, known prefixes
(``mixamorig``, ``m_avg_``, ``f_avg_``, ``Bip01``) removed. The style is chosen automatically as
the one that recognises the most joint names of the file among those that can map every joint
(``rig=`` forces one), and a user name map (``{humanml3d_joint: rig_joint}``; the reverse
direction is accepted too) overrides any joint.

Joints without a counterpart are placed, not invented:

* **spine** (``spine1, spine2, spine3, neck``): HumanML3D's spine is ``pelvis - spine1 - spine2 -
  spine3 - neck - head`` with the collars hanging from ``spine3``. When the rig has no joint of
  that name, ``spine3`` is the rig joint both collars hang from (if it lies between pelvis and
  head); the remaining ones are placed along the rig's own spine, the polyline of rig joints
  between the nearest mapped spine joints below and above, at the arc-length fractions of
  HumanML3D's target skeleton (e.g. ``spine1`` at 0.40 and ``spine2`` at 0.83 of the way from the
  pelvis to ``spine3``). A rig with fewer spine joints (CMU: ``LowerBack, Spine, Spine1``) thus
  gets a spine that follows its own curve; a rig with more keeps the named ones and its extra
  joints only shape the polyline.
* **toes** (``left_foot``, ``right_foot``): the End Site below the ankle joint, or its only child.
* **collars** placed on the spine: some rigs put the clavicle joint (CMU's ``LeftShoulder``) at
  zero offset from the spine, where HumanML3D's collar lies half-way out to the shoulder; such a
  collar (zero rest offset from its parent) is placed along the rig's clavicle, spine -> shoulder
  joint, at HumanML3D's proportion (0.51).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from salad_core.skeleton import get_skeleton

__all__ = ["RigError", "RigMapping", "RIG_STYLES", "SPINE_CHAIN", "normalize_name", "map_rig", "load_name_map"]

_SK = get_skeleton("humanml3d")
HML_NAMES: tuple[str, ...] = _SK.joint_names
#: HumanML3D's spine chain, pelvis to head.
SPINE_CHAIN: tuple[str, ...] = ("pelvis", "spine1", "spine2", "spine3", "neck", "head")
_INTERPOLABLE = frozenset({"spine1", "spine2", "spine3", "neck"})
_TOES = {"left_foot": "left_ankle", "right_foot": "right_ankle"}
_PREFIXES = ("mixamorig", "mavg", "favg", "bip01", "bip001")


class RigError(ValueError):
    """The joints of a rig cannot be mapped to the HumanML3D joints (the message lists which)."""


def normalize_name(name: str) -> str:
    """Comparable form of a joint name: ``"mixamorig:LeftUpLeg"`` -> ``"leftupleg"``,
    ``"m_avg_L_Hip"`` -> ``"lhip"``, ``"Bip01 L Thigh"`` -> ``"lthigh"``."""
    n = re.sub(r"[^a-z0-9]", "", name.split(":")[-1].lower())
    for prefix in _PREFIXES:
        if n.startswith(prefix) and len(n) > len(prefix):
            n = n[len(prefix):]
            break
    return n


def _side(side: str, bases: Sequence[str]) -> tuple[str, ...]:
    word = "left" if side == "l" else "right"
    out: list[str] = []
    for b in bases:
        out += [word + b, side + b, b + word, b + side]
    return tuple(out)


def _style(spec: dict[str, tuple[str, ...]], known: Sequence[str] = ()) -> tuple[dict[str, tuple[str, ...]], frozenset]:
    """Expand ``{"*hip": bases}`` into left/right HumanML3D joints; collect every recognised name."""
    joints: dict[str, tuple[str, ...]] = {}
    for key, bases in spec.items():
        if key.startswith("*"):
            joints[f"left_{key[1:]}"] = _side("l", bases)
            joints[f"right_{key[1:]}"] = _side("r", bases)
        else:
            joints[key] = tuple(bases)
    unknown = set(joints) - set(HML_NAMES)
    assert not unknown, unknown
    names = {c for cands in joints.values() for c in cands}
    for k in known:
        names.update(_side("l", [k[1:]]) + _side("r", [k[1:]]) if k.startswith("*") else [k])
    return joints, frozenset(names)


#: Rig styles: HumanML3D joint -> candidate normalised names (first present wins), and every name
#: the style recognises (used to choose the style).
RIG_STYLES: dict[str, tuple[dict[str, tuple[str, ...]], frozenset]] = {
    "smpl": _style({
        "pelvis": ("pelvis",), "*hip": ("hip",), "*knee": ("knee",), "*ankle": ("ankle",), "*foot": ("foot",),
        "spine1": ("spine1",), "spine2": ("spine2",), "spine3": ("spine3",), "neck": ("neck",),
        "*collar": ("collar",), "head": ("head",), "*shoulder": ("shoulder",), "*elbow": ("elbow",),
        "*wrist": ("wrist",)}, known=("jaw", "*hand", "*eye", "*eyesmplhf")),
    "mixamo": _style({
        "pelvis": ("hips",), "*hip": ("upleg",), "*knee": ("leg",), "*ankle": ("foot",), "*foot": ("toebase",),
        "spine1": ("spine",), "spine2": ("spine1",), "spine3": ("spine2",), "neck": ("neck",), "head": ("head",),
        "*collar": ("shoulder",), "*shoulder": ("arm",), "*elbow": ("forearm",), "*wrist": ("hand",)},
        known=("headtopend", "*toeend", *(f"*hand{f}{i}" for f in ("thumb", "index", "middle", "ring", "pinky")
                                          for i in range(1, 5)))),
    "cmu": _style({
        "pelvis": ("hips",), "*hip": ("upleg",), "*knee": ("leg",), "*ankle": ("foot",), "*foot": ("toebase",),
        "spine3": ("spine1",), "neck": ("neck1",), "head": ("head",),
        "*collar": ("shoulder",), "*shoulder": ("arm",), "*elbow": ("forearm",), "*wrist": ("hand",)},
        known=("lowerback", "spine", "neck", "lhipjoint", "rhipjoint", "*fingerbase", "*handindex1",
               "lthumb", "rthumb")),
    "generic": _style({
        "pelvis": ("hips", "pelvis", "hip"),
        "*hip": ("upleg", "upperleg", "thigh", "hip"),
        "*knee": ("lowerleg", "calf", "shin", "knee", "leg"),
        "*ankle": ("ankle", "foot"),
        "*foot": ("toebase", "toes", "toe", "toe0", "ball"),
        "spine3": ("upperchest", "chest", "spine3"),
        "neck": ("neck", "neck01", "neck1"),
        "head": ("head",),
        "*collar": ("clavicle", "collar", "shoulder"),
        "*shoulder": ("upperarm", "arm", "shoulder"),
        "*elbow": ("forearm", "lowerarm", "elbow"),
        "*wrist": ("hand", "wrist")},
        known=("spine", "spine01", "spine02", "spine03", "spine1", "spine2", "root")),
}


@dataclass(frozen=True)
class _Interp:
    """A joint placed along the rig polyline ``path`` (point indices) at ``fraction`` of its length."""

    path: tuple[int, ...]
    fraction: float


@dataclass(frozen=True)
class RigMapping:
    """Where each of the 22 HumanML3D joints comes from in a rig.

    Attributes
    ----------
    style : str
        The rig style used (a key of :data:`RIG_STYLES`), with ``"+map"`` when a user name map
        overrode joints.
    sources : tuple of 22 (int or _Interp)
        Point index (joints and End Sites, as :meth:`BvhMotion.point_names`) or a placement along
        the rig's spine.
    point_names : tuple of str
        The rig's point names (for :meth:`describe`).
    """

    style: str
    sources: tuple
    point_names: tuple[str, ...]

    def describe(self) -> dict[str, str]:
        """``{humanml3d_joint: "RigJoint"}`` or ``"along A > B > C at 0.40"`` for placed joints."""
        out = {}
        for name, src in zip(HML_NAMES, self.sources):
            if isinstance(src, _Interp):
                chain = " > ".join(self.point_names[i] for i in src.path)
                out[name] = f"along {chain} at {src.fraction:.2f}"
            else:
                out[name] = self.point_names[src]
        return out

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Rig points ``(N, P, 3)`` -> HumanML3D joints ``(N, 22, 3)`` (float64)."""
        pts = np.asarray(points, dtype=np.float64)
        out = np.empty(pts.shape[:-2] + (len(HML_NAMES), 3))
        for j, src in enumerate(self.sources):
            out[..., j, :] = _along(pts[..., list(src.path), :], src.fraction) if isinstance(src, _Interp) \
                else pts[..., src, :]
        return out


def _along(poly: np.ndarray, fraction: float) -> np.ndarray:
    """The point at ``fraction`` of the arc length of polylines ``(..., M, 3)`` -> ``(..., 3)``.

    Each segment contributes the part of it that lies before the target arc length, so the sum
    walks the polyline; zero-length segments contribute nothing.
    """
    seg = np.diff(poly, axis=-2)                                   # (..., M-1, 3)
    length = np.linalg.norm(seg, axis=-1)                          # (..., M-1)
    cum = np.concatenate([np.zeros(length.shape[:-1] + (1,)), np.cumsum(length, axis=-1)], axis=-1)
    target = fraction * cum[..., -1:]
    used = np.clip((target - cum[..., :-1]) / np.maximum(length, 1e-12), 0.0, 1.0)
    return poly[..., 0, :] + (used[..., None] * seg).sum(axis=-2)


def load_name_map(name_map: Mapping[str, str] | str | os.PathLike | None) -> dict[str, str]:
    """A user name map as ``{humanml3d_joint: rig_joint}``.

    Parameters
    ----------
    name_map : dict, JSON file path or None
        ``{humanml3d_joint: rig_joint}`` or the reverse ``{rig_joint: humanml3d_joint}`` (told apart
        by which side holds HumanML3D joint names), as a dict or a JSON file holding one object.

    Raises
    ------
    RigError
        If the map is not an object of strings, or a key is not a HumanML3D joint name; for a file,
        also if it is over 1 MiB, not UTF-8 text (a binary file) or not valid JSON.
    """
    if name_map is None:
        return {}
    if isinstance(name_map, (str, os.PathLike)):
        from salad_core import limits

        path = Path(name_map)
        if not path.is_file():
            raise RigError(f"name_map: file not found: {path}")
        # size, UTF-8 (a binary file given by mistake), nesting and an object at the top, before parsing
        name_map = limits.read_json(path, "name map", max_bytes=limits.NAME_MAP_MAX_BYTES,
                                    error=lambda msg: RigError(f"name_map: {msg}"), expect=None)
    if not isinstance(name_map, Mapping) or not all(isinstance(k, str) and isinstance(v, str)
                                                    for k, v in name_map.items()):
        import reprlib

        raise RigError(f"name_map must map joint names to joint names (strings), got {reprlib.repr(name_map)}")
    out = dict(name_map)
    hml = set(HML_NAMES)
    if out and not set(out) <= hml and set(out.values()) <= hml:
        out = {v: k for k, v in out.items()}          # given as {rig_joint: humanml3d_joint}
    bad = sorted(set(out) - hml)
    if bad:
        what = "is not a HumanML3D joint name" if len(bad) == 1 else "are not HumanML3D joint names"
        raise RigError(f"name_map: {', '.join(map(repr, bad))} {what}; allowed keys: {', '.join(HML_NAMES)}")
    return out


def _match_style(style: str, names: Sequence[str], taken: set[int] | None = None) -> dict[str, int]:
    """HumanML3D joint -> rig joint index, by the style's candidate names (each rig joint once)."""
    cands, _ = RIG_STYLES[style]
    index: dict[str, int] = {}
    for i, n in enumerate(names):
        index.setdefault(normalize_name(n), i)
    used = set(taken or ())
    out: dict[str, int] = {}
    for hml in HML_NAMES:
        for c in cands.get(hml, ()):
            i = index.get(c)
            if i is not None and i not in used:
                out[hml] = i
                used.add(i)
                break
    return out


def _ancestry(point: int, parents: Sequence[int]) -> list[int]:
    chain = [point]
    while parents[chain[-1]] >= 0:
        chain.append(parents[chain[-1]])
    return chain


def _resolve(direct: dict[str, int], joint_names: Sequence[str], point_parents: Sequence[int],
             rest: np.ndarray | None = None) -> tuple[dict[str, object], list[str]]:
    """Complete a direct mapping with the structural rules (module docstring); return it and the
    HumanML3D joints still missing."""
    out: dict[str, object] = dict(direct)
    used = set(direct.values())
    _place_toes(out, used, len(joint_names), point_parents)
    if "pelvis" in out and "head" in out:
        head_up = _ancestry(out["head"], point_parents)                       # head, ..., root
        if out["pelvis"] in head_up:
            spine_path = head_up[: head_up.index(out["pelvis"]) + 1][::-1]   # pelvis, ..., head
            _place_spine3(out, used, spine_path, point_parents)
            _place_spine(out, spine_path)
    if rest is not None:
        _place_collars(out, point_parents, rest)
    return out, [n for n in HML_NAMES if n not in out]


def _place_toes(out: dict, used: set, n_joints: int, point_parents: Sequence[int]) -> None:
    """Unmapped toes: the End Site below the ankle, or the ankle's only child joint."""
    for toe, ankle in _TOES.items():
        if toe in out or ankle not in out:
            continue
        kids = [i for i, p in enumerate(point_parents) if p == out[ankle] and i not in used]
        ends = [i for i in kids if i >= n_joints]
        joints = [i for i in kids if i < n_joints]
        pick = ends[0] if ends else (joints[0] if len(joints) == 1 else None)
        if pick is not None:
            out[toe] = pick
            used.add(pick)


def _place_spine3(out: dict, used: set, spine_path: list[int], point_parents: Sequence[int]) -> None:
    """Unmapped spine3: the rig joint both collars hang from, if strictly between pelvis and head."""
    if "spine3" in out or "left_collar" not in out or "right_collar" not in out:
        return
    pl, pr = point_parents[out["left_collar"]], point_parents[out["right_collar"]]
    if pl == pr and pl in spine_path[1:-1] and pl not in used:
        out["spine3"] = pl
        used.add(pl)


def _place_spine(out: dict, spine_path: list[int]) -> None:
    """Unmapped spine joints: along the rig's spine between the nearest mapped spine joints, at
    the arc-length fractions of HumanML3D's target bone lengths."""
    lengths = dict(zip(HML_NAMES, _SK.bone_lengths))
    anchors = {k: out[n] for k, n in enumerate(SPINE_CHAIN) if n in out}   # pelvis and head included
    for k, name in enumerate(SPINE_CHAIN):
        if name in out:
            continue
        lo, hi = max(i for i in anchors if i < k), min(i for i in anchors if i > k)
        a, b = anchors[lo], anchors[hi]
        if a not in spine_path or b not in spine_path or spine_path.index(a) > spine_path.index(b):
            continue    # the named spine joints are not in chain order: left missing (reported)
        path = tuple(spine_path[spine_path.index(a): spine_path.index(b) + 1])
        seg = [lengths[SPINE_CHAIN[i]] for i in range(lo + 1, hi + 1)]          # bone i-1 -> i
        out[name] = _Interp(path, float(sum(seg[: k - lo]) / sum(seg)))


def _place_collars(out: dict, point_parents: Sequence[int], rest: np.ndarray) -> None:
    """Collars at zero rest offset from their parent: along the clavicle, at HumanML3D's proportion."""
    size = float(np.ptp(rest, axis=0).max()) or 1.0
    lengths = dict(zip(HML_NAMES, _SK.bone_lengths))
    for side in ("left", "right"):
        c, sh = out.get(f"{side}_collar"), out.get(f"{side}_shoulder")
        if not (isinstance(c, int) and isinstance(sh, int)) or point_parents[c] < 0:
            continue
        up = _ancestry(sh, point_parents)
        if c in up and np.linalg.norm(rest[c] - rest[point_parents[c]]) < 1e-6 * size:
            a, b = lengths[f"{side}_collar"], lengths[f"{side}_shoulder"]
            out[f"{side}_collar"] = _Interp(tuple(up[: up.index(c) + 1][::-1]), a / (a + b))


def map_rig(joint_names: Sequence[str], point_names: Sequence[str], point_parents: Sequence[int], *,
            rest: np.ndarray | None = None, name_map: Mapping[str, str] | str | os.PathLike | None = None,
            style: str | None = None, source: str = "the file") -> RigMapping:
    """Map a rig to the 22 HumanML3D joints.

    Parameters
    ----------
    joint_names : sequence of str
        The rig's joints (``BvhMotion.joint_names``).
    point_names, point_parents : sequences
        Joints then End Sites with their parents (``BvhMotion.point_names()`` / ``point_parents()``).
    rest : ndarray (P, 3), optional
        Rest-pose positions of the points (``BvhMotion.world_positions(rest=True)[0]``): finds
        collars placed on the spine.
    name_map : dict or JSON path, optional
        User overrides ``{humanml3d_joint: rig_joint}`` (see :func:`load_name_map`).
    style : str, optional
        Force a rig style (a key of :data:`RIG_STYLES`); default: detect.
    source : str
        How to name the rig in errors (e.g. the file path).

    Returns
    -------
    RigMapping

    Raises
    ------
    RigError
        When a joint cannot be mapped: the message lists the missing HumanML3D joints and the
        rig's joint names, and says how to pass a name map.
    """
    if style is not None and style not in RIG_STYLES:
        raise RigError(f"rig style {style!r} is not known; allowed: {', '.join(RIG_STYLES)} (or None to detect)")
    user = load_name_map(name_map)
    user_idx: dict[str, int] = {}
    exact = {n: i for i, n in reversed(list(enumerate(joint_names)))}
    norm = {}
    for i, n in reversed(list(enumerate(joint_names))):
        norm[normalize_name(n)] = i
    for hml, rig_name in user.items():
        i = exact.get(rig_name, norm.get(normalize_name(rig_name)))
        if i is None:
            raise RigError(f"name_map: {source} has no joint {rig_name!r} (given for {hml}); its joints: "
                           f"{', '.join(joint_names)}")
        user_idx[hml] = i
    if len(set(user_idx.values())) != len(user_idx):
        raise RigError(f"name_map maps two HumanML3D joints to the same rig joint: {user}")

    styles = [style] if style is not None else list(RIG_STYLES)
    normalized = {normalize_name(n) for n in joint_names}
    best = None
    for s in styles:
        direct = _match_style(s, joint_names, taken=set(user_idx.values()))
        direct.update(user_idx)
        resolved, missing = _resolve(direct, joint_names, point_parents, rest)
        score = (not missing, len(normalized & RIG_STYLES[s][1]), len(direct))
        if best is None or score > best[0]:
            best = (score, s, resolved, missing)
    _, s, resolved, missing = best
    if missing:
        hint = ("pass a name map {humanml3d_joint: rig_joint} for them (name_map= or --name-map FILE.json)")
        forced = f" as a {style!r} rig" if style is not None else f" (closest rig style: {s})"
        raise RigError(f"cannot map the joints of {source} to the 22 HumanML3D joints{forced}: missing "
                       f"{', '.join(missing)}; the file's joints are {', '.join(joint_names)}; {hint}")
    label = s + ("+map" if user else "")
    return RigMapping(label, tuple(resolved[n] for n in HML_NAMES), tuple(point_names))
