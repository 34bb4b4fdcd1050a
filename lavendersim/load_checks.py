"""The Sim's checks of bodies that effects act on: the decay bound and the growth budget.

Two checks, both from what derive printed (issue 28: no finite blow-up is silent, with or without effects):

* **The decay bound.** An effect that derive recognised as a pure linear decay (derive/effect_decay.py:
  ``linear_damping``'s ``c/m``, ``angular_damping``'s ``c/I_min``, a user's spin drag) has a printed decay
  rate; an explicit step of it is stable while ``rate * dt`` (summed over the decays on one body) stays within
  the integrator's limit on the negative real axis, ``REAL_AXIS_STABILITY`` (derive/tableaux.py: euler 2,
  rk4 2.785, splitting 4, …). The Sim checks it when built and on every ``set_effect_params``, with its
  ``on_bound`` choice. The adaptive dopri5 controls its own error (a stiff decay shrinks its steps): none.

* **The growth budget.** A body that effects act on (not on a spherical joint: the joint's reaction is not a
  declared load) may gain momentum only from its loads: ``|L(t)| <= |L(t0)| + ∫|tau|`` and
  ``|p(t)| <= |p(t0)| + ∫|F|``, where the decays count for nothing (they only take momentum out) and the
  other loads at the largest rate seen at any check (at the reference, at every check, at the state being
  checked). The check refuses a body beyond ``max_growth`` times that budget: with ``Lmax``, ``Pmax`` so
  defined, ``|L| <= Lmax`` and (plain bodies) kinetic energy ``<= Pmax²/2m + Lmax²/2I_min``, or (wheeled
  bodies: |L| of body and wheels, the motors' torques are internal) ``m|v| <= Pmax``. A budget grows with
  time, so the limits the C screen holds (set at the last passed check) are never looser than this check's.
"""
from __future__ import annotations

import numpy as np

from . import backends
from . import effects as effects_mod
from .kernels import K
from .generated import layout as LY
from .generated import tableaux as TABLEAUX

# The C screen's rounding margin on every limit it reads (Sim._safe_rates, LoadBudget.screen_rows): the screen never
# passes what the NumPy check would refuse.
SCREEN_MARGIN = 1 - 1e-12


def decay_rows(effects: np.ndarray) -> np.ndarray:
    """Boolean mask of the effect table's rows whose effect is a pure linear decay (it has a printed rate)."""
    codes = effects[:, effects_mod.ROW_CODE].astype(np.int64) if len(effects) else np.zeros(0, np.int64)
    codes, at = np.unique(codes, return_inverse=True)     # one look-up per code, not per row
    return np.array([effects_mod.spec_for_code(c).is_decay for c in codes], dtype=bool)[at.reshape(-1)]


def decay_stiffness(effects: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Per body, the summed decay rate (1/s) of the decays acting on it (0 where none).

    Parameters
    ----------
    effects : ndarray (n_rows, width)
        The effect table ([code, body (-1: every body), parameters …]).
    params : ndarray (nb, PARAM_SIZE)
        The bodies' parameters (mass, principal moments).
    """
    nb = params.shape[0]
    rate = np.zeros(nb)
    for r in np.flatnonzero(decay_rows(effects)):
        row = effects[r]
        spec = effects_mod.spec_for_code(int(row[effects_mod.ROW_CODE]))
        assert spec.decay_rate is not None, spec.name   # (decay_rows picked it)
        body = int(row[effects_mod.ROW_BODY])
        idx = np.arange(nb) if body < 0 else np.array([body])
        p = np.repeat(row[effects_mod.ROW_PARAMS:effects_mod.ROW_PARAMS + spec.n_params][None], idx.size, axis=0)
        with np.errstate(all="ignore"):
            rate[idx] += spec.decay_rate(p, params[idx, LY.PARAM_M], params[idx][:, LY.PARAM_I_B])
    return rate


def decay_limit(integrator: str) -> float | None:
    """The integrator's stability limit for a decay (|lambda| dt), or None (adaptive: it has none)."""
    if integrator in backends.ADAPTIVE:
        return None
    tab = backends.tableau_of(integrator)   # a user's explicit tableau: its limit from R(z) (derive/user.py)
    return tab.real_axis if tab is not None else TABLEAUX.REAL_AXIS_STABILITY[integrator]


def decay_excess(effects: np.ndarray, params: np.ndarray, dt: float, integrator: str) -> tuple[int, float, float] | None:
    """The first body whose decays are beyond the integrator's limit: (body, rate * dt, limit), or None."""
    limit = decay_limit(integrator)
    if limit is None or not len(effects):
        return None
    rdt = decay_stiffness(effects, params) * dt
    bad = np.flatnonzero(~(rdt <= limit))
    return None if not bad.size else (int(bad[0]), float(rdt[bad[0]]), float(limit))


def decay_text(integrator: str, rdt: float, limit: float) -> str:
    return (f"its decays (damping) have rate*dt = {rdt:.3g} (c*dt/m, c*dt/I_min, summed over the body's decays), beyond "
            f"{integrator}'s stability limit {limit:.4g} for a linear decay (REAL_AXIS_STABILITY, derive/tableaux.py): "
            "the step would amplify what the damping should remove; reduce dt or the damping")


def _supplying_groups(effects: np.ndarray, nb: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The effect rows that are not decays, grouped by code: (code, parameter rows (k, n_params), body indices (k,)),
    a scene-wide row expanded to every body."""
    out: list[tuple[int, np.ndarray, np.ndarray]] = []
    if not len(effects):
        return out
    rows = effects[~decay_rows(effects)]
    codes = rows[:, effects_mod.ROW_CODE].astype(np.int64)
    for code in np.unique(codes):
        spec = effects_mod.spec_for_code(int(code))
        sel = rows[codes == code]
        body = sel[:, effects_mod.ROW_BODY].astype(np.int64)
        p = sel[:, effects_mod.ROW_PARAMS:effects_mod.ROW_PARAMS + spec.n_params]
        every = body < 0
        idx = np.concatenate([body[~every], np.tile(np.arange(nb), int(every.sum()))])
        p = np.concatenate([p[~every], np.repeat(p[every], nb, axis=0)])
        out.append((int(code), p, idx))
    return out


def _reads_no_state(spec) -> bool:
    """Whether an effect's loads depend on no state value (its kernel reads parameters, m, I_b only)."""
    return not set(spec.state_inputs) - {"m", "I_b"} and not spec.uses_v_w


class LoadBudget:
    """The growth budget of the bodies effects act on (module docstring): references, rates, limits.

    Parameters
    ----------
    params : ndarray (nb, PARAM_SIZE)
    effects : ndarray (n_rows, width)
        The effect table.
    rows : ndarray (nb, MODEL_SIZE)
        Model rows (joints, wheels).
    loaded : ndarray (nb,) of bool
        The bodies the check covers.
    dt : float
    growth : float
        max_growth.
    """

    def __init__(self, params, effects, rows, loaded, dt: float, growth: float):
        self.params, self.rows, self.dt, self.g = params, rows, float(dt), float(growth)
        self.loaded = np.asarray(loaded, bool)
        kind = np.zeros(len(self.loaded), np.int64)     # read from the loaded bodies' rows only (untouched pages)
        kind[self.loaded] = rows[self.loaded, LY.MODEL_KIND]
        self.wheeled = np.flatnonzero(self.loaded & ((kind & backends.KIND_WHEELS) != 0))   # (indices)
        self.plain = self.loaded & ((kind & backends.KIND_WHEELS) == 0)
        self.idx = np.flatnonzero(self.loaded)
        nb = params.shape[0]
        # (a group over every body once, in order: its loads are added, not scattered with np.add.at)
        self._groups: list[tuple[int, np.ndarray, np.ndarray | None]] = [
            (c, p, None if np.array_equal(i, np.arange(nb)) else i) for c, p, i in _supplying_groups(effects, nb)]
        # per-body constants, once: the loaded (and plain) bodies (a slice when all are), 2m, 2 I_min
        self._sel = slice(None) if self.loaded.all() else self.idx
        self._psel = slice(None) if self.plain.all() else np.flatnonzero(self.plain)
        self._2m = 2 * params[:, LY.PARAM_M]
        self._2I = 2 * params[:, LY.PARAM_I_B].min(axis=1)
        self._plain_sel = None if self.plain[self._sel].all() else self.plain[self._sel]
        # every supplying load reads no state (gravity: m and g only): its rates are those of any state, computed on
        # the first call and kept (_rates)
        self._const_rates = all(_reads_no_state(effects_mod.spec_for_code(c)) for c, _, _ in self._groups)
        self._rates_kept: tuple[np.ndarray, np.ndarray] | None = None
        self.L0, self.P0, self.RL, self.RP = np.zeros(nb), np.zeros(nb), np.zeros(nb), np.zeros(nb)
        self.t0 = np.zeros(nb)    # the step count of each body's reference
        self._scratch: np.ndarray | None = None
        self._wrote: np.ndarray | None = None        # the G screen_rows last filled, while its rows cannot change (no rates, no new data)

    def snapshot(self) -> tuple:
        """What pickling a Sim keeps of the budget (references, rates, reference steps)."""
        return tuple(a.copy() for a in (self.L0, self.P0, self.RL, self.RP, self.t0))

    def restore(self, snap: tuple) -> None:
        self.L0, self.P0, self.RL, self.RP, self.t0 = (np.array(a, dtype=np.float64) for a in snap)
        self._wrote = None

    def _momenta(self, x, Omega, v=None, w=None) -> tuple[np.ndarray, np.ndarray]:
        """(|L|, |p|) per body (0 outside the check): body |I omega|, or body + wheels for a wheeled one. v, w: x's
        v_w and omega_b columns when the caller has them (contiguous copies, _columns), else read from x."""
        nb = x.shape[0]
        if v is None or w is None:
            v, w = x[:, LY.STATE_V_W], x[:, LY.STATE_OMEGA_B]
        L, P = np.zeros(nb), np.zeros(nb)
        with np.errstate(over="ignore", invalid="ignore"):
            f = self._psel
            if self.plain.any():
                L[f] = np.linalg.norm(K.body_momentum(self.params[f, LY.PARAM_I_B], w[f]), axis=-1)
            if self.wheeled.size:     # one batched call of the printed total momentum (as the C screen's)
                wh = self.wheeled
                L[wh] = np.linalg.norm(backends.wheel_total_momentum_batch(self.rows[wh], x[wh, LY.STATE_Q], w[wh],
                                                                           Omega[wh]), axis=-1)
            s = self._sel
            P[s] = self.params[s, LY.PARAM_M] * np.linalg.norm(v[s], axis=-1)
        return L, P

    def _rates(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(|tau|, |F|) per body of the loads that can supply momentum (the decays left out), from the printed
        NumPy effect functions, one call per effect code; when none reads the state, those of the first call (the
        arrays are not written by the callers)."""
        if self._rates_kept is not None:
            return self._rates_kept
        rates = self._rates_of(x)
        if self._const_rates:
            self._rates_kept = rates
        return rates

    def _rates_of(self, x) -> tuple[np.ndarray, np.ndarray]:
        nb = x.shape[0]
        F, tau = np.zeros((nb, 3)), np.zeros((nb, 3))
        x = np.asarray(x[:, :LY.STATE_SIZE], dtype=np.float64)
        with np.errstate(all="ignore"):
            for code, p, idx in self._groups:
                at = slice(None) if idx is None else idx
                xs = x[at]
                f, t = effects_mod.numpy_apply(code)(p, xs, xs[:, LY.STATE_V_W], self.params[at, LY.PARAM_M],
                                                     self.params[at, LY.PARAM_I_B])
                for acc, v in ((F, f), (tau, t)):
                    if v is None:
                        continue
                    if idx is None:
                        acc += v
                    else:
                        np.add.at(acc, idx, np.broadcast_to(v, (idx.size, 3)))
            return np.linalg.norm(tau, axis=-1), np.linalg.norm(F, axis=-1)

    def reference(self, x, Omega, steps: int, mask=None) -> None:
        """The budget starts again from state x at step `steps` (construction, set_state: mask selects bodies)."""
        m = self.loaded if mask is None else (self.loaded & mask)
        L, P = self._momenta(x, Omega)
        RL, RP = self._rates(x)
        self.L0[m], self.P0[m], self.RL[m], self.RP[m], self.t0[m] = L[m], P[m], RL[m], RP[m], steps
        self._wrote = None

    def limits(self, steps: int, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(Lmax, Pmax) per body at step `steps`; with x, its loads' rates count too (and are remembered)."""
        if x is not None:
            self._wrote = None
            RL, RP = self._rates(x)
            with np.errstate(invalid="ignore"):
                self.RL = np.fmax(self.RL, np.where(self.loaded, RL, 0.0))
                self.RP = np.fmax(self.RP, np.where(self.loaded, RP, 0.0))
        t = (steps - self.t0) * self.dt
        with np.errstate(over="ignore", invalid="ignore"):
            return self.g * (self.L0 + t * self.RL), self.g * (self.P0 + t * self.RP)

    def screen_rows(self, G: np.ndarray, steps: int) -> None:
        """The C screen's limits (csrc/fast_step.c LV_G_*) of the loaded bodies at step `steps`, in place: no
        no-work rate, |L|² <= Lmax², and kinetic energy <= Pmax²/2m + Lmax²/2I_min (plain bodies) or (wheeled: the
        screen's |L| is of body and wheels, its energy the translational one at omega 0) <= Pmax²/2m, which is
        m|v| <= Pmax. Margin as Sim._safe_rates'."""
        s = self._sel
        if not self.idx.size or self._wrote is G:   # (rows written, and with no rates they do not grow with steps)
            return
        if self._scratch is None:                   # (made once: no fresh pages per call)
            self._scratch = np.empty((3, self.idx.size))
        t, L2, E = self._scratch                   # limits(steps)' arithmetic, on the loaded bodies only
        with np.errstate(over="ignore", invalid="ignore"):
            np.subtract(steps, self.t0[s], out=t)
            t *= self.dt
            for out, ref, rate in ((L2, self.L0, self.RL), (E, self.P0, self.RP)):   # (g * (ref + t * rate))²
                np.multiply(t, rate[s], out=out)
                out += ref[s]
                out *= self.g
                np.square(out, out=out)
            E /= self._2m[s]
            if self._plain_sel is None:
                E += np.divide(L2, self._2I[s], out=t)
            else:
                E = np.where(self._plain_sel, E + L2 / self._2I[s], E)
            G[s, 0] = -np.inf
            G[s, 1] = np.multiply(E, SCREEN_MARGIN, out=E)
            G[s, 2] = np.multiply(L2, SCREEN_MARGIN, out=L2)
        self._wrote = None if self.RL[s].any() or self.RP[s].any() else G

    def violation(self, x, Omega, steps: int) -> tuple[int, str] | None:
        """The first loaded body beyond its budget at step `steps`: (body, cause), or None."""
        # v_w and omega_b read once from the rows of x (each strided read of a column streams all of x), for the
        # momenta and the kinetic energy
        v, w = np.ascontiguousarray(x[:, LY.STATE_V_W]), np.ascontiguousarray(x[:, LY.STATE_OMEGA_B])
        L, P = self._momenta(x, Omega, v, w)
        Lmax, Pmax = self.limits(steps, x)
        f, ps = self.plain, self._psel
        with np.errstate(over="ignore", invalid="ignore"):
            E = np.zeros(x.shape[0])
            if f.any():
                E[ps] = K.kinetic_energy(self.params[ps, LY.PARAM_M], self.params[ps, LY.PARAM_I_B], v[ps], w[ps])
            Emax = Pmax ** 2 / self._2m + Lmax ** 2 / self._2I
            bad = self.loaded & ~(L <= Lmax)
            badE = f & ~(E <= Emax)
            badP = self.loaded & ~f & ~(P <= Pmax)
        worst = bad | badE | badP
        if not worst.any():
            return None
        b = int(np.flatnonzero(worst)[0])
        what = (f"|L| = {L[b]:.3g}" if bad[b] else f"kinetic energy {E[b]:.3g} J" if badE[b] else f"|p| = {P[b]:.3g}")
        return b, (f"{what} is beyond max_growth = {self.g:g} times what its loads can supply since step "
                   f"{int(self.t0[b])} (|L| <= {Lmax[b]:.3g} N·m·s, |p| <= {Pmax[b]:.3g} N·s: the decays supply "
                   "nothing, the other loads at the largest rate seen): the step is unstable here; reduce dt")
