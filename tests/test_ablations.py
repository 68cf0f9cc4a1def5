"""The ablation study: recipe parsing, job planning, and a tiny end-to-end train -> ship -> load."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.ablations import (list_ablations, load_ablation_pipeline, load_ablation_vae, load_recipe, plan_jobs,
                                  run_jobs, ship)
from salad_core.models.denoiser import DenoiserConfig
from salad_core.models.vae import VAEConfig
from salad_core.io import config_from_dict
from _doubles import make_fake_corpus

REPO = Path(__file__).resolve().parents[1]


def test_long_table3_recipe_differs_from_the_study_only_in_the_denoiser_budget(tmp_path):
    """configs/ablations_table3_long.json (the 2,500-step check in the ablation model card): the same
    VAEs and denoiser models as the shipped study, only the denoisers' step budget changes."""
    short = {j.run_dir.name: j.config for j in plan_jobs(load_recipe(REPO / "configs" / "ablations.json"), tmp_path)}
    long = {j.run_dir.name: j.config for j in plan_jobs(load_recipe(REPO / "configs" / "ablations_table3_long.json"),
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
    recipe = load_recipe(REPO / "configs" / "ablations.json")
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
    with pytest.raises(FileNotFoundError, match="train_ablations"):
        list_ablations(tmp_path / "nothing")
