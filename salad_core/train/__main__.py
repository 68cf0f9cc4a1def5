"""``python -m salad_core.train vae|denoiser|keymotion ...`` (also the target of ``torchrun -m``): the same as
``salad train``. The process is tuned first (OpenMP wait policy, allocator; :func:`salad_core.cli.tune_process`),
before the trainers load torch: importing ``salad_core.train`` itself loads nothing heavy."""
import sys

from salad_core.cli import tune_process

tune_process()
from salad_core.cli.train import main  # noqa: E402  (after the OpenMP policy is chosen)

sys.exit(main())
