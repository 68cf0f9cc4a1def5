"""Mirror edits of real motion capture: how often the active side swaps, and what the edit keeps (issue 21).

Usage:
    python scripts/measure_real_edits.py [--weights DIR] [--steps 50] [--json OUT.json]

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

Joints are the pipeline's ``out.joints`` (with recovery "fit": fixed bones), the same for source and edit.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from salad_core.attention import Mirror, MirrorSelfAttention
from salad_core.attention.measure import left_right_ratio, mirror_closeness
from salad_core.motion import features_to_joints, mirror_features
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import PART_NAMES, get_skeleton

from _measure_common import deepmimic_items, finish_run, mean, print_summary, run_settings, start_run  # scripts/

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
    sk = get_skeleton("humanml3d")
    ids = [j for j, p in enumerate(sk.joint_to_part) if PART_NAMES[p] not in LIMBS[limb] and j != 0]
    a, b = np.asarray(source, np.float64), np.asarray(edited, np.float64)
    n = min(len(a), len(b))
    a, b = a[:n] - a[:n, :1], b[:n] - b[:n, :1]
    return float(np.linalg.norm(a[:, ids] - b[:, ids], axis=-1).mean() * 100)


def real_items(pipe, max_clips: int) -> list[dict]:
    """The DeepMimic takes (:func:`_measure_common.deepmimic_items`) and their mirrored copies."""
    items = []
    for item in deepmimic_items(pipe.skeleton, max_clips):
        items += [item, {**item, "id": f"{item['id']} (mirrored)",
                         "features": mirror_features(item["features"]).astype(np.float32)}]
    return items


def mirror_edits(limb: str, self_attention: tuple[str, ...], window: tuple[float, float]) -> list:
    """``Mirror(limb)``, plus :class:`MirrorSelfAttention` of the same limb over ``window`` when
    ``self_attention`` names kinds (temporal, skeletal)."""
    edits = [Mirror(limb)]
    if self_attention:
        edits.append(MirrorSelfAttention(limb, steps=window, kinds=self_attention))
    return edits


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
    return finish_run(results, start, args.json)


if __name__ == "__main__":
    main()
