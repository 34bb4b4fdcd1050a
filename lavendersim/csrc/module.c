/* lavendersim._lavender_c: CPython glue for the generated kernels and the C stepping loop.
   Arrays arrive through the buffer protocol (no NumPy headers): C-contiguous float64. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "kernels.h"
#include "step.h"

#ifndef LV_GENERATED_HASH
#error "LV_GENERATED_HASH must be defined by the build (sha256 of the generated C sources)"
#endif

static int is_float64_format(const char *fmt)
{
    if (fmt == NULL) return 1; /* no format requested/provided means unsigned bytes; reject below */
    if (fmt[0] == '@' || fmt[0] == '=') fmt++;
#if PY_LITTLE_ENDIAN
    else if (fmt[0] == '<') fmt++;
#else
    else if (fmt[0] == '>' || fmt[0] == '!') fmt++;
#endif
    return strcmp(fmt, "d") == 0;
}

/* Get a C-contiguous float64 buffer; on failure set a clear exception naming `what`. */
static int get_f64(PyObject *obj, Py_buffer *view, int writable, const char *what)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) != 0) {
        PyObject *exc, *val, *tb;
        PyErr_Fetch(&exc, &val, &tb);
        Py_XDECREF(tb);
        PyErr_Format(PyExc_TypeError,
                     "%s must be a C-contiguous%s float64 buffer (e.g. a numpy array), got %.200s (%S)",
                     what, writable ? ", writable" : "", Py_TYPE(obj)->tp_name, val ? val : Py_None);
        Py_XDECREF(exc);
        Py_XDECREF(val);
        return -1;
    }
    if (view->format == NULL || !is_float64_format(view->format) || view->itemsize != 8) {
        PyErr_Format(PyExc_TypeError, "%s must have dtype float64 (buffer format 'd'), got format '%s'",
                     what, view->format ? view->format : "B");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* Require shape (rows, cols) with cols fixed; rows returned. A 1-D empty buffer counts as (0, cols). */
static int rows_of(Py_buffer *v, Py_ssize_t cols, const char *what, const char *layout, Py_ssize_t *rows)
{
    if (v->ndim == 2 && v->shape[1] == cols) {
        *rows = v->shape[0];
        return 0;
    }
    if (v->ndim == 1 && v->shape[0] == 0) {
        *rows = 0;
        return 0;
    }
    if (v->ndim == 2)
        PyErr_Format(PyExc_ValueError, "%s must have shape (n, %zd) %s, got (%zd, %zd)",
                     what, cols, layout, v->shape[0], v->shape[1]);
    else
        PyErr_Format(PyExc_ValueError, "%s must be 2-D with shape (n, %zd) %s, got %d-D",
                     what, cols, layout, v->ndim);
    return -1;
}

/* The user-effect table: an int64 buffer (n, 3) of [function address, n_params, flags] rows, or (n, 6) with the
   tile forms' addresses, or (n, 10) with the body-frame form's too, or (n, 16) with the fused tiles' (lv_user_table_row), row i for code LV_EFFECT_USER_BASE + i (address 0: no such code). On success *out is malloc'ed (or NULL for none). */
static int get_user_table(PyObject *obj, lv_user_effect **out, long *n)
{
    Py_buffer v;
    Py_ssize_t i;
    const char *f;
    *out = NULL;
    *n = 0;
    if (obj == Py_None) return 0;
    if (PyObject_GetBuffer(obj, &v, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) != 0) return -1;
    f = v.format ? v.format : "B";
    if (f[0] == '@' || f[0] == '=' || f[0] == '<') f++;
    if (v.itemsize != 8 || (strcmp(f, "q") != 0 && strcmp(f, "l") != 0) || v.ndim != 2
        || (v.shape[1] != 3 && v.shape[1] != 6 && v.shape[1] != 10 && v.shape[1] != 16)) {
        PyErr_SetString(PyExc_TypeError, "simulate: user_effects must be a C-contiguous int64 array of shape (n, 3) "
                                         "[function address, n_params, flags], (n, 6) [..., tile forms base, avx2, "
                                         "avx512], (n, 10) [..., body-frame form, its tile forms base, avx2, avx512] or "
                                         "(n, 16) [..., fused tiles raw base, avx2, avx512, normalized base, avx2, avx512]");
        PyBuffer_Release(&v);
        return -1;
    }
    *n = (long)v.shape[0];
    *out = (lv_user_effect *)calloc((size_t)*n + 1, sizeof(lv_user_effect));
    if (*out == NULL) { PyBuffer_Release(&v); PyErr_NoMemory(); return -1; }
    for (i = 0; i < v.shape[0]; i++)
        lv_user_table_row((const long long *)v.buf + v.shape[1] * i, (int)v.shape[1], &(*out)[i]);
    PyBuffer_Release(&v);
    return 0;
}

/* The built-in effect codes as text, for error messages: "1 (applied_torque), 2 (...), ...". */
static PyObject *builtin_codes_text(void)
{
    PyObject *parts = PyList_New(0), *sep, *out;
    int code;
    if (parts == NULL) return NULL;
    for (code = 0; code < LV_EFFECT_USER_BASE; code++) {
        const char *name = lv_effect_name(code);
        PyObject *t;
        if (name == NULL) continue;
        t = PyUnicode_FromFormat("%d (%s)", code, name);
        if (t == NULL || PyList_Append(parts, t) != 0) { Py_XDECREF(t); Py_DECREF(parts); return NULL; }
        Py_DECREF(t);
    }
    sep = PyUnicode_FromString(", ");
    out = sep ? PyUnicode_Join(sep, parts) : NULL;
    Py_XDECREF(sep);
    Py_DECREF(parts);
    return out;
}

/* Check every effect row: a declared code (built in, or in the user table) whose parameters fit the row,
   and a body of -1 or a valid index. Sets ValueError naming the row. */
static int check_effects(const double *ef, Py_ssize_t ne, Py_ssize_t row_size, Py_ssize_t nb,
                         const lv_user_effect *user, long n_user)
{
    Py_ssize_t e;
    lv_user_effects table;
    table.entries = user;
    table.n = n_user;
    for (e = 0; e < ne; e++) {
        const double *row = ef + e * row_size;
        const double kind = row[LV_EFFECT_ROW_CODE], body = row[LV_EFFECT_ROW_BODY];
        int np;
        const int status = lv_effect_row_check(row, (long)row_size, (long)nb, &table, &np);
        if (status == LV_UNKNOWN_EFFECT) {
            PyObject *ko = PyFloat_FromDouble(kind), *known = builtin_codes_text();
            if (np < 0)
                PyErr_Format(PyExc_ValueError,
                             "simulate: effects[%zd] code %R is not a declared effect (built-in codes: %U; user "
                             "codes from %d need their table, %ld loaded)", e, ko, known, LV_EFFECT_USER_BASE, n_user);
            else
                PyErr_Format(PyExc_ValueError, "simulate: effects[%zd] (code %R) needs %d parameters but rows hold %zd",
                             e, ko, np, row_size - LV_EFFECT_ROW_PARAMS);
            Py_XDECREF(ko);
            Py_XDECREF(known);
            return -1;
        }
        if (status == LV_BAD_ARGUMENT) {
            PyObject *bo = PyFloat_FromDouble(body);
            PyErr_Format(PyExc_ValueError, "simulate: effects[%zd] body must be -1 (every body) or an index in [0, %zd), got %R",
                         e, nb, bo);
            Py_XDECREF(bo);
            return -1;
        }
    }
    return 0;
}

/* The user's explicit Runge-Kutta method: tableau = (a (s, s) strictly lower, b_num (s,), b_den > 0), float64 and
   finite, 1 <= s <= LV_TABLEAU_MAX_STAGES (lv_tableau). On success *tab points into copies held by *a_buf, *b_buf
   (the caller releases them); else a ValueError or TypeError naming the rule. */
static int get_tableau(PyObject *obj, lv_tableau *tab, Py_buffer *a_buf, Py_buffer *b_buf)
{
    PyObject *a_obj, *b_obj;
    double b_den;
    Py_ssize_t s, i, j;
    const double *a, *bn;
    if (!PyTuple_Check(obj) || !PyArg_ParseTuple(obj, "OOd:simulate tableau", &a_obj, &b_obj, &b_den)) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "simulate: tableau must be a tuple (a (s, s), b_num (s,), b_den)");
        return -1;
    }
    if (get_f64(a_obj, a_buf, 0, "simulate: tableau a") != 0) return -1;
    if (get_f64(b_obj, b_buf, 0, "simulate: tableau b_num") != 0) { PyBuffer_Release(a_buf); return -1; }
    s = b_buf->ndim == 1 ? b_buf->shape[0] : -1;
    if (s < 1 || s > LV_TABLEAU_MAX_STAGES || a_buf->ndim != 2 || a_buf->shape[0] != s || a_buf->shape[1] != s) {
        PyErr_Format(PyExc_ValueError, "simulate: tableau a must have shape (s, s) and b_num (s,) with 1 <= s <= %d",
                     LV_TABLEAU_MAX_STAGES);
        goto fail;
    }
    a = (const double *)a_buf->buf;
    bn = (const double *)b_buf->buf;
    for (i = 0; i < s; i++) {
        if (!isfinite(bn[i])) goto bad;
        for (j = 0; j < s; j++)
            if (!isfinite(a[i * s + j]) || (j >= i && a[i * s + j] != 0.0)) goto bad;
    }
    if (!(b_den > 0.0 && isfinite(b_den))) goto bad;
    tab->s = (int)s;
    tab->a = a;
    tab->b_num = bn;
    tab->b_den = b_den;
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "simulate: tableau must be explicit (a strictly lower triangular) with finite "
                                      "entries and b_den > 0");
fail:
    PyBuffer_Release(a_buf);
    PyBuffer_Release(b_buf);
    return -1;
}

static PyObject *py_kernels(PyObject *self, PyObject *noargs)
{
    PyObject *out = PyList_New(LV_KERNEL_COUNT);
    int i;
    (void)self; (void)noargs;
    if (out == NULL) return NULL;
    for (i = 0; i < LV_KERNEL_COUNT; i++) {
        PyObject *t = Py_BuildValue("(sii)", lv_kernel_table[i].name, lv_kernel_table[i].n_in,
                                    lv_kernel_table[i].n_out);
        if (t == NULL) { Py_DECREF(out); return NULL; }
        PyList_SET_ITEM(out, i, t);
    }
    return out;
}

static PyObject *py_eval_kernel(PyObject *self, PyObject *args)
{
    int index;
    PyObject *inp_obj, *out_obj;
    Py_buffer inp, out;
    Py_ssize_t n_in_total, n_out_total, rows, r;
    const lv_kernel_info *k;
    (void)self;
    if (!PyArg_ParseTuple(args, "iOO:eval_kernel", &index, &inp_obj, &out_obj)) return NULL;
    if (index < 0 || index >= LV_KERNEL_COUNT) {
        PyErr_Format(PyExc_ValueError, "eval_kernel: kernel index %d out of range [0, %d)", index, LV_KERNEL_COUNT);
        return NULL;
    }
    k = &lv_kernel_table[index];
    if (get_f64(inp_obj, &inp, 0, "eval_kernel: inp") != 0) return NULL;
    if (get_f64(out_obj, &out, 1, "eval_kernel: out") != 0) { PyBuffer_Release(&inp); return NULL; }
    n_in_total = inp.len / 8;
    n_out_total = out.len / 8;
    if (n_in_total % k->n_in != 0) {
        PyErr_Format(PyExc_ValueError, "eval_kernel(%s): inp holds %zd doubles, not a multiple of n_in = %d",
                     k->name, n_in_total, k->n_in);
        goto fail;
    }
    rows = n_in_total / k->n_in;
    if (n_out_total != rows * k->n_out) {
        PyErr_Format(PyExc_ValueError, "eval_kernel(%s): out holds %zd doubles, expected %zd rows x n_out %d = %zd",
                     k->name, n_out_total, rows, k->n_out, rows * k->n_out);
        goto fail;
    }
    {
        const double *ip = (const double *)inp.buf;
        double *op = (double *)out.buf;
        Py_BEGIN_ALLOW_THREADS
        for (r = 0; r < rows; r++) k->packed(ip + r * k->n_in, op + r * k->n_out);
        Py_END_ALLOW_THREADS
    }
    PyBuffer_Release(&inp);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
fail:
    PyBuffer_Release(&inp);
    PyBuffer_Release(&out);
    return NULL;
}

/* A kernel on one row of Python numbers, without buffers: call_kernel(index, x0, ..., x{n_in-1}). The outputs are
   few (a kernel's scalars and small vectors), so a fixed row on the stack holds them. */
enum { LV_CALL_MAX = 64 };
static PyObject *py_call_kernel(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double in[LV_CALL_MAX], out[LV_CALL_MAX];
    const lv_kernel_info *k;
    PyObject *res;
    long index;
    Py_ssize_t i;
    (void)self;
    if (nargs < 1) {
        PyErr_SetString(PyExc_TypeError, "call_kernel: expected (index, inputs...)");
        return NULL;
    }
    index = PyLong_AsLong(args[0]);
    if (index == -1 && PyErr_Occurred()) return NULL;
    if (index < 0 || index >= LV_KERNEL_COUNT) {
        PyErr_Format(PyExc_ValueError, "call_kernel: kernel index %ld out of range [0, %d)", index, LV_KERNEL_COUNT);
        return NULL;
    }
    k = &lv_kernel_table[index];
    if (k->n_in > LV_CALL_MAX || k->n_out > LV_CALL_MAX) {
        PyErr_Format(PyExc_ValueError, "call_kernel(%s): %d inputs, %d outputs: more than %d (use eval_kernel)",
                     k->name, k->n_in, k->n_out, (int)LV_CALL_MAX);
        return NULL;
    }
    if (nargs - 1 != k->n_in) {
        PyErr_Format(PyExc_TypeError, "call_kernel(%s): expected %d numbers, got %zd", k->name, k->n_in, nargs - 1);
        return NULL;
    }
    for (i = 0; i < k->n_in; i++) {
        in[i] = PyFloat_AsDouble(args[i + 1]);
        if (in[i] == -1.0 && PyErr_Occurred()) return NULL;
    }
    k->packed(in, out);
    if (k->n_out == 1) return PyFloat_FromDouble(out[0]);
    res = PyTuple_New(k->n_out);
    if (res == NULL) return NULL;
    for (i = 0; i < k->n_out; i++) {
        PyObject *v = PyFloat_FromDouble(out[i]);
        if (v == NULL) { Py_DECREF(res); return NULL; }
        PyTuple_SET_ITEM(res, i, v);
    }
    return res;
}

#define LV_CALL_CACHE "lavendersim.call_cache" /* the capsule name of call_cache (below) */

static PyObject *py_simulate(PyObject *self, PyObject *args)
{
    PyObject *state_obj, *params_obj, *effects_obj;
    PyObject *rows_obj = Py_None, *omega_obj = Py_None, *cmd_obj = Py_None, *app_obj = Py_None;
    PyObject *h_obj = Py_None, *nfev_obj = Py_None, *user_obj = Py_None, *tab_obj = Py_None;
    lv_tableau tableau;
    Py_buffer ta, tb;
    int have_tab = 0;
    PyObject *result = NULL;
    lv_user_effect *user_entries = NULL;
    lv_user_effects user;
    long n_user = 0;
    Py_ssize_t row_size = LV_EFFECT_ROW_PARAMS + LV_EFFECT_ROW_MIN_PARAMS;
    double rtol = 0.0, atol = 0.0;
    Py_buffer hb, nf, dn;
    int have_h = 0, have_nf = 0, have_dn = 0;
    PyObject *dense_obj = Py_None, *cache_obj = Py_None;
    lv_model_cache *kept = NULL;
    int contract = LV_CONTRACT_OFF, contract_was;
    lv_adaptive adaptive;
    int integrator, normalize, n_models, adaptive_rk;
    double dt;
    long long n_steps_ll;
    Py_buffer st, pr, ef, mr, om, cm, ap;
    int have_mr = 0, have_om = 0, have_cm = 0, have_ap = 0;
    Py_ssize_t nb, np_rows, ne, e, rows_n;
    long fail_step = -1, fail_body = -1;
    lv_models models;
    int status;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOipdL|OOOOOOddOOOiO:simulate", &state_obj, &params_obj, &effects_obj, &integrator,
                          &normalize, &dt, &n_steps_ll, &rows_obj, &omega_obj, &cmd_obj, &app_obj,
                          &h_obj, &nfev_obj, &rtol, &atol, &user_obj, &tab_obj, &dense_obj, &contract, &cache_obj))
        return NULL;
    if (cache_obj != Py_None && (kept = (lv_model_cache *)PyCapsule_GetPointer(cache_obj, LV_CALL_CACHE)) == NULL)
        return NULL;   /* (not a call_cache: PyCapsule_GetPointer set the TypeError / ValueError) */
    if (contract != LV_CONTRACT_OFF && contract != LV_CONTRACT_FMA) {
        PyErr_Format(PyExc_ValueError, "simulate: contract must be 0 (bitwise) or 1 (fma), got %d", contract);
        return NULL;
    }
    n_models = (rows_obj != Py_None) + (omega_obj != Py_None) + (cmd_obj != Py_None) + (app_obj != Py_None);
    if (n_models != 0 && n_models != 4) {
        PyErr_SetString(PyExc_ValueError,
                        "simulate: give all four of model_rows, Omega, command, applied, or none of them");
        return NULL;
    }
    if (tab_obj == Py_None && (integrator < 0 || integrator > LV_INTEGRATOR_LAST)) { /* (with a tableau: ignored) */
        PyErr_Format(PyExc_ValueError,
                     "simulate: integrator code must be 0 .. %d (the module's constants, "
                     "lavendersim.generated.tableaux.INTEGRATOR_CODES), got %d", LV_INTEGRATOR_LAST, integrator);
        return NULL;
    }
    adaptive_rk = tab_obj == Py_None && LV_INTEGRATOR_ADAPTIVE(integrator);
    if (adaptive_rk && (h_obj == Py_None || nfev_obj == Py_None)) {
        PyErr_SetString(PyExc_ValueError, "simulate: an adaptive integrator needs h (nb,) and nfev (nb,) float64 arrays, "
                        "rtol and atol");
        return NULL;
    }
    if (adaptive_rk && !(rtol > 0.0 && isfinite(rtol) && atol >= 0.0 && isfinite(atol))) {
        PyErr_SetString(PyExc_ValueError, "simulate: an adaptive integrator needs finite rtol > 0 and atol >= 0");
        return NULL;
    }
    if (n_steps_ll < 0 || n_steps_ll > (long long)LONG_MAX) {
        PyErr_Format(PyExc_ValueError, "simulate: n_steps must be >= 0, got %lld", n_steps_ll);
        return NULL;
    }
    if (!isfinite(dt)) {
        PyErr_SetString(PyExc_ValueError, "simulate: dt must be finite");
        return NULL;
    }
    if (tab_obj != Py_None) {
        if (get_tableau(tab_obj, &tableau, &ta, &tb) != 0) return NULL;
        have_tab = 1;
    }
    if (get_user_table(user_obj, &user_entries, &n_user) != 0) goto fail_tab;
    user.entries = user_entries;
    user.n = n_user;
    if (get_f64(state_obj, &st, 1, "simulate: state") != 0) { free(user_entries); goto fail_tab; }
    if (get_f64(params_obj, &pr, 0, "simulate: params") != 0) { PyBuffer_Release(&st); free(user_entries); goto fail_tab; }
    if (get_f64(effects_obj, &ef, 0, "simulate: effects") != 0) {
        PyBuffer_Release(&st); PyBuffer_Release(&pr); free(user_entries); goto fail_tab;
    }
    if (n_models) {
        if (get_f64(rows_obj, &mr, 0, "simulate: model_rows") != 0) goto fail;
        have_mr = 1;
        if (get_f64(omega_obj, &om, 1, "simulate: Omega") != 0) goto fail;
        have_om = 1;
        if (get_f64(cmd_obj, &cm, 0, "simulate: command") != 0) goto fail;
        have_cm = 1;
        if (get_f64(app_obj, &ap, 1, "simulate: applied") != 0) goto fail;
        have_ap = 1;
    }
    if (adaptive_rk) {
        if (get_f64(h_obj, &hb, 1, "simulate: h") != 0) goto fail;
        have_h = 1;
        if (get_f64(nfev_obj, &nf, 1, "simulate: nfev") != 0) goto fail;
        have_nf = 1;
        if (dense_obj != Py_None) {
            if (get_f64(dense_obj, &dn, 1, "simulate: dense") != 0) goto fail;
            have_dn = 1;
        }
    }
    if (rows_of(&st, LV_STATE_SIZE, "simulate: state", "[p_w(3), q(4), v_w(3), omega_b(3)]", &nb) != 0) goto fail;
    if (rows_of(&pr, LV_PARAM_SIZE, "simulate: params", "[m, I_x, I_y, I_z]", &np_rows) != 0) goto fail;
    if (ef.ndim == 2 && ef.shape[1] >= LV_EFFECT_ROW_PARAMS) row_size = ef.shape[1];
    if (rows_of(&ef, row_size, "simulate: effects", "[code, body, parameters...]", &ne) != 0) goto fail;
    if (np_rows != nb) {
        PyErr_Format(PyExc_ValueError, "simulate: params has %zd rows but state has %zd bodies", np_rows, nb);
        goto fail;
    }
    if (have_h && (hb.len / 8 != nb || nf.len / 8 != nb)) {
        PyErr_Format(PyExc_ValueError, "simulate: h and nfev must hold one float64 per body (%zd), got %zd and %zd",
                     nb, (Py_ssize_t)(hb.len / 8), (Py_ssize_t)(nf.len / 8));
        goto fail;
    }
    if (have_dn && dn.len / 8 != nb * LV_DENSE_SIZE) {
        PyErr_Format(PyExc_ValueError, "simulate: dense must hold %d float64 per body (%zd bodies), got %zd",
                     LV_DENSE_SIZE, nb, (Py_ssize_t)(dn.len / 8));
        goto fail;
    }
    if (have_h) {
        adaptive.rtol = rtol;
        adaptive.atol = atol;
        adaptive.h = (double *)hb.buf;
        adaptive.nfev = (double *)nf.buf;
        adaptive.dense = have_dn ? (double *)dn.buf : NULL;
    }
    if (n_models) {
        if (rows_of(&mr, LV_MODEL_SIZE, "simulate: model_rows",
                    "[kind, I_p(9), r_b(3), anchor_w(3), J(4), torque_limit, speed_limit, c_w, cutoff, A_b(12)]", &rows_n) != 0) goto fail;
        if (rows_n != nb) {
            PyErr_Format(PyExc_ValueError, "simulate: model_rows has %zd rows but state has %zd bodies", rows_n, nb);
            goto fail;
        }
        if (rows_of(&om, LV_NW, "simulate: Omega", "[Omega_1 .. Omega_4]", &rows_n) != 0) goto fail;
        if (rows_n != nb) {
            PyErr_Format(PyExc_ValueError, "simulate: Omega has %zd rows but state has %zd bodies", rows_n, nb);
            goto fail;
        }
        if (rows_of(&cm, LV_NW, "simulate: command", "[u_1 .. u_4]", &rows_n) != 0) goto fail;
        if (rows_n != nb) {
            PyErr_Format(PyExc_ValueError, "simulate: command has %zd rows but state has %zd bodies", rows_n, nb);
            goto fail;
        }
        if (rows_of(&ap, LV_NW, "simulate: applied", "[u_1 .. u_4]", &rows_n) != 0) goto fail;
        if (rows_n != nb) {
            PyErr_Format(PyExc_ValueError, "simulate: applied has %zd rows but state has %zd bodies", rows_n, nb);
            goto fail;
        }
        for (e = 0; e < nb; e++) {
            const double kind = ((const double *)mr.buf)[e * LV_MODEL_SIZE + LV_MODEL_KIND];
            if (!lv_kind_valid(kind)) {
                PyObject *ko = PyFloat_FromDouble(kind);
                PyErr_Format(PyExc_ValueError,
                             "simulate: model_rows[%zd] kind must be 0 (plain), 1 (joint), 2 (wheels) or 3 (joint + wheels), "
                             "got %R",
                             e, ko);
                Py_XDECREF(ko);
                goto fail;
            }
        }
        models.rows = (const double *)mr.buf;
        models.Omega = (double *)om.buf;
        models.command = (const double *)cm.buf;
        models.applied = (double *)ap.buf;
        models.cache = kept;
    }
    if (check_effects((const double *)ef.buf, ne, row_size, nb, user_entries, n_user) != 0) goto fail;
    Py_BEGIN_ALLOW_THREADS
    contract_was = lv_contract_set(contract);
    status = lv_simulate((double *)st.buf, (const double *)pr.buf, (long)nb, (const double *)ef.buf, (long)ne,
                         (long)row_size, n_user ? &user : NULL, n_models ? &models : NULL, kept, integrator, normalize, dt,
                         (long)n_steps_ll, have_h ? &adaptive : NULL, have_tab ? &tableau : NULL, &fail_step, &fail_body);
    (void)lv_contract_set(contract_was);
    Py_END_ALLOW_THREADS
    if (status == LV_NO_MEMORY)
        PyErr_NoMemory();
    else if (status == LV_UNKNOWN_EFFECT)
        PyErr_Format(PyExc_ValueError, "simulate: effects[%ld] has a code no declared effect has", fail_step);
    else if (status < 0)
        PyErr_SetString(PyExc_ValueError, "simulate: lv_simulate rejected its arguments "
                        "(the PLAIN_ONLY integrators of lavendersim.generated.tableaux step plain bodies only: no joint or wheels)");
    else if (status == LV_OK)
        result = Py_BuildValue("(iii)", 0, -1, -1);
    else
        result = Py_BuildValue("(ill)", status, fail_step, fail_body);
fail: /* every exit releases the buffers it holds; result stays NULL on an error */
    PyBuffer_Release(&st);
    PyBuffer_Release(&pr);
    PyBuffer_Release(&ef);
    if (have_mr) PyBuffer_Release(&mr);
    if (have_om) PyBuffer_Release(&om);
    if (have_cm) PyBuffer_Release(&cm);
    if (have_ap) PyBuffer_Release(&ap);
    if (have_h) PyBuffer_Release(&hb);
    if (have_nf) PyBuffer_Release(&nf);
    if (have_dn) PyBuffer_Release(&dn);
    free(user_entries);
fail_tab:
    if (have_tab) { PyBuffer_Release(&ta); PyBuffer_Release(&tb); }
    return result;
}

/* isa([level]) -> (current, current_name, best, best_name): the instruction set of the batched path. */
static PyObject *py_isa(PyObject *self, PyObject *args)
{
    int level = -2, cur;
    (void)self;
    if (!PyArg_ParseTuple(args, "|i", &level)) return NULL;
    if (level != -2) {
        if (level < -1 || level > LV_ISA_AVX512) {
            PyErr_Format(PyExc_ValueError, "isa: level must be -1 (best) or 0..%d, got %d", LV_ISA_AVX512, level);
            return NULL;
        }
        (void)lv_isa_set(level);
    }
    cur = lv_isa_get();
    return Py_BuildValue("(isis)", cur, lv_isa_name(cur), lv_isa_best(), lv_isa_name(lv_isa_best()));
}

/* threads([n]) -> n: the threads that share the SIMD tiles of one simulate call. */
static PyObject *py_threads(PyObject *self, PyObject *args)
{
    int n = 0;
    (void)self;
    if (!PyArg_ParseTuple(args, "|i", &n)) return NULL;
    if (PyTuple_GET_SIZE(args) > 0) {
        if (n < 1 || n > LV_MAX_THREADS) {
            PyErr_Format(PyExc_ValueError, "threads: must be 1..%d, got %d", LV_MAX_THREADS, n);
            return NULL;
        }
        (void)lv_threads_set(n);
    }
    return PyLong_FromLong(lv_threads_get());
}

static PyObject *py_contract_available(PyObject *self, PyObject *noargs)
{
    (void)self;
    (void)noargs;
    return PyBool_FromLong(lv_contract_available());
}

PyObject *lv_py_simulate_f32(PyObject *self, PyObject *args); /* module_f32.c */

/* call_cache(nb, models) -> a capsule holding what lv_simulate decides from the effect table and (models: 1) the model
   rows of nb bodies, kept from call to call (step.h lv_model_cache: the effect index and the fixed-step order of the
   bodies, and with models the rows' entries, compared bytewise per call); simulate(..., cache) uses it. One call at a
   time per cache (a Sim steps under its lock); freed with the capsule. */
static void call_cache_free(PyObject *capsule)
{
    lv_model_cache_free((lv_model_cache *)PyCapsule_GetPointer(capsule, LV_CALL_CACHE));
}

static PyObject *py_call_cache(PyObject *self, PyObject *args)
{
    Py_ssize_t nb;
    int with_models;
    lv_model_cache *c;
    PyObject *capsule;
    (void)self;
    if (!PyArg_ParseTuple(args, "np:call_cache", &nb, &with_models)) return NULL;
    if (nb < 1) {
        PyErr_SetString(PyExc_ValueError, "call_cache: nb must be >= 1");
        return NULL;
    }
    c = lv_model_cache_new(with_models ? (long)nb : 0, 0);   /* not marked: the rows compared per call */
    if (c == NULL) return PyErr_NoMemory();
    capsule = PyCapsule_New(c, LV_CALL_CACHE, call_cache_free);
    if (capsule == NULL) lv_model_cache_free(c);
    return capsule;
}

static PyMethodDef methods[] = {
    {"threads", py_threads, METH_VARARGS,
     "threads([n]) -> n: the threads that share the SIMD tiles (torque-free RK4 groups of >= 16 bodies) and the\n"
     "jointed / wheeled bodies (euler, semi_implicit_euler, rk4) of one simulate call (default 1; set first\n"
     "with n; 1 where the build has no POSIX threads). Results are bitwise those of one thread. simulate runs with the GIL released."},
    {"isa", py_isa, METH_VARARGS,
     "isa([level]) -> (current, name, best, best_name): the instruction set of the batched torque-free RK4 path\n"
     "(ISA_SCALAR 0: off, ISA_BASE 1: the build's baseline (sse2 on x86-64), ISA_AVX2 2, ISA_AVX512 3); with level,\n"
     "select it first (capped at the best this CPU supports; -1: the best). All levels give bitwise the same results."},
    {"contract_available", py_contract_available, METH_NOARGS,
     "contract_available() -> bool: whether simulate(..., contract=1) has its FMA copy of the torque-free RK4 tiles\n"
     "here (a GCC build on a CPU with AVX2 and FMA); without it contract=1 steps bitwise."},
    {"kernels", py_kernels, METH_NOARGS,
     "kernels() -> list of (name, n_in, n_out), in the order of the generated lv_kernel_table."},
    {"eval_kernel", py_eval_kernel, METH_VARARGS,
     "eval_kernel(index, inp, out): run packed kernel `index` over N rows; inp holds N*n_in float64 "
     "(C-contiguous), out N*n_out (writable)."},
    {"call_kernel", (PyCFunction)(void (*)(void))py_call_kernel, METH_FASTCALL,
     "call_kernel(index, x0, ..., x{n_in-1}) -> float (one output) or tuple of n_out floats: packed kernel `index`\n"
     "on one row of numbers (the inputs in the packed order of eval_kernel)."},
    {"call_cache", py_call_cache, METH_VARARGS,
     "call_cache(nb, models) -> capsule: what simulate decides per call from the effect table (and model rows), kept"},
    {"simulate", py_simulate, METH_VARARGS,
     "simulate(state, params, effects, integrator, normalize, dt, n_steps[, model_rows, Omega, command, applied,\n"
     "         h, nfev, rtol, atol, user_effects, tableau, dense, contract, cache])\n"
     "  -> (status, step, body).\n"
     "contract: 0 (default) bitwise; 1 the FMA copy of the torque-free RK4 tiles (see contract_available).\n"
     "cache: None, or a call_cache(nb, models) the caller passes call after call (the same numbers either way).\n"
     "state (nb,13) advanced in place; params (nb,4) [m, I_x, I_y, I_z]; effects (ne, >=2) [code, body, parameters...]\n"
     "(built-in codes, see generated/kernels.h, or user codes from LV_EFFECT_USER_BASE with user_effects: int64 (n,3)\n"
     "[function address, n_params, flags] for codes base .. base+n-1; an undeclared code raises ValueError).\n"
     "Optional, all four or none: model_rows (nb,36) [kind (0 plain, 1 joint, 2 wheels on the A_b axes, 3 both),\n"
     "I_p(9), r_b(3), anchor_w(3), J(4), torque_limit, speed_limit, c_w, cutoff, A_b(3x4)]; Omega (nb,4) advanced\n"
     "in place; command (nb,4) held; applied (nb,4) receives the saturated wheel torques of the last step.\n"
     "The model arrays may be None (all four). dopri5 needs h (nb,) (per-body step proposals, in/out; <= 0:\n"
     "choose) and nfev (nb,) (RHS evaluations added per body), rtol > 0, atol >= 0.\n"
     "integrator: a code of the printed registry (the module's constants EULER, RK4, ...; PLAIN_ONLY ones step plain\n"
     "bodies only). status 2: dopri5 could not meet the tolerance (h[body] = the step that was too small). status 0 ok (step = body = -1); status 1: the\n"
     "state of `body` became non-finite at 0-based `step`: earlier bodies are fully advanced, that body\n"
     "holds its last finite state (and wheel rates), later bodies are untouched.\n"
     "tableau (a (s,s) strictly lower, b_num (s,), b_den): a user's explicit Runge-Kutta method, stepped instead of\n"
     "`integrator` on every body (csrc/step.h lv_tableau)."},
    {"simulate_f32", lv_py_simulate_f32, METH_VARARGS,
     "simulate_f32(state, params, effects, integrator, normalize, dt, n_steps) -> (status, step, body): simulate\n"
     "in float32 (csrc/step_f32.c) for plain bodies, integrators 0-2 and built-in effects; arrays float32."},
    {NULL, NULL, 0, NULL}};

int lv_add_stepper_type(PyObject *m); /* fast_step.c: the Stepper type behind Sim.step() */

static struct PyModuleDef moduledef = {
    PyModuleDef_HEAD_INIT, "_lavender_c",
    "LavenderSim compiled backend: the generated C kernels and the C stepping loop.", -1, methods,
    NULL, NULL, NULL, NULL};

/* One constant per integrator of the printed registry (generated/tableaux.h LV_INTEGRATORS): _c.RK4 == 2, ... */
static int add_integrators(PyObject *m)
{
#define LV_ADD_INTEGRATOR(name, code) if (PyModule_AddIntConstant(m, #name, code) != 0) return -1;
    LV_INTEGRATORS(LV_ADD_INTEGRATOR)
#undef LV_ADD_INTEGRATOR
    return 0;
}

PyMODINIT_FUNC PyInit__lavender_c(void)
{
    PyObject *m = PyModule_Create(&moduledef);
    if (m == NULL) return NULL;
    if (PyModule_AddStringConstant(m, "GENERATED_HASH", LV_GENERATED_HASH) != 0 ||
        PyModule_AddIntConstant(m, "KERNEL_COUNT", LV_KERNEL_COUNT) != 0 ||
        PyModule_AddIntConstant(m, "EFFECT_ABI", LV_EFFECT_ABI) != 0 ||
        PyModule_AddIntConstant(m, "EFFECT_USER_BASE", LV_EFFECT_USER_BASE) != 0 ||
        PyModule_AddIntConstant(m, "ISA_SCALAR", LV_ISA_SCALAR) != 0 ||
        PyModule_AddIntConstant(m, "ISA_BASE", LV_ISA_BASE) != 0 ||
        PyModule_AddIntConstant(m, "ISA_AVX2", LV_ISA_AVX2) != 0 ||
        PyModule_AddIntConstant(m, "ISA_AVX512", LV_ISA_AVX512) != 0 ||
        add_integrators(m) != 0 || lv_add_stepper_type(m) != 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
