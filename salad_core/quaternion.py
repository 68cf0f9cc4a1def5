"""Quaternion and rotation-matrix helpers, for numpy arrays and torch tensors alike.

Conventions (those of HumanML3D's ``common/quaternion.py``, see ``humanml3d_eval_facts`` §2.6):

- quaternions are ``(..., 4)`` in ``(w, x, y, z)`` order with the Hamilton product;
- rotations are *active*: ``qrot(q, v)`` rotates the vector ``v`` by ``q``;
- ``qinv`` is the conjugate (the inputs are assumed to be unit quaternions);
- a rotation matrix ``R`` is ``(..., 3, 3)`` and acts on column vectors (``v' = R v``);
- the continuous 6D representation ("cont6d", Zhou et al. 2019) is the first two **columns** of
  ``R`` concatenated as ``(R00, R10, R20, R01, R11, R21)``.

Every function is vectorised over the leading axes and accepts either numpy arrays (returns
numpy) or torch tensors (returns torch, differentiable). Both operands of a binary function must
be of the same kind; shapes broadcast.
"""
from __future__ import annotations

from typing import Union

import numpy as np
import torch

__all__ = [
    "qnormalize",
    "qmul",
    "qinv",
    "qrot",
    "qbetween",
    "quat_from_axis_angle",
    "quat_to_matrix",
    "matrix_to_quat",
    "cont6d_to_matrix",
    "matrix_to_cont6d",
    "quat_to_cont6d",
]

Array = Union[np.ndarray, torch.Tensor]

# Below this norm a vector is treated as zero (degenerate bone, coincident points).
_EPS = 1e-12


# --------------------------------------------------------------------------- backend helpers
def _is_torch(x) -> bool:
    return isinstance(x, torch.Tensor)


def _stack(xs, axis: int = -1):
    return torch.stack(xs, dim=axis) if _is_torch(xs[0]) else np.stack(xs, axis=axis)


def _sqrt(x):
    return torch.sqrt(x) if _is_torch(x) else np.sqrt(x)


def _clamp_min(x, lo: float):
    return torch.clamp(x, min=lo) if _is_torch(x) else np.maximum(x, lo)


def _where(cond, a, b):
    return torch.where(cond, a, b) if _is_torch(cond) else np.where(cond, a, b)


def _check_last(x, size: int, name: str) -> None:
    if x.shape[-1] != size:
        raise ValueError(f"{name} must have a last axis of size {size}, got shape {tuple(x.shape)}")


def _cross(a, b):
    """Cross product over the last axis, written with components so that it broadcasts."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return _stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx])


def _dot(a, b):
    return (a * b).sum(-1)


def _normalize_vec(v, eps: float = _EPS):
    n = _sqrt(_clamp_min(_dot(v, v), eps * eps))
    return v / n[..., None]


# --------------------------------------------------------------------------- quaternions
def qnormalize(q: Array, eps: float = _EPS) -> Array:
    """Scale quaternions ``(..., 4)`` to unit length (a zero quaternion stays zero)."""
    _check_last(q, 4, "q")
    return _normalize_vec(q, eps)


def qmul(a: Array, b: Array) -> Array:
    """Hamilton product ``a * b`` of quaternions ``(..., 4)``: rotate by ``b`` first, then ``a``."""
    _check_last(a, 4, "a")
    _check_last(b, 4, "b")
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return _stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def qinv(q: Array) -> Array:
    """Inverse of unit quaternions ``(..., 4)``: the conjugate ``(w, -x, -y, -z)``."""
    _check_last(q, 4, "q")
    return _stack([q[..., 0], -q[..., 1], -q[..., 2], -q[..., 3]])


def qrot(q: Array, v: Array) -> Array:
    """Rotate vectors ``v`` ``(..., 3)`` by unit quaternions ``q`` ``(..., 4)`` (broadcasting).

    Uses ``v + 2 (w (u x v) + u x (u x v))`` with ``u = (x, y, z)``.
    """
    _check_last(q, 4, "q")
    _check_last(v, 3, "v")
    w = q[..., :1]
    u = q[..., 1:]
    uv = _cross(u, v)
    uuv = _cross(u, uv)
    return v + 2.0 * (w * uv + uuv)


def qbetween(a: Array, b: Array) -> Array:
    """Shortest-arc unit quaternion rotating direction ``a`` onto direction ``b`` (both ``(..., 3)``).

    ``normalize([|a||b| + a.b, a x b])`` as in HumanML3D, so ``w >= 0``. Where ``a`` and ``b`` are
    opposite that formula is 0/0; we return a half turn about an axis perpendicular to ``a``
    instead (HumanML3D would produce NaN there).
    """
    _check_last(a, 3, "a")
    _check_last(b, 3, "b")
    v = _cross(a, b)
    w = _sqrt(_dot(a, a) * _dot(b, b)) + _dot(a, b)
    q = _stack([w, v[..., 0], v[..., 1], v[..., 2]])
    sq = _dot(q, q)
    # Scale-aware degeneracy test: |q|^2 is ~|a|^2|b|^2 for well-posed pairs.
    scale = _dot(a, a) * _dot(b, b)
    degenerate = sq <= 1e-12 * _clamp_min(scale, _EPS)
    if bool(degenerate.any()):
        # Perpendicular axis: a x e_x, or a x e_y when a is (nearly) parallel to e_x.
        ex = _stack([a[..., 0] * 0 + 1, a[..., 1] * 0, a[..., 2] * 0])
        ey = _stack([a[..., 0] * 0, a[..., 1] * 0 + 1, a[..., 2] * 0])
        ax1 = _cross(a, ex)
        ax2 = _cross(a, ey)
        use2 = (_dot(ax1, ax1) < _dot(ax2, ax2))[..., None]
        axis = _normalize_vec(_where(use2, ax2, ax1))
        half_turn = _stack([axis[..., 0] * 0, axis[..., 0], axis[..., 1], axis[..., 2]])
        q = _where(degenerate[..., None], half_turn, q)
    return qnormalize(q)


def quat_from_axis_angle(axis: Array, angle: Array) -> Array:
    """Unit quaternions ``(..., 4)`` for rotations by ``angle`` (radians, ``(...)``) about ``axis`` ``(..., 3)``."""
    _check_last(axis, 3, "axis")
    axis = _normalize_vec(axis)
    half = angle * 0.5
    if _is_torch(half):
        c, s = torch.cos(half), torch.sin(half)
    else:
        c, s = np.cos(half), np.sin(half)
    return _stack([c + 0 * axis[..., 0], s * axis[..., 0], s * axis[..., 1], s * axis[..., 2]])


# --------------------------------------------------------------------------- matrices
def quat_to_matrix(q: Array) -> Array:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)``."""
    _check_last(q, 4, "q")
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r0 = _stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)])
    r1 = _stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)])
    r2 = _stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
    return _stack([r0, r1, r2], axis=-2)


def matrix_to_quat(R: Array) -> Array:
    """Unit quaternions ``(..., 4)`` with ``w >= 0`` from rotation matrices ``(..., 3, 3)``.

    Shepperd's method: of the four algebraically equivalent formulas, each element uses the one
    with the largest (best-conditioned) denominator.
    """
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have trailing shape (3, 3), got shape {tuple(R.shape)}")
    m00, m01, m02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    m10, m11, m12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    m20, m21, m22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    # 4*w^2, 4*x^2, 4*y^2, 4*z^2
    diag = _stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22])
    cands = _stack([
        _stack([diag[..., 0], m21 - m12, m02 - m20, m10 - m01]),
        _stack([m21 - m12, diag[..., 1], m10 + m01, m02 + m20]),
        _stack([m02 - m20, m10 + m01, diag[..., 2], m12 + m21]),
        _stack([m10 - m01, m20 + m02, m21 + m12, diag[..., 3]]),
    ], axis=-2)  # (..., 4 candidates, 4 components), each proportional to q
    if _is_torch(R):
        best = diag.argmax(-1)
        idx = best[..., None, None].expand(*best.shape, 1, 4)
        q = torch.gather(cands, -2, idx)[..., 0, :]
        q = q * torch.where(q[..., :1] < 0, -1.0, 1.0).to(q.dtype)
    else:
        best = diag.argmax(-1)
        q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
        q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    return qnormalize(q)


def cont6d_to_matrix(cont6d: Array) -> Array:
    """Rotation matrices ``(..., 3, 3)`` from cont6d ``(..., 6)`` (Gram-Schmidt, HumanML3D order).

    ``x = normalize(c[0:3])``, ``z = normalize(x x c[3:6])``, ``y = z x x``; ``R = [x | y | z]``
    (columns).
    """
    _check_last(cont6d, 6, "cont6d")
    x = _normalize_vec(cont6d[..., 0:3])
    z = _normalize_vec(_cross(x, cont6d[..., 3:6]))
    y = _cross(z, x)
    return _stack([x, y, z], axis=-1)


def matrix_to_cont6d(R: Array) -> Array:
    """cont6d ``(..., 6)`` = first two columns of ``R`` ``(..., 3, 3)``: ``(R00,R10,R20,R01,R11,R21)``."""
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have trailing shape (3, 3), got shape {tuple(R.shape)}")
    if _is_torch(R):
        return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)
    return np.concatenate([R[..., :, 0], R[..., :, 1]], axis=-1)


def quat_to_cont6d(q: Array) -> Array:
    """cont6d ``(..., 6)`` of unit quaternions ``(..., 4)``."""
    return matrix_to_cont6d(quat_to_matrix(q))
