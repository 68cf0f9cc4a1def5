"""Time keyframe selection on a 196-frame, 263-d motion with K = 20 (KeyMotion issue target: ms).

Usage: python bench/bench_keyframes.py
"""
import time

import numpy as np

from salad_core.keymotion import select_keyframes


def main() -> None:
    x = np.cumsum(np.random.default_rng(0).normal(size=(196, 263)), 0).astype(np.float32)
    print(f"{'method':8s} {'median ms':>10s} {'min ms':>8s}  (196 frames x 263 dims, K=20, 20 runs)")
    for method in ("uniform", "mdo", "mieo"):
        select_keyframes(x, 20, method)
        times = []
        for _ in range(20):
            t0 = time.perf_counter()
            select_keyframes(x, 20, method)
            times.append((time.perf_counter() - t0) * 1e3)
        print(f"{method:8s} {np.median(times):10.2f} {min(times):8.2f}")


if __name__ == "__main__":
    main()
