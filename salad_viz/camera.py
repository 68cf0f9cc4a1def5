"""Pinhole cameras shared by the pyvista renderer and the 2D rasteriser.

Both backends take the same :class:`Camera`, so a point lands on the same pixel whichever backend
draws it (:func:`project_points` is exactly VTK's projection with a vertical view angle). World
axes follow HumanML3D: +Y up, floor at y = 0, and a processed motion starts facing +Z.

Views are named by where the camera stands relative to a character facing +Z: ``"front"`` (on
+Z, looking at the face), ``"side"`` (on -X, the character's right, so that walking forward goes
left to right in the image), ``"left"`` (on +X), ``"back"``, ``"three_quarter"`` (front-left),
``"top"``; or give the azimuth in degrees (0 = front, 90 = left side, -90 = right side).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["Camera", "VIEWS", "follow_camera", "fixed_camera", "shared_follow_framing", "project_points",
           "view_direction"]

#: Camera azimuth (degrees, from +Z towards +X) and default elevation of each named view.
VIEWS: dict[str, tuple[float, float]] = {
    "front": (0.0, 12.0),
    "three_quarter": (35.0, 18.0),
    "side": (-90.0, 8.0),
    "left": (90.0, 8.0),
    "back": (180.0, 12.0),
    "top": (0.0, 80.0),
}


@dataclass(frozen=True)
class Camera:
    """A perspective camera (VTK conventions)."""

    position: tuple[float, float, float]      # eye position in world metres
    focal_point: tuple[float, float, float]   # point looked at
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)  # world up hint
    view_angle: float = 30.0                  # vertical field of view in degrees

    def __post_init__(self) -> None:
        for name in ("position", "focal_point", "up"):
            v = getattr(self, name)
            if len(v) != 3 or not np.isfinite(np.asarray(v, dtype=float)).all():
                raise ValueError(f"Camera.{name} must be 3 finite numbers, got {v!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if not 1.0 <= float(self.view_angle) <= 170.0:
            raise ValueError(f"Camera.view_angle must be in [1, 170] degrees, got {self.view_angle}")
        if np.allclose(self.position, self.focal_point):
            raise ValueError("Camera.position and Camera.focal_point coincide")

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit ``right``, ``up`` and ``forward`` vectors of the image plane, each ``(3,)``."""
        fwd = np.subtract(self.focal_point, self.position)
        fwd = fwd / np.linalg.norm(fwd)
        right = np.cross(fwd, self.up)
        if np.linalg.norm(right) < 1e-9:  # looking straight along `up`: pick any right vector
            right = np.cross(fwd, (0.0, 0.0, 1.0))
        right = right / np.linalg.norm(right)
        up = np.cross(right, fwd)
        return right, up, fwd


def view_direction(view: str | float, elevation: float | None = None) -> np.ndarray:
    """Unit vector from the focal point towards the camera for a named view or an azimuth."""
    if isinstance(view, str):
        if view not in VIEWS:
            raise ValueError(f"view {view!r} is not known; use one of {sorted(VIEWS)} or an azimuth in degrees")
        azim, elev_default = VIEWS[view]
    else:
        azim, elev_default = float(view), 15.0
    elev = elev_default if elevation is None else float(elevation)
    if not -89.0 <= elev <= 89.0:
        raise ValueError(f"elevation must be in [-89, 89] degrees, got {elev}")
    a, e = np.radians(azim), np.radians(elev)
    return np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])


def _smoothed_root(joints: np.ndarray, window: int) -> np.ndarray:
    """``(N, 3)`` root trajectory averaged over ``2*window+1`` frames (so the camera does not shake)."""
    root = joints[:, 0, :]
    if window <= 0 or len(root) < 3:
        return root
    pad = np.pad(root, ((window, window), (0, 0)), mode="edge")
    kernel = np.ones(2 * window + 1) / (2 * window + 1)
    return np.stack([np.convolve(pad[:, k], kernel, mode="valid") for k in range(3)], axis=1)


#: Share of the image half-width/height the framed motion may fill (1 / margin of the follow framing).
FOLLOW_MARGIN = 1.1


def _follow_cloud(joints: Sequence[np.ndarray], smooth: int) -> np.ndarray:
    """``(M, 3)`` every joint of every frame relative to its frame's smoothed root in x and z (y as it
    is), plus the floor under the root: what a camera following the root must keep in view."""
    pts = [np.zeros((1, 3))]
    for m in joints:
        root = _smoothed_root(m, smooth)
        rel = m - (root * np.array([1.0, 0.0, 1.0]))[:, None, :]
        pts.append(rel.reshape(-1, 3))
    return np.concatenate(pts)


def _fit_follow(cloud: np.ndarray, view: str | float, elevation: float | None, view_angle: float, aspect: float,
                margin: float = FOLLOW_MARGIN) -> tuple[float, float]:
    """``(distance, height)`` of the nearest follow camera that sees every point of ``cloud`` (root-relative,
    :func:`_follow_cloud`) inside the image shrunk by ``margin``, the focal height chosen to need the least
    distance. Points above the head (raised hands, a jump) count like any other."""
    direction = view_direction(view, elevation)
    right, up, fwd = Camera(tuple(direction), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), view_angle).basis()
    tan_v = np.tan(np.radians(view_angle) / 2.0) / margin
    tan_h = tan_v * aspect
    a, b, c = cloud @ right, cloud @ up, cloud @ fwd
    lo, hi = float(cloud[:, 1].min()), float(cloud[:, 1].max())
    heights = np.linspace(lo, hi, 41)[:, None]
    # focal point (0, h, 0): a point p is at (a, b - h up[1], c - h fwd[1]) from it in the camera basis,
    # and at depth D + c - h fwd[1]; it is in view when |a| <= depth tan_h and |b - h up[1]| <= depth tan_v
    cc = c[None, :] - heights * fwd[1]
    need = np.maximum(np.abs(a)[None, :] / tan_h, np.abs(b[None, :] - heights * up[1]) / tan_v) - cc
    dist = need.max(axis=1)
    k = int(np.argmin(dist))
    near = float((-cc[k]).max()) + 0.3          # every point well in front of the camera
    return max(float(dist[k]), near), float(heights[k, 0])


def follow_camera(
    joints: Sequence[np.ndarray],
    frame: int,
    *,
    view: str | float = "three_quarter",
    elevation: float | None = None,
    view_angle: float = 30.0,
    aspect: float = 4.0 / 3.0,
    distance: float | None = None,
    smooth: int = 4,
    height: float | None = None,
) -> Camera:
    """A camera that tracks the (smoothed) root of the motions at ``frame``.

    Parameters
    ----------
    joints : sequence of (N_k, J, 3) arrays
        The motions in the scene (already validated); shorter motions hold their last frame.
    frame : int
        Frame to look at.
    view, elevation : str or float, float
        Named view or azimuth in degrees; elevation in degrees (default: the view's).
    view_angle : float
        Vertical field of view in degrees.
    aspect : float
        Image width / height, used to fit the figure in the narrower field of view.
    distance : float, optional
        Camera distance in metres; by default the nearest at which every joint of every frame (hands
        raised above the head and jumps included) and the floor under the root stay in view while the
        camera follows the root (:func:`shared_follow_framing`).
    smooth : int
        Half-width in frames of the moving average applied to the root before following it.
    height : float, optional
        Height of the focal point in metres; by default the one that frames the motion tightest.
        Side-by-side panels pass one ``distance`` and ``height`` so all are drawn at one scale.
    """
    roots = np.stack([_smoothed_root(m, smooth)[min(frame, len(m) - 1)] for m in joints])
    centre = roots.mean(axis=0)
    if distance is None or height is None:
        # each motion around its own root, placed where its root is now relative to the focal point (one
        # motion: the same cloud at every frame, so the distance does not change while following)
        cloud = np.concatenate([_follow_cloud([m], smooth) + (r - centre) * np.array([1.0, 0.0, 1.0])
                                for m, r in zip(joints, roots)])
        fit_d, fit_h = _fit_follow(cloud, view, elevation, view_angle, aspect)
        distance = fit_d if distance is None else distance
        height = fit_h if height is None else height
    centre[1] = float(height)
    eye = centre + distance * view_direction(view, elevation)
    return Camera(tuple(eye), tuple(centre), (0.0, 1.0, 0.0), view_angle)


def shared_follow_framing(motions: Sequence[np.ndarray], *, view_angle: float = 30.0,
                          aspect: float = 4.0 / 3.0, view: str | float = "three_quarter",
                          elevation: float | None = None, smooth: int = 4) -> tuple[float, float]:
    """``(distance, height)`` in metres at which :func:`follow_camera` frames each motion alone and
    all at one scale: the nearest distance and its focal height at which every joint of every frame of
    every motion (raised hands, jumps) stays in view of a camera following that motion's root.

    Used for side-by-side panels, so that figures of the same size look the same size.
    """
    cloud = np.concatenate([_follow_cloud([m], smooth) for m in motions])
    return _fit_follow(cloud, view, elevation, view_angle, aspect)


def fixed_camera(
    joints: Sequence[np.ndarray],
    *,
    view: str | float = "three_quarter",
    elevation: float | None = None,
    view_angle: float = 30.0,
    aspect: float = 4.0 / 3.0,
    margin: float = 1.1,
) -> Camera:
    """A still camera that keeps every frame of every motion in view, framed tightly.

    The distance is the smallest at which every joint (and the floor under the root) projects
    inside the image shrunk by ``margin``.
    """
    pts = np.concatenate([m.reshape(-1, 3) for m in joints])
    floor_pts = np.concatenate([m[:, 0, :] * np.array([1.0, 0.0, 1.0]) for m in joints])
    pts = np.concatenate([pts, floor_pts])
    direction = view_direction(view, elevation)          # from the focal point towards the eye
    probe = Camera(tuple(direction), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), view_angle)
    right, up, fwd = probe.basis()
    a, b, c = pts @ right, pts @ up, pts @ fwd
    a0, b0, c0 = 0.5 * (a.min() + a.max()), 0.5 * (b.min() + b.max()), 0.5 * (c.min() + c.max())
    tan_v = np.tan(np.radians(view_angle) / 2.0) / margin
    tan_h = tan_v * aspect
    # a point at depth offset (c - c0) behind the focal plane needs distance D with
    # |a - a0| <= (D + c - c0) tan_h and |b - b0| <= (D + c - c0) tan_v
    dist = float(np.max(np.maximum(np.abs(a - a0) / tan_h, np.abs(b - b0) / tan_v) - (c - c0)))
    dist = max(dist, float(np.ptp(c)) / 2.0 + 0.5)
    centre = a0 * right + b0 * up + c0 * fwd
    eye = centre + dist * direction
    return Camera(tuple(eye), tuple(centre), (0.0, 1.0, 0.0), view_angle)


def project_points(points, camera: Camera, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Project world points to pixel coordinates.

    Parameters
    ----------
    points : array (..., 3)
        World coordinates in metres.
    camera : Camera
    size : (width, height)
        Image size in pixels.

    Returns
    -------
    pixels : ndarray (..., 2)
        ``(x, y)`` with x to the right and y *down* from the top-left corner (image rows = y).
    depth : ndarray (...)
        Distance along the viewing direction (points with depth <= 0 are behind the camera).
    """
    w, h = size
    p = np.asarray(points, dtype=np.float64)
    right, up, fwd = camera.basis()
    rel = p - np.asarray(camera.position)
    x, y, z = rel @ right, rel @ up, rel @ fwd
    f = (h / 2.0) / np.tan(np.radians(camera.view_angle) / 2.0)
    safe = np.where(np.abs(z) < 1e-9, 1e-9, z)
    # VTK maps normalised device coordinates [-1, 1] onto pixel edges [0, size].
    px = w / 2.0 + f * x / safe
    py = h / 2.0 - f * y / safe
    return np.stack([px, py], axis=-1), z
