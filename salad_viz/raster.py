"""A scikit-image 2D rasteriser of skeleton scenes: the same views as pyvista, no OpenGL needed.

Bones are drawn as projected capsules (a quad between two discs whose radii follow the
perspective), joints as discs, back to front (painter's algorithm), over a projected
checkerboard floor and the root trajectory. Drawing happens at ``supersample`` times the output
size and is averaged down, which anti-aliases edges.

:func:`salad_viz.render.render_skeleton` falls back to this module automatically when off-screen
OpenGL is unavailable.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from salad_core.skeleton import Skeleton

from ._style import BACKGROUND, FLOOR_DARK, FLOOR_LIGHT, caption_font, to_rgb, to_uint8
from .camera import Camera, project_points
from .meshes import FLOOR_TILE as _TILE
from .scene import STEP_SIDE, STEP_TOP, FrameScene, support_faces

__all__ = ["rasterize_skeleton", "rasterize_scene", "draw_title", "caption_band", "wrap_text", "hstack_images",
           "vstack_images"]

_NEAR = 0.05  # metres: primitives closer to the camera than this are skipped
_OUTLINE = 0.55  # outline colour = fill colour x this factor


def _disk(canvas: np.ndarray, centre, radius: float, color) -> None:
    from skimage.draw import disk

    rr, cc = disk((centre[1], centre[0]), max(radius, 0.75), shape=canvas.shape[:2])
    canvas[rr, cc] = color


def _capsule2d(canvas: np.ndarray, p0, p1, r0: float, r1: float, color) -> None:
    """A 2D capsule: discs at both ends joined by the tangent quad (pixel coordinates)."""
    from skimage.draw import polygon

    d = np.subtract(p1, p0)
    n = float(np.hypot(*d))
    if n > 1e-6:
        nrm = np.array([-d[1], d[0]]) / n
        quad = np.array([p0 + nrm * r0, p1 + nrm * r1, p1 - nrm * r1, p0 - nrm * r0])
        rr, cc = polygon(quad[:, 1], quad[:, 0], shape=canvas.shape[:2])
        canvas[rr, cc] = color
    _disk(canvas, p0, r0, color)
    _disk(canvas, p1, r1, color)


def _draw_floor(canvas: np.ndarray, cam: Camera, centre_xz, half_extent: float) -> None:
    """Checkerboard on y = 0 by casting one ray per pixel (exact, and fast in numpy).

    Uses the same world-aligned tiles as :func:`salad_viz.meshes.floor_tiles` (``_TILE`` metres,
    a tile is dark when the sum of its grid indices is odd).
    """
    h, w = canvas.shape[:2]
    right, up, fwd = cam.basis()
    f = (h / 2.0) / np.tan(np.radians(cam.view_angle) / 2.0)
    xs = (np.arange(w) + 0.5 - w / 2.0) / f
    ys = (h / 2.0 - (np.arange(h) + 0.5)) / f
    # ray direction per pixel = fwd + x * right + y * up; only its Y component and XZ matter
    dy = fwd[1] + ys[:, None] * up[1] + xs[None, :] * right[1]
    eye = np.asarray(cam.position)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -eye[1] / dy
    hit = (t > 0) & np.isfinite(t)
    if eye[1] <= 0:  # camera under the floor: do not draw it
        return
    px = eye[0] + t * (fwd[0] + ys[:, None] * up[0] + xs[None, :] * right[0])
    pz = eye[2] + t * (fwd[2] + ys[:, None] * up[2] + xs[None, :] * right[2])
    cx, cz = float(centre_xz[0]), float(centre_xz[1])
    # the same tile-snapped patch as the mesh floor
    x0, x1 = np.floor((cx - half_extent) / _TILE) * _TILE, np.ceil((cx + half_extent) / _TILE) * _TILE
    z0, z1 = np.floor((cz - half_extent) / _TILE) * _TILE, np.ceil((cz + half_extent) / _TILE) * _TILE
    inside = hit & (px >= x0) & (px <= x1) & (pz >= z0) & (pz <= z1)
    ii = np.floor(np.where(inside, px, 0.0) / _TILE).astype(np.int64)
    kk = np.floor(np.where(inside, pz, 0.0) / _TILE).astype(np.int64)
    dark = ((ii + kk) % 2).astype(bool)
    canvas[inside & dark] = FLOOR_DARK
    canvas[inside & ~dark] = FLOOR_LIGHT


def _draw_steps(canvas: np.ndarray, cam: Camera, quads, size: tuple[int, int], s: int) -> None:
    """The faces of the steps that face the camera, far first (top light, sides shaded), outlined."""
    from skimage.draw import polygon, polygon_perimeter

    eye = np.asarray(cam.position, dtype=np.float64)
    light = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    faces = []
    for quad in quads:
        for k, (corners, nrm) in enumerate(support_faces(quad)):
            if nrm @ (eye - corners.mean(axis=0)) <= 0:
                continue
            pix, depth = project_points(corners, cam, size)
            if (depth <= _NEAR).any():
                continue
            base = np.asarray(STEP_TOP if k == 0 else STEP_SIDE)
            col = base * (0.85 + 0.15 * max(float(nrm @ light), 0.0)) if k else base
            faces.append((float(depth.mean()), pix, col))
    faces.sort(key=lambda f: -f[0])
    for _, pix, col in faces:
        rr, cc = polygon(pix[:, 1], pix[:, 0], shape=canvas.shape[:2])
        canvas[rr, cc] = col
        for _ in range(max(1, s // 2)):
            rr, cc = polygon_perimeter(pix[:, 1], pix[:, 0], shape=canvas.shape[:2], clip=False)
            canvas[rr, cc] = col * _OUTLINE


def rasterize_scene(scene: FrameScene, skeleton: Skeleton, size: tuple[int, int], *,
                    supersample: int = 2, background=BACKGROUND) -> np.ndarray:
    """Draw a :class:`~salad_viz.scene.FrameScene`.

    Returns
    -------
    ndarray (H, W, 3) uint8
    """
    w, h = size
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    big = (w * s, h * s)
    cam = scene.camera
    canvas = np.empty((h * s, w * s, 3), dtype=np.float64)
    canvas[:] = to_rgb(background)
    f_px = (big[1] / 2.0) / np.tan(np.radians(cam.view_angle) / 2.0)

    if scene.floor_centre is not None:
        _draw_floor(canvas, cam, scene.floor_centre, scene.floor_half_extent)

    for path, col in zip(scene.trajectories, scene.trajectory_colors):
        if len(path) < 2:
            continue
        pts = path[:: max(1, len(path) // 120)].copy()  # ~120 segments are plenty for a path
        pts[:, 1] = 0.0
        pix, depth = project_points(pts, cam, big)
        width = max(1.0, 0.006 * f_px / max(float(np.median(depth)), _NEAR))
        for a, b, da, db in zip(pix[:-1], pix[1:], depth[:-1], depth[1:]):
            if da > _NEAR and db > _NEAR:
                _capsule2d(canvas, a, b, width, width, col)

    if scene.supports:
        _draw_steps(canvas, cam, scene.supports, big, s)

    # Painter's algorithm over every bone and joint of every motion (far first).
    prims = []
    for pose, bcol, jcol in zip(scene.poses, scene.bone_colors, scene.joint_colors):
        pix, depth = project_points(pose, cam, big)
        for child, parent in enumerate(skeleton.parents):
            if parent < 0 or depth[child] <= _NEAR or depth[parent] <= _NEAR:
                continue
            r0 = scene.bone_radius * f_px / depth[parent]
            r1 = scene.bone_radius * f_px / depth[child]
            prims.append((0.5 * (depth[child] + depth[parent]), 1, pix[parent], pix[child], r0, r1, bcol[child]))
        for j in range(skeleton.num_joints):
            if depth[j] <= _NEAR:
                continue
            r = scene.joint_radius * f_px / depth[j]
            # joints sort slightly in front of the bones that meet there
            prims.append((depth[j] - scene.joint_radius, 0, pix[j], pix[j], r, r, jcol[j]))
    prims.sort(key=lambda p: -p[0])
    edge = max(1.0, 0.5 * s)
    for _, _, p0, p1, r0, r1, col in prims:
        col = np.asarray(col)
        _capsule2d(canvas, p0, p1, r0 + edge, r1 + edge, col * _OUTLINE)
        _capsule2d(canvas, p0, p1, r0, r1, col)

    if s > 1:
        canvas = canvas.reshape(h, s, w, s, 3).mean(axis=(1, 3))
    return to_uint8(canvas)


def rasterize_skeleton(
    joints,
    skeleton: str | Skeleton = "humanml3d",
    frame: int = 0,
    *,
    camera: Camera | None = None,
    view: str | float = "three_quarter",
    elevation: float | None = None,
    follow: bool = True,
    size: Sequence[int] = (400, 300),
    colors=None,
    joint_colors=None,
    floor: bool = True,
    trajectory: bool = True,
    bone_radius: float = 0.022,
    joint_radius: float = 0.032,
    supersample: int = 2,
    background=BACKGROUND,
    title: str | None = None,
) -> np.ndarray:
    """Draw one frame of one or several motions with scikit-image (no OpenGL).

    Parameters
    ----------
    joints : array (N, J, 3) or list of arrays (N_k, J, 3)
        Joint positions in metres, +Y up, floor y = 0. A list draws several motions in one scene,
        each in its own colour theme; shorter motions hold their last pose.
    skeleton : str or Skeleton
    frame : int
        Frame index (negative counts from the end of the longest motion).
    camera : Camera, optional
        Explicit camera; otherwise one is built from ``view``, ``elevation`` and ``follow``.
    view : str or float
        ``"front"``, ``"three_quarter"``, ``"side"``, ``"back"``, ``"top"`` or an azimuth in degrees.
    elevation : float, optional
        Camera elevation in degrees (default: the view's).
    follow : bool
        ``True``: the camera tracks the root; ``False``: a still camera that sees every frame.
    size : (width, height)
        Output size in pixels.
    colors : list, optional
        One entry per motion: ``None`` (automatic), a colour, or ``(J, 3)`` bone colours.
    joint_colors : array (N, J, 3) or (J, 3), or list of those, optional
        Per-joint colours (e.g. from :func:`salad_viz.attention.joint_attention_colors`).
    floor, trajectory : bool
        Draw the checkerboard floor / the root path.
    bone_radius, joint_radius : float
        Radii in metres.
    supersample : int
        Drawing resolution factor used for anti-aliasing.
    background : colour
    title : str, optional
        Text written in a white band above the scene (the scene gets the rest of ``size``).

    Returns
    -------
    ndarray (H, W, 3) uint8
    """
    from .render import SkeletonRenderer   # render imports this module; the renderer's raster backend

    with SkeletonRenderer(skeleton, size=size, backend="raster", background=background,
                          supersample=supersample) as renderer:
        return renderer.render(joints, frame, camera=camera, view=view, elevation=elevation, follow=follow,
                               colors=colors, joint_colors=joint_colors, floor=floor, trajectory=trajectory,
                               bone_radius=bone_radius, joint_radius=joint_radius, title=title)


def draw_title(image: np.ndarray, title: str, *, color=(0.1, 0.1, 0.1), size: int | None = None) -> np.ndarray:
    """A copy of ``image`` ``(H, W, 3)`` uint8 with ``title`` written at the top-left (Pillow; characters
    the default font lacks from an installed font that has them, else as "?": :func:`_style.caption_font`)."""
    from PIL import Image, ImageDraw

    h = image.shape[0]
    font = caption_font(str(title), size or max(10, min(24, h // 16)))
    pil = Image.fromarray(np.ascontiguousarray(image))
    font.draw(ImageDraw.Draw(pil), (6, 4), font.text, fill=tuple(int(c) for c in to_uint8(to_rgb(color))))
    return np.asarray(pil).copy()


def caption_size(panel_height: int) -> int:
    """Font size (pixels) of the captions of a panel ``panel_height`` pixels high."""
    return max(10, min(20, int(panel_height) // 16))


def wrap_text(draw, text: str, font, width: float, max_lines: int = 3) -> list[str]:
    """Greedy word wrap of ``text`` to ``width`` pixels (``font``: a Pillow font or a
    :class:`~salad_viz._style.CaptionFont`); more than ``max_lines`` lines end in "...". Text without
    spaces (Chinese) is cut where the width is reached."""
    measure = font.length if hasattr(font, "runs") else (lambda t: draw.textlength(t, font=font))
    lines: list[str] = []
    for word in str(text).split():
        if lines and measure(lines[-1] + " " + word) <= width:
            lines[-1] += " " + word
            continue
        while len(word) > 1 and measure(word) > width:       # a word wider than the line: cut it
            cut = max(1, next((k for k in range(len(word), 0, -1) if measure(word[:k]) <= width), 1))
            lines.append(word[:cut])
            word = word[cut:]
        lines.append(word)
    if len(lines) > max_lines:
        lines = lines[:max_lines]
        last = lines[-1]
        while last and measure(last + " ...") > width:
            last = last[:-1]
        lines[-1] = last.rstrip() + " ..."
    return lines or [""]


def caption_band(titles: Sequence[str], width: int, panel_height: int, *, colors=None, max_lines: int = 3,
                 max_fraction: float = 0.4) -> np.ndarray:
    """A white band ``(B, width, 3)`` uint8 with ``titles`` written one under the other, each wrapped to
    ``width`` (at most ``max_lines`` lines, fewer if the band would take more than ``max_fraction`` of
    ``panel_height``), to be stacked *above* a scene so that no caption covers the figure.

    ``colors``: one RGB per title (default dark grey). Characters no installed font has are drawn as
    "?" (warned about once per title, :func:`salad_viz._style.caption_font`).
    """
    from PIL import Image, ImageDraw

    size = caption_size(panel_height)
    cols = [(0.1, 0.1, 0.1)] * len(titles) if colors is None else list(colors)
    fonts = [caption_font(str(t), size) for t in titles]
    probe = ImageDraw.Draw(Image.new("RGB", (4, 4)))
    while True:
        wrapped = [wrap_text(probe, font.text, font, width - 12, max_lines) for font in fonts]
        height = 6 + sum(len(lines) * font.line_height for lines, font in zip(wrapped, fonts)) \
            + 2 * max(0, len(wrapped) - 1)
        if height <= max_fraction * panel_height or max_lines <= 1:
            break
        max_lines -= 1
    pil = Image.new("RGB", (int(width), int(height)), (255, 255, 255))
    draw = ImageDraw.Draw(pil)
    y = 3
    for font, lines, col in zip(fonts, wrapped, cols):
        for line in lines:
            font.draw(draw, (6, y), line, fill=tuple(int(c) for c in to_uint8(to_rgb(col))))
            y += font.line_height
        y += 2
    return np.asarray(pil).copy()


def _pad_to(img: np.ndarray, h: int, w: int, fill: int = 255) -> np.ndarray:
    out = np.full((h, w, img.shape[2]), fill, dtype=img.dtype)
    out[: img.shape[0], : img.shape[1]] = img
    return out


def _stack_images(images: Sequence[np.ndarray], gap: int, fill: int, axis: int) -> np.ndarray:
    """Images ``(H_k, W_k, 3)`` joined along ``axis`` (0: rows, 1: columns), each padded with ``fill``
    to the largest size on the other axis, ``gap`` pixels of ``fill`` between neighbours."""
    if not images:
        raise ValueError("images is empty")
    other = 1 - axis
    across = max(i.shape[other] for i in images)
    parts = []
    for k, img in enumerate(images):
        size = list(img.shape[:2])
        size[other] = across
        parts.append(_pad_to(img, *size, fill))
        if gap and k < len(images) - 1:
            size[axis] = gap
            parts.append(np.full((*size, img.shape[2]), fill, dtype=img.dtype))
    return np.concatenate(parts, axis=axis)


def hstack_images(images: Sequence[np.ndarray], gap: int = 0, fill: int = 255) -> np.ndarray:
    """Images ``(H_k, W_k, 3)`` side by side (padded to the tallest), with ``gap`` pixels between."""
    return _stack_images(images, gap, fill, axis=1)


def vstack_images(images: Sequence[np.ndarray], gap: int = 0, fill: int = 255) -> np.ndarray:
    """Images stacked top to bottom (padded to the widest), with ``gap`` pixels between."""
    return _stack_images(images, gap, fill, axis=0)
