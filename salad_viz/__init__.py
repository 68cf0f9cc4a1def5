"""salad_viz: arrays in, figures and files out (attention heatmaps, skeleton renders, exports).

Functions here take arrays (joints, attention maps, tokens) and a skeleton, never a model.
"""
