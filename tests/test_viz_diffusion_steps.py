"""salad_viz.diffusion_steps: per-step word shares of cross-attention, their plot, denoising strips."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from salad_core.skeleton import PART_NAMES
from salad_viz.diffusion_steps import SPECIAL_LABEL, denoising_strips, plot_word_share_by_step, word_share_by_step
from salad_viz.render import keyframe_strip
from salad_viz.synthetic import synthetic_motion

TOKENS = ["[CLS]", "a", "man", "jump", "##s", ",", "a", "man", "walks", "[SEP]"]
P = len(PART_NAMES)


def _steps_attention(n_steps=6, layers=2, heads=3, n_lat=5, seed=0) -> np.ndarray:
    """(S, L, H, N', P, W) softmax maps in which 'jump ##s' takes over from [CLS] as the steps go."""
    rng = np.random.default_rng(seed)
    logits = rng.normal(0, 0.3, (n_steps, layers, heads, n_lat, P, len(TOKENS)))
    ramp = np.linspace(0.0, 4.0, n_steps)[:, None, None, None, None]
    logits[..., 3] += ramp
    logits[..., 4] += ramp
    logits[..., 0] += 4.0 - ramp
    att = np.exp(logits)
    return att / att.sum(axis=-1, keepdims=True)


def test_word_shares_merge_pieces_label_repeats_and_sum_to_one():
    att = _steps_attention()
    shares, labels = word_share_by_step(att, TOKENS)
    assert labels == ["a", "man", "jumps", "a (2)", "man (2)", "walks", SPECIAL_LABEL]   # "," is no word
    assert shares.shape == (6, len(labels))
    np.testing.assert_allclose(shares.sum(axis=1), 1.0, atol=1e-12)
    # by hand: the mean over layers, heads, frames and parts of the two 'jump' pieces at each step
    by_hand = att[..., 3:5].sum(-1).mean(axis=(1, 2, 3, 4))
    np.testing.assert_allclose(shares[:, labels.index("jumps")], by_hand, rtol=1e-12)
    special = att[..., [0, 5, 9]].sum(-1).mean(axis=(1, 2, 3, 4))
    np.testing.assert_allclose(shares[:, -1], special, rtol=1e-12)
    # the built-in ramp: 'jumps' rises and the special tokens fall over the steps
    assert np.all(np.diff(shares[:, labels.index("jumps")]) > 0)
    assert np.all(np.diff(shares[:, -1]) < 0)


def test_word_shares_without_special_and_with_a_batch_axis():
    att = _steps_attention(seed=1)
    shares, labels = word_share_by_step(att, TOKENS, special=False)
    assert SPECIAL_LABEL not in labels and shares.shape == (6, 6)
    assert np.all(shares.sum(axis=1) < 1.0)
    batched = np.stack([_steps_attention(seed=2), att])              # (B, S, L, H, N', P, W)
    again, _ = word_share_by_step(batched, TOKENS, axes="bslhnpw", batch=1, special=False)
    np.testing.assert_allclose(again, shares, rtol=1e-12)


def test_word_shares_refuse_bad_layouts():
    att = _steps_attention()
    with pytest.raises(ValueError, match="step axis 's'"):
        word_share_by_step(att.mean(axis=0), TOKENS, axes="lhnpw")
    with pytest.raises(ValueError, match="names 5 axes but attention has 6"):
        word_share_by_step(att, TOKENS, axes="slnpw")
    with pytest.raises(ValueError, match="tokens has 9 entries but attention has W = 10"):
        word_share_by_step(att, TOKENS[:-1])
    with pytest.raises(ValueError, match="contain no word"):
        word_share_by_step(att[..., :1], ["[CLS]"])


def test_plot_draws_one_line_per_label_with_the_shares():
    att = _steps_attention()
    shares, labels = word_share_by_step(att, TOKENS)
    fig = plot_word_share_by_step(att, TOKENS, title="jumps over the steps")
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.lines] == labels
    np.testing.assert_allclose(ax.lines[2].get_xdata(), np.arange(1, 7))
    np.testing.assert_allclose(ax.lines[2].get_ydata(), shares[:, 2])
    assert ax.lines[-1].get_linestyle() == "--"
    only = plot_word_share_by_step(att, TOKENS, words=["jumps", "walks"])
    assert [line.get_label() for line in only.axes[0].lines] == ["jumps", "walks", SPECIAL_LABEL]
    with pytest.raises(ValueError, match="'runs'"):
        plot_word_share_by_step(att, TOKENS, words=["runs"])


def test_denoising_strips_stack_one_strip_per_step_in_step_order():
    walk = synthetic_motion(n_frames=24)
    still = np.repeat(walk[:1], 24, axis=0)                          # a motion that does not move
    shots = {7: walk, 0: still}
    img = denoising_strips(shots, num_steps=8, frames=3, size=(64, 80), backend="raster")
    first = keyframe_strip(still, "humanml3d", 3, layout="row", view="side", size=(64, 80), backend="raster",
                           title="after step 1/8")
    last = keyframe_strip(walk, "humanml3d", 3, layout="row", view="side", size=(64, 80), backend="raster",
                          title="after step 8/8")
    assert img.dtype == np.uint8 and img.shape == (first.shape[0] + 4 + last.shape[0], first.shape[1], 3)
    np.testing.assert_array_equal(img[: first.shape[0]], first)       # step 0 on top
    np.testing.assert_array_equal(img[first.shape[0] + 4:], last)
    assert not np.array_equal(first, last)


def test_denoising_strips_refuse_bad_steps():
    walk = synthetic_motion(n_frames=12)
    with pytest.raises(ValueError, match="non-empty mapping"):
        denoising_strips({})
    with pytest.raises(ValueError, match=r"step 8 .*\[0, 8\)"):
        denoising_strips({8: walk}, num_steps=8, backend="raster")
    with pytest.raises(ValueError, match="num_steps must be a positive int"):
        denoising_strips({0: walk}, num_steps=0, backend="raster")
