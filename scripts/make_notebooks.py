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
    ("md", "Export for animation tools: BVH (Blender), GLB, NPY."),
    ("code", '''bvh = viz.export_bvh(joints, "humanml3d", OUT / "quickstart.bvh")
print(bvh, bvh.stat().st_size, "bytes")
print(bvh.read_text().splitlines()[0:3])'''),
]

NOTEBOOKS["01_attention_maps"] = [
    ("md", """# Paper Fig. 6 and supplement Fig. 3: per-word cross-attention maps

For each prompt, the 7-part x frame cross-attention of its words, averaged over the 50 denoising steps,
the 5 layers and the heads. Beside each action phrase: the share of its attention on the body parts the
corpus grammar says it drives, against chance (the parts' share of the rows). The procedural corpus's
language parser maps each prompt to its phrases and parts; frames are not known for a generated motion, so
the score here is over body parts only (`scripts/measure_editing.py` scores parts x frames on the corpus's
ground truth)."""),
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
        rows.append(dict(prompt=prompt, phrase=ph.text, parts=", ".join(ph.parts),
                         part_share=round(score["part_share"], 3), chance=round(score["part_chance"], 3),
                         lift=round(score["part_share"] / score["part_chance"], 2)))
    fig = viz.plot_attention_grid(maps.cross_map(b), maps.tokens(b),
                                  word_ids=[" ".join(maps.words(b)[i] for i in range(*ph.words)) for ph in phrases] or None,
                                  prompt=prompt)
    display(fig)
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
    ("md", "**Re-weighting** the word *high* (s from -1 to 3): the wrist height follows s."),
    ("code", '''heights = {}
for s in ([-1.0, 1.0, 3.0] if QUICK else [-2.0, -1.0, 0.0, 1.0, 2.0, 3.0]):
    e = pipe.edit("a man raises his right hand high", edits=[Reweight(words="high", scale=s)],
                  lengths=LENGTH, seed=SEED, num_steps=STEPS)
    heights[s] = float(np.max(wrist_height(e.edited.joints[0], side="right")))
print({k: round(v, 3) for k, v in heights.items()})'''),
    ("md", "**Mirroring** the legs and arms rows: the left/right activity ratio flips."),
    ("code", '''e = pipe.edit("a person kicks with the left leg", edits=[Mirror(parts="all")], lengths=LENGTH, seed=SEED,
              num_steps=STEPS)
print("source", left_right_ratio(e.source.joints[0]), "\\nedited", left_right_ratio(e.edited.joints[0]))
show(e, "mirror", ["source", "mirrored"])'''),
    ("md", "**Editing a given motion**: a corpus motion, inverted to noise under its caption, then re-weighted."),
    ("code", '''import tempfile
from salad_core.data.procedural import build_corpus
root = Path(tempfile.mkdtemp())
build_corpus(root, size="tiny", progress=False)
name = (root / "test.txt").read_text().split()[0]
feats = np.load(root / "new_joint_vecs" / f"{name}.npy")[:96]
caption = (root / "texts" / f"{name}.txt").read_text().splitlines()[0].split("#")[0]
inv = pipe.invert(feats, caption, num_steps=STEPS)
print(caption, inv.errors)
e = pipe.edit(edits=[Mirror(parts="all")], inversion=inv)
show(e, "inverted_mirror", ["reconstruction", "mirrored"])'''),
]

NOTEBOOKS["05_keymotion_keyframes"] = [
    ("md", """# KeyMotion: keyframe selection (uniform, MIEO, MDO)

KeyMotion §III-A: the Maximum-Distance-Optimal keyframes maximise the summed feature distance between
consecutive keyframes (exact dynamic programming); Minimum-Interpolation-Error-Optimal keyframes minimise
the linear-interpolation error; uniform spacing is the baseline. Shown on a procedural-corpus motion."""),
    ("code", SETUP + '''
K = 12'''),
    ("code", '''import tempfile
import numpy as np
import matplotlib.figure
from IPython.display import display
from PIL import Image
from salad_core.data.procedural import build_corpus
from salad_core.keymotion import select_keyframes, interpolation_errors
from salad_core.motion import features_to_joints
import salad_viz as viz

root = Path(tempfile.mkdtemp())
build_corpus(root, size="tiny", progress=False)
name = max((root / "train.txt").read_text().split(), key=lambda n: len(np.load(root / "new_joint_vecs" / f"{n}.npy")))
feats = np.load(root / "new_joint_vecs" / f"{name}.npy")
caption = (root / "texts" / f"{name}.txt").read_text().splitlines()[0].split("#")[0]
print(caption, feats.shape)'''),
    ("code", '''fig = matplotlib.figure.Figure(figsize=(9, 3))
ax = fig.subplots()
speed = np.linalg.norm(np.diff(feats, axis=0), axis=1)
ax.plot(speed, color="0.6", label="feature change per frame")
rows = []
for i, method in enumerate(["uniform", "mieo", "mdo"]):
    idx = select_keyframes(feats, K, method)
    ax.scatter(idx, np.full(K, -0.1 - 0.1 * i) * speed.max(), label=method, s=18)
    err = interpolation_errors(feats)[idx[:-1], idx[1:]].sum()
    dist = np.linalg.norm(np.diff(feats[idx], axis=0), axis=1)
    rows.append((method, list(idx), round(float(err), 1), round(float(dist.sum()), 2), round(float(dist.min()), 3)))
ax.legend(loc="upper right"); ax.set_xlabel("frame")
display(fig)
for r in rows:
    print(f"{r[0]:8s} interp. error {r[2]:>8}  summed distance {r[3]:>7}  closest pair {r[4]:>6}  {r[1]}")'''),
    ("code", '''joints = features_to_joints(feats)
for method in ["uniform", "mdo"]:
    print(method)
    display(Image.fromarray(viz.keyframe_strip(joints, "humanml3d", select_keyframes(feats, 6, method), layout="row")))'''),
]

NOTEBOOKS["08_teaching_diffusion"] = [
    ("md", """# Teaching: the diffusion process step by step, and what guidance does

The denoising loop (`salad_core.sampling.denoise`) starts from Gaussian noise in the skeleton-aware latent
space (frames/4 x 7 body parts x 32) and removes noise over the DDIM steps; each intermediate latent can be
decoded by the VAE. Classifier-free guidance mixes the conditional and unconditional predictions with weight w."""),
    ("code", SETUP + '''
PROMPT = "a person jumps forward"
LENGTH, STEPS, SEED = 80, (20 if QUICK else 50), 1'''),
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
]


def build(name: str, cells: list[tuple[str, str]]) -> None:
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [new_markdown_cell(src) if kind == "md" else new_code_cell(src) for kind, src in cells]
    nbformat.write(nb, HERE / f"{name}.ipynb")


if __name__ == "__main__":
    HERE.mkdir(exist_ok=True)
    for name, cells in NOTEBOOKS.items():
        build(name, cells)
        print("wrote", HERE / f"{name}.ipynb")
