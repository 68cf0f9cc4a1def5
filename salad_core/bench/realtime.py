"""The ``realtime`` section: a whole generation (text encoding, sampling, decoding, joint recovery) of a
196-frame motion at batch 1 with the few-step ("realtime") weights, side by side with the default weights'
50-step guided sampler, in one process (:func:`~salad_core.bench.interleave.interleaved_medians`).

Without distilled weights (``salad_core/weights/salad_realtime`` missing and none given) the section times a
stand-in and says so: the default weights sampled exactly as a realtime folder is (the ``"lcm"`` solver, its
steps, guidance off, one branch per step). A consistency-distilled student has the teacher's architecture, so
its cost per call is the stand-in's; its quality is not measured here.
"""
from __future__ import annotations

import time
from pathlib import Path

from .interleave import interleaved_medians
from .plan import MOTION_FRAMES, SOURCE, Row

__all__ = ["realtime_pipelines", "realtime_rows", "REALTIME_TARGET_S"]

#: The real-time variant's target: seconds for a 196-frame motion at batch 1 (on 2 threads).
REALTIME_TARGET_S = 0.1


def realtime_pipelines(default, realtime: str | Path | None = None, *, stand_in_steps: int | None = None):
    """``(realtime pipeline, description)``: the realtime folder (``realtime``, else the shipped
    ``salad_core/weights/salad_realtime`` when present) or, without one, a stand-in sharing ``default``'s
    models and sampled with the ``"lcm"`` solver at ``stand_in_steps`` (default: the distillation's export
    default) and guidance off."""
    from salad_core.pipeline import SaladPipeline, realtime_weights_dir
    from salad_core.sampling import Guidance
    from salad_core.train.consistency import DEFAULT_SAMPLE_STEPS

    folder = Path(realtime) if realtime is not None else realtime_weights_dir()
    if realtime is not None or (folder / "pipeline.json").is_file():
        pipe = SaladPipeline.from_pretrained(folder, preset="realtime")
        return pipe, f"realtime weights {pipe.source} ({pipe.solver}, {pipe.num_steps} steps)"
    steps = DEFAULT_SAMPLE_STEPS if stand_in_steps is None else stand_in_steps
    stand_in = SaladPipeline(default.vae, default.denoiser, default.text_encoder, default.mean, default.std,
                             diffusion=default.diffusion, solver="lcm", guidance=Guidance(1.0),
                             recovery=default.recovery, num_steps=steps, latent_stats=default.latent_stats)
    return stand_in, (f"stand-in: no realtime weights in {folder}; the default weights sampled as a realtime "
                      f"folder is (lcm, {steps} steps, no guidance), whose cost a distilled student shares")


def _timed_call(pipe, frames: int, num_steps: int | None):
    def call() -> float:
        t = time.perf_counter()
        pipe(SOURCE, lengths=frames, seed=0, num_steps=num_steps)
        return time.perf_counter() - t
    return call


def realtime_rows(default, realtime=None, *, frames: int = MOTION_FRAMES, rounds: int = 5,
                  default_steps: int = 50) -> tuple[list[Row], str]:
    """Rows: seconds per motion of the default pipeline (``default_steps``, its own guidance) and of the realtime
    one (its own steps; ratio = realtime / default, reference = the default's time), and the realtime time
    against :data:`REALTIME_TARGET_S` (ratio = time / target). ``realtime``: a pipeline, a folder or None
    (:func:`realtime_pipelines`). Returns ``(rows, note)``."""
    from salad_core.pipeline import SaladPipeline

    if isinstance(realtime, SaladPipeline):
        fast, what = realtime, f"realtime pipeline {realtime.source or '(in memory)'}"
    else:
        fast, what = realtime_pipelines(default, realtime)
    slow_s, fast_s = interleaved_medians(_timed_call(default, frames, default_steps), _timed_call(fast, frames, None),
                                         rounds)
    setting = f"{frames} frames, batch 1"
    rows = [Row("realtime", f"default: {default.solver} {default_steps} steps, guidance {default.guidance.scale:g}",
                setting, slow_s, "s/motion"),
            Row("realtime", f"realtime: {fast.solver} {fast.num_steps} steps, guidance {fast.guidance.scale:g}",
                setting, fast_s, "s/motion", slow_s, fast_s / slow_s, "ratio = realtime / default"),
            Row("realtime", "realtime against the target", setting, fast_s, "s/motion", REALTIME_TARGET_S,
                fast_s / REALTIME_TARGET_S, f"target <= {REALTIME_TARGET_S} s (ratio <= 1)")]
    note = (f"realtime: whole calls (text encoding, sampling, decoding, joint recovery), median of {rounds} "
            f"interleaved round(s) after a warm-up of each; {what}")
    return rows, note
