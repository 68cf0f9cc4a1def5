#!/usr/bin/env python
"""Measure what attention and editing do, on the procedural corpus's ground truth.

Usage::

    python lab/scripts/editing/measure_editing.py --data CORPUS                # shipped weights, full run
    python lab/scripts/editing/measure_editing.py --data CORPUS --weights DIR --quick --json out.json
    python lab/scripts/editing/measure_editing.py --data CORPUS --deepmimic    # also the DeepMimic clips

``CORPUS`` is a folder written by ``salad_core.data.procedural.build_corpus`` (HumanML3D layout
with ``annotations/``). Prints, with the numbers also returned / written as JSON:

(a) localisation: each test motion is inverted under its first caption and regenerated with the
    cross-attention recorded; for every annotated action phrase, the share of its words'
    attention on its annotated body parts and frames, against chance (a uniform map); with
    ``--student DIR`` (a few-step student, e.g. the real-time weights) the same for the student's
    generation from the teacher's inverted noise, whose first consistency step lands on the
    teacher's ODE solution (``student_lift_ratio``: its lift over the teacher's);
(b) mirroring: ``Mirror("all")`` on prompts that name a side; the left/right activity ratio of
    the arms and legs before and after (it should flip), and how close the edit is to the mirror
    image of the source (``--mirror-self-attention temporal skeletal``: with ``MirrorSelfAttention``);
(c) word swap: one action word swapped (``WordSwap(tau)`` + self-attention injection); the root
    path and timing kept (compared with plain generation of the target from the same noise) while
    the swapped action's parts change;
(d) re-weighting "high": wrist height for scales s, and its rank correlation with s;
(e) inversion: reconstruction MPJPE (no edit) of each inversion method, its cost, and whether a
    mirror edit still acts on the inverted motion; with ``--deepmimic`` the same on real capture.
"""
from __future__ import annotations

import argparse
import math
import sys
from functools import partial
from pathlib import Path

import numpy as np

from salad_core.attention import CaptureConfig, InjectSelfAttention, Mirror, Reweight, WordSwap
from salad_core.attention.measure import (left_right_ratio, localisation, mirror_closeness, part_activity_change,
                                          root_path_difference, spearman, wrist_height)
from salad_core.data.procedural import PRIMITIVES, Action, in_language, parse_prompt, primitive_parts
from salad_core.data.texts import parse_text_line, split_words
from salad_core.eval.metrics import mpjpe
from salad_core.motion import bone_lengths, features_to_joints
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import get_skeleton

from _measure_common import (annotated_clips, deepmimic_items, finish_run, mean, mirror_edits, print_summary, run_settings,
                             start_run)  # scripts/

#: Word swaps that keep the number of words (source word -> target word).
SWAPS = {"waves": "raises", "waving": "raising", "raises": "waves", "raising": "waving", "walks": "runs",
         "walking": "running", "punches": "waves", "kicks": "punches", "claps": "waves", "nods": "bows",
         "jogs": "walks", "jogging": "walking", "runs": "walks", "running": "walking"}
HIGH_PROMPTS = ("a man is walking while raising his left hand up high", "a man raises his right hand up high")
#: Prints a section's summary table (keys in 18 columns, nested figures to 4 digits).
_print_table = partial(print_summary, width=18, nested_digits=4)


# ------------------------------------------------------------------------------ corpus
def read_corpus(root: Path, split: str, n: int, max_len: int) -> list[dict]:
    """The first ``n`` clips of a split that have annotations: features, captions, phrases."""
    out = []
    for cid, doc, feats in annotated_clips(root, split, max_frames=max_len, min_frames=16):
        captions = [parse_text_line(line).caption for line in (root / "texts" / f"{cid}.txt").read_text().splitlines()
                    if line.strip()]
        out.append({"id": cid, "features": feats, "captions": captions, "annotation": doc})
        if len(out) >= n:
            break
    return out


def _phrase_parts(prompt: str, word: int) -> tuple[str, ...]:
    for p in parse_prompt(prompt) or ():
        if p.words[0] <= word < p.words[1]:
            spec = PRIMITIVES[p.kind]
            side = p.side if p.side in spec.sides else spec.sides[0]
            reps = p.reps if p.reps in spec.reps else spec.reps[0]
            mods = tuple(m for m in p.mods if m in spec.mods)   # a swapped-in verb may not take the source's
            return primitive_parts(Action(p.kind, side, mods, reps, p.variant))[0]    # modifier ("runs slowly")
    return ()


def _all_captions(root: Path, split: str) -> list[str]:
    out = []
    for cid in (root / f"{split}.txt").read_text().split():
        path = root / "texts" / f"{cid}.txt"
        if path.is_file():
            out += [parse_text_line(line).caption for line in path.read_text().splitlines() if line.strip()]
    return out


# ------------------------------------------------------------------------------ sections
def measure_localisation(pipe, clips, args, student=None) -> dict:
    """Section (a) for ``pipe``, and for ``student`` (a pipeline over the same VAE latents) when given: each row
    has ``share``/``lift``/``mpjpe`` and, with a student, ``student_share``/``student_lift``/``student_mpjpe``."""
    rows = []
    for clip in clips:
        cap = clip["annotation"]["captions"][0]
        inv = pipe.invert(clip["features"], cap["caption"], method=args.method, num_steps=args.steps,
                          iterations=args.iterations, guidance_scale=args.guidance, reconstruct=False)
        rec = pipe.reconstruct(inv, capture_attention=CaptureConfig())
        maps = rec.attention
        n = len(clip["features"])
        true = features_to_joints(clip["features"], pipe.skeleton)
        err = mpjpe(rec.joints[0], true)
        if student is not None:
            srec = student(cap["caption"], lengths=list(inv.lengths), noise=inv.noise, capture_attention=CaptureConfig())
            s_maps, s_err = srec.attention, mpjpe(srec.joints[0], true)
        for ph in cap["phrases"]:
            if ph["frames"][0] >= n:
                continue
            frames = (ph["frames"][0], min(ph["frames"][1], n))
            loc = localisation(maps.word_map(0, tuple(ph["words"])), ph["parts"], frames, pipe.skeleton.unit_length)
            row = {"id": clip["id"], "phrase": ph["text"], "parts": ph["parts"], "mpjpe": err, **loc}
            if student is not None:
                s_loc = localisation(s_maps.word_map(0, tuple(ph["words"])), ph["parts"], frames,
                                     pipe.skeleton.unit_length)
                row.update(student_share=s_loc["share"], student_lift=s_loc["lift"], student_mpjpe=s_err)
            rows.append(row)
    keys = ("share", "chance", "lift", "part_share", "part_chance", "frame_share", "frame_chance", "mpjpe")
    if student is not None:
        keys += ("student_share", "student_lift", "student_mpjpe")
    summary = {k: mean(r[k] for r in rows) for k in keys}
    summary["above_chance"] = mean(float(r["share"] > r["chance"]) for r in rows)
    if student is not None:
        summary["student_lift_ratio"] = summary["student_lift"] / summary["lift"]
    return {"summary": summary, "phrases": rows}


def measure_mirroring(pipe, prompts, args) -> dict:
    rows = []
    for i, prompt in enumerate(prompts):
        edits = mirror_edits("all", args.mirror_self_attention, args.mirror_window)
        out = pipe.edit(prompt, edits=edits, lengths=args.length, num_steps=args.steps,
                        guidance_scale=args.guidance, seed=args.seed + i)
        before, after = left_right_ratio(out.source.joints[0]), left_right_ratio(out.edited.joints[0])
        close = mirror_closeness(out.source.joints[0], out.edited.joints[0], "all")
        side = "left" if "left" in split_words(prompt) else "right"
        limb = "legs" if any(w in split_words(prompt) for w in ("leg", "foot", "knee", "kicks", "kick")) else "arms"
        flipped = np.sign(math.log(before[limb])) != np.sign(math.log(after[limb]))
        rows.append({"prompt": prompt, "side": side, "limb": limb, "ratio_before": before[limb],
                     "ratio_after": after[limb], "flipped": bool(flipped), **close})
    return {"summary": {"flip_rate": mean(float(r["flipped"]) for r in rows),
                        "log_ratio_before": mean(math.log(r["ratio_before"]) for r in rows),
                        "log_ratio_after": mean(math.log(r["ratio_after"]) for r in rows),
                        "closeness_ratio": mean(r["ratio"] for r in rows)},
            "prompts": rows}


def swap_pairs(captions, n) -> list[tuple[str, str, int]]:
    pairs, seen = [], set()
    for cap in captions:
        words = split_words(cap)
        for k, w in enumerate(words):
            if w in SWAPS:
                target = " ".join(words[:k] + [SWAPS[w]] + words[k + 1:])
                source = " ".join(words)
                if source not in seen and in_language(target) and _phrase_parts(target, k):
                    pairs.append((source, target, k))
                    seen.add(source)
                break
        if len(pairs) >= n:
            break
    return pairs


def measure_word_swap(pipe, pairs, args) -> dict:
    rows = []
    for i, (source, target, k) in enumerate(pairs):
        edits = [WordSwap(args.tau), InjectSelfAttention((0.0, args.self_attention))]
        out = pipe.edit(source, target, edits=edits, lengths=args.length, num_steps=args.steps,
                        guidance_scale=args.guidance, seed=args.seed + i)
        plain = pipe(target, lengths=args.length, num_steps=args.steps, guidance_scale=args.guidance,
                     noise=out.noise)
        src, ed = out.source.joints[0], out.edited.joints[0]
        parts = _phrase_parts(target, k)
        kept, free = root_path_difference(src, ed), root_path_difference(src, plain.joints[0])
        rows.append({"source": source, "target": target, "parts": list(parts),
                     "path_rmse_swap": kept["path_rmse"], "path_rmse_plain": free["path_rmse"],
                     "speed_corr_swap": kept["speed_corr"], "speed_corr_plain": free["speed_corr"],
                     "action_change": part_activity_change(src, ed, parts),
                     "other_change": part_activity_change(src, ed, [p for p in ("root", "spine", "head")
                                                                    if p not in parts] or ["root"])})
    keys = ("path_rmse_swap", "path_rmse_plain", "speed_corr_swap", "speed_corr_plain", "action_change", "other_change")
    summary = {k: mean(r[k] for r in rows) for k in keys}
    # a swap of the locomotion itself (walks -> runs) changes the path by design; the path can only be
    # expected to stay where the swapped action leaves the root alone
    for group, keep in (("root_kept", lambda r: "root" not in r["parts"]), ("locomotion", lambda r: "root" in r["parts"])):
        sel = [r for r in rows if keep(r)]
        summary[f"{group}_pairs"] = float(len(sel))
        for k in ("path_rmse_swap", "path_rmse_plain", "speed_corr_swap", "speed_corr_plain"):
            summary[f"{group}_{k}"] = mean(r[k] for r in sel)
        summary[f"{group}_path_closer"] = mean(float(r["path_rmse_swap"] < r["path_rmse_plain"]) for r in sel)
    return {"summary": summary, "pairs": rows}


#: Issue 20's target: Reweight("high", s) for s in [-2, 3] moves the wrist without the upper arm's length
#: straying by more than this (cm, 95th percentile of frames, raw position joints).
UPPER_ARM_LIMIT_CM = 3.0


def upper_arm_error_cm(joints: np.ndarray, side: str) -> float:
    """95th percentile over frames of |upper arm length - the skeleton's| (cm) of the ``side`` arm
    ("both": the worse arm); ``joints`` (T, 22, 3) raw positions (features read as they are)."""
    sk = get_skeleton("humanml3d")
    names = {"left": ("left_elbow",), "right": ("right_elbow",), "both": ("left_elbow", "right_elbow")}[side]
    ids = [sk.joint_names.index(n) for n in names]
    length = bone_lengths(np.asarray(joints, np.float64), sk)[:, ids]         # (T, arms): shoulder -> elbow
    err = np.abs(length - np.asarray([sk.bone_lengths[i] for i in ids])) * 100
    return float(np.percentile(err.max(axis=1), 95))


def measure_reweight(pipe, prompts, scales, args) -> dict:
    """Wrist height against s, on the pipeline's ``out.joints`` (with recovery "fit" the bones are fixed,
    so the raw position joints are measured too: the wrist's height there and the upper arm's length
    error, which the fit would hide)."""
    rows = []
    for i, prompt in enumerate(prompts):
        side = "left" if "left" in split_words(prompt) else ("right" if "right" in split_words(prompt) else "both")
        heights, raw_heights, upper = [], [], []
        for s in scales:
            out = pipe.edit(prompt, edits=[Reweight("high", s)], lengths=args.length, num_steps=args.steps,
                            guidance_scale=args.guidance, seed=args.seed + i)
            heights.append(wrist_height(out.edited.joints[0], side))
            n = out.edited.lengths[0]
            raw = features_to_joints(np.asarray(out.edited.features[0][:n], np.float64))
            raw_heights.append(wrist_height(raw, side))
            upper.append(upper_arm_error_cm(raw, side))
        rows.append({"prompt": prompt, "scales": list(scales), "wrist_height": heights,
                     "spearman": spearman(scales, heights),
                     "monotonic": bool(np.all(np.diff(heights) > 0)),
                     "wrist_height_raw": raw_heights, "spearman_raw": spearman(scales, raw_heights),
                     "upper_arm_error_cm": upper, "upper_arm_within_limit": bool(max(upper) <= UPPER_ARM_LIMIT_CM)})
    return {"summary": {"spearman": mean(r["spearman"] for r in rows),
                        "monotonic_rate": mean(float(r["monotonic"]) for r in rows),
                        "spearman_raw": mean(r["spearman_raw"] for r in rows),
                        "upper_arm_error_cm_max": max(max(r["upper_arm_error_cm"]) for r in rows),
                        "upper_arm_error_cm_mean": mean(float(np.mean(r["upper_arm_error_cm"])) for r in rows),
                        "upper_arm_within_limit_rate": mean(float(r["upper_arm_within_limit"]) for r in rows)},
            "prompts": rows}


def _inversion_rows(pipe, items, methods, args) -> list[dict]:
    """Invert and mirror each item with each (method, exact) pair. Null-text inversion optimises against a plain
    guidance weight, so with a rescaled or interval guidance it is left out (said once) rather than failing."""
    guidance = pipe.resolve_guidance(args.guidance)
    if any(m == "null_text" for m, _ in methods) and (guidance.rescale or guidance.interval is not None):
        print(f"  null-text inversion left out: it takes a plain guidance weight, the weights' is {guidance}")
        methods = [(m, e) for m, e in methods if m != "null_text"]
    rows = []
    for item in items:
        for method, exact in methods:
            inv = pipe.invert(item["features"], item["prompt"], method=method, exact=exact, num_steps=args.steps,
                              iterations=None if method == "ddim" else args.iterations_for(method),
                              guidance_scale=args.guidance)
            edit = pipe.edit(inversion=inv, edits=[Mirror("all")])
            before, after = left_right_ratio(edit.source.joints[0]), left_right_ratio(edit.edited.joints[0])
            change = float(np.abs(np.log(after["arms"]) - np.log(before["arms"])) +
                           np.abs(np.log(after["legs"]) - np.log(before["legs"])))
            rows.append({"id": item["id"], "method": method + ("+exact" if exact else ""), **inv.errors,
                         "seconds": inv.seconds, "forward_rows": inv.forward_rows,
                         "max_step_residual": float(np.nanmax(inv.residuals)) if np.isfinite(inv.residuals).any()
                         else float("nan"),
                         "mirror_lr_change": change,
                         "mirror_closeness": mirror_closeness(edit.source.joints[0], edit.edited.joints[0])["ratio"]})
    return rows


def _summarise_methods(rows) -> dict:
    out = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        sub = [r for r in rows if r["method"] == m]
        out[m] = {k: mean(r[k] for r in sub) for k in ("mpjpe", "mpjpe_global", "inversion_mpjpe",
                                                          "inversion_mpjpe_global", "vae_mpjpe", "vae_mpjpe_global",
                                                          "seconds", "forward_rows", "max_step_residual",
                                                          "mirror_lr_change", "mirror_closeness")}
    return out


def measure_inversion(pipe, clips, args) -> dict:
    items = [{"id": c["id"], "features": c["features"], "prompt": c["captions"][0]} for c in clips]
    rows = _inversion_rows(pipe, items, args.methods, args)
    return {"summary": _summarise_methods(rows), "motions": rows}


def measure_deepmimic(pipe, args) -> dict:
    from salad_core.data import deepmimic

    if not deepmimic.pybullet_available():
        return {"skipped": "pybullet (extra 'deepmimic') is not installed"}
    items = deepmimic_items(pipe.skeleton, args.n_deepmimic)
    # the plain method and the exact replay that invert() uses by default
    rows = _inversion_rows(pipe, items, [(args.default_method, False), (args.default_method, True)], args)
    return {"summary": _summarise_methods(rows), "clips": rows}


# ------------------------------------------------------------------------------ main
def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, type=Path, help="procedural corpus folder (build_corpus)")
    ap.add_argument("--weights", type=Path, default=None, help="pipeline folder (default: the shipped weights)")
    ap.add_argument("--student", type=Path, default=None,
                    help="(a): also a few-step student's pipeline folder (e.g. the real-time weights), from the "
                         "teacher's inverted noise, with its own sampler")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n", type=int, default=12, help="motions / prompts per section")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--guidance", type=float, default=None,
                    help="CFG weight (default: the weights' own, pipeline.json; the paper's is 7.5)")
    ap.add_argument("--length", type=int, default=120, help="frames of generated motions")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tau", type=float, default=0.8, help="word swap: source maps while t >= tau T")
    ap.add_argument("--self-attention", type=float, default=0.2, help="word swap: self-attention injection window")
    ap.add_argument("--scales", type=float, nargs="+", default=[-2.0, -1.0, 0.0, 1.0, 2.0, 3.0])
    ap.add_argument("--method", default="fixed_point", help="inversion for (a) localisation")
    ap.add_argument("--iterations", type=int, default=None, help="inversion iterations (default per method)")
    ap.add_argument("--n-inversion", type=int, default=4, help="motions for the inversion comparison")
    ap.add_argument("--deepmimic", action="store_true", help="also invert and edit the DeepMimic clips")
    ap.add_argument("--n-deepmimic", type=int, default=20)
    ap.add_argument("--mirror-self-attention", nargs="*", default=[], choices=["temporal", "skeletal"],
                    help="(b): also mirror the source's self-attention of these kinds (MirrorSelfAttention)")
    ap.add_argument("--mirror-window", type=float, nargs=2, default=(0.0, 1.0), metavar=("START", "STOP"),
                    help="(b): step fractions of the self-attention mirroring (default 0 1)")
    ap.add_argument("--sections", default="abcde", help="which of the sections (a)-(e) to run, e.g. 'c' or 'ae'")
    ap.add_argument("--quick", action="store_true", help="tiny run (2 items, 10 steps) to check the script")
    ap.add_argument("--json", type=Path, default=None, help="write all numbers here")
    ap.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's choice)")
    args = ap.parse_args(argv)
    if not args.sections or set(args.sections) - set("abcde"):
        ap.error(f"--sections {args.sections!r}: use letters from 'abcde'")
    if args.quick:
        args.n, args.steps, args.n_inversion, args.n_deepmimic = 2, 10, 1, 2
        args.length = min(args.length, 40)
        args.scales = [-1.0, 1.0, 3.0]
        args.iterations = args.iterations or 2
    args.default_method = args.method
    args.methods = [("ddim", False), ("fixed_point", False), ("null_text", False), ("fixed_point", True)]
    defaults = {"ddim": 0, "fixed_point": 5, "null_text": 10}
    args.iterations_for = lambda m: args.iterations if args.iterations is not None else defaults[m]
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    start = start_run(args.threads)
    pipe = SaladPipeline.from_pretrained(args.weights)
    if args.guidance is None:                  # the weights' own default (pipeline.json), recorded as a number
        args.guidance = float(pipe.guidance.scale)
    max_len = pipe.skeleton.max_length
    clips = read_corpus(args.data, args.split, args.n, max_len)
    captions = _all_captions(args.data, args.split)
    sided = [c for c in captions if {"left", "right"} & set(split_words(c))][: args.n]
    pairs = swap_pairs(captions, args.n)
    high = list(dict.fromkeys([c for c in captions if "high" in split_words(c)][: max(args.n - 2, 1)]
                              + list(HIGH_PROMPTS)))[: args.n]
    print(f"weights: {pipe.source or args.weights}; corpus {args.data} ({args.split}): {len(clips)} clips, "
          f"{len(sided)} sided prompts, {len(pairs)} swap pairs, {len(high)} 'high' prompts; {args.steps} steps, "
          f"w = {args.guidance}")
    results: dict = {"settings": run_settings(args, skip=("iterations_for",))}
    if "a" in args.sections:
        student = None
        if args.student is not None:
            student = SaladPipeline.from_pretrained(args.student, text_encoder=pipe.text_encoder)
            if student.denoiser.config.latent_dim != pipe.denoiser.config.latent_dim:
                raise SystemExit(f"--student {args.student}: its latents ({student.denoiser.config.latent_dim}-d) "
                                 f"are not the teacher's ({pipe.denoiser.config.latent_dim}-d)")
        results["localisation"] = measure_localisation(pipe, clips, args, student)
        _print_table("(a) localisation: attention share on the annotated parts x frames (vs chance)",
                     results["localisation"]["summary"])
    if "b" in args.sections:
        results["mirroring"] = measure_mirroring(pipe, sided, args)
        _print_table("(b) mirroring: left/right activity ratio of the named limb", results["mirroring"]["summary"])
    if "c" in args.sections:
        results["word_swap"] = measure_word_swap(pipe, pairs, args)
        _print_table("(c) word swap: root path kept (vs plain target generation), action changed",
                     results["word_swap"]["summary"])
    if "d" in args.sections:
        results["reweight"] = measure_reweight(pipe, high, args.scales, args)
        _print_table(f"(d) re-weighting 'high' with s in {args.scales}: wrist height", results["reweight"]["summary"])
        for row in results["reweight"]["prompts"]:
            print(f"     {row['prompt']!r}: " + ", ".join(f"{h:.3f}" for h in row["wrist_height"])
                  + "  raw " + ", ".join(f"{h:.3f}" for h in row["wrist_height_raw"])
                  + "  upper arm (cm) " + ", ".join(f"{e:.1f}" for e in row["upper_arm_error_cm"]))
    if "e" in args.sections:
        results["inversion"] = measure_inversion(pipe, clips[: args.n_inversion], args)
        _print_table("(e) inversion of corpus motions (no edit; metres)", results["inversion"]["summary"])
    if args.deepmimic:
        results["deepmimic"] = measure_deepmimic(pipe, args)
        if "skipped" in results["deepmimic"]:
            print(f"\n== DeepMimic: skipped ({results['deepmimic']['skipped']})")
        else:
            _print_table(f"DeepMimic clips, {args.default_method} inversion, plain and exact (real capture)",
                         results["deepmimic"]["summary"])
            for row in results["deepmimic"]["clips"]:
                print(f"     {row['id']:22s} {row['method']:18s} mpjpe={row['mpjpe']:.3f} "
                      f"inversion={row['inversion_mpjpe']:.3f} "
                      f"vae={row['vae_mpjpe']:.3f} mirror_closeness={row['mirror_closeness']:.2f}")
    return finish_run(results, start, args.json)


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
