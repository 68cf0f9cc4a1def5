"""The orderings of the paper's ablation tables that the study reproduces, and how one is read.

This module is the one place that says *which pairs of rows* each paper table compares
(:data:`PAPER_PAIRS`, in the paper's own row labels) and *on which metrics*
(:data:`TABLE_METRICS`). The *direction* the paper claims is not written here: it is read from the
published numbers in :mod:`salad_core.eval.paper_tables` (:func:`paper_ordering`), with the same rule
that reads our own numbers (:func:`compare`), so a claim and its measurement are judged alike.

An ordering is one of three symbols, always from the first row's point of view:

* ``">"``: the first row is better (lower FID / MPJPE, higher R-precision);
* ``"<"``: the first row is worse;
* ``"="``: level. With ``mode="intervals"`` (the default) two rows are level when their 95 %
  intervals overlap (``|a - b| <= half_a + half_b``), so an ordering is only claimed when the
  intervals separate; with ``mode="means"`` only exactly equal means are level.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

__all__ = ["PAPER_PAIRS", "TABLE_METRICS", "BETTER", "COMPARE_MODES", "KIND_OF_TABLE", "compare", "paired_advantage",
           "paper_value", "paper_ordering", "paper_rows", "pair_key", "check_table_rows"]

#: Paper table -> the pairs of rows it compares (paper row labels; the first is the paper's model).
PAPER_PAIRS: dict[str, tuple[tuple[str, str], ...]] = {
    "table2": (("SALAD (skeleton-aware VAE)", "MoMask (VQ-VAE)"),),
    "supp_table4": (("Full model", "without L_pos"), ("Full model", "without L_vel"),
                    ("Full model", "without both")),
    "table3": (("Full model", "w/o ST-Latent"), ("Full model", "w/o CrossAttn"), ("Full model", "w/o both")),
    "supp_table2": (("v-prediction", "epsilon-prediction"), ("v-prediction", "x-prediction")),
    "supp_table3": (("with FiLM", "without FiLM"),),
}
#: Paper table -> "vae" (reconstruction tables) or "denoiser" (generation tables).
KIND_OF_TABLE = {"table2": "vae", "supp_table4": "vae", "table3": "denoiser", "supp_table2": "denoiser",
                 "supp_table3": "denoiser"}
#: Metrics whose ordering is compared, per kind of table (those the paper's tables print).
TABLE_METRICS = {"vae": ("FID", "MPJPE"), "denoiser": ("FID", "R-precision top-3")}
#: Which way is better for each compared metric.
BETTER = {"FID": "lower", "MPJPE": "lower", "R-precision top-3": "higher"}
#: Values of ``mode`` in :func:`compare`.
COMPARE_MODES = ("intervals", "means")


def pair_key(table: str, a: str, b: str, metric: str) -> str:
    """The key of one ordering in an evaluation file: ``"table3: full vs no_st, FID"``."""
    return f"{table}: {a} vs {b}, {metric}"


def compare(a: tuple[float, float], b: tuple[float, float], metric: str, mode: str = "intervals") -> str:
    """The ordering of row ``a`` against row ``b`` on ``metric`` (see the module docstring).

    Parameters
    ----------
    a, b : (mean, 95% half-width)
    metric : str
        A key of :data:`BETTER`.
    mode : {"intervals", "means"}

    Returns
    -------
    str
        ``">"`` (``a`` better), ``"<"`` (``a`` worse) or ``"="`` (level).
    """
    if metric not in BETTER:
        raise ValueError(f"metric={metric!r} has no ordering; allowed: {sorted(BETTER)}")
    if mode not in COMPARE_MODES:
        raise ValueError(f"mode={mode!r} is invalid; allowed: {COMPARE_MODES}")
    (ma, ha), (mb, hb) = (tuple(float(v) for v in a), tuple(float(v) for v in b))
    if not all(math.isfinite(v) for v in (ma, ha, mb, hb)):
        raise ValueError(f"cannot order non-finite values a={a!r}, b={b!r} on {metric}")
    diff = ma - mb
    if diff == 0 or (mode == "intervals" and abs(diff) <= abs(ha) + abs(hb)):
        return "="
    a_better = diff < 0 if BETTER[metric] == "lower" else diff > 0
    return ">" if a_better else "<"


def paired_advantage(a: Sequence[float], b: Sequence[float], metric: str) -> tuple[float, float]:
    """Row ``a``'s advantage over row ``b`` on ``metric``, replication by replication.

    Every row of a stage is scored on the same crops, captions and noise seeds in each replication, so
    the per-replication differences are paired: their spread leaves out what the replication itself
    does to both rows (an easy or hard draw of crops), and their interval is narrower than the
    two rows' intervals together. The stop rule does not use it (:func:`compare` does); the card prints
    it beside the orderings as a second reading of a level pair.

    Parameters
    ----------
    a, b : sequence of float ``(R,)``
        The two rows' values of ``metric`` per replication, in replication order.
    metric : str
        A key of :data:`BETTER`.

    Returns
    -------
    (mean, half) : tuple of float
        The mean advantage (positive: ``a`` better, i.e. ``b - a`` for a lower-is-better metric) and its
        95 % half-width, as every interval of the protocol (:func:`salad_core.eval.metrics.mean_ci`:
        ``1.96 std / sqrt(R)``, population std; 0 for one replication).
    """
    if metric not in BETTER:
        raise ValueError(f"metric={metric!r} has no ordering; allowed: {sorted(BETTER)}")
    a, b = [float(v) for v in a], [float(v) for v in b]
    if len(a) != len(b) or not a:
        raise ValueError(f"paired values need the same replications on both rows, got {len(a)} and {len(b)}")
    if not all(math.isfinite(v) for v in a + b):
        raise ValueError(f"cannot pair non-finite values a={a!r}, b={b!r} on {metric}")
    from salad_core.eval.metrics import mean_ci

    sign = -1.0 if BETTER[metric] == "lower" else 1.0
    mean, half = mean_ci([sign * (x - y) for x, y in zip(a, b)])
    return float(mean), float(half)


def paper_rows(table: str) -> tuple[str, ...]:
    """The row labels of a paper table (HumanML3D), as :mod:`~salad_core.eval.paper_tables` holds them."""
    from salad_core.eval.paper_tables import PAPER_DENOISER_ABLATIONS, PAPER_VAE_TABLES

    if table in PAPER_VAE_TABLES:
        return tuple(PAPER_VAE_TABLES[table])
    if table in PAPER_DENOISER_ABLATIONS:
        return tuple(PAPER_DENOISER_ABLATIONS[table]["humanml3d"])
    raise ValueError(f"table={table!r} is not one of the paper's ablation tables; allowed: {sorted(PAPER_PAIRS)}")


def paper_value(table: str, row: str, metric: str) -> tuple[float, float]:
    """``(mean, 95% half-width)`` the paper prints for ``row`` of ``table`` (HumanML3D), read from
    :mod:`salad_core.eval.paper_tables`; MPJPE in metres."""
    from salad_core.eval.paper_tables import PAPER_DENOISER_ABLATIONS, PAPER_VAE_TABLES

    rows = paper_rows(table)
    if row not in rows:
        raise ValueError(f"row={row!r} is not a row of the paper's {table}; rows: {list(rows)}")
    if table in PAPER_VAE_TABLES:
        _, fid, mpjpe = PAPER_VAE_TABLES[table][row]
        cells = {"FID": fid, "MPJPE": mpjpe}
    else:
        top3, fid = PAPER_DENOISER_ABLATIONS[table]["humanml3d"][row]
        cells = {"FID": fid, "R-precision top-3": top3}
    if metric not in cells:
        raise ValueError(f"metric={metric!r} is not printed in the paper's {table}; it has {sorted(cells)}")
    mean, half = cells[metric]
    return float(mean), float(half)


def paper_ordering(table: str, a: str, b: str, metric: str, mode: str = "intervals") -> str:
    """The ordering the paper's numbers give row ``a`` against row ``b`` (paper labels) on ``metric``."""
    return compare(paper_value(table, a, metric), paper_value(table, b, metric), metric, mode)


def check_table_rows(table: str, rows: Mapping[str, str]) -> None:
    """Raise ``ValueError`` unless every label in ``rows`` (variant -> paper label) is a row of ``table``."""
    known = paper_rows(table)
    bad = sorted(label for label in rows.values() if label not in known)
    if bad:
        raise ValueError(f"paper rows {bad} are not rows of the paper's {table}; rows: {list(known)}")
