"""lab/scripts/keymotion/keymotion_keyframe_check.py: whether a keyframe VAE keeps the steps of real keyframes."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from _doubles import make_fake_corpus
from salad_core.skeleton import get_skeleton

from _lab import script_path  # noqa: E402

SCRIPT = script_path("keymotion_keyframe_check.py")
spec = importlib.util.spec_from_file_location("keymotion_keyframe_check", SCRIPT)
kc = importlib.util.module_from_spec(spec)
spec.loader.exec_module(kc)

D = get_skeleton("humanml3d").feature_dim


def stepping_motion(n: int = 60, amplitude: float = 0.3) -> np.ndarray:
    """Features whose ankles alternate front and back by ``amplitude`` m (left = +, right = -)."""
    rng = np.random.default_rng(0)
    x = (0.05 * rng.standard_normal((n, D))).astype(np.float32)
    phase = np.sin(np.linspace(0, 4 * np.pi, n)).astype(np.float32)
    ric = x[:, 4:4 + 63].reshape(n, 21, 3)
    ric[:, kc.L_ANKLE - 1, 2] = amplitude * phase
    ric[:, kc.R_ANKLE - 1, 2] = -amplitude * phase
    x[:, 4:4 + 63] = ric.reshape(n, 63)
    x[:, 3] = 0.9                                        # root height
    return x


class _FakeVAE:
    """Keyframe-VAE double: ``identity`` returns the keyframes it is given, ``mean`` the mean pose."""

    def __init__(self, mode: str, k: int = 10) -> None:
        self.mode = mode
        self.config = SimpleNamespace(num_keyframes=k, max_length=196)
        self.skeleton = "humanml3d"
        self.norm = SimpleNamespace(normalize=lambda t: t, denormalize=lambda t: t)

    def positions_of(self, indices, lengths):
        from salad_core.keymotion.kf_vae import indices_to_positions

        return indices_to_positions(indices, lengths)

    def indices_of(self, positions, lengths):
        from salad_core.keymotion.kf_vae import positions_to_indices

        return positions_to_indices(positions, lengths)

    def encode(self, keyframes, positions, sample=False):
        self._positions = positions
        return SimpleNamespace(mu=keyframes)

    def decode(self, mu):
        out = mu if self.mode == "identity" else torch.zeros_like(mu)
        return SimpleNamespace(keyframes=out, positions=self._positions)


def test_forward_separation_is_left_minus_right_ankle_along_the_facing_axis():
    x = stepping_motion(n=5, amplitude=0.25)
    sep = kc.forward_separation(x)
    np.testing.assert_allclose(sep, 0.5 * np.sin(np.linspace(0, 4 * np.pi, 5)), atol=1e-6)


def test_a_perfect_vae_keeps_the_stride_and_the_mean_pose_keeps_none():
    x = stepping_motion()
    perfect = kc.check_window(_FakeVAE("identity"), x)
    assert perfect["stride_true_m"] == pytest.approx(perfect["stride_rec_m"]) and perfect["stride_true_m"] > 0.4
    assert perfect["kept"] == pytest.approx(1.0) and perfect["pose_cm"] == pytest.approx(0.0, abs=1e-4)
    assert perfect["index_frames"] == 0.0
    flat = kc.check_window(_FakeVAE("mean"), x)
    assert flat["stride_rec_m"] == 0.0 and flat["kept"] == 0.0 and flat["pose_cm"] > 1.0


def test_the_script_reads_a_keyframe_vae_stage_and_reports_gait_windows(tmp_path):
    from salad_core.io import save_checkpoint
    from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig

    corpus = make_fake_corpus(tmp_path / "corpus", n_train=4, n_val=6, lengths=(40, 60))
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, frame_dim=56, index_dim=8, latent_size=2, latent_dim=16,
                                        num_layers=1, num_heads=4, ff_dim=64, dropout=0.0))
    run = tmp_path / "kf_vae"
    run.mkdir()
    save_checkpoint(run / "best", vae, model_type="keymotion_kf_vae", config=vae.config)
    out = tmp_path / "check.json"
    assert kc.main(["--data", str(corpus), "--kf-vae", str(run), "--words", "walks", "runs", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    captions = [w["caption"] for w in doc["windows"]]
    assert captions and all(("walks" in c) or ("runs" in c) for c in captions)
    assert doc["summary"]["windows"] == len(captions)
    assert all(np.isfinite(w["pose_cm"]) and w["stride_true_m"] >= 0 for w in doc["windows"])
    with pytest.raises(SystemExit, match="no test window"):
        kc.main(["--data", str(corpus), "--kf-vae", str(run), "--words", "cartwheels"])
