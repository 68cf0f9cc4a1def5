#!/usr/bin/env python
"""Render example outputs of salad_viz into a folder, for a person to look at.

Uses the real HumanML3D sample motion in tests/data (012314) and the procedural walk, with
synthetic attention maps shaped like the paper's Fig. 6 (no model is needed).

Usage: .venv/bin/python lab/scripts/viz/look_viz.py [--out outputs/look_viz] [--quick] [--backend auto|pyvista|raster]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np

REPO = Path(__file__).resolve().parents[3]
SAMPLE = REPO / "tests" / "data" / "humanml3d_sample" / "new_joints" / "012314.npy"
TOKENS = ["[CLS]", "a", "man", "jumps", "forward", "and", "then", "walks", "forward", ",", "while",
          "waving", "his", "arms", "[SEP]"]
PROMPT = "a man jumps forward and then walks forward, while waving his arms"


def synthetic_attention(n_latent: int, steps: int = 10, layers: int = 4, seed: int = 0) -> np.ndarray:
    """(S, L, N', P, W) softmax maps shaped like Fig. 6: 'jumps forward' early on the whole body,
    'walks forward' late on root and legs, 'waving arms' on the arms throughout. Later steps and
    deeper layers are sharper."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_latent)
    early = np.exp(-((t - n_latent * 0.2) / (n_latent * 0.15)) ** 2)
    late = 1.0 / (1.0 + np.exp(-(t - n_latent * 0.55) * 0.8))
    out = np.empty((steps, layers, n_latent, 7, len(TOKENS)))
    for s in range(steps):
        for l in range(layers):
            sharp = 0.4 + 0.6 * (s / max(steps - 1, 1)) * (0.5 + 0.5 * l / max(layers - 1, 1))
            logits = rng.normal(0, 0.4, (7, n_latent, len(TOKENS)))
            for k in (3, 4):
                logits[:, :, k] += 3.0 * sharp * early
            for k in (7, 8):
                logits[[0, 1, 2], :, k] += 3.0 * sharp * late
            for k in (11, 13):
                logits[[4, 5], :, k] += 2.5 * sharp
            logits[:, :, 0] += 1.0
            att = np.exp(logits)
            att /= att.sum(axis=-1, keepdims=True)
            out[s, l] = att.transpose(1, 0, 2)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "outputs" / "look_viz"), help="output folder")
    ap.add_argument("--quick", action="store_true", help="fewer frames, smaller images")
    ap.add_argument("--backend", default="auto", choices=["auto", "pyvista", "raster"])
    args = ap.parse_args()

    import matplotlib.pyplot as plt

    from salad_core.motion import mirror_joints
    from salad_core.skeleton import get_skeleton
    from salad_viz import attention as A
    from salad_viz.animate import animate
    from salad_viz.export import export_bvh, export_glb, export_npy
    from salad_viz.raster import hstack_images, rasterize_skeleton
    from salad_viz.render import keyframe_strip, offscreen_available, render_skeleton
    from salad_viz.synthetic import synthetic_motion

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    skel = get_skeleton("humanml3d")
    joints = np.load(SAMPLE) if SAMPLE.exists() else synthetic_motion(skel, 120, turn_degrees=90)
    walk = synthetic_motion(skel, 80, turn_degrees=90)
    n_lat = len(joints) // skel.unit_length
    full = synthetic_attention(n_lat)
    att = A.reduce_attention(full, "slnpw")
    stride = 4 if args.quick else 1
    size = (240, 240) if args.quick else (360, 320)
    print(f"off-screen OpenGL available: {offscreen_available()} (backend={args.backend})")
    written = []

    def save_fig(fig, name):
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        written.append(name)

    def save_img(img, name):
        from PIL import Image

        Image.fromarray(img).save(out / name)
        written.append(name)

    t0 = time.time()
    # ---- attention
    save_fig(A.plot_attention_grid(att, TOKENS, ["jumps forward", "walks forward", ["waving", "arms"]],
                                   prompt=PROMPT), "attention_fig6.png")
    save_fig(A.plot_attention_grid(att, TOKENS, prompt=PROMPT), "attention_all_words.png")
    save_fig(A.plot_word_attention(att[:, :, 7] + att[:, :, 8], "walks forward", frame=60),
             "attention_word.png")
    save_fig(A.plot_attention_by_layer(full, TOKENS, "walks forward", axes="slnpw"), "attention_by_layer.png")
    save_fig(A.plot_attention_by_steps(full, TOKENS, "walks forward", axes="slnpw", step_ranges=3),
             "attention_by_steps.png")
    edited = A.reduce_attention(synthetic_attention(n_lat, seed=1), "slnpw")
    edited[:, :, 11] *= np.linspace(0.3, 1.7, n_lat)[None, :]
    save_fig(A.plot_attention_comparison(att, edited, TOKENS, ["walks forward", "waving"],
                                         title="source vs edited"), "attention_source_vs_edited.png")
    save_fig(A.plot_mirror_comparison(att, A.mirror_attention(edited), TOKENS, ["walks forward", "waving"],
                                      title="original vs mirrored"), "attention_mirror.png")
    save_fig(A.plot_joint_attention(joints, skel, att[:, :, 7] + att[:, :, 8], "walks forward", frames=6,
                                    backend=args.backend), "attention_on_joints.png")
    print(f"attention figures: {time.time() - t0:.1f} s")

    # ---- skeletons
    t0 = time.time()
    views = [render_skeleton(joints, skel, 40, view=v, size=size, backend=args.backend, title=v)
             for v in ("front", "three_quarter", "side")]
    save_img(hstack_images(views, gap=4), "render_views.png")
    save_img(hstack_images([render_skeleton(joints, skel, 40, size=size, backend=args.backend, title="pyvista"
                                            if args.backend != "raster" else "raster"),
                            rasterize_skeleton(joints, skel, 40, size=size, title="raster")], gap=4),
             "render_pyvista_vs_raster.png")
    mirrored = mirror_joints(joints, skel)
    save_img(render_skeleton([joints, mirrored], skel, 40, size=size, backend=args.backend,
                             title="original (blue) vs mirrored (orange)"), "render_two_motions.png")
    save_img(keyframe_strip(joints, skel, 6, fps=skel.fps, backend=args.backend), "strip_trail_sample.png")
    save_img(keyframe_strip(walk, skel, 6, backend=args.backend), "strip_trail_walk.png")
    save_img(keyframe_strip(joints, skel, 5, layout="row", view="three_quarter", backend=args.backend),
             "strip_row_sample.png")
    print(f"skeleton images: {time.time() - t0:.1f} s")

    # ---- animations
    t0 = time.time()
    animate([joints, mirrored], skel, out / "side_by_side.gif", layout="side", titles=["original", "mirrored"],
            size=(240, 240), stride=stride * 2, backend=args.backend)
    animate([joints, mirrored], skel, out / "overlay.mp4", layout="overlay", titles=["original", "mirrored"],
            size=size, stride=stride, backend=args.backend)
    colors = A.joint_attention_colors(att[:, :, 7] + att[:, :, 8], skel, len(joints))
    animate(joints, skel, out / "attention_walks.gif", joint_colors=colors, size=(240, 240), stride=stride * 2,
            backend=args.backend, titles=["'walks forward'"])
    written += ["side_by_side.gif", "overlay.mp4", "attention_walks.gif"]
    print(f"animations: {time.time() - t0:.1f} s")

    # ---- exports
    export_bvh(joints, skel, out / "012314.bvh")
    export_bvh(walk, skel, out / "walk.bvh")
    export_glb(joints, skel, out / "012314_frame40.glb", frame=40)
    export_npy(joints, skel, out / "012314_joints.npy")
    written += ["012314.bvh", "walk.bvh", "012314_frame40.glb", "012314_joints.npy"]
    for name in written:
        print(out / name)


if __name__ == "__main__":
    main()
