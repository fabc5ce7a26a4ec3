/* Compiled twins of the fast path's per-move Python (sppl.render.kernels).

   A chain proposes a new object at every move, and working out what that object draws (its
   corners in every camera, its instance rows) and summing a re-rendered patch against its
   parent's terms were, in Python, a third of a move's time. These functions compute what their
   Python twins in drawlist.py and pixels.py compute: the instance rows with the twin's double
   arithmetic in its order (-ffp-contract=off keeps the compiler from fusing it), so the very
   same float32s; the corners' projections and the sums to rounding, which the rectangles'
   pixel of margin and the float64 sums absorb. The tests hold the two to each other. They
   return None for inputs they do not take (another dtype, another shape), and the caller then
   uses the twin. */

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define ROW_FLOATS 28 /* model matrix (16), normal matrix (9), colour (3) */

/* A buffer held for reading through its strides, once its format and shape are checked. */
typedef struct {
    Py_buffer view;
    int held;
} Held;

static int take(PyObject *obj, Held *h, const char *format, int ndim, const Py_ssize_t *shape)
{
    h->held = 0;
    if (PyObject_GetBuffer(obj, &h->view, PyBUF_RECORDS_RO) < 0) {
        PyErr_Clear();
        return 0;
    }
    h->held = 1;
    const char *f = h->view.format ? h->view.format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    if (strcmp(f, format) != 0 || h->view.ndim != ndim)
        return 0;
    for (int i = 0; i < ndim; i++)
        if (shape[i] >= 0 && h->view.shape[i] != shape[i])
            return 0;
    return 1;
}

static void let_go(Held *h)
{
    if (h->held)
        PyBuffer_Release(&h->view);
    h->held = 0;
}

static inline double at2(const Held *h, Py_ssize_t i, Py_ssize_t j)
{
    return *(const double *)((const char *)h->view.buf + i * h->view.strides[0]
                             + j * h->view.strides[1]);
}

/* geometry.linear_inverse: the cofactors of the 3x3 linear part, row by row, in the same
   order of operations; 0 where the part is singular. */
static int linear_inverse(const double m[4][4], double out[9])
{
    double a0 = m[0][0], a1 = m[0][1], a2 = m[0][2];
    double b0 = m[1][0], b1 = m[1][1], b2 = m[1][2];
    double c0 = m[2][0], c1 = m[2][1], c2 = m[2][2];
    double i00 = b1 * c2 - b2 * c1, i01 = a2 * c1 - a1 * c2, i02 = a1 * b2 - a2 * b1;
    double det = a0 * i00 + b0 * i01 + c0 * i02;
    if (det == 0.0 || !isfinite(det))
        return 0;
    double i10 = b2 * c0 - b0 * c2, i11 = a0 * c2 - a2 * c0, i12 = a2 * b0 - a0 * b2;
    double i20 = b0 * c1 - b1 * c0, i21 = a1 * c0 - a0 * c1, i22 = a0 * b1 - a1 * b0;
    double r = 1.0 / det;
    double v[9] = {i00 * r, i01 * r, i02 * r, i10 * r, i11 * r, i12 * r, i20 * r, i21 * r,
                   i22 * r};
    memcpy(out, v, sizeof v);
    return 1;
}

/* draw_data(parts, unit_corners, project, limits, margin)
     -> (rows, rects, nearest), or None for inputs it does not take.

   DrawCache.of_parts's work for a non-empty list of parts: per primitive the instance rows
   (pixels.instance_rows), and per camera the rectangle the parts' corners project to and their
   smallest z-depth (DrawCache._project_corners). unit_corners(primitive) gives a primitive's
   (4, 8) box corners; project is every camera's (3, 4) pixels-from-world stacked; limits is
   per camera (near, width, height). */
static PyObject *draw_data(PyObject *self, PyObject *args)
{
    PyObject *parts, *corners_of, *project_obj, *limits;
    long margin;
    if (!PyArg_ParseTuple(args, "OOOOl", &parts, &corners_of, &project_obj, &limits, &margin))
        return NULL;
    PyObject *seq = PySequence_Fast(parts, "parts must be a sequence");
    if (!seq)
        return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    Py_ssize_t cams = PyTuple_Check(limits) ? PyTuple_GET_SIZE(limits) : -1;
    PyObject *result = NULL, *rows = NULL, *rects = NULL, *nearest = NULL;
    double *corners = NULL, *floats = NULL;
    PyObject **primitives = NULL;
    char *ok = NULL;
    Held project = {0};
    Py_ssize_t pshape[2] = {3 * cams, 4};
    if (n == 0 || cams <= 0 || !take(project_obj, &project, "d", 2, pshape))
        goto unsupported;

    corners = PyMem_Malloc(sizeof(double) * 4 * 8 * n);
    floats = PyMem_Malloc(sizeof(double) * ROW_FLOATS * n);
    primitives = PyMem_Calloc(n, sizeof(PyObject *));
    ok = PyMem_Calloc(n, 1);
    if (!corners || !floats || !primitives || !ok) {
        PyErr_NoMemory();
        goto done;
    }
    Py_ssize_t m44[2] = {4, 4}, u48[2] = {4, 8};
    for (Py_ssize_t p = 0; p < n; p++) {
        PyObject *part = PySequence_Fast_GET_ITEM(seq, p);
        PyObject *primitive = PyObject_GetAttrString(part, "primitive");
        if (!primitive)
            goto done;
        primitives[p] = primitive;
        PyObject *matrix_obj = PyObject_GetAttrString(part, "matrix");
        if (!matrix_obj)
            goto done;
        Held hm;
        int good = take(matrix_obj, &hm, "d", 2, m44);
        double m[4][4];
        if (good)
            for (int i = 0; i < 4; i++)
                for (int j = 0; j < 4; j++)
                    m[i][j] = at2(&hm, i, j);
        let_go(&hm);
        Py_DECREF(matrix_obj);
        if (!good)
            goto unsupported;
        PyObject *unit_obj = PyObject_CallOneArg(corners_of, primitive);
        if (!unit_obj)
            goto done; /* an unknown primitive: unit_corners's own error */
        Held hu;
        good = take(unit_obj, &hu, "d", 2, u48);
        /* The part's box corners in the world: matrix @ unit corners. */
        if (good)
            for (int i = 0; i < 4; i++)
                for (int k = 0; k < 8; k++) {
                    double s = 0.0;
                    for (int j = 0; j < 4; j++)
                        s += m[i][j] * at2(&hu, j, k);
                    corners[(i * n + p) * 8 + k] = s;
                }
        let_go(&hu);
        Py_DECREF(unit_obj);
        if (!good)
            goto unsupported;

        double *row = floats + ROW_FLOATS * p;
        if (!linear_inverse(m, row + 16))
            continue; /* singular: encloses nothing, not drawn */
        for (int j = 0; j < 4; j++) /* column-major */
            for (int i = 0; i < 4; i++)
                row[4 * j + i] = m[i][j];
        PyObject *colour_obj = PyObject_GetAttrString(part, "colour");
        if (!colour_obj)
            goto done;
        PyObject *colour = PySequence_Fast(colour_obj, "a part's colour must be a sequence");
        Py_DECREF(colour_obj);
        if (!colour)
            goto done;
        if (PySequence_Fast_GET_SIZE(colour) != 3) {
            Py_DECREF(colour);
            goto unsupported;
        }
        for (int i = 0; i < 3; i++)
            row[25 + i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(colour, i));
        Py_DECREF(colour);
        if (PyErr_Occurred())
            goto done;
        ok[p] = 1;
    }

    /* Instance rows, grouped by primitive in the order each first has a drawn part: first
       each primitive's list of parts, then each list replaced by the parts' packed rows. */
    rows = PyDict_New();
    if (!rows)
        goto done;
    for (Py_ssize_t p = 0; p < n; p++) {
        if (!ok[p])
            continue;
        PyObject *group = PyDict_GetItemWithError(rows, primitives[p]); /* borrowed */
        if (!group) {
            if (PyErr_Occurred() || !(group = PyList_New(0)))
                goto done;
            int failed = PyDict_SetItem(rows, primitives[p], group);
            Py_DECREF(group); /* the dictionary holds it */
            if (failed)
                goto done;
        }
        PyObject *index = PyLong_FromSsize_t(p);
        if (!index || PyList_Append(group, index) < 0) {
            Py_XDECREF(index);
            goto done;
        }
        Py_DECREF(index);
    }
    Py_ssize_t at = 0;
    PyObject *primitive, *group;
    while (PyDict_Next(rows, &at, &primitive, &group)) { /* only values change: allowed */
        Py_ssize_t count = PyList_GET_SIZE(group);
        PyObject *packed = PyBytes_FromStringAndSize(NULL, count * ROW_FLOATS * 4);
        if (!packed)
            goto done;
        float *out = (float *)PyBytes_AS_STRING(packed);
        for (Py_ssize_t g = 0; g < count; g++) {
            const double *row = floats + ROW_FLOATS * PyLong_AsSsize_t(PyList_GET_ITEM(group, g));
            for (int i = 0; i < ROW_FLOATS; i++)
                *out++ = (float)row[i];
        }
        int failed = PyDict_SetItem(rows, primitive, packed);
        Py_DECREF(packed);
        if (failed)
            goto done;
    }

    /* Per camera, the rectangle of the projected corners, as _project_corners makes it. */
    rects = PyTuple_New(cams);
    nearest = PyList_New(cams);
    if (!rects || !nearest)
        goto done;
    Py_ssize_t total = 8 * n;
    for (Py_ssize_t c = 0; c < cams; c++) {
        PyObject *limit = PyTuple_GET_ITEM(limits, c);
        double near_plane;
        long width, height;
        if (!PyArg_ParseTuple(limit, "dll", &near_plane, &width, &height))
            goto done;
        double su = 0.0, sv = 0.0, sw = 0.0, near = 0.0;
        double umin = 0.0, umax = 0.0, vmin = 0.0, vmax = 0.0;
        for (Py_ssize_t k = 0; k < total; k++) {
            /* Corner k: part k / 8, corner k % 8; row i of corners is corners[(i n + p) 8 + c]. */
            Py_ssize_t p = k / 8, q = k % 8;
            double x[4];
            for (int i = 0; i < 4; i++)
                x[i] = corners[(i * n + p) * 8 + q];
            double uvw[3];
            for (int r = 0; r < 3; r++) {
                double s = 0.0;
                for (int j = 0; j < 4; j++)
                    s += at2(&project, 3 * c + r, j) * x[j];
                uvw[r] = s;
            }
            su += uvw[0];
            sv += uvw[1];
            sw += uvw[2];
            if (k == 0 || uvw[2] < near)
                near = uvw[2];
            double u = uvw[0] / uvw[2], v = uvw[1] / uvw[2];
            if (k == 0) {
                umin = umax = u;
                vmin = vmax = v;
            } else {
                if (u < umin) umin = u;
                if (u > umax) umax = u;
                if (v < vmin) vmin = v;
                if (v > vmax) vmax = v;
            }
        }
        PyObject *w = PyFloat_FromDouble(near);
        if (!w)
            goto done;
        PyList_SET_ITEM(nearest, c, w);
        PyObject *rect;
        if (near <= near_plane || !isfinite(su + sv + sw)) {
            rect = Py_BuildValue("(llll)", 0L, height, 0L, width); /* reaching behind the camera */
        } else {
            double c0 = floor(umin) - margin, c1 = ceil(umax) + margin;
            double r0 = floor(vmin) - margin, r1 = ceil(vmax) + margin;
            c0 = c0 < 0.0 ? 0.0 : c0;
            r0 = r0 < 0.0 ? 0.0 : r0;
            c1 = c1 > (double)width ? (double)width : c1;
            r1 = r1 > (double)height ? (double)height : r1;
            if (c0 >= c1 || r0 >= r1) {
                rect = Py_NewRef(Py_None);
            } else {
                rect = Py_BuildValue("(llll)", (long)r0, (long)r1, (long)c0, (long)c1);
            }
        }
        if (!rect)
            goto done;
        PyTuple_SET_ITEM(rects, c, rect);
    }
    result = PyTuple_Pack(3, rows, rects, nearest);
    goto done;

unsupported:
    result = Py_NewRef(Py_None);
done:
    let_go(&project);
    if (primitives)
        for (Py_ssize_t p = 0; p < n; p++)
            Py_XDECREF(primitives[p]);
    PyMem_Free(primitives);
    PyMem_Free(corners);
    PyMem_Free(floats);
    PyMem_Free(ok);
    Py_XDECREF(rows);
    Py_XDECREF(rects);
    Py_XDECREF(nearest);
    Py_DECREF(seq);
    return result;
}

/* change(new, old) -> (image, depth), or None for inputs it does not take.

   PixelScorer.change: the float64 sums of the two channels of new's (rows, cols, 2) float32
   terms less old's (None: no terms). Each difference of two float32 values is exact in
   float64, as in the twin; only the order of the additions differs. */
static PyObject *change(PyObject *self, PyObject *args)
{
    PyObject *new_obj, *old_obj;
    if (!PyArg_ParseTuple(args, "OO", &new_obj, &old_obj))
        return NULL;
    Held a = {0}, b = {0};
    Py_ssize_t any[3] = {-1, -1, 2};
    PyObject *result = NULL;
    int has_old = old_obj != Py_None;
    if (!take(new_obj, &a, "f", 3, any))
        goto unsupported;
    if (has_old) {
        Py_ssize_t same[3] = {a.view.shape[0], a.view.shape[1], 2};
        if (!take(old_obj, &b, "f", 3, same))
            goto unsupported;
    }
    double s0 = 0.0, s1 = 0.0;
    const Py_ssize_t *as = a.view.strides, *bs = has_old ? b.view.strides : NULL;
    for (Py_ssize_t i = 0; i < a.view.shape[0]; i++) {
        const char *ra = (const char *)a.view.buf + i * as[0];
        const char *rb = has_old ? (const char *)b.view.buf + i * bs[0] : NULL;
        for (Py_ssize_t j = 0; j < a.view.shape[1]; j++) {
            const char *pa = ra + j * as[1];
            double x0 = *(const float *)pa, x1 = *(const float *)(pa + as[2]);
            if (has_old) {
                const char *pb = rb + j * bs[1];
                x0 -= *(const float *)pb;
                x1 -= *(const float *)(pb + bs[2]);
            }
            s0 += x0;
            s1 += x1;
        }
    }
    result = Py_BuildValue("(dd)", s0, s1);
    goto done;
unsupported:
    result = Py_NewRef(Py_None);
done:
    let_go(&a);
    let_go(&b);
    return result;
}

static PyMethodDef methods[] = {
    {"draw_data", draw_data, METH_VARARGS,
     "draw_data(parts, unit_corners, project, limits, margin) -> (rows, rects, nearest) or None"},
    {"change", change, METH_VARARGS, "change(new, old) -> (image, depth) or None"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "sppl.render._kernels",
    "Compiled twins of the fast path's per-move Python (see sppl.render.kernels).", -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void)
{
    return PyModule_Create(&module);
}
