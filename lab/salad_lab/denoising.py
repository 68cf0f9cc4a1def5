"""The record of ``lab/scripts/ablations/ablation_denoising_error.py``: the study's denoisers' estimates of the clean latent per
timestep (:mod:`salad_core.eval.denoising_error`), summarised per variant and paired with the first, and as markdown
tables for notebook 07 (issue 24)."""
from __future__ import annotations

__all__ = ["summarise", "denoising_markdown", "text_response", "text_response_markdown"]


def _short(x: float, sign: str = "") -> str:
    """Two significant digits, without an exponent for the hundreds (``-176``, not ``-1.8e+02``)."""
    return f"{x:{sign}.0f}" if abs(x) >= 100 else f"{x:{sign}.2g}"


def summarise(results: dict, first: str) -> dict:
    """Per variant: ``means`` and, against ``first``, ``paired`` ``{metric: {mode: {t: [mean, half]}}}``."""
    from salad_core.eval.denoising_error import paired_difference

    out = {}
    base = results[first]
    for name, r in results.items():
        row = {"prediction_type": r.prediction_type, "latent_shape": list(r.latent_shape), "means": r.means(),
               "fid_clean": r.fid_clean}
        if name != first:
            paired = {}
            for metric in ("latent", "joints"):
                if metric == "latent" and r.latent_shape != base.latent_shape:
                    continue                              # another VAE: its latent space is not comparable
                mine, theirs = getattr(r, metric), getattr(base, metric)
                paired[metric] = {mode: {t: list(paired_difference(v, theirs[mode][t])) for t, v in per_t.items()}
                                  for mode, per_t in mine.items()}
            row["paired_vs_" + first] = paired
        out[name] = row
    return out


def denoising_markdown(record: dict, metric: str = "joints", mode: str = "guided", timesteps=None) -> str:
    """One row per variant, one column per timestep: the mean, and for the other variants the paired difference
    from the first (``+``: the first is better)."""
    first = record["first"]
    rows = record["variants"]
    ts = [str(t) for t in (timesteps or record["timesteps"])]
    unit = "cm" if metric == "joints" else ""
    first_col = f"variant ({metric}, {mode}{', ' + unit if unit else ''})"
    if metric == "fid":
        first_col = f"variant (FID, {mode}; decoded clean latents)"
    scale = 100.0 if metric == "joints" else 1.0
    lines = [f"| {first_col} | " + " | ".join(f"t={t}" for t in ts) + " |",
             "|---|" + "---|" * len(ts)]
    for name, row in rows.items():
        means = row["means"][metric][mode]
        cells = []
        for t in ts:
            cell = f"{means[t] * scale:.3g}"
            paired = row.get(f"paired_vs_{first}", {}).get(metric, {}).get(mode, {}).get(t)
            if paired is not None:
                cell += f" ({_short(paired[0] * scale, '+')} ± {_short(paired[1] * scale)})"
            cells.append(cell)
        label = f"{name} ({row['fid_clean']:.3g})" if metric == "fid" and row.get("fid_clean") is not None else name
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def text_response(record: dict, variant: str) -> dict[str, dict[str, float]]:
    """The size of a denoiser's text response, read from a record with the ``cond``, ``uncond`` and ``guided`` latent
    errors (``lab/scripts/ablations/ablation_denoising_error.py --unconditional``); nothing is measured here.

    With ``c``, ``u`` the conditional and unconditional estimates of the clean latent ``x0`` and the guided one
    ``g = u + w (c - u)``, per clip ``|c - x0|^2 = |u - x0|^2 + 2 <u - x0, c - u> + |c - u|^2`` and ``|g - x0|^2 =
    |u - x0|^2 + 2 w <u - x0, c - u> + w^2 |c - u|^2``; the record's means of the three errors (per latent element, in
    the denoiser's normalised latent space) therefore give the means of ``|c - u|^2`` (how far the caption moves the
    estimate) and ``<u - x0, c - u>`` exactly. Returns ``{t: {"response": mean |c - u|^2, "relative": that over the
    conditional error, "cosine": <u - x0, c - u> / sqrt(|u - x0|^2 |c - u|^2)}}`` (means, so the cosine is of the
    means: negative when the caption moves the estimate towards the clean latent)."""
    w = float(record["guidance_scale"])
    if w in (0.0, 1.0):
        raise ValueError(f"guidance weight {w:g}: the guided error gives nothing beyond the other two")
    means = record["variants"][variant]["means"]["latent"]
    if not {"cond", "uncond", "guided"} <= set(means):
        raise ValueError(f"{variant}'s record has modes {sorted(means)}: measure it with --unconditional")
    out = {}
    for t in record["timesteps"]:
        t = str(t)
        c, a, g = means["cond"][t], means["uncond"][t], means["guided"][t]
        d = (g - a - w * (c - a)) / (w * w - w)
        x = (c - a - d) / 2
        out[t] = {"response": d, "relative": d / c if c > 0 else float("nan"),
                  "cosine": x / (a * d) ** 0.5 if a > 0 and d > 0 else float("nan")}
    return out


def text_response_markdown(record: dict, timesteps=None) -> str:
    """:func:`text_response` of every variant of ``record`` as a table: per timestep, the text response's size over
    the conditional error (and the cosine between the unconditional error and the response)."""
    ts = [str(t) for t in (timesteps or record["timesteps"])]
    lines = ["| variant (‖c - u‖² / ‖c - x0‖², cosine) | " + " | ".join(f"t={t}" for t in ts) + " |",
             "|---|" + "---|" * len(ts)]
    for name in record["variants"]:
        r = text_response(record, name)
        lines.append(f"| {name} | " + " | ".join(f"{r[t]['relative']:.3f} ({r[t]['cosine']:+.2f})" for t in ts) + " |")
    return "\n".join(lines)
