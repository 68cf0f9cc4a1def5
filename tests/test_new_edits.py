"""Edits beyond the paper (Erase, Shift, ExampleBased) and repetition counting: specs, pure kernels,
invariants through the pipeline, composition order, and the measuring script."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from _doubles import rest_pose
from salad_core.attention import CaptureConfig, EditController, Mirror, Reweight, TokenInfo, WordSwap, validate_edits
from salad_core.attention.counting import (attention_signal, count_peaks, count_repetitions, motion_repetitions,
                                           motion_signal)
from salad_core.attention.edits import (Erase, ExampleBased, Shift, ShiftTemporal, erase_columns, reweight_columns,
                                        seeded_noise, shift_columns, shift_temporal)
from salad_core.sampling import StepInfo
from salad_core.skeleton import PART_NAMES, get_skeleton

STEPS = 8
SRC = "a man waves his right hand and then jumps"
PIPE_SEED = 3  # seed of the tiny pipeline, conftest's `pipe` fixture

pytestmark = pytest.mark.usefixtures("single_thread")


def _probs(*shape, seed=0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    m = torch.rand(*shape, generator=g)
    return m / m.sum(-1, keepdim=True)


# ------------------------------------------------------------------------------ specs
def test_new_specs_validate_on_construction():
    assert Erase("waves").words == ("waves",) and Erase((2, 6)).words == ((2, 6),)
    assert Erase("waves").mode == "special"
    assert Erase(["Waves  his", (0, 1)]).words == ("waves his", (0, 1))
    with pytest.raises(ValueError, match="empty"):
        Erase(())
    with pytest.raises(ValueError, match="neither a word"):
        Erase((3, 1))
    with pytest.raises(ValueError, match=r"Erase.mode='gone'; allowed: \('special', 'others', 'zero'\)"):
        Erase("waves", mode="gone")
    with pytest.raises(ValueError, match="Erase.steps"):
        Erase("waves", steps=(0.5, 0.5))
    assert Shift("jumps", 20).latent_frames == 5 and Shift("jumps", -8).latent_frames == -2
    with pytest.raises(ValueError, match="Shift.frames=10 is not a multiple of unit_length=4.*use 8 or 12"):
        Shift("jumps", 10)
    with pytest.raises(TypeError, match="Shift.frames must be an int"):
        Shift("jumps", 4.0)
    with pytest.raises(TypeError, match="keep_sums must be a bool"):
        Shift("jumps", 4, keep_sums=1)
    assert ExampleBased(3).edited_seed == 3 and Erase("x").edited_seed is None
    with pytest.raises(ValueError, match="ExampleBased.seed=-1"):
        ExampleBased(-1)
    with pytest.raises(ValueError, match="ExampleBased.kinds"):
        ExampleBased(1, kinds=("cross",))
    with pytest.raises(ValueError, match="at most one edit may give the edited sample its own noise"):
        validate_edits([ExampleBased(1), ExampleBased(2)])
    with pytest.raises(ValueError, match="must come before the modifiers"):
        validate_edits([Shift("a", 4), WordSwap()])


def test_erase_errors_name_the_word_and_the_prompt(pipe):
    with pytest.raises(ValueError, match=r"Erase word 'kicks' is not in the prompt 'a man walks'; its words are"):
        pipe.edit("a man walks", edits=[Erase("kicks")], lengths=40, num_steps=2)
    with pytest.raises(ValueError, match=r"Shift word \(5, 9\) is not in the prompt"):
        pipe.edit("a man walks", edits=[Shift((5, 9), 4)], lengths=40, num_steps=2)


# ------------------------------------------------------------------------------ kernels
@pytest.mark.parametrize("mode", ["others", "special", "zero"])
def test_erase_kernel_empties_the_columns_and_moves_their_mass(mode):
    maps = _probs(2, 2, 6, 7, 5)
    before = maps.clone()
    cols = [[1], [2, 3]]
    receivers = {"others": [[0, 2, 3, 4], [0, 1, 4]], "special": [[0, 4], [0, 4]], "zero": None}[mode]
    out = erase_columns(maps, cols, receivers)
    assert torch.equal(maps, before)                                           # pure
    assert out[0, ..., 1].abs().max() == 0 and out[1, ..., 2:4].abs().max() == 0
    if mode == "zero":
        torch.testing.assert_close(out, reweight_columns(maps, cols, 0.0, per_row=True))
    else:
        torch.testing.assert_close(out.sum(-1), maps.sum(-1))                 # rows stay probabilities
    if mode == "special":                                                      # only [CLS]/[SEP] gained
        torch.testing.assert_close(out[0, ..., [2, 3]], maps[0, ..., [2, 3]])
        assert (out[0, ..., [0, 4]] > maps[0, ..., [0, 4]]).all()
    if mode == "others":                                                       # proportional: ratios kept
        torch.testing.assert_close(out[1, ..., 0] / out[1, ..., 4], maps[1, ..., 0] / maps[1, ..., 4])


def test_shift_kernel_moves_the_columns_along_frames():
    maps = _probs(2, 2, 6, 7, 5, seed=1)
    assert torch.equal(shift_columns(maps, [[1], [2]], 0), maps)
    out = shift_columns(maps, [[1], [2, 3]], 2, keep_sums=False)
    assert torch.equal(out[0, :, 2:, :, 1], maps[0, :, :4, :, 1]) and out[0, :, :2, :, 1].abs().max() == 0
    assert torch.equal(out[1, :, 2:, :, 2:4], maps[1, :, :4, :, 2:4])
    assert torch.equal(out[0, ..., [0, 2, 3, 4]], maps[0, ..., [0, 2, 3, 4]])  # other columns untouched
    back = shift_columns(maps, [[1], [2]], -3, keep_sums=False)
    assert torch.equal(back[0, :, :3, :, 1], maps[0, :, 3:, :, 1]) and back[0, :, 3:, :, 1].abs().max() == 0
    kept = shift_columns(maps, [[1], [2]], 2)
    torch.testing.assert_close(kept.sum(-1), maps.sum(-1))                    # every query keeps its total
    torch.testing.assert_close(kept[0, :, 2:, :, 1], maps[0, :, :4, :, 1])
    gone = shift_columns(maps, [[1], [2]], 6, keep_sums=False)                 # past the end: nothing left
    assert gone[0, ..., 1].abs().max() == 0


def test_shift_temporal_kernel_slides_the_parts_maps():
    maps = _probs(1, 7, 2, 6, 6, seed=3)                       # (B, P, H, N', N')
    assert torch.equal(shift_temporal(maps, [5], 0), maps)
    out = shift_temporal(maps, [5, 6], 2)
    assert torch.equal(out[:, :5], maps[:, :5])                # other parts as they were
    torch.testing.assert_close(out.sum(-1), maps.sum(-1))     # rows stay probabilities
    # inside, query t and key s take the source's (t - 2, s - 2) up to the row's re-normalisation
    ratio = out[0, 5, :, 2:, 2:] / maps[0, 5, :, :4, :4]
    torch.testing.assert_close(ratio, ratio[..., :1].expand_as(ratio))
    assert out[0, 5, :, :, :2].abs().max() == 0               # keys before the shift get nothing
    with pytest.raises(ValueError, match="ShiftTemporal.parts"):
        ShiftTemporal(("tail",), 4)
    with pytest.raises(ValueError, match="not a multiple of unit_length"):
        ShiftTemporal(("head",), 6)


def test_shift_temporal_hands_the_moved_source_maps_to_the_edit(pipe):
    cap = CaptureConfig(mode="full", self_attention=True)
    out = pipe.edit(SRC, edits=[Shift("jumps", 8), ShiftTemporal(("left leg", "right leg"), 8, steps=(0.0, 0.5))],
                    lengths=40, num_steps=STEPS, seed=1, capture_attention=cap)
    src, ed = out.source.attention.full(0, "temporal"), out.edited.attention.full(0, "temporal")  # (S, L, H, P, N', N')
    half = STEPS // 2
    as_rows = lambda a: torch.from_numpy(a[:half].astype(np.float32)).flatten(0, 2).unsqueeze(2)  # (SLH, P, 1, N', N')
    want, got = shift_temporal(as_rows(src), [1, 2], 2), as_rows(ed)
    torch.testing.assert_close(got, want, atol=2e-3, rtol=0)   # float16 storage
    assert (out.edited.latents - out.source.latents).abs().max() > 1e-3


def test_seeded_noise_is_the_pipelines_noise(pipe):
    torch.testing.assert_close(seeded_noise(7, (2, 10, 7, 32)), pipe.make_noise([7, 8], 10), atol=0, rtol=0)


# ------------------------------------------------------------------------ invariants
def test_zero_edits_equal_plain_sampling(pipe):
    plain = pipe(SRC, lengths=40, num_steps=STEPS, seed=5)
    for edits in ([Shift("jumps", 0)], [Erase("waves", steps=(0.99, 1.0))], [Shift("jumps", 8, steps=(0.99, 1.0))]):
        out = pipe.edit(SRC, edits=edits, lengths=40, num_steps=STEPS, seed=5)
        torch.testing.assert_close(out.source.latents, plain.latents, atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(out.edited.latents, plain.latents, atol=1e-5, rtol=1e-5)
    for edits in ([Shift("jumps", 8)], [Erase("waves his right hand")], [Erase((2, 6), mode="special")]):
        out = pipe.edit(SRC, edits=edits, lengths=40, num_steps=STEPS, seed=5)
        torch.testing.assert_close(out.source.latents, plain.latents, atol=1e-5, rtol=1e-5)
        assert (out.edited.latents - out.source.latents).abs().max() > 1e-3, edits


def test_example_based_starts_from_its_own_noise(pipe):
    example = pipe(SRC, lengths=40, num_steps=STEPS, seed=0)
    other = pipe(SRC, lengths=40, num_steps=STEPS, seed=11)
    # a window that holds no step: the edited sample is the plain sample of seed 11
    idle = pipe.edit(SRC, edits=[ExampleBased(11, steps=(0.99, 1.0))], lengths=40, num_steps=STEPS, seed=0)
    torch.testing.assert_close(idle.source.latents, example.latents, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(idle.edited.latents, other.latents, atol=1e-5, rtol=1e-5)
    # each branch reports the noise and seeds it started from
    torch.testing.assert_close(idle.edited.noise, other.noise)
    assert idle.edited.seeds == [11] and idle.source.seeds == [0]
    torch.testing.assert_close(idle.source.noise, example.noise)
    var = pipe.edit(SRC, edits=[ExampleBased(11)], lengths=40, num_steps=STEPS, seed=0)
    torch.testing.assert_close(var.source.latents, example.latents, atol=1e-5, rtol=1e-5)
    assert (var.edited.latents - other.latents).abs().max() > 1e-3            # the example's maps acted
    assert (var.edited.latents - example.latents).abs().max() > 1e-3          # and it is not the example
    # two seeds give two different variations
    var2 = pipe.edit(SRC, edits=[ExampleBased(12)], lengths=40, num_steps=STEPS, seed=0)
    assert (var2.edited.latents - var.edited.latents).abs().max() > 1e-3


def test_example_based_uses_the_examples_temporal_maps_exactly(pipe):
    cap = CaptureConfig(mode="full", self_attention=True)
    out = pipe.edit(SRC, edits=[ExampleBased(4, steps=(0.0, 0.5))], lengths=40, num_steps=STEPS, seed=1,
                    capture_attention=cap)
    src, ed = out.source.attention.full(0, "temporal"), out.edited.attention.full(0, "temporal")
    half = STEPS // 2
    assert np.array_equal(ed[:half], src[:half])
    assert np.abs(ed[half:].astype(np.float32) - src[half:].astype(np.float32)).max() > 1e-3


def test_example_based_varies_an_inverted_motion(pipe):
    ref = pipe(SRC, lengths=40, num_steps=STEPS, seed=2)
    inv = pipe.invert(ref.features[0, :40], SRC, method="ddim", num_steps=STEPS, reconstruct=False)
    out = pipe.edit(inversion=inv, edits=[ExampleBased(9)])
    rec = pipe.reconstruct(inv)
    torch.testing.assert_close(out.source.latents, rec.latents, atol=1e-4, rtol=1e-4)   # the example, exactly
    assert (out.edited.latents - out.source.latents).abs().max() > 1e-3


def test_captured_maps_show_erase_and_shift_exactly(pipe):
    cap = CaptureConfig(mode="full")
    shifted = pipe.edit(SRC, edits=[Shift("jumps", 8, keep_sums=False)], lengths=40, num_steps=STEPS, seed=1,
                        capture_attention=cap)
    src, ed = shifted.source.attention.full(0), shifted.edited.attention.full(0)   # (S, L, H, N', P, W)
    cols = shifted.source.attention.word_columns(0, "jumps")
    np.testing.assert_array_equal(ed[:, :, :, 2:][..., cols], src[:, :, :, :-2][..., cols])
    assert np.abs(ed[:, :, :, :2][..., cols]).max() == 0
    erased = pipe.edit(SRC, edits=[Erase("waves", mode="others")], lengths=40, num_steps=STEPS, seed=1,
                       capture_attention=cap)
    src, ed = erased.source.attention.full(0).astype(np.float32), erased.edited.attention.full(0).astype(np.float32)
    cols = erased.source.attention.word_columns(0, "waves")
    assert np.abs(ed[..., cols]).max() == 0
    np.testing.assert_allclose(ed.sum(-1), src.sum(-1), atol=3e-3)            # float16 storage


def test_composition_applies_the_modifiers_in_order(pipe):
    text = pipe.text_encoder.encode([SRC])
    info = TokenInfo.from_batch(text)
    width = text.features.shape[1]
    maps = _probs(1, 2, 6, 7, width, seed=2)
    cols = [info.word_columns(0, "jumps")]
    step = StepInfo(0, STEPS, 980.0, True, 1)

    def composed(edits):
        ctrl = EditController(edits, info, info, width, cfg=True)
        ctrl.on_step(step)
        return ctrl.edit_cross(maps, None)

    shift_then_scale = composed([Shift("jumps", 8), Reweight("jumps", 2.0)])
    shifted = shift_columns(maps, cols, 2)
    torch.testing.assert_close(shift_then_scale, reweight_columns(shifted, cols, 2.0, per_row=True))
    scale_then_shift = composed([Reweight("jumps", 2.0), Shift("jumps", 8)])
    scaled = reweight_columns(maps, cols, 2.0, per_row=True)
    torch.testing.assert_close(scale_then_shift, shift_columns(scaled, cols, 2))
    assert (shift_then_scale - scale_then_shift).abs().max() > 1e-3           # these two do not commute
    # erasing acts on columns, mirroring on rows: either order gives the same map
    torch.testing.assert_close(composed([Erase("jumps"), Mirror("arms")]), composed([Mirror("arms"), Erase("jumps")]))


# ------------------------------------------------------------------------------ counting
def _bumps(k: int, n: int = 120, width: int = 10) -> np.ndarray:
    """``k`` raised-cosine bumps separated by rests, ``(n,)``."""
    x = np.zeros(n)
    centres = np.linspace(0, n, k + 2)[1:-1]
    t = np.arange(n)
    for c in centres:
        d = np.abs(t - c)
        x += np.where(d < width, 0.5 * (1 + np.cos(np.pi * d / width)), 0.0)
    return x


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_count_peaks_counts_bumps(k):
    rng = np.random.default_rng(k)
    assert count_peaks(_bumps(k)) == k
    assert count_peaks(_bumps(k) + 0.02 * rng.standard_normal(120), smooth=1.0) == k
    assert count_peaks(np.ones(30)) == 0 and count_peaks([]) == 0
    with pytest.raises(ValueError, match="prominence"):
        count_peaks(_bumps(k), prominence=0.0)


def test_count_repetitions_reads_the_words_attention():
    class Maps:                      # the two things count_repetitions asks of AttentionMaps
        unit_length = 4

        def word_map(self, b, word):
            m = np.full((len(PART_NAMES), 30), 0.01)
            m[PART_NAMES.index("right arm")] += 0.5 * _bumps(3, 30, 3)
            return m

    maps = Maps()
    assert count_repetitions(maps, "jumps", parts=["right arm"]) == 3
    assert attention_signal(maps, "jumps").shape == (30,)
    assert count_repetitions(maps, "jumps", parts=["right arm"], frames=(0, 40)) == 1     # first 10 latent frames
    with pytest.raises(ValueError, match="must be a non-empty list"):
        count_repetitions(maps, "jumps", parts=["tail"])


@pytest.mark.parametrize("k", [1, 2, 3])
def test_motion_repetitions_counts_kicks_and_squats(k):
    sk = get_skeleton()
    pose = rest_pose()
    n = 120
    b = _bumps(k, n, 8)
    kick = np.repeat(pose[None], n, 0)
    leg = [j for j, p in enumerate(sk.joint_to_part) if PART_NAMES[p] == "left leg"]
    hip = pose[sk.joint_names.index("left_hip")]
    for j in leg:                                           # swing forward, more the further from the hip
        kick[:, j, 2] += 0.6 * b * np.linalg.norm(pose[j] - hip)
    assert motion_repetitions(kick, ["left leg"]) == k
    squat = np.repeat(pose[None], n, 0)
    upper = [j for j, p in enumerate(sk.joint_to_part) if PART_NAMES[p] not in ("left leg", "right leg")]
    squat[:, upper, 1] -= 0.3 * b[:, None]                 # the pelvis goes down and back up: troughs
    assert motion_signal(squat, ["root"]).max() > 0.1        # made positive: excursions are peaks
    assert motion_repetitions(squat, ["root"]) == k
    assert motion_repetitions(kick, ["left leg"], frames=(0, n // 2)) == (k + 1) // 2    # the first half


# ------------------------------------------------------------------ the measuring script
# ------------------------------------------------------------------------ mirrored self-attention
def test_mirror_self_attention_kernel_relabels_parts():
    from salad_core.attention.edits import MirrorSelfAttention, mirror_permutation, mirror_self_attention

    perm = mirror_permutation("all", 7)
    temporal = _probs(2, 7, 2, 5, 5, seed=4)                          # (B, P, H, N', N')
    out = mirror_self_attention(temporal, "temporal", "all")
    for j in range(7):
        assert torch.equal(out[:, j], temporal[:, perm[j]])
    skeletal = _probs(2, 5, 2, 7, 7, seed=5)                          # (B, N', H, P, P)
    out = mirror_self_attention(skeletal, "skeletal", "all")
    for i in range(7):
        for k in range(7):
            assert torch.equal(out[..., i, k], skeletal[..., perm[i], perm[k]])
    torch.testing.assert_close(out.sum(-1), skeletal.sum(-1)[..., perm])     # rows stay probabilities
    for kind, maps in (("temporal", temporal), ("skeletal", skeletal)):
        assert torch.equal(mirror_self_attention(mirror_self_attention(maps, kind, "legs"), kind, "legs"), maps)
    legs = mirror_self_attention(temporal, "temporal", "legs")
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    assert torch.equal(legs[:, arms], temporal[:, arms])                       # "legs" leaves the arms alone
    with pytest.raises(ValueError, match="self-attention kinds"):
        mirror_self_attention(temporal, "cross", "all")
    with pytest.raises(ValueError, match="Mirror.parts"):
        MirrorSelfAttention("tails")
    with pytest.raises(ValueError, match="MirrorSelfAttention.kinds"):
        MirrorSelfAttention("all", kinds=("cross",))
    assert MirrorSelfAttention("lower").parts == "legs"


def test_mirror_self_attention_hands_the_mirrored_source_maps_to_the_edit(pipe):
    from salad_core.attention.edits import MirrorSelfAttention, mirror_self_attention

    cap = CaptureConfig(mode="full", self_attention=True)
    out = pipe.edit(SRC, edits=[Mirror("all"), MirrorSelfAttention("all", steps=(0.0, 0.5))], lengths=40,
                    num_steps=STEPS, seed=1, capture_attention=cap)
    half = STEPS // 2
    # captured maps (S, L, H, ...) -> (S L H, ...) with a head axis of one at 2: temporal (., P, 1, N', N'),
    # skeletal (., N', 1, P, P), the kernel's layouts
    as_rows = lambda a: torch.from_numpy(a[:half].astype(np.float32)).flatten(0, 2).unsqueeze(2)
    for kind in ("temporal", "skeletal"):
        src, ed = out.source.attention.full(0, kind), out.edited.attention.full(0, kind)
        want = mirror_self_attention(as_rows(src), kind, "all")
        torch.testing.assert_close(as_rows(ed), want, atol=2e-3, rtol=0)             # float16 storage
        later = np.abs(ed[half:].astype(np.float32) - src[half:].astype(np.float32)).max()
        assert later > 1e-3, kind                                          # after the window: its own maps
    plain = pipe.edit(SRC, edits=[Mirror("all")], lengths=40, num_steps=STEPS, seed=1)
    assert (out.edited.latents - plain.edited.latents).abs().max() > 1e-3  # the self-attention acted
    torch.testing.assert_close(out.source.latents, plain.source.latents, atol=1e-5, rtol=1e-5)
