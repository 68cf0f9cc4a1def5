"""``salad bench``: how fast salad runs on this machine, as one table measured in one run.

Seven sections, each a function returning rows of the table (:class:`Row`), run in this order:

* ``memory``: peak memory of one generation with streaming attention capture (the default
  ``capture_attention=True``, a running mean per step bin) at 50 and at 200 DDIM steps: the peak
  resident set size (RSS) during the call minus the RSS before it. On Linux the kernel's
  high-water mark ``VmHWM`` is reset before each call (``/proc/self/clear_refs``), elsewhere the
  process peak ``ru_maxrss`` is used (a delta then only shows growth beyond earlier peaks). It runs
  first, before large batches have grown the process.
* ``overheads``: wall time of attention capture, of each edit (word swap, refinement, re-weighting,
  mirroring) and of inversion relative to a plain generation of the same prompt, every variant
  timed in the same rounds, interleaved, so that a busy machine slows all of them alike (medians).
  The full plan also times 32 prompts through the pipeline one at a time, in one batch, and in
  chunks of 8 (:func:`batching_rows`; the pipeline's default chunk is 32 with the tuned allocator).
* ``speed``: seconds per motion of the denoiser alone (random text features: the text encoder is
  excluded; VAE decoding too, which costs under 1 % of 50 steps) for 196 frames, 50 DDIM steps,
  guidance 7.5 (both branches in one batched forward), at batch 1 and 32, for the paper
  configuration and the shipped default, and for a 120-frame motion with the shipped default.
  Beside each, the *roofline* row: the denoiser's achieved GFLOP/s (FLOPs per step computed from
  the configuration by :func:`gemm_flops`) against this machine's matmul GFLOP/s at the same
  shapes, measured by running the step's own matrix products alone right after every timed step
  (:func:`step_products`, :func:`paired_step_times`); the fraction is the median over those pairs of
  products time over step time. Where sampling folds the cross-attention (fewer FLOPs than the
  configuration's count), the note gives the same fraction against the products actually run, and
  the older per-shape yardstick (:func:`matmul_rates`) for comparison.
* ``training``: optimiser steps per second of the VAE and of the denoiser on random data, with the
  shipped recipe's model configs and batch sizes (``runs.json`` beside the shipped weights, else
  the library defaults). The denoiser step is the trainer's own
  (:func:`~salad_core.train.denoiser_trainer.prepare_denoiser_batch`: frozen-VAE encoding, noising,
  caption dropping; then forward, backward, AdamW), with random text features.

* ``train`` (opt-in: it builds a small procedural corpus, unless ``--train-data`` names one, and a
  latent cache; a few minutes): where a denoiser training step goes, part by part (data, VAE
  latents, text features, noising, forward, backward, clipping, optimiser, logging, validation;
  :mod:`salad_core.train.profile`), for the trainer *before* the issue-19 changes (random batches,
  VAE encoder at every step) and *after* (length buckets, latent cache), steps interleaved in one
  process; ``ratio`` = before / after (a speed-up). Shipped VAE and MiniLM, the shipped recipe's
  denoiser and batch size.

* ``realtime`` (opt-in): a whole 196-frame generation at batch 1 with the few-step weights distilled from the
  default ones (``--realtime DIR``, else the shipped ``salad_realtime`` folder, else a stand-in of the same cost:
  the default weights sampled with the ``lcm`` solver, its steps, no guidance; the notes say which), side by side
  with the default's 50 guided DDIM steps in interleaved rounds; ratio = realtime / default, and the realtime time
  against the 0.1 s target.

* ``compile`` (opt-in, not part of the default run: compiling takes about a minute): one guided
  forward of the shipped default denoiser (196 frames, batch 1) eager against ``torch.compile``
  (inductor), the compile time and the number of 50-step generations after which compiling pays
  for itself. If compiling fails, the row says so and sampling is unaffected (salad never compiles
  by default).

``salad bench`` (:func:`salad_core.cli.bench.main`) runs with the tuned allocator of :mod:`salad_core.allocator`, as the
``salad`` command does (``SALAD_ALLOCATOR=system`` for glibc's default); the header says which. Freed
memory then stays with the process, so the memory rows measure growth beyond what it already holds.

``--quick`` (about a minute) times fewer steps and rounds, measures batch 32 on one step and
extrapolates to 50 (every DDIM step costs the same), uses 120-frame motions for the overheads and
the memory, and says so in the notes under the table.

One job per module:

``plan``              constants, :class:`Row`, :class:`Case` and the quick/full :class:`Plan`
``flops``             the FLOP model (:func:`gemm_flops`, :func:`step_flops`)
``inputs``            the timed configurations and the random inputs of a step
``roofline``          matmul rates, a step's own products, steps and products timed side by side
``speed``             the ``speed`` section (and the forward variants)
``overheads``         the ``overheads`` section and pipeline batching
``naive_algorithm1``  the official code's three-forward Algorithm 1 (a strategy of the one
                      denoising loop), the overheads' reference
``memory``            the ``memory`` section (peak RSS)
``training``          the ``training`` and ``train`` sections
``compile_trial``     the opt-in ``compile`` section
``realtime``          the opt-in ``realtime`` section
``run``               :func:`run_benchmarks`: every section into one table
``table``             the table as Markdown

The command line (``salad bench``, ``python -m salad_core.bench``) is :mod:`salad_core.cli.bench`.
"""

from salad_core.lazy import lazy_exports

#: The public names and the module each comes from.
_EXPORTS: dict[str, str] = {
    "compile_rows": "compile_trial", "ONCE_PER_CALL": "flops", "gemm_flops": "flops", "step_flops": "flops",
    "attended_tokens": "inputs", "denoiser_cases": "inputs", "folded_keys": "inputs", "random_inputs": "inputs",
    "memory_rows": "memory", "peak_rss_delta": "memory", "NaiveAlgorithm1Prediction": "naive_algorithm1",
    "batching_rows": "overheads", "bench_pipeline": "overheads",
    "overhead_rows": "overheads", "BATCHES": "plan", "COLUMNS": "plan", "GUIDANCE": "plan",
    "MOTION_FRAMES": "plan", "OPTIONAL_SECTIONS": "plan", "PROMPT_TOKENS": "plan", "REFINED": "plan",
    "SAMPLING_STEPS": "plan", "SECTIONS": "plan", "SHORT_FRAMES": "plan", "SKELETON": "plan", "SOURCE": "plan",
    "SWAPPED": "plan", "Case": "plan", "Plan": "plan", "Row": "plan", "best_rates": "roofline",
    "matmul_rates": "roofline", "matmul_rates_by_backend": "roofline", "paired_step_times": "roofline",
    "roofline_seconds": "roofline", "step_products": "roofline", "REALTIME_TARGET_S": "realtime",
    "realtime_pipelines": "realtime", "realtime_rows": "realtime", "run_benchmarks": "run",
    "forward_variant_rows": "speed", "speed_rows": "speed", "time_denoiser_steps": "speed",
    "format_table": "table", "machine_header": "table", "TrainRecipe": "training",
    "train_profile_rows": "training", "train_recipe": "training", "training_rows": "training",
}

__all__ = ["Row", "Case", "Plan", "SECTIONS", "OPTIONAL_SECTIONS", "compile_rows", "train_profile_rows",
           "batching_rows", "gemm_flops", "step_flops", "matmul_rates", "attended_tokens", "matmul_rates_by_backend",
           "roofline_seconds", "time_denoiser_steps", "speed_rows", "forward_variant_rows", "overhead_rows",
           "training_rows", "memory_rows", "peak_rss_delta", "denoiser_cases", "TrainRecipe", "train_recipe",
           "bench_pipeline", "machine_header", "run_benchmarks", "format_table",
           # public since the split into a package
           "ONCE_PER_CALL", "step_products", "paired_step_times", "folded_keys", "best_rates", "random_inputs",
           "NaiveAlgorithm1Prediction", "BATCHES", "COLUMNS", "GUIDANCE",
           "MOTION_FRAMES", "PROMPT_TOKENS", "REFINED", "SAMPLING_STEPS", "SHORT_FRAMES", "SKELETON", "SOURCE",
           "SWAPPED"]


# imported on first use: importing the package loads no torch (python -m tunes the process first)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
