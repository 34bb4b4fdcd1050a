"""`python -m lavendersim.bench` — the same as `lavendersim bench`."""
import sys

from . import main

sys.exit(main())
