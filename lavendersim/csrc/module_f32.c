/* lavendersim._lavender_c.simulate_f32: CPython glue of the float32 stepping loop (step_f32.c). Arrays arrive
   through the buffer protocol as C-contiguous float32; shapes and effect codes are checked here. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "kernels.h"
#include "step.h"
#include "step_f32.h"

/* A C-contiguous float32 buffer of `cols` columns (a 1-D empty one counts as (0, cols)); *rows set. */
static int get_f32(PyObject *obj, Py_buffer *v, int writable, Py_ssize_t cols, const char *what, Py_ssize_t *rows)
{
    const char *f;
    if (PyObject_GetBuffer(obj, v, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) != 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "simulate_f32: %s must be a C-contiguous%s float32 array, got %.200s", what,
                     writable ? ", writable" : "", Py_TYPE(obj)->tp_name);
        return -1;
    }
    f = v->format ? v->format : "B";
    if (f[0] == '@' || f[0] == '=' || f[0] == '<') f++;
    if (strcmp(f, "f") != 0 || v->itemsize != 4) {
        PyErr_Format(PyExc_TypeError, "simulate_f32: %s must have dtype float32 (format 'f'), got format '%s'", what,
                     v->format ? v->format : "B");
        PyBuffer_Release(v);
        return -1;
    }
    if (v->ndim == 1 && v->shape[0] == 0) { *rows = 0; return 0; }
    if (v->ndim != 2 || (cols > 0 && v->shape[1] != cols) || (cols < 0 && v->shape[1] < -cols)) {
        PyErr_Format(PyExc_ValueError, "simulate_f32: %s must have shape (n, %zd%s)", what, cols < 0 ? -cols : cols,
                     cols < 0 ? " or more" : "");
        PyBuffer_Release(v);
        return -1;
    }
    *rows = v->shape[0];
    return 0;
}

PyObject *lv_py_simulate_f32(PyObject *self, PyObject *args)
{
    PyObject *state_obj, *params_obj, *effects_obj;
    Py_buffer st, pa, ef;
    Py_ssize_t nb, np_, ne, e;
    int integrator, normalize, status;
    double dt;
    long n_steps, fail_step = -1, fail_body = -1, row_size;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOipdl:simulate_f32", &state_obj, &params_obj, &effects_obj, &integrator, &normalize,
                          &dt, &n_steps))
        return NULL;
    if (get_f32(state_obj, &st, 1, LV_STATE_SIZE, "state", &nb) != 0) return NULL;
    if (get_f32(params_obj, &pa, 0, LV_PARAM_SIZE, "params", &np_) != 0) { PyBuffer_Release(&st); return NULL; }
    if (get_f32(effects_obj, &ef, 0, -LV_EFFECT_ROW_PARAMS, "effects", &ne) != 0) {
        PyBuffer_Release(&st); PyBuffer_Release(&pa); return NULL;
    }
    row_size = ne > 0 ? (long)ef.shape[1] : LV_EFFECT_ROW_PARAMS;
    status = LV_OK;
    if (np_ != nb) {
        PyErr_Format(PyExc_ValueError, "simulate_f32: params has %zd rows, state %zd", np_, nb);
        status = LV_BAD_ARGUMENT;
    } else if (n_steps < 0 || !(dt > 0.0) || !isfinite(dt)) {
        PyErr_SetString(PyExc_ValueError, "simulate_f32: n_steps must be >= 0 and dt finite and > 0");
        status = LV_BAD_ARGUMENT;
    } else if (!(integrator >= 0 && integrator <= LV_INTEGRATOR_LAST && LV_INTEGRATOR_FLOAT32(integrator))) {
        PyErr_Format(PyExc_ValueError, "simulate_f32: integrator %d does not step float32 (the registry's float32 "
                     "integrators: lavendersim.generated.tableaux.FLOAT32_INTEGRATORS)", integrator);
        status = LV_BAD_ARGUMENT;
    }
    for (e = 0; status == LV_OK && e < ne; e++) {
        const float *row = (const float *)ef.buf + e * row_size;
        double head[LV_EFFECT_ROW_PARAMS]; /* code and body, exact in double: the one row check (step.c) */
        int k, np, check;
        for (k = 0; k < LV_EFFECT_ROW_PARAMS; k++) head[k] = (double)row[k];
        check = lv_effect_row_check(head, row_size, (long)nb, NULL, &np);
        if (check == LV_UNKNOWN_EFFECT) {
            PyObject *code = PyFloat_FromDouble(head[LV_EFFECT_ROW_CODE]);
            PyErr_Format(PyExc_ValueError, "simulate_f32: effects[%zd] code %R is not a built-in effect with parameters "
                         "that fit the row (float32 steps built-in effects only)", e, code);
            Py_XDECREF(code);
            status = LV_BAD_ARGUMENT;
        } else if (check != LV_OK) {
            PyErr_Format(PyExc_ValueError, "simulate_f32: effects[%zd] body must be -1 or an index in [0, %zd)", e, nb);
            status = LV_BAD_ARGUMENT;
        }
    }
    if (status == LV_OK) {
        Py_BEGIN_ALLOW_THREADS
        status = lv_simulate_f32((float *)st.buf, (const float *)pa.buf, (long)nb, (const float *)ef.buf, (long)ne,
                                 row_size, integrator, normalize, (float)dt, n_steps, &fail_step, &fail_body);
        Py_END_ALLOW_THREADS
        if (status == LV_NO_MEMORY) PyErr_NoMemory();
        else if (status < 0) PyErr_Format(PyExc_ValueError, "simulate_f32: bad argument (status %d)", status);
    }
    PyBuffer_Release(&st);
    PyBuffer_Release(&pa);
    PyBuffer_Release(&ef);
    if (status < 0) return NULL;
    return Py_BuildValue("(ill)", status, status == LV_OK ? -1L : fail_step, status == LV_OK ? -1L : fail_body);
}
