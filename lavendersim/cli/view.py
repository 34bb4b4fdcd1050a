"""``lavendersim view NAME``: run a scene live (or recorded, then replayed) in the browser viewer
(:func:`lavendersim.viewer.run_scene`; the viewer extra)."""
from __future__ import annotations

import contextlib
import os
import sys

from . import _common

HELP = "run a scene live in the browser viewer (viewer extra)"


def add_parser(sub) -> None:
    from lavendersim.labs import register_views
    from lavendersim.viewer import DEFAULT_HOST, DEFAULT_PORT, SCENES

    register_views()   # the labs' scenes (lab03) beside the viewer's own, in the help and for run

    v = sub.add_parser("view", help=HELP, parents=[_common.parent(json=False)],
                       description="Run a scene in real time and stream it to a browser page "
                                   f"(scenes: {', '.join(SCENES)}). Needs the viewer extra: pip install -e '.[viewer]'.")
    v.add_argument("scene", metavar="NAME", help=f"scene to run: {', '.join(SCENES)}")
    v.add_argument("--duration", type=float, default=None, help="simulated seconds to run (default: until Ctrl-C)")
    v.add_argument("--host", default=DEFAULT_HOST, help=f"interface to bind (default {DEFAULT_HOST}: this machine only; "
                                                        "0.0.0.0 or :: listens on every interface, with a warning)")
    v.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0 = any free port)")
    v.add_argument("--rate", type=float, default=60.0, help="frames published per second of simulated time (default 60)")
    v.add_argument("--replay", action="store_true",
                   help="record --duration simulated seconds (default 10) first, then replay them with a time slider "
                        "to scrub (until Ctrl-C). Live or replayed, the page's side panel has Pause/Resume, a speed "
                        "slider and checkboxes for the body axes and each vector")
    v.set_defaults(fn=run)


def run(args) -> int:
    from lavendersim import viewer

    with open(os.devnull, "w") if args.quiet else contextlib.nullcontext(sys.stdout) as out:
        try:   # the labs' scenes (lab03) were registered when the parser was built (add_parser)
            viewer.run_scene(args.scene, duration=args.duration, host=args.host, port=args.port, rate_hz=args.rate,
                             replay=args.replay, out=out)
        except viewer.ViewerError as exc:  # a frame could not be drawn: one line, exit 1 (not a usage error)
            return _common.fail(exc, 1, prog="lavendersim view")
    return 0

