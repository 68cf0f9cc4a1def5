"""The ``salad`` command line.

Each sub-command lives in a small function that parses nothing itself: ``main`` builds the parser,
and errors that users can fix (bad input, missing files) print one line and exit with status 2,
without a traceback unless ``--debug`` is given.
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import sys
from pathlib import Path
from typing import Callable

log = logging.getLogger("salad")

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


# ----------------------------------------------------------------------------- outputs
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


def _load_pipeline(weights: str | None):
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained(weights)   # a missing or corrupt folder raises CheckpointError


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


_FUNCTION_WORDS = frozenset("a an the and then while his her their its is are to of in on up with as".split())


def _has_words(text: str) -> bool:
    """Whether a prompt holds a word (letters or digits); "!!! ???" and emoji strings do not."""
    return any(ch.isalnum() for ch in text)


def _attention_figure(out: Path, stem: str, result, b: int, force: bool, normalize: str = "global") -> Path | None:
    """The Fig. 6-style per-word heatmap grid of sample ``b`` (needs captured attention): one panel
    per content word, repeated words told apart by their index in the prompt, words the weights never
    saw in training marked "(unknown)"; ``normalize``: one colour scale for all panels ("global") or
    each panel to its own maximum ("each"). None when there is nothing to draw (:func:`_no_figure_reason`)."""
    if result.attention is None:
        return None
    import numpy as np

    from salad_core.io import atomic_path
    from salad_viz import plot_attention_grid

    maps = result.attention
    words = list(maps.words(b))
    if not words:
        return None
    (path,) = _outputs(out, [f"{stem}_attention.png"], force)
    keep = [i for i, w in enumerate(words) if w not in _FUNCTION_WORDS] or list(range(len(words)))
    # (P, N', W) word maps; the panels pick words by position, so repeated words are fine
    stacked = np.stack([maps.word_map(b, i) for i in range(len(words))], axis=-1)
    unknown = getattr(result, "unknown_words", None)
    fig = plot_attention_grid(stacked, words, word_ids=keep, prompt=result.texts[b], normalize=normalize,
                              unknown_words=unknown[b] if unknown else ())
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=90, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


def _no_figure_reason(result, b: int) -> str:
    """Why :func:`_attention_figure` drew nothing for sample ``b``."""
    if result.attention is None:
        return "no attention maps were captured"
    if not result.attention.words(b):
        return "the prompt has no English (a-z) words, the words attention maps are drawn for"
    return "nothing to draw"


# ----------------------------------------------------------------------------- generate / demo
DEMO_PROMPT = "a man jumps forward and then walks forward, while waving his arms"


def _weights_info(weights: str | None) -> tuple[str, int]:
    """``(skeleton name, diffusion timesteps)`` from a pipeline folder's ``pipeline.json``, read
    without loading any weights, so that arguments can be checked first; the defaults
    (humanml3d, 1000) when the file is missing or odd (loading the weights then says why)."""
    import json

    from salad_core.pipeline import default_weights_dir

    root = Path(weights) if weights is not None else default_weights_dir()
    try:
        cfg = json.loads((root / "pipeline.json").read_text())
        skeleton = str(cfg.get("skeleton", "humanml3d"))
        steps = int(cfg.get("diffusion", {}).get("num_train_timesteps", 1000))
    except (OSError, ValueError, TypeError, AttributeError):
        return "humanml3d", 1000
    return skeleton, steps


def _check_sampling_args(args: argparse.Namespace, n_prompts: int, *, length: bool = True,
                         solver: bool = True) -> None:
    """Check --length, --steps, --solver, --seed and --guidance before any weights load (a few
    seconds); a length that is not a multiple of the unit is rounded down with one note."""
    from salad_core.pipeline import MAX_GUIDANCE, SEED_RANGE
    from salad_core.skeleton import get_skeleton

    skeleton, max_steps = _weights_info(getattr(args, "weights", None))
    try:
        sk = get_skeleton(skeleton)
    except (KeyError, ValueError):
        sk = get_skeleton("humanml3d")
    if length and getattr(args, "length", None) is not None:
        unit, max_len = sk.unit_length, sk.max_length
        if not unit <= args.length <= max_len:
            raise UserError(f"--length {args.length} frames is out of range; allowed: {unit}..{max_len} "
                            f"({unit / sk.fps:g}-{max_len / sk.fps:g} s at {sk.fps:g} fps)")
        if args.length % unit:
            floored = args.length - args.length % unit
            _note(args, f"--length {args.length} is not a multiple of {unit}; generating {floored} frames")
            args.length = floored
    steps = getattr(args, "steps", None)
    if steps is not None and not 1 <= steps <= max_steps:
        raise UserError(f"--steps {steps}: allowed 1..{max_steps} (the model's diffusion timesteps; default 50)")
    if solver and getattr(args, "solver", None) is not None:
        from salad_core.sampling import SOLVERS

        if args.solver.lower() not in SOLVERS:
            raise UserError(f"--solver {args.solver!r} is unknown; allowed: {', '.join(SOLVERS)}")
    seed = getattr(args, "seed", None)
    if seed is not None and not (SEED_RANGE[0] <= seed and seed + n_prompts - 1 <= SEED_RANGE[1]):
        raise UserError(f"--seed {seed} is out of range; allowed: -2**63..2**64-1"
                        + (f" minus {n_prompts - 1} (prompt b uses seed + b)" if n_prompts > 1 else ""))
    w = getattr(args, "guidance", None)
    if w is not None:
        _check_finite("--guidance", w)
        if abs(w) > MAX_GUIDANCE:
            raise UserError(f"--guidance {w:g} is out of range; allowed: -{MAX_GUIDANCE:g}..{MAX_GUIDANCE:g} "
                            "(the papers use 1-10, default 7.5; larger weights make the sampler diverge)")
        if w < 0:
            import warnings

            _note(args, f"--guidance {w:g} is negative: the motion is steered away from the prompt "
                        "(1 = no guidance, 7.5 = the paper's)", kind="warning")
            # said once, here; the pipeline's own warning would repeat it (restored after the command)
            warnings.filterwarnings("ignore", message=r"guidance_scale=\S+ is negative")
    _check_guidance_refinements(args)


def _check_guidance_refinements(args: argparse.Namespace) -> None:
    """Check --guidance-rescale and parse --guidance-interval ``LO:HI`` into ``(lo, hi)`` in place."""
    phi = getattr(args, "guidance_rescale", None)
    if phi is not None:
        _check_finite("--guidance-rescale", phi)
        if not 0.0 <= phi <= 1.0:
            raise UserError(f"--guidance-rescale {phi:g} is out of range; allowed: 0..1 (0 = plain guidance, "
                            "0.7 = Lin et al.'s choice)")
    interval = getattr(args, "guidance_interval", None)
    if isinstance(interval, str):
        parts = interval.split(":")
        try:
            lo, hi = (float(v) for v in parts)
        except ValueError:
            raise UserError(f"--guidance-interval {interval!r}: expected LO:HI, two numbers with "
                            "0 <= LO < HI <= 1 (fractions of the diffusion timesteps, e.g. 0:0.5)") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi <= 1.0):
            raise UserError(f"--guidance-interval {interval}: allowed 0 <= LO < HI <= 1 (fractions of the "
                            "diffusion timesteps, e.g. 0:0.5)")
        args.guidance_interval = (lo, hi)


def _guidance(args: argparse.Namespace, pipe):
    """The :class:`~salad_core.sampling.Guidance` a command samples with: the weights' own (pipeline.json), its
    weight replaced by ``--guidance``, its rescale and interval by ``--guidance-rescale`` / ``--guidance-interval``."""
    from dataclasses import replace

    guidance = pipe.resolve_guidance(getattr(args, "guidance", None))
    changes = {}
    if getattr(args, "guidance_rescale", None) is not None:
        changes["rescale"] = args.guidance_rescale
    if getattr(args, "guidance_interval", None) is not None:
        changes["interval"] = args.guidance_interval
    if changes and not guidance.cfg:
        _note(args, f"--guidance-rescale and --guidance-interval change nothing at w = {guidance.scale:g} "
                    "(no guidance)")
    return replace(guidance, **changes) if changes else guidance


def _note(args: argparse.Namespace, text: str, kind: str = "note") -> None:
    """One line on stderr, ``salad <command>: note: ...`` (also under -q: it changes the result)."""
    print(f"salad {getattr(args, 'command', '')}: {kind}: {text}", file=sys.stderr)


def _note_unknown_words(args: argparse.Namespace, pipe, prompts: list[str], labels: list[str] | None = None) -> None:
    """One line per prompt holding words the weights never saw in training (their ``vocabulary.json``) or
    text in another script or emoji; the pipeline's own UnknownWordsWarning is turned off, so it is said once.
    A prompt without any word already got its own line ("has no words")."""
    from salad_core.vocabulary import check_prompt, describe_unknown

    pipe.warn_unknown_words = False
    for b, p in enumerate(prompts):
        check = check_prompt(p, getattr(pipe, "vocabulary", None))
        if check and _has_words(p):
            _note(args, describe_unknown(check, labels[b] if labels else b, getattr(pipe, "vocabulary_source", None)),
                  kind="warning")


def _generate_stems(texts: list[str]) -> list[str]:
    return [f"{b:02d}_{_slug(text)}" for b, text in enumerate(texts)]


def cmd_generate(args: argparse.Namespace) -> int:
    from salad_core.data.texts import split_words
    from salad_core.pipeline import validate_prompts

    try:
        prompts = validate_prompts(args.prompt)
    except (TypeError, ValueError) as exc:
        raise UserError(str(exc)) from None
    if getattr(args, "keymotion", None) is not None:
        return _generate_keymotion(args, prompts)
    _check_sampling_args(args, len(prompts))
    out = _check_out_dir(args.out, args.force)
    attention = not args.no_attention
    figures = [attention and _has_words(p) for p in prompts]
    for b, p in enumerate(prompts):
        if attention and not figures[b]:
            _note(args, f"prompt {b} {p!r} has no words: no attention figure for it", kind="warning")
        elif figures[b] and not split_words(p):     # e.g. another script: the maps are drawn per a-z word
            figures[b] = False
            _note(args, f"prompt {b} {p!r} has no English (a-z) words, the words attention maps are drawn for: "
                        "no attention figure for it", kind="warning")
    # every file of the run is checked before anything is written
    stems = _generate_stems(prompts)
    _outputs(out, [name for st in stems for name in _motion_file_names(st, gif=not args.no_render)]
             + [f"{st}_attention.png" for st, fig in zip(stems, figures) if fig], args.force, write=False)
    pipe = _load_pipeline(args.weights)
    _note_unknown_words(args, pipe, prompts)
    guidance = _guidance(args, pipe)
    _say_guidance(args, guidance)
    result = pipe(prompts, lengths=args.length, seed=args.seed, guidance_scale=guidance,
                  num_steps=args.steps, solver=args.solver, capture_attention=attention and any(figures),
                  progress=not args.quiet)
    for b, text in enumerate(result.texts):
        stem = stems[b]
        n = result.lengths[b]
        files = _write_motion_files(out, stem, result.features[b, :n], result.joints[b], pipe.skeleton,
                                    force=args.force, gif=not args.no_render, bvh=True, title=text)
        if figures[b]:
            fig = _attention_figure(out, stem, result, b, args.force, normalize=getattr(args, "normalize", "global"))
            files += [fig] if fig else []
            if not fig:
                _note(args, f"prompt {b} {text!r}: no attention figure ({_no_figure_reason(result, b)})",
                      kind="warning")
        print(f"{text!r} ({n} frames): " + ", ".join(str(f) for f in files))
    return 0


def _generate_keymotion(args: argparse.Namespace, prompts: list[str]) -> int:
    """``salad generate --keymotion [DIR]``: the same files from KeyMotion (the shipped weights, or a pipeline
    folder), one call per prompt with seed ``SEED + b``, so that a prompt's motion does not depend on the others
    given with it. KeyMotion has no 7-part cross-attention, so no attention figure is drawn."""
    from salad_core.keymotion.pipeline import KeyMotionPipeline

    if args.weights is not None:
        raise UserError(f"--weights {args.weights} names a SALAD pipeline; with --keymotion give the KeyMotion "
                        "folder as --keymotion DIR (or --keymotion alone for the shipped weights)")
    _check_sampling_args(args, len(prompts), length=False)
    out = _check_out_dir(args.out, args.force)
    stems = _generate_stems(prompts)
    _outputs(out, [name for st in stems for name in _motion_file_names(st, gif=not args.no_render)], args.force,
             write=False)
    source = None if args.keymotion == "shipped" else args.keymotion
    pipe = KeyMotionPipeline.from_pretrained(source, solver=(args.solver or "ddim").lower())
    _note_unknown_words(args, pipe, prompts)
    if not pipe.num_keyframes <= args.length <= pipe.max_length:
        raise UserError(f"--length {args.length} frames is out of range for KeyMotion; allowed: "
                        f"{pipe.num_keyframes}..{pipe.max_length} (at least its {pipe.num_keyframes} keyframes)")
    if not args.no_attention:      # also under -q: a figure is never left out silently
        _note(args, "KeyMotion has no cross-attention maps: no attention figure is drawn")
    guidance = _guidance(args, pipe)
    _say_guidance(args, guidance, source="keymotion.json")
    for b, text in enumerate(prompts):
        result = pipe(text, lengths=args.length, seed=args.seed + b, guidance_scale=guidance,
                      num_steps=args.steps, progress=not args.quiet)
        n = result.lengths[0]
        files = _write_motion_files(out, stems[b], result.features[0, :n], result.joints[0], pipe.skeleton,
                                    force=args.force, gif=not args.no_render, bvh=True, title=f"KeyMotion: {text}")
        print(f"{text!r} ({n} frames, KeyMotion): " + ", ".join(str(f) for f in files))
    return 0


def _say_guidance(args: argparse.Namespace, guidance, source: str = "pipeline.json") -> None:
    """Print the guidance a command samples with (:func:`_guidance`) and where it comes from (``source``: the
    weights' file that holds their default)."""
    if getattr(args, "quiet", False):
        return
    given = [flag for flag, attr in (("--guidance", "guidance"), ("--guidance-rescale", "guidance_rescale"),
                                     ("--guidance-interval", "guidance_interval"))
             if getattr(args, attr, None) is not None]
    print(f"guidance w = {guidance.describe()}"
          + (f" ({', '.join(given)})" if given else f" (the weights' default, {source})"))


def cmd_demo(args: argparse.Namespace) -> int:
    """Generate the paper's Fig. 6 prompt with the shipped weights; render it and its attention."""
    args.prompt = [args.prompt or DEMO_PROMPT]
    args.no_attention = False
    args.no_render = False
    return cmd_generate(args)


def _edit_args(p: argparse.ArgumentParser) -> None:
    """The edit flags shared by ``salad edit`` and ``salad invert`` (parsed by :func:`_edit_specs`)."""
    p.add_argument("--target", default=None,
                   help="target prompt; needed by --swap (same number of words) and --refine; default: the source")
    p.add_argument("--swap", type=float, default=None, metavar="TAU",
                   help="word swap: source maps while t >= TAU*T, TAU in [0, 1) (paper: 0.8)")
    p.add_argument("--refine", action="store_true", help="prompt refinement (aligned words keep the source maps)")
    p.add_argument("--reweight", action="append", metavar="WORD=SCALE", help="scale a word's attention, s in [-3, 3]")
    p.add_argument("--mirror", choices=["legs", "arms", "all"], help="swap left/right body-part rows")
    p.add_argument("--mirror-self-attention", action="store_true",
                   help="with --mirror: also swap the parts' temporal and skeletal self-attention (the source's, "
                        "MirrorSelfAttention; beyond the paper): the side swaps more often, the rest moves more")
    p.add_argument("--window", default=None, metavar="START:STOP",
                   help="step window of --refine/--reweight/--mirror as fractions of the sampling steps, "
                        "0 <= START < STOP <= 1 (0 = the noisiest step; default 0:1)")


def _parse_window(text: str) -> tuple[float, float]:
    parts = text.replace(",", ":").split(":")
    if len(parts) != 2:
        raise UserError(f"--window takes START:STOP step fractions (e.g. 0:0.5), got {text!r}")
    try:
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise UserError(f"--window {text!r}: START and STOP must be numbers in [0, 1] (e.g. 0:0.5)") from None


def _spec(flag: str, build: Callable):
    """Build one edit spec; its validation error becomes one line naming the flag."""
    try:
        return build()
    except (TypeError, ValueError) as exc:
        raise UserError(f"{flag}: {exc}") from None


def _edit_specs(args: argparse.Namespace, required: bool = True) -> list:
    """Edit specifications from the flags of :func:`_edit_args`, in the order the pipeline needs
    (the replacement first, then the modifiers); ``[]`` if none was given and not ``required``."""
    from salad_core.attention import Mirror, MirrorSelfAttention, Refine, Reweight, WordSwap

    window = {} if args.window is None else {"steps": _parse_window(args.window)}
    in_window = "" if args.window is None else f" --window {args.window}"
    specs = []
    if args.swap is not None:
        specs.append(_spec(f"--swap {args.swap:g}", lambda: WordSwap(tau=args.swap)))
    if args.refine:
        specs.append(_spec(f"--refine{in_window}", lambda: Refine(**window)))
    for item in args.reweight or []:
        word, sep, scale = item.rpartition("=")
        if not sep or not word:
            raise UserError(f"--reweight takes WORD=SCALE (e.g. high=-1), got {item!r}")
        try:
            value = float(scale)
        except ValueError:
            raise UserError(f"--reweight {item!r}: the scale {scale!r} is not a number") from None
        specs.append(_spec(f"--reweight {item}{in_window}", lambda: Reweight(words=word, scale=value, **window)))
    if args.mirror:
        specs.append(_spec(f"--mirror {args.mirror}{in_window}", lambda: Mirror(parts=args.mirror, **window)))
        if getattr(args, "mirror_self_attention", False):
            specs.append(_spec(f"--mirror-self-attention{in_window}",
                               lambda: MirrorSelfAttention(parts=args.mirror, **window)))
    elif getattr(args, "mirror_self_attention", False):
        raise UserError("--mirror-self-attention goes with --mirror PARTS (it mirrors the same parts' self-attention)")
    if args.window is not None and not (args.refine or args.reweight or args.mirror):
        raise UserError("--window applies to --refine, --reweight and --mirror; give one of them "
                        "(word swap is timed by TAU alone)")
    if not specs and required:
        raise UserError("give at least one edit: --swap TAU, --refine, --reweight WORD=SCALE or --mirror PARTS")
    return specs


def _check_finite(flag: str, value: float) -> float:
    """NaN and infinite scales are refused here, before any weights are loaded."""
    if not math.isfinite(value):
        raise UserError(f"{flag} must be a finite number, got {value}")
    return value


def _check_edit_target(args: argparse.Namespace, source: str) -> None:
    """A word swap or a refinement into the source prompt itself gives back the source: refuse it."""
    kind = "--swap" if args.swap is not None else "--refine" if args.refine else None
    if kind is None:
        return
    target = " ".join((args.target or "").split())
    if not target or target.lower() == " ".join(source.split()).lower():
        what = "replaces the source's words with the target's" if kind == "--swap" else \
            "keeps the source's maps for the target's words shared with it"
        raise UserError(f"{kind} needs --target, a prompt that differs from the source ({kind[2:]} {what}); "
                        f"without one the edit gives back the source motion")


def cmd_edit(args: argparse.Namespace) -> int:
    """Edit a generated motion (same noise) or, with --motion, a given motion through inversion."""
    if not (args.source or "").strip():
        raise UserError("the source prompt is empty; describe a motion, e.g. 'a person walks forward'")
    specs = _edit_specs(args)
    _check_edit_target(args, args.source)
    _check_sampling_args(args, 1, length=not args.motion, solver=not args.motion)
    if args.motion and args.solver is not None and args.solver.lower() != "ddim":
        raise UserError(f"--solver {args.solver}: editing a given motion (--motion) uses the DDIM sampler its "
                        "inversion is made for")
    features = None
    if args.motion:
        skeleton, _ = _weights_info(args.weights)
        sk, features, _ = _load_features(args.motion, skeleton)
        if len(features) % sk.unit_length:
            _note(args, f"{args.motion} has {len(features)} frames, not a multiple of {sk.unit_length}; editing the "
                        f"first {len(features) - len(features) % sk.unit_length}")
    out = _check_out_dir(args.out, args.force)
    names = [name for b in ("source", "edited") for name in _motion_file_names(b, gif=False)]
    attention = bool(getattr(args, "attention", False))
    _outputs(out, names + ["source_vs_edited.gif"] + ["edited_attention.png"] * attention, args.force, write=False)
    pipe = _load_pipeline(args.weights)
    _note_unknown_words(args, pipe, [args.source] + [args.target] * bool(args.target), ["source", "target"])
    guidance = _guidance(args, pipe)
    _say_guidance(args, guidance)
    if features is not None:
        inv = _invert(pipe, features, args.source, args, method="fixed_point", guidance=guidance)
        result = pipe.edit(target=args.target, edits=specs, inversion=inv, progress=not args.quiet,
                           capture_attention=attention)
    else:
        result = pipe.edit(args.source, args.target, edits=specs, lengths=args.length, seed=args.seed,
                           guidance_scale=guidance, num_steps=args.steps, solver=args.solver,
                           progress=not args.quiet, capture_attention=attention)
    src, dst = result.source, result.edited
    n = src.lengths[0]
    files = _write_motion_files(out, "source", src.features[0, :n], src.joints[0], pipe.skeleton, force=args.force,
                                gif=False, bvh=True)
    files += _write_motion_files(out, "edited", dst.features[0, :n], dst.joints[0], pipe.skeleton, force=args.force,
                                 gif=False, bvh=True)
    from salad_viz import animate

    (gif,) = _outputs(out, ["source_vs_edited.gif"], args.force)
    files.append(animate([src.joints[0], dst.joints[0]], pipe.skeleton, gif, layout="side",
                         titles=[f"source: {src.texts[0]}", f"edited: {dst.texts[0]}"], size=(240, 240), stride=2))
    if attention:    # the maps the edited motion used (a negative re-weight: negative, on a diverging scale)
        fig = _attention_figure(out, "edited", dst, 0, args.force, normalize=args.normalize)
        files += [fig] if fig else []
        if not fig:
            _note(args, f"no attention figure ({_no_figure_reason(dst, 0)})", kind="warning")
    print(f"{src.texts[0]!r} -> {dst.texts[0]!r} with {[type(e).__name__ for e in specs]}: "
          + ", ".join(str(f) for f in files))
    return 0


# ----------------------------------------------------------------------------- motion files
def _load_motion_array(motion: str, skeleton: str):
    """``(skeleton, array, path)``: a validated features ``(N, D)`` or joints ``(N, J, 3)`` .npy."""
    import numpy as np

    from salad_core.motion import MAX_FEATURE_MAGNITUDE, check_features
    from salad_core.skeleton import get_skeleton

    try:
        sk = get_skeleton(skeleton)
    except (KeyError, ValueError) as exc:
        raise UserError(f"--skeleton: {exc.args[0] if exc.args else exc}") from None
    path = Path(motion)
    if not path.is_file():
        raise UserError(f"motion file not found: {path}")
    try:
        arr = np.load(path, allow_pickle=False)   # never unpickle: a .npy must not run code
    except (ValueError, OSError, EOFError):
        # numpy calls any file without the .npy header "pickled" and suggests allow_pickle: never that
        raise UserError(f"cannot read {path} as a .npy array (a text, pickled, truncated or corrupt file); motion "
                        "files hold float arrays written by numpy.save") from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "iuf":     # complex parts would be dropped
        raise UserError(f"{path} does not hold a numeric array (got {getattr(arr, 'dtype', type(arr).__name__)})")
    if arr.ndim == 2:
        try:
            check_features(arr, sk, name=str(path))
        except ValueError as exc:
            raise UserError(str(exc)) from None
        top = float(np.abs(arr).max(initial=0.0))
        if top > MAX_FEATURE_MAGNITUDE:
            raise UserError(f"{path} reaches |value| = {top:.3g}, beyond {MAX_FEATURE_MAGNITUDE:g}: not HumanML3D "
                            "features (metres, radians, metres per frame; of order 1); check its units")
        return sk, arr.astype(np.float32, copy=False), path
    if arr.ndim == 3 and arr.shape[1:] == (sk.num_joints, 3):
        if not np.isfinite(arr).all():
            raise UserError(f"{path} contains NaN or infinite values")
        return sk, arr.astype(np.float32, copy=False), path
    raise UserError(f"{path} has shape {arr.shape}; expected features (N, {sk.feature_dim}) or "
                    f"joints (N, {sk.num_joints}, 3)")


def _load_joints(motion: str, skeleton: str):
    """``(skeleton, joints (N, J, 3), path)`` from a features ``(N, D)`` or joints ``(N, J, 3)`` .npy.

    Features are recovered as the pipeline recovers them (:data:`salad_core.recovery.DEFAULT_METHOD`, the
    skeleton fit), so that ``salad export`` and ``salad render`` of a ``*_features.npy`` show the joints that
    ``salad generate`` wrote beside it (and its BVH), not the raw position features."""
    import numpy as np

    from salad_core.recovery import DEFAULT_METHOD, recover_joints

    sk, arr, path = _load_motion_array(motion, skeleton)
    if arr.ndim == 2:
        arr = np.asarray(recover_joints(arr, DEFAULT_METHOD, sk), dtype=np.float32)
    return sk, arr, path


def _load_features(motion: str, skeleton: str):
    """``(skeleton, features (N, D), path)``: the models need features; joints files are refused."""
    sk, arr, path = _load_motion_array(motion, skeleton)
    if arr.ndim != 2:
        raise UserError(f"{path} holds joints {arr.shape}; inversion needs HumanML3D features (N, {sk.feature_dim}) "
                        "(the *_features.npy that salad generate writes)")
    unit, max_len = sk.unit_length, sk.max_length
    if not unit <= len(arr) - len(arr) % unit <= max_len:
        raise UserError(f"{path} has {len(arr)} frames; allowed: {unit}..{max_len} (at {sk.fps:g} fps; longer "
                        f"motions must be cropped first)")
    return sk, arr, path


# ----------------------------------------------------------------------------- invert
def _invert(pipe, features, prompt: str, args: argparse.Namespace, method: str, iterations=None, exact=True,
            guidance=None):
    """Invert one motion under its prompt and print the reconstruction error in cm; ``guidance`` is the command's
    :func:`_guidance` when the caller has it already."""
    unit = pipe.skeleton.unit_length
    features = features[: len(features) - len(features) % unit]   # the callers said so already
    guidance = _guidance(args, pipe) if guidance is None else guidance
    inv = pipe.invert(features, prompt, method=method, guidance_scale=guidance, num_steps=args.steps,
                      iterations=iterations, exact=exact, progress=not args.quiet)
    cm = _errors_cm(inv.errors, pipe.skeleton)
    print(f"inversion ({method}, {inv.num_steps} steps, w={inv.guidance_scale:g}): reconstruction MPJPE "
          f"{cm['mpjpe_cm']:.2f} cm root-aligned, {cm['mpjpe_global_cm']:.2f} cm global "
          f"(VAE floor {cm['vae_mpjpe_cm']:.2f} cm)")
    return inv


def _take_errors(loaded, features, start: int, reconstruction, skeleton) -> dict[str, float] | None:
    """Errors (cm) against the take itself, for a .bvh or joints .npy input (``None`` for features): the
    reconstruction's joints ``(n, J, 3)`` (raw position recovery, as ``inversion.errors``) and the retargeted input's
    (what the model was given, ``features_to_joints(features)``) against the take's own joints of the same frames
    (from ``start``), placed in the features' frame (:func:`salad_core.bvh.take_in_features_frame`): MPJPE
    root-aligned and global."""
    if loaded.kind == "features" or skeleton.bone_lengths is None:
        return None
    import numpy as np

    from salad_core.bvh import take_in_features_frame
    from salad_core.eval.metrics import mpjpe
    from salad_core.motion import features_to_joints

    take = take_in_features_frame(loaded.joints, features, start, skeleton)
    given = np.asarray(features_to_joints(features, skeleton), dtype=np.float64)
    rec = np.asarray(reconstruction, dtype=np.float64)
    cm = 100.0 * skeleton.feature_scale
    return {"mpjpe_cm": cm * mpjpe(rec, take), "mpjpe_global_cm": cm * mpjpe(rec, take, root_aligned=False),
            "retargeting_mpjpe_cm": cm * mpjpe(given, take),
            "retargeting_mpjpe_global_cm": cm * mpjpe(given, take, root_aligned=False)}


def _errors_cm(errors: dict, skeleton) -> dict[str, float]:
    """The inversion's joint errors (skeleton length units) in centimetres; other figures as they are."""
    to_cm = 100.0 * skeleton.feature_scale    # feature_scale: the skeleton's length unit in metres
    return {(f"{k}_cm" if "mpjpe" in k else k): float(v) * (to_cm if "mpjpe" in k else 1.0)
            for k, v in errors.items()}


def _parse_crop(text: str) -> tuple[float, float | None]:
    """``START:STOP`` in seconds (STOP may be empty: to the end)."""
    start, sep, stop = text.partition(":")
    try:
        a = float(start) if start.strip() else 0.0
        b = float(stop) if stop.strip() else None
    except ValueError:
        a = b = float("nan")
    if not sep or not math.isfinite(a) or a < 0 or (b is not None and not (math.isfinite(b) and b > a)):
        raise UserError(f"--crop takes START:STOP in seconds, 0 <= START < STOP (e.g. 2:9.5 or 2:), got {text!r}")
    return a, b


def _bvh_args(p: argparse.ArgumentParser) -> None:
    """The BVH import options shared by ``salad invert`` and ``salad import``."""
    p.add_argument("--crop", default=None, metavar="START:STOP",
                   help="use only this part of the motion, in seconds (e.g. 2:9.5; STOP empty = to the end)")
    p.add_argument("--rig", default=None, choices=["smpl", "mixamo", "cmu", "generic"],
                   help="BVH: the rig's naming style (default: detected from the joint names)")
    p.add_argument("--name-map", default=None, metavar="FILE.json",
                   help='BVH: JSON object {"humanml3d_joint": "RigJoint", ...} for joints the rig names '
                        "differently (the error for an unknown rig lists them)")
    p.add_argument("--units", default=None,
                   help="BVH: length unit, m, cm, mm, inch, ft or metres per unit (default: detected from the "
                        "skeleton's size)")
    p.add_argument("--up", default=None, choices=["y", "z", "-y", "-z", "x", "-x"],
                   help="BVH: the file's up axis (default: detected)")


def cmd_import(args: argparse.Namespace) -> int:
    """Convert a BVH take (or a joints .npy) for the other commands: the take's own joints (its bone lengths, on its
    floor, 20 fps), their copy retargeted to HumanML3D's skeleton and that copy's features."""
    import numpy as np

    from salad_core.io import atomic_path
    from salad_core.motion import joints_to_features
    from salad_core.recovery import DEFAULT_METHOD, recover_joints

    sk, loaded, features, start = _motion_input(args, check_length=False)
    out = _check_out_dir(args.out, args.force)
    stem = loaded.path.stem
    retargeted = None
    if loaded.kind == "features":        # no take: the features' joints, recovered as the pipeline does
        take = np.asarray(recover_joints(features, DEFAULT_METHOD, sk), dtype=np.float32)
    else:
        take = np.asarray(loaded.joints[start:start + len(features) + 1], dtype=np.float32)
        if len(take) < 2:
            raise UserError(f"--crop {args.crop} leaves {len(take)} frame of {loaded.path.name}; a motion needs 2")
        if start or len(take) < len(loaded.joints):     # cropped: the features of exactly these frames
            features = joints_to_features(take.astype(np.float64), sk)
        if sk.bone_lengths is not None:
            from salad_core.bvh import retarget_error, retargeted_joints

            retargeted = retargeted_joints(take, sk)
    names = _motion_file_names(stem, gif=not args.no_render, bvh=False)
    names += [f"{stem}_retargeted_joints.npy"] if retargeted is not None else []
    paths = _outputs(out, names, args.force)
    arrays = {f"{stem}_features.npy": features, f"{stem}_joints.npy": take,
              f"{stem}_retargeted_joints.npy": retargeted}
    for path in paths:
        if path.suffix == ".npy":
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.save(fh, np.asarray(arrays[path.name], dtype=np.float32))
    if not args.no_render:
        from salad_viz import animate

        animate(take, sk, out / f"{stem}.gif", size=(320, 320), stride=2)
    if loaded.bvh is not None and not args.quiet:
        for hml, src in loaded.bvh.rig.describe().items():
            print(f"  {hml:15s} <- {src}")
    if retargeted is not None:
        print(f"retargeted to the {sk.name} skeleton (what the features and {stem}_retargeted_joints.npy hold): "
              f"{retarget_error(take, sk)} from the take (per frame, root and heading aligned)")
    n = len(take)
    cropped = f" (--crop {args.crop} from frame {start})" if args.crop is not None else ""
    if loaded.kind == "features":
        what = f"joints {n} frames (the pipeline's {DEFAULT_METHOD} recovery of the features), features {len(features)}"
    else:
        what = (("take joints and retargeted joints " if retargeted is not None else "joints ")
                + f"{n} frames, features {len(features)} (one per step between frames)")
    print(f"{n} frames at {sk.fps:g} fps ({n / sk.fps:.2f} s){cropped}: {what}: " + ", ".join(map(str, paths)))
    return 0


def _motion_input(args: argparse.Namespace, check_length: bool = True):
    """``(skeleton, loaded motion, features to invert, first frame)`` from a .bvh take or a .npy of features or
    joints.

    BVH takes and joints are converted with :func:`salad_core.motion.joints_to_features`
    (retargeted, on the floor, facing +Z); ``--crop`` then cuts the features (20 fps), which start at
    frame ``first frame`` of the loaded motion (0 without ``--crop``).
    """
    from salad_core.bvh import JointsConversionError, load_motion
    from salad_core.skeleton import get_skeleton

    try:
        sk = get_skeleton(args.skeleton)
    except (KeyError, ValueError) as exc:
        raise UserError(f"--skeleton: {exc.args[0] if exc.args else exc}") from None
    path = Path(args.motion)
    given = {k: getattr(args, k) for k in ("rig", "name_map", "units", "up") if getattr(args, k) is not None}
    if given and path.suffix.lower() != ".bvh":
        flags = ", ".join("--" + k.replace("_", "-") for k in given)
        raise UserError(f"{flags} appl{'y' if len(given) > 1 else 'ies'} to .bvh files; {path.name} is not one")
    if "units" in given:
        try:
            given["units"] = float(given["units"])      # metres per unit; otherwise a unit name
        except ValueError:
            pass
    try:
        loaded = load_motion(path, sk.name, **given)
    except JointsConversionError as exc:
        needs = "inversion needs" if getattr(args, "command", "") in ("invert", "edit") else "salad works on"
        raise UserError(f"{needs} HumanML3D features (N, {sk.feature_dim}); {exc}") from None
    except (FileNotFoundError, ValueError) as exc:   # BvhError and RigError name the file (and line)
        raise UserError(str(exc)) from None
    if loaded.bvh is not None:
        print(loaded.bvh.summary())
    features = loaded.features
    from salad_core.motion import MAX_FEATURE_MAGNITUDE

    top = float(abs(features).max(initial=0.0))
    if top > MAX_FEATURE_MAGNITUDE:      # before any weights load; the inversion would diverge
        raise UserError(f"{path} reaches |value| = {top:.3g}, beyond {MAX_FEATURE_MAGNITUDE:g}: not HumanML3D "
                        "features (metres, radians, metres per frame; of order 1); check its units")
    i = 0
    if args.crop is not None:
        a, b = _parse_crop(args.crop)
        i, j = int(round(a * sk.fps)), (len(features) if b is None else int(round(b * sk.fps)))
        if i >= len(features):
            raise UserError(f"--crop {args.crop}: the motion lasts {len(features) / sk.fps:.2f} s "
                            f"({len(features)} frames at {sk.fps:g} fps)")
        features = features[i:j]
    unit, max_len = sk.unit_length, sk.max_length
    if check_length and not unit <= len(features) - len(features) % unit <= max_len:
        hint = "" if args.crop is not None else "; pick a part with --crop START:STOP (seconds)"
        raise UserError(f"{path} has {len(features)} frames; allowed: {unit}..{max_len} (at {sk.fps:g} fps, "
                        f"{max_len / sk.fps:g} s at most{hint})")
    return sk, loaded, features, i


def cmd_invert(args: argparse.Namespace) -> int:
    """Invert a given motion (.bvh take, or .npy features / joints) under its prompt; write the
    reconstruction, its error, any edit and a side-by-side GIF of the source and the result."""
    import json

    from salad_core.attention import INVERSION_METHODS
    from salad_core.io import atomic_write_text

    specs = _edit_specs(args, required=False)
    if args.method not in INVERSION_METHODS:
        raise UserError(f"--method {args.method!r}; allowed: {', '.join(INVERSION_METHODS)}")
    if not (args.prompt or "").strip():
        raise UserError("--prompt is empty; describe what the motion shows, e.g. 'a person walks forward'")
    _check_edit_target(args, args.prompt)
    _check_sampling_args(args, 1, length=False, solver=False)
    if args.iterations is not None and (args.iterations < 0 or (args.method != "ddim" and args.iterations < 1)):
        raise UserError(f"--iterations {args.iterations}: allowed {0 if args.method == 'ddim' else 1} or more "
                        f"for --method {args.method}")
    sk, loaded, features, start = _motion_input(args)
    path = loaded.path
    out = _check_out_dir(args.out, args.force)
    stem = path.stem
    branches = ["reconstruction"] + (["edited"] if specs else [])
    gif_name = f"{stem}_source_vs_{branches[-1]}.gif"
    # refuse before any work: every file this run would write
    _outputs(out, [name for b in branches for name in _motion_file_names(f"{stem}_{b}", gif=False)]
             + [f"{stem}_inversion.json"] + ([] if args.no_render else [gif_name])
             + ([f"{stem}_input_features.npy"] if loaded.kind != "features" else []), args.force, write=False)
    if len(features) % sk.unit_length:
        n = len(features) - len(features) % sk.unit_length
        _note(args, f"the motion has {len(features)} frames, not a multiple of {sk.unit_length}; inverting the first {n}")
    pipe = _load_pipeline(args.weights)
    _note_unknown_words(args, pipe, [args.prompt] + [args.target] * bool(specs and args.target), ["prompt", "target"])
    if pipe.skeleton.name != sk.name:
        raise UserError(f"the weights are for skeleton {pipe.skeleton.name!r}, the motion was read as {sk.name!r}; "
                        f"pass --skeleton {pipe.skeleton.name}")
    files = []
    if loaded.kind != "features":     # what the model sees of a take: its features (20 fps, on the floor)
        from salad_core.io import atomic_path
        import numpy as np

        (inp,) = _outputs(out, [f"{stem}_input_features.npy"], args.force)
        with atomic_path(inp) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, np.asarray(features, dtype=np.float32))
        files.append(inp)
    inv = _invert(pipe, features, args.prompt, args, method=args.method, iterations=args.iterations,
                  exact=args.exact)
    rec = inv.reconstruction
    n = rec.lengths[0]
    vs_take = _take_errors(loaded, inv.features[0][:n], start, rec.raw_joints[0][:n], pipe.skeleton)
    if vs_take is not None:
        print(f"against the take itself (its own bone lengths; the line above is against its copy retargeted to "
              f"{pipe.skeleton.name}, which the model was given): reconstruction MPJPE "
              f"{vs_take['mpjpe_cm']:.2f} cm root-aligned, {vs_take['mpjpe_global_cm']:.2f} cm global; the "
              f"retargeted input alone is {vs_take['retargeting_mpjpe_cm']:.2f} cm root-aligned, "
              f"{vs_take['retargeting_mpjpe_global_cm']:.2f} cm global from it")
    files += _write_motion_files(out, f"{stem}_reconstruction", rec.features[0, :n], rec.joints[0], pipe.skeleton,
                                 force=args.force, gif=False, bvh=True)
    target, shown = None, rec.joints[0]
    if specs:
        result = pipe.edit(target=args.target, edits=specs, inversion=inv, progress=not args.quiet)
        dst = result.edited
        target, shown = dst.texts[0], dst.joints[0]
        files += _write_motion_files(out, f"{stem}_edited", dst.features[0, :n], dst.joints[0], pipe.skeleton,
                                     force=args.force, gif=False, bvh=True)
    if not args.no_render:
        from salad_viz import animate

        (gif,) = _outputs(out, [gif_name], args.force)
        from salad_core.recovery import recover_joints

        source = recover_joints(inv.features[0][:n], pipe.recovery, pipe.skeleton)   # as the reconstruction's
        files.append(animate([source, shown], pipe.skeleton, gif, layout="side", titles=["source", branches[-1]],
                             size=(240, 240), stride=2))
    report = {"motion": str(path), "prompt": inv.prompts[0], "frames": n, "input_frames": int(len(features)),
              "method": inv.method, "num_steps": inv.num_steps, "guidance_scale": inv.guidance_scale,
              "iterations": inv.iterations, "exact": inv.exact, "seconds": round(float(inv.seconds), 3),
              "errors": _errors_cm(inv.errors, pipe.skeleton), "weights": pipe.source,
              "edit": None if not specs else {"target": target, "edits": [repr(e) for e in specs]},
              "input": {"kind": loaded.kind, "crop": args.crop}}
    if vs_take is not None:
        report["errors_vs_take"] = vs_take
    if loaded.bvh is not None:
        b = loaded.bvh
        report["input"]["bvh"] = {"source_fps": b.source_fps, "source_frames": b.source_frames, "units": b.units,
                                  "metres_per_unit": b.metres_per_unit, "up": b.up, "rig": b.rig.style,
                                  "detected": list(b.detected), "joints": b.rig.describe()}
    (json_path,) = _outputs(out, [f"{stem}_inversion.json"], args.force)
    files.append(atomic_write_text(json_path, json.dumps(report, indent=2) + "\n"))
    print(", ".join(str(f) for f in files))
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    import numpy as np

    from salad_viz import animate, keyframe_strip

    from salad_viz._arrays import MAX_SIZE

    if not 8 <= args.size <= MAX_SIZE:
        raise UserError(f"--size {args.size}: allowed 8..{MAX_SIZE} pixels (the side of a square frame)")
    out = _check_out_dir(args.out, args.force)
    sk, joints, path = _load_joints(args.motion, args.skeleton)
    stem = path.stem
    _outputs(out, [f"{stem}.{args.format}"] + ([f"{stem}_strip.png"] if args.strip else []), args.force,
             write=False)
    if args.strip:
        from salad_core.io import atomic_path
        import imageio.v3 as iio

        (p,) = _outputs(out, [f"{stem}_strip.png"], args.force)
        img = keyframe_strip(joints, sk, np.linspace(0, len(joints) - 1, 6).astype(int), layout="row")
        with atomic_path(p) as tmp:
            iio.imwrite(tmp, img, extension=".png")
        print(p)
    (p,) = _outputs(out, [f"{stem}.{args.format}"], args.force)
    print(animate(joints, sk, p, size=(args.size, args.size)))
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from salad_viz import export_bvh, export_glb, export_npy

    out = _check_out_dir(args.out, args.force)
    sk, arr, path = _load_joints(args.motion, args.skeleton)
    (p,) = _outputs(out, [f"{path.stem}.{args.format}"], args.force)
    fn = {"bvh": export_bvh, "glb": export_glb, "npy": export_npy}[args.format]
    written = fn(arr, sk, p)
    print(written)
    err = getattr(written, "max_error", None)      # BVH: how far a reader's joints are from these
    if err is not None and err > 0.005:
        _note(args, f"{written.name} holds these joints to {100 * err:.1f} cm ({100 * written.mean_error:.2f} cm "
                    "mean): a BVH skeleton is rigid, and these joints' bones change length or their pelvis or "
                    "chest is not rigid")
    return 0


# ----------------------------------------------------------------------------- corpus
def cmd_corpus(args: argparse.Namespace) -> int:
    from salad_core.data.procedural import build_corpus, corpus_figures

    if args.action == "build":
        summary = build_corpus(args.out, size=args.size, seed=args.seed, overwrite=args.force,
                               progress=not args.quiet)
        print(f"corpus written to {args.out}: " + ", ".join(f"{k}={v}" for k, v in summary.items()
                                                            if isinstance(v, (int, float, str))))
    else:
        root = Path(args.out)
        missing = [n for n in ("all.txt", "new_joint_vecs", "texts") if not (root / n).exists()]
        if not root.is_dir() or missing:
            raise UserError(f"--out {root} is not a corpus folder" + (f" (no {', '.join(missing)})" if root.is_dir()
                            else " (no such folder)") + f"; build one with: salad corpus build --out {root}")
        figs = corpus_figures(args.out)
        for k, v in figs.items():
            print(f"{k}: {v}")
    return 0


# ----------------------------------------------------------------------------- train
def cmd_eval(args: argparse.Namespace, rest: list[str]) -> int:
    from salad_core.eval.cli import main as eval_main

    return int(eval_main(rest) or 0)


def _option_value(rest: list[str], flag: str) -> str | None:
    """The value of ``flag`` (``--flag V`` or ``--flag=V``) among pass-through arguments."""
    for i, item in enumerate(rest):
        if item == flag and i + 1 < len(rest):
            return rest[i + 1]
        if item.startswith(flag + "="):
            return item.split("=", 1)[1]
    return None


def cmd_train(args: argparse.Namespace, rest: list[str]) -> int:
    import json

    from salad_core.train import main as train_main

    try:
        return int(train_main(([args.what] if args.what else []) + rest) or 0)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        # the trainers' parser reads --config without naming it in the error: say which file and why
        config = _option_value(rest, "--config")
        try:
            if config is None:
                raise ValueError
            json.loads(Path(config).read_text(encoding="utf-8"))
        except (OSError, ValueError):        # the --config file is the culprit (JSONDecodeError is a ValueError)
            what = (f"{exc.msg} at line {exc.lineno}, column {exc.colno}" if isinstance(exc, json.JSONDecodeError)
                    else "it is not UTF-8 text")
            if config is not None:
                raise UserError(f"--config {config} is not a JSON document ({what}); see "
                                "configs/salad-0.3/vae.json for the format") from None
        raise


def cmd_bench(args: argparse.Namespace, rest: list[str]) -> int:
    from salad_core.bench import main as bench_main

    return int(bench_main(rest) or 0)


def _generation_args(p: argparse.ArgumentParser, length: int) -> None:
    p.add_argument("--length", type=int, default=length,
                   help=f"frames at 20 fps, 4..196 (default {length}); other values are rounded down to a "
                        "multiple of 4, with a note")
    p.add_argument("--seed", type=int, default=0,
                   help="noise seed (default 0); prompt b of a batch uses SEED + b")
    p.add_argument("--guidance", type=float, default=None,
                   help="classifier-free guidance weight w, -100..100 (default: the weights' own, "
                        "pipeline.json: 4.5 for the shipped SALAD; 7.5 = the paper's; 1 = no guidance; negative "
                        "steers away from the prompt)")
    p.add_argument("--guidance-rescale", type=float, default=None, metavar="PHI",
                   help="guidance rescale phi in [0, 1] (Lin et al. 2024; default: the weights' own, 0 for the shipped "
                        "SALAD): keeps strong guidance from inflating the motion; 0.7 at w 4.5 measured straighter "
                        "bones and less skating but weaker re-weighting (see the model card)")
    p.add_argument("--guidance-interval", default=None, metavar="LO:HI",
                   help="guide only at steps with LO <= t/T <= HI, 0 <= LO < HI <= 1 (Kynkaenniemi et al. 2024; "
                        "default: the weights' own, every step for the shipped SALAD); e.g. 0:0.5 = the "
                        "low-noise half")
    p.add_argument("--steps", type=int, default=None, help="sampler steps, 1..1000 (default 50)")
    p.add_argument("--solver", default=None,
                   help="scheduler: ddim (default), ddpm, dpm++, euler, euler_ancestral, unipc")
    p.add_argument("--preset", default=None, choices=("paper", "fast"),
                   help="sampler preset instead of --solver/--steps: paper = DDIM 50 steps, fast = DPM-Solver++ 20 steps")
    p.add_argument("--weights", default=None, help="pipeline folder (default: the shipped weights)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")


def _normalize_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--normalize", choices=["global", "each"], default="global",
                   help="colour scale of the attention figure's panels: global = one scale for all panels (default; "
                        "a dim word looks dim), each = every panel to its own maximum (shapes only; brightness does "
                        "not compare across panels)")


def _resolve_sampler(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Fill ``args.solver``/``args.steps`` from ``--preset`` (exclusive with them) or the defaults."""
    if args.preset is not None:
        if args.solver is not None or args.steps is not None:
            parser.error("--preset sets the solver and the steps; give --preset or --solver/--steps, not both")
        from salad_core.sampling import SAMPLER_PRESETS

        args.solver, args.steps = SAMPLER_PRESETS[args.preset]
    elif args.steps is None:
        args.steps = 50


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="salad", description="salad: text-driven motion generation and attention-based editing")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("-q", "--quiet", action="store_true", help="less output, no progress bars")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    d = _sub(sub, "demo", "the main job on the embedded defaults: generate the paper's Fig. 6 prompt, "
             "render it, draw its attention maps, export a BVH", "salad demo --out demo_out")
    d.add_argument("--out", default="salad_demo", help="output folder (default: salad_demo)")
    d.add_argument("--prompt", default=None, help=f"text prompt (default: {DEMO_PROMPT!r})")
    _normalize_arg(d)
    _generation_args(d, length=120)

    g = _sub(sub, "generate", "generate motions from text prompts",
             'salad generate "a person jumps" "a man waves his left hand" --length 80 --out gen_out')
    g.add_argument("prompt", nargs="+", help="one or more text prompts")
    g.add_argument("--out", required=True, help="output folder (created if missing)")
    g.add_argument("--no-attention", action="store_true",
                   help="do not capture and plot attention maps (by default one NN_<prompt>_attention.png per "
                        "prompt: a 7-part x frame heatmap per content word)")
    g.add_argument("--no-render", action="store_true", help="skip the GIF animation")
    _normalize_arg(g)
    g.add_argument("--keymotion", nargs="?", const="shipped", default=None, metavar="DIR",
                   help="generate with KeyMotion, the second generator, instead of SALAD: the shipped weights, or "
                        "the KeyMotion pipeline folder DIR (guidance default: its keymotion.json, 7.5 for the shipped; "
                        "lengths from its 20 keyframes to 196; no attention figure)")
    _generation_args(g, length=120)

    ed = _sub(sub, "edit", "edit a motion by modulating its cross-attention (word swap, refinement, "
              "re-weighting, mirroring); with --motion, edit a given motion through inversion",
              'salad edit "a man raises his right hand high" --reweight high=-1 --out edit_out')
    ed.add_argument("source", help="source prompt (for --motion: what the given motion shows)")
    _edit_args(ed)
    ed.add_argument("--motion", default=None, help="a features .npy (N, 263) to edit instead of a generated one "
                    "(inverted first; see also salad invert)")
    ed.add_argument("--out", required=True, help="output folder (created if missing)")
    ed.add_argument("--attention", action="store_true",
                    help="also write edited_attention.png: the cross-attention maps the edited motion used, one panel "
                         "per content word (a negative re-weight shows on a blue-white-red scale centred at 0)")
    _normalize_arg(ed)
    _generation_args(ed, length=100)

    iv = _sub(sub, "invert", "invert a given motion to noise under its prompt: write its reconstruction and the "
              "reconstruction error (MPJPE, cm); with edit flags, also the edited motion (npy, BVH and a GIF)",
              'salad invert my_take.bvh --prompt "a person walks forward" --mirror all --out inv_out')
    iv.add_argument("motion", help="a .bvh take (any frame rate; SMPL, Mixamo, CMU and similar rigs; see --name-map) "
                    "or a .npy of HumanML3D features (N, 263) or joints (N, 22, 3); 4 <= N <= 196 frames at "
                    "20 fps (cropped to a multiple of 4; see --crop)")
    iv.add_argument("--prompt", required=True, help="what the motion shows (the source prompt)")
    iv.add_argument("--out", required=True, help="output folder")
    _edit_args(iv)
    iv.add_argument("--method", default="fixed_point",
                    help="inversion method: ddim, fixed_point (default: DDIM inversion made faithful under "
                         "guidance) or null_text")
    iv.add_argument("--iterations", type=int, default=None, help="fixed-point updates / null-text steps per step")
    iv.add_argument("--exact", action=argparse.BooleanOptionalAction, default=True,
                    help="per-step corrections, so the reconstruction is exact (default; --no-exact: the plain "
                         "method)")
    iv.add_argument("--guidance", type=float, default=None,
                    help="guidance scale the inversion is made for (default: the weights' own, pipeline.json)")
    iv.add_argument("--steps", type=int, default=50, help="DDIM steps (default 50)")
    _bvh_args(iv)
    iv.add_argument("--no-render", action="store_true", help="skip the GIF")
    iv.add_argument("--weights", default=None, help="pipeline folder (default: the shipped weights)")
    iv.add_argument("--skeleton", default="humanml3d", help="skeleton of the motion: humanml3d (22 joints, "
                    "default) or kit (21)")
    iv.add_argument("--force", action="store_true", help="overwrite existing files")

    im = _sub(sub, "import", "convert a BVH motion-capture take (SMPL, Mixamo, CMU and similar rigs, any frame rate, "
              "unit and up axis) to the 22 HumanML3D joints at 20 fps: the take's own (its bone lengths, on its "
              "floor: NAME_joints.npy), a copy retargeted to HumanML3D's skeleton (NAME_retargeted_joints.npy, with "
              "its distance from the take printed) and that copy's features (NAME_features.npy), and a GIF",
              "salad import my_take.bvh --out takes")
    im.add_argument("motion", help="a .bvh take (or a joints .npy (N, 22, 3))")
    im.add_argument("--out", required=True, help="output folder")
    _bvh_args(im)
    im.add_argument("--no-render", action="store_true", help="skip the GIF")
    im.add_argument("--skeleton", default="humanml3d", help=argparse.SUPPRESS)
    im.add_argument("--force", action="store_true", help="overwrite existing files")

    r = _sub(sub, "render", "animate a motion file (features .npy or joints .npy) as GIF or MP4",
             "salad render gen_out/00_a_person_jumps_joints.npy --out renders --format mp4")
    r.add_argument("motion", help="a .npy file: features (N, 263) or joints (N, 22, 3)")
    r.add_argument("--out", required=True, help="output folder (created if missing)")
    r.add_argument("--format", choices=["gif", "mp4"], default="gif", help="animation format (default gif)")
    r.add_argument("--size", type=int, default=320, help="side of the square frame in pixels, 8..4096 (default 320)")
    r.add_argument("--strip", action="store_true", help="also write a keyframe strip PNG")
    r.add_argument("--skeleton", default="humanml3d", help="skeleton of the motion: humanml3d (default) or kit")
    r.add_argument("--force", action="store_true", help="overwrite existing files")

    e = _sub(sub, "export", "export a motion file to BVH (Blender), GLB or NPY joints",
             "salad export gen_out/00_a_person_jumps_features.npy --format bvh --out exports")
    e.add_argument("motion", help="a .npy file: features (N, 263) or joints (N, 22, 3)")
    e.add_argument("--out", required=True, help="output folder (created if missing)")
    e.add_argument("--format", choices=["bvh", "glb", "npy"], default="bvh",
                   help="bvh (Blender; default), glb (first frame as a 3D scene) or npy (joints (N, J, 3), metres)")
    e.add_argument("--skeleton", default="humanml3d", help="skeleton of the motion: humanml3d (default) or kit")
    e.add_argument("--force", action="store_true", help="overwrite existing files")

    c = _sub(sub, "corpus", "build or inspect the procedural motion-language corpus",
             "salad corpus build --out data/procedural --size default --seed 0")
    c.add_argument("action", choices=["build", "check"], help="build a corpus, or print the figures of one")
    c.add_argument("--out", required=True, help="corpus folder (HumanML3D layout)")
    c.add_argument("--size", default="default", choices=["tiny", "small", "default"],
                   help="build: how many motions (default: the full corpus, 4,000 plus mirrors)")
    c.add_argument("--seed", type=int, default=0, help="build: random seed (default 0)")
    c.add_argument("--force", action="store_true", help="write into a non-empty folder")

    t = _sub(sub, "train", "train the SALAD VAE or denoiser, or the three KeyMotion models (torchrun-ready)",
             "salad train vae --data data/procedural --out runs/vae", add_help=False)
    # --help and the choices go to salad_core.train.cli (TRAIN_TARGETS), which owns them; importing
    # them here would load torch for every command
    t.add_argument("what", nargs="?", help="vae, denoiser or keymotion")

    _sub(sub, "eval", "evaluate generators with the T2M protocol (R-precision, FID, MM-Dist, Diversity, "
         "MultiModality), CFG sweeps", "salad eval --data data/procedural --quick --out eval_out",
         add_help=False)  # --help goes to the evaluation's own parser
    _sub(sub, "bench", "measure speed, roofline fraction, edit overheads, training rate and memory on this "
         "machine; one table", "salad bench --quick --threads 1 --out bench.md",
         add_help=False)  # --help goes to salad_core.bench's own parser
    return p


COMMANDS: dict[str, Callable] = {"corpus": cmd_corpus, "demo": cmd_demo, "generate": cmd_generate,
                                 "render": cmd_render, "export": cmd_export, "edit": cmd_edit, "invert": cmd_invert,
                                 "import": cmd_import}
#: Commands whose remaining arguments go to another module's parser.
PASS_THROUGH: dict[str, Callable] = {"train": cmd_train, "eval": cmd_eval, "bench": cmd_bench}


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


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    if args.quiet:
        _quiet_libraries()
    from salad_core.allocator import tune_from_environment

    try:
        tune_from_environment()     # large activations from the heap, freed memory kept for reuse
    except ValueError as exc:
        parser.error(str(exc))
    if rest and args.command not in PASS_THROUGH:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    if hasattr(args, "preset"):
        _resolve_sampler(args, parser)
    if args.command in PASS_THROUGH:
        return run_reporting_errors(f"salad {args.command}", args.debug, lambda: PASS_THROUGH[args.command](args, rest))
    return run_reporting_errors(f"salad {args.command}", args.debug, lambda: COMMANDS[args.command](args))

if __name__ == "__main__":
    sys.exit(main())
