"""lab/scripts/vae/measure_vae_real.py: its measures by hand, and its VAE loader against every VAE location the
toolkit resolves (moved from tests/test_vae_root.py and tests/test_train.py, whose fixtures they use)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from _doubles import HashTextEncoder
from _lab import script_path
from test_train import (corpus, den_train_config, tiny_denoiser_config, tiny_vae_run,  # noqa: F401
                        train_denoiser)
from test_vae_root import D, SK, _standing_window, _vae  # noqa: F401


def _measure_module():
    import importlib.util

    path = script_path("measure_vae_real.py")
    spec = importlib.util.spec_from_file_location("measure_vae_real", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_root_channel_stats_and_ric_error_by_hand():
    m = _measure_module()
    rng = np.random.default_rng(0)
    ref = rng.standard_normal((2, 8, D)) * 0.02
    ref[..., 0] -= ref[..., 0].mean()                                       # zero-mean angular velocity
    rec = ref.copy()
    rec[..., 0] *= 0.5                                                      # a decoder at half the gain
    rec[..., 3] = ref[..., 3].mean()                                        # a flat root height
    s = m.root_channel_stats([(rec[0], ref[0]), (rec[1], ref[1])], unit=4)
    rv = s["rot_vel"]
    assert rv["corr"] == pytest.approx(1.0) and rv["rms_rec"] == pytest.approx(0.5 * rv["rms_true"])
    assert rv["r2"] == pytest.approx(0.75)                                  # 1 - 0.5^2
    assert s["vel_x"]["r2"] == 1.0 and np.isnan(s["root_y"]["corr"])         # flat: no correlation
    blocks = ref[..., 0].reshape(-1, 4).sum(1)
    assert s["rot_vel_latent"]["rms_true"] == pytest.approx(np.sqrt((blocks ** 2).mean()))
    # ric: every joint 1 cm off along x -> 1 cm; nothing else in the vector counts
    off = ref[0].copy()
    off[:, SK.feature_slices["ric"]] += np.tile([0.01, 0.0, 0.0], SK.num_joints - 1)
    off[:, :4] += 5.0
    assert m.ric_error_cm(off, ref[0]) == pytest.approx(1.0)
    assert m.ric_error_cm(ref[0], ref[0]) == 0.0


def test_foot_slide_by_hand():
    """``foot_slide``: the mean speed (m/frame) of contact joints over frames planted in the input, on the
    integrated path: a standing pose with planted feet gives 0; the same pose drifting 3 cm per frame along
    the heading gives 0.03 on every planted step; unplanted feet and masked frames do not count."""
    vae = _vae(lambda_foot=2.0)
    still = _standing_window(12, b=2)
    c = SK.feature_slices["contacts"]
    still[..., c] = 1.0
    assert vae.foot_slide(still, still).item() == 0.0
    drift = still.clone()
    drift[..., 2] = 0.03                                              # z velocity: 3 cm per frame
    assert vae.foot_slide(drift, still).item() == pytest.approx(0.03, rel=1e-6)
    lifted = still.clone()
    lifted[..., c] = 0.0                                              # nothing planted: nothing measured
    assert vae.foot_slide(drift, lifted).item() == 0.0
    half = still.clone()
    half[:, 6:, c] = 0.0                                              # planted on frames 0-5: steps 0-4
    late = still.clone()
    late[:, 6:, 2] = 0.5                                              # the slide begins where no foot is planted
    assert vae.foot_slide(late, half).item() == 0.0
    mask = torch.ones(2, 12, dtype=torch.bool)
    mask[:, 3:] = False                                               # only steps 0-1 are valid
    fast = still.clone()
    fast[:, 3:, 2] = 0.5
    assert vae.foot_slide(fast, still, mask).item() == 0.0
    recon = drift.clone().requires_grad_(True)
    vae.foot_slide(recon, still).backward()
    assert recon.grad[..., 2].abs().sum() > 0                         # the root velocity gets a gradient
    # feet the contact channels mark but that move in the input itself (2 cm per frame, 0.4 m/s) are not
    # asked to stop: only steps where the input's foot moves < foot_planted_step (5 mm) count
    walking = still.clone()
    walking[..., 2] = 0.02
    assert vae.foot_slide(drift, walking).item() == 0.0
    loose = _vae(lambda_foot=2.0, foot_planted_step=None)             # the channels alone
    assert loose.foot_slide(drift, walking).item() == pytest.approx(0.03, rel=1e-6)
    slow = still.clone()
    slow[..., 2] = 0.004                                              # input slides 4 mm/frame: still planted
    assert vae.foot_slide(drift, slow).item() == pytest.approx(0.03, rel=1e-6)
    with pytest.raises(ValueError, match="foot_planted_step"):
        _vae(foot_planted_step=0.0)


def test_load_vae_reads_every_vae_location_the_toolkit_resolves(corpus, tiny_vae_run, tmp_path):  # noqa: F811
    """measure_vae_real.py's load_vae accepts what salad_core.train.assemble.vae_source accepts (a run folder, a
    checkpoint stem or file in it, an exported VAE folder or its stem, a pipeline folder) and gives the same weights
    and Mean/Std; a folder without the statistics is refused."""
    from test_train import assert_same_tensors

    from salad_core.train.assemble import assemble_pipeline, export_vae, vae_source
    from salad_core.train.denoiser_trainer import load_frozen_vae, vae_statistics

    mvr = _measure_module()
    den = tmp_path / "den"
    train_denoiser(corpus, den, tiny_vae_run, tiny_denoiser_config(), den_train_config(max_steps=1), HashTextEncoder())
    exported = export_vae(tiny_vae_run, tmp_path / "exported", dtype=None)
    pipeline = assemble_pipeline(tiny_vae_run, den, tmp_path / "pipe", dtype=None, text_encoder=HashTextEncoder())
    stem = vae_source(tiny_vae_run).stem
    want = load_frozen_vae(tiny_vae_run).state_dict()
    want_mean, _ = vae_statistics(tiny_vae_run)
    for where in [tiny_vae_run, stem, stem.with_suffix(".safetensors"), stem.with_suffix(".json"), exported,
                  exported / "vae", exported / "vae.safetensors", pipeline, pipeline / "vae"]:
        vae, m2, s2, desc = mvr.load_vae(where)
        assert_same_tensors(vae.state_dict(), want)
        np.testing.assert_array_equal(m2, want_mean)
        assert vae_source(where).stats.name in desc
    (tmp_path / "nostats").mkdir()
    for name in ("vae.json", "vae.safetensors"):
        (tmp_path / "nostats" / name).write_bytes((exported / name).read_bytes())
    with pytest.raises(FileNotFoundError, match="stats.safetensors"):
        mvr.load_vae(tmp_path / "nostats")
