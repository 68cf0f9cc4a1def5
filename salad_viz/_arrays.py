"""Input checks shared by salad_viz: arrays in (numpy or CPU torch), validated copies out.

Every public function passes its inputs through here, which is also what guarantees that inputs
are never mutated: the helpers always return new float64 arrays.
"""
from __future__ import annotations

import logging
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from salad_core.limits import MAX_JOINT_MAGNITUDE
from salad_core.skeleton import Skeleton

log = logging.getLogger(__name__)

__all__ = ["to_numpy", "as_joints", "as_joints_list", "check_frame", "check_size", "check_frames_memory",
           "atomic_output", "MAX_SIZE"]

# Joint extents above this many "metres" almost surely mean millimetres (KIT files).
_MAX_PLAUSIBLE_EXTENT_M = 50.0


def to_numpy(x, name: str) -> np.ndarray:
    """A float64 copy of an array-like (numpy array, list, or torch tensor on any device)."""
    if hasattr(x, "detach") and hasattr(x, "cpu"):  # torch tensor, without importing torch
        x = x.detach().cpu().numpy()
    kind = getattr(getattr(x, "dtype", None), "kind", None)
    if kind is not None and kind not in "iuf":        # complex parts would be dropped, strings parsed
        raise TypeError(f"{name} must hold real numbers, got dtype {x.dtype}")
    try:
        arr = np.array(x, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be an array of numbers, got {type(x).__name__}: {exc}") from None
    return arr


def as_joints(joints, skeleton: Skeleton, name: str = "joints") -> np.ndarray:
    """Validate one motion: ``(N, J, 3)`` (or one pose ``(J, 3)``), finite, within
    :data:`salad_core.limits.MAX_JOINT_MAGNITUDE` metres, J = skeleton joints.

    Returns a float64 copy of shape ``(N, J, 3)``.
    """
    arr = to_numpy(joints, name)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[-1] != 3 or arr.shape[1] != skeleton.num_joints:
        raise ValueError(
            f"{name} must have shape (N, J, 3) with J = {skeleton.num_joints} for skeleton "
            f"{skeleton.name!r}, got {tuple(np.shape(joints))}"
        )
    if arr.shape[0] == 0:
        raise ValueError(f"{name} has no frames (shape {arr.shape})")
    if not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name} contains NaN or inf (first at frame {bad[0]}, joint {bad[1]})")
    top = float(np.abs(arr).max())
    if top > MAX_JOINT_MAGNITUDE:       # a kilometre from the origin: another unit, or a broken array
        bad = np.unravel_index(int(np.argmax(np.abs(arr))), arr.shape)
        raise ValueError(f"{name} reaches |value| = {top:.3g} (frame {bad[0]}, joint {bad[1]}), beyond "
                         f"{MAX_JOINT_MAGNITUDE:g} m; joints are positions in metres (KIT millimetres: multiply by "
                         "skeleton.feature_scale)")
    extent = float(np.ptp(arr.reshape(-1, 3), axis=0).max())
    if extent > _MAX_PLAUSIBLE_EXTENT_M:
        log.warning("%s spans %.1f units; salad_viz expects metres (multiply KIT millimetres by "
                    "skeleton.feature_scale)", name, extent)
    return arr


def as_joints_list(joints, skeleton: Skeleton, name: str = "joints") -> list[np.ndarray]:
    """Motions as a list of validated ``(N_k, J, 3)`` copies.

    ``joints`` is one motion ``(N, J, 3)``, a batch ``(M, N, J, 3)``, or a list of arrays (one
    motion each; a ``(J, 3)`` array is a one-frame motion).
    """
    if isinstance(joints, (list, tuple)):
        if not joints:
            raise ValueError(f"{name} is an empty list; pass at least one (N, J, 3) motion")
        # a list of arrays is several motions (a (J, 3) entry is a one-frame motion); a list of
        # plain nested lists is one motion written out as lists
        if isinstance(joints[0], np.ndarray) or hasattr(joints[0], "detach"):
            return [as_joints(m, skeleton, f"{name}[{k}]") for k, m in enumerate(joints)]
    arr = to_numpy(joints, name)
    if arr.ndim == 4:  # (M, N, J, 3): a batch of equal-length motions
        return [as_joints(m, skeleton, f"{name}[{k}]") for k, m in enumerate(arr)]
    return [as_joints(arr, skeleton, name)]


def check_frame(frame: int, n_frames: int, name: str = "frame") -> int:
    """A frame index in ``[-n_frames, n_frames)`` as a non-negative int."""
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(frame).__name__}")
    if not -n_frames <= frame < n_frames:
        raise ValueError(f"{name}={frame} is out of range for a motion of {n_frames} frames")
    return int(frame) % n_frames


#: Largest image side in pixels. VTK renders at twice the size (anti-aliasing); at 100000 pixels it
#: aborted the process ("Frame buffer object was not initialized correctly") and at 20000 it grew to
#: 24 GB, so sizes are checked before anything is created.
MAX_SIZE = 4096

#: Largest memory, in bytes, the frames of one animation may take (checked before rendering).
MAX_ANIMATION_BYTES = 2 * 1024 ** 3


def check_size(size: Sequence[int], name: str = "size") -> tuple[int, int]:
    """``(width, height)`` in pixels, both in ``8..MAX_SIZE``."""
    if isinstance(size, (str, bytes)):
        raise ValueError(f"{name} must be (width, height) in pixels, got {size!r}")
    try:
        w, h = size
        if any(isinstance(v, bool) or float(v) != int(v) for v in (w, h)):
            raise ValueError
        w, h = int(w), int(h)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be (width, height) in whole pixels, got {size!r}") from None
    if not (8 <= w <= MAX_SIZE and 8 <= h <= MAX_SIZE):
        raise ValueError(f"{name} must be at least 8x8 and at most {MAX_SIZE}x{MAX_SIZE} pixels, got {size!r}")
    return w, h


def check_frames_memory(n_frames: int, width: int, height: int, name: str = "animation") -> None:
    """Refuse ``n_frames`` RGB frames of ``width x height`` beyond :data:`MAX_ANIMATION_BYTES`."""
    need = int(n_frames) * int(width) * int(height) * 3
    if need > MAX_ANIMATION_BYTES:
        raise ValueError(f"the {name} would need {need / 1024 ** 3:.1f} GiB for {n_frames} frames of {width}x{height} "
                         f"pixels (at most {MAX_ANIMATION_BYTES / 1024 ** 3:g} GiB); use a smaller size or a larger "
                         "stride")


@contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path with the same suffix beside ``path``; rename it onto ``path`` on success.

    The suffix is kept because writers (imageio, trimesh) pick the format from it. On any
    exception the temporary file is removed and ``path`` is left untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix="".join(path.suffixes[-1:]), dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; outputs get normal permissions
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
