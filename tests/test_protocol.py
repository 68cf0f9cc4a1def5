"""Evaluation protocol: replay/noise generators prove the plumbing; tables, plot, settings, sweeps."""
from __future__ import annotations

import zlib
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from salad_core.data.dataset import load_mean_std
from salad_core.eval.batches import real_batches
from salad_core.eval.metrics import mean_ci
from salad_core.eval.paper_tables import paper_cfg_sweep
from salad_core.eval.protocol import cfg_sweep, evaluate_generator, evaluate_real, run_ablation
from salad_core.eval.settings import METRICS, REAL_NAME, EvalResult, EvalSettings
from salad_core.eval.tables import format_mean_ci, results_frame, to_latex, to_markdown
from salad_core.skeleton import get_skeleton


SK = get_skeleton("humanml3d")
SETTINGS = EvalSettings(replications=2, mm=False, seed=3)


pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def corpus(tiny_procedural_corpus):
    return tiny_procedural_corpus


@pytest.fixture(scope="module")
def evaluator(tiny_random_evaluator):
    return tiny_random_evaluator


class Replay:
    """Returns the real motions of the protocol's own batches (features padded to 196 frames)."""

    source = "replay"

    def __init__(self, root, settings: EvalSettings) -> None:
        self.queue = [b for r in range(settings.replications) for b in real_batches(root, settings, r)]
        self.calls: list[dict] = []

    def __call__(self, prompts, lengths=None, seed=0, guidance_scale=7.5, num_steps=50):
        b = self.queue.pop(0)
        assert list(prompts) == b.captions and list(lengths) == b.lengths.tolist()
        self.calls.append(dict(seed=seed, guidance_scale=guidance_scale, num_steps=num_steps))
        feats = np.full((len(prompts), SK.max_length, SK.feature_dim), 0.0, np.float32)
        feats[:, : b.motions.shape[1]] = b.motions
        return SimpleNamespace(features=feats, lengths=list(lengths))


class Noise:
    """Gaussian features around the corpus mean; ``per_caption`` ignores the seed (deterministic per text)."""

    def __init__(self, mean, std, scale: float = 1.0, per_caption: bool = False, by_guidance: bool = False):
        self.mean, self.std, self.scale = mean, std, scale
        self.per_caption, self.by_guidance = per_caption, by_guidance
        self.calls: list[dict] = []

    def __call__(self, prompts, lengths=None, seed=0, guidance_scale=7.5, num_steps=50):
        self.calls.append(dict(seed=seed, guidance_scale=guidance_scale, num_steps=num_steps, n=len(prompts)))
        n = max(lengths)
        out = np.zeros((len(prompts), n, SK.feature_dim), np.float32)
        scale = self.scale * (guidance_scale if self.by_guidance else 1.0)
        for i, (p, length) in enumerate(zip(prompts, lengths)):
            s = zlib.crc32(p.encode()) if self.per_caption else seed + i
            z = np.random.default_rng(s).standard_normal((length, SK.feature_dim))
            out[i, :length] = self.mean + scale * self.std * z
        return SimpleNamespace(features=out, lengths=list(lengths))


@pytest.fixture(scope="module")
def real(corpus, evaluator):
    return evaluate_real(corpus, evaluator, SETTINGS)


@pytest.fixture(scope="module")
def replay(corpus, evaluator):
    gen = Replay(corpus, SETTINGS)
    res = evaluate_generator(gen, corpus, evaluator, SETTINGS, name="replay")
    return gen, res


@pytest.fixture(scope="module")
def noise(corpus, evaluator):
    mean, std = load_mean_std(corpus)
    return evaluate_generator(Noise(mean, std, scale=2.0), corpus, evaluator, SETTINGS, name="noise")


# ------------------------------------------------------------------------------ plumbing
def test_real_batches_are_reproducible_and_protocol_shaped(corpus):
    a = real_batches(corpus, SETTINGS, 0)
    b = real_batches(corpus, SETTINGS, 0)
    c = real_batches(corpus, SETTINGS, 1)
    # tiny test split: 60 clips -> one full batch of 32 (drop_last)
    assert len(a) == 1 and len(a[0].captions) == 32
    assert a[0].captions == b[0].captions and np.array_equal(a[0].motions, b[0].motions)
    assert a[0].names != c[0].names or not np.array_equal(a[0].lengths, c[0].lengths)
    ln = a[0].lengths
    assert (ln % SK.unit_length == 0).all() and ln.min() >= SK.min_length - SK.unit_length
    assert a[0].motions.shape == (32, ln.max(), SK.feature_dim)
    for i, n in enumerate(ln):
        assert not a[0].motions[i, n:].any() and a[0].motions[i, n - 1].any()


def test_replay_generator_scores_like_the_real_row(real, replay):
    gen, res = replay
    assert res.values.keys() == set(METRICS) - {"MultiModality"}
    for m in ("R-precision top-1", "R-precision top-2", "R-precision top-3", "MM-Dist", "Diversity"):
        assert res.values[m] == real.values[m], m
    assert max(res.values["FID"]) < 1e-5            # identical embeddings (FID against the same batches)
    assert min(real.values["FID"]) > 1e-3           # the real row compares against other crops/captions
    # what the generator was asked for
    assert [c["guidance_scale"] for c in gen.calls] == [7.5, 7.5] and {c["num_steps"] for c in gen.calls} == {50}
    assert len({c["seed"] for c in gen.calls}) == 2 and not gen.queue


def test_noise_generator_has_a_large_fid(real, noise):
    # even an untrained evaluator separates i.i.d. noise from motion (measured: ~3.5 vs ~0.4)
    assert min(noise.values["FID"]) > 5 * max(real.values["FID"])
    assert all(0.0 <= v <= 1.0 for m in METRICS[:3] for v in noise.values[m])


def test_multimodality_zero_for_seed_independent_generator(corpus, evaluator):
    mean, std = load_mean_std(corpus)
    s = SETTINGS.replace(replications=1, mm=True, mm_prompts=8, mm_repeats=4, mm_pairs=2)
    fixed = Noise(mean, std, per_caption=True)
    seeded = Noise(mean, std)
    r_fixed = evaluate_generator(fixed, corpus, evaluator, s)
    r_seeded = evaluate_generator(seeded, corpus, evaluator, s)
    assert r_fixed.values["MultiModality"] == (0.0,)
    assert r_seeded.values["MultiModality"][0] > 0.1
    # one main batch + 4 repeats of the 8 MultiModality prompts
    assert [c["n"] for c in seeded.calls] == [32, 8, 8, 8, 8]
    assert len({c["seed"] for c in seeded.calls}) == 5


def test_generator_output_is_checked(corpus, evaluator):
    class WrongLengths(Noise):
        def __call__(self, prompts, lengths=None, **kw):
            out = super().__call__(prompts, lengths=lengths, **kw)
            out.lengths = [n - 4 for n in out.lengths]
            return out

    mean, std = load_mean_std(corpus)
    with pytest.raises(ValueError, match="lengths"):
        evaluate_generator(WrongLengths(mean, std), corpus, evaluator, SETTINGS.replace(replications=1))
    with pytest.raises(TypeError, match="features"):
        evaluate_generator(lambda p, **kw: object(), corpus, evaluator, SETTINGS.replace(replications=1))


# ------------------------------------------------------------------------------ settings
def test_settings_validation_and_quick_mode():
    with pytest.raises(ValueError, match="batch_size"):
        EvalSettings(batch_size=1)
    with pytest.raises(ValueError, match="mm_repeats"):
        EvalSettings(mm_repeats=10, mm_pairs=10)
    with pytest.raises(ValueError, match="max_samples"):
        EvalSettings(max_samples=16)
    q = EvalSettings.quick_mode()
    assert (q.replications, q.max_samples, q.mm, q.quick) == (2, 64, False, True)
    assert "QUICK MODE" in q.describe() and "QUICK" not in EvalSettings().describe()
    full = EvalSettings()
    assert (full.replications, full.batch_size, full.mm, full.mm_prompts, full.mm_repeats) == (20, 32, True, 100, 30)


def test_settings_recorded_in_every_result(real, replay, noise):
    for res in (real, replay[1], noise):
        s = res.settings
        for key in ("split", "batch_size", "replications", "mm", "num_steps", "guidance_scale", "seed", "weights",
                    "evaluator", "data", "quick", "samples", "max_samples"):
            assert key in s, (res.name, key)
        assert (s["split"], s["batch_size"], s["replications"], s["seed"], s["samples"]) == ("test", 32, 2, 3, 32)
        assert s["evaluator"] == "tiny-random-evaluator"
    assert replay[1].settings["weights"] == "replay" and noise.settings["weights"] == "Noise"
    assert replay[1].settings["guidance_scale"] == 7.5 and replay[1].settings["num_steps"] == 50
    assert real.settings["kind"] == "real" and real.settings["guidance_scale"] is None


def test_max_samples_caps_batches(corpus, evaluator):
    s = EvalSettings.quick_mode(max_samples=32, replications=1)
    res = evaluate_real(corpus, evaluator, s)
    assert res.settings["samples"] == 32 and res.settings["quick"] is True
    assert all(len(v) == 1 for v in res.values.values())


def test_capped_real_row_is_referenced_against_the_same_items(corpus, evaluator, monkeypatch):
    """With --max-samples below the split size, the real row's FID reference must be another pass
    (other crops/captions) over the SAME clips, as the generator rows compare with their own clips;
    a reference of other clips would inflate the real row's FID by small-sample bias alone."""
    import salad_core.eval.protocol as protocol

    seen = []
    original = protocol.batches_for

    def spy(dataset, settings, epoch, order_tag):
        out = original(dataset, settings, epoch, order_tag)
        seen.append((epoch, sorted(n for b in out for n in b.names)))
        return out

    monkeypatch.setattr(protocol, "batches_for", spy)
    evaluate_real(corpus, evaluator, EvalSettings.quick_mode(max_samples=32, replications=1))
    (epoch_a, names_a), (epoch_b, names_b) = seen
    assert epoch_a != epoch_b                      # independent crops and captions
    assert names_a == names_b and len(names_a) == 32


# ------------------------------------------------------------------------------ tables
def test_mean_ci_and_formatting():
    res = EvalResult("x", {"FID": (1.0, 2.0, 3.0)})
    mean, half = res.summary()["FID"]
    assert mean == 2.0 and half == pytest.approx(1.96 * np.std([1, 2, 3]) / np.sqrt(3))
    assert (mean, half) == tuple(float(v) for v in mean_ci([1.0, 2.0, 3.0]))
    assert format_mean_ci(0.5114, 0.0031) == "0.511 ± 0.003"
    assert format_mean_ci(0.5114, 0.0031, digits=2, latex=True) == "$0.51^{\\pm 0.00}$"
    assert format_mean_ci(float("nan"), 0.1) == "-"


def test_results_frame_columns(real, replay, noise):
    df = results_frame([real, replay[1], noise])
    metric_cols = [c for m in METRICS for c in (m, m + " ±")]
    assert list(df.columns[: 1 + len(metric_cols)]) == ["name", *metric_cols]
    assert list(df["name"]) == [REAL_NAME, "replay", "noise"]
    assert df["MultiModality"].isna().all()
    s = real.summary()
    assert df.loc[0, "FID"] == s["FID"][0] and df.loc[0, "FID ±"] == s["FID"][1]
    assert list(df["kind"]) == ["real", "generator", "generator"]
    assert df.loc[1, "guidance_scale"] == 7.5 and pd.isna(df.loc[0, "guidance_scale"])


def test_markdown_and_latex_exports(real, noise):
    df = results_frame([real, noise])
    md = to_markdown(df)
    lines = md.splitlines()
    header = next(line for line in lines if line.startswith("| Method"))
    assert "R-precision top-1 ↑" in header and "FID ↓" in header and "MultiModality" not in header
    row = next(line for line in lines if line.startswith("| noise"))
    assert format_mean_ci(df.loc[1, "FID"], df.loc[1, "FID ±"]) in row
    # 2 replications without MultiModality: said to be a reduced protocol, never "full"
    assert "Reduced T2M protocol (2 replications instead of 20, no MultiModality)" in md
    assert "Full T2M protocol" not in md and "replications 2" in md and "w 7.5" in md
    tex = to_latex(df)
    assert tex.startswith("% Reduced T2M protocol") and "\\begin{tabular}{lcccccc}" in tex
    full = df.assign(replications=20, max_samples=None, mm=True)
    assert to_markdown(full).startswith("**Full T2M protocol;")
    capped = df.assign(replications=20, max_samples=192, mm=True)
    assert "at most 192 samples per replication instead of the whole split" in to_markdown(capped)
    assert "reduced protocol" in SETTINGS.describe() and EvalSettings().describe().startswith("full protocol")
    assert EvalSettings().protocol_deviations() == []
    assert format_mean_ci(df.loc[0, "MM-Dist"], df.loc[0, "MM-Dist ±"], latex=True) in tex
    assert "$\\downarrow$" in tex and tex.rstrip().endswith("\\end{tabular}")
    # quick mode is stated loudly; names are escaped
    quick = df.assign(quick=True, name=["Real motion", "SALAD_no_skel"])
    assert to_markdown(quick).startswith("**QUICK MODE")
    assert "SALAD\\_no\\_skel" in to_latex(quick)


def test_paper_numbers_only_when_labelled(real, noise):
    paper = paper_cfg_sweep("humanml3d")
    assert len(paper) == 13 and all(n.startswith("paper: ") for n in paper["name"])
    row = paper[paper["name"] == "paper: SALAD w=7.5"].iloc[0]
    assert (row["R-precision top-3"], row["FID"]) == (0.857, 0.076)
    df = results_frame([real, noise])
    md = to_markdown(df, reference=paper)
    assert "copied from the paper" in md and "| paper: SALAD w=7.5" in md
    assert "Published (copied from the paper)" in to_latex(df, reference=paper)
    with pytest.raises(ValueError, match="labelled"):
        to_markdown(df, reference=df)


# ------------------------------------------------------------------------------ sweep / ablation
def test_cfg_sweep_and_plot(corpus, evaluator):
    mean, std = load_mean_std(corpus)
    gen = Noise(mean, std, scale=0.5, by_guidance=True)
    s = SETTINGS.replace(replications=1)
    results = cfg_sweep(gen, corpus, evaluator, s, scales=[2.0, 5.0], name="Fake")
    assert [r.name for r in results] == [REAL_NAME, "Fake w=2", "Fake w=5"]
    assert [c["guidance_scale"] for c in gen.calls] == [2.0, 5.0]
    assert [r.settings["guidance_scale"] for r in results[1:]] == [2.0, 5.0]
    assert results[2].values["FID"][0] > results[1].values["FID"][0]    # more noise, larger FID
    df = results_frame(results)
    assert to_markdown(df).splitlines()[2].startswith("| Method      | w ")  # the varying setting is a column
    from salad_viz.plots import plot_cfg_sweep

    fig = plot_cfg_sweep(df)
    assert len(fig.axes) == 2
    for ax, metric in zip(fig.axes, ("FID", "R-precision top-3")):
        xy = ax.containers[0].lines[0].get_xydata()
        assert np.allclose(xy[:, 0], [2.0, 5.0]) and np.allclose(xy[:, 1], df[metric].to_numpy()[1:])
        real_line = next(line for line in ax.lines if line.get_label() == REAL_NAME)
        assert np.allclose(real_line.get_ydata(), df.loc[0, metric])
        assert ax.get_xlabel() == "CFG weight w" and ax.get_ylabel() == metric


def test_run_ablation(corpus, evaluator):
    mean, std = load_mean_std(corpus)
    s = SETTINGS.replace(replications=1)
    res = run_ablation({"a": Noise(mean, std, 0.5), "b": Noise(mean, std, 3.0)}, corpus, evaluator, s)
    assert [r.name for r in res] == [REAL_NAME, "a", "b"]
    assert res[2].values["FID"][0] > res[1].values["FID"][0]
    with pytest.raises(ValueError, match="generators"):
        run_ablation({}, corpus, evaluator, s)


# ------------------------------------------------------------------------------ module layout
def test_protocol_holds_only_the_protocol():
    """Tables, published numbers, settings and the plot live in the modules of their jobs only (no
    re-exports left in the protocol); the package keeps its public API. The plot is salad_viz's alone
    (salad_core.eval keeps no alias of it: only the command line imports salad_viz)."""
    import salad_core.eval as ev
    import salad_core.eval.protocol as protocol
    import salad_viz
    from salad_viz import plots

    for name in protocol.__all__:
        assert getattr(protocol, name).__module__ == protocol.__name__, name
    for name in ("results_frame", "to_markdown", "paper_cfg_sweep", "CI_SUFFIX", "plot_cfg_sweep", "real_batches"):
        assert not hasattr(protocol, name), name
    assert plots.plot_cfg_sweep is salad_viz.plot_cfg_sweep and not hasattr(ev, "plot_cfg_sweep")
    assert ev.results_frame is results_frame and ev.EvalSettings is EvalSettings and ev.cfg_sweep is cfg_sweep
    for name in ev.__all__:
        assert getattr(ev, name) is not None, name
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        ev.nope


def test_plot_takes_a_plain_table(real, noise, tmp_path):
    """salad_viz.plots needs only the table's columns: a results frame written to CSV and read back
    (no salad_core objects) draws the same points; a missing column is named."""
    from salad_viz.plots import plot_cfg_sweep

    a = EvalResult("Fake w=2", {"FID": (1.0, 3.0), "R-precision top-3": (0.5, 0.7)},
                   {"kind": "generator", "guidance_scale": 2.0, "quick": True})
    b = EvalResult("Fake w=5", {"FID": (4.0, 6.0), "R-precision top-3": (0.6, 0.6)},
                   {"kind": "generator", "guidance_scale": 5.0, "quick": True})
    results_frame([real, b, a]).to_csv(tmp_path / "r.csv", index=False)
    df = pd.read_csv(tmp_path / "r.csv")
    fig = plot_cfg_sweep(df)
    fid, top3 = fig.axes
    xy = fid.containers[0].lines[0].get_xydata()
    assert xy.tolist() == [[2.0, 2.0], [5.0, 5.0]]                     # sorted by w; means of the replications
    assert top3.containers[0].lines[0].get_xydata()[:, 1] == pytest.approx([0.6, 0.6])
    assert "QUICK MODE" in fig.get_suptitle()
    with pytest.raises(ValueError, match=r"lacks the columns \['FID ±'\]"):
        plot_cfg_sweep(df.drop(columns=["FID ±"]))
    with pytest.raises(ValueError, match="r_precision='MM-Dist'"):
        plot_cfg_sweep(df, r_precision="MM-Dist")
    with pytest.raises(ValueError, match="no generator rows"):
        plot_cfg_sweep(df[df["kind"] == "real"])
