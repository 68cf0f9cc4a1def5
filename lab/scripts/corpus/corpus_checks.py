"""Print the quality figures of a procedural corpus.

    python lab/scripts/corpus/corpus_checks.py                # builds a tiny corpus in a temporary folder
    python lab/scripts/corpus/corpus_checks.py DIR            # measures the corpus in DIR
    python lab/scripts/corpus/corpus_checks.py --size default --keep DIR   # builds DIR (timed), then measures

Figures: bone-length std and error, lowest joint, foot sliding of the corpus against the real
HumanML3D sample 012314 (same measure), joint-angle ranges, per-phrase body-part activity ratios
(driven parts against idle parts, and against every part no phrase drives), caption counts,
and how much the modifiers change the motion.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]
SAMPLE = REPO / "tests" / "data" / "humanml3d_sample"


def _du(path: Path) -> int:
    return sum(p.stat().st_blocks * 512 for p in path.rglob("*") if p.is_file())


def modifier_effects(seeds=range(4)) -> dict[str, dict[str, float]]:
    """Mean of a motion measure per modifier, on freshly generated single-action clips."""
    from salad_core.data.procedural import Action, Plan, Step, realise
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton("humanml3d")
    wrist = sk.joint_names.index("left_wrist")
    ankle = sk.joint_names.index("right_ankle")

    def clip(kind, side, mods, s):
        return realise(Plan((Step(Action(kind, side, mods)),)), np.random.default_rng(s))

    def speed(c):
        f0, f1 = c.events[0].frames
        return float(np.linalg.norm(c.joints[f1 - 1, 0, [0, 2]] - c.joints[f0, 0, [0, 2]]) / ((f1 - f0) / 20))

    table = {
        "jump apex pelvis height (m)": ("jump", None, lambda c: c.joints[:, 0, 1].max(), ((), ("high",), ("low",))),
        "raise: top wrist height (m)": ("raise", "left", lambda c: c.joints[:, wrist, 1].max(), ((), ("high",), ("low",))),
        "kick: top ankle height (m)": ("kick", "right", lambda c: c.joints[:, ankle, 1].max(), ((), ("high",), ("low",))),
        "walk: root speed (m/s)": ("walk", None, speed, ((), ("slowly",), ("quickly",))),
        "squat: lowest pelvis (m)": ("squat", None, lambda c: c.joints[:, 0, 1].min(), ((), ("low",))),
        "wave: duration (s)": ("wave", "right", lambda c: np.diff(c.events[0].frames)[0] / 20, ((), ("slowly",), ("quickly",))),
    }
    out = {}
    for name, (kind, side, measure, variants) in table.items():
        out[name] = {(" ".join(m) or "plain"): round(float(np.mean([measure(clip(kind, side, m, s)) for s in seeds])), 3)
                     for m in variants}
    return out


def main(argv=None) -> int:
    from salad_core.data.procedural import build_corpus, corpus_figures

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", nargs="?", help="corpus folder to measure (default: build a tiny one)")
    ap.add_argument("--size", default="tiny", help="size to build when DIR is absent or --keep is given")
    ap.add_argument("--keep", metavar="OUT", help="build into OUT (kept) instead of a temporary folder")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--reference", default=str(SAMPLE), help="HumanML3D-layout folder for the foot-sliding reference")
    args = ap.parse_args(argv)

    tmp = None
    if args.dir and not args.keep:
        root = Path(args.dir)
    else:
        if args.keep:
            root = Path(args.keep)
        else:
            tmp = tempfile.TemporaryDirectory()
            root = Path(tmp.name) / "corpus"
        t0 = time.perf_counter()
        summary = build_corpus(root, size=args.size, seed=args.seed, progress=True, overwrite=bool(args.keep))
        print(f"built {summary['clips']} clips ({summary['motions']} motions + mirrors) in "
              f"{time.perf_counter() - t0:.1f} s; {_du(root) / 2**20:.0f} MiB on disk")
    t0 = time.perf_counter()
    f = corpus_figures(root, reference=args.reference if Path(args.reference).is_dir() else None)
    summary = json.loads((root / "corpus.json").read_text())
    print(f"\ncorpus {root}  (measured in {time.perf_counter() - t0:.1f} s)")
    print(f"  clips {f['clips']}  captions {f['captions']}  (min per clip {f['captions_per_clip_min']})  "
          f"phrases {f['phrases']}  frames mean {summary['frames']['mean']} [{summary['frames']['min']}, "
          f"{summary['frames']['max']}]")
    print(f"  splits {summary['splits']}")
    print(f"  bone length std max          {f['bone_length_std_max']:.2e} m  (error vs target {f['bone_length_error_max']:.2e} m)")
    print(f"  lowest joint                 {f['min_joint_height']:+.4f} m")
    ref = f.get("foot_sliding_reference")
    ref_s = f"{ref:.4f} m/s" if ref is not None else "n/a"
    print(f"  foot sliding (feet on floor) {f['foot_sliding']:.4f} m/s   HumanML3D 012314: {ref_s}")
    print(f"  knee flexion max {f['knee_flexion_max_deg']:.0f} deg, elbow {f['elbow_flexion_max_deg']:.0f} deg, "
          f"ankle angle {f['ankle_angle_range_deg'][0]:.0f}-{f['ankle_angle_range_deg'][1]:.0f} deg, "
          f"knee bend sense min {f['knee_bend_min']:+.3f}")
    print(f"  phrase parts vs idle parts   min ratio {f['phrase_ratio_idle_min']:.2f}, median "
          f"{f['phrase_ratio_idle_median']:.1f}, pass {100 * f['phrase_ratio_idle_pass']:.1f}%")
    print(f"  phrase parts vs all others   median ratio {f['phrase_ratio_others_median']:.2f}, pass "
          f"{100 * f['phrase_ratio_others_pass']:.1f}%  (others include incidental motion such as arm swing)")
    print(f"  driven part activity min     {f['phrase_driven_activity_min']:.3f} m/s")
    print(f"  captions in the language     {100 * f['captions_in_language']:.1f}%   mirror annotations consistent "
          f"{100 * f['mirror_annotations_consistent']:.1f}%")
    print("  primitives:", ", ".join(f"{k} {v}" for k, v in summary["primitives"].items()))
    print("\nmodifier effects (mean of 4 generated clips):")
    for name, row in modifier_effects().items():
        print(f"  {name:32s} " + "  ".join(f"{k}={v}" for k, v in row.items()))
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
