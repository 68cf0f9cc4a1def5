"""Foot skating of the general-motion set, mode by mode (issue 20's skating lever, issue 21's VAE data).

    python lab/scripts/vae/general_skating.py [--clips 40] [--seed 7]

For each mode of :data:`salad_core.data.procedural.general.MODES`, ``--clips`` clips are drawn
(``sample_general(default_rng([seed, i, mode index]), mode=...)``) and passed through the HumanML3D
features (``joints_to_features`` -> ``features_to_joints``, what a VAE trained on the set sees).
Printed per mode, with :mod:`salad_core.eval.physics`'s definitions (the same measure as
``salad eval --physics``): foot skating mean and p95 (m/s) over the frame pairs in contact, the share of
those faster than 10 cm/s, and how many pairs there are; last, the mean weighted by the modes' default
shares. The captioned corpus's clips skate about 0.01 m/s on the same measure.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def measure_mode(mode: str, clips: int, seed: int) -> dict[str, float]:
    """Skating figures of ``clips`` clips of ``mode`` (see the module docstring)."""
    from salad_core.data.procedural.general import MODES, sample_general
    from salad_core.eval.physics import foot_skating
    from salad_core.motion import features_to_joints, joints_to_features

    speeds = []
    k = list(MODES).index(mode)
    for i in range(clips):
        clip = sample_general(np.random.default_rng([seed, i, k]), mode=mode)
        speeds.append(foot_skating(features_to_joints(joints_to_features(clip.joints))))
    s = np.concatenate(speeds)
    return {"mean": float(s.mean()), "p95": float(np.percentile(s, 95)), "share": float((s > 0.10).mean()),
            "pairs": int(len(s))}


def main(argv=None) -> int:
    from salad_core.data.procedural.general import MODES
    from salad_core.data.procedural.general_build import GENERAL_VERSION

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=40, help="clips per mode (default 40)")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args(argv)
    if args.clips < 1:
        ap.error(f"--clips={args.clips} must be >= 1")
    t0 = time.perf_counter()
    print(f"general-motion generator {GENERAL_VERSION}, {args.clips} clips per mode, seed {args.seed}")
    print(f"{'mode':<11} {'skating mean':>12} {'p95':>6} {'> 0.1 m/s':>9} {'pairs':>6}")
    total, pairs = 0.0, 0
    for mode in MODES:
        r = measure_mode(mode, args.clips, args.seed)
        total += r["mean"] * r["pairs"] * MODES[mode]
        pairs += r["pairs"] * MODES[mode]
        print(f"{mode:<11} {r['mean']:>12.3f} {r['p95']:>6.3f} {r['share']:>9.2f} {r['pairs']:>6d}")
    print(f"{'weighted':<11} {total / pairs:>12.3f}   (modes weighted by their default shares)")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
