"""salad_viz.render: pyvista off-screen renders, the automatic raster fallback, keyframe strips."""
from __future__ import annotations

import numpy as np
import pytest

import salad_viz.render as render_mod
from salad_core.skeleton import get_skeleton
from salad_viz._style import bone_colors, to_uint8
from salad_viz.camera import Camera, project_points
from salad_viz.kinematics import rest_pose
from salad_viz.raster import rasterize_skeleton
from salad_viz.render import SkeletonRenderer, keyframe_strip, offscreen_available, render_skeleton
from salad_viz.synthetic import synthetic_motion

SKEL = get_skeleton("humanml3d")
SIZE = (160, 200)

needs_gl = pytest.mark.skipif(not offscreen_available(), reason="no off-screen OpenGL on this machine")


def _tpose_motion(n: int = 4) -> np.ndarray:
    pose = rest_pose(SKEL)
    return np.stack([pose + np.array([0.0, 0.0, 0.1 * t]) for t in range(n)])


def _camera() -> Camera:
    return Camera((0.0, 0.9, 4.0), (0.0, 0.85, 0.0), (0, 1, 0), 35.0)


@pytest.fixture
def fresh_probe(monkeypatch):
    """Forget the cached probe result (restored afterwards)."""
    monkeypatch.setattr(render_mod, "_probe_result", None)
    monkeypatch.delenv("SALAD_VIZ_BACKEND", raising=False)
    return render_mod


@needs_gl
def test_pyvista_render_matches_projection_and_chain_colours():
    motion = _tpose_motion()
    before = motion.copy()
    cam = _camera()
    img = render_skeleton(motion, SKEL, 0, camera=cam, size=SIZE, backend="pyvista", bone_radius=0.05,
                          joint_radius=0.05, trajectory=False)
    np.testing.assert_array_equal(motion, before)
    assert img.shape == (SIZE[1], SIZE[0], 3) and img.dtype == np.uint8
    assert (np.abs(img.astype(int) - 255).sum(-1) > 30).mean() > 0.1  # not blank
    expected = to_uint8(bone_colors(SKEL)).astype(int)
    for name in ("left_knee", "right_knee", "left_elbow", "right_elbow", "spine2"):
        j = SKEL.joint_names.index(name)
        mid = 0.5 * (motion[0, j] + motion[0, SKEL.parents[j]])
        x, y = project_points(mid, cam, SIZE)[0]
        px = img[int(y), int(x)].astype(int)
        # shading changes brightness, not which channel dominates
        assert np.argmax(px) == np.argmax(expected[j]) or np.ptp(expected[j]) < 40, name
        assert np.abs(px - expected[j]).max() < 90, (name, px, expected[j])
    lk = img[tuple(int(v) for v in project_points(0.5 * (motion[0, 4] + motion[0, 1]), cam, SIZE)[0][::-1])]
    rk = img[tuple(int(v) for v in project_points(0.5 * (motion[0, 5] + motion[0, 2]), cam, SIZE)[0][::-1])]
    assert int(lk[2]) > int(lk[0]) + 50 and int(rk[0]) > int(rk[2]) + 50  # left blue, right red


@needs_gl
def test_pyvista_and_raster_draw_the_same_view(sample_joints):
    kw = dict(size=SIZE, view="three_quarter")
    gl = render_skeleton(sample_joints, SKEL, 30, backend="pyvista", **kw)
    ras = rasterize_skeleton(sample_joints, SKEL, 30, **kw)
    # same camera, same floor, same figure: only shading and edges differ
    assert np.abs(gl.astype(int) - ras).mean() < 12
    fg_gl = np.abs(gl.astype(int) - 255).sum(-1) > 30
    fg_ras = np.abs(ras.astype(int) - 255).sum(-1) > 30
    assert (fg_gl == fg_ras).mean() > 0.95


@needs_gl
def test_renderer_reuses_window_and_camera_follows_each_frame():
    motion = synthetic_motion(SKEL, 30)
    with SkeletonRenderer(SKEL, size=(96, 120), backend="pyvista") as r:
        frames = [r.render(motion, f, view="side") for f in (0, 15, 29)]
        plotter = r._plotter
        assert plotter is not None
    assert r._plotter is None  # closed on exit
    for f, img in zip((0, 15, 29), frames):
        ref = rasterize_skeleton(motion, SKEL, f, view="side", size=(96, 120))
        assert np.abs(img.astype(int) - ref).mean() < 15, f


@needs_gl
def test_several_motions_and_cylinder_bones():
    a = _tpose_motion()
    b = a + np.array([0.9, 0.0, 0.0])
    img = render_skeleton([a, b], SKEL, 0, size=SIZE, backend="pyvista", bone_shape="cylinder")
    assert (np.abs(img.astype(int) - 255).sum(-1) > 30).mean() > 0.1
    with pytest.raises(ValueError, match="bone_shape must be one of"):
        render_skeleton(a, SKEL, backend="pyvista", bone_shape="box")


def test_auto_backend_falls_back_to_raster_when_probe_fails(fresh_probe, monkeypatch):
    monkeypatch.setattr(fresh_probe, "_PROBE_CODE", "raise SystemExit(3)")
    assert fresh_probe.offscreen_available() is False
    assert fresh_probe.resolve_backend("auto") == "raster"
    motion = _tpose_motion()
    img = render_skeleton(motion, SKEL, 1, size=SIZE)
    np.testing.assert_array_equal(img, rasterize_skeleton(motion, SKEL, 1, size=SIZE))


def test_probe_is_cached_and_env_override(fresh_probe, monkeypatch):
    calls = []
    real_run = fresh_probe.subprocess.run

    def counting_run(*args, **kwargs):
        calls.append(1)
        return real_run(*args, **kwargs)

    monkeypatch.setattr(fresh_probe.subprocess, "run", counting_run)
    monkeypatch.setattr(fresh_probe, "_PROBE_CODE", "raise SystemExit(0)")
    assert fresh_probe.offscreen_available() is True
    assert fresh_probe.offscreen_available() is True
    assert len(calls) == 1
    monkeypatch.setenv("SALAD_VIZ_BACKEND", "raster")
    assert fresh_probe.offscreen_available() is False and len(calls) == 1
    with pytest.raises(ValueError, match="backend must be one of"):
        fresh_probe.resolve_backend("opengl")


def test_keyframe_strip_row_and_grid_layouts(sample_joints):
    strip = keyframe_strip(sample_joints, SKEL, 4, layout="row", size=(64, 80), backend="raster")
    assert strip.shape == (80, 4 * 64 + 3 * 4, 3)
    tiles = [strip[:, k * 68:k * 68 + 64] for k in range(4)]
    assert all((np.abs(t.astype(int) - 255).sum(-1) > 60).mean() > 0.05 for t in tiles)
    assert np.abs(tiles[0].astype(int) - tiles[2]).mean() > 1.0  # different poses
    grid = keyframe_strip(sample_joints, SKEL, [0, 50, 100], layout="grid", size=(64, 80), backend="raster",
                          labels=False)
    assert grid.shape == (2 * 80 + 4, 2 * 64 + 4, 3)


def _figure_mask(img: np.ndarray) -> np.ndarray:
    """Pixels that are neither background nor floor (the floor greys are neutral, the figure is not)."""
    from salad_viz._style import FLOOR_DARK, FLOOR_LIGHT

    px = img.astype(int)
    neutral = [to_uint8(c).astype(int) for c in ((1.0, 1.0, 1.0), FLOOR_LIGHT, FLOOR_DARK)]
    far = np.stack([np.abs(px - c).sum(-1) for c in neutral]).min(axis=0)
    return far > 60


def test_keyframe_strip_trail_fans_out_a_motion_in_place():
    from skimage.measure import label

    motion = np.repeat(rest_pose(SKEL)[None], 20, axis=0)  # standing still: poses must be fanned out
    strip = keyframe_strip(motion, SKEL, 4, layout="trail", view="front", size=(120, 160), backend="raster",
                           labels=False)
    assert strip.shape[0] == 160 and strip.shape[1] > 3 * 160
    parts = label(_figure_mask(strip), connectivity=2)
    sizes = np.bincount(parts.ravel())[1:]
    assert (sizes > 50).sum() == 4  # four separate figures
    # with real positions the four identical poses coincide: one figure
    same = keyframe_strip(motion, SKEL, 4, layout="trail", view="front", size=(120, 160), backend="raster",
                          labels=False, spacing=None)
    sizes = np.bincount(label(_figure_mask(same), connectivity=2).ravel())[1:]
    assert (sizes > 50).sum() == 1
    with pytest.raises(ValueError, match="layout must be"):
        keyframe_strip(motion, SKEL, 3, layout="film")


def test_keyframe_strip_trail_runs_left_to_right_for_a_walk():
    motion = synthetic_motion(SKEL, 40)  # walks along +Z
    strip = keyframe_strip(motion, SKEL, [0, 39], layout="trail", size=(120, 160), backend="raster",
                           labels=False, spacing=None)
    mask = _figure_mask(strip)
    cols = np.flatnonzero(mask.any(axis=0))
    # the last pose is drawn at full colour, the first faded: the darker figure is on the right
    left, right = strip[:, : cols.mean().astype(int)], strip[:, cols.mean().astype(int):]
    dark = lambda im, m: im[m].astype(int).sum(-1).mean()  # noqa: E731
    ml, mr = mask[:, : cols.mean().astype(int)], mask[:, cols.mean().astype(int):]
    assert dark(right, mr) < dark(left, ml)
