"""``python -m salad_core.bench``: the same as ``salad bench``."""
import sys

from .cli import main

sys.exit(main())
