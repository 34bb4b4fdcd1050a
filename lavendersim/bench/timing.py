"""Short interleaved calls: the timing protocol of the bench's effect_cost, dopri5 and simd sections (issue 30).

On a shared host a disturbance (another process's burst on the other core, a context switch that cools the caches)
lasts milliseconds and slows whatever runs through it, in CPU time too. A long call (tens of ms) is hit by one more
often than a short one, and a case whose calls are longer than its peer's is hit more often than the peer: the min
over a few long calls then reads the disturbance, not the machine. So every case here is timed in calls of about
the same length, CALL_S (a few ms: a disturbance spoils few samples), its count of work per call (steps, iterations)
calibrated once per case before timing; the cases alternate call by call (each pass over the cases starts one case
later, so no case always follows the same one), CALLS_PER_ROUND calls per case per round; each figure is the
minimum over all calls of that case (the median is kept). Ours and its peers go through the same protocol.

A call must still hold enough work to amortize what every call pays once (a batch call's copy between the state
and its tiles, a Sim's checks per chunk): the sections give a least count per call (min_count) or count in whole
units (effect_cost: whole chunks of the Sim), so a call can be longer than CALL_S; a round then holds fewer calls
(the same time per round), at least MIN_CALLS_PER_ROUND.

Every call is timed in CPU time of the process (time.process_time), or by the wall clock for a case marked "wall".
"""
from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

CALL_S = 3e-3          # the target length of one timed call, seconds
CALLS_PER_ROUND = 20   # timed calls of each case per round when the calls are CALL_S long (--rounds R: R * 20 each)
MIN_CALLS_PER_ROUND = 2   # ... fewer when some cannot be that short (the same time per round), but at least this
_CAL_MAX_COUNT = 1 << 40


def calibrate(fn: Callable[[int], Any], clock: Callable[[], float] = time.process_time, call_s: float = CALL_S,
              min_count: int = 1) -> tuple[int, float, int]:
    """The count k (>= min_count) for which one call fn(k) takes about call_s seconds, that call's length, and the
    count of the last call calibration made (k itself when the last call was already at the timed length).

    fn(min_count) runs once to warm up; then k grows (at most 64-fold per try, guided by the last reading) until one
    call takes at least a quarter of call_s, and is scaled to call_s from that reading (never below min_count)."""
    fn(min_count)
    k = min_count
    while True:
        t0 = clock()
        fn(k)
        t = clock() - t0
        if t <= 0 and k < _CAL_MAX_COUNT:
            k = min(_CAL_MAX_COUNT, k * 64)
        elif t >= call_s / 4 or k >= _CAL_MAX_COUNT:
            if t <= 0:
                return k, t, k
            kk = max(min_count, min(_CAL_MAX_COUNT, round(k * call_s / t)))
            return kk, t * kk / k, k
        else:
            k = min(_CAL_MAX_COUNT, max(2 * k, min(64 * k, math.ceil(k * call_s / t))))


def stats(ns: list[float], **extra) -> dict:
    """Min, median and the samples (ns per unit), with the calls' bookkeeping in extra."""
    return {"ns_min": min(ns), "ns_median": statistics.median(ns), "rounds": len(ns), "ns_samples": ns, **extra}


def interleaved_calls(cases: dict, rounds: int, label: str = "", progress: Callable[[str], None] | None = None,
                      call_s: float = CALL_S, per_round: int = CALLS_PER_ROUND, min_count: int = 1) -> dict:
    """Time every case in short calls of equal length, interleaved call by call (see the module docstring).

    Parameters
    ----------
    cases : dict
        name -> (fn, units_per_count) or (fn, units_per_count, mark). ``fn(k)`` does k counts of work (steps,
        iterations), ``k * units_per_count`` units; mark "wall": timed by the wall clock; mark "counted": fn
        returns the units it did (e.g. right-hand-side evaluations of an adaptive integrator).
    rounds : int
        Rounds (>= 1); each times every case per_round times.
    label, progress
        ``progress(f"{label}: round r/R")`` is called before each round when both are given.
    call_s : float
        The length of one call, seconds.
    per_round : int
        Calls of each case per round when every call is call_s long; when some take longer (a case whose
        min_count, or whose single count, takes longer) proportionally fewer, at least MIN_CALLS_PER_ROUND:
        a round costs about per_round * call_s per case either way. Every case gets the same number of calls.
    min_count : int
        The fewest counts per call (a case whose per-call setup must be amortized over enough steps).

    Returns
    -------
    dict
        name -> {``ns_min``, ``ns_median`` (ns per unit), ``rounds`` (calls timed), ``ns_samples``,
        ``units_per_call`` (of the first timed call), ``count_per_call`` (k), ``clock`` ("cpu" or "wall"),
        ``call_s`` (the calibrated length of one call, s), ``calls_per_round``, and ``units_samples`` (each
        call's units) when fn returns them}.
    """
    clocks = {nm: time.perf_counter if c[2:] == ("wall",) else time.process_time for nm, c in cases.items()}
    cal = {nm: calibrate(c[0], clocks[nm], call_s, min_count) for nm, c in cases.items()}
    counts = {nm: k for nm, (k, _, _) in cal.items()}
    one_pass = sum(t for _, t, _ in cal.values())   # a round's budget: per_round calls of call_s per case
    per_round = max(MIN_CALLS_PER_ROUND, min(per_round, round(per_round * call_s * len(cases) / max(one_pass, 1e-9))))
    for nm, (fn, *_) in cases.items():   # one warm call at the timed length (calibration's last call was not)
        if cal[nm][2] != counts[nm]:
            fn(counts[nm])
    names = list(cases)
    ns: dict[str, list[float]] = {nm: [] for nm in names}
    units: dict[str, list[float]] = {nm: [] for nm in names}
    returned = {nm for nm, c in cases.items() if c[2:] == ("counted",)}   # fn returns its units
    calls = rounds * per_round
    for i in range(calls):
        if label and progress and i % per_round == 0:
            progress(f"{label}: round {i // per_round + 1}/{rounds}")
        s = i % len(names)
        for nm in names[s:] + names[:s]:
            fn, per = cases[nm][0], cases[nm][1]
            clock, k = clocks[nm], counts[nm]
            t0 = clock()
            r = fn(k)
            t = clock() - t0
            u = float(r) if nm in returned else float(k * per)
            units[nm].append(u)
            ns[nm].append(t / max(u, 1.0) * 1e9)
    return {nm: stats(ns[nm], units_per_call=units[nm][0], count_per_call=counts[nm], call_s=cal[nm][1],
                      calls_per_round=per_round,
                      clock="wall" if clocks[nm] is time.perf_counter else "cpu",
                      **({"units_samples": units[nm]} if nm in returned else {})) for nm in names}
