"""KeyMotion (keyframe-based text-to-motion): keyframe selection, keyframe VAE, PST denoiser, MMAE.

``select_keyframes`` and friends (numpy only) are imported eagerly; the torch models, the
pipeline and the trainers are re-exported lazily (on first attribute access), so that keyframe
selection stays cheap to import.
"""
from importlib import import_module

from salad_core.keymotion.selection import (KEYFRAME_METHODS, interpolation_errors, mdo_keyframes,
                                            mieo_keyframes, select_keyframes, uniform_keyframes)

# public name -> submodule that defines it (loaded on first access)
_LAZY = {
    "KeyframeVAE": "kf_vae", "KeyframeVAEConfig": "kf_vae", "indices_to_positions": "kf_vae",
    "positions_to_indices": "kf_vae", "gather_keyframes": "kf_vae",
    "ParallelSkipTransformer": "pst", "PSTConfig": "pst", "PST_DIFFUSION": "pst", "sample_latents": "pst", "PSTPrediction": "pst",
    "MotionMaskedAutoencoder": "mmae", "MMAEConfig": "mmae", "keyframe_lerp": "mmae", "scatter_keyframes": "mmae",
    "KeyMotionPipeline": "pipeline", "KeyMotionOutput": "pipeline",
    "side_ids": "sides", "side_ids_of": "sides", "RestPaddedDataset": "rest_padding", "hold_features": "rest_padding",
    "KeyMotionTrainConfig": "train", "train_keymotion": "train", "train_kf_vae": "train", "train_pst": "train",
    "train_mmae": "train", "KeyMotionRecipe": "train", "load_keymotion_recipe": "train",
}

__all__ = ["select_keyframes", "mdo_keyframes", "mieo_keyframes", "uniform_keyframes",
           "interpolation_errors", "KEYFRAME_METHODS", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(f"salad_core.keymotion.{_LAZY[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'salad_core.keymotion' has no attribute {name!r}")
