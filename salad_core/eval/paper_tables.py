"""The SALAD paper's published numbers, in the shape of our own tables, for display beside them.

Everything here is copied from the paper (SALAD, CVPR 2025, and its supplement) and labelled as such
(row names ``"paper: ..."``, ``kind == "paper"``, ``data`` naming the table); nothing is computed.

- :data:`PAPER_TABLE1`, :func:`paper_table1`: Table 1, text-to-motion on HumanML3D and KIT-ML
  (SALAD and the methods it compares with);
- :data:`PAPER_CFG_SWEEP`, :func:`paper_cfg_sweep`: supplement Table 1, SALAD at every CFG weight
  (the numbers behind Fig. 5);
- :data:`PAPER_DENOISER_ABLATIONS`, :func:`paper_denoiser_ablations`: Table 3 and supplement
  Tables 2-3 (R-precision top-3 and FID);
- :data:`PAPER_VAE_TABLES`, :func:`paper_vae_tables`: Table 2 and supplement Table 4 (VAE
  reconstruction: parameters, FID, MPJPE).

Generation rows come out as :func:`~salad_core.eval.tables.results_frame`-shaped frames, to pass as
``reference=`` to :func:`~salad_core.eval.tables.to_markdown`; VAE rows as
:func:`~salad_core.eval.reconstruction.reconstruction_frame`-shaped frames.
"""
from __future__ import annotations

from typing import Sequence

import pandas as pd

from salad_core.skeleton import get_skeleton

from .settings import METRICS, REAL_NAME
from .tables import paper_frame, paper_row

__all__ = [
    "PAPER_TABLE1",
    "PAPER_TABLE1_DEFAULT_ROWS",
    "paper_table1",
    "PAPER_CFG_SWEEP",
    "paper_cfg_sweep",
    "PAPER_DENOISER_ABLATIONS",
    "paper_denoiser_ablations",
    "PAPER_VAE_TABLES",
    "paper_vae_tables",
]

_NA = None   # a cell the paper prints as "-"

# SALAD (CVPR 2025) Table 1, test sets: method -> (top-1, top-2, top-3, FID, MM-Dist, Diversity,
# MultiModality) as (mean, 95% half-width), in METRICS order. Copied from the paper; never computed.
PAPER_TABLE1: dict[str, dict[str, tuple]] = {
    "humanml3d": {
        "Real motion": ((.511, .003), (.703, .003), (.797, .002), (.002, .000), (2.974, .008), (9.503, .065), _NA),
        "T2M": ((.457, .002), (.639, .003), (.740, .003), (1.067, .002), (3.340, .008), (9.188, .002), (2.090, .083)),
        "AttT2M": ((.499, .003), (.690, .002), (.786, .002), (.112, .006), (3.038, .007), (9.700, .090), (2.452, .051)),
        "ParCo": ((.515, .003), (.706, .003), (.801, .002), (.109, .005), (2.927, .008), (9.576, .088), (1.382, .060)),
        "MoMask": ((.521, .002), (.713, .002), (.807, .002), (.045, .002), (2.958, .008), _NA, (1.241, .040)),
        "MDM": ((.320, .005), (.498, .004), (.611, .007), (.544, .044), (5.566, .027), (9.559, .086), (2.799, .072)),
        "MLD": ((.481, .003), (.673, .003), (.772, .002), (.473, .013), (3.196, .010), (9.724, .082), (2.413, .079)),
        "MotionDiffuse": ((.491, .001), (.681, .001), (.782, .001), (.630, .001), (3.113, .001), (9.410, .049),
                          (1.553, .042)),
        "ReMoDiffuse": ((.510, .005), (.698, .006), (.795, .004), (.103, .004), (2.974, .016), (9.018, .075),
                        (1.795, .043)),
        "SALAD": ((.581, .003), (.769, .003), (.857, .002), (.076, .002), (2.649, .009), (9.696, .096), (1.751, .062)),
    },
    "kit": {
        "Real motion": ((.424, .005), (.649, .006), (.779, .006), (.031, .004), (2.788, .012), (11.08, .097), _NA),
        "T2M": ((.370, .005), (.569, .007), (.693, .007), (2.770, .109), (3.401, .008), (10.91, .119), (1.482, .065)),
        "AttT2M": ((.413, .006), (.632, .006), (.751, .006), (.870, .039), (3.039, .021), (10.96, .123), (2.281, .047)),
        "ParCo": ((.430, .004), (.649, .007), (.772, .006), (.453, .027), (2.820, .028), (10.95, .094), (1.245, .022)),
        "MoMask": ((.433, .007), (.656, .005), (.781, .005), (.204, .011), (2.779, .022), _NA, (1.131, .043)),
        "MDM": ((.164, .004), (.291, .004), (.396, .004), (.497, .021), (9.191, .022), (10.847, .109), (1.907, .214)),
        "MLD": ((.390, .008), (.609, .008), (.734, .007), (.404, .027), (3.204, .027), (10.80, .117), (2.192, .071)),
        "MotionDiffuse": ((.417, .004), (.621, .004), (.739, .004), (1.954, .062), (2.958, .005), (11.10, .143),
                          (.730, .013)),
        "ReMoDiffuse": ((.427, .014), (.641, .004), (.765, .055), (.155, .006), (2.814, .012), (10.80, .105),
                        (1.239, .028)),
        "SALAD": ((.477, .006), (.711, .005), (.828, .005), (.296, .012), (2.585, .016), (11.097, .095), (1.004, .040)),
    },
}
#: Rows :func:`paper_table1` shows by default (the rows this project reproduces).
PAPER_TABLE1_DEFAULT_ROWS = ("Real motion", "SALAD")


def paper_table1(dataset: str = "humanml3d",
                 methods: Sequence[str] | None = PAPER_TABLE1_DEFAULT_ROWS) -> pd.DataFrame:
    """SALAD Table 1 (published numbers) as a :func:`~salad_core.eval.tables.results_frame`-shaped frame.

    Parameters
    ----------
    dataset : {"humanml3d", "kit"}
    methods : sequence of str or None
        Rows in this order (default: Real motion and SALAD); None: every row of the table.

    Returns
    -------
    DataFrame
        Rows named ``"paper: <method>"`` with ``kind == "paper"``; cells the paper prints as "-"
        are NaN. Pass it as ``reference=`` to :func:`~salad_core.eval.tables.to_markdown`.
    """
    key = get_skeleton(dataset).name
    if key not in PAPER_TABLE1:
        raise ValueError(f"dataset={dataset!r}: the paper's Table 1 covers {sorted(PAPER_TABLE1)}")
    table = PAPER_TABLE1[key]
    names = list(table) if methods is None else list(methods)
    unknown = [m for m in names if m not in table]
    if unknown or not names:
        raise ValueError(f"methods={unknown or names!r} are not rows of the paper's Table 1; rows: {list(table)}")
    source = f"SALAD paper (CVPR 2025), Table 1 ({key})"
    return paper_frame([paper_row(method, dict(zip(METRICS, table[method])), source) for method in names])


# SALAD (CVPR 2025) denoiser ablations, HumanML3D test set (supp. Table 3 also KIT-ML): method ->
# (R-precision top-3, FID) as (mean, 95% half-width). Copied from the paper; never computed.
PAPER_DENOISER_ABLATIONS: dict[str, dict[str, dict[str, tuple]]] = {
    "table3": {"humanml3d": {
        "Full model": ((.857, .002), (.076, .002)),
        "w/o ST-Latent": ((.816, .002), (.433, .006)),
        "w/o CrossAttn": ((.778, .002), (.274, .007)),
        "w/o both": ((.752, .002), (.345, .007)),
    }},
    "supp_table2": {"humanml3d": {
        "x-prediction": ((.860, .002), (.111, .003)),
        "epsilon-prediction": ((.803, .002), (.257, .008)),
        "v-prediction": ((.857, .002), (.076, .002)),
    }},
    "supp_table3": {
        "humanml3d": {"with FiLM": ((.857, .002), (.076, .002)), "without FiLM": ((.843, .002), (.087, .003))},
        "kit": {"with FiLM": ((.828, .005), (.296, .012)), "without FiLM": ((.803, .006), (.311, .013))},
    },
}
_TABLE_TITLES = {"table3": "Table 3", "supp_table2": "supplement Table 2", "supp_table3": "supplement Table 3"}


def paper_denoiser_ablations(which: str = "table3", dataset: str = "humanml3d") -> pd.DataFrame:
    """The paper's denoiser ablations (R-precision top-3 and FID only) as a results-frame-shaped
    DataFrame with rows ``"paper: <method>"``, for ``to_markdown(ours, reference=...)``.

    ``which``: ``"table3"`` (w/o ST-Latent, w/o CrossAttn, both), ``"supp_table2"`` (the three
    diffusion parametrisations) or ``"supp_table3"`` (FiLM; HumanML3D and KIT-ML).
    """
    if which not in PAPER_DENOISER_ABLATIONS:
        raise ValueError(f"which={which!r}; choose one of {sorted(PAPER_DENOISER_ABLATIONS)}")
    key = get_skeleton(dataset).name
    tables = PAPER_DENOISER_ABLATIONS[which]
    if key not in tables:
        raise ValueError(f"the paper's {_TABLE_TITLES[which]} has no {key!r} rows; it covers {sorted(tables)}")
    source = f"SALAD paper (CVPR 2025), {_TABLE_TITLES[which]} ({key})"
    return paper_frame([paper_row(method, {"R-precision top-3": top3, "FID": fid}, source)
                        for method, (top3, fid) in tables[key].items()])


# SALAD supplement Table 1 (not the paper's Table 1, which is PAPER_TABLE1), v-prediction, 50 DDIM
# steps: CFG weight -> top-1, top-2, top-3, FID, MM-Dist, Diversity as printed (mean, 95%
# half-width). Published numbers, never computed here.
PAPER_CFG_SWEEP: dict[str, dict[str | float, tuple]] = {
    "humanml3d": {
        "Real motion": ((.511, .003), (.703, .003), (.797, .002), (.002, .000), (2.974, .008), (9.503, .065)),
        1.5: ((.438, .003), (.622, .002), (.727, .002), (1.291, .020), (3.411, .011), (9.298, .085)),
        2.5: ((.517, .003), (.705, .002), (.801, .002), (.457, .011), (2.945, .011), (9.616, .089)),
        3.5: ((.548, .003), (.738, .002), (.829, .002), (.223, .006), (2.782, .009), (9.711, .092)),
        4.5: ((.563, .003), (.755, .002), (.842, .002), (.132, .004), (2.711, .008), (9.737, .090)),
        5.5: ((.573, .003), (.763, .002), (.850, .002), (.093, .003), (2.674, .008), (9.741, .094)),
        6.5: ((.578, .003), (.767, .002), (.854, .002), (.078, .003), (2.656, .009), (9.722, .095)),
        7.5: ((.581, .003), (.769, .003), (.857, .002), (.076, .002), (2.649, .009), (9.696, .096)),
        8.5: ((.581, .003), (.770, .002), (.857, .002), (.083, .002), (2.650, .009), (9.669, .094)),
        9.5: ((.581, .003), (.771, .002), (.858, .002), (.097, .003), (2.655, .009), (9.638, .093)),
        10.5: ((.581, .003), (.770, .002), (.857, .001), (.116, .003), (2.663, .008), (9.608, .094)),
        11.5: ((.581, .002), (.769, .002), (.857, .002), (.138, .003), (2.673, .008), (9.577, .093)),
        12.5: ((.578, .002), (.768, .002), (.856, .002), (.164, .003), (2.686, .008), (9.657, .091)),
    },
    "kit": {
        "Real motion": ((.424, .005), (.649, .006), (.779, .006), (.031, .004), (2.788, .012), (11.08, .097)),
        1.5: ((.439, .005), (.656, .006), (.774, .007), (.837, .033), (2.755, .018), (11.033, .115)),
        2.5: ((.471, .006), (.691, .005), (.809, .005), (.489, .017), (2.593, .013), (11.085, .118)),
        3.5: ((.480, .006), (.706, .005), (.818, .006), (.396, .013), (2.562, .013), (11.086, .120)),
        4.5: ((.484, .006), (.709, .005), (.823, .006), (.352, .011), (2.559, .015), (11.083, .122)),
        5.5: ((.484, .006), (.710, .005), (.824, .006), (.324, .009), (2.571, .016), (11.078, .122)),
        6.5: ((.481, .007), (.708, .006), (.824, .006), (.308, .009), (2.588, .016), (11.077, .119)),
        7.5: ((.480, .007), (.707, .006), (.826, .006), (.298, .009), (2.608, .015), (11.079, .119)),
        8.5: ((.476, .008), (.705, .005), (.823, .006), (.294, .008), (2.630, .015), (11.083, .120)),
        9.5: ((.477, .007), (.704, .005), (.822, .005), (.294, .008), (2.651, .015), (11.089, .120)),
        10.5: ((.474, .006), (.703, .005), (.820, .006), (.297, .009), (2.674, .015), (11.096, .121)),
        11.5: ((.472, .006), (.702, .006), (.818, .006), (.303, .009), (2.697, .015), (11.102, .121)),
        12.5: ((.471, .006), (.697, .006), (.815, .006), (.311, .010), (2.719, .015), (11.108, .122)),
    },
}


def paper_cfg_sweep(dataset: str = "humanml3d") -> pd.DataFrame:
    """The SALAD paper's own CFG sweep (supplement Table 1) as a results-frame-shaped DataFrame.

    Rows are named ``"paper: Real motion"`` and ``"paper: SALAD w=..."``, with ``kind`` ``"paper"``
    and ``data`` naming the source. Only for display beside our numbers (``reference=`` of
    :func:`~salad_core.eval.tables.to_markdown` / :func:`~salad_core.eval.tables.to_latex`);
    nothing here is computed.
    """
    key = get_skeleton(dataset).name
    if key not in PAPER_CFG_SWEEP:
        raise ValueError(f"no published CFG sweep for {dataset!r}; available: {sorted(PAPER_CFG_SWEEP)}")
    rows = []
    for w, cells in PAPER_CFG_SWEEP[key].items():
        real = w == "Real motion"
        rows.append(paper_row(REAL_NAME if real else f"SALAD w={w:g}", dict(zip(METRICS[:6], cells)),
                              f"SALAD paper, supplement Table 1 ({key})",
                              guidance_scale=None if real else float(w), num_steps=None if real else 50))
    return paper_frame(rows)


# SALAD (CVPR 2025) Table 2 and supplement Table 4, HumanML3D test set: (params, FID, MPJPE in metres)
# as (mean, 95% half-width). Copied from the paper; never computed.
PAPER_VAE_TABLES: dict[str, dict[str, tuple]] = {
    "table2": {
        "MoMask (VQ-VAE)": (19.44e6, (0.020, 0.000), (0.030, 0.000)),
        "ParCo (part-aware VQ-VAE)": (6.35e6, (0.021, 0.000), (0.108, 0.000)),
        "SALAD (skeleton-aware VAE)": (0.16e6, (0.003, 0.000), (0.016, 0.000)),
    },
    "supp_table4": {
        "Full model": (None, (0.003, 0.000), (0.016, 0.000)),
        "without L_pos": (None, (0.005, 0.000), (0.023, 0.000)),
        "without L_vel": (None, (0.009, 0.000), (0.016, 0.000)),
        "without both": (None, (0.012, 0.000), (0.024, 0.000)),
    },
}


def paper_vae_tables(which: str = "table2") -> pd.DataFrame:
    """The paper's VAE numbers (HumanML3D test set), rows named ``"paper: ..."``.

    ``which``: ``"table2"`` (MoMask, ParCo and SALAD VAEs: parameters, FID, MPJPE) or
    ``"supp_table4"`` (the VAE loss-term ablation). MPJPE in metres, as
    :func:`~salad_core.eval.reconstruction.reconstruction_frame` gives it.
    """
    tables = PAPER_VAE_TABLES
    if which not in tables:
        raise ValueError(f"which={which!r}; choose one of {sorted(tables)}")
    rows = []
    for method, (params, fid, err) in tables[which].items():
        rows.append({"name": f"paper: {method}", "parameters": params, "FID": fid[0], "FID ±": fid[1],
                     "MPJPE": err[0], "MPJPE ±": err[1], "kind": "paper",
                     "data": f"SALAD paper (CVPR 2025), {'Table 2' if which == 'table2' else 'supp. Table 4'}"})
    return pd.DataFrame(rows)
