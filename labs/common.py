"""Shared plumbing of the labs: figure checks, results.json, PNG plots, printing.

A lab's ``run(out_dir, backend=..., **options)`` returns a :class:`LabResult`: a ``dict`` whose
items are exactly what is written to ``OUT/NAME/results.json`` (a flat object of named figures,
the parameters used, one ``check_<name>`` bool per check and ``passed``), plus attributes
``checks`` (list of :class:`Check`), ``files`` (paths written) and ``passed``. ``run`` never
raises because a figure is off; the CLI turns ``passed == False`` into exit code 1 and prints
a message naming the figure, its value, the expected value and the tolerance.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lavendersim import backends
from lavendersim import validate as V
from lavendersim.generated import layout as LY
from lavendersim.kernels import K
from lavendersim.figures import new_figure  # noqa: F401  (the labs' figures; re-exported)

DEFAULT_OUT = "lab-output"
# The most steps a lab's run may take (its duration / dt): labs are demonstrations, and a dt of 1e-300 must
# be a clear error at once, not a run that never ends (lab 04 steps in Python and records every step:
# MAX_PY_STEPS).
MAX_STEPS = 1_000_000
MAX_PY_STEPS = 200_000
BACKENDS = backends.BACKEND_CHOICES  # "auto" (default), "c", "numpy"
# what a lab that steps no scene records as its backend (--backend does not apply to it)
NO_SIMULATOR = "none (kernels evaluated directly with the generated NumPy kernels)"


# --------------------------------------------------------------------------
# checks
# --------------------------------------------------------------------------


# The comparators, defined once: rule -> (test(value, bound, tol), how a report says the expectation).
RULES = {
    "≈": (lambda v, b, tol: abs(v - b) <= tol, "{b} ± {tol}"),
    "<=": (lambda v, b, _: v <= b, "<= {b}"),
    "<": (lambda v, b, _: v < b, "< {b}"),
    ">=": (lambda v, b, _: v >= b, ">= {b}"),
    ">": (lambda v, b, _: v > b, "> {b}"),
}
HOLDS = "holds"     # the rule of a paw-check or failure-mode assertion (value is a bool)


@dataclass(frozen=True)
class Check:
    """One acceptance check of a figure: ``value rule bound`` (and why it is the chapter's figure).

    Parameters
    ----------
    name : str
        The figure's name (results.json gets ``check_<name>``).
    value : float or bool
        The figure (a bool for rule ``"holds"``).
    rule : {"≈", "<=", "<", ">=", ">", "holds"}
        ``"≈"``: |value - bound| <= tol; the others compare value with bound; ``"holds"``: value is true.
    bound : float, optional
        The expected value or the limit.
    tol : float, optional
        Absolute tolerance of a ``"≈"`` check.
    why : str, default ""
        Said after the check in reports (what the figure is, its unit, where the bound comes from).
    """

    name: str
    value: float | bool
    rule: str
    bound: float | None = None
    tol: float | None = None
    why: str = ""

    @property
    def passed(self) -> bool:
        """Whether the check holds (a non-finite value fails every numeric rule).

        Raises
        ------
        ValueError
            Unknown ``rule``.
        """
        if self.rule == HOLDS:
            return bool(self.value)
        if self.rule not in RULES:
            raise ValueError(f"unknown check rule {self.rule!r}")
        return _finite(self.value) and RULES[self.rule][0](float(self.value), self.bound, self.tol)

    @property
    def expected(self) -> float | None:
        """The bound (the expected value of a ``"≈"`` check, the limit of the others; None for ``"holds"``)."""
        return self.bound

    def describe(self) -> str:
        """``name = value (expected ...)`` in words, for PASS and FAIL lines alike."""
        if self.rule == HOLDS:
            text = f"{self.name}: {'holds' if self.value else 'does NOT hold'}"
        else:
            exp = RULES[self.rule][1].format(b=_fmt(self.bound), tol=_fmt(self.tol) if self.tol is not None else "")
            if not _finite(self.value):
                got = "not computed" if math.isnan(float(self.value)) else f"infinite ({_fmt(self.value)})"
                text = f"{self.name}: {got}, expected {exp}"
            else:
                text = f"{self.name} = {_fmt(self.value)}, expected {exp}"
                if self.rule == "≈" and self.bound is not None:
                    text += f" (off by {_fmt(abs(float(self.value) - self.bound))})"
        return text + (f" — {self.why}" if self.why else "")


def finite_or_none(x) -> float | None:
    """float(x) when it is finite, else None (how results.json says a figure was not measured).

    Parameters
    ----------
    x : float or None
        A figure.

    Returns
    -------
    float or None
    """
    return float(x) if x is not None and _finite(x) else None


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def _fmt(x) -> str:
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    x = float(x)
    if x == 0:
        return "0"
    if not math.isfinite(x):
        return repr(x)
    if 1e-4 <= abs(x) < 1e6:
        return f"{x:.10g}"
    return f"{x:.6e}"


def check(name: str, value, rule: str, bound=None, why: str = "") -> Check:
    """One declared check: ``value rule bound``.

    Parameters
    ----------
    name : str
        The figure's name.
    value : float or bool
        The figure (a bool for ``"holds"``).
    rule : {"≈", "<=", "<", ">=", ">", "holds"}
        How value is compared with bound.
    bound : float or (float, float), optional
        The limit; for ``"≈"`` the pair (expected, absolute tolerance); None for ``"holds"``.
    why : str, optional
        Said after the check in reports.

    Returns
    -------
    Check
    """
    if rule == HOLDS:
        return Check(name, bool(value), HOLDS, None, None, why)
    if rule == "≈":
        return Check(name, float(value), rule, float(bound[0]), float(bound[1]), why)
    if rule not in RULES:
        raise ValueError(f"unknown check rule {rule!r}")
    return Check(name, float(value), rule, float(bound), None, why)


def checks(*rows) -> list[Check]:
    """A lab's table of declared checks: one ``(name, value, rule, bound, why)`` row each (see :func:`check`);
    a row that is None or False is left out (a check that does not apply to this run: ``cond and (row)``).

    Parameters
    ----------
    *rows : tuple, None or False
        ``(name, value, rule, bound, why)``.

    Returns
    -------
    list of Check
    """
    return [check(*row) for row in rows if row]


def close(name, value, expected, tol, note="") -> Check:
    """|value - expected| <= tol (the rule ``"≈"``).

    Parameters
    ----------
    name : str
        The figure's name.
    value, expected, tol : float
        The figure, its expected value and the absolute tolerance.
    note : str, optional
        Said after the check in reports.

    Returns
    -------
    Check
    """
    return check(name, value, "≈", (expected, tol), note)


def holds(name, condition, note="") -> Check:
    """A paw-check or failure-mode assertion (the rule ``"holds"``).

    Parameters
    ----------
    name : str
        What is asserted.
    condition : bool
        Whether it holds.
    note : str, optional
        Said after the check in reports.

    Returns
    -------
    Check
    """
    return check(name, condition, HOLDS, None, note)


def _comparator(rule: str, words: str):
    def compare(name, value, limit, note="") -> Check:
        return check(name, value, rule, limit, note)
    compare.__name__ = compare.__qualname__ = words
    compare.__doc__ = f"""value {rule} limit.

    Parameters
    ----------
    name : str
        The figure's name.
    value : float
        The figure.
    limit : float
        The bound.
    note : str, optional
        Said after the check in reports.

    Returns
    -------
    Check
    """
    return compare


at_most, below, at_least, above = (_comparator(r, w) for r, w in
                                   (("<=", "at_most"), ("<", "below"), (">=", "at_least"), (">", "above")))


# --------------------------------------------------------------------------
# the printed measures of a rigid body's state (generated/: kernels and the state layout)
# --------------------------------------------------------------------------

P_W, Q, V_W, OMEGA_B = LY.STATE_P_W, LY.STATE_Q, LY.STATE_V_W, LY.STATE_OMEGA_B   # named slices of a state row


def energy_momentum(I_b, x, m=1.0):
    """Kinetic energy and world angular momentum of rigid-body states, from the printed kernels.

    Parameters
    ----------
    I_b : array_like (..., 3)
        Principal moments, body frame, kg·m².
    x : array_like (..., 13)
        States (generated/layout.py STATE layout: p_w, q (x, y, z, w), v_w, omega_b).
    m : float or array_like (...), default 1.0
        Mass, kg (the labs' bodies have 1 kg).

    Returns
    -------
    T : ndarray (...)
        Kinetic energy (translational plus rotational), J.
    L_w : ndarray (..., 3)
        Angular momentum about the COM, world frame, kg·m²/s.
    """
    x = np.asarray(x, dtype=float)
    w = x[..., OMEGA_B]
    return K.kinetic_energy(m, I_b, x[..., V_W], w), K.angular_momentum_world(x[..., Q], I_b, w)


# --------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------


class LabResult(dict):
    """A lab's results: the flat items of results.json plus ``checks``, ``files``, ``passed``.

    Made by a lab's ``compute(...)`` (:func:`make_result`), which writes nothing; :meth:`save` writes
    ``OUT/lab/results.json``, the PNGs and any extra files. :meth:`figure` draws a plot as a matplotlib
    Figure from the data the computation kept (``data``), without re-running the physics.

    Parameters
    ----------
    lab : str
        The lab's name.
    out_dir : str or Path or None
        Where it was saved (None: not yet).
    items : dict
        The flat results.json items.
    checks : list of Check
    """

    def __init__(self, lab: str, out_dir, items: dict, checks: list[Check]):
        super().__init__(items)
        self.lab = lab
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.checks = list(checks)
        self.files: list[Path] = []
        self.param_names: list[str] = []
        self.figure_names: list[str] = []
        self.data: dict = {}                 # what the plots are drawn from (arrays, not JSON)
        self.plotters: dict = {}             # PNG file name -> callable(data) -> Figure
        self.extra_files: dict = {}          # file name -> text, written by save() beside results.json
        self.headline: tuple[str, str] | None = None   # (figure name, what is expected) for summary_line
        self.mode: str = ""                  # e.g. "quick sweep", said in summary_line

    @property
    def passed(self) -> bool:
        """True when every check passes."""
        return all(c.passed for c in self.checks)

    @property
    def failures(self) -> list[Check]:
        """The checks that do not pass."""
        return [c for c in self.checks if not c.passed]

    @property
    def plot_names(self) -> list[str]:
        """The PNG file names :meth:`save` writes (the keys :meth:`figure` accepts)."""
        return list(self.plotters)

    def figure(self, name: str | None = None, *, ax=None):
        """A new matplotlib Figure of plot ``name`` (a PNG file name, with or without ``.png``).

        Parameters
        ----------
        name : str, optional
            Which plot; default the lab's first (headline) plot. ``plot_names`` lists them.
        ax : matplotlib Axes or sequence of Axes, optional
            Draw into these (as many as the plot has panels, in row order) instead of a new figure.

        Returns
        -------
        matplotlib.figure.Figure
            Drawn from ``self.data`` (nothing is written, nothing re-run): a new headless figure whose
            ``show()`` opens it through pyplot, or the figure of ``ax``.
        """
        if not self.plotters:
            raise V.LavenderInputError("name", f"lab {self.lab} draws no plot")
        if name is None:
            name = next(iter(self.plotters))
        key = name if name in self.plotters else f"{name}.png"
        if key not in self.plotters:
            raise V.LavenderInputError("name", f"must be one of {', '.join(self.plotters)}", f", got {name!r}")
        if ax is None:
            return self.plotters[key](self.data)
        return self.plotters[key](self.data, ax=ax)

    def summary_line(self, seconds: float | None = None) -> str:
        """One line: the lab, its headline figure, what is expected, PASS/FAIL (and the seconds).

        Parameters
        ----------
        seconds : float, optional
            Run time to append, s.

        Returns
        -------
        str
        """
        status = (f"PASS ({len(self.checks)} checks)" if self.passed
                  else f"FAIL ({len(self.failures)} of {len(self.checks)} checks)")
        head = ""
        if self.headline is not None and self.headline[0] in self:
            key, expected = self.headline
            head = f"{key} = {_show(self[key])}, expected {expected}"
        elif self.checks:
            c = (self.failures or self.checks)[0]
            head = c.describe().split(" — ")[0]
        if self.mode:
            head += f" [{self.mode}]"
        took = "" if seconds is None else f"  {seconds:.1f} s"
        return f"{self.lab:<9} {status:<22} {head}{took}"

    def save(self, out_dir=None) -> "LabResult":
        """Write OUT/lab/results.json, every PNG of ``plot_names`` and ``extra_files``; return self.

        The folder is written whole, never through a link, one run at a time (:mod:`lavendersim.labs.output`):
        a save that fails or is killed leaves ``OUT/lab`` as it was.

        Parameters
        ----------
        out_dir : str or Path, optional
            OUT (default DEFAULT_OUT); the files go to ``OUT/lab/``.

        Returns
        -------
        LabResult
            self, with ``out_dir`` and ``files`` set.

        Raises
        ------
        lavendersim.validate.LavenderInputError
            The folder cannot be written, is a link or not a lab's folder, or another run writes it (naming ``out``).
        """
        from .output import write_folder

        out = Path(DEFAULT_OUT if out_dir is None else out_dir)
        files: dict = {"results.json": json.dumps(dict(self), indent=2 if _flat(self) else 1, allow_nan=False) + "\n"}
        for fname in self.plotters:
            files[fname] = lambda f, fname=fname: self.figure(fname).savefig(f, dpi=110, format="png")
        files.update(self.extra_files)
        self.files = write_folder(out, self.lab, files)
        self.out_dir = out / self.lab
        return self


def _flat(d: dict) -> bool:
    return all(not isinstance(v, (dict, list)) or (isinstance(v, list) and all(not isinstance(x, (dict, list)) for x in v))
               for v in d.values())


def _json_value(name: str, v):
    """JSON-ready scalar (float/int/bool/str) or list of floats; rejects anything nested deeper."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            return str(f)  # JSON has no nan/inf; keep it visible rather than invalid
        return f
    if isinstance(v, str):
        return v
    arr = np.asarray(v)
    if arr.ndim == 1 and arr.dtype.kind in "iuf":
        return [_json_value(name, x) for x in arr]
    raise TypeError(f"results.json: {name!r} must be a number, bool, string or flat vector, got {type(v).__name__}")


def make_result(lab: str, figures: dict, params: dict, checks: list[Check], plots: dict | None = None,
                data: dict | None = None, headline: tuple[str, str] | None = None) -> LabResult:
    """The :class:`LabResult` of a computation, writing nothing.

    ``figures`` and ``params`` are flat dicts (a name clash is an error); ``plots`` maps a PNG file
    name to ``callable(data) -> Figure`` (or to a ready Figure, kept as is); ``data`` is what the
    plots are drawn from; ``headline`` = (figure name, expected) for :meth:`LabResult.summary_line`.

    Parameters
    ----------
    lab : str
        The lab's name.
    figures, params : dict
        Flat dicts of the figures and the parameters used (numbers, bools, strings, flat vectors).
    checks : list of Check
    plots : dict, optional
        PNG file name -> ``callable(data) -> Figure`` or a Figure.
    data : dict, optional
        What the plots are drawn from.
    headline : tuple (str, str), optional
        (figure name, what is expected).

    Returns
    -------
    LabResult

    Raises
    ------
    ValueError
        A name used as both figure and parameter.
    TypeError
        A value that is not a number, bool, string or flat vector.
    """
    clash = set(figures) & set(params)
    if clash:
        raise ValueError(f"lab {lab}: names used as both figure and parameter: {sorted(clash)}")
    items: dict = {"lab": lab}
    for k, v in {**params, **figures}.items():
        items[k] = _json_value(k, v)
    for c in checks:
        items[f"check_{c.name}"] = c.passed
    result = LabResult(lab, None, items, checks)
    result.param_names = list(params)
    result.figure_names = list(figures)
    result["passed"] = result.passed
    result.data = dict(data or {})
    for fname, p in (plots or {}).items():
        result.plotters[fname] = p if callable(p) else (lambda _d, fig=p: fig)
    result.headline = headline
    return result


def finish(lab: str, out_dir, figures: dict, params: dict, checks: list[Check], plots: dict) -> LabResult:
    """:func:`make_result` then :meth:`LabResult.save` to ``out_dir`` (``plots``: file name -> Figure).

    Parameters
    ----------
    lab : str
        The lab's name.
    out_dir : str or Path or None
        OUT (None: DEFAULT_OUT).
    figures, params : dict
        As :func:`make_result`.
    checks : list of Check
    plots : dict
        PNG file name -> Figure (or ``callable(data) -> Figure``).

    Returns
    -------
    LabResult
    """
    return make_result(lab, figures, params, checks, plots).save(out_dir)


# --------------------------------------------------------------------------
# plotting (no pyplot: no global state, no display needed): new_figure is lavendersim.figures'
# --------------------------------------------------------------------------


def progress(iterable=None, *, total: int | None = None, desc: str = "", unit: str = "it", enabled: bool = True):
    """A tqdm progress bar on stderr, shown only when ``enabled`` and stderr is a terminal.

    Anywhere else (a pipe, a log file, CI, ``--quiet``) it is a silent pass-through with the same
    interface (iterate it, or call ``update(n)``/``close()``), so no progress text ends up in logs.

    Parameters
    ----------
    iterable : iterable, optional
        What to iterate over.
    total : int, optional
        Expected number of items.
    desc : str, default ""
        Label before the bar.
    unit : str, default "it"
        Unit shown with the count.
    enabled : bool, default True
        False hides the bar everywhere.

    Returns
    -------
    tqdm.tqdm
    """
    import shutil
    import sys

    from tqdm import tqdm

    show = bool(enabled) and hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    # a terminal that reports a 0 x 0 size (a bare pty) would hide the bar: 100 x 24 then
    cols, rows = shutil.get_terminal_size((100, 24))
    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=not show, leave=False, file=sys.stderr,
                ncols=cols, nrows=rows)


def map_with_progress(executor, fn, tasks, bar, *, feature: str) -> list:
    """``executor.map(fn, tasks)`` advancing ``bar`` as results arrive (in chunks of a few tasks per worker).

    With the bar hidden (not a terminal, or quiet) it is exactly one ``executor.map`` call; with the bar
    shown, the tasks go in chunks of 4 per worker, so the bar moves while the sweep runs. Results are in
    task order either way.

    Parameters
    ----------
    executor : lavendersim.executor executor
        Anything with ``map(fn, tasks, feature=...)`` (and optionally ``workers``).
    fn : callable
        Applied to each task.
    tasks : iterable
        The tasks.
    bar : tqdm.tqdm
        A :func:`progress` bar.
    feature : str
        Passed on to ``executor.map``.

    Returns
    -------
    list
        The results, in task order.
    """
    tasks = list(tasks)
    if bar.disable:
        return executor.map(fn, tasks, feature=feature)
    chunk = max(1, 4 * int(getattr(executor, "workers", 1) or 1))
    out: list = []
    for i in range(0, len(tasks), chunk):
        out += executor.map(fn, tasks[i:i + chunk], feature=feature)
        bar.update(len(tasks[i:i + chunk]))
    return out


# --------------------------------------------------------------------------
# option validation and small numerical helpers
# --------------------------------------------------------------------------


# The magnitude a lab's scale-type option (an offset, a mass factor) may take: beyond it the lab's own
# arithmetic overflows and the run would end in warnings instead of one clear line.
MAX_OPTION = 1e100


def bounded(field: str, value: float, *, positive: bool = False) -> float:
    """A finite option value with 1/MAX_OPTION <= |value| <= MAX_OPTION (0 allowed unless positive).

    Parameters
    ----------
    field : str
        The option's name, used in the error.
    value : float
    positive : bool, default False
        Require value > 0.

    Returns
    -------
    float

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``field`` and the bound.
    """
    x = V.scalar(field, value, positive=positive)
    if abs(x) > MAX_OPTION or (x != 0 and abs(x) < 1 / MAX_OPTION):
        raise V.LavenderInputError(field, f"magnitude must be within [{1 / MAX_OPTION:g}, {MAX_OPTION:g}]"
                                   + ("" if positive else " (or 0)"), f", got {x!r}")
    return x


def steps(field: str, duration: float, dt: float, *, whole: bool = True, limit: int = MAX_STEPS,
          value: float | None = None) -> int:
    """round(duration / dt), rejected (LavenderInputError naming `field`, the bound stated) when it is more
    than `limit` steps, fewer than 1, or — with whole=True — not a whole number of steps.
    `value` is what the user gave for `field` (default: dt).

    Parameters
    ----------
    field : str
        The option named in the error.
    duration, dt : float
        Run duration and step, s.
    whole : bool, default True
        Require duration to be a whole number of steps.
    limit : int, default MAX_STEPS
        Most steps allowed.
    value : float, optional
        The value quoted in the error (default ``dt``).

    Returns
    -------
    int

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming ``field`` and the bound.
    """
    got = f", got {field} = {dt if value is None else value!r}"
    with np.errstate(over="ignore"):
        ratio = float(duration) / float(dt)
    if not ratio <= limit + 0.5:
        raise V.LavenderInputError(field, f"would take {ratio:.3g} steps of dt = {dt:g} s over {duration:g} s; "
                                   f"at most {limit:,} steps are allowed", got)
    n = int(round(ratio))
    if n < 1 or (whole and abs(n * dt - duration) > 1e-9 * duration):
        raise V.LavenderInputError(field, f"T = {duration:g} s must be a whole number of steps", got)
    return n


def check_out_dir(out_dir, lab: str | None = None) -> Path:
    """Create OUT (and OUT/lab) if needed and make sure a file can be written there; LavenderInputError naming
    ``out`` otherwise (checked before a lab runs, so a long lab never fails at its very end).

    Parameters
    ----------
    out_dir : str or Path
        OUT.
    lab : str, optional
        Also create ``OUT/lab``.

    Returns
    -------
    Path
    """
    if lab and isinstance(out_dir, (str, os.PathLike)):
        out_dir = Path(out_dir) / lab
    return V.writable_dir("out", out_dir)


def flags(**named) -> None:
    """Each keyword must be a bool (True or False); LavenderInputError naming the first that is not.

    Parameters
    ----------
    **named : bool
        Option name -> value.

    Raises
    ------
    lavendersim.validate.LavenderInputError
        Naming the option.
    """
    for name, v in named.items():
        if not isinstance(v, (bool, np.bool_)):
            raise V.LavenderInputError(name, "must be True or False", f", got {v!r}")


def check_backend(backend) -> str:
    """The backend name ``backend`` stands for (:func:`lavendersim.backends.resolve`).

    Parameters
    ----------
    backend : {"auto", "c", "numpy"}

    Returns
    -------
    str
        "c" or "numpy".
    """
    return backends.resolve(backend)


def angle_between_deg(K, q_a, q_b):
    """Rotation angle (degrees, in [0, 180]) between two orientations; q and -q are the same.

    Both are normalized first (an unnormalized state still names an orientation).

    Parameters
    ----------
    K : module
        The kernels to use (e.g. ``lavendersim.kernels.K``).
    q_a, q_b : array_like (..., 4)
        Quaternions (x, y, z, w); leading axes broadcast.

    Returns
    -------
    ndarray (...)
        Degrees.
    """
    qa = K.quat_normalize(q_a)
    qb = K.quat_normalize(q_b)
    _, ang = K.quat_to_axis_angle(K.quat_mul(K.quat_conj(qb), qa))
    ang = np.asarray(ang, dtype=float)
    ang = np.minimum(ang, 2 * np.pi - ang)
    return np.degrees(ang)


# --------------------------------------------------------------------------
# printing
# --------------------------------------------------------------------------


NOT_COMPUTED = "not computed"
PARAM_WIDTH = 100          # the report wraps the parameters line at this width
PARAM_SHOWN = 80           # a parameter whose text is longer is named only (its value is in results.json)


def _show(v) -> str:
    """A figure or parameter as printed: never a bare ``nan`` (a non-finite value says it was not computed)."""
    if isinstance(v, list):
        return "[" + ", ".join(x if isinstance(x, str) else _fmt(x) for x in v) + "]"
    if isinstance(v, str) and v in ("nan", "inf", "-inf"):   # how results.json keeps a non-finite float
        v = float(v)
    if isinstance(v, (float, int)) and not isinstance(v, bool):
        if isinstance(v, float) and math.isnan(v):
            return f"{NOT_COMPUTED} (NaN)"
        return _fmt(v)
    return str(v)


def parameters_text(result: LabResult, width: int = PARAM_WIDTH, longest: int = PARAM_SHOWN) -> list[str]:
    """The parameters as wrapped lines; a long one is only named, after "in results.json only (long):".

    Parameters
    ----------
    result : LabResult
    width : int, default PARAM_WIDTH
        Line width.
    longest : int, default PARAM_SHOWN
        A parameter whose text is longer is named only.

    Returns
    -------
    list of str
    """
    import textwrap

    short: list[str] = []
    long_: list[str] = []
    for k in result.param_names:
        text = _show(result[k])
        (short if len(text) <= longest else long_).append(f"{k}={text}" if len(text) <= longest else k)
    body = "; ".join(short)
    if long_:
        body += f"; in results.json only (long): {', '.join(long_)}"
    return textwrap.wrap("parameters: " + body, width=width, initial_indent="  ", subsequent_indent="    ",
                         break_on_hyphens=False)


def report(result: LabResult, stream=None, verbosity: int = 1) -> int:
    """Print the lab's result; return 0 if all checks pass, else 1.

    verbosity 0: only failures (on stderr); 1: parameters (wrapped, long ones named), figures,
    every check and the files; 2: as 1 with every parameter printed in full.

    Parameters
    ----------
    result : LabResult
    stream : file, optional
        Where the report goes (default stdout); failures always go to stderr.
    verbosity : int, default 1
        0, 1 or 2 as above.

    Returns
    -------
    int
        0 or 1.
    """
    import sys

    out = stream or sys.stdout
    if verbosity >= 1:
        print(f"== lab {result.lab} -> {result.out_dir}", file=out)
        if verbosity >= 2:
            print("  parameters: " + ", ".join(f"{k}={_show(result[k])}" for k in result.param_names), file=out)
        else:
            for line in parameters_text(result):
                print(line, file=out)
        for k in result.figure_names:
            print(f"  {k} = {_show(result[k])}", file=out)
        for c in result.checks:
            print(f"  {'PASS' if c.passed else 'FAIL'}  {c.describe()}", file=out)
        for p in result.files:
            print(f"  wrote {p}", file=out)
    if result.passed:
        if verbosity >= 1:
            print(f"lab {result.lab}: all {len(result.checks)} checks pass", file=out)
        return 0
    for c in result.failures:
        print(f"lab {result.lab}: figure {c.describe()}", file=sys.stderr)
    print(f"lab {result.lab}: {len(result.failures)} of {len(result.checks)} checks FAILED", file=sys.stderr)
    return 1
