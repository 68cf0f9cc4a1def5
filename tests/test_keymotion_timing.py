"""Keyframe timing (KeyframeVAEConfig.timing): positions relative to each motion's length or absolute frames."""
import pytest
import torch

from salad_core.keymotion.kf_vae import (KeyframeVAE, KeyframeVAEConfig, indices_to_positions,
                                         positions_to_indices)

pytestmark = pytest.mark.usefixtures("single_thread")

SMALL = dict(num_keyframes=6, max_length=96, frame_dim=32, index_dim=8, latent_dim=16, num_layers=1, ff_dim=64)


def test_positions_round_trip_relative_and_absolute():
    idx = torch.tensor([[0, 5, 17, 39], [0, 20, 60, 95]])
    lengths = torch.tensor([40, 96])
    rel = indices_to_positions(idx, lengths)
    torch.testing.assert_close(rel[:, -1], torch.ones(2))                       # last frame -> 1 whatever L
    ab = indices_to_positions(idx, lengths, span=95)
    torch.testing.assert_close(ab[0], idx[0].float() / 95)                     # frame / span: the 40-frame motion
    assert float(ab[0, -1]) == pytest.approx(39 / 95)                         # ends at 39/95, not at 1
    assert torch.equal(positions_to_indices(rel, lengths), idx)
    assert torch.equal(positions_to_indices(ab, lengths, span=95), idx)


def test_absolute_positions_keep_the_pace_at_another_length():
    """The same decoded positions give the same frames at any length (only the last keyframe moves to L - 1);
    relative positions scale every keyframe with the length."""
    pos = torch.tensor([[0.0, 0.05, 0.1, 0.2, 0.3]])                            # a 0.3 x 95 = 28-frame clip's
    short, long = torch.tensor([29]), torch.tensor([96])
    a_short = positions_to_indices(pos, short, span=95)
    a_long = positions_to_indices(pos, long, span=95)
    assert a_short.tolist() == [[0, 5, 10, 19, 28]]
    assert a_long.tolist() == [[0, 5, 10, 19, 95]]                             # pace kept, last at L - 1
    r_long = positions_to_indices(pos / 0.3, long)                            # the relative reading of that clip
    assert r_long.tolist() == [[0, 16, 32, 63, 95]]                            # every keyframe stretched 3.3x


@pytest.mark.parametrize("span, lengths, message", [(0, [10], "span=0"), (2.5, [10], "span=2.5"),
                                                    (True, [10], "span=True"), (20, [30], "exceed span")])
def test_bad_span_is_refused(span, lengths, message):
    with pytest.raises(ValueError, match=message):
        indices_to_positions(torch.tensor([[0, 9]]), torch.tensor(lengths), span=span)


def test_config_rejects_unknown_timing():
    with pytest.raises(ValueError, match="timing='frames'"):
        KeyframeVAEConfig(timing="frames")


def test_decoded_positions_relative_end_at_one_absolute_at_most_one():
    torch.manual_seed(0)
    z = torch.randn(4, 2, 16)
    rel = KeyframeVAE(KeyframeVAEConfig(**SMALL)).eval()
    ab = KeyframeVAE(KeyframeVAEConfig(timing="absolute", **SMALL)).eval()
    ab.load_state_dict(rel.state_dict())                                      # same weights, other timing
    with torch.no_grad():
        p_rel, p_abs = rel.decode(z).positions, ab.decode(z).positions
    for p in (p_rel, p_abs):
        assert torch.all(p[:, 0] == 0) and torch.all(p[:, 1:] > p[:, :-1])
    torch.testing.assert_close(p_rel[:, -1], torch.ones(4))
    assert torch.all(p_abs[:, -1] < 1) and torch.all(p_abs[:, -1] > 0)
    assert rel.position_span is None and ab.position_span == 95
    idx, lengths = torch.tensor([[0, 3, 9, 20, 30, 39]]), torch.tensor([40])
    torch.testing.assert_close(ab.positions_of(idx, lengths), idx.float() / 95)
    torch.testing.assert_close(rel.positions_of(idx, lengths), idx.float() / 39)
    assert torch.equal(ab.indices_of(ab.positions_of(idx, lengths), lengths), idx)


def test_absolute_vae_learns_where_a_short_motion_ends():
    """A few hundred steps on two keyframe sets of different lengths: the absolute model's decoded last position
    tells the lengths apart (the relative model's is 1 for both by construction)."""
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(timing="absolute", lambda_bone=0.0, **SMALL))
    vae.set_normalization(torch.zeros(263), torch.ones(263))
    kf = torch.randn(2, 6, 263) * 0.5
    idx = torch.tensor([[0, 4, 8, 15, 22, 31], [0, 15, 30, 50, 70, 95]])
    lengths = torch.tensor([32, 96])
    pos = vae.positions_of(idx, lengths)
    opt = torch.optim.Adam(vae.parameters(), lr=3e-3)
    for _ in range(300):
        dec, mu, logvar = vae(kf, pos, eps=torch.zeros(2, 2, 16))
        loss = vae.loss(kf, pos, dec, mu, logvar)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    vae.eval()
    with torch.no_grad():
        dec = vae.decode(vae.encode(kf, pos, sample=False).mu)
    assert abs(float(dec.positions[0, -1]) - 31 / 95) < 0.03
    assert abs(float(dec.positions[1, -1]) - 1.0) < 0.03
    rec = vae.indices_of(dec.positions, lengths)
    assert (rec - idx).abs().max() <= 3
