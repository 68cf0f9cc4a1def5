"""salad_viz.attention: reduction, word selection, heatmap content, grids, comparisons, joint colours."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from salad_core.skeleton import PART_MIRROR, PART_NAMES, get_skeleton
from salad_viz.attention import (
    attention_limits,
    joint_attention,
    joint_attention_colors,
    merge_tokens,
    mirror_attention,
    plot_attention_by_layer,
    plot_attention_by_steps,
    plot_attention_comparison,
    plot_attention_grid,
    plot_attention_rows,
    plot_mirror_comparison,
    plot_word_attention,
    reduce_attention,
    select_words,
    word_token_ids,
)

TOKENS = ["[CLS]", "a", "man", "jumps", "forward", "and", "then", "walks", "forward", ",", "while",
          "waving", "his", "arms", "[SEP]"]
P = len(PART_NAMES)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _attention(n_lat: int = 25, seed: int = 0) -> np.ndarray:
    """(P, N', W) softmax maps with 'jumps' early everywhere, 'walks' late on root and legs."""
    rng = np.random.default_rng(seed)
    logits = rng.normal(0, 0.3, (P, n_lat, len(TOKENS)))
    t = np.arange(n_lat)
    logits[:, :, 3] += 3.0 * np.exp(-((t - 4) / 3.0) ** 2)
    logits[:3, :, 7] += 3.0 * (t > n_lat // 2)
    att = np.exp(logits)
    return att / att.sum(axis=-1, keepdims=True)


def _image_of(fig):
    """The AxesImage arrays of a figure, one per panel that shows a map."""
    return [ax.images[0] for ax in fig.axes if ax.images]


# ----------------------------------------------------------------------------- reduction
def test_reduce_attention_matches_manual_mean_and_selects_steps_layers_heads():
    rng = np.random.default_rng(1)
    arr = rng.random((6, 3, 2, 5, P, 4))  # s l h n p w
    before = arr.copy()
    out = reduce_attention(arr, "slhnpw")
    assert out.shape == (P, 5, 4)
    np.testing.assert_allclose(out, arr.mean(axis=(0, 1, 2)).transpose(1, 0, 2))
    sel = reduce_attention(arr, "slhnpw", steps=(2, 5), layers=[0, 2], heads=1)
    np.testing.assert_allclose(sel, arr[2:5][:, [0, 2]][:, :, [1]].mean(axis=(0, 1, 2)).transpose(1, 0, 2))
    np.testing.assert_array_equal(arr, before)  # input untouched


def test_reduce_attention_batch_axis_and_errors():
    rng = np.random.default_rng(2)
    arr = rng.random((2, 3, 5, P, 4))  # b h n p w
    np.testing.assert_allclose(reduce_attention(arr, "bhnpw", batch=1), arr[1].mean(axis=0).transpose(1, 0, 2))
    with pytest.raises(ValueError, match="batch=<index>"):
        reduce_attention(arr, "bhnpw")
    with pytest.raises(ValueError, match="names 4 axes"):
        reduce_attention(arr, "hnpw")
    with pytest.raises(ValueError, match="must contain 'w'"):
        reduce_attention(arr[..., 0], "bhnp")
    with pytest.raises(ValueError, match="no layer axis"):
        reduce_attention(arr, "bhnpw", batch=0, layers=1)
    with pytest.raises(ValueError, match="out of range"):
        reduce_attention(arr, "bhnpw", batch=0, heads=7)


def test_reduce_attention_accepts_torch_tensors():
    torch = pytest.importorskip("torch")
    arr = torch.rand(2, 5, P, 4)
    out = reduce_attention(arr, "snpw")
    np.testing.assert_allclose(out, arr.numpy().mean(axis=0).transpose(1, 0, 2), rtol=1e-6)


# ----------------------------------------------------------------------------- words
def test_merge_tokens_wordpiece_and_clip_pieces():
    assert merge_tokens(["[CLS]", "a", "tread", "##mill", "[SEP]"]) == [("a", (1,)), ("treadmill", (2, 3))]
    clip = ["<|startoftext|>", "a</w>", "tread", "mill</w>", "walk</w>", "<|endoftext|>"]
    assert merge_tokens(clip) == [("a", (1,)), ("treadmill", (2, 3)), ("walk", (4,))]


def test_word_token_ids_by_text_index_and_list():
    assert word_token_ids(TOKENS, "walks forward") == (7, 8)
    assert word_token_ids(TOKENS, "JUMPS") == (3,)
    assert word_token_ids(TOKENS, -2) == (13,)
    assert word_token_ids(TOKENS, ["waving", "arms"]) == (11, 13)
    with pytest.raises(ValueError, match=r"occurs 2 times.*\[4\].*\[8\]"):
        word_token_ids(TOKENS, "forward")
    with pytest.raises(ValueError, match="not in the tokens; words are: a man jumps"):
        word_token_ids(TOKENS, "runs")
    with pytest.raises(ValueError, match="out of range"):
        word_token_ids(TOKENS, 15)


def test_select_words_sums_pairs_and_skips_specials_and_punctuation():
    att = _attention()
    maps, labels = select_words(att, TOKENS, ["jumps forward", 7, ["waving", "arms"]])
    assert labels == ["jumps forward", "walks", "waving arms"]
    np.testing.assert_allclose(maps[0], att[:, :, 3] + att[:, :, 4])
    np.testing.assert_allclose(maps[1], att[:, :, 7])
    np.testing.assert_allclose(maps[2], att[:, :, 11] + att[:, :, 13])
    _, all_labels = select_words(att, TOKENS)
    assert all_labels == ["a", "man", "jumps", "forward", "and", "then", "walks", "forward", "while",
                          "waving", "his", "arms"]
    with pytest.raises(ValueError, match="W = 15"):
        select_words(att, TOKENS[:-1])


# ----------------------------------------------------------------------------- heatmaps
def test_word_heatmap_rows_labels_time_axis_and_normalisation():
    m = np.full((P, 10), 0.1)
    m[PART_NAMES.index("left arm"), 3] = 0.5
    before = m.copy()
    fig = plot_word_attention(m, "waving")
    ax = fig.axes[0]
    im = ax.images[0]
    np.testing.assert_allclose(im.get_array(), m / 0.5)  # divided by the max, as the official plots
    assert [t.get_text() for t in ax.get_yticklabels()] == list(PART_NAMES)
    assert im.get_extent()[:2] == [0, 40]  # 10 latent frames x 4 motion frames
    assert ax.get_title() == "waving" and im.get_cmap().name == "viridis"
    np.testing.assert_array_equal(m, before)

    # the brightest cell is drawn where the data says: left-arm row, motion frames 12-16
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    x, y = ax.transData.transform((14.0, PART_NAMES.index("left arm")))
    px = rgba[int(round(rgba.shape[0] - y)), int(round(x)), :3].astype(int)
    top = (np.asarray(plt.get_cmap("viridis")(1.0)[:3]) * 255).astype(int)
    assert np.abs(px - top).max() <= 3
    x2, y2 = ax.transData.transform((30.0, PART_NAMES.index("root")))
    low = (np.asarray(plt.get_cmap("viridis")(0.2)[:3]) * 255).astype(int)
    assert np.abs(rgba[int(round(rgba.shape[0] - y2)), int(round(x2)), :3].astype(int) - low).max() <= 3


def test_word_heatmap_into_given_axes_and_frame_cursor():
    fig, ax = plt.subplots()
    out = plot_word_attention(np.ones((P, 5)), ax=ax, frame=7, colorbar=False)
    assert out is fig
    assert len(ax.lines) == 2 and ax.lines[0].get_xdata()[0] == pytest.approx(7.5)
    with pytest.raises(ValueError, match=r"\(P, N'\) with P = 7"):
        plot_word_attention(np.ones((6, 5)))


def test_attention_grid_layout_of_fig6():
    att = _attention()
    words = ["jumps forward", "walks forward", ["waving", "arms"]]
    prompt = "a man jumps forward and then walks forward, while waving his arms"
    fig = plot_attention_grid(att, TOKENS, words, prompt=prompt, normalize="each")
    images = _image_of(fig)
    assert len(images) == 3
    panels = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in panels][:2] == ["jumps forward", "walks forward"]
    assert fig._suptitle.get_text() == prompt
    # part labels on the left panel only
    assert [t.get_text() for t in panels[0].get_yticklabels()] == list(PART_NAMES)
    assert all(t.get_text() == "" for t in panels[1].get_yticklabels())
    walks = att[:, :, 7] + att[:, :, 8]
    np.testing.assert_allclose(images[1].get_array(), walks / walks.max())
    # 'walks forward' peaks on root/legs in the second half: the heatmap shows it
    shown = np.asarray(images[1].get_array())
    assert shown[:3, 13:].mean() > 2 * shown[3:, 13:].mean()


def test_attention_grid_all_words_wraps_rows():
    fig = plot_attention_grid(_attention(), TOKENS, ncols=5)
    assert len(_image_of(fig)) == 12  # every word, no specials or punctuation
    assert sum(1 for ax in fig.axes if not ax.images and not ax.axison) == 3  # empty cells hidden


def test_by_layer_and_by_steps_views():
    rng = np.random.default_rng(3)
    arr = rng.random((8, 3, 2, 6, P, len(TOKENS)))  # s l h n p w
    fig = plot_attention_by_layer(arr, TOKENS, "walks", axes="slhnpw")
    images = _image_of(fig)
    assert len(images) == 4  # 3 layers + mean
    per_layer = [reduce_attention(arr, "slhnpw", layers=i)[:, :, 7] for i in range(3)]
    mean = reduce_attention(arr, "slhnpw")[:, :, 7]
    top = max(m.max() for m in per_layer + [mean])  # shared scale
    for im, expect in zip(images, per_layer + [mean]):
        np.testing.assert_allclose(im.get_array(), expect / top)

    fig = plot_attention_by_steps(arr, TOKENS, 7, axes="slhnpw", step_ranges=[(0, 2), (2, 8)])
    images = _image_of(fig)
    assert [ax.get_title() for ax in fig.axes if ax.images] == ["steps 0-1", "steps 2-7"]
    a = reduce_attention(arr, "slhnpw", steps=(0, 2))[:, :, 7]
    b = reduce_attention(arr, "slhnpw", steps=(2, 8))[:, :, 7]
    top = max(a.max(), b.max())
    np.testing.assert_allclose(images[0].get_array(), a / top)
    np.testing.assert_allclose(images[1].get_array(), b / top)
    with pytest.raises(ValueError, match="needs a step axis"):
        plot_attention_by_steps(arr[0], TOKENS, 7, axes="lhnpw")


# ----------------------------------------------------------------------------- comparisons
def test_comparison_difference_and_absent_words():
    src = _attention(seed=4)
    edit_tokens = TOKENS[:-1] + ["high", "[SEP]"]
    edit = np.concatenate([_attention(seed=5), _attention(seed=6)[:, :, :1]], axis=2)
    fig = plot_attention_comparison(src, edit, TOKENS, ["walks", "high"], edited_tokens=edit_tokens)
    panels = [ax for ax in fig.axes if ax.images]
    # row 'walks': source, edited, difference; row 'high': edited only + nothing else
    assert len(panels) == 4
    top = max(src[:, :, 7].max(), edit[:, :, 7].max())
    np.testing.assert_allclose(panels[0].images[0].get_array(), src[:, :, 7] / top)
    np.testing.assert_allclose(panels[2].images[0].get_array(), (edit[:, :, 7] - src[:, :, 7]) / top)
    lo, hi = panels[2].images[0].get_clim()
    assert lo == pytest.approx(-hi)  # diverging scale centred on zero
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert "'high' absent" in texts
    with pytest.raises(ValueError, match="neither token list"):
        plot_attention_comparison(src, edit, TOKENS, ["runs"], edited_tokens=edit_tokens)


def test_mirror_attention_swaps_sides_and_is_an_involution():
    att = _attention()
    mir = mirror_attention(att)
    np.testing.assert_array_equal(mir[PART_NAMES.index("left leg")], att[PART_NAMES.index("right leg")])
    np.testing.assert_array_equal(mir[PART_NAMES.index("right arm")], att[PART_NAMES.index("left arm")])
    np.testing.assert_array_equal(mir[0], att[0])
    np.testing.assert_array_equal(mirror_attention(mir), att)
    assert PART_MIRROR[PART_MIRROR[1]] == 1
    # a perfectly mirrored generation shows an all-zero third column
    fig = plot_mirror_comparison(att, mir, TOKENS, ["jumps", "walks"])
    diffs = [ax.images[0].get_array() for ax in fig.axes if ax.images][2::3]
    assert len(diffs) == 2 and all(np.abs(d).max() < 1e-12 for d in diffs)


# ----------------------------------------------------------------------------- joints
def test_joint_attention_follows_parts_and_time():
    skel = get_skeleton("humanml3d")
    maps = np.arange(P * 5, dtype=float).reshape(P, 5)
    vals = joint_attention(maps, skel, n_frames=23)
    assert vals.shape == (23, skel.num_joints)
    wrist = skel.joint_names.index("left_wrist")
    assert vals[13, wrist] == maps[PART_NAMES.index("left arm"), 3]  # frame 13 -> latent 3
    assert vals[22, 0] == maps[PART_NAMES.index("root"), 4]  # past the end: last latent column
    head = skel.joint_names.index("head")
    np.testing.assert_array_equal(vals[:, head], maps[PART_NAMES.index("head")][np.minimum(np.arange(23) // 4, 4)])


def test_joint_attention_colors_use_heatmap_colormap():
    skel = get_skeleton("humanml3d")
    maps = np.zeros((P, 4))
    maps[PART_NAMES.index("right leg"), 2] = 2.0
    cols = joint_attention_colors(maps, skel)
    assert cols.shape == (16, skel.num_joints, 3)
    knee = skel.joint_names.index("right_knee")
    np.testing.assert_allclose(cols[9, knee], plt.get_cmap("viridis")(1.0)[:3])
    np.testing.assert_allclose(cols[9, 0], plt.get_cmap("viridis")(0.0)[:3])
    np.testing.assert_allclose(cols[2, knee], plt.get_cmap("viridis")(0.0)[:3])


def test_colour_bar_says_what_the_colours_mean_and_repeated_words_are_indexed():
    att = _attention()
    fig = plot_attention_grid(att, TOKENS, [4, 8, 3], normalize="each")   # "forward" twice, then "jumps"
    panels = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in panels] == ["forward [4]", "forward [8]", "jumps"]
    cbar = [ax for ax in fig.axes if not ax.images and ax.get_ylabel()]
    assert [ax.get_ylabel() for ax in cbar] == ["attention / its panel's maximum"]
    # every panel divided by its own maximum: each reaches 1
    assert all(np.isclose(np.asarray(im.get_array()).max(), 1.0) for im in _image_of(fig))
    plt.close(fig)
    fig = plot_attention_grid(att, TOKENS, ["jumps", "walks"], normalize="shared")
    assert [ax.get_ylabel() for ax in fig.axes if not ax.images and ax.get_ylabel()] == \
        ["attention / maximum over all panels"]
    assert sorted(np.asarray(im.get_array()).max() for im in _image_of(fig))[-1] == pytest.approx(1.0)
    assert sorted(np.asarray(im.get_array()).max() for im in _image_of(fig))[0] < 0.999
    plt.close(fig)
    # every word: "forward" appears twice among the words and gets its word index
    fig = plot_attention_grid(att, TOKENS)
    titles = [ax.get_title() for ax in fig.axes if ax.images]
    assert titles.count("forward [3]") == 1 and titles.count("forward [7]") == 1 and "forward" not in titles


def test_long_prompt_titles_wrap():
    prompt = "a man jumps forward and then walks forward, while waving his arms above his head and smiling " * 2
    fig = plot_attention_grid(_attention(), TOKENS, ["jumps"], prompt=prompt)
    lines = fig._suptitle.get_text().split("\n")
    assert len(lines) >= 3 and " ".join(lines) == prompt.strip()


# ----------------------------------------------------------------------------- issue 64: global scale, signs
def _two_panel_attention() -> tuple[np.ndarray, list[str]]:
    """'walks' draws twice the attention of 'waves' (same shape)."""
    tokens = ["[CLS]", "walks", "waves", "[SEP]"]
    att = np.full((P, 10, 4), 0.05)
    att[:, :, 1] = 0.4
    att[:, :, 2] = 0.2
    att[2, 5, 1], att[2, 5, 2] = 0.8, 0.4
    return att, tokens


def _panel_rgb(fig, k: int, part: str, frame: float) -> np.ndarray:
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    ax = [a for a in fig.axes if a.images][k]
    x, y = ax.transData.transform((frame, PART_NAMES.index(part)))
    return rgba[int(round(rgba.shape[0] - y)), int(round(x)), :3].astype(int)


def test_attention_grid_defaults_to_one_colour_scale_for_all_panels():
    att, tokens = _two_panel_attention()
    fig = plot_attention_grid(att, tokens)                                   # normalize="global"
    walks, waves = _image_of(fig)
    assert np.asarray(walks.get_array()).max() == pytest.approx(1.0)
    assert np.asarray(waves.get_array()).max() == pytest.approx(0.5)        # half as bright, as the data says
    assert walks.norm.vmin == waves.norm.vmin == 0 and walks.norm.vmax == waves.norm.vmax == 1
    assert [ax.get_ylabel() for ax in fig.axes if not ax.images and ax.get_ylabel()] == \
        ["attention / maximum over all panels"]
    # the peak cell is drawn in different colours in the two panels
    assert np.abs(_panel_rgb(fig, 0, "right leg", 22.0) - _panel_rgb(fig, 1, "right leg", 22.0)).max() > 40
    plt.close(fig)
    fig = plot_attention_grid(att, tokens, normalize="each")                 # the official per-panel scaling
    assert [np.asarray(im.get_array()).max() for im in _image_of(fig)] == pytest.approx([1.0, 1.0])
    assert np.abs(_panel_rgb(fig, 0, "right leg", 22.0) - _panel_rgb(fig, 1, "right leg", 22.0)).max() <= 3
    with pytest.raises(ValueError, match="normalize must be 'global'"):
        plot_attention_grid(att, tokens, normalize="per-panel")


def test_signed_maps_use_a_diverging_scale_centred_at_zero():
    from matplotlib.colors import CenteredNorm

    att, tokens = _two_panel_attention()
    att[:, :, 2] *= -1                                                       # a negative re-weight of "waves"
    for normalize in ("global", "each"):
        fig = plot_attention_grid(att, tokens, normalize=normalize)
        for im in _image_of(fig):
            assert isinstance(im.norm, CenteredNorm) and im.norm.vcenter == 0 and im.get_cmap().name == "RdBu_r"
            assert im.norm.vmin == pytest.approx(-im.norm.vmax)
        waves = np.asarray(_image_of(fig)[1].get_array())
        assert waves.min() < -0.2 and waves.max() <= 0                      # kept, not clipped to a blank panel
        # the negative panel is blue, the positive red, zero white
        neg, pos = _panel_rgb(fig, 1, "right leg", 22.0), _panel_rgb(fig, 0, "right leg", 22.0)
        assert neg[2] > neg[0] + 60 and pos[0] > pos[2] + 60
        plt.close(fig)
    fig = plot_word_attention(-np.abs(_attention()[:, :, 3]), "high")
    im = fig.axes[0].images[0]
    assert isinstance(im.norm, CenteredNorm) and im.get_cmap().name == "RdBu_r"
    assert np.asarray(im.get_array()).min() == pytest.approx(-1.0)


def test_unknown_words_are_marked_in_the_panel_titles():
    tokens = ["[CLS]", "a", "person", "does", "a", "cart", "##wheel", "[SEP]"]
    att = _attention(8)[:, :, :len(tokens)]
    fig = plot_attention_grid(att, tokens, ["person", "does", "cartwheel"], unknown_words=["cartwheel"])
    panels = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in panels] == ["person", "does", "cartwheel (unknown)"]
    assert panels[2].title.get_color() != panels[0].title.get_color()


def test_titles_in_another_script_never_draw_boxes(monkeypatch):
    import warnings

    from salad_viz import _style

    tokens = ["[CLS]", "a", "person", "walks", "[SEP]"]
    prompt = "一个人在跳舞 a person walks"
    monkeypatch.setattr(_style, "_font_files", lambda: ())                  # no font has the characters
    with pytest.warns(UserWarning, match="no installed font draws .*一个人在跳舞.*drawn as '\\?'"):
        fig = plot_attention_grid(_attention(6)[:, :, :5], tokens, prompt=prompt)
    assert fig._suptitle.get_text() == "?????? a person walks"
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                       # no "Glyph missing" warning
        fig.canvas.draw()
    monkeypatch.undo()
    fonts, missing = _style.fonts_covering("一", _style._cmap(
        __import__("matplotlib").font_manager.findfont("DejaVu Sans")))
    if not fonts:
        pytest.skip("no installed font has CJK characters (e.g. Debian fonts-noto-cjk, fonts-droid-fallback)")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = plot_attention_grid(_attention(6)[:, :, :5], tokens, prompt=prompt)
        fig.canvas.draw()
    assert fig._suptitle.get_text() == prompt and len(fig._suptitle.get_fontfamily()) > 1


# ----------------------------------------------------------------------------- issue 67: source vs edit, one scale
def _reweighted(att: np.ndarray, column: int, scale: float) -> np.ndarray:
    """The maps after a re-weight of one token column (post-softmax, not re-normalised)."""
    out = att.copy()
    out[:, :, column] *= scale
    return out


def test_attention_limits_one_scale_symmetric_when_a_map_is_negative():
    src = _attention()
    dst = _reweighted(src, 3, -1.5)                                         # --reweight jumps=-1.5
    vmin, vmax = attention_limits(src, dst)
    assert vmin < 0 < vmax and vmin == -vmax
    assert vmax == pytest.approx(max(np.abs(src).max(), np.abs(dst).max()))
    assert attention_limits(src) == (0.0, pytest.approx(src.max()))         # no negative value: 0..max
    assert attention_limits(np.zeros((7, 3))) == (0.0, 1.0)
    assert attention_limits(np.array([np.nan, -0.5, 0.2])) == (-0.5, 0.5)   # an absent word's NaN is ignored
    with pytest.raises(ValueError, match="at least one"):
        attention_limits()


def test_two_grids_with_shared_limits_draw_the_same_value_in_the_same_colour():
    from matplotlib.colors import CenteredNorm

    src = _attention()
    dst = _reweighted(src, 3, -1.5)
    limits = attention_limits(src, dst)
    figs = [plot_attention_grid(a, TOKENS, ["jumps", "walks"], limits=limits) for a in (src, dst)]
    (s_jumps, s_walks), (d_jumps, d_walks) = (_image_of(f) for f in figs)
    for im in (s_jumps, s_walks, d_jumps, d_walks):                         # all-positive source too: diverging
        assert isinstance(im.norm, CenteredNorm) and im.norm.vmin == -1 and im.norm.vmax == 1
        assert im.get_cmap().name == "RdBu_r"
    # values divided by ONE maximum: the untouched word is drawn identically in both figures
    np.testing.assert_allclose(s_walks.get_array(), d_walks.get_array())
    np.testing.assert_allclose(d_jumps.get_array(), -1.5 * np.asarray(s_jumps.get_array()), atol=1e-12)
    assert np.asarray(d_jumps.get_array()).min() == pytest.approx(-1.0)
    # without shared limits the source would be drawn on its own 0..1 viridis scale
    own = _image_of(plot_attention_grid(src, TOKENS, ["jumps", "walks"]))[0]
    assert own.norm.vmin == 0 and own.get_cmap().name == "viridis"
    with pytest.raises(ValueError, match="limits"):
        plot_attention_grid(src, TOKENS, limits=(-0.5, 1.0))


def test_attention_rows_one_colour_bar_titled_blocks_and_balanced_lines():
    from matplotlib.colors import CenteredNorm

    src = select_words(_attention(), TOKENS, ["jumps", "walks", "waving"])[0]     # (3, P, N')
    dst = src.copy()
    dst[2] *= -1
    fig = plot_attention_rows([src, dst], [["jumps", "walks", "waving"]] * 2,
                              ["source: a man jumps", "Reweight(waving=-1): a man jumps"])
    images = _image_of(fig)
    assert len(images) == 6 and len({(im.norm.vmin, im.norm.vmax) for im in images}) == 1
    assert all(isinstance(im.norm, CenteredNorm) and im.get_cmap().name == "RdBu_r" for im in images)
    top = max(np.abs(src).max(), np.abs(dst).max())
    np.testing.assert_allclose(images[5].get_array(), dst[2] / top)        # the edit's negative word, on the scale
    blocks = fig.subfigs[0].subfigs
    assert [b._suptitle.get_text() for b in blocks] == ["source: a man jumps", "Reweight(waving=-1): a man jumps"]
    colour_bars = [ax for ax in fig.axes if not ax.images and ax.get_ylabel()]
    assert len(colour_bars) == 1 and "over all panels" in colour_bars[0].get_ylabel()
    # 7 words: two lines of 4 and 3 panels, not 6 and 1; a block with fewer words leaves panels empty
    many = np.repeat(src[:1], 7, axis=0)
    fig = plot_attention_rows([many, many[:5]], [list("abcdefg"), list("abcde")], ["source", "edited"])
    shown = [ax for ax in fig.subfigs[0].subfigs[0].axes if ax.images]
    assert len(shown) == 7 and len(fig.subfigs[0].subfigs[0].axes) == 8
    with pytest.raises(ValueError, match="one entry per block"):
        plot_attention_rows([src], [["a", "b", "c"]], ["x", "y"])
    with pytest.raises(ValueError, match="labels for 3 maps"):
        plot_attention_rows([src], [["a"]], ["x"])
