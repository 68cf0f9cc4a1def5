"""``python -m salad_core.bench``: the same as ``salad bench``. The process is tuned first (OpenMP wait policy,
allocator; :func:`salad_core.cli.tune_process`), before the benchmarks load torch: importing ``salad_core.bench``
itself loads nothing heavy."""
import sys

from salad_core.cli import tune_process

tune_process()
from salad_core.cli.bench import main  # noqa: E402  (after the OpenMP policy is chosen)

sys.exit(main())
