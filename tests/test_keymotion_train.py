"""``salad train keymotion``: config document, CLI, staged resume, and the shipped KeyMotion weights.

The CLI runs on a tiny procedural corpus with tiny models and a deterministic hashing text encoder
(patched in place of MiniLM, which the training would otherwise load and run on every caption).
The shipped-weights tests load the real package folder ``salad_core/weights/keymotion`` with MiniLM.
"""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors import safe_open

from salad_core.io import load_tensors
from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR, KeyMotionPipeline
from salad_core.keymotion.train import STAGES, KeyMotionRecipe, KeyMotionTrainConfig, load_keymotion_recipe
from salad_core.skeleton import get_skeleton
from salad_core.cli.train import TRAIN_TARGETS, build_parser
from salad_core.cli.train import main as train_main
from _doubles import HashTextEncoder

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = ROOT / "configs" / "keymotion-0.2.json"    # the shipped KeyMotion's recipe
D = get_skeleton("humanml3d").feature_dim
TEXT_DIM = 16
SIZE_CAP = 10 * 1024 * 1024


pytestmark = pytest.mark.usefixtures("single_thread")


TINY_DOC = {
    "text_encoder": "minilm",
    "train": {"batch_size": 8, "lr": 1e-3, "warmup_steps": 1, "val_every": 2, "val_batches": 1, "ckpt_every": 1,
              "log_every": 1, "seed": 7, "num_threads": 1, "device": "cpu", "max_length": 96},
    "kf_vae": {"model": {"num_keyframes": 8, "max_length": 96, "frame_dim": 56, "index_dim": 8, "latent_size": 2,
                         "latent_dim": 16, "num_layers": 1, "num_heads": 4, "ff_dim": 64, "dropout": 0.0},
               "train": {"max_steps": 3}},
    "pst": {"model": {"text_dim": TEXT_DIM, "width": 32, "num_heads": 4, "ff_dim": 64, "num_cond_layers": 1,
                      "num_cross_layers": 2, "dropout": 0.0, "max_length": 96},
            "train": {"max_steps": 3, "lr": 2e-3}},
    "mmae": {"model": {"text_dim": TEXT_DIM, "max_length": 96, "width": 32, "num_layers": 1, "num_heads": 4,
                       "ff_dim": 64, "dropout": 0.0},
             "train": {"max_steps": 3, "keyframe_noise": 0.05}},
}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    """The tiny procedural corpus (HumanML3D layout), built once."""
    from salad_core.data.procedural import build_corpus

    root = tmp_path_factory.mktemp("procedural_tiny")
    build_corpus(root, size="tiny", seed=0, progress=False)
    return root


@pytest.fixture()
def hash_encoder(monkeypatch) -> HashTextEncoder:
    """``load_text_encoder`` returns the hashing encoder (the trainers import it at call time)."""
    enc = HashTextEncoder()
    monkeypatch.setattr("salad_core.text.load_text_encoder", lambda name, device="cpu": enc)
    return enc


def _config_file(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "km.json"
    path.write_text(json.dumps(doc))
    return path


def _weights(path: Path) -> dict[str, torch.Tensor]:
    return load_tensors(path)


# ----------------------------------------------------------------------------- parsing
def test_parser_targets_and_keymotion_options():
    parser = build_parser()
    what = next(a for a in parser._actions if a.dest == "what")
    assert tuple(what.choices) == TRAIN_TARGETS and "keymotion" in TRAIN_TARGETS
    args = parser.parse_args(["keymotion", "--data", "d", "--out", "o", "--steps-per-stage", "10", "20", "30",
                              "--resume"])
    assert args.what == "keymotion" and args.steps_per_stage == [10, 20, 30] and args.resume
    with pytest.raises(SystemExit):
        parser.parse_args(["keymotion", "--data", "d", "--out", "o", "--steps-per-stage", "10", "20"])
    with pytest.raises(SystemExit):
        parser.parse_args(["gan", "--data", "d", "--out", "o"])


@pytest.mark.parametrize("argv, message", [
    (["vae", "--steps-per-stage", "1", "2", "3"], "for keymotion only"),
    (["keymotion", "--steps", "5", "--steps-per-stage", "1", "2", "3"], "not both"),
    (["keymotion", "--steps-per-stage", "1", "-2", "3"], "must be integers >= 0"),
    (["keymotion", "--vae", "runs/vae"], "denoiser only"),
])
def test_cli_rejects_bad_combinations(argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        train_main([*argv[:1], "--data", str(tmp_path), "--out", str(tmp_path / "o"), *argv[1:]])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_default_config_file_parses_into_three_stages():
    recipe = load_keymotion_recipe(DEFAULT_CONFIG)
    doc = json.loads(DEFAULT_CONFIG.read_text())
    assert recipe.text_encoder == "minilm"
    for stage in STAGES:
        train = getattr(recipe, f"{stage}_train")
        assert isinstance(train, KeyMotionTrainConfig)
        assert train.max_steps == doc[stage]["train"]["max_steps"]        # stage field
        assert train.num_threads == doc["train"]["num_threads"] and train.seed == doc["train"]["seed"]  # shared
        model = getattr(recipe, f"{stage}_model")
        assert {k: getattr(model, k) for k in doc[stage]["model"]} == doc[stage]["model"]
    # the PST denoises the VAE's latents, the text stages read MiniLM's 384-d features
    assert (recipe.pst_model.latent_size, recipe.pst_model.latent_dim) == \
        (recipe.kf_vae_model.latent_size, recipe.kf_vae_model.latent_dim)
    assert recipe.pst_model.text_dim == recipe.mmae_model.text_dim == 384
    assert recipe.mmae_train.keyframe_noise == doc["mmae"]["train"]["keyframe_noise"]
    assert recipe.kf_vae_train.keyframe_noise == 0.0
    # the written document reads back to the same recipe
    assert KeyMotionRecipe.from_doc(json.loads(json.dumps(recipe.to_doc()))) == recipe


def test_recipe_overrides_defaults_and_errors():
    doc = {"train": {"batch_size": 16, "max_steps": 50},
           "kf_vae": {"model": {"latent_size": 3, "latent_dim": 8, "num_keyframes": 10}},
           "pst": {"model": {"width": 64}, "train": {"max_steps": 70}}}
    r = KeyMotionRecipe.from_doc(doc, train_overrides={"batch_size": 4, "max_steps": None},
                                 stage_overrides={"mmae": {"max_steps": 9}})
    assert [getattr(r, f"{s}_train").max_steps for s in STAGES] == [50, 70, 9]
    assert {getattr(r, f"{s}_train").batch_size for s in STAGES} == {4}
    assert (r.pst_model.latent_size, r.pst_model.latent_dim, r.pst_model.width) == (3, 8, 64)  # from the VAE
    assert r.mmae_model is None and r.text_encoder == "minilm"
    kw = r.train_kwargs()
    assert kw["vae_config"].num_keyframes == 10 and kw["mmae_train"].max_steps == 9
    with pytest.raises(ValueError, match=r"unknown keys \['vae'\]"):
        KeyMotionRecipe.from_doc({"vae": {}})
    with pytest.raises(ValueError, match=r"section 'pst' .* unknown keys \['diffusion'\]"):
        KeyMotionRecipe.from_doc({"pst": {"diffusion": {}}})
    with pytest.raises(ValueError, match="batch_size"):
        KeyMotionRecipe.from_doc({"train": {"batch_size": 0}})
    with pytest.raises(ValueError, match=r"unknown stages \['denoiser'\]"):
        KeyMotionRecipe.from_doc({}, stage_overrides={"denoiser": {"max_steps": 1}})


# ------------------------------------------------------------------------------- training
def test_cli_trains_three_stages_then_resumes_exactly(tmp_path, corpus, hash_encoder, capsys):
    cfg = _config_file(tmp_path, TINY_DOC)
    base = ["keymotion", "--data", str(corpus), "--config", str(cfg), "--no-progress"]
    # one run straight through: 3 steps per stage
    full = tmp_path / "full"
    assert train_main([*base, "--out", str(full)]) == 0
    printed = capsys.readouterr().out
    assert all(f"keymotion {s}: step 3" in printed for s in STAGES)
    for stage in STAGES:
        lines = [json.loads(l) for l in (full / stage / "log.jsonl").read_text().splitlines()]
        assert [l["step"] for l in lines if "loss" in l] == [1, 2, 3]
        assert all(np.isfinite(l["loss"]) for l in lines if "loss" in l)
    written = json.loads((full / "config.json").read_text())
    assert written["pst"]["train"]["lr"] == 2e-3 and written["mmae"]["model"]["width"] == 32
    assert json.loads((full / "keymotion.json").read_text())["format"] == "keymotion_pipeline"

    # the same run stopped inside the PST (step 1) and before the MMAE, then resumed from config.json
    part = tmp_path / "part"
    assert train_main([*base, "--out", str(part), "--steps-per-stage", "3", "1", "0"]) == 0
    assert json.loads((part / "config.json").read_text())["pst"]["train"]["max_steps"] == 1
    capsys.readouterr()
    assert train_main(["keymotion", "--data", str(corpus), "--out", str(part), "--resume", "--no-progress",
                       "--steps-per-stage", "3", "3", "3"]) == 0
    printed = capsys.readouterr().out
    assert all(f"keymotion {s}: step 3" in printed for s in STAGES)
    for stage in STAGES:
        a, b = _weights(full / stage / "latest.safetensors"), _weights(part / stage / "latest.safetensors")
        assert a.keys() == b.keys()
        assert all(torch.equal(a[k], b[k]) for k in a), f"{stage}: resumed weights differ from the straight run"

    # the trained folder loads and generates motions of the asked lengths
    pipe = KeyMotionPipeline.from_pretrained(part, text_encoder=hash_encoder)
    assert pipe.num_keyframes == 8 and pipe.mmae.config.width == 32
    assert pipe.default_length == 96                                  # capped by the trained max_length
    out = pipe(["a person walks", "a person jumps"], lengths=[40, 64], num_steps=3, guidance_scale=2.0)
    assert out.features.shape == (2, 64, D) and np.isfinite(out.features).all()
    assert not out.features[0, 40:].any()

    # a second fresh run into a used folder is refused, and its recorded recipe is left alone
    before = (full / "config.json").read_bytes()
    with pytest.raises(SystemExit, match="already holds a KeyMotion training run"):
        train_main([*base, "--out", str(full), "--steps", "9"])
    assert (full / "config.json").read_bytes() == before


# -------------------------------------------------------------------------- shipped weights
@pytest.fixture(scope="module")
def shipped() -> KeyMotionPipeline:
    return KeyMotionPipeline.from_pretrained()


def test_shipped_folder_is_safetensors_json_md_under_the_size_cap():
    files = sorted(p for p in DEFAULT_WEIGHTS_DIR.iterdir() if p.is_file())
    names = {p.name for p in files}
    assert {"keymotion.json", "MODEL_CARD.md"} | {f"{s}.{e}" for s in STAGES for e in ("json", "safetensors")} <= names
    assert {p.suffix for p in files} <= {".safetensors", ".json", ".md"}
    tensors = [p for p in files if p.suffix == ".safetensors"]
    assert sum(p.stat().st_size for p in tensors) < SIZE_CAP
    for p in tensors:
        with safe_open(str(p), "pt") as fh:                            # real safetensors, stored in fp16
            dtypes = {fh.get_slice(k).get_dtype() for k in fh.keys()}
        assert dtypes <= {"F16", "I64", "BOOL"} and "F16" in dtypes, (p.name, dtypes)
    # the package data globs of pyproject.toml pick up every shipped file
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["salad_core"]
    packaged = {q for g in globs for q in (ROOT / "salad_core").glob(g)}
    assert set(files) <= packaged


def test_shipped_pipeline_loads_in_float32_and_generates_deterministically(shipped):
    assert shipped.text_encoder_name == "minilm" and shipped.text_encoder.dim == 384
    for model in (shipped.kf_vae, shipped.pst, shipped.mmae):
        assert {p.dtype for p in model.parameters()} == {torch.float32}   # fp16 storage cast back
    prompts = ["a person walks forward", "a man waves his left hand"]
    a = shipped(prompts, lengths=[60, 100], seed=3, num_steps=10)
    assert a.features.shape == (2, 100, D) and a.lengths == [60, 100]
    assert np.isfinite(a.features).all() and not a.features[0, 60:].any()
    assert [j.shape for j in a.joints] == [(60, 22, 3), (100, 22, 3)]
    assert all(np.isfinite(j).all() for j in a.joints)
    assert all(k[0] == 0 and k[-1] == n - 1 and (np.diff(k) > 0).all() for k, n in zip(a.keyframes, a.lengths))
    b = shipped(prompts, lengths=[60, 100], seed=3, num_steps=10)
    np.testing.assert_array_equal(a.features, b.features)
    c = shipped(prompts, lengths=[60, 100], seed=4, num_steps=10)
    assert not np.allclose(a.features, c.features)


# ----------------------------------------------------------------------------- throughput (issue 19)
@pytest.fixture(scope="module")
def fake_corpus(tmp_path_factory) -> Path:
    from _doubles import make_fake_corpus

    return make_fake_corpus(tmp_path_factory.mktemp("fake_km"), n_train=6, n_val=2, lengths=(44, 90))


def _keyframe_sets(root: Path, k: int = 8):
    from salad_core.data.dataset import MotionTextDataset
    from salad_core.keymotion.train import KeyframeDataset

    train = MotionTextDataset(root, "train", max_length=96, random_crop=True, seed=0)
    val = MotionTextDataset(root, "val", max_length=96, mean=train.mean, std=train.std, random_crop=False)
    return KeyframeDataset(train, k, "uniform"), KeyframeDataset(val, k, "uniform")


def test_pst_latent_cache_equals_encoding_the_keyframes(fake_corpus, tmp_path):
    """Cached keyframe-VAE posteriors give the PST's on-the-fly inputs; a weight change rebuilds the cache."""
    from salad_core.data.dataset import collate_motion_text  # noqa: F401  (collate_keyframes uses it)
    from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig
    from salad_core.keymotion.pst import PST_DIFFUSION
    from salad_core.keymotion.train import collate_keyframes, kf_vae_latent_cache, prepare_pst_batch
    from salad_core.sampling import make_scheduler
    from salad_core.train.common import StepContext
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    train, val = _keyframe_sets(fake_corpus)
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, max_length=96, frame_dim=32, latent_dim=16, num_layers=1,
                                        ff_dim=64, dropout=0.1)).eval()
    vae.set_normalization(train.mean, train.std)
    env = DistEnv()
    cache = kf_vae_latent_cache(vae, [train, val], tmp_path, env)
    assert len(cache) == len(train.base.crops()) + len(val.base.crops())
    items = [train[i] for i in range(4)]
    batch = collate_keyframes(items)

    class Text:
        def encode(self, captions):
            return torch.ones(len(captions), 3, TEXT_DIM), torch.ones(len(captions), 3, dtype=torch.bool)

    cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False)
    kw = dict(vae=vae, text=Text(), scheduler=make_scheduler(PST_DIFFUSION, "ddim"), config=cfg,
              latent_shape=vae.latent_shape)
    out = {}
    for name, latents in (("fly", None), ("cache", cache)):
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(2), env), env, train=True, step=0)
        out[name] = prepare_pst_batch(batch, ctx, latents=latents, **kw)
    torch.testing.assert_close(out["cache"]["noisy"], out["fly"]["noisy"], rtol=1e-5, atol=1e-6)
    assert torch.equal(out["cache"]["target"], out["fly"]["target"])
    assert kf_vae_latent_cache(vae, [train, val], tmp_path, env).folder == cache.folder      # reused
    with torch.no_grad():
        next(vae.parameters()).view(-1)[0] += 1e-3
    assert kf_vae_latent_cache(vae, [train, val], tmp_path, env).folder != cache.folder   # rebuilt


def test_mmae_buckets_weigh_every_frame_alike(fake_corpus, hash_encoder):
    """The MMAE task declares item lengths (bucketing); in training its losses are scaled by
    valid frames / (batch x expected frames); validation keeps the per-batch means."""
    from salad_core.keymotion.mmae import MMAEConfig
    from salad_core.keymotion.train import build_mmae_task
    from salad_core.train.batching import expected_latent_frames
    from salad_core.train.common import StepContext
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    env = DistEnv()
    cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, batch_size=4)
    task = build_mmae_task(fake_corpus, MMAEConfig(text_dim=hash_encoder.dim, max_length=96, width=32, num_layers=1,
                                                   num_heads=4, ff_dim=64, dropout=0.0), cfg, env, "minilm", 8)
    assert np.array_equal(task.lengths, task.train_set.lengths)
    batch = task.collate([task.train_set[i] for i in range(4)])
    norm = 4 * expected_latent_frames(task.lengths, 4)
    losses = {}
    for train in (True, False):
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(1), env), env, train=train, step=0)
        inputs = task.prepare(batch, ctx)
        assert ("frame_weight" in inputs) == train
        if train:
            assert float(inputs["frame_weight"]) == pytest.approx(float(batch["length"].sum()) / (4 * norm), rel=1e-6)
        with torch.no_grad():
            losses[train] = task.objective(**inputs)
    for k in ("loss", "rec", "vel"):
        assert float(losses[True][k]) == pytest.approx(float(losses[False][k]) * float(batch["length"].sum()) / (4 * norm),
                                                       rel=1e-5)
    random_cfg = cfg.replace(batching="random")
    plain = build_mmae_task(fake_corpus, task.model_config, random_cfg, env, "minilm", 8)
    ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(1), env), env, train=True, step=0)
    assert "frame_weight" not in plain.prepare(batch, ctx)


def test_mmae_equal_frame_batches_divide_by_the_nominal_batch(fake_corpus, hash_encoder):
    """With ``batching="frames"`` a batch holds a varying number of items: the frame weight divides by
    the configured batch x expected frames, never by the items this batch happens to have."""
    from salad_core.keymotion.mmae import MMAEConfig
    from salad_core.keymotion.train import build_mmae_task
    from salad_core.train.batching import expected_latent_frames
    from salad_core.train.common import StepContext
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    env = DistEnv()
    cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, batch_size=4, batching="frames")
    task = build_mmae_task(fake_corpus, MMAEConfig(text_dim=hash_encoder.dim, max_length=96, width=32, num_layers=1,
                                                   num_heads=4, ff_dim=64, dropout=0.0), cfg, env, "minilm", 8)
    norm = 4 * expected_latent_frames(task.lengths, 4)
    for n_items in (2, 3, 6):
        batch = task.collate([task.train_set[i % len(task.train_set)] for i in range(n_items)])
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(1), env), env, train=True, step=0)
        weight = float(task.prepare(batch, ctx)["frame_weight"])
        assert weight == pytest.approx(float(batch["length"].sum()) / (4 * norm), rel=1e-6)


# --------------------------------------------------------------------- keyframe ratio (issue 22)
def test_mmae_keyframe_ratio_places_each_items_own_keyframes(fake_corpus, hash_encoder):
    """With ``keyframe_ratio`` an item of L frames gets max(2, round(ratio L)) MDO keyframes; a batch
    pads the shorter lists by repeating the last index, and the MMAE's inputs hold exactly each
    item's keyframes (with one noise value per keyframe), nothing else."""
    from salad_core.keymotion.mmae import MMAEConfig
    from salad_core.keymotion.selection import select_keyframes
    from salad_core.keymotion.train import build_mmae_task
    from salad_core.train.common import StepContext
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    env = DistEnv()
    cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, batch_size=4, keyframe_ratio=0.1,
                               keyframe_noise=0.3)
    model = MMAEConfig(text_dim=hash_encoder.dim, max_length=96, width=32, num_layers=1, num_heads=4, ff_dim=64,
                       dropout=0.0)
    task = build_mmae_task(fake_corpus, model, cfg, env, "minilm", 8)
    items = [task.train_set[i] for i in range(len(task.train_set))]
    lengths = [int(it["length"]) for it in items]
    assert len(set(lengths)) > 1                                           # the fake corpus has 44 and 90 frames
    for it, n in zip(items, lengths):
        k = max(2, round(0.1 * n))
        assert np.array_equal(it["keyframes"], select_keyframes(it["motion"][:n], k, "mdo"))
    batch = task.collate(items[:4])
    counts = batch["keyframe_count"].tolist()
    assert counts == [len(it["keyframes"]) for it in items[:4]] and len(set(counts)) > 1
    assert batch["keyframes"].shape == (4, max(counts))
    ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(3), env), env, train=True, step=0)
    inputs = task.prepare(batch, ctx)
    assert inputs["keyframe_mask"].sum(1).tolist() == counts               # padding adds no keyframe
    for b, it in enumerate(items[:4]):
        frames = torch.nonzero(inputs["keyframe_mask"][b])[:, 0].numpy()
        assert np.array_equal(frames, it["keyframes"])
        noise = inputs["inputs"][b, frames] - inputs["motion"][b, frames]
        assert 0.2 < float(noise.std()) < 0.4                              # keyframe_noise 0.3, one draw per keyframe
        assert float(inputs["inputs"][b][~inputs["keyframe_mask"][b]].abs().max()) == 0.0
    # the keyframe VAE and the PST keep a fixed K
    from salad_core.keymotion.train import build_kf_vae_task

    with pytest.raises(ValueError, match="keyframe_ratio=0.1 is for the MMAE only"):
        build_kf_vae_task(fake_corpus, None, cfg, env)
    with pytest.raises(ValueError, match="keyframe_ratio"):
        KeyMotionTrainConfig(keyframe_ratio=1.5)


def test_fixed_keyframes_collate_unchanged(fake_corpus):
    """Without a ratio every item has K keyframes: no padding, counts all K."""
    from salad_core.keymotion.train import collate_keyframes

    train, _ = _keyframe_sets(fake_corpus, k=8)
    batch = collate_keyframes([train[i] for i in range(3)])
    assert batch["keyframes"].shape == (3, 8) and batch["keyframe_count"].tolist() == [8, 8, 8]
    assert np.array_equal(batch["keyframes"][0].numpy(), train[0]["keyframes"])
