"""KeyMotion on a given motion's own keyframes: the keyframe VAE round trip and MMAE in-filling,
with errors in metres (notebook 05).

- :func:`keyframe_roundtrip`: select a motion's keyframes, encode them with the keyframe VAE
  (posterior mean) and decode them;
- :func:`infill_from_keyframes`: rebuild the motion from those keyframes with the MMAE, beside the
  linear-interpolation baseline;
- :func:`generation_chain`: the same motion at each stage of KeyMotion's generation path (its own
  keyframes in-filled, the keyframe VAE's round trip of them in-filled, and a motion generated from its
  caption), to find the stage where a property of real motion (ballistic flight, planted feet) is lost.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    from salad_core.keymotion.pipeline import KeyMotionPipeline

__all__ = ["KeyframeRoundTrip", "Infilling", "keyframe_roundtrip", "infill_from_keyframes", "generation_chain",
           "CHAIN_STAGES"]

#: The stages of :func:`generation_chain`, in the order of the generation path.
CHAIN_STAGES = ("true", "true_keyframes", "vae_keyframes", "generated")


@dataclass(frozen=True)
class KeyframeRoundTrip:
    """A motion's own keyframes through the keyframe VAE (encode -> posterior mean -> decode)."""

    indices: np.ndarray            # (K,) int64 selected keyframe frames of the input
    decoded_indices: np.ndarray    # (K,) int64 frames the VAE decoded (positions -> frames)
    keyframes: np.ndarray          # (K, D) the selected keyframes, raw features
    decoded: np.ndarray            # (K, D) decoded keyframes, raw features, in decoded time order
    joints: np.ndarray             # (K, J, 3) each selected pose alone (root at the origin), metres
    decoded_joints: np.ndarray     # (K, J, 3) each decoded pose alone, metres
    pose_mpjpe: float              # root-aligned MPJPE between the two, metres
    index_error: float             # mean |decoded - selected| frame index, frames


@dataclass(frozen=True)
class Infilling:
    """A motion rebuilt by the MMAE from its own keyframes, and the linear-interpolation baseline."""

    indices: np.ndarray            # (K,) int64 keyframe frames given to the MMAE
    features: np.ndarray           # (N, D) in-filled motion, raw features
    joints: np.ndarray             # (N, J, 3) in-filled motion, metres
    lerp_joints: np.ndarray        # (N, J, 3) keyframes linearly interpolated (no model), metres
    true_joints: np.ndarray        # (N, J, 3) the input motion, metres
    mpjpe: float                   # MMAE vs input, root-aligned, metres
    mpjpe_global: float            # MMAE vs input, not root-aligned, metres
    lerp_mpjpe: float              # interpolation vs input, root-aligned, metres
    lerp_mpjpe_global: float       # interpolation vs input, not root-aligned, metres


def _keyframe_inputs(pipe, features: np.ndarray, method: str, num_keyframes: int | None):
    from salad_core.keymotion import select_keyframes

    x = np.asarray(features, dtype=np.float32)
    d = pipe.skeleton.feature_dim
    if x.ndim != 2 or x.shape[1] != d:
        raise ValueError(f"features must be one motion (N, {d}) of raw {pipe.skeleton.name} features, got {x.shape}")
    k = pipe.num_keyframes if num_keyframes is None else int(num_keyframes)
    if not k <= len(x) <= pipe.max_length:
        raise ValueError(f"the motion has {len(x)} frames; use {k} (keyframes) to {pipe.max_length} frames")
    norm = pipe.mmae.norm
    xn = norm.normalize(torch.from_numpy(x)).numpy()
    # selected on normalised features, as the keyframe VAE and MMAE were trained (keymotion.train)
    idx = select_keyframes(xn, k, method).astype(np.int64)
    return x, torch.from_numpy(xn)[None], torch.from_numpy(idx)[None]


def _captioned_inputs(pipe, features: np.ndarray, caption: str, method: str):
    """:func:`_keyframe_inputs` and the caption's token features ``(1, W, C)`` and mask on the pipeline's device."""
    if not isinstance(caption, str) or not caption.strip():
        raise ValueError(f"caption={caption!r} must be a non-empty string")
    x, xn, idx = _keyframe_inputs(pipe, features, method, None)
    tb = pipe.text_encoder.encode([caption])
    return x, xn, idx, tb.features.to(pipe.device), tb.mask.to(pipe.device)


@torch.no_grad()
def keyframe_roundtrip(pipe: "KeyMotionPipeline", features: np.ndarray, method: str = "mdo") -> KeyframeRoundTrip:
    """Select a motion's keyframes, encode them with KeyMotion's keyframe VAE and decode them.

    Parameters
    ----------
    pipe : KeyMotionPipeline
    features : array ``(N, D)``
        One motion, raw (de-normalised) features, ``K <= N <= pipe.max_length``.
    method : {"mdo", "mieo", "uniform"}
        Keyframe selection (KeyMotion §III-A; the models were trained on MDO keyframes).
    """
    from salad_core.eval.metrics import mpjpe
    from salad_core.keymotion.kf_vae import gather_keyframes
    from salad_core.keymotion.models import pose_joints
    from salad_core.keymotion.pipeline import decode_keyframes

    x, xn, idx = _keyframe_inputs(pipe, features, method, None)
    length = torch.tensor([len(x)])
    kf = gather_keyframes(xn, idx)                                        # (1, K, D) normalised
    enc = pipe.kf_vae.encode(kf, pipe.kf_vae.positions_of(idx, length), sample=False)
    dec, dec_idx = decode_keyframes(pipe.kf_vae, enc.mu, length)
    norm = pipe.mmae.norm
    true_kf = norm.denormalize(kf)[0]
    dec_kf = norm.denormalize(dec)[0]
    tj = pose_joints(true_kf, pipe.skeleton).numpy()
    dj = pose_joints(dec_kf, pipe.skeleton).numpy()
    return KeyframeRoundTrip(indices=idx[0].numpy(), decoded_indices=dec_idx[0].numpy().astype(np.int64),
                             keyframes=true_kf.numpy(), decoded=dec_kf.numpy(), joints=tj, decoded_joints=dj,
                             pose_mpjpe=float(mpjpe(dj, tj)),
                             index_error=float(np.abs(dec_idx[0].numpy() - idx[0].numpy()).mean()))


@torch.no_grad()
def infill_from_keyframes(pipe: "KeyMotionPipeline", features: np.ndarray, caption: str, method: str = "mdo",
                          keep_keyframes: bool = False) -> Infilling:
    """Rebuild a motion from its own keyframes with KeyMotion's MMAE (text-conditioned in-filling).

    Parameters
    ----------
    pipe : KeyMotionPipeline
    features : array ``(N, D)``
        One motion, raw features, ``K <= N <= pipe.max_length``.
    caption : str
        Its caption (the MMAE is conditioned on text).
    method : {"mdo", "mieo", "uniform"}
        Keyframe selection.
    keep_keyframes : bool
        Paste the given keyframes over the MMAE's output at their frames.

    Returns
    -------
    Infilling
        The in-filled motion and its errors, beside per-channel linear interpolation of the same
        keyframes (:func:`~salad_core.keymotion.mmae.keyframe_lerp`), the floor the MMAE should beat.
    """
    from salad_core.eval.metrics import mpjpe
    from salad_core.keymotion.kf_vae import gather_keyframes
    from salad_core.keymotion.mmae import keyframe_lerp, scatter_keyframes
    from salad_core.motion import features_to_joints

    x, xn, idx, text, text_mask = _captioned_inputs(pipe, features, caption, method)
    n = len(x)
    dev = pipe.device
    out = pipe.mmae.infill(gather_keyframes(xn, idx).to(dev), idx.to(dev), torch.tensor([n], device=dev),
                           text, text_mask, keep_keyframes=keep_keyframes)
    canvas, mask = scatter_keyframes(gather_keyframes(xn, idx), idx, n)
    lerp = keyframe_lerp(canvas, mask)
    norm = pipe.mmae.norm
    feats = norm.denormalize(out.float().cpu())[0].numpy()
    lerp_feats = norm.denormalize(lerp)[0].numpy()
    sk = pipe.skeleton
    joints = features_to_joints(feats, sk).astype(np.float32)
    lerp_joints = features_to_joints(lerp_feats, sk).astype(np.float32)
    true_joints = features_to_joints(x, sk).astype(np.float32)
    return Infilling(indices=idx[0].numpy(), features=feats, joints=joints, lerp_joints=lerp_joints,
                     true_joints=true_joints, mpjpe=float(mpjpe(joints, true_joints)),
                     mpjpe_global=float(mpjpe(joints, true_joints, root_aligned=False)),
                     lerp_mpjpe=float(mpjpe(lerp_joints, true_joints)),
                     lerp_mpjpe_global=float(mpjpe(lerp_joints, true_joints, root_aligned=False)))


@torch.no_grad()
def generation_chain(pipe: "KeyMotionPipeline", features: np.ndarray, caption: str, seed: int = 0,
                     method: str = "mdo", recovery: str = "positions", guidance_scale: float | None = None,
                     generate: bool = True) -> dict[str, np.ndarray]:
    """One motion at every stage of KeyMotion's generation path, as joints read from the position
    features (``recovery="positions"``, no fit: what each model itself made) or after the skeleton fit
    (``"fit"``: fixed bones, locked feet, a floor; what ``out.joints`` shows by default).

    Parameters
    ----------
    pipe : KeyMotionPipeline
    features : array ``(N, D)``
        One motion, raw features, ``K <= N <= pipe.max_length``.
    caption : str
        Its caption (conditions the MMAE and the generation).
    seed : int
        Seed of the generated stage.
    method : {"mdo", "mieo", "uniform"}
        Keyframe selection.
    recovery : {"positions", "fit"}
        How joints are read from the three generated stages' features (:func:`salad_core.recovery.recover_joints`);
        the ``"true"`` stage is always the clip's own position joints.
    guidance_scale : float, optional
        Guidance weight of the generated stage (default: the pipeline's).
    generate : bool
        False leaves the ``"generated"`` stage out (no PST call): how a keyframe VAE is measured before a
        PST has been trained on its latent.

    Returns
    -------
    dict
        :data:`CHAIN_STAGES` -> joints ``(N, J, 3)`` in metres: ``"true"`` the motion;
        ``"true_keyframes"`` the MMAE's in-filling of its own keyframes; ``"vae_keyframes"`` the MMAE's
        in-filling of those keyframes after the keyframe VAE (posterior mean, decoded poses and frames);
        ``"generated"`` the pipeline's motion of ``N`` frames for ``caption`` (PST, VAE decoder, MMAE).
    """
    from salad_core.keymotion.kf_vae import gather_keyframes
    from salad_core.keymotion.pipeline import decode_keyframes
    from salad_core.motion import features_to_joints
    from salad_core.recovery import recover_joints

    if recovery not in ("positions", "fit"):
        raise ValueError(f"recovery={recovery!r}: use 'positions' or 'fit'")
    x, xn, idx, text, mask = _captioned_inputs(pipe, features, caption, method)
    dev = pipe.device
    length = torch.tensor([len(x)], device=dev)
    kf = gather_keyframes(xn, idx).to(dev)
    idx = idx.to(dev)
    own = pipe.mmae.infill(kf, idx, length, text, mask)
    enc = pipe.kf_vae.encode(kf, pipe.kf_vae.positions_of(idx, length), sample=False)
    dec, dec_idx = decode_keyframes(pipe.kf_vae, enc.mu, length)
    through_vae = pipe.mmae.infill(dec, dec_idx, length, text, mask)
    sk, norm = pipe.skeleton, pipe.mmae.norm

    def joints(motion: torch.Tensor) -> np.ndarray:
        f = norm.denormalize(motion.float().cpu())[0].numpy()
        return np.asarray(recover_joints(f, recovery, sk), np.float32)

    chain = {"true": features_to_joints(x, sk).astype(np.float32), "true_keyframes": joints(own),
             "vae_keyframes": joints(through_vae)}
    if generate:
        generated = pipe([caption], lengths=[len(x)], seed=seed, recovery=recovery,
                         guidance_scale=guidance_scale).joints[0]
        chain["generated"] = np.asarray(generated, np.float32)
    return chain
