#!/usr/bin/env python
"""KeyMotion's ship rule (lab/docs/keymotion.md, "A one-action prompt asked for longer ...": fixed before v3-rest and
v4 were measured), read from the records of ``evaluate_keymotion.sh OUT physics10 sides stretch diversity t2m``.

A candidate replaces KeyMotion 0.2 only if, against 0.2 on the physics benchmark with 10 seeds (its shown joints,
its default settings):

* flight: the median per-segment flight fit of the 4 jump prompts (jumping jacks left out) is closer to gravity
  than 0.2's -6.77 m/s^2;
* feet: stance sliding on the forward walks and runs (the benchmark's "[field]" row, pooled over stance phases) is
  at most 0.265 m/s (0.2's 0.245 plus the seed noise seen between runs, 0.02);
* the per-action checks pass at least 0.2's 509 of 640;
* on seeds 0-2 the named-side checks pass at least 24 of 30 (the 10 prompts that name a side of a turn, kick, wave,
  raised arm or punch; a prompt passes on a seed when its side-bearing checks, ``turn_deg`` and
  ``arm_ratio``/``leg_ratio`` of the named side, pass);
* seed diversity at least 20 cm;
* Table 1 with the packaged evaluator (``t2m/results.json``) not worse than 0.2: top-3 >= 0.677, FID <= 2.14.

The stretch probe's peak speeds (``stretch.json``: the pace should no longer fall with the length asked for) are
printed beside, as ratios of 120 and 196 frames to 40, without a bound (the rule names none).

    python lab/scripts/keymotion/keymotion_ship_rule.py OUT [--baseline lab/records/physics/keymotion-0.2_10-seeds.json]

Prints one line per rule and the verdict; exits 0 when every rule with its record present passes, 1 when one fails,
2 when a record the rule needs is missing. ``--baseline`` prints the same readings of another 10-seed benchmark
record (0.2's) beside, to check that the readings reproduce the rule's reference figures.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from salad_core.eval.physics import GRAVITY
from salad_core.eval.physics_prompts import targets

JUMP_PROMPTS = ("a person jumps", "a man is jumping high", "a person hops in place", "a man jumps forward")
SIDE_ACTIONS = ("turn", "kick", "wave", "raise", "punch")
SIDE_MEASURES = ("turn_deg", "arm_ratio", "leg_ratio")
REFERENCE_FLIGHT = -6.77          # 0.2's flight fit, 10 seeds
MAX_SLIDE = 0.265                 # m/s
MIN_CHECKS = 509                  # of 640
MIN_NAMED_SIDE = 24               # of 30
MIN_DIVERSITY_CM = 20.0
MIN_TOP3, MAX_FID = 0.677, 2.14


def _generator(result: dict) -> dict:
    gens = result["generators"]
    if "KeyMotion" not in gens:
        raise ValueError(f"no KeyMotion generator in the record (has {sorted(gens)})")
    return gens["KeyMotion"]


def flight_fit(result: dict) -> tuple[float | None, int, int]:
    """Median per-segment flight fit (m/s^2) over the motions of :data:`JUMP_PROMPTS`, the motions with a flight
    segment, and the motions."""
    motions = [r.get("flight_segment_accels") or [] for p in _generator(result)["prompts"] if p["text"] in JUMP_PROMPTS
               for r in p["reports"]]
    segs = [a for m in motions for a in m if a is not None]
    return (float(np.median(segs)) if segs else None), sum(1 for m in motions if m), len(motions)


def stance_sliding(result: dict) -> float | None:
    """The benchmark's "[field] stance sliding on the forward walks and runs" value for KeyMotion (m/s)."""
    row = next(r for r in targets(result) if r["target"].startswith("[field] stance sliding"))
    return row["cells"]["KeyMotion"][0]


def named_side(result: dict, seeds=(0, 1, 2)) -> tuple[int, int]:
    """``(passed, total)`` named-side checks over the prompts of :data:`SIDE_ACTIONS` that name a side, on ``seeds``."""
    passed = total = 0
    for p in _generator(result)["prompts"]:
        if p["action"] not in SIDE_ACTIONS or not {"left", "right"} & set(p["text"].split()):
            continue
        for seed, row in zip(p["seeds"], p["checks"]):
            if seed not in seeds:
                continue
            side = [c for c in row if c["check"].split()[0].split("[")[0] in SIDE_MEASURES]
            if not side:
                continue
            total += 1
            passed += all(c["passed"] for c in side)
    return passed, total


def benchmark_readings(result: dict) -> dict:
    g = _generator(result)
    fit, found, motions = flight_fit(result)
    side = named_side(result)
    return {"flight_fit": fit, "flight_found": f"{found}/{motions}", "stance_sliding": stance_sliding(result),
            "checks": (g["checks_passed"], g["checks_total"]), "named_side": side,
            "seed_diversity_cm": g["aggregate"].get("seed_diversity_cm"), "seeds": len(g["prompts"][0]["seeds"])}


def table1(path: Path) -> dict | None:
    """``{"top3": (mean, interval), "fid": (mean, interval)}`` of the KeyMotion row of ``results.json``."""
    if not path.exists():
        return None
    rows = [r for r in json.loads(path.read_text()) if r.get("settings", {}).get("kind") != "real"]
    if not rows:
        return None
    s = rows[0]["summary"]
    return {"name": rows[0]["name"], "top3": tuple(s["R-precision top-3"]), "fid": tuple(s["FID"])}


def stretch_ratios(path: Path) -> list[str]:
    """Lines of the probe's peak speed at 120 and 196 frames over the one at 40, per model and prompt
    (``stretch.json``: ``{"stretch": {model: {prompt: {length: {"peak_speed": ...}}}}}``)."""
    if not path.exists():
        return []
    lines = []
    for model, prompts in json.loads(path.read_text()).get("stretch", {}).items():
        for prompt, by_length in prompts.items():
            peak = {int(k): v["peak_speed"] for k, v in by_length.items()}
            if peak.get(40):
                lines.append(f"    {model:10s} {prompt:36s} 120/40 {peak.get(120, float('nan')) / peak[40]:.2f}  "
                             f"196/40 {peak.get(196, float('nan')) / peak[40]:.2f}")
    return lines


def verdict(out: Path, baseline: Path | None = None) -> int:
    physics = out / "physics10" / "physics.json"
    if not physics.exists():
        print(f"missing {physics}: run evaluate_keymotion.sh {out} physics10", file=sys.stderr)
        return 2
    r = benchmark_readings(json.loads(physics.read_text()))
    if r["seeds"] != 10:
        print(f"{physics} has {r['seeds']} seeds per prompt; the rule reads the 10-seed benchmark (physics10)",
              file=sys.stderr)
        return 2
    b = benchmark_readings(json.loads(baseline.read_text())) if baseline else None
    rules = []

    def rule(name, value, ok, ref=""):
        rules.append(ok)
        base = f"   [baseline {ref}]" if b is not None else ""
        print(f"{'PASS' if ok else 'FAIL'}  {name}: {value}{base}")

    fit = r["flight_fit"]
    closer = fit is not None and abs(fit + GRAVITY) < abs(REFERENCE_FLIGHT + GRAVITY)
    rule(f"flight fit of the 4 jump prompts closer to -9.81 than {REFERENCE_FLIGHT}",
         f"{fit:.2f} m/s^2 (flight in {r['flight_found']} motions)" if fit is not None else "no flight", closer,
         b and f"{b['flight_fit']:.2f}, {b['flight_found']}")
    sl = r["stance_sliding"]
    rule(f"stance sliding on walks and runs <= {MAX_SLIDE}", f"{sl:.3f} m/s", sl is not None and sl <= MAX_SLIDE,
         b and f"{b['stance_sliding']:.3f}")
    c = r["checks"]
    rule(f"per-action checks >= {MIN_CHECKS}/640", f"{c[0]}/{c[1]}", c[0] >= MIN_CHECKS and c[1] == 640,
         b and f"{b['checks'][0]}/{b['checks'][1]}")
    ns = r["named_side"]
    rule(f"named-side checks on seeds 0-2 >= {MIN_NAMED_SIDE}/30", f"{ns[0]}/{ns[1]}",
         ns[0] >= MIN_NAMED_SIDE and ns[1] == 30, b and f"{b['named_side'][0]}/{b['named_side'][1]}")
    dv = r["seed_diversity_cm"]
    rule(f"seed diversity >= {MIN_DIVERSITY_CM:.0f} cm", f"{dv:.1f} cm", dv is not None and dv >= MIN_DIVERSITY_CM,
         b and f"{b['seed_diversity_cm']:.1f}")
    t = table1(out / "t2m" / "results.json")
    if t is None:
        print(f"missing {out / 't2m' / 'results.json'}: run evaluate_keymotion.sh {out} t2m", file=sys.stderr)
        return 2
    rule(f"Table 1 (packaged evaluator) top-3 >= {MIN_TOP3} and FID <= {MAX_FID}",
         f"top-3 {t['top3'][0]:.3f} +- {t['top3'][1]:.3f}, FID {t['fid'][0]:.2f} +- {t['fid'][1]:.2f}",
         t["top3"][0] >= MIN_TOP3 and t["fid"][0] <= MAX_FID, b and "0.677 / 2.14 (model card)")
    lines = stretch_ratios(out / "stretch.json")
    if lines:
        print("stretch probe, peak speed ratios (no bound):")
        print("\n".join(lines))
    ok = all(rules)
    print(f"verdict: {'ship' if ok else 'keep 0.2'} ({sum(rules)} of {len(rules)} rules pass)")
    return 0 if ok else 1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="evaluate_keymotion.sh's results folder")
    ap.add_argument("--baseline", type=Path, default=None, help="another 10-seed physics.json to read beside")
    args = ap.parse_args(argv)
    return verdict(args.out, args.baseline)


if __name__ == "__main__":
    sys.exit(main())
