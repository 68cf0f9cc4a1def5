"""Animations: frames of one or several motions (side by side or overlaid) as GIF or MP4.

MP4 uses the ffmpeg binary shipped by the PyPI package ``imageio-ffmpeg`` (H.264, yuv420p, so it
plays in browsers and Jupyter); GIF uses Pillow through imageio. :func:`show_animation` embeds
either in a notebook.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import as_joints_list, atomic_output, check_frames_memory, check_size
from ._style import THEME_HUES, limb_colors
from .camera import fixed_camera, follow_camera, shared_follow_framing
from .raster import caption_band, hstack_images
from .render import SkeletonRenderer

__all__ = ["LAYOUTS", "COMPARISON_PANEL", "render_frames", "animate", "write_video", "show_animation"]

LAYOUTS = ("side", "overlay")
#: Panel size (width, height) in pixels of a side-by-side comparison (a source and its edit): large enough
#: for 20 px captions and key, read on a projector.
COMPARISON_PANEL = (360, 360)
_FORMATS = (".gif", ".mp4")


def _theme_text_color(k: int) -> tuple[float, float, float]:
    import colorsys

    return colorsys.hls_to_rgb(THEME_HUES[k % len(THEME_HUES)] / 360.0, 0.38, 0.8)


def render_frames(
    joints,
    skeleton: str | Skeleton = "humanml3d",
    *,
    layout: str = "side",
    titles: Sequence[str] | None = None,
    size: Sequence[int] = (320, 320),
    frames: Sequence[int] | None = None,
    view: str | float = "three_quarter",
    elevation: float | None = None,
    follow: bool = True,
    colors=None,
    joint_colors=None,
    floor: bool = True,
    trajectory: bool = True,
    backend: str = "auto",
    bone_shape: str = "capsule",
    side_legend: bool = True,
    supports: bool | None = None,
) -> np.ndarray:
    """Render every frame of one or several motions.

    Parameters
    ----------
    joints : array (N, J, 3) or list of arrays (N_k, J, 3)
        Motions in metres. Shorter motions hold their last pose until the longest ends.
    skeleton : str or Skeleton
    layout : {"side", "overlay"}
        ``"side"``: one panel per motion, side by side, each with its own following camera and its
        chain colours, all drawn at one scale (the same camera distance and height, so figures
        of the same size look the same size). ``"overlay"``: all motions in one scene, one colour
        theme each.
    titles : sequence of str (or of sequences of str), optional
        One per motion: panel titles (``"side"``) or a legend in the theme colours (``"overlay"``),
        written in a white band *above* the scene (the scene gets the rest of ``size``, so no caption
        covers the figure); long titles wrap onto several lines (at most 3, then "..."). A title given
        as a sequence of strings is written one under the other, the first near black and the rest
        dark grey (e.g. ``("Mirror(legs)", "a person walks forward")``: an edit's label over its
        prompt). Characters the default font lacks (CJK, emoji) come from an installed font that has
        them, else "?".
    size : (width, height)
        Size of one panel in pixels.
    frames : sequence of int, optional
        Which frames to render (default all).
    view, elevation, follow, colors, joint_colors, floor, trajectory, backend, bone_shape
        As in :func:`salad_viz.render.render_skeleton`; ``colors`` and ``joint_colors`` take one
        entry per motion.
    side_legend : bool
        Draw a key of the limb colours as drawn ("left: leg arm" in the left leg's and arm's blues,
        "right: leg arm" in the right's red and orange) in the bottom-left corner of every panel, where
        the motions are drawn in those colours (no ``colors``/``joint_colors``, not an overlay of several
        motions).
    supports : bool, optional
        Draw steps under feet planted above the floor (stairs: :func:`salad_viz.scene.support_boxes`);
        default: with the floor, when a motion has such plants.

    The following camera keeps every joint of every frame in view (hands raised above the head and
    jumps included), at one distance for the whole motion.

    Returns
    -------
    ndarray (T, H, W, 3) uint8
    """
    skel = get_skeleton(skeleton)
    motions = as_joints_list(joints, skel)
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    if titles is not None and len(titles) != len(motions):
        raise ValueError(f"titles must have one entry per motion ({len(motions)}), got {len(titles)}")
    w, h = check_size(size)
    n = max(len(m) for m in motions)
    idx = range(n) if frames is None else [int(f) for f in frames]
    if not len(idx):
        raise ValueError("frames is empty")
    side = layout == "side" and len(motions) > 1
    check_frames_memory(len(idx), w * (len(motions) if side else 1) + 4 * (len(motions) - 1) * side, h)
    chain_coloured = colors is None and joint_colors is None and (side or len(motions) == 1)
    keyed = (lambda scene: _side_key(scene, skel)) if side_legend and chain_coloured else (lambda scene: scene)
    jc = joint_colors
    if jc is not None and not isinstance(jc, (list, tuple)):
        jc = [jc] + [None] * (len(motions) - 1) if len(motions) > 1 else jc
    # the captions go in a band above the scene (made once: they do not change from frame to frame)
    bands = _title_bands(titles, w, h, side=side) if titles else None
    hs = h - (bands[0].shape[0] if bands else 0)
    if side:
        distance, height = shared_follow_framing(motions, aspect=w / hs, view=view, elevation=elevation)
        shared_fixed = None if follow else fixed_camera(motions, view=view, elevation=elevation, aspect=w / hs)
    out = []
    with SkeletonRenderer(skel, size=(w, hs), backend=backend, bone_shape=bone_shape) as r:
        for f in idx:
            if layout == "overlay" or len(motions) == 1:
                img = keyed(r.render(motions, f, view=view, elevation=elevation, follow=follow, colors=colors,
                                     joint_colors=jc, floor=floor, trajectory=trajectory, supports=supports))
                if bands:
                    img = np.concatenate([bands[0], img], axis=0)
            else:
                panels = []
                for k, m in enumerate(motions):
                    fk = min(f, len(m) - 1)
                    # one scale for every panel: the same distance and focal height
                    cam = (follow_camera([m], fk, view=view, elevation=elevation, aspect=w / hs, distance=distance,
                                         height=height) if follow else shared_fixed)
                    panel = keyed(r.render(m, fk, camera=cam, view=view, elevation=elevation, follow=follow,
                                           colors=None if colors is None else [colors[k]],
                                           joint_colors=None if jc is None else jc[k], floor=floor,
                                           trajectory=trajectory, supports=supports))
                    if bands:
                        panel = np.concatenate([bands[k], panel], axis=0)
                    panels.append(panel)
                img = hstack_images(panels, gap=4)
            out.append(img)
    return np.stack(out)


#: Colours of a panel caption's lines (:func:`render_frames` ``titles`` given as lines): the first (a label such
#: as "source" or "Mirror(legs)") near black, the rest (the prompt) dark grey.
CAPTION_LINE_COLORS = ((0.05, 0.05, 0.05), (0.30, 0.30, 0.30))


def _caption_lines(title) -> list[str]:
    """A panel title as its lines: a string is one caption, a sequence of strings one line each."""
    if isinstance(title, str):
        return [title]
    lines = [str(t) for t in title]
    if not lines:
        raise ValueError("a title given as lines needs at least one line")
    return lines


def _title_bands(titles, w: int, h: int, *, side: bool) -> list[np.ndarray]:
    """Caption bands of one height: one per panel (``side``; a title given as lines writes one line under
    the other, :data:`CAPTION_LINE_COLORS`) or one with every title (themed colours when several motions
    share the scene; lines joined by ": ")."""
    if side:
        bands = []
        for t in titles:
            lines = _caption_lines(t)
            colors = [CAPTION_LINE_COLORS[min(i, 1)] for i in range(len(lines))] if len(lines) > 1 else None
            bands.append(caption_band(lines, w, h, colors=colors))
        return _pad_bands(bands)
    titles = [": ".join(_caption_lines(t)) for t in titles]
    if len(titles) > 1:
        bands = [caption_band(titles, w, h, colors=[_theme_text_color(k) for k in range(len(titles))],
                              max_lines=max(1, 4 // len(titles)))]
    else:
        bands = [caption_band(titles, w, h)]
    return _pad_bands(bands)


def _pad_bands(bands: list[np.ndarray]) -> list[np.ndarray]:
    """Caption bands ``(B_k, W, 3)`` padded with white at the bottom to the tallest."""
    top = max(b.shape[0] for b in bands)
    return [np.pad(b, ((0, top - b.shape[0]), (0, 0), (0, 0)), constant_values=255) for b in bands]


def _font(h: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=max(10, min(20, h // 16)))
    except TypeError:
        return ImageFont.load_default()


def _side_key(img: np.ndarray, skeleton: Skeleton | None = None) -> np.ndarray:
    """A key of the limb colours as drawn, in the bottom-left corner: one line per side, ``left: leg arm``
    with "leg" and "arm" written in that leg's and arm's colours (:func:`salad_viz._style.limb_colors`)."""
    from PIL import Image, ImageDraw

    skel = get_skeleton("humanml3d" if skeleton is None else skeleton)
    h = img.shape[0]
    font = _font(h)                    # as large as the captions (caption_size): readable on a projector
    pil = Image.fromarray(np.ascontiguousarray(img))
    draw = ImageDraw.Draw(pil)
    entries = limb_colors(skel)
    sides = [s for s in ("left", "right") if any(e[0] == s for e in entries)]
    line_h = draw.textbbox((0, 0), "right:", font=font)[3] + 2
    label_w = max(draw.textlength(f"{s}:", font=font) for s in sides)
    width = label_w + 5 + max(sum(draw.textlength(e[1], font=font) + 5 for e in entries if e[0] == s) for s in sides)
    if line_h * len(sides) > 0.25 * h or 6 + width > 0.75 * img.shape[1]:
        return img                     # too small a frame: the key would cover the figure
    y = h - 4 - line_h * len(sides)
    for side in sides:
        draw.text((6, y), f"{side}:", fill=(60, 60, 60), font=font, stroke_width=2, stroke_fill=(255, 255, 255))
        x = 6 + label_w + 5
        for s, limb, rgb in entries:
            if s != side:
                continue
            col = tuple(int(round(c * 255)) for c in rgb)
            draw.text((x, y), limb, fill=col, font=font, stroke_width=2, stroke_fill=(255, 255, 255))
            x += draw.textlength(limb, font=font) + 5
        y += line_h
    return np.asarray(pil).copy()


def write_video(frames, path: str | os.PathLike, fps: float = 20.0, *, loop: bool = True) -> Path:
    """Write ``(T, H, W, 3)`` uint8 frames as ``.gif`` or ``.mp4`` (chosen by the suffix), atomically.

    MP4 frames are padded with white to even sizes (H.264 with yuv420p needs them).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in _FORMATS:
        raise ValueError(f"path must end in one of {_FORMATS}, got {path.name!r}")
    arr = np.asarray(frames)
    if arr.ndim != 4 or arr.shape[-1] != 3 or arr.dtype != np.uint8:
        raise ValueError(f"frames must be (T, H, W, 3) uint8, got {arr.shape} {arr.dtype}")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive finite number, got {fps}")
    with atomic_output(path) as tmp:
        if suffix == ".gif":
            import imageio.v3 as iio

            # GIF delays are whole centiseconds; 20 fps -> 50 ms is exact
            iio.imwrite(tmp, arr, extension=".gif", duration=1000.0 / fps, loop=0 if loop else 1)
        else:
            import imageio.v2 as iio2

            t, hh, ww, _ = arr.shape
            if hh % 2 or ww % 2:
                arr = np.pad(arr, ((0, 0), (0, hh % 2), (0, ww % 2), (0, 0)), constant_values=255)
            writer = iio2.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                     pixelformat="yuv420p", macro_block_size=1, quality=8,
                                     ffmpeg_log_level="error")
            try:
                for fr in arr:
                    writer.append_data(fr)
            finally:
                writer.close()
    return path


def animate(
    joints,
    skeleton: str | Skeleton,
    path: str | os.PathLike,
    fps: float | None = None,
    *,
    layout: str = "side",
    titles: Sequence[str] | None = None,
    size: Sequence[int] = (320, 320),
    stride: int = 1,
    view: str | float = "three_quarter",
    elevation: float | None = None,
    follow: bool = True,
    colors=None,
    joint_colors=None,
    floor: bool = True,
    trajectory: bool = True,
    backend: str = "auto",
    bone_shape: str = "capsule",
    side_legend: bool = True,
    supports: bool | None = None,
) -> Path:
    """Animate one or several motions to a GIF or MP4 file.

    Parameters
    ----------
    joints : array (N, J, 3) or list of arrays (N_k, J, 3)
        Motions in metres (e.g. ``[source, edited]`` or ``[original, mirrored]``).
    skeleton : str or Skeleton
    path : str or PathLike
        ``.gif`` or ``.mp4``.
    fps : float, optional
        Playback rate; default the skeleton's (20 for HumanML3D). With ``stride`` > 1 the rate is
        divided so that the animation keeps real time.
    layout : {"side", "overlay"}
        Panels side by side, or one scene with a colour theme per motion.
    titles : sequence of str, optional
        One per motion.
    size : (width, height)
        One panel, in pixels.
    stride : int
        Render every ``stride``-th frame (smaller files, faster).
    view, elevation, follow, colors, joint_colors, floor, trajectory, backend, bone_shape, side_legend, supports
        As in :func:`render_frames`.

    Returns
    -------
    Path
    """
    skel = get_skeleton(skeleton)
    if Path(path).suffix.lower() not in _FORMATS:
        raise ValueError(f"path must end in one of {_FORMATS}, got {Path(path).name!r}")
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride must be a positive int, got {stride!r}")
    check_size(size)                     # before anything is created (a huge size can abort VTK)
    if fps is not None and not (isinstance(fps, (int, float, np.integer, np.floating)) and not isinstance(fps, bool)
                                and np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive finite number of frames per second, got {fps!r}")
    motions = as_joints_list(joints, skel)
    n = max(len(m) for m in motions)
    frames = render_frames(motions, skel, layout=layout, titles=titles, size=size, frames=range(0, n, stride),
                           view=view, elevation=elevation, follow=follow, colors=colors,
                           joint_colors=joint_colors, floor=floor, trajectory=trajectory, backend=backend,
                           bone_shape=bone_shape, side_legend=side_legend, supports=supports)
    rate = (skel.fps if fps is None else float(fps)) / stride
    return write_video(frames, path, rate)


def show_animation(path: str | os.PathLike, *, width: int | None = None):
    """An IPython display object that shows a GIF or MP4 inline (the data is embedded).

    Returns
    -------
    IPython.display.Image (GIF) or IPython.display.Video (MP4)
    """
    from IPython.display import Image, Video

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no animation at {path}")
    suffix = path.suffix.lower()
    if suffix == ".gif":
        return Image(data=path.read_bytes(), format="gif", width=width)
    if suffix == ".mp4":
        return Video(str(path), embed=True, mimetype="video/mp4", width=width)
    raise ValueError(f"path must be a .gif or .mp4 file, got {path.name!r}")
