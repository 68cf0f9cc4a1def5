"""No network at run time, and determinism: generation, editing, capture and rendering with sockets
disabled; the same seed gives bit-identical motions across calls."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def tiny_pipe(make_tiny_pipeline):
    return make_tiny_pipeline(seed=0)


def test_everything_runs_without_network(tiny_pipe, tmp_path):
    import pytest_socket

    from salad_core.attention import Mirror
    from salad_core.text import clear_text_encoder_cache, load_text_encoder
    from salad_viz import animate, rasterize_skeleton

    import urllib3  # noqa: F401  (its import probes IPv6 support by creating a socket: no traffic)

    pytest_socket.disable_socket()
    try:
        clear_text_encoder_cache()
        tiny_pipe.text_encoder = load_text_encoder("minilm")   # loads from the installed package only
        out = tiny_pipe("a person waves his left hand", lengths=40, num_steps=3, capture_attention=True)
        assert out.attention.cross_map(0).shape[0] == 7
        edit = tiny_pipe.edit("a person waves his left hand", edits=[Mirror(parts="arms")], lengths=40, num_steps=3)
        assert edit.edited.joints[0].shape == (40, 22, 3)
        img = rasterize_skeleton(out.joints[0], "humanml3d", frame=0, size=(64, 64))
        assert img.shape == (64, 64, 3)
        assert animate(out.joints[0], "humanml3d", tmp_path / "a.gif", size=(64, 64), stride=8, backend="raster").is_file()
    finally:
        pytest_socket.enable_socket()


def test_same_seed_is_bit_identical(tiny_pipe):
    a = tiny_pipe(["a man jumps high", "a person walks"], lengths=[40, 48], seed=7, num_steps=4)
    b = tiny_pipe(["a man jumps high", "a person walks"], lengths=[40, 48], seed=7, num_steps=4)
    assert np.array_equal(a.features, b.features)
    assert all(np.array_equal(x, y) for x, y in zip(a.joints, b.joints))
    c = tiny_pipe(["a man jumps high", "a person walks"], lengths=[40, 48], seed=8, num_steps=4)
    assert not np.array_equal(a.features, c.features)
