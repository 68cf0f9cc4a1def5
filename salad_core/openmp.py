"""How torch's OpenMP worker threads wait between parallel regions (set before torch loads).

PyTorch's CPU build runs its intra-op parallelism on GNU OpenMP (libgomp). Between two parallel
regions libgomp's worker threads *spin* (``GOMP_SPINCOUNT``, 300,000 iterations by default) before
they sleep. A denoiser step at batch 1 is hundreds of small parallel regions, and on a machine
whose cores are shared with other CPU-bound work the spinning workers burn the time slices the
main thread and the other processes need: on this project's 2-core VM, with other work running,
a paper-configuration step at batch 1 took 1.3-4.6 s with the default and 0.14-0.19 s with
``OMP_WAIT_POLICY=PASSIVE`` (``bench/bench_under_load.py``, same run, 2 threads). On a quiet machine
the passive policy costs instead: 74-81 ms against 57-65 ms per step (the workers' wake-up latency), and
intermediate spin counts (``GOMP_SPINCOUNT`` 20,000 or 200,000) were as fast as the default quiet but
no better than it under load. So the default (``auto``) decides once, when the process starts: passive when
the 1-minute load average is at least 3/4 of the cores (other work is running), the runtime's spinning
default otherwise.

Training runs are the exception: they last hours, and a machine quiet when one starts rarely stays
quiet. A 2-thread VAE trainer started on a quiet machine (spinning workers) fell from 1.6 to 0.05
steps/s once other CPU-bound work arrived, while the passive policy costs a training step nothing on a
quiet machine (VAE step at 2 threads, ``bench/bench_training.py --threads-ab --what vae``, load 1.5:
473 ms passive against 476 ms spinning). So ``auto`` is passive for a training command
(``python -m salad_core.train``, ``torchrun -m salad_core.train``, ``salad train``) whatever the load.

libgomp reads these variables once, when the library is loaded (that is, when ``torch`` is first
imported), so :func:`configure` must run before that. The command line does it
(:func:`salad_core.cli.tune_process`: ``salad``, ``python -m salad_core.cli``, ``python -m salad_core.train``,
``torchrun -m salad_core.train``, ``python -m salad_core.bench``) before a command loads torch; ``import
salad_core`` does not (a library leaves its host process alone). A Python program that wants the same policy
calls :func:`configure` itself, before it imports torch::

    from salad_core import openmp
    openmp.configure()          # then: import torch, salad_core.pipeline, ...

It is a no-op when torch (libgomp) is already loaded, when the user set ``OMP_WAIT_POLICY`` or
``GOMP_SPINCOUNT`` themselves, or when ``SALAD_OMP_WAIT=keep``. :func:`wait_policy` says what is
in force. ``SALAD_OMP_WAIT=active`` or ``passive`` chooses explicitly; ``auto`` is the default.
"""
from __future__ import annotations

import os
import sys

__all__ = ["configure", "wait_policy", "ENV_VAR", "DEFAULT_POLICY"]

#: ``auto`` (default: passive on a busy machine, else the runtime's default), ``keep`` (the runtime's
#: default), ``passive`` or ``active`` (set ``OMP_WAIT_POLICY`` before torch loads).
ENV_VAR = "SALAD_OMP_WAIT"
#: The choice when ``SALAD_OMP_WAIT`` is not set.
DEFAULT_POLICY = "auto"
#: ``auto`` goes passive when the 1-minute load average is at least this share of the cores.
BUSY_SHARE = 0.75

_state: dict[str, str] = {"policy": "not configured", "reason": ""}


def _openmp_loaded() -> bool:
    """Whether an OpenMP runtime is already mapped into this process (then it is too late)."""
    if "torch" in sys.modules:
        return True
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            return any(("libgomp" in line or "libiomp" in line or "libomp" in line) for line in maps)
    except OSError:           # not Linux: only the torch check above applies
        return False


def _busy(load: float | None, cores: int | None) -> bool:
    if load is None:
        try:
            load = os.getloadavg()[0]
        except (OSError, AttributeError):     # no load average (Windows): assume quiet
            return False
    cores = cores or os.cpu_count() or 1
    return load >= BUSY_SHARE * cores


def _is_training_command(argv: list[str] | None = None) -> bool:
    """Whether this process was started as a training run (the module or the ``salad train`` verb).

    ``sys.orig_argv`` keeps the interpreter's own arguments (``-m salad_core.train``), which
    ``sys.argv`` does not show while the package is being imported.
    """
    argv = list(getattr(sys, "orig_argv", sys.argv)) if argv is None else list(argv)
    for i, arg in enumerate(argv):
        if arg == "-m" and i + 1 < len(argv) and argv[i + 1].startswith("salad_core.train"):
            return True
        if arg.startswith("-msalad_core.train"):
            return True
    for i, arg in enumerate(argv[:-1]):
        if os.path.basename(arg) == "salad" and argv[i + 1] == "train":
            return True
    return False


def configure(environ: dict[str, str] | None = None, *, load: float | None = None,
              cores: int | None = None, argv: list[str] | None = None) -> str:
    """Set ``OMP_WAIT_POLICY`` for this process if nothing chose one yet; returns the policy in force.

    The command line calls it before a command loads torch; call it yourself, before importing torch, for the
    same policy in your own program (``import salad_core`` does not call it).

    Parameters
    ----------
    environ : mapping, optional
        The environment to read and change (default ``os.environ``; tests pass a dict).
    load, cores : optional
        The 1-minute load average and the core count ``auto`` compares (default: this machine's).
    argv : list of str, optional
        The command line ``auto`` reads to recognise a training run (default ``sys.orig_argv``).

    Returns
    -------
    str
        ``"passive"`` or ``"active"`` when salad set it, ``"user: ..."`` when the user's variables
        decide, ``"runtime default"`` when it was too late or ``SALAD_OMP_WAIT=keep``.
    """
    env = os.environ if environ is None else environ
    choice = env.get(ENV_VAR, DEFAULT_POLICY).strip().lower()
    if choice not in ("auto", "passive", "active", "keep"):
        raise ValueError(f"{ENV_VAR}={env.get(ENV_VAR)!r}; allowed: auto, passive, active, keep")
    user = [f"{k}={env[k]}" for k in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT") if k in env]
    training = choice == "auto" and _is_training_command(argv)
    if user:
        policy, reason = "user: " + ", ".join(user), "set in the environment"
    elif choice == "keep":
        policy, reason = "runtime default", f"{ENV_VAR}=keep"
    elif choice == "auto" and not training and not _busy(load, cores):
        policy, reason = "runtime default", "auto: the machine was not busy when configured"
    elif environ is None and _openmp_loaded():
        policy, reason = "runtime default", "torch was imported before the policy was chosen"
    else:
        chosen = "passive" if choice == "auto" else choice
        env["OMP_WAIT_POLICY"] = chosen.upper()
        policy = chosen
        why = "a training run; " if training else "the machine was busy; "
        reason = (f"auto: {why}" if choice == "auto" else "") + "set by salad_core before torch loaded"
    if environ is None:
        _state.update(policy=policy, reason=reason)
    return policy


def wait_policy() -> str:
    """What :func:`configure` found or set for this process, with the reason."""
    return f"{_state['policy']} ({_state['reason']})" if _state["reason"] else _state["policy"]
