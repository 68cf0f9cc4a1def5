"""The ablation study: recipe parsing, job planning, and a tiny end-to-end train -> ship -> load."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_lab import (list_ablations, load_ablation_pipeline, load_ablation_vae, load_recipe, plan_jobs,
                                  run_jobs, ship)
from salad_core.models.denoiser import DenoiserConfig
from salad_core.models.vae import VAEConfig
from salad_core.io import config_from_dict
from _doubles import make_fake_corpus

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402


def test_long_table3_recipe_differs_from_the_study_only_in_the_denoiser_budget(tmp_path):
    """lab/configs/ablations_table3_long.json (the 2,500-step check in the ablation model card): the same
    VAEs and denoiser models as the shipped study, only the denoisers' step budget changes."""
    short = {j.run_dir.name: j.config for j in plan_jobs(load_recipe(REPO / "lab" / "configs" / "ablations.json"), tmp_path)}
    long = {j.run_dir.name: j.config for j in plan_jobs(load_recipe(REPO / "lab" / "configs" / "ablations_table3_long.json"),
                                                          tmp_path)}
    assert {n for n in long if n.startswith("den_")} == {"den_full", "den_no_st"}
    for name, config in long.items():
        if name.startswith("vae_"):
            assert config == short[name]
        else:
            assert {k: config[k] for k in config if k != "train"} == {k: short[name][k] for k in short[name] if k != "train"}
            assert config["train"]["max_steps"] == 2500 and short[name]["train"]["max_steps"] == 700
            strip = ("max_steps", "val_every", "ckpt_every")
            assert {k: v for k, v in config["train"].items() if k not in strip} == \
                {k: v for k, v in short[name]["train"].items() if k not in strip}


def test_shipped_recipe_plans_every_table_row(tmp_path):
    recipe = load_recipe(REPO / "lab" / "configs" / "ablations.json")
    jobs = plan_jobs(recipe, tmp_path)
    by_name = {j.variant.name: j for j in jobs}
    assert {n for n, j in by_name.items() if j.variant.kind == "vae"} == \
        {"st", "no_pos", "no_vel", "no_pos_vel", "st_long", "pose_long"}
    assert {n for n, j in by_name.items() if j.variant.kind == "denoiser"} == \
        {"full", "no_st", "no_cross", "no_both", "eps", "x0", "no_film"}
    # the denoisers learn on Table 2's pair of VAEs
    assert {j.depends_on.name for j in jobs if j.depends_on is not None} == {"vae_st_long", "vae_pose_long"}
    assert by_name["no_st"].depends_on.name == by_name["no_both"].depends_on.name == "vae_pose_long"
    # VAE jobs come before the denoisers that need them
    order = [j.run_dir.name for j in jobs]
    for j in jobs:
        if j.depends_on is not None:
            assert order.index(j.depends_on.name) < order.index(j.run_dir.name)
    # every VAE variant trains with the same recipe except its own overrides
    st, nopos = by_name["st"].config, by_name["no_pos"].config
    assert st["train"] == nopos["train"] and st["train"]["max_steps"] == 400
    assert nopos["model"]["lambda_pos"] == 0.0 and "lambda_pos" not in recipe.variant("st").model
    # Table 2's pair has a budget of its own (a variant's "train" overrides the shared one), equal for both
    long_st, long_pose = by_name["st_long"].config, by_name["pose_long"].config
    assert long_st["train"] == long_pose["train"] and long_st["train"]["max_steps"] == 1500
    assert long_st["train"]["batch_size"] == st["train"]["batch_size"]          # the rest is inherited
    assert long_pose["model"]["kind"] == "pose" and recipe.variant("st_long").table == "Table 2"
    # denoisers are sized to their VAE's latent: the pose VAE gives one 224-channel token per frame
    vae_pose = config_from_dict(VAEConfig, by_name["pose_long"].config["model"])
    no_st = config_from_dict(DenoiserConfig, by_name["no_st"].config["model"])
    full = config_from_dict(DenoiserConfig, by_name["full"].config["model"])
    assert (no_st.num_parts, no_st.latent_dim) == (vae_pose.num_parts, vae_pose.z_dim) == (1, 224)
    assert (full.num_parts, full.latent_dim) == (7, 32)
    assert full.width == no_st.width == 96 and full.layers == 3
    assert by_name["no_cross"].config["model"]["cross_attention"] is False
    assert by_name["no_film"].config["model"]["film"] is False
    assert by_name["eps"].config["diffusion"]["prediction_type"] == "epsilon"
    assert by_name["x0"].config["diffusion"]["prediction_type"] == "sample"
    assert by_name["full"].config["diffusion"] == {} or \
        by_name["full"].config["diffusion"].get("prediction_type", "v_prediction") == "v_prediction"
    # all denoisers share one budget
    assert len({json.dumps(j.config["train"], sort_keys=True) for j in jobs if j.variant.kind == "denoiser"}) == 1


def _write_recipe(tmp_path: Path, vaes: dict, denoisers: dict) -> Path:
    (tmp_path / "vae.json").write_text(json.dumps({"model": {"latent_dim": 8, "n_extra_layers": 0}, "train": {}}))
    (tmp_path / "den.json").write_text(json.dumps({"model": {"width": 32, "heads": 2, "ff_dim": 64, "layers": 1,
                                                             "text_dim": 384}, "train": {}}))
    doc = {"vae_base": "vae.json", "denoiser_base": "den.json",
           "vae_train": {"batch_size": 8, "max_steps": 2, "window": 64, "warmup_steps": 1, "milestones": [],
                         "val_every": 0, "ckpt_every": 0, "num_threads": 1},
           "denoiser_train": {"batch_size": 4, "max_steps": 2, "warmup_steps": 1, "milestones": [], "max_length": 64,
                              "val_every": 0, "ckpt_every": 0, "num_threads": 1},
           "vaes": vaes, "denoisers": denoisers}
    path = tmp_path / "recipe.json"
    path.write_text(json.dumps(doc))
    return path


def test_bad_recipes_are_named(tmp_path):
    with pytest.raises(ValueError, match="names VAE 'nope'"):
        load_recipe(_write_recipe(tmp_path, {"st": {}}, {"full": {"vae": "nope"}}))
    with pytest.raises(ValueError, match="unknown keys \\['lr'\\]"):
        load_recipe(_write_recipe(tmp_path, {"st": {"lr": 1.0}}, {}))
    with pytest.raises(ValueError, match="unique"):
        load_recipe(_write_recipe(tmp_path, {"x": {}}, {"x": {"vae": "x"}}))
    with pytest.raises(ValueError, match="max_parallel"):
        run_jobs([], tmp_path, max_parallel=0)


def test_tiny_study_trains_ships_and_loads(tmp_path):
    data = make_fake_corpus(tmp_path / "corpus")
    recipe = load_recipe(_write_recipe(tmp_path, {"st": {"label": "full VAE"}, "pose": {"model": {"kind": "pose"}}},
                                       {"full": {"vae": "st", "label": "full"},
                                        "no_st": {"vae": "pose", "label": "w/o ST-Latent"}}))
    jobs = plan_jobs(recipe, tmp_path / "work")
    # one job through a subprocess (the real launcher), the rest inline (no interpreter start-ups)
    first = run_jobs(jobs[:1], data, poll_s=0.2)
    codes = {**first, **run_jobs(jobs[1:], data, inline=True)}
    assert codes == {"vae_st": 0, "vae_pose": 0, "den_full": 0, "den_no_st": 0}, \
        {n: (tmp_path / "work" / f"{n}.log").read_text()[-2000:] for n, c in codes.items() if c}
    out = ship(jobs[:2], tmp_path / "shipped")
    assert set(list_ablations(out)) == {"vae_st", "vae_pose"}
    ship(jobs[2:], out)                       # a later subset keeps the earlier entries
    index = list_ablations(out)
    assert set(index) == {"vae_st", "vae_pose", "full", "no_st"}
    assert index["no_st"]["vae"] == "vae_pose" and index["full"]["label"] == "full"
    assert index["vae_st"]["steps"] == 2
    vae, mean, std = load_ablation_vae("pose", out)
    assert vae.num_parts == 1 and mean.shape == std.shape == (263,)
    # the pipelines share their VAE variant's folder instead of copying it
    assert not (out / "no_st" / "vae.safetensors").exists()
    assert json.loads((out / "no_st" / "pipeline.json").read_text())["vae"] == "../vae_pose/vae"
    pipe = load_ablation_pipeline("no_st", out)
    assert all(torch.equal(a, b) for a, b in zip(pipe.vae.parameters(), vae.parameters(), strict=True))
    assert pipe.latent_shape == (1, 7 * 8)   # pose latent = parts x latent_dim of the tiny VAE
    res = pipe("a person walks", lengths=16, seed=0, num_steps=2)
    assert res.features.shape == (1, 16, 263) and np.isfinite(res.features).all()
    # a second run finds everything finished and changes nothing
    before = (tmp_path / "work" / "den_full" / "latest.safetensors").read_bytes()
    assert run_jobs(jobs, data, inline=True) == codes
    assert (tmp_path / "work" / "den_full" / "latest.safetensors").read_bytes() == before
    with pytest.raises(KeyError, match="not a shipped denoiser"):
        load_ablation_pipeline("vae_st", out)
    with pytest.raises(KeyError, match="choose one of \\['pose', 'st'\\]"):
        load_ablation_vae("no_pos", out)
    with pytest.raises(FileNotFoundError, match="no index.json"):
        list_ablations(tmp_path / "nothing")


# ------------------------------------------------------------------ the staged study (issue 24)
from salad_lab import (GroupOutcome, StopDecision, StopRule, compare, decide, group_orderings,  # noqa: E402
                                  load_staged_recipe, model_card, paper_ordering, run_study, stage_jobs, study_plan)
from salad_lab.stage_eval import evaluation_path, stage_dir  # noqa: E402


def test_stop_rule_stable_flipping_and_budget():
    stages = [10, 20, 30, 40]
    a, b = {"p FID": ">", "p R": "="}, {"p FID": "<", "p R": "="}
    assert decide([a], stages) == StopDecision(False, "continue", 10, 20)
    assert decide([a, a], stages) == StopDecision(True, "stable", 20, None)
    assert decide([a, b, a], stages) == StopDecision(False, "continue", 30, 40)            # flipping goes on
    assert decide([a, b, a, b], stages) == StopDecision(True, "budget", 40, None)          # budget spent
    assert decide([b, a, a], stages).reason == "stable"
    three = StopRule(consecutive=3)
    assert decide([a, a], stages, three).reason == "continue" and decide([a, a, a], stages, three).reason == "stable"
    assert decide([a], [10]).reason == "budget"                                           # one stage: its budget
    with pytest.raises(ValueError, match="same pairs"):
        decide([a, {"p FID": ">"}], stages)
    with pytest.raises(ValueError, match="consecutive=1"):
        StopRule(consecutive=1)
    with pytest.raises(ValueError, match="compare='median'"):
        StopRule(compare="median")


def test_orderings_read_intervals_and_the_papers_directions():
    assert compare((1.0, 0.1), (2.0, 0.1), "FID") == ">"              # lower FID is better
    assert compare((0.9, 0.01), (0.8, 0.01), "R-precision top-3") == ">"  # higher R-precision is better
    assert compare((1.0, 0.6), (2.0, 0.6), "FID") == "="              # overlapping intervals: level
    assert compare((1.0, 0.6), (2.0, 0.6), "FID", mode="means") == ">"
    assert compare((0.02, 0.0), (0.01, 0.0), "MPJPE") == "<"
    with pytest.raises(ValueError, match="metric='Diversity'"):
        compare((1, 0), (2, 0), "Diversity")
    # the paper's claims, read from eval/paper_tables with the same rule
    assert paper_ordering("table3", "Full model", "w/o ST-Latent", "FID") == ">"
    assert paper_ordering("table3", "Full model", "w/o CrossAttn", "R-precision top-3") == ">"
    assert paper_ordering("supp_table2", "v-prediction", "x-prediction", "R-precision top-3") == "="  # .857 vs .860 +- .002
    assert paper_ordering("supp_table2", "v-prediction", "x-prediction", "FID") == ">"
    assert paper_ordering("supp_table4", "Full model", "without L_vel", "MPJPE") == "="              # 0.016 both
    assert paper_ordering("table2", "SALAD (skeleton-aware VAE)", "MoMask (VQ-VAE)", "MPJPE") == ">"


def test_v2_recipe_equal_budgets_constant_schedule_and_the_default_recipe(tmp_path):
    recipe = load_staged_recipe(REPO / "lab" / "configs" / "ablations_v2.json")
    groups = {g.name: g for g in recipe.groups}
    assert [g.kind for g in recipe.groups] == ["vae", "denoiser"]            # VAEs first: denoisers need them
    den, vae = groups["denoisers"], groups["vaes"]
    assert den.stages[0] >= 2500 and list(den.stages) == sorted(den.stages)
    assert set(den.tables) == {"table3", "supp_table2", "supp_table3"} and set(vae.tables) == {"table2", "supp_table4"}
    assert set(den.variants) == {"full", "no_st", "no_cross", "no_both", "eps", "x0", "no_film"}
    assert vae.tables["table2"]["st_long"] == "SALAD (skeleton-aware VAE)" and "st_long" in vae.tables["supp_table4"]
    frozen = {v: tmp_path / "frozen" / f"vae_{v}" for v in vae.variants}
    for group in recipe.groups:
        for steps in group.stages:
            jobs = stage_jobs(recipe, group, steps, tmp_path, frozen)
            assert {j.variant.name for j in jobs} == set(group.variants)
            trains = [j.config["train"] for j in jobs]
            # every row of every table of the group: the same steps and the same schedule and batch
            assert {t["max_steps"] for t in trains} == {steps}
            assert len({json.dumps(t, sort_keys=True) for t in trains}) == 1
            assert trains[0]["milestones"] == [] and trains[0]["warmup_steps"] < group.stages[0]
    den_cfg = {j.variant.name: j.config for j in stage_jobs(recipe, den, den.stages[0], tmp_path, frozen)}
    assert all(c["train"]["latent_norm"] is True and c["train"]["micro_batches"] == 4
               and c["train"]["autocast"] is None for c in den_cfg.values())      # float32: see the recipe's "about"
    assert all(c["model"]["width"] == 96 and c["model"]["layers"] == 3 for c in den_cfg.values())
    # one latent cache folder for all denoisers: those on the same VAE reuse one cache (its signature hashes the VAE)
    assert {c["train"]["latent_cache_dir"] for c in den_cfg.values()} == {str(tmp_path / "latent_cache")}
    assert den_cfg["no_st"]["model"]["num_parts"] == 1 and den_cfg["full"]["model"]["num_parts"] == 7
    vae_cfg = {j.variant.name: j.config for j in stage_jobs(recipe, vae, vae.stages[0], tmp_path)}
    assert all(c["train"]["autocast"] is None for c in vae_cfg.values())
    assert vae_cfg["pose_long"]["model"]["kind"] == "pose" and vae_cfg["no_pos"]["model"]["lambda_pos"] == 0.0
    # denoisers learn on the frozen VAE snapshot, not on the VAE's live run
    by_name = {j.variant.name: j for j in stage_jobs(recipe, den, den.stages[0], tmp_path, frozen)}
    assert by_name["no_st"].depends_on == frozen["pose_long"] and by_name["full"].depends_on == frozen["st_long"]
    with pytest.raises(ValueError, match="needs its VAE"):
        stage_jobs(recipe, den, den.stages[0], tmp_path)
    with pytest.raises(ValueError, match="not a stage"):
        stage_jobs(recipe, den, 123, tmp_path, frozen)
    plan = study_plan(recipe)
    assert [p["new_steps_per_variant"] for p in plan if p["group"] == "denoisers"] == \
        [den.stages[0], *np.diff(den.stages).tolist()]


def _staged_doc(vaes=None, denoisers=None, groups=None, **top):
    doc = {"vae_base": "vae.json", "denoiser_base": "den.json",
           "vae_train": {"batch_size": 8, "window": 64, "warmup_steps": 0, "milestones": [], "val_every": 0,
                         "ckpt_every": 0, "num_threads": 1, "log_every": 1},
           "denoiser_train": {"batch_size": 4, "warmup_steps": 0, "milestones": [], "max_length": 64, "val_every": 0,
                              "ckpt_every": 0, "num_threads": 1, "log_every": 1},
           "vaes": vaes if vaes is not None else {"st": {"label": "ST VAE"}, "pose": {"model": {"kind": "pose"}}},
           "denoisers": denoisers if denoisers is not None else {},
           "groups": groups if groups is not None else {
               "vaes": {"kind": "vae", "stages": [1, 2],
                        "evaluation": {"replications": 2, "batch_size": 8, "max_samples": 8, "mm": False},
                        "tables": {"table2": {"st": "SALAD (skeleton-aware VAE)", "pose": "MoMask (VQ-VAE)"}}}},
           **top}
    return doc


def _write_staged(tmp_path: Path, doc: dict) -> Path:
    (tmp_path / "vae.json").write_text(json.dumps({"model": {"latent_dim": 8, "n_extra_layers": 0}, "train": {}}))
    (tmp_path / "den.json").write_text(json.dumps({"model": {"width": 32, "heads": 2, "ff_dim": 64, "layers": 1,
                                                             "text_dim": 384}, "train": {"latent_norm": True}}))
    path = tmp_path / "staged.json"
    path.write_text(json.dumps(doc))
    return path


def test_kept_group_of_another_recipe_is_refused(tmp_path):
    """A keep folder whose group was trained by other configs is an error naming the group, not a silent restore."""
    from salad_lab import group_fingerprint, restore_group

    recipe = load_staged_recipe(_write_staged(tmp_path, _staged_doc()))
    group = recipe.group("vaes")
    keep = tmp_path / "keep"
    assert restore_group(recipe, group, keep, tmp_path / "work") is False         # nothing kept: nothing to do
    other_doc = _staged_doc()
    other_doc["vae_train"]["batch_size"] = 16
    other_dir = tmp_path / "other"
    other_dir.mkdir()
    other = load_staged_recipe(_write_staged(other_dir, other_doc))
    assert group_fingerprint(other, other.group("vaes")) != group_fingerprint(recipe, group)
    assert group_fingerprint(recipe, group) == group_fingerprint(load_staged_recipe(recipe.path), group)
    keep.mkdir()
    (keep / "groups.json").write_text(json.dumps({"vaes": {"steps": 2, "reason": "stable", "stages": [1, 2],
                                                           "variants": ["st", "pose"],
                                                           "fingerprint": group_fingerprint(other, other.group("vaes"))}}))
    with pytest.raises(ValueError, match="group 'vaes' kept in .* another recipe"):
        restore_group(recipe, group, keep, tmp_path / "work")


@pytest.mark.parametrize("change, message", [
    (lambda d: d["vae_train"].update(milestones=[1]), r"train.milestones=\[1\].*constant learning rate"),
    (lambda d: d["vae_train"].pop("milestones"), r"train.milestones='\(missing\)'"),
    (lambda d: d["vaes"]["st"].update(train={"max_steps": 5}), r"variant 'st'.*\['max_steps'\]"),
    (lambda d: d["vae_train"].update(warmup_steps=1), r"train.warmup_steps=1.*first stage 1"),
    (lambda d: d["groups"]["vaes"].update(stages=[2, 1]), r"groups.vaes.stages=\[2, 1\]"),
    (lambda d: d["groups"]["vaes"].update(kind="gan"), r"groups.vaes.kind='gan'"),
    (lambda d: d["groups"]["vaes"]["tables"].update(table9={}), r"groups.vaes.tables.table9.*not a paper table"),
    (lambda d: d["groups"]["vaes"]["tables"].update(table3={"st": "Full model"}), r"is a denoiser table in a vae group"),
    (lambda d: d["groups"]["vaes"]["tables"]["table2"].update(pose="ParCo"), r"paper rows \['ParCo'\]"),
    (lambda d: d["vaes"].update(extra={}), r"variants \['extra'\] are in no group"),
    (lambda d: d["groups"]["vaes"]["evaluation"].update(replicas=3), r"evaluation.*unknown fields \['replicas'\]"),
    (lambda d: d["groups"]["vaes"]["evaluation"].update(replications=0), r"EvalSettings.replications=0"),
    (lambda d: d.update(stop={"consecutive": 1}), r"StopRule.consecutive=1"),
    (lambda d: d.update(groups={}), r"groups: missing or empty"),
    (lambda d: d.update(timing={"steps_per_s": {"st": -1}}), r"timing.steps_per_s"),
])
def test_staged_recipe_errors_name_the_field(tmp_path, change, message):
    doc = _staged_doc()
    change(doc)
    with pytest.raises(ValueError, match=message):
        load_staged_recipe(_write_staged(tmp_path, doc))


def _fake_rows(summaries: dict, steps: int) -> dict:
    return {v: {"variant": v, "label": f"label {v}", "steps": steps, "summary": {m: list(s) for m, s in ms.items()},
                "settings": {"evaluator": "fake evaluator"}} for v, ms in summaries.items()}


def test_paired_advantage_removes_what_a_replication_does_to_both_rows():
    from salad_lab.orderings import paired_advantage

    # each replication moves both rows alike (an easy or hard draw): their own intervals overlap widely,
    # the paired differences are all 1.0 lower FID for the first row
    a, b = [5.0, 9.0, 6.0, 12.0, 7.0], [6.0, 10.0, 7.0, 13.0, 8.0]
    half_a = 1.96 * np.std(a) / np.sqrt(5)
    assert compare((np.mean(a), half_a), (np.mean(b), 1.96 * np.std(b) / np.sqrt(5)), "FID") == "="
    assert paired_advantage(a, b, "FID") == pytest.approx((1.0, 0.0))
    # higher-is-better metric: a's advantage is a - b; the half-width is the protocol's 1.96 std / sqrt(R)
    mean, half = paired_advantage([0.8, 0.7, 0.9], [0.7, 0.7, 0.6], "R-precision top-3")
    d = np.array([0.1, 0.0, 0.3])
    assert mean == pytest.approx(d.mean()) and half == pytest.approx(1.96 * d.std() / np.sqrt(3))
    assert paired_advantage([0.02], [0.03], "MPJPE") == pytest.approx((0.01, 0.0))
    with pytest.raises(ValueError, match="same replications"):
        paired_advantage([1.0, 2.0], [1.0], "FID")
    with pytest.raises(ValueError, match="non-finite"):
        paired_advantage([1.0, float("nan")], [1.0, 2.0], "FID")
    with pytest.raises(ValueError, match="metric='Diversity'"):
        paired_advantage([1.0], [2.0], "Diversity")


def test_model_card_is_written_from_the_evaluation_files_alone(tmp_path):
    recipe = load_staged_recipe(_write_staged(tmp_path, _staged_doc()))
    group = recipe.groups[0]
    docs = []
    for steps, st_fid in ((1, 0.30), (2, 0.10)):
        summaries = {"st": {"FID": (st_fid, 0.01), "MPJPE": (0.020, 0.001)},
                     "pose": {"FID": (0.20, 0.01), "MPJPE": (0.020, 0.002)}}
        docs.append({"steps": steps, "rows": _fake_rows(summaries, steps), "real": None, "compare": "intervals",
                     "orderings": group_orderings(summaries, group)})
    assert docs[0]["orderings"]["table2: st vs pose, FID"]["ours"] == "<"
    assert docs[1]["orderings"]["table2: st vs pose, FID"] == {
        "table": "table2", "a": "st", "b": "pose", "metric": "FID", "ours": ">", "paper": ">", "agrees": True,
        "separated": True}
    assert docs[1]["orderings"]["table2: st vs pose, MPJPE"]["agrees"] is False      # level here, better in the paper
    outcome = GroupOutcome(group, decide([{k: o["ours"] for k, o in d["orderings"].items()} for d in docs],
                                         group.stages), tuple(docs))
    assert outcome.decision == StopDecision(True, "budget", 2, None)
    card = model_card({"vaes": outcome}, command="python lab/scripts/ablations/train_ablations.py --data C --work W", size_mb=1.25)
    assert "python lab/scripts/ablations/train_ablations.py --data C --work W" in card
    assert "stopped because the budget was spent" in card and "1.2 MB" in card
    assert "| label st | `st` | 2 | 0.100 ± 0.010 | 2.000 ± 0.100 cm | paper: SALAD (skeleton-aware VAE) | 0.003 ± 0.000 " \
           "| 1.600 ± 0.000 cm |" in card
    assert "| `st` vs `pose` | FID | `<` | `>` | `>` | yes | yes |" in card
    assert "| `st` vs `pose` | MPJPE | `=` | `=` | `>` | no | no |" in card
    assert "Evaluator: `fake evaluator`" in card and "ours level, paper better" in card
    assert "Probes" not in card
    assert "| `st` vs `pose` | FID | `<` | `>` | `>` | yes | yes | - |" in card        # no per-replication values
    # with the replications' values the card prints the paired advantage, starred when it excludes 0
    docs[-1]["rows"]["st"]["values"] = {"FID": [0.09, 0.11, 0.10], "MPJPE": [0.019, 0.021, 0.020]}
    docs[-1]["rows"]["pose"]["values"] = {"FID": [0.19, 0.21, 0.20], "MPJPE": [0.020, 0.020, 0.020]}
    card = model_card({"vaes": outcome}, command="c")
    assert "| `st` vs `pose` | FID | `<` | `>` | `>` | yes | yes | 0.100 ± 0.000 `*` |" in card
    # the shipped evaluator is named as such, not by the path of the machine that scored the study
    for row in docs[-1]["rows"].values():
        row["settings"]["evaluator"] = "/root/runs/code/salad_core/weights/evaluator"
    card = model_card({"vaes": outcome}, command="c")
    assert "Evaluator: the shipped procedural-corpus evaluator (`salad_core/weights/evaluator`)." in card
    assert "/root/runs" not in card
    assert "| `st` vs `pose` | MPJPE | `=` | `=` | `>` | no | no | 0.000 ± 0.092 cm |" in card
    # probes made on the final stage are printed beside the tables, with their commands; others are not
    probe = {"label": "narrow pose VAE", "base_variant": "pose", "change": {"model.pose_width": 4}, "parameters": 900,
             "summary": {"FID": [0.5, 0.02], "MPJPE": [0.05, 0.003]}, "commands": ["train it", "score it"]}
    card = model_card({"vaes": outcome}, command="c", probes={"narrow": {**probe, "stage": "vaes@2"},
                                                               "old": {**probe, "stage": "vaes@1", "label": "old one"}})
    assert "| **probe** narrow pose VAE (pose with model.pose_width = 4) | 900 | 0.500 ± 0.020 | 5.00 ± 0.30 |" in card
    assert "| label pose (pose) | - | 0.200 ± 0.010 | 2.00 ± 0.20 |" in card        # a row without a count
    assert "Probe `narrow` was made by:\n\n```bash\ntrain it\nscore it\n```" in card and "old one" not in card


def test_staged_study_trains_evaluates_resumes_and_ships(tmp_path, monkeypatch):
    """The whole staged machinery on a fake corpus: 2 VAEs and 2 denoisers, stages of 1 and 2 steps."""
    import functools

    import salad_core.text
    from _doubles import make_tiny_evaluator

    # MiniLM is loaded once for the test's trainers, packaging and evaluation (the same encoder each time)
    monkeypatch.setattr(salad_core.text, "load_text_encoder", functools.lru_cache(salad_core.text.load_text_encoder))
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=40)
    evaluator = make_tiny_evaluator(data, dim_word=8, dim_text_hidden=16, dim_coemb=32, dim_movement_enc_hidden=16,
                                    dim_movement_latent=16, dim_motion_hidden=32)
    doc = _staged_doc(denoisers={"full": {"vae": "st", "label": "full"}, "no_st": {"vae": "pose", "label": "w/o ST"}})
    doc["groups"]["vaes"]["evaluation"] = {"replications": 2, "batch_size": 16, "max_samples": 32, "mm": False}
    doc["groups"]["dens"] = {"kind": "denoiser", "stages": [1, 2],
                             "evaluation": {"replications": 2, "batch_size": 16, "max_samples": 32, "mm": False,
                                            "num_steps": 2},
                             "tables": {"table3": {"full": "Full model", "no_st": "w/o ST-Latent"}}}
    recipe = load_staged_recipe(_write_staged(tmp_path, doc))
    work = tmp_path / "work"
    # a half-trained stage: one of the first stage's runs is trained already (its snapshot is not taken yet)
    pre = stage_jobs(recipe, recipe.group("vaes"), 1, work)
    assert run_jobs(pre[:1], data, inline=True) == {"vae_st": 0}
    keep = tmp_path / "keep"
    outcomes = run_study(recipe, data, work, evaluator=evaluator, inline=True, keep=keep)
    for name, outcome in outcomes.items():
        group = recipe.group(name)
        assert outcome.decision.stop and outcome.decision.reason in ("stable", "budget")
        for ev in outcome.evaluations:
            steps = ev["steps"]
            assert evaluation_path(work, group, steps).is_file()
            assert {r["steps"] for r in ev["rows"].values()} == {steps}             # equal budgets in the table
            for v in group.variants:
                run = f"vae_{v}" if group.kind == "vae" else f"den_{v}"
                meta = json.loads((stage_dir(work, group, steps) / "runs" / run / "latest.json").read_text())
                assert meta.get("step", meta.get("meta", {}).get("step")) == steps
            assert set(ev["orderings"]) == {f"table{'2' if group.kind == 'vae' else '3'}: "
                                            f"{'st vs pose' if group.kind == 'vae' else 'full vs no_st'}, {m}"
                                            for m in (("FID", "MPJPE") if group.kind == "vae"
                                                      else ("FID", "R-precision top-3"))}
    dens = outcomes["dens"]
    assert dens.evaluations[-1]["real"]["summary"]["FID"][0] >= 0
    vae_stop = outcomes["vaes"].decision.steps
    # the denoisers learn on the VAE group's packaged fp16 models (what ships), not on the float32 snapshot
    frozen = stage_dir(work, recipe.group("vaes"), vae_stop) / "models" / "vae_pose" / "vae"
    assert json.loads((work / "den_no_st" / "config.json").read_text())["task"]["vae"] == str(frozen)
    # the stopped VAE group is kept: its final models and every evaluation of the group
    from salad_lab import kept_groups

    kept = kept_groups(keep)
    assert list(kept) == ["vaes", "dens"] and kept["vaes"]["steps"] == vae_stop
    assert kept["vaes"]["stages"] == [e["steps"] for e in outcomes["vaes"].evaluations]
    assert kept["dens"]["stopped"] and kept["dens"]["steps"] == outcomes["dens"].decision.steps
    # the stopped denoiser group too (its pipelines, as they ship); no progress is left once both stopped
    assert sorted(p.name for p in keep.iterdir()) == ["evaluations", "full", "groups.json", "no_st", "vae_pose",
                                                      "vae_st"]
    assert (keep / "vae_pose" / "vae.safetensors").read_bytes() == (frozen.parent / "vae.safetensors").read_bytes()

    # rerun after the end: nothing is trained or scored again
    def boom(*a, **k):
        raise AssertionError("recomputed")
    monkeypatch.setattr("salad_lab.runner.run_jobs", boom)
    monkeypatch.setattr("salad_lab.stage_eval._score_vae", boom)
    monkeypatch.setattr("salad_lab.stage_eval._score_denoiser", boom)
    again = run_study(recipe, data, work, evaluator=evaluator, inline=True)
    assert {n: o.decision for n, o in again.items()} == {n: o.decision for n, o in outcomes.items()}
    # a new machine: an empty work folder gets the VAE group back from the keep folder, nothing is retrained,
    # and the denoisers would learn on byte-identical VAEs
    fresh = tmp_path / "fresh_work"
    restored = run_study(recipe, data, fresh, evaluator=evaluator, inline=True, groups=["vaes"], keep=keep)
    assert restored["vaes"].decision == outcomes["vaes"].decision
    assert [e["orderings"] for e in restored["vaes"].evaluations] == [e["orderings"] for e in outcomes["vaes"].evaluations]
    for v in ("st", "pose"):
        rel = Path("stages") / f"vaes@{vae_stop}" / "models" / f"vae_{v}" / "vae.safetensors"
        assert (fresh / rel).read_bytes() == (work / rel).read_bytes()
    # an interrupted evaluation: one row left to score; only that row is scored
    last = dens.evaluations[-1]["steps"]
    stage_file = evaluation_path(work, recipe.group("dens"), last)
    before = json.loads(stage_file.read_text())
    stage_file.unlink()
    stage_file.with_suffix(".rows").joinpath("no_st.json").unlink()
    scored = []
    monkeypatch.setattr("salad_lab.stage_eval._score_denoiser",
                        lambda folder, *a, **k: scored.append(folder.name) or _fake_result(before["rows"]["no_st"]))
    run_study(recipe, data, work, evaluator=evaluator, inline=True)
    assert scored == ["no_st"] and json.loads(stage_file.read_text())["orderings"] == before["orderings"]

    # ship: the final stage's fp16 models, the evaluations, the index and the card
    from salad_lab import ship_study

    out = ship_study(recipe, outcomes, tmp_path / "shipped", work, command="python lab/scripts/ablations/train_ablations.py ...")
    index = list_ablations(out)
    assert set(index) == {"vae_st", "vae_pose", "full", "no_st"}
    assert index["full"]["steps"] == dens.decision.steps and index["vae_st"]["steps"] == vae_stop
    assert json.loads((out / "no_st" / "pipeline.json").read_text())["vae"] == "../vae_pose/vae"
    assert (out / "evaluations" / f"dens@{last}.json").is_file() and "## Group `dens`" in (out / "MODEL_CARD.md").read_text()
    assert not (out / "probes.json").exists()
    # a probe of the VAE group's final stage is printed in the card (its record stays in the lab); shipping again
    # without probes removes it
    probe = {"stage": f"vaes@{vae_stop}", "label": "a probe", "base_variant": "pose", "change": {"model.x": 1},
             "parameters": 7, "summary": {"FID": [1.0, 0.1], "MPJPE": [0.1, 0.01]}, "commands": ["make it"]}
    ship_study(recipe, outcomes, out, work, command="c", probes={"p": probe})
    assert not (out / "probes.json").exists()
    assert "| **probe** a probe (pose with model.x = 1) | 7 |" in (out / "MODEL_CARD.md").read_text()
    ship_study(recipe, outcomes, out, work, command="python lab/scripts/ablations/train_ablations.py ...")
    assert not (out / "probes.json").exists() and "**probe**" not in (out / "MODEL_CARD.md").read_text()
    # the notebooks' tables: read back from the shipped folder alone, exactly the card's sections
    from salad_lab import shipped_tables

    tables = shipped_tables(out)
    assert list(tables) == ["table2", "table3"]
    card = (out / "MODEL_CARD.md").read_text()
    for md in tables.values():
        assert md.strip() in card
    assert "| `full` vs `no_st` | FID |" in tables["table3"] and "paper: w/o ST-Latent" in tables["table3"]
    old_style = tmp_path / "fixed_budget"                        # the 0.3 study's index: no evaluations
    old_style.mkdir()
    (old_style / "index.json").write_text(json.dumps({k: {kk: vv for kk, vv in e.items()
                                                          if kk not in ("evaluation", "paper_rows")}
                                                      for k, e in index.items()}))
    assert shipped_tables(old_style) == {}
    (out / "evaluations" / f"dens@{last}.json").unlink()
    with pytest.raises(FileNotFoundError, match=f"dens@{last}.json"):
        shipped_tables(out)
    pipe = load_ablation_pipeline("no_st", out)
    res = pipe("a person walks", lengths=16, seed=0, num_steps=2)
    assert res.features.shape == (1, 16, 263) and np.isfinite(res.features).all()


def _fake_result(row: dict):
    from salad_core.eval.settings import EvalResult

    return EvalResult(row["label"], {m: tuple(v) for m, v in row["values"].items()}, row["settings"]), None


def _script():
    import importlib.util

    spec = importlib.util.spec_from_file_location("train_ablations_script", script_path("train_ablations.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_script_dry_run_prints_the_plan_and_marks_evaluated_stages(tmp_path, capsys):
    script = _script()
    recipe = load_staged_recipe(REPO / "lab" / "configs" / "ablations_v2.json")
    vaes = recipe.group("vaes")
    evaluation_path(tmp_path, vaes, vaes.stages[0]).parent.mkdir(parents=True)
    evaluation_path(tmp_path, vaes, vaes.stages[0]).write_text("{}")
    assert script.main(["--recipe", str(REPO / "lab" / "configs" / "ablations_v2.json"), "--work", str(tmp_path),
                        "--dry-run", "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if "@" in line]
    assert len(lines) == len(vaes.stages) + len(recipe.group("denoisers").stages)
    assert f"vaes@{vaes.stages[0]}" in lines[0] and "[evaluated]" in lines[0] and "[evaluated]" not in lines[1]
    assert "7 denoisers x 2,500 new steps" in out and "--jobs 2" in out
    with pytest.raises(SystemExit):
        script.main(["--recipe", str(REPO / "lab" / "configs" / "ablations_v2.json"), "--work", str(tmp_path), "--only", "st"])
    assert "--only and --ship-only are for recipes without groups" in capsys.readouterr().err



def test_timing_measures_cpu_per_step_and_the_plan_takes_alike_variants(tmp_path, monkeypatch):
    """ablations.timing: a denoiser's VAE is timed first, the figures are CPU seconds per real step
    (warm-up steps left out), written to WORK/timing.json; the dry run's plan takes an untimed variant's
    speed from a timed one alike (denoisers on the same VAE), and leaves unlike ones unmeasured."""
    import functools

    import salad_core.text
    from salad_lab.timing import TIMING_FILE, time_variants

    monkeypatch.setattr(salad_core.text, "load_text_encoder", functools.lru_cache(salad_core.text.load_text_encoder))
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=40)
    doc = _staged_doc(denoisers={"full": {"vae": "st"}, "no_film": {"vae": "st", "model": {"film": False}},
                                 "no_st": {"vae": "pose"}})
    doc["groups"]["dens"] = {"kind": "denoiser", "stages": [3],
                             "evaluation": {"replications": 2, "batch_size": 16, "max_samples": 32, "mm": False},
                             "tables": {"table3": {"full": "Full model", "no_st": "w/o ST-Latent"},
                                        "supp_table3": {"full": "with FiLM", "no_film": "without FiLM"}}}
    recipe = load_staged_recipe(_write_staged(tmp_path, doc))
    work = tmp_path / "work"
    with pytest.raises(ValueError, match="must exceed skip"):
        time_variants(recipe, ["full"], data, work, steps=3, skip=3)
    with pytest.raises(ValueError, match=r"\['nope'\] are not in the recipe"):
        time_variants(recipe, ["nope"], data, work, steps=4, skip=1)
    result = time_variants(recipe, ["full"], data, work, steps=4, skip=1)
    assert set(result["steps_per_cpu_s"]) == {"st", "full"}            # the denoiser's VAE was timed too
    for name, rate in result["steps_per_cpu_s"].items():
        assert rate > 0 and result["cpu_s_per_step"][name] == pytest.approx(1.0 / rate, abs=1e-4)
        assert result["wall_s_per_step"][name] > 0
    assert json.loads((work / TIMING_FILE).read_text()) == result
    plan = {(p["group"], p["steps"]): p for p in study_plan(recipe, result["steps_per_cpu_s"])}
    rate = result["steps_per_cpu_s"]
    assert plan[("vaes", 1)]["cpu_seconds"] is None                    # the pose VAE is like no timed one
    assert plan[("dens", 3)]["cpu_seconds"] is None                    # no_st's denoiser runs on that VAE
    doc["denoisers"].pop("no_st")
    doc["groups"]["dens"]["tables"]["table3"].pop("no_st")
    recipe = load_staged_recipe(_write_staged(tmp_path, doc))
    dens = {p["steps"]: p for p in study_plan(recipe, rate) if p["group"] == "dens"}
    assert dens[3]["cpu_seconds"] == pytest.approx(2 * 3 / rate["full"])  # no_film takes full's speed


def test_pipelined_study_overlaps_stages_in_subprocesses_and_stops_cleanly(tmp_path, monkeypatch):
    """The default (subprocess) scheduler: two VAEs trained side by side, stages overlap, a stop at the second
    stage interrupts what trains beyond it, and the stages it scored are exactly the snapshots' steps."""
    import subprocess as sp

    from _doubles import make_tiny_evaluator

    import salad_lab.runner as runner

    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=40)
    evaluator = make_tiny_evaluator(data, dim_word=8, dim_text_hidden=16, dim_coemb=32, dim_movement_enc_hidden=16,
                                    dim_movement_latent=16, dim_motion_hidden=32)
    doc = _staged_doc()
    doc["groups"]["vaes"].update(stages=[1, 2, 3], evaluation={"replications": 2, "batch_size": 16,
                                                               "max_samples": 32, "mm": False})
    recipe = load_staged_recipe(_write_staged(tmp_path, doc))
    real_decide = runner.decide

    def stop_at_two(history, stages, rule):           # the orderings of tiny models are noise: stop at stage 2
        d = real_decide(history, stages, rule)
        return runner.StopDecision(True, "stable", d.steps, None) if d.steps == 2 else d
    monkeypatch.setattr(runner, "decide", stop_at_two)
    started = []
    real_popen = sp.Popen

    def recording_popen(cmd, *a, **k):
        started.append(cmd)
        return real_popen(cmd, *a, **k)
    monkeypatch.setattr(runner.subprocess, "Popen", recording_popen)
    work = tmp_path / "work"
    outcome = run_study(recipe, data, work, evaluator=evaluator, max_parallel=2)["vaes"]
    assert outcome.decision.steps == 2 and [e["steps"] for e in outcome.evaluations] == [1, 2]
    assert evaluation_path(work, recipe.group("vaes"), 2).is_file()
    assert not evaluation_path(work, recipe.group("vaes"), 3).exists()
    for steps in (1, 2):
        for v in ("st", "pose"):
            meta = json.loads((stage_dir(work, recipe.group("vaes"), steps) / "runs" / f"vae_{v}" /
                               "latest.json").read_text())
            assert meta.get("step", meta.get("meta", {}).get("step")) == steps
    assert all("--resume" in c for c in started) and len(started) >= 4       # at least stages 1 and 2 of both
    # a second call trains and scores nothing: the evaluations and snapshots are read back
    monkeypatch.setattr(runner.subprocess, "Popen", lambda *a, **k: (_ for _ in ()).throw(AssertionError("trained")))
    monkeypatch.setattr("salad_lab.stage_eval._score_vae",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("scored")))
    again = run_study(recipe, data, work, evaluator=evaluator, max_parallel=2)["vaes"]
    assert again.decision == outcome.decision


def test_group_in_progress_is_kept_and_a_new_machine_warm_starts_it(tmp_path, monkeypatch):
    """After each new evaluation of a group that goes on, its runs' fp16 weights and its evaluations are kept;
    an empty work folder gets them back and the runs continue from that stage, not from step 0."""
    from salad_lab import keep_study, kept_groups
    from salad_core.eval.reconstruction import ReconstructionResult
    from salad_core.io import load_tensors

    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=8)
    doc = _staged_doc()
    doc["groups"]["vaes"]["stages"] = [1, 2, 3]
    recipe = load_staged_recipe(_write_staged(tmp_path, doc))
    group = recipe.group("vaes")
    scored = []

    class Stop(Exception):
        pass

    def fake_score(folder, label, data, evaluator, settings, weights, stop_at=None):
        steps = int(folder.parent.parent.name.split("@")[1])          # stages/vaes@<steps>/models/<folder>
        if steps == stop_at:
            raise Stop(f"the machine stops during stage {steps}")
        scored.append((steps, folder.name))
        # the orderings flip at every stage: the group never becomes stable, it runs to its budget
        fid = {"vae_st": 0.1 if steps % 2 else 0.3, "vae_pose": 0.2}[folder.name]
        res = ReconstructionResult(label, {"FID": (fid, fid + 0.001), "MPJPE": (0.02, 0.0201)}, 10, {"evaluator": "fake"})
        return res, res.parameters

    import functools

    monkeypatch.setattr("salad_lab.stage_eval._score_vae", functools.partial(fake_score, stop_at=2))
    work, keep = tmp_path / "work", tmp_path / "keep"
    with pytest.raises(Stop):
        run_study(recipe, data, work, evaluator=object(), inline=True, keep=keep)
    kept = kept_groups(keep)["vaes"]
    assert (kept["steps"], kept["stopped"], kept["reason"], kept["stages"]) == (1, False, "in progress", [1])
    assert sorted(p.name for p in (keep / "progress" / "vaes").iterdir()) == [
        "vae_pose.json", "vae_pose.safetensors", "vae_st.json", "vae_st.safetensors"]
    snap = load_tensors(stage_dir(work, group, 1) / "runs" / "vae_st" / "latest.safetensors")
    kept_w = load_tensors(keep / "progress" / "vaes" / "vae_st.safetensors")
    assert set(kept_w) == set(snap) and all(kept_w[k].dtype == torch.float16 for k in kept_w if kept_w[k].is_floating_point())
    for k, v in snap.items():
        torch.testing.assert_close(kept_w[k].float(), v, rtol=1e-3, atol=1e-4)
    # keeping at once (--keep-now, on a copy) takes the runs where they are: past stage 1, at the interrupted stage 2
    import shutil

    shutil.copytree(keep, tmp_path / "keep_now")
    assert keep_study(recipe, work, tmp_path / "keep_now") == {
        "vaes": "in progress, evaluated up to 1 steps; runs kept at {'vae_st': 2, 'vae_pose': 2}"}
    assert kept_groups(tmp_path / "keep_now")["vaes"]["snapshots"] == {"2": ["vae_st", "vae_pose"]}

    # a new machine: nothing of work survives; the group goes on from stage 1 with the kept weights
    monkeypatch.setattr("salad_lab.stage_eval._score_vae", fake_score)
    fresh = tmp_path / "fresh"
    scored.clear()
    outcome = run_study(recipe, data, fresh, evaluator=object(), inline=True, keep=keep)["vaes"]
    assert outcome.decision.reason == "budget" and outcome.decision.steps == 3
    assert sorted({s for s, _ in scored}) == [2, 3]                          # stage 1 was not trained or scored again
    assert outcome.evaluations[0] == json.loads(evaluation_path(work, group, 1).read_text())
    for run in ("vae_st", "vae_pose"):
        rows = [json.loads(l) for l in (fresh / run / "log.jsonl").read_text().splitlines()]
        assert rows[0]["step"] == 1 and "warm_start" in rows[0]              # continued from the kept step
        assert [r["step"] for r in rows if "loss" in r] == [2, 3]
    # the stopped group replaces its progress
    kept = kept_groups(keep)["vaes"]
    assert (kept["steps"], kept["stopped"], kept["stages"]) == (3, True, [1, 2, 3])
    assert not (keep / "progress").exists()
    assert sorted(p.name for p in keep.iterdir()) == ["evaluations", "groups.json", "vae_pose", "vae_st"]
    with pytest.raises(ValueError, match="as stopped already"):
        from salad_lab import keep_progress

        keep_progress(recipe, group, [1], work, keep)


def test_a_session_keeps_its_runs_inside_a_stage_and_a_new_machine_loses_no_step(tmp_path, monkeypatch):
    """``keep_study`` (``--keep-now``) before a session ends keeps each run at its latest step, inside a stage,
    and the snapshots of stages not evaluated yet; an empty work folder continues from exactly there."""
    from salad_lab import keep_study, kept_groups
    from salad_lab.stage_eval import snapshot_run
    from salad_core.eval.reconstruction import ReconstructionResult
    from salad_core.io import load_tensors

    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=8)
    doc = _staged_doc()
    doc["groups"]["vaes"]["stages"] = [2, 3, 4]
    recipe = load_staged_recipe(_write_staged(tmp_path, doc))
    group = recipe.group("vaes")
    work, keep = tmp_path / "work", tmp_path / "keep"
    assert keep_study(recipe, work, keep) == {"vaes": "nothing trained"}
    assert not (keep / "groups.json").exists()
    # the session ends with vae_st trained past the first stage (its snapshot taken, not evaluated) up to the
    # second (no snapshot yet: its latest is kept as one), and vae_pose not started
    assert run_jobs(stage_jobs(recipe, group, 2, work)[:1], data, inline=True) == {"vae_st": 0}
    snapshot_run(work / "vae_st", stage_dir(work, group, 2) / "runs" / "vae_st", 2)
    assert run_jobs(stage_jobs(recipe, group, 3, work)[:1], data, inline=True) == {"vae_st": 0}
    assert keep_study(recipe, work, keep) == {"vaes": "in progress, nothing evaluated yet; runs kept at {'vae_st': 3}"}
    kept = kept_groups(keep)["vaes"]
    assert (kept["stopped"], kept["stages"], kept["runs"], kept["snapshots"]) == (False, [], {"vae_st": 3},
                                                                                 {"2": ["vae_st"], "3": ["vae_st"]})
    progress = keep / "progress" / "vaes"
    assert sorted(p.name for p in progress.iterdir()) == ["snapshots", "vae_st.json", "vae_st.safetensors"]
    for kept_file, original in ((progress / "vae_st.safetensors", work / "vae_st" / "latest.safetensors"),
                                (progress / "snapshots" / "2" / "vae_st" / "latest.safetensors",
                                 stage_dir(work, group, 2) / "runs" / "vae_st" / "latest.safetensors")):
        w, ref = load_tensors(kept_file), load_tensors(original)
        assert set(w) == set(ref) and all(t.dtype == torch.float16 for t in w.values() if t.is_floating_point())
        for k, v in ref.items():
            torch.testing.assert_close(w[k].float(), v, rtol=1e-3, atol=1e-4)
    assert json.loads((progress / "vae_st.json").read_text())["meta"]["step"] == 3

    scored = []

    def fake_score(folder, label, data, evaluator, settings, weights):
        steps = int(folder.parent.parent.name.split("@")[1])
        scored.append((steps, folder.name))
        fid = {"vae_st": 0.1 if steps % 2 else 0.3, "vae_pose": 0.2}[folder.name]      # never stable
        res = ReconstructionResult(label, {"FID": (fid, fid + 0.001), "MPJPE": (0.02, 0.0201)}, 10, {"evaluator": "fake"})
        return res, res.parameters

    monkeypatch.setattr("salad_lab.stage_eval._score_vae", fake_score)
    fresh = tmp_path / "fresh"
    outcome = run_study(recipe, data, fresh, evaluator=object(), inline=True, keep=keep)["vaes"]
    assert outcome.decision.reason == "budget" and outcome.decision.steps == 4
    assert sorted(set(scored)) == [(s, f) for s in (2, 3, 4) for f in ("vae_pose", "vae_st")]
    # stages 2 and 3 of vae_st are the kept snapshots (fp16-rounded), not retrained ones
    for s in (2, 3):
        used = load_tensors(stage_dir(fresh, group, s) / "runs" / "vae_st" / "latest.safetensors")
        ref = load_tensors((stage_dir(work, group, 2) / "runs" / "vae_st" if s == 2 else work / "vae_st")
                           / "latest.safetensors")
        assert set(used) == set(ref) and all(torch.equal(used[k], ref[k].half() if ref[k].is_floating_point()
                                                         else ref[k]) for k in ref)
    st_rows = [json.loads(l) for l in (fresh / "vae_st" / "log.jsonl").read_text().splitlines()]
    assert st_rows[0]["step"] == 3 and "warm_start" in st_rows[0]           # continued from the kept step 3
    assert [r["step"] for r in st_rows if "loss" in r] == [4]
    pose_rows = [json.loads(l) for l in (fresh / "vae_pose" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in pose_rows if "loss" in r] == [1, 2, 3, 4]     # not started before: from 0
    assert kept_groups(keep)["vaes"]["stopped"] and not (keep / "progress").exists()
