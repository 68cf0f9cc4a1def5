"""The opt-in ``compile`` section: one guided forward eager against ``torch.compile`` (inductor).

salad never compiles by default; this says what compiling would buy on this machine and after how
many generations it pays for itself. A failure to compile is a measurement (in the row's note).
"""
from __future__ import annotations

import time

import numpy as np
import torch

from salad_core.models.denoiser import Denoiser

from .inputs import random_inputs
from .plan import MOTION_FRAMES, SAMPLING_STEPS, SKELETON, Case, Row

__all__ = ["compile_rows"]


def compile_rows(case: Case, batch: int = 1, reps: int = 10) -> list[Row]:
    """Best seconds of one guided forward eager vs ``torch.compile`` (inductor, static shapes), the
    compile time, and after how many 50-step generations compiling pays off. A failure to compile
    is reported in the row's note (value NaN), not raised."""
    torch.manual_seed(0)
    model = Denoiser(case.config).eval()
    cond, _, noise, fm = random_inputs(case, 2 * batch, MOTION_FRAMES // SKELETON.unit_length)
    ctx = model.prepare_text(*cond)
    t = torch.tensor([500])
    setting = f"{case.name}, {MOTION_FRAMES} frames, batch {batch}"

    def timed(fn) -> float:
        best = float("inf")
        with torch.inference_mode():
            for _ in range(reps):
                t0 = time.perf_counter()
                fn()
                best = min(best, time.perf_counter() - t0)
        return best

    with torch.inference_mode():
        eager_out = model(noise, t, frame_mask=fm, text_context=ctx)
    eager = timed(lambda: model(noise, t, frame_mask=fm, text_context=ctx))
    try:
        compiled = torch.compile(model, dynamic=False)
        t0 = time.perf_counter()
        with torch.inference_mode():
            out = compiled(noise, t, frame_mask=fm, text_context=ctx)
        compile_s = time.perf_counter() - t0
    except Exception as err:  # noqa: BLE001 - any backend failure is a measurement, not a crash
        return [Row("compile", "forward, torch.compile", setting, float("nan"), "s", reference=eager,
                    note=f"torch.compile failed ({type(err).__name__}: {str(err).splitlines()[0][:120]})")]
    fast = timed(lambda: compiled(noise, t, frame_mask=fm, text_context=ctx))
    diff = float((out - eager_out).abs().max())
    saved = (eager - fast) * SAMPLING_STEPS
    payoff = compile_s / saved if saved > 0 else float("inf")
    return [Row("compile", "forward, torch.compile (inductor)", setting, fast, "s", reference=eager,
                ratio=fast / eager, note=f"vs eager (best of {reps}); max |difference| {diff:.1e}"),
            Row("compile", "compile time (first call)", setting, compile_s, "s",
                note=f"pays off after {payoff:.0f} generations of {SAMPLING_STEPS} steps" if np.isfinite(payoff)
                else "never pays off: the compiled forward is not faster")]
