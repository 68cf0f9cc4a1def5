"""Build the general-motion set (uncaptioned procedural motion for VAE training, issue 21).

Usage::

    python scripts/build_general_motion.py --out data/general --n 4000 --seed 0 [--workers 2] [--force]

Writes new_joint_vecs/, new_joints/, train/val/test/all.txt, Mean.npy, Std.npy and general.json
(see :mod:`salad_core.data.procedural.general_build`) and prints the summary: motions per mode,
frames and the round-trip error of the HumanML3D representation on the set.
"""
from __future__ import annotations

import argparse
import json
import time

from salad_core.data.procedural.general_build import build_general


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="folder to write (HumanML3D layout, no texts)")
    ap.add_argument("--n", type=int, default=4000, help="motions (default 4000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=None, help="processes (default: up to 2)")
    ap.add_argument("--force", action="store_true", help="replace a set already in --out")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    summary = build_general(args.out, n=args.n, seed=args.seed, workers=args.workers, overwrite=args.force)
    print(json.dumps(summary, indent=2))
    print(f"built {args.n} motions in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
