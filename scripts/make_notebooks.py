"""Write the notebooks in notebooks/ from the cell lists below (stored without outputs).

Notebooks are thin: a title saying what they reproduce, a parameters cell with a QUICK mode
(the default, what CI runs; ``SALAD_QUICK=0`` for the full settings), library calls and figures.
Usage: python scripts/make_notebooks.py
"""
from __future__ import annotations

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parents[1] / "notebooks"

SETUP = '''import os
from pathlib import Path
QUICK = os.environ.get("SALAD_QUICK", "1") == "1"      # QUICK: shipped weights, few steps, < 2 min
OUT = Path(os.environ.get("SALAD_NOTEBOOK_OUT", "notebook_outputs"))
OUT.mkdir(parents=True, exist_ok=True)
%matplotlib inline'''

NOTEBOOKS: dict[str, list[tuple[str, str]]] = {}

NOTEBOOKS["00_quickstart"] = [
    ("md", """# Quickstart: generate a motion, look at its attention, edit it, export it

salad's SALAD pipeline on the embedded defaults: weights trained on the procedural corpus, the MiniLM
text encoder, 50 DDIM steps with classifier-free guidance (w = 7.5). Runs on a CPU in about a minute."""),
    ("code", SETUP + '''
PROMPT = "a man is walking while raising his left hand up high"
LENGTH = 100          # frames at 20 fps (multiple of 4, at most 196)
STEPS = 50
SEED = 0'''),
    ("code", '''from salad_core.pipeline import SaladPipeline
import salad_viz as viz

pipe = SaladPipeline.from_pretrained()          # the shipped default weights
out = pipe(PROMPT, lengths=LENGTH, seed=SEED, num_steps=STEPS, capture_attention=True)
joints = out.joints[0]                           # (N, 22, 3) metres, +Y up
print(out.texts[0], joints.shape, out.settings)'''),
    ("md", "The motion as a keyframe strip and an animation (pyvista off-screen; a 2D rasteriser is used where OpenGL is missing)."),
    ("code", '''import numpy as np
from IPython.display import display
from PIL import Image
display(Image.fromarray(viz.keyframe_strip(joints, "humanml3d", np.linspace(0, len(joints) - 1, 6).astype(int), layout="row")))
gif = viz.animate(joints, "humanml3d", OUT / "quickstart.gif", size=(240, 240), stride=2)
viz.show_animation(gif)'''),
    ("md", "Cross-attention of every word: rows are the 7 body parts, columns the motion frames (paper Fig. 6 layout)."),
    ("code", '''maps = out.attention
words = [w for w in dict.fromkeys(maps.words(0)) if w not in {"a", "is", "his", "up"}]
viz.plot_attention_grid(maps.cross_map(0), maps.tokens(0), word_ids=words, prompt=out.texts[0])'''),
    ("md", "One edit: mirror the arms (swap the left-arm and right-arm rows of the maps while sampling from the same noise)."),
    ("code", '''from salad_core.attention import Mirror
edit = pipe.edit(PROMPT, edits=[Mirror(parts="arms")], lengths=LENGTH, seed=SEED, num_steps=STEPS)
src, dst = edit.source.joints[0], edit.edited.joints[0]
print("edit cost vs one generation:", edit.settings.get("cost_vs_generation"))
gif = viz.animate([src, dst], "humanml3d", OUT / "quickstart_mirror.gif", layout="side",
                  titles=["source", "mirrored arms"], size=(220, 220), stride=2)
viz.show_animation(gif)'''),
    ("md", """Export for animation tools: BVH (Blender: rotations solved from the joints), GLB (one frame as a 3D
scene) and NPY (the joints, HumanML3D's `new_joints` format). `salad export MOTION.npy --format bvh|glb|npy`
does the same from the command line."""),
    ("code", '''bvh = viz.export_bvh(joints, "humanml3d", OUT / "quickstart.bvh")
glb = viz.export_glb(joints, "humanml3d", OUT / "quickstart.glb", frame=len(joints) // 2)
npy = viz.export_npy(joints, "humanml3d", OUT / "quickstart_joints.npy")
for path in (bvh, glb, npy):
    print(f"{path.name}: {path.stat().st_size:,} bytes")
print(bvh.read_text().splitlines()[0:3])
print("NPY round trip exact:", np.array_equal(np.load(npy), joints.astype(np.float32)))'''),
]

NOTEBOOKS["01_attention_maps"] = [
    ("md", """# Paper Fig. 6 and supplement Fig. 3: per-word cross-attention maps

For each prompt, the 7-part x frame cross-attention of its words, averaged over the 50 denoising steps,
the 5 layers and the heads. Beside each action phrase: the share of its attention on the body parts the
corpus grammar says it drives, against chance (the parts' share of the rows). The procedural corpus's
language parser maps each prompt to its phrases and parts; frames are not known for a generated motion, so
the score here is over body parts only (`scripts/measure_editing.py` scores parts x frames on the corpus's
ground truth). A phrase that drives all seven parts (e.g. "jumps") has share = chance = 1, which says
nothing: the table marks it "not scored"."""),
    ("code", SETUP + '''
PROMPTS = [
    "a man jumps forward and then walks forward, while waving his arms",
    "a man is walking while raising his left hand up high",
    "a man sits on the ground",
    "the person stretches their arms forward",
] if QUICK else [
    "a man jumps forward and then walks forward, while waving his arms",
    "a man is walking while raising his left hand up high",
    "a man sits on the ground",
    "the person stretches their arms forward",
    "a person puts both hands in the air",
    "a man is jumping high",
]
LENGTH, STEPS, SEED = 120, 50, 0'''),
    ("code", '''import pandas as pd
from IPython.display import display
from salad_core.pipeline import SaladPipeline
from salad_core.attention.measure import localisation
from salad_core.data.procedural import parse_prompt
import salad_viz as viz

pipe = SaladPipeline.from_pretrained()
out = pipe(PROMPTS, lengths=LENGTH, seed=SEED, num_steps=STEPS, capture_attention=True)'''),
    ("code", '''rows = []
for b, prompt in enumerate(out.texts):
    maps = out.attention
    phrases = parse_prompt(prompt) or []
    for ph in phrases:
        span = tuple(ph.words)
        m = maps.word_map(b, span)
        score = localisation(m, ph.parts, (0, out.lengths[b]))
        # a phrase driving all 7 parts has share = chance = 1: nothing to localise, so no score
        scored = score["part_chance"] < 1.0
        rows.append(dict(prompt=prompt, phrase=ph.text, parts=", ".join(ph.parts),
                         part_share=round(score["part_share"], 3) if scored else None,
                         chance=round(score["part_chance"], 3) if scored else None,
                         lift=round(score["part_share"] / score["part_chance"], 2) if scored else None,
                         note="" if scored else "all 7 parts: not scored"))
    fig = viz.plot_attention_grid(maps.cross_map(b), maps.tokens(b),
                                  word_ids=[" ".join(maps.words(b)[i] for i in range(*ph.words)) for ph in phrases] or None,
                                  prompt=prompt)
    display(fig)
with pd.option_context("display.max_colwidth", None, "display.width", 250):     # full prompts and parts
    display(pd.DataFrame(rows))'''),
]

NOTEBOOKS["02_editing"] = [
    ("md", """# Paper Fig. 7: zero-shot editing by attention modulation

Word swap, prompt refinement, re-weighting (including negative weights on "high") and mirroring, each
with the source beside the edit (same initial noise), and editing a motion the model did not generate
through inversion."""),
    ("code", SETUP + '''
LENGTH, STEPS, SEED = 100, (30 if QUICK else 50), 0'''),
    ("code", '''import numpy as np
from IPython.display import display
from salad_core.pipeline import SaladPipeline
from salad_core.attention import WordSwap, Refine, Reweight, Mirror
from salad_core.attention.measure import wrist_height, left_right_ratio
from salad_core.motion import bone_lengths
import salad_viz as viz

pipe = SaladPipeline.from_pretrained()
def show(edit, name, titles):
    gif = viz.animate([edit.source.joints[0], edit.edited.joints[0]], "humanml3d", OUT / f"{name}.gif",
                      layout="side", titles=titles, size=(200, 200), stride=2)
    display(viz.show_animation(gif))'''),
    ("md", "**Word swap** (tau = 0.8: the source maps for the first 20% of the steps)."),
    ("code", '''e = pipe.edit("a man walks forward", "a man runs forward", edits=[WordSwap(tau=0.8)],
              lengths=LENGTH, seed=SEED, num_steps=STEPS)
show(e, "swap", ["walks", "runs"])'''),
    ("md", "**Prompt refinement**: aligned tokens keep the source maps, new words their own."),
    ("code", '''e = pipe.edit("a man walks forward", "a man walks forward while waving his right hand", edits=[Refine()],
              lengths=LENGTH, seed=SEED, num_steps=STEPS)
show(e, "refine", ["source", "+ waving his right hand"])'''),
    ("md", """**Re-weighting** the word *high* (s from -1 to 3): the wrist height (above the floor, metres) follows s.
With the shipped weights it overshoots: above about 2.2 m the wrist gets higher by stretching the arm, because
the generated joint positions do not hold bone lengths (the model card measures this drift)."""),
    ("code", '''heights = {}
for s in ([-1.0, 1.0, 3.0] if QUICK else [-2.0, -1.0, 0.0, 1.0, 2.0, 3.0]):
    e = pipe.edit("a man raises his right hand high", edits=[Reweight(words="high", scale=s)],
                  lengths=LENGTH, seed=SEED, num_steps=STEPS)
    heights[s] = float(np.max(wrist_height(e.edited.joints[0], side="right")))
print("wrist height (m) per s:", {k: round(v, 2) for k, v in heights.items()})
print("right upper-arm length (m) at the largest s:", round(float(np.median(bone_lengths(e.edited.joints[0])[:, 19])), 2),
      "(the skeleton's:", round(pipe.skeleton.bone_lengths[19], 2), ")")'''),
    ("md", "**Mirroring** the legs and arms rows: the left/right activity ratio flips."),
    ("code", '''e = pipe.edit("a person kicks with the left leg", edits=[Mirror(parts="all")], lengths=LENGTH, seed=SEED,
              num_steps=STEPS)
print("source", left_right_ratio(e.source.joints[0]), "\\nedited", left_right_ratio(e.edited.joints[0]))
show(e, "mirror", ["source", "mirrored"])'''),
    ("md", """**Editing a given motion** (supplement B) takes a held-out test motion of the procedural corpus, one the
model never saw in training, and inverts it to noise under its own caption (`pipe.invert`: DDIM inversion
with fixed-point refinement, which stays faithful under guidance; `exact=True`, the default, also stores the
small per-step corrections, so that regenerating reproduces the motion up to the VAE's own error). Regenerating
from that noise reconstructs the motion. Without `exact` (`exact=False`), at few steps the shipped model can lose what it
generates badly: for the motion below (arms waved over the head) the plain fixed-point reconstruction at 20
steps keeps the arms down (9.7 cm MPJPE), the exact one keeps them up (1.1 cm). The printed errors separate two things:
- the VAE's own encode/decode error, the floor of any inversion;
- the inversion's own error.

The edit then starts from the same noise. Here it is mirroring, which swaps the left and right rows of the
attention maps. The exact corrections anchor the reconstruction, not the edited sample: with the shipped weights
the mirrored sample of this motion loses the arms over the head and its arms' left/right ratio does not flip
(compare the printed ratios), because the edit is regenerated by a model that generates that action badly."""),
    ("code", '''import tempfile
from salad_core.eval.report import heldout_corpus
from salad_core.motion import features_to_joints
root = heldout_corpus(Path(tempfile.mkdtemp()) / "heldout", motions=8)
def caption_of(name):
    return (root / "texts" / f"{name}.txt").read_text().splitlines()[0].split("#")[0]
names = (root / "test.txt").read_text().split()
name = next((n for n in names if " left " in f" {caption_of(n)} "), names[0])    # a one-sided action to mirror
feats = np.load(root / "new_joint_vecs" / f"{name}.npy")[:120]
caption = caption_of(name)
inv = pipe.invert(feats, caption, num_steps=STEPS, exact=True)
err = inv.errors
print(f"{name}: {caption!r}, {inv.lengths[0]} frames")
print(f"reconstruction MPJPE {100 * err['mpjpe']:.1f} cm root-aligned, {100 * err['mpjpe_global']:.1f} cm global; "
      f"VAE floor {100 * err['vae_mpjpe']:.1f} cm; the inversion's own error {100 * err['inversion_mpjpe']:.1f} cm")
e = pipe.edit(edits=[Mirror(parts="all")], inversion=inv)
given = features_to_joints(inv.features[0])
print("left/right activity, given:", left_right_ratio(given), "\\nmirrored:", left_right_ratio(e.edited.joints[0]))
gif = viz.animate([given, e.source.joints[0], e.edited.joints[0]], "humanml3d", OUT / "inverted_mirror.gif",
                  layout="side", titles=["given motion", "reconstruction", "mirrored"], size=(200, 200), stride=2)
viz.show_animation(gif)'''),
]

NOTEBOOKS["03_table1"] = [
    ("md", """# Paper Table 1: Real motion, SALAD and KeyMotion on the T2M protocol

R-precision (top 1/2/3), FID, MM-Dist, Diversity and MultiModality, each as mean ± 95% confidence half-width
over replications (`salad_core.eval.protocol`). Each replication goes through the test split in batches of
32. Each item has a random caption and a random crop whose length is a multiple of 4. Every generator is
asked for exactly those captions and lengths, and the real motions, the generated motions and the captions
are embedded with the evaluator.

**QUICK mode (the default, what CI runs).** It uses the shipped SALAD and KeyMotion weights, trained on
CPU on salad's procedural corpus, and the shipped procedural-corpus evaluator. It scores 64 held-out test
motions and their mirrors: clips that none of the three models saw in training. The run is **2
replications of 64 samples, 10 DDIM steps instead of 50, and no MultiModality**, because MultiModality
needs 100 prompts x 30 generations per replication.
- These numbers are **not** HumanML3D numbers and cannot be compared with the paper's.
- FID from 64 samples of a 128-d embedding is dominated by estimation bias. The real row's FID, measured
  against another pass over the split, shows that floor.
- The confidence intervals from 2 replications are rough.
- What the numbers can show: that the whole protocol runs end to end, and how the rows compare under
  the same settings.

SALAD runs through `LengthBucketed`, which denoises each batch in up to 3 groups of similar length instead
of padding every motion to the longest. The motions are the same, and it is about 2.5x faster on a CPU.

**FULL mode** (`SALAD_QUICK=0`) follows the paper's protocol: 20 replications of the whole test split,
MultiModality on (100 prompts x 30), 50 DDIM steps, w = 7.5. Two ways to run it:
- Set `CHECKPOINTS` (the official release's `checkpoints` folder: T2M evaluator, GloVe, SALAD weights,
  CLIP) and `DATA_ROOT` (HumanML3D or KIT-ML). This reproduces the paper's rows with the official
  weights. The KeyMotion row appears only if `KEYMOTION_WEIGHTS` points to a KeyMotion trained on that
  dataset.
- Leave both unset. This runs the protocol on the procedural corpus with the shipped models. The full
  protocol takes days on a CPU.

The paper's numbers are shown afterwards in a separate table. They are copied from the paper and not
computed here."""),
    ("code", SETUP + '''
# QUICK settings: measured to keep this notebook under 2 minutes on a 2-core CPU
QUICK_SETTINGS = dict(replications=2, max_samples=64, num_steps=10, mm=False)
HELDOUT_MOTIONS = 64          # QUICK: held-out procedural test motions (x2 with mirrors)
# FULL mode only (SALAD_QUICK=0); environment variables or edit here
DATA_ROOT = os.environ.get("SALAD_DATA")                  # HumanML3D / KIT-ML root (new_joint_vecs/, texts/, test.txt)
CHECKPOINTS = os.environ.get("SALAD_CHECKPOINTS")         # official 'checkpoints' folder (evaluator, GloVe, SALAD, CLIP)
DATASET = os.environ.get("SALAD_DATASET", "humanml3d")    # "humanml3d" or "kit"
SALAD_RUN = os.environ.get("SALAD_RUN", "t2m_denoiser_vpred_vaegelu")   # official denoiser run name
KEYMOTION_WEIGHTS = os.environ.get("SALAD_KEYMOTION")     # KeyMotion folder (None: the shipped weights)'''),
    ("code", '''import time
from IPython.display import Markdown, display
from salad_core.eval import EvalSettings, evaluate_generator, evaluate_real, results_frame, to_markdown
from salad_core.eval.report import LengthBucketed, evaluation_data, official_salad_pipeline, paper_table1
from salad_core.keymotion import KeyMotionPipeline
from salad_core.pipeline import SaladPipeline

settings = EvalSettings.quick_mode(**QUICK_SETTINGS) if QUICK else EvalSettings()
data, evaluator = evaluation_data(QUICK, OUT, data_root=DATA_ROOT, checkpoints=CHECKPOINTS, dataset=DATASET,
                                  heldout_motions=HELDOUT_MOTIONS)
generators = {}
if not QUICK and CHECKPOINTS:          # the paper's setting: real data, official evaluator and weights
    generators["SALAD (official weights)"] = (LengthBucketed(official_salad_pipeline(CHECKPOINTS, DATASET, SALAD_RUN)),
                                              "official")
    if KEYMOTION_WEIGHTS:
        generators["KeyMotion"] = (KeyMotionPipeline.from_pretrained(KEYMOTION_WEIGHTS), KEYMOTION_WEIGHTS)
    else:
        print("KeyMotion row left out: the shipped KeyMotion is trained on the procedural corpus; set KEYMOTION_WEIGHTS")
else:                                  # the procedural corpus with the shipped models
    generators["SALAD"] = (LengthBucketed(SaladPipeline.from_pretrained()), "shipped (procedural corpus)")
    generators["KeyMotion"] = (KeyMotionPipeline.from_pretrained(KEYMOTION_WEIGHTS),
                               KEYMOTION_WEIGHTS or "shipped (procedural corpus)")
print(settings.describe())
print("data:", data)'''),
    ("code", '''results = [evaluate_real(data, evaluator, settings)]
for name, (gen, weights) in generators.items():
    t0 = time.perf_counter()
    results.append(evaluate_generator(gen, data, evaluator, settings, name=name, weights=weights))
    print(f"{name}: {time.perf_counter() - t0:.0f} s")
table = results_frame(results)
display(Markdown(to_markdown(table)))'''),
    ("md", """## The paper's numbers (copied from SALAD, CVPR 2025, Table 1, not computed here)

HumanML3D test set (KIT-ML when `DATASET = "kit"`), official T2M evaluator, 20 replications. The KeyMotion
paper reports its own table in another protocol variant, but the numbers are missing from our copy of that
paper, so no KeyMotion reference row is shown."""),
    ("code", '''display(Markdown(to_markdown(paper_table1(DATASET))))'''),
    ("md", "The same results as a DataFrame (per-row settings included), for export with `to_latex` or `to_csv`."),
    ("code", '''table.to_csv(OUT / "table1.csv", index=False)
table[["name", "R-precision top-3", "R-precision top-3 ±", "FID", "FID ±", "MM-Dist", "Diversity", "samples", "num_steps"]]'''),
]

NOTEBOOKS["04_cfg_sweep"] = [
    ("md", """# Paper Fig. 5 and supplement Table 1: FID and R-precision against the CFG weight w

Classifier-free guidance mixes the conditional and unconditional predictions,
`eps = eps_uncond + w (eps_cond - eps_uncond)`. SALAD's Fig. 5 shows the trade-off: a larger w aligns the
motion with the text better (R-precision rises, then plateaus), and beyond about w = 7.5 FID worsens as the
motions leave the data distribution. Each w is evaluated with the T2M protocol (`salad_core.eval.cfg_sweep`)
on the same real batches.

**QUICK mode (the default, what CI runs).** It uses the shipped SALAD weights (procedural corpus) and the
shipped procedural-corpus evaluator, on 64 held-out test motions and their mirrors. The run covers **4
values of w, 2 replications of 64 samples each, 4 DDIM steps**, so that it fits in 2 minutes of CPU.
- FID from 64 samples is dominated by estimation bias, and 2 replications give rough intervals.
- The curve shows the direction of the effect, not its size, and nothing here is comparable with the
  paper.

SALAD runs through `LengthBucketed`, which groups each batch by length. The motions are the same, and
it is faster.

**FULL mode** (`SALAD_QUICK=0`) sweeps w = 1.5, 2.5, ..., 12.5 with the paper's protocol: 20
replications, the whole split, 50 DDIM steps. It uses the official weights and evaluator when
`CHECKPOINTS` and `DATA_ROOT` are set. The paper's curve is plotted separately and labelled "paper"."""),
    ("code", SETUP + '''
# QUICK settings: measured to keep this notebook under 2 minutes on a 2-core CPU
QUICK_SCALES = [1.5, 4.5, 7.5, 10.5]
QUICK_SETTINGS = dict(replications=2, max_samples=64, num_steps=4, mm=False)
HELDOUT_MOTIONS = 64
# FULL mode only (SALAD_QUICK=0)
DATA_ROOT = os.environ.get("SALAD_DATA")                  # HumanML3D / KIT-ML root
CHECKPOINTS = os.environ.get("SALAD_CHECKPOINTS")         # official 'checkpoints' folder
DATASET = os.environ.get("SALAD_DATASET", "humanml3d")
SALAD_RUN = os.environ.get("SALAD_RUN", "t2m_denoiser_vpred_vaegelu")'''),
    ("code", '''from IPython.display import Markdown, display
from salad_core.eval import DEFAULT_CFG_SCALES, EvalSettings, cfg_sweep, paper_cfg_sweep, plot_cfg_sweep
from salad_core.eval import results_frame, to_markdown
from salad_core.eval.report import LengthBucketed, evaluation_data, official_salad_pipeline
from salad_core.pipeline import SaladPipeline

settings = EvalSettings.quick_mode(**QUICK_SETTINGS) if QUICK else EvalSettings(mm=False)
scales = QUICK_SCALES if QUICK else list(DEFAULT_CFG_SCALES)
data, evaluator = evaluation_data(QUICK, OUT, data_root=DATA_ROOT, checkpoints=CHECKPOINTS, dataset=DATASET,
                                  heldout_motions=HELDOUT_MOTIONS)
if not QUICK and CHECKPOINTS:
    pipe, weights = LengthBucketed(official_salad_pipeline(CHECKPOINTS, DATASET, SALAD_RUN)), "official"
else:
    pipe, weights = LengthBucketed(SaladPipeline.from_pretrained()), "shipped (procedural corpus)"
print(settings.describe(), "\\nw:", scales)'''),
    ("code", '''results = cfg_sweep(pipe, data, evaluator, settings, scales=scales, name="SALAD", weights=weights)
sweep = results_frame(results)
sweep.to_csv(OUT / "cfg_sweep.csv", index=False)
fig = plot_cfg_sweep(sweep)
fig.savefig(OUT / "cfg_sweep.png", dpi=110)
display(fig)
display(Markdown(to_markdown(sweep)))'''),
    ("md", """## The paper's curve (SALAD supplement Table 1, HumanML3D, official evaluator; copied, not computed)

Plotted on its own axes: its FID and R-precision come from the official evaluator on HumanML3D and do not
share a scale with the numbers above."""),
    ("code", '''paper = paper_cfg_sweep(DATASET)
paper.loc[paper["name"] == "paper: Real motion", "kind"] = "real"     # draw the paper's real row as the dashed line
fig = plot_cfg_sweep(paper)
fig.suptitle(f"paper: SALAD supplement Table 1 ({DATASET}), published numbers")
display(fig)
display(Markdown(to_markdown(paper_cfg_sweep(DATASET))))'''),
]

NOTEBOOKS["05_keymotion_keyframes"] = [
    ("md", """# KeyMotion: keyframe selection, keyframe reconstruction, generation and in-filling

KeyMotion (Geng et al.) generates the keyframes of a motion first and then fills in the frames between them:

1. **Keyframe selection** (§III-A) has three methods:
   - Maximum-Distance-Optimal (MDO) keyframes maximise the summed feature distance between consecutive
     keyframes. They are found by exact dynamic programming and are the ones the models are trained on.
   - Minimum-Interpolation-Error-Optimal (MIEO) keyframes minimise the error of linear interpolation.
   - Uniform spacing is the baseline.
2. **Keyframe VAE** (§III-B) compresses the K keyframes and their positions into a small latent
   (Lz x Dz).
3. **PST denoiser** (§III-C) generates that latent from text.
4. **MMAE** (§III-D) in-fills the whole motion from the decoded keyframes, conditioned on the text.

Everything below runs on a held-out test motion of salad's procedural corpus, with the shipped KeyMotion
weights. They are trained on CPU on that corpus (not on HumanML3D), so the errors are those of a small model
on synthetic data."""),
    ("code", SETUP + '''
K = 12                                        # keyframes for the selection comparison
PROMPT = "a person walks forward and then waves his right hand"
LENGTH, STEPS, SEED = 120, 50, 0              # generation: frames, DDIM steps, noise seed
KEYMOTION_WEIGHTS = os.environ.get("SALAD_KEYMOTION")   # a KeyMotion folder; None: the shipped weights'''),
    ("code", '''import tempfile
import numpy as np
import matplotlib.figure
import torch
from IPython.display import display
from PIL import Image
from salad_core.eval.report import heldout_corpus, infill_from_keyframes, keyframe_roundtrip
from salad_core.keymotion import KeyMotionPipeline, interpolation_errors, select_keyframes
from salad_core.motion import features_to_joints
import salad_viz as viz

km = KeyMotionPipeline.from_pretrained(KEYMOTION_WEIGHTS)
print(f"KeyMotion: {km.num_keyframes} keyframes per motion, latent {km.kf_vae.latent_shape}, up to {km.max_length} frames")
root = heldout_corpus(Path(tempfile.mkdtemp()) / "heldout", motions=16)
names = [n for n in (root / "test.txt").read_text().split()
         if len(np.load(root / "new_joint_vecs" / f"{n}.npy")) <= km.max_length]
name = max(names, key=lambda n: len(np.load(root / "new_joint_vecs" / f"{n}.npy")))   # the longest held-out clip
feats = np.load(root / "new_joint_vecs" / f"{name}.npy")
caption = (root / "texts" / f"{name}.txt").read_text().splitlines()[0].split("#")[0]
xn = km.mmae.norm.normalize(torch.from_numpy(feats)).numpy()   # selection runs on normalised features, as in training
print(name, repr(caption), feats.shape)'''),
    ("md", """## Keyframe selection

The grey curve is how much the normalised features change per frame. The dots mark where each method puts
its keyframes. MDO spends its keyframes where the motion changes most, while uniform spacing ignores the
content."""),
    ("code", '''fig = matplotlib.figure.Figure(figsize=(9, 3), layout="constrained")
ax = fig.subplots()
speed = np.linalg.norm(np.diff(xn, axis=0), axis=1)
ax.plot(speed, color="0.6", label="feature change per frame")
rows = []
for i, method in enumerate(["uniform", "mieo", "mdo"]):
    idx = select_keyframes(xn, K, method)
    ax.scatter(idx, np.full(K, -0.1 - 0.1 * i) * speed.max(), label=method, s=18)
    err = interpolation_errors(xn)[idx[:-1], idx[1:]].sum()
    dist = np.linalg.norm(np.diff(xn[idx], axis=0), axis=1)
    rows.append((method, idx.tolist(), round(float(err), 1), round(float(dist.sum()), 2), round(float(dist.min()), 3)))
ax.legend(loc="upper right", fontsize=8); ax.set_xlabel("frame"); ax.set_yticks([])
display(fig)
for r in rows:
    print(f"{r[0]:8s} interp. error {r[2]:>8}  summed distance {r[3]:>7}  closest pair {r[4]:>6}  {r[1]}")'''),
    ("code", '''joints = features_to_joints(feats)
for method in ["uniform", "mdo"]:
    print(method)
    display(Image.fromarray(viz.keyframe_strip(joints, "humanml3d", select_keyframes(xn, 6, method), layout="row")))'''),
    ("md", """## Keyframe reconstruction (keyframe VAE)

The motion's own MDO keyframes go through the keyframe VAE: they are encoded, the posterior mean is taken,
and the result is decoded. Each decoded pose is compared with the pose it came from (root-aligned MPJPE of
each pose taken alone), and each decoded position with its frame. In the strip below, the selected pose and
its reconstruction are drawn on top of each other."""),
    ("code", '''rt = keyframe_roundtrip(km, feats)
print(f"keyframe pose MPJPE {100 * rt.pose_mpjpe:.1f} cm; mean keyframe frame error {rt.index_error:.1f} frames")
print("selected frames:", rt.indices.tolist())
print("decoded frames: ", rt.decoded_indices.tolist())
show = np.linspace(0, km.num_keyframes - 1, 6).round().astype(int)
display(Image.fromarray(viz.keyframe_strip([rt.joints, rt.decoded_joints], "humanml3d", show, layout="row",
                                           labels=False, colors=["tab:gray", "tab:orange"],
                                           title="selected keyframes (grey) and their keyframe-VAE reconstruction (orange)")))'''),
    ("md", """This long motion is only one sample. The same round trip over every held-out clip of the folder puts its
errors in context (the KeyMotion model card reports the mean over 300 test clips)."""),
    ("code", '''trips = {n: keyframe_roundtrip(km, np.load(root / "new_joint_vecs" / f"{n}.npy")) for n in names}
frame_err = np.array([t.index_error for t in trips.values()])
pose_err = 100 * np.array([t.pose_mpjpe for t in trips.values()])
print(f"{len(trips)} held-out clips: frame error mean {frame_err.mean():.1f}, median {np.median(frame_err):.1f}, "
      f"max {frame_err.max():.1f} frames; pose MPJPE mean {pose_err.mean():.1f} cm")
print(f"this notebook's motion {name}: {trips[name].index_error:.1f} frames, "
      f"rank {int((frame_err < trips[name].index_error).sum()) + 1} of {len(trips)} from the best")'''),
    ("md", """## In-filling from ground-truth keyframes (MMAE)

The MMAE gets the true keyframes at their true frames, plus the caption, and predicts every frame. The
floor it has to beat is per-channel linear interpolation of the same keyframes. The errors are MPJPE
against the given motion: root-aligned (pose), and global (which also counts the drift of the root
trajectory)."""),
    ("code", '''inf = infill_from_keyframes(km, feats, caption)
print(f"MMAE in-filling: MPJPE {100 * inf.mpjpe:.1f} cm root-aligned, {100 * inf.mpjpe_global:.1f} cm global")
print(f"linear interpolation: MPJPE {100 * inf.lerp_mpjpe:.1f} cm root-aligned, {100 * inf.lerp_mpjpe_global:.1f} cm global")
gif = viz.animate([inf.true_joints, inf.joints, inf.lerp_joints], "humanml3d", OUT / "keymotion_infill.gif",
                  layout="side", titles=["given motion", "MMAE in-filled", "linear interpolation"],
                  size=(200, 200), stride=2)
viz.show_animation(gif)'''),
    ("md", """## Generation from text

The PST denoises the keyframe latent under the prompt (classifier-free guidance, w = 7.5). The keyframe
VAE decodes the latent into keyframes and their frames, and the MMAE fills in the motion. The strip shows
the generated motion at some of its generated keyframes."""),
    ("code", '''out = km(PROMPT, lengths=LENGTH, seed=SEED, num_steps=STEPS)
kf = out.keyframes[0]
print(PROMPT, "->", out.joints[0].shape, "keyframes at", kf.tolist())
shown = kf[np.linspace(0, len(kf) - 1, 6).round().astype(int)]            # 6 of the generated keyframes
display(Image.fromarray(viz.keyframe_strip(out.joints[0], "humanml3d", shown, layout="row")))
gif = viz.animate(out.joints[0], "humanml3d", OUT / "keymotion_generated.gif", size=(240, 240), stride=2)
viz.show_animation(gif)'''),
]

NOTEBOOKS["06_table2_vae"] = [
    ("md", """# Paper Table 2 and supplement Table 4: the skeleton-aware VAE against a pose-vector VAE, and the VAE's loss terms

SALAD compresses a motion into a skeleto-temporal latent: one 32-d code per body part (7) and per 4 frames.
Table 2 of the paper compares this VAE with VAEs that treat each pose as one vector (MoMask) or each body
part on its own (ParCo). Supplement Table 4 removes the auxiliary losses `L_pos` (joint positions) and
`L_vel` (velocities). Both tables report two numbers, lower is better for both:
- **FID**: how far the evaluator embeddings of the reconstructions lie from those of the real clips;
- **MPJPE**: the root-aligned joint position error of the reconstructions.

Both come from `salad_core.eval.reconstruction`, computed as the official `test_vae` does. Each
replication reconstructs the same random crops that the generation protocol uses.

**QUICK mode (the default, what CI runs).** The VAEs come from the shipped ablation study
(`configs/ablations.json`, trained by `scripts/train_ablations.py` on salad's procedural corpus, one CPU
core each). They are scored on 64 held-out test motions and their mirrors, with the shipped
procedural-corpus evaluator, in 2 replications of 64 clips.
- Table 2's pair (skeleton-aware and pose-vector) is trained for 1,500 steps each. The loss-term variants
  are trained for 400 steps each, so they compare with each other, not with the Table 2 rows.
- The shipped SALAD VAE (3,000 steps, the one the generator uses) is shown as a reference row.
- Our pose-vector VAE is salad's `kind="pose"` VAE: the same joint MLPs and temporal convolutions as the
  skeleton-aware one, with the pose flattened into one vector per 4 frames. It is not MoMask's VQ-VAE or
  ParCo's part-wise VQ-VAE, which salad does not implement.
- None of these numbers are HumanML3D numbers.

**FULL mode** (`SALAD_QUICK=0`) runs 20 replications over the whole test split. With `CHECKPOINTS` and
`DATA_ROOT` set, it scores the official SALAD VAE with the official evaluator on HumanML3D or KIT-ML. To
score ablation VAEs trained on that dataset as well, set `ABLATIONS` to the folder written by
`scripts/train_ablations.py --data DATA_ROOT --ship ABLATIONS`.

The paper's numbers are shown separately and labelled as the paper's. They are copied, not computed."""),
    ("code", SETUP + '''
QUICK_SETTINGS = dict(replications=2, max_samples=64)   # QUICK: 2 replications of 64 clips
HELDOUT_MOTIONS = 64                                     # QUICK: held-out procedural test motions (x2 with mirrors)
# FULL mode only (SALAD_QUICK=0); environment variables or edit here
DATA_ROOT = os.environ.get("SALAD_DATA")                 # HumanML3D / KIT-ML root
CHECKPOINTS = os.environ.get("SALAD_CHECKPOINTS")        # official 'checkpoints' folder (evaluator, SALAD VAE)
DATASET = os.environ.get("SALAD_DATASET", "humanml3d")
SALAD_RUN = os.environ.get("SALAD_RUN", "t2m_denoiser_vpred_vaegelu")
ABLATIONS = os.environ.get("SALAD_ABLATIONS")            # shipped ablation folder (None: salad's own)'''),
    ("code", '''from IPython.display import Markdown, display
from salad_core.ablations import list_ablations, load_ablation_vae
from salad_core.eval import EvalSettings
from salad_core.eval.reconstruction import (evaluate_reconstruction, paper_vae_tables, reconstruction_frame,
                                            reconstruction_markdown)
from salad_core.eval.report import evaluation_data, official_salad_pipeline
from salad_core.pipeline import SaladPipeline

settings = EvalSettings.quick_mode(**QUICK_SETTINGS) if QUICK else EvalSettings(mm=False)
data, evaluator = evaluation_data(QUICK, OUT, data_root=DATA_ROOT, checkpoints=CHECKPOINTS, dataset=DATASET,
                                  heldout_motions=HELDOUT_MOTIONS)
if not QUICK and CHECKPOINTS:          # the paper's setting: real data, official evaluator and VAE
    reference = official_salad_pipeline(CHECKPOINTS, DATASET, SALAD_RUN)
    reference_name = "SALAD VAE (official weights)"
else:                                  # the procedural corpus with the shipped models
    reference = SaladPipeline.from_pretrained()
    reference_name = "shipped SALAD VAE, 3,000 steps"
# salad's own ablation models are trained on the procedural corpus: used with it, or when asked for
index = list_ablations(ABLATIONS) if (ABLATIONS or not CHECKPOINTS) else {}
vae_rows = {k[len("vae_"):]: v for k, v in index.items() if v["kind"] == "vae"}
print(f"{'QUICK MODE' if QUICK else 'full protocol'}: {settings.replications} replications of "
      f"{settings.max_samples or 'all'} {settings.split} clips (batches of {settings.batch_size}), seed {settings.seed}")
print("data:", data)
print("ablation VAEs:", {k: f"{v['label']}, {v['steps']} steps" for k, v in vae_rows.items()})

loaded = {}                            # row name -> (vae, mean, std), for the figures below

def score(variant):
    """Reconstruction FID / MPJPE of one shipped ablation VAE, labelled with its training steps."""
    entry = vae_rows[variant]
    name = f"{entry['label']}, {entry['steps']} steps"
    loaded[name] = load_ablation_vae(variant, ABLATIONS)
    return evaluate_reconstruction(*loaded[name], data, evaluator, settings, weights=f"vae_{variant}", name=name)'''),
    ("md", """## Table 2: skeleton-aware against pose-vector latent

Both VAEs have the same training steps, batch, learning rate and loss. `Params` counts the learnable
weights. The skeleton-aware VAE's fixed graph matrices are structure, not weights, and are not counted."""),
    ("code", '''table2 = [score(v) for v in ("st_long", "pose_long") if v in vae_rows]
table2.append(evaluate_reconstruction(reference.vae, reference.mean, reference.std, data, evaluator, settings,
                                      name=reference_name))
display(Markdown(reconstruction_markdown(reconstruction_frame(table2))))
display(Markdown("**Published (SALAD, CVPR 2025, Table 2, HumanML3D test set; copied, not computed here):**\\n\\n"
                 + reconstruction_markdown(paper_vae_tables("table2"))))'''),
    ("md", """**What the QUICK numbers say** (shipped ablation weights, 2026-11-22): at an equal budget of 1,500
steps, our pose-vector VAE reconstructs *better* than the skeleton-aware one (FID 0.007 against 0.027,
MPJPE 1.7 cm against 2.6 cm), with 17 times the parameters (2.73M against 0.16M). So the paper's Table 2
ordering is not reproduced against a continuous pose-vector VAE of the same design. The paper compared
against vector-quantised VAEs (MoMask, ParCo), whose quantisation costs accuracy; salad has no VQ-VAE to
repeat that comparison. The skeleton-aware VAE's advantage is its size: it gets within 1 cm of the
pose-vector VAE with 6 % of the weights. Whether the ST latent is the better space *to generate in* is
Table 3's question (notebook 07), not this table's."""),
    ("md", """Where the error sits: the root-aligned error of each body part over the first replication's clips,
for each VAE of the table above."""),
    ("code", '''import matplotlib.figure
import numpy as np
from salad_core.eval.protocol import real_batches
from salad_core.eval.reconstruction import part_errors, reconstruct_features
from salad_core.motion import features_to_joints

vaes = {r.name: loaded[r.name] for r in table2[:-1]}
vaes[reference_name] = (reference.vae, reference.mean, reference.std)
per_part = {}
for name, (vae, mean, std) in vaes.items():
    pred, gt = [], []
    for b in real_batches(data, settings, 0):
        rec = reconstruct_features(vae, mean, std, b.motions, b.lengths)
        for k, n in enumerate(b.lengths):
            pred.append(features_to_joints(rec[k, :n])); gt.append(features_to_joints(b.motions[k, :n]))
    per_part[name] = part_errors(np.concatenate(pred), np.concatenate(gt))
parts = list(next(iter(per_part.values())))
fig = matplotlib.figure.Figure(figsize=(8, 3.2))
ax = fig.subplots()
width = 0.8 / len(per_part)
for i, (name, errs) in enumerate(per_part.items()):
    ax.bar(np.arange(len(parts)) + i * width, [100 * errs[p] for p in parts], width, label=name)
ax.set_xticks(np.arange(len(parts)) + 0.4 - width / 2, parts)
ax.set_ylabel("root-aligned error (cm)"); ax.legend(fontsize=8); ax.grid(axis="y", alpha=0.3)
display(fig)'''),
    ("md", """## Supplement Table 4: the VAE's auxiliary losses

The full loss is the feature reconstruction plus `L_pos` (joint positions recovered from the features) and
`L_vel` (their velocities), plus the KL term. Each variant drops one or both and trains with the same
400-step budget."""),
    ("code", '''table4 = [score(v) for v in ("st", "no_pos", "no_vel", "no_pos_vel") if v in vae_rows]
if table4:
    display(Markdown(reconstruction_markdown(reconstruction_frame(table4))))
else:
    print("no loss-term ablation VAEs here; train them with scripts/train_ablations.py")
display(Markdown("**Published (SALAD, CVPR 2025, supplement Table 4, HumanML3D; copied, not computed here):**\\n\\n"
                 + reconstruction_markdown(paper_vae_tables("supp_table4"))))'''),
    ("md", """**What the QUICK numbers say** (shipped ablation weights, 2026-11-22): as in the paper, dropping
`L_pos` hurts both FID and MPJPE, and dropping both auxiliary losses gives by far the worst FID. Dropping
`L_vel` leaves FID about where it was (0.64 against 0.61) and MPJPE slightly lower (4.1 cm against
4.3 cm), where the paper saw FID worsen. At 400 steps these VAEs are far from converged, so only the large
effects are readable."""),
    ("md", "The same results as a DataFrame, for `to_csv` or LaTeX."),
    ("code", '''frame = reconstruction_frame(table2 + table4)
frame.to_csv(OUT / "table2_vae.csv", index=False)
frame[["name", "parameters", "FID", "FID ±", "MPJPE", "MPJPE ±", "samples", "replications"]]'''),
]

NOTEBOOKS["07_table3_denoiser_ablations"] = [
    ("md", """# Paper Table 3 and supplement Tables 2-3: what the denoiser's parts are worth

SALAD's denoiser works on the skeleto-temporal latent (ST-Latent), reads the text through cross-attention,
predicts v, and modulates every block with FiLM of the diffusion time. The paper removes each in turn:
- **Table 3** swaps the ST-Latent for a pose-vector latent ("w/o ST-Latent"). It also replaces the
  cross-attention with self-attention over the motion tokens plus one sentence feature ("w/o CrossAttn"),
  and drops both at once.
- **Supplement Table 2** trains with epsilon-, x- (sample) and v-prediction.
- **Supplement Table 3** replaces FiLM by adding the time embedding ("without FiLM").

Every variant is evaluated with the same T2M protocol (`salad_core.eval.run_ablation`): R-precision,
FID, MM-Dist and Diversity, each as mean ± 95% confidence half-width over replications.

**QUICK mode (the default, what CI runs).** The variants come from the shipped ablation study
(`configs/ablations.json`, trained by `scripts/train_ablations.py` on salad's procedural corpus).
- Every denoiser has the same small size (width 96, 3 layers) and the same budget of 700 steps. Each
  learns on the latents of one of notebook 06's Table 2 VAEs (1,500 steps each): the skeleton-aware VAE,
  or the pose-vector VAE for "w/o ST-Latent" and "w/o both".
- The shipped SALAD model (width 256, 3,600 steps) is not one of the rows. The rows compare only with
  each other.
- They are scored on 64 held-out test motions and their mirrors, with the shipped procedural-corpus
  evaluator, in 2 replications of 64 samples, 10 DDIM steps and w = 7.5.
- At this budget the models are far from converged. FID from 64 samples is dominated by estimation
  bias, and 2 replications give rough intervals. What these tables can show is a large effect, or the
  absence of one, not the paper's margins.

**FULL mode** (`SALAD_QUICK=0`) runs the paper's protocol: 20 replications of the whole test split, 50
steps, w = 7.5. To evaluate variants trained on HumanML3D or KIT-ML, set `DATA_ROOT`, `CHECKPOINTS` (the
official evaluator) and `ABLATIONS` (the folder written by
`scripts/train_ablations.py --data DATA_ROOT --ship ABLATIONS`).

The paper's numbers are shown separately and labelled as the paper's. They are copied, not computed."""),
    ("code", SETUP + '''
QUICK_SETTINGS = dict(replications=2, max_samples=64, num_steps=10, mm=False)
HELDOUT_MOTIONS = 64                                     # QUICK: held-out procedural test motions (x2 with mirrors)
# FULL mode only (SALAD_QUICK=0); environment variables or edit here
DATA_ROOT = os.environ.get("SALAD_DATA")                 # HumanML3D / KIT-ML root
CHECKPOINTS = os.environ.get("SALAD_CHECKPOINTS")        # official 'checkpoints' folder (evaluator)
DATASET = os.environ.get("SALAD_DATASET", "humanml3d")
ABLATIONS = os.environ.get("SALAD_ABLATIONS")            # shipped ablation folder (None: salad's own)'''),
    ("code", '''import time
from IPython.display import Markdown, display
from salad_core.ablations import list_ablations, load_ablation_pipeline
from salad_core.eval import EvalSettings, evaluate_generator, evaluate_real, results_frame, to_markdown
from salad_core.eval.report import LengthBucketed, evaluation_data, paper_denoiser_ablations
from salad_core.text import load_text_encoder

settings = EvalSettings.quick_mode(**QUICK_SETTINGS) if QUICK else EvalSettings()
if not QUICK and CHECKPOINTS and not ABLATIONS:
    raise ValueError("FULL mode with CHECKPOINTS needs ABLATIONS: variants trained on DATA_ROOT with "
                     "scripts/train_ablations.py --data DATA_ROOT --ship ABLATIONS")
data, evaluator = evaluation_data(QUICK, OUT, data_root=DATA_ROOT, checkpoints=CHECKPOINTS, dataset=DATASET,
                                  heldout_motions=HELDOUT_MOTIONS)
index = {k: v for k, v in list_ablations(ABLATIONS).items() if v["kind"] == "denoiser"}
text_encoder = load_text_encoder("minilm")            # one encoder shared by every variant
print(settings.describe())
print("data:", data)
for name, entry in index.items():
    print(f"  {name:9s} {entry['label']}: {entry['steps']} steps on {entry['vae']}")'''),
    ("md", """Every variant is evaluated once, on the same real batches, crops, captions and noise seeds. The three
tables below are cut from these results."""),
    ("code", '''results = {"real": evaluate_real(data, evaluator, settings)}
for name, entry in index.items():
    t0 = time.perf_counter()
    gen = LengthBucketed(load_ablation_pipeline(name, ABLATIONS, text_encoder=text_encoder))
    results[name] = evaluate_generator(gen, data, evaluator, settings, name=entry["label"], weights=f"ablation {name}")
    print(f"{name}: {time.perf_counter() - t0:.0f} s")

def table(names, which, dataset=DATASET):
    """Our rows (those shipped) and, apart, the paper's rows of the same table."""
    ours = results_frame([results["real"], *[results[n] for n in names if n in results]])
    return to_markdown(ours, reference=paper_denoiser_ablations(which, dataset))'''),
    ("md", "## Table 3: ST-Latent and cross-attention"),
    ("code", '''display(Markdown(table(["full", "no_st", "no_cross", "no_both"], "table3")))'''),
    ("md", """**What the QUICK numbers say** (shipped ablation weights, 2026-11-22): at 700 steps the paper's
ordering is **not** reproduced. Both models on the pose-vector latent ("w/o ST-Latent", "w/o both") are
ahead of the models on the ST latent (FID about 18 and 31 against 60 and 33). A pose-vector latent is 49
tokens of 224 channels, while the ST latent is 343 tokens of 32, and a small denoiser at 700 steps learns
the short sequence sooner. All four are far from the real row and from the shipped SALAD model (FID 0.5 on
the same clips in notebook 03, trained 3,600 steps at width 128). On the ST latent, removing
cross-attention does not hurt at this budget either (FID 33 against 60; R-precision equal within the
intervals). This table needs budgets closer to convergence before it can confirm or contradict the
paper. A first step, measured separately and not shipped (see the ablation model card): trained to 2,500
steps (`configs/ablations_table3_long.json`), the full denoiser catches up with "w/o ST-Latent"
(FID 4.6 +- 0.6 against 4.2 +- 0.4, R-precision top-3 0.94 against 0.93, 5 x 192 samples): the
700-step gap is the ST latent's slower start."""),
    ("md", "## Supplement Table 2: the diffusion parametrisation"),
    ("code", '''display(Markdown(table(["x0", "eps", "full"], "supp_table2")))'''),
    ("md", """**What the QUICK numbers say:** v-prediction gives the best FID, MM-Dist and R-precision of the
three, and epsilon-prediction the worst R-precision, as in the paper. Unlike the paper, x-prediction is
not level with v-prediction here (FID 88 against 60)."""),
    ("md", "## Supplement Table 3: FiLM"),
    ("code", '''display(Markdown(table(["full", "no_film"], "supp_table3")))'''),
    ("md", """**What the QUICK numbers say:** with FiLM the FID is lower (60 against 76) and MM-Dist too, in the
paper's direction; R-precision is equal within the intervals, where the paper saw a small gain."""),
    ("md", "All rows as one DataFrame, for `to_csv` or `to_latex`."),
    ("code", '''frame = results_frame(list(results.values()))
frame.to_csv(OUT / "table3_denoiser_ablations.csv", index=False)
frame[["name", "R-precision top-3", "R-precision top-3 ±", "FID", "FID ±", "MM-Dist", "Diversity", "weights"]]'''),
]

NOTEBOOKS["08_teaching_diffusion"] = [
    ("md", """# Teaching: the diffusion process step by step, what guidance does, attention over the steps, latent walks

The denoising loop (`salad_core.sampling.denoise`) starts from Gaussian noise in the skeleton-aware latent
space (frames/4 x 7 body parts x 32). It removes the noise over the DDIM steps, and the VAE can decode
any intermediate latent. Classifier-free guidance mixes the conditional and unconditional predictions with
weight w. The cross-attention maps show which words drive which body parts, and how that changes from the
first step to the last. Walking between two motions' latents shows what the latent space encodes."""),
    ("code", SETUP + '''
PROMPT = "a person jumps forward"
LENGTH, STEPS, SEED = 80, (20 if QUICK else 50), 1
WORD = "jumps"                 # the word whose attention map is followed over the steps'''),
    ("code", '''import numpy as np
import torch
from IPython.display import display
from PIL import Image
from salad_core.pipeline import SaladPipeline
from salad_core.sampling import denoise, make_scheduler
import salad_viz as viz

pipe = SaladPipeline.from_pretrained()
n_lat = LENGTH // 4
noise = pipe.make_noise([SEED], n_lat)
text, null = pipe.encode_text([PROMPT])
cond = pipe.denoiser.prepare_text(text.features, text.mask)
uncond = pipe.denoiser.prepare_text(null.features, null.mask)
snapshots = {}
def keep(info, z):
    if info.index in (0, STEPS // 4, STEPS // 2, STEPS - 1):
        snapshots[info.index] = z.clone()
z = denoise(pipe.denoiser, make_scheduler(pipe.diffusion), cond, uncond, noise, guidance_scale=7.5,
            num_steps=STEPS, callback=keep)
for i, zi in sorted(snapshots.items()):
    _, joints = pipe.decode(zi, [LENGTH])
    print(f"after step {i + 1}/{STEPS}")
    display(Image.fromarray(viz.keyframe_strip(joints[0], "humanml3d", np.linspace(0, LENGTH - 1, 5).astype(int), layout="row")))'''),
    ("md", "Guidance: the same noise at w = 1 (no guidance), 3 and 7.5. The jump height and the forward travel grow with w."),
    ("code", '''for w in [1.0, 3.0, 7.5]:
    out = pipe(PROMPT, lengths=LENGTH, seed=SEED, guidance_scale=w, num_steps=STEPS)
    j = out.joints[0]
    print(f"w={w}: max root height {j[:, 0, 1].max():.2f} m, forward travel {j[-1, 0, 2] - j[0, 0, 2]:.2f} m")'''),
    ("md", """## How attention evolves over the steps

The same generation, captured with every step, layer and head kept (`CaptureConfig(mode="full")`). Two
views:
- **One word's map (body parts x frames), averaged over windows of steps.** The early, high-noise steps
  decide the coarse motion. This is why attention edits such as the word swap replace the maps during the
  first steps (tau).
- **The share of cross-attention on each word, per step.** It is averaged over layers, heads, frames and
  body parts, and shows which words the model listens to at each stage.

What you see depends on the weights: with the shipped, briefly trained model the maps are less sharp than
the paper's Fig. 6."""),
    ("code", '''import matplotlib.figure
from salad_core.attention import CaptureConfig

out = pipe(PROMPT, lengths=LENGTH, seed=SEED, num_steps=STEPS, capture_attention=CaptureConfig(mode="full"))
maps = out.attention
full = maps.full(0)                                    # (steps, layers, heads, N', parts, tokens)
print("captured", full.shape, "tokens", maps.tokens(0))
display(viz.plot_attention_by_steps(full, maps.tokens(0), WORD, axes="slhnpw", step_ranges=4))
per_step = full.astype(np.float32).mean(axis=(1, 2, 3, 4))        # (steps, tokens)
fig = matplotlib.figure.Figure(figsize=(7, 3), layout="constrained")
ax = fig.subplots()
steps = np.arange(1, STEPS + 1)
for i, word in enumerate(maps.words(0)):
    ax.plot(steps, per_step[:, maps.word_columns(0, i)].sum(-1), marker=".", label=word)
special = [j for j, w in enumerate(maps.token_to_word(0)) if w is None]
ax.plot(steps, per_step[:, special].sum(-1), "--", color="0.5", label="special tokens")
ax.set_xlabel("denoising step (1 = pure noise)"); ax.set_ylabel("share of cross-attention")
ax.legend(fontsize=8, ncol=2); ax.grid(alpha=0.3)
display(fig)'''),
    ("md", """## A walk in the skeleton-aware latent space

Two held-out corpus motions are encoded by the VAE (posterior means, `frames/4 x 7 parts x 32`). Their
latents are mixed linearly, and each mix is decoded. The latent keeps one code per body part and time
step, so the in-betweens mix the two motions part by part and frame by frame. The printed distances
(root-aligned MPJPE, against each end's own decoding) show how far each in-between is from either end."""),
    ("code", '''import tempfile
from salad_core.eval.metrics import mpjpe
from salad_core.eval.report import heldout_corpus

root = heldout_corpus(Path(tempfile.mkdtemp()) / "heldout", motions=16)
def load(name):
    return np.load(root / "new_joint_vecs" / f"{name}.npy"), (root / "texts" / f"{name}.txt").read_text().split("#")[0]
names = (root / "test.txt").read_text().split()
a = next((n for n in names if "walk" in load(n)[1]), names[0])
b = next((n for n in names if "walk" not in load(n)[1] and n != a), names[1])
(fa, ca), (fb, cb) = load(a), load(b)
n = min(len(fa), len(fb), pipe.skeleton.max_length) // 4 * 4
za, zb = pipe.encode_motion(fa[:n]), pipe.encode_motion(fb[:n])    # (1, n/4, 7, 32) each
print(f"A: {ca!r}\\nB: {cb!r}\\n{n} frames")
_, ends = pipe.decode(torch.cat([za, zb]), [n, n])
for alpha in np.linspace(0.0, 1.0, 5):
    _, joints = pipe.decode((1 - alpha) * za + alpha * zb, [n])
    print(f"alpha = {alpha:.2f}: MPJPE to A {100 * mpjpe(joints[0], ends[0]):5.1f} cm, to B {100 * mpjpe(joints[0], ends[1]):5.1f} cm")
    display(Image.fromarray(viz.keyframe_strip(joints[0], "humanml3d", np.linspace(0, n - 1, 5).astype(int), layout="row",
                                               size=(160, 200), title=f"alpha = {alpha:.2f}")))'''),
]


def build(name: str, cells: list[tuple[str, str]]) -> None:
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [new_markdown_cell(src) if kind == "md" else new_code_cell(src) for kind, src in cells]
    for i, cell in enumerate(nb.cells):
        cell.id = f"cell-{i:02d}"       # stable ids: regenerating an unchanged notebook changes no byte
    nbformat.write(nb, HERE / f"{name}.ipynb")


if __name__ == "__main__":
    HERE.mkdir(exist_ok=True)
    for name, cells in NOTEBOOKS.items():
        build(name, cells)
        print("wrote", HERE / f"{name}.ipynb")
