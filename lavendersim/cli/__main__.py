"""`python -m lavendersim.cli` — the same as the `lavendersim` command."""
import sys

from . import main

sys.exit(main())
