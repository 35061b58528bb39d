// model/base/util.c — errors, files, hashes, number parsing, threads.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "model/internal.h"

static _Thread_local char last_error[2048];
static _Thread_local bool quiet_thread;   // this thread's errors are kept, not printed
static atomic_bool quiet_mode;

static void error_keep(const char *where_file, int where_line, const char *fmt, va_list ap)
{
    char msg[1536];
    vsnprintf(msg, sizeof msg, fmt, ap);
    if (where_file && where_line > 0)
        snprintf(last_error, sizeof last_error, "%s:%d: %s", where_file, where_line, msg);
    else if (where_file)
        snprintf(last_error, sizeof last_error, "%s: %s", where_file, msg);
    else
        snprintf(last_error, sizeof last_error, "%s", msg);
}

void model_error(const char *where_file, int where_line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    error_keep(where_file, where_line, fmt, ap);
    va_end(ap);
    if (!atomic_load(&quiet_mode) && !quiet_thread)
        fprintf(stderr, "%s\n", last_error);
}

void model_error_set(const char *where_file, int where_line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    error_keep(where_file, where_line, fmt, ap);
    va_end(ap);
}

const char *model_last_error(void) { return last_error; }

int model_error_report(const char *cmd)
{
    if (!atomic_load(&quiet_mode)) fprintf(stderr, "refl %s: %s\n", cmd, last_error[0] ? last_error : "failed");
    return 1;
}
void model_error_clear(void) { last_error[0] = 0; }
bool model_error_quiet(bool quiet) { return atomic_exchange(&quiet_mode, quiet); }
bool model_error_quiet_global(void) { return atomic_load(&quiet_mode); }

bool model_error_quiet_thread(bool quiet)
{
    bool old = quiet_thread;
    quiet_thread = quiet;
    return old;
}

char *model_read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        model_error(path, 0, "cannot open: %s", strerror(errno));
        return NULL;
    }
    size_t cap = 1 << 16, n = 0;
    char *buf = malloc(cap + 1);
    if (!buf) {
        fclose(f);
        model_error(path, 0, "out of memory");
        return NULL;
    }
    for (;;) {
        size_t got = fread(buf + n, 1, cap - n, f);
        n += got;
        if (n < cap) break;
        char *nb = realloc(buf, 2 * cap + 1);
        if (!nb) {
            free(buf);
            fclose(f);
            model_error(path, 0, "out of memory");
            return NULL;
        }
        buf = nb;
        cap *= 2;
    }
    if (ferror(f)) {
        model_error(path, 0, "read error: %s", strerror(errno));
        free(buf);
        fclose(f);
        return NULL;
    }
    fclose(f);
    buf[n] = 0;
    if (len) *len = n;
    return buf;
}

void model_sha256_hex(const void *data, size_t len, char out[65])
{
    gchar *s = g_compute_checksum_for_data(G_CHECKSUM_SHA256, data, len);
    memcpy(out, s, 64);
    out[64] = 0;
    g_free(s);
}

bool model_sha256_file(const char *path, char out[65])
{
    size_t len;
    char *buf = model_read_file(path, &len);
    if (!buf) return false;
    model_sha256_hex(buf, len, out);
    free(buf);
    return true;
}

bool model_parse_double(const char *s, double *out)
{
    if (!s) return false;
    while (*s == ' ' || *s == '\t') s++;
    if (!*s) return false;
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || errno == ERANGE || !isfinite(v)) return false;
    while (*end == ' ' || *end == '\t' || *end == '\r' || *end == '\n') end++;
    if (*end) return false;
    *out = v;
    return true;
}

int model_parse_doubles(const char *s, const char *seps, double lo, double hi, double *v, int max)
{
    if (!s) return -1;
    gchar **w = g_strsplit_set(s, seps, -1);
    int k = 0;
    bool ok = true;
    for (int i = 0; w[i] && ok; i++) {
        if (!w[i][0]) continue;
        double x;
        ok = k < max && model_parse_double(w[i], &x) && x >= lo && x <= hi;
        if (ok) v[k++] = x;
    }
    g_strfreev(w);
    return ok && k > 0 ? k : -1;
}

bool model_parse_int(const char *s, long *out)
{
    if (!s) return false;
    while (*s == ' ' || *s == '\t') s++;
    if (!*s) return false;
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || errno == ERANGE) return false;
    while (*end == ' ' || *end == '\t' || *end == '\r' || *end == '\n') end++;
    if (*end) return false;
    *out = v;
    return true;
}

int model_default_threads(void)
{
    const char *e = getenv("REFL_THREADS");
    long n;
    if (e && model_parse_int(e, &n) && n >= 1 && n <= 256) return (int)n;
    long c = sysconf(_SC_NPROCESSORS_ONLN);
    return c >= 1 ? (int)(c > 64 ? 64 : c) : 1;
}

double model_now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

typedef struct {
    atomic_int next;
    int n, chunk;
    void (*fn)(void *, int, int, int);
    void *ctx;
} pfor_t;

typedef struct {
    pfor_t *p;
    int thread;
} pfor_arg_t;

static void *pfor_worker(void *arg)
{
    pfor_arg_t *a = arg;
    pfor_t *p = a->p;
    for (;;) {
        int b = atomic_fetch_add(&p->next, p->chunk);
        if (b >= p->n) break;
        int e = b + p->chunk < p->n ? b + p->chunk : p->n;
        p->fn(p->ctx, b, e, a->thread);
    }
    return NULL;
}

void model_parallel_for(int n, int chunk, int nthreads,
                        void (*fn)(void *ctx, int begin, int end, int thread), void *ctx)
{
    if (n <= 0) return;
    if (chunk < 1) chunk = 1;
    if (nthreads <= 1 || n <= chunk) {
        fn(ctx, 0, n, 0);
        return;
    }
    if (nthreads > 64) nthreads = 64;
    pfor_t p = { .n = n, .chunk = chunk, .fn = fn, .ctx = ctx };
    atomic_init(&p.next, 0);
    pthread_t th[64];
    pfor_arg_t args[64];
    int started = 0;
    for (int i = 1; i < nthreads; i++) {
        args[i] = (pfor_arg_t){ &p, i };
        if (pthread_create(&th[i], NULL, pfor_worker, &args[i]) != 0) break;
        started = i;
    }
    args[0] = (pfor_arg_t){ &p, 0 };
    pfor_worker(&args[0]);
    for (int i = 1; i <= started; i++) pthread_join(th[i], NULL);
}

// ---------------------------------------------------------------------------
// Metadata lists

struct model_meta {
    GPtrArray   *kv;     // owned strings: key, value, key, value, ...
    const char **list;   // NULL-terminated view handed to the writers
};

model_meta_t *model_meta_new(void)
{
    model_meta_t *m = g_new0(model_meta_t, 1);
    m->kv = g_ptr_array_new_with_free_func(g_free);
    return m;
}

void model_meta_add(model_meta_t *m, const char *key, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    g_ptr_array_add(m->kv, g_strdup(key));
    g_ptr_array_add(m->kv, g_strdup_vprintf(fmt, ap));
    va_end(ap);
}

const char *const *model_meta_list(model_meta_t *m)
{
    const char **l = g_renew(const char *, m->list, m->kv->len + 1);
    for (guint i = 0; i < m->kv->len; i++) l[i] = g_ptr_array_index(m->kv, i);
    l[m->kv->len] = NULL;
    m->list = l;
    return l;
}

const char *model_meta_get(const model_meta_t *m, const char *key)
{
    for (guint i = 0; i + 1 < m->kv->len; i += 2)
        if (!strcmp(g_ptr_array_index(m->kv, i), key)) return g_ptr_array_index(m->kv, i + 1);
    return NULL;
}

void model_meta_free(model_meta_t *m)
{
    if (!m) return;
    g_ptr_array_free(m->kv, TRUE);
    g_free(m->list);
    g_free(m);
}

// ---------------------------------------------------------------------------
// Provenance helpers

double model_realtime_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void model_utc_text(double t_s, char out[40])
{
    double whole = floor(t_s);
    time_t t = (time_t)whole;
    struct tm tm;
    gmtime_r(&t, &tm);
    size_t n = strftime(out, 40, "%Y-%m-%dT%H:%M:%S", &tm);
    int ms = (int)floor((t_s - whole) * 1000);
    snprintf(out + n, 40 - n, ".%03dZ", ms > 999 ? 999 : ms);
}

static int    whole_argc;
static char **whole_argv;

void model_set_command_line(int argc, char **argv)
{
    whole_argc = argc;
    whole_argv = argv;
}

char *model_command_line(int argc, char **argv)
{
    // argv + argc ends where the whole line ends and starts inside it: a
    // dispatcher's tail, so take the whole line (main's argv[0] is the program).
    if (whole_argv && argv && argc > 0) {
        uintptr_t a = (uintptr_t)argv, lo = (uintptr_t)(whole_argv + 1), end = (uintptr_t)(whole_argv + whole_argc);
        if (a >= lo && a < end && (uintptr_t)(argv + argc) == end) {
            argc = whole_argc - 1;
            argv = whole_argv + 1;
        }
    }
    GString *s = g_string_new("refl");
    for (int i = 0; i < argc; i++) {
        g_string_append_c(s, ' ');
        bool plain = argv[i][0] != 0;
        for (const char *p = argv[i]; *p; p++)
            if (!(g_ascii_isalnum(*p) || strchr("-_./=:,+@%", *p))) plain = false;
        if (plain) {
            g_string_append(s, argv[i]);
        } else {
            gchar *q = g_shell_quote(argv[i]);
            g_string_append(s, q);
            g_free(q);
        }
    }
    return g_string_free(s, FALSE);
}

bool model_solve_linear(double *A, double *b, int n)
{
    for (int c = 0; c < n; c++) {
        int piv = c;
        for (int r = c + 1; r < n; r++)
            if (fabs(A[r * n + c]) > fabs(A[piv * n + c])) piv = r;
        if (!(fabs(A[piv * n + c]) > 1e-300)) return false;
        if (piv != c) {
            for (int k = 0; k < n; k++) {
                double t = A[c * n + k];
                A[c * n + k] = A[piv * n + k];
                A[piv * n + k] = t;
            }
            double t = b[c];
            b[c] = b[piv];
            b[piv] = t;
        }
        for (int r = c + 1; r < n; r++) {
            double f = A[r * n + c] / A[c * n + c];
            for (int k = c; k < n; k++) A[r * n + k] -= f * A[c * n + k];
            b[r] -= f * b[c];
        }
    }
    for (int r = n - 1; r >= 0; r--) {
        double s = b[r];
        for (int k = r + 1; k < n; k++) s -= A[r * n + k] * b[k];
        b[r] = s / A[r * n + r];
    }
    return true;
}

int model_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    if (isnan(x) || isnan(y)) return isnan(x) - isnan(y);
    return x < y ? -1 : x > y;
}

// Hoare's selection on v[lo..hi].
double model_kth(double *v, int n, int k)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        double piv = v[lo + (hi - lo) / 2];
        int i = lo, j = hi;
        while (i <= j) {
            while (v[i] < piv) i++;
            while (v[j] > piv) j--;
            if (i <= j) {
                double t = v[i];
                v[i++] = v[j];
                v[j--] = t;
            }
        }
        if (k <= j) hi = j;
        else if (k >= i) lo = i;
        else return v[k];
    }
    return v[k];
}

void model_sym_eigen(int n, double *A, double *V)
{
    if (V) {
        memset(V, 0, (size_t)n * n * sizeof *V);
        for (int i = 0; i < n; i++) V[i * n + i] = 1;
    }
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = 0, tot = 0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                if (i == j) tot += A[i * n + j] * A[i * n + j];
                else off += A[i * n + j] * A[i * n + j];
            }
        if (off == 0 || off <= 1e-30 * (tot + off)) break;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++) {
                if (A[p * n + q] == 0) continue;
                double th = 0.5 * atan2(2 * A[p * n + q], A[q * n + q] - A[p * n + p]);
                double c = cos(th), sn = sin(th);
                for (int k = 0; k < n; k++) {   // A <- G^T A G, the rotation in the (p, q) plane
                    double a = A[k * n + p], b = A[k * n + q];
                    A[k * n + p] = c * a - sn * b;
                    A[k * n + q] = sn * a + c * b;
                }
                for (int k = 0; k < n; k++) {
                    double a = A[p * n + k], b = A[q * n + k];
                    A[p * n + k] = c * a - sn * b;
                    A[q * n + k] = sn * a + c * b;
                }
                for (int k = 0; V && k < n; k++) {
                    double a = V[k * n + p], b = V[k * n + q];
                    V[k * n + p] = c * a - sn * b;
                    V[k * n + q] = sn * a + c * b;
                }
            }
    }
}

double model_median(double *v, int n)
{
    if (n <= 0) return NAN;
    for (int i = 0; i < n; i++)
        if (isnan(v[i])) {
            qsort(v, (size_t)n, sizeof *v, model_cmp_double);
            return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
        }
    double hi = model_kth(v, n, n / 2);
    if (n % 2) return hi;
    // the largest value below position n/2
    double lo = v[0];
    for (int i = 1; i < n / 2; i++)
        if (v[i] > lo) lo = v[i];
    return 0.5 * (lo + hi);
}


void model_pchip_slopes(const double *x, const double *y, int n, double *d)
{
#define H(k)   (x[(k) + 1] - x[(k)])
#define DEL(k) ((y[(k) + 1] - y[(k)]) / H(k))
    if (n < 2) return;
    if (n == 2) {
        d[0] = d[1] = DEL(0);
        return;
    }
    for (int k = 1; k < n - 1; k++) {
        double w1 = 2 * H(k) + H(k - 1), w2 = H(k) + 2 * H(k - 1), a = DEL(k - 1), b = DEL(k);
        d[k] = a * b > 0 ? (w1 + w2) / (w1 / a + w2 / b) : 0;
    }
    for (int e = 0; e < 2; e++) {   // the ends
        int k0 = e ? n - 2 : 0, k1 = e ? n - 3 : 1, kd = e ? n - 1 : 0;
        double h0 = H(k0), h1 = H(k1), a = DEL(k0), b = DEL(k1);
        double s = ((2 * h0 + h1) * a - h0 * b) / (h0 + h1);
        if (s * a <= 0) s = 0;
        else if (a * b <= 0 && fabs(s) > 3 * fabs(a)) s = 3 * a;
        d[kd] = s;
    }
    for (int k = 0; k < n - 1; k++) {   // Fritsch & Carlson's monotonicity condition
        double del = DEL(k);
        if (del == 0) {   // a flat interval stays flat
            d[k] = d[k + 1] = 0;
            continue;
        }
        double al = d[k] / del, be = d[k + 1] / del, r = al * al + be * be;
        if (r > 9) {
            double tau = 3 / sqrt(r);
            d[k] = tau * al * del;
            d[k + 1] = tau * be * del;
        }
    }
#undef H
#undef DEL
}

double model_pchip_eval(const double *x, const double *y, const double *d, int n, double t, double *slope)
{
    int lo = 0, hi = n - 1;   // x[lo] <= t < x[hi]
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (x[mid] <= t) lo = mid;
        else hi = mid;
    }
    double h = x[hi] - x[lo], u = (t - x[lo]) / h, u2 = u * u, u3 = u2 * u;
    double y0 = y[lo], y1 = y[hi], d0 = d[lo] * h, d1 = d[hi] * h;
    // the cubic Hermite basis and its derivative
    if (slope)
        *slope = ((6 * u2 - 6 * u) * y0 + (3 * u2 - 4 * u + 1) * d0 + (-6 * u2 + 6 * u) * y1 + (3 * u2 - 2 * u) * d1) / h;
    return (2 * u3 - 3 * u2 + 1) * y0 + (u3 - 2 * u2 + u) * d0 + (-2 * u3 + 3 * u2) * y1 + (u3 - u2) * d1;
}
