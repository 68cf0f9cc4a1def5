"""Results as tables: a pandas DataFrame of :class:`~salad_core.eval.settings.EvalResult` objects, and
Markdown / LaTeX renderings of it that state how the numbers were made.

- :func:`results_frame`: one row per result (each metric's mean and ``" ±"`` 95% half-width, then
  the settings recorded with it);
- :func:`to_markdown`, :func:`to_latex`: the frame with a settings note (quick mode first and loud)
  and, optionally, published numbers below ours (``reference=``, rows labelled as the paper's);
- :func:`paper_row`, :func:`paper_frame`: published rows in the same shape
  (:mod:`salad_core.eval.paper_tables` builds them);
- :func:`format_mean_ci`: ``"0.511 ± 0.003"``.

The CFG-sweep figure drawn from such a frame is :func:`salad_viz.plots.plot_cfg_sweep`.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from .settings import CI_SUFFIX, METRICS, PROTOCOL_REPLICATIONS, SETTING_COLUMNS, EvalResult, protocol_deviations

__all__ = ["results_frame", "format_mean_ci", "to_markdown", "to_latex", "paper_row", "paper_frame", "check_frame"]

#: Direction marks of the paper's tables (higher, lower, closer to real is better).
_ARROWS = {"R-precision top-1": "↑", "R-precision top-2": "↑", "R-precision top-3": "↑", "FID": "↓",
           "MM-Dist": "↓", "Diversity": "→", "MultiModality": "↑"}
_LATEX_ARROWS = {"↑": r"$\uparrow$", "↓": r"$\downarrow$", "→": r"$\rightarrow$"}


def results_frame(results: Sequence[EvalResult]) -> pd.DataFrame:
    """One row per result: ``name``, each metric's mean and its ``" ±"`` half-width, then the settings.

    Metrics a result did not compute (MultiModality with ``mm`` off, or for the real row) are NaN.
    """
    if not results:
        raise ValueError("results is empty")
    rows = []
    for res in results:
        if not isinstance(res, EvalResult):
            raise TypeError(f"results must hold EvalResult objects, got {type(res).__name__}")
        row: dict[str, Any] = {"name": res.name}
        summ = res.summary()
        for m in METRICS:
            mean, half = summ.get(m, (np.nan, np.nan))
            row[m], row[m + CI_SUFFIX] = mean, half
        for k in SETTING_COLUMNS:
            row[k] = res.settings.get(k)
        rows.append(row)
    return pd.DataFrame(rows, columns=["name", *[c for m in METRICS for c in (m, m + CI_SUFFIX)], *SETTING_COLUMNS])


def format_mean_ci(mean: float, half: float, digits: int = 3, latex: bool = False) -> str:
    """``"0.511 ± 0.003"`` (LaTeX ``"$0.511^{\\pm 0.003}$"``); NaN gives ``"-"``."""
    if mean is None or half is None or not np.isfinite(mean):
        return "-"
    if not np.isfinite(half):
        return f"{mean:.{digits}f}"
    if latex:
        return f"${mean:.{digits}f}^{{\\pm {half:.{digits}f}}}$"
    return f"{mean:.{digits}f} ± {half:.{digits}f}"


def check_frame(df: pd.DataFrame) -> None:
    """Raise unless ``df`` is a DataFrame with a ``name`` column and every metric column."""
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"expected the DataFrame of results_frame(...), got {type(df).__name__}")
    missing = [c for c in ("name", *METRICS) if c not in df.columns]
    if missing:
        raise ValueError(f"the DataFrame lacks the columns {missing}; build it with results_frame(results)")


def _shown_metrics(*frames: pd.DataFrame) -> list[str]:
    return [m for m in METRICS if any(f[m].notna().any() for f in frames)]


def _kind(df: pd.DataFrame) -> pd.Series:
    return df["kind"] if "kind" in df.columns else pd.Series(["generator"] * len(df), index=df.index)


def _unique(df: pd.DataFrame, key: str) -> list:
    if key not in df.columns:
        return []
    return list(dict.fromkeys(v for v in df[key].tolist()
                              if v is not None and not (isinstance(v, float) and np.isnan(v))))


#: Table headers of the generation settings that may become columns.
_SETTING_LABELS = {"guidance_scale": "w", "num_steps": "steps", "solver": "solver", "weights": "weights"}
#: Generation settings: read from generator rows only (the real row generates nothing).
_GEN_SETTINGS = ("guidance_scale", "num_steps", "solver", "weights", "mm")


def _varying_settings(*frames: pd.DataFrame) -> list[str]:
    """Generation settings that differ between generator rows (shown as table columns)."""
    out = []
    for k in ("guidance_scale", "num_steps", "solver", "weights"):
        if any(len(_unique(f[_kind(f) == "generator"], k)) > 1 for f in frames):
            out.append(k)
    return out


def _fmt_setting(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "on" if v else "off"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):g}"
    return str(v)


def _note(df: pd.DataFrame) -> str:
    """Settings shared by the rows, as one sentence; quick mode first and loud."""
    quick = any(bool(v) for v in _unique(df, "quick"))
    gen_rows = df[_kind(df) == "generator"]
    short: list[str] = []
    for _, r in df.iterrows():
        mm = r.get("mm") if _kind(df).loc[r.name] == "generator" else None     # the real row has no MultiModality
        for d in protocol_deviations(r.get("replications"), r.get("max_samples"), mm):
            if d not in short:
                short.append(d)
    if quick:
        parts = ["QUICK MODE: fewer replications and samples than the protocol, not comparable with published "
                 "numbers"]
    elif short:
        parts = [f"Reduced T2M protocol ({', '.join(short)}), not comparable with published numbers"]
    else:
        parts = ["Full T2M protocol"]
    for label, key in (("split", "split"), ("batch", "batch_size"), ("replications", "replications"),
                       ("samples/replication", "samples"), ("MultiModality", "mm"), ("steps", "num_steps"),
                       ("w", "guidance_scale"), ("solver", "solver"), ("seed", "seed"), ("weights", "weights"),
                       ("evaluator", "evaluator"), ("data", "data")):
        vals = _unique(gen_rows if key in _GEN_SETTINGS else df, key)
        if key == "solver" and not vals and len(gen_rows):
            vals = ["generator default"]
        if len(vals) == 1:
            parts.append(f"{label} {_fmt_setting(vals[0])}")
        elif len(vals) > 1:
            parts.append(f"{label} varies (see table)")
    return "; ".join(parts) + ". Mean ± 1.96·std/√R over R replications."


def _cells(df: pd.DataFrame, digits: int, latex: bool, shown: list[str],
           extra: list[str]) -> tuple[list[str], list[list[str]]]:
    header = ["Method", *[_SETTING_LABELS[k] for k in extra], *[f"{m} {_ARROWS[m]}" for m in shown]]
    rows = []
    for _, r in df.iterrows():
        cells = [str(r["name"])]
        for k in extra:
            v = r.get(k)
            cells.append("-" if v is None or (isinstance(v, float) and np.isnan(v)) else _fmt_setting(v))
        for m in shown:
            half = r.get(m + CI_SUFFIX, np.nan)
            cells.append(format_mean_ci(r[m], np.nan if half is None else half, digits, latex))
        rows.append(cells)
    return header, rows


def to_markdown(df: pd.DataFrame, digits: int = 3, reference: pd.DataFrame | None = None) -> str:
    """A Markdown table of ``results_frame(...)`` with a settings note (quick mode stated first).

    Parameters
    ----------
    df : DataFrame from :func:`results_frame`
    digits : int
    reference : DataFrame, optional
        Published numbers to show in a separate table below ours, e.g.
        :func:`~salad_core.eval.paper_tables.paper_cfg_sweep`; their row names must say they are the
        paper's (:func:`paper_row` names them ``"paper: ..."``).
    """
    check_frame(df)
    header, rows = _cells(df, digits, False, _shown_metrics(df), _varying_settings(df))
    lines = [f"**{_note(df)}**", ""]
    lines += _markdown_table(header, rows)
    if reference is not None:
        _check_reference(reference)
        rh, rr = _cells(reference, digits, False, _shown_metrics(reference), _varying_settings(reference))
        lines += ["", "Published numbers (copied from the paper, not computed here):", ""]
        lines += _markdown_table(rh, rr)
    return "\n".join(lines) + "\n"


def _markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    # pandas.DataFrame.to_markdown needs the optional tabulate package; this is all we need of it
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    fmt = lambda cells: "| " + " | ".join(c.ljust(w) for c, w in zip(cells, widths)) + " |"  # noqa: E731
    align = "|" + "|".join(":" + "-" * (w + 1) if i == 0 else "-" * (w + 1) + ":" for i, w in enumerate(widths)) + "|"
    return [fmt(header), align, *[fmt(r) for r in rows]]


def _check_reference(reference: pd.DataFrame) -> None:
    check_frame(reference)
    unlabeled = [n for n in reference["name"] if "paper" not in str(n).lower()]
    if unlabeled:
        raise ValueError(f"reference rows must be labelled as published numbers (name containing 'paper'); "
                         f"got {unlabeled[:3]}")


_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "_": r"\_", "#": r"\#", "$": r"\$",
                  "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "±": r"$\pm$",
                  "·": r"$\cdot$"}


def _latex_escape(s: str) -> str:
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in s)


def to_latex(df: pd.DataFrame, digits: int = 3, reference: pd.DataFrame | None = None) -> str:
    """A booktabs ``tabular`` of ``results_frame(...)``; the settings note is a LaTeX comment above it.

    ``reference`` rows (e.g. :func:`~salad_core.eval.paper_tables.paper_cfg_sweep`) follow a
    ``\\midrule`` under a heading that marks them as the paper's, and must be labelled so in their names.
    """
    check_frame(df)
    frames = [df] if reference is None else [df, reference]
    if reference is not None:
        _check_reference(reference)
    shown, extra = _shown_metrics(*frames), _varying_settings(*frames)
    header, rows = _cells(df, digits, True, shown, extra)
    ref_rows = _cells(reference, digits, True, shown, extra)[1] if reference is not None else []
    head = [_latex_escape(h) for h in header]
    for a, b in _LATEX_ARROWS.items():
        head = [h.replace(a, b) for h in head]
    lines = [f"% {_note(df)}", r"\begin{tabular}{l" + "c" * (len(header) - 1) + "}", r"\toprule",
             " & ".join(head) + r" \\", r"\midrule"]
    lines += [" & ".join([_latex_escape(r[0]), *r[1:]]) + r" \\" for r in rows]
    if ref_rows:
        lines += [r"\midrule",
                  r"\multicolumn{" + str(len(header)) + r"}{l}{\emph{Published (copied from the paper)}} \\"]
        lines += [" & ".join([_latex_escape(r[0]), *r[1:]]) + r" \\" for r in ref_rows]
    lines += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


def paper_row(name: str, cells: Mapping[str, tuple[float, float] | None], source: str, **settings: Any) -> dict:
    """One published row in the shape of :func:`results_frame`: ``"paper: <name>"``, the given
    metrics as ``(mean, 95% half-width)`` (None or absent: NaN, a cell the paper does not print),
    ``kind="paper"``, the protocol's split/batch/replications, ``data=source`` and ``settings``."""
    unknown = set(cells) - set(METRICS)
    if unknown:
        raise ValueError(f"unknown metrics {sorted(unknown)}; known: {METRICS}")
    row: dict[str, Any] = {"name": f"paper: {name}"}
    for m in METRICS:
        cell = cells.get(m)
        row[m], row[m + CI_SUFFIX] = cell if cell is not None else (np.nan, np.nan)
    row.update({k: None for k in SETTING_COLUMNS})
    row.update(kind="paper", split="test", batch_size=32, replications=PROTOCOL_REPLICATIONS, data=source,
               **settings)
    return row


def paper_frame(rows: Sequence[dict]) -> pd.DataFrame:
    """Rows of :func:`paper_row` as a DataFrame with :func:`results_frame`'s columns."""
    return pd.DataFrame(list(rows), columns=["name", *[c for m in METRICS for c in (m, m + CI_SUFFIX)],
                                             *SETTING_COLUMNS])
