"""The ablation models' ``MODEL_CARD.md``, written from the study's evaluation files alone.

Per group: where it stopped and why, the protocol, and per paper table one row per variant with our
figure and its 95 % interval, the paper's figure beside it (labelled as the paper's), the steps; then
every paper pair's ordering at each evaluated stage, the paper's ordering, whether ours agrees and
whether our intervals separate. Nothing is measured here: every number comes from the evaluations.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from .orderings import TABLE_METRICS, paired_advantage, paper_value

__all__ = ["model_card", "shipped_tables", "TABLE_TITLES"]

#: How the card names the paper's tables.
TABLE_TITLES = {"table2": "Table 2", "supp_table4": "supplement Table 4", "table3": "Table 3",
                "supp_table2": "supplement Table 2", "supp_table3": "supplement Table 3"}
_SYMBOL_WORDS = {">": "better", "<": "worse", "=": "level"}


def _fmt(metric: str, mean: float, half: float | None = None) -> str:
    scale, unit = (100.0, " cm") if metric == "MPJPE" else (1.0, "")
    digits = 3 if metric != "FID" or abs(mean) < 10 else 1
    text = f"{mean * scale:.{digits}f}"
    if half is not None:
        text += f" ± {half * scale:.{digits}f}"
    return text + unit


def _protocol(kind: str, settings) -> str:
    s = settings
    samples = f"at most {s.max_samples} clips" if s.max_samples else "the whole split"
    if kind == "vae":
        return (f"reconstruction FID and MPJPE (posterior mean) of the `{s.split}` split's crops, {s.replications} "
                f"replications of {samples} (batches of {s.batch_size}), seed {s.seed}; mean ± 1.96 std / sqrt(R)")
    return (f"the T2M protocol on the `{s.split}` split, {s.replications} replications of {samples} (batches of "
            f"{s.batch_size}), {s.num_steps} sampler steps, w {s.guidance_scale:g}, MultiModality "
            f"{'on' if s.mm else 'off'}, seed {s.seed}; mean ± 1.96 std / sqrt(R)")


def _stage_list(evaluations: Sequence[Mapping[str, Any]]) -> str:
    return ", ".join(f"{doc['steps']:,}" for doc in evaluations)


def _paired_cell(final: Mapping[str, Any], ordering: Mapping[str, Any]) -> str:
    """The paired-advantage cell of one ordering (``-`` when the rows carry no per-replication values)."""
    metric, rows = ordering["metric"], final["rows"]
    try:
        a, b = rows[ordering["a"]]["values"][metric], rows[ordering["b"]]["values"][metric]
    except KeyError:
        return "-"
    mean, half = paired_advantage(a, b, metric)
    return _fmt(metric, mean, half) + (" `*`" if abs(mean) > half else "")


def _table_section(table: str, rows: Mapping[str, str], final: Mapping[str, Any],
                   evaluations: Sequence[Mapping[str, Any]], kind: str) -> list[str]:
    metrics = TABLE_METRICS[kind]
    head = ["row (ours)", "variant", "steps", *[f"{m} (ours)" for m in metrics], "paper row",
            *[f"{m} (paper)" for m in metrics]]
    lines = [f"### {TABLE_TITLES[table]}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for variant, paper_row in rows.items():
        row = final["rows"][variant]
        ours = [_fmt(m, *row["summary"][m]) for m in metrics]
        paper = [_fmt(m, *paper_value(table, paper_row, m)) for m in metrics]
        lines.append("| " + " | ".join([row["label"], f"`{variant}`", f"{row['steps']:,}", *ours,
                                        f"paper: {paper_row}", *paper]) + " |")
    if kind == "denoiser" and final.get("real"):
        real = final["real"]["summary"]
        lines.append("| Real motion (test split) | - | - | " + " | ".join(_fmt(m, *real[m]) for m in metrics)
                     + " | - | " + " | ".join("-" for _ in metrics) + " |")
    stages = [doc["steps"] for doc in evaluations]
    keys = [k for k, o in final["orderings"].items() if o["table"] == table]
    if keys:
        lines += ["", "Orderings (`>`: the first row is better, `<`: worse, `=`: level"
                  + (", i.e. 95 % intervals overlap" if final.get("compare", "intervals") == "intervals" else "")
                  + "):", "",
                  "| pair | metric | " + " | ".join(f"ours at {s:,}" for s in stages)
                  + f" | paper | agrees | our intervals separate | paired advantage at {stages[-1]:,} |",
                  "|" + "---|" * (6 + len(stages))]
        for k in keys:
            o = final["orderings"][k]
            history = [doc["orderings"][k]["ours"] for doc in evaluations]
            lines.append(f"| `{o['a']}` vs `{o['b']}` | {o['metric']} | " + " | ".join(f"`{h}`" for h in history)
                         + f" | `{o['paper']}` | {'yes' if o['agrees'] else 'no'} | {'yes' if o['separated'] else 'no'} | "
                         + _paired_cell(final, o) + " |")
        lines += ["", "*Paired advantage*: the first row's advantage over the second (positive: better), replication "
                  "by replication on the same crops, captions and noise, mean ± 95 % half-width; `*` where that "
                  "interval excludes 0. It is a second reading of a level pair (the stop rule and the columns "
                  "before it compare the two rows' own intervals)."]
    return lines + [""]


def model_card(outcomes: Mapping[str, Any], *, command: str, recipe_path: str = "", data: str = "",
               size_mb: float | None = None, date: str | None = None, version: str = "0.4",
               probes: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """The card's Markdown.

    Parameters
    ----------
    outcomes : dict
        Group name -> :class:`~salad_lab.runner.GroupOutcome` (or any object with ``group``,
        ``decision`` and ``evaluations``).
    command : str
        The command that trains, evaluates and ships everything (quoted in the card).
    recipe_path, data : str
        The recipe and corpus, named in the card.
    size_mb : float, optional
        The shipped folder's size.
    date : str, optional
    probes : dict, optional
        Probe records (:mod:`~salad_lab.probes`); those made on a group's final stage are printed
        beside its tables with the commands that made them.
    """
    out = [f"# salad ablation models (version {version}, staged study)", "",
           "Small models of the paper's ablations (Table 2, Table 3, supplement Tables 2-4), trained on salad's "
           "procedural corpus, every variant of a table at exactly the same steps, each group of tables until the "
           "orderings of its paper pairs were the same at two consecutive evaluations or its budget was spent. "
           "They are **not** the shipped SALAD model, and no number here is comparable with the paper's HumanML3D "
           "numbers: the paper's figures are printed beside ours, labelled as the paper's, for their *ordering*.", "",
           f"Regenerate everything (training, evaluations, weights and this card) with one command:", "",
           "```bash", command, "```", ""]
    facts = []
    if recipe_path:
        facts.append(f"recipe `{recipe_path}`")
    if data:
        facts.append(f"corpus `{data}`")
    if date:
        facts.append(f"written {date}")
    if size_mb is not None:
        facts.append(f"weights folder {size_mb:.1f} MB (fp16)")
    if facts:
        text = "; ".join(facts)
        out += [text[:1].upper() + text[1:] + ". Load the models with `salad_core.ablation_models.load_ablation_vae` and "
                "`load_ablation_pipeline`; every evaluation is in `evaluations/<group>@<steps>.json` beside this card.", ""]
    for name, outcome in outcomes.items():
        group, decision, evaluations = outcome.group, outcome.decision, outcome.evaluations
        final = evaluations[-1]
        why = ("the orderings were the same at the last evaluations" if decision.reason == "stable"
               else "the budget was spent" if decision.reason == "budget" else "it has not stopped yet")
        out += [f"## Group `{name}` ({'VAEs' if group.kind == 'vae' else 'denoisers'}): {final['steps']:,} steps, "
                f"stopped because {why}", "",
                f"Evaluated at {_stage_list(evaluations)} steps (stages of the recipe: "
                f"{', '.join(f'{s:,}' for s in group.stages)}). Protocol, the same for every row: "
                + _protocol(group.kind, group.evaluation) + ".", ""]
        ev_name = next(iter(final["rows"].values()))["settings"].get("evaluator")
        if ev_name:
            shipped = str(ev_name).replace(os.sep, "/").rstrip("/").endswith("salad_core/weights/evaluator")
            out += [("Evaluator: the shipped procedural-corpus evaluator (`salad_core/weights/evaluator`)." if shipped
                     else f"Evaluator: `{ev_name}`."), ""]
        for table, rows in group.tables.items():
            out += _table_section(table, rows, final, evaluations, group.kind)
        disagree = [o for o in final["orderings"].values() if not o["agrees"]]
        if disagree:
            out += ["Where our ordering differs from the paper's at the final stage: "
                    + "; ".join(f"{TABLE_TITLES[o['table']]} `{o['a']}` vs `{o['b']}` on {o['metric']}: ours "
                                f"{_SYMBOL_WORDS[o['ours']]}, paper {_SYMBOL_WORDS[o['paper']]}" for o in disagree)
                    + ". The notebooks say what was measured and why.", ""]
        stage = final.get("stage", group.stage_name(final["steps"]))
        mine = {k: p for k, p in (probes or {}).items() if p.get("stage") == stage}
        if mine:
            from .probes import probe_markdown

            bases = list(dict.fromkeys(p["base_variant"] for p in mine.values()))
            others = [v for rows in group.tables.values() for v in rows if v not in bases]
            table = probe_markdown({**final, "stage": stage, "kind": group.kind}, mine, bases + list(dict.fromkeys(others)))
            out += ["Probes (`probes.json`): a variant changed in one setting, trained to the same steps outside the "
                    "study and scored with this stage's protocol (the same crops), to measure why an ordering "
                    "differs:", "", table.rstrip(), ""]
            for k, p in mine.items():
                out += [f"Probe `{k}` was made by:", "", "```bash", *p.get("commands", []), "```", ""]
    return "\n".join(out).rstrip() + "\n"


def shipped_tables(root: str | os.PathLike | None = None) -> dict[str, str]:
    """The shipped staged study's paper tables, as the model card prints them: ``{table: markdown}``.

    Each table (keys of :data:`TABLE_TITLES`) gets its rows at the final stage (our figure with its 95 % interval,
    the paper's figure apart) and every paper pair's ordering at each evaluated stage, whether ours agrees and
    whether our intervals separate; read from ``index.json`` and ``evaluations/`` of ``root`` (default: the
    shipped ablation folder) alone, nothing is measured. A folder from the fixed-budget study (no evaluations)
    gives ``{}``; a staged folder whose evaluation files are missing is an error naming the file.
    """
    from .drift import load_group_evaluations
    from .study import ablations_dir, list_ablations

    root = Path(root) if root is not None else ablations_dir()
    index = list_ablations(root)
    staged = {k: e for k, e in index.items() if e.get("evaluation") and e.get("paper_rows")}
    if not staged:
        return {}
    groups: dict[str, dict[str, Any]] = {}
    for entry in staged.values():
        g = groups.setdefault(entry["group"], {"kind": entry["kind"], "final": entry["evaluation"], "tables": {}})
        for table, paper_row in entry["paper_rows"].items():
            g["tables"].setdefault(table, {})[entry["variant"]] = paper_row
    out: dict[str, str] = {}
    for name, g in groups.items():
        final_path = root / g["final"]
        if not final_path.is_file():
            raise FileNotFoundError(f"{final_path} (named by {root / 'index.json'}) is missing: ship the study again")
        evaluations = load_group_evaluations(root, name)
        final = json.loads(final_path.read_text())
        evaluations = [doc for doc in evaluations if doc["steps"] <= final["steps"]]
        for table, rows in g["tables"].items():
            out[table] = "\n".join(_table_section(table, rows, final, evaluations, g["kind"])).rstrip() + "\n"
    return {t: out[t] for t in TABLE_TITLES if t in out}
