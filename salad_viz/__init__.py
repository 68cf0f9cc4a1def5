"""salad_viz: arrays in, figures and files out (attention heatmaps, skeleton renders, exports).

Functions here take arrays (joints, attention maps, tokens) and a skeleton, never a model.

Modules
-------
attention   7-part x frame heatmaps per word, Fig. 6 grids, layer/step views, comparisons
render      pyvista off-screen renders with automatic fallback to ``raster``; keyframe strips
raster      scikit-image 2D rasteriser of the same scenes (no OpenGL needed)
animate     GIF/MP4 (side by side or overlaid), inline display in Jupyter
export      BVH, GLB, NPY
widgets     ipywidgets explorer (words, layers, steps, frames)
explorer_html  the same explorer as one self-contained HTML file (offline; inline in Jupyter)
plots       evaluation figures from result tables (the CFG sweep of SALAD Fig. 5)
diffusion_steps  the denoising process step by step: word share of attention per step, key poses per step
camera      the pinhole camera both backends share; kinematics: rotations from positions, FK
synthetic   a procedural walk for demos and tests

Heavy libraries (matplotlib, pyvista, trimesh, scikit-image, imageio) are imported on first use.
"""
from .animate import animate, render_frames, show_animation, write_video
from .attention import (
    joint_attention,
    joint_attention_colors,
    merge_tokens,
    mirror_attention,
    plot_attention_by_layer,
    plot_attention_by_steps,
    plot_attention_comparison,
    plot_attention_grid,
    plot_joint_attention,
    plot_mirror_comparison,
    plot_word_attention,
    reduce_attention,
    select_words,
    word_token_ids,
)
from .camera import Camera, fixed_camera, follow_camera, project_points
from .diffusion_steps import denoising_strips, plot_word_share_by_step, word_share_by_step
from .explorer_html import ExplorerPage, export_explorer
from .export import export_bvh, export_glb, export_npy
from .kinematics import forward_kinematics, rest_pose, solve_rotations
from .plots import plot_cfg_sweep
from .raster import rasterize_skeleton
from .render import SkeletonRenderer, keyframe_strip, offscreen_available, render_skeleton
from .synthetic import synthetic_motion

__all__ = [
    "denoising_strips",
    "plot_word_share_by_step",
    "word_share_by_step",
    "animate",
    "render_frames",
    "show_animation",
    "write_video",
    "joint_attention",
    "joint_attention_colors",
    "merge_tokens",
    "mirror_attention",
    "plot_attention_by_layer",
    "plot_attention_by_steps",
    "plot_attention_comparison",
    "plot_attention_grid",
    "plot_joint_attention",
    "plot_mirror_comparison",
    "plot_word_attention",
    "reduce_attention",
    "select_words",
    "word_token_ids",
    "Camera",
    "fixed_camera",
    "follow_camera",
    "project_points",
    "ExplorerPage",
    "export_explorer",
    "export_bvh",
    "export_glb",
    "export_npy",
    "forward_kinematics",
    "rest_pose",
    "solve_rotations",
    "plot_cfg_sweep",
    "rasterize_skeleton",
    "SkeletonRenderer",
    "keyframe_strip",
    "offscreen_available",
    "render_skeleton",
    "synthetic_motion",
]
