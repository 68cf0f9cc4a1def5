"""The VAE's integrated-root term (``lambda_root``, issue 21) and decoder fine-tuning
(``VAETrainConfig.init_from`` / ``train_parts="decoder"``).

Tiny and seeded: hand-made feature windows, one procedural clip (the session's tiny corpus) and
the fake corpus of ``test_train.py``; no evaluation data.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.io import load_tensors
from salad_core.models.vae import MotionVAE, VAEConfig
from salad_core.motion import features_to_joints
from salad_core.skeleton import get_skeleton
from salad_core.train import VAETrainConfig, train_vae
from salad_core.train.vae_trainer import build_vae_task, load_init_vae
from salad_core.train.distributed import DistEnv
from _doubles import make_fake_corpus

SK = get_skeleton("humanml3d")
D = SK.feature_dim


def _vae(**kw) -> MotionVAE:
    torch.manual_seed(0)
    return MotionVAE(VAEConfig(latent_dim=8, n_extra_layers=0, **kw))


def _standing_window(n: int, b: int = 1) -> torch.Tensor:
    """De-normalised features of a motionless pose: zero root velocities, ric = a fixed T-ish pose."""
    rng = np.random.default_rng(0)
    f = np.zeros((b, n, D), dtype=np.float64)
    f[..., 3] = 0.9                                                  # root height
    ric = rng.uniform(-0.6, 0.6, size=(SK.num_joints - 1, 3))
    f[..., SK.feature_slices["ric"]] = ric.reshape(-1)
    return torch.from_numpy(f)


def _procedural_window(corpus: Path, n: int = 40) -> np.ndarray:
    ids = [x for x in (corpus / "train.txt").read_text().split() if x]
    for i in ids:
        f = np.load(corpus / "new_joint_vecs" / f"{i}.npy")
        if len(f) >= n and np.abs(f[:n, 0]).sum() > 0.05:           # a clip that turns
            return f[:n].astype(np.float64)
    raise AssertionError("no turning clip in the tiny corpus")


# ---------------------------------------------------------------------------- the term
def test_config_validates_lambda_root():
    assert VAEConfig().lambda_root == 0.0
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="lambda_root"):
            VAEConfig(lambda_root=bad)


def test_torch_integration_equals_motion_numpy(tiny_procedural_corpus):
    f = _procedural_window(tiny_procedural_corpus)
    vae = _vae()
    yaw, joints = vae.root_trajectory(torch.from_numpy(f)[None])
    want = features_to_joints(f)                                      # numpy, float64
    np.testing.assert_allclose(joints[0].numpy(), want, atol=1e-9)
    # yaw: twice the integrated half-angle, 0 on the first frame
    half = np.concatenate([[0.0], np.cumsum(f[:-1, 0])])
    np.testing.assert_allclose(yaw[0].numpy(), 2 * half, atol=1e-12)
    # float32 (what training uses) agrees to float tolerance
    _, j32 = vae.root_trajectory(torch.from_numpy(f).float()[None])
    np.testing.assert_allclose(j32[0].numpy(), want, atol=2e-5)


def test_zero_when_recon_equals_input_and_loss_dict():
    vae = _vae(lambda_root=2.0)
    x = torch.randn(2, 16, D)
    mu = logvar = torch.zeros(2, 4, vae.num_parts, vae.latent_dim)
    stats = (torch.full((D,), 0.1), torch.full((D,), 0.05))
    out = vae.loss(x, x.clone(), mu, logvar, stats=stats)
    assert out["root"].item() == 0.0 and out["root_yaw"].item() == 0.0 and out["root_pos"].item() == 0.0
    recon = x + 0.1 * torch.randn_like(x)
    out = vae.loss(x, recon, mu, logvar, stats=stats)
    base = _vae().loss(x, recon, mu, logvar)
    assert out["root"].item() > 0
    torch.testing.assert_close(out["loss"], base["loss"] + 2.0 * out["root"])
    assert "root" not in base                                         # off by default: the official loss
    with pytest.raises(ValueError, match="stats"):
        vae.loss(x, recon, mu, logvar)


@pytest.mark.parametrize("n", [8, 32])
def test_constant_yaw_bias_grows_with_window_as_by_hand(n):
    vae = _vae()
    x = _standing_window(n)
    b = 0.01                                                          # half-angle per frame (rad)
    recon = x.clone()
    recon[..., 0] += b
    yaw, pos = vae.root_error(recon, x)
    # yaw(t) = 2 b t for t = 0..N-1 -> mean b (N - 1)
    assert yaw.item() == pytest.approx(b * (n - 1), rel=1e-9)
    # the root stays put; joint j turns by 2 b t about the vertical: chord 2 r_j sin(b t)
    ric = x[0, 0, SK.feature_slices["ric"]].reshape(-1, 3).numpy()
    r = np.hypot(ric[:, 0], ric[:, 2])                                # (J-1,) horizontal radius
    t = np.arange(n)
    chord = 2 * r[None, :] * np.abs(np.sin(b * t))[:, None]           # (N, J-1)
    want = np.concatenate([np.zeros((n, 1)), chord], axis=1).mean()
    assert pos.item() == pytest.approx(want, rel=1e-9)
    if n == 32:
        short = vae.root_error(recon[:, :8], x[:, :8])
        assert yaw.item() > 4 * short[0].item() and pos.item() > 4 * short[1].item()


def test_linear_velocity_bias_moves_every_joint():
    vae = _vae()
    n = 10
    x = _standing_window(n)
    recon = x.clone()
    recon[..., 1] += 0.02                                             # 2 cm per frame along the heading x
    yaw, pos = vae.root_error(recon, x)
    assert yaw.item() == 0.0
    # every joint is displaced by 0.02 t metres at frame t
    assert pos.item() == pytest.approx(0.02 * np.arange(n).mean(), rel=1e-9)


def test_gradients_flow_to_velocity_and_ric_channels():
    vae = _vae()
    x = _standing_window(12).float()
    recon = (x + 0.01 * torch.randn_like(x)).requires_grad_(True)
    yaw, pos = vae.root_error(recon, x)
    (yaw + pos).backward()
    g = recon.grad
    assert torch.isfinite(g).all()
    assert g[..., 0].abs().sum() > 0 and g[..., 1].abs().sum() > 0 and g[..., 2].abs().sum() > 0
    assert g[..., SK.feature_slices["ric"]].abs().sum() > 0
    # the last row's velocity moves no frame inside the window
    assert g[0, -1, :3].abs().sum() == 0
    # recon == x: finite (zero) gradients, no NaN from the distance's square root
    same = x.clone().requires_grad_(True)
    sum(vae.root_error(same, x)).backward()
    assert torch.isfinite(same.grad).all()


def test_masked_frames_neither_integrate_nor_count():
    vae = _vae()
    x = _standing_window(16, b=2).float()
    x[..., 0] = 0.02                                                  # the input turns
    recon = x.clone()
    recon[..., 0] += 0.01
    mask = torch.zeros(2, 16, dtype=torch.bool)
    mask[0, :10] = True
    mask[1, :16] = True
    yaw, pos = vae.root_error(recon, x, mask)
    # equals the per-item errors on the valid prefixes, averaged over valid frames
    y0, p0 = vae.root_error(recon[:1, :10], x[:1, :10])
    y1, p1 = vae.root_error(recon[1:], x[1:])
    assert yaw.item() == pytest.approx((10 * y0.item() + 16 * y1.item()) / 26, rel=1e-5)
    assert pos.item() == pytest.approx((10 * p0.item() + 16 * p1.item()) / 26, rel=1e-5)
    # what lies in the masked frames changes nothing
    wild = recon.clone()
    wild[0, 10:] = 50.0
    assert torch.equal(torch.stack(vae.root_error(wild, x, mask)), torch.stack((yaw, pos)))


# ------------------------------------------------------------------------- fine-tuning
@pytest.fixture(scope="module")
def fake_corpus(tmp_path_factory) -> Path:
    return make_fake_corpus(tmp_path_factory.mktemp("corpus"))


def _train_cfg(**kw) -> VAETrainConfig:
    base = dict(batch_size=8, max_steps=4, lr=3e-3, warmup_steps=0, window=64, val_every=0, ckpt_every=0,
                log_every=1, num_threads=1, progress=False, seed=3)
    base.update(kw)
    return VAETrainConfig(**base)


@pytest.fixture(scope="module")
def base_run(fake_corpus, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("base")
    train_vae(fake_corpus, out, VAEConfig(latent_dim=8, n_extra_layers=0), _train_cfg(val_every=2))
    return out


def test_train_config_validates_fine_tuning_fields():
    assert VAETrainConfig().init_from is None and VAETrainConfig().train_parts == "all"
    with pytest.raises(ValueError, match="train_parts='encoder'"):
        VAETrainConfig(train_parts="encoder")
    with pytest.raises(ValueError, match="needs init_from"):
        VAETrainConfig(train_parts="decoder")
    with pytest.raises(ValueError, match="init_from"):
        VAETrainConfig(init_from="")


def test_decoder_fine_tuning_keeps_the_encoder_bit_identical(fake_corpus, base_run, tmp_path):
    cfg = VAEConfig(latent_dim=8, n_extra_layers=0, lambda_root=1.0)
    out = tmp_path / "dec"
    res = train_vae(fake_corpus, out, cfg, _train_cfg(init_from=str(base_run), train_parts="decoder", max_steps=3))
    assert res.step == 3
    before = load_tensors(base_run / "best.safetensors")
    after = load_tensors(out / "latest.safetensors")
    enc = [k for k in before if k.split(".")[0] in ("motion_enc", "conv_enc", "dist")]
    dec = [k for k in before if k.split(".")[0] in ("conv_dec", "motion_dec")]
    assert enc and dec
    for k in enc:
        assert torch.equal(before[k], after[k]), k
    assert any(not torch.equal(before[k], after[k]) for k in dec)
    # the posteriors of the fine-tuned model equal the original's exactly
    from salad_core.io import load_model

    a, _, _ = load_model(base_run / "best")
    b, _, _ = load_model(out / "latest")
    x = torch.randn(2, 16, D, generator=torch.Generator().manual_seed(1))
    ea, eb = a.encode(x, sample=False), b.encode(x, sample=False)
    assert torch.equal(ea.mu, eb.mu) and torch.equal(ea.logvar, eb.logvar)
    # the run normalises with the original run's statistics, and logs the root term
    s0, s1 = load_tensors(base_run / "mean_std.safetensors"), load_tensors(out / "mean_std.safetensors")
    assert torch.equal(s0["mean"], s1["mean"]) and torch.equal(s0["std"], s1["std"])
    entries = [json.loads(l) for l in (out / "log.jsonl").read_text().splitlines()]
    assert all("root" in e and np.isfinite(e["root"]) for e in entries if "loss" in e)


def test_decoder_mode_freezes_encoder_and_keeps_it_in_eval(fake_corpus, base_run):
    task = build_vae_task(fake_corpus, VAEConfig(latent_dim=8, n_extra_layers=0),
                          _train_cfg(init_from=str(base_run), train_parts="decoder"), DistEnv())
    vae = task.model
    assert not any(p.requires_grad for m in (vae.motion_enc, vae.conv_enc, vae.dist) for p in m.parameters())
    assert all(p.requires_grad for m in (vae.conv_dec, vae.motion_dec) for p in m.parameters()
               if not getattr(p, "salad_constant", False))           # graph matrices are structure
    task.objective.train()
    assert not vae.conv_enc.training and vae.conv_dec.training
    # "all" trains everything from the same start
    task_all = build_vae_task(fake_corpus, VAEConfig(latent_dim=8, n_extra_layers=0),
                              _train_cfg(init_from=str(base_run)), DistEnv())
    assert all(p.requires_grad for p in task_all.model.parameters() if not getattr(p, "salad_constant", False))
    ref = load_tensors(base_run / "best.safetensors")
    assert all(torch.equal(v, ref[k]) for k, v in task_all.model.state_dict().items() if k in ref)


def test_init_from_errors_name_the_problem(fake_corpus, base_run, tmp_path):
    with pytest.raises(ValueError, match=r"another architecture.*latent_dim: 8 \(init_from\) vs 16"):
        build_vae_task(fake_corpus, VAEConfig(latent_dim=16, n_extra_layers=0),
                       _train_cfg(init_from=str(base_run)), DistEnv())
    with pytest.raises(FileNotFoundError, match="neither a VAE run folder"):
        load_init_vae(tmp_path)
    with pytest.raises(FileNotFoundError, match="neither a VAE run folder"):
        load_init_vae(tmp_path / "missing")
    # an exported VAE (or its stem) starts a fine-tuning run as its training run does
    from salad_core.train.assemble import export_vae

    exported = export_vae(base_run, tmp_path / "exported", dtype=None)
    want = load_init_vae(base_run)
    for where in (exported, exported / "vae"):
        config, state, mean, std, _ = load_init_vae(where)
        assert config == want[0] and all(torch.equal(state[k], want[1][k]) for k in want[1])
        np.testing.assert_array_equal(mean, want[2])


# ------------------------------------------------------------------ root-channel weight
def test_config_validates_lambda_root_features():
    assert VAEConfig().lambda_root_features == 0.0
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="lambda_root_features"):
            VAEConfig(lambda_root_features=bad)


def test_root_features_term_by_hand():
    # L1 criterion so the expected values are exact: an error of 0.5 on the angular velocity alone
    vae = _vae(recon_loss="l1", lambda_root_features=3.0)
    x = torch.randn(2, 16, D, generator=torch.Generator().manual_seed(0))
    mu = logvar = torch.zeros(2, 4, vae.num_parts, vae.latent_dim)
    recon = x.clone()
    recon[..., 0] += 0.5
    out = vae.loss(x, recon, mu, logvar)
    assert out["root_feat"].item() == pytest.approx(0.5 / 4, rel=1e-6)         # mean over the 4 root columns
    assert out["rec"].item() == pytest.approx(0.5 / D, rel=1e-5)                # its share of rec: 1/263
    base = _vae(recon_loss="l1").loss(x, recon, mu, logvar)
    assert "root_feat" not in base                                             # off by default: official loss
    torch.testing.assert_close(out["loss"], base["loss"] + 3.0 * out["root_feat"])
    # an error outside the root slice leaves the term at 0
    other = x.clone()
    other[..., 4] += 0.5
    assert vae.loss(x, other, mu, logvar)["root_feat"].item() == 0.0
    # masked frames do not count: the error on frames 8.. only
    late = x.clone()
    late[:, 8:, 1] += 1.0
    mask = torch.zeros(2, 16, dtype=torch.bool)
    mask[:, :8] = True
    assert vae.loss(x, late, mu, logvar, mask=mask)["root_feat"].item() == 0.0
    assert vae.loss(x, late, mu, logvar)["root_feat"].item() == pytest.approx(0.5 * 1.0 / 4, rel=1e-6)


def test_root_features_term_moves_the_decoder_towards_the_root_channels():
    # one gradient step of the decoder: with the weight, the root channels' error falls more
    torch.manual_seed(0)
    x = torch.randn(4, 16, D, generator=torch.Generator().manual_seed(2))
    drops = {}
    for w in (0.0, 10.0):
        vae = _vae(lambda_root_features=w)
        vae.eval()
        opt = torch.optim.SGD(list(vae.conv_dec.parameters()) + list(vae.motion_dec.parameters()), lr=0.05)
        enc = vae.encode(x, sample=False)
        before = (vae.decode(enc.mu)[..., :4] - x[..., :4]).abs().mean().item()
        vae.loss(x, vae.decode(enc.mu), enc.mu, enc.logvar)["loss"].backward()
        opt.step()
        with torch.no_grad():
            after = (vae.decode(enc.mu)[..., :4] - x[..., :4]).abs().mean().item()
        drops[w] = before - after
    assert drops[10.0] > 3 * max(drops[0.0], 1e-6)


# ------------------------------------------------------------------------ CLI flags
def test_cli_parses_init_from_and_train_parts(tmp_path):
    from salad_core.cli.train import build_parser, main

    args = build_parser().parse_args(["vae", "--data", "d", "--out", "o", "--init-from", "runs/vae",
                                      "--train-parts", "decoder"])
    assert args.init_from == "runs/vae" and args.train_parts == "decoder"
    assert build_parser().parse_args(["vae", "--data", "d", "--out", "o"]).train_parts is None
    with pytest.raises(SystemExit):
        build_parser().parse_args(["vae", "--data", "d", "--out", "o", "--train-parts", "encoder"])
    for what in ("denoiser", "keymotion"):
        with pytest.raises(SystemExit) as exc:
            main([what, "--data", "d", "--out", str(tmp_path / what), "--init-from", "runs/vae"])
        assert exc.value.code == 2


def test_cli_init_from_flag_error_message(capsys):
    from salad_core.cli.train import main

    with pytest.raises(SystemExit):
        main(["denoiser", "--data", "d", "--out", "o", "--train-parts", "decoder"])
    assert "--init-from/--train-parts are for 'salad train vae' only" in capsys.readouterr().err
    # decoder without any init_from: the config's own error, naming the field
    with pytest.raises(ValueError, match="needs init_from"):
        main(["vae", "--data", "d", "--out", "o", "--train-parts", "decoder"])


def test_cli_decoder_fine_tuning_two_steps(fake_corpus, base_run, tmp_path, capsys):
    from salad_core.io import load_model
    from salad_core.cli.train import main

    conf = tmp_path / "conf.json"
    conf.write_text(json.dumps({
        "model": {"latent_dim": 8, "n_extra_layers": 0, "lambda_root": 0.5, "lambda_root_features": 2.0},
        "train": {"batch_size": 8, "max_steps": 5, "warmup_steps": 0, "num_threads": 1, "window": 64,
                  "val_every": 0, "ckpt_every": 0, "log_every": 1, "seed": 3}}))
    out = tmp_path / "dec"
    assert main(["vae", "--data", str(fake_corpus), "--out", str(out), "--config", str(conf), "--steps", "2",
                 "--init-from", str(base_run), "--train-parts", "decoder", "--no-progress"]) == 0
    assert "vae: step 2" in capsys.readouterr().out
    doc = json.loads((out / "config.json").read_text())
    assert doc["train"]["init_from"] == str(base_run) and doc["train"]["train_parts"] == "decoder"
    assert doc["model"]["lambda_root_features"] == 2.0
    a, _, _ = load_model(base_run / "best")
    b, _, _ = load_model(out / "latest")
    sa, sb = a.state_dict(), b.state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa if k.split(".")[0] in ("motion_enc", "conv_enc", "dist"))
    assert any(not torch.equal(sa[k], sb[k]) for k in sa if k.split(".")[0] in ("conv_dec", "motion_dec"))
    entries = [json.loads(l) for l in (out / "log.jsonl").read_text().splitlines()]
    logged = [e for e in entries if "loss" in e]
    assert len(logged) == 2 and all(np.isfinite(e["root_feat"]) and np.isfinite(e["root"]) for e in logged)


# ------------------------------------------------------------- posterior-mean decoding
def test_posterior_noise_validates_and_zero_decodes_the_mean():
    from salad_core.train.vae_trainer import VAEObjective

    assert VAEConfig().posterior_noise == 1.0                                  # official: decode samples
    with pytest.raises(ValueError, match="posterior_noise"):
        VAEConfig(posterior_noise=-0.5)
    x = torch.randn(2, 16, D, generator=torch.Generator().manual_seed(4))
    g = torch.Generator().manual_seed(5)
    eps1, eps2 = (torch.randn(2, 4, 7, 8, generator=g) for _ in range(2))
    losses = {}
    for pn in (0.0, 1.0):
        vae = _vae(posterior_noise=pn, dropout=0.0)
        obj = VAEObjective(vae).eval()
        with torch.no_grad():
            losses[pn] = (obj(x, eps1)["loss"].item(), obj(x, eps2)["loss"].item())
            if pn == 0.0:
                enc = vae.encode(x, sample=False)
                want = vae.loss(x, vae.decode(enc.mu), enc.mu, enc.logvar)["loss"].item()
    assert losses[0.0][0] == losses[0.0][1] == pytest.approx(want, rel=1e-6)   # the noise plays no part
    assert losses[1.0][0] != losses[1.0][1]


# -------------------------------------------------------------- measurement helpers
# ---------------------------------------------------------------------------- the foot-contact term
def test_foot_term_in_the_loss_and_off_by_default():
    vae = _vae(lambda_foot=2.0)
    x = _standing_window(16, b=2)
    x[..., SK.feature_slices["contacts"]] = 1.0
    recon = x.clone()
    recon[..., 2] = 0.01
    mean, std = torch.zeros(D, dtype=torch.float64), torch.ones(D, dtype=torch.float64)
    mu = logvar = torch.zeros(2, 4, vae.num_parts, vae.latent_dim, dtype=torch.float64)
    out = vae.loss(x, recon, mu, logvar, stats=(mean, std))
    assert out["foot"].item() == pytest.approx(0.01, rel=1e-5)
    base = _vae().loss(x, recon, mu, logvar)
    assert "foot" not in base
    torch.testing.assert_close(out["loss"], base["loss"] + 2.0 * out["foot"].to(base["loss"].dtype))
    with pytest.raises(ValueError, match="lambda_foot > 0 needs stats"):
        vae.loss(x, recon, mu, logvar)
    with pytest.raises(ValueError, match="lambda_foot"):
        VAEConfig(lambda_foot=-1.0)


def test_trainer_logs_the_foot_term(fake_corpus, tmp_path):
    """A run with ``lambda_foot`` gets the statistics it needs and logs the term (metres per frame)."""
    out = tmp_path / "foot"
    res = train_vae(fake_corpus, out, VAEConfig(latent_dim=8, n_extra_layers=0, lambda_foot=1.0), _train_cfg(max_steps=2))
    assert res.step == 2
    logged = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    foot = [r["foot"] for r in logged if "foot" in r]
    assert foot and all(np.isfinite(v) and v >= 0 for v in foot)
