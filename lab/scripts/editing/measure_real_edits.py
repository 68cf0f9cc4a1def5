"""Mirror edits of real motion capture: how often the active side swaps, and what the edit keeps (issue 21).

Usage:
    python lab/scripts/editing/measure_real_edits.py [--weights DIR] [--steps 50] [--json OUT.json]

The real clips are pybullet's DeepMimic takes (``salad_core.data.deepmimic``; needs the ``deepmimic``
extra) and their mirrored copies (``mirror_features``: a kick with the right leg becomes one with the
left). They are evaluation data: this script measures, nothing is trained or tuned on them.

For every clip whose arms or legs are one-sided in the capture itself (left/right activity ratio of
that limb pair beyond ``--sided`` either way), the clip is inverted with its prompt
(:meth:`SaladPipeline.invert`, its defaults: fixed point with the exact replay) and edited with
``Mirror`` of that limb pair (with ``--self-attention``, also ``MirrorSelfAttention`` of it):

- ``swapped``: the limb pair's log left/right activity ratio changes sign between the source
  reconstruction and the edit (the other side now leads);
- ``log_ratio_before`` / ``log_ratio_after``: that log ratio in both;
- ``kept_cm``: root-aligned MPJPE between source and edit over the joints outside the mirrored limbs
  (spine, head and the other limb pair): how much of the take the edit leaves alone;
- ``closeness``: :func:`salad_core.attention.measure.mirror_closeness` of the mirrored limbs (distance to
  the mirror image over distance to the source; below 1: closer to the mirror image).

With ``--other-edits``, every original take is also inverted and edited by re-weighting its action word
(s = -1 and +2) and, where :data:`SWAPS` has one, by swapping it (``WordSwap(0.8)`` with the source's
self-attention for the first 20 % of steps): ``edited_cm`` is how much the body parts holding more than
their share of the word's attention move, ``kept_cm`` how much the other parts move (root-aligned MPJPE
between the source reconstruction and the edit).

Joints are the pipeline's ``out.joints`` (with recovery "fit": fixed bones), the same for source and edit.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from salad_core.attention.measure import left_right_ratio, mirror_closeness
from salad_core.motion import features_to_joints, mirror_features
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import PART_NAMES, get_skeleton

from _measure_common import (deepmimic_items, finish_run, mean, mirror_edits, print_summary, run_settings,  # scripts/
                             start_run)

#: The limb pairs Mirror can act on alone, and the body parts that belong to each.
LIMBS = {"arms": ("left arm", "right arm"), "legs": ("left leg", "right leg")}


def sided_limb(joints: np.ndarray, threshold: float) -> tuple[str, float] | None:
    """The limb pair whose log left/right activity ratio is largest in magnitude, if beyond
    ``log(threshold)``: ``(limb, log ratio)`` (positive: the left side leads); else None."""
    ratios = {k: math.log(v) for k, v in left_right_ratio(joints).items() if k in LIMBS}
    limb = max(ratios, key=lambda k: abs(ratios[k]))
    return (limb, ratios[limb]) if abs(ratios[limb]) > math.log(threshold) else None


def kept_cm(source: np.ndarray, edited: np.ndarray, limb: str) -> float:
    """Root-aligned MPJPE (cm) between two (T, 22, 3) motions over the joints outside ``limb``'s parts
    (the root joint itself excluded: it is the alignment point)."""
    return parts_mpjpe_cm(source, edited, LIMBS[limb], inside=False)


def parts_mpjpe_cm(source: np.ndarray, edited: np.ndarray, parts, *, inside: bool) -> float:
    """Root-aligned MPJPE (cm) between two (T, 22, 3) motions over the joints of body ``parts`` (``inside``)
    or of the other parts; the root joint is the alignment point and never counted. NaN when no joint is left."""
    sk = get_skeleton("humanml3d")
    ids = [j for j, p in enumerate(sk.joint_to_part) if (PART_NAMES[p] in parts) == inside and j != 0]
    if not ids:
        return float("nan")
    a, b = np.asarray(source, np.float64), np.asarray(edited, np.float64)
    n = min(len(a), len(b))
    a, b = a[:n] - a[:n, :1], b[:n] - b[:n, :1]
    return float(np.linalg.norm(a[:, ids] - b[:, ids], axis=-1).mean() * 100)


#: Word swaps for the takes' prompts (same number of words).
SWAPS = {"walks": "runs", "runs": "walks", "kicks": "punches", "punches": "kicks", "jumps": "runs",
         "dances": "jumps", "spins": "jumps"}


def action_word(prompt: str) -> str:
    """The action word of a DeepMimic prompt ("a person kicks" -> "kicks", "a person does a backflip" ->
    "backflip")."""
    words = prompt.split()
    return words[4] if words[2] == "does" and len(words) > 4 else words[2]


def attended_parts(word_map: np.ndarray) -> tuple[str, ...]:
    """The body parts that hold more than their share (1 / P) of a word's attention, from its ``(P, N')``
    map: the parts an edit of that word acts on."""
    share = np.asarray(word_map, np.float64).sum(-1)
    share = share / max(share.sum(), 1e-12)
    return tuple(PART_NAMES[p] for p in np.flatnonzero(share > 1.0 / len(share)))


def measure_other_edits(pipe, items: list[dict], *, steps: int, scales=(-1.0, 2.0)) -> dict:
    """Re-weighting the action word (each scale) and swapping it (:data:`SWAPS`) on every inverted take:
    how much the parts the word attends to change (``edited_cm``) and how much the others keep (``kept_cm``),
    root-aligned MPJPE between the source reconstruction and the edit."""
    from salad_core.attention import CaptureConfig, InjectSelfAttention, Reweight, WordSwap

    rows = []
    for item in items:
        word = action_word(item["prompt"])
        inv = pipe.invert(item["features"], item["prompt"], num_steps=steps)
        edits = {f"reweight {word} {s:+g}": ([Reweight(word, s)], None) for s in scales}
        if word in SWAPS:
            target = item["prompt"].replace(word, SWAPS[word], 1)
            edits[f"swap {word} -> {SWAPS[word]}"] = ([WordSwap(0.8), InjectSelfAttention()], target)
        parts = None
        for name, (specs, target) in edits.items():
            out = pipe.edit(target=target, inversion=inv, edits=specs,
                            capture_attention=CaptureConfig() if parts is None else False)
            if parts is None:
                parts = attended_parts(out.source.attention.word_map(0, word))
            src, ed = out.source.joints[0], out.edited.joints[0]
            rows.append({"id": item["id"], "prompt": item["prompt"], "edit": name, "parts": list(parts),
                         "edited_cm": parts_mpjpe_cm(src, ed, parts, inside=True),
                         "kept_cm": parts_mpjpe_cm(src, ed, parts, inside=False)})
    summary = {}
    for kind in ("reweight", "swap"):
        sel = [r for r in rows if r["edit"].startswith(kind)]
        summary[kind] = {"edits": float(len(sel)), "edited_cm": mean(r["edited_cm"] for r in sel),
                         "kept_cm": mean(r["kept_cm"] for r in sel if not math.isnan(r["kept_cm"]))}
    return {"summary": summary, "edits": rows}


def real_items(pipe, max_clips: int) -> list[dict]:
    """The DeepMimic takes (:func:`_measure_common.deepmimic_items`) and their mirrored copies."""
    items = []
    for item in deepmimic_items(pipe.skeleton, max_clips):
        items += [item, {**item, "id": f"{item['id']} (mirrored)",
                         "features": mirror_features(item["features"]).astype(np.float32)}]
    return items


def measure(pipe, items: list[dict], *, steps: int, sided: float, self_attention: tuple[str, ...] = (),
            window: tuple[float, float] = (0.0, 1.0)) -> dict:
    rows, skipped = [], []
    for item in items:
        side = sided_limb(features_to_joints(item["features"]), sided)
        if side is None:
            skipped.append(item["id"])
            continue
        limb, truth = side
        inv = pipe.invert(item["features"], item["prompt"], num_steps=steps)
        edit = pipe.edit(inversion=inv, edits=mirror_edits(limb, self_attention, window))
        src, out = edit.source.joints[0], edit.edited.joints[0]
        before, after = math.log(left_right_ratio(src)[limb]), math.log(left_right_ratio(out)[limb])
        rows.append({"id": item["id"], "prompt": item["prompt"], "limb": limb, "log_ratio_capture": truth,
                     "log_ratio_before": before, "log_ratio_after": after, "swapped": bool(before * after < 0),
                     "kept_cm": kept_cm(src, out, limb),
                     "closeness": mirror_closeness(src, out, limb)["ratio"],
                     "vae_mpjpe_cm": 100 * float(inv.errors.get("vae_mpjpe", float("nan")))})
    summary = {"clips": float(len(rows)), "skipped_two_sided": float(len(skipped)),
               "swap_rate": mean(float(r["swapped"]) for r in rows),
               "kept_cm": mean(r["kept_cm"] for r in rows),
               "closeness": mean(r["closeness"] for r in rows),
               "log_ratio_before": mean(abs(r["log_ratio_before"]) for r in rows),
               "log_ratio_after_signed": mean(r["log_ratio_after"] * math.copysign(1, r["log_ratio_before"])
                                              for r in rows)}
    return {"summary": summary, "clips": rows, "skipped": skipped}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--weights", type=Path, default=None, help="pipeline folder (default: the shipped weights)")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--sided", type=float, default=1.5,
                    help="a limb pair is one-sided when one side is this many times busier than the other")
    ap.add_argument("--max-clips", type=int, default=40, help="DeepMimic clips (each also mirrored)")
    ap.add_argument("--self-attention", nargs="*", default=[], choices=["temporal", "skeletal"],
                    help="also mirror the source's self-attention of these kinds (MirrorSelfAttention)")
    ap.add_argument("--window", type=float, nargs=2, default=(0.0, 1.0), metavar=("START", "STOP"),
                    help="step fractions of the self-attention mirroring (default 0 1)")
    ap.add_argument("--other-edits", action="store_true",
                    help="also re-weight (-1, +2) and swap each take's action word and measure what the edit keeps")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.sided <= 1:
        ap.error(f"--sided {args.sided}: must be > 1 (a ratio of the busier side over the other)")
    from salad_core.data import deepmimic

    if not deepmimic.pybullet_available():
        raise SystemExit("pybullet is not installed: pip install 'salad[deepmimic]' (the DeepMimic clips come with it)")
    start = start_run(args.threads)
    pipe = SaladPipeline.from_pretrained(args.weights)
    items = real_items(pipe, args.max_clips)
    print(f"weights: {pipe.source or args.weights}; {len(items)} real clips (DeepMimic and mirrored copies); "
          f"{args.steps} steps, w = {pipe.guidance.scale:g}")
    res = measure(pipe, items, steps=args.steps, sided=args.sided, self_attention=tuple(args.self_attention),
                  window=tuple(args.window))
    results = {"settings": run_settings(args), **res}
    print_summary("Mirror of the one-sided limb pair on inverted real clips", res["summary"], width=24,
                  nested_digits=3)
    for r in res["clips"]:
        print(f"  {r['id']:32s} {r['limb']:4s} log L/R {r['log_ratio_before']:+.2f} -> {r['log_ratio_after']:+.2f}"
              f"  {'swapped' if r['swapped'] else 'kept   '}  rest moved {r['kept_cm']:.1f} cm"
              f"  closeness {r['closeness']:.2f}")
    print(f"  two-sided (not measured): {', '.join(res['skipped']) or 'none'}")
    if args.other_edits:
        originals = [it for it in items if not it["id"].endswith("(mirrored)")]
        other = measure_other_edits(pipe, originals, steps=args.steps)
        results["other_edits"] = other
        print_summary("Re-weighting and swapping the action word of inverted real clips (cm moved)", other["summary"],
                      width=24, nested_digits=3)
        for r in other["edits"]:
            print(f"  {r['id']:24s} {r['edit']:28s} word's parts {'+'.join(r['parts']):34s} moved "
                  f"{r['edited_cm']:5.1f} cm, the rest {r['kept_cm']:5.1f} cm")
    return finish_run(results, start, args.json)


if __name__ == "__main__":
    main()
