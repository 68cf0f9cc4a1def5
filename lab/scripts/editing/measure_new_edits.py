#!/usr/bin/env python
"""Measure the edits beyond the paper (Erase, Shift, ExampleBased) and repetition counting on the
procedural corpus's ground-truth annotations.

Usage::

    python lab/scripts/editing/measure_new_edits.py                      # shipped weights, held-out corpus clips
    python lab/scripts/editing/measure_new_edits.py --data CORPUS --n 20 --json out.json
    python lab/scripts/editing/measure_new_edits.py --calibrate          # choose the motion counter's settings
    python lab/scripts/editing/measure_new_edits.py --quick              # 2 items, 10 steps: checks the script

Without ``--data`` it writes held-out test clips of the corpus the shipped weights were trained on
(:func:`salad_core.eval.heldout.heldout_corpus`) to a temporary folder. Every motion is *generated*
from a corpus caption at its clip's length; the caption's annotation (phrase word span, driven parts,
frame interval) says which phrase to edit, which parts it drives and where to look. Sections:

(a) erase: ``Erase(phrase span)`` on captions with two or more phrases: the drop of the phrase's parts'
    activity over its annotated frames, and how much the other parts change (root-aligned MPJPE of
    their joints, source vs edit), against deleting the phrase's words from the prompt (same noise);
(b) shift: ``Shift(phrase span, N)`` with N = +-``--shift`` frames (toward the side with room), alone
    and with ``ShiftTemporal(its parts, N)``: the lag of the phrase's parts' activity between source
    and edit (cross-correlation over the annotated interval widened by N on each side, lags up to
    2|N|); the target is ``|lag - N| <= 0.1 |N|``;
(c) example: ``ExampleBased`` variations of an inverted corpus clip (``pipe.invert``, DDIM with the
    exact replay) against plain samples of its caption with the same seeds: diversity (mean pairwise
    root-aligned MPJPE) and distance to the example;
(d) counting: captions that say how many times ("twice", "three times", "do three squats"):
    ``count_repetitions`` on the phrase's attention against the generated motion's own count
    (``motion_repetitions``) and against the caption's number; the motion counter is also checked on
    the corpus clips themselves.
"""
from __future__ import annotations

import argparse
import itertools
import sys
import tempfile
from functools import partial
from pathlib import Path

import numpy as np

from salad_core.attention.counting import MOTION_COUNT, count_repetitions, motion_repetitions
from salad_core.attention.edits import Erase, ExampleBased, Shift, ShiftTemporal
from salad_core.data.texts import split_words
from salad_core.eval.metrics import mpjpe
from salad_core.part_activity import part_speeds
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import PART_NAMES, get_skeleton

from _measure_common import annotated_clips, finish_run, mean, print_summary, run_settings, start_run  # scripts/

#: Words that say how many times an action happens.
COUNT_WORDS = {"twice": 2, "two": 2, "three": 3, "four": 4, "five": 5}
#: Prints a section's summary table (keys in 24 columns, nested figures to 3 digits).
_print = partial(print_summary, width=24, nested_digits=3)


# ------------------------------------------------------------------------------ corpus
def read_clips(root: Path, split: str, n: int | None = None) -> list[dict]:
    """Annotated clips of a split: id, features, joints, first caption and its phrases."""
    out = []
    for cid, doc, feats in annotated_clips(root, split, max_frames=196, min_frames=40, mirrors=False):
        length = len(feats)
        joints = np.load(root / "new_joints" / f"{cid}.npy").astype(np.float32)[:length]
        for cap in doc["captions"]:
            out.append({"id": cid, "features": feats, "joints": joints, "length": length,
                        "caption": cap["caption"],
                        "phrases": [dict(ph, frames=[min(ph["frames"][0], length), min(ph["frames"][1], length)])
                                    for ph in cap["phrases"]]})
        if n is not None and len({c["id"] for c in out}) >= n:
            break
    return out


def stated_count(text: str) -> int | None:
    """The number of times a phrase says its action happens, or None."""
    words = split_words(text)
    for i, w in enumerate(words):
        if w == "twice":
            return 2
        if w in COUNT_WORDS and (i + 1 < len(words)) and (words[i + 1] == "times" or i > 0):
            return COUNT_WORDS[w]
    return None


def _part_joints(parts, skeleton) -> list[int]:
    sk = get_skeleton(skeleton)
    return [j for j, p in enumerate(sk.joint_to_part) if PART_NAMES[p] in parts]


def activity(joints: np.ndarray, parts, frames) -> float:
    """Mean speed (m/s) of ``parts`` over motion frames ``[f0, f1)``."""
    s = part_speeds(joints)
    f0, f1 = int(frames[0]), min(int(frames[1]), len(s))
    return float(s[f0:max(f1, f0 + 1), [PART_NAMES.index(p) for p in parts]].mean())


def _without(caption: str, span) -> str:
    words = split_words(caption)
    rest = words[:span[0]] + words[span[1]:]
    return " ".join(rest) or "a person"


# ------------------------------------------------------------------------------ sections
def erase_items(clips, n):
    items, seen = [], set()
    for c in clips:
        if len(c["phrases"]) < 2 or c["id"] in seen:
            continue
        # the phrase that drives the fewest parts and leaves the root alone: its erasure is local
        cands = [ph for ph in c["phrases"] if "root" not in ph["parts"] and ph["frames"][1] - ph["frames"][0] >= 8]
        if not cands:
            continue
        ph = min(cands, key=lambda p: len(p["parts"]))
        others = [p for p in PART_NAMES if p not in ph["parts"]]
        items.append({**c, "phrase": ph, "others": others})
        seen.add(c["id"])
        if len(items) >= n:
            break
    return items


def measure_erase(pipe, items, args) -> dict:
    rows = []
    if not items:
        return {"summary": {}, "items": rows}
    deleted = pipe([_without(it["caption"], it["phrase"]["words"]) for it in items],
                   lengths=[it["length"] for it in items], seed=[args.seed + i for i in range(len(items))],
                   num_steps=args.steps, guidance_scale=args.guidance)
    for i, it in enumerate(items):
        ph = it["phrase"]
        for mode in args.erase_modes:
            out = pipe.edit(it["caption"], edits=[Erase(tuple(ph["words"]), mode=mode)], lengths=it["length"],
                            seed=args.seed + i, num_steps=args.steps, guidance_scale=args.guidance)
            src, ed = out.source.raw_joints[0], out.edited.raw_joints[0]
            dl = deleted.raw_joints[i]
            oj = _part_joints(it["others"], pipe.skeleton)
            a_src, a_ed, a_del = (activity(x, ph["parts"], ph["frames"]) for x in (src, ed, dl))
            rows.append({"id": it["id"], "phrase": ph["text"], "parts": ph["parts"], "mode": mode,
                         "activity_source": a_src, "activity_erased": a_ed, "activity_deleted": a_del,
                         "drop_erased": 1 - a_ed / max(a_src, 1e-9), "drop_deleted": 1 - a_del / max(a_src, 1e-9),
                         "others_mpjpe_erased": mpjpe(ed[:, oj], src[:, oj]),
                         "others_mpjpe_deleted": mpjpe(dl[:, oj], src[:, oj])})
    summary = {}
    for mode in args.erase_modes:
        sub = [r for r in rows if r["mode"] == mode]
        summary[mode] = {k: mean(r[k] for r in sub) for k in ("drop_erased", "drop_deleted", "others_mpjpe_erased",
                                                              "others_mpjpe_deleted")}
        summary[mode]["dropped_rate"] = mean(float(r["activity_erased"] < r["activity_source"]) for r in sub)
        summary[mode]["kept_better_rate"] = mean(float(r["others_mpjpe_erased"] < r["others_mpjpe_deleted"])
                                                  for r in sub)
    return {"summary": summary, "items": rows}


def shift_items(clips, n, shift):
    items, seen = [], set()
    for c in clips:
        if c["id"] in seen:
            continue
        for ph in c["phrases"]:
            f0, f1 = ph["frames"]
            if f1 - f0 < 12 or f1 - f0 > c["length"] - 2 * shift:
                continue
            room_after, room_before = c["length"] - f1, f0
            n_frames = shift if room_after >= room_before else -shift
            if max(room_after, room_before) < shift:
                continue
            items.append({**c, "phrase": ph, "shift": n_frames})
            seen.add(c["id"])
            break
        if len(items) >= n:
            break
    return items


def activity_lag(a: np.ndarray, b: np.ndarray, frames, max_lag: int) -> int:
    """The lag ``L`` (frames) that best aligns ``b[f + L]`` with ``a[f]`` over ``frames``
    (Pearson correlation of the activity profiles; ties to the smaller |L|)."""
    f0, f1 = int(frames[0]), int(frames[1])
    best, best_corr = 0, -np.inf
    for lag in sorted(range(-max_lag, max_lag + 1), key=abs):
        lo, hi = max(f0, -lag, 0), min(f1, len(a), len(b) - lag)
        if hi - lo < 6:
            continue
        x, y = a[lo:hi], b[lo + lag:hi + lag]
        if x.std() < 1e-9 or y.std() < 1e-9:
            continue
        corr = float(np.corrcoef(x, y)[0, 1])
        if corr > best_corr + 1e-9:
            best, best_corr = lag, corr
    return best


def shift_edits(variant: str, phrase: dict, n: int) -> list:
    """The edits of a shift variant: ``cross`` (the phrase's columns), ``temporal`` (its parts'
    temporal self-attention), ``cross+temporal`` (both)."""
    edits = []
    if "cross" in variant:
        edits.append(Shift(tuple(phrase["words"]), n))
    if "temporal" in variant:
        edits.append(ShiftTemporal(tuple(phrase["parts"]), n))
    return edits


def measure_shift(pipe, items, args) -> dict:
    rows = []
    for i, it in enumerate(items):
        ph, n = it["phrase"], it["shift"]
        idx = [PART_NAMES.index(p) for p in ph["parts"]]
        f0, f1 = ph["frames"]
        for variant in args.shift_variants:
            out = pipe.edit(it["caption"], edits=shift_edits(variant, ph, n), lengths=it["length"],
                            seed=args.seed + i, num_steps=args.steps, guidance_scale=args.guidance)
            a = part_speeds(out.source.raw_joints[0])[:, idx].mean(1)
            b = part_speeds(out.edited.raw_joints[0])[:, idx].mean(1)
            window = (max(f0 - abs(n), 0), min(f1 + abs(n), len(a)))
            lag = activity_lag(a, b, window, 2 * abs(n))
            rows.append({"id": it["id"], "phrase": ph["text"], "parts": ph["parts"], "frames": [f0, f1], "shift": n,
                         "variant": variant, "lag": lag, "error": abs(lag - n), "met": abs(lag - n) <= 0.1 * abs(n),
                         "sign_right": bool(np.sign(lag) == np.sign(n))})
    summary = {}
    for variant in args.shift_variants:
        sub = [r for r in rows if r["variant"] == variant]
        summary[variant] = {"lag_along_shift": mean(r["lag"] * np.sign(r["shift"]) for r in sub),
                            "mean_abs_error": mean(r["error"] for r in sub),
                            "met_rate": mean(float(r["met"]) for r in sub),
                            "right_direction_rate": mean(float(r["sign_right"]) for r in sub),
                            "zero_lag_rate": mean(float(r["lag"] == 0) for r in sub)}
    return {"summary": summary, "items": rows}


def _pairwise(motions) -> float:
    return mean(mpjpe(a, b) for a, b in itertools.combinations(motions, 2))


def example_settings(args) -> list[tuple[float, tuple[str, ...]]]:
    """(window end, kinds) of every ExampleBased setting measured."""
    return [(float(w), tuple(k.split("+"))) for w in args.example_window for k in args.example_kinds]


def measure_example(pipe, clips, args) -> dict:
    rows, seen = [], set()
    settings = example_settings(args)
    for c in clips:
        if c["id"] in seen:
            continue
        seen.add(c["id"])
        k = args.variations
        inv = pipe.invert([c["features"]] * k, [c["caption"]] * k, method="ddim", num_steps=args.steps,
                          guidance_scale=args.guidance, reconstruct=False)
        plain = pipe([c["caption"]] * k, lengths=c["length"], seed=args.seed + 100, num_steps=args.steps,
                     guidance_scale=args.guidance)
        for window, kinds in settings:
            var = pipe.edit(inversion=inv, edits=[ExampleBased(seed=args.seed + 100, steps=(0.0, window),
                                                               kinds=kinds)])
            example = var.source.raw_joints[0]
            v, p = var.edited.raw_joints, plain.raw_joints
            rows.append({"id": c["id"], "caption": c["caption"], "setting": f"{'+'.join(kinds)} (0, {window:g})",
                         "diversity_variations": _pairwise(v), "diversity_plain": _pairwise(p),
                         "to_example_variations": mean(mpjpe(x, example) for x in v),
                         "to_example_plain": mean(mpjpe(x, example) for x in p),
                         "example_vs_corpus": mpjpe(example, c["joints"][:len(example)])})
        if len(seen) >= args.n_example:
            break
    keys = ("diversity_variations", "diversity_plain", "to_example_variations", "to_example_plain",
            "example_vs_corpus")
    summary = {}
    for setting in dict.fromkeys(r["setting"] for r in rows):
        sub = [r for r in rows if r["setting"] == setting]
        summary[setting] = {key: mean(r[key] for r in sub) for key in keys}
        summary[setting]["closer_than_plain_rate"] = mean(float(r["to_example_variations"] < r["to_example_plain"])
                                                           for r in sub)
    return {"summary": summary, "items": rows}


def count_items(clips, n):
    items, seen = [], set()
    for c in clips:
        for ph in c["phrases"]:
            reps = stated_count(ph["text"])
            if reps is None or (c["id"], ph["text"]) in seen:
                continue
            items.append({**c, "phrase": ph, "reps": reps})
            seen.add((c["id"], ph["text"]))
            break
        if len(items) >= n:
            break
    return items


def measure_counting(pipe, items, args) -> dict:
    rows = []
    for start in range(0, len(items), args.batch):
        chunk = items[start:start + args.batch]
        out = pipe([it["caption"] for it in chunk], lengths=[it["length"] for it in chunk],
                   seed=[args.seed + start + i for i in range(len(chunk))], num_steps=args.steps,
                   guidance_scale=args.guidance, capture_attention=True)
        for i, it in enumerate(chunk):
            ph = it["phrase"]
            frames = tuple(ph["frames"])
            att = count_repetitions(out.attention, tuple(ph["words"]), i, parts=ph["parts"], frames=frames)
            att_all = count_repetitions(out.attention, tuple(ph["words"]), i, parts=ph["parts"])
            mot = motion_repetitions(out.raw_joints[i], ph["parts"], frames)
            corpus = motion_repetitions(it["joints"], ph["parts"], frames)
            rows.append({"id": it["id"], "phrase": ph["text"], "parts": ph["parts"], "truth": it["reps"],
                         "attention": att, "attention_whole_clip": att_all, "motion": mot, "corpus_motion": corpus})
    summary = {"attention_vs_truth": mean(float(r["attention"] == r["truth"]) for r in rows),
               "attention_vs_motion": mean(float(r["attention"] == r["motion"]) for r in rows),
               "motion_vs_truth": mean(float(r["motion"] == r["truth"]) for r in rows),
               "corpus_motion_vs_truth": mean(float(r["corpus_motion"] == r["truth"]) for r in rows),
               "attention_whole_clip_vs_truth": mean(float(r["attention_whole_clip"] == r["truth"]) for r in rows),
               "mean_truth": mean(r["truth"] for r in rows), "mean_attention": mean(r["attention"] for r in rows),
               "mean_motion": mean(r["motion"] for r in rows),
               "always_two_baseline": mean(float(r["truth"] == 2) for r in rows)}
    return {"summary": summary, "items": rows}


def calibrate_motion_counter(root: Path, split: str) -> dict:
    """Accuracy of ``motion_repetitions`` against the stated counts on corpus clips, per setting."""
    clips = read_clips(root, split)
    items = [(c, ph, stated_count(ph["text"])) for c in clips for ph in c["phrases"] if stated_count(ph["text"])]
    items = list({(c["id"], ph["text"]): (c, ph, r) for c, ph, r in items}.values())
    table = {}
    for prom, smooth in itertools.product((0.2, 0.3, 0.4, 0.5, 0.6, 0.7), (0.0, 1.0, 2.0)):
        hits = [motion_repetitions(c["joints"], ph["parts"], tuple(ph["frames"]), prominence=prom, smooth=smooth) == r
                for c, ph, r in items]
        table[f"prominence={prom} smooth={smooth}"] = float(np.mean(hits))
    return {"phrases": len(items), "accuracy": table}


# ------------------------------------------------------------------------------ main
def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="procedural corpus folder (default: held-out clips)")
    ap.add_argument("--weights", type=Path, default=None, help="pipeline folder (default: the shipped weights)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--clips", type=int, default=300, help="held-out motions written when --data is not given")
    ap.add_argument("--n", type=int, default=20, help="prompts per section (a), (b), (d)")
    ap.add_argument("--n-example", type=int, default=3, help="examples for (c)")
    ap.add_argument("--variations", type=int, default=3, help="variations (and plain samples) per example")
    ap.add_argument("--example-window", type=float, nargs="+", default=[0.5, 1.0],
                    help="(c): ends of the step windows (from 0) with the example's maps")
    ap.add_argument("--example-kinds", nargs="+", default=["temporal", "temporal+skeletal"],
                    choices=["temporal", "skeletal", "temporal+skeletal"], help="(c): which self-attention to use")
    ap.add_argument("--shift", type=int, default=20, help="(b): shift in motion frames (a multiple of 4)")
    ap.add_argument("--erase-modes", nargs="+", default=["special", "others"])
    ap.add_argument("--shift-variants", nargs="+", default=["cross", "cross+temporal"],
                    choices=["cross", "temporal", "cross+temporal"])
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--guidance", type=float, default=None,
                    help="CFG weight (default: the weights' own, pipeline.json; the paper's is 7.5)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch", type=int, default=8, help="(d): prompts per generation")
    ap.add_argument("--sections", default="abcd")
    ap.add_argument("--calibrate", action="store_true", help="only: the motion counter's accuracy per setting "
                    "on the --split clips (use a training split)")
    ap.add_argument("--quick", action="store_true", help="tiny run (2 items, 10 steps) to check the script")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)
    if set(args.sections) - set("abcd"):
        ap.error(f"--sections {args.sections!r}: use letters from 'abcd'")
    if args.quick:
        args.n, args.n_example, args.variations, args.steps, args.clips = 2, 1, 2, 10, 40
        args.erase_modes = args.erase_modes[:1]
        args.shift_variants = args.shift_variants[-1:]
        args.example_window, args.example_kinds = args.example_window[:1], args.example_kinds[:1]
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    start = start_run(args.threads)
    tmp = None
    root = args.data
    if root is None:
        from salad_core.eval.heldout import heldout_corpus

        tmp = tempfile.TemporaryDirectory(prefix="salad_new_edits_")
        root = heldout_corpus(Path(tmp.name) / "heldout", motions=args.clips, split=args.split)
    if args.calibrate:
        res = calibrate_motion_counter(root, args.split)
        best = max(res["accuracy"], key=res["accuracy"].get)
        print(f"motion counter on {res['phrases']} stated-count phrases of {root} ({args.split}); "
              f"current {MOTION_COUNT}")
        for key, acc in res["accuracy"].items():
            print(f"  {key:28s} {acc:.3f}" + ("   <- best" if key == best else ""))
        return res
    pipe = SaladPipeline.from_pretrained(args.weights)
    if args.guidance is None:                  # the weights' own default (pipeline.json), recorded as a number
        args.guidance = float(pipe.guidance.scale)
    clips = read_clips(root, args.split)
    results: dict = {"settings": run_settings(args)}
    print(f"weights: {pipe.source}; corpus {root} ({args.split}): {len({c['id'] for c in clips})} clips; "
          f"{args.steps} steps, w = {args.guidance}")
    if "a" in args.sections:
        results["erase"] = measure_erase(pipe, erase_items(clips, args.n), args)
        _print(f"(a) erase a phrase ({len(results['erase']['items']) // len(args.erase_modes)} prompts): "
               "activity drop of its parts, other parts' MPJPE (m) vs deleting its words", results["erase"]["summary"])
    if "b" in args.sections:
        results["shift"] = measure_shift(pipe, shift_items(clips, args.n, args.shift), args)
        prompts = len(results["shift"]["items"]) // len(args.shift_variants)
        _print(f"(b) shift a phrase by +-{args.shift} frames ({prompts} prompts): lag of its "
               "parts' activity (frames)", results["shift"]["summary"])
    if "c" in args.sections:
        results["example"] = measure_example(pipe, clips, args)
        examples = len({r["id"] for r in results["example"]["items"]})
        _print(f"(c) example-based ({examples} examples x {args.variations}): root-aligned "
               "MPJPE (m)", results["example"]["summary"])
    if "d" in args.sections:
        results["counting"] = measure_counting(pipe, count_items(clips, args.n), args)
        _print(f"(d) counting ({len(results['counting']['items'])} phrases): accuracy", results["counting"]["summary"])
    finish_run(results, start, args.json)
    if tmp is not None:
        tmp.cleanup()
    return results


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
