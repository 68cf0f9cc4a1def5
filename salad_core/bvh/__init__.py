"""BVH motion-capture import: read a take, map its rig to the 22 HumanML3D joints, convert it.

::

    from salad_core.bvh import import_bvh, bvh_to_joints, load_motion
    take = import_bvh("my_take.bvh")            # units, up axis and rig style detected
    print(take.summary())
    joints = take.joints                        # (N, 22, 3) the take itself: its bone lengths, metres,
                                                # +Y up, 20 fps, on its floor
    copy = take.retargeted                      # (N, 22, 3) on HumanML3D's skeleton, facing +Z
    print(take.retarget_error)                  # how far that copy is from the take (cm)
    features = take.features()                  # (N-1, 263) HumanML3D features of the copy, for the models

Modules: :mod:`.reader` (parsing and forward kinematics), :mod:`.rigs` (rig styles and the
mapping), :mod:`.convert` (up axis, units, resampling, features; :func:`load_motion` for .bvh and
.npy files).
"""
from .convert import (UNITS, UP_AXES, BvhImport, BvhImportOptions, JointsConversionError, LoadedMotion,
                      RetargetError, bvh_to_features, bvh_to_joints, import_bvh, load_motion, retarget_error,
                      retargeted_joints, take_in_features_frame)
from .reader import BvhError, BvhJoint, BvhMotion, parse_bvh, read_bvh
from .rigs import RIG_STYLES, RigError, RigMapping, load_name_map, map_rig, normalize_name

__all__ = ["BvhError", "BvhJoint", "BvhMotion", "read_bvh", "parse_bvh", "RigError", "RigMapping", "RIG_STYLES",
           "map_rig", "load_name_map", "normalize_name", "BvhImportOptions", "BvhImport", "import_bvh",
           "bvh_to_joints", "bvh_to_features", "LoadedMotion", "load_motion", "JointsConversionError", "UNITS", "UP_AXES",
           "RetargetError", "retarget_error", "retargeted_joints", "take_in_features_frame"]
