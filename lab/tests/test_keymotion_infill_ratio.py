"""lab/scripts/keymotion/keymotion_infill_ratio.py: the MMAE against linear interpolation, and the in-fillings' foot skating."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from _doubles import rest_pose
from _lab import load_script
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.motion import features_to_joints
from salad_core.skeleton import get_skeleton

ir = load_script("keymotion_infill_ratio")

SK = get_skeleton("humanml3d")


@pytest.fixture(scope="module")
def pipe():
    return KeyMotionPipeline.from_pretrained()


def clip_of(corpus: Path, pipe, split: str = "test") -> np.ndarray:
    name = (corpus / f"{split}.txt").read_text().split()[0]
    x = np.load(corpus / "new_joint_vecs" / f"{name}.npy").astype(np.float32)[:pipe.max_length]
    return pipe.mmae.norm.normalize(torch.from_numpy(x)).numpy()


def test_every_frame_a_keyframe_makes_interpolation_the_clip(pipe, tiny_procedural_corpus):
    xn = clip_of(tiny_procedural_corpus, pipe)
    j = ir.infill_joints(pipe, xn, "a person walks forward", len(xn))
    true = features_to_joints(pipe.mmae.norm.denormalize(torch.from_numpy(xn)).numpy(), pipe.skeleton)
    np.testing.assert_allclose(j["true"], true, atol=1e-5)
    np.testing.assert_allclose(j["lerp"], j["true"], atol=1e-4)         # LERP through every frame is the clip
    assert j["mmae"].shape == j["true"].shape == j["mmae_fit"].shape
    m, l = ir.infill_errors(pipe, xn, "a person walks forward", len(xn))
    assert l.max() < 1e-5 and m.shape == (len(xn),)


def test_fewer_keyframes_interpolate_worse(pipe, tiny_procedural_corpus):
    xn = clip_of(tiny_procedural_corpus, pipe)
    sparse = ir.infill_errors(pipe, xn, "a person walks forward", 2)[1].mean()
    dense = ir.infill_errors(pipe, xn, "a person walks forward", len(xn) // 2)[1].mean()
    assert sparse > dense > 0


def test_the_fitted_in_filling_keeps_the_skeletons_bone_lengths(pipe, tiny_procedural_corpus):
    xn = clip_of(tiny_procedural_corpus, pipe)
    j = ir.infill_joints(pipe, xn, "a person walks forward", max(2, len(xn) // 10))
    bones = [(c, p) for c, p in enumerate(SK.parents) if p >= 0]
    target = np.linalg.norm(SK.target_offsets, axis=-1)[[c for c, _ in bones]]
    fitted = np.stack([np.linalg.norm(j["mmae_fit"][:, c] - j["mmae_fit"][:, p], axis=-1) for c, p in bones], -1)
    raw = np.stack([np.linalg.norm(j["mmae"][:, c] - j["mmae"][:, p], axis=-1) for c, p in bones], -1)
    assert np.abs(fitted - target).max() < 1e-3                           # the fit: every bone its skeleton length
    assert np.abs(raw - target).max() > np.abs(fitted - target).max()   # the raw positions do not keep them
    assert j["mmae_fit"][..., 1].min() >= -1e-6                          # nothing below the floor


def test_skating_is_the_foot_speed_in_contact():
    still = np.repeat(rest_pose()[None], 60, axis=0)
    assert ir.skating(still, SK) == 0.0
    v = 0.5                                                               # the whole body slides at 0.5 m/s
    sliding = still + (np.arange(60) / SK.fps * v)[:, None, None] * np.array([1.0, 0, 0])
    assert ir.skating(sliding, SK) == pytest.approx(v, abs=1e-9)


def test_the_table_reports_skating_and_keeps_the_card_keys(tiny_procedural_corpus, tmp_path, capsys):
    out = tmp_path / "infill.json"
    assert ir.main(["--data", str(tiny_procedural_corpus), "--limit", "3", "--ratios", "0.1", "--fixed", "20",
                    "--out", str(out)]) == 0
    report = json.loads(out.read_text())
    assert set(report) == {"ratio 0.1", "K = 20"}
    row = report["ratio 0.1"]
    assert row["windows"] == 3 and 0.09 < row["mean_ratio"] < 0.12
    assert row["gain"] == pytest.approx(1 - row["mmae_cm"] / row["lerp_cm"])
    for key in ("skate_true_ms", "skate_mmae_ms", "skate_lerp_ms", "skate_mmae_fit_ms"):
        assert np.isfinite(row[key]) and row[key] >= 0
    assert "skating m/s: clips" in capsys.readouterr().out


def test_words_keep_only_the_named_captions_and_refuse_none(tiny_procedural_corpus, tmp_path):
    with pytest.raises(SystemExit, match="naming"):
        ir.main(["--data", str(tiny_procedural_corpus), "--words", "xylophone", "--limit", "2", "--fixed"])
    out = tmp_path / "walks.json"
    assert ir.main(["--data", str(tiny_procedural_corpus), "--words", "walk", "--limit", "2", "--ratios", "0.2",
                    "--fixed", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["ratio 0.2"]["windows"] >= 1


def test_contact_transitions_mark_the_frames_where_a_foot_lands_or_lifts():
    c = np.zeros((8, 4))
    c[2:5, 0] = 1                               # the left heel down over frames 2-4, up again at 5
    c[6:, 3] = 1                                # the right toe down from frame 6
    assert np.flatnonzero(ir.contact_transitions(c)).tolist() == [2, 5, 6]


def test_contact_mdo_keyframes_is_mdo_at_weight_0_and_takes_the_events_when_they_are_worth_more():
    from salad_core.keymotion.selection import mdo_keyframes

    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=(60, 5)), axis=0)
    events = np.zeros(60, dtype=bool)
    events[[11, 23, 37]] = True
    np.testing.assert_array_equal(ir.contact_mdo_keyframes(x, 8, events, 0.0), mdo_keyframes(x, 8))
    chosen = ir.contact_mdo_keyframes(x, 8, events, 100.0)
    assert {11, 23, 37} <= set(chosen.tolist()) and chosen[0] == 0 and chosen[-1] == 59 and len(chosen) == 8
