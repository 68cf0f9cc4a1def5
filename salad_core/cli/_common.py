"""What every command of the ``salad`` command line shares: the one-line user errors, the ``--out`` folder checks,
the files a failing command removes again, the motion files a command writes, and :func:`run_reporting_errors`,
which runs a command and turns its errors into one line and an exit status. Also :func:`tune_process`, the
process tuning (OpenMP wait policy, allocator) the command line does before a command loads torch."""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Callable, Iterator

#: Each sub-command's example line (its ``--help`` shows it).
EXAMPLES: dict[str, str] = {}


class UserError(Exception):
    """An error the user can fix; printed as one line."""


def _sub(subparsers, name: str, help: str, example: str, **kwargs) -> argparse.ArgumentParser:
    EXAMPLES[name] = example
    return subparsers.add_parser(
        name, help=help, description=f"{help}\n\nexample:\n  {example}",
        formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs,
    )


class _Created:
    """What the running command created: new output files and folders. When the command fails (an
    error or Ctrl-C) they are removed again, so a failed call leaves nothing behind."""

    def __init__(self) -> None:
        self.files: list[Path] = []
        self.dirs: list[Path] = []

    def clean_up(self) -> None:
        for f in reversed(self.files):
            try:
                f.unlink(missing_ok=True)
            except OSError:
                pass
        for d in reversed(self.dirs):       # deepest first; only folders left empty
            try:
                d.rmdir()
            except OSError:
                pass
        self.files, self.dirs = [], []


_CREATED = _Created()


def _check_out_dir(path: str | os.PathLike, force: bool = False) -> Path:
    """Check that ``--out`` is (or can become) a writable folder; nothing is created here (the first
    output written creates it, see :func:`_outputs`)."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} exists and is not a folder")
    probe = out
    while not probe.exists():              # the nearest existing ancestor must be a writable folder
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise UserError(f"cannot create output folder {out}: {probe} is not a folder")
    if probe.exists() and not os.access(probe, os.W_OK | os.X_OK):
        raise UserError(f"output folder {out} is not writable" if probe == out else
                        f"cannot create output folder {out}: {probe} is not writable")
    return out


def _make_out_dir(out: Path) -> Path:
    """Create ``out`` (and missing parents), remembering what was new for :meth:`_Created.clean_up`."""
    if out.is_dir():
        return out
    new = []
    probe = out
    while not probe.exists() and probe.parent != probe:
        new.append(probe)
        probe = probe.parent
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create output folder {out}: {exc.strerror}") from None
    _CREATED.dirs.extend(reversed(new))
    return out


def _outputs(out_dir: Path, names: list[str], force: bool, *, write: bool = True) -> list[Path]:
    """Paths in ``out_dir``; refuse to overwrite any existing one unless ``force``.

    With ``write`` (the default) the folder is created and the new paths are remembered, so that a
    failing command removes them again; ``write=False`` only checks (call it for every file of a run
    before writing any).
    """
    paths = [out_dir / n for n in names]
    existing = [p.name for p in paths if p.exists()]
    if existing and not force:
        raise UserError(f"{out_dir} already holds {', '.join(existing)}; pass --force to overwrite")
    if write:
        _make_out_dir(out_dir)
        _CREATED.files.extend(p for p in paths if not p.exists())
    return paths


def _slug(text: str, n: int = 40) -> str:
    """A file-name stem from a prompt: lower-case words joined by ``_``, at most ``n`` characters, cut
    at a word boundary (a single word longer than ``n`` is cut)."""
    import re

    words = re.findall(r"[a-z0-9]+", text.lower())
    out = ""
    for w in words:
        cand = f"{out}_{w}" if out else w
        if len(cand) > n:
            break
        out = cand
    return out or (words[0][:n] if words else "motion")


def _motion_file_names(stem: str, *, gif: bool = True, bvh: bool = True) -> list[str]:
    """The files one motion is written as (:func:`_write_motion_files`, in its order): features and joints
    ``.npy``, then the GIF and the BVH when asked for."""
    return [f"{stem}_features.npy", f"{stem}_joints.npy"] + ([f"{stem}.gif"] if gif else []) + \
        ([f"{stem}.bvh"] if bvh else [])


def _write_motion_files(out: Path, stem: str, features, joints, skeleton, *, force: bool,
                        gif: bool = True, bvh: bool = True, title: str | None = None) -> list[Path]:
    """Features/joints .npy, a GIF (titled ``title``, wrapped) and a BVH for one motion (each written
    atomically)."""
    import numpy as np

    from salad_core.io import atomic_path
    from salad_viz import animate, export_bvh

    paths = _outputs(out, _motion_file_names(stem, gif=gif, bvh=bvh), force)
    for path, arr in zip(paths[:2], (features, joints)):
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, np.asarray(arr, dtype=np.float32))
    written = paths[:2]
    if gif:
        written.append(animate(joints, skeleton, out / f"{stem}.gif", size=(320, 320), stride=2,
                               titles=None if title is None else [title]))
    if bvh:
        written.append(export_bvh(joints, skeleton, out / f"{stem}.bvh"))
    return written


def _note(args: argparse.Namespace, text: str, kind: str = "note") -> None:
    """One line on stderr, ``salad <command>: note: ...`` (also under -q: it changes the result)."""
    print(f"salad {getattr(args, 'command', '')}: {kind}: {text}", file=sys.stderr)


def _check_finite(flag: str, value: float) -> float:
    """NaN and infinite scales are refused here, before any weights are loaded."""
    if not math.isfinite(value):
        raise UserError(f"{flag} must be a finite number, got {value}")
    return value


def human_duration(seconds: float) -> str:
    """A rough duration for a person: ``"40 s"``, ``"2 min"``, ``"1.5 h"`` (``"1 s"`` at least)."""
    if not math.isfinite(seconds):
        return "an unknown time"
    if seconds < 90:
        return f"{max(seconds, 1):.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def batch_estimate(total: int, done: int, seconds: float, what: str = "motions") -> str:
    """The line said before the rest of a long batch: ``total`` items, ``done`` of them (the first chunk)
    took ``seconds``: ``"generating 120 motions (about 2 min at 1.1 s each, measured on the first chunk)"``."""
    each = seconds / max(done, 1)
    per = f"{each:.2f}" if each < 1 else f"{each:.1f}" if each < 10 else f"{each:.0f}"
    return (f"generating {total:,} {what} (about {human_duration(each * total)} at {per} s each, measured on "
            "the first chunk)")


def say(text: str) -> None:
    """Print a line on stdout without breaking a tqdm bar that is being drawn (tqdm.write)."""
    from tqdm import tqdm

    tqdm.write(text, file=sys.stdout)


def batch_chunks(total: int, chunk: int, *, progress: bool, what: str = "motions",
                 report: Callable[[str], None] = say) -> Iterator[slice]:
    """The ``slice`` of each consecutive chunk of ``chunk`` items out of ``total``, for a loop that does the
    work of one chunk per step. With more than one chunk, the time the first chunk took is measured (from
    the first ``yield`` to the next) and :func:`batch_estimate` is passed to ``report`` before the second
    chunk starts; with ``progress`` a tqdm bar over the items (on stderr) shows the rest."""
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    starts = range(0, total, chunk)
    bar = None
    if progress and len(starts) > 1:
        from tqdm import tqdm

        bar = tqdm(total=total, desc=f"{what} ({chunk} per chunk)", unit=what.removesuffix("s"), leave=False)
    try:
        began = time.perf_counter()
        for k, start in enumerate(starts):
            rows = slice(start, min(start + chunk, total))
            yield rows
            if k == 0 and len(starts) > 1:
                report(batch_estimate(total, rows.stop - rows.start, time.perf_counter() - began, what))
            if bar is not None:
                bar.update(rows.stop - rows.start)
    finally:
        if bar is not None:
            bar.close()


def run_reporting_errors(label: str, debug: bool, call: Callable[[], int]) -> int:
    """Run a command: Ctrl-C exits 130; any error prints one line ``<label>: error: ...`` and exits 2
    (the full traceback only with ``debug``). Either way the files and folders the command created
    are removed again; Python warnings print as one line ``<label>: warning: ...``."""
    import warnings

    def one_line(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        print(f"{label}: warning: {text}", file=sys.stderr)

    _CREATED.files, _CREATED.dirs = [], []
    try:
        with warnings.catch_warnings():
            warnings.showwarning = one_line
            return call()
    except KeyboardInterrupt:
        _CREATED.clean_up()
        print(f"{label}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one clear line unless --debug
        _CREATED.clean_up()
        if debug:
            raise
        print(f"{label}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        _CREATED.files, _CREATED.dirs = [], []


def _quiet_libraries() -> None:
    """-q: no progress bars from the text encoder's libraries (transformers' "Loading weights")."""
    os.environ["HF_HUB_DISABLE_PROGRESS_BARS"] = "1"        # read when transformers is imported
    os.environ.setdefault("TRANSFORMERS_VERBOSITY", "error")
    if "transformers" in sys.modules:                       # already imported (e.g. in a notebook)
        try:
            from transformers.utils import logging as hf_logging

            hf_logging.disable_progress_bar()
            hf_logging.set_verbosity_error()
        except Exception:   # an old transformers without these: only the bar stays
            pass


def tune_process(parser: argparse.ArgumentParser | None = None) -> None:
    """Tune this process for the commands (once, before torch loads): the OpenMP workers' wait policy
    (:func:`salad_core.openmp.configure`, unless something chose it already) and the allocator
    (:func:`salad_core.allocator.tune_from_environment`). A bad ``SALAD_OMP_WAIT`` or allocator variable is a
    usage error of ``parser`` (exit status 2) when one is given."""
    from salad_core import openmp
    from salad_core.allocator import tune_from_environment

    try:
        if openmp.wait_policy() == "not configured":
            openmp.configure()
        tune_from_environment()     # large activations from the heap, freed memory kept for reuse
    except ValueError as exc:
        if parser is None:
            raise
        parser.error(str(exc))

