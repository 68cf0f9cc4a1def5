#!/usr/bin/env python
"""Merge guidance-sweep records measured in separate runs into one record, and choose again.

    python lab/scripts/guidance/merge_guidance_sweeps.py salad_core/weights/salad/guidance_sweep.json RUN2/guidance_sweep.json \
        [...] --out merged/

``salad eval --guidance-sweep`` measures a grid (weights x rescales x intervals) and chooses the default by the rule
of :func:`salad_core.eval.guidance_sweep.choose`. Candidates that are not one grid (say, an interval at three weights
and a rescale at two), or that were measured in different sessions, come as several records. They may be merged
only if they were measured alike: the same T2M protocol, benchmark and rule settings, the same data and recovery,
the same weights and evaluator (their content digests, ``settings["identity"]``, recorded by sweeps since session 19;
an older record without them is merged on the user's word, with a note), and the same real-motion row (equal up to
float rounding, i.e. the same clips and evaluator); a candidate may appear once. The
merged record keeps the first record's settings, lists where each row came from, and its ``chosen`` is the rule's
choice over all rows. Writes ``guidance_sweep.json`` and ``guidance_sweep.md`` into ``--out``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

#: Settings that must agree for records to be merged (the rest, e.g. timing, may differ).
SAME_SETTINGS = ("t2m", "bench", "rule", "data", "recovery")


def merge_records(records: list[dict], sources: list[str]) -> dict:
    """One record from ``records`` (each as ``salad eval --guidance-sweep`` wrote it), checked (module docstring)."""
    from salad_core.eval.guidance_sweep import choose

    if len(records) < 2:
        raise ValueError("give at least two sweep records to merge")
    first = records[0]
    notes: list[str] = []
    for rec, src in zip(records[1:], sources[1:]):
        for key in SAME_SETTINGS:
            a, b = first["settings"].get(key), rec["settings"].get(key)
            if a != b:
                raise ValueError(f"{src} was measured with other {key!r} settings than {sources[0]}: {b!r} against {a!r}")
        ida, idb = first["settings"].get("identity"), rec["settings"].get("identity")
        if ida and idb:
            for key in ("weights", "evaluator"):
                if ida.get(key) != idb.get(key):
                    raise ValueError(f"{src} measured other {key} than {sources[0]} (digest {idb.get(key)} against "
                                     f"{ida.get(key)})")
        else:
            notes.append(f"{src if not idb else sources[0]} records no weights digest: the same weights are assumed")
        for metric, value in first["real"].items():
            other = rec["real"].get(metric, {}).get("mean")
            if other is None or not math.isclose(other, value["mean"], rel_tol=1e-5, abs_tol=1e-9):
                raise ValueError(f"{src}: the real-motion {metric} ({other}) differs from {sources[0]}'s "
                                 f"({value['mean']}): not the same clips or evaluator")
    rows, seen = [], {}
    for rec, src in zip(records, sources):
        for row in rec["rows"]:
            key = json.dumps(row["guidance"], sort_keys=True)
            if key in seen:
                raise ValueError(f"candidate {row['label']} is in both {seen[key]} and {src}")
            seen[key] = src
            rows.append(dict(row, source=src))
    pick, why = choose(rows)
    settings = dict(first["settings"], merged_from=list(sources), merge_notes=sorted(set(notes)))
    return dict(first, rows=rows, settings=settings, chosen={"index": pick, "why": why, "guidance": rows[pick]["guidance"]})


def main(argv=None) -> int:
    from salad_core.eval.guidance_sweep import sweep_markdown

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("records", nargs="+", type=Path, help="guidance_sweep.json files")
    ap.add_argument("--out", required=True, type=Path, help="folder for the merged guidance_sweep.{json,md}")
    args = ap.parse_args(argv)
    missing = [str(p) for p in args.records if not p.is_file()]
    if missing:
        raise SystemExit(f"no such sweep record: {', '.join(missing)}")
    try:
        merged = merge_records([json.loads(p.read_text()) for p in args.records], [str(p) for p in args.records])
    except ValueError as err:
        raise SystemExit(f"cannot merge: {err}") from None
    md = sweep_markdown(merged, merged["chosen"]["index"]) + f"\n\nChosen: {merged['chosen']['why']}.\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "guidance_sweep.json").write_text(json.dumps(merged, indent=1, default=str) + "\n")
    (args.out / "guidance_sweep.md").write_text(md)
    print(md)
    for note in merged["settings"]["merge_notes"]:
        print("note:", note)
    print('pipeline.json entry: "guidance": ' + json.dumps(merged["chosen"]["guidance"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
