"""Colours shared by every salad_viz view: kinematic chains, motion themes, body parts, floor.

A single motion is drawn with one colour per kinematic chain, left limbs in blues and right
limbs in reds (the official SALAD plots use red/blue for the two sides too). When several motions
share one scene (source vs edited, original vs mirrored) each motion gets a *theme*: one hue whose
shades still separate the chains, so that motions differ at a glance and chains stay readable.

Colours are RGB floats in ``[0, 1]``; :func:`to_uint8` converts for images.
"""
from __future__ import annotations

import colorsys
from functools import lru_cache

import numpy as np

from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

__all__ = [
    "BACKGROUND",
    "FLOOR_LIGHT",
    "FLOOR_DARK",
    "TRAJECTORY",
    "THEME_HUES",
    "SIDE_COLORS",
    "chain_sides",
    "chain_palette",
    "joint_chain",
    "bone_colors",
    "motion_bone_colors",
    "part_colors",
    "to_rgb",
    "to_uint8",
]

BACKGROUND = (1.0, 1.0, 1.0)
FLOOR_LIGHT = (0.90, 0.90, 0.90)
FLOOR_DARK = (0.78, 0.78, 0.78)
TRAJECTORY = (0.15, 0.35, 0.85)

#: Chain colours (RGB floats) by body side: left = blues, right = reds, mid-line (spine, head) =
#: charcoal. Two shades per side so that a leg and an arm on the same side stay distinct.
SIDE_COLORS = {
    "left": ((0.12, 0.35, 0.80), (0.30, 0.65, 0.95)),
    "right": ((0.80, 0.15, 0.15), (0.95, 0.55, 0.15)),
    "mid": ((0.22, 0.22, 0.22), (0.45, 0.45, 0.45)),
}

#: Hues (degrees) of the per-motion themes used when several motions share a scene:
#: blue, orange, green, purple, teal, brown.
THEME_HUES = (215.0, 28.0, 130.0, 280.0, 180.0, 10.0)


def to_rgb(color) -> tuple[float, float, float]:
    """Any matplotlib colour spec (name, hex, RGB floats or 0-255 ints) as RGB floats."""
    if isinstance(color, (tuple, list, np.ndarray)) and len(color) in (3, 4):
        arr = np.asarray(color, dtype=np.float64)[:3]
        if arr.max() > 1.0:
            arr = arr / 255.0
        return tuple(float(x) for x in np.clip(arr, 0.0, 1.0))
    from matplotlib.colors import to_rgb as _mpl_to_rgb

    try:
        return tuple(float(x) for x in _mpl_to_rgb(color))
    except ValueError:
        raise ValueError(f"color {color!r} is not a colour name, hex string or RGB triple") from None


def to_uint8(colors) -> np.ndarray:
    """RGB floats in ``[0, 1]`` (any shape ``(..., 3)``) as uint8."""
    return np.clip(np.round(np.asarray(colors, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)


@lru_cache(maxsize=None)
def chain_sides(skeleton: Skeleton) -> tuple[str, ...]:
    """``"left"``, ``"right"`` or ``"mid"`` for each kinematic chain of ``skeleton``.

    The side comes from the skeleton's mirror pairs (first element = left), so it is the
    dataset's own left/right convention.
    """
    left = {a for a, _ in skeleton.mirror_pairs}
    right = {b for _, b in skeleton.mirror_pairs}
    sides = []
    for chain in skeleton.kinematic_chains:
        n_left = sum(j in left for j in chain)
        n_right = sum(j in right for j in chain)
        sides.append("left" if n_left > n_right else "right" if n_right > n_left else "mid")
    return tuple(sides)


@lru_cache(maxsize=None)
def chain_palette(skeleton: Skeleton) -> np.ndarray:
    """``(C, 3)`` colour of each kinematic chain (C = number of chains), all distinct."""
    used = {"left": 0, "right": 0, "mid": 0}
    out = []
    for side in chain_sides(skeleton):
        shades = SIDE_COLORS[side]
        out.append(shades[used[side] % len(shades)])
        used[side] += 1
    return np.asarray(out, dtype=np.float64)


@lru_cache(maxsize=None)
def joint_chain(skeleton: Skeleton) -> tuple[int, ...]:
    """Index of the chain that draws the bone *ending* at each joint (the root: its first chain).

    Chains share their first joint (pelvis, spine3), so the bone parent->j belongs to the chain
    in which ``j`` is not the first element.
    """
    owner = [-1] * skeleton.num_joints
    for c, chain in enumerate(skeleton.kinematic_chains):
        for j in chain[1:]:
            if owner[j] < 0:
                owner[j] = c
    root_chain = next(c for c, chain in enumerate(skeleton.kinematic_chains) if chain[0] == 0)
    # the root and any joint outside every chain fall back to the mid-line chain
    mid = [c for c, s in enumerate(chain_sides(skeleton)) if s == "mid"]
    fallback = mid[0] if mid else root_chain
    return tuple(fallback if o < 0 else o for o in owner)


def _theme_colors(skeleton: Skeleton, hue_deg: float) -> np.ndarray:
    """``(C, 3)`` chain colours of one hue: darker for left, lighter for right, mid for spine."""
    lightness = {"left": 0.30, "right": 0.62, "mid": 0.45}
    sat = {"left": 0.80, "right": 0.85, "mid": 0.35}
    out = [colorsys.hls_to_rgb(hue_deg / 360.0, lightness[s], sat[s]) for s in chain_sides(skeleton)]
    return np.asarray(out, dtype=np.float64)


def bone_colors(skeleton: str | Skeleton = "humanml3d", *, theme: int | None = None, color=None) -> np.ndarray:
    """``(J, 3)`` colour of the bone ending at each joint (the root entry colours its sphere).

    Parameters
    ----------
    skeleton : str or Skeleton
    theme : int, optional
        ``None`` for the chain palette (one motion); ``k`` for the k-th motion theme
        (:data:`THEME_HUES`), used when several motions share a scene.
    color : colour, optional
        A single colour for every bone (overrides ``theme``).
    """
    skel = get_skeleton(skeleton)
    if color is not None:
        return np.tile(np.asarray(to_rgb(color)), (skel.num_joints, 1))
    if theme is None:
        palette = chain_palette(skel)
    else:
        if not isinstance(theme, (int, np.integer)) or theme < 0:
            raise ValueError(f"theme must be a non-negative int or None, got {theme!r}")
        palette = _theme_colors(skel, THEME_HUES[int(theme) % len(THEME_HUES)])
    return palette[list(joint_chain(skel))]


def motion_bone_colors(skeleton: Skeleton, n_motions: int, colors=None) -> list[np.ndarray]:
    """Per-motion ``(J, 3)`` bone colours: chain palette for one motion, themes for several.

    ``colors`` (optional) is a sequence with one entry per motion: ``None`` (automatic), a
    colour spec (one colour for the whole motion) or a ``(J, 3)`` array.
    """
    if colors is not None and len(colors) != n_motions:
        raise ValueError(f"colors must have one entry per motion ({n_motions}), got {len(colors)}")
    out = []
    for k in range(n_motions):
        spec = None if colors is None else colors[k]
        if spec is None:
            out.append(bone_colors(skeleton, theme=None if n_motions == 1 else k))
        elif isinstance(spec, np.ndarray) and spec.ndim == 2:
            if spec.shape != (skeleton.num_joints, 3):
                raise ValueError(f"colors[{k}] must be (J, 3) = ({skeleton.num_joints}, 3), got {spec.shape}")
            out.append(np.clip(spec.astype(np.float64), 0.0, 1.0))
        else:
            out.append(bone_colors(skeleton, color=spec))
    return out


def part_colors() -> np.ndarray:
    """``(P, 3)`` one qualitative colour per latent body part, in :data:`PART_NAMES` order."""
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return np.asarray([cmap(i)[:3] for i in range(len(PART_NAMES))], dtype=np.float64)
