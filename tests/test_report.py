"""The notebooks' evaluation building blocks: published tables (eval.paper_tables), held-out corpus
clips (eval.heldout), official-release loading (eval.official), length-bucketed generation
(eval.length_buckets) and the KeyMotion round trips (eval.keymotion_roundtrip).

Tiny seeded models, one CPU thread, a hashing text encoder (no MiniLM) and a 40-motion corpus.
"""
from __future__ import annotations

import itertools
import json
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.eval import EvalResult, results_frame, to_markdown
from salad_core.eval.metrics import mpjpe
from salad_core.eval.heldout import heldout_corpus
from salad_core.eval.keymotion_roundtrip import infill_from_keyframes, keyframe_roundtrip
from salad_core.eval.length_buckets import LengthBucketed, length_groups
from salad_core.eval.official import official_salad_pipeline, read_official_options
from salad_core.eval.paper_tables import PAPER_CFG_SWEEP, PAPER_TABLE1, paper_denoiser_ablations, paper_table1
from salad_core.eval.settings import METRICS
from salad_core.keymotion import select_keyframes
from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig
from salad_core.keymotion.mmae import MMAEConfig, MotionMaskedAutoencoder
from salad_core.keymotion.models import pose_joints
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.pst import ParallelSkipTransformer, PSTConfig
from salad_core.models import Denoiser, DenoiserConfig, MotionVAE, VAEConfig
from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import get_skeleton
from _doubles import HashTextEncoder

SK = get_skeleton("humanml3d")
TEXT_DIM = 32
K = 8


pytestmark = pytest.mark.usefixtures("single_thread")


def _tiny_salad(sample_dir, seed=0, activation="gelu", heads=2):
    torch.manual_seed(seed)
    vae = MotionVAE(VAEConfig(activation=activation)).eval()
    den = Denoiser(DenoiserConfig(width=32, heads=heads, ff_dim=64, layers=3, text_dim=TEXT_DIM, dropout=0.0)).eval()
    return vae, den, np.load(sample_dir / "Mean.npy"), np.load(sample_dir / "Std.npy")


@pytest.fixture(scope="module")
def salad_pipe(sample_dir):
    vae, den, mean, std = _tiny_salad(sample_dir)
    return SaladPipeline(vae, den, HashTextEncoder(TEXT_DIM), mean, std)


@pytest.fixture(scope="module")
def keymotion_pipe(sample_dir):
    torch.manual_seed(3)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=K, frame_dim=56, index_dim=8, latent_size=2, latent_dim=16,
                                        num_layers=1, num_heads=4, ff_dim=128, dropout=0.0))
    pst = ParallelSkipTransformer(PSTConfig(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4,
                                            ff_dim=64, num_cond_layers=1, num_cross_layers=2, dropout=0.0))
    mmae = MotionMaskedAutoencoder(MMAEConfig(text_dim=TEXT_DIM, width=64, num_layers=2, num_heads=4, ff_dim=128,
                                              dropout=0.0))
    mean, std = np.load(sample_dir / "Mean.npy"), np.load(sample_dir / "Std.npy")
    for m in (vae, mmae):
        m.set_normalization(mean, std)
    # a non-zero output head, so the MMAE's correction of the interpolation is not trivially zero
    with torch.no_grad():
        for p in mmae.out.parameters():
            p.normal_(0.0, 0.05)
    return KeyMotionPipeline(vae, pst, mmae, HashTextEncoder(TEXT_DIM))


# ------------------------------------------------------------------------------ paper table
def test_paper_table1_holds_the_published_rows_labelled_as_the_papers():
    df = paper_table1()
    assert list(df["name"]) == ["paper: Real motion", "paper: SALAD"]
    assert (df["kind"] == "paper").all()
    salad = df.iloc[1]
    assert (salad["R-precision top-1"], salad["R-precision top-3"], salad["R-precision top-3 ±"]) == (.581, .857, .002)
    assert (salad["FID"], salad["FID ±"], salad["MM-Dist"], salad["MultiModality"]) == (.076, .002, 2.649, 1.751)
    assert np.isnan(df.iloc[0]["MultiModality"]) and df.iloc[0]["FID"] == .002
    kit = paper_table1("kit", methods=["SALAD"])
    assert kit.iloc[0]["FID"] == .296 and kit.iloc[0]["Diversity"] == 11.097
    every = paper_table1(methods=None)
    assert len(every) == len(PAPER_TABLE1["humanml3d"]) == 10
    assert np.isnan(every.set_index("name").loc["paper: MoMask", "Diversity"])
    # usable as the published reference beside computed rows
    ours = results_frame([EvalResult("SALAD", {m: (0.5, 0.6) for m in METRICS[:6]}, {"kind": "generator"})])
    md = to_markdown(ours, reference=df)
    assert "Published numbers" in md and "0.857 ± 0.002" in md and "1.751 ± 0.062" in md
    with pytest.raises(ValueError, match="not rows of the paper's Table 1"):
        paper_table1(methods=["KeyMotion"])


def test_paper_denoiser_ablations_hold_the_published_rows():
    t3 = paper_denoiser_ablations("table3")
    assert list(t3["name"]) == ["paper: Full model", "paper: w/o ST-Latent", "paper: w/o CrossAttn", "paper: w/o both"]
    row = t3.set_index("name").loc["paper: w/o ST-Latent"]
    assert (row["R-precision top-3"], row["FID"], row["FID ±"]) == (.816, .433, .006)
    assert np.isnan(row["R-precision top-1"]) and np.isnan(row["MM-Dist"])
    assert paper_denoiser_ablations("supp_table2").set_index("name").loc["paper: epsilon-prediction", "FID"] == .257
    kit = paper_denoiser_ablations("supp_table3", "kit")
    assert kit["R-precision top-3"].tolist() == [.828, .803] and (kit["kind"] == "paper").all()
    # a reference beside computed rows shows only the two columns the paper printed
    ours = results_frame([EvalResult("full", {m: (0.5, 0.6) for m in METRICS[:6]}, {"kind": "generator"})])
    md = to_markdown(ours, reference=t3)
    published = md.split("Published numbers")[1]
    assert "0.433 ± 0.006" in published and "MM-Dist" not in published
    with pytest.raises(ValueError, match="no 'kit' rows"):
        paper_denoiser_ablations("table3", "kit")
    with pytest.raises(ValueError, match="supp_table2"):
        paper_denoiser_ablations("table4")


# ---------------------------------------------------------------------------- held-out corpus
def test_heldout_corpus_writes_the_split_clips_byte_for_byte(tmp_path):
    from salad_core.data.procedural import build_corpus

    build_corpus(tmp_path / "full", size=40, seed=3, progress=False)
    out = heldout_corpus(tmp_path / "held", motions=3, size=40, seed=3)
    names = (out / "test.txt").read_text().split()
    full_test = (tmp_path / "full" / "test.txt").read_text().split()
    first = sorted({int(n.lstrip("M")) for n in full_test})[:3]       # the split's first 3 motions, by id
    assert names == sorted([f"{i:06d}" for i in first] + [f"M{i:06d}" for i in first])
    assert set(names) <= set(full_test)
    for n in names:
        for sub, ext in (("new_joint_vecs", "npy"), ("new_joints", "npy"), ("texts", "txt"), ("annotations", "json")):
            assert (out / sub / f"{n}.{ext}").read_bytes() == (tmp_path / "full" / sub / f"{n}.{ext}").read_bytes()
    assert not (out / "train.txt").exists()
    with pytest.raises(FileExistsError):
        heldout_corpus(out, motions=1, size=40, seed=3)
    with pytest.raises(ValueError, match="motions=99"):
        heldout_corpus(tmp_path / "other", motions=99, size=40, seed=3)


# ------------------------------------------------------------------------------ official
def test_read_official_options_types(tmp_path):
    p = tmp_path / "opt.txt"
    p.write_text("------------ Options -------------\nname: t2m_denoiser_vpred_vaegelu\nis_continue: False\n"
                 "lr: 0.0005\nn_layers: 5\nmilestones: [50000]\ncheckpoints_dir: ./checkpoints\n"
                 "clip_version: ViT-B/32\n-------------- End ----------------\n")
    opt = read_official_options(p)
    assert opt == {"name": "t2m_denoiser_vpred_vaegelu", "is_continue": False, "lr": 0.0005, "n_layers": 5,
                   "milestones": [50000], "checkpoints_dir": "./checkpoints", "clip_version": "ViT-B/32"}
    with pytest.raises(FileNotFoundError, match="opt.txt"):
        read_official_options(tmp_path / "missing" / "opt.txt")


def test_official_salad_pipeline_loads_a_release_folder(tmp_path, sample_dir):
    vae, den, mean, std = _tiny_salad(sample_dir, seed=5, activation="silu", heads=4)
    ds = tmp_path / "checkpoints" / "t2m"
    for sub in ("den/model", "myvae/model", "Comp_v6_KLD005/meta"):
        (ds / sub).mkdir(parents=True)
    (ds / "den" / "opt.txt").write_text("name: den\nvae_name: myvae\nn_heads: 4\nbeta_end: 0.02\n"
                                        "prediction_type: epsilon\nactivation: gelu\n")
    (ds / "myvae" / "opt.txt").write_text("name: myvae\nactivation: silu\n")
    torch.save({"vae": vae.official_state_dict(), "epoch": 3}, ds / "myvae" / "model" / "net_best_fid.tar")
    torch.save({"denoiser": den.official_state_dict(), "epoch": 7}, ds / "den" / "model" / "net_best_fid.tar")
    np.save(ds / "Comp_v6_KLD005" / "meta" / "mean.npy", mean)
    np.save(ds / "Comp_v6_KLD005" / "meta" / "std.npy", std)

    pipe = official_salad_pipeline(tmp_path / "checkpoints", "humanml3d", "den", text_encoder=HashTextEncoder(TEXT_DIM))
    assert pipe.vae.config.activation == "silu" and pipe.denoiser.config.heads == 4
    assert pipe.diffusion.beta_end == 0.02 and pipe.diffusion.prediction_type == "epsilon"
    assert pipe.diffusion.beta_start == 0.00085                 # not in opt.txt: the official default
    np.testing.assert_array_equal(pipe.mean, mean.astype(np.float32))
    # the same networks: identical outputs on the same input
    x = torch.randn(1, 5, 7, 32)
    text, tmask = torch.randn(1, 4, TEXT_DIM), torch.ones(1, 4, dtype=torch.bool)
    with torch.no_grad():
        t = torch.tensor([10])
        torch.testing.assert_close(pipe.denoiser(x, t, text, tmask), den(x, t, text, tmask))
        torch.testing.assert_close(pipe.vae.decode(x), vae.decode(x))
    out = pipe("a man walks", lengths=40, num_steps=2)
    assert out.features.shape == (1, 40, SK.feature_dim) and np.isfinite(out.features).all()

    (ds / "den" / "opt.txt").write_text("name: den\n")
    with pytest.raises(ValueError, match="vae_name"):
        official_salad_pipeline(tmp_path / "checkpoints", "humanml3d", "den", text_encoder=HashTextEncoder(TEXT_DIM))


# ------------------------------------------------------------------------ length buckets
def _padded_cost(lengths, groups):
    return sum(len(g) * max(lengths[i] for i in g) for g in groups)


def test_length_groups_is_the_least_padding_partition():
    rng = np.random.default_rng(0)
    for _ in range(20):
        lengths = [int(v) for v in rng.integers(10, 50, size=int(rng.integers(1, 9))) * 4]
        for k in (1, 2, 3):
            groups = length_groups(lengths, k)
            assert len(groups) <= k
            assert sorted(np.concatenate(groups).tolist()) == list(range(len(lengths)))
            s = sorted(lengths)
            best = min(sum((b - a) * s[b - 1] for a, b in zip((0, *cuts), (*cuts, len(s))))
                       for r in range(min(k, len(s)))
                       for cuts in itertools.combinations(range(1, len(s)), r))
            assert _padded_cost(lengths, groups) == best
    assert [g.tolist() for g in length_groups([40, 196, 44], 3)] in ([[0, 2], [1]], [[0], [2], [1]])
    with pytest.raises(ValueError, match="groups"):
        length_groups([40], 0)


def test_length_bucketed_generates_the_same_motions_in_fewer_padded_frames(salad_pipe):
    prompts = ["a man walks forward", "a person jumps", "someone waves", "a man kicks", "a person sits"]
    lengths = [40, 160, 44, 48, 152]
    calls = []

    def spy(p, lengths, seed, **kw):
        calls.append(list(lengths))
        return salad_pipe(p, lengths=lengths, seed=seed, **kw)

    spy.source = "spy"
    ref = salad_pipe(prompts, lengths=lengths, seed=11, num_steps=3)
    got = LengthBucketed(spy, groups=2)(prompts, lengths=lengths, seed=11, num_steps=3)
    assert sorted(map(sorted, calls)) == [[40, 44, 48], [152, 160]]
    assert got.features.shape == ref.features.shape and got.lengths == lengths
    np.testing.assert_allclose(got.features, ref.features, atol=1e-4)
    for a, b in zip(got.joints, ref.joints):
        np.testing.assert_allclose(a, b, atol=1e-4)
    assert LengthBucketed(salad_pipe).source == salad_pipe.source
    with pytest.raises(ValueError, match="one length per prompt"):
        LengthBucketed(salad_pipe)(prompts, lengths=[40])


# ------------------------------------------------------------------------------ KeyMotion
def test_keyframe_roundtrip_selects_encodes_and_decodes(keymotion_pipe, sample_features):
    x = sample_features[:80]
    res = keyframe_roundtrip(keymotion_pipe, x)
    xn = (x - keymotion_pipe.mmae.norm.mean.numpy()) / keymotion_pipe.mmae.norm.std.numpy()
    np.testing.assert_array_equal(res.indices, select_keyframes(xn.astype(np.float32), K, "mdo"))
    np.testing.assert_allclose(res.keyframes, x[res.indices], atol=1e-4)
    np.testing.assert_allclose(res.joints, pose_joints(torch.from_numpy(x[res.indices]), SK).numpy(), atol=1e-4)
    d = res.decoded_indices
    assert d[0] == 0 and d[-1] == len(x) - 1 and (np.diff(d) > 0).all()
    assert res.decoded.shape == (K, SK.feature_dim) and res.decoded_joints.shape == (K, SK.num_joints, 3)
    assert res.pose_mpjpe == pytest.approx(mpjpe(res.decoded_joints, res.joints)) and res.pose_mpjpe > 0
    assert res.index_error == pytest.approx(np.abs(d - res.indices).mean())
    uni = keyframe_roundtrip(keymotion_pipe, x, method="uniform")
    np.testing.assert_array_equal(uni.indices, np.round(np.linspace(0, len(x) - 1, K)).astype(int))
    with pytest.raises(ValueError, match="frames"):
        keyframe_roundtrip(keymotion_pipe, x[: K - 1])


def test_infill_from_keyframes_against_interpolation(keymotion_pipe, sample_features):
    x = sample_features[:64]
    res = infill_from_keyframes(keymotion_pipe, x, "a person walks")
    assert res.features.shape == x.shape and res.joints.shape == (64, SK.num_joints, 3)
    assert res.lerp_mpjpe == pytest.approx(mpjpe(res.lerp_joints, res.true_joints))
    assert res.mpjpe == pytest.approx(mpjpe(res.joints, res.true_joints)) and res.mpjpe != res.lerp_mpjpe
    kept = infill_from_keyframes(keymotion_pipe, x, "a person walks", keep_keyframes=True)
    np.testing.assert_allclose(kept.features[kept.indices], x[kept.indices], atol=1e-4)
    # every frame a keyframe: interpolation is the motion itself, and kept keyframes leave nothing to fill
    whole = infill_from_keyframes(keymotion_pipe, x[:K], "a person walks", keep_keyframes=True)
    assert whole.lerp_mpjpe_global < 1e-5 and whole.mpjpe_global < 1e-5
    with pytest.raises(ValueError, match="caption"):
        infill_from_keyframes(keymotion_pipe, x, "  ")


def test_generation_chain_gives_each_stage_of_the_path(keymotion_pipe, sample_features):
    """The chain's stages are the motion, the in-filling of its own keyframes, the same after the keyframe VAE,
    and the pipeline's generation from the caption, all raw position joints of the motion's length."""
    from salad_core.eval.keymotion_roundtrip import CHAIN_STAGES, generation_chain
    from salad_core.motion import features_to_joints

    x = sample_features[:64]
    chain = generation_chain(keymotion_pipe, x, "a person walks", seed=2)
    assert tuple(chain) == CHAIN_STAGES
    assert {k: v.shape for k, v in chain.items()} == {k: (64, SK.num_joints, 3) for k in CHAIN_STAGES}
    np.testing.assert_allclose(chain["true"], features_to_joints(x, SK), atol=1e-5)
    np.testing.assert_allclose(chain["true_keyframes"], infill_from_keyframes(keymotion_pipe, x, "a person walks").joints,
                               atol=1e-5)
    gen = keymotion_pipe(["a person walks"], lengths=[64], seed=2)
    np.testing.assert_allclose(chain["generated"], gen.raw_joints[0], atol=1e-5)
    assert np.abs(chain["vae_keyframes"] - chain["true_keyframes"]).max() > 1e-4    # the VAE changes the keyframes
    with pytest.raises(ValueError, match="caption"):
        generation_chain(keymotion_pipe, x, "")


def test_generation_chain_after_the_skeleton_fit(keymotion_pipe, sample_features):
    """``recovery="fit"``: the generated stages are the fitted joints of the same features (the fit keeps every
    bone at one length and puts nothing below the floor), the true stage stays the clip's position joints."""
    from salad_core.eval.keymotion_roundtrip import generation_chain
    from salad_core.eval.physics import bone_length_errors

    x = sample_features[:64]
    raw = generation_chain(keymotion_pipe, x, "a person walks", seed=2)
    fit = generation_chain(keymotion_pipe, x, "a person walks", seed=2, recovery="fit")
    np.testing.assert_allclose(fit["true"], raw["true"])
    gen = keymotion_pipe(["a person walks"], lengths=[64], seed=2, recovery="fit")
    np.testing.assert_allclose(fit["generated"], gen.joints[0], atol=1e-5)
    for stage in ("true_keyframes", "vae_keyframes", "generated"):
        assert np.abs(fit[stage] - raw[stage]).max() > 1e-3                   # the fit moved joints
        assert fit[stage][..., 1].min() > -1e-6                               # nothing below the floor
        assert bone_length_errors(fit[stage], SK)["self_error"].max() < 1e-3    # fixed bones
    with pytest.raises(ValueError, match="recovery='ik'"):
        generation_chain(keymotion_pipe, x, "a person walks", recovery="ik")
    # the generated stage's guidance weight: the pipeline's call with that weight
    w1 = generation_chain(keymotion_pipe, x, "a person walks", seed=2, guidance_scale=1.0)
    np.testing.assert_allclose(w1["generated"], keymotion_pipe(["a person walks"], lengths=[64], seed=2,
                                                               guidance_scale=1.0).raw_joints[0], atol=1e-5)
    assert np.abs(w1["generated"] - raw["generated"]).max() > 1e-4


def test_procedural_eval_corpus_picks_heldout_clips_or_the_given_root(tmp_path):
    from salad_core.eval.heldout import procedural_eval_corpus

    quick = procedural_eval_corpus(True, tmp_path, heldout_motions=2)
    ids = (quick / "test.txt").read_text().split()
    assert len(ids) == 4 and all((quick / "new_joint_vecs" / f"{i}.npy").is_file() for i in ids)
    assert procedural_eval_corpus(False, tmp_path, data_root=str(tmp_path / "hml")) == tmp_path / "hml"


def test_evaluation_data_picks_the_procedural_or_the_official_setting(tmp_path, monkeypatch):
    from salad_core.eval import heldout

    data, ev = heldout.evaluation_data(True, tmp_path, heldout_motions=2)
    assert (data / "test.txt").is_file() and "evaluator" in str(ev.source)
    assert heldout.evaluation_data(False, tmp_path, data_root=tmp_path / "mine")[0] == tmp_path / "mine"
    with pytest.raises(ValueError, match="needs DATA_ROOT"):
        heldout.evaluation_data(False, tmp_path, checkpoints=tmp_path)
    calls = []
    from salad_core.eval import t2m

    monkeypatch.setattr(t2m.T2MEvaluator, "from_official",
                        classmethod(lambda cls, ckpt, ds: calls.append((ckpt, ds)) or types.SimpleNamespace()))
    data, ev = heldout.evaluation_data(False, tmp_path, data_root=tmp_path / "hml", checkpoints="ck", dataset="kit")
    assert calls == [("ck", "kit")] and data == tmp_path / "hml" and ev.source == "official T2M evaluator (kit)"
    # QUICK ignores the official release
    assert heldout.evaluation_data(True, tmp_path, checkpoints="ck", heldout_motions=2)[1].source != ev.source


# ------------------------------------------------------------------------------ module layout
def test_the_papers_table1_and_its_supplement_table1_have_distinct_names():
    """Table 1 compares methods at w = 7.5; supplement Table 1 sweeps SALAD's CFG weight. They share
    SALAD's w = 7.5 row and the real row, nothing else."""
    from salad_core.eval.paper_tables import paper_cfg_sweep

    assert set(PAPER_TABLE1["humanml3d"]) - {"Real motion"} == {"T2M", "AttT2M", "ParCo", "MoMask", "MDM", "MLD",
                                                              "MotionDiffuse", "ReMoDiffuse", "SALAD"}
    assert set(PAPER_CFG_SWEEP["humanml3d"]) - {"Real motion"} == {1.5 + k for k in range(12)}
    for ds in ("humanml3d", "kit"):
        # the real rows agree on the six metrics both print
        assert PAPER_TABLE1[ds]["Real motion"][:6] == PAPER_CFG_SWEEP[ds]["Real motion"]
    # HumanML3D: the sweep's w = 7.5 row is Table 1's SALAD row (Table 1 adds MultiModality)
    assert PAPER_TABLE1["humanml3d"]["SALAD"][:6] == PAPER_CFG_SWEEP["humanml3d"][7.5]
    sweep = paper_cfg_sweep("kit")
    assert sweep.iloc[0]["data"] == "SALAD paper, supplement Table 1 (kit)"
    assert paper_table1("kit").iloc[0]["data"] == "SALAD paper (CVPR 2025), Table 1 (kit)"
