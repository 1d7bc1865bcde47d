/*
 * cananalyze.runtime._speedups: inner loops of the candump, ASC and BLF readers, the text
 * writer, the frames table's hex column and the MCAP chunks, in C.
 *
 * Why hand-written: no library parses candump or Vector ASC text into columns
 * (python-can makes one Message per frame, about 150k frames/s). Without this
 * helper candump lines go through numpy (a dozen passes over every byte) and ASC
 * lines through the per-line parser, both holding the GIL, so reading cannot run
 * on the other core while the decoder works. These loops read each byte once and
 * release the GIL for the whole chunk. The text writer's lines come out of a
 * matrix of NUL-padded columns about 100 bytes wide; numpy needs four passes to
 * drop the padding (concatenate, compare, compress, row sums), `compact_rows` one.
 *
 * Contract: the helper is optional (setup.py builds it when it can, CANANALYZE_PURE=1
 * ignores it) and every function is a shortcut for a Python/numpy function that
 * must give identical results. The parsers accept only lines whose every field
 * they can vouch for and mark every other line for the Python line parser (which
 * also reports problems), so results are identical by construction; the tests
 * compare both on real logs and fuzzed lines, and CI runs the suite both ways.
 * Buffers come in through the buffer protocol (numpy arrays, bytes, memoryview):
 * no numpy headers needed. Every read is bounds-checked against the line end:
 * lines may be cut, and any byte may appear.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define FLAG_EXT 0x01
#define FLAG_RTR 0x02
#define FLAG_ERR 0x04
#define FLAG_TX 0x40
#define CAN_ERR_FLAG 0x20000000u

static const double P10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                               1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                               1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
static const uint64_t P10I[19] = {1ull,
                                  10ull,
                                  100ull,
                                  1000ull,
                                  10000ull,
                                  100000ull,
                                  1000000ull,
                                  10000000ull,
                                  100000000ull,
                                  1000000000ull,
                                  10000000000ull,
                                  100000000000ull,
                                  1000000000000ull,
                                  10000000000000ull,
                                  100000000000000ull,
                                  1000000000000000ull,
                                  10000000000000000ull,
                                  100000000000000000ull,
                                  1000000000000000000ull};

static signed char HEXV[256]; /* hex digit value, -1 otherwise */

static inline int is_digit(unsigned char c) { return c >= '0' && c <= '9'; }

/* Seconds from `sec` (ni digits) and `frac` (nf digits), exactly as the numpy
 * candump parser computes them (formats/logs/candump.py _parse_time), and float(text):
 * one integer divided once by 10**nf while it is below 2**53, else the sum. */
static inline double seconds(uint64_t sec, int ni, uint64_t frac, int nf) {
    if (nf == 0) return (double)(int64_t)sec;
    if (ni + nf <= 18) {
        uint64_t whole = sec * P10I[nf] + frac;
        if (whole < (1ull << 53)) return (double)(int64_t)whole / P10[nf];
    }
    return (double)(int64_t)sec + (double)(int64_t)frac / P10[nf];
}

/* Buffers: a small helper that releases whatever it acquired. */
typedef struct {
    Py_buffer b[12];
    int n;
} Bufs;

static void bufs_release(Bufs *bs) {
    for (int i = 0; i < bs->n; i++) PyBuffer_Release(&bs->b[i]);
    bs->n = 0;
}

static int bufs_get(Bufs *bs, PyObject *obj, int writable, Py_ssize_t need, const char *what) {
    Py_buffer *b = &bs->b[bs->n];
    if (PyObject_GetBuffer(obj, b, (writable ? PyBUF_WRITABLE : PyBUF_SIMPLE) | PyBUF_C_CONTIGUOUS) <
        0)
        return -1;
    bs->n++;
    if (need >= 0 && b->len < need) {
        PyErr_Format(PyExc_ValueError, "%s: buffer of %zd bytes, need %zd", what, b->len, need);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------ lines */

PyDoc_STRVAR(split_lines_doc,
             "split_lines(buf, starts, ends, all_cr) -> n\n\n"
             "Line starts and ends (int64 buffers) of buf; a last line without '\\n' counts.\n"
             "Strips one '\\r' before each end, or every trailing '\\r' when all_cr.\n"
             "Returns the number of lines, or -1 when the buffers are too small.");

static PyObject *split_lines(PyObject *self, PyObject *args) {
    PyObject *o_buf, *o_s, *o_e;
    int all_cr;
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OOOp", &o_buf, &o_s, &o_e, &all_cr)) return NULL;
    if (bufs_get(&bs, o_buf, 0, -1, "buf") < 0 || bufs_get(&bs, o_s, 1, -1, "starts") < 0 ||
        bufs_get(&bs, o_e, 1, -1, "ends") < 0) {
        bufs_release(&bs);
        return NULL;
    }
    const unsigned char *buf = bs.b[0].buf;
    Py_ssize_t size = bs.b[0].len;
    int64_t *starts = bs.b[1].buf, *ends = bs.b[2].buf;
    Py_ssize_t cap = bs.b[1].len / 8;
    if (bs.b[2].len / 8 < cap) cap = bs.b[2].len / 8;
    Py_ssize_t n = 0;
    int overflow = 0;
    Py_BEGIN_ALLOW_THREADS;
    Py_ssize_t pos = 0;
    for (;;) {
        const unsigned char *nl = pos < size ? memchr(buf + pos, '\n', size - pos) : NULL;
        Py_ssize_t end = nl ? (Py_ssize_t)(nl - buf) : size;
        if (!nl && pos == size && size > 0 && buf[size - 1] == '\n') break; /* no last line */
        if (n >= cap) {
            overflow = 1;
            break;
        }
        Py_ssize_t e = end;
        if (all_cr) {
            while (e > pos && buf[e - 1] == '\r') e--;
        } else if (e > pos && buf[e - 1] == '\r') {
            e--;
        }
        starts[n] = pos;
        ends[n] = e;
        n++;
        if (!nl) break;
        pos = end + 1;
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    return PyLong_FromSsize_t(overflow ? -1 : n);
}

PyDoc_STRVAR(count_lines_doc, "count_lines(buf) -> n: the number of lines split_lines finds.");

static PyObject *count_lines(PyObject *self, PyObject *args) {
    Py_buffer b;
    if (!PyArg_ParseTuple(args, "y*", &b)) return NULL;
    const char *buf = b.buf;
    Py_ssize_t size = b.len, n = 0, pos = 0;
    Py_BEGIN_ALLOW_THREADS;
    const char *nl;
    while (pos < size && (nl = memchr(buf + pos, '\n', size - pos)) != NULL) {
        n++;
        pos = nl - buf + 1;
    }
    if (size == 0 || buf[size - 1] != '\n') n++;
    Py_END_ALLOW_THREADS;
    PyBuffer_Release(&b);
    return PyLong_FromSsize_t(n);
}

/* ---------------------------------------------------------------- candump */

typedef struct {
    const char *p;
    Py_ssize_t len;
} Name;

/* One `(sec.frac) iface id#data [R|T]` line in [q, e). Returns 0 parsed, 1 parsed
 * with an interface not in `names`, 2 for the Python line parser. Accepts exactly
 * the lines candump._bulk_log_lines (numpy) accepts, with the same values. */
static inline int candump_line(const unsigned char *q, const unsigned char *e, const Name *names,
                               Py_ssize_t n_names, Py_ssize_t *hint, double *t, uint32_t *can_id,
                               uint8_t *flags, uint8_t *dlc, uint8_t *data, uint16_t *chan) {
    if (q >= e || *q != '(') return 2;
    q++;
    uint64_t sec = 0, frac = 0;
    int ni = 0, nf = 0;
    while (q < e && is_digit(*q)) {
        if (++ni > 18) return 2;
        sec = sec * 10 + (*q++ - '0');
    }
    if (ni < 1 || q >= e || *q != '.') return 2;
    q++;
    while (q < e && is_digit(*q)) {
        if (++nf > 12) return 2;
        frac = frac * 10 + (*q++ - '0');
    }
    if (nf < 1 || e - q < 2 || q[0] != ')' || q[1] != ' ') return 2;
    q += 2;
    const unsigned char *name = q;
    while (q < e && *q != ' ') q++;
    if (q >= e || q == name) return 2;
    Py_ssize_t name_len = q - name;
    q++; /* identifier */
    uint32_t id = 0;
    int k = 0;
    while (q + k < e && k < 9 && HEXV[q[k]] >= 0) {
        id = (id << 4) | (uint32_t)HEXV[q[k]];
        k++;
    }
    if ((k != 3 && k != 8) || q + k >= e || q[k] != '#') return 2;
    if (k == 3 && id > 0x7FFu) return 2; /* not an 11-bit id: the line parser says so */
    q += k + 1; /* data */
    const unsigned char *d_end = q;
    while (d_end < e && *d_end != ' ') d_end++;
    Py_ssize_t d_len = d_end - q;
    uint8_t fl = 0, n_bytes = 0;
    memset(data, 0, 8);
    if (q < e && *q == '#') return 2; /* CAN FD: the Python path (payloads over 8 bytes) */
    if (q < e && *q == 'R') {
        fl |= FLAG_RTR;
        if (d_len > 2) return 2;
        if (d_len == 2) {
            if (q[1] < '0' || q[1] > '8') return 2;
            n_bytes = (uint8_t)(q[1] - '0');
        }
    } else {
        if (d_len > 16 || (d_len & 1)) return 2;
        for (Py_ssize_t i = 0; i < d_len; i += 2) {
            int hi = HEXV[q[i]], lo = HEXV[q[i + 1]];
            if ((hi | lo) < 0) return 2;
            data[i >> 1] = (uint8_t)((hi << 4) | lo);
        }
        n_bytes = (uint8_t)(d_len >> 1);
    }
    if (d_end < e) { /* direction written by python-can: " R" or " T" */
        if (e - d_end != 2 || (d_end[1] != 'R' && d_end[1] != 'T')) return 2;
        if (d_end[1] == 'T') fl |= FLAG_TX;
    }
    if (k == 8) fl |= (id & CAN_ERR_FLAG) ? FLAG_ERR : FLAG_EXT;
    *t = seconds(sec, ni, frac, nf);
    *can_id = id & 0x1FFFFFFFu;
    *flags = fl;
    *dlc = n_bytes;
    /* interface: usually the one of the previous line */
    Py_ssize_t h = *hint;
    if (h < n_names && names[h].len == name_len && memcmp(names[h].p, name, name_len) == 0) {
        *chan = (uint16_t)h;
        return 0;
    }
    for (Py_ssize_t i = 0; i < n_names; i++) {
        if (names[i].len == name_len && memcmp(names[i].p, name, name_len) == 0) {
            *hint = i;
            *chan = (uint16_t)i;
            return 0;
        }
    }
    return 1;
}

PyDoc_STRVAR(candump_lines_doc,
             "candump_lines(buf, starts, ends, names, t, can_id, flags, dlc, data, channel, status)"
             "\n\nParse candump log-file lines [starts[i], ends[i]) of buf into the column buffers.\n"
             "names: tuple of interface names (bytes), channel = index into it.\n"
             "status[i]: 0 parsed, 1 parsed but interface not in names (channel unset),\n"
             "2 left to the Python parser (column values unset).");

static PyObject *candump_lines(PyObject *self, PyObject *args) {
    PyObject *o[11];
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OOOO!OOOOOOO", &o[0], &o[1], &o[2], &PyTuple_Type, &o[3], &o[4],
                          &o[5], &o[6], &o[7], &o[8], &o[9], &o[10]))
        return NULL;
    if (bufs_get(&bs, o[0], 0, -1, "buf") < 0 || bufs_get(&bs, o[1], 0, -1, "starts") < 0)
        goto fail;
    Py_ssize_t n = bs.b[1].len / 8;
    static const int width[11] = {0, 8, 8, 0, 8, 4, 1, 1, 8, 2, 1};
    static const char *what[11] = {"buf",   "starts", "ends",   "names", "t",     "can_id",
                                   "flags", "dlc",    "data",   "channel", "status"};
    if (bufs_get(&bs, o[2], 0, n * 8, what[2]) < 0) goto fail;
    for (int i = 4; i < 11; i++)
        if (bufs_get(&bs, o[i], 1, n * width[i], what[i]) < 0) goto fail;
    Py_ssize_t n_names = PyTuple_GET_SIZE(o[3]);
    Name *names = PyMem_Malloc(sizeof(Name) * (n_names ? n_names : 1));
    if (!names) {
        PyErr_NoMemory();
        goto fail;
    }
    for (Py_ssize_t i = 0; i < n_names; i++) {
        PyObject *s = PyTuple_GET_ITEM(o[3], i);
        if (!PyBytes_Check(s)) {
            PyMem_Free(names);
            PyErr_SetString(PyExc_TypeError, "names must be bytes");
            goto fail;
        }
        names[i].p = PyBytes_AS_STRING(s);
        names[i].len = PyBytes_GET_SIZE(s);
    }
    const unsigned char *buf = bs.b[0].buf;
    Py_ssize_t size = bs.b[0].len;
    const int64_t *starts = bs.b[1].buf, *ends = bs.b[2].buf;
    double *t = bs.b[3].buf;
    uint32_t *can_id = bs.b[4].buf;
    uint8_t *flags = bs.b[5].buf, *dlc = bs.b[6].buf, *data = bs.b[7].buf;
    uint16_t *chan = bs.b[8].buf;
    uint8_t *status = bs.b[9].buf;
    Py_BEGIN_ALLOW_THREADS;
    Py_ssize_t hint = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t s = starts[i], e = ends[i];
        if (s < 0 || e > size || s > e) {
            status[i] = 2;
            continue;
        }
        status[i] = (uint8_t)candump_line(buf + s, buf + e, names, n_names, &hint, t + i, can_id + i,
                                          flags + i, dlc + i, data + 8 * i, chan + i);
    }
    Py_END_ALLOW_THREADS;
    PyMem_Free(names);
    bufs_release(&bs);
    Py_RETURN_NONE;
fail:
    bufs_release(&bs);
    return NULL;
}

/* -------------------------------------------------------------------- ASC */

/* Next whitespace-separated token in [*q, e): separators are bytes <= 32. */
static inline int next_token(const unsigned char **q, const unsigned char *e,
                             const unsigned char **ts, Py_ssize_t *tl) {
    const unsigned char *p = *q;
    while (p < e && *p <= 32) p++;
    if (p >= e) return 0;
    const unsigned char *s = p;
    while (p < e && *p > 32) p++;
    *ts = s;
    *tl = p - s;
    *q = p;
    return 1;
}

/* One classic data-frame line `t ch id[x] Rx|Tx d dlc b0 ...` (base hex, absolute
 * times): 1 when parsed, with the values asc._LineParser gives the line; 0 leaves
 * it to that parser (which also reads every line without the helper). */
static inline int asc_line(const unsigned char *q, const unsigned char *e, double *t,
                           int64_t *chan, uint32_t *can_id, uint8_t *flags, uint8_t *dlc,
                           uint8_t *data) {
    /* str.split() also splits on other controls and latin-1 NBSP/NEL: such lines go slow */
    for (const unsigned char *p = q; p < e; p++) {
        unsigned char c = *p;
        if ((c < 32 && c != 9 && c != 10 && c != 13) || c >= 127) return 0;
    }
    const unsigned char *ts;
    Py_ssize_t tl;
    /* time: digits, optionally '.' and digits */
    if (!next_token(&q, e, &ts, &tl) || tl < 3) return 0;
    uint64_t sec = 0, frac = 0;
    int ni = 0, nf = 0;
    Py_ssize_t i = 0;
    while (i < tl && is_digit(ts[i])) {
        if (++ni > 18) return 0;
        sec = sec * 10 + (ts[i++] - '0');
    }
    if (ni < 1) return 0;
    if (i < tl) {
        if (ts[i++] != '.') return 0;
        while (i < tl && is_digit(ts[i])) {
            if (++nf > 12) return 0;
            frac = frac * 10 + (ts[i++] - '0');
        }
        if (i < tl) return 0;
    }
    /* channel: 1-3 decimal digits */
    if (!next_token(&q, e, &ts, &tl) || tl < 1 || tl > 3) return 0;
    int64_t ch = 0;
    for (i = 0; i < tl; i++) {
        if (!is_digit(ts[i])) return 0;
        ch = ch * 10 + (ts[i] - '0');
    }
    /* identifier: 1-8 hex digits, 'x' for 29-bit */
    if (!next_token(&q, e, &ts, &tl)) return 0;
    int ext = ts[tl - 1] == 'x' || ts[tl - 1] == 'X';
    Py_ssize_t il = tl - ext;
    if (il < 1 || il > 8) return 0;
    uint32_t id = 0;
    for (i = 0; i < il; i++) {
        int v = HEXV[ts[i]];
        if (v < 0) return 0;
        id = (id << 4) | (uint32_t)v;
    }
    if (id > (ext ? 0x1FFFFFFFu : 0x7FFu)) return 0;
    /* direction */
    if (!next_token(&q, e, &ts, &tl) || tl != 2 || ts[1] != 'x' || (ts[0] != 'R' && ts[0] != 'T'))
        return 0;
    uint8_t fl = (uint8_t)((ts[0] == 'T' ? FLAG_TX : 0) | (ext ? FLAG_EXT : 0));
    /* 'd' and a one-digit DLC code (9..15 still mean 8 bytes) */
    if (!next_token(&q, e, &ts, &tl) || tl != 1 || ts[0] != 'd') return 0;
    if (!next_token(&q, e, &ts, &tl) || tl != 1 || HEXV[ts[0]] < 0) return 0;
    int n_bytes = HEXV[ts[0]] < 8 ? HEXV[ts[0]] : 8;
    memset(data, 0, 8);
    for (int j = 0; j < n_bytes; j++) {
        if (!next_token(&q, e, &ts, &tl) || tl != 2) return 0;
        int hi = HEXV[ts[0]], lo = HEXV[ts[1]];
        if ((hi | lo) < 0) return 0;
        data[j] = (uint8_t)((hi << 4) | lo);
    }
    *t = seconds(sec, ni, frac, nf);
    *chan = ch;
    *can_id = id;
    *flags = fl;
    *dlc = (uint8_t)n_bytes;
    return 1;
}

PyDoc_STRVAR(asc_lines_doc,
             "asc_lines(buf, starts, ends, t, chan, can_id, flags, dlc, data, ok)\n\n"
             "Classic data-frame ASC lines (hex base, absolute times) into column buffers\n"
             "(chan int64, the channel number); ok[i] = 1 where parsed, else 0 and the\n"
             "line is for the Python line parser.");

static PyObject *asc_lines(PyObject *self, PyObject *args) {
    PyObject *o[10];
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OOOOOOOOOO", &o[0], &o[1], &o[2], &o[3], &o[4], &o[5], &o[6],
                          &o[7], &o[8], &o[9]))
        return NULL;
    if (bufs_get(&bs, o[0], 0, -1, "buf") < 0 || bufs_get(&bs, o[1], 0, -1, "starts") < 0)
        goto fail;
    Py_ssize_t n = bs.b[1].len / 8;
    static const int width[10] = {0, 8, 8, 8, 8, 4, 1, 1, 8, 1};
    static const char *what[10] = {"buf", "starts", "ends", "t",    "chan",
                                   "can_id", "flags", "dlc", "data", "ok"};
    for (int i = 2; i < 10; i++)
        if (bufs_get(&bs, o[i], i > 2, n * width[i], what[i]) < 0) goto fail;
    const unsigned char *buf = bs.b[0].buf;
    Py_ssize_t size = bs.b[0].len;
    const int64_t *starts = bs.b[1].buf, *ends = bs.b[2].buf;
    double *t = bs.b[3].buf;
    int64_t *chan = bs.b[4].buf;
    uint32_t *can_id = bs.b[5].buf;
    uint8_t *flags = bs.b[6].buf, *dlc = bs.b[7].buf, *data = bs.b[8].buf, *ok = bs.b[9].buf;
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t s = starts[i], e = ends[i];
        if (s < 0 || e > size || s > e) {
            ok[i] = 0;
            continue;
        }
        ok[i] = (uint8_t)asc_line(buf + s, buf + e, t + i, chan + i, can_id + i, flags + i,
                                  dlc + i, data + 8 * i);
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    Py_RETURN_NONE;
fail:
    bufs_release(&bs);
    return NULL;
}

PyDoc_STRVAR(asc_base_line_doc,
             "asc_base_line(buf, starts) -> k\n\n"
             "1 + the index of the last line matching (?i)^[ \\t]*base[ \\t] (a header line\n"
             "that sets the number base and time mode), 0 when none does.");

static PyObject *asc_base_line(PyObject *self, PyObject *args) {
    PyObject *o_buf, *o_s;
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OO", &o_buf, &o_s)) return NULL;
    if (bufs_get(&bs, o_buf, 0, -1, "buf") < 0 || bufs_get(&bs, o_s, 0, -1, "starts") < 0) {
        bufs_release(&bs);
        return NULL;
    }
    const unsigned char *buf = bs.b[0].buf;
    Py_ssize_t size = bs.b[0].len, n = bs.b[1].len / 8, last = 0;
    const int64_t *starts = bs.b[1].buf;
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t q = starts[i];
        if (q < 0) continue;
        while (q < size && (buf[q] == ' ' || buf[q] == '\t')) q++;
        if (size - q >= 5 && (buf[q] | 0x20) == 'b' && (buf[q + 1] | 0x20) == 'a' &&
            (buf[q + 2] | 0x20) == 's' && (buf[q + 3] | 0x20) == 'e' &&
            (buf[q + 4] == ' ' || buf[q + 4] == '\t'))
            last = i + 1;
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    return PyLong_FromSsize_t(last);
}

/* Separators of a frame line the line parser's str.split() splits on too; any other
 * byte that str.split() takes for whitespace (other controls, latin-1 NBSP/NEL) ends
 * the fast parse and the line goes to the line parser. */
#if defined(__GNUC__)
#define ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE inline
#endif
static ALWAYS_INLINE int asc_sep(unsigned char c) { return c == ' ' || c == '\t' || c == '\r'; }

/* Skip separators, eight spaces at a time (writers pad columns with runs of them);
 * 0 when the line ends there. */
static ALWAYS_INLINE int asc_skip(const unsigned char **q, const unsigned char *e) {
    const unsigned char *p = *q;
    while (p < e) {
        if (*p == ' ' && e - p >= 8) {
            uint64_t w;
            memcpy(&w, p, 8);
            w ^= 0x2020202020202020ull; /* zero bytes where spaces were */
            if (!w) {
                p += 8;
                continue;
            }
            /* the first byte that is not a space: the lowest nonzero byte of w in memory
             * order, which is the lowest-order byte on a little-endian machine only */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
            p += __builtin_ctzll(w) >> 3;
            continue;
#endif
        }
        if (!asc_sep(*p)) break;
        p++;
    }
    *q = p;
    return p < e;
}

/* The token at q ended at p: the next byte must be a separator or the line's end. */
#define ASC_END(p) ((p) >= e || asc_sep(*(p)))

/* asc_line's grammar in one pass over the line: each field is checked byte by byte as
 * it is read and must end at a separator, so no pass over the whole line first. The
 * same lines give the same values; bytes after the last data byte are not read (the
 * line parser ignores the tokens there too). */
static inline int asc_frame(const unsigned char *q, const unsigned char *e, double *t,
                            uint16_t *chan, uint32_t *can_id, uint8_t *flags, uint8_t *dlc,
                            uint8_t *data) {
    /* time: digits, optionally '.' and digits, 3 bytes or more */
    if (!asc_skip(&q, e)) return 0;
    const unsigned char *s = q;
    uint64_t sec = 0, frac = 0;
    int ni = 0, nf = 0;
    while (q < e && is_digit(*q)) {
        if (++ni > 18) return 0;
        sec = sec * 10 + (*q++ - '0');
    }
    if (ni < 1) return 0;
    if (q < e && *q == '.') {
        q++;
        while (q < e && is_digit(*q)) {
            if (++nf > 12) return 0;
            frac = frac * 10 + (*q++ - '0');
        }
    }
    if (q - s < 3 || !ASC_END(q)) return 0;
    /* channel: 1-3 decimal digits */
    if (!asc_skip(&q, e)) return 0;
    int ch = 0, k = 0;
    while (q < e && is_digit(*q)) {
        if (++k > 3) return 0;
        ch = ch * 10 + (*q++ - '0');
    }
    if (k < 1 || !ASC_END(q)) return 0;
    /* identifier: 1-8 hex digits, 'x' for 29-bit */
    if (!asc_skip(&q, e)) return 0;
    uint32_t id = 0;
    k = 0;
    while (q < e && HEXV[*q] >= 0) {
        if (++k > 8) return 0;
        id = (id << 4) | (uint32_t)HEXV[*q++];
    }
    if (k < 1) return 0;
    int ext = q < e && (*q == 'x' || *q == 'X');
    q += ext;
    if (!ASC_END(q) || id > (ext ? 0x1FFFFFFFu : 0x7FFu)) return 0;
    /* direction */
    if (!asc_skip(&q, e) || e - q < 2 || q[1] != 'x' || (q[0] != 'R' && q[0] != 'T')) return 0;
    uint8_t fl = (uint8_t)((q[0] == 'T' ? FLAG_TX : 0) | (ext ? FLAG_EXT : 0));
    q += 2;
    if (!ASC_END(q)) return 0;
    /* 'd' and a one-digit DLC code (9..15 still mean 8 bytes) */
    if (!asc_skip(&q, e) || *q != 'd') return 0;
    q++;
    if (!ASC_END(q) || !asc_skip(&q, e) || HEXV[*q] < 0) return 0;
    int n_bytes = HEXV[*q] < 8 ? HEXV[*q] : 8;
    q++;
    if (!ASC_END(q)) return 0;
    uint8_t d[8] = {0};
    for (int j = 0; j < n_bytes; j++) {
        if (e - q >= 3 && q[0] == ' ' && q[1] > ' ') { /* " XX", the usual spacing */
            q++;
        } else if (!asc_skip(&q, e)) {
            return 0;
        }
        if (e - q < 2) return 0;
        int hi = HEXV[q[0]], lo = HEXV[q[1]];
        if ((hi | lo) < 0) return 0;
        q += 2;
        if (!ASC_END(q)) return 0;
        d[j] = (uint8_t)((hi << 4) | lo);
    }
    memcpy(data, d, 8);
    *t = seconds(sec, ni, frac, nf);
    *chan = (uint16_t)ch;
    *can_id = id;
    *flags = fl;
    *dlc = (uint8_t)n_bytes;
    return 1;
}
#undef ASC_END

/* A `base ...` header line: (?i)^[ \t]*base[ \t] (asc_base_line's test). */
static inline int asc_is_base(const unsigned char *q, const unsigned char *e) {
    while (q < e && (*q == ' ' || *q == '\t')) q++;
    return e - q >= 5 && (q[0] | 0x20) == 'b' && (q[1] | 0x20) == 'a' && (q[2] | 0x20) == 's' &&
           (q[3] | 0x20) == 'e' && (q[4] == ' ' || q[4] == '\t');
}

PyDoc_STRVAR(asc_chunk_doc,
             "asc_chunk(buf, first_line, t, chan, can_id, flags, dlc, data, line, slow, first_row)\n"
             "    -> (n_lines, n_rows, n_slow, last_base)\n\n"
             "One pass over a chunk of ASC lines (hex base, absolute times): lines as\n"
             "split_lines(buf, ..., True) cuts them, classic data-frame lines (asc_lines'\n"
             "grammar and values) into rows 0..n_rows-1 of the columns (chan uint16, the\n"
             "channel number; line int64 = first_line + the line's index); every other\n"
             "line not blank (only ' ', '\\t', '\\r') into slow (int64 (k, 3): index, start,\n"
             "end), for the line parser. first_row (int64, 1000, -1 where unseen): the row\n"
             "where each channel number first appears. last_base: asc_base_line(buf).\n"
             "n_lines -1: more frame lines than the columns' rows or other lines than\n"
             "slow's (as many as count_lines(buf) always do); nothing is final then.");

static PyObject *asc_chunk(PyObject *self, PyObject *args) {
    PyObject *o[11];
    long long first_line;
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OLOOOOOOOOO", &o[0], &first_line, &o[2], &o[3], &o[4], &o[5],
                          &o[6], &o[7], &o[8], &o[9], &o[10]))
        return NULL;
    if (bufs_get(&bs, o[0], 0, -1, "buf") < 0 || bufs_get(&bs, o[2], 1, -1, "t") < 0) goto fail;
    Py_ssize_t cap = bs.b[1].len / 8;
    static const int width[11] = {0, 0, 8, 2, 4, 1, 1, 8, 8, 0, 0};
    static const char *what[11] = {"buf", "",     "t",    "chan", "can_id", "flags",
                                   "dlc", "data", "line", "slow", "first_row"};
    for (int i = 3; i < 10; i++)
        if (bufs_get(&bs, o[i], 1, cap * width[i], what[i]) < 0) goto fail;
    if (bufs_get(&bs, o[10], 1, 1000 * 8, what[10]) < 0) goto fail;
    Py_ssize_t cap_slow = bs.b[8].len / 24;
    const unsigned char *buf = bs.b[0].buf;
    Py_ssize_t size = bs.b[0].len;
    double *t = bs.b[1].buf;
    uint16_t *chan = bs.b[2].buf;
    uint32_t *can_id = bs.b[3].buf;
    uint8_t *flags = bs.b[4].buf, *dlc = bs.b[5].buf, *data = bs.b[6].buf;
    int64_t *line = bs.b[7].buf, *slow = bs.b[8].buf, *first_row = bs.b[9].buf;
    Py_ssize_t n_lines = 0, n = 0, n_slow = 0, last_base = 0;
    int overflow = 0;
    Py_BEGIN_ALLOW_THREADS;
    Py_ssize_t pos = 0;
    for (;;) {
        const unsigned char *nl = pos < size ? memchr(buf + pos, '\n', size - pos) : NULL;
        Py_ssize_t end = nl ? (Py_ssize_t)(nl - buf) : size;
        if (!nl && pos == size && size > 0 && buf[size - 1] == '\n') break; /* no last line */
        if (n >= cap || n_slow >= cap_slow) {
            overflow = 1;
            break;
        }
        Py_ssize_t e = end;
        while (e > pos && buf[e - 1] == '\r') e--;
        if (asc_frame(buf + pos, buf + e, t + n, chan + n, can_id + n, flags + n, dlc + n,
                      data + 8 * n)) {
            line[n] = first_line + n_lines;
            if (first_row[chan[n]] < 0) first_row[chan[n]] = n;
            n++;
        } else {
            Py_ssize_t q = pos;
            while (q < e && asc_sep(buf[q])) q++;
            if (q < e) { /* blank lines mean nothing to the line parser */
                if (asc_is_base(buf + pos, buf + e)) last_base = n_lines + 1;
                int64_t *sl = slow + 3 * n_slow++;
                sl[0] = n_lines, sl[1] = pos, sl[2] = e;
            }
        }
        n_lines++;
        if (!nl) break;
        pos = end + 1;
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    if (overflow) return Py_BuildValue("(nnnn)", (Py_ssize_t)-1, n, n_slow, last_base);
    return Py_BuildValue("(nnnn)", n_lines, n, n_slow, last_base);
fail:
    bufs_release(&bs);
    return NULL;
}

/* -------------------------------------------------------------------- BLF */

/* The object walk of formats/logs/blf.py (_Records.parse and _columns) for one buffer of inflated
 * container bytes: python-can makes one Message per record and its struct unpacking
 * is the whole cost; numpy needs a dozen strided passes per field. Here each object
 * header is read once and each CAN record goes straight into the frame columns. */

#define BLF_CAN_MESSAGE 1
#define BLF_CAN_ERROR_EXT 73
#define BLF_CAN_MESSAGE2 86
#define BLF_CAN_FD_MESSAGE 100
#define BLF_CAN_FD_MESSAGE_64 101
#define BLF_FLAG_FD 0x08
#define BLF_FLAG_BRS 0x10
#define BLF_FLAG_ESI 0x20
/* why bytes were skipped, as formats/logs/blf.py words them (_REASONS) */
#define BLF_GARBAGE 1
#define BLF_BAD_SIZE 2
#define BLF_BAD_TYPE 3
#define BLF_BAD_HEADER 4
#define BLF_BAD_RECORD 5
#define BLF_BAD_TIME 6
#define BLF_NO_NEXT 7
#define BLF_CUT 8
#define BLF_RUN_COLS 6
#define BLF_RUN_GAP 16 /* skipped ranges closer than this (no object between): one run */
#define BLF_LOG_CONTAINER 10
#if defined(__GNUC__) || defined(__clang__)
#define BLF_UNLIKELY(x) __builtin_expect(!!(x), 0)
#else
#define BLF_UNLIKELY(x) (x)
#endif

static const uint8_t DLC2LEN[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};

static inline uint32_t rd16(const unsigned char *p) { return (uint32_t)p[0] | (uint32_t)p[1] << 8; }
static inline uint32_t rd32(const unsigned char *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static inline uint64_t rd64(const unsigned char *p) {
    return (uint64_t)rd32(p) | (uint64_t)rd32(p + 4) << 32;
}

/* bytes of a record body that must be present (formats/logs/blf.py _BODY); 0: not a CAN record */
static inline int64_t blf_body(uint32_t kind) {
    switch (kind) {
    case BLF_CAN_MESSAGE:
    case BLF_CAN_MESSAGE2:
        return 16;
    case BLF_CAN_ERROR_EXT:
        return 32;
    case BLF_CAN_FD_MESSAGE:
        return 84;
    case BLF_CAN_FD_MESSAGE_64:
        return 40;
    }
    return 0;
}

/* First "LOBJ" starting in [from, to) and ending by `end`, or -1 (bytes.find). */
static Py_ssize_t find_lobj(const unsigned char *buf, Py_ssize_t from, Py_ssize_t to,
                            Py_ssize_t end) {
    if (to > end - 3) to = end - 3;
    for (Py_ssize_t i = from; i < to;) {
        const unsigned char *l = memchr(buf + i, 'L', (size_t)(to - i));
        if (!l) return -1;
        i = l - buf;
        if (l[1] == 'O' && l[2] == 'B' && l[3] == 'J') return i;
        i++;
    }
    return -1;
}

PyDoc_STRVAR(blf_records_doc,
             "blf_records(buf, record, limits, start, lo, hi, span, final, t, can_id, flags,\n"
             "            dlc, data, chan, line, long, runs)\n"
             "    -> (ok, n, pos, record, n_long, n_runs, lo, hi)\n\n"
             "formats/logs/blf.py's object walk (_Records._parse_py) over buf (inflated\n"
             "container bytes, the previous tail first) into column buffers of at least\n"
             "len(buf) // 48 rows: t float64, can_id uint32, flags, dlc uint8, data (n, 8)\n"
             "uint8, chan uint16 (the BLF channel number), line int64 (record number).\n"
             "record: objects seen before buf. limits: (MAX_INNER, MAX_OBJECT_TYPE,\n"
             "MAX_OBJ_HEADER, MAX_CAN_OBJECT). A CAN record is taken when its time from\n"
             "the start lies in [lo, hi] (both nan: span around the first record's time) and\n"
             "the next object's signature follows it; final: no bytes follow buf.\n"
             "long: int64 (len(buf) // 72, 4) of (row, payload offset, bytes stored, length)\n"
             "for CAN FD rows over 8 bytes. runs: int64 (k, 6) of the runs of skipped bytes\n"
             "(start, end, reason, a, b, c). pos: where the unwalked tail starts. ok 0: more\n"
             "than k runs (hostile input): nothing is final, the Python walk takes the buffer.");

static PyObject *blf_records(PyObject *self, PyObject *args) {
    PyObject *o[13];
    long long record0, max_inner, max_type, max_header, max_can;
    double start, lo, hi, span;
    int final;
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OL(LLLL)ddddpOOOOOOOOO", &o[0], &record0, &max_inner, &max_type,
                          &max_header, &max_can, &start, &lo, &hi, &span, &final, &o[4], &o[5],
                          &o[6], &o[7], &o[8], &o[9], &o[10], &o[11], &o[12]))
        return NULL;
    if (bufs_get(&bs, o[0], 0, -1, "buf") < 0) goto fail;
    /* a row's object holds a 32-byte header and a body of 16 or more: at most end / 48
     * rows; one over 8 bytes of CAN FD data is 72 bytes or more */
    Py_ssize_t end = bs.b[0].len, cap = end / 48;
    static const int width[13] = {0, 0, 0, 0, 8, 4, 1, 1, 8, 2, 8, 32, 0};
    static const char *what[13] = {"buf",  "", "",     "",     "t",    "can_id", "flags",
                                   "dlc", "data", "chan", "line", "long",   "runs"};
    for (int i = 4; i < 12; i++)
        if (bufs_get(&bs, o[i], 1, (i == 11 ? end / 72 : cap) * width[i], what[i]) < 0) goto fail;
    if (bufs_get(&bs, o[12], 1, -1, what[12]) < 0) goto fail;
    const unsigned char *buf = bs.b[0].buf;
    double *t = bs.b[1].buf;
    uint32_t *can_id = bs.b[2].buf;
    uint8_t *flags = bs.b[3].buf, *dlc = bs.b[4].buf, *data = bs.b[5].buf;
    uint16_t *chan = bs.b[6].buf;
    int64_t *line = bs.b[7].buf, *lng = bs.b[8].buf, *runs = bs.b[9].buf;
    Py_ssize_t max_runs = bs.b[9].len / (8 * BLF_RUN_COLS);
    /* an object is taken when its successor can be seen: pos + size <= lim */
    Py_ssize_t lim = final ? end : end - 16;
    Py_ssize_t pos = 0, n = 0, nl = 0, nr = 0;
    int64_t rec = record0;
    int ok = 1;
    /* the last object taken: start, end, type, its row (-1: none, or refused for its time) */
    Py_ssize_t prev_s = -1, prev_e = -1, prev_row = -1;
    int64_t prev_kind = 0;
    /* the open run of skipped bytes */
    Py_ssize_t rs = -1, re = 0;
    int64_t rw = 0, ra = 0, rb = 0, rc = 0;
#define BLF_EMIT()                                                                                 \
    do {                                                                                           \
        if (nr >= max_runs) {                                                                      \
            ok = 0;                                                                                \
            goto walked;                                                                           \
        }                                                                                          \
        int64_t *r_ = runs + BLF_RUN_COLS * nr++;                                                  \
        r_[0] = rs, r_[1] = re, r_[2] = rw, r_[3] = ra, r_[4] = rb, r_[5] = rc;                   \
    } while (0)
#define BLF_SKIP(s, e, why, a, b, c)                                                               \
    do {                                                                                           \
        if (rs >= 0 && (s) - re < BLF_RUN_GAP) {                                                   \
            re = (e);                                                                              \
        } else {                                                                                   \
            if (rs >= 0) BLF_EMIT();                                                               \
            rs = (s), re = (e), rw = (why), ra = (a), rb = (b), rc = (c);                          \
        }                                                                                          \
    } while (0)
/* garbage right after the last object taken: that object is not believed either */
#define BLF_NOT_FOLLOWED()                                                                         \
    do {                                                                                           \
        if (pos == prev_e) {                                                                       \
            if (prev_row >= 0) {                                                                   \
                n--;                                                                               \
                if (nl > 0 && lng[4 * (nl - 1)] == n) nl--;                                        \
            }                                                                                      \
            if (prev_row != -2) BLF_SKIP(prev_s, prev_e, BLF_NO_NEXT, prev_kind, 0, 0);          \
        }                                                                                          \
    } while (0)
    Py_BEGIN_ALLOW_THREADS;
    while (pos + 16 <= end) {
        if (memcmp(buf + pos, "LOBJ", 4) != 0) {
            Py_ssize_t nxt = find_lobj(buf, pos, pos + 5, end); /* objects are padded to 4 */
            if (nxt < 0) {
                BLF_NOT_FOLLOWED();
                nxt = find_lobj(buf, pos, end, end);
                Py_ssize_t stop = nxt >= 0 ? nxt : (final ? end : end - 3);
                BLF_SKIP(pos, stop, BLF_GARBAGE, 0, 0, 0);
                if (nxt < 0) {
                    pos = stop;
                    break;
                }
            }
            pos = nxt;
            if (pos + 16 > end) break;
        }
        const unsigned char *obj = buf + pos;
        int64_t hsize = rd16(obj + 4), hver = rd16(obj + 6), size = rd32(obj + 8);
        int64_t kind = rd32(obj + 12);
        int64_t body = blf_body((uint32_t)kind);
        int why = 0;
        int64_t wa = 0, wb = 0, wc = 0;
        if (size < 16 || size > max_inner) { /* a claimed 60 MiB swallowed the containers after it */
            why = BLF_BAD_SIZE, wa = size;
        } else if (kind == 0 || kind > max_type || kind == BLF_LOG_CONTAINER) {
            why = BLF_BAD_TYPE, wa = kind;
        } else if (body) {
            if ((hver != 1 && hver != 2) || hsize < 32 || hsize > max_header)
                why = BLF_BAD_HEADER, wa = kind, wb = hver, wc = hsize;
            else if (size < hsize + body || size > max_can)
                why = BLF_BAD_RECORD, wa = kind, wb = size;
        } else if (hsize < 16 || hsize > max_header || hsize > size) {
            why = BLF_BAD_HEADER, wa = kind, wb = hver, wc = hsize;
        }
        if (BLF_UNLIKELY(why != 0)) {
            rec++;
            BLF_SKIP(pos, pos + 4, why, wa, wb, wc);
            pos += 4;
            continue;
        }
        if (pos + size > lim) {
            if (final) { /* continues beyond the data */
                rec++;
                BLF_SKIP(pos, end, BLF_CUT, 0, 0, 0);
                pos = end;
            }
            break; /* continues in the next container */
        }
        rec++;
        prev_s = pos, prev_e = pos + size, prev_kind = kind, prev_row = -1;
        if (body) {
            /* every read below is inside the object: the time ends at 32, the body fits */
            double stamp = (double)(int64_t)rd64(obj + 24);
            double rel = rd32(obj + 16) == 1 ? stamp * 1e-5 : stamp * 1e-9;
            if (BLF_UNLIKELY(!(rel >= lo && rel <= hi))) {
                if (lo != lo) { /* nan: no file times, a range around the first record's */
                    lo = rel - span;
                    hi = rel + span;
                } else {
                    BLF_SKIP(pos, pos + size, BLF_BAD_TIME, kind, (int64_t)rel, 0);
                    prev_row = -2; /* already skipped */
                    pos += size;
                    continue;
                }
            }
            const unsigned char *p = obj + hsize;
            t[n] = rel + start;
            line[n] = rec;
            uint8_t *d = data + 8 * n;
            memset(d, 0, 8);
            uint32_t raw;
            uint8_t fl = 0;
            if (kind == BLF_CAN_MESSAGE || kind == BLF_CAN_MESSAGE2) {
                uint8_t mf = p[2], len = p[3] < 8 ? p[3] : 8;
                raw = rd32(p + 4);
                chan[n] = (uint16_t)rd16(p);
                if (mf & 0x80)
                    fl |= FLAG_RTR;
                else
                    memcpy(d, p + 8, len);
                if (mf & 0x01) fl |= FLAG_TX;
                dlc[n] = len;
            } else if (kind == BLF_CAN_ERROR_EXT) {
                uint8_t len = p[11] < 8 ? p[11] : 8;
                raw = rd32(p + 16);
                chan[n] = (uint16_t)rd16(p);
                fl |= FLAG_ERR;
                memcpy(d, p + 24, len);
                dlc[n] = len;
            } else if (kind == BLF_CAN_FD_MESSAGE) {
                uint8_t mf = p[2], code = p[3] & 0x0F, fd = p[13];
                int64_t valid = p[14] < 64 ? p[14] : 64;
                int rtr = (mf & 0x80) != 0;
                raw = rd32(p + 4);
                chan[n] = (uint16_t)rd16(p);
                if (rtr) fl |= FLAG_RTR;
                if (mf & 0x01) fl |= FLAG_TX;
                if (fd & 0x1) fl |= BLF_FLAG_FD;
                if (fd & 0x2) fl |= BLF_FLAG_BRS;
                if (fd & 0x4) fl |= BLF_FLAG_ESI;
                dlc[n] = (uint8_t)(rtr && valid == 0 ? DLC2LEN[code] : valid);
                memcpy(d, p + 20, valid < 8 ? valid : 8);
                if (valid > 8) {
                    int64_t *l = lng + 4 * nl++;
                    l[0] = n, l[1] = p + 20 - buf, l[2] = valid, l[3] = valid;
                }
            } else { /* CAN_FD_MESSAGE_64 */
                uint8_t code = p[1] & 0x0F, direction = p[34], ext_off = p[35];
                int64_t valid = p[2] < 64 ? p[2] : 64;
                uint32_t fd = rd32(p + 12);
                int rtr = (fd & 0x0010) != 0;
                /* python-can issue 1905: valid_bytes may exceed the bytes stored */
                int64_t room = (ext_off > 0 && ext_off < size ? ext_off : size) - hsize - 40;
                int64_t stored = valid < room ? valid : room;
                if (stored < 0) stored = 0;
                raw = rd32(p + 4);
                chan[n] = p[0];
                if (rtr) fl |= FLAG_RTR;
                if (direction) fl |= FLAG_TX;
                if (fd & 0x1000) fl |= BLF_FLAG_FD;
                if (fd & 0x2000) fl |= BLF_FLAG_BRS;
                if (fd & 0x4000) fl |= BLF_FLAG_ESI;
                dlc[n] = (uint8_t)(rtr && valid == 0 ? DLC2LEN[code] : valid);
                memcpy(d, p + 40, stored < 8 ? stored : 8);
                if (valid > 8) {
                    int64_t *l = lng + 4 * nl++;
                    l[0] = n, l[1] = p + 40 - buf, l[2] = stored, l[3] = valid;
                }
            }
            if (raw & 0x80000000u) fl |= FLAG_EXT;
            can_id[n] = raw & 0x1FFFFFFFu;
            flags[n] = fl;
            prev_row = n++;
        }
        pos += size;
    }
    if (final && pos < end) { /* less than an object header is left (under 4 bytes: padding) */
        if (end - pos >= 4 && find_lobj(buf, pos, pos + 5, end) >= 0) {
            BLF_SKIP(pos, end, BLF_CUT, 0, 0, 0);
        } else if (end - pos >= 4) {
            BLF_NOT_FOLLOWED();
            BLF_SKIP(pos, end, BLF_GARBAGE, 0, 0, 0);
        }
        pos = end;
    }
    if (rs >= 0) BLF_EMIT();
walked:
    Py_END_ALLOW_THREADS;
#undef BLF_EMIT
#undef BLF_SKIP
#undef BLF_NOT_FOLLOWED
    bufs_release(&bs);
    return Py_BuildValue("(innLnndd)", ok, n, pos, (long long)rec, nl, nr, lo, hi);
fail:
    bufs_release(&bs);
    return NULL;
}

/* -------------------------------------------------------------- hex column */

PyDoc_STRVAR(hex_payload_doc,
             "hex_payload(data, dlc, flags, rtr_flag, chars, offsets) -> n_chars\n\n"
             "Arrow string-column buffers of lowercase hex payloads: data (n, 8) uint8,\n"
             "dlc/flags uint8; rows with rtr_flag set are empty, others min(dlc, 8) bytes.\n"
             "chars needs 16 n bytes, offsets (int32) n + 1 entries.");

/* The arguments of hex_payload and payload_pack: (data, dlc, flags, rtr_flag, out, offsets),
 * into bs as dlc, data, flags, out, offsets, with out holding `per_row` bytes a row; the row
 * count, or -1 with an exception set (bs released). */
static Py_ssize_t payload_args(PyObject *args, Bufs *bs, int *rtr, Py_ssize_t per_row,
                               const char *out_name) {
    PyObject *o_data, *o_dlc, *o_flags, *o_out, *o_off;
    if (!PyArg_ParseTuple(args, "OOOiOO", &o_data, &o_dlc, &o_flags, rtr, &o_out, &o_off))
        return -1;
    if (bufs_get(bs, o_dlc, 0, -1, "dlc") < 0) goto fail;
    Py_ssize_t n = bs->b[0].len;
    if (bufs_get(bs, o_data, 0, n * 8, "data") < 0 || bufs_get(bs, o_flags, 0, n, "flags") < 0 ||
        bufs_get(bs, o_out, 1, n * per_row, out_name) < 0 ||
        bufs_get(bs, o_off, 1, (n + 1) * 4, "offsets") < 0)
        goto fail;
    if (n * per_row > INT32_MAX) {
        PyErr_SetString(PyExc_OverflowError, "too many rows for int32 offsets");
        goto fail;
    }
    return n;
fail:
    bufs_release(bs);
    return -1;
}

static PyObject *hex_payload(PyObject *self, PyObject *args) {
    int rtr;
    Bufs bs = {.n = 0};
    Py_ssize_t n = payload_args(args, &bs, &rtr, 16, "chars");
    if (n < 0) return NULL;
    const uint8_t *dlc = bs.b[0].buf, *data = bs.b[1].buf, *flags = bs.b[2].buf;
    char *chars = bs.b[3].buf;
    int32_t *off = bs.b[4].buf;
    static const char hexd[] = "0123456789abcdef";
    int32_t pos = 0;
    Py_BEGIN_ALLOW_THREADS;
    off[0] = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        int len = (flags[i] & rtr) ? 0 : (dlc[i] < 8 ? dlc[i] : 8);
        const uint8_t *d = data + 8 * i;
        for (int j = 0; j < len; j++) {
            chars[pos++] = hexd[d[j] >> 4];
            chars[pos++] = hexd[d[j] & 15];
        }
        off[i + 1] = pos;
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    return PyLong_FromLong(pos);
}

/* ---------------------------------------------------------- classification */

PyDoc_STRVAR(classify_doc,
             "classify(can_id, flags, dlc, data, svc_tab, node_tab, pdo_tab, prev_rtr, codes,\n"
             "         service, node, pdo) -> None\n\n"
             "protocol.cobid.CobClassifier.classify in one pass: 2048-entry tables (uint8,\n"
             "int16, uint8) looked up for standard frames with an 11-bit id (others and\n"
             "29-bit frames are OTHER), error frames marked, and the\n"
             "error-control COB-IDs split into heartbeat / boot-up / guarding with the\n"
             "per-COB-ID 'last frame was an RTR' state (prev_rtr, 2048 bytes, updated);\n"
             "a data frame there that is not 1 byte is ERRCTL_INVALID and leaves prev_rtr.\n"
             "codes: uint8 [OTHER, ERROR_FRAME, HEARTBEAT, BOOTUP, GUARD_RESPONSE,\n"
             "GUARD_REQUEST, ERRCTL_INVALID]. Outputs: service uint8, node int16, pdo uint8\n"
             "(n each).");

static PyObject *classify(PyObject *self, PyObject *args) {
    PyObject *o[12];
    Bufs bs = {.n = 0};
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOO", &o[0], &o[1], &o[2], &o[3], &o[4], &o[5], &o[6],
                          &o[7], &o[8], &o[9], &o[10], &o[11]))
        return NULL;
    if (bufs_get(&bs, o[0], 0, -1, "can_id") < 0) goto fail;
    Py_ssize_t n = bs.b[0].len / 4;
    if (bufs_get(&bs, o[1], 0, n, "flags") < 0 || bufs_get(&bs, o[2], 0, n, "dlc") < 0 ||
        bufs_get(&bs, o[3], 0, n * 8, "data") < 0 || bufs_get(&bs, o[4], 0, 2048, "svc_tab") < 0 ||
        bufs_get(&bs, o[5], 0, 2048 * 2, "node_tab") < 0 ||
        bufs_get(&bs, o[6], 0, 2048, "pdo_tab") < 0 ||
        bufs_get(&bs, o[7], 1, 2048, "prev_rtr") < 0 || bufs_get(&bs, o[8], 0, 7, "codes") < 0 ||
        bufs_get(&bs, o[9], 1, n, "service") < 0 || bufs_get(&bs, o[10], 1, n * 2, "node") < 0 ||
        bufs_get(&bs, o[11], 1, n, "pdo") < 0)
        goto fail;
    const uint32_t *can_id = bs.b[0].buf;
    const uint8_t *flags = bs.b[1].buf, *dlc = bs.b[2].buf, *data = bs.b[3].buf;
    const uint8_t *svc_tab = bs.b[4].buf, *pdo_tab = bs.b[6].buf, *codes = bs.b[8].buf;
    const int16_t *node_tab = bs.b[5].buf;
    uint8_t *prev_rtr = bs.b[7].buf, *service = bs.b[9].buf, *pdo = bs.b[11].buf;
    int16_t *node = bs.b[10].buf;
    const uint8_t OTHER = codes[0], ERROR_FRAME = codes[1], HEARTBEAT = codes[2];
    const uint8_t BOOTUP = codes[3], GUARD_RESPONSE = codes[4], GUARD_REQUEST = codes[5];
    const uint8_t ERRCTL_INVALID = codes[6];
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t i = 0; i < n; i++) {
        uint8_t f = flags[i];
        if (f & (FLAG_EXT | FLAG_ERR)) {
            service[i] = (f & FLAG_ERR) ? ERROR_FRAME : OTHER;
            node[i] = -1;
            pdo[i] = 0;
            continue;
        }
        if (can_id[i] > 0x7FF) { /* a "standard" id a bus cannot carry: never CANopen */
            service[i] = OTHER;
            node[i] = -1;
            pdo[i] = 0;
            continue;
        }
        uint32_t idx = can_id[i];
        uint8_t s = svc_tab[idx];
        node[i] = node_tab[idx];
        pdo[i] = pdo_tab[idx];
        if (s == HEARTBEAT) { /* error control: the previous frame on this COB-ID decides */
            int rtr = (f & FLAG_RTR) != 0;
            if (!rtr && dlc[i] != 1) { /* CiA 301: 1 byte; not error control, state kept */
                service[i] = ERRCTL_INVALID;
                continue;
            }
            int after_rtr = prev_rtr[idx] != 0;
            uint8_t b0 = data[8 * i];
            if (rtr)
                s = GUARD_REQUEST;
            else if (b0 == 0)
                s = BOOTUP;
            else if (after_rtr && (b0 & 0x7F) != 0)
                s = GUARD_RESPONSE;
            prev_rtr[idx] = (uint8_t)rtr;
        }
        service[i] = s;
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    Py_RETURN_NONE;
fail:
    bufs_release(&bs);
    return NULL;
}

/* ------------------------------------------------------------- text lines */

#define MAX_PARTS 64

PyDoc_STRVAR(compact_rows_doc,
             "compact_rows(parts, widths, n, pad, ends) -> bytes\n\n"
             "The text writer's lines from its column matrices: row by row, the bytes of\n"
             "every part (a C-contiguous uint8 buffer of n rows x widths[i], or of one\n"
             "row: the same on every row) in order, leaving out every byte equal to pad.\n"
             "ends: None, or an int64 buffer of n that receives each row's end offset in\n"
             "the result. Equals np.concatenate(parts, axis=1) (one-row parts repeated),\n"
             "then m[m != pad].tobytes() and the cumulative sum of kept bytes per row, in\n"
             "one pass without the GIL; a one-row part is copied whole, its pad bytes\n"
             "dropped once.");

static PyObject *compact_rows(PyObject *self, PyObject *args) {
    PyObject *o_parts, *o_widths, *o_ends;
    Py_ssize_t n;
    int pad;
    if (!PyArg_ParseTuple(args, "OOniO", &o_parts, &o_widths, &n, &pad, &o_ends)) return NULL;
    PyObject *parts = PySequence_Fast(o_parts, "parts must be a sequence");
    if (!parts) return NULL;
    PyObject *widths = PySequence_Fast(o_widths, "widths must be a sequence");
    if (!widths) {
        Py_DECREF(parts);
        return NULL;
    }
    Py_ssize_t np_ = PySequence_Fast_GET_SIZE(parts);
    Py_buffer bufs[MAX_PARTS + 1];
    Py_ssize_t w[MAX_PARTS];
    /* a one-row part: its bytes without pad, written whole on every row */
    uint8_t *fixed[MAX_PARTS] = {0};
    Py_ssize_t fixed_len[MAX_PARTS] = {0};
    int got = 0;
    PyObject *out = NULL;
    Py_ssize_t total = 0;
    if (np_ > MAX_PARTS || PySequence_Fast_GET_SIZE(widths) != np_ || n < 0 || pad < 0 ||
        pad > 255) {
        PyErr_SetString(PyExc_ValueError, "compact_rows: bad parts, widths, n or pad");
        goto done;
    }
    for (Py_ssize_t i = 0; i < np_; i++) {
        w[i] = PyLong_AsSsize_t(PySequence_Fast_GET_ITEM(widths, i));
        if (w[i] < 0) {
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "negative width");
            goto done;
        }
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(parts, i), &bufs[got],
                               PyBUF_SIMPLE | PyBUF_C_CONTIGUOUS) < 0)
            goto done;
        got++;
        if (w[i] && bufs[i].len / w[i] < n && bufs[i].len != w[i]) {
            PyErr_Format(PyExc_ValueError, "part %zd: %zd bytes, need %zd rows x %zd", i,
                         bufs[i].len, n, w[i]);
            goto done;
        }
        if (w[i] && n > 1 && bufs[i].len == w[i]) {
            fixed[i] = PyMem_Malloc((size_t)w[i]);
            if (!fixed[i]) {
                PyErr_NoMemory();
                goto done;
            }
            const uint8_t *row = bufs[i].buf;
            for (Py_ssize_t c = 0; c < w[i]; c++)
                if (row[c] != (uint8_t)pad) fixed[i][fixed_len[i]++] = row[c];
        }
        total += w[i];
    }
    int64_t *ends = NULL;
    if (o_ends != Py_None) {
        if (PyObject_GetBuffer(o_ends, &bufs[got], PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0)
            goto done;
        got++;
        if (bufs[got - 1].len < n * 8) {
            PyErr_SetString(PyExc_ValueError, "ends: buffer too small");
            goto done;
        }
        ends = bufs[got - 1].buf;
    }
    if (total && n > PY_SSIZE_T_MAX / total) {
        PyErr_SetString(PyExc_OverflowError, "compact_rows: too large");
        goto done;
    }
    out = PyBytes_FromStringAndSize(NULL, n * total);
    if (!out) goto done;
    char *dst = PyBytes_AS_STRING(out);
    Py_ssize_t pos = 0;
    const uint8_t p = (uint8_t)pad;
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t r = 0; r < n; r++) {
        for (Py_ssize_t i = 0; i < np_; i++) {
            if (fixed[i]) {
                memcpy(dst + pos, fixed[i], (size_t)fixed_len[i]);
                pos += fixed_len[i];
                continue;
            }
            const uint8_t *src = (const uint8_t *)bufs[i].buf + r * w[i];
            for (Py_ssize_t c = 0; c < w[i]; c++) {
                uint8_t b = src[c];
                dst[pos] = (char)b; /* written always, kept only when not padding */
                pos += b != p;
            }
        }
        if (ends) ends[r] = pos;
    }
    Py_END_ALLOW_THREADS;
    if (_PyBytes_Resize(&out, pos) < 0) out = NULL;
done:
    for (int i = 0; i < got; i++) PyBuffer_Release(&bufs[i]);
    for (Py_ssize_t i = 0; i < MAX_PARTS; i++) PyMem_Free(fixed[i]);
    Py_DECREF(parts);
    Py_DECREF(widths);
    return out;
}

/* ------------------------------------------------------------- MCAP records */

PyDoc_STRVAR(gather_rows_doc,
             "gather_rows(heads, width, sources, part, starts, lengths) -> bytes\n\n"
             "Records end to end: for each i, row i of heads (a C-contiguous buffer of\n"
             "n rows x width bytes), then lengths[i] bytes of sources[part[i]] from\n"
             "starts[i]. part: int32, starts and lengths: int64 buffers of n entries.\n"
             "Every range is checked against its source. The MCAP chunk layout: one\n"
             "pass of memcpy without the GIL instead of a numpy gather per byte.");

static PyObject *gather_rows(PyObject *self, PyObject *args) {
    PyObject *o_heads, *o_sources, *o_part, *o_starts, *o_lengths;
    Py_ssize_t width;
    if (!PyArg_ParseTuple(args, "OnOOOO", &o_heads, &width, &o_sources, &o_part, &o_starts,
                          &o_lengths))
        return NULL;
    PyObject *sources = PySequence_Fast(o_sources, "sources must be a sequence");
    if (!sources) return NULL;
    Py_ssize_t ns = PySequence_Fast_GET_SIZE(sources);
    Py_buffer *src = PyMem_Calloc(ns ? ns : 1, sizeof(Py_buffer));
    Py_ssize_t got = 0;
    Bufs bs = {.n = 0};
    PyObject *out = NULL;
    if (!src) {
        PyErr_NoMemory();
        goto done;
    }
    if (width < 0) {
        PyErr_SetString(PyExc_ValueError, "gather_rows: negative width");
        goto done;
    }
    for (; got < ns; got++)
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(sources, got), &src[got],
                               PyBUF_SIMPLE | PyBUF_C_CONTIGUOUS) < 0)
            goto done;
    if (bufs_get(&bs, o_lengths, 0, -1, "lengths") < 0) goto done;
    Py_ssize_t n = bs.b[0].len / 8;
    if (bufs_get(&bs, o_starts, 0, n * 8, "starts") < 0 ||
        bufs_get(&bs, o_part, 0, n * 4, "part") < 0 ||
        bufs_get(&bs, o_heads, 0, n * width, "heads") < 0)
        goto done;
    const int64_t *len = bs.b[0].buf, *start = bs.b[1].buf;
    const int32_t *part = bs.b[2].buf;
    const char *heads = bs.b[3].buf;
    Py_ssize_t total = 0, bad = -1;
    for (Py_ssize_t i = 0; i < n; i++) {
        int32_t k = part[i];
        if (k < 0 || k >= ns || start[i] < 0 || len[i] < 0 || start[i] > src[k].len ||
            len[i] > src[k].len - start[i] || total > PY_SSIZE_T_MAX - width - len[i]) {
            bad = i;
            break;
        }
        total += width + len[i];
    }
    if (bad >= 0) {
        PyErr_Format(PyExc_ValueError, "gather_rows: record %zd is outside its source", bad);
        goto done;
    }
    out = PyBytes_FromStringAndSize(NULL, total);
    if (!out) goto done;
    char *dst = PyBytes_AS_STRING(out);
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t i = 0; i < n; i++) {
        memcpy(dst, heads + i * width, (size_t)width);
        dst += width;
        memcpy(dst, (const char *)src[part[i]].buf + start[i], (size_t)len[i]);
        dst += len[i];
    }
    Py_END_ALLOW_THREADS;
done:
    for (Py_ssize_t i = 0; i < got; i++) PyBuffer_Release(&src[i]);
    PyMem_Free(src);
    bufs_release(&bs);
    Py_DECREF(sources);
    return out;
}

/* ------------------------------------------------------------- MCAP frames */

PyDoc_STRVAR(frame_json_doc,
             "frame_json(channels, services, channel, can_id, dlc, data, shown, flags, service,\n"
             "           node, ends) -> bytes\n\n"
             "The /can/frames documents of formats/mcap_frames.py, row after row:\n"
             "{\"channel\":C,\"can_id\":I,\"dlc\":D,\"data\":\"HEX\",\"flags\":F,\"service\":S,\"node\":N}\n"
             "channels and services: sequences of bytes (JSON strings, quotes included)\n"
             "indexed by channel (uint16) and service (uint8); can_id uint32, dlc uint8,\n"
             "data n rows of uint8 (width = its length / n), shown int64 (payload bytes\n"
             "written, at most the width), flags uint8, node int16. ends: int64 n, each\n"
             "row's end offset. frame_payloads' numpy path (a byte matrix per field, one\n"
             "compaction) gives the same bytes in about ten passes; this is one.");

/* the decimal digits of v (after a '-' when negative) at dst; returns the length */
static inline Py_ssize_t put_int(char *dst, int64_t v) {
    char tmp[24];
    int k = 0;
    uint64_t m = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
    do {
        tmp[k++] = (char)('0' + m % 10);
        m /= 10;
    } while (m);
    Py_ssize_t len = 0;
    if (v < 0) dst[len++] = '-';
    while (k) dst[len++] = tmp[--k];
    return len;
}

#define PUT(text)                                     \
    do {                                              \
        memcpy(dst + pos, text, sizeof(text) - 1);    \
        pos += sizeof(text) - 1;                      \
    } while (0)

static int bytes_table(PyObject *seq, const char ***text, Py_ssize_t **len, Py_ssize_t *count,
                       Py_ssize_t *longest) {
    Py_ssize_t k = PySequence_Fast_GET_SIZE(seq);
    *text = PyMem_Calloc(k ? k : 1, sizeof(char *));
    *len = PyMem_Calloc(k ? k : 1, sizeof(Py_ssize_t));
    if (!*text || !*len) {
        PyErr_NoMemory();
        return -1;
    }
    *count = k;
    *longest = 0;
    for (Py_ssize_t i = 0; i < k; i++) {
        PyObject *b = PySequence_Fast_GET_ITEM(seq, i);
        if (!PyBytes_Check(b)) {
            PyErr_SetString(PyExc_TypeError, "frame_json: channels and services must be bytes");
            return -1;
        }
        (*text)[i] = PyBytes_AS_STRING(b);
        (*len)[i] = PyBytes_GET_SIZE(b);
        if ((*len)[i] > *longest) *longest = (*len)[i];
    }
    return 0;
}

static PyObject *frame_json(PyObject *self, PyObject *args) {
    PyObject *o_ch_text, *o_svc_text, *o[9];
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOO", &o_ch_text, &o_svc_text, &o[0], &o[1], &o[2],
                          &o[3], &o[4], &o[5], &o[6], &o[7], &o[8]))
        return NULL;
    PyObject *chs = PySequence_Fast(o_ch_text, "channels must be a sequence");
    if (!chs) return NULL;
    PyObject *svcs = PySequence_Fast(o_svc_text, "services must be a sequence");
    if (!svcs) {
        Py_DECREF(chs);
        return NULL;
    }
    const char **ch_text = NULL, **svc_text = NULL;
    Py_ssize_t *ch_len = NULL, *svc_len = NULL, n_ch = 0, n_svc = 0, ch_max = 0, svc_max = 0;
    Bufs bs = {.n = 0};
    PyObject *out = NULL;
    if (bytes_table(chs, &ch_text, &ch_len, &n_ch, &ch_max) < 0 ||
        bytes_table(svcs, &svc_text, &svc_len, &n_svc, &svc_max) < 0)
        goto done;
    if (bufs_get(&bs, o[0], 0, -1, "channel") < 0) goto done;
    Py_ssize_t n = bs.b[0].len / 2;
    if (bufs_get(&bs, o[1], 0, n * 4, "can_id") < 0 || bufs_get(&bs, o[2], 0, n, "dlc") < 0 ||
        bufs_get(&bs, o[3], 0, -1, "data") < 0 || bufs_get(&bs, o[4], 0, n * 8, "shown") < 0 ||
        bufs_get(&bs, o[5], 0, n, "flags") < 0 || bufs_get(&bs, o[6], 0, n, "service") < 0 ||
        bufs_get(&bs, o[7], 0, n * 2, "node") < 0 || bufs_get(&bs, o[8], 1, n * 8, "ends") < 0)
        goto done;
    const uint16_t *channel = bs.b[0].buf;
    const uint32_t *can_id = bs.b[1].buf;
    const uint8_t *dlc = bs.b[2].buf, *data = bs.b[3].buf;
    const int64_t *shown = bs.b[4].buf;
    const uint8_t *flags = bs.b[5].buf, *service = bs.b[6].buf;
    const int16_t *node = bs.b[7].buf;
    int64_t *ends = bs.b[8].buf;
    Py_ssize_t width = n ? bs.b[3].len / n : 0;
    if (n && bs.b[3].len != n * width) {
        PyErr_SetString(PyExc_ValueError, "frame_json: data is not n rows");
        goto done;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        if (channel[i] >= n_ch || service[i] >= n_svc || shown[i] < 0 || shown[i] > width) {
            PyErr_Format(PyExc_ValueError,
                         "frame_json: row %zd: channel, service or shown out of range", i);
            goto done;
        }
    }
    /* the longest row: 67 bytes of fixed text, the four numbers at their widest (22),
     * both labels and the hex */
    Py_ssize_t row_max = 96 + ch_max + svc_max + 2 * width;
    if (n && row_max > PY_SSIZE_T_MAX / n) {
        PyErr_SetString(PyExc_OverflowError, "frame_json: too large");
        goto done;
    }
    out = PyBytes_FromStringAndSize(NULL, n * row_max);
    if (!out) goto done;
    char *dst = PyBytes_AS_STRING(out);
    Py_ssize_t pos = 0;
    static const char hexd[] = "0123456789abcdef";
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t i = 0; i < n; i++) {
        PUT("{\"channel\":");
        memcpy(dst + pos, ch_text[channel[i]], (size_t)ch_len[channel[i]]);
        pos += ch_len[channel[i]];
        PUT(",\"can_id\":");
        pos += put_int(dst + pos, can_id[i]);
        PUT(",\"dlc\":");
        pos += put_int(dst + pos, dlc[i]);
        PUT(",\"data\":\"");
        const uint8_t *d = data + i * width;
        for (int64_t j = 0; j < shown[i]; j++) {
            dst[pos++] = hexd[d[j] >> 4];
            dst[pos++] = hexd[d[j] & 15];
        }
        PUT("\",\"flags\":");
        pos += put_int(dst + pos, flags[i]);
        PUT(",\"service\":");
        memcpy(dst + pos, svc_text[service[i]], (size_t)svc_len[service[i]]);
        pos += svc_len[service[i]];
        PUT(",\"node\":");
        pos += put_int(dst + pos, node[i]);
        PUT("}");
        ends[i] = pos;
    }
    Py_END_ALLOW_THREADS;
    if (_PyBytes_Resize(&out, pos) < 0) out = NULL;
done:
    PyMem_Free(ch_text);
    PyMem_Free(ch_len);
    PyMem_Free(svc_text);
    PyMem_Free(svc_len);
    bufs_release(&bs);
    Py_DECREF(chs);
    Py_DECREF(svcs);
    return out;
}

/* The decimal digits of v into o; their count. */
static int write_uint(uint64_t v, char *o) {
    char d[24];
    int n = 0, len = 0;
    do {
        d[n++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (n) o[len++] = d[--n];
    return len;
}

/* repr(x) into o when x is a whole number of microseconds below 2**32 (a logged time
   stamp, a time relative to the first): the shortest text that reads back as x is then
   its six decimals less their trailing zeros (one decimal kept), since no other text of
   six decimals or fewer lies within half a unit in the last place of x (below 2**32
   that unit is at most 2**-21 s < 1 us). Whether x is such a number: k = x * 1e6
   rounded, and k / 1e6 (both exact below 2**53: one correctly rounded division) is x.
   Returns the length, or 0 when x is not such a number. */
static int micro_repr(double x, char *o) {
    double a = fabs(x);
    if (!(a >= 1e-4 && a < 4294967296.0)) return 0;
    double r = nearbyint(a * 1e6);
    if (r / 1e6 != a) return 0;
    uint64_t k = (uint64_t)r, frac = k % 1000000;
    int len = 0;
    if (signbit(x)) o[len++] = '-';
    len += write_uint(k / 1000000, o + len);
    o[len++] = '.';
    int keep = 6;
    while (keep > 1 && frac % 10 == 0) {
        frac /= 10;
        keep--;
    }
    for (int j = keep - 1; j >= 0; j--) {
        o[len + j] = (char)('0' + frac % 10);
        frac /= 10;
    }
    return len + keep;
}

PyDoc_STRVAR(float_repr_doc,
             "float_repr(v, data, offsets, out, todo) -> width\n\n"
             "repr() of each float64 of v into the rows of out (uint8, len(v) x 24, zeroed:\n"
             "NUL-padded; 24 bytes hold any double's repr), \"null\" where not finite (JSON);\n"
             "returns the longest text's length. A whole number of microseconds below 2**32\n"
             "(a time stamp) is written from its digits; any other row from data/offsets\n"
             "(uint8; int64, len(v) + 1), Arrow's cast of v to text, which is repr's where\n"
             "it has no exponent and 1e-4 <= |v| < 1e16 (or v is 0) once \".0\" ends a whole\n"
             "number, else by Python's own formatter (PyOS_double_to_string, as\n"
             "float.__repr__). With data None, such rows are left empty and marked in todo\n"
             "(uint8, len(v)), for a second call with Arrow's text of those alone. The numpy\n"
             "path's passes over the text matrix and Arrow's cast were 0.4 s of a 1M-frame\n"
             "JSONL decode's time column; Python's formatter alone is 4x Arrow's cast.");

static PyObject *float_repr(PyObject *self, PyObject *args) {
    PyObject *o_v, *o_data, *o_off, *o_out, *o_todo;
    if (!PyArg_ParseTuple(args, "OOOOO", &o_v, &o_data, &o_off, &o_out, &o_todo)) return NULL;
    Bufs bs = {.n = 0};
    int arrow = o_data != Py_None;
    if (bufs_get(&bs, o_v, 0, -1, "v") < 0) goto fail;
    Py_ssize_t n = bs.b[0].len / 8, nd = 0, width = 0;
    if (bufs_get(&bs, o_out, 1, n * 24, "out") < 0) goto fail;
    const char *data = NULL;
    const int64_t *off = NULL;
    uint8_t *todo = NULL;
    if (arrow) {
        if (bufs_get(&bs, o_data, 0, -1, "data") < 0 ||
            bufs_get(&bs, o_off, 0, (n + 1) * 8, "offsets") < 0)
            goto fail;
        data = bs.b[2].buf;
        nd = bs.b[2].len;
        off = bs.b[3].buf;
    } else {
        if (bufs_get(&bs, o_todo, 1, n, "todo") < 0) goto fail;
        todo = bs.b[2].buf;
    }
    const double *v = bs.b[0].buf;
    char *out = bs.b[1].buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        double x = v[i], a = fabs(x);
        char *o = out + 24 * i;
        int64_t len = isfinite(x) ? micro_repr(x, o) : 0;
        if (len) {
            /* written from its digits */
        } else if (!isfinite(x)) {
            memcpy(o, "null", 4);
            len = 4;
        } else if (!arrow) {
            todo[i] = 1;
        } else {
            int64_t lo = off[i];
            len = off[i + 1] - lo;
            if ((a == 0 || (a >= 1e-4 && a < 1e16)) && lo >= 0 && len > 0 && len <= 22 &&
                lo + len <= nd && !memchr(data + lo, 'e', (size_t)len)) {
                memcpy(o, data + lo, (size_t)len);
                if (!memchr(o, '.', (size_t)len)) {
                    o[len++] = '.';
                    o[len++] = '0';
                }
            } else {
                char *s = PyOS_double_to_string(x, 'r', 0, Py_DTSF_ADD_DOT_0, NULL);
                if (!s) goto fail;
                len = (int64_t)strlen(s);
                if (len > 24) len = 24; /* never: no double's repr is longer */
                memcpy(o, s, (size_t)len);
                PyMem_Free(s);
            }
        }
        if (len > width) width = len;
    }
    bufs_release(&bs);
    return PyLong_FromSsize_t(width);
fail:
    bufs_release(&bs);
    return NULL;
}

/* Python's own text of x in format 'f' or 'g' (PyOS_double_to_string, as format()
   calls it) into o (at most cap bytes); returns its length, or -1 (error set, or longer
   than cap: *too_long). */
static int py_format(double x, char code, int precision, char *o, int cap, int *too_long) {
    char *s = PyOS_double_to_string(x, code, precision, 0, NULL);
    if (!s) return -1;
    size_t len = strlen(s);
    if ((int)len > cap) {
        PyMem_Free(s);
        *too_long = 1;
        return -1;
    }
    memcpy(o, s, len);
    PyMem_Free(s);
    return (int)len;
}

/* The arguments (v, out) of time_text and g6_text: v float64, out n rows of W bytes; the
   row count, or -1 with an exception set (bs released). */
static Py_ssize_t float_rows(PyObject *args, Bufs *bs, Py_ssize_t W) {
    PyObject *o_v, *o_out;
    if (!PyArg_ParseTuple(args, "OO", &o_v, &o_out)) return -1;
    if (bufs_get(bs, o_v, 0, -1, "v") < 0) goto fail;
    Py_ssize_t n = bs->b[0].len / 8;
    if (bufs_get(bs, o_out, 1, n * W, "out") < 0) goto fail;
    return n;
fail:
    bufs_release(bs);
    return -1;
}

PyDoc_STRVAR(time_text_doc,
             "time_text(v, out) -> width\n\n"
             "f\"{x:12.6f}\" of each float64 of v, right-aligned in the rows of out (uint8,\n"
             "len(v) x 40, zeroed: NUL on the left); returns the longest text's length, or\n"
             "-(i + 1) for the first row i whose text is longer than 40. Rounded from x * 1e6\n"
             "when that is no closer than 1e-3 to a half (its rounding error is far below);\n"
             "negative, huge, not finite or near a tie, Python formats it (as format()).\n"
             "numpy's passes (digits, blanking, a scatter) were 0.3 s per 1M frames of text.");

static PyObject *time_text(PyObject *self, PyObject *args) {
    Bufs bs = {.n = 0};
    const int W = 40;
    Py_ssize_t n = float_rows(args, &bs, W), width = 0;
    if (n < 0) return NULL;
    const double *v = bs.b[0].buf;
    char *out = bs.b[1].buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        double x = v[i], vv = x * 1e6;
        char buf[48];
        int len;
        if (!signbit(x) && vv < 1e12 && fabs(vv - floor(vv) - 0.5) >= 1e-3) {
            uint64_t k = (uint64_t)nearbyint(vv), frac = k % 1000000;
            len = write_uint(k / 1000000, buf);
            buf[len++] = '.';
            for (int j = 5; j >= 0; j--) {
                buf[len + j] = (char)('0' + frac % 10);
                frac /= 10;
            }
            len += 6;
        } else {
            int too_long = 0;
            len = py_format(x, 'f', 6, buf, W, &too_long);
            if (len < 0) {
                bufs_release(&bs);
                return too_long ? PyLong_FromSsize_t(-(i + 1)) : NULL;
            }
        }
        int shown = len < 12 ? 12 : len;
        char *o = out + W * i + (W - shown);
        memset(o, ' ', (size_t)(shown - len));
        memcpy(o + (shown - len), buf, (size_t)len);
        if (shown > width) width = shown;
    }
    bufs_release(&bs);
    return PyLong_FromSsize_t(width);
}

static const double P10_9[10] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9};

PyDoc_STRVAR(g6_text_doc,
             "g6_text(v, out) -> width\n\n"
             "f\"{x:.6g}\" of each float64 of v, left-aligned in the rows of out (uint8,\n"
             "len(v) x 24, zeroed); returns the longest text's length. Six digits rounded\n"
             "from |x| * 10**(5 - e) (one rounding, exact power of ten) where the exponent e\n"
             "is -4..5 and no tie is near (1e-6); any other value (an exponent, a near tie,\n"
             "not finite) Python formats (as format()). numtext.g6_text's numpy twin.");

static PyObject *g6_text(PyObject *self, PyObject *args) {
    Bufs bs = {.n = 0};
    const int W = 24;
    Py_ssize_t n = float_rows(args, &bs, W), width = 0;
    if (n < 0) return NULL;
    const double *v = bs.b[0].buf;
    char *out = bs.b[1].buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        double x = v[i], a = fabs(x);
        char *o = out + W * i;
        int len = 0, fast = 0;
        if (x == 0) {
            if (signbit(x)) o[len++] = '-';
            o[len++] = '0';
            fast = 1;
        } else if (isfinite(x)) {
            int e = (int)floor(log10(a));
            if (e >= -4 && e <= 5) {
                double m = a * P10_9[5 - e], r = nearbyint(m), frac = m - floor(m);
                if (m >= 1e5 && r < 1e6 && fabs(frac - 0.5) > 1e-6) {
                    char d[6];
                    uint64_t k = (uint64_t)r;
                    for (int j = 5; j >= 0; j--) {
                        d[j] = (char)('0' + k % 10);
                        k /= 10;
                    }
                    int last = 5; /* the last non-zero digit, never inside the integer part */
                    while (last > 0 && d[last] == '0') last--;
                    if (signbit(x)) o[len++] = '-';
                    if (e >= 0) {
                        memcpy(o + len, d, (size_t)(e + 1));
                        len += e + 1;
                        if (last > e) {
                            o[len++] = '.';
                            memcpy(o + len, d + e + 1, (size_t)(last - e));
                            len += last - e;
                        }
                    } else {
                        o[len++] = '0';
                        o[len++] = '.';
                        for (int z = 0; z < -e - 1; z++) o[len++] = '0';
                        memcpy(o + len, d, (size_t)(last + 1));
                        len += last + 1;
                    }
                    fast = 1;
                }
            }
        }
        if (!fast) {
            int too_long = 0;
            len = py_format(x, 'g', 6, o, W, &too_long);
            if (len < 0) goto fail; /* never too long: '-1.23457e+308' */
        }
        if (len > width) width = len;
    }
    bufs_release(&bs);
    return PyLong_FromSsize_t(width);
fail:
    bufs_release(&bs);
    return NULL;
}

PyDoc_STRVAR(frame_text_doc,
             "frame_text(can_id, flags, dlc, data, out)\n\n"
             "The text output's identifier, length and data columns of each frame into the\n"
             "rows of out (uint8, n x 39): the identifier as 8 upper-case hex digits, the\n"
             "first 5 blank unless flags has 0x01 or 0x04 (29-bit, error frame), 2 spaces;\n"
             "'[' the length's tens (NUL when 0) and units ']' and 2 spaces; then the first\n"
             "min(dlc, 8) bytes as 'HH ' (23 characters, spaces past them), or 'remote\n"
             "request' when flags has 0x02. can_id uint32, flags and dlc uint8, data\n"
             "(n, 8) uint8. The numpy twin (outputs/text/writer.py) builds the same\n"
             "columns in a dozen passes: 0.1 s per 1M frames.");

static PyObject *frame_text(PyObject *self, PyObject *args) {
    PyObject *o[5];
    if (!PyArg_ParseTuple(args, "OOOOO", &o[0], &o[1], &o[2], &o[3], &o[4])) return NULL;
    Bufs bs = {.n = 0};
    if (bufs_get(&bs, o[0], 0, -1, "can_id") < 0) goto fail;
    Py_ssize_t n = bs.b[0].len / 4;
    if (bufs_get(&bs, o[1], 0, n, "flags") < 0 || bufs_get(&bs, o[2], 0, n, "dlc") < 0 ||
        bufs_get(&bs, o[3], 0, n * 8, "data") < 0 || bufs_get(&bs, o[4], 1, n * 39, "out") < 0)
        goto fail;
    const uint32_t *id = bs.b[0].buf;
    const uint8_t *flags = bs.b[1].buf, *dlc = bs.b[2].buf, *data = bs.b[3].buf;
    uint8_t *out = bs.b[4].buf;
    static const char H[] = "0123456789ABCDEF";
    static const char REMOTE[] = "remote request         ";
    Py_BEGIN_ALLOW_THREADS;
    for (Py_ssize_t i = 0; i < n; i++) {
        uint8_t *o = out + 39 * i;
        uint32_t v = id[i];
        for (int j = 0; j < 8; j++) o[j] = (uint8_t)H[(v >> (4 * (7 - j))) & 15];
        if (!(flags[i] & 0x05)) memset(o, ' ', 5);
        o[8] = o[9] = ' ';
        uint8_t d = dlc[i];
        o[10] = '[';
        o[11] = d / 10 ? (uint8_t)('0' + d / 10) : 0;
        o[12] = (uint8_t)('0' + d % 10);
        o[13] = ']';
        o[14] = o[15] = ' ';
        uint8_t *h = o + 16;
        if (flags[i] & 0x02) {
            memcpy(h, REMOTE, 23);
            continue;
        }
        int shown = d < 8 ? d : 8;
        const uint8_t *b = data + 8 * i;
        for (int j = 0; j < 8; j++) {
            if (j < shown) {
                h[3 * j] = (uint8_t)H[b[j] >> 4];
                h[3 * j + 1] = (uint8_t)H[b[j] & 15];
            } else {
                h[3 * j] = h[3 * j + 1] = ' ';
            }
            if (j < 7) h[3 * j + 2] = ' ';
        }
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    Py_RETURN_NONE;
fail:
    bufs_release(&bs);
    return NULL;
}

static PyMethodDef methods[] = {
    {"count_lines", count_lines, METH_VARARGS, count_lines_doc},
    {"split_lines", split_lines, METH_VARARGS, split_lines_doc},
    {"candump_lines", candump_lines, METH_VARARGS, candump_lines_doc},
    {"asc_lines", asc_lines, METH_VARARGS, asc_lines_doc},
    {"asc_base_line", asc_base_line, METH_VARARGS, asc_base_line_doc},
    {"asc_chunk", asc_chunk, METH_VARARGS, asc_chunk_doc},
    {"blf_records", blf_records, METH_VARARGS, blf_records_doc},
    {"hex_payload", hex_payload, METH_VARARGS, hex_payload_doc},
    {"classify", classify, METH_VARARGS, classify_doc},
    {"compact_rows", compact_rows, METH_VARARGS, compact_rows_doc},
    {"gather_rows", gather_rows, METH_VARARGS, gather_rows_doc},
    {"frame_json", frame_json, METH_VARARGS, frame_json_doc},
    {"float_repr", float_repr, METH_VARARGS, float_repr_doc},
    {"time_text", time_text, METH_VARARGS, time_text_doc},
    {"g6_text", g6_text, METH_VARARGS, g6_text_doc},
    {"frame_text", frame_text, METH_VARARGS, frame_text_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_speedups",
    "Compiled inner loops of the text readers and writer, the classifier, the frames table "
    "and the MCAP chunks (optional).", -1, methods,
};

static int add_decode_functions(PyObject *m); /* the decode section, at the end */
static int add_table_functions(PyObject *m);  /* the table-writer section, after it */

PyMODINIT_FUNC PyInit__speedups(void) {
    memset(HEXV, -1, sizeof HEXV);
    for (int c = '0'; c <= '9'; c++) HEXV[c] = (signed char)(c - '0');
    for (int c = 'a'; c <= 'f'; c++) HEXV[c] = (signed char)(c - 'a' + 10);
    for (int c = 'A'; c <= 'F'; c++) HEXV[c] = (signed char)(c - 'A' + 10);
    PyObject *m = PyModule_Create(&module);
    if (m && (add_decode_functions(m) < 0 || add_table_functions(m) < 0)) Py_CLEAR(m);
    return m;
}

/* ---- the decode path (FrameBatch -> DecodedBatch): its own section and method table -------- */

/* A counting sort's first half, shared by stable_order and group_gaps (called without
   the GIL): next[key] becomes the first slot of each key's rows (exclusive prefix sums of
   the counts), and the start of each key that has rows goes to starts (if not NULL), in
   key order; returns the number of such keys, or -(i + 1) for the first row i whose key
   is not below nkeys or whose row is not below nrows (rows given; next is left unusable). */
static Py_ssize_t bucket_starts(const uint16_t *keys, Py_ssize_t n, Py_ssize_t nkeys,
                                const Py_ssize_t *rows, Py_ssize_t nrows, Py_ssize_t *next,
                                Py_ssize_t *starts) {
    for (Py_ssize_t i = 0; i < n; i++) {
        if (keys[i] >= nkeys || (rows && (rows[i] < 0 || rows[i] >= nrows))) return -(i + 1);
        next[keys[i]]++;
    }
    Py_ssize_t at = 0, groups = 0;
    for (Py_ssize_t k = 0; k < nkeys; k++) {
        Py_ssize_t c = next[k];
        next[k] = at;
        if (c && starts) starts[groups] = at;
        groups += c != 0;
        at += c;
    }
    return groups;
}

PyDoc_STRVAR(stable_order_doc,
             "stable_order(keys, nkeys, order)\n\n"
             "The stable sort order of keys (uint16, n of them, each < nkeys) into order\n"
             "(intp, n): np.argsort(keys, kind='stable'), as a counting sort. A batch's\n"
             "PDO rows by COB-ID have a hundred distinct keys: one count and one scatter\n"
             "pass instead of numpy's two-pass radix sort (4x faster on such rows).");

static PyObject *stable_order(PyObject *self, PyObject *args) {
    PyObject *o_keys, *o_order;
    Py_ssize_t nkeys;
    if (!PyArg_ParseTuple(args, "OnO", &o_keys, &nkeys, &o_order)) return NULL;
    if (nkeys < 1 || nkeys > 65536) {
        PyErr_SetString(PyExc_ValueError, "stable_order: nkeys must be 1..65536");
        return NULL;
    }
    Bufs bs = {.n = 0};
    if (bufs_get(&bs, o_keys, 0, -1, "keys") < 0) goto fail;
    Py_ssize_t n = bs.b[0].len / 2;
    if (bufs_get(&bs, o_order, 1, n * (Py_ssize_t)sizeof(Py_ssize_t), "order") < 0) goto fail;
    const uint16_t *keys = bs.b[0].buf;
    Py_ssize_t *order = bs.b[1].buf;
    Py_ssize_t *next = PyMem_Calloc((size_t)nkeys, sizeof(Py_ssize_t));
    if (!next) {
        PyErr_NoMemory();
        goto fail;
    }
    Py_ssize_t got;
    Py_BEGIN_ALLOW_THREADS;
    got = bucket_starts(keys, n, nkeys, NULL, 0, next, NULL);
    if (got >= 0)
        for (Py_ssize_t i = 0; i < n; i++) order[next[keys[i]]++] = i;
    Py_END_ALLOW_THREADS;
    PyMem_Free(next);
    if (got < 0) {
        PyErr_Format(PyExc_ValueError, "stable_order: key %zd is not below nkeys", -got - 1);
        goto fail;
    }
    bufs_release(&bs);
    Py_RETURN_NONE;
fail:
    bufs_release(&bs);
    return NULL;
}

PyDoc_STRVAR(group_gaps_doc,
             "group_gaps(keys, rows, t, last, k, tt, prev, r, starts) -> groups\n\n"
             "checks.gaps.grouped_gaps in one counting sort: rows (intp, n) grouped by\n"
             "keys (uint16, n, each < len(last)), row order kept in a group; writes the\n"
             "sorted keys k (intp), their times tt = t[r] (float64), the previous time of\n"
             "the same key prev (float64; the group's first from last, float64 per key,\n"
             "then updated to each group's last time), the rows r (intp), and the\n"
             "start of each group into starts (intp, len(last)); returns the groups.");

static PyObject *group_gaps(PyObject *self, PyObject *args) {
    PyObject *o[9];
    if (!PyArg_ParseTuple(args, "OOOOOOOOO", &o[0], &o[1], &o[2], &o[3], &o[4], &o[5], &o[6],
                          &o[7], &o[8]))
        return NULL;
    Bufs bs = {.n = 0};
    Py_ssize_t *next = NULL, groups = 0, bad = -1;
    if (bufs_get(&bs, o[0], 0, -1, "keys") < 0 || bufs_get(&bs, o[2], 0, -1, "t") < 0 ||
        bufs_get(&bs, o[3], 1, -1, "last") < 0)
        goto fail;
    Py_ssize_t n = bs.b[0].len / 2, nt = bs.b[1].len / 8, nkeys = bs.b[2].len / 8;
    const Py_ssize_t W = (Py_ssize_t)sizeof(Py_ssize_t);
    if (bufs_get(&bs, o[1], 0, n * W, "rows") < 0 || bufs_get(&bs, o[4], 1, n * W, "k") < 0 ||
        bufs_get(&bs, o[5], 1, n * 8, "tt") < 0 || bufs_get(&bs, o[6], 1, n * 8, "prev") < 0 ||
        bufs_get(&bs, o[7], 1, n * W, "r") < 0 || bufs_get(&bs, o[8], 1, nkeys * W, "starts") < 0)
        goto fail;
    const uint16_t *keys = bs.b[0].buf;
    const double *t = bs.b[1].buf;
    double *last = bs.b[2].buf;
    const Py_ssize_t *rows = bs.b[3].buf;
    Py_ssize_t *k = bs.b[4].buf, *r = bs.b[7].buf, *starts = bs.b[8].buf;
    double *tt = bs.b[5].buf, *prev = bs.b[6].buf;
    next = PyMem_Calloc((size_t)(nkeys ? nkeys : 1), sizeof(Py_ssize_t));
    if (!next) {
        PyErr_NoMemory();
        goto fail;
    }
    Py_BEGIN_ALLOW_THREADS;
    groups = bucket_starts(keys, n, nkeys, rows, nt, next, starts);
    if (groups < 0) {
        bad = -groups - 1;
        groups = 0;
    } else {
        for (Py_ssize_t i = 0; i < n; i++) {
            uint16_t key = keys[i];
            Py_ssize_t p = next[key]++;
            double ti = t[rows[i]];
            k[p] = key;
            r[p] = rows[i];
            tt[p] = ti;
            prev[p] = last[key];
            last[key] = ti;
        }
    }
    Py_END_ALLOW_THREADS;
    if (bad >= 0) {
        PyErr_Format(PyExc_ValueError, "group_gaps: key or row %zd out of range", bad);
        goto fail;
    }
    PyMem_Free(next);
    bufs_release(&bs);
    return PyLong_FromSsize_t(groups);
fail:
    PyMem_Free(next);
    bufs_release(&bs);
    return NULL;
}

static PyMethodDef decode_methods[] = {
    {"stable_order", stable_order, METH_VARARGS, stable_order_doc},
    {"group_gaps", group_gaps, METH_VARARGS, group_gaps_doc},
    {NULL, NULL, 0, NULL},
};

static int add_decode_functions(PyObject *m) { return PyModule_AddFunctions(m, decode_methods); }

/* ---- the table writers (outputs/tables): their own section and method table ---------------- */

PyDoc_STRVAR(payload_pack_doc,
             "payload_pack(data, dlc, flags, rtr_flag, values, offsets) -> n_bytes\n\n"
             "Arrow binary-column buffers of the payloads: data (n, 8) uint8, dlc/flags\n"
             "uint8; rows with rtr_flag set are empty, others min(dlc, 8) bytes.\n"
             "values needs 8 n bytes, offsets (int32) n + 1 entries. columns.payloads'\n"
             "numpy path gives the same bytes; its mask and boolean gather were 0.7 s of\n"
             "CPU per 10M frames, this one pass (an 8-byte copy per row) a tenth of it.");

static PyObject *payload_pack(PyObject *self, PyObject *args) {
    int rtr;
    Bufs bs = {.n = 0};
    Py_ssize_t n = payload_args(args, &bs, &rtr, 8, "values");
    if (n < 0) return NULL;
    const uint8_t *dlc = bs.b[0].buf, *data = bs.b[1].buf, *flags = bs.b[2].buf;
    uint8_t *values = bs.b[3].buf;
    int32_t *off = bs.b[4].buf;
    int32_t pos = 0;
    Py_BEGIN_ALLOW_THREADS;
    off[0] = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        /* the whole row is copied and the position advanced by its length: pos <= 8 i,
         * so the 8 bytes stay inside values (8 n), and the next row overwrites the rest */
        memcpy(values + pos, data + 8 * i, 8);
        pos += (flags[i] & rtr) ? 0 : (dlc[i] < 8 ? dlc[i] : 8);
        off[i + 1] = pos;
    }
    Py_END_ALLOW_THREADS;
    bufs_release(&bs);
    return PyLong_FromLong(pos);
}

static PyMethodDef table_methods[] = {
    {"payload_pack", payload_pack, METH_VARARGS, payload_pack_doc},
    {NULL, NULL, 0, NULL},
};

static int add_table_functions(PyObject *m) { return PyModule_AddFunctions(m, table_methods); }
