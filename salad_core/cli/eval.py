"""``salad eval``: run the evaluation protocol from the command line.

::

    salad eval --data DIR [--weights DIR] [--evaluator DIR] [--quick] [--cfg-sweep]
               [--replications N] [--out DIR] ...
    salad eval --data DIR --keymotion [DIR] [...]      # the same protocol for KeyMotion (Table 1's other row)
    salad eval --physics --data CORPUS [--weights DIR] [--keymotion [DIR]] [--steps N] [--guidance W]
               [--seeds N] [--prompts N] [--prompt-set core|general|all] [--sample DIR] [--out DIR]

Prints the results table (Markdown) and, with ``--out``, writes ``results.csv``, ``results.md``,
``results.tex``, ``results.json`` (per-replication values and settings) and ``results.png``
(FID and R-precision against w). ``--quick`` runs 2 replications of at most 64 samples without
MultiModality, and says so in every output. Without ``--quick`` the protocol is followed exactly:
20 replications of the whole split, MultiModality on (100 prompts x 30).

The evaluator is the packaged one for the procedural corpus (``--evaluator``, default
``salad_core/weights/evaluator``), or with ``--official CHECKPOINTS_DIR`` the official T2M
evaluator with GloVe, for real HumanML3D / KIT-ML.

Cost on this 2-core CPU: one batch of 32 prompts at 50 DDIM steps takes about a minute with the
default pipeline. ``--quick`` (4 batches) therefore takes minutes. The full protocol on the
procedural test split (1,200 clips: 37 batches x 20 replications, plus 100 x 30 MultiModality
generations per replication) takes days; ``--no-mm`` removes most of that.

``--physics`` runs the physical-plausibility benchmark instead
(:mod:`salad_core.eval.physics_prompts`): the fixed prompts, ``--seeds`` seeds each (3 by default,
from ``--seed``), with SALAD and, with ``--keymotion`` (the shipped weights, or a folder), KeyMotion;
reference rows for the corpus's test split and for the real clips of ``--sample`` (by default the
source checkout's ``tests/data/humanml3d_sample``, when present; ``--sample none`` leaves it out).
It prints the Markdown report and with ``--out`` writes ``physics.md``, ``physics.json`` and the
generated joints (``physics_motions.npz``); ``--motions physics_motions.npz`` measures such saved
joints again without generating (after a change of the measures). The measured joints are each
pipeline's own recovery (``--recovery``, default the pipeline's: "fit" for the shipped weights); the
same features are also read raw ("positions") for the shown-vs-raw deviation. Beside the old measures
the report prints the field's (GMD's skating ratio, PhysDiff's joint-based Penetrate / Float /
Skate, stance sliding apart from low swings, floating during stance, per-segment flight fits, pooled
p99s, the per-prompt breakdown) with a real-capture reference row (HumanML3D 012314, shipped, and
pybullet's DeepMimic clips when pybullet is installed). The full
benchmark (41 prompts x 3 seeds, 50 steps) took 289 s for SALAD and 13 s for KeyMotion with one
thread on this 2-core CPU while other jobs loaded it (load average about 7).

``--prompt-set`` chooses the prompts: "core" (default) the 41 above, unchanged, so runs stay comparable
with the records; "general" the 13 general-motion prompts
(:data:`~salad_core.eval.physics_prompts.GENERAL_PROMPTS`: cartwheels, a handstand, forward rolls, a
backflip, lying down on the back, kneeling on a named knee, crawling on all fours, climbing stairs,
getting up from the floor), each with checks measured on the generated joints (head below the pelvis,
upside down on the hands, head-over-heels turn, time in the air, pelvis height at the end, the named
knee on the floor with the other foot planted, hands on the floor and forward travel, pelvis rise with
the feet planted higher step by step) whose thresholds come from the corpus's own clips; the report adds
a table of the seeds whose motion passed every check of its prompt and the general-motion target (each prompt
of cartwheel, roll, lie down, kneel, crawl and climb stairs in >= 80 % of seeds); "all" both. The general
set (13 prompts x 3 seeds, 50 steps) took 36 s for SALAD with one thread on this machine.

Errors the user can fix print one line and return status 2 (``--debug`` shows the traceback).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

__all__ = ["build_parser", "comma_floats", "main"]

log = logging.getLogger("salad.eval")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="salad eval",
        description="Evaluate a text-to-motion model with the T2M protocol (R-precision, FID, MM-Dist, "
                    "Diversity, MultiModality; mean ± 95% CI over replications).",
        epilog="example:\n  salad eval --data data/procedural --quick --out runs/eval_quick\n"
               "  salad eval --physics --data data/procedural --keymotion --out runs/physics\n"
               "  salad eval --physics --prompt-set general --data data/procedural --out runs/physics_general",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="dataset folder in the HumanML3D layout")
    p.add_argument("--weights", default=None, help="SALAD pipeline folder (default: the shipped weights)")
    p.add_argument("--evaluator", default=None,
                   help="evaluator folder with evaluator.{safetensors,json} (default: salad_core/weights/evaluator)")
    p.add_argument("--official", default=None, metavar="CHECKPOINTS_DIR",
                   help="use the official T2M evaluator (+ GloVe) of a T2M/MoMask/SALAD 'checkpoints' folder "
                        "instead of --evaluator (real HumanML3D / KIT-ML)")
    p.add_argument("--dataset", default="humanml3d", choices=["humanml3d", "kit"],
                   help="which official evaluator to load with --official")
    p.add_argument("--quick", action="store_true",
                   help="2 replications, at most 64 samples each, MultiModality off (not the full protocol)")
    p.add_argument("--cfg-sweep", action="store_true", help="evaluate at every CFG weight of --scales")
    p.add_argument("--scales", default=None,
                   help="comma-separated CFG weights for --cfg-sweep (default 1.5,2.5,...,12.5)")
    p.add_argument("--replications", type=int, default=None, help="override the number of replications")
    p.add_argument("--max-samples", type=int, default=None, help="cap on samples per replication")
    p.add_argument("--split", default="test")
    p.add_argument("--steps", type=int, default=50, help="sampler steps (default 50)")
    p.add_argument("--guidance", type=float, default=None,
                   help="CFG weight w without --cfg-sweep (default 7.5; with --physics: each model's default "
                        "guidance, a value replaces only its weight)")
    p.add_argument("--solver", default=None, help="scheduler name (default: the pipeline's)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--mm", dest="mm", action="store_true", default=None, help="compute MultiModality")
    p.add_argument("--no-mm", dest="mm", action="store_false", help="skip MultiModality")
    p.add_argument("--name", default="SALAD", help="row label of the model")
    p.add_argument("--no-real", action="store_true", help="leave out the 'Real motion' row")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    phys = p.add_argument_group("physical-plausibility benchmark (--physics)")
    phys.add_argument("--physics", action="store_true",
                      help="run the physical-plausibility benchmark (bone lengths, foot skating, penetration, "
                           "jumps, per-action checks) instead of the T2M protocol")
    phys.add_argument("--keymotion", nargs="?", const="shipped", default=None, metavar="DIR",
                      help="KeyMotion weights (no value: the shipped ones): with --physics, benchmarked beside "
                           "SALAD; without, the T2M protocol evaluates KeyMotion instead of SALAD (row 'KeyMotion')")
    phys.add_argument("--seeds", type=int, default=3, help="seeds per prompt, from --seed (default 3)")
    phys.add_argument("--prompts", type=int, default=None, metavar="N",
                      help="only the first N benchmark prompts of the set (default: all)")
    phys.add_argument("--prompt-set", default="core", choices=["core", "general", "all"],
                      help="which prompts: 'core' (default: the 41 fixed prompts of the corpus's actions, as every "
                           "record so far), 'general' (the 13 general-motion prompts: cartwheel, "
                           "handstand, forward roll, backflip, lying down, kneeling, crawling, climbing stairs, "
                           "getting up; the report adds the share of seeds passing every check per prompt) or "
                           "'all' (both, core first)")
    phys.add_argument("--recovery", default=None, metavar="METHOD",
                      help="how the measured joints are read from the generated features: 'positions' (the raw "
                           "model output, HumanML3D's recover_from_ric), a salad_core.recovery method ('fk', 'fit') "
                           "or 'pipeline' (each pipeline's own out.joints). Default with --physics: each pipeline's "
                           "own recovery (the shipped weights: 'fit'), and the shown-vs-raw deviation compares it "
                           "with 'positions' of the same features; with --guidance-sweep: 'positions'")
    phys.add_argument("--no-salad", action="store_true",
                      help="with --keymotion: benchmark KeyMotion alone (comparing KeyMotion weights; SALAD's rows "
                           "take most of the run's time); checks relative to SALAD are then left out")
    phys.add_argument("--motions", default=None, metavar="NPZ",
                      help="measure the joints a run saved (its physics_motions.npz) instead of generating; "
                           "give the run's --seed/--seeds/--prompts")
    phys.add_argument("--sample", default=None, metavar="DIR",
                      help="folder of real HumanML3D clips for a reference row (default: tests/data/"
                           "humanml3d_sample of a source checkout if present; 'none' to leave it out)")
    sweep = p.add_argument_group("choosing the default guidance (--guidance-sweep)")
    sweep.add_argument("--guidance-sweep", action="store_true",
                       help="evaluate every guidance of --scales x --rescales x --intervals x --thresholds x "
                            "--projections with the T2M protocol "
                            "AND the physics benchmark (--seeds, --prompts, --recovery) and choose the default by "
                            "the rule of salad_core.eval.guidance_sweep (default --scales 1,2,3,4.5,6,7.5); with --out, "
                            "each finished candidate is kept in OUT/candidates/ and a sweep run again with the same "
                            "settings, data and weights continues where it stopped")
    sweep.add_argument("--rescales", default="0", help="comma-separated guidance rescale values phi in [0, 1] "
                                                        "(default 0)")
    sweep.add_argument("--intervals", default="full",
                       help="comma-separated guidance intervals of t/T: 'full' or 'lo-hi', e.g. full,0-0.5")
    sweep.add_argument("--thresholds", default="off",
                       help="comma-separated dynamic thresholds (Imagen): 'off' or 'P[:BOUND]', P the quantile of "
                            "|x0| in (0, 1], BOUND what it maps to (default 1), e.g. off,0.995,0.99:4")
    sweep.add_argument("--projections", default="off",
                       help="comma-separated projected guidance (APG): 'off' or 'ETA[:CAP]', ETA in [0, 1] the "
                            "weight of the update's part parallel to the conditional x0 (1 = plain CFG), CAP the "
                            "update's norm cap, e.g. off,0,0.5:5")
    p.add_argument("--out", default=None, help="folder for results.{csv,md,tex,json,png} (with --physics: "
                                               "physics.{md,json} and physics_motions.npz; with --guidance-sweep: "
                                               "guidance_sweep.{md,json})")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    return p


def _settings(args):
    from salad_core.eval.settings import EvalSettings

    changes = dict(split=args.split, num_steps=args.steps,
                   guidance_scale=7.5 if args.guidance is None else args.guidance, solver=args.solver,
                   seed=args.seed)
    if args.replications is not None:
        changes["replications"] = args.replications
    if args.max_samples is not None:
        changes["max_samples"] = args.max_samples
    if args.mm is not None:
        changes["mm"] = args.mm
    return EvalSettings.quick_mode(**changes) if args.quick else EvalSettings(**changes)


def comma_floats(flag: str, text: str) -> list[float]:
    """``"1,4.5, 7.5"`` -> ``[1.0, 4.5, 7.5]``; a ValueError naming ``flag`` for a non-number or an empty list."""
    try:
        out = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"{flag} {text!r} must be comma-separated numbers, e.g. 1.5,7.5") from None
    if not out:
        raise ValueError(f"{flag} is empty")
    return out


def _scales(text: str | None) -> list[float]:
    from salad_core.eval.settings import DEFAULT_CFG_SCALES

    if text is None:
        return list(DEFAULT_CFG_SCALES)
    return comma_floats("--scales", text)


def _write(out_dir: Path, results, df, md: str, tex: str) -> list[Path]:
    from salad_viz.plots import plot_cfg_sweep

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "results.csv", out_dir / "results.md", out_dir / "results.tex", out_dir / "results.json"]
    df.to_csv(paths[0], index=False)
    paths[1].write_text(md, encoding="utf-8")
    paths[2].write_text(tex, encoding="utf-8")
    doc = [{"name": r.name, "values": {k: list(v) for k, v in r.values.items()}, "summary": r.summary(),
            "settings": dict(r.settings)} for r in results]
    paths[3].write_text(json.dumps(doc, indent=2, default=str) + "\n", encoding="utf-8")
    if (df["kind"] == "generator").any():
        fig = plot_cfg_sweep(df)                     # on an Agg canvas: savefig needs no pyplot
        png = out_dir / "results.png"
        fig.savefig(png, dpi=120)
        paths.append(png)
    return paths


def _as_dict(obj) -> dict:
    from dataclasses import asdict, is_dataclass

    return asdict(obj) if is_dataclass(obj) else {"value": repr(obj)}


def _default_sample() -> Path | None:
    """The real HumanML3D sample of a source checkout (not installed with the package)."""
    path = Path(__file__).resolve().parents[2] / "tests" / "data" / "humanml3d_sample"
    return path if (path / "new_joints").is_dir() else None


def _physics_generators(args, settings) -> tuple[dict, dict]:
    """The generators of ``--physics`` (SALAD, and KeyMotion with ``--keymotion``) and their settings."""
    from salad_core.pipeline import SaladPipeline

    from salad_core.eval.physics import joints_reader

    from salad_core.eval.physics_prompts import Generated

    pipe = SaladPipeline.from_pretrained(args.weights)
    # None keeps each model's own default guidance (a SALAD pipeline folder may set rescale/interval)
    g = settings.guidance

    def reader(model):
        """Features generated once, read twice: the shown joints (``--recovery``, default the model's own
        recovery) and the raw position read (the shown-vs-raw deviation)."""
        method = args.recovery or getattr(model, "recovery", None) or "positions"
        read = joints_reader(method, model.skeleton, with_raw=True)
        return method, (lambda out: Generated(*read(out)))

    salad_recovery, salad_of = reader(pipe)

    def salad(texts, lengths, seed):
        return salad_of(pipe(texts, lengths=lengths, seed=[seed] * len(texts), num_steps=settings.steps,
                             solver=args.solver, **({} if g is None else {"guidance_scale": g})))

    generators = {} if args.no_salad else {args.name: salad}
    resolved = pipe.resolve_guidance(g) if hasattr(pipe, "resolve_guidance") else (7.5 if g is None else g)
    info = {} if args.no_salad else {
        "salad_guidance": resolved if isinstance(resolved, float) else _as_dict(resolved),
        "solver": args.solver or pipe.solver, "weights": pipe.source, "recovery": salad_recovery}
    if args.keymotion is not None:
        from salad_core.keymotion.pipeline import KeyMotionPipeline

        km = KeyMotionPipeline.from_pretrained(None if args.keymotion == "shipped" else args.keymotion)
        km_recovery, km_of = reader(km)

        def keymotion(texts, lengths, seed):
            return km_of(km(texts, lengths=lengths, seed=seed, num_steps=settings.steps,
                            **({} if g is None else {"guidance_scale": g})))

        generators["KeyMotion"] = keymotion
        info["keymotion_guidance"] = _as_dict(km.resolve_guidance(g))
        info["keymotion_weights"] = args.keymotion
        info["keymotion_recovery"] = km_recovery
        info.setdefault("recovery", km_recovery)
    info["recovery_requested"] = args.recovery or "each pipeline's own"
    info["deviation_against"] = "positions"
    return generators, info


def run_physics(args) -> int:
    """``salad eval --physics``: generate the benchmark prompts, measure, check and report."""
    from salad_core.eval.physics_prompts import BenchSettings, benchmark_markdown, prompt_set, run_benchmark

    for flag, on in (("--cfg-sweep", args.cfg_sweep), ("--quick", args.quick), ("--official", args.official)):
        if on:
            raise ValueError(f"{flag} does not apply to --physics; use --steps, --seeds and --prompts for a "
                             "quicker run")
    if args.seeds < 1:
        raise ValueError(f"--seeds {args.seeds} must be >= 1")
    if args.no_salad and (args.keymotion is None or args.motions is not None):
        raise ValueError("--no-salad benchmarks KeyMotion alone: give --keymotion [DIR] (and not --motions)")
    data = Path(args.data)
    if not (data / f"{args.split}.txt").is_file():
        raise FileNotFoundError(f"--data {data} has no {args.split}.txt; give a corpus folder "
                                "(salad corpus build --out DIR)")
    if args.sample is None:
        sample = _default_sample()
    elif args.sample.lower() == "none":
        sample = None
    else:
        sample = Path(args.sample)
        if not sample.is_dir():
            raise FileNotFoundError(f"--sample {sample} is not a folder")
    settings = BenchSettings(steps=args.steps, guidance=args.guidance,
                             seeds=tuple(range(args.seed, args.seed + args.seeds)), num_prompts=args.prompts)
    prompts = prompt_set(args.prompt_set)
    if args.motions is not None:
        import numpy as np

        from salad_core.eval.physics_prompts import saved_generators

        path = Path(args.motions)
        if not path.is_file():
            raise FileNotFoundError(f"--motions {path} does not exist (a physics_motions.npz of salad eval --physics)")
        from salad_core.limits import read_npz

        generators = saved_generators(read_npz(path))        # every member's header checked, never unpickled
        info = {"motions": str(path)}
        run_json = path.parent / "physics.json"
        if run_json.is_file():                  # the steps, guidance and weights the motions were made with
            info["saved_run_settings"] = json.loads(run_json.read_text(encoding="utf-8")).get("settings")
    else:
        generators, info = _physics_generators(args, settings)
    t0 = time.perf_counter()
    motions: dict = {}
    info = {"prompt_set": args.prompt_set, **info}
    result = run_benchmark(generators, settings, data_root=data, sample_dir=sample, info=info, prompts=prompts,
                           log=lambda line: print(line, flush=True), motions_sink=motions)
    result["settings"]["seconds"] = round(time.perf_counter() - t0, 1)
    md = benchmark_markdown(result)
    print(md)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "physics.md").write_text(md, encoding="utf-8")
        (out / "physics.json").write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
        import numpy as np

        np.savez_compressed(out / "physics_motions.npz", **motions)
        print(f"wrote {out / 'physics.md'}, {out / 'physics.json'} and {out / 'physics_motions.npz'} "
              "(joints, '<generator>/<prompt index>/<seed>')")
    return 0


def _intervals(text: str) -> list[tuple[float, float] | None]:
    out: list[tuple[float, float] | None] = []
    for part in (s.strip() for s in text.split(",") if s.strip()):
        if part == "full":
            out.append(None)
            continue
        try:
            lo, hi = (float(v) for v in part.split("-"))
        except ValueError:
            raise ValueError(f"--intervals: {part!r} is neither 'full' nor 'lo-hi' (e.g. 0-0.5)") from None
        out.append((lo, hi))
    if not out:
        raise ValueError("--intervals is empty; use e.g. full or full,0-0.5")
    return out


def _pairs(flag: str, text: str, example: str) -> list[tuple[float, float | None] | None]:
    """``"off,0.5,0.5:4"`` -> ``[None, (0.5, None), (0.5, 4.0)]``: the ``--thresholds`` / ``--projections`` syntax."""
    out: list[tuple[float, float | None] | None] = []
    for part in (s.strip() for s in text.split(",") if s.strip()):
        if part == "off":
            out.append(None)
            continue
        try:
            values = [float(v) for v in part.split(":")]
        except ValueError:
            values = []
        if len(values) not in (1, 2):
            raise ValueError(f"{flag}: {part!r} is neither 'off' nor {example}")
        out.append((values[0], values[1] if len(values) == 2 else None))
    if not out:
        raise ValueError(f"{flag} is empty; use 'off' or {example}")
    return out


def _thresholds(text: str) -> list[tuple[float, float] | None]:
    """``--thresholds``: ``(p, bound)`` per entry (bound 1, Imagen's, when not given), None for 'off'."""
    return [None if t is None else (t[0], 1.0 if t[1] is None else t[1])
            for t in _pairs("--thresholds", text, "P or P:BOUND (e.g. 0.995:4)")]


def _projections(text: str) -> list[tuple[float, float | None] | None]:
    """``--projections``: ``(eta, norm_cap)`` per entry (no cap when not given), None for 'off'."""
    return _pairs("--projections", text, "ETA or ETA:CAP (e.g. 0.5:5)")


def _weights_digest(folder) -> str | None:
    """SHA-256 over the ``*.json`` and ``*.safetensors`` files of a weights folder (None when there is no such
    folder): a kept sweep result is reused only for the same weights."""
    import hashlib

    root = Path(folder) if folder is not None else None
    if root is None or not root.is_dir():
        return None
    h = hashlib.sha256()
    for f in sorted(root.glob("*")):
        if f.suffix in (".json", ".safetensors") and f.is_file():
            h.update(f.name.encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def run_guidance_sweep(args) -> int:
    """``salad eval --guidance-sweep``: T2M protocol + physics benchmark per candidate guidance, and the
    default chosen by :func:`salad_core.eval.guidance_sweep.choose`."""
    from salad_core.pipeline import SaladPipeline

    from salad_core.eval.guidance_sweep import choose, guidance_grid, run_sweep, sweep_markdown
    from salad_core.eval.physics import joints_reader
    from salad_core.eval.physics_prompts import BenchSettings
    from salad_core.eval.train_evaluator import default_evaluator_dir, load_packaged_evaluator

    if args.cfg_sweep or args.official or args.keymotion is not None or args.motions is not None:
        raise ValueError("--guidance-sweep takes neither --cfg-sweep, --official, --keymotion nor --motions")
    if args.prompt_set != "core":
        raise ValueError("--prompt-set is for --physics; the guidance sweep scores the core prompts")
    if args.seeds < 1:
        raise ValueError(f"--seeds {args.seeds} must be >= 1")
    if args.no_salad:
        raise ValueError("--no-salad is for --physics --keymotion; the guidance sweep sweeps SALAD")
    data = Path(args.data)
    if not (data / f"{args.split}.txt").is_file():
        raise FileNotFoundError(f"--data {data} has no {args.split}.txt; give a corpus folder "
                                "(salad corpus build --out DIR)")
    grid = guidance_grid(_scales(args.scales or "1,2,3,4.5,6,7.5"), comma_floats("--rescales", args.rescales),
                         _intervals(args.intervals), _thresholds(args.thresholds), _projections(args.projections))
    settings = _settings(args)
    bench = BenchSettings(steps=args.steps, seeds=tuple(range(args.seed, args.seed + args.seeds)),
                          num_prompts=args.prompts)
    evaluator, _ = load_packaged_evaluator(args.evaluator)
    pipe = SaladPipeline.from_pretrained(args.weights)
    sample = _default_sample() if args.sample is None else (None if args.sample.lower() == "none" else Path(args.sample))
    print(f"{len(grid)} candidates; {settings.describe()}", flush=True)
    t0 = time.perf_counter()
    store = Path(args.out) / "candidates" if args.out else None
    recovery = args.recovery or "positions"              # the sweep's recorded default (its candidates are kept by it)
    identity = {"weights": _weights_digest(pipe.source),
                "evaluator": _weights_digest(args.evaluator or default_evaluator_dir()),
                "recovery": recovery, "sample": None if sample is None else str(Path(sample).resolve())}
    result = run_sweep(pipe, grid, data, evaluator, settings, bench, joints_of=joints_reader(recovery, pipe.skeleton),
                       sample_dir=sample, log=lambda line: print(line, flush=True), store=store, identity=identity)
    reused = sum(1 for r in result["rows"] if r.get("reused"))
    if reused:
        print(f"{reused} of {len(grid)} candidates reused from {store} (measured before with the same settings)")
    pick, why = choose(result["rows"])
    result["chosen"] = {"index": pick, "why": why, "guidance": grid[pick].to_json_dict()}
    result["settings"].update(weights=pipe.source, data=str(data), recovery=recovery,
                              seconds=round(time.perf_counter() - t0, 1), identity=identity)
    md = sweep_markdown(result, pick) + f"\n\nChosen: {why}.\n"
    print(md)
    print('pipeline.json entry: "guidance": ' + json.dumps(grid[pick].to_json_dict()))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "guidance_sweep.md").write_text(md, encoding="utf-8")
        (out / "guidance_sweep.json").write_text(json.dumps(result, indent=1, default=str) + "\n", encoding="utf-8")
        print(f"wrote {out / 'guidance_sweep.md'} and {out / 'guidance_sweep.json'}")
    return 0


def run(args) -> int:
    import torch

    from salad_core.eval.protocol import cfg_sweep, evaluate_generator, evaluate_real
    from salad_core.eval.tables import results_frame, to_latex, to_markdown
    from salad_core.eval.train_evaluator import load_packaged_evaluator

    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads {args.threads} must be >= 1")
        torch.set_num_threads(args.threads)
    if args.physics and args.guidance_sweep:
        raise ValueError("--physics and --guidance-sweep are separate runs; --guidance-sweep already runs the "
                         "physics benchmark for every candidate")
    if args.physics:
        return run_physics(args)
    if args.guidance_sweep:
        return run_guidance_sweep(args)
    if args.no_salad:
        raise ValueError("--no-salad is for --physics --keymotion (the T2M protocol with --keymotion already "
                         "evaluates KeyMotion alone)")
    if args.prompt_set != "core":
        raise ValueError("--prompt-set is for --physics (the T2M protocol evaluates the corpus's test split)")
    data = Path(args.data)
    if not data.is_dir():
        raise FileNotFoundError(f"--data {data} is not a folder")
    settings = _settings(args)
    if args.official is not None:
        from salad_core.eval.t2m import T2MEvaluator

        evaluator = T2MEvaluator.from_official(args.official, args.dataset)
        evaluator.source = f"official T2M evaluator ({args.dataset}) from {args.official}"
    else:
        evaluator, _ = load_packaged_evaluator(args.evaluator)
    name, weights = args.name, args.weights
    if args.keymotion is not None:
        if args.weights is not None:
            raise ValueError("--weights names a SALAD pipeline and --keymotion a KeyMotion one: the T2M protocol "
                             "evaluates one model per run (run it twice for both rows)")
        from salad_core.keymotion.pipeline import KeyMotionPipeline

        weights = "salad_core/weights/keymotion" if args.keymotion == "shipped" else args.keymotion
        pipe = KeyMotionPipeline.from_pretrained(None if args.keymotion == "shipped" else args.keymotion)
        name = "KeyMotion" if args.name == "SALAD" else args.name
    else:
        from salad_core.pipeline import SaladPipeline

        pipe = SaladPipeline.from_pretrained(args.weights)
    print(settings.describe(), flush=True)
    t0 = time.perf_counter()
    if args.cfg_sweep:
        results = cfg_sweep(pipe, data, evaluator, settings, scales=_scales(args.scales), name=name,
                            include_real=not args.no_real, weights=weights, progress=args.progress)
    else:
        results = [] if args.no_real else [evaluate_real(data, evaluator, settings)]
        results.append(evaluate_generator(pipe, data, evaluator, settings, name=name, weights=weights,
                                          progress=args.progress))
    df = results_frame(results)
    md, tex = to_markdown(df), to_latex(df)
    print(md)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if args.out:
        for path in _write(Path(args.out), results, df, md, tex):
            print(f"wrote {path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``salad eval``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    from salad_core.cli._common import run_reporting_errors

    return run_reporting_errors("salad eval", args.debug, lambda: run(args))

if __name__ == "__main__":
    sys.exit(main())
