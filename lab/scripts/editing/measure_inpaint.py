"""In-painting (issue 67): regenerate body parts or a frame span of a motion, keep the rest.

Usage:
    python lab/scripts/editing/measure_inpaint.py [--steps 50] [--frames 120] [--threads 1]
        [--blends 0,1,2] [--json lab/records/editing/inpaint.json]
    python lab/scripts/editing/measure_inpaint.py --tuning N [--offset M] [--only parts|frames] [--grid NAMES] ...
        (procedural validation clips over tuning_grid(); --grid without --tuning: those settings on the held-out cases)
    python lab/scripts/editing/measure_inpaint.py --tuning-generated [--grid NAMES] ...
        (the validation set of generated frame spans: TUNING_SPAN_SOURCES at TUNING_SEED, over GENERATED_SPAN_ROWS)

Cases (held out: nothing here is trained; the only choice made on them is ``Inpaint.blend``):

- generated, parts: a source prompt (walking, standing, jogging in place, squatting) is generated from a seed
  and its arms / legs / head regenerated from a benchmark prompt of ``salad_core.eval.physics_prompts``
  whose checks test that limb (``a man waves his right hand`` -> ``arm_ratio[right] >= 2``, ...);
- generated, frames: the source's frames ``[40, 80)`` (in-between) or ``[80, end)`` (suffix) regenerated
  from ``a person jumps`` / ``a person squats down`` / ``a person turns left``;
- real: DeepMimic takes (pybullet), the MocapBank BVH take and the HumanML3D sample, inverted with their
  prompt (``pipe.invert``, its defaults) and edited as above (arms from the wave prompt; the middle third
  of the take from the jump prompt).

Measured per case (joints: the pipeline's ``out.joints``, metres -> cm):

- ``kept_cm``: root-aligned MPJPE between source and edit over what is kept (the other parts' joints, all
  frames; or every joint over the kept frames); ``kept_pose_cm`` the same after turning each pose to face
  +z (the heading of the kept frames after a regenerated span follows from the span's turning: a
  relative-feature motion integrates it); ``kept_segment_cm`` (frame spans) the global distance after moving
  each run of kept frames bodily onto the take's (:func:`segment_aligned_cm`: the frames after a span whose turn
  they follow, ``Inpaint(root="auto")``, are the take's own turned whole);
- ``edited_cm``: the same over the regenerated joints / frames (it must be far from 0);
- ``seam_jerk_ratio`` (frame spans): the largest jerk (third difference of the joint positions, mean
  over joints, m/s^3) within 4 frames of an inner seam over the source's own 95th percentile of jerk
  (``salad_core.attention.composite.seam_jerk_ratio``, which ``Inpaint(seam_bound=...)`` ranks with);
- ``check``: the prompt's checks on the edit (the whole motion; a turn over the regenerated span), and
  whether the source passed them already (``fresh``: it did not, so the pass is the edit's doing);
  ``check_span`` (frame spans): every check over the regenerated span alone.

Targets (issue 67): kept <= 2 cm, seam jerk <= 1.5x, the regenerated part passes its prompt's check in >= 80 % of
cases: ``target_check_pass`` in the summary, which counts ``check_span`` for a frame span (the check over the
regenerated span: the rest of the motion is the source's by design) and ``check`` for body parts (both columns are
printed).

Settings that differ only after decoding (:data:`POST_KEYS`: the composite, its fade, root handling and seam
smoothing) share one sampling run per case: the edit is sampled with ``composite=False, ground=False`` and each
setting's composite and grounding applied to it, as ``pipe.edit`` does.

``best of K`` settings (``Inpaint.candidates``): the case is sampled from the region seeds 0 .. K-1 (seed 0 is the
run the same setting without candidates has), each composited and grounded as above, and the one closest to the
target by the evaluator's text-motion distance kept (``salad_core.attention.ranking.choose_candidate``, as
``pipe.edit`` does); the row records every candidate's distance and target check (``candidate_checks``), and the
summary the check of any candidate (an oracle), of a random one (expected) and of the first. ``scored on parts``
settings rank the candidates with ``Inpaint(score="parts")`` (the kept body parts held still in the scored motion,
``salad_core.attention.ranking.isolate_parts``); they share the sampling runs of the same setting scored whole, and
are body-part settings only (a frame span skips them). ``seam-aware`` settings (``Inpaint(seam_bound=1.5)``) rank a
frame span's candidates by the distance among those whose seam jerk ratio is within 1.5x only (none: the smoothest,
``salad_core.attention.ranking.pick_candidate``); they share the sampling runs too, and their rows record every
candidate's seam ratio (``seam_ratios``; the summary's ``seam_fallback``: the share of cases where no candidate was
within the bound).

``--tuning-generated``: a *validation* set of generated frame spans, apart from the held-out ones: the sources
:data:`TUNING_SPAN_SOURCES` (none of :data:`SOURCES` / :data:`SPAN_SOURCES`) generated at :data:`TUNING_SEED` (the
held-out ones at seeds 0 ..), with the held-out cases' span prompts and spans (:data:`SPAN_TARGETS` x :data:`SPANS`):
24 cases, run over :data:`GENERATED_SPAN_ROWS` (or ``--grid``). Where the settings of a generated source's span are
chosen.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from salad_core.attention import Inpaint
from salad_core.attention.composite import composite_output, frame_jerk, seam_jerk, seam_jerk_ratio
from salad_core.attention.grounding import ground_edit
from salad_core.attention.ranking import TextMotionScorer, candidate_seam_ratios, choose_candidate
from salad_core.eval.physics_prompts import PROMPTS
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import PART_NAMES, get_skeleton

from _measure_common import deepmimic_items, finish_run, mean, run_settings, start_run  # scripts/

ROOT = Path(__file__).resolve().parents[3]
SOURCES = ("a person walks forward", "a person stands still", "a man jogs in place", "a person squats down")
PART_TARGETS = (("arms", "a man waves his right hand"), ("arms", "a woman waves with her left hand"),
                ("arms", "a person raises his left arm"), ("arms", "someone punches forward with their right fist"),
                ("arms", "a person raises both arms"), ("legs", "a man kicks with his left leg"),
                ("head", "a man nods his head"))
SPAN_SOURCES = ("a person walks forward", "a person stands still")
SPAN_TARGETS = ("a person jumps", "a person squats down", "a person turns left")
#: The regenerated motion frames of a generated source's span: in-between and suffix (None: the end).
SPANS = ((40, 80), (80, None))
#: Validation (not held out) generated sources for the span settings of a generated source (``--tuning-generated``):
#: fixed before measuring, none of SOURCES / SPAN_SOURCES, generated at TUNING_SEED.
TUNING_SPAN_SOURCES = ("a man walks slowly", "a woman stands and looks around", "a person walks in a circle",
                       "a man stands with his arms crossed")
TUNING_SEED = 100
DEEPMIMIC = ("walk", "run", "punch", "dance_a", "kick", "walker/0walk_forward", "walker/turn_left0", "spin")
BY_TEXT = {p.text: p for p in PROMPTS}


def facing(joints: np.ndarray, sk) -> np.ndarray:
    """Root-aligned poses turned about the vertical so that the hips' left-right axis is +x."""
    x = joints - joints[:, :1]
    li, ri = sk.joint_names.index("left_hip"), sk.joint_names.index("right_hip")
    across = x[:, li] - x[:, ri]
    ang = np.arctan2(across[:, 2], across[:, 0])
    c, s = np.cos(-ang), np.sin(-ang)
    out = x.copy()
    out[..., 0] = c[:, None] * x[..., 0] - s[:, None] * x[..., 2]
    out[..., 2] = s[:, None] * x[..., 0] + c[:, None] * x[..., 2]
    return out


def segment_aligned_cm(src: np.ndarray, ed: np.ndarray, frames) -> float:
    """Mean joint distance (cm) between ``src`` and ``ed`` ``(N, J, 3)`` over ``frames``, each contiguous run of them
    first moved bodily onto the source's (one rotation about the vertical and one translation per run, least squares):
    how far the kept frames are from the take's own when the frames after a span that turned may follow its turn
    (``Inpaint(root="auto")``); unlike the per-frame root alignment it keeps every within-run turn and travel."""
    frames = sorted(frames)
    if not frames:
        return float("nan")
    runs, cur = [], [frames[0]]
    for f in frames[1:]:
        if f == cur[-1] + 1:
            cur.append(f)
        else:
            runs.append(cur)
            cur = [f]
    runs.append(cur)
    total, count = 0.0, 0
    for run in runs:
        a, b = ed[run].reshape(-1, 3), src[run].reshape(-1, 3)
        ca, cb = a.mean(0), b.mean(0)
        x, y = a - ca, b - cb
        t = np.arctan2((x[:, 0] * y[:, 2] - x[:, 2] * y[:, 0]).sum(), (x[:, 0] * y[:, 0] + x[:, 2] * y[:, 2]).sum())
        c, sn = np.cos(t), np.sin(t)
        r = np.stack([c * x[:, 0] - sn * x[:, 2], x[:, 1], sn * x[:, 0] + c * x[:, 2]], -1)
        total += float(np.linalg.norm(r - y, axis=-1).sum())
        count += len(r)
    return total / count * 100


def dist_cm(a: np.ndarray, b: np.ndarray, frames, joints) -> float:
    if not len(frames) or not len(joints):
        return float("nan")
    d = np.linalg.norm(a[np.ix_(frames, joints)] - b[np.ix_(frames, joints)], axis=-1)
    return float(d.mean() * 100)


def evaluate(prompt: str, joints: np.ndarray, span: tuple[int, int] | None) -> bool:
    results = []
    for c in BY_TEXT[prompt].checks:
        x = joints[span[0]:span[1]] if (span is not None and c.measure in ("turn_deg", "abs_turn_deg")) else joints
        results.append(c.evaluate(x).passed)
    return all(results)


def measure(pipe, out, inp: Inpaint, target: str, sk) -> dict:
    src, ed = out.source.joints[0], out.edited.joints[0]
    n = len(src)
    jt = np.array(sk.joint_to_part)
    parts = inp.parts or PART_NAMES
    regen_j = [j for j in range(len(jt)) if PART_NAMES[jt[j]] in parts]
    kept_j = [j for j in range(len(jt)) if j not in regen_j]
    if inp.frames is None:
        span, regen_f, kept_f = None, list(range(n)), list(range(n))
    else:
        s, e = inp.latent_span(n)
        span = (s * inp.unit_length, e * inp.unit_length)
        regen_f = list(range(*span))
        kept_f = [f for f in range(n) if f not in regen_f]
        kept_j = list(range(len(jt))) if inp.parts is None else kept_j
    ra_s, ra_e = src - src[:, :1], ed - ed[:, :1]
    fa_s, fa_e = facing(src, sk), facing(ed, sk)
    if inp.frames is None:
        kept, kept_pose = dist_cm(ra_s, ra_e, kept_f, kept_j), dist_cm(fa_s, fa_e, kept_f, kept_j)
    else:       # kept frames: every joint (the chosen parts too, when only some were regenerated)
        allj = list(range(len(jt)))
        kept, kept_pose = dist_cm(ra_s, ra_e, kept_f, allj), dist_cm(fa_s, fa_e, kept_f, allj)
    row = {"kept_cm": kept, "kept_pose_cm": kept_pose, "edited_cm": dist_cm(fa_s, fa_e, regen_f, regen_j)}
    if inp.frames is not None:      # the kept runs moved bodily onto the take's (a followed turn turns them whole)
        row["kept_segment_cm"] = segment_aligned_cm(src, ed, kept_f)
    if span is not None:        # the product's seam measure (m/s^3 for the record: per frame^3 times fps^3)
        cuts = [b for b in span if 0 < b < n]
        row["seam_jerk"] = seam_jerk(ed, cuts) * sk.fps ** 3
        row["source_jerk_p95"] = float(np.percentile(frame_jerk(src), 95)) * sk.fps ** 3
        row["seam_jerk_ratio"] = seam_jerk_ratio(src, ed, cuts)
    row["check"] = evaluate(target, ed, span)
    row["source_check"] = evaluate(target, src, span)
    if span is not None:        # every check over the regenerated span alone (the rest of the take is the source's)
        whole = (span[0], span[1])
        row["check_span"] = all(c.evaluate(ed[whole[0]:whole[1]]).passed for c in BY_TEXT[target].checks)
        row["source_check_span"] = all(c.evaluate(src[whole[0]:whole[1]]).passed for c in BY_TEXT[target].checks)
    return row


def target_check(row: dict) -> bool:
    """The check the target counts ("the regenerated part passes the physics benchmark's check for its prompt"):
    over the regenerated span for a frame span (``check_span``), over the whole motion for body parts
    (``check``)."""
    return bool(row["check_span"] if "check_span" in row else row["check"])


def summarize(rows: list[dict]) -> dict:
    fresh = [r for r in rows if not r["source_check"]]
    out = {"cases": len(rows), "kept_cm": mean(r["kept_cm"] for r in rows),
           "kept_cm_max": max((r["kept_cm"] for r in rows), default=float("nan")),
           "kept_pose_cm": mean(r["kept_pose_cm"] for r in rows),
           "kept_within_2cm": mean(float(r["kept_cm"] <= 2.0) for r in rows),
           **({"kept_segment_within_2cm": mean(float(r["kept_segment_cm"] <= 2.0) for r in rows
                                               if "kept_segment_cm" in r)}
              if any("kept_segment_cm" in r for r in rows) else {}),
           "edited_cm": mean(r["edited_cm"] for r in rows),
           "check_pass": mean(float(r["check"]) for r in rows),
           "check_pass_fresh": mean(float(r["check"]) for r in fresh), "fresh_cases": len(fresh),
           "target_check_pass": mean(float(target_check(r)) for r in rows),
           "seconds": mean(r.get("seconds") for r in rows)}
    if any("check_span" in r for r in rows):
        out["check_span_pass"] = mean(float(r["check_span"]) for r in rows if "check_span" in r)
    if any("seam_jerk_ratio" in r for r in rows):
        out["seam_jerk_ratio"] = mean(r.get("seam_jerk_ratio") for r in rows)
        out["seam_within_1.5x"] = mean(float(r["seam_jerk_ratio"] <= 1.5) for r in rows if "seam_jerk_ratio" in r)
    ranked = [r for r in rows if "candidate_checks" in r]
    if ranked:      # the best of K by the evaluator against any of the K (an oracle) and a random one (expected)
        out["any_candidate_pass"] = mean(float(any(r["candidate_checks"])) for r in ranked)
        out["random_candidate_pass"] = mean(float(np.mean(r["candidate_checks"])) for r in ranked)
        out["first_candidate_pass"] = mean(float(r["candidate_checks"][0]) for r in ranked)
        out["chosen_not_first"] = mean(float(r["chosen"] != 0) for r in ranked)
        bounded = [r for r in ranked if r.get("seam_bound") is not None and r.get("seam_ratios") is not None]
        if bounded:     # seam-aware ranking: no candidate within the bound (the smoothest kept instead)
            out["seam_fallback"] = mean(float(min(r["seam_ratios"]) > r["seam_bound"]) for r in bounded)
    return out


def real_takes(sk, frames: int) -> list[dict]:
    items = [it for it in deepmimic_items(sk, 64) if it["id"] in DEEPMIMIC]
    from salad_core.bvh.convert import bvh_to_features
    mocap = bvh_to_features(ROOT / "tests/data/bvh/mocapbank.bvh")
    items.append({"id": "mocapbank", "features": mocap, "prompt": "a person kneels down on the right knee and stands up"})
    hml = ROOT / "tests/data/humanml3d_sample/new_joint_vecs/012314.npy"
    items.append({"id": "humanml3d_012314", "features": np.load(hml),
                  "prompt": "a person walks forward and turns around"})
    return _cut(items, frames)


def _cut(items: list[dict], frames: int) -> list[dict]:
    for it in items:
        f = np.asarray(it["features"], np.float32)
        n = min(len(f), frames)
        it["features"] = f[:n - n % 4]
    return [it for it in items if len(it["features"]) >= 48]


def tuning_takes(n: int, frames: int) -> list[dict]:
    """``n`` procedural *validation* clips (first caption each, no mirrors): where the settings are chosen."""
    import tempfile

    from salad_core.eval.heldout import heldout_corpus

    from _measure_common import annotated_clips

    # the val split has 200 motions (the clips are taken in id order, so a larger n keeps the first ones)
    root = heldout_corpus(Path(tempfile.mkdtemp()) / "val", min(max(3 * n, 30), 200), split="val")
    out = []
    for cid, doc, feats in annotated_clips(root, "val", max_frames=frames, min_frames=48, mirrors=False):
        out.append({"id": cid, "features": feats, "prompt": doc["captions"][0]["caption"]})
        if len(out) >= n:
            break
    return _cut(out, frames)


#: Settings compared on the held-out cases: the latent in-painting alone (SALAD 0.3, before issue 67's levers: every
#: option that changed since spelled out) and :class:`Inpaint`'s defaults.
CONFIGS = {"latent": dict(noise="source", composite=False, guidance=None, resample=1, smooth=0.0, prior="none"),
           "default": {}}

#: Inpaint options that act after decoding only (the composite): settings that differ only in these share one
#: sampling run per case.
POST_KEYS = ("composite", "fade", "root", "smooth", "smooth_window")
#: Post-decoding options that only change a frame span (a parts-only edit is the same with any of them).
SPAN_ONLY_KEYS = ("fade", "root", "smooth", "smooth_window")


def tuning_grid() -> dict[str, dict]:
    """Settings tried on the tuning clips (every option spelled out, so the grid does not move with the defaults):
    the sampling (the region's noise, the edited branch's guidance, RePaint resampling) crossed with the composite
    (off; fade 8; fade 8 plus the least-squares seam smoothing with strength / window); and the region's noise
    matched to the source's inverted noise (``noise="matched"``) with the chosen composite only."""
    base = dict(noise="fresh", guidance=None, resample=1, jump=1, candidates=1, score="whole", seam_bound=None, prior="none")
    sampling = {"source noise": dict(base, noise="source"),
                "fresh": dict(base),
                "fresh g7.5": dict(base, guidance=7.5),
                "source noise g7.5": dict(base, noise="source", guidance=7.5),
                "fresh resample 2": dict(base, resample=2),
                "fresh resample 3 jump 5": dict(base, resample=3, jump=5),
                "fresh g7.5 resample 2": dict(base, guidance=7.5, resample=2),
                "fresh g7.5 resample 3 jump 5": dict(base, guidance=7.5, resample=3, jump=5)}
    comp = dict(composite=True, fade=8, root="source", smooth=0.0, smooth_window=8)
    post = {"latent": dict(comp, composite=False),
            "fade 8": dict(comp),
            "fade 8 smooth 100/8": dict(comp, smooth=100.0, smooth_window=8),
            "fade 8 smooth 100/16": dict(comp, smooth=100.0, smooth_window=16),
            "fade 8 smooth 1000/16": dict(comp, smooth=1000.0, smooth_window=16)}
    grid = {f"{s} | {p}": dict(skw, **pkw) for s, skw in sampling.items() for p, pkw in post.items()}
    matched = {"matched": dict(base, noise="matched"),
               "matched g7.5": dict(base, noise="matched", guidance=7.5),
               "matched resample 3 jump 5": dict(base, noise="matched", resample=3, jump=5)}
    # the best of 4 fresh-noise seeds by the evaluator's text-motion distance (Inpaint.candidates)
    ranked = {"fresh best of 4": dict(base, candidates=4),
              "fresh g7.5 best of 4": dict(base, guidance=7.5, candidates=4),
              "fresh g7.5 best of 8": dict(base, guidance=7.5, candidates=8),
              "fresh resample 3 jump 5 best of 4": dict(base, resample=3, jump=5, candidates=4),
              "fresh g7.5 resample 3 jump 5 best of 4": dict(base, guidance=7.5, resample=3, jump=5, candidates=4),
              # body parts: the candidates scored with the kept parts held still (Inpaint.score="parts")
              "fresh best of 4 scored on parts": dict(base, candidates=4, score="parts"),
              "fresh resample 3 jump 5 best of 4 scored on parts": dict(base, resample=3, jump=5, candidates=4,
                                                                         score="parts"),
              # frame spans: ranked by distance among the candidates whose seams are within 1.5x (Inpaint.seam_bound)
              "fresh g7.5 best of 4 seam-aware": dict(base, guidance=7.5, candidates=4, seam_bound=1.5),
              "fresh g7.5 best of 8 seam-aware": dict(base, guidance=7.5, candidates=8, seam_bound=1.5)}
    # paste, then harmonise: the region starts from the target prompt sampled alone (Inpaint.prior="prompt")
    for strength in (0.5, 0.7):
        prior = dict(prior="prompt", prior_strength=strength)
        ranked.update({f"fresh prior {strength}": dict(base, **prior),
                       f"fresh resample 3 jump 5 prior {strength}": dict(base, resample=3, jump=5, **prior),
                       f"fresh g7.5 prior {strength}": dict(base, guidance=7.5, **prior),
                       f"source noise g7.5 prior {strength}": dict(base, noise="source", guidance=7.5, **prior),
                       f"fresh g7.5 prior {strength} best of 8 seam-aware": dict(base, guidance=7.5, candidates=8,
                                                                                  seam_bound=1.5, **prior)})
    chosen = "fade 8 smooth 100/8"
    grid.update({f"{s} | {chosen}": dict(skw, **post[chosen]) for s, skw in {**matched, **ranked}.items()})
    # the pasted prior's candidates ranked by their pelvis and feet heights against the prior, falling back to the
    # candidates without the prior when none is smooth (Inpaint(score="prior"); run through pipe.edit itself)
    grid["fresh g7.5 prior 0.7 best of 8 seam-aware scored by prior heights | fade 8 smooth 100/8"] = dict(
        base, guidance=7.5, prior="prompt", prior_strength=0.7, candidates=8, seam_bound=1.5, score="prior",
        product=True, **post[chosen])
    # a generated source's span: its own noise, pasted (0.5), the best of 4 pasted samples by the heights
    grid["source noise g7.5 prior 0.5 best of 4 seam-aware scored by prior heights | fade 8 smooth 100/8"] = dict(
        base, noise="source", guidance=7.5, prior="prompt", prior_strength=0.5, candidates=4, seam_bound=1.5,
        score="prior", **post[chosen])
    # a generated source's span: seed 0, and only when its seams are rough the next seeds until one joins smoothly
    grid["source noise g7.5 prior 0.5 first smooth of 4 | fade 8 smooth 100/8"] = dict(
        base, noise="source", guidance=7.5, prior="prompt", prior_strength=0.5, candidates=4, seam_bound=1.5,
        score="first_smooth", **post[chosen])
    # root="auto": the kept frames after a span that turned follow it (composite.TURN_FOLLOW_DEG)
    grid.update({f"{name} root auto": dict(kw, root="auto") for name, kw in list(grid.items())
                 if name.endswith(f"| {chosen}")})
    return grid


#: ``--tuning-generated``'s rows: (i) a generated source's span as ``Inpaint()``'s defaults make it today (the
#: source's noise, guidance 7.5, one candidate: spelled out), (ii) fresh noise, (iii) the best of 4 fresh seeds.
GENERATED_SPAN_ROWS = ("source noise g7.5 | fade 8 smooth 100/8", "fresh g7.5 | fade 8 smooth 100/8",
                       "fresh g7.5 best of 4 | fade 8 smooth 100/8")


def select_grid(text: str, error) -> dict[str, dict]:
    """``--grid``'s comma-separated :func:`tuning_grid` names -> those settings (``error``: the parser's)."""
    grid = tuning_grid()
    names = [g.strip() for g in text.split(",") if g.strip()]
    unknown = [g for g in names if g not in grid]
    if unknown:
        error(f"--grid: unknown settings {unknown}; choose from {list(grid)}")
    return {g: grid[g] for g in names}


#: Inpaint options of the ranking of candidates (after the composite): settings that differ only in these share
#: the sampling runs.
RANK_KEYS = ("candidates", "score", "seam_bound")


def split_config(kw: dict) -> tuple[dict, dict, dict]:
    """Inpaint options -> (sampling options, post-decoding options of :data:`POST_KEYS`, ranking options of
    :data:`RANK_KEYS`): the candidates (``Inpaint.candidates``, ranked after the composite; absent: the default's,
    resolved per case) are run as that many single edits from seeds 0, 1, ..., shared by the settings that differ
    only in the ranking."""
    samp = {k: v for k, v in kw.items() if k not in POST_KEYS and k not in RANK_KEYS}
    return (samp, {k: v for k, v in kw.items() if k in POST_KEYS},
            {k: v for k, v in kw.items() if k in RANK_KEYS})


def span_configs(configs: dict[str, dict]) -> dict[str, dict]:
    """The configs that apply to a frame span of every part: all but those scored on the body parts alone."""
    return {name: kw for name, kw in configs.items() if kw.get("score") != "parts"}


def part_configs(configs: dict[str, dict]) -> dict[str, dict]:
    """The configs that differ for a parts-only edit: the first of each (sampling, composite) setting."""
    out, seen = {}, set()
    for name, kw in configs.items():
        key = tuple(sorted((k, repr(v)) for k, v in kw.items() if k not in SPAN_ONLY_KEYS))
        if key not in seen:
            seen.add(key)
            out[name] = kw
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--blends", default="1", help="Inpaint.blend values to compare on the frame spans")
    ap.add_argument("--seeds", type=int, default=1, help="seeds per generated case")
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--skip-generated", action="store_true")
    ap.add_argument("--tuning", type=int, default=0,
                    help="instead: the real-take protocol on N procedural validation clips over tuning_grid()")
    ap.add_argument("--tuning-generated", action="store_true",
                    help="instead: the validation set of generated frame spans (TUNING_SPAN_SOURCES at TUNING_SEED, "
                         "the held-out span prompts and spans) over GENERATED_SPAN_ROWS")
    ap.add_argument("--generated-seeds", type=int, nargs="+", default=[TUNING_SEED], metavar="SEED",
                    help="with --tuning-generated: the sources' seeds (default TUNING_SEED; other seeds give new "
                         "validation spans of the same sources)")
    ap.add_argument("--grid", default=None,
                    help="comma-separated tuning_grid() names to run: with --tuning instead of all of them, with "
                         "--tuning-generated instead of GENERATED_SPAN_ROWS, on the held-out cases instead of CONFIGS "
                         "(latent, default)")
    ap.add_argument("--offset", type=int, default=0,
                    help="with --tuning: skip the first N validation clips (a check on clips the grid was not chosen on)")
    ap.add_argument("--only", choices=("parts", "frames"), default=None,
                    help="with --tuning: only the body-part or only the frame-span cases")
    ap.add_argument("--json", type=Path, default=ROOT / "lab/records/editing/inpaint.json")
    args = ap.parse_args()
    if args.tuning and args.tuning_generated:
        ap.error("--tuning and --tuning-generated are two validation sets: give one")
    t0 = start_run(args.threads)
    pipe = SaladPipeline.from_pretrained()
    scorer = TextMotionScorer()
    sk = get_skeleton()
    blends = [int(b) for b in args.blends.split(",")]
    n = args.frames
    rows: list[dict] = []

    def record(kind, name, blend, config, inp, target, out, seconds, ranking=None):
        row = dict(kind=kind, case=name, target=target, inpaint=inp.describe(), blend=blend, config=config,
                   seconds=seconds, **measure(pipe, out, inp, target, sk), **(ranking or {}))
        rows.append(row)
        print(f"{kind:14s} {name[:24]:24s} {inp.describe():10s} b{blend} {config[:40]:40s} kept {row['kept_cm']:5.2f} "
              f"pose {row['kept_pose_cm']:5.2f} edited {row['edited_cm']:5.1f} "
              f"seam {row.get('seam_jerk_ratio', float('nan')):5.2f} check {row['check']!s:5s} "
              f"span {row.get('check_span', '-')!s:5s} (src {row['source_check']})", flush=True)

    def run(kind, name, blend, configs, make, target, **kw):
        """Every config (name -> Inpaint options) on one case: one sampling per distinct sampling setting and
        candidate seed, then each config's composite of it (as pipe.edit makes it: composite, then grounding when
        editing a take); a config with candidates keeps the best of its seeds' composites as pipe.edit does
        (choose_candidate), and records every candidate's distance and check."""
        groups: dict[tuple, list] = {}
        inverted = "inversion" in kw
        for config, ckw in configs.items():
            if ckw.get("product"):       # the edit exactly as pipe.edit makes it (ranking and fallback inside)
                inp = make(**{k: v for k, v in ckw.items() if k != "product"})
                t = time.perf_counter()
                out = pipe.edit(target=target, edits=[inp], num_steps=None if inverted else args.steps, **kw)
                seconds = time.perf_counter() - t
                rec = out.settings.get("inpaint_candidates")
                ranking = None
                if rec is not None:
                    ranking = dict(candidates=len(rec["seeds"]), chosen=rec["chosen"], distances=rec["distances"],
                                   score=rec["score"], seam_ratios=rec["seam_ratios"], seam_bound=rec["seam_bound"],
                                   fallback=rec.get("fallback"))
                record(kind, name, blend, config, out.edits[0], target, out, seconds, ranking)
                continue
            samp, post, rank = split_config(ckw)
            groups.setdefault(tuple(sorted(samp.items())), []).append((config, post, rank))
        for samp, members in groups.items():
            base = make(**dict(samp), composite=False)
            # each config's ranking (candidates "auto" resolved as pipe.edit does); the candidates sampled one by one
            members = [(config, post, dataclasses.replace(base, **rank)) for config, post, rank in members]
            members = [(config, post, spec.candidates_for(inverted), spec.score, spec.seam_bound)
                       for config, post, spec in members]
            base = dataclasses.replace(base, candidates=1)
            raws, seconds = [], []
            for seed in range(max(m[2] for m in members)):
                t = time.perf_counter()
                raws.append(pipe.edit(target=target, edits=[dataclasses.replace(base, seed=base.seed + seed)],
                                      num_steps=None if "inversion" in kw else args.steps, ground=False, **kw))
                seconds.append(time.perf_counter() - t)
            for config, post, k, score, bound in members:
                inp = dataclasses.replace(base, **{"composite": True, **post})
                outs = []
                for raw in raws[:k]:
                    out = composite_output(pipe, raw, [inp]) if inp.composite else raw
                    outs.append(ground_edit(pipe, out) if "inversion" in kw else out)
                ranking = None
                if k > 1:
                    ranked = dataclasses.replace(inp, candidates=k, score=score, seam_bound=bound)
                    ratios = candidate_seam_ratios(outs, ranked)
                    best, dists, window = choose_candidate(outs, ranked, scorer, inverted=inverted, skeleton=sk.name,
                                                           seam_ratios=ratios)
                    checks = [target_check(measure(pipe, o, inp, target, sk)) for o in outs]
                    ranking = dict(candidates=k, chosen=best, distances=dists, scored_frames=list(window),
                                   score=ranked.score_for(inverted), candidate_checks=checks, seam_ratios=ratios,
                                   seam_bound=ranked.seam_bound_for(inverted))
                    outs = [outs[best]]
                    if ranked.score_for(inverted) == "first_smooth":     # the product stops at the first smooth one
                        k = best + 1 if ratios[best] <= ranked.seam_bound_for(inverted) else k
                        ranking["candidates_run"] = k
                record(kind, name, blend, config, inp, target, outs[0], sum(seconds[:k]), ranking)

    def real_cases(kind, takes, configs, blends, only=None):
        for it in takes:
            inv = pipe.invert(it["features"], it["prompt"], num_steps=args.steps)
            print(f"inverted {it['id']}: {inv.errors['inversion_mpjpe'] * 100:.2f} cm", flush=True)
            if only != "frames":
                run(f"{kind}/parts", it["id"], 0, part_configs(configs), lambda **k: Inpaint(parts="arms", **k),
                    "a man waves his right hand", inversion=inv)
            m = len(it["features"])         # the middle third of the take (whole latent frames)
            span = (4 * round(m / 12), 4 * round(m / 6))
            for blend in blends if only != "parts" else ():
                run(f"{kind}/frames", it["id"], blend, span_configs(configs),
                    lambda **k: Inpaint(frames=span, blend=blend, **k), "a person jumps", inversion=inv)

    def generated_spans(kind, sources, seeds, configs):
        """Each source generated from each seed, its SPANS regenerated from each of SPAN_TARGETS."""
        for seed in seeds:
            for src in sources:
                for target in SPAN_TARGETS:
                    for span in SPANS:
                        for blend in blends:
                            run(kind, f"{src} s{seed}", blend, span_configs(configs),
                                lambda span=span, blend=blend, **k: Inpaint(frames=span, blend=blend, **k),
                                target, source=src, lengths=n, seed=seed)

    if args.tuning:
        grid = select_grid(args.grid, ap.error) if args.grid else tuning_grid()
        takes = tuning_takes(args.offset + args.tuning, n)[args.offset:]
        real_cases("tuning", takes, grid, blends, only=args.only)
    elif args.tuning_generated:
        grid = select_grid(args.grid or ",".join(GENERATED_SPAN_ROWS), ap.error)
        generated_spans("tuning-gen/frames", TUNING_SPAN_SOURCES, tuple(args.generated_seeds), grid)
    else:
        configs = select_grid(args.grid, ap.error) if args.grid else CONFIGS
        if not args.skip_generated:
            for seed in range(args.seeds):
                for src in SOURCES:
                    for parts, target in PART_TARGETS:
                        run("gen/parts", f"{src} s{seed}", 0, part_configs(configs),
                            lambda parts=parts, **k: Inpaint(parts=parts, **k), target, source=src, lengths=n,
                            seed=seed)
                generated_spans("gen/frames", SPAN_SOURCES, (seed,), configs)
        if not args.skip_real:
            real_cases("real", real_takes(sk, n), configs, blends)

    summary = {}
    for kind in sorted({r["kind"] for r in rows}):
        for config in dict.fromkeys(r["config"] for r in rows if r["kind"] == kind):
            for blend in sorted({r["blend"] for r in rows if r["kind"] == kind and r["config"] == config}):
                sel = [r for r in rows if r["kind"] == kind and r["blend"] == blend and r["config"] == config]
                summary[f"{kind} {config} blend={blend}"] = summarize(sel)
                if kind.endswith("frames"):     # the turning target separately: its kept frames follow the turn
                    for tag, keep in (("turn", True), ("no turn", False)):
                        sub = [r for r in sel if ("turns" in r["target"]) == keep]
                        if sub and len(sub) < len(sel):
                            summary[f"{kind} {config} blend={blend} ({tag})"] = summarize(sub)
    cols = ("cases", "kept_cm", "kept_cm_max", "kept_pose_cm", "kept_within_2cm", "kept_segment_within_2cm",
            "edited_cm", "seam_jerk_ratio",
            "seam_within_1.5x", "target_check_pass", "check_pass", "check_span_pass", "check_pass_fresh", "fresh_cases",
            "seconds", "any_candidate_pass", "random_candidate_pass", "first_candidate_pass", "chosen_not_first",
            "seam_fallback")
    print("\ntarget_check_pass is the target's check: over the regenerated span for frame spans (check_span_pass), "
          "over the whole motion for body parts (check_pass); seconds: one sampling run (shared by the settings "
          "that differ only after decoding; with candidates: the K runs); *_candidate_pass (best of K): the target "
          "check of any of the K candidates, of a random one (expected), of the first (seed 0)")
    print("\n| setting | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for k, v in summary.items():
        cells = [("-" if v.get(c) is None else (f"{v[c]:.2f}" if isinstance(v[c], float) else str(v[c]))) for c in cols]
        print(f"| {k.replace('|', '/')} | " + " | ".join(cells) + " |")
    finish_run({"settings": run_settings(args), "summary": summary, "rows": rows}, t0, args.json)


if __name__ == "__main__":
    main()
