"""salad_viz.camera + salad_viz.raster: projection maths and image content of the 2D rasteriser."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.skeleton import get_skeleton
from salad_viz._style import BACKGROUND, FLOOR_DARK, FLOOR_LIGHT, bone_colors, chain_palette, chain_sides, to_uint8
from salad_viz.camera import Camera, fixed_camera, follow_camera, project_points
from salad_viz.kinematics import rest_pose
from salad_viz.raster import hstack_images, rasterize_skeleton
from salad_viz.synthetic import synthetic_motion

SKEL = get_skeleton("humanml3d")
SIZE = (160, 200)


def _tpose_motion(n: int = 5) -> np.ndarray:
    """A T-pose (FK of the target offsets) sliding 0.1 m per frame along +Z."""
    pose = rest_pose(SKEL)
    return np.stack([pose + np.array([0.0, 0.0, 0.1 * t]) for t in range(n)])


def _front_camera(joints: np.ndarray, frame: int = 0) -> Camera:
    root = joints[frame, 0]
    return Camera((root[0], 0.9, root[2] + 4.0), (root[0], 0.85, root[2]), (0, 1, 0), 35.0)


def _pixel(img: np.ndarray, xy) -> np.ndarray:
    x, y = int(np.floor(xy[0])), int(np.floor(xy[1]))
    return img[y, x].astype(int)


def test_project_points_centre_axes_and_depth():
    cam = Camera((0.0, 1.0, 5.0), (0.0, 1.0, 0.0), (0, 1, 0), 30.0)
    pts = np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 10.0]])
    pix, depth = project_points(pts, cam, (200, 100))
    np.testing.assert_allclose(pix[0], (100.0, 50.0))
    assert pix[1, 1] < 50.0  # +Y is up in the image
    assert pix[2, 0] > 100.0  # +X is to the right when looking down -Z
    np.testing.assert_allclose(depth[:3], 5.0)
    assert depth[3] < 0  # behind the camera
    # 1 m at 5 m distance spans f / 5 pixels, with f = (H/2) / tan(fov/2)
    f = 50.0 / np.tan(np.radians(15.0))
    assert pix[0, 1] - pix[1, 1] == pytest.approx(f / 5.0)


def test_follow_camera_tracks_root_and_fixed_camera_sees_every_joint():
    motion = synthetic_motion(SKEL, 30)
    cam0, cam1 = follow_camera([motion], 0), follow_camera([motion], 29)
    assert cam1.focal_point[2] - cam0.focal_point[2] > 1.0  # follows the walk along +Z
    assert np.allclose(np.subtract(cam1.position, cam1.focal_point), np.subtract(cam0.position, cam0.focal_point))
    cam = fixed_camera([motion], view="side", aspect=SIZE[0] / SIZE[1])
    pix, depth = project_points(motion.reshape(-1, 3), cam, SIZE)
    assert (depth > 0).all()
    assert (pix[:, 0] >= 0).all() and (pix[:, 0] < SIZE[0]).all()
    assert (pix[:, 1] >= 0).all() and (pix[:, 1] < SIZE[1]).all()


def test_raster_image_has_bones_in_chain_colours_where_the_projection_puts_them():
    motion = _tpose_motion()
    before = motion.copy()
    cam = _front_camera(motion)
    img = rasterize_skeleton(motion, SKEL, 0, camera=cam, size=SIZE, bone_radius=0.05, joint_radius=0.05,
                             trajectory=False)
    np.testing.assert_array_equal(motion, before)
    assert img.shape == (SIZE[1], SIZE[0], 3) and img.dtype == np.uint8
    expected = to_uint8(bone_colors(SKEL))
    checked = set()
    for child in (SKEL.joint_names.index(n) for n in ("left_knee", "right_knee", "spine2", "left_elbow",
                                                        "right_elbow")):
        parent = SKEL.parents[child]
        mid = 0.5 * (motion[0, child] + motion[0, parent])
        pix, _ = project_points(mid, cam, SIZE)
        assert np.abs(_pixel(img, pix) - expected[child]).max() <= 6, SKEL.joint_names[child]
        checked.add(tuple(expected[child]))
    assert len(checked) == 5  # five chains, five distinct colours


def test_raster_left_is_blue_right_is_red_and_character_faces_front_camera():
    motion = _tpose_motion()
    cam = _front_camera(motion)
    img = rasterize_skeleton(motion, SKEL, 0, camera=cam, size=SIZE, bone_radius=0.04, trajectory=False,
                             floor=False)
    lw = project_points(motion[0, SKEL.joint_names.index("left_elbow")], cam, SIZE)[0]
    rw = project_points(motion[0, SKEL.joint_names.index("right_elbow")], cam, SIZE)[0]
    assert lw[0] > rw[0]  # seen from the front, the character's left is on the image's right
    left, right = _pixel(img, lw), _pixel(img, rw)
    assert left[2] > left[0] + 60 and right[0] > right[2] + 60
    sides = chain_sides(SKEL)
    assert sorted(sides) == ["left", "left", "mid", "right", "right"]
    assert len({tuple(c) for c in chain_palette(SKEL)}) == len(sides)


def test_raster_floor_background_and_up_direction():
    motion = _tpose_motion()
    cam = _front_camera(motion)
    img = rasterize_skeleton(motion, SKEL, 0, camera=cam, size=SIZE, trajectory=False)
    floors = {tuple(to_uint8(FLOOR_LIGHT)), tuple(to_uint8(FLOOR_DARK))}
    # a floor point 1 m in front of the feet is drawn in a floor colour (the tile interior)
    spot = np.array([0.25, 0.0, 1.25])
    assert tuple(_pixel(img, project_points(spot, cam, SIZE)[0])) in floors
    # sky above the head is background; the head projects above the feet (+Y up)
    head = project_points(motion[0, SKEL.joint_names.index("head")], cam, SIZE)[0]
    foot = project_points(motion[0, SKEL.joint_names.index("left_foot")], cam, SIZE)[0]
    assert head[1] < foot[1] - 80
    assert tuple(img[2, 2]) == tuple(to_uint8(BACKGROUND))
    # figure pixels: neither background nor floor
    flat = img.reshape(-1, 3)
    other = ~np.isin(flat.view([("", flat.dtype)] * 3).ravel(),
                     np.array(list(floors) + [tuple(to_uint8(BACKGROUND))], dtype=np.uint8).view([("", np.uint8)] * 3).ravel())
    assert 0.01 < other.mean() < 0.4


def test_raster_several_motions_use_distinct_themes_and_joint_colors_override():
    a = _tpose_motion()
    b = a + np.array([0.9, 0.0, 0.0])
    cam = Camera((0.45, 0.9, 4.5), (0.45, 0.85, 0.0), (0, 1, 0), 40.0)
    img = rasterize_skeleton([a, b], SKEL, 0, camera=cam, size=(240, 200), bone_radius=0.05, trajectory=False)
    knee = SKEL.joint_names.index("left_knee")
    mids = [0.5 * (m[0, knee] + m[0, SKEL.parents[knee]]) for m in (a, b)]
    got = [_pixel(img, project_points(p, cam, (240, 200))[0]) for p in mids]
    want = [to_uint8(bone_colors(SKEL, theme=k))[knee] for k in (0, 1)]
    for g, w in zip(got, want):
        assert np.abs(g - w).max() <= 6
    assert np.abs(want[0].astype(int) - want[1]).max() > 60
    red = np.zeros((SKEL.num_joints, 3))
    red[:, 0] = 1.0
    img2 = rasterize_skeleton(a, SKEL, 0, camera=cam, size=(240, 200), bone_radius=0.05, joint_colors=red)
    assert tuple(_pixel(img2, project_points(mids[0], cam, (240, 200))[0])) == (255, 0, 0)


def test_raster_real_motion_every_view_is_non_blank(sample_joints):
    for view in ("front", "three_quarter", "side", "top", 120.0):
        img = rasterize_skeleton(sample_joints, SKEL, 40, view=view, size=(96, 96), supersample=1)
        figure = (np.abs(img.astype(int) - img[0, 0]).sum(-1) > 60).mean()
        assert figure > 0.05, view


def test_raster_input_errors_name_the_problem():
    with pytest.raises(ValueError, match=r"J = 22 for skeleton 'humanml3d'"):
        rasterize_skeleton(np.zeros((4, 21, 3)), SKEL)
    with pytest.raises(ValueError, match="frame=9 is out of range for a motion of 5 frames"):
        rasterize_skeleton(_tpose_motion(), SKEL, 9)
    bad = _tpose_motion()
    bad[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf .*frame 2, joint 3"):
        rasterize_skeleton(bad, SKEL)
    with pytest.raises(ValueError, match="view 'diagonal' is not known"):
        rasterize_skeleton(_tpose_motion(), SKEL, view="diagonal")
    with pytest.raises(ValueError, match="at least 8x8"):
        rasterize_skeleton(_tpose_motion(), SKEL, size=(4, 100))


def test_hstack_pads_to_tallest():
    a = np.zeros((10, 4, 3), np.uint8)
    b = np.zeros((6, 5, 3), np.uint8)
    out = hstack_images([a, b], gap=2)
    assert out.shape == (10, 11, 3)
    assert (out[6:, 6:] == 255).all() and (out[:, 4:6] == 255).all()


def test_joint_inputs_one_motion_lists_batches_and_tensors():
    from salad_viz._arrays import as_joints_list

    motion = _tpose_motion(3)
    assert [m.shape for m in as_joints_list(motion, SKEL)] == [(3, 22, 3)]
    assert [m.shape for m in as_joints_list(motion.tolist(), SKEL)] == [(3, 22, 3)]  # nested lists: one motion
    assert [m.shape for m in as_joints_list([motion, motion[:2]], SKEL)] == [(3, 22, 3), (2, 22, 3)]
    assert [m.shape for m in as_joints_list([motion[0], motion[1]], SKEL)] == [(1, 22, 3), (1, 22, 3)]
    assert len(as_joints_list(np.stack([motion, motion]), SKEL)) == 2  # (M, N, J, 3) batch
    out = as_joints_list(motion, SKEL)[0]
    out[0, 0, 0] = 99.0
    assert motion[0, 0, 0] != 99.0  # validated copies, never views of the input
    torch = pytest.importorskip("torch")
    img = rasterize_skeleton(torch.as_tensor(motion), SKEL, 0, size=(32, 32))
    np.testing.assert_array_equal(img, rasterize_skeleton(motion, SKEL, 0, size=(32, 32)))
