#!/usr/bin/env python
"""Print the Corpus 2.0 targets (issue 27) of a procedural corpus folder, measured, with PASS/FAIL.

Usage::

    python scripts/corpus_stats.py CORPUS_DIR [--reference tests/data/humanml3d_sample]
                                   [--max-clips N] [--mirrors] [--json OUT.json]

``--reference`` is a HumanML3D-layout folder: its ``Std.npy`` (aggregate statistics of the real
dataset) is the reference of the feature-std ratios and its clips' foot sliding is printed beside
the corpus's. Definitions of every figure: :mod:`salad_core.data.procedural.stats`.
Relative targets use the figures of the generator 1.0 corpus (``stats.BASELINE``).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

from salad_core.data.procedural.stats import corpus_realism, targets_table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("corpus", help="corpus folder (salad corpus build --out ...)")
    ap.add_argument("--reference", default=None, help="HumanML3D-layout folder with the real Std.npy")
    ap.add_argument("--max-clips", type=int, default=None, help="measure only the first N clips")
    ap.add_argument("--mirrors", action="store_true", help="include the mirrored clips M<id>")
    ap.add_argument("--json", default=None, help="also write the raw figures to this file")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    fig = corpus_realism(args.corpus, reference=args.reference, max_clips=args.max_clips, mirrors=args.mirrors)
    rows = targets_table(fig)
    w = max(len(r.name) for r in rows)
    v = max(len(r.value) for r in rows)
    print(f"corpus {args.corpus}: {fig['clips']} clips, {fig['captions']} captions "
          f"({time.perf_counter() - t0:.0f} s)")
    for r in rows:
        verdict = {True: "PASS", False: "FAIL", None: "  - "}[r.passed]
        print(f"{verdict}  {r.name:<{w}}  {r.value:>{v}}   target {r.goal}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(fig, fh, indent=2)
    return 0 if all(r.passed is not False for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
