"""lavendersim.bench.timing: the short-call protocol of the effect_cost, dopri5 and simd sections (issue 30).

Driven by a fake CPU clock (each case's work advances it by a known cost per count), so the calibrated counts, the
call-by-call interleaving, the per-round budget and the minima are checked exactly; nothing here times anything."""
from __future__ import annotations

import pytest

from lavendersim.bench import timing


class FakeClock:
    """A process clock that advances only when a case does work: cost seconds per count (plus a disturbance)."""

    def __init__(self):
        self.now = 0.0
        self.log: list[tuple[str, int]] = []

    def __call__(self) -> float:
        return self.now

    def case(self, name: str, cost: float, slow: dict | None = None, units=None):
        """fn(k) for a case costing cost s per count; slow: call index -> factor (a disturbance on that call);
        units: fn returns units(k) (a "counted" case)."""
        calls = []

        def fn(k: int):
            f = (slow or {}).get(len(calls), 1.0)
            calls.append(k)
            self.log.append((name, k))
            self.now += cost * k * f
            return None if units is None else units(k)
        return fn


@pytest.fixture
def clock(monkeypatch):
    c = FakeClock()
    monkeypatch.setattr(timing.time, "process_time", c)
    return c


def test_calibrate_reaches_the_call_length_and_respects_the_least_count(clock):
    k, t, last = timing.calibrate(clock.case("a", 1e-8), clock, 3e-3)
    assert k == 300_000 and t == pytest.approx(3e-3) and last != k
    k, t, last = timing.calibrate(clock.case("b", 1e-2), clock, 3e-3)   # one count takes longer than a call: k = 1
    assert k == 1 and t == pytest.approx(1e-2) and last == 1
    k, t, last = timing.calibrate(clock.case("c", 1e-6), clock, 3e-3, min_count=400)
    assert k == 3000
    k, t, last = timing.calibrate(clock.case("d", 1e-4), clock, 3e-3, min_count=400)   # 30 would do; at least 400
    assert k == 400 and t == pytest.approx(4e-2) and last == 400


def test_cases_alternate_call_by_call_with_equal_lengths_and_the_min_per_case(clock):
    # "ours" costs 2.5x "plain" per step; a disturbance doubles two of ours' calls and one of plain's
    cases = {"plain": (clock.case("plain", 2e-6, slow={5: 2.0}), 1000),
             "ours": (clock.case("ours", 5e-6, slow={4: 2.0, 9: 2.0}), 1000)}
    t = timing.interleaved_calls(cases, rounds=2, call_s=3e-3, per_round=5)
    assert t["plain"]["count_per_call"] == 1500 and t["ours"]["count_per_call"] == 600   # both calls ~3 ms
    assert t["plain"]["call_s"] == pytest.approx(3e-3) and t["ours"]["call_s"] == pytest.approx(3e-3)
    assert t["plain"]["rounds"] == t["ours"]["rounds"] == 10 and t["plain"]["calls_per_round"] == 5
    timed = [nm for nm, _ in clock.log][-20:]   # after calibration and the warm calls: one call of each per pass,
    passes = [timed[i:i + 2] for i in range(0, 20, 2)]   # each pass starting one case later
    assert passes == [["plain", "ours"], ["ours", "plain"]] * 5
    assert [k for _, k in clock.log][-20:] == [1500 if nm == "plain" else 600 for nm in timed]
    assert t["plain"]["ns_min"] == pytest.approx(2e-6 / 1000 * 1e9)   # the disturbed calls do not set the figure
    assert t["ours"]["ns_min"] == pytest.approx(5e-6 / 1000 * 1e9)
    assert max(t["ours"]["ns_samples"]) == pytest.approx(2 * t["ours"]["ns_min"])
    assert t["ours"]["clock"] == "cpu" and t["ours"]["units_per_call"] == 600 * 1000
    assert "units_samples" not in t["ours"]


def test_a_case_is_warmed_at_its_timed_length_once(clock):
    """Calibration's last call warms a case whose count it already had (a long call is not repeated for nothing);
    otherwise one warm call at the timed count precedes the timed ones."""
    cases = {"long": (clock.case("long", 1e-2), 1), "short": (clock.case("short", 1e-6), 1)}
    t = timing.interleaved_calls(cases, rounds=1, call_s=3e-3, per_round=2)
    assert [k for nm, k in clock.log if nm == "long"] == [1, 1] + [1] * t["long"]["rounds"]   # warm-up, calibration
    short = [k for nm, k in clock.log if nm == "short"]
    assert short[-t["short"]["rounds"] - 1:] == [3000] * (t["short"]["rounds"] + 1)   # one warm call, then timed


def test_long_calls_get_fewer_calls_per_round_but_the_same_for_every_case(clock):
    cases = {"short": (clock.case("short", 1e-6), 1), "long": (clock.case("long", 1e-4), 1)}
    t = timing.interleaved_calls(cases, rounds=3, call_s=3e-3, per_round=20, min_count=400)
    # short: 3000 counts (3 ms); long: 400 counts (40 ms, its least count) -> a pass takes 43 ms against 2 * 3 ms
    assert t["short"]["count_per_call"] == 3000 and t["long"]["count_per_call"] == 400
    assert t["short"]["calls_per_round"] == t["long"]["calls_per_round"] == 3   # round(20 * 6 / 43)
    assert t["short"]["rounds"] == t["long"]["rounds"] == 9
    cases = {"a": (clock.case("a", 1.0), 1), "b": (clock.case("b", 1.0), 1)}   # never below MIN_CALLS_PER_ROUND
    t = timing.interleaved_calls(cases, rounds=1, call_s=3e-3, per_round=20)
    assert t["a"]["rounds"] == timing.MIN_CALLS_PER_ROUND


def test_a_counted_case_reports_its_own_units(clock):
    cases = {"adaptive": (clock.case("adaptive", 1e-6, units=lambda k: 2 * k + 1), 1, "counted")}
    t = timing.interleaved_calls(cases, rounds=1, call_s=3e-3, per_round=4)
    k = t["adaptive"]["count_per_call"]
    assert t["adaptive"]["units_samples"] == [2 * k + 1] * 4
    assert t["adaptive"]["ns_min"] == pytest.approx(1e-6 * k / (2 * k + 1) * 1e9)


def test_sim_chunk_steps_is_the_chunk_run_steps_in():
    """Sim.chunk_steps (read-only): the effect_cost section times whole chunks through it; run(k * chunk) is k
    chunks (the step counter moves by exactly that)."""
    import numpy as np

    from lavendersim.scene import Scene
    from lavendersim.sim import CHUNK_WORK, Sim

    scene = Scene()
    scene.add_bodies([f"b{i}" for i in range(1000)], np.full(1000, 2.0), np.tile([0.03, 0.11, 0.13], (1000, 1)))
    sim = Sim(scene, dt=1e-3, integrator="rk4", backend="c")
    c = sim.chunk_steps
    assert isinstance(c, int) and c == CHUNK_WORK // (1000 * 4)   # RK4: 4 evaluations per body-step
    sim.run(2 * c)
    assert sim.steps == 2 * c
    with pytest.raises(AttributeError):
        sim.chunk_steps = 5
