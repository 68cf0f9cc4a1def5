"""Training attention (dropout > 0) on the explicit route: short key axes mix the values with
``F.dropout``-ed probabilities instead of going to SDPA's unfused dropout path (bench/bench_attention_dropout.py
measures the step); inside ``sdpa_attention_dropout`` the old route is taken."""
from __future__ import annotations

import torch
import torch.nn.functional as F

from salad_core.models.kernels import attention_probs, attention_with_probs, fast_attention, sdpa_attention_dropout


def _qkv(rows=6, heads=2, lq=9, lk=7, dh=4, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(rows, heads, lq, dh, generator=g), torch.randn(rows, heads, lk, dh, generator=g),
            torch.randn(rows, heads, lk, dh, generator=g))


def test_training_attention_drops_out_explicit_probabilities():
    q, k, v = _qkv()
    torch.manual_seed(5)
    out, probs = attention_with_probs(q, k, v, None, 0.2)
    assert probs is not None                              # explicit route; the probabilities before dropout
    torch.testing.assert_close(probs, attention_probs(q, k, None))
    torch.manual_seed(5)
    want = torch.matmul(F.dropout(probs, p=0.2, training=True), v)
    torch.testing.assert_close(out, want, rtol=0, atol=0)
    assert not torch.allclose(out, fast_attention(q, k, v, None, 0.0))     # dropout did happen
    with sdpa_attention_dropout():                        # the old route: SDPA with its own dropout
        _, none = attention_with_probs(q, k, v, None, 0.2)
        assert none is None
    _, again = attention_with_probs(q, k, v, None, 0.2)   # the block ended
    assert again is not None
    long_k, long_v = torch.randn(6, 2, 60, 4), torch.randn(6, 2, 60, 4)
    assert attention_with_probs(q, long_k, long_v, None, 0.2)[1] is None    # long key axes: SDPA as before


def test_training_attention_is_unbiased_and_never_attends_masked_keys():
    """With a prefix key mask of two row runs (which sampling attends run by run) and dropout, masked keys
    still get no weight, and the mean over draws is the attention without dropout, on both routes."""
    q, k, v = _qkv(rows=4, lk=8)
    key_mask = torch.ones(4, 8, dtype=torch.bool)
    key_mask[2:, 5:] = False
    v_bad = v.clone()
    v_bad[2:, :, 5:] = 1e6                                # what a masked key would leak
    clean = fast_attention(q, k, v_bad, key_mask, 0.0)
    assert clean.abs().max().item() < 100
    for reference in (False, True):
        torch.manual_seed(6)
        with sdpa_attention_dropout(reference):
            draws = torch.stack([fast_attention(q, k, v_bad, key_mask, 0.3) for _ in range(3000)])
        assert draws.abs().max().item() < 1e3, reference
        assert draws.std(0).max().item() > 0.05, reference        # dropout applied on the runs' rows too
        torch.testing.assert_close(draws.mean(0), clean, rtol=0, atol=0.12)


def test_denoiser_training_step_matches_the_sdpa_route_in_eval_and_trains_on_either():
    """Without dropout (eval) the routes are the same computation; in training both give finite losses and
    gradients for every parameter."""
    from salad_core.models.denoiser import Denoiser, DenoiserConfig

    torch.manual_seed(0)
    den = Denoiser(DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=3, text_dim=16, dropout=0.1))
    z, t = torch.randn(3, 6, 7, 8), torch.randint(0, 1000, (3,))
    text, mask = torch.randn(3, 5, 16), torch.ones(3, 5, dtype=torch.bool)
    mask[1:, 3:] = False
    den.eval()
    with torch.no_grad():
        a = den(z, t, text, mask)
        with sdpa_attention_dropout():
            b = den(z, t, text, mask)
    torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)
    den.train()
    for reference in (False, True):
        den.zero_grad()
        with sdpa_attention_dropout(reference):
            den(z, t, text, mask).pow(2).mean().backward()
        grads = [p.grad for p in den.parameters() if p.requires_grad]
        assert all(g is not None and torch.isfinite(g).all() for g in grads), reference
