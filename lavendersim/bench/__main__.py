"""`python -m lavendersim.bench` — the same as `lavendersim bench` (its options are in lavendersim.cli.bench)."""
import sys

from lavendersim.cli import main

sys.exit(main(["bench", *sys.argv[1:]]))
