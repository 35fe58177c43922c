/*
 * flock_swarm._rclbatch: a lockstep step's serialised messages moved through rcl in one call.
 *
 * rclpy takes and publishes one message per Python call (and, for a subscription, one
 * executor event and one callback per message); at N = 1000 agents that per-message Python
 * work bounds the pipeline (docs/performance.md, issue 28). Two types move a whole step:
 *
 *   Taker(subscriptions)     take() -> (data, meta): every available serialised message of
 *                            every subscription, in one contiguous bytes object, and per
 *                            message (subscription index, size, source timestamp [ns]) as
 *                            int64 triplets. An rcl error raises, and the messages taken
 *                            before it in that call are dropped.
 *   Publishers(publishers)   publish(data, targets, sizes): message m (sizes[m] bytes, the
 *                            messages back to back in data) to publisher targets[m].
 *
 * The handles are rcl pointers (rclpy's `handle.pointer`); the Python side
 * (flock_swarm.nodes.batch) keeps every rclpy handle entered (in use) while a Taker or
 * Publishers holds its pointer, so rclpy cannot destroy it underneath. Every rcl error
 * becomes flock_swarm._rclbatch.RclError with rcl's message; every buffer is bounds-checked;
 * the GIL is released around the rcl calls (they touch no Python object).
 */

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stdint.h>
#include <string.h>

#include <rcl/error_handling.h>
#include <rcl/publisher.h>
#include <rcl/subscription.h>
#include <rcutils/allocator.h>
#include <rcutils/error_handling.h>
#include <rmw/types.h>

/* int64 fields per taken message: subscription index, size, source timestamp. */
#define META_FIELDS 3
/* Bytes one take() gathers at most: a flood of messages cannot grow the buffer without bound
 * (what is left is taken by the next call). */
#define DEFAULT_MAX_BYTES ((size_t)64 << 20)
/* Room for rcl's whole error string. */
#define ERR_LEN RCUTILS_ERROR_MESSAGE_MAX_LENGTH

static PyObject *RclError;

/* rcl's error string (reset afterwards) as an RclError; returns NULL for the caller. */
static PyObject *
raise_rcl(const char *what, rcl_ret_t ret, const char *message)
{
  PyErr_Format(RclError, "%s failed (rcl return %d): %s", what, (int)ret, message);
  return NULL;
}

/* Copy rcl's current error message into buf (GIL not needed) and reset it. */
static void
take_rcl_error(char *buf, size_t size)
{
  snprintf(buf, size, "%s", rcl_get_error_string().str);
  rcl_reset_error();
}

/* A tuple or list of ints -> a malloc'ed array of pointers (none may be 0). */
static void **
pointers_of(PyObject *seq, Py_ssize_t *count, const char *what)
{
  PyObject *fast = PySequence_Fast(seq, "expected a sequence of rcl handle pointers");
  if (fast == NULL) {
    return NULL;
  }
  Py_ssize_t n = PySequence_Fast_GET_SIZE(fast);
  void **out = PyMem_Calloc(n > 0 ? (size_t)n : 1, sizeof(void *));
  if (out == NULL) {
    Py_DECREF(fast);
    PyErr_NoMemory();
    return NULL;
  }
  for (Py_ssize_t i = 0; i < n; i++) {
    void *p = PyLong_AsVoidPtr(PySequence_Fast_GET_ITEM(fast, i));
    if (p == NULL) {
      if (!PyErr_Occurred()) {
        PyErr_Format(PyExc_ValueError, "%s %zd is a null pointer", what, i);
      }
      PyMem_Free(out);
      Py_DECREF(fast);
      return NULL;
    }
    out[i] = p;
  }
  Py_DECREF(fast);
  *count = n;
  return out;
}

/* ---------------------------------------------------------------------------- Taker ---- */

typedef struct
{
  PyObject_HEAD
  rcl_subscription_t **subs;
  Py_ssize_t n;
  rcl_serialized_message_t scratch;
  int scratch_ready;
  uint8_t *data;
  size_t data_cap;
  int64_t *meta;
  size_t meta_cap; /* messages */
  size_t max_bytes;
  int closed;
} Taker;

static void
taker_release(Taker *self)
{
  if (self->scratch_ready) {
    if (rmw_serialized_message_fini(&self->scratch) != RMW_RET_OK) {
      rcl_reset_error();
    }
    self->scratch_ready = 0;
  }
  PyMem_Free(self->subs);
  self->subs = NULL;
  self->n = 0;
  /* Raw: grown by grow() without the GIL. */
  PyMem_RawFree(self->data);
  self->data = NULL;
  self->data_cap = 0;
  PyMem_RawFree(self->meta);
  self->meta = NULL;
  self->meta_cap = 0;
  self->closed = 1;
}

static int
taker_init(Taker *self, PyObject *args, PyObject *kwds)
{
  static char *kwlist[] = {"subscriptions", "max_bytes", NULL};
  PyObject *seq;
  Py_ssize_t max_bytes = (Py_ssize_t)DEFAULT_MAX_BYTES;
  if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|n", kwlist, &seq, &max_bytes)) {
    return -1;
  }
  if (self->subs != NULL || self->closed) {
    PyErr_SetString(PyExc_RuntimeError, "Taker is initialised once");
    return -1;
  }
  if (max_bytes <= 0) {
    PyErr_SetString(PyExc_ValueError, "max_bytes must be > 0");
    return -1;
  }
  Py_ssize_t n = 0;
  void **subs = pointers_of(seq, &n, "subscription");
  if (subs == NULL) {
    return -1;
  }
  self->subs = (rcl_subscription_t **)subs;
  self->n = n;
  self->max_bytes = (size_t)max_bytes;
  self->scratch = rmw_get_zero_initialized_serialized_message();
  rcutils_allocator_t alloc = rcutils_get_default_allocator();
  if (rmw_serialized_message_init(&self->scratch, 1024, &alloc) != RMW_RET_OK) {
    char msg[ERR_LEN];
    take_rcl_error(msg, sizeof(msg));
    raise_rcl("rmw_serialized_message_init", RCL_RET_ERROR, msg);
    return -1;
  }
  self->scratch_ready = 1;
  return 0;
}

static void
taker_dealloc(Taker *self)
{
  taker_release(self);
  Py_TYPE(self)->tp_free((PyObject *)self);
}

static int
taker_open(Taker *self)
{
  if (self->closed || self->subs == NULL) {
    PyErr_SetString(PyExc_ValueError, "Taker is closed");
    return 0;
  }
  return 1;
}

/* Grow a buffer to hold `need` items of `item` bytes; 0 on overflow or no memory. */
static int
grow(void **buf, size_t *cap, size_t need, size_t item)
{
  if (need <= *cap) {
    return 1;
  }
  size_t cap2 = *cap ? *cap : 64;
  while (cap2 < need) {
    if (cap2 > SIZE_MAX / 2) {
      return 0;
    }
    cap2 *= 2;
  }
  if (cap2 > SIZE_MAX / item) {
    return 0;
  }
  /* PyMem_RawRealloc: called without the GIL. */
  void *p = PyMem_RawRealloc(*buf, cap2 * item);
  if (p == NULL) {
    return 0;
  }
  *buf = p;
  *cap = cap2;
  return 1;
}

static PyObject *
taker_take(Taker *self, PyObject *Py_UNUSED(ignored))
{
  if (!taker_open(self)) {
    return NULL;
  }
  size_t used = 0, count = 0;
  rcl_ret_t failed = RCL_RET_OK;
  int no_memory = 0;
  char msg[ERR_LEN] = "";
  /* The data and meta buffers are PyMem_Raw-allocated (see grow) and this object's own. */
  Py_BEGIN_ALLOW_THREADS
  for (Py_ssize_t i = 0; i < self->n && failed == RCL_RET_OK && !no_memory; i++) {
    while (used < self->max_bytes) {
      rmw_message_info_t info = rmw_get_zero_initialized_message_info();
      rcl_ret_t ret = rcl_take_serialized_message(self->subs[i], &self->scratch, &info, NULL);
      if (ret == RCL_RET_SUBSCRIPTION_TAKE_FAILED) {
        break;
      }
      if (ret != RCL_RET_OK) {
        take_rcl_error(msg, sizeof(msg));
        failed = ret;
        break;
      }
      size_t size = self->scratch.buffer_length;
      if (size > SIZE_MAX - used
        || !grow((void **)&self->data, &self->data_cap, used + size, 1)
        || !grow((void **)&self->meta, &self->meta_cap, count + 1,
                 META_FIELDS * sizeof(int64_t)))
      {
        no_memory = 1;
        break;
      }
      if (size) {
        memcpy(self->data + used, self->scratch.buffer, size);
      }
      int64_t *row = self->meta + META_FIELDS * count;
      row[0] = (int64_t)i;
      row[1] = (int64_t)size;
      row[2] = (int64_t)info.source_timestamp;
      used += size;
      count++;
    }
  }
  Py_END_ALLOW_THREADS
  if (no_memory) {
    return PyErr_NoMemory();
  }
  if (failed != RCL_RET_OK) {
    return raise_rcl("rcl_take_serialized_message", failed, msg);
  }
  PyObject *data = PyBytes_FromStringAndSize((const char *)self->data, (Py_ssize_t)used);
  if (data == NULL) {
    return NULL;
  }
  PyObject *meta = PyBytes_FromStringAndSize(
    (const char *)self->meta, (Py_ssize_t)(count * META_FIELDS * sizeof(int64_t)));
  if (meta == NULL) {
    Py_DECREF(data);
    return NULL;
  }
  PyObject *out = PyTuple_Pack(2, data, meta);
  Py_DECREF(data);
  Py_DECREF(meta);
  return out;
}

static PyObject *
taker_close(Taker *self, PyObject *Py_UNUSED(ignored))
{
  taker_release(self);
  Py_RETURN_NONE;
}

static PyMethodDef taker_methods[] = {
  {"take", (PyCFunction)taker_take, METH_NOARGS,
    "take() -> (data, meta): every available serialised message of every subscription, "
    "back to back in data; meta holds int64 (subscription index, size, source timestamp "
    "[ns]) per message."},
  {"close", (PyCFunction)taker_close, METH_NOARGS,
    "close(): free the buffers; the Taker is unusable after."},
  {NULL, NULL, 0, NULL}
};

static PyTypeObject TakerType = {
  PyVarObject_HEAD_INIT(NULL, 0)
  .tp_name = "flock_swarm._rclbatch.Taker",
  .tp_basicsize = sizeof(Taker),
  .tp_flags = Py_TPFLAGS_DEFAULT,
  .tp_doc = "Taker(subscriptions, max_bytes=64 MiB): takes every available serialised "
    "message of a list of rcl subscriptions (rcl pointers) at once.",
  .tp_new = PyType_GenericNew,
  .tp_init = (initproc)taker_init,
  .tp_dealloc = (destructor)taker_dealloc,
  .tp_methods = taker_methods,
};

/* ----------------------------------------------------------------------- Publishers ---- */

typedef struct
{
  PyObject_HEAD
  rcl_publisher_t **pubs;
  Py_ssize_t n;
  int closed;
} Publishers;

static int
publishers_init(Publishers *self, PyObject *args, PyObject *kwds)
{
  static char *kwlist[] = {"publishers", NULL};
  PyObject *seq;
  if (!PyArg_ParseTupleAndKeywords(args, kwds, "O", kwlist, &seq)) {
    return -1;
  }
  if (self->pubs != NULL || self->closed) {
    PyErr_SetString(PyExc_RuntimeError, "Publishers is initialised once");
    return -1;
  }
  Py_ssize_t n = 0;
  void **pubs = pointers_of(seq, &n, "publisher");
  if (pubs == NULL) {
    return -1;
  }
  self->pubs = (rcl_publisher_t **)pubs;
  self->n = n;
  return 0;
}

static void
publishers_release(Publishers *self)
{
  PyMem_Free(self->pubs);
  self->pubs = NULL;
  self->n = 0;
  self->closed = 1;
}

static void
publishers_dealloc(Publishers *self)
{
  publishers_release(self);
  Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Check that `view` is a C-contiguous buffer of `count` int64 (native order). */
static int
int64_view(Py_buffer *view, const char *name)
{
  if (view->itemsize != (Py_ssize_t)sizeof(int64_t)
    || (view->format != NULL && strcmp(view->format, "q") != 0
    && strcmp(view->format, "l") != 0 && strcmp(view->format, "<q") != 0
    && strcmp(view->format, "=q") != 0 && strcmp(view->format, "<l") != 0))
  {
    PyErr_Format(PyExc_TypeError, "%s must be a contiguous int64 array (format %s)", name,
                 view->format ? view->format : "B");
    return 0;
  }
  return 1;
}

static PyObject *
publishers_publish(Publishers *self, PyObject *args)
{
  Py_buffer data, targets, sizes;
  if (self->closed || self->pubs == NULL) {
    PyErr_SetString(PyExc_ValueError, "Publishers is closed");
    return NULL;
  }
  if (!PyArg_ParseTuple(args, "y*y*y*", &data, &targets, &sizes)) {
    return NULL;
  }
  PyObject *result = NULL;
  if (!int64_view(&targets, "targets") || !int64_view(&sizes, "sizes")) {
    goto done;
  }
  Py_ssize_t count = targets.len / (Py_ssize_t)sizeof(int64_t);
  if (sizes.len != targets.len) {
    PyErr_Format(PyExc_ValueError, "targets and sizes differ in length (%zd, %zd messages)",
                 count, sizes.len / (Py_ssize_t)sizeof(int64_t));
    goto done;
  }
  const int64_t *target = targets.buf, *size = sizes.buf;
  /* Every bound checked before the first publish: a batch goes out whole or not at all. */
  Py_ssize_t total = 0;
  for (Py_ssize_t m = 0; m < count; m++) {
    if (target[m] < 0 || target[m] >= self->n) {
      PyErr_Format(PyExc_IndexError, "message %zd: publisher %lld out of range (%zd)", m,
                   (long long)target[m], self->n);
      goto done;
    }
    if (size[m] < 0 || size[m] > data.len - total) {
      PyErr_Format(PyExc_ValueError, "message %zd: %lld bytes at offset %zd overrun the "
                   "%zd-byte buffer", m, (long long)size[m], total, data.len);
      goto done;
    }
    total += (Py_ssize_t)size[m];
  }
  rcl_ret_t failed = RCL_RET_OK;
  Py_ssize_t failed_at = -1;
  char msg[ERR_LEN] = "";
  Py_BEGIN_ALLOW_THREADS
  const uint8_t *at = data.buf;
  for (Py_ssize_t m = 0; m < count; m++) {
    rcl_serialized_message_t one = rmw_get_zero_initialized_serialized_message();
    /* rcl only reads the message: the buffer is the caller's, held by the Py_buffer. */
    one.buffer = (uint8_t *)at;
    one.buffer_length = (size_t)size[m];
    one.buffer_capacity = (size_t)size[m];
    one.allocator = rcutils_get_default_allocator();
    rcl_ret_t ret = rcl_publish_serialized_message(self->pubs[target[m]], &one, NULL);
    if (ret != RCL_RET_OK) {
      take_rcl_error(msg, sizeof(msg));
      failed = ret;
      failed_at = m;
      break;
    }
    at += size[m];
  }
  Py_END_ALLOW_THREADS
  if (failed != RCL_RET_OK) {
    char what[96];
    snprintf(what, sizeof(what), "rcl_publish_serialized_message (message %zd)", failed_at);
    raise_rcl(what, failed, msg);
    goto done;
  }
  result = PyLong_FromSsize_t(count);
done:
  PyBuffer_Release(&data);
  PyBuffer_Release(&targets);
  PyBuffer_Release(&sizes);
  return result;
}

static PyObject *
publishers_close(Publishers *self, PyObject *Py_UNUSED(ignored))
{
  publishers_release(self);
  Py_RETURN_NONE;
}

static PyMethodDef publishers_methods[] = {
  {"publish", (PyCFunction)publishers_publish, METH_VARARGS,
    "publish(data, targets, sizes) -> count: message m (sizes[m] bytes, back to back in "
    "data) to publisher targets[m]; targets and sizes are int64 arrays."},
  {"close", (PyCFunction)publishers_close, METH_NOARGS,
    "close(): forget the publishers; unusable after."},
  {NULL, NULL, 0, NULL}
};

static PyTypeObject PublishersType = {
  PyVarObject_HEAD_INIT(NULL, 0)
  .tp_name = "flock_swarm._rclbatch.Publishers",
  .tp_basicsize = sizeof(Publishers),
  .tp_flags = Py_TPFLAGS_DEFAULT,
  .tp_doc = "Publishers(publishers): publishes batches of serialised messages to a list of "
    "rcl publishers (rcl pointers).",
  .tp_new = PyType_GenericNew,
  .tp_init = (initproc)publishers_init,
  .tp_dealloc = (destructor)publishers_dealloc,
  .tp_methods = publishers_methods,
};

/* --------------------------------------------------------------------------- module ---- */

static struct PyModuleDef module = {
  PyModuleDef_HEAD_INIT,
  .m_name = "flock_swarm._rclbatch",
  .m_doc = "A lockstep step's serialised messages taken from and published to rcl in one "
    "call (see flock_swarm.nodes.batch).",
  .m_size = -1,
};

PyMODINIT_FUNC
PyInit__rclbatch(void)
{
  if (PyType_Ready(&TakerType) < 0 || PyType_Ready(&PublishersType) < 0) {
    return NULL;
  }
  PyObject *m = PyModule_Create(&module);
  if (m == NULL) {
    return NULL;
  }
  RclError = PyErr_NewExceptionWithDoc(
    "flock_swarm._rclbatch.RclError", "An rcl call failed; the message is rcl's.",
    PyExc_RuntimeError, NULL);
  if (RclError == NULL
    || PyModule_AddObjectRef(m, "RclError", RclError) < 0
    || PyModule_AddObjectRef(m, "Taker", (PyObject *)&TakerType) < 0
    || PyModule_AddObjectRef(m, "Publishers", (PyObject *)&PublishersType) < 0
    || PyModule_AddIntConstant(m, "META_FIELDS", META_FIELDS) < 0)
  {
    Py_XDECREF(RclError);
    Py_DECREF(m);
    return NULL;
  }
  return m;
}
