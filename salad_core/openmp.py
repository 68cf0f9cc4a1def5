"""How torch's OpenMP worker threads wait between parallel regions (set before torch loads).

PyTorch's CPU build runs its intra-op parallelism on GNU OpenMP (libgomp). Between two parallel
regions libgomp's worker threads *spin* (``GOMP_SPINCOUNT``, 300,000 iterations by default) before
they sleep. A denoiser step at batch 1 is hundreds of small parallel regions, and on a machine
whose cores are shared with other CPU-bound work the spinning workers burn the time slices the
main thread and the other processes need: on this project's 2-core VM, with other work running,
a paper-configuration step at batch 1 took 1.3-4.6 s with the default and 0.14-0.19 s with
``OMP_WAIT_POLICY=PASSIVE`` (``bench/bench_under_load.py``, same run, 2 threads).

libgomp reads these variables once, when the library is loaded (that is, when ``torch`` is first
imported), so :func:`configure` must run before that: ``import salad_core`` does it, and it is a
no-op when torch (libgomp) is already loaded, when the user set ``OMP_WAIT_POLICY`` or
``GOMP_SPINCOUNT`` themselves, or when ``SALAD_OMP_WAIT=keep``. :func:`wait_policy` says what is
in force. ``SALAD_OMP_WAIT=active`` or ``passive`` chooses explicitly.
"""
from __future__ import annotations

import os
import sys

__all__ = ["configure", "wait_policy", "ENV_VAR", "DEFAULT_POLICY"]

#: ``keep`` leaves the OpenMP runtime's defaults; ``passive`` (default) or ``active`` sets
#: ``OMP_WAIT_POLICY`` before torch loads.
ENV_VAR = "SALAD_OMP_WAIT"
#: The wait policy salad sets when nothing else chose one.
DEFAULT_POLICY = "passive"

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


def configure(environ: dict[str, str] | None = None) -> str:
    """Set ``OMP_WAIT_POLICY`` for this process if nothing chose one yet; returns the policy in force.

    Parameters
    ----------
    environ : mapping, optional
        The environment to read and change (default ``os.environ``; tests pass a dict).

    Returns
    -------
    str
        ``"passive"`` or ``"active"`` when salad set it, ``"user: ..."`` when the user's variables
        decide, ``"runtime default"`` when it was too late or ``SALAD_OMP_WAIT=keep``.
    """
    env = os.environ if environ is None else environ
    choice = env.get(ENV_VAR, DEFAULT_POLICY).strip().lower()
    if choice not in ("passive", "active", "keep"):
        raise ValueError(f"{ENV_VAR}={env.get(ENV_VAR)!r}; allowed: passive, active, keep")
    user = [f"{k}={env[k]}" for k in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT") if k in env]
    if user:
        policy, reason = "user: " + ", ".join(user), "set in the environment"
    elif choice == "keep":
        policy, reason = "runtime default", f"{ENV_VAR}=keep"
    elif environ is None and _openmp_loaded():
        policy, reason = "runtime default", "torch was imported before salad_core"
    else:
        env["OMP_WAIT_POLICY"] = choice.upper()
        policy, reason = choice, "set by salad_core before torch loaded"
    if environ is None:
        _state.update(policy=policy, reason=reason)
    return policy


def wait_policy() -> str:
    """What :func:`configure` found or set for this process, with the reason."""
    return f"{_state['policy']} ({_state['reason']})" if _state["reason"] else _state["policy"]
