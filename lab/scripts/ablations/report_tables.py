#!/usr/bin/env python
"""Print the ablation study's tables behind lab/docs/ablations.md, from its records alone (nothing is measured).

    python lab/scripts/ablations/report_tables.py [--sections vaes denoisers]

What notebooks 06 and 07 printed before the study moved to the lab: per group the drift of every row across the
stages (salad_lab.drift), the probes beside the final stage (parameter-matched VAEs, the loss terms without the
bone-length term, the training seed, the denoiser's size), the sampler and guidance probes, the continuation with a
decaying learning rate, and each denoiser's estimate of the clean motion per noise level. Records: the shipped
study's evaluations (salad_core/weights/ablations/evaluations) and the lab's probe records (lab/records/ablations_v2).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "lab"))   # salad_lab

SHIPPED = REPO / "salad_core" / "weights" / "ablations"
STUDY = REPO / "lab" / "records" / "ablations_v2"
SHOWN = [0, 10, 50, 100, 200, 500, 800, 999]                  # of the denoising records' timesteps


def _load(path: Path):
    return json.loads(path.read_text())


def vaes() -> None:
    from salad_lab.drift import drift_markdown
    from salad_lab.probes import load_probes, paired_probe_markdown, probe_markdown

    stage = _load(SHIPPED / "evaluations" / "vaes@6000.json")
    probes = load_probes(STUDY / "probes.json")
    vae_probes = {k: p for k, p in probes.items() if p["stage"] == "vaes@6000"}
    table2 = {k: p for k, p in vae_probes.items() if p["base_variant"] == "pose_long"}
    table4 = {k: p for k, p in vae_probes.items() if p["base_variant"] != "pose_long"}
    print("**Table 2 at 6,000 steps, with the parameter-matched probe:**\n")
    print(probe_markdown(stage, table2, ["st_long", "pose_long"]))
    print("**Supplement Table 4 at 6,000 steps:**\n")
    print(probe_markdown(stage, table4, ["st_long", "no_pos", "no_vel", "no_pos_vel"]))
    print("**Supplement Table 4's pairs, paired** (the full loss's advantage, positive: the term helps; first with the "
          "study's bone-length term, then without it, the probes):\n")
    print(paired_probe_markdown(stage, vae_probes, [("st_long", "no_pos"), ("st_long", "no_vel"), ("st_long", "no_pos_vel"),
                                                    ("st_nobone", "no_pos_nobone"), ("st_nobone", "no_vel_nobone"),
                                                    ("st_nobone", "no_pos_vel_nobone")]))
    for name, probe in vae_probes.items():
        print(f"probe {name}, made by:", *probe["commands"], sep="\n  ")
    print()
    print(drift_markdown(SHIPPED, "vaes"))


def denoisers() -> None:
    from salad_lab.denoising import denoising_markdown, text_response_markdown
    from salad_lab.drift import drift_markdown
    from salad_lab.probes import (continuation_probe_markdown, continued_pairs_markdown, guidance_pair_markdown,
                                  load_probes, paired_probe_markdown, probe_markdown, sampler_probe_markdown)

    stage = _load(SHIPPED / "evaluations" / "denoisers@8000.json")
    probes = load_probes(STUDY / "probes.json")
    cont = _load(STUDY / "continuation_probe.json")
    sampler = _load(STUDY / "sampler_probe.json")
    print(drift_markdown(SHIPPED, "denoisers"))
    print(sampler_probe_markdown(sampler))
    print(continuation_probe_markdown({"lr_decay": cont["lr_decay"]}))
    print("**At 8,000 steps** (the stage's protocol; the probes on the parameter-matched VAE):\n")
    print(probe_markdown(stage, probes, ["full", "no_st", "no_both"]))
    print(paired_probe_markdown(stage, probes, [("full", "no_st"), ("full", "no_st_matched"), ("full", "no_both"),
                                                ("full", "no_both_matched")]))
    print("**The training seed at 8,000** (seed 1234: the study's rows; seed 2026: the probes):\n")
    print(paired_probe_markdown(stage, probes, [("full", "full_s2026"), ("full_s2026", "no_st_s2026"),
                                                ("no_st", "no_st_s2026")]))
    print(continuation_probe_markdown({k: cont[k] for k in ("lr_decay_pose_matched", "lr_decay_w4.5", "lr_decay_w2.5",
                                                            "lr_decay_seed2026") if k in cont}))
    print("**The training seed after the decay** (both seeds' continued rows, paired across the probes):\n")
    print(continued_pairs_markdown(cont, [("full", "full_s2026"), ("no_st", "no_st_s2026"), ("full", "no_st"),
                                          ("full_s2026", "no_st_s2026")]))
    for name, what in (("denoising_error.json", (("joints", "cond"), ("joints", "guided"), ("fid", "cond"), ("fid", "guided"))),
                       ("denoising_error_unconditional.json", (("joints", "uncond"), ("fid", "uncond")))):
        record = _load(STUDY / name)
        for metric, mode in what:
            print(f"**{metric}, {mode}**, {record['clips']} clips, {record['stage']}:\n")
            print(denoising_markdown(record, metric, mode, SHOWN))
        print(f"Made by: `{record['command']}`\n")
    print("**The ST latent against the pose latent under each guidance** (paired: + the full model better):\n")
    print(guidance_pair_markdown(stage, sampler, "full", "no_st"))
    print("**The text response**, |c - u|^2 over the conditional error |c - x0|^2:\n")
    print(text_response_markdown(_load(STUDY / "denoising_error_unconditional.json"), SHOWN))
    print("**The size probe at 8,000 steps** (the stage's protocol, w 7.5; paired: + the first better):\n")
    print(paired_probe_markdown(stage, probes, [("full_w128", "no_st_w128"), ("full", "no_st"), ("full_w128", "full"),
                                                ("no_st_w128", "no_st")]))
    print(continuation_probe_markdown({k: cont[k] for k in ("lr_decay_w128", "lr_decay_w128_w1") if k in cont}))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sections", nargs="+", choices=("vaes", "denoisers"), default=["vaes", "denoisers"])
    args = ap.parse_args(argv)
    for section in args.sections:
        print(f"# {section}\n")
        {"vaes": vaes, "denoisers": denoisers}[section]()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
