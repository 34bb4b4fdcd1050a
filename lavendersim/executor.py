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
processes do not see). The calling process pickles ``fn`` and each task before anything runs: one
that does not pickle (a lambda on local processes, an object holding a lock or an open file) raises
:class:`UnpicklableTaskError` naming it (``fn`` or ``tasks[i]``) and why. An exception raised by
``fn`` in a worker reaches the caller as itself (type and fields: every exception of this package
pickles; a :class:`~lavendersim.errors.DivergenceError` stays one), with the worker's traceback as
its cause; one that cannot cross the process boundary, and a result that does not pickle, arrive as
:class:`WorkerError` naming the task. The first failing task in task order is reported.

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
import pickle
import re
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from . import validate as V
from ._version import __version__

__all__ = ["DASK", "PROCESSES", "SERIAL", "Executor", "UnpicklableTaskError", "WorkerError", "WorkerMismatchError",
           "local_cores", "map_tasks", "resolve"]

SERIAL, PROCESSES, DASK = "serial", "processes", "dask"
DASK_CONNECT_TIMEOUT_S = 30.0


class WorkerMismatchError(RuntimeError):
    """The Dask workers run another LavenderSim version than this process."""


class UnpicklableTaskError(V.LavenderInputError, TypeError):
    """``fn`` or a task cannot be sent to a worker (it does not pickle): a LavenderInputError and a TypeError.
    Raised before any task runs.

    Parameters
    ----------
    field : str
        ``"fn"`` or ``"tasks[i]"``.
    rule : str
        What it must be.
    detail : str, optional
        Why it is not: what pickling it raised.
    """


class WorkerError(RuntimeError):
    """A task failed in a worker in a way that cannot cross the process boundary as itself: its exception does not
    pickle, its result does not, or the worker could not load ``fn`` or the task. The message names the task
    (``tasks[i]``), the original exception's type and message; the worker's traceback is the cause."""


class _RemoteTraceback(Exception):
    """The traceback text of an exception raised in a worker (set as that exception's ``__cause__``)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def local_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform tells, else os.cpu_count())."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def _worker_version() -> str:
    from ._version import __version__ as v

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
        UnpicklableTaskError
            (local processes, Dask) ``fn`` or a task does not pickle; raised before any task runs.
        Exception
            What ``fn`` raised for the first failing task in task order, as itself (a DivergenceError stays one,
            with its fields); from a worker, its traceback is the ``__cause__``.
        WorkerError
            A worker's exception or result that cannot come back to this process, or ``fn`` or a task that the
            worker could not load; the message names the task.
        lavendersim._install.MissingExtraError
            Dask executor without the distributed extra installed.
        lavendersim.validate.LavenderInputError
            A Dask executor built without a scheduler address (``address``).
        WorkerMismatchError
            The Dask workers run another LavenderSim version.
        """
        tasks = list(tasks)
        if self.kind == SERIAL or (self.kind == PROCESSES and len(tasks) <= 1):
            return [fn(t) for t in tasks]
        if self.kind == PROCESSES:
            return _map_processes(fn, tasks, min(self.workers, len(tasks)))
        if not self.address:   # distributed.Client(None) would start a local cluster of its own, silently
            raise V.LavenderInputError("address", "a Dask executor needs its scheduler's address "
                                       "(lavendersim.executor.resolve(dask='tcp://host:8786'))")
        return _map_dask(fn, tasks, self.address, feature)


# ---- what crosses the process boundary: bytes pickled here, a (status, payload) pair back -------------------------
_OK, _ERR = "ok", "error"


def _fn_name(fn) -> str:
    return getattr(fn, "__qualname__", None) or type(fn).__name__


def _dumps(what: str, obj, dumps) -> bytes:
    """obj pickled by `dumps`, or UnpicklableTaskError naming `what` and why (nothing has run yet)."""
    try:
        return dumps(obj)
    except Exception as exc:   # PicklingError, TypeError (a lock), AttributeError (a local object), anything
        hint = ("a module-level function (not a lambda, nested function or bound method of an unpicklable object)"
                if what == "fn" else "picklable (no lock, open file, generator or live connection in it)")
        raise UnpicklableTaskError(what, f"cannot be sent to a worker process: it must be {hint}, or run the tasks "
                                   "serially (workers=1, --workers 1)", f"; pickling it raised {type(exc).__name__}: "
                                   f"{exc}") from None


def _packed_error(i: int, fn_name: str, exc: BaseException, what: str | None = None) -> tuple[str, bytes, str]:
    """A worker's failure as (status, pickled exception, traceback text): exc itself where it survives a pickle round
    trip (its type and fields), else a WorkerError naming the task and exc."""
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    if what is None:
        step = "pickling"
        try:
            data = pickle.dumps(exc)
            step = "unpickling"
            back = pickle.loads(data)
            if type(back) is type(exc) and back.args == exc.args:
                return _ERR, data, tb
            why = "it comes back changed from a pickle round trip"
        except Exception as err:
            why = f"{step} it raised {type(err).__name__}: {err}"
        module = type(exc).__module__.replace("__mp_main__", "__main__")    # (a worker's name for the main script)
        what = (f"raised {module}.{type(exc).__qualname__}: {exc}; that exception cannot be sent back to the calling "
                f"process ({why}), so it is reported as this")
    return _ERR, pickle.dumps(WorkerError(f"tasks[{i}]: {fn_name} {what}")), tb


def _run_packed(fn_data: bytes, i: int, task_data: bytes) -> tuple[str, bytes, str]:
    """In a worker: load fn and task i, run, and return (status, pickled result or exception, traceback text).

    Never raises for what the task does (an exception the pool would have to pickle, or fail to, is packed here)."""
    try:
        fn = pickle.loads(fn_data)
    except Exception as exc:
        return _packed_error(i, "fn", exc, f"could not be loaded in the worker process ({type(exc).__name__}: {exc}): "
                                           "a function of an interactive session or notebook is not importable there; "
                                           "define it in a module, or run the tasks serially")
    name = _fn_name(fn)
    try:
        task = pickle.loads(task_data)
    except Exception as exc:
        return _packed_error(i, name, exc, f"could not run: the task could not be loaded in the worker process "
                                           f"({type(exc).__name__}: {exc})")
    try:
        result = fn(task)
    except Exception as exc:
        return _packed_error(i, name, exc)
    try:
        return _OK, pickle.dumps(result), ""
    except Exception as exc:
        return _packed_error(i, name, exc, f"returned a {type(result).__qualname__} that cannot be sent back "
                                           f"({type(exc).__name__}: {exc}): return picklable results")


def _unpacked(i: int, packed: tuple[str, bytes, str]):
    """The result of task i in this process; its exception raised (the worker's traceback as its cause)."""
    status, data, tb = packed
    try:
        value = pickle.loads(data)
    except Exception as exc:
        raise WorkerError(f"tasks[{i}]: its {'result' if status == _OK else 'exception'} could not be loaded in this "
                          f"process ({type(exc).__name__}: {exc})") from _RemoteTraceback(tb) if tb else None
    if status == _OK:
        return value
    raise value from _RemoteTraceback(tb)


def _packed_tasks(fn, tasks: list, dumps) -> tuple[bytes, list[bytes]]:
    return _dumps("fn", fn, dumps), [_dumps(f"tasks[{i}]", t, dumps) for i, t in enumerate(tasks)]


def _map_processes(fn, tasks: list, workers: int) -> list:
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    fn_data, task_data = _packed_tasks(fn, tasks, pickle.dumps)     # before any process starts
    ctx = multiprocessing.get_context(_start_method())
    if ctx.get_start_method() == "forkserver":
        # the server imports these once; every worker forks from it with them loaded (no per-worker import)
        module = getattr(fn, "__module__", None)
        ctx.set_forkserver_preload(["lavendersim"] + ([module] if module and module != "__main__" else []))
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        try:
            out = []
            for i, packed in enumerate(pool.map(_run_packed, [fn_data] * len(tasks), range(len(tasks)), task_data,
                                                chunksize=1)):    # map yields in task order
                out.append(_unpacked(i, packed))
            return out
        except BrokenProcessPool as exc:
            raise BrokenProcessPool(
                f"a worker process died while running {_fn_name(fn)} ({exc}): it was killed (out of memory, a "
                "signal), crashed in compiled code or called os._exit. If the calling script has no "
                "`if __name__ == '__main__':` guard, each worker runs it again on start and dies so: guard its entry "
                "point; or run the tasks serially (workers=1, --workers 1)") from exc
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _require_distributed(feature: str):
    from ._install import require

    return require("distributed", "distributed", feature)


def _map_dask(fn, tasks: list, address: str, feature: str) -> list:
    distributed = _require_distributed(feature)
    import cloudpickle    # what Dask sends functions with (lambdas and closures too); a dependency of distributed

    fn_data, task_data = _packed_tasks(fn, tasks, cloudpickle.dumps)     # before connecting
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
        futures = client.map(_run_packed, [fn_data] * len(tasks), range(len(tasks)), task_data, pure=False)
        return [_unpacked(i, packed) for i, packed in enumerate(client.gather(futures))]   # in the order of futures
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
        if re.fullmatch(r"((tcp|tls)://)?[^/]+/?", dask.strip()) and not re.search(r":\d+/?$", dask.strip()):
            # distributed refuses it only inside Client(): a traceback, then a 60 s hang in Client.__del__
            raise V.LavenderInputError("dask", "must name the scheduler's port, such as tcp://host:8786", f", got {dask!r}")
        _require_distributed(feature)
        return Executor(DASK, 0, dask.strip())
    n = local_cores() if workers is None else V.integer("workers", workers, minimum=1)
    return Executor(SERIAL, 1) if n == 1 else Executor(PROCESSES, n)


def map_tasks(fn: Callable[[Any], Any], tasks: Iterable[Any], executor: Executor | None = None, *,
              feature: str = "a dask sweep", progress: Callable[[int], Any] | None = None) -> list:
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
    progress : callable, optional
        Called with the number of tasks just done: the tasks then go in chunks of 4 per worker, so a
        progress bar moves while the sweep runs (None: one ``map`` call).

    Returns
    -------
    list
        The results in task order.
    """
    executor = executor or Executor()
    if progress is None:
        return executor.map(fn, tasks, feature=feature)
    tasks, out = list(tasks), []
    chunk = max(1, 4 * int(executor.workers or 1))
    for i in range(0, len(tasks), chunk):
        out += executor.map(fn, tasks[i:i + chunk], feature=feature)
        progress(len(tasks[i:i + chunk]))
    return out
