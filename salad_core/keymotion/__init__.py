"""KeyMotion (keyframe-based text-to-motion): keyframe selection and, later, its models."""
from salad_core.keymotion.selection import (KEYFRAME_METHODS, interpolation_errors, mdo_keyframes,
                                            mieo_keyframes, select_keyframes, uniform_keyframes)

__all__ = ["select_keyframes", "mdo_keyframes", "mieo_keyframes", "uniform_keyframes",
           "interpolation_errors", "KEYFRAME_METHODS"]
