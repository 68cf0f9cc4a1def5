"""``python -m salad_core.train vae|denoiser ...`` (also the target of ``torchrun -m``)."""
import sys

from salad_core.train.cli import main

sys.exit(main())
