/* Counts allocations while switched on: every NumPy data buffer (NumPy's memory handler,
 * NEP 49) and every block of Python's object allocator (PYMEM_DOMAIN_OBJ: objects and
 * their small buffers), transient ones included. Both are hooks: each call is passed on to
 * the allocator that was in place, so memory from before and after stays consistent.
 * Built and loaded by hil/tools/alloc_count.py. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_22_API_VERSION
#include <numpy/arrayobject.h>

static int counting = 0;
static long long numpy_buffers = 0, python_blocks = 0;
static PyMemAllocatorEx previous_obj;
static PyDataMem_Handler *previous_numpy = NULL;
static PyObject *previous_numpy_capsule = NULL;
static int installed = 0;
static PyObject *sites = NULL;
static long long unattributed = 0;   /* traced buffers made with no Python line to name */       /* where: "file:line" -> NumPy buffers made there (when tracing) */

/* The Python line that asked for a NumPy buffer (counting off meanwhile: this allocates). */
static void record_site(void) {
    if (sites == NULL) return;
    if (!PyGILState_Check()) { unattributed++; return; }
    int was = counting;
    counting = 0;
    PyFrameObject *frame = PyEval_GetFrame();
    if (frame == NULL) unattributed++;
    if (frame != NULL) {
        PyCodeObject *code = PyFrame_GetCode(frame);
        PyObject *key = PyUnicode_FromFormat("%U:%d", code->co_filename, PyFrame_GetLineNumber(frame));
        Py_DECREF(code);
        if (key != NULL) {
            PyObject *old = PyDict_GetItem(sites, key);
            PyObject *count = PyLong_FromLong(old ? PyLong_AsLong(old) + 1 : 1);
            if (count != NULL) {
                PyDict_SetItem(sites, key, count);
                Py_DECREF(count);
            }
            Py_DECREF(key);
        }
    }
    counting = was;
}

static void *obj_malloc(void *ctx, size_t size) {
    if (counting) python_blocks++;
    return previous_obj.malloc(previous_obj.ctx, size);
}
static void *obj_calloc(void *ctx, size_t n, size_t size) {
    if (counting) python_blocks++;
    return previous_obj.calloc(previous_obj.ctx, n, size);
}
static void *obj_realloc(void *ctx, void *ptr, size_t size) {
    if (counting) python_blocks++;
    return previous_obj.realloc(previous_obj.ctx, ptr, size);
}
static void obj_free(void *ctx, void *ptr) { previous_obj.free(previous_obj.ctx, ptr); }

static void *np_malloc(void *ctx, size_t size) {
    if (counting) { numpy_buffers++; record_site(); }
    return previous_numpy->allocator.malloc(previous_numpy->allocator.ctx, size);
}
static void *np_calloc(void *ctx, size_t n, size_t size) {
    if (counting) { numpy_buffers++; record_site(); }
    return previous_numpy->allocator.calloc(previous_numpy->allocator.ctx, n, size);
}
static void *np_realloc(void *ctx, void *ptr, size_t size) {
    if (counting) { numpy_buffers++; record_site(); }
    return previous_numpy->allocator.realloc(previous_numpy->allocator.ctx, ptr, size);
}
static void np_free(void *ctx, void *ptr, size_t size) {
    previous_numpy->allocator.free(previous_numpy->allocator.ctx, ptr, size);
}

static PyDataMem_Handler counting_handler = {
    "hydrapod_counting_allocator", 1, {NULL, np_malloc, np_calloc, np_realloc, np_free}};

static PyObject *install(PyObject *self, PyObject *args) {
    if (installed) Py_RETURN_NONE;
    previous_numpy_capsule = PyDataMem_GetHandler();
    if (previous_numpy_capsule == NULL) return NULL;
    previous_numpy = (PyDataMem_Handler *)PyCapsule_GetPointer(previous_numpy_capsule, "mem_handler");
    if (previous_numpy == NULL) return NULL;
    PyObject *capsule = PyCapsule_New(&counting_handler, "mem_handler", NULL);
    if (capsule == NULL) return NULL;
    PyObject *old = PyDataMem_SetHandler(capsule);
    Py_DECREF(capsule);
    if (old == NULL) return NULL;
    Py_DECREF(old);
    PyMem_GetAllocator(PYMEM_DOMAIN_OBJ, &previous_obj);
    PyMemAllocatorEx hook = {NULL, obj_malloc, obj_calloc, obj_realloc, obj_free};
    PyMem_SetAllocator(PYMEM_DOMAIN_OBJ, &hook);
    installed = 1;
    Py_RETURN_NONE;
}

static PyObject *uninstall(PyObject *self, PyObject *args) {
    if (!installed) Py_RETURN_NONE;
    counting = 0;
    PyMem_SetAllocator(PYMEM_DOMAIN_OBJ, &previous_obj);
    PyObject *old = PyDataMem_SetHandler(previous_numpy_capsule);
    Py_XDECREF(old);
    installed = 0;
    Py_RETURN_NONE;
}

static int paused_from = 0;          /* what `pause` found, for `resume` */
static PyObject *on(PyObject *self, PyObject *args) { counting = 1; Py_RETURN_NONE; }
static PyObject *pause_counting(PyObject *self, PyObject *args) {
    paused_from = counting;
    counting = 0;
    Py_RETURN_NONE;
}
static PyObject *resume_counting(PyObject *self, PyObject *args) { counting = paused_from; Py_RETURN_NONE; }
static PyObject *off(PyObject *self, PyObject *args) { counting = 0; Py_RETURN_NONE; }
static PyObject *reset(PyObject *self, PyObject *args) {
    numpy_buffers = python_blocks = 0;
    Py_RETURN_NONE;
}
static PyObject *trace(PyObject *self, PyObject *args) {
    if (sites == NULL) sites = PyDict_New();
    if (sites == NULL) return NULL;
    Py_INCREF(sites);
    return sites;
}

static PyObject *counts(PyObject *self, PyObject *args) {
    return Py_BuildValue("(LLL)", numpy_buffers, python_blocks, unattributed);
}

static PyMethodDef methods[] = {
    {"install", install, METH_NOARGS, "hook NumPy's memory handler and Python's object allocator"},
    {"uninstall", uninstall, METH_NOARGS, "put the previous allocators back"},
    {"on", on, METH_NOARGS, "count from now"},
    {"off", off, METH_NOARGS, "stop counting"},
    {"pause", pause_counting, METH_NOARGS, "stop counting until resume (code to leave out)"},
    {"resume", resume_counting, METH_NOARGS, "count again if pause found it counting"},
    {"reset", reset, METH_NOARGS, "counts to zero"},
    {"trace", trace, METH_NOARGS, "record where each NumPy buffer is made: the dict it fills"},
    {"counts", counts, METH_NOARGS, "(NumPy buffers, Python object-allocator blocks) counted"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_hydrapod_alloc_counter", NULL, -1, methods};

PyMODINIT_FUNC PyInit__hydrapod_alloc_counter(void) {
    import_array();
    return PyModule_Create(&module);
}
