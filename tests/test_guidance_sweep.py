"""Choosing the default guidance: the grid, the fixed-guidance wrapper, the rule, the sweep and its CLI."""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from salad_core.data.dataset import load_mean_std
from salad_core.eval import guidance_sweep as gs
from salad_core.eval.physics_prompts import BenchSettings
from salad_core.eval.settings import EvalSettings
from salad_core.motion import features_to_joints
from salad_core.sampling import Guidance
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
pytestmark = pytest.mark.usefixtures("single_thread")


def test_grid_is_the_product_in_order_and_labels_are_distinct():
    grid = gs.guidance_grid([1.0, 4.0], [0.0, 0.7], [None, (0.0, 0.5)])
    assert len(grid) == 8
    assert grid[0] == Guidance(1.0) and grid[1] == Guidance(1.0, 0.0, (0.0, 0.5)) and grid[-1] == Guidance(4.0, 0.7,
                                                                                                        (0.0, 0.5))
    assert [gs.guidance_label(g) for g in grid[:4]] == ["w=1", "w=1 t/T in [0,0.5]", "w=1 phi=0.7",
                                                        "w=1 phi=0.7 t/T in [0,0.5]"]
    with pytest.raises(ValueError, match="repeats a candidate"):
        gs.guidance_grid([2.0, 2.0])
    with pytest.raises(ValueError, match="empty"):
        gs.guidance_grid([])
    with pytest.raises(ValueError, match="rescale must be in"):
        gs.guidance_grid([2.0], [1.5])


def test_fixed_guidance_replaces_the_weight_the_protocol_asks_for():
    calls = []

    def pipe(prompts, **kw):
        calls.append(kw)
        return "out"

    g = Guidance(3.0, 0.5, (0.0, 0.6))
    gen = gs.FixedGuidance(pipe, g)
    assert gen(["a person walks"], lengths=[40], seed=2, guidance_scale=7.5, num_steps=5, solver="ddim") == "out"
    assert calls == [dict(lengths=[40], seed=2, guidance_scale=g, num_steps=5, solver="ddim")]
    with pytest.raises(TypeError, match="Guidance"):
        gs.FixedGuidance(pipe, 7.5)


def _row(label, r3, fid, targets_passed, bone=2.0):
    return {"label": label, "t2m": {"r_precision_top3": {"mean": r3, "ci": 0.01}, "fid": {"mean": fid, "ci": 0.1}},
            "physics": {"targets_passed": targets_passed, "bone_p95_cm": bone}}


def test_rule_text_faithfulness_first_then_physics_then_fid_then_bones():
    rows = [_row("w=1", 0.80, 0.5, 5),          # most plausible but ignores the text: not eligible
            _row("w=3", 0.955, 0.9, 3),         # eligible (0.955 >= 0.96 - 0.01), 3 targets
            _row("w=5", 0.960, 0.4, 2),         # best text, fewer targets
            _row("w=7", 0.951, 0.3, 3)]         # eligible, 3 targets, lower FID than w=3
    pick, why = gs.choose(rows)
    assert pick == 3 and why.startswith("w=7:") and "3 of 4 candidates" in why
    rows[3]["t2m"]["r_precision_top3"]["mean"] = 0.949           # falls out of the tolerance
    assert gs.choose(rows)[0] == 1
    rows[1]["t2m"]["fid"]["mean"] = 0.3                          # FID tie with nobody; bones break ties
    rows.append(_row("w=4", 0.958, 0.3, 3, bone=1.0))
    assert gs.choose(rows)[0] == 4
    rows[4]["t2m"]["fid"]["mean"] = float("nan")                 # a missing FID loses the tie
    assert gs.choose(rows)[0] == 1
    with pytest.raises(ValueError, match="no sweep rows"):
        gs.choose([])


class NoisyPipe:
    """Features around the corpus mean whose noise grows with the guidance weight (a stand-in whose
    FID and bone error must rise with w), recording the Guidance of every call."""

    source = "noisy"

    def __init__(self, mean, std):
        self.mean, self.std, self.seen = mean, std, []

    def __call__(self, prompts, lengths=None, seed=0, guidance_scale=None, num_steps=50):
        assert isinstance(guidance_scale, Guidance)
        self.seen.append(guidance_scale)
        seeds = seed if isinstance(seed, list) else [seed + i for i in range(len(prompts))]
        n = max(lengths)
        feats = np.zeros((len(prompts), n, SK.feature_dim), np.float32)
        for i, (s, m) in enumerate(zip(seeds, lengths)):
            z = np.random.default_rng(s).standard_normal((m, SK.feature_dim))
            feats[i, :m] = self.mean + 0.5 * guidance_scale.scale ** 2 * self.std * z
        return SimpleNamespace(features=feats, lengths=list(lengths))


def test_sweep_measures_every_candidate_with_both_protocols(tiny_procedural_corpus, tiny_random_evaluator):
    mean, std = load_mean_std(tiny_procedural_corpus)
    pipe = NoisyPipe(mean, std)
    grid = gs.guidance_grid([1.0, 6.0], [0.0, 0.5])
    settings = EvalSettings(replications=1, mm=False, seed=1)
    bench = BenchSettings(steps=1, seeds=(0, 1), num_prompts=2)

    def joints_of(out):
        return [features_to_joints(out.features[b, :n], SK) for b, n in enumerate(out.lengths)]

    lines = []
    res = gs.run_sweep(pipe, grid, tiny_procedural_corpus, tiny_random_evaluator, settings, bench,
                       joints_of=joints_of, log=lines.append)
    assert [r["label"] for r in res["rows"]] == ["w=1", "w=1 phi=0.5", "w=6", "w=6 phi=0.5"]
    assert {g.scale for g in pipe.seen} == {1.0, 6.0} and {g.rescale for g in pipe.seen} == {0.0, 0.5}
    assert "corpus test split (real)" in res["references"]
    by = {r["label"]: r for r in res["rows"]}
    # the noise grows with w: the distribution moves away (FID) and the bones stretch
    assert by["w=6"]["t2m"]["fid"]["mean"] > by["w=1"]["t2m"]["fid"]["mean"]
    assert by["w=6"]["physics"]["bone_p95_cm"] > by["w=1"]["physics"]["bone_p95_cm"]
    for r in res["rows"]:
        assert r["physics"]["checks_total"] > 0 and 0 <= r["physics"]["targets_passed"] <= len(gs.PHYSICS_TARGETS)
        assert set(r["t2m"]) >= {"r_precision_top3", "fid"}
    md = gs.sweep_markdown(res, chosen=2)
    assert "| w=6 **(chosen)** |" in md and "Rule: eligible" in md and md.count("\n| w=") == 4
    assert any("T2M protocol done" in line for line in lines)
    json.dumps(res)                                                  # JSON-ready
    # as a frame for the CFG plot: one line per rescale setting, the real row apart
    df = gs.sweep_frame({**res, "chosen": {"index": 2}}, "toy")
    assert list(df["name"]) == ["toy w=1", "toy rescale 0.5 w=1", "toy w=6", "toy rescale 0.5 w=6", "Real motion"]
    assert list(df["chosen"]) == [False, False, True, False, False]
    assert df.loc[2, "FID"] == by["w=6"]["t2m"]["fid"]["mean"] and df.loc[2, "FID ±"] == by["w=6"]["t2m"]["fid"]["ci"]
    assert df.loc[4, "kind"] == "real" and df.loc[3, "bone p95 (cm)"] == by["w=6 phi=0.5"]["physics"]["bone_p95_cm"]
    from salad_viz.plots import plot_cfg_sweep

    fig = plot_cfg_sweep(df)
    assert len(fig.axes[0].lines) >= 2                               # the two rescale settings are two curves


def test_a_stopped_sweep_continues_from_its_kept_candidates(tiny_procedural_corpus, tiny_random_evaluator, tmp_path):
    """With a store, each finished candidate is kept; a sweep stopped midway and run again measures only the
    rest, gives the same rows, and measures again when the settings, data or identity differ."""
    mean, std = load_mean_std(tiny_procedural_corpus)
    grid = gs.guidance_grid([1.0, 6.0])
    settings = EvalSettings(replications=1, mm=False, seed=1)
    bench = BenchSettings(steps=1, seeds=(0,), num_prompts=1)
    store = tmp_path / "kept"

    def joints_of(out):
        return [features_to_joints(out.features[b, :n], SK) for b, n in enumerate(out.lengths)]

    class StopAfterFirst(NoisyPipe):
        def __call__(self, prompts, guidance_scale=None, **kw):
            if guidance_scale.scale == 6.0:
                raise KeyboardInterrupt("stopped")
            return super().__call__(prompts, guidance_scale=guidance_scale, **kw)

    with pytest.raises(KeyboardInterrupt):
        gs.run_sweep(StopAfterFirst(mean, std), grid, tiny_procedural_corpus, tiny_random_evaluator, settings, bench,
                     joints_of=joints_of, store=store, identity={"weights": "a"})
    assert sorted(f.name for f in store.iterdir()) == ["real.json", "w=1.json"]
    pipe = NoisyPipe(mean, std)
    lines = []
    res = gs.run_sweep(pipe, grid, tiny_procedural_corpus, tiny_random_evaluator, settings, bench,
                       joints_of=joints_of, store=store, identity={"weights": "a"}, log=lines.append)
    assert [r["reused"] for r in res["rows"]] == [True, False]
    assert {g.scale for g in pipe.seen} == {6.0}                       # w=1 was not generated again
    assert any("w=1: measured before" in line for line in lines)
    fresh = gs.run_sweep(NoisyPipe(mean, std), grid, tiny_procedural_corpus, tiny_random_evaluator, settings, bench,
                         joints_of=joints_of)
    for kept, new in zip(res["rows"], fresh["rows"]):
        assert {k: v for k, v in kept.items() if k not in ("seconds", "reused")} == \
               {k: v for k, v in new.items() if k not in ("seconds", "reused")}
    assert res["real"] == fresh["real"] and res["references"] == fresh["references"]
    grid = gs.guidance_grid([1.0, 6.0], intervals=[(0.0, 0.5)])          # tuples are kept as JSON lists
    gs.run_sweep(NoisyPipe(mean, std), grid, tiny_procedural_corpus, tiny_random_evaluator, settings, bench,
                 joints_of=joints_of, store=store, identity={"weights": "a"})
    again = gs.run_sweep(NoisyPipe(mean, std), grid, tiny_procedural_corpus, tiny_random_evaluator, settings, bench,
                         joints_of=joints_of, store=store, identity={"weights": "a"})
    assert [r["reused"] for r in again["rows"]] == [True, True]
    for change in ({"identity": {"weights": "b"}}, {"bench_settings": BenchSettings(steps=2, seeds=(0,), num_prompts=1)}):
        pipe = NoisyPipe(mean, std)
        kw = dict(joints_of=joints_of, store=store, identity=change.get("identity", {"weights": "a"}))
        again = gs.run_sweep(pipe, grid, tiny_procedural_corpus, tiny_random_evaluator, settings,
                             change.get("bench_settings", bench), **kw)
        assert [r["reused"] for r in again["rows"]] == [False, False] and {g.scale for g in pipe.seen} == {1.0, 6.0}


def test_cli_sweep_on_the_shipped_weights(tiny_procedural_corpus, tmp_path, capsys):
    from salad_core.cli.eval import main

    out = tmp_path / "sweep"
    status = main(["--guidance-sweep", "--data", str(tiny_procedural_corpus), "--scales", "5", "--intervals",
                   "full,0-0.5", "--replications", "1", "--no-mm", "--prompts", "1", "--seeds", "2", "--steps", "3",
                   "--sample", "none", "--out", str(out)])
    assert status == 0
    doc = json.loads((out / "guidance_sweep.json").read_text())
    assert [r["label"] for r in doc["rows"]] == ["w=5", "w=5 t/T in [0,0.5]"]
    chosen = doc["chosen"]
    assert 0 <= chosen["index"] < 2 and chosen["guidance"] == doc["rows"][chosen["index"]]["guidance"]
    assert doc["settings"]["weights"].endswith("salad") and doc["settings"]["recovery"] == "positions"
    printed = capsys.readouterr().out
    assert '"guidance": {"scale":' in printed and "Chosen: " in (out / "guidance_sweep.md").read_text()
    assert sorted(f.name for f in (out / "candidates").iterdir()) == ["real.json", "w=5.json", "w=5_t_T_in_0_0.5.json"]
    status = main(["--guidance-sweep", "--data", str(tiny_procedural_corpus), "--scales", "5", "--intervals",
                   "full,0-0.5", "--replications", "1", "--no-mm", "--prompts", "1", "--seeds", "2", "--steps", "3",
                   "--sample", "none", "--out", str(out)])
    assert status == 0 and "2 of 2 candidates reused" in capsys.readouterr().out
    assert json.loads((out / "guidance_sweep.json").read_text())["rows"][0]["t2m"] == doc["rows"][0]["t2m"]
    assert main(["--guidance-sweep", "--physics", "--data", str(tiny_procedural_corpus)]) == 2
    assert main(["--guidance-sweep", "--data", str(tiny_procedural_corpus), "--intervals", "0.5"]) == 2
    assert "neither 'full' nor 'lo-hi'" in capsys.readouterr().err


def test_the_shipped_sweep_record_chose_the_shipped_guidance():
    """salad_core/weights/salad/guidance_sweep.json is the measurement that chose pipeline.json's guidance."""
    from salad_core.pipeline import default_weights_dir

    root = default_weights_dir()
    if not (root / "guidance_sweep.json").is_file():
        pytest.skip("no guidance sweep record beside the shipped weights")
    record = json.loads((root / "guidance_sweep.json").read_text())
    chosen = record["rows"][record["chosen"]["index"]]["guidance"]
    assert chosen == json.loads((root / "pipeline.json").read_text())["guidance"]
    assert gs.choose(record["rows"])[0] == record["chosen"]["index"]          # the rule gives the same choice


def test_grid_spells_thresholds_and_projections_with_distinct_labels():
    grid = gs.guidance_grid([7.5], thresholds=[None, (0.995, 1.0), (0.99, 4.0)], projections=[None, (0.0, None),
                                                                                             (0.5, 5.0)])
    assert len(grid) == 9
    assert grid[0] == Guidance(7.5) and grid[1] == Guidance(7.5, projection=0.0)
    assert grid[-1] == Guidance(7.5, threshold=0.99, threshold_bound=4.0, projection=0.5, norm_cap=5.0)
    assert [gs.guidance_label(g) for g in grid[:3]] == ["w=7.5", "w=7.5 eta=0", "w=7.5 eta=0.5 cap=5"]
    assert gs.guidance_label(grid[3]) == "w=7.5 thr=0.995" and gs.guidance_label(grid[-1]) == \
        "w=7.5 thr=0.99 b=4 eta=0.5 cap=5"
    assert gs.guidance_grid([2.0, 3.0]) == [Guidance(2.0), Guidance(3.0)]          # off by default
    with pytest.raises(ValueError, match="repeats a candidate"):
        gs.guidance_grid([2.0], projections=[(0.5, None), (0.5, None)])
    with pytest.raises(ValueError, match="Guidance.threshold must be"):
        gs.guidance_grid([2.0], thresholds=[(1.5, 1.0)])


def test_cli_sweep_takes_thresholds_and_projections(tiny_procedural_corpus, tmp_path, capsys):
    from salad_core.cli.eval import main

    out = tmp_path / "sweep"
    common = ["--guidance-sweep", "--data", str(tiny_procedural_corpus), "--scales", "5", "--replications", "1",
              "--no-mm", "--prompts", "1", "--seeds", "1", "--steps", "3", "--sample", "none"]
    assert main(common + ["--thresholds", "off,0.9:0.5", "--projections", "0", "--out", str(out)]) == 0
    doc = json.loads((out / "guidance_sweep.json").read_text())
    assert [r["label"] for r in doc["rows"]] == ["w=5 eta=0", "w=5 thr=0.9 b=0.5 eta=0"]
    g = doc["rows"][1]["guidance"]
    assert (g["threshold"], g["threshold_bound"], g["projection"], g.get("norm_cap")) == (0.9, 0.5, 0.0, None)
    assert Guidance(**g) == Guidance(5, threshold=0.9, threshold_bound=0.5, projection=0.0)
    assert list(gs.sweep_frame(doc, "toy")["name"][:2]) == ["toy projection 0 w=5", "toy threshold 0.9 projection 0 w=5"]
    # the two candidates generated different motions: the threshold reached the sampler
    assert doc["rows"][0]["t2m"]["fid"]["mean"] != doc["rows"][1]["t2m"]["fid"]["mean"]
    capsys.readouterr()
    assert main(common + ["--projections", "0.5:x"]) == 2
    assert "--projections: '0.5:x' is neither 'off' nor ETA or ETA:CAP" in capsys.readouterr().err
    assert main(common + ["--thresholds", "1.5"]) == 2
    assert "Guidance.threshold must be None or a quantile" in capsys.readouterr().err
