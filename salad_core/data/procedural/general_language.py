"""Captions of the general-motion set: what each clip does, said in the corpus's language.

The general-motion generator (:mod:`.general`) records the plan it followed on every clip
(:attr:`~.general.GeneralClip.events`: the postures it moved between, the jumps, rolls, cartwheels
and handstands it made, the gait of every stretch of walking, with their frame spans). This module
turns that plan into *steps* (:func:`general_steps`: one nameable action each, with its frames,
side and body parts) and the steps into captions (:func:`render_general_captions`) with the
corpus's subjects, sentence frames, openings and manner words (:mod:`.language`), so a model
trained on both learns the words of the general set ("a person lies down on their back, rolls
onto the left side and gets up", "someone does a cartwheel to the right", "a woman crawls forward
on all fours", "the man jumps and spins around").

What a step may say, and what it may not
----------------------------------------
A step is said only if the clip shows it whole and the joints show what the plan meant:

* the window the generator cut the clip from often starts or ends in the middle of a movement;
  such a part is left out (a roll, cartwheel or handstand needs 85 % of its frames inside the clip, a
  jump its whole flight and landing);
* every planned step is checked on the clip's joints before it is said (:func:`measured_postures`,
  :func:`pitch_rotation`, :func:`yaw_rotation`, :func:`travel`, :func:`airborne`, :func:`inverted`):
  a roll or flip turns head over heels the planned way (and a flip leaves the floor), a cartwheel and
  a handstand go upside down (on the hands), a spin turns the planned amount, a jump or walk travels
  the said way, a turn turns the said way; a side word that the joints do not bear out is dropped;
* floor work is named from the joints alone, at the plan's key frames: the generator's posture
  draws do not always make the posture they are named after (a "sit" key with bent knees leaves
  the body on its feet, a "prone" key with the arms drawn down props it up on the hands), so the
  measured postures (lying on the back / front / a side, sitting, kneeling, on one knee, on hands
  and knees, on hands and feet, squatting, bent over, standing) and the moves between them are said,
  and a clip whose postures are none of these says nothing of them; crawling is a run of frames on
  all fours in which the pelvis travels 20 cm.

Sides are the plan's (the sense of a cartwheel, log roll, spin, sideways jump or walk) or the
joints' (the knee down, the side lain on); the mirrored clip takes the captions with the side words
swapped (:func:`mirror_general_caption`).

* ``free`` mode (random upright movement with no nameable action) gets generic captions ("a person
  moves their arms and legs around freely"): true, and they keep the motion's variety in the
  denoiser's data; the words commit to nothing.
* a clip of another mode in which no action is whole (a 2-s clip cut from the middle of a
  cartwheel) gets no captions (:func:`general_steps` returns ``[]``); the corpus build leaves it out.

:data:`GENERAL_ACTIONS` lists the step names with their key words and example prompts (for a
benchmark's per-action checks).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ...side_words import mirror_side_words
from ...skeleton import PART_NAMES
from ..texts import split_words
from .general import GeneralClip, GeneralEvent
from .language import (EXTRA_SUBJECTS, FRAMES, MOOD_STYLE, SUBJECTS, Caption, Item, _Builder, _choose, _cover,
                       _distinct_captions, _fill, _items, _open_frame, _styled_phrases, _units, _word, _write_frame)

__all__ = ["GeneralStep", "GeneralAction", "GENERAL_ACTIONS", "GENERAL_RULES", "MEASURED_POSTURES", "general_steps",
           "measured_postures", "body_axes", "facing", "pitch_rotation", "yaw_rotation", "travel", "airborne", "inverted",
           "render_general_caption", "render_general_captions", "mirror_general_caption", "general_vocabulary",
           "step_parts", "parse_general_prompt", "GeneralPhrase"]

_LR = ("left", "right")
_LOWER = ("root", "left leg", "right leg")
_ALL = tuple(PART_NAMES)


@dataclass(frozen=True)
class GeneralStep:
    """One nameable action of a general clip.

    ``action`` is a key of :data:`GENERAL_RULES`; ``frames`` the joint frames ``[f0, f1)`` it takes;
    ``side`` the side its words name ("left" / "right"), ``turn`` the way the body turned meanwhile
    (locomotion: "left", "right" or "around"), ``reps`` how many times in a row it is done.
    """

    action: str
    frames: tuple[int, int]
    side: str | None = None
    reps: int = 1
    turn: str | None = None
    turn_side: str | None = None
    info: dict = field(default_factory=dict, hash=False, compare=False)

    @property
    def parts(self) -> tuple[str, ...]:
        return step_parts(self.action)


@dataclass(frozen=True)
class _Rule:
    """A way of saying a step: a template of :func:`.language._fill` tokens (``V:lemma``, ``{poss}``,
    ``{side}``, ``{refl}``, ``{num}``, ``word/POS``). ``reps``: "once" (a single time only), "suffix"
    ("twice", "three times" follow when repeated) or "count" (``{num}`` says the count, two or more)."""

    template: str
    sides: tuple = (None,)
    reps: str = "once"


def _r(template: str, sides=(None,), reps: str = "once") -> list[_Rule]:
    """Rules for every choice of the ``[a|b]`` groups of ``template``."""
    import re

    parts = re.split(r"(\[[^\]]*\])", template)
    choices = [p[1:-1].split("|") if p.startswith("[") else [p] for p in parts]
    return [_Rule(" ".join("".join(c).split()), sides, reps) for c in itertools.product(*choices)]


def _rules(*groups: list[_Rule]) -> tuple[_Rule, ...]:
    return tuple(r for g in groups for r in g)


_S = "suffix"
#: Phrase rules per step action.
GENERAL_RULES: dict[str, tuple[_Rule, ...]] = {
    # ------------------------------------------------------------------ free movement (generic)
    "free": _rules(_r("V:move {poss} arms and legs around [freely|randomly]"), _r("V:move around [freely|randomly]"),
                   _r("V:make random/ADJ movements"), _r("V:make [random/ADJ|unusual/ADJ] movements with {poss} [arms and legs|body]"),
                   _r("V:move {poss} [whole|entire] body [freely|randomly|around]"), _r("V:move {poss} limbs around [freely|randomly]"),
                   _r("V:move freely"), _r("V:do a series of random/ADJ movements"), _r("V:move around aimlessly"),
                   _r("V:shift {poss} weight and V:move {poss} arms around")),
    # ------------------------------------------------------------------ locomotion
    "walk_forward": _rules(_r("V:walk forward"), _r("V:walk"), _r("V:move forward"), _r("V:take a few steps/NOUN forward"),
                           _r("V:stroll forward"), _r("V:walk ahead"), _r("V:step forward")),
    "walk_backward": _rules(_r("V:walk [backward|backwards]"), _r("V:step backward"), _r("V:move backward"),
                            _r("V:back up"), _r("V:take a few steps/NOUN back/ADV"), _r("V:walk back/ADV")),
    "walk_side": _rules(_r("V:walk sideways to the {side:NOUN}", _LR), _r("V:sidestep to the {side:NOUN}", _LR),
                        _r("V:step sideways to the {side:NOUN}", _LR), _r("V:move sideways to the {side:NOUN}", _LR),
                        _r("V:shuffle sideways to the {side:NOUN}", _LR)),
    "walk_diagonal": _rules(_r("V:walk diagonally forward to the {side:NOUN}", _LR),
                            _r("V:walk forward and to the {side:NOUN}", _LR),
                            _r("V:move diagonally forward to the {side:NOUN}", _LR),
                            _r("V:walk diagonally to the {side:NOUN}", _LR)),
    "walk_diagonal_back": _rules(_r("V:walk diagonally backward to the {side:NOUN}", _LR),
                                 _r("V:walk backward and to the {side:NOUN}", _LR),
                                 _r("V:step back/ADV diagonally to the {side:NOUN}", _LR),
                                 _r("V:move backward and to the {side:NOUN}", _LR)),
    "run_forward": _rules(_r("V:run forward"), _r("V:run"), _r("V:jog forward"), _r("V:run ahead"), _r("V:jog"),
                          _r("V:run a short distance/NOUN")),
    "run_backward": _rules(_r("V:run [backward|backwards]"), _r("V:jog backward"), _r("V:run back/ADV")),
    "run_side": _rules(_r("V:run sideways to the {side:NOUN}", _LR), _r("V:jog sideways to the {side:NOUN}", _LR),
                       _r("V:run to the {side:NOUN}", _LR)),
    "run_diagonal": _rules(_r("V:run diagonally forward to the {side:NOUN}", _LR),
                           _r("V:run forward and to the {side:NOUN}", _LR), _r("V:jog diagonally to the {side:NOUN}", _LR)),
    "run_diagonal_back": _rules(_r("V:run diagonally backward to the {side:NOUN}", _LR),
                                _r("V:jog backward and to the {side:NOUN}", _LR)),
    "move_forward": _rules(_r("V:move forward"), _r("V:go forward"), _r("V:walk and V:jog forward"),
                           _r("V:make {poss} way/NOUN forward")),
    "move_backward": _rules(_r("V:move backward"), _r("V:go backward"), _r("V:move back/ADV")),
    "move_side": _rules(_r("V:move sideways to the {side:NOUN}", _LR), _r("V:go sideways to the {side:NOUN}", _LR),
                        _r("V:move to the {side:NOUN}", _LR)),
    "move_diagonal": _rules(_r("V:move diagonally forward to the {side:NOUN}", _LR),
                            _r("V:move forward and to the {side:NOUN}", _LR)),
    "move_diagonal_back": _rules(_r("V:move diagonally backward to the {side:NOUN}", _LR),
                                 _r("V:move backward and to the {side:NOUN}", _LR)),
    "stop": _rules(_r("V:stop"), _r("V:stand still"), _r("V:come to a stop/NOUN"), _r("V:pause"),
                   _r("V:stop for a moment/NOUN"), _r("V:stand still for a moment/NOUN")),
    "turn": _rules(_r("V:turn to the {side:NOUN}", _LR), _r("V:turn {side:ADV}", _LR), _r("V:turn to {poss} {side:NOUN}", _LR),
                   _r("V:turn to face/VERB {poss} {side:NOUN}", _LR)),
    "turn_around": _rules(_r("V:turn around"), _r("V:turn to face/VERB the other/ADJ way/NOUN"), _r("V:turn all the way around"),
                          _r("V:turn around to the {side:NOUN}", _LR), _r("V:turn around to {poss} {side:NOUN}", _LR)),
    # ------------------------------------------------------------------ jumps
    "jump_up": _rules(_r("V:jump", reps=_S), _r("V:jump up", reps=_S), _r("V:jump in place", reps=_S),
                      _r("V:jump straight up", reps=_S), _r("V:jump on the spot", reps=_S), _r("V:hop in place", reps=_S),
                      _r("V:jump into the air", reps=_S), _r("V:do {num} jumps/NOUN in place", reps="count")),
    "jump_forward": _rules(_r("V:jump forward", reps=_S), _r("V:leap forward", reps=_S), _r("V:jump ahead", reps=_S),
                           _r("V:hop forward", reps=_S), _r("V:do {num} jumps/NOUN forward", reps="count")),
    "long_jump": _rules(_r("V:do a long/ADJ jump/NOUN"), _r("V:leap far/ADV forward"), _r("V:jump far/ADV forward"),
                        _r("V:take a big leap/NOUN forward"), _r("V:do a long/ADJ jump/NOUN forward")),
    "jump_backward": _rules(_r("V:jump [backward|backwards]", reps=_S), _r("V:jump back/ADV", reps=_S),
                            _r("V:hop backward", reps=_S), _r("V:leap backward", reps=_S)),
    "jump_side": _rules(_r("V:jump to the {side:NOUN}", _LR, _S), _r("V:jump sideways to the {side:NOUN}", _LR, _S),
                        _r("V:hop to the {side:NOUN}", _LR, _S), _r("V:leap to the {side:NOUN}", _LR, _S),
                        _r("V:jump over to the {side:NOUN}", _LR, _S)),
    "jump_turn": _rules(_r("V:jump and V:turn to the {side:NOUN}", _LR, _S), _r("V:jump and V:turn {side:ADV} in the air", _LR, _S),
                        _r("V:do a quarter/NOUN turn/NOUN jump/NOUN to the {side:NOUN}", _LR, _S),
                        _r("V:jump and V:turn a quarter/NOUN to the {side:NOUN}", _LR, _S)),
    "jump_around": _rules(_r("V:jump and V:turn around", reps=_S), _r("V:jump and V:turn around in the air", reps=_S),
                          _r("V:do a half/ADJ turn/NOUN in the air", reps=_S), _r("V:jump around to face/VERB the other way/NOUN", reps=_S),
                          _r("V:jump and V:turn around to the {side:NOUN}", _LR, _S)),
    "jump_spin": _rules(_r("V:jump and V:spin around", reps=_S), _r("V:jump and V:spin around in the air", reps=_S),
                        _r("V:do a full/ADJ spin/NOUN in the air", reps=_S), _r("V:jump and V:spin in a full circle", reps=_S),
                        _r("V:jump and V:spin all the way around", reps=_S), _r("V:do a spinning/VERB jump/NOUN", reps=_S), _r("V:jump and V:spin", reps=_S),
                        _r("V:jump and V:spin to the {side:NOUN}", _LR, _S), _r("V:jump and V:spin {side:ADV}", _LR, _S)),
    "tuck_jump": _rules(_r("V:do a tuck/NOUN jump/NOUN", reps=_S), _r("V:jump and V:pull {poss} knees to {poss} chest", reps=_S),
                        _r("V:jump and V:tuck {poss} knees up", reps=_S), _r("V:jump up and V:tuck {poss} legs in", reps=_S),
                        _r("V:do {num} tuck/NOUN jumps/NOUN", reps="count")),
    "star_jump": _rules(_r("V:jump and V:spread {poss} arms and legs", reps=_S),
                        _r("V:jump with {poss} arms and legs spread/VERB wide", reps=_S),
                        _r("V:jump and V:spread {poss} arms and legs wide in the air", reps=_S),
                        _r("V:leap up with arms and legs spread/VERB out", reps=_S)),
    "split_jump": _rules(_r("V:do a split/NOUN jump/NOUN", reps=_S), _r("V:jump with {poss} legs apart", reps=_S),
                         _r("V:jump and V:do the splits/NOUN in the air", reps=_S),
                         _r("V:leap with one leg forward and one leg back/ADV", reps=_S)),
    # ------------------------------------------------------------------ acrobatics
    "front_flip": _rules(_r("V:do a front/ADJ flip/NOUN", reps=_S), _r("V:flip forward", reps=_S),
                         _r("V:do a forward/ADJ somersault/NOUN in the air", reps=_S), _r("V:do a front/ADJ somersault/NOUN", reps=_S),
                         _r("V:jump and V:flip forward", reps=_S), _r("V:do a flip/NOUN forward", reps=_S)),
    "back_flip": _rules(_r("V:do a backflip", reps=_S), _r("V:do a back/ADJ flip/NOUN", reps=_S), _r("V:flip backward", reps=_S),
                        _r("V:do a backward/ADJ somersault/NOUN in the air", reps=_S), _r("V:jump and V:flip backward", reps=_S),
                        _r("V:do a back/ADJ somersault/NOUN", reps=_S), _r("V:do {num} backflips", reps="count")),
    "forward_roll": _rules(_r("V:do a forward/ADJ roll/NOUN", reps=_S), _r("V:roll forward", reps=_S),
                           _r("V:do a somersault/NOUN on the [floor|ground]", reps=_S), _r("V:tuck and V:roll forward", reps=_S),
                           _r("V:do a forward/ADJ somersault/NOUN", reps=_S), _r("V:roll forward on the [floor|ground]", reps=_S),
                           _r("V:do {num} forward/ADJ rolls/NOUN", reps="count")),
    "backward_roll": _rules(_r("V:do a backward/ADJ roll/NOUN", reps=_S), _r("V:roll backward", reps=_S),
                            _r("V:roll [backward|backwards] on the [floor|ground]", reps=_S), _r("V:tuck and V:roll backward", reps=_S),
                            _r("V:do a backward/ADJ somersault/NOUN on the floor", reps=_S), _r("V:do a back/ADJ roll/NOUN", reps=_S)),
    "log_roll": _rules(_r("V:roll over on the [floor|ground]"), _r("V:roll sideways across the floor"),
                       _r("V:roll to the {side:NOUN}", _LR), _r("V:roll over to the {side:NOUN}", _LR),
                       _r("V:roll across the floor to the {side:NOUN}", _LR), _r("V:roll over")),
    "log_roll_many": _rules(_r("V:roll over several times"), _r("V:roll over and over"),
                            _r("V:roll over several times to the {side:NOUN}", _LR), _r("V:roll across the floor"),
                            _r("V:roll several times to the {side:NOUN}", _LR), _r("V:roll sideways across the [floor|ground]")),
    "lie_and_roll": _rules(_r("V:lie down and V:roll over"), _r("V:lie down on the [floor|ground] and V:roll over"),
                           _r("V:lie down and V:roll to the {side:NOUN}", _LR), _r("V:get down on the floor and V:roll over"),
                           _r("V:lie down and V:roll sideways")),
    "cartwheel": _rules(_r("V:do a cartwheel/NOUN", reps=_S), _r("V:do a cartwheel/NOUN to the {side:NOUN}", _LR, _S),
                        _r("V:cartwheel to the {side:NOUN}", _LR, _S), _r("V:perform a cartwheel/NOUN", reps=_S),
                        _r("V:turn a cartwheel/NOUN", reps=_S), _r("V:do a cartwheel/NOUN sideways", reps=_S),
                        _r("V:do {num} cartwheels/NOUN", reps="count"),
                        _r("V:do {num} cartwheels/NOUN to the {side:NOUN}", _LR, "count")),
    "handstand": _rules(_r("V:do a handstand"), _r("V:kick up into a handstand"), _r("V:go into a handstand"),
                        _r("V:do a handstand and V:come back/ADV down"), _r("V:stand on {poss} hands"),
                        _r("V:balance on {poss} hands"), _r("V:put {poss} hands on the floor and V:kick up into a handstand"),
                        _r("V:do a handstand and then V:stand back/ADV up")),
    "walkover": _rules(_r("V:do a walkover"), _r("V:do a handstand walkover"),
                       _r("V:go over into a handstand and V:come down on the other/ADJ side/NOUN"),
                       _r("V:do a handstand and V:come down on the other/ADJ side/NOUN"),
                       _r("V:kick up into a handstand and V:come down on the other/ADJ side/NOUN")),
    # ------------------------------------------------------------------ floor work: states at the start of a clip
    "lying_back": _rules(_r("V:lie on {poss} back"), _r("V:lie on the [floor|ground]"), _r("V:lie on {poss} back on the floor")),
    "lying_front": _rules(_r("V:lie on {poss} [stomach|belly]"), _r("V:lie face/NOUN down"), _r("V:lie face/NOUN down on the floor")),
    "lying_side": _rules(_r("V:lie on {poss} {side} side", _LR), _r("V:lie on the floor on {poss} {side} side", _LR)),
    "sitting": _rules(_r("V:sit on the [floor|ground]"), _r("V:sit on the floor")),
    "kneeling": _rules(_r("V:kneel on the [floor|ground]"), _r("V:kneel"), _r("V:kneel on both knees")),
    "kneeling_heels": _rules(_r("V:sit on {poss} heels"), _r("V:kneel and V:sit back/ADV on {poss} heels")),
    "kneeling_one": _rules(_r("V:kneel on {poss} {side} knee", _LR), _r("V:kneel on one knee", _LR)),
    "on_hands_knees": _rules(_r("V:rest on {poss} hands and knees"), _r("V:kneel on all/DET fours/NOUN"),
                             _r("V:stay on {poss} hands and knees"), _r("V:stay on all/DET fours/NOUN")),
    "on_hands_feet": _rules(_r("V:bend over with {poss} hands on the floor"), _r("V:stand on {poss} hands and feet")),
    "crouching": _rules(_r("V:crouch"), _r("V:squat"), _r("V:crouch low"), _r("V:squat low")),
    "bent_over": _rules(_r("V:bend over"), _r("V:bend forward")),
    # ------------------------------------------------------------------ floor work: moves between postures
    "lie_down_back": _rules(_r("V:lie down on {poss} back"), _r("V:lie back/ADV"), _r("V:lie down"), _r("V:lie back/ADV on the [floor|ground]"),
                            _r("V:lower {refl} onto {poss} back"), _r("V:lie down on the [floor|ground]")),
    "lie_down_front": _rules(_r("V:lie down on {poss} [stomach|belly]"), _r("V:lie face/NOUN down on the floor"),
                             _r("V:lie down face/NOUN down"), _r("V:lower {refl} onto {poss} stomach")),
    "lie_down_side": _rules(_r("V:lie down on {poss} {side} side", _LR), _r("V:lie on {poss} {side} side", _LR),
                            _r("V:lower {refl} onto {poss} {side} side", _LR)),
    "roll_onto_back": _rules(_r("V:roll onto {poss} back"), _r("V:roll over onto {poss} back"), _r("V:turn over onto {poss} back"),
                             _r("V:roll back/ADV onto {poss} back")),
    "roll_onto_front": _rules(_r("V:roll onto {poss} [stomach|belly]"), _r("V:roll over onto {poss} stomach"),
                              _r("V:turn over onto {poss} [stomach|belly]"), _r("V:roll over to/PART lie/VERB face/NOUN down")),
    "roll_onto_side": _rules(_r("V:roll onto {poss} {side} side", _LR), _r("V:roll over onto {poss} {side} side", _LR),
                             _r("V:turn onto {poss} {side} side", _LR)),
    "sit_up": _rules(_r("V:sit up"), _r("V:sit back/ADV up"), _r("V:sit up on the floor"), _r("V:push {refl} up to/PART sit/VERB")),
    "sit_down": _rules(_r("V:sit down on the [floor|ground]"), _r("V:sit down"), _r("V:sit on the floor"),
                       _r("V:lower {refl} to the [floor|ground]"), _r("V:take a seat/NOUN on the floor")),
    "get_up": _rules(_r("V:get up"), _r("V:stand up"), _r("V:get back/ADV up"), _r("V:get up off the [floor|ground]"),
                     _r("V:rise to {poss} feet/NOUN"), _r("V:get back/ADV on {poss} feet/NOUN"), _r("V:stand back/ADV up")),
    "stand_up": _rules(_r("V:stand up"), _r("V:stand back/ADV up"), _r("V:rise"), _r("V:get up"), _r("V:stand up straight/ADV")),
    "straighten_up": _rules(_r("V:straighten up"), _r("V:stand up straight/ADV"), _r("V:straighten {poss} back")),
    "squat_down": _rules(_r("V:squat down"), _r("V:crouch down"), _r("V:squat"), _r("V:crouch"), _r("V:go down into a squat/NOUN")),
    "into_squat": _rules(_r("V:come up into a squat/NOUN"), _r("V:get into a crouch/NOUN"), _r("V:move into a squat/NOUN"),
                         _r("V:rise into a crouch/NOUN")),
    "kneel_one": _rules(_r("V:kneel on {poss} {side} knee", _LR), _r("V:kneel down on {poss} {side} knee", _LR),
                        _r("V:go down on {poss} {side} knee", _LR), _r("V:drop to {poss} {side} knee", _LR),
                        _r("V:go down on one knee", _LR), _r("V:kneel on one knee", _LR)),
    "kneel_down": _rules(_r("V:kneel down"), _r("V:kneel on both knees"), _r("V:get down on {poss} knees"),
                         _r("V:go down on both knees"), _r("V:kneel on the floor"),
                         _r("V:kneel down on both knees")),
    "kneel_up": _rules(_r("V:kneel up"), _r("V:come up onto {poss} knees"), _r("V:kneel upright/ADV"),
                       _r("V:straighten up on {poss} knees")),
    "sit_on_heels": _rules(_r("V:sit back/ADV on {poss} heels"), _r("V:kneel and V:sit on {poss} heels"),
                           _r("V:lower {refl} onto {poss} heels")),
    "onto_knees": _rules(_r("V:push {refl} up onto {poss} knees"), _r("V:get up onto {poss} knees"),
                         _r("V:come up onto {poss} knees")),
    "hands_knees": _rules(_r("V:get down on {poss} hands and knees"), _r("V:go down on all/DET fours/NOUN"),
                          _r("V:get on all/DET fours/NOUN"), _r("V:get down on all/DET fours/NOUN"),
                          _r("V:put {poss} hands on the floor and V:kneel on all/DET fours/NOUN")),
    "push_up_hands_knees": _rules(_r("V:push up onto {poss} hands and knees"), _r("V:push {refl} up onto all/DET fours/NOUN"),
                                  _r("V:get up on {poss} hands and knees")),
    "hands_feet": _rules(_r("V:put {poss} hands on the floor"), _r("V:bend down and V:put {poss} hands on the [floor|ground]"),
                         _r("V:get onto {poss} hands and feet")),
    "knees_off": _rules(_r("V:lift {poss} knees off the floor"), _r("V:raise {poss} hips and V:lift {poss} knees off the floor"),
                        _r("V:push {poss} hips up")),
    "bend_over": _rules(_r("V:bend over"), _r("V:bend forward"), _r("V:bend down"), _r("V:lean forward and V:bend over")),
    "crawl_forward": _rules(_r("V:crawl forward"), _r("V:crawl forward on all/DET fours/NOUN"), _r("V:crawl on all/DET fours/NOUN"),
                            _r("V:crawl ahead on the floor"), _r("V:move forward on all/DET fours/NOUN"),
                            _r("V:crawl along the floor"), _r("V:crawl forward on {poss} hands and feet/NOUN")),
    "crawl_backward": _rules(_r("V:crawl backward"), _r("V:crawl backward on all/DET fours/NOUN"),
                             _r("V:move backward on all/DET fours/NOUN"), _r("V:crawl [backward|backwards] on the floor")),
}
GENERAL_RULES["crawl_forward_knees"] = GENERAL_RULES["crawl_forward"][:-1] + _rules(
    _r("V:crawl on {poss} hands and knees"), _r("V:crawl forward on {poss} hands and knees"))
GENERAL_RULES["crawl_backward_knees"] = GENERAL_RULES["crawl_backward"] + _rules(
    _r("V:crawl backward on {poss} hands and knees"))

#: Words after a locomotion phrase that say how the body turned meanwhile ("{side}" is the turn's).
_TURN_TAILS = {
    "side": ("and V:turn {side:ADV}", "and V:turn to the {side:NOUN}", "while turning/VERB to the {side:NOUN}",
             "and V:turn to {poss} {side:NOUN}", "in a curve/NOUN to the {side:NOUN}"),
    "around": ("and V:turn around", "and then V:turn around", "while turning/VERB around"),
}
#: Manner words (before the verb?) that fit any step without changing what it says.
_MANNER = tuple((w, pre) for w, pre, kinds in MOOD_STYLE if kinds is None
                and w.split()[0] not in ("awkwardly", "clumsily", "nervously", "shyly", "dramatically", "loosely",
                                         "firmly", "in", "with"))
#: Subjects (words, possessives, pronoun) per mode: acrobatics take gymnasts and young people.
_YOUNG = {"an old man", "an elderly man", "an elderly woman", "an old woman", "an older person"}
_ACRO_SUBJECTS = (("a gymnast", ("her", "his", "their"), None), ("the gymnast", ("her", "his", "their"), None),
                  ("an acrobat", ("his", "her", "their"), None), ("the athlete", ("his", "her"), None))

_ACROBATIC = frozenset({"front_flip", "back_flip", "forward_roll", "backward_roll", "cartwheel", "handstand", "walkover"})


def step_parts(action: str) -> tuple[str, ...]:
    """Body parts a step drives (annotation ``parts``, canonical order): locomotion and jumps the root
    and legs (the corpus's walk, turn and jump rules: jumps all parts), everything on the floor, the
    acrobatics and the free movement all parts; crawling the root, legs and arms."""
    if action in ("free",) or action in _ACROBATIC or action.startswith(("log_roll", "lie", "roll", "sit", "get_up",
                                                                        "stand_up", "straighten", "bend", "bent")):
        return _ALL
    if action.startswith(("jump", "long_jump", "tuck_jump", "star_jump", "split_jump")):
        return _ALL
    if action.startswith(("crawl", "hands", "push_up_hands", "on_hands", "knees_off")):
        return ("root", "left leg", "right leg", "left arm", "right arm")
    if action.startswith(("walk", "run", "move", "stop", "turn")):
        return _LOWER
    return _LOWER + ("spine",)                       # kneeling, squatting, crouching


# ============================================================================ measuring the clip
def body_axes(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame unit vectors of the trunk: ``up`` (pelvis to neck), ``right`` (left to right hip and
    shoulder, square to ``up``) and ``front`` (``up x right``: the way the chest faces)."""
    up = joints[:, 12] - joints[:, 0]
    up = up / (np.linalg.norm(up, axis=-1, keepdims=True) + 1e-9)
    right = (joints[:, 2] - joints[:, 1]) + (joints[:, 17] - joints[:, 16])
    right = right - (right * up).sum(-1, keepdims=True) * up
    right = right / (np.linalg.norm(right, axis=-1, keepdims=True) + 1e-9)
    return up, right, np.cross(up, right)


def facing(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(forward, left) horizontal unit vectors per frame, from the hips and shoulders (HumanML3D's facing)."""
    from ...skeleton import get_skeleton

    r_hip, l_hip, sdr_r, sdr_l = get_skeleton("humanml3d").face_joint_indx
    across = (joints[:, r_hip] - joints[:, l_hip]) + (joints[:, sdr_r] - joints[:, sdr_l])
    across = across * np.array([1.0, 0.0, 1.0])
    across /= np.linalg.norm(across, axis=-1, keepdims=True) + 1e-9
    fwd = np.cross(np.array([0.0, 1.0, 0.0]), across)
    return fwd, -across


#: Postures :func:`measured_postures` tells apart.
MEASURED_POSTURES = ("standing", "bent_over", "squatting", "kneeling", "kneeling_one", "sitting", "hands_knees",
                     "hands_feet", "lying_back", "lying_front", "lying_side", "other")
_L_KNEE, _R_KNEE, _L_WRIST, _R_WRIST, _HEAD, _PELVIS = 4, 5, 20, 21, 15, 0


def measured_postures(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The posture of every frame as the joints show it (:data:`MEASURED_POSTURES`) and its side
    (``"left"`` / ``"right"``: the knee down when kneeling on one knee, the side lain on; else ``""``).

    Heights are joint centres (m): a knee resting on the floor is about 0.05 up, a flat foot's
    ankle 0.08, a pelvis on the floor 0.11.
    """
    y = joints[..., 1]
    up, right, front = body_axes(joints)
    pel, head = y[:, _PELVIS], y[:, _HEAD]
    lk, rk, lw, rw = y[:, _L_KNEE], y[:, _R_KNEE], y[:, _L_WRIST], y[:, _R_WRIST]
    lf, rf = np.minimum(y[:, 7], y[:, 10]), np.minimum(y[:, 8], y[:, 11])
    feet_down = np.maximum(lf, rf) < 0.12
    knees_down = np.maximum(lk, rk) < 0.15
    hands_down = (np.minimum(lw, rw) < 0.12) & (np.maximum(lw, rw) < 0.2)
    flat, low = np.abs(up[:, 1]) < 0.5, pel < 0.35
    out = np.full(len(joints), "other", dtype=object)
    side = np.full(len(joints), "", dtype=object)
    out[(pel > 0.75) & (up[:, 1] > 0.8) & (np.minimum(lf, rf) < 0.1)] = "standing"
    out[(pel > 0.6) & (up[:, 1] < 0.6) & (up[:, 1] > -0.3) & feet_down] = "bent_over"
    thigh_l, thigh_r = joints[:, 4] - joints[:, 1], joints[:, 5] - joints[:, 2]
    shin_l, shin_r = joints[:, 7] - joints[:, 4], joints[:, 8] - joints[:, 5]

    def flexion(a, b):
        c = (a * b).sum(-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1) + 1e-9)
        return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))

    knees_bent = np.minimum(flexion(thigh_l, shin_l), flexion(thigh_r, shin_r)) > 70.0
    out[(pel > 0.3) & (pel < 0.72) & (up[:, 1] > 0.5) & feet_down & knees_bent & (np.minimum(lk, rk) > 0.25)
        & (head - pel > 0.3)] = "squatting"
    out[hands_down & feet_down & (np.minimum(lk, rk) > 0.12) & (up[:, 1] < 0.7) & (front[:, 1] < -0.3)] = "hands_feet"
    one_l = (lk < 0.15) & (rk > 0.25) & (rf < 0.12)
    one_r = (rk < 0.15) & (lk > 0.25) & (lf < 0.12)
    m = (one_l | one_r) & (up[:, 1] > 0.6)
    out[m] = "kneeling_one"
    side[m & one_l] = "left"
    side[m & one_r] = "right"
    out[knees_down & (up[:, 1] > 0.6)] = "kneeling"
    out[knees_down & hands_down & (np.abs(up[:, 1]) < 0.6) & (front[:, 1] < -0.6)] = "hands_knees"
    out[low & (up[:, 1] > 0.5) & (head - pel > 0.3)] = "sitting"
    out[low & flat & (front[:, 1] > 0.6)] = "lying_back"
    out[low & flat & (front[:, 1] < -0.6)] = "lying_front"
    m = low & flat & (np.abs(right[:, 1]) > 0.6)
    out[m] = "lying_side"
    side[m] = np.where(right[m, 1] > 0, "left", "right")      # the right side up: lying on the left
    side[(out != "kneeling_one") & (out != "lying_side")] = ""
    return out, side


def _posture_at(postures: np.ndarray, sides: np.ndarray, f: int) -> tuple[str, str]:
    """The posture at frame ``f`` if it also holds on most of the frames within 2 of it."""
    lo, hi = max(0, f - 2), min(len(postures), f + 3)
    name = postures[f]
    if name == "other" or (postures[lo:hi] == name).sum() < 0.6 * (hi - lo):
        return "other", ""
    return str(name), str(sides[f])


def pitch_rotation(joints: np.ndarray) -> float:
    """Degrees the trunk turned head over heels (> 0 forwards: about the body's left axis), summed per frame."""
    up, right, _ = body_axes(joints)
    axis = -right[:-1]
    cross = np.cross(up[:-1], up[1:])
    return float(np.degrees(np.arctan2((cross * axis).sum(-1), (up[:-1] * up[1:]).sum(-1)).sum()))


def yaw_rotation(joints: np.ndarray) -> float:
    """Degrees the facing turned about the vertical (> 0 to the left), summed per frame."""
    fwd, _ = facing(joints)
    yaw = np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2]))
    return float(np.degrees(yaw[-1] - yaw[0]))


def travel(joints: np.ndarray, fixed: bool = False) -> tuple[float, float]:
    """(forward, leftward) metres the pelvis travelled, each frame's step taken in that frame's facing
    (``fixed``: in the first frame's facing, for a body that turns over, whose hips swap sides)."""
    fwd, left = facing(joints[:1] if fixed else joints)
    step = np.diff(joints[:, 0], axis=0)
    if fixed:
        d = step.sum(axis=0)
        return float(d @ fwd[0]), float(d @ left[0])
    return float((step * fwd[:-1]).sum()), float((step * left[:-1]).sum())


def airborne(joints: np.ndarray) -> np.ndarray:
    """Frames in flight: every joint at least 3 cm above the lowest a joint rests (a flat foot's toes, 1.2 cm)."""
    return joints[..., 1].min(axis=1) > 0.042


def inverted(joints: np.ndarray) -> np.ndarray:
    """Frames with the head below the pelvis."""
    return joints[:, _HEAD, 1] < joints[:, _PELVIS, 1]


# ============================================================================ the plan -> steps
def _coverage(e: GeneralEvent) -> float:
    span = e.planned[1] - e.planned[0]
    return 1.0 if span <= 0 else (e.frames[1] - e.frames[0]) / span


def _span(clip: GeneralClip, frames: tuple[int, int]) -> np.ndarray:
    return clip.joints[frames[0]:max(frames[1], frames[0] + 2)]


def _turn_of(dh: float) -> tuple[str | None, str | None]:
    if abs(dh) >= 140.0:
        return "around", "left" if dh > 0 else "right"
    if abs(dh) >= 50.0:
        return "side", "left" if dh > 0 else "right"
    return None, None


_WAY = {0.0: "forward", 180.0: "backward", 90.0: "side", 45.0: "diagonal", 135.0: "diagonal_back"}


def _locomotion_steps(clip: GeneralClip) -> list[GeneralStep]:
    """Stretches of one gait and direction (merged gait keys), each checked on the joints: the pelvis
    travels at least 0.3 m within 45 deg of the said direction; a turn is said when the facing turned
    50 deg (140: "around") and the plan's heading agrees."""
    groups: list[list] = []                              # [(label, direction), f0, f1, gaits]
    for e in clip.events:
        if e.action not in ("walk", "run", "stand"):
            continue
        key = ("stand", None) if e.action == "stand" else ("move", e.info["direction"])
        if groups and groups[-1][0] == key:
            groups[-1][2] = e.frames[1]
            groups[-1][3].add(e.action)
        else:
            groups.append([key, e.frames[0], e.frames[1], {e.action}])
    n = clip.num_frames
    steps = []
    for (label, d), f0, f1, kinds in groups:
        f1 = min(f1 + 1, n)                              # the gait keys' spans share their end frames
        if f1 - f0 < 8:
            continue
        seg = clip.joints[f0:f1]
        dh = yaw_rotation(seg)
        plan_dh = float(np.degrees(clip.dofs[f1 - 1, 0] - clip.dofs[f0, 0]))
        mode, tside = _turn_of(dh)
        if mode is not None and _turn_of(plan_dh)[1] != tside:
            mode = tside = None
        if label == "stand":
            speed = np.linalg.norm(np.diff(seg[:, 0, [0, 2]], axis=0), axis=-1) * 20.0
            if mode == "around":
                steps.append(GeneralStep("turn_around", (f0, f1), side=tside))
            elif mode == "side":
                steps.append(GeneralStep("turn", (f0, f1), side=tside))
            elif 0 < f0 and f1 < n and speed.min() < 0.25:   # a stop between two stretches of moving
                steps.append(GeneralStep("stop", (f0, f1)))
            continue
        fwd_m, left_m = travel(seg)
        if np.hypot(fwd_m, left_m) < 0.3:
            continue
        ad = abs(d)
        want = np.radians(d)
        got = np.arctan2(left_m, fwd_m)
        if abs((np.degrees(got - want) + 180.0) % 360.0 - 180.0) > 45.0:
            continue                                     # the legs' direction did not carry the body that way
        gait = "walk" if kinds == {"walk"} else ("run" if kinds == {"run"} else "move")
        side = None if ad in (0.0, 180.0) else ("left" if d > 0 else "right")
        steps.append(GeneralStep(f"{gait}_{_WAY[ad]}", (f0, f1), side=side, turn=mode, turn_side=tside))
    return steps


def _jump_step(clip: GeneralClip, e: GeneralEvent) -> GeneralStep | None:
    """The step of a jump or flip event, or None if the joints do not show it (no flight; a spin,
    flip or direction of travel other than the plan's)."""
    i = e.info
    seg = _span(clip, e.frames)
    fl0, fl1 = i["flight"]
    if airborne(clip.joints[max(fl0, 0):fl1 + 1]).sum() < 2:
        return None
    if e.action == "flip":
        rot = pitch_rotation(seg)
        if abs(rot) < 270 or np.sign(rot) != np.sign(i["flip"]) or not inverted(seg).any():
            return None
        return GeneralStep("front_flip" if i["flip"] > 0 else "back_flip", e.frames)
    spin, dyaw = i["spin"], yaw_rotation(seg)
    side = "left" if spin > 0 else "right"
    if abs(spin) >= 60:
        if abs(dyaw - spin) > 60:
            return None
        action = "jump_spin" if abs(spin) >= 300 else ("jump_around" if abs(spin) >= 150 else "jump_turn")
        return GeneralStep(action, e.frames, side=side)
    if abs(dyaw) > 45:
        return None
    if i["air"] in ("tuck", "star", "split"):
        return GeneralStep(f"{i['air']}_jump", e.frames)
    d, dist = i["direction"], i["distance"]
    fwd_m, left_m = travel(seg)
    if dist < 0.4:
        return GeneralStep("jump_up", e.frames) if np.hypot(fwd_m, left_m) < 0.35 else None
    if abs(d) <= 45.0:
        if fwd_m < 0.3:
            return None
        return GeneralStep("long_jump" if fwd_m >= 1.3 else "jump_forward", e.frames)
    if abs(d) >= 135.0:
        return GeneralStep("jump_backward", e.frames) if fwd_m < -0.3 else None
    left = d > 0
    if (left_m > 0.3) if left else (left_m < -0.3):
        return GeneralStep("jump_side", e.frames, side="left" if left else "right")
    return None


def _jump_whole(e: GeneralEvent, n: int) -> bool:
    f0, f1 = e.info["flight"]
    return f0 >= 0 and f1 + 4 <= n and _coverage(e) >= 0.7


def _merge_reps(steps: list[GeneralStep]) -> list[GeneralStep]:
    """Consecutive equal steps that can be counted ("jumps forward twice") become one."""
    out: list[GeneralStep] = []
    for s in steps:
        prev = out[-1] if out else None
        if (prev is not None and prev.action == s.action and prev.side == s.side and prev.reps < 3
                and any(r.reps != "once" for r in GENERAL_RULES[s.action])):
            out[-1] = GeneralStep(s.action, (prev.frames[0], s.frames[1]), s.side, prev.reps + 1, info=prev.info)
        else:
            out.append(s)
    return out


def _jump_steps(clip: GeneralClip) -> list[GeneralStep]:
    n = clip.num_frames
    steps = [_jump_step(clip, e) for e in clip.events if e.action in ("jump", "flip") and _jump_whole(e, n)]
    return _merge_reps([s for s in steps if s is not None])


def _acrobatic_step(clip: GeneralClip, e: GeneralEvent) -> GeneralStep | None:
    i, seg = e.info, _span(clip, e.frames)
    pelvis = seg[:, 0, 1]
    if e.action == "roll":
        rot = pitch_rotation(seg)
        if abs(rot) < 270 or np.sign(rot) != np.sign(i["sign"]) or not inverted(seg).any():
            return None
        return GeneralStep("forward_roll" if i["sign"] > 0 else "backward_roll", e.frames)
    if e.action == "cartwheel":
        if not inverted(seg).any():
            return None
        _, left_m = travel(seg, fixed=True)
        side = "left" if i["sign"] > 0 else "right"
        ok_side = (left_m > 0.3) if side == "left" else (left_m < -0.3)
        return GeneralStep("cartwheel", e.frames, side=side if ok_side else None)
    if e.action == "handstand":
        up0, up1 = i["up"]
        if not (e.frames[0] <= up0 and up1 < clip.num_frames):
            return None
        low = seg[:, :, 1].argmin(axis=1)
        on_hands = inverted(seg) & np.isin(low, (18, 19, _L_WRIST, _R_WRIST))
        if on_hands.sum() < 3:
            return None
        return GeneralStep("walkover" if i["walkover"] else "handstand", e.frames)
    if e.action == "logroll":
        lying = pelvis < 0.35
        if lying.mean() < 0.4:
            return None
        _, left_m = travel(seg[np.argmax(lying):], fixed=True)
        side = "left" if i["sign"] > 0 else "right"
        side = side if ((left_m > 0.3) if side == "left" else (left_m < -0.3)) else None
        if e.planned[0] >= 0 and pelvis[0] > 0.6:
            return GeneralStep("lie_and_roll", e.frames, side=side)
        return GeneralStep("log_roll_many" if abs(i["turn"]) >= 330 else "log_roll", e.frames, side=side)
    return None


def _acrobatic_steps(clip: GeneralClip) -> list[GeneralStep]:
    n = clip.num_frames
    steps = []
    for e in clip.events:
        if e.action in ("jump", "flip"):
            s = _jump_step(clip, e) if _jump_whole(e, n) else None
        elif e.action in ("roll", "logroll", "cartwheel", "handstand") and _coverage(e) >= 0.85:
            s = _acrobatic_step(clip, e)
        else:
            continue
        if s is not None:
            steps.append(s)
    return _merge_reps(steps)


_STATE = {"lying_back": "lying_back", "lying_front": "lying_front", "lying_side": "lying_side", "sitting": "sitting",
          "kneeling_one": "kneeling_one", "hands_knees": "on_hands_knees", "hands_feet": "on_hands_feet",
          "squatting": "crouching", "bent_over": "bent_over"}
_LYING = ("lying_back", "lying_front", "lying_side")
_ALL_FOURS = ("hands_knees", "hands_feet")


def _state_step(name: str, side: str, frames: tuple[int, int], high: bool) -> GeneralStep | None:
    if name == "kneeling":
        return GeneralStep("kneeling" if high else "kneeling_heels", frames)
    if name not in _STATE:
        return None
    return GeneralStep(_STATE[name], frames, side=side or None)


def _move_step(a: str, b: str, side: str, frames: tuple[int, int], high: bool) -> GeneralStep | None:
    """The step of a move from measured posture ``a`` to ``b`` (``side``: ``b``'s, ``high``: kneeling upright)."""
    if b == "standing":
        action = {"squatting": "stand_up", "kneeling_one": "stand_up", "bent_over": "straighten_up"}.get(a, "get_up")
    elif b == "squatting":
        action = "squat_down" if a in ("standing", "bent_over") else "into_squat"
    elif b == "kneeling_one":
        action = "kneel_one"
    elif b == "kneeling":
        if a == "lying_front":
            action = "onto_knees"
        elif a in _ALL_FOURS:
            action = "kneel_up" if high else "sit_on_heels"
        else:
            action = "kneel_down" if high else "sit_on_heels"
    elif b == "sitting":
        action = "sit_up" if a in _LYING else "sit_down"
    elif b in _LYING:
        way = {"lying_back": "back", "lying_front": "front", "lying_side": "side"}[b]
        action = f"roll_onto_{way}" if a in _LYING else f"lie_down_{way}"
    elif b == "hands_knees":
        action = "push_up_hands_knees" if a == "lying_front" else ("onto_knees_all_fours" if a == "hands_feet"
                                                                 else "hands_knees")
    elif b == "hands_feet":
        action = "knees_off" if a == "hands_knees" else "hands_feet"
    elif b == "bent_over":
        action = "bend_over"
    else:
        return None
    if action == "onto_knees_all_fours":
        return None                                      # knees down from hands and feet: no words for it
    return GeneralStep(action, frames, side=side or None)


def _crawls(clip: GeneralClip, postures: np.ndarray) -> list[GeneralStep]:
    """Runs of at least 1 s on all fours (gaps up to 4 frames bridged) in which the pelvis travels at
    least 0.2 m along the facing: "crawls forward" / "backward" (on hands and knees if the knees were
    down on most frames)."""
    from .general_root import intervals

    y = clip.joints[..., 1]
    up, _, front = body_axes(clip.joints)
    fours = ((np.minimum(y[:, _L_WRIST], y[:, _R_WRIST]) < 0.15)
             & (np.minimum(np.maximum(y[:, 7], y[:, 8]), np.maximum(y[:, _L_KNEE], y[:, _R_KNEE])) < 0.18)
             & (np.abs(up[:, 1]) < 0.6) & (front[:, 1] < -0.5) & (y[:, _PELVIS] < 0.8))
    runs = intervals(fours)
    merged: list[list[int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] <= 4:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    out = []
    for a, b in merged:
        if b - a < 20:
            continue
        fwd_m, _ = travel(clip.joints[a:b])
        if abs(fwd_m) < 0.2:
            continue
        knees = (np.maximum(y[a:b, _L_KNEE], y[a:b, _R_KNEE]) < 0.15).mean() > 0.5
        out.append(GeneralStep(f"crawl_{'forward' if fwd_m > 0 else 'backward'}{'_knees' if knees else ''}", (a, b)))
    return out


def _floor_steps(clip: GeneralClip) -> list[GeneralStep]:
    """Floor work, named by the joints: the posture at each of the plan's key frames
    (:func:`measured_postures`; the generator's posture draws do not always make the posture they are
    named after: a "sit" key with bent knees leaves the body on its feet), a step for each change
    between named postures (unnamed ones in between are passed over), the posture the clip starts
    in, and crawling."""
    n = clip.num_frames
    postures, sides = measured_postures(clip.joints)
    keys = [0] + sorted({e.frames[1] - 1 for e in clip.events
                         if e.action == "posture" and e.planned[1] <= n and 0 < e.frames[1] - 1})
    if n - 1 - keys[-1] >= 8:
        keys.append(n - 1)                              # where the clip ends, if it is a posture
    pel = clip.joints[:, _PELVIS, 1]
    named = [(f, *_posture_at(postures, sides, f)) for f in keys]
    while named and named[0][1] == "other":
        named.pop(0)
    steps: list[GeneralStep] = []
    if not named:
        return _crawls(clip, postures)
    f0, p0, s0 = named[0]
    if f0 == 0 and p0 != "standing":                    # the posture the clip starts in, while it is held
        j = 0
        while j + 1 < len(named) and named[j + 1][1:] == (p0, s0):
            j += 1
        if named[j][0] >= 10:
            st = _state_step(p0, s0, (0, named[j][0] + 1), pel[0] > 0.45)
            if st is not None:
                steps.append(st)
    f_last, p_prev, s_prev = named[0]
    away, f_key = False, named[0][0]
    for f, p, s in named[1:]:
        f_before, f_key = f_key, f
        if p == "other":                                 # an unnamed posture: the body left the last named one
            away = True
            continue
        if (p, s) == (p_prev, s_prev):
            if not away:
                f_last = f                               # still holding it (else: back to it, unsaid)
            away = False
            continue
        away = False
        mv = _move_step(p_prev, p, s, (f_before, f + 1), pel[f] > 0.45)   # from the key before (named or not)
        if mv is not None:
            steps.append(mv)
        f_last, p_prev, s_prev = f, p, s
    crawls = _crawls(clip, postures)
    if crawls:
        # moves between all-fours postures inside a crawl are part of it
        steps = [s for s in steps if not any(c.frames[0] <= s.frames[0] and s.frames[1] <= c.frames[1] + 2
                                             and s.action in ("on_hands_knees", "on_hands_feet", "knees_off",
                                                              "hands_knees") for c in crawls)]
        steps = sorted(steps + crawls, key=lambda s: (s.frames[0], s.frames[1]))
    return steps


def general_steps(clip: GeneralClip) -> list[GeneralStep]:
    """The nameable steps of a general clip, in time order (``[]``: nothing nameable is whole)."""
    if clip.mode == "free":
        return [GeneralStep("free", (0, clip.num_frames))]
    if clip.mode == "locomotion":
        return _locomotion_steps(clip)
    if clip.mode == "jump":
        return _jump_steps(clip)
    if clip.mode == "acrobatic":
        return _acrobatic_steps(clip)
    if clip.mode == "floor":
        return _floor_steps(clip)
    raise ValueError(f"unknown general mode {clip.mode!r}")


# ============================================================================ steps -> words
_REPS = {2: ("twice", "two times"), 3: ("three times",), 4: ("four times",)}


def _realisations(step: GeneralStep, form: str, poss: str) -> list[list[Item]]:
    """Every wording of ``step`` (``form`` "pres": "rolls", "ger": "rolling")."""
    out = []
    for rule in GENERAL_RULES[step.action]:
        if rule.sides != (None,) and step.side not in rule.sides:
            continue                                     # the rule names a side the step does not have
        if (rule.reps == "once" and step.reps > 1) or (rule.reps == "count" and step.reps < 2):
            continue
        items = _fill(rule.template, form, step.side if rule.sides != (None,) else None, poss, step.reps)
        tails = [[]]
        if rule.reps == "suffix" and step.reps > 1:
            tails = [[_word(w) for w in t.split()] for t in _REPS[step.reps]]
        for tail in tails:
            out.append(items + tail)
    if step.turn is not None:
        turned = []
        for items in out:
            for t in _TURN_TAILS[step.turn]:
                if "{side" in t and step.turn_side is None:
                    continue
                turned.append(items + _fill(t, form, step.turn_side, poss, 1))
        out = turned
    return out


def _subjects(steps: list[GeneralStep]) -> list[tuple[str, tuple[str, ...], str | None]]:
    subs = list(SUBJECTS) + [s[:3] for s in EXTRA_SUBJECTS if s[3] is None]
    if any(s.action in _ACROBATIC or s.action.startswith(("jump", "tuck", "star", "split", "long")) for s in steps):
        subs = [s for s in subs if s[0] not in _YOUNG] + list(_ACRO_SUBJECTS)
    return subs


def render_general_caption(steps: list[GeneralStep], rng: np.random.Generator, manner_p: float = 0.2) -> Caption:
    """One caption of ``steps`` (phrase spans in step order), in the corpus's sentence frames."""
    if not steps:
        raise ValueError("render_general_caption: no steps to say")
    if rng.random() < 0.65:
        subj, posses, pron = _choose(rng, list(SUBJECTS))
    else:
        subj, posses, pron = _choose(rng, _subjects(steps))
    poss = _choose(rng, list(posses))
    b = _Builder()

    def say(i: int, form: str) -> None:
        items = _choose(rng, _realisations(steps[i], form, poss))
        if rng.random() < manner_p:
            words, before = _choose(rng, [m for m in _MANNER if not (b.after_phrase and m[1])])
            extra = _items(words)
            items = extra + items if before else items + extra
        b.phrase(i, items)

    k = len(steps)
    shape = "single" if k == 1 else ("seq2" if k == 2 else "seq3")
    frames = [f for f in FRAMES[shape] if (pron or "{P}" not in f) and "for a" not in f]
    frame = _choose(rng, frames)
    if k > 3:
        frame = "{S} " + " , then ".join(f"{{A{i}}}" for i in range(k - 1)) + " , and then {A%d}" % (k - 1)
        if rng.random() < 0.5:
            frame = "{S} " + " , then ".join(f"{{A{i}}}" for i in range(k))
    _write_frame(b, _open_frame(frame, rng), subj, pron, say)
    return b.caption(k, period=bool(rng.random() < 0.5))


def render_general_captions(steps: list[GeneralStep], rng: np.random.Generator, n: int = 3,
                            tries: int = 40) -> list[Caption]:
    """``n`` distinct captions of ``steps`` (fewer only if the language has fewer; none without steps)."""
    if not steps:
        return []
    return _distinct_captions(lambda: render_general_caption(steps, rng), n, tries)


def mirror_general_caption(caption: Caption) -> Caption:
    """The caption of the mirrored clip: side words swapped (:func:`salad_core.side_words.mirror_side_words`)
    in the text and the tokens; the spans stay."""
    tokens = tuple((mirror_side_words(t), p) for t, p in caption.tokens)
    return Caption(mirror_side_words(caption.text), tokens, caption.spans)


def general_vocabulary() -> set[str]:
    """Every word a general caption's phrases can use (the frames' and subjects' words are the corpus's)."""
    out: set[str] = set()
    for rules in GENERAL_RULES.values():
        for rule in rules:
            for poss in ("his", "her", "their"):
                for form in ("pres", "ger"):
                    for side in rule.sides:
                        out.update(w for w, _, _ in _fill(rule.template, form, side, poss, 2))
    for tails in _TURN_TAILS.values():
        for t in tails:
            for side in _LR:
                out.update(w for w, _, _ in _fill(t, "pres", side, "his", 1))
                out.update(w for w, _, _ in _fill(t, "ger", side, "his", 1))
    for ws in _REPS.values():
        for w in ws:
            out.update(w.split())
    return out


# ============================================================================ reading prompts
@dataclass(frozen=True)
class GeneralPhrase:
    """A general-motion phrase found in a prompt: word span ``[i0, i1)``, step action (the first of
    ``actions``, every step action whose rules say these words), side (or None)."""

    words: tuple[int, int]
    text: str
    action: str
    side: str | None
    actions: tuple[str, ...] = ()
    turn: str | None = None         # a locomotion phrase's turn: "left", "right" or "around"


@lru_cache(maxsize=1)
def _general_table() -> tuple[dict[tuple[str, ...], set], set[tuple[str, ...]], int]:
    table: dict[tuple[str, ...], set] = {}
    for action, rules in GENERAL_RULES.items():
        for rule in rules:
            for side in rule.sides:
                for reps in ((1,) if rule.reps == "once" else ((2, 3) if rule.reps == "count" else (1, 2, 3))):
                    step = GeneralStep(action, (0, 1), side=side, reps=reps)
                    for form in ("pres", "ger"):
                        for poss in ("his", "her", "their"):
                            for items in _realisations(step, form, poss):
                                table.setdefault(tuple(w for w, _, _ in items), set()).add((action, side))
    tails = set()
    for ts in _TURN_TAILS.values():
        for t in ts:
            for side in _LR:
                for form in ("pres", "ger"):
                    tails.add(tuple(w for w, _, _ in _fill(t, form, side, "his", 1)))
                    tails.add(tuple(w for w, _, _ in _fill(t, form, side, "their", 1)))
                    tails.add(tuple(w for w, _, _ in _fill(t, form, side, "her", 1)))
    longest = max(len(k) for k in table)
    return table, tails, longest


def parse_general_prompt(prompt: str) -> list[GeneralPhrase] | None:
    """The general-motion phrases of a prompt said in the general captions' language (subjects,
    sentence frames and manner words of the corpus; phrases of :data:`GENERAL_RULES`), in order; None
    if some words are neither (the action corpus's phrases are :func:`.language.parse_prompt`'s)."""
    words = split_words(prompt)
    if not words:
        return None
    table, tails, longest = _general_table()
    _, glue, pre, post, glue_longest = _units()
    glue = glue | {tuple(sub[0].split()) for sub in _ACRO_SUBJECTS}
    units = _cover(words, table, glue, pre, tails | post.keys(), max(longest, glue_longest))
    if units is None:
        return None
    out = []
    for (i, j), (i0, i1), _, after in _styled_phrases(units):
        options = sorted(table[tuple(words[i:j])], key=lambda o: (o[0], str(o[1])))
        sides = {o[1] for o in options}
        turn = None
        for a, b in after:
            tail = tuple(words[a:b])
            if tail in tails:
                turn = "around" if "around" in tail else next((w for w in tail if w in _LR), None)
        out.append(GeneralPhrase((i0, i1), " ".join(words[i0:i1]), options[0][0],
                                 sides.pop() if len(sides) == 1 else None, tuple(sorted({o[0] for o in options})),
                                 turn))
    return out or None


# ============================================================================ the action list
@dataclass(frozen=True)
class GeneralAction:
    """A nameable action of the general set: its step names, key words and example prompts."""

    name: str
    steps: tuple[str, ...]
    words: tuple[str, ...]
    prompts: tuple[str, ...]
    check: str                      # what the clip does, as a measurable statement


#: The actions the general captions add to the corpus's language (for a benchmark's per-action checks).
GENERAL_ACTIONS: dict[str, GeneralAction] = {a.name: a for a in [
    GeneralAction("cartwheel", ("cartwheel",), ("cartwheel", "cartwheels"),
                  ("a person does a cartwheel", "someone does a cartwheel to the left"),
                  "goes upside down (head below the pelvis) and travels sideways"),
    GeneralAction("handstand", ("handstand",), ("handstand",), ("a person does a handstand", "a man kicks up into a handstand"),
                  "upside down on the hands: head below the pelvis, wrists the lowest joints"),
    GeneralAction("walkover", ("walkover",), ("walkover",), ("a gymnast does a walkover",),
                  "upside down on the hands, comes down on the other side"),
    GeneralAction("forward_roll", ("forward_roll",), ("forward roll", "rolls forward", "somersault"),
                  ("a person does a forward roll", "someone rolls forward on the floor"),
                  "turns head over heels forwards on the floor"),
    GeneralAction("backward_roll", ("backward_roll",), ("backward roll", "rolls backward"),
                  ("a person does a backward roll",), "turns head over heels backwards on the floor"),
    GeneralAction("flip", ("front_flip", "back_flip"), ("flip", "backflip", "somersault in the air"),
                  ("a person does a backflip", "a man does a front flip"), "turns over in the air and lands on the feet"),
    GeneralAction("log_roll", ("log_roll", "log_roll_many", "lie_and_roll"), ("rolls over", "rolls to the"),
                  ("a person lies down and rolls over", "someone rolls over several times to the left"),
                  "lying, turns about the body's long axis"),
    GeneralAction("lie_down", ("lie_down_back", "lie_down_front", "lie_down_side", "lie_and_roll"),
                  ("lies down", "lies on", "lies face down"),
                  ("a person lies down on their back", "a woman lies down on her stomach"), "the pelvis comes down below 0.35 m"),
    GeneralAction("roll_over", ("roll_onto_back", "roll_onto_front", "roll_onto_side"), ("rolls onto", "turns over onto"),
                  ("a person lying on the floor rolls onto their stomach",), "lying, turns onto the back, front or a side"),
    GeneralAction("get_up", ("get_up", "stand_up"), ("gets up", "stands up", "rises to"),
                  ("a person lies on the floor and gets up", "someone sits on the floor and then stands up"),
                  "the pelvis rises to standing height"),
    GeneralAction("sit_up", ("sit_up",), ("sits up",), ("a person lying on their back sits up",), "from lying to sitting"),
    GeneralAction("sit_down", ("sit_down",), ("sits down on the floor",), ("a person sits down on the floor",),
                  "the pelvis comes down to the floor, trunk upright"),
    GeneralAction("kneel", ("kneel_one", "kneel_down", "kneeling", "kneeling_one", "kneel_up", "onto_knees"),
                  ("kneels", "on one knee", "on both knees"),
                  ("a man kneels on his left knee", "a person kneels down on both knees"), "a knee rests on the floor"),
    GeneralAction("crawl", ("crawl_forward", "crawl_backward", "crawl_forward_knees", "crawl_backward_knees"),
                  ("crawls", "on all fours", "hands and knees"),
                  ("a woman crawls forward on all fours", "a person crawls on their hands and knees"),
                  "hands and knees near the floor, the body travels"),
    GeneralAction("hands_and_knees", ("hands_knees", "push_up_hands_knees", "on_hands_knees"),
                  ("gets down on hands and knees", "on all fours"), ("a person gets down on their hands and knees",),
                  "hands and knees on the floor"),
    GeneralAction("squat", ("squat_down", "into_squat", "crouching"), ("squats", "crouches"), ("a person squats down",),
                  "the pelvis lowers with bent knees, feet on the floor"),
    GeneralAction("jump_spin", ("jump_spin", "jump_around", "jump_turn"), ("jumps and spins", "turns around in the air"),
                  ("a person jumps and spins", "someone jumps and turns around in the air"),
                  "in the air, the body turns about the vertical"),
    GeneralAction("jump_shape", ("tuck_jump", "star_jump", "split_jump"), ("tuck jump", "split jump", "arms and legs spread"),
                  ("a person does a tuck jump", "a man does a split jump"), "a jump with a shape in the air"),
    GeneralAction("jump_direction", ("jump_up", "jump_forward", "long_jump", "jump_backward", "jump_side"),
                  ("jumps forward", "jumps backward", "jumps to the", "long jump"),
                  ("a person jumps to the left", "a man jumps backward", "someone does a long jump"),
                  "the body travels in the said direction while in the air"),
    GeneralAction("walk_direction", ("walk_backward", "walk_side", "walk_diagonal", "walk_diagonal_back", "run_backward",
                                     "run_side", "run_diagonal", "run_diagonal_back"),
                  ("walks backward", "walks sideways", "diagonally", "runs backward"),
                  ("a person walks diagonally forward to the right", "someone runs backward"),
                  "the pelvis travels in the said direction relative to the facing"),
    GeneralAction("turn", ("turn", "turn_around"), ("turns left", "turns around", "turns to face"),
                  ("someone turns around", "a person turns to the left"),
                  "the facing turns the said way (a walk's turn is the phrase's ``turn``: \"walks forward and turns left\")"),
]}
