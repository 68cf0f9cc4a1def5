"""What salad accepts from outside: the limits on files, configs and prompts, and the checks that apply them.

Files from outside (BVH takes, ``.npy`` arrays, weight folders, name maps) and prompts reach the
toolkit from users, shells and other programs. Each limit below is a named constant, and each is
checked in one function here, called where the input first enters, *before* any work or allocation
sized by it: a file that claims 10^12 frames, a Frame Time of 1e-300 s or a config asking for a
positional table of 10^10 rows is refused with a message naming the file, the key or line and the
numbers, instead of an internal error, a huge allocation or minutes of silence.

The checks raise the error types the loaders document: :class:`ValueError` (or the loader's own
subclass: :class:`~salad_core.bvh.reader.BvhError`, :class:`~salad_core.io.CheckpointError`,
:class:`~salad_core.bvh.rigs.RigError`, passed as ``error=``) and :class:`TypeError` for a JSON
value of the wrong type. The BVH reader asks the ``*_problem`` functions, which return the problem
as text (or None), so that its own error can add the line.

Limits (all can be read, none is meant to be changed at run time):

==========================  ===============  ======================================================
constant                    value            what it bounds
==========================  ===============  ======================================================
BVH_MAX_FILE_BYTES          64 MiB           a BVH file, a name-map JSON (NAME_MAP_MAX_BYTES 1 MiB)
BVH_MIN/MAX_FRAME_TIME      1e-4 .. 1 s      ``Frame Time:`` (10,000 fps .. 1 fps)
BVH_MAX_FRAMES              1,000,000        ``Frames:``
BVH_MAX_JOINTS / DEPTH      1,000 / 128      joints of a hierarchy / nesting of ROOT/JOINT blocks
IMPORT_MAX_FRAMES           72,000           frames after resampling (one hour at 20 fps)
WORK_MAX_BYTES              1 GiB            one working array of a loader (forward kinematics,
                                             resampling), estimated before it is made
NPY_MAX_BYTES / NDIM        1 GiB / 8        the data of one ``.npy`` file (read from its header)
MAX_JOINT_MAGNITUDE         1e3 (metres)     joint coordinates (features: motion.MAX_FEATURE_MAGNITUDE)
JSON_MAX_BYTES / DEPTH      16 MiB / 64      a JSON file of a weight folder / its nesting
CONFIG_MAX_INT              1,000,000        any integer of a model config (``max_len``, widths)
CONFIG_MAX_COUNT            256              layers / heads / blocks of a model config
CHECKPOINT_MAX_BYTES        4 GiB            a ``.safetensors`` weight file
MODEL_MAX_BYTES             4 GiB            the parameters + buffers a checkpoint's config builds
PROMPT_MAX_CHARS            10,000           one prompt
PROMPT_MAX_WORD_CHARS       100              one word of a prompt (whitespace-separated)
PROMPT_CHUNK                64               prompts above which a call reports its progress (and
                                             KeyMotion's chunk of motions denoised together)
==========================  ===============  ======================================================
"""
from __future__ import annotations

import dataclasses
import difflib
import json
import math
import os
import re
import types
import typing
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

__all__ = [
    "KIB", "MIB", "GIB",
    "BVH_MAX_FILE_BYTES", "NAME_MAP_MAX_BYTES", "BVH_MIN_FRAME_TIME", "BVH_MAX_FRAME_TIME", "BVH_MAX_FRAMES",
    "BVH_MAX_JOINTS", "BVH_MAX_DEPTH", "IMPORT_MAX_FRAMES", "WORK_MAX_BYTES",
    "NPY_MAX_BYTES", "NPY_MAX_NDIM", "MAX_JOINT_MAGNITUDE",
    "JSON_MAX_BYTES", "JSON_MAX_DEPTH", "CONFIG_MAX_INT", "CONFIG_MAX_COUNT", "CHECKPOINT_MAX_BYTES", "MODEL_MAX_BYTES",
    "PROMPT_MAX_CHARS", "PROMPT_MAX_WORD_CHARS", "PROMPT_CHUNK",
    "human_bytes", "file_size_problem", "refusal", "check_file_size", "read_text_file",
    "frame_time_problem", "bvh_size_problem", "hierarchy_problem", "resample_problem", "ascii_number_problem",
    "npy_header", "read_npy", "read_npz", "check_array_values",
    "json_depth", "read_json", "unknown_keys_message", "check_known_keys", "config_fields", "check_fields",
    "check_config_values", "check_stats", "short_json",
    "resolve_inside", "check_inside", "shipped_weights_dir",
]

KIB, MIB, GIB = 1 << 10, 1 << 20, 1 << 30

# ----------------------------------------------------------------------------------------------- BVH
#: Largest BVH file read (a 100-channel take at 120 fps for 9 minutes is about 60 MB).
BVH_MAX_FILE_BYTES = 64 * MIB
#: Largest name-map JSON file (``--name-map``; a real one is under 2 KB).
NAME_MAP_MAX_BYTES = 1 * MIB
#: ``Frame Time:`` range in seconds: 10,000 fps (motion capture runs at up to ~1,000) .. 1 fps.
BVH_MIN_FRAME_TIME = 1e-4
BVH_MAX_FRAME_TIME = 1.0
#: Most frames a BVH file may declare (``Frames:``).
BVH_MAX_FRAMES = 1_000_000
#: Most joints in a BVH hierarchy, and the deepest nesting of ROOT/JOINT blocks (real rigs: < 60 and < 30).
BVH_MAX_JOINTS = 1_000
BVH_MAX_DEPTH = 128
#: Most frames an import produces after resampling (one hour at 20 fps).
IMPORT_MAX_FRAMES = 72_000
#: Largest working array a loader makes (forward kinematics, resampling), estimated before it is made.
WORK_MAX_BYTES = 1 * GIB

# ----------------------------------------------------------------------------------------------- arrays
#: Largest data a ``.npy`` file may hold (its header says how much, before anything is read).
NPY_MAX_BYTES = 1 * GIB
#: Most axes of a ``.npy`` array.
NPY_MAX_NDIM = 8
#: Largest joint coordinate accepted, in metres (a kilometre: anything beyond is another unit or a broken
#: array). Features have their own: :data:`salad_core.motion.MAX_FEATURE_MAGNITUDE`.
MAX_JOINT_MAGNITUDE = 1e3

# ----------------------------------------------------------------------------------------------- JSON, weights
#: Largest JSON file of a weight folder (``pipeline.json``, checkpoint configs, ``vocabulary.json``).
JSON_MAX_BYTES = 16 * MIB
#: Deepest nesting of a JSON file (the project's are at most 3 deep).
JSON_MAX_DEPTH = 64
#: Largest magnitude of an integer in a model config (``max_len`` 5000, widths <= 1024 in the shipped ones).
CONFIG_MAX_INT = 1_000_000
#: Largest count of repeated blocks in a model config (fields named ``*layers``, ``*heads``, ``*blocks``; the
#: shipped models have at most 8): each is a Python module, built even for the size check on the meta device.
CONFIG_MAX_COUNT = 256
#: Largest ``.safetensors`` weight file read (the shipped ones are under 15 MB).
CHECKPOINT_MAX_BYTES = 4 * GIB
#: Largest model (parameters + buffers) a checkpoint's config may build.
MODEL_MAX_BYTES = 4 * GIB

# ----------------------------------------------------------------------------------------------- prompts
#: Longest prompt, in characters (HumanML3D captions are under 300; MiniLM reads 512 tokens, about 2,500
#: characters, and a longer prompt is cut with a warning naming the dropped words, up to this limit).
PROMPT_MAX_CHARS = 10_000
#: Longest word of a prompt, in characters: the tokenizers read words of up to 100 characters (BERT's
#: WordPiece turns a longer one into a single [UNK]).
PROMPT_MAX_WORD_CHARS = 100
#: Prompts in one call above which the pipelines log their progress and, with ``progress=True``, show a
#: bar over the chunks and the motions; also the chunk size of KeyMotion's pipeline (its ``max_batch``
#: default), and the batch size above which ``salad generate`` says how many motions and roughly how long.
PROMPT_CHUNK = 64


def human_bytes(n: float) -> str:
    """``1536`` -> ``"1.5 KiB"``."""
    n = float(n)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EiB"  # pragma: no cover


# ----------------------------------------------------------------------------------------------- files
def file_size_problem(size: int, limit: int, what: str) -> str | None:
    """Why a ``what`` of ``size`` bytes is refused (over ``limit``), or None."""
    if size > limit:
        return f"the {what} is {human_bytes(size)}, over the limit of {human_bytes(limit)}"
    return None


def refusal(error: Callable[[str], Exception], message: str, reason: str) -> Exception:
    """``error(message)`` carrying ``reason`` as its ``.reason`` attribute: the problem alone, without the
    file's name, for a caller that names the file its own way (``salad train --config FILE``)."""
    exc = error(message)
    try:
        exc.reason = reason
    except AttributeError:      # an error type with __slots__: the message alone
        pass
    return exc


def check_file_size(path: str | os.PathLike, limit: int, what: str, error: Callable[[str], Exception] = ValueError
                    ) -> int:
    """The size of ``path`` in bytes, if at most ``limit`` (else ``error`` naming the file and both sizes;
    its ``.reason`` is the problem alone, see :func:`refusal`)."""
    size = os.path.getsize(path)
    problem = file_size_problem(size, limit, what)
    if problem:
        raise refusal(error, f"{path}: {problem}", problem)
    return size


def read_text_file(path: str | os.PathLike, limit: int, what: str, error: Callable[[str], Exception] = ValueError,
                   *, bom: bool = True, replace: bool = False) -> str:
    """A text file as UTF-8 (a byte-order mark dropped with ``bom``), after :func:`check_file_size`.

    A file that is not UTF-8 (a binary file given by mistake) raises ``error`` naming the first bad byte
    and its offset (its ``.reason``: ``"it is not UTF-8 text"``), unless ``replace`` (then undecodable bytes
    become U+FFFD).
    """
    check_file_size(path, limit, what, error)
    data = Path(path).read_bytes()
    encoding = "utf-8-sig" if bom else "utf-8"
    if replace:
        return data.decode(encoding, errors="replace")
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise refusal(error, f"{path}: the {what} is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                      f"{exc.start}; a binary file?)", "it is not UTF-8 text") from None


# ----------------------------------------------------------------------------------------------- BVH checks
def frame_time_problem(value: float) -> str | None:
    """Why ``Frame Time: value`` is refused, or None."""
    if not (math.isfinite(value) and value > 0):
        return f"the frame time must be a positive number of seconds, got {value!r}"
    if not BVH_MIN_FRAME_TIME <= value <= BVH_MAX_FRAME_TIME:
        return (f"Frame Time {value:g} s ({1.0 / value:.4g} fps) is outside the accepted range "
                f"{BVH_MIN_FRAME_TIME:g}..{BVH_MAX_FRAME_TIME:g} s ({1 / BVH_MAX_FRAME_TIME:g}.."
                f"{1 / BVH_MIN_FRAME_TIME:g} fps); is the file's Frame Time in seconds?")
    return None


def bvh_size_problem(n_frames: int, n_joints: int, n_points: int) -> str | None:
    """Why a take of ``n_frames`` frames of ``n_joints`` joints (``n_points`` with End Sites) is refused.

    Forward kinematics holds a rotation (9 values) and a position (3) per joint and frame, and the
    positions of every point: estimated at twice that in float64 (temporaries).
    """
    if n_frames > BVH_MAX_FRAMES:
        return f"'Frames: {n_frames}' is more than the {BVH_MAX_FRAMES:,} frames a take may have"
    work = 2 * 8 * n_frames * (12 * n_joints + 3 * n_points)
    if work > WORK_MAX_BYTES:
        return (f"{n_frames:,} frames of {n_joints} joints need about {human_bytes(work)} for forward kinematics, "
                f"over the limit of {human_bytes(WORK_MAX_BYTES)}; split the take")
    return None


def hierarchy_problem(n_joints: int, depth: int) -> str | None:
    """Why a hierarchy with ``n_joints`` joints so far, nested ``depth`` deep, is refused (checked while parsing)."""
    if n_joints > BVH_MAX_JOINTS:
        return f"the hierarchy has more than {BVH_MAX_JOINTS:,} joints"
    if depth > BVH_MAX_DEPTH:
        return f"the hierarchy nests joints more than {BVH_MAX_DEPTH} deep"
    return None


def resample_problem(n_in: int, src_fps: float, n_out: int, fps: float, joints: int = 22) -> str | None:
    """Why resampling ``n_in`` frames at ``src_fps`` to ``n_out`` frames at ``fps`` is refused (before any
    array is made): too many output frames, or a working set over :data:`WORK_MAX_BYTES`."""
    if n_out > IMPORT_MAX_FRAMES:
        return (f"{n_in:,} frames at {src_fps:.4g} fps ({n_in / src_fps:.4g} s) would resample to {n_out:,} frames "
                f"at {fps:g} fps, more than the {IMPORT_MAX_FRAMES:,} an import may make "
                f"({IMPORT_MAX_FRAMES / fps:.4g} s); check the Frame Time, or split the take")
    work = 4 * 8 * n_out * joints * 3          # output, two gathered copies and the weights, float64
    if work > WORK_MAX_BYTES:
        return (f"resampling to {n_out:,} frames of {joints} joints needs about {human_bytes(work)}, over the limit "
                f"of {human_bytes(WORK_MAX_BYTES)}")
    return None


#: A decimal number in ASCII (what BVH exporters write); Python's float() also reads other digits
#: (Arabic-Indic, fullwidth), underscores and surrounding spaces, which a BVH file never holds.
_ASCII_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_NONFINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.ASCII | re.IGNORECASE)


def ascii_number_problem(token: str, what: str) -> str | None:
    """Why ``token``, which Python's ``float()`` reads, is still not a number as BVH files write them
    (ASCII decimal digits; ``float()`` also reads Arabic-Indic or fullwidth digits and underscores), or
    None. NaN and inf pass here: the caller refuses them as non-finite with its own message."""
    if _ASCII_NUMBER.fullmatch(token) or _NONFINITE.fullmatch(token):
        return None
    return f"{what} {token!r} is not a plain decimal number in ASCII digits (0-9), as BVH files write numbers"


# ----------------------------------------------------------------------------------------------- .npy
def npy_header(path: str | os.PathLike, *, max_bytes: int = NPY_MAX_BYTES, kinds: str = "iuf",
               error: Callable[[str], Exception] = ValueError) -> tuple[tuple[int, ...], bool, np.dtype, int]:
    """Read and check the header of a ``.npy`` file without reading its data.

    Returns ``(shape, fortran_order, dtype, data_offset)``. Refused (``error`` naming the file): a file
    that is not a ``.npy`` (no magic string, or a header that does not parse), format version 3, a
    dtype outside ``kinds`` (numpy kind letters; objects, which would unpickle, and structured dtypes
    are always refused), more than :data:`NPY_MAX_NDIM` axes, data over ``max_bytes``, or a file
    shorter than its header says (truncated).
    """
    fmt = np.lib.format
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        try:
            version = fmt.read_magic(fh)
        except (ValueError, EOFError):
            raise error(f"cannot read {path} as a .npy array (a text, pickled, truncated or corrupt file: it does "
                        "not start with the .npy magic string); motion and statistics files are arrays written by "
                        "numpy.save") from None
        try:
            if version == (1, 0):
                shape, fortran, dtype = fmt.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, fortran, dtype = fmt.read_array_header_2_0(fh)
            else:
                raise ValueError(f"format version {version[0]}.{version[1]} is not supported")
        except Exception as exc:    # safe_eval of a broken header raises ValueError, SyntaxError, TypeError...
            text = " ".join(str(exc).split())[:200]
            raise error(f"cannot read {path} as a .npy array: its header is not valid ({text})") from None
        offset = fh.tell()
    nbytes = _check_header(str(path), shape, dtype, kinds, max_bytes, error)
    if size - offset < nbytes:
        raise error(f"cannot read {path} as a .npy array: it is truncated (its header claims shape {shape} of "
                    f"{dtype}, {nbytes:,} bytes of data, but the file holds {max(size - offset, 0):,})")
    return tuple(shape), bool(fortran), dtype, offset


def read_npy(path: str | os.PathLike, *, max_bytes: int = NPY_MAX_BYTES, kinds: str = "iuf",
             error: Callable[[str], Exception] = ValueError) -> np.ndarray:
    """A ``.npy`` array, its header checked first (:func:`npy_header`): never unpickles, never allocates
    more than the header's checked size. Values are not checked (:func:`check_array_values`)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    shape, fortran, dtype, offset = npy_header(path, max_bytes=max_bytes, kinds=kinds, error=error)
    count = math.prod(shape)
    with open(path, "rb") as fh:
        fh.seek(offset)
        data = np.fromfile(fh, dtype=dtype, count=count)
    if data.size != count:       # the file shrank between the two reads
        raise error(f"cannot read {path} as a .npy array: it is truncated ({data.size:,} of {count:,} values)")
    return data.reshape(shape, order="F" if fortran else "C")


def _check_header(where: str, shape: Any, dtype: np.dtype, kinds: str, budget: int,
                  error: Callable[[str], Exception]) -> int:
    """The data size in bytes of an array header ``(shape, dtype)``, if numeric and within ``budget``."""
    if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None or dtype.kind not in kinds:
        raise error(f"cannot read {where} as a .npy array: it does not hold a numeric array (got {dtype}); .npy "
                    "files are never unpickled")
    if len(shape) > NPY_MAX_NDIM:
        raise error(f"cannot read {where} as a .npy array: its header claims {len(shape)} axes; at most "
                    f"{NPY_MAX_NDIM} are read")
    nbytes = math.prod(shape) * dtype.itemsize       # Python ints: no overflow for absurd shapes
    if nbytes > budget:
        raise error(f"cannot read {where} as a .npy array: its header claims shape {tuple(shape)} of {dtype} "
                    f"({human_bytes(nbytes)}), over the limit of {human_bytes(budget)}")
    return nbytes


def read_npz(path: str | os.PathLike, *, max_bytes: int = NPY_MAX_BYTES, kinds: str = "iuf",
             error: Callable[[str], Exception] = ValueError) -> dict[str, np.ndarray]:
    """Every array of a ``.npz`` archive (``numpy.savez``), each header checked before its data is read
    (as :func:`read_npy`; ``max_bytes`` bounds the archive's arrays together, never unpickles). Only the
    bytes a header announces are decompressed, so a member that claims more than it holds, or a zip bomb,
    cannot grow past the limit."""
    import zipfile

    fmt = np.lib.format
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    out: dict[str, np.ndarray] = {}
    left = max_bytes
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise error(f"cannot read {path} as a .npz archive ({exc})") from None
    with zf:
        for name in zf.namelist():
            where = f"{path}[{name!r}]"
            if not name.endswith(".npy"):
                raise error(f"cannot read {where}: a .npz archive holds .npy members only")
            try:
                fh = zf.open(name)
            except Exception as exc:        # a broken zip entry (bad header, unsupported compression)
                raise error(f"cannot read {where} ({' '.join(str(exc).split())[:200]})") from None
            with fh:
                try:
                    version = fmt.read_magic(fh)
                    if version not in ((1, 0), (2, 0)):
                        raise ValueError(f"format version {version[0]}.{version[1]} is not supported")
                    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
                    shape, fortran, dtype = read_header(fh)
                except Exception as exc:    # bad magic, a header that does not parse, a CRC error
                    raise error(f"cannot read {where} as a .npy array: its header is not valid "
                                f"({' '.join(str(exc).split())[:200]})") from None
                nbytes = _check_header(where, shape, dtype, kinds, left, error)
                try:
                    data = fh.read(nbytes)
                except Exception as exc:    # corrupt compressed data, a CRC error
                    raise error(f"cannot read {where} ({' '.join(str(exc).split())[:200]})") from None
            if len(data) != nbytes:
                raise error(f"cannot read {where} as a .npy array: it is truncated ({len(data):,} of {nbytes:,} "
                            "bytes)")
            left -= nbytes
            arr = np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")
            out[name[:-4]] = arr.copy()
    return out


def check_array_values(arr: np.ndarray, name: str, *, max_abs: float | None = None,
                       error: Callable[[str], Exception] = ValueError, hint: str = "") -> np.ndarray:
    """``arr`` if every value is finite and (with ``max_abs``) of magnitude at most ``max_abs``.

    The message names the array, the count and the first offending index and value; ``hint`` is appended
    (e.g. what unit the values should be in).
    """
    a = np.asarray(arr)
    if a.dtype.kind == "f" or a.dtype.kind == "c":
        bad = ~np.isfinite(a)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise error(f"{name}: {int(bad.sum()):,} non-finite value(s) (NaN or inf); the first at index "
                        f"{first}")
    if max_abs is not None and a.size:
        mags = np.abs(a)
        top = float(mags.max())
        if top > max_abs:
            first = tuple(int(i) for i in np.unravel_index(int(np.argmax(mags)), a.shape))
            raise error(f"{name}: |value| reaches {top:.3g} (at index {first}), beyond the limit of {max_abs:g}"
                        + (f"; {hint}" if hint else ""))
    return arr


# ----------------------------------------------------------------------------------------------- JSON
#: A JSON string, its closing quote optional (an unterminated one runs to the end): one pass, no backtracking
#: (the unrolled form: runs of plain characters between escapes).
_JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"?', re.DOTALL)


def json_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in JSON text (strings skipped), without parsing it: a
    100,000-deep file is measured, not recursed into. Linear in the text's length, for any text."""
    bare = _JSON_STRING.sub("", text).encode("utf-8", "surrogatepass")
    b = np.frombuffer(bare, dtype=np.uint8)
    steps = ((b == 0x5B) | (b == 0x7B)).astype(np.int64) - ((b == 0x5D) | (b == 0x7D))
    return int(np.cumsum(steps).max(initial=0))


def read_json(path: str | os.PathLike, what: str = "JSON file", *, max_bytes: int = JSON_MAX_BYTES,
              max_depth: int = JSON_MAX_DEPTH, error: Callable[[str], Exception] = ValueError,
              expect: type | None = dict) -> Any:
    """Parse a JSON file from outside: size, UTF-8, nesting (before parsing) and the top-level type checked.

    Raises ``error`` (a message naming the file) for a file over ``max_bytes``, not UTF-8, nested deeper
    than ``max_depth``, not valid JSON, or (with ``expect``) whose top level is not of that type;
    ``FileNotFoundError`` for a missing file. The error's ``.reason`` is the problem without the file's
    name (``"Expecting value at line 2, column 1"``; :func:`refusal`).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    text = read_text_file(path, max_bytes, what, error)
    depth = json_depth(text)
    if depth > max_depth:
        reason = f"it nests {depth} levels deep; at most {max_depth} are read"
        raise refusal(error, f"{path}: the {what} nests {depth} levels deep; at most {max_depth} are read", reason)
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise refusal(error, f"{path} is not valid JSON ({exc})",
                      f"{exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    except RecursionError:      # cannot happen below max_depth; kept as a guard
        raise refusal(error, f"{path}: the {what} nests too deeply to parse", "it nests too deeply to parse") from None
    if expect is not None and not isinstance(doc, expect):
        names = {dict: "an object {...}", list: "an array [...]"}
        wanted = names.get(expect, expect.__name__)
        raise refusal(error, f"{path}: the {what} must hold {wanted}, found {_json_type(doc)}",
                      f"it holds {_json_type(doc)}, not {wanted}")
    return doc


def _json_type(value: Any) -> str:
    if value is None:
        return "null"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
            dict: "an object"}.get(type(value), type(value).__name__)


def unknown_keys_message(unknown: Iterable[str], known: Iterable[str]) -> str:
    """``"'guidence' (did you mean 'guidance'?), 'x'"``: each unknown key with its closest known one."""
    known, unknown = sorted(known), list(unknown)
    parts = []
    for key in unknown[:5]:
        close = difflib.get_close_matches(str(key)[:100], known, n=1, cutoff=0.6)
        name = repr(key) if len(str(key)) <= 60 else repr(str(key)[:57]) + "..."
        parts.append(name + (f" (did you mean {close[0]!r}?)" if close else ""))
    return ", ".join(parts) + (f" and {len(unknown) - 5:,} more" if len(unknown) > 5 else "")


def check_known_keys(data: Mapping[str, Any], known: Iterable[str], where: str,
                     error: Callable[[str], Exception] = ValueError) -> None:
    """Refuse keys of ``data`` outside ``known``, naming each with its closest known key."""
    known = list(known)
    unknown = [k for k in data if k not in known]
    if unknown:
        raise error(f"{where}: unknown key{'s' if len(unknown) > 1 else ''} {unknown_keys_message(unknown, known)}; "
                    f"known keys: {', '.join(sorted(known))}")


class _Problem(typing.NamedTuple):
    message: str
    wrong_type: bool     # True: the JSON type is wrong (TypeError); False: the value is out of range


def _type_problem(value: Any, hint: Any, key: str, max_int: int | None = None) -> _Problem | None:
    """Why a JSON ``value`` does not fit the annotation ``hint`` (int, float, bool, str, None, unions,
    tuples and lists of these); None if it fits or the annotation is not one of these."""
    def wrong(what: str) -> _Problem:
        return _Problem(f"{key} must be {what}, got {_json_type(value)} {short_json(value)}", True)

    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(hint)
        problems = [_type_problem(value, h, key, max_int) for h in options]
        if any(p is None for p in problems):
            return None
        # a value of the right kind but out of range reports the range, else the union's types
        return next((p for p in problems if not p.wrong_type), wrong(_describe(hint)))
    if hint is type(None):
        return None if value is None else wrong("null")
    if hint is bool:
        return None if isinstance(value, bool) else wrong("true or false")
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return wrong("an integer")
        if max_int is not None and abs(value) > max_int:
            return _Problem(f"{key} = {value} is out of range (at most {max_int:,} in magnitude)", False)
        return None
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return wrong("a number")
        if not math.isfinite(value):
            return _Problem(f"{key} must be a finite number, got {value!r}", False)
        return None
    if hint is str:
        return None if isinstance(value, str) else wrong("a string")
    if hint is dict:
        return None if isinstance(value, dict) else wrong("an object {...}")
    if origin in (tuple, list) or hint in (tuple, list):
        if not isinstance(value, (list, tuple)):
            return wrong("an array")
        args = typing.get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                return _Problem(f"{key} must be an array of {len(args)} entries, got {len(value)}", True)
            items = list(zip(value, args))
        else:
            items = [(v, args[0] if args else Any) for v in value]
        for i, (v, h) in enumerate(items):
            problem = None if h is Any else _type_problem(v, h, f"{key}[{i}]", max_int)
            if problem:
                return problem
        return None
    return None


def _describe(hint: Any) -> str:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(h) for h in typing.get_args(hint))
    return {type(None): "null", bool: "true/false", int: "an integer", float: "a number", str: "a string",
            dict: "an object {...}"}.get(hint, "an array" if origin in (tuple, list) else str(hint))


def short_json(value: Any, limit: int = 60) -> str:
    """``value`` as JSON for a message, cut to ``limit`` characters."""
    try:
        text = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def config_fields(config_cls: type) -> dict[str, Any]:
    """``{field: annotation}`` of a config dataclass (``Any`` where an annotation cannot be resolved)."""
    try:
        hints = typing.get_type_hints(config_cls)
    except Exception:
        hints = {}
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(config_cls)}


def check_fields(data: Any, fields: Mapping[str, Any], where: str, error: Callable[[str], Exception] = ValueError,
                 type_error: Callable[[str], Exception] = TypeError, max_int: int | None = None) -> None:
    """Check a JSON object against a table ``{key: annotation}`` (int, float, bool, str, None, unions,
    tuples and lists of these; ``Any`` is not checked).

    Refused: ``data`` not an object and a value of the wrong JSON type (``type_error``), an unknown key
    (``error``, naming the closest known key: a misspelt ``"guidence"`` is not silently ignored), a
    non-finite number and, with ``max_int``, an integer beyond it in magnitude (``error``).
    """
    if not isinstance(data, Mapping):
        raise type_error(f"{where} must be an object {{...}}, got {_json_type(data)} {short_json(data)}")
    check_known_keys(data, fields, where, error)
    for key, value in data.items():
        problem = _type_problem(value, fields[key], f"{where}: {key!r}", max_int)
        if problem:
            raise (type_error if problem.wrong_type else error)(problem.message)


def check_config_values(config_cls: type, data: Any, where: str, error: Callable[[str], Exception] = ValueError,
                        type_error: Callable[[str], Exception] = TypeError,
                        max_int: int | None = CONFIG_MAX_INT) -> None:
    """:func:`check_fields` of a config dict against a (frozen) dataclass's fields; integers within
    ``max_int`` (:data:`CONFIG_MAX_INT`: a ``max_len`` of 10^10 would build a positional table of 10^10
    rows). The dataclass's own ``__post_init__`` checks the rest when it is built."""
    check_fields(data, config_fields(config_cls), where, error, type_error, max_int)
    if max_int is None:
        return
    for key, value in data.items():
        if _COUNT_FIELD.search(key) and isinstance(value, int) and value > CONFIG_MAX_COUNT:
            raise error(f"{where}: {key!r} = {value} is out of range (at most {CONFIG_MAX_COUNT:,} repeated blocks)")


_COUNT_FIELD = re.compile(r"(^|_)(layers|heads|blocks)$")


def check_stats(mean: Any, std: Any, source: str, error: Callable[[str], Exception] = ValueError,
                names: tuple[str, str] = ("mean", "std")) -> None:
    """Normalisation statistics: same shape, every value finite, every ``std`` > 0 (the features are
    divided by it)."""
    m, s = np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64)
    if m.shape != s.shape:
        raise error(f"{source}: {names[0]} {m.shape} and {names[1]} {s.shape} differ in shape")
    check_array_values(m, f"{source}: {names[0]}", error=error)
    check_array_values(s, f"{source}: {names[1]}", error=error)
    bad = np.flatnonzero(~(s.reshape(-1) > 0))
    if bad.size:
        raise error(f"{source}: {names[1]} has {bad.size} entr{'y' if bad.size == 1 else 'ies'} <= 0 (first at "
                    f"index {int(bad[0])}: {float(s.reshape(-1)[bad[0]]):g}); the features are divided by it")


# ----------------------------------------------------------------------------------------------- paths
def shipped_weights_dir() -> Path:
    """The package's own weights folder (``salad_core/weights``), resolved."""
    return (Path(__file__).resolve().parent / "weights").resolve()


def _inside(path: Path, root: Path) -> bool:
    try:
        path.relative_to(root)
    except ValueError:
        return False
    return True


def resolve_inside(root: str | os.PathLike, value: Any, key: str, source: str | os.PathLike,
                   allow_outside: bool | str | os.PathLike = False,
                   error: Callable[[str], Exception] = ValueError,
                   type_error: Callable[[str], Exception] = TypeError) -> Path:
    """``root / value`` for a path a weight folder's JSON names, if it stays inside the folder.

    Inside means: after ``..`` and symbolic links are resolved, the path lies in ``root`` (or, for a
    folder inside the package's shipped weights, anywhere in them: the shipped ablations share VAEs and
    statistics between sibling folders). ``allow_outside=True`` accepts any path, a folder accepts
    paths inside that folder too. Otherwise ``error`` names the key, what it says and where that leads.
    """
    if not isinstance(value, str) or not value:
        raise type_error(f"{source}: {key!r} must be a non-empty path string relative to the folder, got "
                         f"{_json_type(value)} {short_json(value)}")
    if "\x00" in value or len(value) > 4096 or any(len(part.encode("utf-8", "surrogatepass")) > 255
                                                   for part in Path(value).parts):
        raise error(f"{source}: {key!r} = {short_json(value)} is not a usable path (a NUL character, a name over 255 "
                    "bytes or a path over 4096 characters)")
    target = Path(root) / value         # an absolute value replaces root
    check_inside(root, target, key, value, source, allow_outside, error)
    return target


def check_inside(root: str | os.PathLike, target: str | os.PathLike, key: str, value: Any,
                 source: str | os.PathLike, allow_outside: bool | str | os.PathLike = False,
                 error: Callable[[str], Exception] = ValueError) -> None:
    """Refuse ``target`` (a file about to be opened for ``key`` = ``value`` of ``source``) unless it
    lies inside ``root`` after ``..`` and symbolic links are resolved (see :func:`resolve_inside`)."""
    if allow_outside is True:
        return
    root, target = Path(root), Path(target)
    try:
        real_root, real = root.resolve(), target.resolve()
    except (OSError, RuntimeError) as exc:      # a symbolic link loop, a name the system refuses
        raise error(f"{source}: {key!r} = {short_json(value, 300)} cannot be resolved ({exc})") from None
    allowed = [real_root]
    shipped = shipped_weights_dir()
    if _inside(real_root, shipped):
        allowed.append(shipped)
    if allow_outside not in (False, None):
        allowed.append(Path(allow_outside).resolve())
    if any(_inside(real, a) for a in allowed):
        return
    text = str(value)
    how = ("is an absolute path" if Path(text).is_absolute() else
           "climbs out with '..'" if ".." in Path(text).parts else
           "leads (through a symbolic link or the folder's own name)")
    raise error(f"{source}: {key!r} = {short_json(value, 300)} {how} to {real}, outside the weights folder "
                f"{real_root}; refusing to load files from elsewhere (pass allow_outside_paths=True to "
                "from_pretrained if you trust this folder)")
