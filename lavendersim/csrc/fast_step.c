/* lavendersim._lavender_c.Stepper: one Sim.step() inside C, with the Sim's per-step checks.

   A Stepper holds the Sim's arrays (buffers taken once), a snapshot of the last state that passed the
   checks, and the Sim's step counters. step() advances one step only when it can prove that the Python
   path (Sim._advance(1)) would accept it unchanged:
     * no other thread is inside the Sim's lock (`busy` is 0; it is set by Sim's lock guard),
     * the state and wheel rates are those of the last check (bytewise; else the pre-step bound check is due),
     * the step returns LV_OK (finite),
     * every body's |omega| * wdt_scale <= bound (the validity bound) and it is inside the growth check's
       limits (screen_pass: its no-work rate, else its E and |L| from the generated kernels).
   Otherwise it restores the arrays from the snapshot (bitwise) and returns False: the caller takes the
   Python path, which re-runs the step and raises or warns exactly as before. The GIL is held throughout
   (the Sim enables the fast path only for small scenes), so a step never interleaves with another
   Python thread. Control flow only: every number comes from lv_simulate and the arrays Sim fills.
   dopri5 (an adaptive integrator): the Adaptive's arrays h, nfev and dense are stepped in place and are part of the
   snapshot and of the "unchanged" test; rhs_evals grows by the largest per-body increment of nfev (Sim's rule). */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "kernels.h"
#include "step.h"

/* The growth check's per-body limits, a row of G (nb, LV_G_COLS) that Sim fills (Sim._safe_rates,
   LoadBudget.screen_rows): the no-work rate w_safe (|omega| <= w_safe proves E and |L| inside their limits; +inf where
   no growth check applies, -inf where the limits are always evaluated), and the limits themselves, each shrunk by a
   rounding margin (+inf where the check does not apply): of the kinetic energy and of |L|^2 — for a wheeled body
   (its model row's kind has LV_KIND_WHEELS) of its translational kinetic energy and of the total |L|^2 of body and
   wheels (the motors' torques are internal). */
enum { LV_G_W = 0, LV_G_E = 1, LV_G_L2 = 2, LV_G_COLS = 3 };

enum { FS_STATE, FS_PARAMS, FS_EFFECTS, FS_WDT, FS_GROWTH, FS_ROWS, FS_OMEGA, FS_COMMAND, FS_APPLIED, FS_H, FS_NFEV,
       FS_DENSE, FS_N };

typedef struct {
    PyObject_HEAD
    Py_buffer buf[FS_N];
    int have[FS_N];
    lv_user_effect *user_entries;
    lv_user_effects user;
    lv_models models;      /* models.cache: what lv_simulate decides from the rows and the effect table, kept (step.h) */
    int has_models, integrator, normalize, adaptive;
    double dt, bound, rtol, atol;
    size_t n_snap;         /* doubles in snap */
    long nb, ne, row_size;
    double *snap;          /* x (nb*13), Omega (nb*3), applied (nb*3) of the last checked state */
    int valid;             /* snap holds a checked state */
    long busy;             /* > 0 while the Python path holds the Sim's lock */
    long long steps, rhs_evals, per_step, max_steps;
    PyObject *fallback;    /* called by step_or_fallback when the fast path steps aside (the Python path) */
} Stepper;

static void stepper_release(Stepper *s)
{
    int i;
    for (i = 0; i < FS_N; i++)
        if (s->have[i]) { PyBuffer_Release(&s->buf[i]); s->have[i] = 0; }
    free(s->user_entries);
    s->user_entries = NULL;
    free(s->snap);
    s->snap = NULL;
    lv_model_cache_free(s->models.cache);
    s->models.cache = NULL;
}

static int stepper_traverse(Stepper *s, visitproc visit, void *arg)
{
    Py_VISIT(s->fallback);
    return 0;
}

static int stepper_clear(Stepper *s)
{
    Py_CLEAR(s->fallback);
    return 0;
}

static void stepper_dealloc(Stepper *s)
{
    PyObject_GC_UnTrack(s);
    stepper_clear(s);
    stepper_release(s);
    Py_TYPE(s)->tp_free((PyObject *)s);
}

static int take(Stepper *s, int i, PyObject *obj, int writable, Py_ssize_t n_doubles, const char *what)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &s->buf[i], flags) != 0) return -1;
    s->have[i] = 1;
    if (s->buf[i].itemsize != 8 || s->buf[i].format == NULL || strchr(s->buf[i].format, 'd') == NULL
        || (n_doubles >= 0 && s->buf[i].len != n_doubles * 8)) {
        PyErr_Format(PyExc_ValueError, "Stepper: %s must be a C-contiguous float64 array of %zd numbers", what, n_doubles);
        return -1;
    }
    return 0;
}

/* Stepper(state, params, effects, integrator, normalize, dt, per_step, max_steps, wdt_scale, bound, growth,
           user_effects, rows, Omega, command, applied[, h, nfev, dense, rtol, atol]) — the model arrays all None or
   all given; an adaptive integrator with its Adaptive's h, nfev (nb,), dense (nb, LV_DENSE_SIZE) or None, rtol, atol. */
static int stepper_init(Stepper *s, PyObject *args, PyObject *kw)
{
    PyObject *st, *pr, *ef, *wdt, *growth, *user_obj, *rows, *om, *cm, *ap, *h_obj = Py_None, *nfev_obj = Py_None,
             *dense_obj = Py_None;
    long long per_step, max_steps;
    Py_ssize_t nb;
    (void)kw;
    stepper_release(s);
    s->rtol = s->atol = 0.0;
    if (!PyArg_ParseTuple(args, "OOOipdLLOdOOOOOO|OOOdd:Stepper", &st, &pr, &ef, &s->integrator, &s->normalize, &s->dt,
                          &per_step, &max_steps, &wdt, &s->bound, &growth, &user_obj, &rows, &om, &cm, &ap, &h_obj,
                          &nfev_obj, &dense_obj, &s->rtol, &s->atol))
        return -1;
    s->adaptive = s->integrator >= 0 && s->integrator <= LV_INTEGRATOR_LAST && LV_INTEGRATOR_ADAPTIVE(s->integrator);
    if (s->integrator < 0 || s->integrator > LV_INTEGRATOR_LAST || (s->adaptive && (h_obj == Py_None || nfev_obj == Py_None))) {
        PyErr_SetString(PyExc_ValueError, "Stepper: an integrator code (an adaptive one with h, nfev, dense, rtol, atol)");
        return -1;
    }
    if (take(s, FS_STATE, st, 1, -1, "state") != 0) return -1;
    nb = s->buf[FS_STATE].len / 8 / LV_STATE_SIZE;
    if (nb * LV_STATE_SIZE * 8 != s->buf[FS_STATE].len || nb == 0) {
        PyErr_SetString(PyExc_ValueError, "Stepper: state must be (nb, 13), nb >= 1");
        return -1;
    }
    s->nb = (long)nb;
    if (take(s, FS_PARAMS, pr, 0, nb * LV_PARAM_SIZE, "params") != 0) return -1;
    if (take(s, FS_EFFECTS, ef, 0, -1, "effects") != 0) return -1;
    if (s->buf[FS_EFFECTS].ndim == 2 && s->buf[FS_EFFECTS].shape[1] >= LV_EFFECT_ROW_PARAMS) {
        s->row_size = (long)s->buf[FS_EFFECTS].shape[1];
        s->ne = (long)s->buf[FS_EFFECTS].shape[0];
    } else if (s->buf[FS_EFFECTS].len == 0) {
        s->row_size = LV_EFFECT_ROW_PARAMS + LV_EFFECT_ROW_MIN_PARAMS;
        s->ne = 0;
    } else {
        PyErr_SetString(PyExc_ValueError, "Stepper: effects must be (ne, row) with row >= 2");
        return -1;
    }
    if (take(s, FS_WDT, wdt, 0, nb, "wdt_scale") != 0 || take(s, FS_GROWTH, growth, 0, nb * LV_G_COLS, "growth") != 0) return -1;
    s->has_models = rows != Py_None;
    if (s->has_models) {
        if (take(s, FS_ROWS, rows, 0, nb * LV_MODEL_SIZE, "rows") != 0 || take(s, FS_OMEGA, om, 1, nb * LV_NW, "Omega") != 0
            || take(s, FS_COMMAND, cm, 0, nb * LV_NW, "command") != 0 || take(s, FS_APPLIED, ap, 1, nb * LV_NW, "applied") != 0)
            return -1;
        s->models.rows = (const double *)s->buf[FS_ROWS].buf;
        s->models.Omega = (double *)s->buf[FS_OMEGA].buf;
        s->models.command = (const double *)s->buf[FS_COMMAND].buf;
        s->models.applied = (double *)s->buf[FS_APPLIED].buf;
    }
    /* marked: Sim reports its writes to the rows (rows_written); a plain scene's keeps only the effect index and the
       bodies' order (no model entries) */
    s->models.cache = lv_model_cache_new(s->has_models ? (long)nb : 0, 1);
    if (s->models.cache == NULL) { PyErr_NoMemory(); return -1; }
    if (s->adaptive && (take(s, FS_H, h_obj, 1, nb, "h") != 0 || take(s, FS_NFEV, nfev_obj, 1, nb, "nfev") != 0
                        || (dense_obj != Py_None && take(s, FS_DENSE, dense_obj, 1, nb * LV_DENSE_SIZE, "dense") != 0)))
        return -1;
    s->user.entries = NULL;
    s->user.n = 0;
    if (user_obj != Py_None) {
        Py_buffer v;
        Py_ssize_t i;
        if (PyObject_GetBuffer(user_obj, &v, PyBUF_C_CONTIGUOUS) != 0) return -1;
        if (v.itemsize != 8 || v.ndim != 2 || (v.shape[1] != 3 && v.shape[1] != 6 && v.shape[1] != 10 && v.shape[1] != 16)) {
            PyBuffer_Release(&v);
            PyErr_SetString(PyExc_ValueError, "Stepper: user_effects must be int64 (n, 3), (n, 6), (n, 10) or (n, 16)");
            return -1;
        }
        s->user.n = (long)v.shape[0];
        s->user_entries = (lv_user_effect *)calloc((size_t)s->user.n + 1, sizeof(lv_user_effect));
        if (s->user_entries == NULL) { PyBuffer_Release(&v); PyErr_NoMemory(); return -1; }
        for (i = 0; i < s->user.n; i++)
            lv_user_table_row((const long long *)v.buf + v.shape[1] * i, (int)v.shape[1], &s->user_entries[i]);
        PyBuffer_Release(&v);
        s->user.entries = s->user_entries;
    }
    /* x, Omega, applied; then h, nfev, dense of an adaptive integrator */
    s->n_snap = (size_t)nb * (LV_STATE_SIZE + 2 * LV_NW
                              + (s->adaptive ? 2 + (s->have[FS_DENSE] ? LV_DENSE_SIZE : 0) : 0));
    s->snap = (double *)malloc(sizeof(double) * s->n_snap);
    if (s->snap == NULL) { PyErr_NoMemory(); return -1; }
    s->valid = 0;
    s->busy = 0;
    s->per_step = per_step;
    s->max_steps = max_steps;
    return 0;
}

/* The adaptive arrays in the snapshot's order (h, nfev, dense), from offset nx + 2 nw: 0 .. 3 arrays. */
static int adaptive_parts(const Stepper *s, double **part, size_t *len)
{
    static const int which[3] = {FS_H, FS_NFEV, FS_DENSE};
    int i, n = 0;
    for (i = 0; i < 3; i++)
        if (s->adaptive && s->have[which[i]]) {
            part[n] = (double *)s->buf[which[i]].buf;
            len[n++] = (size_t)(s->buf[which[i]].len / 8);
        }
    return n;
}

/* Copy the arrays into the snapshot (to = 1) or back from it (to = 0). */
static void snap_copy(Stepper *s, int to)
{
    const size_t nx = (size_t)s->nb * LV_STATE_SIZE, nw = (size_t)s->nb * LV_NW;
    double *x = (double *)s->buf[FS_STATE].buf, *part[3], *at = s->snap + nx + 2 * nw;
    size_t len[3];
    int i, n = adaptive_parts(s, part, len);
    if (to) memcpy(s->snap, x, nx * sizeof(double)); else memcpy(x, s->snap, nx * sizeof(double));
    for (i = 0; i < n; at += len[i], i++)
        if (to) memcpy(at, part[i], len[i] * sizeof(double)); else memcpy(part[i], at, len[i] * sizeof(double));
    if (!s->has_models) return;
    if (to) {
        memcpy(s->snap + nx, s->models.Omega, nw * sizeof(double));
        memcpy(s->snap + nx + nw, s->models.applied, nw * sizeof(double));
    } else {
        memcpy(s->models.Omega, s->snap + nx, nw * sizeof(double));
        memcpy(s->models.applied, s->snap + nx + nw, nw * sizeof(double));
    }
}

static int unchanged(const Stepper *s)
{
    const size_t nx = (size_t)s->nb * LV_STATE_SIZE, nw = (size_t)s->nb * LV_NW;
    const double *at = s->snap + nx + 2 * nw;
    double *part[3];
    size_t len[3];
    int i, n = adaptive_parts(s, part, len);
    if (!s->valid || memcmp(s->snap, s->buf[FS_STATE].buf, nx * sizeof(double)) != 0) return 0;
    for (i = 0; i < n; at += len[i], i++)
        if (memcmp(at, part[i], len[i] * sizeof(double)) != 0) return 0;
    return !s->has_models || memcmp(s->snap + nx, s->models.Omega, nw * sizeof(double)) == 0;
}

/* 1 when body x (params prm) is inside its growth limits g: |omega| = w <= w_safe, else its kinetic energy and |L|^2
   from the generated kinetic_energy and body_momentum kernels are at most g's limits (NaN fails). A wheeled body (row
   not NULL, its kind with LV_KIND_WHEELS; Omega its wheel rates): the kinetic energy at omega = 0 (translation) and
   the total |L| of body and wheels from the printed LV_WHEELS_TOTAL_MOMENTUM, as LoadBudget._momenta and
   Sim._invariants (backends.wheel_total_momentum_batch, the NumPy print of the same kernel); with its row's
   momentum-bound factors (bound, not NULL) first the printed LV_WHEELS_MOMENTUM_BOUND, an upper bound on that |L|^2
   as computed (derive/growth_bound.py): inside the limit, |L| is not evaluated (the same answer, as |L|^2 <= it). */
static int growth_pass(const double *x, const double *prm, const double *g, double w, const double *row,
                       const double *Omega, const double *bound)
{
    static const double at_rest[3] = {0.0, 0.0, 0.0};
    double T, L[3], L2_max;
    if (w <= g[LV_G_W]) return 1;
    if (row != NULL && ((int)row[LV_MODEL_KIND] & LV_KIND_WHEELS)) {
        lv_kinetic_energy(prm[LV_PARAM_M], prm + LV_PARAM_I_B, x + LV_STATE_V_W, at_rest, &T);
        if (!(T <= g[LV_G_E])) return 0;
        if (bound != NULL) {
            LV_WHEELS_MOMENTUM_BOUND(x + LV_STATE_Q, w, Omega, bound, &L2_max);
            if (L2_max <= g[LV_G_L2]) return 1;
        }
        LV_WHEELS_TOTAL_MOMENTUM(x + LV_STATE_Q, x + LV_STATE_OMEGA_B, Omega, row + LV_MODEL_I_P, row + LV_MODEL_A_B,
                                 row + LV_MODEL_J, L);
    } else {
        lv_kinetic_energy(prm[LV_PARAM_M], prm + LV_PARAM_I_B, x + LV_STATE_V_W, x + LV_STATE_OMEGA_B, &T);
        lv_body_momentum(prm + LV_PARAM_I_B, x + LV_STATE_OMEGA_B, L);
    }
    return T <= g[LV_G_E] && L[0] * L[0] + L[1] * L[1] + L[2] * L[2] <= g[LV_G_L2];
}

/* 1 when every body's |omega| * scale <= bound and it passes growth_pass with its row of G (NaN fails): the
   per-chunk screen, shared by the Stepper and the module-level checks_pass. Exact where it passes: a body beyond
   its no-work rate has its invariants evaluated here, so a spinning body whose rate exceeds w_safe (any body with
   I_max/I_min > max_growth) does not send every step to the Python path. rows, Omega: the model rows (nb,
   LV_MODEL_SIZE) and wheel rates (nb, LV_NW), or NULL (no wheeled body); factors: the rows' momentum-bound factors
   (nb, LV_WHEELS_BOUND_SIZE: the Stepper's model cache, made from these rows), or NULL. */
static int screen_pass(const double *x, const double *params, long nb, const double *scale, double bound,
                       const double *G, const double *rows, const double *Omega, const double *factors)
{
    long b;
    for (b = 0; b < nb; b++) {
        const double *xb = x + b * LV_STATE_SIZE;
        double w, wdt;
        lv_validity_wdt(xb + LV_STATE_OMEGA_B, scale[b], &w, &wdt); /* the printed validity measure, as Sim's */
        if (!(wdt <= bound)
            || !growth_pass(xb, params + b * LV_PARAM_SIZE, G + b * LV_G_COLS, w,
                            rows ? rows + b * LV_MODEL_SIZE : NULL, rows ? Omega + b * LV_NW : NULL,
                            rows && factors ? factors + b * LV_WHEELS_BOUND_SIZE : NULL))
            return 0;
    }
    return 1;
}

/* Relative margin of the float32 screen: the Sim's NumPy check of a float32 state rounds some of its
   intermediates to float32 (|omega|, and squares in kinetic_energy: a few float32 roundings, ~1e-6 relative at
   most, every term of E, |L|^2 and |omega|^2 positive), so the screen passes only what is this far inside. */
#define LV_SCREEN_F32_MARGIN 1e-5

/* screen_pass of a float32 state (Sim(dtype="float32"): params and limits float64): each body's numbers
   converted to double (exact), the bound, the no-work rate and the E and |L|^2 limits shrunk by
   LV_SCREEN_F32_MARGIN. A body at or below the shrunk no-work rate is inside its limits by more than the margin
   (E <= T_v + I_max |omega|^2 / 2 and |L| <= I_max |omega|, the rate's definition in Sim._safe_rates), whatever
   the NumPy check's float32 roundings. Passes only what the NumPy check passes. Plain bodies (float32 steps no
   models). */
static int screen_pass_f32(const float *x, const double *params, long nb, const double *scale, double bound,
                           const double *G)
{
    const double keep = 1.0 - LV_SCREEN_F32_MARGIN;
    long b;
    int k;
    for (b = 0; b < nb; b++) {
        const double *g = G + b * LV_G_COLS;
        double xb[LV_STATE_SIZE], gb[LV_G_COLS], w, wdt;
        for (k = 0; k < LV_STATE_SIZE; k++) xb[k] = (double)x[b * LV_STATE_SIZE + k];
        lv_validity_wdt(xb + LV_STATE_OMEGA_B, scale[b], &w, &wdt);
        gb[LV_G_W] = g[LV_G_W] * keep; /* a NaN w fails the bound test below */
        gb[LV_G_E] = g[LV_G_E] * keep;
        gb[LV_G_L2] = g[LV_G_L2] * keep;
        if (!(wdt <= bound * keep) || !growth_pass(xb, params + b * LV_PARAM_SIZE, gb, w, NULL, NULL, NULL)) return 0;
    }
    return 1;
}

/* The Stepper's screen after a call: the wheeled bodies' momentum bounds from its model cache when that is made from
   the rows as they are (valid: lv_simulate's fixed-step calls make it; the rows are not written inside a call). */
static int checks_pass(const Stepper *s)
{
    const lv_model_cache *c = s->has_models ? s->models.cache : NULL;
    return screen_pass((const double *)s->buf[FS_STATE].buf, (const double *)s->buf[FS_PARAMS].buf, s->nb,
                       (const double *)s->buf[FS_WDT].buf, s->bound, (const double *)s->buf[FS_GROWTH].buf,
                       s->has_models ? s->models.rows : NULL, s->has_models ? s->models.Omega : NULL,
                       c != NULL && c->valid && c->nb == s->nb ? c->bound : NULL);
}

static int fast_step(Stepper *s, long n)
{
    long fail_step = -1, fail_body = -1, b;
    int status;
    lv_adaptive ad;
    double inc = 0.0;
    if (s->busy || s->snap == NULL || n < 1 || s->steps + n > s->max_steps || !unchanged(s))
        return 0;
    if (s->adaptive) {
        ad.rtol = s->rtol, ad.atol = s->atol;
        ad.h = (double *)s->buf[FS_H].buf, ad.nfev = (double *)s->buf[FS_NFEV].buf;
        ad.dense = s->have[FS_DENSE] ? (double *)s->buf[FS_DENSE].buf : NULL;
    }
    status = lv_simulate((double *)s->buf[FS_STATE].buf, (const double *)s->buf[FS_PARAMS].buf, s->nb,
                         (const double *)s->buf[FS_EFFECTS].buf, s->ne, s->row_size, s->user.n ? &s->user : NULL,
                         s->has_models ? &s->models : NULL, s->models.cache, s->integrator, s->normalize, s->dt, n,
                         s->adaptive ? &ad : NULL, NULL, &fail_step, &fail_body);
    /* lv_simulate checks its arguments (effect codes and bodies, model kinds) before it writes anything: a table it
       rejects, as a step that fails a check, goes to the Python path, which raises the named error */
    if (status != LV_OK || !checks_pass(s)) {
        snap_copy(s, 0);
        return 0;
    }
    if (s->adaptive) {   /* the largest per-body increment (nfev's copy in the snapshot follows h's) */
        const double *before = s->snap + (size_t)s->nb * (LV_STATE_SIZE + 2 * LV_NW + 1);
        for (b = 0; b < s->nb; b++)
            if (ad.nfev[b] - before[b] > inc) inc = ad.nfev[b] - before[b];
    }
    snap_copy(s, 1);
    s->steps += n;
    s->rhs_evals += s->adaptive ? (long long)inc : s->per_step * n;
    return 1;
}

static PyObject *stepper_step(Stepper *s, PyObject *noargs)
{
    (void)noargs;
    return PyBool_FromLong(fast_step(s, 1));
}

/* advance(n) -> bool: n steps in one call, checked at the end only — what Sim._advance(n) does for n up to
   its chunk (the caller guarantees that, and that n * the scene's work fits the fast path). */
static PyObject *stepper_advance(Stepper *s, PyObject *arg)
{
    long n = PyLong_AsLong(arg);
    if (n == -1 && PyErr_Occurred()) return NULL;
    return PyBool_FromLong(fast_step(s, n));
}

static PyObject *stepper_step_or_fallback(Stepper *s, PyObject *noargs)
{
    (void)noargs;
    if (fast_step(s, 1)) Py_RETURN_NONE;
    if (s->fallback == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Stepper: no fallback set");
        return NULL;
    }
    return PyObject_CallNoArgs(s->fallback);
}

static PyObject *stepper_set_fallback(Stepper *s, PyObject *fn)
{
    if (!PyCallable_Check(fn)) {
        PyErr_SetString(PyExc_TypeError, "Stepper.set_fallback: needs a callable");
        return NULL;
    }
    Py_INCREF(fn);
    Py_XSETREF(s->fallback, fn);
    Py_RETURN_NONE;
}

static PyObject *stepper_mark_checked(Stepper *s, PyObject *noargs)
{
    (void)noargs;
    if (s->snap != NULL) {
        snap_copy(s, 1);
        s->valid = 1;
    }
    Py_RETURN_NONE;
}

/* rows_written(): the Sim wrote its model rows (Sim._model_row, _load_snapshot: their only writers once the Stepper
   exists; the public view is read-only): the per-body decisions kept from them are made again at the next call. */
static PyObject *stepper_rows_written(Stepper *s, PyObject *noargs)
{
    (void)noargs;
    if (s->has_models) lv_model_cache_rows_written(s->models.cache);
    Py_RETURN_NONE;
}

static PyObject *stepper_is_checked(Stepper *s, PyObject *noargs)
{
    (void)noargs;
    return PyBool_FromLong(s->snap != NULL && unchanged(s));
}

static PyMethodDef stepper_methods[] = {
    {"step", (PyCFunction)stepper_step, METH_NOARGS,
     "step() -> bool: one step with the Sim's checks passed (True), or nothing changed (False: take the Python path)."},
    {"advance", (PyCFunction)stepper_advance, METH_O,
     "advance(n) -> bool: n steps checked at the end (as one chunk of Sim._advance), or nothing changed (False)."},
    {"step_or_fallback", (PyCFunction)stepper_step_or_fallback, METH_NOARGS,
     "step_or_fallback(): one step, inside C when every check passes, else by the fallback (the Python path)."},
    {"set_fallback", (PyCFunction)stepper_set_fallback, METH_O, "set_fallback(fn): what step_or_fallback calls."},
    {"mark_checked", (PyCFunction)stepper_mark_checked, METH_NOARGS,
     "mark_checked(): the current arrays passed the checks; snapshot them."},
    {"rows_written", (PyCFunction)stepper_rows_written, METH_NOARGS,
     "rows_written(): the model rows were written; what the Stepper keeps from them is made again at the next call."},
    {"is_checked", (PyCFunction)stepper_is_checked, METH_NOARGS,
     "is_checked() -> bool: state and wheel rates are bytewise those of the last mark_checked / step."},
    {NULL, NULL, 0, NULL}};

static PyObject *get_ll(Stepper *s, void *field) { return PyLong_FromLongLong(*(long long *)((char *)s + (size_t)field)); }
static int set_ll(Stepper *s, PyObject *v, void *field)
{
    long long n;
    if (v == NULL) { PyErr_SetString(PyExc_AttributeError, "cannot delete"); return -1; }
    n = PyLong_AsLongLong(v);
    if (n == -1 && PyErr_Occurred()) return -1;
    *(long long *)((char *)s + (size_t)field) = n;
    return 0;
}
static PyObject *get_busy(Stepper *s, void *c) { (void)c; return PyLong_FromLong(s->busy); }
static int set_busy(Stepper *s, PyObject *v, void *c)
{
    long n;
    (void)c;
    if (v == NULL) { PyErr_SetString(PyExc_AttributeError, "cannot delete"); return -1; }
    n = PyLong_AsLong(v);
    if (n == -1 && PyErr_Occurred()) return -1;
    s->busy = n;
    return 0;
}

static PyGetSetDef stepper_getset[] = {
    {"steps", (getter)get_ll, (setter)set_ll, "steps taken (the Sim's counter)", (void *)offsetof(Stepper, steps)},
    {"rhs_evals", (getter)get_ll, (setter)set_ll, "RHS evaluations (the Sim's counter)", (void *)offsetof(Stepper, rhs_evals)},
    {"busy", (getter)get_busy, (setter)set_busy, "> 0 while the Python path holds the Sim's lock", NULL},
    {NULL, NULL, NULL, NULL, NULL}};

static PyTypeObject StepperType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "lavendersim._lavender_c.Stepper",
    .tp_basicsize = sizeof(Stepper),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_traverse = (traverseproc)stepper_traverse,
    .tp_clear = (inquiry)stepper_clear,
    .tp_doc = "Stepper(...): one Sim step inside C with the Sim's checks (see fast_step.c).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)stepper_init,
    .tp_dealloc = (destructor)stepper_dealloc,
    .tp_methods = stepper_methods,
    .tp_getset = stepper_getset,
};

/* checks_pass(x, params, wdt_scale, bound, growth[, rows, Omega]) -> bool (x float64, or float32: screen_pass_f32):
   every body's |omega| * wdt_scale <= bound and inside its growth limits (screen_pass; growth (nb, 3) as LV_G_*; rows
   (nb, LV_MODEL_SIZE) and Omega (nb, LV_NW), float64, give the wheeled bodies their total |L|; float32 states are of
   plain bodies), the Sim's screen of its per-chunk checks in one pass without temporaries; False means "look closer"
   (the Sim's NumPy check decides and names the cause). */
static PyObject *py_checks_pass(PyObject *self, PyObject *args)
{
    PyObject *obj[6] = {NULL, NULL, NULL, NULL, Py_None, Py_None};
    Py_buffer buf[6];
    const Py_ssize_t width[6] = {LV_STATE_SIZE, LV_PARAM_SIZE, 1, LV_G_COLS, LV_MODEL_SIZE, LV_NW};
    double bound;
    Py_ssize_t nb;
    int ok = 1, i, got = 0, n;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOdO|OO:checks_pass", &obj[0], &obj[1], &obj[2], &bound, &obj[3], &obj[4], &obj[5]))
        return NULL;
    n = obj[4] == Py_None ? 4 : 6;
    for (got = 0; got < n; got++)
        if (PyObject_GetBuffer(obj[got], &buf[got], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) != 0) { ok = -2; break; }
    if (ok == 1) {
        const char *f = buf[0].format ? buf[0].format : "B";
        const int f32 = buf[0].itemsize == 4 && (strcmp(f, "f") == 0 || strcmp(f, "<f") == 0 || strcmp(f, "=f") == 0);
        nb = buf[0].len / buf[0].itemsize / LV_STATE_SIZE;
        if (!f32 && (buf[0].itemsize != 8 || (strcmp(f, "d") != 0 && strcmp(f, "<d") != 0 && strcmp(f, "=d") != 0)))
            ok = -1;
        if (buf[0].len != nb * LV_STATE_SIZE * buf[0].itemsize || (f32 && n == 6)) ok = -1;
        for (i = 1; i < n; i++)
            if (buf[i].itemsize != 8 || buf[i].len != nb * width[i] * 8) ok = -1;
        if (ok < 0) {
            PyErr_SetString(PyExc_ValueError, "checks_pass: x (nb, 13) float64 or float32, params (nb, PARAM_SIZE), "
                                              "wdt_scale (nb,), growth (nb, 3) float64[, rows (nb, MODEL_SIZE), "
                                              "Omega (nb, WHEELS_MAX) float64 with a float64 x]");
        } else {
            Py_BEGIN_ALLOW_THREADS
            ok = f32 ? screen_pass_f32((const float *)buf[0].buf, (const double *)buf[1].buf, (long)nb,
                                       (const double *)buf[2].buf, bound, (const double *)buf[3].buf)
                     : screen_pass((const double *)buf[0].buf, (const double *)buf[1].buf, (long)nb,
                                   (const double *)buf[2].buf, bound, (const double *)buf[3].buf,
                                   n == 6 ? (const double *)buf[4].buf : NULL, n == 6 ? (const double *)buf[5].buf : NULL,
                                   NULL);
            Py_END_ALLOW_THREADS
        }
    }
    for (i = 0; i < got; i++) PyBuffer_Release(&buf[i]);
    if (ok < 0) return NULL;
    return PyBool_FromLong(ok);
}

static PyMethodDef fast_functions[] = {
    {"checks_pass", py_checks_pass, METH_VARARGS,
     "checks_pass(x, params, wdt_scale, bound, growth[, rows, Omega]) -> bool: all |omega|*wdt_scale <= bound and inside "
     "the growth limits (rows, Omega: the wheeled bodies' total |L|)."},
    {NULL, NULL, 0, NULL}};

int lv_add_stepper_type(PyObject *m)
{
    if (PyModule_AddFunctions(m, fast_functions) != 0) return -1;
    if (PyType_Ready(&StepperType) < 0) return -1;
    Py_INCREF(&StepperType);
    if (PyModule_AddObject(m, "Stepper", (PyObject *)&StepperType) < 0) {
        Py_DECREF(&StepperType);
        return -1;
    }
    return 0;
}
