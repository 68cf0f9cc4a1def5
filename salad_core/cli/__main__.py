"""``python -m salad_core.cli``: the same as the ``salad`` command."""
import sys

from salad_core.cli import main

sys.exit(main())
