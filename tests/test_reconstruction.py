"""VAE reconstruction evaluation (paper Table 2 / supp. Table 4): identity and noisy doubles pin the
metrics, a real MotionVAE runs the plumbing, tables keep the paper's numbers apart."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from salad_core.data.dataset import load_mean_std
from salad_core.eval.batches import real_batches
from salad_core.eval.metrics import mpjpe
from salad_core.eval.reconstruction import (
    evaluate_reconstruction,
    part_errors,
    paper_vae_tables,
    reconstruct_features,
    reconstruction_frame,
    reconstruction_markdown,
)
from salad_core.eval.settings import EvalSettings
from salad_core.models import MotionVAE, VAEConfig
from salad_core.motion import features_to_joints
from salad_core.skeleton import get_skeleton


pytestmark = pytest.mark.usefixtures("single_thread")

SK = get_skeleton("humanml3d")
SETTINGS = EvalSettings(replications=2, max_samples=32, mm=False, seed=5)


class FeatureVAE:
    """A 'VAE' whose latent is the normalised features themselves; decoding adds ``offset`` (normalised
    units) to the root height channel (index 3), so the reconstruction error is known exactly."""

    config = SimpleNamespace(downsample=4)

    def __init__(self, offset: float = 0.0) -> None:
        self.offset = offset
        self.calls: list[tuple[int, ...]] = []

    def eval(self):
        return self

    def encode(self, x, sample=False, generator=None):
        self.calls.append(tuple(x.shape))
        return SimpleNamespace(z=x.clone(), mu=x, logvar=torch.zeros_like(x))

    def decode(self, z):
        out = z.clone()
        out[..., 3] += self.offset
        return out

    def num_parameters(self, trainable_only: bool = True) -> int:
        return 0


@pytest.fixture(scope="module")
def corpus(tiny_procedural_corpus):
    return tiny_procedural_corpus


@pytest.fixture(scope="module")
def evaluator(tiny_random_evaluator):
    return tiny_random_evaluator


@pytest.fixture(scope="module")
def stats(corpus):
    return load_mean_std(corpus)


def test_identity_vae_scores_zero_error(corpus, evaluator, stats):
    vae = FeatureVAE()
    res = evaluate_reconstruction(vae, *stats, corpus, evaluator, SETTINGS, name="identity")
    assert len(res.values["FID"]) == len(res.values["MPJPE"]) == 2
    assert max(res.values["MPJPE"]) < 1e-5
    assert max(res.values["FID"]) < 1e-3
    # each clip is encoded at its own length (grouped by length), never padded
    assert all(shape[1] % 4 == 0 for shape in vae.calls)
    assert res.settings["samples"] == 32 and res.settings["kind"] == "vae"


def test_root_height_offset_gives_that_error_root_aligned_zero_and_raises_fid(corpus, evaluator, stats):
    mean, std = stats
    clean = evaluate_reconstruction(FeatureVAE(), mean, std, corpus, evaluator, SETTINGS)
    res = evaluate_reconstruction(FeatureVAE(offset=0.5), mean, std, corpus, evaluator, SETTINGS)
    # HumanML3D keeps the other joints' heights absolute (ric y), so raising channel 3 lifts the
    # root joint alone: after root alignment the 21 other joints sit 0.5 * std[3] metres too low
    assert res.values["MPJPE"][0] == pytest.approx(0.5 * std[3] * (SK.num_joints - 1) / SK.num_joints, rel=1e-3)
    assert min(res.values["FID"]) > max(clean.values["FID"]) + 1e-3

    # an offset on a local joint position channel (joint 1's x, index 4) moves that joint only
    class LocalOffset(FeatureVAE):
        def decode(self, z):
            out = z.clone()
            out[..., 4] += 1.0
            return out

    res = evaluate_reconstruction(LocalOffset(), mean, std, corpus, evaluator, SETTINGS)
    # hand computation on the first replication's batches
    errs, poses = 0.0, 0
    for b in real_batches(corpus, SETTINGS, 0):
        for k, n in enumerate(b.lengths):
            gt = features_to_joints(b.motions[k, :n], SK)
            pred_feats = b.motions[k, :n].copy()
            pred_feats[:, 4] += std[4]
            errs += mpjpe(features_to_joints(pred_feats, SK), gt) * n
            poses += n
    assert res.values["MPJPE"][0] == pytest.approx(errs / poses, rel=1e-4)
    # joint 1 moved by std[4] metres, averaged over 22 joints
    assert res.values["MPJPE"][0] == pytest.approx(std[4] / SK.num_joints, rel=1e-3)


def test_real_vae_round_trip_is_deterministic_and_sampling_differs(corpus, evaluator, stats):
    torch.manual_seed(0)
    vae = MotionVAE(VAEConfig())
    a = evaluate_reconstruction(vae, *stats, corpus, evaluator, SETTINGS, name="random VAE")
    b = evaluate_reconstruction(vae, *stats, corpus, evaluator, SETTINGS, name="random VAE")
    s = evaluate_reconstruction(vae, *stats, corpus, evaluator, SETTINGS, sample=True)
    assert a.values == b.values
    assert s.values["MPJPE"] != a.values["MPJPE"]
    assert a.parameters == vae.num_parameters() > 0
    vae.requires_grad_(False)                       # frozen for inference: the same size
    assert evaluate_reconstruction(vae, *stats, corpus, evaluator, SETTINGS).parameters == a.parameters
    assert all(np.isfinite(v) and v > 0 for v in a.values["MPJPE"])


def test_reconstruct_features_checks_its_input(stats):
    mean, std = stats
    vae = FeatureVAE()
    x = np.zeros((2, 8, SK.feature_dim), np.float32)
    with pytest.raises(ValueError, match="multiples of the VAE's downsampling 4"):
        reconstruct_features(vae, mean, std, x, [8, 6])
    with pytest.raises(ValueError, match="2 motions"):
        reconstruct_features(vae, mean, std, x, [8])
    with pytest.raises(ValueError, match=r"\(263,\)"):
        reconstruct_features(vae, mean[:10], std, x, [8, 8])
    with pytest.raises(ValueError, match="std > 0"):
        reconstruct_features(vae, mean, np.zeros_like(std), x, [8, 8])
    out = reconstruct_features(vae, mean, std, x + mean, [8, 4])
    assert out.shape == x.shape and np.all(out[1, 4:] == 0) and np.allclose(out[1, :4], mean, atol=1e-5)


def test_tables_show_parameters_cm_and_keep_the_paper_apart(corpus, evaluator, stats):
    res = evaluate_reconstruction(FeatureVAE(offset=0.2), *stats, corpus, evaluator, SETTINGS, name="ours")
    df = reconstruction_frame([res])
    assert list(df.columns[:6]) == ["name", "parameters", "FID", "FID ±", "MPJPE", "MPJPE ±"]
    md = reconstruction_markdown(df)
    assert "| ours |" in md and "MPJPE (cm)" in md
    paper = paper_vae_tables("table2")
    assert all(n.startswith("paper: ") for n in paper["name"])
    row = paper.set_index("name").loc["paper: SALAD (skeleton-aware VAE)"]
    assert (row["FID"], row["MPJPE"], row["parameters"]) == (0.003, 0.016, 0.16e6)
    md = reconstruction_markdown(paper)
    assert "0.16M" in md and "1.600" in md            # 0.016 m shown as 1.600 cm
    supp = paper_vae_tables("supp_table4")
    assert supp["MPJPE"].tolist() == [0.016, 0.023, 0.016, 0.024]
    with pytest.raises(ValueError, match="table2"):
        paper_vae_tables("table9")
    with pytest.raises(ValueError, match="lacks the columns"):
        reconstruction_markdown(df.drop(columns=["MPJPE"]))


def test_part_errors_put_a_joint_error_in_its_part():
    rng = np.random.default_rng(0)
    gt = rng.standard_normal((10, SK.num_joints, 3))
    pred = gt.copy()
    left_wrist = SK.joint_names.index("left_wrist")
    pred[:, left_wrist, 1] += 0.3
    errs = part_errors(pred, gt, SK)
    part = SK.part_names[SK.joint_to_part[left_wrist]]
    n_joints = sum(1 for j, k in enumerate(SK.joint_to_part) if k == SK.joint_to_part[left_wrist] and j != 0)
    assert errs[part] == pytest.approx(0.3 / n_joints)
    assert all(v == 0 for k, v in errs.items() if k != part)
    assert "root" not in errs and len(errs) == 6            # the root part is the root joint alone
    with pytest.raises(ValueError, match="22, 3"):
        part_errors(pred[:, :5], gt[:, :5], SK)


def test_latent_noise_adds_that_share_of_the_spread_deterministically(corpus, evaluator, stats):
    """With the identity 'VAE' the decoded features are the latents, so the noise is seen exactly: per channel it
    is ``k x spread`` in normalised units; the same seed gives the same noise, k 0 is the plain reconstruction."""
    from salad_core.eval.reconstruction import latent_spread

    mean, std = stats
    vae = FeatureVAE()
    spread = latent_spread(vae, mean, std, corpus, SK, SETTINGS)
    assert spread.shape == (SK.feature_dim,) and torch.all(spread >= 1.0)     # posterior variance 1 for this double
    rng = np.random.default_rng(0)
    x = (mean + std * rng.standard_normal((64, 16, SK.feature_dim))).astype(np.float32)
    plain = reconstruct_features(vae, mean, std, x, [16] * 64)
    assert np.array_equal(reconstruct_features(vae, mean, std, x, [16] * 64, latent_noise=0.0, latent_spread=spread),
                          plain)
    noisy = reconstruct_features(vae, mean, std, x, [16] * 64, seed=3, latent_noise=0.5, latent_spread=spread)
    assert np.array_equal(noisy, reconstruct_features(vae, mean, std, x, [16] * 64, seed=3, latent_noise=0.5,
                                                      latent_spread=spread))
    measured = ((noisy - plain) / std).reshape(-1, SK.feature_dim).std(0)
    assert measured == pytest.approx(0.5 * spread.numpy(), rel=0.08)
    with pytest.raises(ValueError, match="needs latent_spread"):
        reconstruct_features(vae, mean, std, x, [16] * 64, latent_noise=0.5)
    with pytest.raises(ValueError, match=r"latent_spread has shape \(7, 32\)"):
        reconstruct_features(vae, mean, std, x, [16] * 64, latent_noise=0.5, latent_spread=torch.ones(7, 32))
    with pytest.raises(ValueError, match="finite share >= 0"):
        reconstruct_features(vae, mean, std, x, [16] * 64, latent_noise=-1.0, latent_spread=spread)
    clean = evaluate_reconstruction(vae, mean, std, corpus, evaluator, SETTINGS)
    off = evaluate_reconstruction(vae, mean, std, corpus, evaluator, SETTINGS, latent_noise=1.0, latent_spread=spread)
    assert off.settings["latent_noise"] == 1.0 and clean.settings["latent_noise"] == 0.0
    assert min(off.values["MPJPE"]) > max(clean.values["MPJPE"]) and min(off.values["FID"]) > max(clean.values["FID"])
