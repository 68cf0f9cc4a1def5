"""Each ordering of the paper's ablation tables, read at the study's last stage and after the decay (issue 24).

The staged study scores every denoiser variant at a constant learning rate; the continuation probe
(``lab/scripts/ablations/ablation_continuation_probe.py``) carries the study's runs on with a decaying rate and scores them with
the stage's own protocol (the same crops, captions and noise). Both readings of one paper pair are put side by side
here, with the paper's ordering, in one row per pair and metric (VAE stages, Table 2 and supplement Table 4, were not
continued: their reading is the stage's):

* the rows' own 95 % intervals (:func:`~salad_lab.orderings.compare`): an ordering is *separated* when
  they do not overlap, the issue's test of a reproduced row;
* the paired advantage of the first row over the second (:func:`~salad_lab.orderings.paired_advantage`),
  the finer reading, since the rows share their crops and noise: *significant* when its interval leaves 0.

The verdict reads the continued rows where the pair was continued (two training seeds of the full model agree
after the decay and not before: the decayed checkpoints are the steadier reading), else the stage's. Nothing is
measured here: every figure comes from the evaluation and continuation records.
"""
from __future__ import annotations

from typing import Any, Mapping

from .orderings import PAPER_PAIRS, TABLE_METRICS, compare, paired_advantage, paper_ordering, paper_value

__all__ = ["paired_ordering", "verdict", "pair_readings", "reading_markdown"]

_WORDS = {">": "ahead", "<": "behind", "=": "level"}


def paired_ordering(advantage: tuple[float, float]) -> str:
    """``">"`` / ``"<"`` when a paired advantage ``(mean, 95% half-width)`` is significant either way, else ``"="``."""
    mean, half = advantage
    if mean - half > 0:
        return ">"
    if mean + half < 0:
        return "<"
    return "="


def verdict(paper: str, intervals: str, paired: str) -> str:
    """A few words for how our ordering of a pair compares with the paper's.

    ``paper``, ``intervals`` and ``paired`` are orderings (``">"``, ``"<"``, ``"="``) of the same pair: the paper's,
    ours by the rows' own intervals, ours by the paired advantage. ``"reproduced"``: our intervals order the pair as
    the paper's do (separated the paper's way, or overlapping where the paper's overlap); ``"reproduced, paired
    only"``: the paper orders the pair, our paired gap is significant its way, our intervals overlap; ``"level"``:
    the paper orders the pair, ours does not; ``"reversed"``: ours is significant the other way; ``"ordered, the
    paper level"``: our intervals separate a pair the paper has level."""
    if intervals == paper:
        return "reproduced"
    if paper == "=":
        return "ordered, the paper level"
    if intervals not in ("=", paper) or paired not in ("=", paper):
        return "reversed"
    if paired == paper:
        return "reproduced, paired only"
    return "level"


def pair_readings(stage_doc: Mapping[str, Any], continued: Mapping[str, Any] | None = None
                  ) -> list[dict[str, Any]]:
    """Every paper pair of the stage's tables, per metric: the paper's ordering, ours at the stage and (when both
    rows were continued in the probe ``continued``, a continuation record entry) after it, and the verdict.

    Parameters
    ----------
    stage_doc : a VAE or denoiser stage's evaluation document (``evaluations/<group>@<steps>.json``), with ``tables``
        (paper table -> variant -> paper row label) and ``rows`` (variant -> ``values`` and ``summary``)
    continued : one probe of ``continuation_probe.json`` that continued this stage (``stage``, ``rows`` variant ->
        ``values`` / ``summary``, ``steps``), scored with the stage's protocol and sampler, or None

    Returns
    -------
    list of dict
        One per (table, pair, metric): ``table``, ``pair`` (variants), ``labels`` (paper rows), ``metric``,
        ``paper`` ``(a, b)`` values and ``paper_order``; ``stage`` and ``continued`` (None when not continued),
        each with ``values`` ``(a, b)`` summaries, ``intervals`` and ``paired`` orderings and ``advantage``; and
        ``verdict`` (of the continued reading when there is one, else of the stage's) with ``read_at`` (steps).
    """
    kind = stage_doc.get("kind")
    if kind not in TABLE_METRICS:
        raise ValueError(f"stage {stage_doc.get('stage')!r} is a {kind!r} stage: this reads VAE and denoiser stages")
    if continued is not None and continued.get("stage", stage_doc.get("stage")) != stage_doc.get("stage"):
        raise ValueError(f"the continuation continued {continued['stage']}, not {stage_doc.get('stage')}: not paired "
                         "with this stage's rows")
    if continued is not None and dict(continued.get("sampler") or {}):
        raise ValueError(f"the continuation was scored with sampler settings {continued['sampler']}: read the one "
                         "scored with the stage's protocol")
    def reading(rows: Mapping[str, Any], a: str, b: str, metric: str) -> dict[str, Any]:
        sa, sb = (tuple(rows[v]["summary"][metric]) for v in (a, b))
        adv = paired_advantage(rows[a]["values"][metric], rows[b]["values"][metric], metric)
        return {"values": (sa, sb), "intervals": compare(sa, sb, metric), "advantage": adv,
                "paired": paired_ordering(adv)}

    out = []
    for table, rows_of in stage_doc["tables"].items():
        variant_of = {label: v for v, label in rows_of.items()}
        for la, lb in PAPER_PAIRS[table]:
            if la not in variant_of or lb not in variant_of:
                continue
            a, b = variant_of[la], variant_of[lb]
            for metric in TABLE_METRICS[kind]:
                paper = paper_ordering(table, la, lb, metric)
                stage = reading(stage_doc["rows"], a, b, metric)
                cont = (reading(continued["rows"], a, b, metric)
                        if continued is not None and a in continued["rows"] and b in continued["rows"] else None)
                final = cont or stage
                out.append({"table": table, "pair": (a, b), "labels": (la, lb), "metric": metric,
                            "paper": (paper_value(table, la, metric), paper_value(table, lb, metric)),
                            "paper_order": paper, "stage": stage, "continued": cont,
                            "verdict": verdict(paper, final["intervals"], final["paired"]),
                            "read_at": int(continued["steps"]) if cont else int(stage_doc["steps"])})
    return out


def reading_markdown(stage_doc: Mapping[str, Any], continued: Mapping[str, Any] | None = None,
                     notes: Mapping[str, str] | None = None) -> str:
    """:func:`pair_readings` as a markdown table, one row per pair and metric; ``notes`` maps
    ``"<a> vs <b>, <metric>"`` (variants) to what was measured about that row (the last column). MPJPE in cm."""
    notes = dict(notes or {})
    steps = int(stage_doc["steps"])
    cont_steps = f"{int(continued['steps']):,}" if continued is not None else ""

    def cell(r: Mapping[str, Any] | None, scale: float, digits: int) -> str:
        if r is None:
            return "not continued"
        (ma, ha), (mb, hb) = ((m * scale, h * scale) for m, h in r["values"])
        adv, half = (v * scale for v in r["advantage"])
        return (f"{ma:.{digits}f} ± {ha:.{digits}f} vs {mb:.{digits}f} ± {hb:.{digits}f}; "
                f"paired {adv:+.{digits}f} ± {half:.{digits}f}")

    after = f" ours after the decay ({cont_steps}) |" if continued is not None else ""
    lines = [f"| table | pair | metric | paper | ours at {steps:,} |{after} verdict | what was measured |",
             "|---|---|---|---|---|" + ("---|" if continued is not None else "") + "---|---|"]
    for r in pair_readings(stage_doc, continued):
        a, b = r["pair"]
        scale, digits = (100.0, 2) if r["metric"] == "MPJPE" else (1.0, 4 if stage_doc["kind"] == "vae" else 3)
        (pa, _), (pb, _) = r["paper"]
        paper = f"{pa * scale:.{digits}f} vs {pb * scale:.{digits}f} ({_WORDS[r['paper_order']]})"
        key = f"{a} vs {b}, {r['metric']}"
        metric = "MPJPE (cm)" if r["metric"] == "MPJPE" else r["metric"]
        lines.append(f"| {r['table']} | {r['labels'][0]} vs {r['labels'][1]} | {metric} | {paper} | "
                     f"{cell(r['stage'], scale, digits)} |"
                     + (f" {cell(r['continued'], scale, digits)} |" if continued is not None else "")
                     + f" **{r['verdict']}** "
                     f"(at {r['read_at']:,}) | {notes.get(key, '')} |")
    return "\n".join(lines) + "\n"
