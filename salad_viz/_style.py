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
from pathlib import Path

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
    "limb_colors",
    "bone_colors",
    "motion_bone_colors",
    "part_colors",
    "to_rgb",
    "to_uint8",
    "CaptionFont",
    "caption_font",
    "figure_text",
    "fonts_covering",
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


@lru_cache(maxsize=None)
def limb_colors(skeleton: Skeleton) -> tuple[tuple[str, str, tuple[float, float, float]], ...]:
    """``(side, limb, rgb)`` of each left/right chain as :func:`chain_palette` draws it, legs first:
    e.g. ``("left", "leg", dark blue), ("left", "arm", light blue), ...``. A chain hanging from the root
    is a leg, one hanging from the trunk an arm (HumanML3D and KIT)."""
    palette = chain_palette(skeleton)
    out = []
    for c, (side, chain) in enumerate(zip(chain_sides(skeleton), skeleton.kinematic_chains)):
        if side != "mid":
            limb = "leg" if chain[0] == 0 else "arm"
            out.append((side, limb, tuple(float(x) for x in palette[c])))
    return tuple(sorted(out, key=lambda e: (e[0] != "left", e[1] != "leg")))


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


# ----------------------------------------------------------------------------------- text fonts
#: Fonts never used as a fallback: matplotlib's "Last Resort" draws a box for every character.
_EXCLUDED_FONTS = ("lastresort",)
#: What to install when no font has a prompt's characters (named in the warning).
FONT_HINT = "install a font that has them, e.g. Debian's fonts-noto-cjk or fonts-noto-color-emoji"


def _needs_glyph(ch: str) -> bool:
    """Whether ``ch`` is drawn (letters, digits, punctuation, symbols); spaces, controls, joiners and
    variation selectors are not."""
    import unicodedata

    return unicodedata.category(ch)[0] in "LNPS"


@lru_cache(maxsize=None)
def _font_files() -> tuple[str, ...]:
    """Installed font files (the system's and matplotlib's own), regular styles first."""
    import matplotlib.font_manager as fm

    files = set(fm.findSystemFonts(fontext="ttf")) | {f.fname for f in fm.fontManager.ttflist}
    files = {f for f in files if not any(x in f.lower().replace("-", "").replace("_", "") for x in _EXCLUDED_FONTS)}
    styled = ("bold", "italic", "oblique", "light", "thin", "black", "condensed", "mono", "math", "serif")
    liked = ("dejavusans", "notosans", "liberationsans", "droidsans", "wqy")

    def key(f: str) -> tuple:
        name = Path(f).name.lower().replace("-", "").replace("_", "")
        rank = next((k for k, x in enumerate(liked) if name.startswith(x)), len(liked))
        return sum(s in name for s in styled), rank, name

    return tuple(sorted(files, key=key))


@lru_cache(maxsize=None)
def _cmap(source) -> frozenset[int]:
    """Code points a font file (path or bytes) has glyphs for (empty if it cannot be read)."""
    import io

    from fontTools.ttLib import TTFont

    try:
        with TTFont(io.BytesIO(source) if isinstance(source, bytes) else source, fontNumber=0, lazy=True) as font:
            return frozenset(font.getBestCmap() or ())
    except Exception:  # noqa: BLE001 - an unreadable font is no candidate
        return frozenset()


@lru_cache(maxsize=None)
def _default_font_bytes() -> bytes | None:
    """The bytes of Pillow's default scalable font (the one the GIF captions use), if it has any."""
    from PIL import ImageFont

    try:
        font = ImageFont.load_default(size=12)
    except TypeError:       # Pillow without FreeType sizes: a bitmap font
        return None
    path = getattr(font, "path", None)
    return path.getvalue() if hasattr(path, "getvalue") else None


def fonts_covering(text: str, base: frozenset[int] = frozenset()) -> tuple[list[str], str]:
    """Font files for the characters of ``text`` that ``base`` (a cmap) lacks, best first.

    Returns ``(paths, missing)``: installed fonts that have every lacking character (or, if none
    does, the one that has the most), and the characters no installed font has.
    """
    need = {ord(c) for c in text if _needs_glyph(c)} - set(base)
    if not need:
        return [], ""
    scored = []
    for path in _font_files():
        have = len(need & _cmap(path))
        if have:
            scored.append((-have, path))
    scored.sort(key=lambda item: item[0])    # stable: the preferred fonts first among equals
    full = [p for s, p in scored if -s == len(need)]
    best = full or [p for _, p in scored[:3]]
    covered = set().union(*(_cmap(p) for p in best)) if best else set()
    missing = "".join(sorted({chr(c) for c in need - covered}, key=text.index))
    return best, missing


def _replace_missing(text: str, missing: str) -> str:
    return "".join("?" if c in missing else c for c in text)


class CaptionFont:
    """Pillow fonts to draw one caption: Pillow's default font, then, per character it lacks, the first
    installed font that has it (CJK from e.g. Noto Sans CJK or Droid Sans Fallback, emoji from an emoji
    font Pillow can scale). Characters no loadable font has are drawn as ``"?"``, never as tofu boxes,
    with one UserWarning naming them.

    Attributes
    ----------
    text : str
        The caption as it will be drawn (missing characters replaced by ``"?"``).
    missing : str
        The characters that no installed font draws.
    """

    def __init__(self, text: str, size: int, *, warn: bool = True, stacklevel: int = 2) -> None:
        import warnings

        from PIL import ImageFont

        try:
            default = ImageFont.load_default(size=size)
        except TypeError:      # Pillow without FreeType sizes: a fixed bitmap font
            default = ImageFont.load_default()
        raw = _default_font_bytes()
        base = _cmap(raw) if raw else frozenset(range(32, 127))
        self.fonts: list = [default]
        self._cmaps: list[frozenset[int]] = [base]
        remaining = {ord(c) for c in text if _needs_glyph(c)} - base
        if remaining:
            for path in _font_files():
                cover = remaining & _cmap(path)
                if not cover:
                    continue
                try:
                    font = ImageFont.truetype(path, size)
                except OSError:    # e.g. a colour-bitmap emoji font that has one pixel size only
                    continue
                self.fonts.append(font)
                self._cmaps.append(_cmap(path))
                remaining -= cover
                if not remaining:
                    break
        self.missing = "".join(dict.fromkeys(c for c in text if ord(c) in remaining))
        self.text = _replace_missing(text, self.missing)
        if self.missing and warn:
            warnings.warn(f"the caption {text!r} has characters that no installed font draws ({self.missing}): "
                          f"drawn as '?'; {FONT_HINT}", UserWarning, stacklevel=stacklevel + 1)
        metrics = [f.getmetrics() if hasattr(f, "getmetrics") else (size, 0) for f in self.fonts]
        self.ascent = max(m[0] for m in metrics)
        self.line_height = self.ascent + max(m[1] for m in metrics) + 2

    def runs(self, text: str) -> list[tuple[object, str]]:
        """``text`` cut into ``(font, piece)`` runs, each piece drawn by the first font that has it."""
        out: list[tuple[object, str]] = []
        for ch in text:
            k = next((i for i, cm in enumerate(self._cmaps) if ord(ch) in cm), 0) if _needs_glyph(ch) else \
                (self.fonts.index(out[-1][0]) if out else 0)
            font = self.fonts[k]
            if out and out[-1][0] is font:
                out[-1] = (font, out[-1][1] + ch)
            else:
                out.append((font, ch))
        return out

    def length(self, text: str) -> float:
        """Width of ``text`` in pixels."""
        return float(sum(font.getlength(piece) for font, piece in self.runs(text)))

    def draw(self, draw, xy: tuple[float, float], text: str, **kwargs) -> None:
        """Write ``text`` with its top-left corner at ``xy`` (``kwargs``: ``fill``, ``stroke_width``, ...),
        every run on one baseline."""
        x, y = xy
        for font, piece in self.runs(text):
            draw.text((x, y + self.ascent), piece, font=font, anchor="ls", **kwargs)
            x += font.getlength(piece)


def caption_font(text: str, size: int, *, warn: bool = True) -> CaptionFont:
    """:class:`CaptionFont` of ``text`` at ``size`` pixels (warnings point at the caller's caller)."""
    return CaptionFont(text, size, warn=warn, stacklevel=3)


def figure_text(text: str, *, warn: bool = True) -> tuple[str, list[str] | None]:
    """``(text, fontfamily)`` for a matplotlib title: the families to list (DejaVu Sans, then installed
    fallbacks that have the characters DejaVu lacks; None when DejaVu has them all), and the text with
    characters no installed font has replaced by ``"?"`` (warned about), so no glyph is drawn as a box."""
    import warnings

    import matplotlib.font_manager as fm

    base = _cmap(fm.findfont(fm.FontProperties(family="DejaVu Sans")))
    paths, missing = fonts_covering(text, base)
    families = None
    if paths:
        families = ["DejaVu Sans"]
        for path in paths:
            try:
                fm.fontManager.addfont(path)
                name = fm.FontProperties(fname=path).get_name()
            except Exception:  # noqa: BLE001 - a font matplotlib cannot read is no fallback
                continue
            if name not in families:
                families.append(name)
        families = families if len(families) > 1 else None
    if missing and warn:
        warnings.warn(f"the title {text!r} has characters that no installed font draws ({missing}): drawn as '?'; "
                      f"{FONT_HINT}", UserWarning, stacklevel=3)
    return _replace_missing(text, missing), families
