// tests/enospc_shim.c — a full disk for LD_PRELOAD, where the test machine
// cannot mount a small tmpfs: writes to files under $REFL_ENOSPC_DIR share a
// budget of $REFL_ENOSPC_BYTES bytes; once it is spent they fail with ENOSPC,
// as a full file system does (a write that does not fit writes what fits).
// Covers the calls refl's writers reach through the PLT: fwrite (libpng and
// refl's own stdio), write/pwrite/pwrite64 (SQLite, plain files). Only for
// tests (tests/test_rig_capture.c); the product is unchanged.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static long long budget = -1;   // -1: not read yet
static char dir[PATH_MAX];
static size_t dirlen;

static void init(void)
{
    if (budget != -1) return;
    const char *d = getenv("REFL_ENOSPC_DIR"), *b = getenv("REFL_ENOSPC_BYTES");
    budget = b ? atoll(b) : 0;
    if (d && realpath(d, dir)) dirlen = strlen(dir);
    else dirlen = 0;
}

// How many of n bytes to fd may be written (0: none; sets errno).
static size_t allow(int fd, size_t n)
{
    char link[64], path[PATH_MAX];
    snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    ssize_t k = readlink(link, path, sizeof path - 1);
    if (k <= 0) return n;
    path[k] = 0;
    pthread_mutex_lock(&lock);
    init();
    size_t ok = n;
    if (dirlen && !strncmp(path, dir, dirlen) && (path[dirlen] == '/' || path[dirlen] == 0)) {
        ok = budget <= 0 ? 0 : (size_t)budget < n ? (size_t)budget : n;
        budget -= (long long)ok;
    }
    pthread_mutex_unlock(&lock);
    return ok;
}

typedef size_t (*fwrite_fn)(const void *, size_t, size_t, FILE *);
typedef ssize_t (*write_fn)(int, const void *, size_t);
typedef ssize_t (*pwrite_fn)(int, const void *, size_t, off_t);
#define REAL(name, type) static type real_##name; if (!real_##name) real_##name = (type)dlsym(RTLD_NEXT, #name)

size_t fwrite(const void *p, size_t size, size_t nmemb, FILE *f)
{
    REAL(fwrite, fwrite_fn);
    if (!size || !nmemb) return real_fwrite(p, size, nmemb, f);
    size_t want = size * nmemb, ok = allow(fileno(f), want);
    if (ok == want) return real_fwrite(p, size, nmemb, f);
    size_t items = ok / size;
    if (items) real_fwrite(p, size, items, f);
    errno = ENOSPC;
    return items;
}

ssize_t write(int fd, const void *p, size_t n)
{
    REAL(write, write_fn);
    size_t ok = n ? allow(fd, n) : 0;
    if (n && !ok) {
        errno = ENOSPC;
        return -1;
    }
    return real_write(fd, p, n ? ok : 0);
}

ssize_t pwrite(int fd, const void *p, size_t n, off_t off)
{
    REAL(pwrite, pwrite_fn);
    size_t ok = n ? allow(fd, n) : 0;
    if (n && !ok) {
        errno = ENOSPC;
        return -1;
    }
    return real_pwrite(fd, p, n ? ok : 0, off);
}

ssize_t pwrite64(int fd, const void *p, size_t n, off_t off)
{
    REAL(pwrite64, pwrite_fn);
    size_t ok = n ? allow(fd, n) : 0;
    if (n && !ok) {
        errno = ENOSPC;
        return -1;
    }
    return real_pwrite64(fd, p, n ? ok : 0, off);
}

// Removing a file under the directory gives its space back, as on a real file
// system (the writer removes a half-written frame; the journal then records
// the fault in the space that frees).
typedef int (*unlink_fn)(const char *);
int unlink(const char *path)
{
    REAL(unlink, unlink_fn);
    char full[PATH_MAX];
    struct stat st;
    long long give = 0;
    pthread_mutex_lock(&lock);
    init();
    if (dirlen && realpath(path, full) && !strncmp(full, dir, dirlen) && full[dirlen] == '/' && stat(full, &st) == 0 &&
        S_ISREG(st.st_mode) && st.st_nlink == 1)
        give = (long long)st.st_size;
    pthread_mutex_unlock(&lock);
    int r = real_unlink(path);
    if (r == 0 && give) {
        pthread_mutex_lock(&lock);
        budget += give;
        pthread_mutex_unlock(&lock);
    }
    return r;
}
