"""The procedural motion-language corpus: the toolkit's embedded default dataset.

HumanML3D and KIT-ML cannot be shipped, so salad generates text-annotated motion itself, in the
HumanML3D format and layout (every code path is the one real HumanML3D takes):

* motions: forward kinematics and limb IK on the HumanML3D 22-joint skeleton with its target
  bone lengths, 20 fps, feet planted without sliding, converted with
  :func:`salad_core.motion.joints_to_features`;
* 58 action primitives over all 7 body parts with left/right variants (locomotion, crawling, jumps, kicks
  to the front, side and back, dance steps, throwing, boxing, kneeling, lying down, stairs up and down, shuffles,
  forward and side lunges, pivots, picking things up, touching the toes, golf and bat swings, reaching up high,
  balancing on one leg, hands on and across the body, ...), composed into sequences ("X, then Y"), layers ("X while Y"),
  repetitions ("twice") and modifiers ("high", "low", "slowly", "quickly") that change the motion
  measurably;
* 3-4 captions per motion in many sentence frames, with synonyms, style and intent words, and
  word/POS tokens, and ground truth no benchmark has: for every
  caption, each action phrase's word span, the body parts it drives and its frames
  (``annotations/<id>.json``);
* mirror augmentation (``M<id>``) with left/right swapped in captions and annotations;
* optionally (corpus 2.8, ``build_corpus(general=N)``): the general-motion set's clips (lying, rolls,
  cartwheels, handstands, flips, spins, kneeling, crawling, ...) with captions made from the plan
  each clip followed (:mod:`.general_language`), as ``G<id>`` / ``MG<id>``.

Entry points: :func:`build_corpus` (``salad corpus build``), :func:`corpus_figures`,
:func:`in_language` / :func:`parse_prompt`, :func:`generate_clip`.
"""
from .checks import bone_length_error, foot_sliding, joint_angles, part_activity, part_speeds, phrase_activity
from .composition import Clip, Event, Plan, Step, generate_clip, realise, sample_plan
from .corpus import (GENERAL_CORPUS_VERSION, GENERATOR_VERSION, SIZES, build_corpus, corpus_digest, corpus_figures,
                     make_motion)
from .language import (FIGURE_PROMPTS, Caption, in_language, mirror_caption, parse_prompt, render_captions,
                       sentence_frame, sentence_frames, vocabulary)
from .primitives import MODIFIERS, PRIMITIVES, Action, primitive_parts

__all__ = [
    "build_corpus", "corpus_figures", "corpus_digest", "make_motion", "SIZES", "GENERATOR_VERSION",
    "GENERAL_CORPUS_VERSION",
    "generate_clip", "realise", "sample_plan", "Plan", "Step", "Event", "Clip",
    "Action", "PRIMITIVES", "MODIFIERS", "primitive_parts",
    "in_language", "parse_prompt", "render_captions", "mirror_caption", "Caption", "FIGURE_PROMPTS",
    "sentence_frame", "sentence_frames", "vocabulary",
    "part_speeds", "part_activity", "phrase_activity", "foot_sliding", "bone_length_error", "joint_angles",
]
