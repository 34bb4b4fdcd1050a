"""`python -m lavendersim` — the same as the `lavendersim` command."""
import sys

from .cli import main

sys.exit(main())
