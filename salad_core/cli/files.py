"""``salad import``, ``salad render`` and ``salad export``: motion files in and out (BVH takes, features and joints
``.npy``, GIF/MP4, BVH/GLB), and the readers of a motion file that ``salad invert`` and ``salad edit --motion``
share."""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Callable

from ._common import UserError, _check_out_dir, _motion_file_names, _note, _outputs, _sub


def _load_motion_array(motion: str, skeleton: str):
    """``(skeleton, array, path)``: a validated features ``(N, D)`` or joints ``(N, J, 3)`` .npy."""
    import numpy as np

    from salad_core.motion import MAX_FEATURE_MAGNITUDE, check_features
    from salad_core.skeleton import get_skeleton

    try:
        sk = get_skeleton(skeleton)
    except (KeyError, ValueError) as exc:
        raise UserError(f"--skeleton: {exc.args[0] if exc.args else exc}") from None
    path = Path(motion)
    if not path.is_file():
        raise UserError(f"motion file not found: {path}")
    from salad_core.limits import MAX_JOINT_MAGNITUDE, read_npy

    try:
        # the header first (size, dtype, truncation) and never unpickled: salad_core.limits.read_npy
        arr = read_npy(path, kinds="biuf", error=UserError)
    except (OSError, EOFError):
        raise UserError(f"cannot read {path} as a .npy array (a text, pickled, truncated or corrupt file); motion "
                        "files hold float arrays written by numpy.save") from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "iuf":     # complex parts would be dropped
        raise UserError(f"{path} does not hold a numeric array (got {getattr(arr, 'dtype', type(arr).__name__)})")
    if arr.ndim == 2:
        try:
            check_features(arr, sk, name=str(path))
        except ValueError as exc:
            raise UserError(str(exc)) from None
        top = float(np.abs(arr).max(initial=0.0))
        if top > MAX_FEATURE_MAGNITUDE:
            raise UserError(f"{path} reaches |value| = {top:.3g}, beyond {MAX_FEATURE_MAGNITUDE:g}: not HumanML3D "
                            "features (metres, radians, metres per frame; of order 1); check its units")
        return sk, arr.astype(np.float32, copy=False), path
    if arr.ndim == 3 and arr.shape[1:] == (sk.num_joints, 3):
        if not np.isfinite(arr).all():
            raise UserError(f"{path} contains NaN or infinite values")
        top = float(np.abs(arr).max(initial=0.0))
        if top > MAX_JOINT_MAGNITUDE:
            raise UserError(f"{path} reaches |value| = {top:.3g}, beyond {MAX_JOINT_MAGNITUDE:g} m: not joint "
                            "positions in metres; check its units")
        return sk, arr.astype(np.float32, copy=False), path
    raise UserError(f"{path} has shape {arr.shape}; expected features (N, {sk.feature_dim}) or "
                    f"joints (N, {sk.num_joints}, 3)")


def _load_joints(motion: str, skeleton: str):
    """``(skeleton, joints (N, J, 3), path)`` from a features ``(N, D)`` or joints ``(N, J, 3)`` .npy.

    Features are recovered as the pipeline recovers them (:data:`salad_core.recovery.DEFAULT_METHOD`, the
    skeleton fit), so that ``salad export`` and ``salad render`` of a ``*_features.npy`` show the joints that
    ``salad generate`` wrote beside it (and its BVH), not the raw position features."""
    import numpy as np

    from salad_core.recovery import DEFAULT_METHOD, recover_joints

    sk, arr, path = _load_motion_array(motion, skeleton)
    if arr.ndim == 2:
        arr = np.asarray(recover_joints(arr, DEFAULT_METHOD, sk), dtype=np.float32)
    return sk, arr, path


def _load_features(motion: str, skeleton: str):
    """``(skeleton, features (N, D), path)``: the models need features; joints files are refused."""
    sk, arr, path = _load_motion_array(motion, skeleton)
    if arr.ndim != 2:
        raise UserError(f"{path} holds joints {arr.shape}; inversion needs HumanML3D features (N, {sk.feature_dim}) "
                        "(the *_features.npy that salad generate writes)")
    unit, max_len = sk.unit_length, sk.max_length
    if not unit <= len(arr) - len(arr) % unit <= max_len:
        raise UserError(f"{path} has {len(arr)} frames; allowed: {unit}..{max_len} (at {sk.fps:g} fps; longer "
                        f"motions must be cropped first)")
    return sk, arr, path


def _parse_crop(text: str) -> tuple[float, float | None]:
    """``START:STOP`` in seconds (STOP may be empty: to the end)."""
    start, sep, stop = text.partition(":")
    try:
        a = float(start) if start.strip() else 0.0
        b = float(stop) if stop.strip() else None
    except ValueError:
        a = b = float("nan")
    if not sep or not math.isfinite(a) or a < 0 or (b is not None and not (math.isfinite(b) and b > a)):
        raise UserError(f"--crop takes START:STOP in seconds, 0 <= START < STOP (e.g. 2:9.5 or 2:), got {text!r}")
    return a, b


def _bvh_args(p: argparse.ArgumentParser) -> None:
    """The BVH import options shared by ``salad invert`` and ``salad import``."""
    p.add_argument("--crop", default=None, metavar="START:STOP",
                   help="use only this part of the motion, in seconds (e.g. 2:9.5; STOP empty = to the end)")
    p.add_argument("--rig", default=None, choices=["smpl", "mixamo", "cmu", "generic"],
                   help="BVH: the rig's naming style (default: detected from the joint names)")
    p.add_argument("--name-map", default=None, metavar="FILE.json",
                   help='BVH: JSON object {"humanml3d_joint": "RigJoint", ...} for joints the rig names '
                        "differently (the error for an unknown rig lists them)")
    p.add_argument("--units", default=None,
                   help="BVH: length unit, m, cm, mm, inch, ft or metres per unit (default: detected from the "
                        "skeleton's size)")
    p.add_argument("--up", default=None, choices=["y", "z", "-y", "-z", "x", "-x"],
                   help="BVH: the file's up axis (default: detected)")


def _motion_input(args: argparse.Namespace, check_length: bool = True):
    """``(skeleton, loaded motion, features to invert, first frame)`` from a .bvh take or a .npy of features or
    joints.

    BVH takes and joints are converted with :func:`salad_core.motion.joints_to_features`
    (retargeted, on the floor, facing +Z); ``--crop`` then cuts the features (20 fps), which start at
    frame ``first frame`` of the loaded motion (0 without ``--crop``).
    """
    from salad_core.bvh import JointsConversionError, load_motion
    from salad_core.skeleton import get_skeleton

    try:
        sk = get_skeleton(args.skeleton)
    except (KeyError, ValueError) as exc:
        raise UserError(f"--skeleton: {exc.args[0] if exc.args else exc}") from None
    path = Path(args.motion)
    given = {k: getattr(args, k) for k in ("rig", "name_map", "units", "up") if getattr(args, k) is not None}
    if given and path.suffix.lower() != ".bvh":
        flags = ", ".join("--" + k.replace("_", "-") for k in given)
        raise UserError(f"{flags} appl{'y' if len(given) > 1 else 'ies'} to .bvh files; {path.name} is not one")
    if "units" in given:
        try:
            given["units"] = float(given["units"])      # metres per unit; otherwise a unit name
        except ValueError:
            pass
    try:
        loaded = load_motion(path, sk.name, **given)
    except JointsConversionError as exc:
        needs = "inversion needs" if getattr(args, "command", "") in ("invert", "edit") else "salad works on"
        raise UserError(f"{needs} HumanML3D features (N, {sk.feature_dim}); {exc}") from None
    except (FileNotFoundError, ValueError) as exc:   # BvhError and RigError name the file (and line)
        raise UserError(str(exc)) from None
    if loaded.bvh is not None:
        print(loaded.bvh.summary())
    features = loaded.features
    from salad_core.motion import MAX_FEATURE_MAGNITUDE

    top = float(abs(features).max(initial=0.0))
    if top > MAX_FEATURE_MAGNITUDE:      # before any weights load; the inversion would diverge
        raise UserError(f"{path} reaches |value| = {top:.3g}, beyond {MAX_FEATURE_MAGNITUDE:g}: not HumanML3D "
                        "features (metres, radians, metres per frame; of order 1); check its units")
    i = 0
    if args.crop is not None:
        a, b = _parse_crop(args.crop)
        i, j = int(round(a * sk.fps)), (len(features) if b is None else int(round(b * sk.fps)))
        if i >= len(features):
            raise UserError(f"--crop {args.crop}: the motion lasts {len(features) / sk.fps:.2f} s "
                            f"({len(features)} frames at {sk.fps:g} fps)")
        features = features[i:j]
    unit, max_len = sk.unit_length, sk.max_length
    if check_length and not unit <= len(features) - len(features) % unit <= max_len:
        hint = "" if args.crop is not None else "; pick a part with --crop START:STOP (seconds)"
        raise UserError(f"{path} has {len(features)} frames; allowed: {unit}..{max_len} (at {sk.fps:g} fps, "
                        f"{max_len / sk.fps:g} s at most{hint})")
    return sk, loaded, features, i


def cmd_import(args: argparse.Namespace) -> int:
    """Convert a BVH take (or a joints .npy) for the other commands: the take's own joints (its bone lengths, on its
    floor, 20 fps), their copy retargeted to HumanML3D's skeleton and that copy's features."""
    import numpy as np

    from salad_core.io import atomic_path
    from salad_core.motion import joints_to_features
    from salad_core.recovery import DEFAULT_METHOD, recover_joints

    sk, loaded, features, start = _motion_input(args, check_length=False)
    out = _check_out_dir(args.out, args.force)
    stem = loaded.path.stem
    retargeted = None
    if loaded.kind == "features":        # no take: the features' joints, recovered as the pipeline does
        take = np.asarray(recover_joints(features, DEFAULT_METHOD, sk), dtype=np.float32)
    else:
        take = np.asarray(loaded.joints[start:start + len(features) + 1], dtype=np.float32)
        if len(take) < 2:
            raise UserError(f"--crop {args.crop} leaves {len(take)} frame of {loaded.path.name}; a motion needs 2")
        if start or len(take) < len(loaded.joints):     # cropped: the features of exactly these frames
            features = joints_to_features(take.astype(np.float64), sk)
        if sk.bone_lengths is not None:
            from salad_core.bvh import retarget_error, retargeted_joints

            retargeted = retargeted_joints(take, sk)
    names = _motion_file_names(stem, gif=not args.no_render, bvh=False)
    names += [f"{stem}_retargeted_joints.npy"] if retargeted is not None else []
    paths = _outputs(out, names, args.force)
    arrays = {f"{stem}_features.npy": features, f"{stem}_joints.npy": take,
              f"{stem}_retargeted_joints.npy": retargeted}
    for path in paths:
        if path.suffix == ".npy":
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.save(fh, np.asarray(arrays[path.name], dtype=np.float32))
    if not args.no_render:
        from salad_viz import animate

        animate(take, sk, out / f"{stem}.gif", size=(320, 320), stride=2)
    if loaded.bvh is not None and not args.quiet:
        for hml, src in loaded.bvh.rig.describe().items():
            print(f"  {hml:15s} <- {src}")
    if retargeted is not None:
        print(f"retargeted to the {sk.name} skeleton (what the features and {stem}_retargeted_joints.npy hold): "
              f"{retarget_error(take, sk)} from the take (per frame, root and heading aligned)")
    n = len(take)
    cropped = f" (--crop {args.crop} from frame {start})" if args.crop is not None else ""
    if loaded.kind == "features":
        what = f"joints {n} frames (the pipeline's {DEFAULT_METHOD} recovery of the features), features {len(features)}"
    else:
        what = (("take joints and retargeted joints " if retargeted is not None else "joints ")
                + f"{n} frames, features {len(features)} (one per step between frames)")
    print(f"{n} frames at {sk.fps:g} fps ({n / sk.fps:.2f} s){cropped}: {what}: " + ", ".join(map(str, paths)))
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    import numpy as np

    from salad_viz import animate, keyframe_strip

    from salad_viz._arrays import MAX_SIZE

    if not 8 <= args.size <= MAX_SIZE:
        raise UserError(f"--size {args.size}: allowed 8..{MAX_SIZE} pixels (the side of a square frame)")
    out = _check_out_dir(args.out, args.force)
    sk, joints, path = _load_joints(args.motion, args.skeleton)
    stem = path.stem
    _outputs(out, [f"{stem}.{args.format}"] + ([f"{stem}_strip.png"] if args.strip else []), args.force,
             write=False)
    if args.strip:
        from salad_core.io import atomic_path
        import imageio.v3 as iio

        (p,) = _outputs(out, [f"{stem}_strip.png"], args.force)
        img = keyframe_strip(joints, sk, np.linspace(0, len(joints) - 1, 6).astype(int), layout="row")
        with atomic_path(p) as tmp:
            iio.imwrite(tmp, img, extension=".png")
        print(p)
    (p,) = _outputs(out, [f"{stem}.{args.format}"], args.force)
    print(animate(joints, sk, p, size=(args.size, args.size)))
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from salad_viz import export_bvh, export_glb, export_npy

    out = _check_out_dir(args.out, args.force)
    sk, arr, path = _load_joints(args.motion, args.skeleton)
    (p,) = _outputs(out, [f"{path.stem}.{args.format}"], args.force)
    fn = {"bvh": export_bvh, "glb": export_glb, "npy": export_npy}[args.format]
    written = fn(arr, sk, p)
    print(written)
    err = getattr(written, "max_error", None)      # BVH: how far a reader's joints are from these
    if err is not None and err > 0.005:
        _note(args, f"{written.name} holds these joints to {100 * err:.1f} cm ({100 * written.mean_error:.2f} cm "
                    "mean): a BVH skeleton is rigid, and these joints' bones change length or their pelvis or "
                    "chest is not rigid")
    return 0


def add_parsers(sub) -> None:
    """The sub-commands of this module: import, render, export."""
    im = _sub(sub, "import", "convert a BVH motion-capture take (SMPL, Mixamo, CMU and similar rigs, any frame rate, "
              "unit and up axis) to the 22 HumanML3D joints at 20 fps: the take's own (its bone lengths, on its "
              "floor: NAME_joints.npy), a copy retargeted to HumanML3D's skeleton (NAME_retargeted_joints.npy, with "
              "its distance from the take printed) and that copy's features (NAME_features.npy), and a GIF",
              "salad import my_take.bvh --out takes")
    im.add_argument("motion", help="a .bvh take (or a joints .npy (N, 22, 3))")
    im.add_argument("--out", required=True, help="output folder")
    _bvh_args(im)
    im.add_argument("--no-render", action="store_true", help="skip the GIF")
    im.add_argument("--skeleton", default="humanml3d", help=argparse.SUPPRESS)
    im.add_argument("--force", action="store_true", help="overwrite existing files")

    r = _sub(sub, "render", "animate a motion file (features .npy or joints .npy) as GIF or MP4",
             "salad render gen_out/00_a_person_jumps_joints.npy --out renders --format mp4")
    r.add_argument("motion", help="a .npy file: features (N, 263) or joints (N, 22, 3)")
    r.add_argument("--out", required=True, help="output folder (created if missing)")
    r.add_argument("--format", choices=["gif", "mp4"], default="gif", help="animation format (default gif)")
    r.add_argument("--size", type=int, default=320, help="side of the square frame in pixels, 8..4096 (default 320)")
    r.add_argument("--strip", action="store_true", help="also write a keyframe strip PNG")
    r.add_argument("--skeleton", default="humanml3d", help="skeleton of the motion: humanml3d (default) or kit")
    r.add_argument("--force", action="store_true", help="overwrite existing files")

    e = _sub(sub, "export", "export a motion file to BVH (Blender), GLB or NPY joints",
             "salad export gen_out/00_a_person_jumps_features.npy --format bvh --out exports")
    e.add_argument("motion", help="a .npy file: features (N, 263) or joints (N, 22, 3)")
    e.add_argument("--out", required=True, help="output folder (created if missing)")
    e.add_argument("--format", choices=["bvh", "glb", "npy"], default="bvh",
                   help="bvh (Blender; default), glb (first frame as a 3D scene) or npy (joints (N, J, 3), metres)")
    e.add_argument("--skeleton", default="humanml3d", help="skeleton of the motion: humanml3d (default) or kit")
    e.add_argument("--force", action="store_true", help="overwrite existing files")


COMMANDS: dict[str, Callable] = {"import": cmd_import, "render": cmd_render, "export": cmd_export}
