"""Probes beside a staged ablation study: one extra model scored with exactly a stage's protocol (issue 24).

Where an ordering of the paper is not reproduced, the notebook must say why, with a measurement. A probe
is that measurement: a run trained outside the study from one of its variants' configs with one change
(for example the pose-vector VAE of Table 2 narrowed to the skeleton-aware VAE's parameter count), scored
here with the stage evaluation's own settings (split, replications, crops, seed), so its row compares with
the stage's rows as the rows compare with each other. The study itself is not touched: its recipe, kept
groups and shipped models stay as they are.

A probe record (``probes.json`` beside the study's kept groups, e.g. ``lab/records/ablations_v2/probes.json``)
maps a probe name to its row document (the layout of a stage's rows: ``values`` per replication,
``summary`` mean and 95 % half-width, ``parameters``, ``settings``) plus what it changed, the stage it
compares with and the commands that made it. :func:`probe_markdown` prints the probe beside the stage's
rows it answers.

Trained probes at an equal budget are VAE probes (:func:`score_vae_probe`, ``lab/scripts/ablations/ablation_vae_probe.py``) and
denoiser probes (:func:`score_denoiser_probe`, ``lab/scripts/ablations/ablation_denoiser_probe.py``: a study variant's denoiser
trained on another frozen VAE, e.g. "w/o ST-latent" on the parameter-matched pose-vector VAE). Denoisers are also
probed by scoring the shipped models again with another sampler setting (``lab/scripts/ablations/ablation_sampler_probe.py``,
:func:`sampler_probe_markdown`) and by *continuing* the study's runs (or a denoiser probe) past their last stage with
another schedule (``lab/scripts/ablations/ablation_continuation_probe.py``, :func:`score_denoiser_continuation`,
:func:`continuation_probe_markdown`; their own record, not ``probes.json``: they trained longer than the stage).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Mapping, Sequence

from .stage_eval import _jsonable, _row_doc, _score_vae, latest_step

__all__ = ["SAMPLER_SETTINGS", "stage_settings", "score_vae_probe", "score_denoiser_probe", "record_probe", "load_probes",
           "probe_markdown", "sampler_probe_markdown", "guidance_pair_markdown", "score_denoiser_continuation", "continuation_probe_markdown",
           "paired_probe_markdown", "continued_pairs_markdown", "assemble_latest"]


#: evaluation settings a denoiser probe may change without unpairing its rows from the stage's crops and noise
SAMPLER_SETTINGS = ("guidance_scale", "num_steps", "solver")


def stage_settings(stage_doc: Mapping[str, Any], kind: str = "vae"):
    """The :class:`~salad_core.eval.settings.EvalSettings` a stage was scored with; the stage must be of ``kind``
    (``"vae"`` or ``"denoiser"``), the kind of model the probe scores."""
    from salad_core.eval.settings import EvalSettings

    if stage_doc.get("kind") != kind:
        name = "VAE" if kind == "vae" else kind
        raise ValueError(f"stage {stage_doc.get('stage')!r} is a {stage_doc.get('kind')!r} stage; {name} probes "
                         f"compare with a {name} group's stage")
    return EvalSettings(**stage_doc["settings"])


def _equal_budget(stage_doc: Mapping[str, Any], run, base_variant: str) -> int:
    """The stage's steps, once ``base_variant`` is one of its rows and the probe run ``run`` is at those steps (an
    equal budget); ValueError naming what is not."""
    steps = int(stage_doc["steps"])
    if base_variant not in stage_doc["rows"]:
        raise ValueError(f"base_variant {base_variant!r} is not a row of {stage_doc['stage']}; its rows: "
                         f"{sorted(stage_doc['rows'])}")
    at = latest_step(run)
    if at != steps:
        raise ValueError(f"probe run {run} is at step {at}, the stage {stage_doc['stage']} at {steps}: a probe "
                         "compares at an equal budget; train it to that step (max_steps) first")
    return steps


def score_vae_probe(stage_doc: Mapping[str, Any], run: str | os.PathLike, *, label: str, change: Mapping[str, Any],
                    base_variant: str, data: str | os.PathLike, evaluator=None) -> dict:
    """Score the VAE run ``run`` with the protocol of the VAE stage ``stage_doc``; return its row document.

    Parameters
    ----------
    stage_doc : dict
        A VAE group's stage evaluation (``evaluations/<group>@<steps>.json``): its ``settings`` are the
        protocol, its ``steps`` the budget the probe must have trained for.
    run : path
        The probe's training run (``python -m salad_core.train vae --config ...``); its ``latest``
        checkpoint must be at the stage's steps (equal budgets).
    label, change, base_variant
        What the probe is, what it changed (e.g. ``{"model.pose_width": 46}``) and of which variant of
        the stage: recorded with the row.
    data : path
        The study's corpus (the stage's ``data`` may be a path of another machine).
    evaluator : T2MEvaluator, optional
        Default: the packaged procedural-corpus evaluator, the study's.

    Returns
    -------
    dict
        The row document of :mod:`~salad_lab.stage_eval` (``values``, ``summary``, ``parameters``,
        ``settings``) with ``label``, ``change``, ``base_variant``, ``stage`` and ``run``.

    Raises
    ------
    ValueError
        When the run is not at the stage's steps, the stage is not a VAE stage or ``base_variant`` is not
        one of its rows.
    """
    from salad_core.train.assemble import export_vae

    settings = stage_settings(stage_doc)
    steps = _equal_budget(stage_doc, run, base_variant)
    if evaluator is None:
        from salad_core.eval.train_evaluator import load_packaged_evaluator

        evaluator = load_packaged_evaluator()[0]
    with tempfile.TemporaryDirectory() as tmp:
        folder = export_vae(run, Path(tmp) / "vae_probe")          # fp16, as the study's rows were scored
        result, params = _score_vae(folder, label, data, evaluator, settings,
                                    f"probe {label} at {steps} steps ({run})")
    row = _row_doc(result, "probe", label, steps, params)
    return _jsonable({**row, "label": label, "change": dict(change), "base_variant": base_variant,
                      "stage": stage_doc["stage"], "run": str(run)})


def load_probes(path: str | os.PathLike) -> dict[str, dict]:
    """The probe record at ``path`` (``{}`` when there is none yet)."""
    path = Path(path)
    return json.loads(path.read_text()) if path.is_file() else {}


def record_probe(path: str | os.PathLike, name: str, row: Mapping[str, Any], *, commands: Sequence[str]) -> Path:
    """Add (or replace) the probe ``name`` in the record at ``path`` with the ``commands`` that made it."""
    from salad_core.io import atomic_write_text

    path = Path(path)
    doc = load_probes(path)
    doc[name] = {**row, "commands": list(commands)}
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(doc, indent=2) + "\n")
    return path


def _cell(summary: Mapping[str, Sequence[float]], metric: str, scale: float, digits: int) -> str:
    if metric not in summary:
        return "-"
    mean, half = summary[metric]
    return f"{mean * scale:.{digits}f} ± {half * scale:.{digits}f}"


def probe_markdown(stage_doc: Mapping[str, Any], probes: Mapping[str, Mapping[str, Any]],
                   variants: Sequence[str] | None = None) -> str:
    """A markdown table: the stage's rows ``variants`` (default: all of them) and every probe of ``probes`` made on
    that stage, with parameters (``-`` where a row has no count, as denoiser rows) and the stage kind's metrics
    (a VAE stage: FID and MPJPE in cm; a denoiser stage: FID and R-precision top-3) as mean ± 95 % half-width over
    the replications."""
    from .orderings import TABLE_METRICS

    metrics = TABLE_METRICS[stage_doc["kind"]]
    fmt = {"MPJPE": (100, 2)}
    mine = {k: p for k, p in probes.items() if p.get("stage") == stage_doc["stage"]}
    if variants is None:
        variants = list(stage_doc["rows"])

    def cells(doc: Mapping[str, Any]) -> str:
        n = doc.get("parameters")
        return " | ".join([f"{n:,}" if n else "-"] + [_cell(doc["summary"], m, *fmt.get(m, (1, 3))) for m in metrics])

    lines = ["| model | parameters | " + " | ".join(f"{m} (cm)" if m == "MPJPE" else m for m in metrics) + " |",
             "|---|---:|" + "---:|" * len(metrics)]
    for v in variants:
        r = stage_doc["rows"][v]
        lines.append(f"| {r['label']} ({v}) | {cells(r)} |")
    for k, p in mine.items():
        change = ", ".join(f"{a} = {b}" for a, b in p.get("change", {}).items())
        lines.append(f"| **probe** {p['label']} ({p['base_variant']} with {change}) | {cells(p)} |")
    return "\n".join(lines) + "\n"


def _stage_and_probe_tables(probe: Mapping[str, Any], first: str, stage_col: str, probe_col: str,
                            stage_pair_col: str, probe_pair_col: str) -> list[str]:
    """Markdown lines of a denoiser probe record's two tables: each variant's FID and R-precision top-3 at the stage
    (``at_stage``) and in the probe (``summary``), then the paired advantage of ``first`` over each other variant at
    both (``paired``: ``at_stage`` and ``probe``), mean ± 95 % half-width."""
    metrics = ("FID", "R-precision top-3")
    lines = ["| variant | " + " | ".join(f"{m} {c}" if c.startswith("at ") else f"{m}, {c}"
                                          for m in metrics for c in (stage_col, probe_col)) + " |",
             "|---|---|---|---|---|"]
    for v, row in probe["rows"].items():
        cells = [f"{row[k][m][0]:.3f} ± {row[k][m][1]:.3f}" for m in metrics for k in ("at_stage", "summary")]
        lines.append(f"| `{v}` | " + " | ".join(cells) + " |")
    lines += ["", f"Paired advantage of `{first}` (positive: better; 95 % half-width):", "",
              f"| pair | {stage_pair_col} | {probe_pair_col} |", "|---|---|---|"]
    for pair, p in probe["paired"].items():
        lines.append(f"| {pair} | {p['at_stage'][0]:+.3f} ± {p['at_stage'][1]:.3f} | "
                     f"{p['probe'][0]:+.3f} ± {p['probe'][1]:.3f} |")
    return lines


def _guidance_refinements(probe: Mapping[str, Any]) -> list[str]:
    """How a sampler probe refined classifier-free guidance beyond its weight, in words: ``["rescale 0.7"]``, ``["only
    at 0 <= t/T <= 0.5"]``, both, or ``[]`` for plain guidance (records written before the probe had these keys too)."""
    phi, interval = probe.get("guidance_rescale") or 0.0, probe.get("guidance_interval")
    extra = [f"rescale {phi:g}"] if phi else []
    if interval:
        extra.append(f"only at {interval[0]:g} <= t/T <= {interval[1]:g}")
    return extra


def sampler_probe_markdown(record: Mapping[str, Mapping[str, Any]]) -> str:
    """The record of ``lab/scripts/ablations/ablation_sampler_probe.py`` (denoisers scored again with another number of sampler
    steps or another guidance: weight, rescale, interval; the stage's protocol otherwise) as markdown: per probe, each row at the stage's
    setting and at the probe's, then each pair's paired advantage at both, and the command that made it."""
    out = []
    for name, probe in record.items():
        n = probe["num_steps"]
        first = next(iter(probe["rows"]))
        stage_steps = probe.get("stage_num_steps", 10)
        w, stage_w = probe.get("guidance_scale"), probe.get("stage_guidance_scale")
        extra = _guidance_refinements(probe)
        if extra:                              # guidance refined: rescale and/or an interval of t/T
            ours, theirs = f"{n} steps, w {w:g} ({', '.join(extra)})", f"{stage_steps} steps, w {stage_w:g}"
            what = f"{n} sampler steps and guidance weight {w:g}, " + ", ".join(extra)
            if probe.get("guided_timesteps") is not None:
                what += f" (guided timesteps: {', '.join(str(t) for t in probe['guided_timesteps']) or 'none'})"
        elif w is None or w == stage_w:        # a probe of the sampler steps alone
            ours, theirs, what = f"{n} steps", f"{stage_steps} steps", f"{n} sampler steps"
        else:
            ours, theirs = f"{n} steps, w {w:g}", f"{stage_steps} steps, w {stage_w:g}"
            what = f"{n} sampler steps and guidance weight {w:g}"
        out += [f"**{name}** (the stage's protocol with {what}):", ""]
        out += _stage_and_probe_tables(probe, first, theirs, ours, theirs, ours)
        out += ["", f"Made by: `{probe['command']}`", ""]
    return "\n".join(out).rstrip() + "\n"


def guidance_pair_markdown(stage_doc: Mapping[str, Any], record: Mapping[str, Mapping[str, Any]], first: str,
                           second: str) -> str:
    """How one pair of denoisers orders under each guidance the sampler probe scored them with: one row for the stage's
    own setting, then one per entry of ``record`` (``lab/scripts/ablations/ablation_sampler_probe.py``) that scored both at the
    stage's number of steps (other step counts are left out: one change at a time). Columns: the guided timesteps
    (``all`` at the stage's setting), each row's FID and R-precision top-3 (mean ± 95 % half-width) and ``first``'s
    paired advantage (positive: ``first`` better)."""
    from .orderings import paired_advantage

    metrics = ("FID", "R-precision top-3")
    steps = stage_doc["settings"]["num_steps"]
    head = (f"| guidance ({steps} sampler steps) | guided timesteps | "
            + " | ".join(f"{m} `{v}`" for m in metrics for v in (first, second))
            + " | " + " | ".join(f"{m}, paired" for m in metrics) + " |")
    lines = [head, "|---|---|" + "---:|" * 6]

    def cells(summary_a, summary_b, paired) -> str:
        out = [f"{s[m][0]:.3f} ± {s[m][1]:.3f}" for m in metrics for s in (summary_a, summary_b)]
        out += [f"{paired[m][0]:+.3f} ± {paired[m][1]:.3f}" for m in metrics]
        return " | ".join(out)

    rows = stage_doc["rows"]
    paired = {m: paired_advantage(rows[first]["values"][m], rows[second]["values"][m], m) for m in metrics}
    lines.append(f"| w {stage_doc['settings']['guidance_scale']:g} at every step (the stage) | all | "
                 + cells(rows[first]["summary"], rows[second]["summary"], paired) + " |")
    for probe in record.values():
        if probe.get("num_steps") != steps or not {first, second} <= set(probe["rows"]):
            continue
        if first != next(iter(probe["rows"])):
            continue                            # the record pairs its first variant with the others
        w = probe["guidance_scale"]
        label = ", ".join([f"w {w:g}", *_guidance_refinements(probe)])
        label = f"{label} (no guidance)" if w == 1 else label
        guided = probe.get("guided_timesteps")
        if w == 1:
            guided_text = "none"
        elif guided is not None and len(guided) == probe["num_steps"]:
            guided_text = "all"
        elif guided is not None:
            guided_text = ", ".join(str(t) for t in guided) or "none"
        else:                                   # a record written before the probe listed them: every step
            guided_text = "all"
        pair = {m: probe["paired"][f"{first} vs {second}, {m}"]["probe"] for m in metrics}
        lines.append(f"| {label} | {guided_text} | "
                     + cells(probe["rows"][first]["summary"], probe["rows"][second]["summary"], pair) + " |")
    return "\n".join(lines) + "\n"


def score_denoiser_continuation(stage_doc: Mapping[str, Any], run: str | os.PathLike, *,
                                vae: str | os.PathLike | None = None, label: str, data: str | os.PathLike,
                                evaluator=None, text_encoder=None, sampler: Mapping[str, Any] | None = None) -> dict:
    """Score a denoiser run that *continued* a stage's run (e.g. with a decaying learning rate) with that stage's
    protocol; return its row document.

    Unlike a VAE probe (:func:`score_vae_probe`, an equal budget), a continuation has trained past the stage:
    it starts from the study run's train state at the stage's steps and changes the schedule from there, so it
    answers "does the pair's gap at the stage survive more training of this kind?" Compare continuations with
    each other (the same crops, captions and noise: :func:`~salad_lab.orderings.paired_advantage`),
    and with the stage's rows only as a second reading.

    Parameters
    ----------
    stage_doc : dict
        A denoiser group's stage evaluation: its ``settings`` are the protocol.
    run : path
        The continued denoiser run; its ``latest`` checkpoint must be past the stage's steps.
    vae : path, optional
        The frozen VAE the run learned on (an exported VAE folder, e.g. the shipped
        ``weights/ablations/vae_st_long``, or the stage's VAE run); default: the one the run records.
    label : str
        What the row is (recorded).
    data : path
        The study's corpus.
    evaluator, text_encoder : optional
        Default: the packaged procedural-corpus evaluator and the run's text encoder.
    sampler : dict, optional
        Sampler settings that replace the stage's (:data:`SAMPLER_SETTINGS`: ``guidance_scale``, ``num_steps``,
        ``solver``), e.g. ``{"guidance_scale": 3.5}``; the crops, captions and noise stay the stage's, so rows
        scored with the same ``sampler`` are paired. Any other key is refused (it would unpair the rows).

    Returns
    -------
    dict
        The row document of :mod:`~salad_lab.stage_eval` (``values`` per replication, ``summary``,
        ``settings`` (the sampler's included), ``steps`` = the run's step) with ``label``, ``from_step`` and ``run``.
    """
    import dataclasses

    settings = stage_settings(stage_doc, "denoiser")
    if sampler:
        other = sorted(set(sampler) - set(SAMPLER_SETTINGS))
        if other:
            raise ValueError(f"sampler settings {other} are not sampler settings ({list(SAMPLER_SETTINGS)}): "
                             "changing the protocol would unpair the rows")
        settings = dataclasses.replace(settings, **sampler)
    from_step = int(stage_doc["steps"])
    at = latest_step(run)
    if at is None or at <= from_step:
        raise ValueError(f"denoiser run {run} is at step {at}: a continuation of {stage_doc['stage']} must have "
                         f"trained past its {from_step} steps")
    result = _score_denoiser_run(run, vae, label, data, evaluator, settings, text_encoder,
                                 f"continuation {label} at {at} steps ({run})")
    row = _row_doc(result, "continuation", label, at)
    return _jsonable({**row, "label": label, "from_step": from_step, "stage": stage_doc["stage"], "run": str(run)})


def _score_denoiser_run(run, vae, label: str, data, evaluator, settings, text_encoder, weights: str):
    """Assemble the denoiser run ``run``'s ``latest`` checkpoint (the step a probe is reported at, never its
    ``best``: a run's validation choice is not the stage's budget) with the VAE ``vae`` (None: the one the run
    records) as the study's rows were (fp16) and score it with ``settings``; return the evaluation result."""
    from .stage_eval import _score_denoiser

    if evaluator is None:
        from salad_core.eval.train_evaluator import load_packaged_evaluator

        evaluator = load_packaged_evaluator()[0]
    if text_encoder is None:
        from salad_core.text import load_text_encoder

        text_encoder = load_text_encoder(json.loads((Path(run) / "config.json").read_text())
                                         .get("task", {}).get("text_encoder", "minilm"))
    with tempfile.TemporaryDirectory() as tmp:
        folder = assemble_latest(run, vae, tmp, text_encoder=text_encoder)
        result, _ = _score_denoiser(folder, label, data, evaluator, settings, weights, text_encoder)
    return result


def assemble_latest(run, vae, tmp: str | os.PathLike, *, text_encoder=None) -> Path:
    """A pipeline folder (under ``tmp``) of the denoiser run ``run``'s ``latest`` checkpoint, never its ``best``,
    with the VAE ``vae`` (None: the one the run records), in fp16 as the study's rows were shipped."""
    from salad_core.train.assemble import assemble_pipeline

    from .stage_eval import snapshot_run

    view = snapshot_run(run, Path(tmp) / "run", latest_step(run))           # latest.* only: no best.* to prefer
    return assemble_pipeline(vae, view, Path(tmp) / "pipeline", text_encoder=text_encoder)


def score_denoiser_probe(stage_doc: Mapping[str, Any], run: str | os.PathLike, *, vae: str | os.PathLike | None,
                         label: str, change: Mapping[str, Any], base_variant: str, data: str | os.PathLike,
                         evaluator=None, text_encoder=None) -> dict:
    """Score a denoiser probe, trained from scratch to a denoiser stage's budget with one change to a study
    variant (typically its frozen VAE), with that stage's protocol; return its row document.

    The denoiser counterpart of :func:`score_vae_probe`: an equal budget, the stage's crops, captions and noise,
    so the row is paired with the stage's rows (:func:`paired_probe_markdown`).

    Parameters
    ----------
    stage_doc : dict
        A denoiser group's stage evaluation; its ``steps`` are the budget the run must be at.
    run : path
        The probe's denoiser run (``python -m salad_core.train denoiser ... --vae VAE``).
    vae : path or None
        The frozen VAE it learned on (a VAE run or exported VAE folder); None: the one the run records.
    label, change, base_variant
        What the probe is, what it changed (e.g. ``{"vae": "pose_matched probe VAE"}``) and of which row of the
        stage: recorded with the row.
    data : path
        The study's corpus.
    evaluator, text_encoder : optional
        Default: the packaged procedural-corpus evaluator and the run's text encoder.

    Returns
    -------
    dict
        The row document (``values``, ``summary``, ``settings``, ``steps``) with ``label``, ``change``,
        ``base_variant``, ``stage`` and ``run``.

    Raises
    ------
    ValueError
        When the stage is not a denoiser stage, ``base_variant`` not one of its rows, or the run not at its steps.
    """
    settings = stage_settings(stage_doc, "denoiser")
    steps = _equal_budget(stage_doc, run, base_variant)
    result = _score_denoiser_run(run, vae, label, data, evaluator, settings, text_encoder,
                                 f"probe {label} at {steps} steps ({run})")
    row = _row_doc(result, "probe", label, steps)
    return _jsonable({**row, "label": label, "change": dict(change), "base_variant": base_variant,
                      "stage": stage_doc["stage"], "run": str(run)})


def continuation_probe_markdown(record: Mapping[str, Mapping[str, Any]]) -> str:
    """The record of ``lab/scripts/ablations/ablation_continuation_probe.py`` as markdown: per probe, each variant at the stage
    and after the continuation (FID, R-precision top-3, mean ± 95 % half-width), then the paired advantage of its
    first variant over each other one at both, and the commands that made it."""
    out = []
    for name, probe in record.items():
        first = next(iter(probe["rows"]))
        s, n = probe["from_step"], probe["steps"]
        sampler = ", ".join(f"{k} {v}" for k, v in probe.get("sampler", {}).items())
        protocol = f"the stage's protocol with {sampler}" if sampler else "the stage's protocol"
        out += [f"**{name}** ({probe['change_text']}; {protocol}):", ""]
        cont = f"at {n:,} (continued{', ' + sampler if sampler else ''})"
        out += _stage_and_probe_tables(probe, first, f"at {s:,}", f"at {n:,}{', ' + sampler if sampler else ''}",
                                       f"at {s:,} (the stage)", cont)
        out += ["", "Made by:", ""] + [f"    {c}" for c in probe["commands"]] + [""]
    return "\n".join(out).rstrip() + "\n"


def paired_probe_markdown(stage_doc: Mapping[str, Any], probes: Mapping[str, Mapping[str, Any]],
                          pairs: Sequence[tuple[str, str]]) -> str:
    """Paired gaps between rows of a stage and probes made on it, as a markdown table.

    Every probe of a stage is scored with the stage's protocol (the same crops, in the same replications), so any
    two of these rows are paired, as the stage's own rows are. ``pairs`` names ``(a, b)``: each a stage row
    (variant) or a probe (its key in ``probes``). Each cell is ``a``'s advantage over ``b`` (positive: ``a``
    better) on each metric of the stage's kind, mean ± 95 % half-width (MPJPE in cm).

    Raises
    ------
    KeyError
        A name that is neither a row of the stage nor one of its probes.
    ValueError
        A probe scored with other settings than the stage (not paired).
    """
    from .orderings import TABLE_METRICS, paired_advantage

    metrics = TABLE_METRICS[stage_doc["kind"]]
    protocol = ("split", "batch_size", "replications", "max_samples", "seed")

    def row(name: str) -> Mapping[str, Any]:
        if name in stage_doc["rows"]:
            return stage_doc["rows"][name]
        if name in probes and probes[name].get("stage") == stage_doc["stage"]:
            p = probes[name]
            ours = {k: p["settings"].get(k) for k in protocol}
            theirs = {k: stage_doc["settings"].get(k) for k in protocol}
            if ours != theirs:
                raise ValueError(f"probe {name!r} was scored with {ours}, the stage with {theirs}: not paired")
            return p
        raise KeyError(f"{name!r} is neither a row of {stage_doc['stage']} ({sorted(stage_doc['rows'])}) nor one of "
                       f"its probes ({sorted(k for k, p in probes.items() if p.get('stage') == stage_doc['stage'])})")

    lines = ["| pair | " + " | ".join(f"{m}{' (cm)' if m == 'MPJPE' else ''}" for m in metrics) + " |",
             "|---|" + "---:|" * len(metrics)]
    for a, b in pairs:
        ra, rb = row(a), row(b)
        cells = []
        for m in metrics:
            mean, half = paired_advantage(ra["values"][m], rb["values"][m], m)
            scale, digits = (100, 2) if m == "MPJPE" else (1, 4 if stage_doc["kind"] == "vae" else 3)
            cells.append(f"{mean * scale:+.{digits}f} ± {half * scale:.{digits}f}")
        lines.append(f"| `{a}` over `{b}` | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def continued_pairs_markdown(record: Mapping[str, Mapping[str, Any]], pairs: Sequence[tuple[str, str]], *,
                             sampler: Mapping[str, Any] | None = None) -> str:
    """Paired gaps between continued rows of *different* probes of a continuation record, as a markdown table.

    Each probe of ``lab/scripts/ablations/ablation_continuation_probe.py`` pairs its first variant with the others; rows of two
    probes are paired as well when both continued the same stage to the same step and were scored with the same
    sampler settings (the stage's crops, captions and noise). The schedule of each continuation is not compared:
    pair rows of probes that changed the same thing (their ``change_text`` says what). ``pairs`` names ``(a, b)`` variants; a variant is
    looked up in every probe of ``record`` scored with ``sampler`` (default: the stage's own, ``{}``). Each cell is
    ``a``'s advantage over ``b`` after the continuation (positive: ``a`` better), mean ± 95 % half-width. A variant scored in two probes (the same run, scored
    twice) must have the same figures there, to float rounding. (The gaps
    at the stage itself are :func:`paired_probe_markdown`'s: the record keeps only the rows' stage summaries.)

    Raises
    ------
    KeyError
        A variant in no probe of ``record`` with these sampler settings.
    ValueError
        A variant whose rows in two probes differ (not the same run), two variants continued from other stages or
        to other steps (not paired), or pairs at different steps (one table has one step).
    """
    from .orderings import paired_advantage

    sampler = dict(sampler or {})
    metrics = ("FID", "R-precision top-3")

    def find(name: str) -> tuple[Mapping[str, Any], Mapping[str, Any]]:
        found = [(probe, probe["rows"][name]) for probe in record.values()
                 if dict(probe.get("sampler") or {}) == sampler and name in probe["rows"]]
        if not found:
            raise KeyError(f"{name!r} is in no probe scored with sampler settings {sampler or 'of the stage'} "
                           f"(probes: {sorted(record)})")
        for probe, row in found[1:]:
            a, b = row["values"], found[0][1]["values"]   # the same run scored twice: equal to float noise
            if set(a) != set(b) or any(not math.isclose(x, y, rel_tol=1e-5, abs_tol=1e-7)
                                       for m in a for x, y in zip(a[m], b[m], strict=True)):
                raise ValueError(f"{name!r} has other figures in two probes: not the same run, rename one")
        return found[0]

    steps = None
    lines = ["| pair | " + " | ".join(metrics) + " |", "|---|" + "---:|" * len(metrics)]
    for a, b in pairs:
        (pa, ra), (pb, rb) = find(a), find(b)
        if (pa["stage"], pa["steps"]) != (pb["stage"], pb["steps"]):
            raise ValueError(f"{a!r} continued {pa['stage']} to {pa['steps']} steps, {b!r} {pb['stage']} to "
                             f"{pb['steps']}: not paired")
        if steps is not None and pa["steps"] != steps:
            raise ValueError(f"the pairs were continued to {steps} and {pa['steps']} steps: one table per step")
        steps = pa["steps"]
        cells = [("{:+.3f} ± {:.3f}").format(*paired_advantage(ra["values"][m], rb["values"][m], m)) for m in metrics]
        lines.append(f"| `{a}` over `{b}` | " + " | ".join(cells) + " |")
    if steps is not None:
        lines[0] = lines[0].replace("| pair |", f"| pair, at {steps:,} steps |")
    return "\n".join(lines) + "\n"
