"""Reading BVH motion-capture files and their forward kinematics.

A BVH file is a joint hierarchy (``HIERARCHY``: ``ROOT``/``JOINT`` blocks with an ``OFFSET`` from
the parent, a ``CHANNELS`` list and optional ``End Site`` blocks) followed by the motion
(``MOTION``: ``Frames:``, ``Frame Time:`` and one line of channel values per frame, in the order
the channels were declared, depth first).

Conventions implemented here (those of the common exporters: MotionBuilder, Blender, CMU's
conversion, Mixamo, this project's :func:`salad_viz.export.export_bvh`):

* rotation channels are Euler angles in degrees, composed in the order they are listed, each a
  rotation about a fixed parent-frame axis applied to column vectors: ``Zrotation Xrotation
  Yrotation`` gives ``R = Rz @ Rx @ Ry``. Any permutation (and any subset) of the three axes works;
* a joint's local translation is its ``OFFSET``; position channels, on the root or on any other
  joint, *replace* the offset's coordinates they name (MotionBuilder/Mixamo files with 6 channels
  on every joint store the offset there);
* the world transform is ``parent_R @ local_R`` and the world position
  ``parent_p + parent_R @ local_translation``; an End Site is a point at its offset in its joint's
  frame.

Parsing is written here rather than delegated to a PyPI parser so that every malformed file gets
an error naming the problem and its line (:class:`BvhError`), and forward kinematics is
vectorised over frames with numpy.
"""
from __future__ import annotations

import logging
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from salad_core import limits

__all__ = ["BvhError", "BvhJoint", "BvhMotion", "read_bvh", "parse_bvh", "CHANNEL_NAMES"]

#: Channel names a BVH file may declare (matched case-insensitively).
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CHANNEL_KEY = {n.lower(): n for n in CHANNEL_NAMES}
_AXIS = {"X": 0, "Y": 1, "Z": 2}

log = logging.getLogger(__name__)


class BvhError(ValueError):
    """A malformed BVH file. ``str(err)`` reads ``<file>, line <n>: <problem>``.

    Attributes
    ----------
    path : str
        The file (or ``"<string>"`` for text).
    line : int or None
        1-based line of the problem (``None`` when it concerns the whole file).
    problem : str
        What is wrong, without the location.
    """

    def __init__(self, path: str, line: int | None, problem: str):
        self.path, self.line, self.problem = path, line, problem
        where = path if line is None else f"{path}, line {line}"
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class BvhJoint:
    """One ``ROOT`` or ``JOINT`` of the hierarchy.

    Attributes
    ----------
    name : str
    parent : int
        Index of the parent joint, -1 for the root.
    offset : tuple of 3 floats
        Rest translation from the parent, in the file's length unit.
    channels : tuple of str
        The declared channels (canonical spelling, e.g. ``"Zrotation"``), in order.
    first_channel : int
        Column of the joint's first channel in a frame line.
    end_site : tuple of 3 floats or None
        Offset of the joint's End Site, if it has one.
    line : int
        Line of the joint's ``ROOT``/``JOINT`` keyword.
    channels_line : int
        Line of its ``CHANNELS`` statement (0 when it has none).
    """

    name: str
    parent: int
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    first_channel: int
    end_site: tuple[float, float, float] | None
    line: int
    channels_line: int = 0


@dataclass(frozen=True, eq=False)
class BvhMotion:
    """A parsed BVH file.

    Attributes
    ----------
    joints : tuple of BvhJoint
        Depth-first order (parents before children); ``joints[0]`` is the root.
    frame_time : float
        Seconds per frame (``Frame Time:``).
    values : ndarray (N, C) float64
        Channel values per frame (C = total channel count, degrees and file length units).
    path : str
        Where the motion was read from (``"<string>"`` for text).
    """

    joints: tuple[BvhJoint, ...]
    frame_time: float
    values: np.ndarray
    path: str = "<string>"

    @property
    def num_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def parents(self) -> tuple[int, ...]:
        return tuple(j.parent for j in self.joints)

    def point_names(self) -> tuple[str, ...]:
        """Names of the points :meth:`world_positions` returns: the joints, then every End Site as
        ``"<joint>/End"`` (in joint order)."""
        return self.joint_names + tuple(f"{j.name}/End" for j in self.joints if j.end_site is not None)

    def point_parents(self) -> tuple[int, ...]:
        """Parent point of each point of :meth:`point_names` (End Sites hang from their joint)."""
        return self.parents + tuple(i for i, j in enumerate(self.joints) if j.end_site is not None)

    def world_positions(self, frames: slice | np.ndarray | None = None, *, rest: bool = False) -> np.ndarray:
        """Forward kinematics: world positions of every joint and End Site.

        Parameters
        ----------
        frames : slice or index array, optional
            Frames to evaluate (default all).
        rest : bool
            Evaluate the rest pose instead: one frame of the offsets alone (no rotation, and the
            OFFSET, not a zero, where a joint has position channels).

        Returns
        -------
        ndarray (N, P, 3) float64
            In the file's length unit and axes; P = joints + End Sites, in :meth:`point_names`
            order.
        """
        vals = np.zeros((1, self.values.shape[1])) if rest else self.values
        if frames is not None and not rest:
            vals = vals[frames]
        n = vals.shape[0]
        pos = np.zeros((n, len(self.joints), 3))
        rot = np.zeros((n, len(self.joints), 3, 3))
        for i, j in enumerate(self.joints):
            local_t = np.broadcast_to(np.asarray(j.offset, dtype=np.float64), (n, 3)).copy()
            local_r = None
            for k, ch in enumerate(() if rest else j.channels):
                col = vals[:, j.first_channel + k]
                axis = _AXIS[ch[0]]
                if ch.endswith("position"):
                    local_t[:, axis] = col
                else:
                    r = _axis_rotation(axis, np.deg2rad(col))
                    local_r = r if local_r is None else local_r @ r
            if local_r is None:
                local_r = np.broadcast_to(np.eye(3), (n, 3, 3))
            if j.parent < 0:
                pos[:, i] = local_t
                rot[:, i] = local_r
            else:
                pr = rot[:, j.parent]
                pos[:, i] = pos[:, j.parent] + np.einsum("nab,nb->na", pr, local_t)
                rot[:, i] = pr @ local_r
        ends = [(i, np.asarray(j.end_site, dtype=np.float64)) for i, j in enumerate(self.joints)
                if j.end_site is not None]
        if ends:
            end_pos = np.stack([pos[:, i] + rot[:, i] @ off for i, off in ends], axis=1)
            pos = np.concatenate([pos, end_pos], axis=1)
        return pos


def _axis_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)`` rotations by ``angle`` (radians, ``(N,)``) about coordinate axis ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    a, b = [(1, 2), (2, 0), (0, 1)][axis]      # the plane the rotation acts in, right-handed
    out[..., axis, axis] = 1.0
    out[..., a, a] = c
    out[..., a, b] = -s
    out[..., b, a] = s
    out[..., b, b] = c
    return out


# ----------------------------------------------------------------------------- parsing
class _Tokens:
    """Whitespace tokens of the hierarchy with their line numbers."""

    def __init__(self, lines: list[str], path: str):
        self.path = path
        self.items: list[tuple[str, int]] = []
        self.motion_line: int | None = None       # index (0-based) of the MOTION line
        for i, line in enumerate(lines):
            toks = line.split()
            if toks and toks[0].upper() == "MOTION":
                self.motion_line = i
                break
            self.items.extend((t, i + 1) for t in toks)
        self.pos = 0
        self.last_line = len(lines)

    def error(self, line: int | None, problem: str) -> BvhError:
        return BvhError(self.path, line, problem)

    def peek(self) -> tuple[str, int] | None:
        return self.items[self.pos] if self.pos < len(self.items) else None

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            line = self.items[-1][1] if self.items else None
            where = "the MOTION section" if self.motion_line is not None else "the end of the file"
            raise self.error(line, f"the hierarchy is truncated: expected {what} but reached {where}")
        tok = self.items[self.pos]
        self.pos += 1
        return tok

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise self.error(line, f"expected {word!r}, got {tok!r}")
        return line

    def rest_of_line(self, line: int) -> list[str]:
        out = []
        while (nxt := self.peek()) is not None and nxt[1] == line and nxt[0] != "{":
            out.append(nxt[0])
            self.pos += 1
        return out

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            value = float(tok)
        except ValueError:
            raise self.error(line, f"{what} must be a number, got {tok!r}") from None
        if (problem := limits.ascii_number_problem(tok, what)) is not None:
            raise self.error(line, problem)
        if not math.isfinite(value):
            raise self.error(line, f"{what} is {tok} (NaN or infinite)")
        return value


def _parse_offset(tokens: _Tokens, owner: str) -> tuple[float, float, float]:
    tokens.expect("OFFSET")
    return tuple(tokens.number(f"OFFSET {axis} of {owner}") for axis in "xyz")  # type: ignore[return-value]


def _open_joint(tokens: _Tokens, kw_line: int, parent: int, joints: list[BvhJoint], n_channels: int,
                depth: int) -> int:
    """Read a ROOT/JOINT header (name, ``{``, OFFSET, optional CHANNELS), append the joint; returns the
    channel count so far. The joint count and the nesting ``depth`` are checked first."""
    if (problem := limits.hierarchy_problem(len(joints) + 1, depth)) is not None:
        raise tokens.error(kw_line, problem)
    name_toks = tokens.rest_of_line(kw_line)
    if not name_toks:
        raise tokens.error(kw_line, "a ROOT/JOINT keyword without a joint name")
    name = " ".join(name_toks)
    tokens.expect("{")
    offset = _parse_offset(tokens, f"joint {name!r}")
    channels: tuple[str, ...] = ()
    ch_line = 0
    nxt = tokens.peek()
    if nxt is not None and nxt[0].upper() == "CHANNELS":
        _, ch_line = tokens.next("CHANNELS")
        count_tok, line = tokens.next("the channel count")
        if not (count_tok.isascii() and count_tok.lstrip("+-").isdigit()):
            raise tokens.error(line, f"CHANNELS of joint {name!r}: the count must be an integer, got {count_tok!r}")
        count = int(count_tok)
        names = tokens.rest_of_line(ch_line)
        if count < 0 or count > 6 or count != len(names):
            raise tokens.error(ch_line, f"CHANNELS of joint {name!r} declares {count} channel(s) but lists "
                                        f"{len(names)} ({' '.join(names) or 'none'}); a joint has 0-6 channels")
        canon = []
        for n in names:
            if n.lower() not in _CHANNEL_KEY:
                raise tokens.error(ch_line, f"unknown channel {n!r} on joint {name!r}; allowed: "
                                            f"{', '.join(CHANNEL_NAMES)}")
            canon.append(_CHANNEL_KEY[n.lower()])
        if len(set(canon)) != len(canon):
            raise tokens.error(ch_line, f"joint {name!r} declares a channel twice: {' '.join(names)}")
        channels = tuple(canon)
    joints.append(BvhJoint(name, parent, offset, channels, n_channels, None, kw_line, ch_line))
    return n_channels + len(channels)


def _parse_hierarchy(tokens: _Tokens, root_line: int) -> tuple[list[BvhJoint], int]:
    """The joints (depth first) and the channel count of the hierarchy whose ROOT keyword is on
    ``root_line``. Iterative (a stack of the open joints), so no file can make Python recurse; the
    nesting is bounded by :data:`salad_core.limits.BVH_MAX_DEPTH`."""
    joints: list[BvhJoint] = []
    n_channels = _open_joint(tokens, root_line, -1, joints, 0, 1)
    stack: list[list] = [[0, None]]           # open joints: [index, End Site offset or None]
    while stack:
        index, end_site = stack[-1]
        name = joints[index].name
        tok, line = tokens.next(f"'}}' closing joint {name!r}")
        key = tok.upper()
        if key == "JOINT":
            n_channels = _open_joint(tokens, line, index, joints, n_channels, len(stack) + 1)
            stack.append([len(joints) - 1, None])
        elif key == "END":
            site = tokens.rest_of_line(line)
            if [s.upper() for s in site] != ["SITE"]:
                raise tokens.error(line, f"expected 'End Site', got {' '.join(['End', *site])!r}")
            if end_site is not None:
                raise tokens.error(line, f"joint {name!r} has a second End Site")
            tokens.expect("{")
            stack[-1][1] = _parse_offset(tokens, f"the End Site of {name!r}")
            tokens.expect("}")
        elif tok == "}":
            stack.pop()
            if end_site is not None:
                j = joints[index]
                joints[index] = BvhJoint(j.name, j.parent, j.offset, j.channels, j.first_channel, end_site, j.line,
                                         j.channels_line)
        else:
            raise tokens.error(line, f"expected JOINT, End Site or '}}' in joint {name!r}, got {tok!r}")
    return joints, n_channels


#: Characters of a frame line of plain ASCII numbers (a line with others is checked token by token).
_ROW_CHARS = re.compile(r"[0-9eE+\-.\s]*", re.ASCII)
_FRAMES_RE = re.compile(r"^\s*Frames\s*:\s*(\S+)\s*$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^\s*Frame\s+Time\s*:\s*(\S+)\s*$", re.IGNORECASE)


def _channel_label(joints: tuple[BvhJoint, ...], column: int) -> str:
    for j in joints:
        if j.first_channel <= column < j.first_channel + len(j.channels):
            return f"{j.name} {j.channels[column - j.first_channel]}"
    return f"column {column + 1}"


def _root_chain(joints: tuple[BvhJoint, ...]) -> list[BvhJoint]:
    """The root and its single-child descendants down to the first branching joint: where a file
    may carry the root motion (``Reference > Hips`` rigs move the hips, not the reference)."""
    chain = [0]
    while True:
        kids = [i for i, j in enumerate(joints) if j.parent == chain[-1]]
        if len(kids) != 1:
            return [joints[i] for i in chain]
        chain.append(kids[0])


def parse_bvh(text: str, path: str = "<string>") -> BvhMotion:
    """Parse the contents of a BVH file (see :func:`read_bvh`)."""
    if (problem := limits.file_size_problem(len(text), limits.BVH_MAX_FILE_BYTES, "BVH text")) is not None:
        raise BvhError(path, None, problem)
    lines = text.splitlines()
    tokens = _Tokens(lines, path)
    first = tokens.peek()
    if first is None:
        raise BvhError(path, None, "the file is empty" if not text.strip() else "no HIERARCHY section")
    if first[0].upper() != "HIERARCHY":
        raise BvhError(path, first[1], f"a BVH file starts with HIERARCHY, got {first[0]!r}")
    tokens.next("HIERARCHY")
    tok, line = tokens.next("ROOT")
    if tok.upper() != "ROOT":
        raise BvhError(path, line, f"expected ROOT after HIERARCHY, got {tok!r}")
    joints, width = _parse_hierarchy(tokens, line)
    if (extra := tokens.peek()) is not None:
        problem = ("a second ROOT: files with several skeletons are not supported" if extra[0].upper() == "ROOT"
                   else f"unexpected {extra[0]!r} after the hierarchy (expected MOTION)")
        raise BvhError(path, extra[1], problem)
    if tokens.motion_line is None:
        raise BvhError(path, len(lines), "the file ends after the hierarchy: no MOTION section")
    joints_t = tuple(joints)
    carriers = _root_chain(joints_t)
    if not any(c.endswith("position") for j in carriers for c in j.channels):
        root = joints_t[0]
        verb = "does" if len(carriers) == 2 else "do"
        below = f" nor {verb} {', '.join(repr(j.name) for j in carriers[1:])} below it" if len(carriers) > 1 else ""
        raise BvhError(path, root.channels_line or root.line,
                       f"the root joint {root.name!r} has no position channels "
                       f"({' '.join(root.channels) or 'no channels'}){below}: the file carries no root motion")

    # MOTION section: Frames, Frame Time, then one line per frame
    i = tokens.motion_line + 1
    header: list[tuple[str, int]] = []
    while i < len(lines) and len(header) < 2:
        if lines[i].strip():
            header.append((lines[i], i + 1))
        i += 1
    if len(header) < 1:
        raise BvhError(path, tokens.motion_line + 1, "the file ends after MOTION: no 'Frames:' line")
    m = _FRAMES_RE.match(header[0][0])
    if not m:
        raise BvhError(path, header[0][1], f"expected 'Frames: <count>', got {header[0][0].strip()!r}")
    if not re.fullmatch(r"[+-]?[0-9]+", m.group(1)):    # int() would also read other digits and '1_000'
        raise BvhError(path, header[0][1], f"the frame count must be an integer, got {m.group(1)!r}")
    n_frames = int(m.group(1))
    if n_frames <= 0:
        raise BvhError(path, header[0][1], f"the file has {n_frames} frames; a motion needs at least one")
    n_points = len(joints_t) + sum(j.end_site is not None for j in joints_t)
    if (problem := limits.bvh_size_problem(n_frames, len(joints_t), n_points)) is not None:
        raise BvhError(path, header[0][1], problem)
    if len(header) < 2:
        raise BvhError(path, header[0][1], "the file ends after 'Frames:': no 'Frame Time:' line")
    m = _FRAME_TIME_RE.match(header[1][0])
    if not m:
        raise BvhError(path, header[1][1], f"expected 'Frame Time: <seconds>', got {header[1][0].strip()!r}")
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise BvhError(path, header[1][1], f"the frame time must be a number, got {m.group(1)!r}") from None
    problem = (limits.ascii_number_problem(m.group(1), "the frame time")
               or limits.frame_time_problem(frame_time))
    if problem is not None:
        raise BvhError(path, header[1][1], problem)

    rows: list[list[str]] = []
    row_lines: list[int] = []
    while i < len(lines) and len(rows) < n_frames:
        toks = lines[i].split()
        i += 1
        if not toks:
            continue
        if len(toks) != width:
            hint = " (the line looks cut short: is the file truncated?)" if len(toks) < width else ""
            raise BvhError(path, i, f"frame {len(rows) + 1} has {len(toks)} values, but the hierarchy declares "
                                    f"{width} channels{hint}")
        if not _ROW_CHARS.fullmatch(lines[i - 1]):       # numpy, like float(), reads other digits too
            for c, t in enumerate(toks):
                what = f"frame {len(rows) + 1}: value ({_channel_label(joints_t, c)})"
                try:
                    float(t)
                except ValueError:
                    continue            # reported below as "is not a number"
                if (problem := limits.ascii_number_problem(t, what)) is not None:
                    raise BvhError(path, i, problem)
        rows.append(toks)
        row_lines.append(i)
    if len(rows) < n_frames:
        raise BvhError(path, len(lines), f"the file is truncated: 'Frames: {n_frames}' but it ends after "
                                         f"{len(rows)} frame line(s)")
    try:
        values = np.array(rows, dtype=np.float64).reshape(n_frames, width)
    except ValueError:
        for toks, ln in zip(rows, row_lines):
            for c, t in enumerate(toks):
                try:
                    float(t)
                except ValueError:
                    raise BvhError(path, ln, f"value {t!r} ({_channel_label(joints_t, c)}) is not a number") from None
        raise
    bad = ~np.isfinite(values)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise BvhError(path, row_lines[r], f"frame {r + 1} has a non-finite value {rows[r][c]} "
                                           f"({_channel_label(joints_t, int(c))}); {int(bad.sum())} in all")
    extra = sum(1 for rest in lines[i:] if rest.strip())
    if extra:   # some exporters miscount; the declared frames are kept, the rest is reported
        log.warning("%s: %d line(s) after the %d frames 'Frames:' declares (from line %d) are ignored",
                    path, extra, n_frames, i + 1)
    return BvhMotion(joints_t, frame_time, values, path)


def read_bvh(path: str | os.PathLike) -> BvhMotion:
    """Read a BVH file.

    Parameters
    ----------
    path : str or PathLike
        The ``.bvh`` file (ASCII/UTF-8; a byte-order mark is ignored).

    Returns
    -------
    BvhMotion
        The hierarchy, the frame time and the ``(N, C)`` channel values.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    BvhError
        If the file is malformed (truncated, a frame line with the wrong number of values, NaN or
        infinite values, numbers in other than ASCII digits, no root position channels, zero frames,
        ...) or beyond the limits of :mod:`salad_core.limits` (a Frame Time outside 1e-4..1 s, more than
        1,000,000 frames, a hierarchy of more than 1,000 joints or nested more than 128 deep, a file over
        64 MiB, forward kinematics over 1 GiB); the message names the problem and the line.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"BVH file not found: {p}")
    problem = limits.file_size_problem(p.stat().st_size, limits.BVH_MAX_FILE_BYTES, "file")
    if problem is not None:
        raise BvhError(str(p), None, problem)
    text = p.read_text(encoding="utf-8-sig", errors="replace")
    return parse_bvh(text, str(p))
