"""Tests for the skeleto-temporal VAE (salad_core.models.vae) and its layers."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from salad_core.io import CheckpointError, load_model, save_checkpoint
from salad_core.models.layers import (
    GraphConv,
    MultiLinear,
    STConv,
    STPool,
    STUnpool,
    adjacency_with_self_loops,
)
from salad_core.models.vae import MotionVAE, VAEConfig, VAEEncoding
from salad_core.skeleton import PART_NAMES, get_skeleton


pytestmark = pytest.mark.usefixtures("single_thread")


def _vae(seed: int = 0, **kw) -> MotionVAE:
    torch.manual_seed(seed)
    return MotionVAE(VAEConfig(**kw))


def _normalised_clip(sample_dir, sample_features, n: int = 64) -> torch.Tensor:
    mean = np.load(sample_dir / "Mean.npy")
    std = np.load(sample_dir / "Std.npy")
    x = (sample_features[:n] - mean) / std
    return torch.from_numpy(x).float()[None]  # (1, n, 263)


# ----------------------------------------------------------------- sizes
@pytest.mark.parametrize("skeleton, trainable, total", [("humanml3d", 162_503, 168_223), ("kit", 159_579, 164_931)])
def test_parameter_counts_match_official(skeleton, trainable, total):
    vae = _vae(skeleton=skeleton)
    assert sum(p.numel() for p in vae.parameters() if p.requires_grad) == trainable
    assert sum(p.numel() for p in vae.parameters()) == total
    assert vae.num_parameters() == trainable and vae.num_parameters(trainable_only=False) == total


@pytest.mark.parametrize("skeleton", ["humanml3d", "kit"])
@pytest.mark.parametrize("n, n_lat", [(64, 16), (196, 49)])
def test_shapes(skeleton, n, n_lat):
    vae = _vae(skeleton=skeleton).eval()
    d = get_skeleton(skeleton).feature_dim
    x = torch.randn(2, n, d)
    enc = vae.encode(x)
    assert isinstance(enc, VAEEncoding)
    for t in enc:
        assert t.shape == (2, n_lat, 7, 32)
    assert (vae.num_parts, vae.latent_dim, vae.downsample) == (7, 32, 4)
    assert vae.decode(enc.z).shape == (2, n, d)
    recon, mu, logvar = vae(x)
    assert recon.shape == x.shape and mu.shape == logvar.shape == (2, n_lat, 7, 32)


def test_pose_variant_shapes_and_latent_size():
    vae = _vae(kind="pose").eval()
    x = torch.randn(2, 64, 263)
    enc = vae.encode(x)
    # one vector per latent frame with as many numbers as the 7 x 32 ST latent
    assert enc.z.shape == (2, 16, 1, 7 * 32)
    assert (vae.num_parts, vae.latent_dim, vae.downsample) == (1, 224, 4)
    assert vae.decode(enc.z).shape == x.shape
    # no skeletal graph: no adjacency anywhere, skeletal pooling is a 1x1 identity
    keys = vae.state_dict().keys()
    assert not any("adj_matrix" in k or "graph_conv" in k for k in keys)
    assert vae.state_dict()["conv_enc.layers.0.2.skeleton_pool"].tolist() == [[1.0]]
    narrow = _vae(kind="pose", pose_width=48, pose_latent_dim=64).eval()
    z = narrow.encode(x, sample=False).z
    assert z.shape == (2, 16, 1, 64) and narrow.decode(z).shape == x.shape
    assert narrow.latent_proj is not None and vae.latent_proj is None


def test_one_pooling_level_gives_twelve_nodes():
    vae = _vae(n_layers=1).eval()
    z = vae.encode(torch.randn(1, 8, 263)).z
    assert z.shape == (1, 4, 12, 32) and vae.downsample == 2
    assert vae.decode(z).shape == (1, 8, 263)


def test_bad_inputs_raise_clear_errors():
    vae = _vae().eval()
    with pytest.raises(ValueError, match="multiple of 4"):
        vae.encode(torch.randn(1, 30, 263))
    with pytest.raises(ValueError, match=r"\(B, N, 263\)"):
        vae.encode(torch.randn(1, 32, 251))
    with pytest.raises(ValueError, match=r"\(B, N', 7, 32\)"):
        vae.decode(torch.randn(1, 8, 1, 32))


@pytest.mark.parametrize("kwargs, word", [
    ({"kind": "vq"}, "kind"), ({"activation": "tanh"}, "activation"), ({"norm": "group"}, "norm"),
    ({"kernel_size": 4}, "kernel_size"), ({"n_layers": 3}, "n_layers"), ({"dropout": 1.0}, "dropout"),
    ({"recon_loss": "huber"}, "recon_loss"), ({"lambda_kl": -1.0}, "lambda_kl"), ({"skeleton": "smpl"}, "smpl"),
    ({"pose_latent_dim": 224}, "pose_latent_dim"), ({"latent_dim": 0}, "latent_dim"),
])
def test_config_validation(kwargs, word):
    with pytest.raises(ValueError, match=word):
        VAEConfig(**kwargs)


def test_config_canonicalises_skeleton_alias():
    assert VAEConfig(skeleton="t2m") == VAEConfig()


# ------------------------------------------------------ official layout
def test_official_state_dict_keys_and_shapes():
    sd = _vae().official_state_dict()
    assert len(sd) == 294
    expected = {
        "dist.weight": (7, 32, 64),
        "dist.bias": (7, 64),
        "conv_enc.layers.0.2.skeleton_pool": (12, 22),
        "conv_enc.layers.1.2.skeleton_pool": (7, 12),
        "conv_dec.layers.0.0.skeleton_unpool": (12, 7),
        "conv_dec.layers.1.0.skeleton_unpool": (22, 12),
        "motion_enc.layers.0.0.weight": (32, 7),
        "motion_enc.layers.1.0.weight": (32, 12),
        "motion_enc.layers.7.0.weight": (32, 13),
        "motion_enc.layers.7.2.weight": (32, 32),
        "motion_dec.layers.0.2.weight": (7, 32),
        "motion_dec.layers.10.2.weight": (13, 32),
        "motion_dec.layers.21.2.bias": (12,),
        "conv_enc.layers.0.0.layers.2.adj_matrix": (22, 22),
        "conv_enc.layers.1.1.layers.5.adj_matrix": (12, 12),
        "conv_enc.layers.0.1.layers.5.graph_conv.linear1.weight": (32, 32),
        "conv_enc.layers.0.1.layers.5.graph_conv.linear2.bias": (32,),
        "conv_enc.layers.1.0.layers.2.temp_conv.weight": (32, 32, 3),
        "conv_dec.layers.0.1.layers.2.adj_matrix": (12, 12),
        "conv_dec.layers.1.2.layers.5.adj_matrix": (22, 22),
        "conv_dec.layers.1.2.layers.5.temp_conv.bias": (32,),
    }
    for key, shape in expected.items():
        assert tuple(sd[key].shape) == shape, key
    # 22 joints x 4 (enc) + 22 x 4 (dec) + 2 x (4 ResSTConv x 2 STConv x 7 + 2 pool) + 2 (dist)
    assert sum(k.startswith("motion_enc.") for k in sd) == 88
    assert sum(k.startswith("conv_enc.") for k in sd) == 58
    assert not any(".layers.0.weight" in k and k.startswith("conv_") for k in sd)  # norm "none": no keys
    kit = _vae(skeleton="kit").official_state_dict()
    assert len(kit) == 286
    assert tuple(kit["conv_enc.layers.0.2.skeleton_pool"].shape) == (12, 21)
    assert tuple(kit["conv_dec.layers.1.0.skeleton_unpool"].shape) == (21, 12)


def test_official_round_trip_gives_identical_outputs():
    src = _vae(seed=1).eval()
    sd = {k: v.clone() for k, v in src.official_state_dict().items()}
    dst = MotionVAE.from_official_state_dict(sd).eval()
    also = MotionVAE.from_official_state_dict({"vae": sd, "epoch": 3}).eval()  # whole checkpoint dict
    x = torch.randn(2, 32, 263)
    with torch.no_grad():
        a = src.decode(src.encode(x, generator=torch.Generator().manual_seed(5)).z)
        b = dst.decode(dst.encode(x, generator=torch.Generator().manual_seed(5)).z)
        c = also.decode(also.encode(x, sample=False).z)
        d = src.decode(src.encode(x, sample=False).z)
    assert torch.equal(a, b) and torch.equal(c, d)
    assert dst.config == VAEConfig()


def test_official_loader_infers_architecture_from_keys():
    for kw in ({"norm": "layer"}, {"norm": "batch"}, {"n_extra_layers": 0, "latent_dim": 16}):
        sd = _vae(**kw).official_state_dict()
        loaded = MotionVAE.from_official_state_dict(sd)
        for field, value in kw.items():
            assert getattr(loaded.config, field) == value
    kit = MotionVAE.from_official_state_dict(_vae(skeleton="kit").official_state_dict(), dataset="kit",
                                             activation="silu")
    assert kit.config.skeleton == "kit" and kit.config.activation == "silu"


def test_official_loader_rejects_bad_state_dicts():
    sd = _vae().official_state_dict()
    wrong = dict(sd, **{"dist.weight": torch.zeros(7, 32, 60)})
    with pytest.raises(CheckpointError, match=r"dist\.weight.*\(7, 32, 64\)"):
        MotionVAE.from_official_state_dict(wrong)
    missing = {k: v for k, v in sd.items() if k != "conv_enc.layers.1.0.layers.5.temp_conv.bias"}
    with pytest.raises(CheckpointError, match="missing keys.*temp_conv.bias"):
        MotionVAE.from_official_state_dict(missing)
    extra = dict(sd, **{"conv_enc.layers.0.0.layers.0.bogus": torch.zeros(1)})
    with pytest.raises(CheckpointError, match="unexpected keys"):
        MotionVAE.from_official_state_dict(extra)
    with pytest.raises(ValueError, match="22 joint MLPs.*21 joints"):
        MotionVAE.from_official_state_dict(sd, dataset="kit")
    with pytest.raises(ValueError, match="pose"):
        _vae(kind="pose").official_state_dict()


def test_checkpoint_round_trip_through_registry(tmp_path):
    src = _vae(seed=2, kind="pose", pose_width=32, pose_latent_dim=40).eval()
    save_checkpoint(tmp_path / "vae", src, model_type="salad_vae", config=src.config)
    model, config, _ = load_model(tmp_path / "vae")
    assert isinstance(model, MotionVAE) and config == src.config
    x = torch.randn(1, 16, 263)
    with torch.no_grad():
        assert torch.equal(model.decode(model.encode(x, sample=False).z), src.decode(src.encode(x, sample=False).z))


# ---------------------------------------------------------------- layers
def test_graph_conv_matches_hand_computation_on_a_chain():
    torch.manual_seed(0)
    gc = GraphConv(2, 2)
    adj = torch.from_numpy(adjacency_with_self_loops([(0, 1), (1, 2)], 3))
    assert adj.tolist() == [[1, 1, 0], [1, 1, 1], [0, 1, 1]]
    x = torch.tensor([[[[1.0, 2.0], [-1.0, 0.5], [3.0, -2.0]]]])  # (B=1, N=1, J=3, C=2)
    w1, b1 = gc.linear1.weight.detach().numpy(), gc.linear1.bias.detach().numpy()
    w2, b2 = gc.linear2.weight.detach().numpy(), gc.linear2.bias.detach().numpy()
    xs = x[0, 0].numpy()
    closed = {0: [0, 1], 1: [0, 1, 2], 2: [1, 2]}  # N(j) ∪ {j} on the chain 0-1-2
    expected = np.stack([
        w1 @ xs[j] + b1 + sum(w2 @ xs[k] + b2 for k in closed[j]) / len(closed[j]) for j in range(3)
    ])
    out = gc(x, adj)[0, 0].detach().numpy()
    np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-5)


def test_stconv_is_graph_plus_temporal_term():
    torch.manual_seed(0)
    conv = STConv(4, [(0, 1), (1, 2)], 3, kernel_size=3)
    x = torch.randn(2, 5, 3, 4)
    graph = conv.graph_conv(x, conv.adj_matrix)
    # (B, N, J, C) -> (B*J, C, N) for the shared Conv1d, then back
    t = conv.temp_conv(x.permute(0, 2, 3, 1).reshape(6, 4, 5)).reshape(2, 3, 4, 5).permute(0, 3, 1, 2)
    torch.testing.assert_close(conv(x), graph + t)
    # a joint's temporal term only sees its own time series
    x2 = x.clone()
    x2[:, :, 2] += 10.0
    t2 = conv.temp_conv(x2.permute(0, 2, 3, 1).reshape(6, 4, 5)).reshape(2, 3, 4, 5).permute(0, 3, 1, 2)
    torch.testing.assert_close(t2[:, :, :2], t[:, :, :2])


def test_multilinear_uses_separate_weights_per_part():
    torch.manual_seed(0)
    ml = MultiLinear(3, 4, 5)
    x = torch.randn(2, 6, 3, 4)
    out = ml(x)
    for p in range(3):
        torch.testing.assert_close(out[:, :, p], x[:, :, p] @ ml.weight[p] + ml.bias[p])


def test_pool_and_unpool_operators():
    sk = get_skeleton("humanml3d")
    pool = STPool(sk.pool_matrix(0))
    x = torch.randn(2, 6, 22, 3)
    groups = sk.pooling_levels[0]
    skel = torch.stack([x[:, :, list(g)].mean(dim=2) for g in groups], dim=2)  # (B, N, 12, C)
    expected = F.avg_pool1d(skel.permute(0, 2, 3, 1).reshape(2, 36, 6), 2).reshape(2, 12, 3, 3).permute(0, 3, 1, 2)
    torch.testing.assert_close(pool(x), expected)

    unpool = STUnpool(sk.unpool_matrix(0))
    const = torch.randn(1, 1, 12, 2).expand(1, 3, 12, 2)  # constant in time: upsampling keeps it
    out = unpool(const)
    assert out.shape == (1, 6, 22, 2)
    pelvis_groups = [i for i, g in enumerate(groups) if 0 in g]
    assert len(pelvis_groups) == 4  # the pelvis belongs to 4 groups and receives their *sum*
    torch.testing.assert_close(out[0, 0, 0], const[0, 0, pelvis_groups].sum(dim=0))
    ankle = sk.joint_names.index("left_ankle")
    assert [i for i, g in enumerate(groups) if ankle in g] == [2]  # a joint of a single group
    ramp = torch.tensor([0.0, 1.0]).reshape(1, 2, 1, 1).expand(1, 2, 12, 1)
    # linear upsampling, align_corners=False: [0, 1] -> [0, .25, .75, 1]
    torch.testing.assert_close(unpool(ramp)[0, :, ankle, 0], torch.tensor([0.0, 0.25, 0.75, 1.0]))


@pytest.mark.parametrize("skeleton", ["humanml3d", "kit"])
def test_model_skeleton_matrices(skeleton):
    sk = get_skeleton(skeleton)
    sd = _vae(skeleton=skeleton).state_dict()
    pool0, pool1 = sd["conv_enc.layers.0.2.skeleton_pool"], sd["conv_enc.layers.1.2.skeleton_pool"]
    for pool in (pool0, pool1):
        torch.testing.assert_close(pool.sum(dim=1), torch.ones(pool.shape[0]))  # means
    torch.testing.assert_close(sd["conv_dec.layers.1.0.skeleton_unpool"], (pool0 > 0).float().T)
    torch.testing.assert_close(sd["conv_dec.layers.0.0.skeleton_unpool"], (pool1 > 0).float().T)
    adj = sd["conv_enc.layers.0.0.layers.2.adj_matrix"]
    torch.testing.assert_close(adj, torch.from_numpy(sk.adjacency.astype(np.float32)) + torch.eye(sk.num_joints))
    torch.testing.assert_close(sd["conv_dec.layers.1.1.layers.5.adj_matrix"], adj)

    # joint -> part support of the composite J -> 7 pooling
    support = (pool1 @ pool0) > 0  # (7, J)
    assert support.any(dim=0).all()  # every joint reaches some part
    if skeleton == "humanml3d":
        j = sk.joint_names.index
        left_leg, right_leg = PART_NAMES.index("left leg"), PART_NAMES.index("right leg")
        allowed = {j(n) for n in ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "left_ankle", "left_foot")}
        assert set(torch.nonzero(support[left_leg]).flatten().tolist()) == allowed
        for name in ("left_knee", "left_ankle", "left_foot"):
            assert not support[right_leg, j(name)]
        for name, part in (("left_wrist", "left arm"), ("right_wrist", "right arm"), ("head", "head")):
            assert torch.nonzero(support[:, j(name)]).flatten().tolist() == [PART_NAMES.index(part)]


# ------------------------------------------------------ joint split/merge
@pytest.mark.parametrize("skeleton", ["humanml3d", "kit"])
def test_joint_split_and_merge_are_inverse(skeleton):
    sk = get_skeleton(skeleton)
    vae = _vae(skeleton=skeleton)
    d = sk.feature_dim
    cols = torch.arange(d, dtype=torch.float32).reshape(1, 1, d)
    tokens = vae.motion_enc.split(cols)
    assert len(tokens) == sk.num_joints
    gathered = torch.cat(tokens, dim=-1).flatten().long().tolist()
    assert sorted(gathered) == list(range(d))  # every column gathered exactly once
    for jnt, (tok, idx) in enumerate(zip(tokens, sk.joint_feature_index)):
        assert tok.flatten().long().tolist() == list(idx)
        assert vae.motion_enc.layers[jnt][0].in_features == len(idx)
        assert vae.motion_dec.layers[jnt][2].out_features == len(idx)
    x = torch.randn(2, 3, d)
    torch.testing.assert_close(vae.motion_dec.merge(vae.motion_enc.split(x)), x)
    # the official layout: root = 4 root dims + its velocity; contacts go last to their joints
    sl = sk.feature_slices
    assert tokens[0].flatten().long().tolist() == [0, 1, 2, 3, *range(sl["local_vel"].start, sl["local_vel"].start + 3)]
    for c, jnt in enumerate(sk.contact_joints):
        assert int(tokens[jnt][0, 0, -1]) == sl["contacts"].start + c


def test_decoder_reassembles_columns_in_feature_order():
    # make each joint MLP output a constant equal to its column ids: the merged vector must be 0..D-1
    vae = _vae()
    with torch.no_grad():
        for mlp, idx in zip(vae.motion_dec.layers, vae.skeleton.joint_feature_index):
            mlp[2].weight.zero_()
            mlp[2].bias.copy_(torch.tensor(idx, dtype=torch.float32))
        out = vae.motion_dec(torch.randn(1, 2, 22, 32))
    torch.testing.assert_close(out, torch.arange(263, dtype=torch.float32).expand(1, 2, 263))


# ------------------------------------------------------------------ loss
def test_loss_is_zero_for_perfect_reconstruction_and_prior_posterior():
    vae = _vae()
    x = torch.randn(2, 8, 263)
    zeros = torch.zeros(2, 2, 7, 32)
    out = vae.loss(x, x.clone(), zeros, zeros)
    assert set(out) == {"loss", "rec", "pos", "vel", "kl"}
    for v in out.values():
        assert v.item() == 0.0


def test_kl_hand_case_and_weighting():
    vae = _vae()  # lambda_kl 0.02
    x = torch.randn(1, 4, 263)
    mu = torch.tensor([1.0, 0.0]).reshape(1, 1, 1, 2)
    logvar = torch.tensor([0.0, math.log(2.0)]).reshape(1, 1, 1, 2)
    out = vae.loss(x, x, mu, logvar)
    # 0.5 * mean([1 + 1 - 0 - 1, 0 + 2 - ln 2 - 1]) : a mean over elements, not a sum
    expected = 0.25 * (2.0 - math.log(2.0))
    assert out["kl"].item() == pytest.approx(expected, rel=1e-6)
    assert out["loss"].item() == pytest.approx(0.02 * expected, rel=1e-6)


def test_reconstruction_terms_use_the_right_slices():
    vae = _vae()  # SmoothL1, beta 1: an error of 0.5 costs 0.5 * 0.5**2 = 0.125
    sl = vae.skeleton.feature_slices
    x = torch.randn(2, 8, 263)
    recon = x.clone()
    recon[..., sl["ric"]] += 0.5
    zeros = torch.zeros(2, 2, 7, 32)
    out = vae.loss(x, recon, zeros, zeros)
    n_ric = sl["ric"].stop - sl["ric"].start
    assert out["pos"].item() == pytest.approx(0.125, rel=1e-5)
    assert out["vel"].item() == 0.0
    assert out["rec"].item() == pytest.approx(0.125 * n_ric / 263, rel=1e-5)
    assert out["loss"].item() == pytest.approx(out["rec"].item() + 0.5 * 0.125, rel=1e-5)
    l1 = _vae(recon_loss="l1").loss(x, recon, zeros, zeros)
    assert l1["pos"].item() == pytest.approx(0.5, rel=1e-5)


def test_mask_ignores_padded_frames():
    vae = _vae()
    x = torch.randn(2, 8, 263)
    recon = x.clone()
    recon[1, 4:] += 100.0  # garbage in the padding of the second motion
    mu = torch.zeros(2, 2, 7, 32)
    mu[1, 1] = 50.0  # its second latent frame covers only padded frames
    mask = torch.ones(2, 8, dtype=torch.bool)
    mask[1, 4:] = False
    masked = vae.loss(x, recon, mu, torch.zeros_like(mu), mask=mask)
    for v in masked.values():
        assert v.item() == 0.0
    assert vae.loss(x, recon, mu, torch.zeros_like(mu))["rec"].item() > 1.0


# --------------------------------------------------- sampling and training
def test_sampling_is_deterministic_with_a_generator():
    vae = _vae().eval()
    x = torch.randn(1, 16, 263)
    z1 = vae.encode(x, generator=torch.Generator().manual_seed(7)).z
    z2 = vae.encode(x, generator=torch.Generator().manual_seed(7)).z
    z3 = vae.encode(x, generator=torch.Generator().manual_seed(8)).z
    assert torch.equal(z1, z2) and not torch.allclose(z1, z3)
    enc = vae.encode(x, sample=False)
    assert torch.equal(enc.z, enc.mu)
    # z = mu + eps * exp(logvar / 2) with eps ~ N(0, 1) drawn from the generator
    eps = torch.randn(enc.mu.shape, generator=torch.Generator().manual_seed(7))
    torch.testing.assert_close(z1, enc.mu + eps * torch.exp(0.5 * enc.logvar))


def test_overfit_one_real_clip(sample_dir, sample_features):
    x = _normalised_clip(sample_dir, sample_features)
    vae = _vae(seed=0)
    opt = torch.optim.Adam(vae.parameters(), lr=2e-3)
    frozen = {k: v.clone() for k, v in vae.state_dict().items() if k.endswith(("adj_matrix", "_pool", "_unpool"))}

    def rec_loss() -> float:
        vae.eval()
        with torch.no_grad():
            enc = vae.encode(x, sample=False)
            value = vae.loss(x, vae.decode(enc.z), enc.mu, enc.logvar)["rec"].item()
        vae.train()
        return value

    before = rec_loss()
    for _ in range(150):
        recon, mu, logvar = vae(x)
        loss = vae.loss(x, recon, mu, logvar)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    after = rec_loss()
    assert after < 0.25 * before, (before, after)
    for k, v in vae.state_dict().items():  # the skeleton matrices are not trained
        if k in frozen:
            assert torch.equal(v, frozen[k]), k


def test_pose_variant_trains(sample_dir, sample_features):
    x = _normalised_clip(sample_dir, sample_features, n=32)
    vae = _vae(seed=0, kind="pose", pose_width=64)
    opt = torch.optim.Adam(vae.parameters(), lr=2e-3)
    losses = []
    for _ in range(60):
        recon, mu, logvar = vae(x)
        loss = vae.loss(x, recon, mu, logvar)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:5])


def _sample_features() -> torch.Tensor:
    from pathlib import Path
    path = Path(__file__).parent / "data" / "humanml3d_sample" / "new_joint_vecs" / "012314.npy"
    return torch.from_numpy(np.load(path)).float()


def test_bone_lengths_from_features_match_forward_kinematics():
    from salad_core.motion import features_to_joints

    feats = _sample_features()                                      # (N, 263) real motion
    joints = features_to_joints(feats.numpy())
    sk = get_skeleton("humanml3d")
    want = np.linalg.norm(joints[:, 1:] - joints[:, list(sk.parents[1:])], axis=-1)
    got = MotionVAE(VAEConfig()).bone_lengths(feats).numpy()
    assert got.shape == (feats.shape[0], sk.num_joints - 1)
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_bone_term_measures_stretched_limbs_in_metres():
    sk = get_skeleton("humanml3d")
    feats = _sample_features()[:40]
    mean, std = feats.mean(0), feats.std(0) + 1e-3
    x = ((feats - mean) / std)[None]                                # (1, 40, 263) normalised
    vae = MotionVAE(VAEConfig(lambda_bone=2.0))
    zero = torch.zeros(1, 10, 7, 32)
    same = vae.loss(x, x.clone(), zero, zero, stats=(mean, std))
    assert float(same["bone"]) == 0.0
    # lift the left wrist's ric y by 0.1 m in every frame: one bone (elbow-wrist) changes
    wrist = sk.joint_names.index("left_wrist")
    col = sk.feature_slices["ric"].start + 3 * (wrist - 1) + 1
    moved = feats.clone()
    moved[:, col] += 0.1
    recon = ((moved - mean) / std)[None]
    out = vae.loss(x, recon, zero, zero, stats=(mean, std))
    lengths = vae.bone_lengths(feats)
    changed = (vae.bone_lengths(moved) - lengths).abs()             # only the forearm moves
    assert float(out["bone"]) == pytest.approx(float(changed.mean()), rel=1e-4)
    assert 0.0 < float(out["bone"]) < 0.1 / (sk.num_joints - 1) + 1e-6
    base = MotionVAE(VAEConfig()).loss(x, recon, zero, zero)["loss"]     # the official objective
    assert float(out["loss"]) == pytest.approx(float(base) + 2.0 * float(out["bone"]), rel=1e-6)
    with pytest.raises(ValueError, match="stats"):
        vae.loss(x, recon, zero, zero)


@pytest.mark.parametrize("field", ["lambda_bone", "latent_noise"])
def test_robustness_options_are_validated(field):
    with pytest.raises(ValueError, match=field):
        VAEConfig(**{field: -1.0})


def _two_branch_stconv(conv: STConv, x: torch.Tensor) -> torch.Tensor:
    """Paper eq. 1 as written: a Conv1d over every joint's time series plus the graph convolution."""
    b, n, j, c = x.shape
    t = conv.temp_conv(x.permute(0, 2, 3, 1).reshape(b * j, c, n)).reshape(b, j, c, n).permute(0, 3, 1, 2)
    return t if conv.graph_conv is None else t + conv.graph_conv(x, conv.adj_matrix)


@pytest.mark.parametrize("edges, nodes, kernel", [([(0, 1), (1, 2), (1, 3), (3, 4)], 5, 3), (None, 1, 5), ([(0, 1)], 2, 1)])
def test_stconv_single_product_equals_the_two_branch_form_with_gradients(edges, nodes, kernel):
    torch.manual_seed(0)
    conv = STConv(6, edges, nodes, kernel_size=kernel).double()
    x = torch.randn(3, 7, nodes, 6, dtype=torch.float64, requires_grad=True)
    out = conv(x)
    ref = _two_branch_stconv(conv, x)
    torch.testing.assert_close(out, ref, rtol=1e-12, atol=1e-12)
    w = torch.randn_like(out)
    params = [x] + [p for p in conv.parameters() if p.requires_grad]
    grads = torch.autograd.grad((out * w).sum(), params, retain_graph=True)
    ref_grads = torch.autograd.grad((ref * w).sum(), params)
    for g, r in zip(grads, ref_grads):
        torch.testing.assert_close(g, r, rtol=1e-10, atol=1e-12)
    # zero padding at the clip's ends: the first frame never sees a frame before it
    x2 = x.detach().clone()
    x2[:, -1] += 5.0
    if kernel == 1 or x.shape[1] > kernel:
        torch.testing.assert_close(conv(x2)[:, 0], out[:, 0].detach())
