"""salad_viz.animate: GIF/MP4 files (frame count, timing, layout, content) and inline display."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.skeleton import get_skeleton
from salad_viz._style import to_uint8
from salad_viz.animate import animate, render_frames, show_animation, write_video
from salad_viz.raster import rasterize_skeleton
from salad_viz.synthetic import synthetic_motion

SKEL = get_skeleton("humanml3d")


@pytest.fixture(scope="module")
def walk() -> np.ndarray:
    return synthetic_motion(SKEL, 12)


def test_gif_frames_timing_and_content(tmp_path, walk):
    before = walk.copy()
    path = animate(walk, SKEL, tmp_path / "walk.gif", size=(64, 80), backend="raster")
    np.testing.assert_array_equal(walk, before)
    from PIL import Image

    with Image.open(path) as im:
        assert im.n_frames == 12
        assert im.info["duration"] == 50  # 20 fps -> 50 ms per frame
        assert im.size == (64, 80)
        first = np.asarray(im.convert("RGB"))
        im.seek(11)
        last = np.asarray(im.convert("RGB"))
    ref = rasterize_skeleton(walk, SKEL, 0, size=(64, 80))
    assert np.abs(first.astype(int) - ref).mean() < 8  # GIF palette quantisation only
    assert np.abs(first.astype(int) - last).mean() > 1  # the figure moves


def test_mp4_reads_back_with_its_frame_rate(tmp_path, walk):
    import imageio.v3 as iio

    path = animate(walk, SKEL, tmp_path / "walk.mp4", size=(63, 81), stride=2, backend="raster")
    frames = iio.imread(path)
    assert frames.shape == (6, 82, 64, 3)  # odd sizes are padded to even for H.264
    meta = iio.immeta(path)
    assert meta["fps"] == pytest.approx(10.0)  # 20 fps with stride 2 keeps real time
    ref = rasterize_skeleton(walk, SKEL, 2, size=(63, 81))
    assert np.abs(frames[1, :81, :63].astype(int) - ref).mean() < 10


def test_side_by_side_and_overlay_layouts(walk):
    other = walk + np.array([1.0, 0.0, 0.0])
    side = render_frames([walk, other[:6]], SKEL, layout="side", titles=["source", "edited"], size=(64, 80),
                         backend="raster")
    assert side.shape == (12, 80, 64 * 2 + 4, 3)
    # the shorter motion holds its last pose
    np.testing.assert_array_equal(side[8, :, 68:], side[11, :, 68:])
    assert np.abs(side[8, :, :64].astype(int) - side[11, :, :64]).mean() > 0.5
    over = render_frames([walk, other], SKEL, layout="overlay", titles=["source", "edited"], size=(96, 80),
                         backend="raster")
    assert over.shape == (12, 80, 96, 3)
    # the legend is written in each motion's theme colour (blue then orange)
    legend = over[0, :30, :60].reshape(-1, 3).astype(int)
    blueish = (legend[:, 2] > legend[:, 0] + 60).sum()
    orangeish = (legend[:, 0] > legend[:, 2] + 60).sum()
    assert blueish > 5 and orangeish > 5


def test_joint_colors_follow_time(tmp_path, walk):
    cols = np.zeros((12, SKEL.num_joints, 3))
    cols[:6, :, 0] = 1.0  # red for the first half
    cols[6:, :, 1] = 1.0  # green afterwards
    frames = render_frames(walk, SKEL, size=(64, 80), joint_colors=cols, backend="raster", floor=False,
                           trajectory=False)
    fig0 = frames[0].reshape(-1, 3).astype(int)
    fig9 = frames[9].reshape(-1, 3).astype(int)
    assert ((fig0[:, 0] > 200) & (fig0[:, 1] < 60)).sum() > 20
    assert ((fig9[:, 1] > 200) & (fig9[:, 0] < 60)).sum() > 20
    assert ((fig9[:, 0] > 200) & (fig9[:, 1] < 60)).sum() == 0


def test_show_animation_embeds_gif_and_mp4(tmp_path):
    from IPython.display import Image, Video

    frames = np.zeros((3, 16, 16, 3), np.uint8)
    frames[:, 4:12, 4:12] = to_uint8((1.0, 0.0, 0.0))
    gif = write_video(frames, tmp_path / "a.gif")
    mp4 = write_video(frames, tmp_path / "a.mp4")
    shown = show_animation(gif)
    assert isinstance(shown, Image) and shown.data[:6] == b"GIF89a"
    video = show_animation(mp4, width=200)
    assert isinstance(video, Video) and "data:video/mp4;base64," in video._repr_html_()
    with pytest.raises(FileNotFoundError):
        show_animation(tmp_path / "missing.gif")


def test_animation_errors(tmp_path, walk):
    with pytest.raises(ValueError, match=r"must end in one of \('.gif', '.mp4'\)"):
        animate(walk, SKEL, tmp_path / "walk.avi")
    with pytest.raises(ValueError, match="layout must be one of"):
        animate(walk, SKEL, tmp_path / "walk.gif", layout="grid")
    with pytest.raises(ValueError, match="titles must have one entry per motion"):
        render_frames([walk, walk], SKEL, titles=["only one"], backend="raster")
    with pytest.raises(ValueError, match="stride must be a positive int"):
        animate(walk, SKEL, tmp_path / "walk.gif", stride=0)
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_pyvista_backend_animation_matches_raster_frames(tmp_path, walk):
    import imageio.v3 as iio

    from salad_viz.render import offscreen_available

    if not offscreen_available():
        pytest.skip("no off-screen OpenGL on this machine")
    path = animate(walk[:3], SKEL, tmp_path / "gl.gif", size=(64, 80), backend="pyvista")
    frames = iio.imread(path)[..., :3]
    assert frames.shape == (3, 80, 64, 3)
    for f in range(3):
        ref = rasterize_skeleton(walk[:3], SKEL, f, size=(64, 80))
        assert np.abs(frames[f].astype(int) - ref).mean() < 15


def _colour_pixels(img: np.ndarray, rgb, tol: int = 40) -> int:
    return int((np.abs(img.astype(int) - np.asarray(rgb) * 255).max(axis=-1) < tol).sum())


def test_side_panels_share_one_scale_and_are_labelled(walk):
    # the same pose in both panels, but the second motion jumps 0.6 m later on: framed on its own,
    # its figure was drawn smaller; at one scale both panels show frame 0 identically
    jumper = walk.copy()
    jumper[6:, :, 1] += 0.6
    frames = render_frames([walk, jumper], SKEL, size=(96, 96), frames=[0], backend="raster", side_legend=False)
    left, right = frames[0][:, :96], frames[0][:, 100:]
    assert np.abs(left.astype(int) - right.astype(int)).mean() < 0.5
    titled = render_frames([walk, jumper], SKEL, size=(160, 160), frames=[0], backend="raster",
                           titles=["source", "edited: a person jumps forward and then walks forward, waving"])
    # a dark title in each panel's top rows; the long one wraps onto more rows than the short one
    rows = lambda img: int(((img[:60] < 80).all(axis=-1)).any(axis=1).sum())      # noqa: E731
    assert 0 < rows(titled[0][:, :160]) < rows(titled[0][:, 164:])


def test_left_right_key_in_the_chain_colours(walk):
    from salad_viz._style import SIDE_COLORS, limb_colors

    # the key names the colours of legs and arms as drawn: left leg dark blue, left arm light blue,
    # right leg red, right arm orange (HumanML3D's chains)
    assert [(side, limb) for side, limb, _ in limb_colors(SKEL)] == [("left", "leg"), ("left", "arm"),
                                                                     ("right", "leg"), ("right", "arm")]
    assert [rgb for *_, rgb in limb_colors(SKEL)] == [SIDE_COLORS["left"][0], SIDE_COLORS["left"][1],
                                                       SIDE_COLORS["right"][0], SIDE_COLORS["right"][1]]
    with_key = render_frames(walk, SKEL, size=(160, 160), frames=[0], backend="raster")[0]
    without = render_frames(walk, SKEL, size=(160, 160), frames=[0], backend="raster", side_legend=False)[0]
    corner = (slice(120, 160), slice(0, 100))
    diff = np.abs(with_key.astype(int) - without.astype(int))
    assert diff[corner].sum() > 0 and diff.sum() == diff[corner].sum()      # only the bottom-left corner
    for side in ("left", "right"):
        for shade in SIDE_COLORS[side]:                                      # the leg's and the arm's colour
            assert _colour_pixels(with_key[corner], shade) > _colour_pixels(without[corner], shade) + 3
    # too small a frame for the key: left out rather than drawn over the figure
    small = render_frames(walk, SKEL, size=(64, 80), frames=[0], backend="raster")[0]
    assert np.array_equal(small, render_frames(walk, SKEL, size=(64, 80), frames=[0], backend="raster",
                                               side_legend=False)[0])
    # an overlay of two motions uses theme colours, not the chain colours: no key
    over = render_frames([walk, walk + 0.5], SKEL, layout="overlay", size=(160, 160), frames=[0], backend="raster")
    over_nokey = render_frames([walk, walk + 0.5], SKEL, layout="overlay", size=(160, 160), frames=[0],
                               backend="raster", side_legend=False)
    assert np.array_equal(over, over_nokey)


# ----------------------------------------------------------------------------- issue 64: caption, camera, fonts
def _raised_hands(walk: np.ndarray) -> np.ndarray:
    """The walk with both hands raised far above the head (2.4 m) in two frames."""
    out = walk.copy()
    for j in (20, 21):                                                      # the wrists
        out[5:7, j, 1] = 2.4
    return out


def test_follow_camera_keeps_raised_hands_and_feet_in_view(walk):
    from salad_viz.camera import follow_camera, project_points, shared_follow_framing

    m = _raised_hands(walk)
    w, h = 160, 120
    for f in range(len(m)):
        cam = follow_camera([m], f, aspect=w / h)
        pix, depth = project_points(m[f], cam, (w, h))
        assert (depth > 0).all()
        assert (pix[:, 0] >= 0).all() and (pix[:, 0] < w).all() and (pix[:, 1] >= 0).all() and (pix[:, 1] < h).all()
    # the same distance all along (no zooming while following), and side panels share it
    cams = [follow_camera([m], f, aspect=w / h) for f in (0, 6, 11)]
    assert len({round(float(np.linalg.norm(np.subtract(c.position, c.focal_point))), 6) for c in cams}) == 1
    d, height = shared_follow_framing([walk, m], aspect=w / h)
    assert d >= shared_follow_framing([walk], aspect=w / h)[0] - 1e-9


def test_caption_sits_above_the_scene_and_raised_hands_stay_below_it(walk):
    from salad_viz._style import SIDE_COLORS
    from salad_viz.raster import caption_band

    m = _raised_hands(walk)
    title = "a man raises both hands high above his head while he walks forward slowly"
    frames = render_frames(m, SKEL, size=(200, 200), titles=[title], frames=[0, 5], backend="raster",
                           side_legend=False)
    assert frames.shape == (2, 200, 200, 3)                                # the size is the whole frame
    band = caption_band([title], 200, 200)
    b = band.shape[0]
    assert 20 < b < 80 and (band.max(axis=-1) < 90).any()                  # dark caption text, wrapped
    # the top rows are the caption band and nothing else; the scene (raised arms included) is below it
    assert np.array_equal(frames[1][:b], band) and np.array_equal(frames[0][:b], band)
    scene = render_frames(m, SKEL, size=(200, 200 - b), frames=[5], backend="raster", side_legend=False)[0]
    assert np.array_equal(frames[1][b:], scene)
    arms = _colour_pixels(scene, SIDE_COLORS["left"][1]) + _colour_pixels(scene, SIDE_COLORS["right"][1])
    assert arms > 20
    # the side layout: each panel's band above its own scene, at one height
    side = render_frames([walk, m], SKEL, size=(160, 160), titles=["source", "edited: hands up"], frames=[5],
                         backend="raster", side_legend=False)[0]
    assert side.shape == (160, 324, 3)
    b1, b2 = caption_band(["source"], 160, 160), caption_band(["edited: hands up"], 160, 160)
    assert b1.shape == b2.shape and np.array_equal(side[:b1.shape[0], :160], b1)
    assert np.array_equal(side[:b2.shape[0], 164:], b2)


def test_captions_in_another_script_use_a_fallback_font_or_question_marks(monkeypatch):
    from salad_viz import _style
    from salad_viz.raster import caption_band

    text = "一个人在跳舞"
    monkeypatch.setattr(_style, "_font_files", lambda: ())                  # no installed font has them
    with pytest.warns(UserWarning, match="no installed font draws.*drawn as '\\?'"):
        band = caption_band([text], 200, 200)
    assert np.array_equal(band, caption_band(["??????"], 200, 200))           # question marks, not boxes
    monkeypatch.undo()
    font = _style.CaptionFont(text + " 🤸 walks", 16, warn=False)
    if len(font.fonts) == 1:
        pytest.skip("no installed font has CJK characters (e.g. Debian fonts-noto-cjk, fonts-droid-fallback)")
    assert font.text.startswith(text) and font.text.endswith("walks")       # CJK and Latin drawn, each by a font
    assert {piece for _, piece in font.runs(font.text)} >= {text, " walks"} or len(font.runs(font.text)) >= 2
    assert not np.array_equal(caption_band([text], 200, 200), caption_band(["??????"], 200, 200))


# ----------------------------------------------------------------------------- issue 67: labelled comparison GIFs
def test_comparison_panels_each_carry_their_caption_and_the_left_right_key(tmp_path, walk):
    from PIL import Image

    from salad_viz._style import SIDE_COLORS
    from salad_viz.animate import COMPARISON_PANEL
    from salad_viz.raster import caption_band

    w, h = COMPARISON_PANEL
    assert w >= 360 and h >= 360                                           # read on a projector
    titles = [("source", "a person walks forward"), ("Mirror(legs)", "a person walks forward")]
    frames = render_frames([walk, walk], SKEL, size=COMPARISON_PANEL, titles=titles, frames=[0], backend="raster")
    assert frames.shape == (1, h, 2 * w + 4, 3)
    left, right = frames[0][:, :w], frames[0][:, w + 4:]
    # each panel its own two-line caption: the label over the prompt, one band height for both
    bands = [caption_band(list(t), w, h, colors=[(0.05, 0.05, 0.05), (0.30, 0.30, 0.30)]) for t in titles]
    b = bands[0].shape[0]
    assert bands[1].shape[0] == b and np.array_equal(left[:b], bands[0]) and np.array_equal(right[:b], bands[1])
    assert not np.array_equal(bands[0], bands[1])
    one_line = caption_band(["source"], w, h).shape[0]
    assert b > 1.5 * one_line                                               # two lines: label, then prompt
    # the key of the limb colours in the bottom-left corner of BOTH panels
    bare = render_frames([walk, walk], SKEL, size=COMPARISON_PANEL, titles=titles, frames=[0], backend="raster",
                         side_legend=False)[0]
    corner = (slice(h - 60, h), slice(0, 130))
    for k, panel in enumerate((left, right)):
        ref = bare[:, k * (w + 4):k * (w + 4) + w]
        for side in ("left", "right"):
            for shade in SIDE_COLORS[side]:
                assert _colour_pixels(panel[corner], shade) > _colour_pixels(ref[corner], shade) + 3
    # the GIF reads back at that size
    path = animate([walk[:4], walk[:4]], SKEL, tmp_path / "cmp.gif", titles=titles, size=COMPARISON_PANEL,
                   backend="raster")
    with Image.open(path) as im:
        assert im.size == (2 * w + 4, h)


def test_titles_given_as_lines_in_an_overlay_are_joined():
    from salad_viz.animate import _title_bands

    (band,) = _title_bands([("Mirror(legs)", "a person walks")], 200, 200, side=False)
    from salad_viz.raster import caption_band

    assert np.array_equal(band, caption_band(["Mirror(legs): a person walks"], 200, 200))
    with pytest.raises(ValueError, match="at least one line"):
        _title_bands([()], 200, 200, side=True)
