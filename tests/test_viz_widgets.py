"""salad_viz.widgets: the explorer's controls drive the map, the heatmap and the skeleton together."""
from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

pytest.importorskip("ipywidgets")

from salad_core.skeleton import PART_NAMES, get_skeleton
from salad_viz.attention import reduce_attention
from salad_viz.synthetic import synthetic_motion
from salad_viz.widgets import explore_attention

SKEL = get_skeleton("humanml3d")
TOKENS = ["[CLS]", "a", "person", "walks", "and", "waves", "[SEP]"]
S, L, NL = 6, 3, 5  # steps, layers, latent frames


def _png_array(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


@pytest.fixture
def explorer():
    rng = np.random.default_rng(0)
    att = rng.random((S, L, NL, len(PART_NAMES), len(TOKENS)))  # s l n p w
    # 'walks' (token 3): legs only, and only in layer 2 of the late steps
    att[3:, 2, :, :, 3] = 0.0
    att[3:, 2, :, [1, 2], 3] = 5.0
    joints = synthetic_motion(SKEL, NL * 4)
    ex = explore_attention(att, TOKENS, joints, SKEL, axes="slnpw", backend="raster", size=(120, 100))
    yield ex, att
    ex.close()


def test_controls_reflect_the_data(explorer):
    ex, _ = explorer
    assert [label for label, _ in ex.words.options] == ["1: a", "2: person", "3: walks", "4: and", "5: waves"]
    assert ex.layers.value == (0, 1, 2)
    assert (ex.steps.min, ex.steps.max) == (0, S - 1)
    assert ex.frame.max == NL * 4 - 1
    assert ex.heatmap.value[:4] == b"\x89PNG" and ex.skeleton_view.value[:4] == b"\x89PNG"


def test_selection_changes_the_map_like_reduce_attention(explorer):
    ex, att = explorer
    ex.words.value = ((3,), (5,))  # 'walks' + 'waves' are summed
    full = reduce_attention(att, "slnpw")
    np.testing.assert_allclose(ex.selected_map, full[:, :, 3] + full[:, :, 5])
    ex.words.value = ((3,),)
    ex.layers.value = (2,)
    ex.steps.value = (3, 5)
    np.testing.assert_allclose(ex.selected_map, reduce_attention(att, "slnpw", steps=(3, 6), layers=2)[:, :, 3])
    legs = [PART_NAMES.index("left leg"), PART_NAMES.index("right leg")]
    assert ex.selected_map[legs].min() == 5.0 and np.delete(ex.selected_map, legs, axis=0).max() == 0.0


def test_views_update_together_and_joints_show_the_attention(explorer):
    ex, _ = explorer
    ex.words.value = ((3,),)
    ex.layers.value = (2,)
    ex.steps.value = (3, 5)
    heat0, skel0 = ex.heatmap.value, ex.skeleton_view.value
    ex.frame.value = 10
    assert ex.heatmap.value != heat0 and ex.skeleton_view.value != skel0  # cursor moved, pose moved
    img = _png_array(ex.skeleton_view.value).reshape(-1, 3).astype(int)
    # legs carry all the attention: viridis yellow (253, 231, 37) on the legs, dark purple elsewhere
    yellow = (np.abs(img - [253, 231, 37]).max(axis=1) < 40).sum()
    purple = (np.abs(img - [68, 1, 84]).max(axis=1) < 40).sum()
    assert yellow > 20 and purple > 20


def test_empty_selection_reports_instead_of_failing(explorer):
    ex, _ = explorer
    before = ex.heatmap.value
    ex.layers.value = ()
    assert ex.status.value == "select at least one layer"
    assert ex.heatmap.value == before
    ex.layers.value = (0,)
    assert ex.status.value == ""


def test_token_count_mismatch_is_an_error():
    att = np.ones((NL, len(PART_NAMES), 3))
    with pytest.raises(ValueError, match="tokens has 7 entries but attention has W = 3"):
        explore_attention(att, TOKENS, synthetic_motion(SKEL, 8), SKEL, axes="npw", backend="raster")
