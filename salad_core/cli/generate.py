"""``salad demo``, ``salad generate``, ``salad edit`` and ``salad invert``: motions from text, their attention
figures, edits through the cross-attention, and the inversion of a given motion."""
from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Callable

from ._common import (UserError, _check_finite, _check_out_dir, _motion_file_names, _note, _outputs, _slug, _sub,
                      _write_motion_files)
from .files import _bvh_args, _load_features, _motion_input


def _load_pipeline(weights: str | None, preset: str | None = None):
    """The SALAD pipeline of ``--weights`` (``preset="realtime"``: the distilled weights; ``weights`` their folder)."""
    from salad_core.pipeline import SaladPipeline

    # a missing or corrupt folder raises CheckpointError (a missing realtime folder names the command that makes it)
    return SaladPipeline.from_pretrained(weights, preset=preset)


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


def _model_name(weights: str | None) -> str:
    """How an explorer page names the model: ``SALAD (shipped weights)`` or ``SALAD (<folder>)``."""
    return "SALAD (shipped weights)" if weights is None else f"SALAD ({weights})"


def _full_capture():
    """The capture an explorer page needs: every step, layer and head (``CaptureConfig(mode="full")``)."""
    from salad_core.attention import CaptureConfig

    return CaptureConfig(mode="full")


def _explorer_page(out: Path, name: str, force: bool, result, b: int, *, model: str, compare=None,
                   edit: str | None = None, label: str | None = None, words=None) -> Path:
    """Write the offline attention explorer (:func:`salad_viz.export_explorer`) of sample ``b`` of ``result``
    (a MotionOutput with a full capture) as ``out/name``; ``compare``: the edited MotionOutput, shown beside it
    on one colour scale, with ``edit`` (its label) in the header."""
    from salad_viz import export_explorer

    (path,) = _outputs(out, [name], force)
    other = None
    if compare is not None:
        other = dict(attention=compare.attention, joints=compare.joints[0], label="edited")
    export_explorer(result.attention, None, result.joints[b], batch=b, path=path, model=model, compare=other,
                    edit=edit, label=label, words=words)
    return path


def _edit_words(specs, maps, source: str | None, target: str | None) -> list[str] | None:
    """The words an edit's page opens on: the words its edits name (re-weighted, erased, shifted, or swapped
    by a word swap) that are words of the source prompt, function words left out; ``None`` (the page's
    default, the first content word) when there are none."""
    from salad_core.data.texts import split_words

    have = list(maps.words(0))
    named: list[str] = []
    for spec in specs:
        if type(spec).__name__ == "WordSwap":
            named += [a for a, b in zip(split_words(source or ""), split_words(target or "")) if a != b]
        words = getattr(spec, "words", None)
        if isinstance(words, (str, tuple, list)):
            items = (words,) if isinstance(words, str) else words
            named += [w for item in items if isinstance(item, str) for w in split_words(item)]
    picked = [w for w in dict.fromkeys(named) if w in have]
    return [w for w in picked if w not in _FUNCTION_WORDS] or picked or None


DEMO_PROMPT = "a man jumps forward and then walks forward, while waving his arms"


def _weights_info(weights: str | None) -> tuple[str, int]:
    """``(skeleton name, diffusion timesteps)`` from a pipeline folder's ``pipeline.json``, read
    without loading any weights, so that arguments can be checked first; the defaults
    (humanml3d, 1000) when the file is missing or odd (loading the weights then says why)."""
    from salad_core.limits import read_json
    from salad_core.pipeline import default_weights_dir

    root = Path(weights) if weights is not None else default_weights_dir()
    try:
        cfg = read_json(root / "pipeline.json", "pipeline.json")      # size and nesting checked before parsing
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
    html = bool(getattr(args, "html", False))
    if html and not attention:
        raise UserError("--html shows the attention maps, --no-attention turns their capture off: give one of them")
    figures = [attention and _has_words(p) for p in prompts]
    for b, p in enumerate(prompts):
        if attention and not figures[b]:
            _note(args, f"prompt {b} {p!r} has no words: no attention figure for it", kind="warning")
        elif figures[b] and not split_words(p):     # e.g. another script: the maps are drawn per a-z word
            figures[b] = False
            _note(args, f"prompt {b} {p!r} has no English (a-z) words, the words attention maps are drawn for: "
                        "no attention figure for it" + (" and no explorer page" if html else ""), kind="warning")
    pages = [html and fig for fig in figures]        # --html: one offline explorer page per motion with words
    # every file of the run is checked before anything is written
    stems = _generate_stems(prompts)
    _outputs(out, [name for st in stems for name in _motion_file_names(st, gif=not args.no_render)]
             + [f"{st}_attention.png" for st, fig in zip(stems, figures) if fig]
             + [f"{st}_explorer.html" for st, page in zip(stems, pages) if page], args.force, write=False)
    pipe = _load_pipeline(args.weights, getattr(args, "weights_preset", None))
    _note_unknown_words(args, pipe, prompts)
    guidance = _guidance(args, pipe)
    _say_guidance(args, guidance)
    # a long batch runs in the pipeline's chunks, each written before the next (prompt b keeps seed SEED + b):
    # one line with the count and the time the first chunk measured, then a bar over the motions
    from salad_core import limits

    from ._common import batch_chunks, say

    chunk = pipe.chunk_size() if len(prompts) > limits.PROMPT_CHUNK else len(prompts)
    for rows in batch_chunks(len(prompts), chunk, progress=not args.quiet,
                             report=(lambda line: None) if args.quiet else say):
        # a page shows every step and layer (full capture); the figure alone needs the step means
        capture = _full_capture() if any(pages[rows]) else attention and any(figures[rows])
        result = pipe(prompts[rows], lengths=args.length, seed=args.seed + rows.start, guidance_scale=guidance,
                      num_steps=args.steps, solver=args.solver, capture_attention=capture,
                      progress=not args.quiet)
        for i, text in enumerate(result.texts):
            b, n = rows.start + i, result.lengths[i]
            files = _write_motion_files(out, stems[b], result.features[i, :n], result.joints[i], pipe.skeleton,
                                        force=args.force, gif=not args.no_render, bvh=True, title=text)
            if figures[b]:
                fig = _attention_figure(out, stems[b], result, i, args.force,
                                        normalize=getattr(args, "normalize", "global"))
                files += [fig] if fig else []
                if not fig:
                    _note(args, f"prompt {b} {text!r}: no attention figure ({_no_figure_reason(result, i)})",
                          kind="warning")
            if pages[b] and result.attention is not None and result.attention.words(i):
                files.append(_explorer_page(out, f"{stems[b]}_explorer.html", args.force, result, i,
                                            model=_model_name(args.weights)))
            say(f"{text!r} ({n} frames): " + ", ".join(str(f) for f in files))
    return 0


def _generate_keymotion(args: argparse.Namespace, prompts: list[str]) -> int:
    """``salad generate --keymotion [DIR]``: the same files from KeyMotion (the shipped weights, or a pipeline
    folder), one call per prompt with seed ``SEED + b``, so that a prompt's motion does not depend on the others
    given with it. KeyMotion has no 7-part cross-attention, so no attention figure is drawn."""
    from salad_core.keymotion.pipeline import KeyMotionPipeline

    if getattr(args, "html", False):
        raise UserError("--html shows SALAD's 7-part cross-attention, which KeyMotion does not have; drop --html or "
                        "--keymotion")
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
    from salad_core import limits
    from salad_core.cli._common import batch_chunks

    many = len(prompts) > limits.PROMPT_CHUNK       # one motion at a time: say how many and roughly how long
    order = (rows.start for rows in batch_chunks(len(prompts), 1, progress=not args.quiet)) if many \
        else range(len(prompts))
    for b in order:
        text = prompts[b]
        result = pipe(text, lengths=args.length, seed=args.seed + b, guidance_scale=guidance,
                      num_steps=args.steps, progress=not args.quiet and not many)
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


#: ``--inpaint-noise`` choices: :data:`salad_core.attention.inpaint.NOISE_MODES` (spelled out to keep the parser light).
INPAINT_NOISE = ("auto", "fresh", "source", "matched")
#: ``--inpaint-score`` choices: :data:`salad_core.attention.inpaint.SCORE_MODES` (spelled out likewise).
INPAINT_SCORE = ("auto", "whole", "parts", "prior", "first_smooth")
#: ``--inpaint-prior`` choices: :data:`salad_core.attention.inpaint.PRIOR_MODES` (spelled out likewise).
INPAINT_PRIOR = ("auto", "none", "prompt")


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
    p.add_argument("--erase", action="append", metavar="WORDS",
                   help="erase a word or phrase: its attention goes to the special tokens (Erase; beyond the paper)")
    p.add_argument("--shift", action="append", metavar="WORDS=FRAMES",
                   help="move a phrase's attention in time by FRAMES motion frames, a multiple of 4 (Shift)")
    p.add_argument("--example-seed", type=int, default=None, metavar="SEED",
                   help="a variation of the source from new noise SEED that keeps its temporal self-attention "
                        "(ExampleBased)")
    p.add_argument("--inpaint", default=None, metavar="PARTS[@START:END]",
                   help="regenerate body parts and/or frames from --target, keep the rest (Inpaint): e.g. arms, "
                        "legs@40:80, @40:80, all@:40")
    p.add_argument("--inpaint-blend", type=int, default=1, metavar="N",
                   help="latent frames over which an in-painted span fades into the kept frames (default 1)")
    p.add_argument("--inpaint-root", choices=["source", "edit", "auto"], default="auto",
                   help="after an in-painted span: 'source' keeps the later frames where the take has them (a turn "
                        "in the span is turned back), 'edit' lets them follow the span's path, 'auto' (default) "
                        "lets them follow a span that turned on its own (more than 45 degrees, and that much beyond "
                        "the take) and keeps them in place after any other")
    p.add_argument("--inpaint-fade", type=int, default=8, metavar="N",
                   help="frames over which an in-painted span's seams are cross-faded in the features (default 8)")
    p.add_argument("--inpaint-smooth", type=float, default=None, metavar="LAMBDA",
                   help="jerk penalty of the least-squares smoothing of an in-painted span's frames next to its seams "
                        "(default 100; 0: off)")
    p.add_argument("--inpaint-smooth-window", type=int, default=None, metavar="N",
                   help="frames of an in-painted span next to each seam that the smoothing may move (default 8)")
    p.add_argument("--inpaint-resample", type=int, default=None, metavar="U",
                   help="RePaint resampling: denoise each jump of steps U times, re-noising the in-painted region in "
                        "between (1: off; about U times the cost; default: 3 for body parts alone, off for a span)")
    p.add_argument("--inpaint-jump", type=int, default=None, metavar="J",
                   help="sampler steps per resampling jump (default 5)")
    p.add_argument("--inpaint-noise", choices=INPAINT_NOISE, default=None,
                   help="what the in-painted region starts from: 'fresh' white noise from the seed, 'source' the "
                        "source's noise (a given take's inverted noise), 'matched' fresh noise shaped to the source "
                        "noise's std and frame-to-frame correlation; default 'auto': fresh for a given take, the "
                        "source's for a generated motion")
    p.add_argument("--inpaint-guidance", default=None, metavar="W|auto|motion",
                   help="guidance weight of the in-painted region's branch: a number, 'auto' (default: 7.5 for a "
                        "frame span, the motion's own for body parts alone) or 'motion' (the motion's own)")
    p.add_argument("--inpaint-candidates", type=int, default=None, metavar="K",
                   help="run the in-painting K times, the region's noise (and pasted prior) from K seeds (0 .. K-1), "
                        "and keep the best by --inpaint-score (K times the cost; 1: one edit; default: 8 for a frame "
                        "span of a given take, 1 otherwise). Needs fresh noise in the region (the default for a given "
                        "take: --motion, salad invert) or a pasted prior")
    p.add_argument("--inpaint-score", choices=INPAINT_SCORE, default=None,
                   help="what the evaluator scores of each in-painting candidate: 'whole' the edited motion, 'parts' "
                        "the regenerated body parts with the kept ones held still (needs --inpaint PARTS); 'prior': "
                        "no evaluator, the pelvis and feet heights against the pasted prior (needs a pasted prior; "
                        "none smooth: the candidates again without it); 'first_smooth': no score, the candidates "
                        "run one at a time until one's seams are within --inpaint-seam-bound (default 1.5; a frame "
                        "span only); default 'auto': 'prior' for a frame span of a given take, the whole motion "
                        "otherwise")
    p.add_argument("--inpaint-seam-bound", default=None, metavar="B|auto|off",
                   help="rank a frame span's in-painting candidates by the evaluator only among those whose seam jerk "
                        "is at most B times the source's own 95th percentile (none within: the smoothest; e.g. 1.5); "
                        "'off': by the evaluator alone; default 'auto': 1.5 for a frame span of a given take, off "
                        "otherwise. Body parts alone have no seam")
    p.add_argument("--inpaint-prior", choices=INPAINT_PRIOR, default=None,
                   help="'prompt': paste, then harmonise: the target prompt is first sampled alone (the span's length, "
                        "or the whole motion for body parts) and the region starts from it, noised, for the first "
                        "steps; 'none': the region is denoised from noise; default 'auto': 'prompt' for every edit of "
                        "a given take (--motion, salad invert) and for a frame span of a generated source")
    p.add_argument("--inpaint-prior-strength", type=float, default=None, metavar="S",
                   help="with --inpaint-prior prompt: the share of the steps (0 < S <= 1) in which the region is free "
                        "to fit the kept motion (smaller keeps more of the pasted motion; default 0.7 for a frame span "
                        "of a given take, 0.5 otherwise)")
    p.add_argument("--no-composite", action="store_true",
                   help="keep what the decoder makes of the kept parts instead of taking them from the source's "
                        "decoding (--inpaint, --mirror-take; the decoder lets edited parts move kept ones a few cm)")
    p.add_argument("--mirror-take", choices=["legs", "arms", "limbs", "all"], default=None,
                   help="for a given take (salad invert, salad edit --motion): flip these limbs' side through the "
                        "inversion of the take's exact mirror image, keeping the other parts (MirrorTake + Mirror; "
                        "inverts the mirror image too); 'all' gives the exact mirror image")
    p.add_argument("--no-ground", action="store_true",
                   help="do not lower an edited take whose pelvis rises more than 10 cm above the take's range "
                        "(grounding is on for given takes unless the target asks to jump or climb)")
    p.add_argument("--window", default=None, metavar="START:STOP",
                   help="step window of --refine/--reweight/--mirror/--erase/--shift as fractions of the sampling "
                        "steps, 0 <= START < STOP <= 1 (0 = the noisiest step; default 0:1)")


def _edit_figure_args(p: argparse.ArgumentParser, prefix: str, source: str = "source") -> None:
    """``--attention`` and ``--normalize`` of ``salad edit`` / ``salad invert`` (files named ``{prefix}...``)."""
    p.add_argument("--attention", action="store_true",
                   help=f"also capture the cross-attention and write its figures, one panel per content word, the "
                        f"source's and the edit's on ONE colour scale (blue-white-red centred at 0 when a value is "
                        f"negative, e.g. a negative re-weight): {prefix}{source}_attention.png (the source's maps"
                        + (", captured while reconstructing the take from its inverted noise; without an edit flag "
                           "this costs one more sampling pass" if source == "reconstruction" else "")
                        + f"), {prefix}edited_attention.png and {prefix}attention_compare.png (a source block over an "
                          "edited block, titled with the edit, e.g. Reweight(high=-1))")
    _normalize_arg(p)


def _parse_window(text: str) -> tuple[float, float]:
    parts = text.replace(",", ":").split(":")
    if len(parts) != 2:
        raise UserError(f"--window takes START:STOP step fractions (e.g. 0:0.5), got {text!r}")
    try:
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise UserError(f"--window {text!r}: START and STOP must be numbers in [0, 1] (e.g. 0:0.5)") from None


def _number_or_word(flag: str, text: str, off_word: str, example: str):
    """A number, ``auto``, or ``off_word`` (None) for ``flag``."""
    word = text.strip().lower()
    if word in ("auto", off_word):
        return None if word == off_word else "auto"
    try:
        return float(word)
    except ValueError:
        raise UserError(f"{flag} {text}: give a number{example}, 'auto' or '{off_word}'") from None


def _inpaint_guidance(text: str):
    """``--inpaint-guidance``: a number, ``auto`` or ``motion`` (None: the motion's weight)."""
    return _number_or_word("--inpaint-guidance", text, "motion", "")


def _inpaint_seam_bound(text: str):
    """``--inpaint-seam-bound``: a number, ``auto`` or ``off`` (None: no bound)."""
    return _number_or_word("--inpaint-seam-bound", text, "off", " (e.g. 1.5)")


def _inpaint_options(args: argparse.Namespace) -> dict:
    """The ``--inpaint-*`` options that were given (the others keep :class:`Inpaint`'s defaults)."""
    out = {name: getattr(args, f"inpaint_{name}") for name in ("smooth", "smooth_window", "resample", "jump", "noise",
                                                               "candidates", "score", "prior", "prior_strength")
           if getattr(args, f"inpaint_{name}", None) is not None}
    if getattr(args, "inpaint_guidance", None) is not None:
        out["guidance"] = _inpaint_guidance(args.inpaint_guidance)
    if getattr(args, "inpaint_seam_bound", None) is not None:
        out["seam_bound"] = _inpaint_seam_bound(args.inpaint_seam_bound)
    return out


def _spec(flag: str, build: Callable):
    """Build one edit spec; its validation error becomes one line naming the flag."""
    try:
        return build()
    except (TypeError, ValueError) as exc:
        raise UserError(f"{flag}: {exc}") from None


def _edit_specs(args: argparse.Namespace, required: bool = True) -> list:
    """Edit specifications from the flags of :func:`_edit_args`, in the order the pipeline needs
    (the replacement first, then the modifiers); ``[]`` if none was given and not ``required``."""
    from salad_core.attention import (Erase, ExampleBased, Mirror, MirrorSelfAttention, Refine, Reweight, Shift,
                                      WordSwap, parse_inpaint)

    window = {} if args.window is None else {"steps": _parse_window(args.window)}
    in_window = "" if args.window is None else f" --window {args.window}"
    specs = []
    if args.swap is not None:
        specs.append(_spec(f"--swap {args.swap:g}", lambda: WordSwap(tau=args.swap)))
    if args.refine:
        specs.append(_spec(f"--refine{in_window}", lambda: Refine(**window)))
    for item in args.reweight or []:
        word, value = _word_value("--reweight", item, float, "WORD=SCALE (e.g. high=-1)", "the scale {!r} is not a number")
        specs.append(_spec(f"--reweight {item}{in_window}", lambda: Reweight(words=word, scale=value, **window)))
    if args.mirror:
        specs.append(_spec(f"--mirror {args.mirror}{in_window}", lambda: Mirror(parts=args.mirror, **window)))
        if getattr(args, "mirror_self_attention", False):
            specs.append(_spec(f"--mirror-self-attention{in_window}",
                               lambda: MirrorSelfAttention(parts=args.mirror, **window)))
    elif getattr(args, "mirror_self_attention", False):
        raise UserError("--mirror-self-attention goes with --mirror PARTS (it mirrors the same parts' self-attention)")
    for words in getattr(args, "erase", None) or []:
        specs.append(_spec(f"--erase {words}{in_window}", lambda: Erase(words=words, **window)))
    for item in getattr(args, "shift", None) or []:
        words, n = _word_value("--shift", item, int, "WORDS=FRAMES (e.g. 'waves=20')",
                               "FRAMES {!r} is not a whole number of frames")
        specs.append(_spec(f"--shift {item}{in_window}", lambda: Shift(words=words, frames=n, **window)))
    if getattr(args, "example_seed", None) is not None:
        specs.append(_spec(f"--example-seed {args.example_seed}", lambda: ExampleBased(seed=args.example_seed)))
    if getattr(args, "inpaint", None) is not None:
        specs.append(_spec(f"--inpaint {args.inpaint}", lambda: dataclasses.replace(
            parse_inpaint(args.inpaint, blend=args.inpaint_blend), root=args.inpaint_root, fade=args.inpaint_fade,
            composite=not args.no_composite, **_inpaint_options(args))))
    if args.window is not None and not (args.refine or args.reweight or args.mirror or getattr(args, "erase", None)
                                        or getattr(args, "shift", None)):
        raise UserError("--window applies to --refine, --reweight, --mirror, --erase and --shift; give one of them "
                        "(word swap is timed by TAU alone)")
    if not specs and required and getattr(args, "mirror_take", None) is None:
        raise UserError("give at least one edit: --swap TAU, --refine, --reweight WORD=SCALE, --mirror PARTS, "
                        "--mirror-take PARTS, --erase WORDS, --shift WORDS=FRAMES, --example-seed SEED or --inpaint "
                        "PARTS[@START:END]")
    return specs


def _take_edits(args: argparse.Namespace, pipe, inv, specs: list, quiet: bool) -> list:
    """``specs`` plus, with ``--mirror-take PARTS``, :class:`~salad_core.attention.MirrorTake` and ``Mirror`` of those
    parts built on the inversion of the take's mirror image (one more inversion)."""
    parts = getattr(args, "mirror_take", None)
    if parts is None:
        return specs
    from salad_core.attention import invert_mirror, mirror_take_edits

    if getattr(args, "example_seed", None) is not None:
        raise UserError("--mirror-take starts the limbs from the mirror image's noise; it cannot be combined with "
                        "--example-seed (new noise)")
    mirrored = invert_mirror(pipe, inv, progress=not quiet)
    return specs + mirror_take_edits(parts, mirrored, composite=not getattr(args, "no_composite", False))


def _word_value(flag: str, item: str, convert: Callable, form: str, bad: str):
    """``(words, value)`` of a ``WORDS=VALUE`` flag (the last ``=`` splits), or a one-line error naming the flag."""
    words, sep, text = item.rpartition("=")
    if not sep or not words:
        raise UserError(f"{flag} takes {form}, got {item!r}")
    try:
        return words, convert(text)
    except ValueError:
        raise UserError(f"{flag} {item!r}: {bad.format(text)}") from None


def _check_edit_target(args: argparse.Namespace, source: str) -> None:
    """A word swap or a refinement into the source prompt itself gives back the source: refuse it."""
    kind = ("--swap" if args.swap is not None else "--refine" if args.refine else
            "--inpaint" if getattr(args, "inpaint", None) is not None else None)
    if kind is None:
        return
    target = " ".join((args.target or "").split())
    if not target or target.lower() == " ".join(source.split()).lower():
        what = {"--swap": "replaces the source's words with the target's",
                "--refine": "keeps the source's maps for the target's words shared with it",
                "--inpaint": "regenerates the chosen parts or frames from the target prompt"}[kind]
        raise UserError(f"{kind} needs --target, a prompt that differs from the source ({kind[2:]} {what}); "
                        f"without one the edit gives back the source motion")


def _content_word_maps(maps, b: int):
    """``(maps (K, P, N'), words, positions)`` of prompt ``b``'s content words (function words left out unless
    the prompt has nothing else; ``positions``: their indices among the prompt's words), or None when the
    prompt has no a-z word to draw."""
    import numpy as np

    words = list(maps.words(b))
    if not words:
        return None
    keep = [i for i, w in enumerate(words) if w not in _FUNCTION_WORDS] or list(range(len(words)))
    stacked = np.stack([maps.word_map(b, i) for i in keep])     # by position: repeated words stay apart
    return stacked, [words[i] for i in keep], keep


def _save_png(fig, path: Path, limits: tuple[float, float]) -> Path:
    """Save a figure atomically as PNG with its colour limits (attention units) in the PNG text chunk
    ``Attention limits`` (``vmin=... vmax=...``), so figures meant to share one scale can be checked."""
    import matplotlib.pyplot as plt

    from salad_core.io import atomic_path

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=90, bbox_inches="tight",
                        metadata={"Attention limits": f"vmin={limits[0]!r} vmax={limits[1]!r}"})
    finally:
        plt.close(fig)
    return path


def _edit_figure_names(prefix: str, source: str, edited: bool) -> list[str]:
    """The attention figures of an edit command: ``{prefix}{source}_attention.png``, and with an edit
    ``{prefix}edited_attention.png`` and ``{prefix}attention_compare.png``."""
    names = [f"{prefix}{source}_attention.png"]
    return names + ([f"{prefix}edited_attention.png", f"{prefix}attention_compare.png"] if edited else [])


def edit_attention_limits(branches) -> tuple[float, float]:
    """The one colour scale ``(vmin, vmax)`` of an edit's attention figures: :func:`salad_viz.attention.
    attention_limits` over the content-word maps of every branch (``(title, MotionOutput)`` pairs with captured
    attention); symmetric about 0 when any map is negative (a negative re-weight)."""
    from salad_viz.attention import attention_limits

    drawn = [_content_word_maps(out.attention, 0) for _, out in branches]
    return attention_limits(*[d[0] for d in drawn if d is not None])


def _edit_attention_figures(out: Path, names: list[str], branches, force: bool, normalize: str) -> list[Path]:
    """Write the attention figures of an edit on ONE colour scale (:func:`edit_attention_limits`): one grid per
    branch (``names[k]``; branches are ``(title, MotionOutput)``, e.g. ``("source", src)`` and
    ``("Reweight(high=-1)", dst)``, titled ``"<title>: <prompt>"``) and, with two branches, the comparison
    (``names[2]``): a source block over an edited block, panel for panel. Returns the files written; none
    when a prompt has no word to draw."""
    import numpy as np

    from salad_viz import plot_attention_grid
    from salad_viz.attention import plot_attention_rows

    drawn = [_content_word_maps(o.attention, 0) for _, o in branches]
    if any(d is None for d in drawn):
        return []
    limits = edit_attention_limits(branches)
    titles = [f"{title}: {o.texts[0]}" for title, o in branches]
    unknown = [(o.unknown_words[0] if o.unknown_words else ()) for _, o in branches]
    paths = _outputs(out, names, force)
    files = []
    for (maps, words, _), title, unk, path in zip(drawn, titles, unknown, paths):
        grid = np.moveaxis(maps, 0, -1)                                  # (P, N', K) for plot_attention_grid
        fig = plot_attention_grid(grid, words, word_ids=list(range(len(words))), prompt=title, normalize=normalize,
                                  unknown_words=unk, limits=limits)
        files.append(_save_png(fig, path, limits))
    if len(branches) > 1:
        fig = plot_attention_rows([d[0] for d in drawn], [d[1] for d in drawn], titles, normalize=normalize,
                                  limits=limits, unknown_words=unknown)
        files.append(_save_png(fig, paths[len(branches)], limits))
    return files


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
    html = bool(getattr(args, "html", False))
    figures = _edit_figure_names("", "source", edited=True) if attention else []
    pages = [EDIT_PAGE] if html else []
    _outputs(out, names + ["source_vs_edited.gif", EDIT_REPORT] + figures + pages, args.force, write=False)
    capture = _full_capture() if html else attention
    pipe = _load_pipeline(args.weights)
    _note_unknown_words(args, pipe, [args.source] + [args.target] * bool(args.target), ["source", "target"])
    guidance = _guidance(args, pipe)
    _say_guidance(args, guidance)
    if features is not None:
        inv = _invert(pipe, features, args.source, args, method="fixed_point", guidance=guidance)
        specs = _take_edits(args, pipe, inv, specs, args.quiet)
        result = pipe.edit(target=args.target, edits=specs, inversion=inv, progress=not args.quiet,
                           capture_attention=capture, ground=not args.no_ground)
    else:
        if args.mirror_take is not None:
            raise UserError("--mirror-take mirrors a given take's limbs: give the take with --motion (or use "
                            "salad invert); for a generated motion use --mirror PARTS")
        result = pipe.edit(args.source, args.target, edits=specs, lengths=args.length, seed=args.seed,
                           guidance_scale=guidance, num_steps=args.steps, solver=args.solver,
                           progress=not args.quiet, capture_attention=capture)
    src, dst = result.source, result.edited
    n = src.lengths[0]
    files = _write_motion_files(out, "source", src.features[0, :n], src.joints[0], pipe.skeleton, force=args.force,
                                gif=False, bvh=True)
    files += _write_motion_files(out, "edited", dst.features[0, :n], dst.joints[0], pipe.skeleton, force=args.force,
                                 gif=False, bvh=True)
    from salad_core.attention.labels import edit_label

    label = edit_label(specs, src.texts[0], dst.texts[0])
    files.append(_comparison_gif(out, "source_vs_edited.gif", [src.joints[0], dst.joints[0]], pipe.skeleton,
                                 [("source", src.texts[0]), (label, dst.texts[0])], args.force))
    if attention:    # the source's maps and the edit's (a negative re-weight: a diverging scale), one scale
        figs = _edit_attention_figures(out, figures, [("source", src), (label, dst)], args.force, args.normalize)
        files += figs
        if not figs:
            _note(args, f"no attention figure ({_no_figure_reason(dst, 0)})", kind="warning")
    if html:
        files += _edit_page(args, out, pages[0], src, dst, specs, label)
    import json

    from salad_core.io import atomic_write_text

    report = {"source": src.texts[0], "target": dst.texts[0], "label": label,
              "edits": [repr(e) for e in result.edits],       # as run: with candidates, the kept one's (its seed)
              "frames": int(n), "seed": None if features is not None else args.seed,
              "motion": None if features is None else str(args.motion),
              "inversion": None if features is None else {"method": inv.method, "num_steps": inv.num_steps,
                                                          "errors": _errors_cm(inv.errors, pipe.skeleton)},
              "settings": result.settings}
    (report_path,) = _outputs(out, [EDIT_REPORT], args.force)
    files.append(atomic_write_text(report_path, json.dumps(report, indent=2, default=str) + "\n"))
    print(f"{src.texts[0]!r} -> {dst.texts[0]!r} with {label}: " + ", ".join(str(f) for f in files))
    return 0


#: The explorer page of ``salad edit --html``: the source and its edit side by side.
EDIT_PAGE = "source_vs_edited_explorer.html"
#: ``salad edit``'s record of what was run: the prompts, the edits as run (an in-painting's kept candidate), the seed or
#: the given take and its inversion, and the edit's settings (guidance, steps, ``inpaint_candidates``, ``inpaint_prior``,
#: ``composite``, ``grounding``, ...).
EDIT_REPORT = "edit.json"


def _edit_page(args: argparse.Namespace, out: Path, name: str, src, dst, specs, label: str) -> list[Path]:
    """``--html`` of an edit: the source (``src``) and the edited motion (``dst``, MotionOutputs with full
    captures) side by side in one offline explorer page on one colour scale, the edit named (``label``) and
    the page opening on the words the edit names. ``[]`` (with a warning) when a prompt has no word."""
    lacking = [o for o in (src, dst) if o.attention is None or not o.attention.words(0)]
    if lacking:
        _note(args, f"no explorer page ({_no_figure_reason(lacking[0], 0)})", kind="warning")
        return []
    words = _edit_words(specs, src.attention, src.texts[0], dst.texts[0])
    return [_explorer_page(out, name, args.force, src, 0, model=_model_name(args.weights), compare=dst, edit=label,
                           label="source", words=words)]


def _comparison_gif(out: Path, name: str, motions: list, skeleton, captions: list[tuple[str, str]],
                    force: bool) -> Path:
    """The side-by-side GIF of a source and its edit: motions ``(N, J, 3)``, one panel each of
    :data:`salad_viz.animate.COMPARISON_PANEL` pixels, captioned ``(label, prompt)`` (e.g. ``("source", ...)``,
    ``("Mirror(legs)", ...)``), the left/right key in each; every second frame, in real time."""
    from salad_viz.animate import COMPARISON_PANEL, animate

    (gif,) = _outputs(out, [name], force)
    return animate(motions, skeleton, gif, layout="side", titles=captions, size=COMPARISON_PANEL, stride=2)


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
    edited = bool(specs) or args.mirror_take is not None      # --mirror-take's edits are built after the inversion
    branches = ["reconstruction"] + (["edited"] if edited else [])
    gif_name = f"{stem}_source_vs_{branches[-1]}.gif"
    attention = bool(getattr(args, "attention", False))
    html = bool(getattr(args, "html", False))
    figures = _edit_figure_names(f"{stem}_", "reconstruction", edited=edited) if attention else []
    pages = [f"{stem}_source_vs_edited_explorer.html" if edited else f"{stem}_reconstruction_explorer.html"] \
        if html else []
    capture = _full_capture() if html else attention
    # refuse before any work: every file this run would write
    _outputs(out, [name for b in branches for name in _motion_file_names(f"{stem}_{b}", gif=False)]
             + [f"{stem}_inversion.json"] + ([] if args.no_render else [gif_name]) + figures + pages
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
    target, shown, label = None, rec.joints[0], "reconstruction"
    figure_branches = []
    specs = _take_edits(args, pipe, inv, specs, args.quiet)
    if specs:     # the edit's source branch is the reconstruction: its maps are the source's
        from salad_core.attention.labels import edit_label

        result = pipe.edit(target=args.target, edits=specs, inversion=inv, progress=not args.quiet,
                           capture_attention=capture, ground=not args.no_ground)
        dst = result.edited
        target, shown, label = dst.texts[0], dst.joints[0], edit_label(specs, inv.prompts[0], dst.texts[0])
        files += _write_motion_files(out, f"{stem}_edited", dst.features[0, :n], dst.joints[0], pipe.skeleton,
                                     force=args.force, gif=False, bvh=True)
        figure_branches = [("source", result.source), (label, dst)]
    elif attention or html:   # no edit: the maps of the reconstruction from the inverted noise (one more pass)
        figure_branches = [("source", pipe.reconstruct(inv, capture_attention=capture, progress=not args.quiet))]
    if not args.no_render:
        from salad_core.recovery import recover_joints

        source = recover_joints(inv.features[0][:n], pipe.recovery, pipe.skeleton)   # as the reconstruction's
        files.append(_comparison_gif(out, gif_name, [source, shown], pipe.skeleton,
                                     [("source", inv.prompts[0]), (label, target or inv.prompts[0])], args.force))
    if attention:
        figs = _edit_attention_figures(out, figures, figure_branches, args.force, args.normalize)
        files += figs
        if not figs:
            _note(args, f"no attention figure ({_no_figure_reason(figure_branches[-1][1], 0)})", kind="warning")
    if html and specs:
        files += _edit_page(args, out, pages[0], figure_branches[0][1], figure_branches[1][1], specs, label)
    elif html:
        rec_maps = figure_branches[0][1]
        if rec_maps.attention is not None and rec_maps.attention.words(0):
            files.append(_explorer_page(out, pages[0], args.force, rec_maps, 0, model=_model_name(args.weights),
                                        label="reconstruction"))
        else:
            _note(args, f"no explorer page ({_no_figure_reason(rec_maps, 0)})", kind="warning")
    report = {"motion": str(path), "prompt": inv.prompts[0], "frames": n, "input_frames": int(len(features)),
              "method": inv.method, "num_steps": inv.num_steps, "guidance_scale": inv.guidance_scale,
              "iterations": inv.iterations, "exact": inv.exact, "seconds": round(float(inv.seconds), 3),
              "errors": _errors_cm(inv.errors, pipe.skeleton), "weights": pipe.source,
              "edit": None if not specs else {"target": target, "label": label, "edits": [repr(e) for e in specs]},
              "input": {"kind": loaded.kind, "crop": args.crop}}
    if specs and "inpaint_candidates" in result.settings:    # Inpaint(candidates=K): every candidate's score
        report["edit"]["inpaint_candidates"] = result.settings["inpaint_candidates"]
        report["edit"]["edits"] = [repr(e) for e in result.edits]       # the chosen candidate's (its seed)
    for key in ("inpaint_prior", "composite"):     # what was pasted; the kept frames' source (followed turns)
        if specs and key in result.settings:
            report["edit"][key] = result.settings[key]
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
    p.add_argument("--preset", default=None, choices=("paper", "fast", "realtime"),
                   help="sampler preset instead of --solver/--steps: paper = DDIM 50 steps, fast = DPM-Solver++ 20 "
                        "steps, realtime = the few-step distilled weights (salad_core/weights/salad_realtime, or "
                        "--weights) sampled as their folder says (generate and demo only)")
    p.add_argument("--weights", default=None, help="pipeline folder (default: the shipped weights)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")


def _normalize_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--normalize", choices=["global", "each"], default="global",
                   help="colour scale of the attention figure's panels: global = one scale for all panels (default; "
                        "a dim word looks dim), each = every panel to its own maximum (shapes only; brightness does "
                        "not compare across panels)")


def _html_arg(p: argparse.ArgumentParser, files: str) -> None:
    """``--html`` of generate, edit and invert: the offline attention explorer, ``files`` says which."""
    p.add_argument("--html", action="store_true",
                   help=f"also write the attention explorer as one self-contained HTML file that opens offline in any "
                        f"current browser (no kernel, no server, no network): {files}. It plays the 3D skeleton "
                        "(play, speed, frame scrubber; drag to turn), links the 7-part x frame heatmap of the chosen "
                        "words to the bones' colours, and filters layers and denoising steps. Captures every step, "
                        "layer and head (steps are averaged in groups only if the page would pass 8 MB)")


def _resolve_sampler(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Fill ``args.solver``/``args.steps`` from ``--preset`` (exclusive with them) or the defaults.

    ``--preset realtime`` selects the distilled weights instead (``args.weights_preset``; ``--weights`` then names
    their folder): the solver and steps stay None, so the folder's ``pipeline.json`` decides them."""
    args.weights_preset = None
    if args.preset == "realtime":
        if args.solver is not None or args.steps is not None:
            parser.error("--preset realtime samples as its weights folder says; give --preset or --solver/--steps, "
                         "not both")
        if args.command not in ("generate", "demo") or getattr(args, "keymotion", None) is not None:
            parser.error("--preset realtime is for SALAD's generate and demo; editing and inversion need the "
                         "50-step weights (leave --preset out)")
        args.weights_preset = "realtime"
        return
    if args.preset is not None:
        if args.solver is not None or args.steps is not None:
            parser.error("--preset sets the solver and the steps; give --preset or --solver/--steps, not both")
        from salad_core.sampling import SAMPLER_PRESETS

        args.solver, args.steps = SAMPLER_PRESETS[args.preset]
    elif args.steps is None:
        args.steps = 50


def add_parsers(sub) -> None:
    """The sub-commands of this module: demo, generate, edit, invert."""
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
    _html_arg(g, "NN_<prompt>_explorer.html per prompt")
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
    _edit_figure_args(ed, "")
    _html_arg(ed, "source_vs_edited_explorer.html, the source and the edit side by side on one colour scale, the "
                  "edit named (e.g. Reweight(high=-1)), opening on the words the edit names")
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
    _edit_figure_args(iv, "STEM_", source="reconstruction")
    _html_arg(iv, "STEM_source_vs_edited_explorer.html with an edit flag (the reconstruction and the edit side by "
                  "side, the edit named), else STEM_reconstruction_explorer.html (one more sampling pass)")
    iv.add_argument("--weights", default=None, help="pipeline folder (default: the shipped weights)")
    iv.add_argument("--skeleton", default="humanml3d", help="skeleton of the motion: humanml3d (22 joints, "
                    "default) or kit (21)")
    iv.add_argument("--force", action="store_true", help="overwrite existing files")


COMMANDS: dict[str, Callable] = {"demo": cmd_demo, "generate": cmd_generate, "edit": cmd_edit, "invert": cmd_invert}
