"""Mirroring real takes and edits that stay human (issue 67): why Mirror does not flip a real take, whether
MirrorTake does, and whether an edit lifts the pelvis.

Usage:
    python lab/scripts/editing/measure_mirror_real.py [--steps 50] [--sections diagnosis mirror turn ground]
        [--tuning N] [--json lab/records/editing/mirror_real.json]

Held-out real takes (evaluation data: nothing is tuned on them): pybullet's DeepMimic takes and their exact
mirrors (``salad_core.data.deepmimic``, needs pybullet), and bvhtoolbox's MocapBank kneel
(``tests/data/bvh/mocapbank.bvh``, frames 64-256: stands, kneels on the right knee, stands up).

Sections:

- ``diagnosis``: per one-sided take, what carries the side: the exact inversion's corrections against the step
  sizes, the inverted noise's standard deviation and lag-1 autocorrelation over latent frames (white noise: 1 and
  0), and how far the edited branch with no edit at all lands from the source (the noise alone regenerates it).
- ``mirror``: every take whose arms or legs are one-sided (log left/right activity ratio beyond log 1.5; the 8 of
  issue 21: jump, kick, spin, spinkick and their mirrors) and the kneel (its side: which knee is down), edited with
  ``Mirror`` of that limb pair, ``Mirror`` + ``MirrorSelfAttention``, and ``MirrorTake`` (``mirror_take_edits``:
  ``Mirror`` + the latents of the inverted mirror image, with its feature-space composite, the default, and without
  it: "latent only"). ``swapped``: the leading side changed; ``kept_cm``:
  root-aligned MPJPE between source reconstruction and edit over the joints outside the mirrored limbs.
- ``turn``: the walk-and-turn takes (DeepMimic walker turns, left and right) edited with ``Mirror("all")`` and
  ``MirrorTake("all")``: the heading change (degrees, from the hips) before and after; ``reversed``: its sign flips.
- ``ground``: every DeepMimic take and the kneel edited by re-weighting the action word (-1, +2), swapping it
  (:data:`measure_real_edits.SWAPS`, with the source's self-attention for 20 % of steps), the walk-and-turns by
  ``Reweight("turns", -1)`` and ``Reweight("turns", 2)``: the highest pelvis (fitted joints) above the source's
  highest, raw and after :func:`salad_core.attention.grounding.ground_edit`; counted where the target prompt does
  not ask to leave the floor (``all_edits_forced``: every edit, the ceiling forced also on those).
- ``--tuning N``: the same ``mirror`` section on N one-sided *procedural validation* clips (where MirrorTake's
  defaults were chosen).
"""
from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np
import torch

from salad_core.attention import InjectSelfAttention, Mirror, MirrorSelfAttention, Reweight, WordSwap
from salad_core.attention.grounding import asks_to_leave_floor, ground_edit
from salad_core.attention.measure import left_right_ratio, mirror_closeness
from salad_core.attention.mirror_take import invert_mirror, mirror_take_edits
from salad_core.motion import features_to_joints, mirror_features
from salad_core.pipeline import SaladPipeline

from _measure_common import annotated_clips, deepmimic_items, finish_run, mean, print_summary, run_settings, start_run
from measure_real_edits import LIMBS, SWAPS, action_word, parts_mpjpe_cm, sided_limb

KNEEL_FILE = Path(__file__).resolve().parents[3] / "tests" / "data" / "bvh" / "mocapbank.bvh"
KNEEL_FRAMES = (64, 256)
KNEEL_PROMPT = "a person kneels down on one knee and stands up"
#: How low (m) the lower knee must be for a frame to count as kneeling.
KNEE_DOWN = 0.25


# ------------------------------------------------------------------------------ measures
def joint(name: str) -> int:
    from salad_core.skeleton import get_skeleton

    return get_skeleton("humanml3d").joint_names.index(name)


def kneeling_side(joints: np.ndarray) -> float:
    """Mean left-minus-right knee height (m) over the frames where the lower knee is below :data:`KNEE_DOWN`:
    positive when the right knee is down; NaN when no knee goes down."""
    lk, rk = joints[:, joint("left_knee"), 1], joints[:, joint("right_knee"), 1]
    floor = joints[..., 1].min()
    down = np.minimum(lk, rk) - floor < KNEE_DOWN
    return float((lk - rk)[down].mean()) if down.any() else float("nan")


def side_of(joints: np.ndarray, limb: str) -> float:
    """The signed side measure: the log left/right activity ratio of ``limb``, or for ``"kneel"`` the kneeling side."""
    if limb == "kneel":
        return kneeling_side(joints)
    return math.log(left_right_ratio(joints)[limb])


def heading_change(joints: np.ndarray) -> float:
    """Degrees the hips' facing turns from the first to the last frame (positive: to the left, counter-clockwise
    seen from above)."""
    v = joints[:, joint("left_hip")] - joints[:, joint("right_hip")]
    ang = np.unwrap(np.arctan2(v[:, 0], v[:, 2]))
    return float(np.degrees(ang[-1] - ang[0]))


def pelvis_rise(source: np.ndarray, edited: np.ndarray) -> float:
    """How far (m) the edited pelvis rises above the source's highest pelvis (0 when it does not)."""
    return max(0.0, float(edited[:, 0, 1].max() - source[:, 0, 1].max()))


# ------------------------------------------------------------------------------ takes
def kneel_item() -> dict:
    from salad_core.bvh import import_bvh

    feats = import_bvh(KNEEL_FILE).features()[KNEEL_FRAMES[0]:KNEEL_FRAMES[1]]
    return {"id": "mocapbank kneel", "features": np.asarray(feats, np.float32), "prompt": KNEEL_PROMPT}


def real_takes(pipe, max_clips: int) -> list[dict]:
    items = []
    for item in deepmimic_items(pipe.skeleton, max_clips):
        items += [item, {**item, "id": f"{item['id']} (mirrored)",
                         "features": mirror_features(item["features"]).astype(np.float32)}]
    return items


def tuning_clips(n: int, sided: float) -> list[dict]:
    """One-sided procedural *validation* clips (first caption each)."""
    from salad_core.eval.heldout import heldout_corpus

    root = heldout_corpus(Path(tempfile.mkdtemp()) / "val", 60, split="val")
    out = []
    for cid, doc, feats in annotated_clips(root, "val", max_frames=196, min_frames=40, mirrors=False):
        side = sided_limb(features_to_joints(feats), sided)
        if side is not None:
            out.append({"id": cid, "features": feats, "prompt": doc["captions"][0]["caption"], "limb": side[0]})
        if len(out) >= n:
            break
    return out


# ------------------------------------------------------------------------------ sections
def diagnosis(pipe, inv) -> dict:
    """What carries the side of an inverted take (see the module docstring)."""
    tr = inv.trajectory[:, 0]
    steps = (tr[1:] - tr[:-1]).flatten(1).norm(dim=1)
    corr = (torch.zeros_like(steps) if inv.corrections is None
            else inv.corrections[:, 0].flatten(1).norm(dim=1))
    n = inv.noise[0]
    lag1 = float((n[1:] * n[:-1]).mean() / (n * n).mean()) if n.shape[0] > 1 else float("nan")
    white = torch.randn(n.shape, generator=torch.Generator().manual_seed(0))
    white_lag1 = float((white[1:] * white[:-1]).mean() / (white * white).mean()) if n.shape[0] > 1 else float("nan")
    out = pipe.edit(inversion=inv, edits=[])          # the edited branch from the same noise, no edit
    return {"corrections_over_steps": float((corr / steps.clamp_min(1e-12)).max()),
            "noise_std": float(n.std()), "noise_lag1": lag1, "white_noise_lag1": white_lag1,
            "no_edit_moves_cm": parts_mpjpe_cm(out.source.joints[0], out.edited.joints[0], (), inside=False)}


def mirror_variants(limb: str, mirrored) -> dict[str, list]:
    pair = "legs" if limb == "kneel" else limb
    return {"Mirror": [Mirror(pair)],
            "Mirror+MirrorSelfAttention": [Mirror(pair), MirrorSelfAttention(pair)],
            "MirrorTake (latent only)": mirror_take_edits(pair, mirrored, composite=False),
            "MirrorTake": mirror_take_edits(pair, mirrored)}


def measure_mirror(pipe, items: list[dict], *, steps: int, sided: float, diagnose: bool) -> dict:
    rows, skipped, diag = [], [], []
    for item in items:
        limb = item.get("limb")
        if limb is None:
            side = sided_limb(features_to_joints(item["features"]), sided)
            if side is None:
                skipped.append(item["id"])
                continue
            limb = side[0]
        inv = pipe.invert(item["features"], item["prompt"], num_steps=steps)
        mirrored = invert_mirror(pipe, inv)
        if diagnose:
            diag.append({"id": item["id"], **diagnosis(pipe, inv)})
        pair = "legs" if limb == "kneel" else limb
        for name, edits in mirror_variants(limb, mirrored).items():
            out = pipe.edit(inversion=inv, edits=edits)
            src, ed = out.source.joints[0], out.edited.joints[0]
            before, after = side_of(src, limb), side_of(ed, limb)
            rows.append({"id": item["id"], "limb": limb, "edit": name, "before": before, "after": after,
                         "swapped": bool(before * after < 0), "kept_cm": parts_mpjpe_cm(src, ed, LIMBS[pair], inside=False),
                         "closeness": mirror_closeness(src, ed, pair)["ratio"]})
    summary = {}
    for name in ("Mirror", "Mirror+MirrorSelfAttention", "MirrorTake (latent only)", "MirrorTake"):
        sel = [r for r in rows if r["edit"] == name]
        summary[name] = {"takes": float(len(sel)), "swapped": float(sum(r["swapped"] for r in sel)),
                         "kept_cm": mean(r["kept_cm"] for r in sel),
                         "kept_cm_max": max((r["kept_cm"] for r in sel), default=float("nan")),
                         "within_3cm": float(sum(r["kept_cm"] <= 3.0 for r in sel)),
                         "swapped_and_within_3cm": float(sum(r["swapped"] and r["kept_cm"] <= 3.0 for r in sel))}
    res = {"summary": summary, "takes": rows, "skipped_two_sided": skipped}
    if diagnose:
        res["diagnosis"] = {"takes": diag, "summary": {k: mean(d[k] for d in diag) for k in diag[0] if k != "id"}}
    return res


def measure_turn(pipe, items: list[dict], *, steps: int) -> dict:
    rows = []
    for item in items:
        inv = pipe.invert(item["features"], item["prompt"], num_steps=steps)
        mirrored = invert_mirror(pipe, inv)
        for name, edits in (("Mirror(all)", [Mirror("all")]), ("MirrorTake(all)", mirror_take_edits("all", mirrored))):
            out = pipe.edit(inversion=inv, edits=edits)
            before, after = heading_change(out.source.joints[0]), heading_change(out.edited.joints[0])
            rows.append({"id": item["id"], "edit": name, "turn_before_deg": before, "turn_after_deg": after,
                         "reversed": bool(before * after < 0),
                         "pelvis_rise_cm": 100 * pelvis_rise(out.source.joints[0], out.edited.joints[0])})
    summary = {name: {"takes": float(len([r for r in rows if r["edit"] == name])),
                      "reversed": float(sum(r["reversed"] for r in rows if r["edit"] == name)),
                      "turn_after_over_before": mean(r["turn_after_deg"] / r["turn_before_deg"]
                                                     for r in rows if r["edit"] == name)}
               for name in ("Mirror(all)", "MirrorTake(all)")}
    return {"summary": summary, "takes": rows}


def measure_ground(pipe, items: list[dict], *, steps: int, margin: float) -> dict:
    rows = []
    for item in items:
        inv = pipe.invert(item["features"], item["prompt"], num_steps=steps)
        word = "turns" if "turns" in item["prompt"].split() else action_word(item["prompt"])
        if word not in item["prompt"].split():
            word = item["prompt"].split()[2]
        edits = {f"reweight {word} {s:+g}": ([Reweight(word, s)], None) for s in (-1.0, 2.0)}
        if word in SWAPS:
            edits[f"swap {word} -> {SWAPS[word]}"] = ([WordSwap(0.8), InjectSelfAttention()],
                                                      item["prompt"].replace(word, SWAPS[word], 1))
        for name, (specs, target) in edits.items():
            out = pipe.edit(target=target, inversion=inv, edits=specs)
            grounded = ground_edit(pipe, out, margin=margin)
            forced = ground_edit(pipe, out, margin=margin, lift_words=False) if asks_to_leave_floor(
                out.edited.texts[0]) else grounded
            src = out.source.joints[0]
            lift = asks_to_leave_floor(out.edited.texts[0])
            rec = grounded.settings["grounding"]["motions"][0]
            rows.append({"id": item["id"], "edit": name, "target": out.edited.texts[0], "lift_words": lift,
                         "source_pelvis_max_m": float(src[:, 0, 1].max()),
                         "raw_pelvis_max_m": float(out.edited.joints[0][:, 0, 1].max()),
                         "raw_rise_cm": 100 * pelvis_rise(src, out.edited.joints[0]),
                         "grounded_rise_cm": 100 * pelvis_rise(src, grounded.edited.joints[0]),
                         "forced_rise_cm": 100 * pelvis_rise(src, forced.edited.joints[0]),
                         "frames_lowered": rec["frames"], "max_drop_cm": 100 * rec["max_drop"],
                         "grounded_moves_cm": parts_mpjpe_cm(out.edited.joints[0], grounded.edited.joints[0], (),
                                                             inside=False)})
    return {"summary": ground_summary(rows), "edits": rows}


#: A rise counts as over 10 cm beyond this (cm): the grounding puts the pelvis at the ceiling to 0.1 mm.
OVER_CM = 10.05


def ground_summary(rows: list[dict]) -> dict:
    """Counts of :func:`measure_ground`'s edits whose pelvis rises more than 10 cm (:data:`OVER_CM`)."""
    counted = [r for r in rows if not r["lift_words"]]
    return {"edits": float(len(rows)), "counted_no_lift_words": float(len(counted)),
            "raw_over_10cm": float(sum(r["raw_rise_cm"] > OVER_CM for r in counted)),
            "grounded_over_10cm": float(sum(r["grounded_rise_cm"] > OVER_CM for r in counted)),
            "raw_rise_cm_max": max((r["raw_rise_cm"] for r in counted), default=float("nan")),
            "grounded_rise_cm_max": max((r["grounded_rise_cm"] for r in counted), default=float("nan")),
            "edits_lowered": float(sum(r["frames_lowered"] > 0 for r in counted)),
            "all_edits_raw_over_10cm": float(sum(r["raw_rise_cm"] > OVER_CM for r in rows)),
            "all_edits_forced_over_10cm": float(sum(r["forced_rise_cm"] > OVER_CM for r in rows)),
            "all_edits_forced_rise_cm_max": max((r["forced_rise_cm"] for r in rows), default=float("nan"))}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--weights", type=Path, default=None)
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--sided", type=float, default=1.5)
    ap.add_argument("--max-clips", type=int, default=40)
    ap.add_argument("--sections", nargs="*", default=["diagnosis", "mirror", "turn", "ground"],
                    choices=["diagnosis", "mirror", "turn", "ground"])
    ap.add_argument("--tuning", type=int, default=0, help="also the mirror section on N procedural validation clips")
    ap.add_argument("--margin", type=float, default=0.10, help="grounding: metres above the source's highest pelvis")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--update", action="store_true",
                    help="keep the sections of an existing --json record that this run does not measure")
    args = ap.parse_args(argv)
    from salad_core.data import deepmimic

    if not deepmimic.pybullet_available():
        raise SystemExit("pybullet is not installed: pip install 'salad[deepmimic]'")
    start = start_run(args.threads)
    pipe = SaladPipeline.from_pretrained(args.weights)
    takes = real_takes(pipe, args.max_clips)
    kneel = {**kneel_item(), "limb": "kneel"}
    results = {"settings": run_settings(args)}
    if "mirror" in args.sections or "diagnosis" in args.sections:
        one_sided = [t for t in takes if "walker" not in t["id"]] + [kneel]
        res = measure_mirror(pipe, one_sided, steps=args.steps, sided=args.sided,
                             diagnose="diagnosis" in args.sections)
        results["mirror"] = res
        print_summary("Mirroring the leading limb of held-out real takes", res["summary"], width=28, nested_digits=3)
        for r in res["takes"]:
            print(f"  {r['id']:28s} {r['limb']:5s} {r['edit']:28s} {r['before']:+.2f} -> {r['after']:+.2f} "
                  f"{'swapped' if r['swapped'] else 'kept   '}  rest moved {r['kept_cm']:5.2f} cm")
        if "diagnosis" in res:
            print_summary("What carries the side (inverted one-sided takes, means)", res["diagnosis"]["summary"],
                          width=28, nested_digits=3)
    if "turn" in args.sections:
        walkers = [t for t in takes if "walker/turn" in t["id"]]
        res = measure_turn(pipe, walkers, steps=args.steps)
        results["turn"] = res
        print_summary("Mirroring a walk-and-turn (heading change)", res["summary"], width=28, nested_digits=3)
        for r in res["takes"]:
            print(f"  {r['id']:30s} {r['edit']:16s} turn {r['turn_before_deg']:+6.1f} -> {r['turn_after_deg']:+6.1f} deg"
                  f"  {'reversed' if r['reversed'] else 'kept'}")
    if "ground" in args.sections:
        originals = [t for t in takes if not t["id"].endswith("(mirrored)")] + [kneel_item()]
        res = measure_ground(pipe, originals, steps=args.steps, margin=args.margin)
        results["ground"] = res
        print_summary("Pelvis rise of edits of held-out real takes (raw / grounded)", res["summary"], width=28,
                      nested_digits=3)
        for r in res["edits"]:
            if r["raw_rise_cm"] > 5:
                print(f"  {r['id']:28s} {r['edit']:28s} pelvis {r['source_pelvis_max_m']:.2f} -> {r['raw_pelvis_max_m']:.2f} m"
                      f" raw +{r['raw_rise_cm']:.1f} cm, grounded +{r['grounded_rise_cm']:.1f} cm"
                      f"{'  (lift words)' if r['lift_words'] else ''}")
    if args.tuning:
        res = measure_mirror(pipe, tuning_clips(args.tuning, args.sided), steps=args.steps, sided=args.sided,
                             diagnose=False)
        results["tuning_procedural_val"] = res
        print_summary("Tuning set: one-sided procedural validation clips", res["summary"], width=28, nested_digits=3)
    if args.update and args.json is not None and args.json.is_file():
        import json

        old = json.loads(args.json.read_text())
        kept = {k: v for k, v in old.items() if k not in results and k != "seconds"}
        if "mirror" in results and "diagnosis" not in results["mirror"] and "diagnosis" in old.get("mirror", {}):
            results["mirror"]["diagnosis"] = old["mirror"]["diagnosis"]      # not measured again: unchanged
        results = {**kept, **results, "updated_sections": sorted(set(results) - {"settings"})}
    return finish_run(results, start, args.json)


if __name__ == "__main__":
    main()
