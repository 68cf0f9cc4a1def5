"""Skeleton renders: pyvista off-screen (capsule bones, sphere joints, floor, trajectory) with an
automatic fallback to the scikit-image rasteriser.

Off-screen OpenGL is probed once per process in a subprocess with a timeout (a broken GL stack
can hang or crash the interpreter that tries it) and the answer is cached. Set the environment
variable ``SALAD_VIZ_BACKEND`` to ``raster`` or ``pyvista`` to skip the probe.

Headless machines: VTK's wheel tries an X display first, then EGL, then OSMesa. Without
``DISPLAY`` we ask for EGL directly (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``), which works
with the Mesa EGL libraries and needs no X server (see the README's set-up).
"""
from __future__ import annotations

import logging
import os
import subprocess
import sys
from typing import Sequence

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import as_joints_list, check_frame, check_size
from ._style import BACKGROUND, to_rgb, to_uint8
from .camera import Camera
from .meshes import BONE_SHAPES, body_mesh, floor_mesh
from .raster import caption_band, draw_title, hstack_images, rasterize_scene, vstack_images
from .scene import FrameScene, build_scene

log = logging.getLogger(__name__)

__all__ = [
    "BACKENDS",
    "offscreen_available",
    "resolve_backend",
    "SkeletonRenderer",
    "render_skeleton",
    "keyframe_strip",
    "select_keyframes",
]

BACKENDS = ("auto", "pyvista", "raster")
_TRAIL_VIEW_ANGLE = 14.0  # degrees
_PROBE_TIMEOUT_S = 60.0
_probe_result: bool | None = None

_PROBE_CODE = """
import numpy as np, pyvista as pv
p = pv.Plotter(off_screen=True, window_size=(48, 32))
p.set_background("white")
p.add_mesh(pv.Sphere(radius=1.0), color="red")
img = p.screenshot(return_img=True)
p.close()
raise SystemExit(0 if (np.abs(img.astype(int) - 255).sum(axis=-1) > 30).mean() > 0.05 else 3)
"""


def _prepare_vtk_env(env: dict | None = None) -> dict:
    """Ask VTK for EGL when there is no X display (skips a failing X attempt and its warning)."""
    target = os.environ if env is None else env
    if not target.get("DISPLAY"):
        target.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    return target


def offscreen_available(*, refresh: bool = False) -> bool:
    """Whether pyvista can render off-screen here (probed once in a subprocess, then cached).

    ``SALAD_VIZ_BACKEND=raster`` makes this ``False`` and ``SALAD_VIZ_BACKEND=pyvista`` makes it
    ``True`` without probing.
    """
    global _probe_result
    forced = os.environ.get("SALAD_VIZ_BACKEND", "").strip().lower()
    if forced == "raster":
        return False
    if forced == "pyvista":
        return True
    if _probe_result is not None and not refresh:
        return _probe_result
    env = _prepare_vtk_env(dict(os.environ))
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE_CODE], env=env, capture_output=True,
                              timeout=_PROBE_TIMEOUT_S, text=True)
        ok = proc.returncode == 0
        if not ok:
            log.info("off-screen OpenGL unavailable (probe exit %s): %s", proc.returncode,
                     proc.stderr.strip().splitlines()[-1:] or "")
    except subprocess.TimeoutExpired:
        ok = False
        log.info("off-screen OpenGL probe timed out after %.0f s", _PROBE_TIMEOUT_S)
    except OSError as exc:
        ok = False
        log.info("off-screen OpenGL probe could not start: %s", exc)
    if not ok:
        log.warning("pyvista off-screen rendering is unavailable; using the 2D rasteriser")
    _probe_result = ok
    return ok


def resolve_backend(backend: str) -> str:
    """``"auto"`` -> ``"pyvista"`` when off-screen OpenGL works, else ``"raster"``."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "pyvista" if offscreen_available() else "raster"
    return backend


def _to_polydata(mesh):
    """trimesh -> pyvista PolyData with an ``rgba`` cell array."""
    import pyvista as pv

    faces = np.hstack([np.full((len(mesh.faces), 1), 3, dtype=np.int64), mesh.faces.astype(np.int64)]).ravel()
    poly = pv.PolyData(np.asarray(mesh.vertices, dtype=np.float64), faces)
    poly.cell_data["rgba"] = np.asarray(mesh.visual.face_colors, dtype=np.uint8)[:, :3]
    return poly


def _steps_mesh(quads):
    """The steps of a scene (:func:`salad_viz.scene.support_faces`) as one trimesh with face colours."""
    import trimesh

    from .scene import STEP_SIDE, STEP_TOP, support_faces

    verts, faces, cols = [], [], []
    for quad in quads:
        for k, (corners, nrm) in enumerate(support_faces(quad)):
            base = len(verts) * 4
            verts.append(corners)
            # wind the two triangles so that they face along the outward normal
            tri = np.array([[0, 1, 2], [0, 2, 3]])
            if np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ nrm < 0:
                tri = tri[:, ::-1]
            faces.append(tri + base)
            cols += [STEP_TOP if k == 0 else STEP_SIDE] * 2
    rgb = to_uint8(np.asarray(cols))
    rgba = np.concatenate([rgb, np.full((len(rgb), 1), 255, np.uint8)], axis=1)
    return trimesh.Trimesh(vertices=np.concatenate(verts), faces=np.concatenate(faces), face_colors=rgba,
                           process=False)


class SkeletonRenderer:
    """Renders frames of skeleton scenes, keeping one off-screen pyvista window alive between calls.

    Creating an OpenGL context costs about a second, so animations and widgets render all their
    frames through one renderer. With ``backend="raster"`` (or when ``"auto"`` finds no OpenGL)
    frames are drawn by :func:`salad_viz.raster.rasterize_scene` instead.

    Parameters
    ----------
    skeleton : str or Skeleton
    size : (width, height)
        Image size in pixels.
    backend : {"auto", "pyvista", "raster"}
    bone_shape : {"capsule", "cylinder"}
        pyvista bone geometry (the rasteriser always draws capsules).
    background : colour
    supersample : int
        Anti-aliasing: SSAA in pyvista when > 1; the rasteriser's drawing-resolution factor.

    Examples
    --------
    >>> with SkeletonRenderer("humanml3d", size=(320, 240)) as r:      # doctest: +SKIP
    ...     frames = [r.render(joints, t) for t in range(len(joints))]
    """

    def __init__(self, skeleton: str | Skeleton = "humanml3d", *, size: Sequence[int] = (400, 300),
                 backend: str = "auto", bone_shape: str = "capsule", background=BACKGROUND,
                 supersample: int = 2):
        self.skeleton = get_skeleton(skeleton)
        self.size = check_size(size)
        if bone_shape not in BONE_SHAPES:
            raise ValueError(f"bone_shape must be one of {BONE_SHAPES}, got {bone_shape!r}")
        self.bone_shape = bone_shape
        self.background = to_rgb(background)
        self.supersample = int(supersample)
        self.backend = resolve_backend(backend)
        self._plotter = None
        self._floor = (None, None)  # (key, PolyData) of the last floor patch

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> "SkeletonRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the OpenGL window (safe to call twice)."""
        if self._plotter is not None:
            try:
                self._plotter.close()
            finally:
                self._plotter = None

    def __del__(self):  # pragma: no cover - best effort at interpreter exit
        try:
            self.close()
        except Exception:
            pass

    # ------------------------------------------------------------------ drawing
    def render(self, joints, frame: int = 0, *, camera: Camera | None = None, view: str | float = "three_quarter",
               elevation: float | None = None, follow: bool = True, colors=None, joint_colors=None,
               floor: bool = True, trajectory: bool = True, bone_radius: float = 0.022,
               joint_radius: float = 0.032, title: str | None = None, supports: bool | None = None) -> np.ndarray:
        """One frame as an image; arguments as in :func:`render_skeleton`. A ``title`` goes in a white band
        above the scene (the scene gets the rest of the image), so it never covers the figure.

        Returns
        -------
        ndarray (H, W, 3) uint8
        """
        motions = as_joints_list(joints, self.skeleton)
        frame = check_frame(frame, max(len(m) for m in motions))
        w, h = self.size
        band = caption_band([title], w, h) if title else None
        hs = h - (0 if band is None else band.shape[0])
        scene = build_scene(motions, self.skeleton, frame, camera=camera, view=view, elevation=elevation,
                            follow=follow, aspect=w / hs, colors=colors, joint_colors=joint_colors,
                            trajectory=trajectory, floor=floor, bone_radius=bone_radius,
                            joint_radius=joint_radius, supports=supports)
        img = self.render_scene(scene, size=(w, hs))
        return img if band is None else np.concatenate([band, img], axis=0)

    def render_scene(self, scene: FrameScene, size: Sequence[int] | None = None) -> np.ndarray:
        """Draw a prepared :class:`~salad_viz.scene.FrameScene` -> ``(H, W, 3)`` uint8 (``size``: the
        renderer's unless given)."""
        size = self.size if size is None else tuple(int(v) for v in size)
        if self.backend == "raster":
            return rasterize_scene(scene, self.skeleton, size, supersample=self.supersample,
                                   background=self.background)
        return self._render_pyvista(scene, size)

    def _get_plotter(self, size: tuple[int, int] | None = None):
        size = self.size if size is None else tuple(size)
        if self._plotter is None:
            _prepare_vtk_env()
            import pyvista as pv

            self._plotter = pv.Plotter(off_screen=True, window_size=size)
            self._plotter.set_background(self.background)
            if self.supersample > 1:
                self._plotter.enable_anti_aliasing("ssaa")
        elif tuple(self._plotter.window_size) != size:
            self._plotter.window_size = size
        return self._plotter

    def _render_pyvista(self, scene: FrameScene, size: tuple[int, int] | None = None) -> np.ndarray:
        import pyvista as pv

        p = self._get_plotter(size)
        p.clear_actors()
        if scene.floor_centre is not None:
            # the tiles are snapped to a world grid: rebuild only when the patch changes
            from .meshes import FLOOR_TILE

            (cx, cz), half = scene.floor_centre, scene.floor_half_extent
            key = tuple(int(f(v / FLOOR_TILE)) for f, v in ((np.floor, cx - half), (np.ceil, cx + half),
                                                             (np.floor, cz - half), (np.ceil, cz + half)))
            if self._floor[0] != key:
                self._floor = (key, _to_polydata(floor_mesh(scene.floor_centre, scene.floor_half_extent)))
            p.add_mesh(self._floor[1], scalars="rgba", rgb=True, lighting=False,
                       show_scalar_bar=False, name="floor", render=False)
        if scene.supports:
            p.add_mesh(_to_polydata(_steps_mesh(scene.supports)), scalars="rgba", rgb=True, ambient=0.45,
                       diffuse=0.6, specular=0.0, smooth_shading=False, show_scalar_bar=False, name="steps",
                       render=False)
        for k, (path, col) in enumerate(zip(scene.trajectories, scene.trajectory_colors)):
            if len(path) >= 2:
                pts = path.copy()
                pts[:, 1] = 0.004
                line = pv.lines_from_points(pts)
                p.add_mesh(line, color=col, line_width=max(1.5, self.size[1] / 160), lighting=False,
                           name=f"trajectory{k}", render=False)
        for k, (pose, bcol, jcol) in enumerate(zip(scene.poses, scene.bone_colors, scene.joint_colors)):
            mesh = body_mesh(pose, self.skeleton, bcol, jcol, bone_shape=self.bone_shape,
                             bone_radius=scene.bone_radius, joint_radius=scene.joint_radius)
            p.add_mesh(_to_polydata(mesh), scalars="rgba", rgb=True, ambient=0.35, diffuse=0.75,
                       specular=0.15, smooth_shading=False, show_scalar_bar=False, name=f"body{k}",
                       render=False)
        cam = scene.camera
        p.camera_position = [cam.position, cam.focal_point, cam.up]
        p.camera.view_angle = cam.view_angle
        p.renderer.ResetCameraClippingRange()
        # render explicitly: pyvista's screenshot alone can show the previous camera
        p.render()
        img = p.screenshot(return_img=True)
        return np.ascontiguousarray(img[..., :3]).copy()


def render_skeleton(
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
    bone_shape: str = "capsule",
    bone_radius: float = 0.022,
    joint_radius: float = 0.032,
    backend: str = "auto",
    title: str | None = None,
    supports: bool | None = None,
) -> np.ndarray:
    """Render one frame of one or several motions.

    Parameters
    ----------
    joints : array (N, J, 3) or list of arrays (N_k, J, 3)
        Joint positions in metres, +Y up, floor y = 0. A list draws several motions in one scene
        (e.g. source vs edited) with distinct colour themes; shorter motions hold their last pose.
    skeleton : str or Skeleton
    frame : int
        Frame index (negative counts from the end).
    camera : Camera, optional
        Explicit camera (see :mod:`salad_viz.camera`); otherwise built from the options below.
    view : str or float
        ``"front"``, ``"three_quarter"``, ``"side"``, ``"back"``, ``"top"`` or an azimuth in degrees.
    elevation : float, optional
        Degrees above the horizon (default: the view's).
    follow : bool
        Track the root (``True``) or keep a still camera that sees the whole motion.
    size : (width, height)
    colors : list, optional
        One entry per motion: ``None``, a colour, or ``(J, 3)`` bone colours.
    joint_colors : array (N, J, 3) or (J, 3), or list of those
        Per-joint colours, e.g. attention (:func:`salad_viz.attention.joint_attention_colors`).
    floor, trajectory : bool
    bone_shape : {"capsule", "cylinder"}
    bone_radius, joint_radius : float
        Metres.
    backend : {"auto", "pyvista", "raster"}
        ``"auto"`` uses pyvista when off-screen OpenGL works, the rasteriser otherwise.
    title : str, optional
    supports : bool, optional
        Draw steps under feet planted above the floor (stairs, a box stepped onto:
        :func:`salad_viz.scene.support_boxes`); default: with the floor, when a motion has such plants.

    Returns
    -------
    ndarray (H, W, 3) uint8
    """
    with SkeletonRenderer(skeleton, size=size, backend=backend, bone_shape=bone_shape) as r:
        return r.render(joints, frame, camera=camera, view=view, elevation=elevation, follow=follow,
                        colors=colors, joint_colors=joint_colors, floor=floor, trajectory=trajectory,
                        bone_radius=bone_radius, joint_radius=joint_radius, title=title, supports=supports)


def select_keyframes(n_frames: int, count: int) -> np.ndarray:
    """``count`` evenly spaced frame indices from 0 to ``n_frames - 1`` inclusive."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    return np.unique(np.round(np.linspace(0, n_frames - 1, min(count, n_frames))).astype(int))


def keyframe_strip(
    joints,
    skeleton: str | Skeleton = "humanml3d",
    frames: Sequence[int] | int = 6,
    *,
    layout: str = "trail",
    view: str | float = "side",
    elevation: float | None = None,
    size: Sequence[int] = (200, 260),
    colors=None,
    joint_colors=None,
    backend: str = "auto",
    labels: bool = True,
    fps: float | None = None,
    spacing: float | str | None = "auto",
    title: str | None = None,
) -> np.ndarray:
    """Key poses of a motion in one image, in the style of the papers' figures.

    Parameters
    ----------
    joints : array (N, J, 3) or list of arrays
        One motion, or several (e.g. source and edited) drawn together in each key pose.
    skeleton : str or Skeleton
    frames : sequence of int or int
        Frame indices, or how many evenly spaced frames to take.
    layout : {"trail", "row", "grid"}
        ``"trail"``: one wide scene from a still camera with every key pose at its real position,
        earlier poses faded (the papers' motion strips). ``"row"``: one tile per key pose with a
        camera that follows the root, side by side. ``"grid"``: tiles on two rows.
    view, elevation
        Camera view (``"side"`` suits walking along +Z).
    size : (width, height)
        Size of one tile (``"row"``/``"grid"``); for ``"trail"`` the height (the width follows the poses).
    colors, joint_colors
        As in :func:`render_skeleton`.
    backend : {"auto", "pyvista", "raster"}
    labels : bool
        Write the frame number (or time, when ``fps`` is given) on each tile.
    spacing : float, "auto" or None
        ``"trail"`` only: minimum distance in metres between consecutive poses across the image;
        poses closer than that (a motion in place) are shifted sideways, as in the papers'
        figures. ``"auto"``: a little more than the widest pose seen from the camera. ``None``
        keeps the real positions (and draws the root path).
    title : str, optional
        Written above the strip.

    Returns
    -------
    ndarray (H, W, 3) uint8
    """
    skel = get_skeleton(skeleton)
    motions = as_joints_list(joints, skel)
    n = max(len(m) for m in motions)
    idx = select_keyframes(n, frames) if isinstance(frames, (int, np.integer)) else \
        np.asarray([check_frame(int(f), n, "frames") for f in frames])
    if len(idx) == 0:
        raise ValueError("frames is empty")
    if layout not in ("trail", "row", "grid"):
        raise ValueError(f"layout must be 'trail', 'row' or 'grid', got {layout!r}")
    w, h = check_size(size)

    def _label(f: int) -> str:
        return f"{f / fps:.1f} s" if fps else f"frame {f}"

    if layout in ("row", "grid"):
        tiles = []
        with SkeletonRenderer(skel, size=(w, h), backend=backend) as r:
            for f in idx:
                tiles.append(r.render(motions, int(f), view=view, elevation=elevation, colors=colors,
                                      joint_colors=joint_colors, title=_label(int(f)) if labels else None))
        if layout == "row":
            img = hstack_images(tiles, gap=4)
        else:
            half = (len(tiles) + 1) // 2
            img = vstack_images([hstack_images(tiles[:half], gap=4), hstack_images(tiles[half:], gap=4)], gap=4)
    else:
        img = _trail_image(motions, skel, idx, view=view, elevation=elevation, size=(w, h), colors=colors,
                           joint_colors=joint_colors, backend=backend, labels=labels, label=_label,
                           spacing=spacing)
    if title:
        band = np.full((max(20, h // 9), img.shape[1], 3), 255, np.uint8)
        img = np.concatenate([draw_title(band, title), img], axis=0)
    return img


def _spread_shifts(roots: np.ndarray, right: np.ndarray, spacing: float) -> np.ndarray:
    """``(K, 3)`` shifts along the image's ``right`` axis keeping consecutive poses >= ``spacing`` apart.

    Poses keep their real positions where they are already far enough apart (a walk); a motion
    in place (a jump, a wave) is fanned out in the direction it drifts on screen.
    """
    x = roots @ right
    direction = 1.0 if x[-1] >= x[0] else -1.0
    y = direction * x
    z = y.copy()
    for i in range(1, len(z)):
        z[i] = max(y[i], z[i - 1] + spacing)
    return (direction * (z - y))[:, None] * right[None, :]


def _trail_image(motions, skel, idx, *, view, elevation, size, colors, joint_colors, backend, labels, label,
                 spacing):
    """All key poses in one still-camera scene; earlier poses are blended towards white."""
    from ._style import motion_bone_colors
    from .camera import Camera, fixed_camera, project_points, view_direction
    from .scene import frame_joint_colors

    w, h = size
    frames = [np.minimum(idx, len(m) - 1) for m in motions]
    direction = view_direction(view, elevation)
    right = Camera(tuple(direction), (0.0, 0.0, 0.0)).basis()[0]
    travel = (motions[0][frames[0][-1], 0] - motions[0][frames[0][0], 0]) @ right
    if view == "side" and travel < -0.05:
        # look from the other side so that time runs left to right, as in the papers' figures
        view = "left"
        direction = view_direction(view, elevation)
        right = Camera(tuple(direction), (0.0, 0.0, 0.0)).basis()[0]
    shifts = np.zeros((len(idx), 3))
    if spacing == "auto":
        # a little more than the widest key pose as seen from the camera
        widths = [np.ptp(m[f] @ right, axis=1).max() for m, f in zip(motions, frames)]
        spacing = max(0.55, 1.1 * max(widths))
    if spacing:
        shifts = _spread_shifts(motions[0][frames[0], 0], right, float(spacing))
    keyposes = [m[f] + shifts[:, None, :] for m, f in zip(motions, frames)]      # (K, J, 3) each
    pts = np.concatenate([k.reshape(-1, 3) for k in keyposes])
    probe = Camera(tuple(direction), (0.0, 0.0, 0.0))
    r, u, _ = probe.basis()
    aspect = float(np.clip(1.15 * np.ptp(pts @ r) / max(np.ptp(pts @ u), 0.5), 1.0, 8.0))
    width = int(min(4096, max(w, round(h * aspect))))
    width += width % 2
    # a narrow field of view keeps near and far poses at similar sizes
    # frame the poses plus room for the labels above the heads
    headroom = 0.3 if labels else 0.08
    tops = np.stack([keyposes[0][:, 0, 0], np.max([k[:, :, 1].max(axis=1) for k in keyposes], axis=0) + headroom,
                     keyposes[0][:, 0, 2]], axis=-1)
    framed = keyposes + [tops[:, None, :]]
    cam = fixed_camera(framed, view=view, elevation=elevation, aspect=width / h, margin=1.05,
                       view_angle=_TRAIL_VIEW_ANGLE)
    base = motion_bone_colors(skel, len(motions), colors)
    posed, cols, jcols = [], [], []
    for i, f in enumerate(idx):
        fade = 0.55 * (1.0 - (i + 1) / len(idx))  # the last pose is drawn at full colour
        per_frame = frame_joint_colors(joint_colors, len(motions), [len(m) for m in motions],
                                       skel.num_joints, int(f))
        for k in range(len(motions)):
            posed.append(keyposes[k][i][None])
            c = base[k] if per_frame[k] is None else per_frame[k]
            c = c + (1.0 - c) * fade
            cols.append(c)
            jcols.append(c * 0.7 if per_frame[k] is None else c)
    with SkeletonRenderer(skel, size=(width, h), backend=backend) as rend:
        scene = build_scene(posed, skel, 0, camera=cam, follow=False, aspect=width / h, colors=cols,
                            joint_colors=jcols, trajectory=False, floor=True)
        if not np.abs(shifts).any():  # real positions: the root path is meaningful
            scene = FrameScene(**{**scene.__dict__, "trajectories": tuple(m[:, 0, :].copy() for m in motions),
                                  "trajectory_colors": scene.trajectory_colors[: len(motions)]})
        img = rend.render_scene(scene)
    if labels:
        anchors = []
        for i in range(len(idx)):
            head = max(float(k[i, :, 1].max()) for k in keyposes)
            root = keyposes[0][i, 0]
            anchors.append(project_points(np.array([root[0], head + 0.12, root[2]]), cam, (width, h))[0])
        img = _labels_at(img, [label(int(f)) for f in idx], anchors)
    return img


def _labels_at(image: np.ndarray, texts: Sequence[str], anchors) -> np.ndarray:
    """Write each text centred above its anchor pixel, moving a label up while it overlaps another."""
    from PIL import Image, ImageDraw, ImageFont

    h = image.shape[0]
    try:
        font = ImageFont.load_default(size=max(10, min(16, h // 18)))
    except TypeError:
        font = ImageFont.load_default()
    pil = Image.fromarray(np.ascontiguousarray(image))
    draw = ImageDraw.Draw(pil)
    placed: list[tuple[float, float, float, float]] = []
    for text, (ax_, ay) in zip(texts, anchors):
        l, t, r, b = draw.textbbox((0, 0), text, font=font)
        tw, th = r - l, b - t
        x, y0 = float(ax_) - tw / 2, float(np.clip(float(ay) - th, 0, h - th - 1))
        # candidate rows: the anchor's, then alternately higher and lower
        steps = [0] + [s * k for k in range(1, 8) for s in (-1, 1)]
        y = y0
        for k in steps:
            y = y0 + k * (th + 3)
            if not 0 <= y <= h - th - 1:
                continue
            box = (x - 2, y - 1, x + tw + 2, y + th + 1)
            if not any(box[0] < q[2] and q[0] < box[2] and box[1] < q[3] and q[1] < box[3] for q in placed):
                break
        placed.append((x - 2, y - 1, x + tw + 2, y + th + 1))
        draw.text((x, y - t), text, fill=(40, 40, 40), font=font)
    return np.asarray(pil).copy()
