"""The former name of :mod:`lavendersim.oracle` (the deliberately independent accuracy references), kept only
until the labs import it by its name; use ``from lavendersim import oracle``."""
from .oracle import *  # noqa: F401,F403
from .oracle import __all__  # noqa: F401
