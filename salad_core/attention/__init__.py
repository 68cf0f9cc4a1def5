"""Attention capture, zero-shot editing (SALAD §3.3, supplement B) and inversion of given motions.

* :mod:`.capture`: :func:`capture_cross_attention` records the cross-attention (and on request
  the self-attention) of the conditional branch while sampling; the result,
  :class:`AttentionMaps`, carries its tokens and words (``word_map``, ``token_map``, ``select``).
* :mod:`.hooks`: hook points on every site (``layers.{i}.{kind}`` probabilities, ``.out``,
  ``.q``/``.k``/``.v``), :func:`use_hooks` for one call, :class:`ActivationCache`
  (``pipe(..., hooks=...)``, ``pipe.run_with_cache(...)``).
* :mod:`.patching`: :func:`patch_activations` between a clean and a corrupt prompt, measured per
  body part.
* :mod:`.edits`: typed edit specifications (:class:`WordSwap`, :class:`Refine`,
  :class:`Reweight`, :class:`Mirror`, :class:`InjectSelfAttention`; beyond the paper, after MotionCLR:
  :class:`Erase`, :class:`Shift`, :class:`ShiftTemporal`, :class:`ExampleBased`) and their pure kernels.
* :mod:`.inpaint`: :class:`Inpaint`, regenerate chosen body parts / a frame span and keep the rest
  (a latent-space step of the edit loop), and :func:`parse_inpaint` for ``PARTS[@START:END]``.
* :mod:`.ranking`: ``Inpaint(candidates=K)``, the best of ``K`` fresh-noise seeds by the T2M evaluator's
  text-motion distance to the target prompt over the regenerated frames (:class:`TextMotionScorer`).
* :mod:`.labels`: :func:`edit_label`, the short caption of edits that figures and GIFs show (``Mirror(legs)``,
  ``Inpaint(arms@20:60)``).
* :mod:`.composite`: what :class:`Inpaint` and :class:`MirrorTake` keep, taken from the source's decoded
  features after decoding (:func:`composite_features`; the VAE decoder mixes neighbouring parts and frames).
* :mod:`.counting`: counting an action's repetitions from its attention over frames
  (:func:`count_repetitions`) and from the motion itself (:func:`motion_repetitions`).
* :mod:`.align`: token alignment of source and target prompts.
* :mod:`.controller` and :mod:`.editing`: Algorithm 1 in one batched forward per step.
* :mod:`.inversion`: DDIM inversion made faithful under guidance, to edit given motions.

The pipeline entry points are ``pipe(..., capture_attention=True)``, ``pipe.edit(...)`` and
``pipe.invert(...)`` (:class:`salad_core.pipeline.SaladPipeline`).
"""
from .align import alignment_matrix, global_align, word_swap_matrix
from .capture import AttentionMaps, AttentionStore, CaptureConfig, TokenInfo, as_capture_config, capture_cross_attention
from .controller import EditController, RowLayout
from .editing import EditPrediction, EditRun, edit_latents
from .counting import attention_signal, count_peaks, count_repetitions, motion_repetitions, motion_signal
from .edits import (ERASE_MODES, MIRROR_GROUPS, REWEIGHT_RANGE, EditSpec, Erase, ExampleBased, InjectSelfAttention, Mirror,
                    MirrorSelfAttention, Refine, Reweight, Shift, ShiftTemporal, WordSwap, erase_columns, map_columns, mirror_parts,
                    mirror_permutation, mirror_self_attention, refine_columns, reweight_columns, seeded_noise, shift_columns, shift_temporal,
                    validate_edits)
from .inpaint import INPAINT_GROUPS, Inpaint, inpaint_parts, parse_inpaint
from .grounding import ground_edit
from .ranking import TextMotionScorer
from .mirror_take import MirrorTake, invert_mirror, mirror_take_edits
from .composite import composite_features, composite_output
from .labels import edit_label
from .inversion import INVERSION_METHODS, Inversion, LatentInversion, ddim_step_coefficients, invert_latents
from .hooks import (ActivationCache, HookContext, HookPoint, hook_point_names, hook_points, select_hook_points,
                    use_hooks)
from .patching import PatchingResult, patch_activations
from .processor import HookedProcessor, flat_rows, named_rows, row_taker

__all__ = [
    "capture_cross_attention", "CaptureConfig", "AttentionStore", "AttentionMaps", "TokenInfo", "as_capture_config",
    "EditSpec", "WordSwap", "Refine", "Reweight", "Mirror", "MirrorSelfAttention", "InjectSelfAttention", "validate_edits",
    "Erase", "Shift", "ShiftTemporal", "ExampleBased", "ERASE_MODES", "erase_columns", "shift_columns",
    "shift_temporal", "seeded_noise", "Inpaint", "INPAINT_GROUPS", "inpaint_parts", "parse_inpaint", "TextMotionScorer",
    "MirrorTake", "invert_mirror", "mirror_take_edits", "ground_edit", "composite_features", "composite_output", "edit_label",
    "count_repetitions", "motion_repetitions", "count_peaks", "attention_signal", "motion_signal",
    "MIRROR_GROUPS", "REWEIGHT_RANGE", "mirror_parts", "mirror_self_attention", "mirror_permutation", "reweight_columns", "map_columns",
    "refine_columns", "global_align", "alignment_matrix", "word_swap_matrix",
    "EditController", "RowLayout", "edit_latents", "EditRun", "EditPrediction",
    "invert_latents", "Inversion", "LatentInversion", "INVERSION_METHODS", "ddim_step_coefficients",
    "HookedProcessor", "flat_rows", "named_rows", "row_taker",
    "use_hooks", "HookContext", "HookPoint", "hook_points", "hook_point_names", "select_hook_points",
    "ActivationCache", "patch_activations", "PatchingResult",
]
