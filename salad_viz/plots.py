"""Evaluation figures from plain tables: the CFG sweep of SALAD Fig. 5.

Functions here take a pandas DataFrame whose columns follow the evaluation tables'
convention (``salad_core.eval.tables.results_frame``): a ``name`` column, one column per metric
(e.g. ``"FID"``, ``"R-precision top-3"``) with its 95% half-width in ``metric + " ±"``, and the
settings ``kind`` (``"real"``, ``"generator"`` or ``"paper"``), ``guidance_scale`` and ``quick``.
Any frame with those columns will do (our results, the paper's numbers, a CSV read back).
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["R_PRECISION_COLUMNS", "plot_cfg_sweep"]

#: The R-precision columns a CFG-sweep plot can show.
R_PRECISION_COLUMNS = ("R-precision top-1", "R-precision top-2", "R-precision top-3")


def plot_cfg_sweep(df: Any, r_precision: str = "R-precision top-3", figsize: tuple[float, float] = (9.0, 3.6),
                   *, ci_suffix: str = " ±"):
    """FID and R-precision against the CFG weight ``w`` (SALAD Fig. 5), with 95% CI error bars.

    Parameters
    ----------
    df : pandas.DataFrame
        One row per evaluated setting: ``name``, ``FID`` and ``r_precision`` (their half-widths in
        ``FID ±`` and ``<r_precision> ±``), ``guidance_scale`` and optionally ``kind`` and
        ``quick``. Rows with a ``guidance_scale`` that are not ``kind == "real"`` are drawn, one
        line per name stem (the name without a trailing ``" w=<number>"``). A ``kind == "real"``
        row, if present, is a dashed horizontal line.
    r_precision : str
        Which R-precision column to plot (the paper's figure uses top-3); one of
        :data:`R_PRECISION_COLUMNS`.
    figsize : (float, float)
        Inches.
    ci_suffix : str
        Suffix of the half-width columns.

    Returns
    -------
    matplotlib.figure.Figure
        Two axes: ``axes[0]`` FID, ``axes[1]`` R-precision. Built without pyplot (Agg canvas), so it
        leaks no global state; a notebook shows it as a cell's value.
    """
    import pandas as pd
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas DataFrame of evaluation results, got {type(df).__name__}")
    if r_precision not in R_PRECISION_COLUMNS:
        raise ValueError(f"r_precision={r_precision!r}; allowed: {R_PRECISION_COLUMNS}")
    needed = ["name", "FID", "FID" + ci_suffix, r_precision, r_precision + ci_suffix]
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise ValueError(f"the DataFrame lacks the columns {missing}; build it with "
                         "salad_core.eval.tables.results_frame(results)")
    kind = df["kind"] if "kind" in df.columns else pd.Series(["generator"] * len(df), index=df.index)
    gen = df[(kind != "real") & df["guidance_scale"].notna()] if "guidance_scale" in df.columns else df.iloc[0:0]
    if gen.empty:
        raise ValueError("no generator rows with a guidance_scale to plot; build df from cfg_sweep results")
    real = df[kind == "real"]
    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    stems = gen["name"].astype(str).str.replace(r"\s+w=[-+0-9.eE]+$", "", regex=True)
    # any row of a quick run marks the whole figure (missing values are not quick)
    quick = "quick" in df.columns and any(bool(v) for v in df["quick"].tolist()
                                          if v is not None and not (isinstance(v, float) and np.isnan(v)))
    for ax, metric in zip(axes, ("FID", r_precision)):
        for stem in dict.fromkeys(stems):
            rows = gen[stems == stem].sort_values("guidance_scale")
            ax.errorbar(rows["guidance_scale"].astype(float).to_numpy(), rows[metric].to_numpy(float),
                        yerr=rows[metric + ci_suffix].to_numpy(float), marker="o", capsize=3, label=stem)
        for _, r in real.iterrows():
            ax.axhline(float(r[metric]), color="0.4", linestyle="--", linewidth=1.0, label=str(r["name"]))
        ax.set_xlabel("CFG weight w")
        ax.set_ylabel(metric)
        ax.grid(alpha=0.3)
    axes[0].set_title("FID (lower is better)")
    axes[1].set_title(f"{r_precision} (higher is better)")
    axes[1].legend(fontsize=8)
    if quick:
        fig.suptitle("QUICK MODE: not the full protocol", color="tab:red")
    return fig
