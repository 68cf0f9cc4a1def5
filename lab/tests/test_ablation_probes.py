"""Probes beside the ablation study (issue 24): a changed VAE variant scored with a stage's own protocol."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from salad_lab.probes import load_probes, probe_markdown, record_probe, score_vae_probe
from salad_core.models.vae import MotionVAE, VAEConfig
from _doubles import make_fake_corpus, make_tiny_evaluator

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402
SETTINGS = {"split": "test", "batch_size": 4, "replications": 2, "max_samples": 4, "mm": False, "seed": 0}


def _script():
    spec = importlib.util.spec_from_file_location("ablation_vae_probe", script_path("ablation_vae_probe.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _study_configs(root: Path) -> Path:
    """What a study's <work>/configs folder holds for a pose-vector VAE variant (tiny, 2 steps)."""
    root.mkdir(parents=True)
    (root / "vae_pose.json").write_text(json.dumps({
        "model": {"latent_dim": 8, "n_extra_layers": 0, "kind": "pose"},
        "train": {"batch_size": 8, "max_steps": 2, "window": 64, "warmup_steps": 1, "milestones": [], "val_every": 0,
                  "ckpt_every": 0, "num_threads": 1}}))
    return root


def _stage_doc(steps: int) -> dict:
    """A VAE stage evaluation as the study writes it (rows' figures made up: only the layout matters here)."""
    rows = {v: {"variant": v, "label": lab, "steps": steps, "parameters": p,
                "summary": {"FID": [f, 0.01], "MPJPE": [m, 0.001]}}
            for v, lab, p, f, m in (("st", "skeleton-aware VAE", 1000, 0.5, 0.04), ("pose", "pose-vector VAE", 9000,
                                                                                   0.4, 0.03))}
    return {"stage": f"vaes@{steps}", "group": "vaes", "kind": "vae", "steps": steps, "settings": dict(SETTINGS),
            "rows": rows}


def _train(config: Path, run: Path, data: Path) -> None:
    from salad_core.cli.train import main as train_main

    assert train_main(["vae", "--data", str(data), "--out", str(run), "--config", str(config), "--resume",
                       "--no-progress"]) == 0


def test_probe_config_changes_only_the_named_keys(tmp_path):
    mod = _script()
    configs = _study_configs(tmp_path / "configs")
    out = tmp_path / "probe" / "vae_pose_narrow.json"
    assert mod.main(["config", "--study-configs", str(configs), "--variant", "pose", "--set", "model.pose_width=12",
                     "--out", str(out)]) == 0
    base, probe = json.loads((configs / "vae_pose.json").read_text()), json.loads(out.read_text())
    assert probe["model"].pop("pose_width") == 12
    assert probe == base
    assert mod.parse_sets(["model.kind=\"st\"", "train.lr=0.5"]) == {"model.kind": "st", "train.lr": 0.5}
    with pytest.raises(ValueError, match="SECTION.KEY=VALUE"):
        mod.parse_sets(["pose_width=12"])
    with pytest.raises(ValueError, match="'model.x' is not an override"):
        mod.parse_sets(["model.x"])
    with pytest.raises(ValueError, match="no section 'modle'"):
        mod.apply_sets(base, {"modle.pose_width": 12})
    with pytest.raises(SystemExit):
        mod.main(["config", "--study-configs", str(configs), "--variant", "st", "--set", "model.x=1", "--out",
                  str(out)])


def test_probe_is_scored_with_the_stages_protocol_and_recorded(tmp_path):
    mod = _script()
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=6)
    configs = _study_configs(tmp_path / "configs")
    cfg = tmp_path / "probe" / "vae_pose_narrow.json"
    mod.main(["config", "--study-configs", str(configs), "--variant", "pose", "--set", "model.pose_width=12",
              "--out", str(cfg)])
    run = tmp_path / "probe" / "vae_pose_narrow"
    _train(cfg, run, data)
    evaluator = make_tiny_evaluator(data, dim_word=8, dim_text_hidden=16, dim_coemb=32, dim_movement_enc_hidden=16,
                                    dim_movement_latent=16, dim_motion_hidden=32)
    stage = _stage_doc(2)
    row = score_vae_probe(stage, run, label="pose-vector VAE, narrow", change={"model.pose_width": 12},
                          base_variant="pose", data=data, evaluator=evaluator)
    # the probe's own parameter count, the stage's protocol, one value per replication
    expected = MotionVAE(VAEConfig(latent_dim=8, n_extra_layers=0, kind="pose", pose_width=12))
    assert row["parameters"] == sum(p.numel() for p in expected.parameters() if p.requires_grad)
    assert row["steps"] == 2 and row["stage"] == "vaes@2" and row["base_variant"] == "pose"
    for key in ("split", "batch_size", "replications", "max_samples", "seed"):
        assert row["settings"][key] == SETTINGS[key], key
    assert all(len(v) == 2 and np.isfinite(v).all() for v in row["values"].values())
    assert set(row["summary"]) == {"FID", "MPJPE"} and row["summary"]["MPJPE"][0] > 0
    # the same crops every time: scoring again gives the same figures
    again = score_vae_probe(stage, run, label="again", change={}, base_variant="pose", data=data, evaluator=evaluator)
    assert again["values"] == row["values"]

    record = tmp_path / "probes.json"
    record_probe(record, "narrow", row, commands=["train", "score"])
    record_probe(record, "other", {**row, "stage": "vaes@4"}, commands=["x"])
    doc = load_probes(record)
    assert set(doc) == {"narrow", "other"} and doc["narrow"]["commands"] == ["train", "score"]
    table = probe_markdown(stage, doc, ["pose", "st"])
    lines = table.strip().splitlines()
    assert len(lines) == 2 + 2 + 1                     # header, rule, the two stage rows, the probe of this stage
    assert lines[2].startswith("| pose-vector VAE (pose) | 9,000 | 0.400 ± 0.010 | 3.00 ± 0.10 |")
    mpjpe = row["summary"]["MPJPE"]
    assert "model.pose_width = 12" in lines[4] and f"{mpjpe[0] * 100:.2f} ± {mpjpe[1] * 100:.2f}" in lines[4]


def test_probe_refuses_another_budget_and_unknown_rows(tmp_path):
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=3)
    cfg = _study_configs(tmp_path / "configs") / "vae_pose.json"
    run = tmp_path / "run"
    _train(cfg, run, data)
    with pytest.raises(ValueError, match="equal budget"):
        score_vae_probe(_stage_doc(4), run, label="x", change={}, base_variant="pose", data=data, evaluator=object())
    with pytest.raises(ValueError, match="not a row of vaes@2"):
        score_vae_probe(_stage_doc(2), run, label="x", change={}, base_variant="no_pos", data=data,
                        evaluator=object())
    with pytest.raises(ValueError, match="VAE group's stage"):
        score_vae_probe({**_stage_doc(2), "kind": "denoiser"}, run, label="x", change={}, base_variant="pose",
                        data=data, evaluator=object())


def test_the_kept_studys_probes_match_their_stage_and_config():
    """The committed record: each probe compares with a kept stage at its steps and protocol, and its parameter
    count is that of the config it trained with."""
    from salad_core.io import config_from_dict

    study = STUDY
    probes = load_probes(study / "probes.json")
    assert probes, "lab/records/ablations_v2/probes.json is missing"
    for name, probe in probes.items():
        stage = json.loads((SHIPPED / "evaluations" / f"{probe['stage']}.json").read_text())   # the kept study's are the shipped ones
        assert probe["steps"] == stage["steps"] and probe["base_variant"] in stage["rows"], name
        base = stage["rows"][probe["base_variant"]]["settings"]
        for key in ("split", "batch_size", "replications", "max_samples", "seed"):
            assert probe["settings"][key] == base[key], (name, key)
        if stage["kind"] == "vae":
            model = MotionVAE(config_from_dict(VAEConfig, probe["trained_config"]["model"]))
            assert probe["parameters"] == sum(p.numel() for p in model.parameters() if p.requires_grad), name
        else:                   # a denoiser probe: trained on the VAE it names, as its command says
            assert Path(probe["vae"]).name in Path(probe["trained_config"]["task"]["vae"]).parts, name
            assert f"--vae {probe['vae']}" in probe["commands"][0], name
        for key, value in probe["change"].items():
            if key == "vae":
                continue
            section, _, field = key.partition(".")
            assert probe["trained_config"][section][field] == value, (name, key)
        for metric in ("FID", "MPJPE" if stage["kind"] == "vae" else "R-precision top-3"):
            assert len(probe["values"][metric]) == stage["settings"]["replications"], (name, metric)


def _sampler_script():
    spec = importlib.util.spec_from_file_location("ablation_sampler_probe", script_path("ablation_sampler_probe.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_sampler_probe_refuses_what_is_not_the_shipped_stage(tmp_path):
    """The sampler probe rescores shipped denoisers with a stage's protocol: a VAE stage, a variant the stage did not
    score, or shipped models of other steps than the stage are refused before anything is loaded."""
    main = _sampler_script().main
    stage = tmp_path / "stage.json"
    common = ["--stage-eval", str(stage), "--num-steps", "50", "--data", str(tmp_path), "--out", str(tmp_path / "o.json")]
    stage.write_text(json.dumps({**_stage_doc(100), "kind": "vae"}))
    with pytest.raises(SystemExit, match="not a denoiser stage"):
        main([*common, "--variants", "st"])
    rows = {"full": {"summary": {}}, "x0": {"summary": {}}}
    stage.write_text(json.dumps({"kind": "denoiser", "stage": "denoisers@100", "steps": 100, "rows": rows,
                                 "settings": {"num_steps": 10}}))
    with pytest.raises(SystemExit, match="'no_film' is not a row"):
        main([*common, "--variants", "full", "no_film"])
    shipped = json.loads((REPO / "salad_core" / "weights" / "ablations" / "index.json").read_text())["full"]["steps"]
    with pytest.raises(SystemExit, match=f"shipped 'full' has {shipped} steps, the stage 100"):
        main([*common, "--variants", "full", "x0"])
    with pytest.raises(SystemExit, match="at least 1"):
        main([*common[:2], "--num-steps", "0", *common[4:], "--variants", "full"])
    assert not (tmp_path / "o.json").exists()


def test_sampler_probe_markdown_prints_both_sampler_settings_side_by_side():
    from salad_lab.probes import sampler_probe_markdown

    row = lambda f10, f50: {"at_stage": {"FID": [f10, 0.1], "R-precision top-3": [0.8, 0.01]},
                            "summary": {"FID": [f50, 0.2], "R-precision top-3": [0.7, 0.02]}}
    record = {"denoisers@8000, 50 steps": {
        "num_steps": 50, "stage_num_steps": 10, "rows": {"full": row(3.0, 2.5), "x0": row(3.5, 3.25)},
        "paired": {"full vs x0, FID": {"at_stage": [0.5, 0.25], "probe": [0.75, 0.5]}}, "command": "python probe"}}
    text = sampler_probe_markdown(record)
    assert "| `full` | 3.000 ± 0.100 | 2.500 ± 0.200 | 0.800 ± 0.010 | 0.700 ± 0.020 |" in text
    assert "| full vs x0, FID | +0.500 ± 0.250 | +0.750 ± 0.500 |" in text
    assert "FID, 10 steps | FID, 50 steps" in text and "Made by: `python probe`" in text


def _den_study(root: Path, data: Path) -> tuple[Path, Path]:
    """A study's work folder as the staged study leaves it: two denoiser variants (v and x prediction, tiny) trained
    2 steps at a constant learning rate on one frozen VAE, their configs in ``configs/``."""
    from salad_core.train import train_vae
    from salad_core.cli.train import main as train_main
    from salad_core.train.config import VAETrainConfig

    vae = root / "vae"
    train_vae(data, vae, VAEConfig(latent_dim=8, n_extra_layers=0),
              VAETrainConfig(batch_size=8, max_steps=0, window=64, val_every=0, ckpt_every=0, num_threads=1,
                             progress=False))
    (root / "configs").mkdir(parents=True)
    for name, pred in (("full", "v_prediction"), ("x0", "sample")):
        cfg = root / "configs" / f"den_{name}.json"
        cfg.write_text(json.dumps({
            "model": {"latent_dim": 8, "width": 16, "heads": 2, "ff_dim": 32, "layers": 1, "text_dim": 384},
            "diffusion": {"prediction_type": pred}, "text_encoder": "minilm",
            "train": {"batch_size": 4, "max_steps": 2, "lr": 2e-3, "warmup_steps": 1, "milestones": [], "gamma": 0.2,
                      "max_length": 72, "val_every": 0, "ckpt_every": 0, "log_every": 1, "num_threads": 1}}))
        assert train_main(["denoiser", "--data", str(data), "--out", str(root / f"den_{name}"), "--config", str(cfg),
                           "--vae", str(vae), "--no-progress"]) == 0
    return root, vae


def _den_stage_doc(steps: int) -> dict:
    settings = {"split": "test", "batch_size": 4, "replications": 2, "max_samples": 4, "mm": False, "seed": 0,
                "num_steps": 2}
    rows = {v: {"variant": v, "label": lab, "steps": steps, "values": {"FID": f, "R-precision top-3": r},
                "summary": {"FID": [sum(f) / 2, 0.1], "R-precision top-3": [sum(r) / 2, 0.05]}}
            for v, lab, f, r in (("full", "v prediction", [3.0, 3.2], [0.8, 0.82]),
                                 ("x0", "x prediction", [3.1, 3.5], [0.75, 0.8]))}
    return {"stage": f"dens@{steps}", "group": "dens", "kind": "denoiser", "steps": steps, "settings": settings,
            "rows": rows}


def test_continuation_probe_continues_the_study_runs_with_a_decaying_rate_and_scores_them_paired(tmp_path,
                                                                                                monkeypatch):
    """prepare copies the study's runs (train state included) and writes their configs with the change; the runs
    resume where the study stopped and train on with the new schedule; score assembles each with the frozen VAE,
    scores it with the stage's protocol and records both rows and the pair's paired gap at the stage and after."""
    import functools

    import salad_core.eval.train_evaluator
    import salad_core.text
    from salad_core.cli.train import main as train_main
    from _lab import load_script

    monkeypatch.setattr(salad_core.text, "load_text_encoder", functools.lru_cache(salad_core.text.load_text_encoder))
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=6)
    work, vae = _den_study(tmp_path / "work", data)
    mod = load_script("ablation_continuation_probe")
    out_dir = tmp_path / "decay"
    assert mod.main(["prepare", "--study-work", str(work), "--variants", "full", "x0", "--set", "train.max_steps=4",
                     "train.milestones=[1]", "--out-dir", str(out_dir)]) == 0
    for name in ("full", "x0"):
        cfg = json.loads((out_dir / f"den_{name}.json").read_text())
        base = json.loads((work / "configs" / f"den_{name}.json").read_text())
        assert cfg["train"].pop("max_steps") == 4 and cfg["train"].pop("milestones") == [1]
        assert base["train"].pop("max_steps") == 2 and base["train"].pop("milestones") == []
        assert cfg == base
        assert (out_dir / f"den_{name}" / "train_state.json").is_file()
        # continue from the copied train state: the study's steps 1-2 at the warm-up and the constant rate, the
        # continued steps 3 and 4 at x0.2 (milestone 1 after 1 warm-up step; a log line's step counts from 1)
        assert train_main(["denoiser", "--data", str(data), "--out", str(out_dir / f"den_{name}"), "--config",
                           str(out_dir / f"den_{name}.json"), "--vae", str(vae), "--no-progress", "--resume"]) == 0
        logs = [json.loads(line) for line in (out_dir / f"den_{name}" / "log.jsonl").read_text().splitlines()]
        lrs = {d["step"]: d["lr"] for d in logs if "lr" in d}
        assert [lrs[k] for k in (1, 2, 3, 4)] == pytest.approx([1e-3, 2e-3, 4e-4, 4e-4])
        # the study's own run is untouched
        assert json.loads((work / f"den_{name}" / "latest.json").read_text())["meta"]["step"] == 2
    # a second prepare of the folder (another variant) is recorded beside the first; the same one is not repeated
    assert mod.main(["prepare", "--study-work", str(work), "--variants", "x0", "--set", "train.max_steps=4",
                     "train.milestones=[1]", "--out-dir", str(out_dir)]) == 0
    assert mod.main(["prepare", "--study-work", str(work), "--variants", "x0", "--set", "train.max_steps=4",
                     "train.milestones=[1]", "--out-dir", str(out_dir)]) == 0
    prepared = (out_dir / "prepare_command.txt").read_text().splitlines()
    assert len(prepared) == 2 and all("--set train.max_steps=4" in c for c in prepared)
    assert "--variants full x0" in prepared[0] and "--variants x0 --set" in prepared[1]

    evaluator = make_tiny_evaluator(data, dim_word=8, dim_text_hidden=16, dim_coemb=32, dim_movement_enc_hidden=16,
                                    dim_movement_latent=16, dim_motion_hidden=32)
    monkeypatch.setattr(salad_core.eval.train_evaluator, "load_packaged_evaluator", lambda *a, **k: (evaluator,))
    stage = _den_stage_doc(2)
    stage_file = tmp_path / "dens@2.json"
    stage_file.write_text(json.dumps(stage))
    record = tmp_path / "continuation_probe.json"
    assert mod.main(["score", "--stage-eval", str(stage_file), "--out-dir", str(out_dir), "--variants", "full", "x0",
                     "--name", "decay", "--change-text", "lr x0.2 from step 2", "--data",
                     str(data), "--out", str(record)]) == 0
    probe = json.loads(record.read_text())["decay"]
    assert probe["from_step"] == 2 and probe["steps"] == 4 and probe["stage"] == "dens@2"
    for name in ("full", "x0"):
        row = probe["rows"][name]
        assert row["steps"] == 4 and row["from_step"] == 2
        assert all(len(v) == 2 and np.isfinite(v).all() for v in row["values"].values())
        assert row["at_stage"] == stage["rows"][name]["summary"]
        for key in ("split", "batch_size", "replications", "max_samples", "seed", "num_steps"):
            assert row["settings"][key] == stage["settings"][key], key
    # the paired gap, at the stage from its rows, after the continuation from the probe's rows
    from salad_lab.orderings import paired_advantage

    pair = probe["paired"]["full vs x0, R-precision top-3"]
    assert pair["at_stage"] == pytest.approx(list(paired_advantage([0.8, 0.82], [0.75, 0.8], "R-precision top-3")))
    assert pair["probe"] == pytest.approx(list(paired_advantage(probe["rows"]["full"]["values"]["R-precision top-3"],
                                                                probe["rows"]["x0"]["values"]["R-precision top-3"],
                                                                "R-precision top-3")))
    assert probe["commands"][:2] == prepared and probe["commands"][2].startswith(
        "python lab/scripts/ablations/ablation_continuation_probe.py score")
    from salad_lab.probes import continuation_probe_markdown, score_denoiser_continuation

    table = continuation_probe_markdown({"decay": probe})
    assert "| `full` | 3.100 ± 0.100 |" in table and "| full vs x0, FID | +0.200 ± " in table
    # a run not past the stage, or a VAE stage, is refused
    with pytest.raises(ValueError, match="trained past its 4 steps"):
        score_denoiser_continuation(_den_stage_doc(4), out_dir / "den_full", vae=vae, label="x", data=data,
                                    evaluator=evaluator)
    with pytest.raises(ValueError, match="denoiser probes compare with a denoiser group's stage"):
        score_denoiser_continuation({**stage, "kind": "vae"}, out_dir / "den_full", vae=vae, label="x", data=data,
                                    evaluator=evaluator)


def test_paired_probe_markdown_pairs_stage_rows_and_probes_and_refuses_unpaired_ones():
    """Probes of a stage share its crops: a probe and a stage row are paired as two rows are; the gap is the
    orderings module's paired advantage, in cm for MPJPE; a probe scored otherwise, or an unknown name, is refused."""
    from salad_lab.orderings import paired_advantage
    from salad_lab.probes import paired_probe_markdown

    stage = {**_stage_doc(2), "settings": dict(SETTINGS)}
    stage["rows"]["st"]["values"] = {"FID": [0.5, 0.52], "MPJPE": [0.040, 0.042]}
    stage["rows"]["pose"]["values"] = {"FID": [0.4, 0.41], "MPJPE": [0.030, 0.031]}
    probe = {"stage": "vaes@2", "settings": dict(SETTINGS), "values": {"FID": [0.6, 0.66], "MPJPE": [0.050, 0.050]}}
    table = paired_probe_markdown(stage, {"narrow": probe}, [("st", "pose"), ("st", "narrow")]).splitlines()
    assert table[0] == "| pair | FID | MPJPE (cm) |" and len(table) == 4
    fid = paired_advantage([0.5, 0.52], [0.6, 0.66], "FID")
    mpjpe = paired_advantage([0.040, 0.042], [0.050, 0.050], "MPJPE")
    assert table[3] == (f"| `st` over `narrow` | {fid[0]:+.4f} ± {fid[1]:.4f} | "
                        f"{mpjpe[0] * 100:+.2f} ± {mpjpe[1] * 100:.2f} |")
    assert table[2].startswith("| `st` over `pose` | -0.1050 ± ")
    with pytest.raises(ValueError, match="not paired"):
        paired_probe_markdown(stage, {"narrow": {**probe, "settings": {**SETTINGS, "seed": 1}}}, [("st", "narrow")])
    with pytest.raises(KeyError, match="neither a row of vaes@2"):
        paired_probe_markdown(stage, {"narrow": {**probe, "stage": "vaes@4"}}, [("st", "narrow")])


def test_denoiser_probe_trains_a_variant_on_another_vae_and_is_scored_paired_and_continued(tmp_path, monkeypatch):
    """The denoiser probe: a study variant's config (only --set keys changed) trained on another frozen VAE to the
    stage's budget, scored with the stage's protocol (the same figures when scored again), recorded with its
    commands and printed beside the stage's rows; then continued past the stage with the study's runs and scored
    paired with them, its figures at the stage read from the probe record."""
    import functools

    import salad_core.eval.train_evaluator
    import salad_core.text
    from salad_lab.probes import score_denoiser_probe
    from salad_core.train import train_vae
    from salad_core.cli.train import main as train_main
    from salad_core.train.config import VAETrainConfig
    from _lab import load_script

    monkeypatch.setattr(salad_core.text, "load_text_encoder", functools.lru_cache(salad_core.text.load_text_encoder))
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=6)
    work, _ = _den_study(tmp_path / "work", data)
    other_vae = tmp_path / "other_vae"                 # another VAE of the same latent shape (other seed, trained)
    train_vae(data, other_vae, VAEConfig(latent_dim=8, n_extra_layers=0),
              VAETrainConfig(batch_size=8, max_steps=2, window=64, val_every=0, ckpt_every=0, num_threads=1,
                             progress=False, seed=7))
    mod = load_script("ablation_denoiser_probe")
    cfg = tmp_path / "probe" / "den_x0_other.json"
    assert mod.main(["config", "--study-configs", str(work / "configs"), "--variant", "x0", "--vae", str(other_vae),
                     "--set", "train.lr=0.001", "--out", str(cfg)]) == 0
    probe_cfg, base = json.loads(cfg.read_text()), json.loads((work / "configs" / "den_x0.json").read_text())
    assert probe_cfg["train"].pop("lr") == 0.001 and base["train"].pop("lr") == 2e-3 and probe_cfg == base
    with pytest.raises(SystemExit, match="one of its den variants"):
        mod.main(["config", "--study-configs", str(work / "configs"), "--variant", "no_st", "--vae", str(other_vae),
                  "--out", str(cfg)])
    run = cfg.with_suffix("")
    assert train_main(["denoiser", "--data", str(data), "--out", str(run), "--config", str(cfg), "--vae",
                       str(other_vae), "--no-progress"]) == 0

    evaluator = make_tiny_evaluator(data, dim_word=8, dim_text_hidden=16, dim_coemb=32, dim_movement_enc_hidden=16,
                                    dim_movement_latent=16, dim_motion_hidden=32)
    monkeypatch.setattr(salad_core.eval.train_evaluator, "load_packaged_evaluator", lambda *a, **k: (evaluator,))
    stage = _den_stage_doc(2)
    stage_file = tmp_path / "dens@2.json"
    stage_file.write_text(json.dumps(stage))
    record = tmp_path / "probes.json"
    assert mod.main(["score", "--stage-eval", str(stage_file), "--run", str(run), "--vae", str(other_vae),
                     "--vae-label", "the other VAE", "--name", "x0_other", "--variant", "x0", "--set",
                     "train.lr=0.001", "train.num_threads=1", "--label", "x prediction on another VAE", "--data",
                     str(data), "--out", str(record)]) == 0
    probe = load_probes(record)["x0_other"]
    assert probe["change"] == {"vae": "the other VAE", "train.lr": 0.001}      # threads are not a change
    assert probe["steps"] == 2 and probe["stage"] == "dens@2" and probe["base_variant"] == "x0"
    assert Path(probe["trained_config"]["task"]["vae"]).parent == other_vae      # its checkpoint, <run>/latest
    for key in ("split", "batch_size", "replications", "max_samples", "seed", "num_steps"):
        assert probe["settings"][key] == stage["settings"][key], key
    assert set(probe["values"]) >= {"FID", "R-precision top-3"}
    assert all(len(probe["values"][m]) == 2 and np.isfinite(probe["values"][m]).all()
               for m in ("FID", "R-precision top-3"))
    assert "--vae-label 'the other VAE'" in probe["commands"][1] and f"--vae {other_vae}" in probe["commands"][0]
    again = score_denoiser_probe(stage, run, vae=other_vae, label="again", change={}, base_variant="x0", data=data,
                                 evaluator=evaluator)
    assert again["values"] == probe["values"]
    lines = probe_markdown(stage, {"x0_other": probe}).strip().splitlines()
    assert lines[0] == "| model | parameters | FID | R-precision top-3 |" and len(lines) == 2 + 2 + 1
    assert lines[2] == "| v prediction (full) | - | 3.100 ± 0.100 | 0.810 ± 0.050 |"
    assert lines[4].startswith("| **probe** x prediction on another VAE (x0 with vae = the other VAE, "
                               "train.lr = 0.001) | - | ")
    with pytest.raises(ValueError, match="equal budget"):
        score_denoiser_probe(_den_stage_doc(4), run, vae=other_vae, label="x", change={}, base_variant="x0",
                             data=data, evaluator=evaluator)
    with pytest.raises(ValueError, match="not a row of dens@2"):
        score_denoiser_probe(stage, run, vae=other_vae, label="x", change={}, base_variant="eps", data=data,
                             evaluator=evaluator)

    # continued past the stage beside the study's run, scored paired with it; its figures at the stage: the probe's
    cont = load_script("ablation_continuation_probe")
    out_dir = tmp_path / "decay"
    assert cont.main(["prepare", "--study-work", str(work), "--variants", "full", f"x0_other={run}", "--set",
                      "train.max_steps=3", "--out-dir", str(out_dir)]) == 0
    assert json.loads((out_dir / "den_x0_other.json").read_text())["train"]["lr"] == 0.001
    for name in ("full", "x0_other"):
        task = json.loads((out_dir / f"den_{name}" / "config.json").read_text())["task"]
        assert train_main(["denoiser", "--data", str(data), "--out", str(out_dir / f"den_{name}"), "--config",
                           str(out_dir / f"den_{name}.json"), "--vae", task["vae"], "--no-progress", "--resume"]) == 0
    cont_record = tmp_path / "continuation_probe.json"
    score = ["score", "--stage-eval", str(stage_file), "--out-dir", str(out_dir), "--variants", "full", "x0_other",
             "--name", "longer", "--change-text", "one more step", "--data", str(data), "--out", str(cont_record)]
    with pytest.raises(SystemExit, match="needs --probes"):
        cont.main(score)
    with pytest.raises(SystemExit, match="holds no trained run"):          # a probe of the stage not continued
        cont.main(["score", "--stage-eval", str(stage_file), "--out-dir", str(tmp_path / "elsewhere"), "--variants",
                   "full", "x0_other", "--probes", str(record), "--name", "n", "--change-text", "t", "--data",
                   str(data), "--out", str(cont_record)])
    assert cont.main(score + ["--probes", str(record)]) == 0
    longer = json.loads(cont_record.read_text())["longer"]
    assert longer["steps"] == 3
    assert longer["rows"]["x0_other"]["at_stage"] == {m: probe["summary"][m] for m in ("FID", "R-precision top-3")}
    assert longer["rows"]["x0_other"]["label"].startswith("x prediction on another VAE, one more step")
    from salad_lab.orderings import paired_advantage

    pair = longer["paired"]["full vs x0_other, FID"]
    assert pair["at_stage"] == pytest.approx(list(paired_advantage(stage["rows"]["full"]["values"]["FID"],
                                                                   probe["values"]["FID"], "FID")))
    # scored again with another guidance weight: the stage's crops and noise, the sampler's weight recorded and
    # printed; a setting that would unpair the rows is refused
    assert cont.main(["score", "--stage-eval", str(stage_file), "--out-dir", str(out_dir), "--variants", "full",
                      "x0_other", "--name", "longer_w2", "--change-text", "one more step", "--sampler",
                      "guidance_scale=2.0", "--probes", str(record), "--data", str(data), "--out",
                      str(cont_record)]) == 0
    w2 = json.loads(cont_record.read_text())["longer_w2"]
    assert w2["sampler"] == {"guidance_scale": 2.0} and set(json.loads(cont_record.read_text())) == {"longer",
                                                                                                    "longer_w2"}
    for name in ("full", "x0_other"):
        assert w2["rows"][name]["settings"]["guidance_scale"] == 2.0
        assert longer["rows"][name]["settings"]["guidance_scale"] == stage["settings"].get("guidance_scale", 7.5)
        for key in ("split", "batch_size", "replications", "max_samples", "seed", "num_steps"):
            assert w2["rows"][name]["settings"][key] == stage["settings"][key], key
    assert w2["rows"]["full"]["values"] != longer["rows"]["full"]["values"]        # the weight changed the samples
    from salad_lab.probes import continuation_probe_markdown, score_denoiser_continuation

    text = continuation_probe_markdown({"longer_w2": w2})
    assert "the stage's protocol with guidance_scale 2.0" in text and "at 3, guidance_scale 2.0" in text
    with pytest.raises(ValueError, match=r"\['seed'\] are not sampler settings"):
        score_denoiser_continuation(stage, out_dir / "den_full", label="x", data=data, evaluator=evaluator,
                                    sampler={"seed": 3})


def test_continued_pairs_markdown_pairs_rows_of_different_continuation_probes():
    """Rows continued from one stage to one step with one sampler are paired across probes: the gap is the
    orderings module's paired advantage; a run scored twice must agree (to float rounding), and rows of another
    sampler, stage or step, or an unknown variant, are refused."""
    from salad_lab.orderings import paired_advantage
    from salad_lab.probes import continued_pairs_markdown

    def row(fid, top3):
        return {"values": {"FID": fid, "R-precision top-3": top3}}

    seed_a = {"stage": "denoisers@8", "steps": 10, "sampler": None,
              "rows": {"full": row([1.6, 1.8], [0.85, 0.86]), "no_st": row([1.5, 1.6], [0.83, 0.83])}}
    seed_b = {"stage": "denoisers@8", "steps": 10, "sampler": {},
              "rows": {"full_b": row([1.7, 1.6], [0.84, 0.85]), "full": row([1.6 + 1e-9, 1.8], [0.85, 0.86])}}
    weak = {"stage": "denoisers@8", "steps": 10, "sampler": {"guidance_scale": 4.5},
            "rows": {"full": row([1.1, 1.2], [0.8, 0.8]), "no_st": row([1.3, 1.2], [0.8, 0.81])}}
    record = {"a": seed_a, "b": seed_b, "w4.5": weak}
    table = continued_pairs_markdown(record, [("full_b", "no_st"), ("full", "full_b")]).splitlines()
    assert table[0] == "| pair, at 10 steps | FID | R-precision top-3 |" and len(table) == 4
    fid = paired_advantage([1.7, 1.6], [1.5, 1.6], "FID")
    top3 = paired_advantage([0.84, 0.85], [0.83, 0.83], "R-precision top-3")
    assert table[2] == f"| `full_b` over `no_st` | {fid[0]:+.3f} ± {fid[1]:.3f} | {top3[0]:+.3f} ± {top3[1]:.3f} |"
    assert fid[0] < 0 < top3[0]
    weak_table = continued_pairs_markdown(record, [("full", "no_st")], sampler={"guidance_scale": 4.5})
    assert f"| `full` over `no_st` | {paired_advantage([1.1, 1.2], [1.3, 1.2], 'FID')[0]:+.3f}" in weak_table
    with pytest.raises(KeyError, match="'full_b' is in no probe"):
        continued_pairs_markdown(record, [("full", "full_b")], sampler={"guidance_scale": 4.5})
    with pytest.raises(ValueError, match="not the same run"):
        continued_pairs_markdown({**record, "b": {**seed_b, "rows": {**seed_b["rows"], "full": row([1.0, 1.8],
                                                                                              [0.85, 0.86])}}},
                                 [("full", "no_st")])
    with pytest.raises(ValueError, match="not paired"):
        continued_pairs_markdown({**record, "b": {**seed_b, "steps": 12}}, [("full_b", "no_st")])
    with pytest.raises(ValueError, match="one table per step"):
        continued_pairs_markdown({**record, "c": {**seed_b, "steps": 12, "rows": {"x": row([1.0, 1.1], [0.8, 0.8]),
                                                                                 "y": row([1.0, 1.2], [0.8, 0.8])}}},
                                 [("full_b", "no_st"), ("x", "y")])


#: train settings that say where and how fast a run trained, not what it learnt: a probe may change them mid-run
#: (full_w128 went from one to two threads at step 2,500, session 35)
RUNTIME_KEYS = ("latent_cache_dir", "num_threads")


def test_study_configs_rebuild_a_restored_studys_denoiser_configs_as_its_probes_trained_them(tmp_path):
    """On a new machine the study is restored from lab/records/ablations_v2 (no run folders, no configs/); the
    ``study-configs`` step writes each denoiser's final-stage config and its frozen VAE. They must be what the
    study's denoiser probes trained with: the committed probes' trained configs, less their recorded changes."""
    from salad_lab import load_staged_recipe, restore_group

    spec = importlib.util.spec_from_file_location("ablation_denoiser_probe", script_path("ablation_denoiser_probe.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    recipe_path = REPO / "lab" / "configs" / "ablations_v2.json"
    recipe = load_staged_recipe(recipe_path)
    work = tmp_path / "work"
    with pytest.raises(SystemExit, match="restore the study first"):
        mod.main(["study-configs", "--recipe", str(recipe_path), "--work", str(work)])
    for group in recipe.groups:
        assert restore_group(recipe, group, STUDY, work)
    assert mod.main(["study-configs", "--recipe", str(recipe_path), "--work", str(work)]) == 0
    vaes = json.loads((work / "study_vaes.json").read_text())
    assert vaes["full"] == str(work / "stages" / "vaes@6000" / "models" / "vae_st_long" / "vae")
    assert vaes["no_st"] == str(work / "stages" / "vaes@6000" / "models" / "vae_pose_long" / "vae")
    assert all((Path(v).parent / "vae.safetensors").is_file() for v in vaes.values())
    compared = 0
    for name, probe in load_probes(STUDY / "probes.json").items():
        if probe["stage"] != "denoisers@8000" or probe["change"].get("vae") != "the study's own VAE for this row":
            continue
        config = json.loads((work / "configs" / f"den_{probe['base_variant']}.json").read_text())
        trained = probe["trained_config"]
        changed = {k for k in probe["change"] if k != "vae"}
        for section in ("model", "train", "diffusion"):
            for key, value in config.get(section, {}).items():
                if f"{section}.{key}" in changed or key in RUNTIME_KEYS:
                    continue
                got = trained[section][key] if section != "diffusion" else trained["task"]["diffusion"][key]
                assert got == value, (name, section, key)
        assert Path(vaes[probe["base_variant"]]).parts[-3:] == Path(trained["task"]["vae"]).parts[-3:], name
        compared += 1
    assert compared >= 2       # the seed and size probes of session 32-33 at least
    # written again: identical, kept; a config edited by hand is not overwritten
    assert mod.main(["study-configs", "--recipe", str(recipe_path), "--work", str(work)]) == 0
    edited = work / "configs" / "den_full.json"
    edited.write_text(json.dumps({**json.loads(edited.read_text()), "model": {"width": 1}}))
    with pytest.raises(SystemExit, match="differs"):
        mod.main(["study-configs", "--recipe", str(recipe_path), "--work", str(work)])


def test_sampler_probe_markdown_names_a_guidance_probe_by_its_weight():
    from salad_lab.probes import sampler_probe_markdown

    row = {"at_stage": {"FID": [2.0, 0.1], "R-precision top-3": [0.8, 0.01]},
           "summary": {"FID": [4.0, 0.2], "R-precision top-3": [0.6, 0.02]}}
    record = {"denoisers@8000, 10 steps, w 1": {
        "num_steps": 10, "stage_num_steps": 10, "guidance_scale": 1.0, "stage_guidance_scale": 7.5,
        "rows": {"full": row, "no_st": row}, "paired": {"full vs no_st, FID": {"at_stage": [0.1, 0.2], "probe": [1.0, 0.5]}},
        "command": "python probe --guidance 1"}}
    text = sampler_probe_markdown(record)
    assert "10 sampler steps and guidance weight 1)" in text
    assert "FID, 10 steps, w 7.5 | FID, 10 steps, w 1" in text
    assert "| full vs no_st, FID | +0.100 ± 0.200 | +1.000 ± 0.500 |" in text


def test_sampler_probe_markdown_names_a_refined_guidance_and_its_guided_steps():
    from salad_lab.probes import sampler_probe_markdown

    row = {"at_stage": {"FID": [2.0, 0.1], "R-precision top-3": [0.8, 0.01]},
           "summary": {"FID": [6.5, 0.2], "R-precision top-3": [0.7, 0.02]}}
    record = {"denoisers@8000, 10 steps, w=7.5 t/T in [0,0.5]": {
        "num_steps": 10, "stage_num_steps": 10, "guidance_scale": 7.5, "stage_guidance_scale": 7.5,
        "guidance_rescale": 0.0, "guidance_interval": [0.0, 0.5], "guided_timesteps": [500, 400, 300, 200, 100, 0],
        "rows": {"full": row, "no_st": row}, "paired": {"full vs no_st, FID": {"at_stage": [0.1, 0.2], "probe": [-3.5, 1.0]}},
        "command": "python probe --interval 0-0.5"}}
    text = sampler_probe_markdown(record)
    assert "guidance weight 7.5, only at 0 <= t/T <= 0.5 (guided timesteps: 500, 400, 300, 200, 100, 0))" in text
    assert "FID, 10 steps, w 7.5 | FID, 10 steps, w 7.5 (only at 0 <= t/T <= 0.5)" in text
    assert "| full vs no_st, FID | +0.100 ± 0.200 | -3.500 ± 1.000 |" in text
    record[next(iter(record))].update(guidance_interval=None, guidance_rescale=0.7, guided_timesteps=None)
    assert "FID, 10 steps, w 7.5 (rescale 0.7)" in sampler_probe_markdown(record)


def test_guidance_pair_markdown_orders_one_pair_under_each_guidance():
    """One row for the stage's setting (its paired advantage computed from the replications), one per probe that
    scored both variants at the stage's steps with the pair's first variant first; other probes are left out."""
    from salad_lab.probes import guidance_pair_markdown

    stage = {"settings": {"num_steps": 10, "guidance_scale": 7.5},
             "rows": {"full": {"summary": {"FID": [3.0, 0.2], "R-precision top-3": [0.81, 0.01]},
                               "values": {"FID": [3.0, 3.2, 2.8], "R-precision top-3": [0.8, 0.81, 0.82]}},
                      "no_st": {"summary": {"FID": [2.0, 0.4], "R-precision top-3": [0.79, 0.02]},
                                "values": {"FID": [2.0, 2.1, 1.9], "R-precision top-3": [0.79, 0.80, 0.78]}}}}
    row = lambda f: {"summary": {"FID": [f, 0.5], "R-precision top-3": [0.7, 0.02]}}
    pair = lambda f, r: {"full vs no_st, FID": {"probe": [f, 0.4]}, "full vs no_st, R-precision top-3": {"probe": [r, 0.03]}}
    record = {
        "s, 50 steps": {"num_steps": 50, "guidance_scale": 7.5, "rows": {"full": row(1), "no_st": row(1)},
                        "paired": pair(9, 9)},
        "s, 10 steps, w 1": {"num_steps": 10, "guidance_scale": 1.0, "rows": {"full": row(11.0), "no_st": row(11.5)},
                             "paired": pair(0.5, -0.01)},
        "s, interval": {"num_steps": 10, "guidance_scale": 7.5, "guidance_rescale": 0.0, "guidance_interval": [0.0, 0.5],
                        "guided_timesteps": [500, 0], "rows": {"full": row(6.5), "no_st": row(3.0)},
                        "paired": pair(-3.5, -0.04)},
        "s, w 2": {"num_steps": 10, "guidance_scale": 2.0, "guidance_rescale": 0.0, "guidance_interval": None,
                   "guided_timesteps": list(range(900, -1, -100)), "rows": {"full": row(2.5), "no_st": row(2.0)},
                   "paired": pair(-0.5, 0.01)},
        "s, other first": {"num_steps": 10, "guidance_scale": 2.0, "rows": {"no_st": row(1), "full": row(1)},
                           "paired": {}},
    }
    text = guidance_pair_markdown(stage, record, "full", "no_st")
    lines = text.strip().splitlines()
    assert len(lines) == 6                                       # head, rule, the stage, w 1, the interval, w 2
    assert lines[2] == ("| w 7.5 at every step (the stage) | all | 3.000 ± 0.200 | 2.000 ± 0.400 | 0.810 ± 0.010 | "
                        "0.790 ± 0.020 | -1.000 ± 0.092 | +0.020 ± 0.016 |")   # 1.96 sd / sqrt(3), sd over 3
    assert lines[3].startswith("| w 1 (no guidance) | none | 11.000 ± 0.500 | 11.500 ± 0.500 |")
    assert lines[3].endswith("| +0.500 ± 0.400 | -0.010 ± 0.030 |")
    assert lines[4].startswith("| w 7.5, only at 0 <= t/T <= 0.5 | 500, 0 | 6.500 ± 0.500 | 3.000 ± 0.500 |")
    assert lines[5].startswith("| w 2 | all | 2.500 ± 0.500 | 2.000 ± 0.500 |")      # every step guided
    assert "9.000" not in text


def test_sampler_probe_refuses_a_bad_interval_or_rescale_before_loading(tmp_path):
    main = _sampler_script().main
    stage = tmp_path / "stage.json"
    stage.write_text(json.dumps({"kind": "denoiser", "stage": "denoisers@100", "steps": 100, "rows": {"full": {}},
                                 "settings": {"num_steps": 10, "guidance_scale": 7.5}}))
    common = ["--stage-eval", str(stage), "--data", str(tmp_path), "--out", str(tmp_path / "o.json"), "--variants", "full"]
    with pytest.raises(SystemExit, match="--interval 'low': give LO-HI"):
        main([*common, "--interval", "low"])
    with pytest.raises(SystemExit, match="0 <= lo < hi <= 1"):
        main([*common, "--interval", "0.8-0.2"])
    with pytest.raises(SystemExit, match=r"rescale must be in \[0, 1\]"):
        main([*common, "--rescale", "2"])
    assert not (tmp_path / "o.json").exists()


def test_sampler_probe_guides_only_inside_its_interval(tmp_path, monkeypatch):
    """``--interval``: each shipped pipeline is called with the whole Guidance (weight, interval), and the record
    names the guided timesteps of the stage's sampler (10 DDIM steps: 900 ... 0)."""
    import salad_lab as abl
    import salad_core.eval as ev
    import salad_core.eval.train_evaluator as te
    import salad_core.text as text
    from salad_core.sampling import Guidance

    mod = _sampler_script()
    calls = []

    class FakePipe:
        diffusion = None
        solver = "ddim"

        def __call__(self, prompts, **kwargs):
            from types import SimpleNamespace

            calls.append(kwargs["guidance_scale"])
            return SimpleNamespace(features=np.zeros((len(prompts), 40, 3)), joints=[None] * len(prompts))

    class Result:
        values = {"FID": [1.0, 2.0], "R-precision top-3": [0.5, 0.6]}

        def summary(self):
            return {"FID": (1.5, 0.1), "R-precision top-3": (0.55, 0.01)}

    def fake_eval(gen, data, evaluator, settings, **kw):
        gen(["a person walks"], lengths=[40], seed=0, guidance_scale=settings.guidance_scale,
            num_steps=settings.num_steps)
        return Result()

    steps = json.loads((REPO / "salad_core" / "weights" / "ablations" / "index.json").read_text())["full"]["steps"]
    stage = tmp_path / "stage.json"
    rows = {v: {"summary": {"FID": [1.0, 0.1], "R-precision top-3": [0.5, 0.01]},
                "values": {"FID": [1.0, 2.0], "R-precision top-3": [0.5, 0.6]}} for v in ("full", "no_st")}
    stage.write_text(json.dumps({**_stage_doc(steps), "kind": "denoiser", "stage": f"denoisers@{steps}", "rows": rows,
                                 "settings": {**_stage_doc(steps)["settings"], "num_steps": 10, "guidance_scale": 7.5}}))
    monkeypatch.setattr(abl, "load_ablation_pipeline", lambda *a, **k: FakePipe())
    monkeypatch.setattr(ev, "evaluate_generator", fake_eval)
    monkeypatch.setattr(te, "load_packaged_evaluator", lambda: (None,))
    monkeypatch.setattr(text, "load_text_encoder", lambda name: None)
    out = tmp_path / "o.json"
    assert mod.main(["--stage-eval", str(stage), "--data", str(tmp_path), "--out", str(out),
                     "--variants", "full", "no_st", "--interval", "0-0.5"]) == 0
    assert calls == [Guidance(7.5, 0.0, (0.0, 0.5))] * 2
    rec = json.loads(out.read_text())[f"denoisers@{steps}, 10 steps, w=7.5 t/T in [0,0.5]"]
    assert rec["guided_timesteps"] == [500, 400, 300, 200, 100, 0]
    assert rec["guidance_interval"] == [0.0, 0.5] and rec["guidance_rescale"] == 0.0
    assert "--interval 0-0.5" in rec["command"]


def test_sampler_probe_refuses_a_guidance_weight_below_1(tmp_path):
    main = _sampler_script().main
    stage = tmp_path / "stage.json"
    stage.write_text(json.dumps({"kind": "denoiser", "stage": "denoisers@100", "steps": 100, "rows": {},
                                 "settings": {"num_steps": 10, "guidance_scale": 7.5}}))
    with pytest.raises(SystemExit, match="--guidance must be a weight >= 1"):
        main(["--stage-eval", str(stage), "--guidance", "0.5", "--data", str(tmp_path), "--out",
              str(tmp_path / "o.json"), "--variants", "full"])


def test_denoising_error_script_reads_a_probe_run_at_its_latest_checkpoint(tmp_path):
    """``NAME=RUN`` in lab/scripts/ablations/ablation_denoising_error.py: the run's latest weights, with the VAE it records, in fp16
    as the study's rows (a run with a better-validating ``best`` must not be read at ``best``)."""
    import shutil

    import torch

    from _lab import load_script
    from salad_core.io import load_model

    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=3)
    work, _ = _den_study(tmp_path / "work", data)
    run = work / "den_x0"
    shutil.copy(work / "den_full" / "latest.safetensors", run / "best.safetensors")   # a "best" of other weights
    shutil.copy(run / "latest.json", run / "best.json")
    pipe = load_script("ablation_denoising_error").run_pipeline(run)
    latest, _, _ = load_model(run / "latest")
    assert pipe.diffusion.prediction_type == "sample"
    for (name, got), want in zip(pipe.denoiser.state_dict().items(), latest.state_dict().values()):
        torch.testing.assert_close(got, want.half().float(), msg=name)
    with pytest.raises(SystemExit, match="holds no denoiser run"):
        load_script("ablation_denoising_error").run_pipeline(tmp_path / "corpus")
