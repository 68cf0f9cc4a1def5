"""The corpus's language: a lexicon, phrase rules per primitive, captions with word spans,
left/right mirroring of captions, and a parser that maps a prompt back to primitives.

Every caption is built from phrase rules, so the word span of each action phrase (verb plus its
side, body-part, modifier and repetition words, e.g. "waving his left hand", "jumps high twice")
is known exactly. Tokens follow HumanML3D's processing: NOUN and VERB words are lemmatised, every
word carries a coarse POS tag; the lexicon knows every word the rules can produce.

Words are ``salad_core.data.texts.split_words`` of the caption, so word indices match the
annotation convention of the whole toolkit.
"""
from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..texts import split_words
from .composition import Plan
from .primitives import PRIMITIVES, Action

__all__ = ["Caption", "ParsedPhrase", "render_captions", "render_caption", "mirror_caption",
           "mirror_words", "parse_prompt", "in_language", "phrase_realisations", "LEXICON", "VERBS",
           "POS_TAGS", "SUBJECTS", "FIGURE_PROMPTS"]

#: Coarse POS tags used in the tokens (spaCy's universal tags, as in HumanML3D's texts).
POS_TAGS = ("VERB", "NOUN", "DET", "ADP", "NUM", "AUX", "PRON", "ADJ", "ADV", "CCONJ", "PART", "SCONJ", "PROPN")

#: Verb lemma -> (third person singular, gerund).
VERBS: dict[str, tuple[str, str]] = {
    "walk": ("walks", "walking"), "run": ("runs", "running"), "jog": ("jogs", "jogging"),
    "march": ("marches", "marching"), "step": ("steps", "stepping"), "move": ("moves", "moving"),
    "take": ("takes", "taking"), "stroll": ("strolls", "strolling"), "sprint": ("sprints", "sprinting"),
    "sidestep": ("sidesteps", "sidestepping"), "shuffle": ("shuffles", "shuffling"), "turn": ("turns", "turning"),
    "spin": ("spins", "spinning"), "jump": ("jumps", "jumping"), "leap": ("leaps", "leaping"),
    "hop": ("hops", "hopping"), "do": ("does", "doing"), "perform": ("performs", "performing"),
    "kick": ("kicks", "kicking"), "lift": ("lifts", "lifting"), "raise": ("raises", "raising"),
    "bring": ("brings", "bringing"), "squat": ("squats", "squatting"), "crouch": ("crouches", "crouching"),
    "sit": ("sits", "sitting"), "bow": ("bows", "bowing"), "bend": ("bends", "bending"),
    "wave": ("waves", "waving"), "put": ("puts", "putting"), "punch": ("punches", "punching"),
    "throw": ("throws", "throwing"), "stretch": ("stretches", "stretching"), "extend": ("extends", "extending"),
    "hold": ("holds", "holding"), "reach": ("reaches", "reaching"), "clap": ("claps", "clapping"),
    "spread": ("spreads", "spreading"), "nod": ("nods", "nodding"), "shake": ("shakes", "shaking"),
    "look": ("looks", "looking"), "glance": ("glances", "glancing"),
}

#: Word -> (token, POS): the token is the lemma for NOUN and VERB (HumanML3D convention).
LEXICON: dict[str, tuple[str, str]] = {}


def _lex(pos: str, words: str, lemmas: dict[str, str] | None = None) -> None:
    for w in words.split():
        LEXICON[w] = ((lemmas or {}).get(w, w), pos)


_lex("DET", "a the both some all his her their")
_lex("NOUN", "man woman person hand hands arm arms leg foot fist knee head ground floor air circle place "
             "spot steps jacks punch punches squat squats bow jump turn height level shoulder sides side way "
             "time times front",
     {"hands": "hand", "arms": "arm", "steps": "step", "jacks": "jack", "punches": "punch",
      "squats": "squat", "sides": "side", "times": "time"})
_lex("PRON", "someone he she they him them that")
_lex("ADJ", "left right few small little full half big same")
_lex("ADV", "forward backward backwards straight ahead around up down back out together high low slowly "
            "quickly fast rapidly clockwise counterclockwise sideways twice then first very deeply wide "
            "once over forth")
_lex("ADP", "in on to of with above from at before after into")
_lex("NUM", "one two three four five")
_lex("CCONJ", "and")
_lex("SCONJ", "while as")
_lex("AUX", "is")
for _lemma, (_pres, _ger) in VERBS.items():
    LEXICON.setdefault(_pres, (_lemma, "VERB"))
    LEXICON.setdefault(_ger, (_lemma, "VERB"))
# "jumping jacks": spaCy reads "jumping" as a verb form
LEXICON["jumping"] = ("jump", "VERB")

#: Subjects: (words, possessives, object pronoun per possessive, subject pronoun or None).
SUBJECTS: tuple[tuple[str, tuple[str, ...], str | None], ...] = (
    ("a man", ("his",), "he"), ("the man", ("his",), "he"), ("a woman", ("her",), "she"),
    ("the woman", ("her",), "she"), ("a person", ("his", "their"), None),
    ("the person", ("their", "his"), None), ("someone", ("their", "his"), None),
)
_OBJECT = {"his": "him", "her": "her", "their": "them"}
_COUNT = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five"}
_REPS = {2: ("twice", "two times"), 3: ("three times",), 4: ("four times",), 5: ("five times",)}
_MIRROR_WORDS = {"left": "right", "right": "left", "clockwise": "counterclockwise",
                 "counterclockwise": "clockwise"}

#: Prompts of the SALAD paper's figures that the corpus's language covers.
FIGURE_PROMPTS = (
    "a man jumps forward and then walks forward, while waving his arms",
    "a man is jumping high",
    "a man sits on the ground",
    "the person stretches their arms forward",
    "a person puts both hands in the air",
    "a man is walking while raising his left hand up high",
)


# ============================================================================ phrase rules
@dataclass(frozen=True)
class Rule:
    """One way of saying an action. Template tokens: ``V:lemma`` (inflected verb), ``{poss}``,
    ``{obj}``, ``{side}`` / ``{side:NOUN}`` / ``{side:ADV}``, ``{cw}`` (clockwise word of the side),
    ``{num}`` (repetition count), ``{mod}`` (height modifier slot), ``word/POS`` (explicit tag)."""

    template: str
    sides: tuple = (None,)              # sides the rule can say
    variant: str = ""                   # action variant it says
    expresses: tuple[str, ...] = ()     # modifiers the template itself says
    reps: str = "suffix"                # "suffix" | "count" | "implicit" | "optional"
    min_reps: int = 1                   # smallest repetition count the rule says
    post_height: bool = True            # may a height modifier follow the template?
    high: tuple[str, ...] | None = None  # override of the kind's "high" words
    low: tuple[str, ...] | None = None   # override of the kind's "low" words


_LR, _B, _N = ("left", "right"), ("both",), (None,)
_HIGH_DEFAULT = {"jump": ("high", "very high"), "kick": ("high",), "knee_lift": ("high", "up high"),
                 "wave": ("high", "above {poss} head", "high above {poss} head"),
                 "raise": ("high", "up high", "high above {poss} head", "high into the air")}
_LOW_DEFAULT = {"squat": ("low", "down low"), "bow": ("low", "deeply"), "kick": ("low",), "wave": ("low",),
                "raise": ("to shoulder height", "to shoulder level")}
_LOCOMOTION = {"walk", "run", "jog", "march", "walk_backward", "sidestep", "circle", "turn", "spin"}


def _R(template, sides=_N, **kw) -> Rule:
    return Rule(template, sides, **kw)


RULES: dict[str, list[Rule]] = {
    "walk": [_R("V:walk forward"), _R("V:walk"), _R("V:walk straight ahead"), _R("V:walk straight"),
             _R("V:walk ahead"), _R("V:move forward"), _R("V:stroll forward"),
             _R("V:take a few steps/NOUN forward"),
             _R("V:walk in place", variant="in_place"), _R("V:walk on the spot", variant="in_place"),
             _R("V:step in place", variant="in_place")],
    "run": [_R("V:run forward"), _R("V:run"), _R("V:run straight ahead"), _R("V:run ahead"),
            _R("V:sprint forward", expresses=("quickly",)), _R("V:sprint", expresses=("quickly",))],
    "jog": [_R("V:jog forward"), _R("V:jog"), _R("V:jog straight ahead"),
            _R("V:jog in place", variant="in_place"), _R("V:jog on the spot", variant="in_place")],
    "march": [_R("V:march forward"), _R("V:march"), _R("V:march ahead"),
              _R("V:march in place", variant="in_place"), _R("V:march on the spot", variant="in_place")],
    "walk_backward": [_R("V:walk backward"), _R("V:walk backwards"), _R("V:step backward"), _R("V:move backward"),
                      _R("V:take a few steps/NOUN back"), _R("V:walk back")],
    "sidestep": [_R("V:sidestep to the {side:NOUN}", _LR), _R("V:step sideways to the {side:NOUN}", _LR),
                 _R("V:walk sideways to the {side:NOUN}", _LR), _R("V:shuffle to the {side:NOUN}", _LR),
                 _R("V:move sideways to the {side:NOUN}", _LR), _R("V:step to the {side:NOUN}", _LR)],
    "circle": [_R("V:walk in a circle", _LR), _R("V:walk around in a circle", _LR), _R("V:walk in a big circle", _LR),
               _R("V:walk in a circle {cw}", _LR), _R("V:walk {cw} in a circle", _LR),
               _R("V:walk in a circle to the {side:NOUN}", _LR)],
    "turn": [_R("V:turn {side:ADV}", _LR), _R("V:turn to the {side:NOUN}", _LR), _R("V:turn to {poss} {side:NOUN}", _LR),
             _R("V:turn around", _LR, variant="around"), _R("V:turn all the way around", _LR, variant="around"),
             _R("V:turn around to {poss} {side:NOUN}", _LR, variant="around"), _R("V:do a half turn/NOUN", _LR, variant="around")],
    "spin": [_R("V:spin around", _LR), _R("V:spin in a circle", _LR), _R("V:spin around once", _LR),
             _R("V:turn around in a full circle", _LR), _R("V:do a full turn/NOUN", _LR),
             _R("V:spin around to the {side:NOUN}", _LR), _R("V:spin {cw}", _LR)],
    "jump": [_R("V:jump"), _R("V:jump up", high=("high",)), _R("V:jump in place", post_height=False),
             _R("V:jump on the spot", post_height=False),
             _R("V:jump up and down", reps="implicit", min_reps=2, post_height=False),
             _R("V:hop", expresses=("low",)), _R("V:hop in place", expresses=("low",)),
             _R("V:do a small jump/NOUN", expresses=("low",)), _R("V:jump a little", expresses=("low",)),
             _R("V:hop up and down", expresses=("low",), reps="implicit", min_reps=2),
             _R("V:jump forward", variant="forward"), _R("V:leap forward", variant="forward"),
             _R("V:jump ahead", variant="forward")],
    "jumping_jacks": [_R("V:do jumping jacks", reps="implicit", min_reps=2),
                      _R("V:perform jumping jacks", reps="implicit", min_reps=2),
                      _R("V:do some jumping jacks", reps="implicit", min_reps=2),
                      _R("V:do {num} jumping jacks", reps="count", min_reps=2)],
    "kick": [_R("V:kick {mod} with {poss} {side} leg", _LR), _R("V:kick {poss} {side} leg {mod}", _LR),
             _R("V:kick {poss} {side} leg forward", _LR, post_height=False),
             _R("V:kick forward with {poss} {side} leg", _LR, post_height=False),
             _R("V:kick {mod} with {poss} {side} foot", _LR)],
    "knee_lift": [_R("V:lift {poss} {side} knee {mod}", _LR), _R("V:raise {poss} {side} knee {mod}", _LR),
                  _R("V:bring {poss} {side} knee up", _LR, high=("high",)),
                  _R("V:lift {poss} {side} knee up", _LR, high=("high",))],
    "squat": [_R("V:squat"), _R("V:squat down", low=("low",)), _R("V:do a squat/NOUN", post_height=False),
              _R("V:crouch down", low=("low",)), _R("V:do a low squat/NOUN", expresses=("low",)),
              _R("V:do {num} squats/NOUN", reps="count", min_reps=2, post_height=False)],
    "sit": [_R("V:sit on the ground"), _R("V:sit down on the ground"), _R("V:sit on the floor"),
            _R("V:sit down on the floor"), _R("V:sit down")],
    "bow": [_R("V:bow"), _R("V:bow forward"), _R("V:bow down"), _R("V:take a bow/NOUN", post_height=False),
            _R("V:bend forward"), _R("V:bend over")],
    "wave": [_R("V:wave {poss} {side} hand", _LR), _R("V:wave with {poss} {side} hand", _LR),
             _R("V:wave {poss} {side} hand back and forth", _LR, post_height=False),
             _R("V:wave both hands", _B), _R("V:wave with both hands", _B), _R("V:wave {poss} hands", _B),
             _R("V:wave {poss} arms", _B, variant="arms"), _R("V:wave both arms", _B, variant="arms"),
             _R("V:wave {poss} arms above {poss} head", _B, variant="arms"),
             _R("V:wave {poss} arms in the air", _B, variant="arms"),
             _R("V:wave both arms over {poss} head", _B, variant="arms")],
    "raise": [_R("V:raise {poss} {side} arm", _LR), _R("V:raise {poss} {side} hand", _LR),
              _R("V:lift {poss} {side} arm", _LR), _R("V:raise {poss} {side} hand up", _LR, high=("high",), low=()),
              _R("V:put {poss} {side} hand up", _LR, high=("high",), low=()),
              _R("V:put {poss} {side} hand in the air", _LR, post_height=False),
              _R("V:raise both arms", _B), _R("V:raise both hands", _B), _R("V:raise {poss} arms", _B),
              _R("V:lift both arms", _B), _R("V:raise both hands up", _B, high=("high",), low=()),
              _R("V:put both hands up", _B, high=("high",), low=()),
              _R("V:put both hands in the air", _B, post_height=False),
              _R("V:put {poss} hands in the air", _B, post_height=False)],
    "punch": [_R("V:punch with {poss} {side} hand", _LR), _R("V:punch forward with {poss} {side} fist", _LR),
              _R("V:throw a punch/NOUN with {poss} {side} hand", _LR), _R("V:punch with {poss} {side} arm", _LR),
              _R("V:punch {poss} {side} fist forward", _LR),
              _R("V:throw {num} punches/NOUN with {poss} {side} hand", _LR, reps="count", min_reps=2)],
    "stretch": [_R("V:stretch {poss} arms forward", _B), _R("V:stretch both arms forward", _B),
                _R("V:stretch {poss} arms out in front/NOUN of {obj}", _B), _R("V:extend {poss} arms forward", _B),
                _R("V:hold {poss} arms out in front/NOUN of {obj}", _B), _R("V:reach forward with both arms", _B),
                _R("V:hold both arms straight out in front/NOUN of {obj}", _B)],
    "clap": [_R("V:clap", _B), _R("V:clap {poss} hands", _B), _R("V:clap {poss} hands together", _B),
             _R("V:clap both hands together", _B)],
    "arms_out": [_R("V:hold {poss} arms out to the sides", _B), _R("V:stretch {poss} arms out to the sides", _B),
                 _R("V:spread {poss} arms", _B), _R("V:spread {poss} arms wide", _B),
                 _R("V:raise {poss} arms out to the sides", _B), _R("V:put {poss} arms out to the side", _B),
                 _R("V:extend both arms to the sides", _B)],
    "nod": [_R("V:nod", reps="optional", min_reps=2), _R("V:nod {poss} head", reps="optional", min_reps=2),
            _R("V:nod {poss} head up and down", reps="optional", min_reps=2)],
    "shake_head": [_R("V:shake {poss} head", reps="optional", min_reps=2),
                   _R("V:shake {poss} head from side/NOUN to side/NOUN", reps="optional", min_reps=2)],
    "look": [_R("V:look to the {side:NOUN}", _LR), _R("V:look {side:ADV}", _LR),
             _R("V:turn {poss} head to the {side:NOUN}", _LR), _R("V:glance to the {side:NOUN}", _LR),
             _R("V:look over to the {side:NOUN}", _LR), _R("V:look to {poss} {side:NOUN}", _LR)],
}


# ============================================================================ expansion
Item = tuple[str, str, str]  # (word, token, POS)


def _word(w: str, pos: str | None = None) -> Item:
    if w not in LEXICON and pos is None:
        raise KeyError(f"word {w!r} is not in the corpus lexicon")
    tok, default = LEXICON.get(w, (w, pos))
    pos = pos or default
    if pos not in POS_TAGS:
        raise ValueError(f"POS {pos!r} of {w!r} not in {POS_TAGS}")
    if pos in ("NOUN", "VERB"):
        tok = LEXICON[w][0] if w in LEXICON else w
    else:
        tok = w
    return (w, tok, pos)


def _fill(text: str, form: str, side: str | None, poss: str, reps: int) -> list[Item]:
    """Expand a template fragment (no ``{mod}``) into word items."""
    out: list[Item] = []
    for tok in text.split():
        if tok.startswith("V:"):
            lemma = tok[2:]
            pres, ger = VERBS[lemma]
            out.append((pres if form == "pres" else ger, lemma, "VERB"))
        elif tok == "{poss}":
            out.append((poss, poss, "DET"))
        elif tok == "{obj}":
            out.append((_OBJECT[poss], _OBJECT[poss], "PRON"))
        elif tok.startswith("{side"):
            pos = tok[6:-1] if ":" in tok else "ADJ"
            out.append((side, side, pos))
        elif tok == "{cw}":
            w = "counterclockwise" if side == "left" else "clockwise"
            out.append((w, w, "ADV"))
        elif tok == "{num}":
            out.append((_COUNT[reps], _COUNT[reps], "NUM"))
        elif "/" in tok:
            w, pos = tok.split("/")
            out.append(_word(w, pos))
        else:
            out.append(_word(tok))
    return out


def _speed_words(kind: str, mod: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(before-the-verb, after-the-phrase) words of a speed modifier."""
    if mod == "slowly":
        return ("slowly",), ("slowly",)
    fast = ("quickly", "fast") if kind in _LOCOMOTION else ("quickly", "rapidly")
    return ("quickly",), fast


def _height_words(rule: Rule, kind: str, mod: str) -> tuple[str, ...]:
    if mod == "high":
        return rule.high if rule.high is not None else _HIGH_DEFAULT.get(kind, ())
    return rule.low if rule.low is not None else _LOW_DEFAULT.get(kind, ())


def _alternatives(rule: Rule, action: Action, form: str, poss: str) -> list[list[Item]]:
    """Every wording of ``action`` by ``rule`` (empty if the rule cannot say it)."""
    if rule.variant != action.variant or action.side not in rule.sides:
        return []
    if any(m not in action.mods for m in rule.expresses):
        return []
    rest = [m for m in action.mods if m not in rule.expresses]
    height = [m for m in rest if m in ("high", "low")]
    speed = [m for m in rest if m in ("slowly", "quickly")]
    has_slot = "{mod}" in rule.template
    # repetitions
    if action.reps < rule.min_reps:
        return []
    if rule.reps in ("count", "implicit") and action.reps < 2:
        return []
    if rule.reps == "count":
        rep_alts: list[tuple[str, ...]] = [()]
    elif action.reps >= 2:
        suffix = [tuple(w.split()) for w in _REPS[action.reps]]
        rep_alts = [()] if rule.reps == "implicit" else (suffix + [()] if rule.reps == "optional" else suffix)
    else:
        rep_alts = [()]
    if action.kind == "clap" and action.reps == 1:
        rep_alts = [()]
    # height modifier: in the {mod} slot, else after the phrase
    if height:
        words = _height_words(rule, action.kind, height[0])
        if not words or (not has_slot and not rule.post_height):
            return []
        height_alts = list(words)
    else:
        height_alts = [""]
    # speed modifier: before the verb or after the phrase
    if speed:
        pre, post = _speed_words(action.kind, speed[0])
        speed_alts = [(w, "") for w in pre] + [("", w) for w in post]
    else:
        speed_alts = [("", "")]
    out = []
    head, _, tail = rule.template.partition("{mod}")
    for h, (pre_w, post_w), reps in itertools.product(height_alts, speed_alts, rep_alts):
        items: list[Item] = []
        if pre_w:
            items.append(_word(pre_w))
        if has_slot:
            items += _fill(head, form, action.side, poss, action.reps)
            if h:
                items += _fill(h, form, action.side, poss, action.reps)
            if tail.strip():
                items += _fill(tail, form, action.side, poss, action.reps)
        else:
            items += _fill(rule.template, form, action.side, poss, action.reps)
            if h:
                items += _fill(h, form, action.side, poss, action.reps)
        if post_w:
            items.append(_word(post_w))
        items += [_word(w) for w in reps]
        out.append(items)
    return out


def phrase_realisations(action: Action, form: str = "pres", poss: str = "his") -> list[list[Item]]:
    """Every phrase that says ``action`` in ``form`` ("pres": "walks", "ger": "walking")."""
    if form not in ("pres", "ger"):
        raise ValueError(f"form must be 'pres' or 'ger', got {form!r}")
    out = []
    for rule in RULES[action.kind]:
        out += _alternatives(rule, action, form, poss)
    return out


def _all_actions():
    for kind, spec in PRIMITIVES.items():
        heights = [m for m in spec.mods if m in ("high", "low")]
        speeds = [m for m in spec.mods if m in ("slowly", "quickly")]
        for side, variant, reps in itertools.product(spec.sides, spec.variants, spec.reps):
            for h in [None] + heights:
                for s in [None] + speeds:
                    mods = tuple(sorted(m for m in (h, s) if m))
                    try:
                        yield Action(kind, side, mods, reps, variant)
                    except ValueError:
                        continue


# ============================================================================ captions
@dataclass(frozen=True)
class Caption:
    """A caption with its tokens and the word span of every action phrase."""

    text: str                                   # the caption
    tokens: tuple[tuple[str, str], ...]         # (token, POS) per word of split_words(text)
    spans: tuple[tuple[int, int], ...]          # per plan action (Plan.actions() order): [i0, i1)

    @property
    def words(self) -> list[str]:
        return split_words(self.text)


class _Builder:
    """Accumulates words and punctuation, recording phrase spans."""

    def __init__(self) -> None:
        self.pieces: list[str] = []
        self.items: list[Item] = []
        self.spans: dict[int, tuple[int, int]] = {}

    def words(self, text: str) -> None:
        for w in text.split():
            self.items.append(_word(w))
            self.pieces.append(w)

    def punct(self, p: str) -> None:
        if self.pieces:
            self.pieces[-1] += p

    def phrase(self, idx: int, items: list[Item]) -> None:
        i0 = len(self.items)
        self.items += items
        self.pieces += [w for w, _, _ in items]
        self.spans[idx] = (i0, len(self.items))

    def caption(self, n_actions: int, period: bool) -> Caption:
        text = " ".join(self.pieces) + ("." if period else "")
        words = split_words(text)
        if words != [w for w, _, _ in self.items]:
            raise AssertionError(f"caption words {words} differ from the built words")
        if sorted(self.spans) != list(range(n_actions)):
            raise AssertionError(f"caption {text!r} misses action phrases: {sorted(self.spans)}")
        return Caption(text, tuple((t, p) for _, t, p in self.items),
                       tuple(self.spans[i] for i in range(n_actions)))


def _choose(rng: np.random.Generator, options: list):
    return options[int(rng.integers(len(options)))]


def render_caption(plan: Plan, rng: np.random.Generator) -> Caption:
    """One random caption of ``plan``; phrase spans in ``plan.actions()`` order."""
    subj, posses, pron = _choose(rng, list(SUBJECTS))
    poss = _choose(rng, list(posses))
    acts = plan.actions()
    index = {(role, i): k for k, (role, i, _) in enumerate(acts)}
    b = _Builder()

    def say(role: str, i: int, form: str) -> None:
        action = acts[index[(role, i)]][2]
        b.phrase(index[(role, i)], _choose(rng, phrase_realisations(action, form, poss)))

    def step(i: int, form: str) -> None:
        """A step of a sequence: its main action, "while" its layer."""
        say("main", i, form)
        if plan.steps[i].layer is not None:
            b.words("while")
            say("layer", i, "ger")

    steps = plan.steps
    if plan.overlay is None and len(steps) == 1 and steps[0].layer is not None:
        choice = int(rng.integers(6 if pron else 5))
        if choice == 0:
            b.words(subj); say("main", 0, "pres"); b.words("while"); say("layer", 0, "ger")
        elif choice == 1:
            b.words(subj + " is"); say("main", 0, "ger"); b.words("while"); say("layer", 0, "ger")
        elif choice == 2:
            b.words("while"); say("main", 0, "ger"); b.punct(","); b.words(subj); say("layer", 0, "pres")
        elif choice == 3:
            b.words(subj); say("layer", 0, "pres"); b.words("while"); say("main", 0, "ger")
        elif choice == 4:
            b.words(subj); say("main", 0, "pres"); b.words("and"); say("layer", 0, "pres")
            b.words("at the same time")
        else:
            b.words(subj); say("layer", 0, "pres"); b.words("as " + pron); say("main", 0, "pres")
    elif plan.overlay is None and len(steps) == 1:
        if rng.random() < 0.7:
            b.words(subj); step(0, "pres")
        else:
            b.words(subj + " is"); step(0, "ger")
    elif plan.overlay is None:
        n = len(steps)
        options = [0, 1, 2, 3] + ([4, 5] if n == 2 else []) + ([6] if n == 2 and pron else [])
        choice = _choose(rng, options)
        if choice == 0:      # X, then Y(, then Z)
            b.words(subj); step(0, "pres")
            for i in range(1, n):
                b.punct(","); b.words("then"); step(i, "pres")
        elif choice == 1:    # X and then Y / X, then Y, and then Z
            b.words(subj); step(0, "pres")
            for i in range(1, n - 1):
                b.punct(","); b.words("then"); step(i, "pres")
            if n > 2:
                b.punct(",")
            b.words("and then"); step(n - 1, "pres")
        elif choice == 2:    # first, S X, then Y
            b.words("first"); b.punct(","); b.words(subj); step(0, "pres")
            for i in range(1, n):
                b.punct(","); b.words("then"); step(i, "pres")
        elif choice == 3:    # S is X-ing and then Y-ing
            b.words(subj + " is"); step(0, "ger")
            for i in range(1, n):
                b.words("and then"); step(i, "ger")
        elif choice == 4:    # S X before Y-ing
            b.words(subj); step(0, "pres"); b.words("before"); step(1, "ger")
        elif choice == 5:    # after X-ing, S Y
            b.words("after"); step(0, "ger"); b.punct(","); b.words(subj); step(1, "pres")
        else:                # S X. after that, he Y
            b.words(subj); step(0, "pres"); b.punct("."); b.words("after that"); b.punct(",")
            b.words(pron); step(1, "pres")
    else:
        n = len(steps)
        choice = int(rng.integers(3))

        def seq(form: str) -> None:
            step(0, form)
            for i in range(1, n):
                if form == "pres" and rng.random() < 0.4:
                    b.punct(","); b.words("then")
                else:
                    b.words("and then")
                step(i, form)
        if choice == 0:
            b.words(subj); seq("pres"); b.punct(","); b.words("while"); say("overlay", -1, "ger")
        elif choice == 1:
            b.words("while"); say("overlay", -1, "ger"); b.punct(","); b.words(subj); seq("pres")
        else:
            b.words(subj); say("overlay", -1, "pres"); b.words("while"); seq("ger")
    return b.caption(len(acts), period=bool(rng.random() < 0.5))


def render_captions(plan: Plan, rng: np.random.Generator, n: int = 3, tries: int = 40) -> list[Caption]:
    """``n`` distinct captions of ``plan`` (fewer only if the language has fewer)."""
    out: dict[str, Caption] = {}
    for _ in range(tries):
        c = render_caption(plan, rng)
        out.setdefault(c.text, c)
        if len(out) == n:
            break
    return list(out.values())


def mirror_words(text: str) -> str:
    """Swap left/right (and clockwise/counterclockwise) words, keeping everything else."""
    return re.sub(r"[A-Za-z]+", lambda m: _MIRROR_WORDS.get(m.group(0).lower(), m.group(0)), text)


def mirror_caption(caption: Caption) -> Caption:
    """The caption of the mirrored motion: same words and spans, left and right swapped."""
    tokens = tuple((_MIRROR_WORDS.get(t, t), p) for t, p in caption.tokens)
    return Caption(mirror_words(caption.text), tokens, caption.spans)


# ============================================================================ parsing
@dataclass(frozen=True)
class ParsedPhrase:
    """An action phrase found in a prompt."""

    words: tuple[int, int]          # [i0, i1) into split_words(prompt)
    text: str
    kind: str                       # primitive
    side: str | None                # None when the phrase does not say (or has no side)
    mods: tuple[str, ...]
    reps: int | None                # None when the phrase does not say how many times
    variant: str

    @property
    def parts(self) -> tuple[str, ...]:
        """Body parts the phrase drives, as the corpus annotations define them.

        A phrase that names no side (e.g. "waves") takes the primitive's first allowed side.
        """
        from .primitives import PRIMITIVES, Action, primitive_parts

        spec = PRIMITIVES[self.kind]
        side = self.side if self.side in spec.sides else spec.sides[0]
        try:
            action = Action(self.kind, side, tuple(sorted(self.mods)), self.reps or 1, self.variant)
        except ValueError:  # a modifier or variant this primitive does not take: parts do not depend on it
            action = Action(self.kind, side)
        return primitive_parts(action)[0]


_GLUE = ("a man", "the man", "a woman", "the woman", "a person", "the person", "someone", "he", "she",
         "is", "while", "as", "then", "and then", "and", "before", "after", "after that", "first",
         "at the same time")


@lru_cache(maxsize=1)
def _phrase_table() -> tuple[dict[tuple[str, ...], set], int]:
    table: dict[tuple[str, ...], set] = {}
    for action in _all_actions():
        for rule in RULES[action.kind]:
            implicit = rule.reps == "implicit"
            for form in ("pres", "ger"):
                for poss in ("his", "her", "their"):
                    for items in _alternatives(rule, action, form, poss):
                        key = tuple(w for w, _, _ in items)
                        reps = None if (implicit or (rule.reps == "optional" and not _states_reps(key))) else action.reps
                        table.setdefault(key, set()).add(
                            (action.kind, action.side, action.mods, reps, action.variant))
    longest = max(len(k) for k in table)
    return table, longest


def _common(options: set) -> tuple:
    """What all readings of a phrase agree on: a side, count or variant the words leave open
    becomes None (side, reps) or the first reading (kind, variant); modifiers are those all say."""
    opts = sorted(options, key=lambda a: (a[0], str(a[1]), a[2], a[3] or 0, a[4]))
    kind = opts[0][0]
    opts = [o for o in opts if o[0] == kind]
    sides = {o[1] for o in opts}
    reps = {o[3] for o in opts}
    mods = set(opts[0][2]).intersection(*[set(o[2]) for o in opts])
    return (kind, sides.pop() if len(sides) == 1 else None, tuple(sorted(mods)),
            reps.pop() if len(reps) == 1 else None, opts[0][4])


def _states_reps(words: tuple[str, ...]) -> bool:
    return bool({"twice", "times"} & set(words))


def parse_prompt(prompt: str) -> list[ParsedPhrase] | None:
    """Split a prompt into the corpus's action phrases and glue words.

    Returns the phrases in order, or None if the prompt is not in the corpus's language (some
    word sequence is neither an action phrase nor a subject/connective).
    """
    words = split_words(prompt)
    if not words:
        return None
    table, longest = _phrase_table()
    glue = {tuple(g.split()) for g in _GLUE}
    n = len(words)
    # best[i]: (number of units, back pointer) to cover words[:i]
    best: list[tuple[int, tuple] | None] = [None] * (n + 1)
    best[0] = (0, ())
    for i in range(n):
        if best[i] is None:
            continue
        for j in range(i + 1, min(n, i + longest) + 1):
            key = tuple(words[i:j])
            unit = None
            if key in table:
                unit = ("phrase", i, j)
            elif key in glue:
                unit = ("glue", i, j)
            if unit is None:
                continue
            cand = (best[i][0] + 1, best[i][1] + (unit,))
            if best[j] is None or cand[0] < best[j][0]:
                best[j] = cand
    if best[n] is None:
        return None
    out = []
    for kind_, i, j in best[n][1]:
        if kind_ != "phrase":
            continue
        key = tuple(words[i:j])
        kind, side, mods, reps, variant = _common(table[key])
        out.append(ParsedPhrase((i, j), " ".join(key), kind, side, mods, reps, variant))
    return out or None


def in_language(prompt: str) -> bool:
    """Whether ``prompt`` can be said with the corpus's subjects, connectives and action phrases."""
    return parse_prompt(prompt) is not None
