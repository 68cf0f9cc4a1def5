"""Ranking in-painting candidates by the text-motion evaluator: the best of ``K`` fresh-noise seeds.

:class:`~salad_core.attention.inpaint.Inpaint` with ``candidates=K`` (K > 1; by default 8 for a frame span of an
inverted motion) runs the whole edit ``K`` times, the region's fresh noise drawn from the seeds ``seed, seed + 1, ...,
seed + K - 1`` (everything else the same), and keeps the candidate whose edited motion lies closest to the target
prompt in the T2M evaluator's embedding space (:class:`TextMotionScorer`: the Euclidean text-motion distance of
MM-Dist; lower is better). It costs ``K`` edits.

What is scored (:func:`scoring_window`): the edited motion's final features (after the composite and grounding, as the
edit returns them) over the regenerated motion frames: every frame for body parts alone; for a frame span, the span
widened by whole latent frames of kept context, alternately on the left and the right, until it reaches the
evaluator's minimum length (:data:`MIN_FRAMES`, the shortest clip the evaluator was trained on), clipped to the
motion (a motion shorter than that is scored whole). With ``Inpaint(score="parts")`` the scored motion is
:func:`isolate_parts`'s: the kept body parts held still, so that only the regenerated ones move (for a parts edit the
kept body, e.g. a walk, otherwise dominates the evaluator's embedding).

With ``Inpaint(seam_bound=B)`` (by default 1.5 for a frame span of an inverted motion) a frame span's candidates are
ranked among the smooth ones only (:func:`pick_candidate`): each candidate's
:func:`~salad_core.attention.composite.seam_jerk_ratio` (its seams' jerk over the source's own 95th percentile,
:func:`candidate_seam_ratios`) is known before choosing, and the closest candidate whose ratio is at most ``B`` is
kept (none: the smoothest). The evaluator's distance does not see seams.

The evaluator's text side takes ``word/POS`` tokens (HumanML3D's format); :func:`caption_tokens` tags a free prompt
with the procedural corpus's own lexicon (:data:`salad_core.data.procedural.language.LEXICON`: the lemma for nouns
and verbs, the word otherwise; an inflected verb form that the lexicon lists as a noun reads as a verb unless a
determiner, number or adjective precedes it), so the corpus's captions get the corpus's tokens. Words the
evaluator's vocabulary lacks become ``unk``, as in the evaluator's own protocol.

The default evaluator is the shipped one for the procedural corpus (``salad_core/weights/evaluator``), HumanML3D
features only.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
from typing import TYPE_CHECKING, Callable, Optional, Sequence

import numpy as np
import torch

if TYPE_CHECKING:  # pragma: no cover
    from salad_core.pipeline import EditOutput

    from .inpaint import Inpaint

log = logging.getLogger(__name__)

__all__ = ["MIN_FRAMES", "TextMotionScorer", "caption_tokens", "scoring_window", "isolate_parts", "prior_height_cm",
           "candidate_specs",
           "ranked_inpaint", "candidate_seam_ratios", "pick_candidate", "choose_candidate", "ranked_edit"]

#: The shortest window the scorer embeds (motion frames): the evaluator's training clips are at least this long
#: (HumanML3D's ``min_length``).
MIN_FRAMES = 40

#: Coarse tags after which an inflected verb form reads as a noun ("two punches", "a few steps").
_NOUN_CONTEXT = ("DET", "NUM", "ADJ")


@functools.lru_cache(maxsize=1)
def _verb_forms() -> dict[str, str]:
    """Inflected verb form (third person, gerund) -> the verb's lemma, over the corpus's verbs."""
    from salad_core.data.procedural.language import VERBS

    return {form: lemma for lemma, forms in VERBS.items() for form in forms}


def caption_tokens(text: str) -> list[str]:
    """A free prompt -> ``word/POS`` tokens for the evaluator, one per word of
    :func:`~salad_core.data.texts.split_words` (lower-cased alphabetic words); see the module docstring.

    Raises
    ------
    ValueError
        ``text`` has no word.
    """
    from salad_core.data.procedural.language import LEXICON
    from salad_core.data.texts import split_words

    words = split_words(text) if isinstance(text, str) else []
    if not words:
        raise ValueError(f"prompt {text!r} has no word to score")
    forms = _verb_forms()
    out, prev = [], None
    for w in words:
        lemma, pos = LEXICON.get(w, (w, "OTHER"))
        if w in forms and pos == "NOUN" and prev not in _NOUN_CONTEXT:
            lemma, pos = forms[w], "VERB"
        out.append(f"{lemma if pos in ('NOUN', 'VERB') else w}/{pos}")
        prev = pos
    return out


def scoring_window(num_frames: int, span: Optional[tuple[int, int]], min_frames: int = MIN_FRAMES,
                   unit: int = 4) -> tuple[int, int]:
    """Motion frames ``[a, b)`` scored for a motion of ``num_frames`` frames whose frames ``span`` ``(s, e)`` were
    regenerated (None: all of them): the span grown by ``unit`` frames at a time, alternately at its start and its
    end (where the motion has frames), until it holds ``min_frames``; the whole motion when it is shorter.

    Raises
    ------
    ValueError
        The span does not lie inside the motion.
    """
    if span is None:
        return 0, int(num_frames)
    a, b = int(span[0]), int(span[1])
    if not 0 <= a < b <= num_frames:
        raise ValueError(f"the regenerated span {span} does not lie inside the motion of {num_frames} frames")
    left = True
    while b - a < min_frames and (a > 0 or b < num_frames):
        if (left and a > 0) or b >= num_frames:
            a = max(0, a - unit)
        else:
            b = min(num_frames, b + unit)
        left = not left
    return a, b


class TextMotionScorer:
    """The T2M evaluator's text-motion distance of a motion to a prompt (lower: the motion matches it better).

    Parameters
    ----------
    evaluator : T2MEvaluator, optional
        With bundled word vectors; default: the shipped evaluator (:func:`salad_core.eval.train_evaluator.
        load_packaged_evaluator`), loaded once per process.
    min_frames : int
        :func:`scoring_window`'s minimum window (motion frames).
    """

    def __init__(self, evaluator=None, min_frames: int = MIN_FRAMES) -> None:
        self.evaluator = _shipped_evaluator() if evaluator is None else evaluator
        self.unit = int(self.evaluator.config.unit_length)
        if isinstance(min_frames, bool) or not isinstance(min_frames, int) or min_frames < self.unit:
            raise ValueError(f"min_frames={min_frames!r} must be an int >= the evaluator's {self.unit} frames per code")
        self.min_frames = min_frames
        self._texts: dict[str, np.ndarray] = {}     # prompt -> embedding: every candidate of an edit has the same one

    @property
    def source(self) -> str:
        """Where the evaluator came from (its folder), for the record."""
        return str(getattr(self.evaluator, "source", type(self.evaluator).__name__))

    def text_embedding(self, text: str) -> np.ndarray:
        """``(C,)`` float64 embedding of a prompt (:func:`caption_tokens`), computed once per prompt (read-only)."""
        emb = self._texts.get(text)
        if emb is None:
            emb = self.evaluator.caption_embeddings([caption_tokens(text)])[0].double().cpu().numpy()
            emb.setflags(write=False)
            self._texts[text] = emb
        return emb

    def motion_embedding(self, features: np.ndarray, span: Optional[tuple[int, int]] = None) -> np.ndarray:
        """``(C,)`` float64 embedding of ``features`` ``(N, D)`` (de-normalised HumanML3D features) over
        :func:`scoring_window` of ``span``."""
        x = np.asarray(features, dtype=np.float32)
        d = self.evaluator.config.dim_pose
        if x.ndim != 2 or x.shape[1] != d:
            raise ValueError(f"features must be (N, {d}) de-normalised motion features, got shape {x.shape}")
        if len(x) < self.unit:
            raise ValueError(f"a motion of {len(x)} frames is too short to score (the evaluator needs {self.unit})")
        a, b = self.window(len(x), span)
        n = (b - a) // self.unit * self.unit
        with torch.no_grad():
            z = self.evaluator.normalize(x[a:a + n][None])                 # the evaluator's own statistics
            emb = self.evaluator.motion_embeddings(z, torch.tensor([n]), mask_padding=True)
        return emb[0].double().cpu().numpy()

    def window(self, num_frames: int, span: Optional[tuple[int, int]]) -> tuple[int, int]:
        """:func:`scoring_window` with this scorer's minimum and the evaluator's frames per code."""
        return scoring_window(num_frames, span, self.min_frames, self.unit)

    def distance(self, features: np.ndarray, text: str, span: Optional[tuple[int, int]] = None) -> float:
        """Euclidean distance between the embeddings of ``text`` and of ``features`` ``(N, D)`` over ``span``'s
        window (MM-Dist's distance of one pair)."""
        return float(np.linalg.norm(self.text_embedding(text) - self.motion_embedding(features, span)))


@functools.lru_cache(maxsize=1)
def _shipped_evaluator():
    from salad_core.eval.train_evaluator import load_packaged_evaluator

    return load_packaged_evaluator()[0]


# ------------------------------------------------------------------------------------------- the scored motion
def _held_columns(sk, moving: np.ndarray) -> dict[str, np.ndarray]:
    """The feature columns ``(D,)`` bool of the joints not ``moving`` (``(J,)`` bool) by how :func:`isolate_parts`
    holds them: ``"median"`` (root height, root-relative positions, 6D rotations), ``"zero"`` (root turn and step,
    local velocities), ``"one"`` (foot contacts)."""
    held = np.zeros(sk.feature_dim, bool)
    for j in np.flatnonzero(~moving):
        held[list(sk.joint_feature_index[j])] = True
    fs = sk.feature_slices

    def kind(*names):
        cols = np.zeros(sk.feature_dim, bool)
        for name in names:
            cols[fs[name]] = True
        return held & cols

    return {"median": kind("root_y", "ric", "rot"), "zero": kind("root_rot_vel", "root_lin_vel", "local_vel"),
            "one": kind("contacts")}


def isolate_parts(features: np.ndarray, parts, skeleton="humanml3d") -> np.ndarray:
    """``features`` ``(N, D)`` (de-normalised HumanML3D-style features of one motion) with every joint outside the
    body ``parts`` held still, so that only those parts move: ``(N, D)``, ``features``' dtype.

    A held joint's columns (the skeleton's joint split, ``Skeleton.joint_feature_index``) become: root-relative
    position and 6D rotation their median over the motion's frames, local velocity 0, foot contact 1; a held root:
    turn and planar step 0 (the body stays in place, facing one way), height its median. The moving joints' columns
    are left exactly as they are (their positions are in the root's heading frame, so they keep their meaning).

    Parameters
    ----------
    parts : str or sequence of str
        The moving body parts (:func:`~salad_core.attention.inpaint.inpaint_parts` names: ``"arms"``,
        ``("left arm", "head")``, ...).

    Raises
    ------
    ValueError
        Features of the wrong shape, an empty motion, or an unknown part.
    """
    from salad_core.skeleton import get_skeleton

    from .composite import part_joint_weights
    from .inpaint import inpaint_parts

    sk = get_skeleton(skeleton)
    f = np.asarray(features)
    if f.ndim != 2 or f.shape[1] != sk.feature_dim or len(f) == 0:
        raise ValueError(f"features must be (N, {sk.feature_dim}) de-normalised {sk.name} features of at least one "
                         f"frame, got shape {f.shape}")
    moving = part_joint_weights(inpaint_parts(parts), sk) > 0
    cols = _held_columns(sk, moving)
    out = f.copy()
    out[:, cols["median"]] = np.median(f[:, cols["median"]], axis=0)
    out[:, cols["zero"]] = 0.0
    out[:, cols["one"]] = 1.0
    return out


# ------------------------------------------------------------------------------------------- the candidates
def prior_height_cm(output: "EditOutput", inpaint: "Inpaint", skeleton="humanml3d") -> float:
    """How far an edit's region strays from its pasted prior in what reads flight and contacts: the mean distance
    (cm) between the heights above the floor of the pelvis and the four foot joints of ``output``'s edited motion
    (its first motion) over the regenerated latent frames, and those of the prior (``output.prior``, the target
    sampled alone) over the frames that were pasted there (``settings["inpaint_prior"]["windows"]``). Each motion's
    floor is its own lowest foot joint over all its frames, so a motion lifted or sunk bodily reads 0. The
    root-relative pose cannot see a pelvis that no longer rises; on procedural validation clips the candidates that
    kept the pasted poses most closely were the ones whose jumps failed, and those that kept its heights the ones
    that passed (lab/docs/editing.md).

    Raises
    ------
    ValueError
        ``output`` has no pasted prior (``Inpaint(prior="prompt")`` pastes one).
    """
    record = output.settings.get("inpaint_prior")
    if output.prior is None or not record or "windows" not in record:
        raise ValueError("this edit pasted no prior (Inpaint(prior='prompt') pastes one): there is nothing to follow; "
                         "score the candidates with score='whole'")
    s, e, frames, c = record["windows"][0]
    unit = inpaint.unit_length
    n = int(output.edited.lengths[0])
    return height_distance_cm(np.asarray(output.edited.joints[0])[:n], np.asarray(output.prior.joints[0])[:int(frames)],
                              (s * unit, e * unit), c * unit, skeleton)


def height_distance_cm(edited: np.ndarray, prior: np.ndarray, span: tuple[int, int], offset: int,
                       skeleton="humanml3d") -> float:
    """Mean distance (cm) between the heights above the floor of the pelvis and the skeleton's foot contact joints
    over ``edited[span[0]:span[1]]`` and ``prior[offset : offset + span length]`` (``(N, J, 3)`` and ``(M, J, 3)``
    joint positions, metres, y up). Each motion's floor is its own lowest foot joint over all its frames, so a
    motion lifted or sunk bodily reads 0 (:func:`prior_height_cm` reads an edit and its pasted prior with it)."""
    from salad_core.skeleton import get_skeleton

    feet = list(get_skeleton(skeleton).contact_joints)
    joints = [0, *feet]
    a = edited[span[0]:span[1]][:, joints, 1] - edited[:, feet, 1].min()
    b = prior[offset:offset + len(a)][:, joints, 1] - prior[:, feet, 1].min()
    if len(a) == 0 or len(b) != len(a):
        raise ValueError(f"span {span} of {len(edited)} edited frames against prior frames {offset}.. of {len(prior)}: "
                         "the two windows must be non-empty and of one length")
    return float(np.abs(a - b).mean() * 100)


def ranked_inpaint(edits: Sequence, inverted: bool, motions: int = 1) -> Optional["Inpaint"]:
    """The edits' :class:`~salad_core.attention.inpaint.Inpaint` if it runs more than one candidate
    (:meth:`~salad_core.attention.inpaint.Inpaint.candidates_for`; ``inverted``: the edit is of an inversion of
    ``motions`` motions), else None."""
    return next((e for e in edits if hasattr(e, "candidates_for") and e.candidates_for(inverted, motions) > 1), None)


def candidate_specs(edits: Sequence, inpaint: "Inpaint", k: int) -> list[tuple]:
    """The ``k`` edit lists of the candidates: ``edits`` with ``inpaint`` replaced by one candidate each (``seed + i``,
    ``candidates=1``), in seed order."""
    return [tuple(dataclasses.replace(e, seed=inpaint.seed + i, candidates=1) if e is inpaint else e for e in edits)
            for i in range(k)]


def candidate_seam_ratios(outputs: Sequence["EditOutput"], inpaint: "Inpaint") -> Optional[list[float]]:
    """Each candidate edit's (one motion each) :func:`~salad_core.attention.composite.seam_jerk_ratio`: its edited
    joints' jerk at the inner seams of ``inpaint``'s regenerated span over its source's own 95th percentile of jerk.
    None when ``inpaint`` regenerates body parts alone (no seam)."""
    from .composite import seam_jerk_ratio

    ratios = []
    for out in outputs:
        n = int(out.edited.lengths[0])
        span = inpaint.frame_span(n)
        if span is None:
            return None
        cuts = [b for b in span if 0 < b < n]
        src = np.asarray(out.source.joints[0])[:int(out.source.lengths[0])]
        ratios.append(seam_jerk_ratio(src, np.asarray(out.edited.joints[0])[:n], cuts))
    return ratios


def pick_candidate(distances: Sequence[float], seam_ratios: Optional[Sequence[float]] = None,
                   bound: Optional[float] = None) -> int:
    """The index of the candidate to keep: the smallest of ``distances`` among the candidates whose ``seam_ratios``
    are at most ``bound``; when none is, the smallest seam ratio; ``bound`` or ``seam_ratios`` None: the smallest
    distance. The first of equal ones wins.

    Raises
    ------
    ValueError
        No candidate, or ``seam_ratios`` of another length than ``distances``.
    """
    d = np.asarray(distances, np.float64)
    if d.ndim != 1 or len(d) == 0:
        raise ValueError(f"pick_candidate needs one distance per candidate, got {list(distances)!r}")
    if bound is None or seam_ratios is None:
        return int(np.argmin(d))
    r = np.asarray(seam_ratios, np.float64)
    if r.shape != d.shape:
        raise ValueError(f"{len(r)} seam ratios for {len(d)} candidates: give one per candidate")
    smooth = r <= bound
    if not smooth.any():
        return int(np.argmin(r))
    return int(np.argmin(np.where(smooth, d, np.inf)))


def first_smooth_index(seam_ratios: Sequence[float], bound: float) -> int:
    """``Inpaint(score="first_smooth")``'s pick: the index of the first candidate (in seed order) whose seam ratio is at
    most ``bound``; when none is, the smallest ratio (the first of equal ones).

    Raises
    ------
    ValueError
        No seam ratio (a body-part edit has no seam).
    """
    r = np.asarray(seam_ratios if seam_ratios is not None else [], np.float64)
    if r.ndim != 1 or len(r) == 0:
        raise ValueError(f"first_smooth_index needs one seam ratio per candidate, got {seam_ratios!r}")
    smooth = np.flatnonzero(r <= bound)
    return int(smooth[0]) if len(smooth) else int(np.argmin(r))


def choose_candidate(outputs: Sequence["EditOutput"], inpaint: "Inpaint", scorer: TextMotionScorer, *,
                     inverted: bool = True, skeleton="humanml3d",
                     seam_ratios: Optional[Sequence[float]] = None) -> tuple[int, list[float], tuple[int, int]]:
    """The best of the candidate edits ``outputs`` (one motion each) by ``scorer``: ``(index, distances, window)``,
    the distances of every candidate's edited motion to its target prompt over the scored ``window`` (motion frames,
    :func:`scoring_window` of ``inpaint``'s regenerated span); the first of equal ones wins. What is scored:
    ``inpaint.score_for(inverted)``, the edited motion (``"whole"``) or :func:`isolate_parts` of it with
    ``inpaint``'s regenerated parts (``"parts"``; ``skeleton``: the features' skeleton), or, without the evaluator,
    :func:`prior_height_cm` over the regenerated latent frames (``"prior"``). With a seam bound
    (``inpaint.seam_bound_for(inverted)``, frame spans only) the index is :func:`pick_candidate`'s among the
    candidates' ``seam_ratios`` (default: :func:`candidate_seam_ratios` of ``outputs``)."""
    mode = inpaint.score_for(inverted)
    bound = inpaint.seam_bound_for(inverted)
    if mode == "first_smooth":      # no score: the seams alone, the first smooth candidate in seed order
        ratios = list(candidate_seam_ratios(outputs, inpaint) if seam_ratios is None else seam_ratios)
        n = int(outputs[0].edited.lengths[0])
        s, e = inpaint.latent_span(n)
        return first_smooth_index(ratios, bound), ratios, (s * inpaint.unit_length, e * inpaint.unit_length)
    scores, window = [], None
    for out in outputs:
        ed = out.edited
        n = int(ed.lengths[0])
        span = inpaint.frame_span(n)
        if mode == "prior":
            s, e = inpaint.latent_span(n)
            window = (s * inpaint.unit_length, e * inpaint.unit_length)
            scores.append(prior_height_cm(out, inpaint, skeleton))
            continue
        window = scorer.window(n, span)
        feats = np.asarray(ed.features[0, :n])
        if mode == "parts":
            feats = isolate_parts(feats, inpaint.parts, skeleton)
        scores.append(scorer.distance(feats, ed.texts[0], span))
    if bound is not None and seam_ratios is None:
        seam_ratios = candidate_seam_ratios(outputs, inpaint)
    return pick_candidate(scores, seam_ratios, bound), scores, window


def ranked_edit(run: Callable[[tuple], "EditOutput"], edits: Sequence, *, inverted: bool, skeleton: str,
                motions: int = 1, scorer: Optional[TextMotionScorer] = None) -> "EditOutput":
    """Run an edit whose :class:`~salad_core.attention.inpaint.Inpaint` runs ``K`` > 1 candidates
    (:func:`ranked_inpaint`): ``run(specs)`` (the edit with those specs, e.g. ``pipe.edit`` with everything else
    unchanged) for each of :func:`candidate_specs`, and return the best by ``scorer`` (:func:`choose_candidate`;
    default: the shipped evaluator). Its ``edits`` are the chosen candidate's (run again they give the same motion);
    ``settings`` and ``edited.settings`` record ``"inpaint_candidates"``: the seeds, the distances, the chosen index
    and seed, the scored motion frames, what was scored (``"score"``: ``"whole"`` or ``"parts"``,
    :meth:`~salad_core.attention.inpaint.Inpaint.score_for`), the evaluator, each candidate's seam ratio
    (``"seam_ratios"``, :func:`candidate_seam_ratios`; None for body parts alone) and the seam bound the ranking used
    (``"seam_bound"``, :meth:`~salad_core.attention.inpaint.Inpaint.seam_bound_for`; None: by distance alone).
    With ``score="prior"`` the distances are :func:`prior_height_cm`'s (``"evaluator"`` None), and when no candidate's
    seam ratio is within the bound (and the region starts from fresh noise, :meth:`~salad_core.attention.inpaint.
    Inpaint.fresh_noise`) the ``K`` candidates are run again without the prior and ranked by the evaluator:
    ``"fallback"`` records that ranking (its distances, seam ratios and chosen index; ``"seed"`` is then its
    chosen seed, ``"chosen"`` stays the index the pasted candidates' ranking gave). With ``score="first_smooth"`` the
    candidates are run one at a time and the first whose seam ratio is within the bound ends the run
    (:func:`first_smooth_index`; no evaluator, ``"distances"`` are the seam ratios, ``"seeds"`` those run).

    Parameters
    ----------
    inverted : bool
        The edit is of an inversion (where ``noise="auto"`` draws the region's noise from the seed).
    motions : int
        Motions of the inversion (``candidates="auto"`` ranks one motion only).
    skeleton : str
        The pipeline's skeleton name (the evaluator reads HumanML3D features).

    Raises
    ------
    ValueError
        A region that does not start from the seed's noise (all candidates would be alike); an evaluator for other
        features than the pipeline's; more than one motion in the edit (for a generated source: found after the first
        candidate).
    """
    inpaint = ranked_inpaint(edits, inverted, motions)
    if inpaint is None:
        raise ValueError("ranked_edit needs an Inpaint with candidates > 1 among the edits")
    k = inpaint.candidates_for(inverted, motions)
    if motions != 1:
        raise ValueError(f"Inpaint(candidates={k}) ranks the candidates of one motion; the edit has {motions}: edit "
                         "them one at a time")
    if not inpaint.fresh_noise(inverted) and inpaint.prior_for(inverted) == "none":
        kind = "given" if inverted else "generated"
        raise ValueError(f"Inpaint(candidates={k}) draws the region's noise from {k} seeds, but with "
                         f"noise={inpaint.noise!r} the region of a {kind} motion starts from the source's own noise "
                         "and no prior is pasted, so the candidates would be alike; give noise='fresh' (or "
                         "'matched'), or prior='prompt' (each candidate pastes its own seed's sample)")
    mode, bound = inpaint.score_for(inverted), inpaint.seam_bound_for(inverted)
    if mode != "first_smooth":      # the seams alone need no evaluator
        scorer = TextMotionScorer() if scorer is None else scorer
        dim = scorer.evaluator.config.dim_pose
        from salad_core.skeleton import get_skeleton

        if get_skeleton(skeleton).feature_dim != dim:
            raise ValueError(f"the evaluator reads {dim}-d features; the pipeline's {skeleton} motions cannot be "
                             "ranked with it")
    specs = candidate_specs(edits, inpaint, k)
    if mode == "first_smooth":
        log.info("in-painting: up to %d candidates (region seeds %d..%d), the first whose seams are within %.2fx kept",
                 k, inpaint.seed, inpaint.seed + k - 1, bound)
    else:
        log.info("in-painting: %d candidates (region seeds %d..%d), the best kept", k, inpaint.seed,
                 inpaint.seed + k - 1)
    outputs = [run(specs[0])]
    if len(outputs[0].edited) != 1:
        raise ValueError(f"Inpaint(candidates={k}) ranks the candidates of one motion; the edit has "
                         f"{len(outputs[0].edited)}: edit them one at a time")
    for i, s in enumerate(specs[1:], start=2):
        if mode == "first_smooth" and candidate_seam_ratios(outputs[-1:], inpaint)[0] <= bound:
            log.info("in-painting: candidate %d joins smoothly; the rest not run", i - 1)
            break       # the last candidate joins its context smoothly: the rest are not run
        log.info("in-painting candidate %d of %d", i, k)
        outputs.append(run(s))
    ratios = candidate_seam_ratios(outputs, inpaint)
    best, scores, window = choose_candidate(outputs, inpaint, scorer, inverted=inverted, skeleton=skeleton,
                                            seam_ratios=ratios)
    record = {"seeds": [inpaint.seed + i for i in range(len(outputs))], "distances": scores, "chosen": best,
              "seed": inpaint.seed + best, "frames": list(window), "score": mode,
              "evaluator": None if mode in ("prior", "first_smooth") else scorer.source, "seam_ratios": ratios,
              "seam_bound": bound}
    if (mode == "prior" and ratios is not None and bound is not None and min(ratios) > bound
            and inpaint.fresh_noise(inverted)):
        # no pasted candidate joins its context smoothly: the candidates without the prior, by the evaluator (a
        # region from the source's own noise has no other candidates: the smoothest pasted one is kept)
        plain = dataclasses.replace(inpaint, prior="none", score="whole")
        plain_specs = candidate_specs(tuple(plain if e is inpaint else e for e in edits), plain, k)
        log.info("in-painting: no candidate's seams within %.2fx; %d candidates without the prior", bound, k)
        plain_outputs = [run(s) for s in plain_specs]
        plain_ratios = candidate_seam_ratios(plain_outputs, plain)
        best, plain_scores, plain_window = choose_candidate(plain_outputs, plain, scorer, inverted=inverted,
                                                            skeleton=skeleton, seam_ratios=plain_ratios)
        record["fallback"] = {"reason": f"no candidate's seam ratio within {bound}", "prior": "none",
                              "score": "whole", "evaluator": scorer.source, "distances": plain_scores,
                              "seam_ratios": plain_ratios, "chosen": best, "frames": list(plain_window)}
        outputs, specs = plain_outputs, plain_specs
        record["seed"] = inpaint.seed + best
    out = outputs[best]
    edited = dataclasses.replace(out.edited, settings={**out.edited.settings, "inpaint_candidates": record})
    return dataclasses.replace(out, edited=edited, edits=specs[best],
                               settings={**out.settings, "inpaint_candidates": record})
