"""Map a function over independent tasks: in this process, on local processes, or on a Dask cluster.

Parameter sweeps (the stability atlas, the accuracy lab's error computation) are lists of
independent tasks. This module runs ``fn(task)`` for each task and returns the results **in task
order**, whatever order they finish in, so a sweep gives the same output on any executor::

    from lavendersim import executor

    ex = executor.resolve(workers=None)             # all local cores (serial on a 1-core machine)
    ex = executor.resolve(workers=1)                # this process, one task after the other
    ex = executor.resolve(dask="tcp://host:8786")   # an existing Dask scheduler (the distributed extra)
    results = ex.map(fn, tasks)                     # [fn(t) for t in tasks], computed where ex says

Requirements on ``fn`` and the tasks: ``fn`` is a module-level function (local processes pickle it
by reference; Dask uses cloudpickle) and every task and result is picklable. ``fn`` should be a
pure function of its task (no reliance on state mutated in the calling process, which worker
processes do not see); exceptions raised by ``fn`` propagate to the caller.

Local processes use the ``forkserver`` start method where the platform has it (``spawn``
otherwise): no worker inherits threads or locks of the caller (a Dask client, a viewer). As with
any such pool, the workers import the calling script again, so a script that maps on local
processes guards its entry point with ``if __name__ == "__main__":`` (the ``lavendersim`` command
does). A Dask
executor connects a :class:`distributed.Client` to the scheduler at ``address`` — an engine someone
else started (``dask scheduler`` and ``dask worker``, or a ``LocalCluster``); this module never
starts or stops a cluster, and closes only its own client. The workers must have the same
LavenderSim installed: :meth:`Executor.map` asks one worker for its version first and raises
:class:`WorkerMismatchError` if it differs (results would not be comparable).

Nothing here measures time: a sweep that times things should time them in the calling process,
after :meth:`Executor.map` returns (its worker processes are then shut down).
"""
from __future__ import annotations

import multiprocessing
import os
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from . import validate as V
from ._version import __version__

__all__ = ["DASK", "PROCESSES", "SERIAL", "Executor", "WorkerMismatchError", "local_cores", "map_tasks", "resolve"]

SERIAL, PROCESSES, DASK = "serial", "processes", "dask"
DASK_CONNECT_TIMEOUT_S = 30.0


class WorkerMismatchError(RuntimeError):
    """The Dask workers run another LavenderSim version than this process."""


def local_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform tells, else os.cpu_count())."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def _worker_version() -> str:
    from lavendersim._version import __version__ as v

    return v


def _start_method() -> str:
    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"


@dataclass(frozen=True)
class Executor:
    """Where :meth:`map` runs the tasks.

    Parameters
    ----------
    kind : str
        ``"serial"`` (this process), ``"processes"`` (a pool of local worker processes) or
        ``"dask"`` (the workers of an existing Dask scheduler).
    workers : int
        Local worker processes (1 for serial; for Dask, the cluster decides and this is 0).
    address : str or None
        The Dask scheduler address (``kind == "dask"`` only).
    """

    kind: str = SERIAL
    workers: int = 1
    address: str | None = None

    def describe(self) -> str:
        """One line saying where the tasks run, e.g. ``"2 local processes"``."""
        if self.kind == SERIAL:
            return "serial (this process)"
        if self.kind == PROCESSES:
            return f"{self.workers} local processes ({_start_method()})"
        return f"dask scheduler at {self.address}"

    def map(self, fn: Callable[[Any], Any], tasks: Iterable[Any], *, feature: str = "a dask sweep") -> list:
        """``[fn(t) for t in tasks]``, computed where this executor says, in task order.

        Parameters
        ----------
        fn : callable
            A picklable (module-level) function of one task.
        tasks : iterable
            Picklable tasks; consumed into a list first.
        feature : str
            What the user asked for, named in the error when the distributed extra is missing.

        Returns
        -------
        list
            One result per task, in the order of ``tasks`` (never completion order).

        Raises
        ------
        lavendersim._install.MissingExtraError
            Dask executor without the distributed extra installed.
        WorkerMismatchError
            The Dask workers run another LavenderSim version.
        """
        tasks = list(tasks)
        if self.kind == SERIAL or (self.kind == PROCESSES and len(tasks) <= 1):
            return [fn(t) for t in tasks]
        if self.kind == PROCESSES:
            return _map_processes(fn, tasks, min(self.workers, len(tasks)))
        return _map_dask(fn, tasks, self.address, feature)


def _map_processes(fn, tasks: list, workers: int) -> list:
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context(_start_method())
    if ctx.get_start_method() == "forkserver":
        # the server imports these once; every worker forks from it with them loaded (no per-worker import)
        module = getattr(fn, "__module__", None)
        ctx.set_forkserver_preload(["lavendersim"] + ([module] if module and module != "__main__" else []))
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        try:
            return list(pool.map(fn, tasks, chunksize=1))       # map yields in task order
        except BrokenProcessPool as exc:
            raise BrokenProcessPool(
                f"a worker process died ({exc}). Worker processes import the calling script again: a script "
                "that runs a sweep on local processes must guard its entry point with "
                "`if __name__ == '__main__':`; or run it serially (workers=1, --workers 1)") from exc
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _require_distributed(feature: str):
    from ._install import require

    return require("distributed", "distributed", feature)


def _map_dask(fn, tasks: list, address: str, feature: str) -> list:
    distributed = _require_distributed(feature)
    try:
        client = distributed.Client(address, timeout=DASK_CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:  # unreachable or no scheduler there: one clear line, not a traceback
        raise V.LavenderInputError("dask", f"cannot connect to a Dask scheduler at {address} within "
                                   f"{DASK_CONNECT_TIMEOUT_S:g} s", f" ({type(exc).__name__}: {exc})") from None
    try:
        theirs = client.submit(_worker_version, pure=False).result()
        if theirs != __version__:
            raise WorkerMismatchError(f"the Dask workers at {address} run LavenderSim {theirs}, this process "
                                      f"{__version__}: install the same version on the workers")
        futures = client.map(fn, tasks, pure=False)
        return client.gather(futures)                        # gathered in the order of `futures`
    finally:
        client.close()


def resolve(workers: int | None = None, dask: str | None = None, *, feature: str = "a dask sweep") -> Executor:
    """The executor for a ``--workers N`` / ``--dask ADDRESS`` pair of options.

    Parameters
    ----------
    workers : int or None
        Local worker processes: None = every core this process may use (:func:`local_cores`),
        1 = serial in this process, N > 1 = a pool of N processes. Not allowed together with
        ``dask``.
    dask : str or None
        Address of an existing Dask scheduler (e.g. ``"tcp://10.0.0.5:8786"``); needs the
        distributed extra, checked here so a missing extra is reported before any work is done.
    feature : str
        What the user asked for, named in the missing-extra error.

    Returns
    -------
    Executor

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``workers`` is not a positive integer, ``dask`` is not a non-empty string, or both are given.
    lavendersim._install.MissingExtraError
        ``dask`` given and the distributed extra is not installed.
    """
    if dask is not None:
        if workers is not None:
            raise V.LavenderInputError("workers", "cannot be combined with a Dask scheduler address "
                                       "(the cluster decides how many workers run)")
        if not isinstance(dask, str) or not re.fullmatch(r"([a-z][a-z0-9+.-]*://)?[A-Za-z0-9._\-\[\]:]+/?", dask.strip()):
            raise V.LavenderInputError("dask", "must be a scheduler address such as tcp://host:8786", f", got {dask!r}")
        _require_distributed(feature)
        return Executor(DASK, 0, dask.strip())
    n = local_cores() if workers is None else V.integer("workers", workers, minimum=1)
    return Executor(SERIAL, 1) if n == 1 else Executor(PROCESSES, n)


def map_tasks(fn: Callable[[Any], Any], tasks: Iterable[Any], executor: Executor | None = None, *,
              feature: str = "a dask sweep") -> list:
    """``[fn(t) for t in tasks]`` on ``executor`` (default: serial), in task order.

    Parameters
    ----------
    fn : callable
        A picklable (module-level) function of one task.
    tasks : iterable
        Picklable tasks.
    executor : Executor or None
        From :func:`resolve`; None runs serially in this process.
    feature : str
        Named in the missing-extra error of a Dask executor.

    Returns
    -------
    list
        The results in task order.
    """
    return (executor or Executor()).map(fn, tasks, feature=feature)
