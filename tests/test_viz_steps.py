"""Steps drawn under feet planted above the floor (issue 69: "a person climbs stairs ... walks on air
over the drawn floor"): found on a stair climb, not on a flat walk, a held knee or a floating motion,
and drawn by both backends."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.data.procedural.composition import Plan, Step, realise
from salad_core.data.procedural.primitives import Action
from salad_core.skeleton import get_skeleton
from salad_viz.scene import STEP_TOP, build_scene, support_boxes, support_faces
from salad_viz.synthetic import synthetic_motion

SK = get_skeleton("humanml3d")


@pytest.fixture(scope="module")
def stairs() -> np.ndarray:
    """A walk then a climb up a flight of stairs (the corpus's own stair climb: feet planted at rising heights)."""
    return realise(Plan((Step(Action("walk")), Step(Action("climb_stairs")))), np.random.default_rng(3)).joints


def _action(kind: str, side=None, seed: int = 0) -> np.ndarray:
    return realise(Plan((Step(Action(kind, side)),)), np.random.default_rng(seed)).joints


def test_stair_climb_gets_rising_steps_under_its_feet(stairs):
    boxes = support_boxes(stairs, SK)
    heights = sorted(float(b[0, 1]) for b in boxes)
    assert len(boxes) >= 3 and heights[0] > 0.05
    assert np.all(np.diff(heights) > 0.08)                                   # a staircase, one step per level
    sole_end = min(stairs[-1, 10, 1] - 0.012, stairs[-1, 7, 1] - 0.058)
    assert abs(heights[-1] - sole_end) < 0.05                                # the top step is under the last stance
    for quad in boxes:
        assert quad.shape == (4, 3) and np.allclose(quad[:, 1], quad[0, 1])
        faces = support_faces(quad)
        assert len(faces) == 5 and np.allclose(faces[0][1], [0, 1, 0])
        # each step stands under a foot: some frame has a foot above the box, on it
        centre = quad.mean(axis=0)
        feet = stairs[:, [7, 8, 10, 11]]
        near = np.hypot(feet[..., 0] - centre[0], feet[..., 2] - centre[2]) < 0.25
        on_top = np.abs(feet[..., 1] - centre[1]) < 0.08
        assert (near & on_top).any()


def test_flat_motions_get_no_steps(stairs):
    walk = synthetic_motion("humanml3d", 80)
    assert support_boxes(walk, SK) == []
    assert build_scene([walk], SK, 10).supports == ()
    for kind, side in (("knee_lift", "left"), ("balance", "right"), ("kick", "left"), ("jump", None), ("sit", None)):
        assert support_boxes(_action(kind, side), SK) == [], kind            # a raised foot carries nothing
    floating = walk + np.array([0.0, 0.4, 0.0])
    assert support_boxes(floating, SK) == []                                 # never on the floor: no platform


def test_scene_draws_steps_by_default_and_on_request(stairs):
    assert len(build_scene([stairs], SK, 0).supports) >= 3                   # on by default with the floor
    assert build_scene([stairs], SK, 0, supports=False).supports == ()
    assert build_scene([stairs], SK, 0, floor=False).supports == ()
    assert len(build_scene([stairs], SK, 0, floor=False, supports=True).supports) >= 3


def _step_pixels(img: np.ndarray) -> int:
    top = np.asarray(STEP_TOP) * 255
    return int((np.abs(img.astype(float) - top).max(axis=-1) < 12).sum())


def test_rendered_frames_show_the_steps(stairs, tmp_path):
    from salad_viz.render import render_skeleton

    n = len(stairs)
    img = render_skeleton(stairs, frame=n - 1, size=(240, 180), backend="raster", follow=False, view="side")
    off = render_skeleton(stairs, frame=n - 1, size=(240, 180), backend="raster", follow=False, view="side",
                          supports=False)
    changed = np.abs(img.astype(int) - off.astype(int)).max(axis=-1) > 20
    assert changed.sum() > 400 and _step_pixels(img) > 50 and _step_pixels(off) == 0
    walk = synthetic_motion("humanml3d", 60)
    a = render_skeleton(walk, frame=30, size=(240, 180), backend="raster")
    b = render_skeleton(walk, frame=30, size=(240, 180), backend="raster", supports=False)
    assert np.array_equal(a, b) and _step_pixels(a) == 0


def test_gif_frames_show_the_steps(stairs, tmp_path):
    import imageio.v2 as imageio

    from salad_viz.animate import animate

    path = animate(stairs, "humanml3d", tmp_path / "stairs.gif", stride=24, size=(200, 160), backend="raster",
                   follow=False, view="side")
    frames = imageio.mimread(path)
    assert len(frames) >= 5 and all(_step_pixels(np.asarray(f)[..., :3]) > 50 for f in frames)
