"""The corpus's language: a lexicon, phrase rules per primitive, captions with word spans,
left/right mirroring of captions, and a parser that maps a prompt back to primitives.

Every caption is built from phrase rules, so the word span of each action phrase (verb plus its
side, body-part, modifier and repetition words, e.g. "waving his left hand", "jumps high twice")
is known exactly. A phrase may carry a style word before or after it ("carefully", "energetically",
"at a slow pace": these say the speed modifier, and the motion has it) or a manner or intent
("happily", "angrily", "to the music", "as if greeting a friend": the motion is the plain one);
such words belong to the phrase's span. Captions are laid out by sentence frames (:data:`FRAMES`:
"{S} {A0}, then {A1}", "at first {S} {A0}, later {P} {A1}", "after {G0}, {S} {A1}", ...),
some opened with a scene ("in this clip, ...", "we see {S} ..."); :func:`sentence_frame` reduces a
caption to its frame, :func:`sentence_frames` lists the designed ones and :func:`vocabulary` every
word the captions can use. Tokens follow HumanML3D's processing: NOUN and VERB words are
lemmatised, every word carries a coarse POS tag; the lexicon knows every word the rules can produce.

Words are ``salad_core.data.texts.split_words`` of the caption, so word indices match the
annotation convention of the whole toolkit.
"""
from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Container, Iterator
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..texts import split_words
from .composition import Plan
from .primitives import PRIMITIVES, Action

__all__ = ["Caption", "ParsedPhrase", "render_captions", "render_caption", "mirror_caption",
           "mirror_words", "parse_prompt", "in_language", "phrase_realisations", "LEXICON", "VERBS",
           "POS_TAGS", "SUBJECTS", "EXTRA_SUBJECTS", "FIGURE_PROMPTS", "FRAMES", "OPENINGS", "GERUND_OPENINGS",
           "SPEED_STYLE", "MOOD_STYLE", "INTENT", "sentence_frame", "sentence_frames", "vocabulary"]

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
    # corpus 2.0: new actions, paraphrases and sentence shapes
    "dance": ("dances", "dancing"), "sway": ("sways", "swaying"), "rock": ("rocks", "rocking"),
    "groove": ("grooves", "grooving"), "toss": ("tosses", "tossing"), "pitch": ("pitches", "pitching"),
    "lob": ("lobs", "lobbing"), "bowl": ("bowls", "bowling"), "pick": ("picks", "picking"),
    "grab": ("grabs", "grabbing"), "stumble": ("stumbles", "stumbling"), "trip": ("trips", "tripping"),
    "catch": ("catches", "catching"), "regain": ("regains", "regaining"), "lose": ("loses", "losing"),
    "recover": ("recovers", "recovering"), "fall": ("falls", "falling"), "box": ("boxes", "boxing"),
    "shadowbox": ("shadowboxes", "shadowboxing"), "jab": ("jabs", "jabbing"), "cross": ("crosses", "crossing"),
    "swing": ("swings", "swinging"), "scratch": ("scratches", "scratching"), "touch": ("touches", "touching"),
    "place": ("places", "placing"), "rest": ("rests", "resting"), "stand": ("stands", "standing"),
    "salute": ("salutes", "saluting"), "give": ("gives", "giving"), "fold": ("folds", "folding"),
    "circle": ("circles", "circling"), "rotate": ("rotates", "rotating"), "make": ("makes", "making"),
    "get": ("gets", "getting"), "begin": ("begins", "beginning"), "start": ("starts", "starting"),
    "keep": ("keeps", "keeping"), "greet": ("greets", "greeting"), "say": ("says", "saying"),
    "signal": ("signals", "signalling"), "celebrate": ("celebrates", "celebrating"), "wait": ("waits", "waiting"),
    "think": ("thinks", "thinking"), "exercise": ("exercises", "exercising"), "warm": ("warms", "warming"),
    "dodge": ("dodges", "dodging"), "avoid": ("avoids", "avoiding"), "search": ("searches", "searching"),
    "agree": ("agrees", "agreeing"), "disagree": ("disagrees", "disagreeing"), "applaud": ("applauds", "applauding"),
    "cheer": ("cheers", "cheering"), "fight": ("fights", "fighting"), "spar": ("spars", "sparring"),
    "hit": ("hits", "hitting"), "thank": ("thanks", "thanking"), "try": ("tries", "trying"),
    "hear": ("hears", "hearing"), "explore": ("explores", "exploring"), "pace": ("paces", "pacing"),
    "stride": ("strides", "striding"), "wander": ("wanders", "wandering"), "bounce": ("bounces", "bouncing"),
    "skip": ("skips", "skipping"), "hurry": ("hurries", "hurrying"), "train": ("trains", "training"),
    "play": ("plays", "playing"), "show": ("shows", "showing"), "see": ("sees", "seeing"),
    "rise": ("rises", "rising"), "back": ("backs", "backing"), "clear": ("clears", "clearing"),
    "stomp": ("stomps", "stomping"), "balance": ("balances", "balancing"), "finish": ("finishes", "finishing"),
    "head": ("heads", "heading"), "advance": ("advances", "advancing"), "race": ("races", "racing"),
    "rush": ("rushes", "rushing"), "dart": ("darts", "darting"), "spring": ("springs", "springing"),
    "strike": ("strikes", "striking"), "open": ("opens", "opening"),
    "retreat": ("retreats", "retreating"), "twirl": ("twirls", "twirling"), "peek": ("peeks", "peeking"),
    "face": ("faces", "facing"), "plop": ("plops", "plopping"), "hail": ("hails", "hailing"),
    "volunteer": ("volunteers", "volunteering"), "answer": ("answers", "answering"), "check": ("checks", "checking"),
    "listen": ("listens", "listening"), "refuse": ("refuses", "refusing"),
    "kneel": ("kneels", "kneeling"), "lie": ("lies", "lying"), "lay": ("lays", "laying"), "climb": ("climbs", "climbing"),
    "ascend": ("ascends", "ascending"), "go": ("goes", "going"), "pivot": ("pivots", "pivoting"),
    "tap": ("taps", "tapping"), "tie": ("ties", "tying"), "pray": ("prays", "praying"), "propose": ("proposes", "proposing"),
    "continue": ("continues", "continuing"), "end": ("ends", "ending"),
    "stop": ("stops", "stopping"), "transition": ("transitions", "transitioning"), "follow": ("follows", "following"),
    "combine": ("combines", "combining"), "expect": ("expects", "expecting"), "collect": ("collects", "collecting"),
    "fly": ("flies", "flying"), "sunbathe": ("sunbathes", "sunbathing"),
    "change": ("changes", "changing"), "tidy": ("tidies", "tidying"), "sleep": ("sleeps", "sleeping"),
    "watch": ("watches", "watching"), "drop": ("drops", "dropping"), "settle": ("settles", "settling"),
    "mount": ("mounts", "mounting"), "crawl": ("crawls", "crawling"),
    "twist": ("twists", "twisting"), "descend": ("descends", "descending"), "come": ("comes", "coming"), "lunge": ("lunges", "lunging"),
    "ask": ("asks", "asking"), "chase": ("chases", "chasing"), "lean": ("leans", "leaning"), "loosen": ("loosens", "loosening"), "dash": ("dashes", "dashing"), "lower": ("lowers", "lowering"), "attract": ("attracts", "attracting"), "punctuate": ("punctuates", "punctuating"),
    "aim": ("aims", "aiming"), "tip": ("tips", "tipping"),
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
_lex("CCONJ", "and but or")
_lex("SCONJ", "while as")
_lex("AUX", "is")
# corpus 2.0 words: objects, body parts, subjects, style and intent, timing and sentence shapes
_lex("NOUN", "ball balls rock stone frisbee object objects box boxes bag cup pen coin book toy bottle phone "
             "obstacle log puddle rope hurdle fence hips hip waist chest body forehead brow fists "
             "jab cross hook hooks uppercut uppercuts combination guard stance boxer "
             "circles salute dance music beat party rhythm treadmill room stairs staircase balance "
             "guy lady figure human character individual dancer athlete fighter soldier performer actor "
             "adult subject friend friends crowd audience officer workout exercise "
             "clip video animation footage moment pace hurry energy care effort "
             "noise goodbye hello agreement disbelief confusion thought break attention distance "
             "motion motions stick bus partner opponent face line knees legs",
     {"balls": "ball", "objects": "object", "knees": "knee", "legs": "leg", "boxes": "box", "hips": "hip", "fists": "fist", "hooks": "hook",
      "uppercuts": "uppercut", "circles": "circle", "stairs": "stair", "friends": "friend", "motions": "motion"})
_lex("ADJ", "heavy small tiny low imaginary invisible military outstretched crossed quick slow fast "
            "young old elderly tall short athletic sturdy happy excited tired angry nervous calm relaxed "
            "careful gentle confident casual playful lazy energetic great lively upbeat brief "
            "whole entire next imaginary short same invisible real own steady light soft sudden hard "
            "cautious brisk leisurely unsteady awkward middle upper simple")
_lex("ADV", "overhand underhand upward upwards just simply also simultaneously meanwhile afterwards next "
            "finally eventually later soon immediately shortly again already suddenly almost "
            "happily cheerfully joyfully excitedly angrily furiously aggressively powerfully forcefully "
            "fiercely sadly tiredly wearily lazily calmly casually confidently proudly playfully nervously "
            "carefully cautiously gently softly lightly smoothly gracefully awkwardly clumsily steadily "
            "leisurely unhurriedly energetically vigorously briskly swiftly hurriedly eagerly "
            "enthusiastically impatiently thoughtfully rhythmically hard there when how here")
_lex("ADP", "like across through throughout during until for by off onto toward towards about")
_lex("PRON", "himself herself themselves we you it something somebody")
_lex("DET", "an this another each every no")
_lex("AUX", "can be are was")
_lex("SCONJ", "if once because so")
_lex("PART", "to not")
_lex("NUM", "six")
for _lemma, (_pres, _ger) in VERBS.items():
    LEXICON.setdefault(_pres, (_lemma, "VERB"))
    LEXICON.setdefault(_ger, (_lemma, "VERB"))
# "jumping jacks": spaCy reads "jumping" as a verb form
LEXICON["jumping"] = ("jump", "VERB")
LEXICON["seen"] = ("see", "VERB")
for _w in ("get", "greet", "reach", "rest", "say", "take", "loosen", "fight", "see", "catch"):
    LEXICON[_w] = (_w, "VERB")      # bare infinitives ("to rest", "to greet someone")
_lex("NOUN", "step end excitement baseball pitcher question lot part back flight stair platform bench "
             "crunch crunches heel ball toes knees degrees quarter top shoelace shoelaces prayer proposal",
     {"crunches": "crunch", "toes": "toe", "degrees": "degree", "shoelaces": "shoelace"})
_lex("ADJ", "opposite raised flat top")
_lex("NOUN", "nap home direction basketball player ups feet", {"ups": "up", "feet": "foot"})
_lex("ADV", "briefly")
_lex("NOUN", "airplane applause artist ballerina ceiling chair door joy kick parade park performance race round seat "
             "show star street stroll taxi traffic walk wave weights work",
     {"weights": "weight"})
_lex("ADJ", "deep martial open vertical funny exaggerated silly upbeat cold puzzled slippery professional")
_lex("NOUN", "confidence ease determination enthusiasm purpose force power song routine fitness instructor flag "
             "breath seatbelt dog match seconds", {"seconds": "second"})
_lex("PRON", "nobody")
_lex("ADJ", "slim slender muscular older bald bearded easy full second")
_lex("NOUN", "model speed rush hit general wedding pop gym class curb defender baby fours")
_lex("ADV", "thereafter subsequently so")
LEXICON["followed"] = ("follow", "VERB")
_lex("ADV", "out")
_lex("ADV", "along boldly determinedly dramatically elegantly firmly loosely merrily politely quietly shyly yes no")
LEXICON["touch"] = ("touch", "VERB")
_lex("ADJ", "late ready confused annoyed")
_lex("ADV", "away")
_lex("PRON", "who")
_lex("DET", "which")
_lex("ADP", "without")
LEXICON["done"] = ("do", "VERB")
LEXICON["lost"] = ("lose", "VERB")
_lex("NOUN", "lunge ice torso")
_lex("ADV", "far")

#: Subjects: (words, possessives, object pronoun per possessive, subject pronoun or None).
SUBJECTS: tuple[tuple[str, tuple[str, ...], str | None], ...] = (
    ("a man", ("his",), "he"), ("the man", ("his",), "he"), ("a woman", ("her",), "she"),
    ("the woman", ("her",), "she"), ("a person", ("his", "their"), None),
    ("the person", ("their", "his"), None), ("someone", ("their", "his"), None),
)
_OBJECT = {"his": "him", "her": "her", "their": "them"}
_REFLEXIVE = {"his": "himself", "her": "herself", "their": "themselves"}
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
_LOW_DEFAULT = {"squat": ("low", "down low"), "bow": ("low", "deeply"), "lunge": ("low", "deeply"), "side_bend": ("deeply", "far/ADV down"), "kick": ("low",), "wave": ("low",),
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
                 _R("V:walk sideways to the {side:NOUN}", _LR),
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


def _RS(template: str, sides=_N, **kw) -> list[Rule]:
    """Rules for every choice of the ``[a|b|c]`` groups of ``template`` (choices may hold spaces)."""
    parts = re.split(r"(\[[^\]]*\])", template)
    choices = [p[1:-1].split("|") if p.startswith("[") else [p] for p in parts]
    return [Rule(" ".join("".join(c).split()), sides, **kw) for c in itertools.product(*choices)]


def _rules(*groups) -> list[Rule]:
    out: list[Rule] = []
    for g in groups:
        out += g if isinstance(g, list) else [g]
    return out


_LRN = ("left", "right")
_ONE_THING = "[something|an object/NOUN|a ball/NOUN|a cup/NOUN|a pen/NOUN|a coin/NOUN|a book/NOUN|a toy/NOUN|a bottle/NOUN|a phone/NOUN]"
_BIG_THING = "[a box/NOUN|a heavy/ADJ box/NOUN|something|an object/NOUN|a bag/NOUN|a ball/NOUN]"
_OBSTACLE = "[something|an obstacle/NOUN|a small obstacle/NOUN|a box/NOUN|a log/NOUN|a puddle/NOUN|a rope/NOUN|a hurdle/NOUN|a low/ADJ fence/NOUN]"
RULES.update({
    # dance
    "dance": _rules(_R("V:dance"), _R("V:dance around"), _R("V:dance in place"), _R("V:do a little dance/NOUN"),
                    _R("V:dance from side/NOUN to side/NOUN"), _R("V:step from side/NOUN to side/NOUN"),
                    _R("V:dance a few steps/NOUN"), _R("V:groove from side/NOUN to side/NOUN"),
                    _R("V:do a side/NOUN to side/NOUN dance/NOUN"), _R("V:do a simple/ADJ dance/NOUN step/NOUN")),
    "sway": _rules(_R("V:sway from side/NOUN to side/NOUN"), _R("V:sway {poss} hips"), _R("V:sway side/NOUN to side/NOUN"),
                   _R("V:sway {poss} hips from side/NOUN to side/NOUN"), _R("V:rock from side/NOUN to side/NOUN"),
                   _R("V:move {poss} hips from side/NOUN to side/NOUN"), _R("V:rock {poss} hips")),
    # everyday
    "throw": _rules(_RS("V:throw [a ball/NOUN|something|an object/NOUN|a rock/NOUN|a stone/NOUN|a frisbee/NOUN]", _LRN),
                    _RS("V:throw [a ball/NOUN|something|a stone/NOUN] with {poss} {side} hand", _LRN),
                    _R("V:throw with {poss} {side} arm", _LRN), _R("V:make a throwing/NOUN motion/NOUN", _LRN),
                    _R("V:make a throwing/NOUN motion/NOUN with {poss} {side} arm", _LRN),
                    _RS("V:pitch [a ball/NOUN|a ball/NOUN with {poss} {side} hand]", _LRN),
                    _RS("V:throw [a ball/NOUN|something] overhand", _LRN),
                    _R("V:throw a ball/NOUN overhand with {poss} {side} hand", _LRN),
                    _RS("V:[throw|toss] [a ball/NOUN|something] underhand", _LRN, variant="underhand"),
                    _RS("V:toss [a ball/NOUN|something|an object/NOUN] with {poss} {side} hand", _LRN, variant="underhand"),
                    _R("V:toss a ball/NOUN", _LRN, variant="underhand"),
                    _R("V:bowl a ball/NOUN underhand", _LRN, variant="underhand"),
                    _R("V:lob a ball/NOUN underhand with {poss} {side} hand", _LRN, variant="underhand")),
    "pick_up": _rules(_RS(f"V:pick {_ONE_THING} up with {{poss}} {{side}} hand", _LRN),
                      _RS(f"V:pick up {_ONE_THING} with {{poss}} {{side}} hand", _LRN),
                      _RS(f"V:bend down and V:pick up {_ONE_THING} with {{poss}} {{side}} hand", _LRN),
                      _RS("V:reach down and V:grab [something|an object/NOUN] with {poss} {side} hand", _LRN),
                      _RS(f"V:pick up {_ONE_THING} from the [floor|ground] with {{poss}} {{side}} hand", _LRN),
                      _RS(f"V:pick up {_BIG_THING} with both hands", _B),
                      _RS(f"V:bend down and V:pick up {_BIG_THING} with both hands", _B),
                      _RS(f"V:squat down and V:pick up {_BIG_THING}", _B),
                      _RS(f"V:lift {_BIG_THING} off the [floor|ground]", _B),
                      _RS(f"V:pick {_BIG_THING} up from the [floor|ground] with both hands", _B)),
    "step_over": _rules(_RS(f"V:step over {_OBSTACLE}"), _RS(f"V:walk over {_OBSTACLE}"),
                        _RS(f"V:step high/ADV over {_OBSTACLE}"),
                        _RS(f"V:lift {{poss}} legs high/ADV to/PART V:step over {_OBSTACLE}"),
                        _RS("V:clear [an obstacle/NOUN|a hurdle/NOUN|a low/ADJ fence/NOUN] with high/ADJ steps/NOUN")),
    "stumble": _rules(_R("V:stumble"), _R("V:stumble forward"), _R("V:trip"), _R("V:trip over something"),
                      _R("V:trip and V:catch {refl}"), _R("V:stumble and V:regain {poss} balance/NOUN"),
                      _R("V:lose {poss} balance/NOUN and V:recover"), _R("V:trip and almost V:fall"),
                      _R("V:walk and suddenly V:stumble"), _R("V:stumble while walking/VERB"),
                      _R("V:trip on something and V:catch {refl}"), _R("V:stumble but V:keep {poss} balance/NOUN")),
    # boxing
    "guard": _rules(_R("V:put up {poss} fists", _B), _R("V:raise {poss} fists", _B), _R("V:hold up {poss} fists", _B),
                    _R("V:raise {poss} fists in a boxing/NOUN guard/NOUN", _B), _R("V:get into a boxing/NOUN guard/NOUN", _B),
                    _R("V:hold {poss} hands up like a boxer/NOUN", _B), _R("V:put {poss} guard/NOUN up", _B),
                    _R("V:hold {poss} fists up in front/NOUN of {poss} face/NOUN", _B)),
    "jab_cross": _rules(_R("V:throw a jab/NOUN and a cross/NOUN", _LRN), _R("V:do a jab/NOUN cross/NOUN combination/NOUN", _LRN),
                        _R("V:throw a jab/NOUN with {poss} {side} hand and a cross/NOUN with {poss} {oside} hand", _LRN),
                        _R("V:jab with {poss} {side} hand and V:cross with {poss} {oside} hand", _LRN),
                        _R("V:throw a one two/NUM combination/NOUN", _LRN),
                        _R("V:box", _LRN, reps="implicit"), _R("V:shadowbox", _LRN, reps="implicit"),
                        _R("V:do some shadowboxing/NOUN", _LRN, reps="implicit"),
                        _R("V:punch with {poss} {side} hand and then with {poss} {oside} hand", _LRN)),
    "hook": _rules(_R("V:throw a {side} hook/NOUN", _LRN), _R("V:throw a hook/NOUN with {poss} {side} hand", _LRN),
                   _R("V:punch with a {side} hook/NOUN", _LRN), _R("V:swing a hook/NOUN with {poss} {side} arm", _LRN),
                   _R("V:do a {side} hook/NOUN punch/NOUN", _LRN),
                   _R("V:throw {num} {side} hooks/NOUN", _LRN, reps="count", min_reps=2)),
    "uppercut": _rules(_R("V:throw a {side} uppercut/NOUN", _LRN), _R("V:throw an uppercut/NOUN with {poss} {side} hand", _LRN),
                       _R("V:do a {side} uppercut/NOUN", _LRN), _R("V:punch upward with {poss} {side} fist", _LRN),
                       _R("V:throw an uppercut/NOUN with {poss} {side} fist", _LRN),
                       _R("V:throw {num} {side} uppercuts/NOUN", _LRN, reps="count", min_reps=2)),
    # hands on and across the body
    "hands_on_hips": _rules(_R("V:put {poss} hands on {poss} hips", _B), _R("V:place {poss} hands on {poss} hips", _B),
                            _R("V:rest {poss} hands on {poss} hips", _B), _R("V:stand with {poss} hands on {poss} hips", _B),
                            _R("V:put both hands on {poss} hips", _B), _R("V:put {poss} hands on {poss} waist", _B)),
    "scratch_head": _rules(_R("V:scratch {poss} head with {poss} {side} hand", _LRN), _R("V:scratch {poss} head", _LRN),
                           _R("V:raise {poss} {side} hand and V:scratch {poss} head", _LRN),
                           _R("V:scratch the side/NOUN of {poss} head with {poss} {side} hand", _LRN),
                           _R("V:touch {poss} head with {poss} {side} hand", _LRN)),
    "salute": _rules(_R("V:salute", _LRN), _R("V:salute with {poss} {side} hand", _LRN), _R("V:give a salute/NOUN", _LRN),
                     _R("V:give a military salute/NOUN with {poss} {side} hand", _LRN),
                     _R("V:raise {poss} {side} hand to {poss} forehead in a salute/NOUN", _LRN),
                     _R("V:bring {poss} {side} hand to {poss} brow", _LRN)),
    "cross_arms": _rules(_R("V:cross {poss} arms", _B), _R("V:fold {poss} arms", _B),
                         _R("V:cross {poss} arms over/ADP {poss} chest", _B), _R("V:fold {poss} arms across {poss} chest", _B),
                         _R("V:stand with {poss} arms crossed", _B), _R("V:cross both arms in front/NOUN of {obj}", _B)),
    "reach_across": _rules(_R("V:reach across {poss} body with {poss} {side} hand", _LRN),
                           _R("V:reach across with {poss} {side} arm", _LRN),
                           _R("V:reach {poss} {side} arm across {poss} body", _LRN),
                           _R("V:stretch {poss} {side} arm across {poss} chest", _LRN),
                           _R("V:reach over/ADV to the {oside:NOUN} with {poss} {side} hand", _LRN),
                           _R("V:extend {poss} {side} hand across {poss} body", _LRN)),
    "arm_circles": _rules(_R("V:do arm/NOUN circles/NOUN", _B), _R("V:make circles/NOUN with {poss} arms", _B),
                          _R("V:circle {poss} arms", _B), _R("V:rotate {poss} arms in circles/NOUN", _B),
                          _R("V:swing {poss} arms in circles/NOUN", _B), _R("V:do some arm/NOUN circles/NOUN", _B),
                          _R("V:circle {poss} outstretched arms", _B)),
})
# paraphrases of the older primitives (corpus 2.0): a treadmill is walking in place
RULES.update({
    "kneel": _rules(_R("V:kneel down on {poss} {side} knee", _LR), _R("V:kneel on {poss} {side} knee", _LR),
                    _R("V:go down on {poss} {side} knee", _LR), _R("V:drop to {poss} {side} knee", _LR),
                    _R("V:kneel down", _LR), _R("V:go down on one knee", _LR), _R("V:kneel on one knee", _LR),
                    _R("V:get down on one knee and V:stand back up", _LR),
                    _R("V:kneel down on {poss} {side} knee and V:get back up", _LR)),
    "lie_down": _rules(_R("V:lie down"), _RS("V:lie down on the [floor|ground]"), _RS("V:lie down on {poss} back"),
                       _RS("V:lie on the [floor|ground]"), _R("V:lie down on {poss} back with {poss} knees up"),
                       _R("V:sit down and then V:lie back on the floor"), _R("V:lay {refl} down on the ground"),
                       _R("V:get down and V:lie on {poss} back")),
    "lie_down_get_up": _rules(_RS("V:lie down [on the floor|on the ground|on {poss} back] and then V:get back up"),
                              _R("V:lie down and V:get up again"), _R("V:lie on the floor for a moment and V:get up"),
                              _R("V:lie down briefly/ADV and V:stand back up"),
                              _R("V:lie on {poss} back for a moment and then V:get up"),
                              _R("V:lie down and then V:rise to {poss} feet/NOUN")),
    "step_up": _rules(_RS("V:step up onto [a box|a step|a platform|a bench|a small step] and back down"),
                      _R("V:step up and down", reps="implicit", min_reps=1),
                      _R("V:do step/NOUN ups/NOUN", reps="implicit", min_reps=1),
                      _RS("V:step onto [a box|a step|a platform] and then V:step back off"),
                      _R("V:climb onto a box and back down"), _R("V:step up onto something and back down")),
    "climb_stairs": _rules(_RS("V:walk up [the stairs|some stairs|a flight of stairs|the steps/NOUN|a few steps/NOUN]"),
                           _RS("V:climb [the stairs|some stairs|a flight of stairs|up the stairs|up some steps/NOUN]"),
                           _RS("V:go up [the stairs|some stairs|a few steps/NOUN]"), _R("V:ascend a flight of stairs"),
                           _R("V:ascend the stairs"), _R("V:climb up a staircase"), _R("V:walk up a staircase")),
    "descend_stairs": _rules(_RS("V:walk down [the stairs|some stairs|a flight of stairs|the steps/NOUN|a few steps/NOUN]"),
                             _RS("V:go down [the stairs|some stairs|a few steps/NOUN]"),
                             _R("V:descend a flight of stairs"), _R("V:descend the stairs"),
                             _RS("V:come down [the stairs|a staircase]"), _R("V:walk down a staircase")),
    "shuffle": _rules(_R("V:shuffle forward"), _R("V:shuffle ahead"), _R("V:shuffle {poss} feet/NOUN forward"),
                      _R("V:take small shuffling/VERB steps/NOUN forward"),
                      _R("V:shuffle to the {side:NOUN}", _LR), _R("V:shuffle sideways to the {side:NOUN}", _LR),
                      _R("V:shuffle {poss} feet/NOUN to the {side:NOUN}", _LR)),
    "lunge": _rules(_R("V:lunge forward with {poss} {side} leg", _LR), _R("V:lunge forward on {poss} {side} leg", _LR),
                    _R("V:do a lunge/NOUN with {poss} {side} leg", _LR),
                    _R("V:step forward into a lunge/NOUN with {poss} {side} leg", _LR),
                    _R("V:lunge with {poss} {side} leg forward", _LR)),
    "side_bend": _rules(_R("V:bend to the {side:NOUN}", _LR), _R("V:bend sideways to the {side:NOUN}", _LR),
                        _R("V:lean to the {side:NOUN}", _LR), _R("V:lean over to the {side:NOUN}", _LR),
                        _R("V:stretch sideways to the {side:NOUN}", _LR),
                        _R("V:bend {poss} upper/ADJ body/NOUN to the {side:NOUN}", _LR)),
    "twist": _rules(_R("V:twist to the {side:NOUN}", _LR), _R("V:twist {poss} torso to the {side:NOUN}", _LR),
                    _R("V:rotate {poss} torso to the {side:NOUN}", _LR),
                    _R("V:twist {poss} upper/ADJ body/NOUN to the {side:NOUN}", _LR)),
    "pivot": _rules(_R("V:pivot to the {side:NOUN}", _LR), _R("V:pivot on {poss} {side} foot", _LR),
                    _R("V:pivot {side:ADV} on the ball of {poss} {side} foot", _LR),
                    _R("V:turn {side:ADV} on {poss} {side} foot", _LR),
                    _R("V:pivot on {poss} {side} foot and V:turn around", _LR, variant="around"),
                    _R("V:pivot around on {poss} {side} foot", _LR, variant="around"),
                    _R("V:pivot all the way around", _LR, variant="around"),
                    _R("V:turn around on the ball of {poss} {side} foot", _LR, variant="around")),
    "touch_knee": _rules(_R("V:touch {poss} {oside} knee with {poss} {side} hand", _LR),
                         _R("V:raise {poss} {oside} knee and V:touch it with {poss} {side} hand", _LR),
                         _R("V:lift {poss} {oside} knee and V:tap it with {poss} {side} hand", _LR),
                         _R("V:bring {poss} {side} hand to {poss} {oside} knee", _LR),
                         _R("V:reach across and V:touch {poss} {oside} knee with {poss} {side} hand", _LR),
                         _R("V:do a cross/NOUN body crunch/NOUN with {poss} {side} hand to {poss} {oside} knee", _LR),
                         _R("V:do {num} cross/NOUN body crunches/NOUN", _LR, reps="count", min_reps=2)),
})
RULES["walk"] += _rules(_R("V:walk a few steps/NOUN forward"), _R("V:head forward"), _R("V:advance forward"),
                        _R("V:make {poss} way/NOUN forward"), _R("V:go for a short walk/NOUN"),
                        _R("V:walk toward the front/NOUN"))
RULES["run"] += _rules(_R("V:race forward"), _R("V:rush forward"), _R("V:dart forward"),
                       _R("V:run a short distance/NOUN"))
RULES["jump"] += _rules(_R("V:jump straight up"), _R("V:spring up"), _R("V:jump on both feet/NOUN"),
                        _R("V:do a vertical/ADJ jump/NOUN", post_height=False))
RULES["wave"] += _rules(_R("V:wave hello/NOUN with {poss} {side} hand", _LR), _R("V:wave goodbye/NOUN with {poss} {side} hand", _LR),
                        _R("V:wave at someone with {poss} {side} hand", _LR), _R("V:give a wave/NOUN with {poss} {side} hand", _LR),
                        _R("V:wave to someone with both hands", _B))
RULES["raise"] += _rules(_R("V:hold up {poss} {side} hand", _LR), _R("V:put {poss} {side} arm up", _LR, high=("high",), low=()),
                         _R("V:reach up with {poss} {side} hand", _LR, high=("high",), low=()),
                         _R("V:hold up both hands", _B), _R("V:reach up with both hands", _B, high=("high",), low=()))
RULES["kick"] += _rules(_R("V:kick the air with {poss} {side} leg", _LR), _R("V:do a front/ADJ kick/NOUN with {poss} {side} leg", _LR),
                        _R("V:kick something in front/NOUN of {obj} with {poss} {side} foot", _LR, post_height=False))
RULES["squat"] += _rules(_R("V:do a deep/ADJ squat/NOUN", expresses=("low",)), _R("V:bend {poss} knees deeply", expresses=("low",)),
                         _R("V:squat down and V:stand back up", post_height=False))
RULES["sit"] += _rules(_R("V:take a seat/NOUN on the floor/NOUN"), _R("V:plop down on the floor"),
                       _R("V:lower {refl} onto the floor"))
RULES["bow"] += _rules(_R("V:bow politely/ADV"), _R("V:bow to someone"), _R("V:give a bow/NOUN", post_height=False))
RULES["clap"] += _rules(_R("V:clap along", _B), _R("V:give a round/NOUN of applause/NOUN", _B))
RULES["nod"] += _rules(_R("V:nod yes/ADV", reps="optional", min_reps=2))
RULES["shake_head"] += _rules(_R("V:shake {poss} head no/ADV", reps="optional", min_reps=2))
RULES["look"] += _rules(_R("V:peek to the {side:NOUN}", _LR), _R("V:glance over to the {side:NOUN}", _LR),
                        _R("V:look around to the {side:NOUN}", _LR))
RULES["stretch"] += _rules(_R("V:extend both arms straight ahead", _B), _R("V:reach {poss} arms out in front/NOUN", _B))
RULES["turn"] += _rules(_R("V:rotate to the {side:NOUN}", _LR), _R("V:turn to face/VERB the {side:NOUN}", _LR))
RULES["spin"] += _rules(_R("V:twirl around", _LR), _R("V:spin on the spot", _LR))
RULES["jumping_jacks"] += _rules(_R("V:do star/NOUN jumps/NOUN", reps="implicit", min_reps=2))
RULES["march"] += _rules(_R("V:march with high/ADJ knees"), _R("V:march in place with high/ADJ knees", variant="in_place"))
RULES["punch"] += _rules(_R("V:strike forward with {poss} {side} fist", _LR))
RULES["arms_out"] += _rules(_R("V:open {poss} arms wide", _B), _R("V:stretch {poss} arms sideways", _B))
RULES["walk_backward"] += _rules(_R("V:back up"), _R("V:retreat backward"), _R("V:step back a few steps/NOUN"))
RULES["walk"] += _rules(_R("V:walk on a treadmill/NOUN", variant="in_place"), _R("V:walk in place on a treadmill/NOUN", variant="in_place"),
                        _R("V:stride forward"), _R("V:pace forward"), _R("V:walk across the room/NOUN"),
                        _R("V:walk in a straight line/NOUN"), _R("V:wander forward"))
RULES["run"] += _rules(_R("V:run across the room/NOUN"), _R("V:run in a straight line/NOUN"), _R("V:dash forward/ADV"))
RULES["jog"] += _rules(_R("V:jog on a treadmill/NOUN", variant="in_place"), _R("V:run on a treadmill/NOUN", variant="in_place"),
                       _R("V:jog across the room/NOUN"), _R("V:jog lightly"))
RULES["jump"] += _rules(_R("V:bounce up and down", expresses=("low",), reps="implicit", min_reps=2),
                        _R("V:leap into the air", post_height=False), _R("V:jump into the air", post_height=False),
                        _R("V:skip forward", variant="forward"))
RULES["kick"] += _rules(_R("V:kick out with {poss} {side} leg", _LR), _R("V:kick {poss} {side} foot out", _LR))
RULES["squat"] += _rules(_R("V:bend {poss} knees and V:squat"), _R("V:lower {poss} body into a squat/NOUN", post_height=False))
RULES["bow"] += _rules(_R("V:bow {poss} head and upper/ADJ body"), _R("V:lean forward into a bow/NOUN", post_height=False))
RULES["clap"] += _rules(_R("V:applaud", _B), _R("V:clap {poss} hands a few times/NOUN", _B))
RULES["look"] += _rules(_R("V:look over/ADP {poss} {side} shoulder", _LR), _R("V:turn {poss} head {side:ADV}", _LR))
RULES["sit"] += _rules(_R("V:sit down on the floor/NOUN to/PART V:rest"), _R("V:lower {refl} to the ground"))


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
        elif tok.startswith("{side") or tok.startswith("{oside"):
            pos = tok.split(":")[1][:-1] if ":" in tok else "ADJ"
            w = side if tok.startswith("{side") else _MIRROR_WORDS[side]
            out.append((w, w, pos))
        elif tok == "{refl}":
            out.append((_REFLEXIVE[poss], _REFLEXIVE[poss], "PRON"))
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


# ============================================================================ style and intent
#: Extra subjects (words, possessives, subject pronoun or None, primitives they fit or None for any).
EXTRA_SUBJECTS: tuple[tuple[str, tuple[str, ...], str | None, frozenset | None], ...] = (
    ("somebody", ("their", "his"), None, None), ("a guy", ("his",), "he", None), ("a lady", ("her",), "she", None),
    ("a young man", ("his",), "he", None), ("an old man", ("his",), "he", None),
    ("an elderly man", ("his",), "he", None), ("a tall man", ("his",), "he", None),
    ("a young woman", ("her",), "she", None), ("an elderly woman", ("her",), "she", None),
    ("a short woman", ("her",), "she", None), ("a figure", ("their",), None, None),
    ("the figure", ("their",), None, None), ("a stick figure", ("their",), None, None),
    ("a human", ("their",), None, None), ("the character", ("their", "his"), None, None),
    ("an individual", ("their",), None, None), ("the subject", ("their",), None, None),
    ("an adult", ("their",), None, None), ("a performer", ("their",), None, None),
    ("a slim woman", ("her",), "she", None), ("a slender woman", ("her",), "she", None),
    ("a muscular man", ("his",), "he", None), ("an older person", ("their",), None, None),
    ("a bald man", ("his",), "he", None), ("a bearded man", ("his",), "he", None), ("an actor", ("their", "his"), None, None),
    ("the model", ("her", "his", "their"), None, None), ("an old woman", ("her",), "she", None),
    ("the dancer", ("her", "his", "their"), None, frozenset({"dance", "sway", "spin", "clap"})),
    ("a dancer", ("her", "his", "their"), None, frozenset({"dance", "sway", "spin", "clap"})),
    ("the boxer", ("his",), "he", frozenset({"jab_cross", "hook", "uppercut", "guard", "punch"})),
    ("a fighter", ("his", "her"), None, frozenset({"jab_cross", "hook", "uppercut", "guard", "punch", "kick"})),
    ("the athlete", ("his", "her"), None, frozenset({"jump", "run", "jog", "jumping_jacks", "squat", "knee_lift",
                                                    "arm_circles", "stretch", "kick", "step_over"})),
    ("an athletic man", ("his",), "he", frozenset({"jump", "run", "jog", "jumping_jacks", "squat", "kick"})),
    ("a soldier", ("his",), "he", frozenset({"salute", "march", "turn"})),
)

#: Speed words beyond "slowly" / "quickly": (before the verb, after the phrase) per modifier. Each
#: says the modifier, so the parser reads it back and the motion shows it.
SPEED_STYLE = {
    "slowly": (("slowly", "carefully", "cautiously", "gently", "calmly", "wearily", "lazily", "tiredly", "sadly"),
               ("slowly", "carefully", "gently", "calmly", "leisurely", "unhurriedly", "wearily", "lazily", "sadly",
                "at a slow/ADJ pace", "at an easy/ADJ pace", "without/ADP rushing/VERB", "in a relaxed/ADJ way/NOUN", "with care", "without/ADP hurrying/VERB")),
    "quickly": (("quickly", "briskly", "swiftly", "hurriedly", "energetically", "eagerly", "excitedly"),
                ("quickly", "rapidly", "energetically", "vigorously", "briskly", "swiftly", "hurriedly", "excitedly", "at a fast/ADJ pace", "at full/ADJ speed/NOUN", "in a rush/NOUN",
                 "in a hurry", "with a lot/NOUN of energy", "with great energy")),
}
_FORCE = frozenset({"kick", "punch", "jab_cross", "hook", "uppercut", "throw", "guard", "swing"})
_RHYTHM = frozenset({"dance", "sway", "clap", "march", "jumping_jacks", "nod", "arm_circles"})
_WORKOUT = frozenset({"squat", "jumping_jacks", "knee_lift", "stretch", "arm_circles", "march", "jog", "arms_out",
                      "kick", "bow", "touch_toes"})
#: Manner words that leave the motion as it is: (words, before the verb?, primitives or None for any).
MOOD_STYLE: tuple[tuple[str, bool, frozenset | None], ...] = tuple(
    [(w, True, None) for w in ("happily", "cheerfully", "joyfully", "casually", "confidently", "playfully",
                               "nervously", "proudly", "smoothly", "steadily", "awkwardly", "clumsily", "gracefully",
                               "thoughtfully", "quietly", "boldly", "shyly", "elegantly", "merrily", "dramatically",
                               "loosely", "firmly", "determinedly", "lightly")]
    + [(w, False, None) for w in ("happily", "cheerfully", "casually", "confidently", "playfully", "nervously",
                                  "proudly", "smoothly", "steadily", "awkwardly", "gracefully")]
    + [(w, False, None) for w in ("with confidence/NOUN", "with ease/NOUN", "in a playful/ADJ way/NOUN",
                                  "in a funny/ADJ way/NOUN", "in an exaggerated/ADJ way/NOUN", "in a silly/ADJ way/NOUN",
                                  "with determination/NOUN", "with enthusiasm/NOUN", "with purpose/NOUN")]
    + [(w, False, _FORCE) for w in ("with force/NOUN", "with power/NOUN")]
    + [(w, True, _FORCE) for w in ("angrily", "aggressively", "powerfully", "forcefully", "fiercely")]
    + [(w, False, _FORCE) for w in ("angrily", "aggressively", "powerfully", "forcefully", "hard")]
    + [(w, False, _RHYTHM) for w in ("in time/NOUN with the music/NOUN", "to an upbeat/ADJ song/NOUN", "rhythmically", "to the music/NOUN", "to the beat/NOUN", "to a beat/NOUN",
                                     "to the rhythm/NOUN")]
    + [(w, False, _WORKOUT) for w in ("as part/NOUN of an exercise/NOUN routine/NOUN",
                                      "like a fitness/NOUN instructor/NOUN", "as if warming/VERB up", "as part/NOUN of a workout", "as if exercising/VERB",
                                      "as if training/VERB")]
)
#: Intent clauses after a phrase, per primitive: "as if ..." and "to ...".
INTENT: dict[str, tuple[str, ...]] = {
    "walk": ("as if taking/VERB a stroll/NOUN", "as if walking/VERB in a park/NOUN", "as if heading/VERB to work/NOUN",
             "as if looking for something", "as if exploring/VERB the room/NOUN", "as if pacing/VERB",
             "as if lost/VERB in thought/NOUN"),
    "run": ("as if running/VERB a race/NOUN", "as if in a hurry", "as if late/ADJ for the bus", "as if chasing/VERB someone", "as if training/VERB"),
    "jog": ("as if training/VERB", "as if exercising/VERB"),
    "walk_backward": ("as if backing/VERB away from something", "as if avoiding/VERB something"),
    "sidestep": ("as if dodging/VERB something", "as if avoiding/VERB someone"),
    "turn": ("as if hearing/VERB a noise", "as if looking around"),
    "spin": ("as if dancing/VERB", "as if celebrating/VERB"),
    "jump": ("as if trying/VERB to/PART touch/VERB the ceiling/NOUN", "with joy/NOUN", "as if celebrating/VERB", "as if trying/VERB to/PART reach/VERB something", "with excitement/NOUN"),
    "kick": ("like a martial/ADJ artist/NOUN", "as if kicking/VERB a door/NOUN open/ADJ", "as if kicking/VERB a ball", "as if fighting/VERB someone"),
    "sit": ("to/PART rest/VERB", "as if tired", "to/PART take/VERB a break"),
    "bow": ("at the end of a performance/NOUN", "to the audience", "as if thanking/VERB an audience", "as if greeting/VERB someone"),
    "wave": ("as if hailing/VERB a taxi/NOUN", "as if waving/VERB to a friend across the street/NOUN",
             "as if greeting/VERB a friend", "as if saying/VERB goodbye", "to/PART say/VERB hello",
             "as if signalling/VERB to someone", "to/PART greet/VERB someone"),
    "raise": ("as if volunteering/VERB", "as if answering/VERB a question/NOUN", "as if asking/VERB a question/NOUN", "to/PART get/VERB attention/NOUN"),
    "punch": ("as if fighting/VERB someone", "as if hitting/VERB a punching/NOUN bag", "like a boxer"),
    "clap": ("at the end of a show/NOUN", "as if applauding/VERB", "as if cheering/VERB for someone"),
    "nod": ("as if listening/VERB to someone", "as if agreeing/VERB", "in agreement", "as if agreeing/VERB with someone"),
    "shake_head": ("as if refusing/VERB", "as if disagreeing/VERB", "in disbelief"),
    "look": ("as if checking/VERB for traffic/NOUN", "as if searching/VERB for someone", "as if hearing/VERB a noise"),
    "dance": ("as if at a wedding/NOUN", "like a pop/NOUN star/NOUN", "like nobody is watching/VERB", "as if at a party", "as if celebrating/VERB", "happily to the music/NOUN"),
    "throw": ("as if skipping/VERB a stone", "as if throwing/VERB to a friend", "like a baseball/NOUN pitcher/NOUN", "as if playing/VERB catch/NOUN"),
    "pick_up": ("as if collecting/VERB something", "as if tidying/VERB up", "from the floor", "off the ground"),
    "step_over": ("as if stepping/VERB over a sleeping/VERB dog/NOUN", "as if avoiding/VERB a puddle", "as if stepping/VERB over a log"),
    "stumble": ("as if the floor is slippery/ADJ", "as if tripping/VERB over something", "as if losing/VERB balance/NOUN"),
    "guard": ("as if expecting/VERB a hit/NOUN", "like a boxer", "as if ready/ADJ to/PART fight/VERB", "as if sparring/VERB"),
    "jab_cross": ("as if sparring/VERB", "as if fighting/VERB an opponent", "as if hitting/VERB a punching/NOUN bag"),
    "hook": ("as if in a boxing/NOUN match/NOUN", "like a professional/ADJ boxer", "as if sparring/VERB", "as if fighting/VERB an opponent"),
    "uppercut": ("as if in a boxing/NOUN match/NOUN", "as if sparring/VERB", "as if fighting/VERB an opponent"),
    "hands_on_hips": ("as if out/ADV of breath/NOUN", "as if waiting/VERB", "impatiently", "as if taking/VERB a break"),
    "scratch_head": ("as if puzzled/ADJ", "as if confused/ADJ", "as if thinking/VERB", "in confusion/NOUN"),
    "salute": ("as if greeting/VERB a general/NOUN", "as if saluting/VERB a flag/NOUN", "like a soldier", "as if greeting/VERB an officer"),
    "cross_arms": ("as if cold/ADJ", "as if thinking/VERB", "as if waiting/VERB", "impatiently", "as if annoyed/ADJ"),
    "reach_across": ("as if grabbing/VERB a seatbelt/NOUN", "as if grabbing/VERB something", "as if reaching/VERB for something"),
    "arm_circles": ("as if warming/VERB up", "to/PART loosen/VERB up"),
    "stretch": ("as if warming/VERB up", "as if reaching/VERB for something"),
    "spin": ("like a ballerina/NOUN", "as if dancing/VERB"),
    "squat": ("as if lifting/VERB weights/NOUN", "as if sitting/VERB on an invisible chair/NOUN"),
    "sway": ("as if listening/VERB to music/NOUN", "as if rocking/VERB a baby/NOUN"),
    "arms_out": ("as if flying/VERB", "like an airplane/NOUN", "as if balancing/VERB"),
    "jumping_jacks": ("as if in a gym/NOUN class/NOUN", "as if warming/VERB up", "as part of a workout"),
    "jog": ("as if jogging/VERB in a park/NOUN", "as if training/VERB", "as if exercising/VERB"),
    "sidestep": ("as if making/VERB room/NOUN for someone", "as if dodging/VERB something", "as if avoiding/VERB someone"),
    "march": ("like a soldier", "as if in a parade/NOUN"),
}


INTENT.update({
    "kneel": ("as if looking/VERB at something on the ground", "as if tying/VERB a shoelace", "as if praying/VERB", "as if proposing/VERB"),
    "lie_down": ("as if sunbathing/VERB", "to/PART rest/VERB", "as if tired", "as if taking/VERB a nap/NOUN"),
    "lie_down_get_up": ("as if doing/VERB an exercise", "as part of a workout"),
    "step_up": ("as if stepping/VERB onto a curb/NOUN", "as if exercising/VERB", "as part of a workout", "as if training/VERB"),
    "climb_stairs": ("as if climbing/VERB to the second/ADJ floor/NOUN", "as if going/VERB home/NOUN", "as if in a hurry"),
    "descend_stairs": ("as if going/VERB down to the street/NOUN", "as if in a hurry", "as if going/VERB home/NOUN"),
    "shuffle": ("as if tired", "as if dancing/VERB", "as if on ice/NOUN"),
    "side_bend": ("as if stretching/VERB", "as part of a workout", "as if warming/VERB up"),
    "twist": ("as if warming/VERB up", "as part of a workout", "as if dancing/VERB"),
    "lunge": ("as if exercising/VERB", "as part of a workout", "as if training/VERB", "as if warming/VERB up"),
    "pivot": ("as if dodging/VERB a defender/NOUN", "as if changing/VERB direction/NOUN", "like a basketball/NOUN player/NOUN", "as if dancing/VERB"),
    "touch_knee": ("as if stretching/VERB", "as if warming/VERB up", "as part of a workout", "as if exercising/VERB"),
    "crawl": ("like a baby/NOUN", "as if looking/VERB for something on the floor",
              "as if searching/VERB for something"),
})
# corpus 2.7: whole-body actions with large trunk motion
_lex("NOUN", "toe golf club bat shelf windmill target swing stretch")
RULES.update({
    "touch_toes": _rules(_R("V:touch {poss} toes", _B), _R("V:bend down and V:touch {poss} toes", _B),
                         _R("V:bend over and V:touch {poss} toes", _B), _R("V:reach down and V:touch {poss} toes", _B),
                         _R("V:bend forward to/PART touch/VERB {poss} toes", _B),
                         _R("V:touch {poss} toes with both hands", _B), _R("V:do a toe/NOUN touch/NOUN", _B),
                         _R("V:stretch down to {poss} toes", _B), _R("V:fold forward and V:touch {poss} toes", _B),
                         _R("V:touch {poss} {oside} foot/NOUN with {poss} {side} hand", _LRN),
                         _R("V:touch {poss} {oside} toes with {poss} {side} hand", _LRN),
                         _R("V:bend down and V:touch {poss} {oside} foot/NOUN with {poss} {side} hand", _LRN),
                         _R("V:reach down to {poss} {oside} foot/NOUN with {poss} {side} hand", _LRN),
                         _R("V:bend and V:twist to/PART touch/VERB {poss} {oside} toes with {poss} {side} hand", _LRN),
                         _R("V:do a windmill/NOUN stretch/NOUN with {poss} {side} hand to {poss} {oside} foot/NOUN", _LRN)),
    "swing": _rules(_R("V:swing a golf/NOUN club/NOUN", _LRN), _R("V:swing an imaginary/ADJ golf/NOUN club/NOUN", _LRN),
                    _R("V:take a golf/NOUN swing/NOUN", _LRN), _R("V:make a golf/NOUN swing/NOUN", _LRN),
                    _R("V:hit a golf/NOUN ball/NOUN", _LRN), _R("V:swing a golf/NOUN club/NOUN from {poss} {side} side/NOUN", _LRN),
                    _R("V:swing a golf/NOUN club/NOUN back over {poss} {side} shoulder and through", _LRN),
                    _R("V:swing a baseball/NOUN bat/NOUN", _LRN, variant="bat"), _R("V:swing a bat/NOUN", _LRN, variant="bat"),
                    _R("V:swing an imaginary/ADJ bat/NOUN", _LRN, variant="bat"),
                    _RS("V:take a swing/NOUN with a [bat/NOUN|baseball/NOUN bat/NOUN]", _LRN, variant="bat"),
                    _R("V:hit a ball/NOUN with a bat/NOUN", _LRN, variant="bat"),
                    _R("V:swing a baseball/NOUN bat/NOUN from {poss} {side} shoulder", _LRN, variant="bat"),
                    _R("V:step into a swing/NOUN with a baseball/NOUN bat/NOUN", _LRN, variant="bat")),
    "reach_up": _rules(_R("V:reach up to a high/ADJ shelf/NOUN with {poss} {side} hand", _LRN),
                       _R("V:reach up and over to the {oside:NOUN} with {poss} {side} hand", _LRN),
                       _R("V:reach up high/ADV to the {oside:NOUN} with {poss} {side} hand", _LRN),
                       _R("V:stretch up on {poss} toes to/PART reach/VERB something with {poss} {side} hand", _LRN),
                       _R("V:grab something from a high/ADJ shelf/NOUN with {poss} {side} hand", _LRN),
                       _R("V:step to the {oside:NOUN} and V:reach up with {poss} {side} hand", _LRN),
                       _R("V:get something down from a high/ADJ shelf/NOUN with {poss} {side} hand", _LRN),
                       _R("V:reach across and up with {poss} {side} hand", _LRN)),
})
RULES["kick"] += _rules(_R("V:kick to the {side:NOUN} with {poss} {side} leg", _LR, variant="side"),
                        _R("V:do a side/ADJ kick/NOUN with {poss} {side} leg", _LR, variant="side"),
                        _R("V:kick sideways with {poss} {side} leg", _LR, variant="side"),
                        _R("V:kick {poss} {side} leg out to the side/NOUN", _LR, variant="side"),
                        _R("V:kick backward with {poss} {side} leg", _LR, variant="back"),
                        _R("V:kick back/ADV with {poss} {side} leg", _LR, variant="back"),
                        _R("V:do a back/ADJ kick/NOUN with {poss} {side} leg", _LR, variant="back"),
                        _R("V:kick {poss} {side} leg out behind {obj}", _LR, variant="back"))
_lex("NOUN", "pose gymnast yoga")
_lex("ADP", "behind")
RULES["balance"] = _rules(_R("V:balance on {poss} {side} leg", _LR), _R("V:balance on {poss} {side} foot/NOUN", _LR),
                          _R("V:stand on {poss} {side} leg", _LR),
                          _R("V:balance on {poss} {side} leg with {poss} arms out", _LR),
                          _R("V:do an airplane/NOUN pose/NOUN on {poss} {side} leg", _LR),
                          _R("V:lean forward on {poss} {side} leg and V:lift {poss} {oside} leg behind {obj}", _LR),
                          _R("V:stand on {poss} {side} leg and V:stretch {poss} {oside} leg back/ADV", _LR),
                          _R("V:tip forward and V:balance on {poss} {side} leg", _LR))
INTENT["balance"] = ("like a gymnast/NOUN", "as if doing/VERB yoga/NOUN", "like a ballerina/NOUN", "as if balancing/VERB")
RULES["lunge"] += _rules(_R("V:lunge to the {side:NOUN}", _LR, variant="side"),
                         _R("V:lunge sideways to the {side:NOUN}", _LR, variant="side"),
                         _R("V:do a side/ADJ lunge/NOUN to the {side:NOUN}", _LR, variant="side"),
                         _R("V:do a side/ADJ lunge/NOUN with {poss} {side} leg", _LR, variant="side"),
                         _R("V:step out to the {side:NOUN} into a lunge/NOUN", _LR, variant="side"),
                         _R("V:lunge out to the {side:NOUN} with {poss} {side} leg", _LR, variant="side"))
INTENT.update({
    "touch_toes": ("as if stretching/VERB", "as part of a workout", "as if warming/VERB up", "as if exercising/VERB"),
    "swing": ("as if playing/VERB a match/NOUN", "as if training/VERB", "as if hitting/VERB a ball far/ADV",
              "as if aiming/VERB at a target/NOUN"),
    "reach_up": ("as if reaching/VERB for something", "as if grabbing/VERB something", "as if stretching/VERB"),
})
# corpus 2.1: on all fours
RULES["crawl"] = _rules(_R("V:crawl forward"), _R("V:crawl"), _RS("V:crawl on [all/DET fours/NOUN|{poss} hands and knees]"),
                        _RS("V:crawl [across|along] the floor"), _R("V:move forward on all/DET fours/NOUN"),
                        _R("V:move forward on {poss} hands and knees"), _R("V:crawl ahead on the floor"))

# corpus 2.8: the words of the general-motion set's captions (salad_core.data.procedural.general_language);
# they only add entries, so the captions of the action corpus are unchanged
_GENERAL_VERBS = {"roll": ("rolls", "rolling"), "flip": ("flips", "flipping"), "cartwheel": ("cartwheels", "cartwheeling"),
                  "somersault": ("somersaults", "somersaulting"), "tumble": ("tumbles", "tumbling"),
                  "push": ("pushes", "pushing"), "pull": ("pulls", "pulling"), "straighten": ("straightens", "straightening"),
                  "stay": ("stays", "staying"), "land": ("lands", "landing"), "tuck": ("tucks", "tucking"),
                  "pause": ("pauses", "pausing"), "shift": ("shifts", "shifting"), "flop": ("flops", "flopping"),
                  "roam": ("roams", "roaming"), "curl": ("curls", "curling")}
for _lemma, _forms in _GENERAL_VERBS.items():
    VERBS.setdefault(_lemma, _forms)
    for _f in _forms:
        LEXICON.setdefault(_f, (_lemma, "VERB"))
    LEXICON.setdefault(_lemma, (_lemma, "VERB"))
# (a plural like "cartwheels" reads as the verb by default; templates tag the noun reading "cartwheels/NOUN")
_lex("NOUN", "handstand handstands backflip backflips walkover stomach belly tummy heels curve movements limbs series "
             "acrobat acrobatics gymnastics split splits",
     {"handstands": "handstand", "backflips": "backflip", "heels": "heel", "movements": "movement", "limbs": "limb",
      "splits": "split"})
_lex("ADJ", "random several other upright unusual acrobatic gymnastic tight")
_lex("ADV", "diagonally freely randomly still upside apart aimlessly")
_lex("NOUN", "weight")
_lex("ADJ", "long")
for _w in ("crouch", "leap", "lie", "sit", "spin", "spread", "stop"):
    LEXICON.setdefault(_w, (_w, "VERB"))       # bare forms ("to lie face down"; tagged nouns: "a spin/NOUN")


def _style_options(kind: str) -> list[tuple[str, bool]]:
    """(words, before the verb?) of the manner and intent words that fit ``kind``."""
    out = [(w, pre) for w, pre, kinds in MOOD_STYLE if kinds is None or kind in kinds]
    out += [(w, False) for w in INTENT.get(kind, ())]
    return out


def _items(text: str) -> list[Item]:
    """Word items of literal text; a ``word/POS`` token states its tag."""
    out = []
    for tok in text.split():
        w, _, pos = tok.partition("/")
        out.append(_word(w, pos or None))
    return out


# ============================================================================ sentence frames
#: Sentence frames per plan shape. Slots: {S} subject, {P} subject pronoun, {A<i>} / {G<i>} step i
#: (present / gerund, with its layered gesture after "while"), {M} / {MG} the main action and
#: {L} / {LG} the layered gesture of a one-step plan, {O} / {OG} the overlay, {SEQ} / {SEQG} all
#: steps joined by "and then" / ", then". "," "." ";" are punctuation; ``word/POS`` states a tag.
FRAMES: dict[str, tuple[str, ...]] = {
    "single": ("{S} {A0}", "{S} is {G0}", "{S} just {A0}", "{S} simply {A0}", "{S} {A0} for a moment",
               "{S} {A0} for a few seconds/NOUN"),
    "layered": (
        "{S} {M} while {LG}", "{S} is {MG} while {LG}", "while {MG} , {S} {L}", "{S} {L} while {MG}",
        "{S} {M} and {L} at the same time", "{S} {L} as {P} {M}", "{S} {M} , {LG} at the same time",
        "{S} {M} while also {LG}", "{S} {M} and simultaneously {L}", "{S} {M} , all the while {LG}",
        "{S} is {MG} and {LG} at the same time", "{S} {L} while {P} {M}", "{S} {M} and meanwhile {L}",
        "as {P} {M} , {P} {L}", "{S} {M} , {LG} as {P} does/AUX so/ADV", "{S} {L} all while {MG}",
        "{S} combines/VERB {MG} with {LG}", "{S} {M} while {P} also {L}"),
    "seq2": (
        "{S} {A0} , then {A1}", "{S} {A0} and then {A1}", "{S} {A0} , and then {A1}", "{S} {A0} then {A1}",
        "{S} {A0} and {A1}", "first , {S} {A0} , then {A1}", "first {S} {A0} and then {A1}",
        "{S} first {A0} and then {A1}", "{S} first {A0} , then {A1}", "{S} is {G0} and then {G1}",
        "{S} {A0} before {G1}", "after {G0} , {S} {A1}", "{S} {A0} . after that , {P} {A1}",
        "{S} {A0} , after which {P} {A1}", "{S} {A0} and afterwards {A1}", "{S} {A0} . next , {P} {A1}",
        "{S} {A0} and next {A1}", "{S} {A0} and finally {A1}", "{S} {A0} , and after a while/NOUN {P} {A1}",
        "{S} {A0} , and after a while/NOUN {A1}", "{S} {A0} and eventually {A1}", "{S} {A0} , then eventually {A1}",
        "at first {S} {A0} , later {P} {A1}", "at first {S} {A0} , but then {P} {A1}", "{S} starts by {G0} and then {A1}",
        "{S} begins by {G0} , then {A1}", "{S} {A0} , then immediately {A1}", "{S} {A0} and immediately {A1}",
        "{S} {A0} ; a moment later {P} {A1}", "{S} {A0} and soon after {A1}", "{S} {A0} and later {A1}",
        "{S} {A0} and shortly after {A1}", "{S} {A0} and , once done , {A1}", "{S} is {G0} , and then {P} {A1}",
        "{S} {A0} , and when {P} is done , {P} {A1}", "{S} {A0} first , then {A1}", "{S} {A0} and then also {A1}",
        "{S} {A0} and continues by {G1}", "{S} {A0} and ends by {G1}", "{S} {A0} . afterwards , {P} {A1}",
        "{S} {A0} and in the end {A1}", "{S} {A0} and , a few seconds/NOUN later , {A1}", "{S} {A0} and thereafter {A1}",
        "{S} {A0} ; subsequently , {P} {A1}", "{S} {A0} , then without/ADP stopping/VERB {A1}",
        "{S} {A0} and smoothly transitions/VERB into {G1}"),
    "seq3": (
        "{S} {A0} , then {A1} , then {A2}", "{S} {A0} , then {A1} , and then {A2}", "{S} {A0} , then {A1} , and finally {A2}",
        "first , {S} {A0} , then {A1} , and finally {A2}", "{S} {A0} , {A1} , and then {A2}",
        "{S} is {G0} , then {G1} , and then {G2}", "{S} {A0} . then {P} {A1} . finally , {P} {A2}",
        "{S} {A0} , after that {A1} , and eventually {A2}", "at first {S} {A0} , then {P} {A1} , and at the end {P} {A2}",
        "{S} starts by {G0} , then {A1} and finally {A2}", "{S} {A0} and then {A1} before {G2}",
        "{S} first {A0} , next {A1} , and finally {A2}", "{S} {A0} , followed/VERB by {G1} and {G2}"),
    "overlay": (
        "{S} {SEQ} , while {OG}", "while {OG} , {S} {SEQ}", "{S} {O} while {SEQG}", "{S} {SEQ} , {OG} all the while",
        "{S} {O} the whole time as {P} {SEQ}", "{S} {SEQ} , {OG} the whole time", "{S} keeps {OG} while {P} {SEQ}",
        "throughout , {S} {O} while {SEQG}"),
}
#: Openings that put a frame beginning with "{S} <verb>" into a scene: "in this clip, a man walks".
OPENINGS = ("in this clip ,", "in this video ,", "in the video ,", "here ,", "in this animation ,", "the video shows how")
#: Openings that replace the "{S} is" of a gerund frame: "we see a man walking and then jumping".
GERUND_OPENINGS = ("we see {S}", "the video shows {S}", "there is {S}", "this is {S}", "{S} can be seen",
                   "{S} who is", "an animation/NOUN of {S}", "a clip/NOUN of {S}", "footage of {S}")
_OPEN_P = 0.25


def sentence_frames() -> list[str]:
    """Every sentence frame the caption renderer can produce (frames and their openings), as
    :func:`sentence_frame` writes them: slots become ``<S>``, ``<P>`` and ``<A>``, punctuation goes."""
    out = set()
    for frames in FRAMES.values():
        for f in frames:
            for g in _opened(f):
                out.add(_frame_text(g))
    return sorted(out)


def _opened(frame: str) -> list[str]:
    """``frame`` and each of its openings."""
    out = [frame]
    if frame.startswith("{S} is "):
        out += [o + frame[len("{S} is"):] for o in GERUND_OPENINGS]
    elif frame.startswith("{S} ") and not frame.startswith("{S} {O}"):
        out += [o + " " + frame for o in OPENINGS]
    return out


def _frame_text(frame: str) -> str:
    words = []
    for tok in frame.split():
        if tok in (",", ".", ";"):
            continue
        if tok.startswith("{"):
            slot = tok[1:-1]
            w = "<S>" if slot == "S" else "<P>" if slot == "P" else "<A>"
            if slot in ("SEQ", "SEQG"):
                w = "<A> and then <A>"
            words.append(w)
        else:
            words.append(tok.split("/")[0])
    return " ".join(words)


def vocabulary() -> set[str]:
    """Every word the captions can use: phrase rules (all verb forms, sides, possessives, counts,
    height, speed and repetition words), style and intent words, subjects and sentence frames.

    The words a corpus's captions actually use are a subset (count them with ``split_words``).
    """
    out: set[str] = set()

    def add(text: str) -> None:
        for tok in text.split():
            if tok.startswith("V:"):
                out.update(VERBS[tok[2:]])
            elif tok in ("{poss}", "{obj}", "{refl}"):
                table = {"{poss}": {p: p for p in _OBJECT}, "{obj}": _OBJECT, "{refl}": _REFLEXIVE}[tok]
                out.update(table.values())
            elif tok.startswith("{side") or tok.startswith("{oside"):
                out.update(("left", "right"))
            elif tok == "{cw}":
                out.update(("clockwise", "counterclockwise"))
            elif tok == "{num}":
                out.update(_COUNT.values())
            elif tok.startswith("{") or tok in (",", ".", ";"):
                continue
            else:
                out.add(tok.split("/")[0])

    for rules in RULES.values():
        for rule in rules:
            add(rule.template)
            for words in (rule.high or ()) + (rule.low or ()):
                add(words)
    for table in (_HIGH_DEFAULT, _LOW_DEFAULT):
        for words in table.values():
            for w in words:
                add(w)
    for kind in RULES:
        for mod in ("slowly", "quickly"):
            pre, post = _speed_words(kind, mod)
            out.update(pre + post)
    for words in _REPS.values():
        for w in words:
            add(w)
    for before, after in SPEED_STYLE.values():
        for w in before + after:
            add(w)
    for w, _, _ in MOOD_STYLE:
        add(w)
    for ws in INTENT.values():
        for w in ws:
            add(w)
    for s in SUBJECTS:
        add(s[0])
        out.update(w for w in (s[2],) if w)
    for s in EXTRA_SUBJECTS:
        add(s[0])
    for frames in FRAMES.values():
        for f in frames:
            for g in _opened(f):
                add(g)
    out.update(("and", "then", "while"))                  # the joints of {SEQ} and of layered steps
    return out


def _subject_words() -> list[tuple[str, ...]]:
    subs = {tuple(s[0].split()) for s in SUBJECTS} | {tuple(s[0].split()) for s in EXTRA_SUBJECTS}
    return sorted(subs, key=len, reverse=True)


def sentence_frame(words: list[str], spans) -> str:
    """The sentence frame of a caption: its words with each action phrase span ``[i0, i1)`` as
    ``<A>``, the subject as ``<S>`` and subject pronouns as ``<P>`` (punctuation is not a word).

    Counting distinct frames over a corpus's captions (``annotations/<id>.json`` hold the words'
    spans) measures how many sentence shapes the captions use.
    """
    words = list(words)
    starts = {int(i0): int(i1) for i0, i1 in spans}
    subjects = _subject_words()
    out, i = [], 0
    while i < len(words):
        if i in starts:
            out.append("<A>")
            i = max(starts[i], i + 1)
            continue
        for sub in subjects:
            if tuple(words[i:i + len(sub)]) == sub:
                out.append("<S>")
                i += len(sub)
                break
        else:
            out.append("<P>" if words[i] in ("he", "she", "they") else words[i])
            i += 1
    return " ".join(out)


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

    @property
    def frame(self) -> str:
        """The caption's sentence frame (see :func:`sentence_frame`)."""
        return sentence_frame(self.words, self.spans)


class _Builder:
    """Accumulates words and punctuation, recording phrase spans."""

    def __init__(self) -> None:
        self.pieces: list[str] = []
        self.items: list[Item] = []
        self.spans: dict[int, tuple[int, int]] = {}
        self.after_phrase = False               # no word since the last phrase (punctuation only)

    def words(self, text: str) -> None:
        self.after_phrase = False
        for item in _items(text):
            self.items.append(item)
            self.pieces.append(item[0])

    def punct(self, p: str) -> None:
        if self.pieces:
            self.pieces[-1] += p

    def phrase(self, idx: int, items: list[Item]) -> None:
        i0 = len(self.items)
        self.items += items
        self.pieces += [w for w, _, _ in items]
        self.spans[idx] = (i0, len(self.items))
        self.after_phrase = True

    def caption(self, n_actions: int, period: bool) -> Caption:
        text = " ".join(self.pieces) + ("." if period and not self.pieces[-1].endswith(".") else "")
        words = split_words(text)
        if words != [w for w, _, _ in self.items]:
            raise AssertionError(f"caption words {words} differ from the built words")
        if sorted(self.spans) != list(range(n_actions)):
            raise AssertionError(f"caption {text!r} misses action phrases: {sorted(self.spans)}")
        return Caption(text, tuple((t, p) for _, t, p in self.items),
                       tuple(self.spans[i] for i in range(n_actions)))


def _choose(rng: np.random.Generator, options: list):
    return options[int(rng.integers(len(options)))]


def _shape(plan: Plan) -> str:
    if plan.overlay is not None:
        return "overlay"
    if len(plan.steps) == 1:
        return "layered" if plan.steps[0].layer is not None else "single"
    return "seq2" if len(plan.steps) == 2 else "seq3"


def _subject(plan: Plan, rng: np.random.Generator) -> tuple[str, tuple[str, ...], str | None]:
    if rng.random() < 0.65:
        return _choose(rng, list(SUBJECTS))
    kinds = {a.kind for _, _, a in plan.actions()}
    fits = [s[:3] for s in EXTRA_SUBJECTS if s[3] is None or kinds & s[3]]
    return _choose(rng, fits)


#: Chance that a speed modifier is said with a style word ("carefully") rather than "slowly".
SPEED_STYLE_P = 0.6
#: Chance that an action phrase without such a word gets a manner or intent word.
MANNER_P = 0.3


def _styled_phrase(action: Action, form: str, poss: str, rng: np.random.Generator, before: bool = True) -> list[Item]:
    """One wording of ``action``, sometimes with a style word (speed) or a manner/intent word.

    ``before=False`` keeps style words after the phrase: right after another phrase, a word
    before this one would read as the other phrase's (the parser gives it to that one).
    """
    speed = [m for m in action.mods if m in SPEED_STYLE]
    if speed and rng.random() < SPEED_STYLE_P:
        plain = replace(action, mods=tuple(m for m in action.mods if m not in SPEED_STYLE))
        options = phrase_realisations(plain, form, poss)
        if options:
            pre, post = SPEED_STYLE[speed[0]]
            words = _choose(rng, [(w, True) for w in pre if before] + [(w, False) for w in post])
            return _decorate(_choose(rng, options), words, poss)
    options = phrase_realisations(action, form, poss)
    if not before:
        options = [o for o in options if o[0][0] not in ("slowly", "quickly")] or options
    items = _choose(rng, options)
    if not speed and rng.random() < MANNER_P:
        items = _decorate(items, _choose(rng, [o for o in _style_options(action.kind) if before or not o[1]]), poss)
    return items


def _decorate(items: list[Item], style: tuple[str, bool], poss: str) -> list[Item]:
    words, before = style
    extra = _items(words)
    return extra + items if before else items + extra


def render_caption(plan: Plan, rng: np.random.Generator) -> Caption:
    """One random caption of ``plan``; phrase spans in ``plan.actions()`` order."""
    subj, posses, pron = _subject(plan, rng)
    poss = _choose(rng, list(posses))
    acts = plan.actions()
    index = {(role, i): k for k, (role, i, _) in enumerate(acts)}
    b = _Builder()

    def say(role: str, i: int, form: str) -> None:
        action = acts[index[(role, i)]][2]
        b.phrase(index[(role, i)], _styled_phrase(action, form, poss, rng, before=not b.after_phrase))

    def step(i: int, form: str) -> None:
        """A step of a sequence: its main action, "while" its layer."""
        say("main", i, form)
        if plan.steps[i].layer is not None:
            b.words("while")
            say("layer", i, "ger")

    def seq(form: str) -> None:
        step(0, form)
        for i in range(1, len(plan.steps)):
            if form == "pres" and rng.random() < 0.4:
                b.punct(","); b.words("then")
            else:
                b.words("and then")
            step(i, form)

    shape = _shape(plan)
    frames = [f for f in FRAMES[shape] if pron or "{P}" not in f]
    frame = _choose(rng, frames)
    if len(plan.steps) > 3 and shape != "overlay":
        frame = "{S} " + " , then ".join(f"{{A{i}}}" for i in range(len(plan.steps)))
    slots = {"{M}": lambda: say("main", 0, "pres"), "{MG}": lambda: say("main", 0, "ger"),
             "{L}": lambda: say("layer", 0, "pres"), "{LG}": lambda: say("layer", 0, "ger"),
             "{O}": lambda: say("overlay", -1, "pres"), "{OG}": lambda: say("overlay", -1, "ger"),
             "{SEQ}": lambda: seq("pres"), "{SEQG}": lambda: seq("ger")}
    _write_frame(b, _open_frame(frame, rng), subj, pron, step, slots)
    return b.caption(len(acts), period=bool(rng.random() < 0.5))


def _open_frame(frame: str, rng: np.random.Generator) -> str:
    """``frame``, or (with chance :data:`_OPEN_P`, when it has openings) one of its openings at random."""
    opened = _opened(frame)
    if len(opened) > 1 and rng.random() < _OPEN_P:
        return _choose(rng, opened[1:])
    return frame


def _write_frame(b: _Builder, frame: str, subj: str, pron: str | None, phrase: Callable[[int, str], None],
                 slots: dict[str, Callable[[], None]] | None = None) -> None:
    """Write the tokens of a sentence frame into ``b``: punctuation, the subject ``{S}``, the pronoun
    ``{P}``, the numbered phrase slots ``{A<i>}`` / ``{G<i>}`` (``phrase(i, "pres" | "ger")``), the other
    named ``slots`` (token -> writer) and plain words."""
    slots = slots or {}
    for tok in frame.split():
        if tok in (",", ".", ";"):
            b.punct(tok)
        elif tok == "{S}":
            b.words(subj)
        elif tok == "{P}":
            b.words(pron)
        elif tok[:2] in ("{A", "{G") and tok[2:-1].isdigit():
            phrase(int(tok[2:-1]), "pres" if tok[1] == "A" else "ger")
        elif tok in slots:
            slots[tok]()
        else:
            b.words(tok)


def _distinct_captions(render: Callable[[], Caption], n: int, tries: int) -> list[Caption]:
    """Up to ``n`` captions of distinct text from at most ``tries`` calls of ``render``, in first-seen order."""
    out: dict[str, Caption] = {}
    for _ in range(tries):
        c = render()
        out.setdefault(c.text, c)
        if len(out) == n:
            break
    return list(out.values())


def render_captions(plan: Plan, rng: np.random.Generator, n: int = 3, tries: int = 40) -> list[Caption]:
    """``n`` distinct captions of ``plan`` (fewer only if the language has fewer)."""
    return _distinct_captions(lambda: render_caption(plan, rng), n, tries)


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


def _glue() -> set[tuple[str, ...]]:
    """Word runs between the slots of every sentence frame, subjects and pronouns."""
    out = {tuple(w.split()) for w in ("he", "she", "is")} | set(_subject_words())
    for frames in FRAMES.values():
        for f in frames:
            for g in _opened(f) + [f.replace("{SEQ}", "{A0} , then {A1}")]:
                run: list[str] = []
                for tok in g.split() + ["{END}"]:
                    if tok.startswith("{") or tok in (",", ".", ";"):
                        if run:
                            out.add(tuple(run))
                        run = []
                    else:
                        run.append(tok.split("/")[0])
    out |= {("and", "then"), ("then",)}
    return out


def _style_table() -> tuple[dict[tuple[str, ...], str | None], dict[tuple[str, ...], str | None]]:
    """Style words before the verb and after the phrase -> the modifier they say (or None)."""
    pre: dict[tuple[str, ...], str | None] = {}
    post: dict[tuple[str, ...], str | None] = {}
    for mod, (before, after) in SPEED_STYLE.items():
        for w in before:
            pre[tuple(x.split("/")[0] for x in w.split())] = mod
        for w in after:
            post[tuple(x.split("/")[0] for x in w.split())] = mod
    for w, before, _ in MOOD_STYLE:
        key = tuple(x.split("/")[0] for x in w.split())
        (pre if before else post).setdefault(key, None)
    for ws in INTENT.values():
        for w in ws:
            post.setdefault(tuple(x.split("/")[0] for x in w.split()), None)
    return pre, post


@lru_cache(maxsize=1)
def _units() -> tuple[dict, set, dict, dict, int]:
    table, longest = _phrase_table()
    pre, post = _style_table()
    glue = _glue()
    longest = max([longest] + [len(k) for k in glue] + [len(k) for k in post])
    return table, glue, pre, post, longest


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

    A style word before a phrase ("happily", "carefully") or after it ("energetically", "as if
    greeting a friend", "to the music") belongs to the phrase: its span covers it and a style
    word that says a speed ("carefully": slowly) adds that modifier.

    Returns the phrases in order, or None if the prompt is not in the corpus's language (some
    word sequence is neither an action phrase, a style word next to one, nor a subject or
    connective of a sentence frame).
    """
    words = split_words(prompt)
    if not words:
        return None
    table, glue, pre, post, longest = _units()
    units = _cover(words, table, glue, pre, post, longest, late_ends=True)
    if units is None:
        return None
    out = []
    for (i, j), (i0, i1), before, after in _styled_phrases(units):
        kind, side, mods, reps, variant = _common(table[tuple(words[i:j])])
        mods = set(mods)
        if before is not None:
            mods |= {pre[tuple(words[before[0]:i])]} - {None}
        for a, b in after:
            mods |= {post[tuple(words[a:b])]} - {None}
        out.append(ParsedPhrase((i0, i1), " ".join(words[i0:i1]), kind, side, tuple(sorted(mods)), reps, variant))
    return out or None


def _cover(words: list[str], table: Container, glue: Container, pre: Container, post: Container, longest: int,
           late_ends: bool = False) -> list[tuple[str, int, int]] | None:
    """Read ``words`` as a run of units ``(kind, i, j)`` (``words[i:j]``), kind "phrase" (a key of
    ``table``), "glue", "pre" (a style word before a phrase) or "post" (one after a phrase or another
    "post"), with the fewest phrase and glue units (style words are free); units are at most ``longest``
    words. ``late_ends``: ties go to the reading whose earlier units are longer. None when no reading
    covers the words, or a "pre" unit is not followed by a phrase."""
    n = len(words)
    # best[i]: (number of phrase and glue units, units) covering words[:i]
    best: list[tuple[int, tuple] | None] = [None] * (n + 1)
    best[0] = (0, ())
    for i in range(n):
        if best[i] is None:
            continue
        last = best[i][1][-1][0] if best[i][1] else None
        for j in range(i + 1, min(n, i + longest) + 1):
            key = tuple(words[i:j])
            kinds = []
            if key in table:
                kinds.append("phrase")
            if key in glue:
                kinds.append("glue")
            if key in post and last in ("phrase", "post"):
                kinds.append("post")        # before "pre": a word that can be either follows its phrase
            elif key in pre and last != "pre":
                kinds.append("pre")
            for kind in kinds:
                cand = (best[i][0] + (kind in ("phrase", "glue")), best[i][1] + ((kind, i, j),))
                # with late_ends, a speed word between two phrases ("... quickly, shaking ...") ends
                # the first one, as the renderer writes it
                if best[j] is None or cand[0] < best[j][0] or (late_ends and cand[0] == best[j][0] and kind != "pre"
                                                               and i > best[j][1][-1][1]):
                    best[j] = cand
    if best[n] is None:
        return None
    units = list(best[n][1])
    for k, (kind, _, _) in enumerate(units):
        if kind == "pre" and (k + 1 >= len(units) or units[k + 1][0] != "phrase"):
            return None                     # a style word must lead into a phrase
    return units


def _styled_phrases(units: list[tuple[str, int, int]]) -> Iterator[tuple[tuple[int, int], tuple[int, int],
                                                                         tuple[int, int] | None, list[tuple[int, int]]]]:
    """For each phrase unit of a :func:`_cover` reading, in order: its words ``(i, j)``, its span with
    its style words ``(i0, i1)``, the words of the style word before it (or None) and of those after it."""
    for k, (kind, i, j) in enumerate(units):
        if kind != "phrase":
            continue
        before = units[k - 1][1:] if k > 0 and units[k - 1][0] == "pre" else None
        after = []
        q = k + 1
        while q < len(units) and units[q][0] == "post":
            after.append(units[q][1:])
            q += 1
        yield (i, j), (before[0] if before else i, after[-1][1] if after else j), before, after


def in_language(prompt: str) -> bool:
    """Whether ``prompt`` can be said with the corpus's subjects, connectives and action phrases."""
    return parse_prompt(prompt) is not None
