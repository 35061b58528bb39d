// tests/harness.c — the runner behind tests/test.h.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <glib.h>
#include <sys/file.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "tests/test.h"

typedef struct {
    const char *name, *file;
    test_fn_t fn;
} test_t;

static test_t tests[1024];
static int ntests;
static int cur_failures;
static char tmpdir[512];

void test_register(const char *name, test_fn_t fn, const char *file)
{
    if (ntests < (int)(sizeof tests / sizeof tests[0]))
        tests[ntests++] = (test_t){ name, file, fn };
}

void test_fail(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "  %s:%d: ", file, line);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    cur_failures++;
}

const char *test_tmpdir(void)
{
    if (!tmpdir[0]) {
        const char *base = getenv("TMPDIR");
        snprintf(tmpdir, sizeof tmpdir, "%s/refl-test-XXXXXX", base && *base ? base : "/tmp");
        if (!mkdtemp(tmpdir)) {
            perror("mkdtemp");
            exit(2);
        }
    }
    return tmpdir;
}

const char *test_path(const char *name)
{
    static char bufs[8][1024];
    static int slot;
    char *b = bufs[slot++ % 8];
    snprintf(b, 1024, "%s/%s", test_tmpdir(), name);
    return b;
}

const char *test_write(const char *name, const char *text)
{
    const char *p = test_path(name);
    FILE *f = fopen(p, "wb");
    if (!f) {
        perror(p);
        exit(2);
    }
    fputs(text, f);
    fclose(f);
    return p;
}

const char *test_srcdir(void)
{
    const char *s = getenv("REFL_SRCDIR");
    return s && *s ? s : ".";
}

const char *test_refl(void)
{
    const char *s = getenv("REFL");
    return s && *s ? s : "bin/refl";
}

static int rm_cb(const char *p, const struct stat *sb, int flag, struct FTW *ftw)
{
    (void)sb; (void)flag; (void)ftw;
    return remove(p);
}

static void tmp_cleanup(void)
{
    if (tmpdir[0]) {
        nftw(tmpdir, rm_cb, 16, FTW_DEPTH | FTW_PHYS);
        tmpdir[0] = 0;
    }
}

static void append(char **buf, size_t *len, const char *data, size_t n)
{
    char *nb = realloc(*buf, *len + n + 1);
    if (!nb) return;
    memcpy(nb + *len, data, n);
    *len += n;
    nb[*len] = 0;
    *buf = nb;
}

int test_run(const char *const *argv, double timeout_s, char **out, char **err)
{
    int po[2], pe[2];
    if (pipe2(po, O_CLOEXEC) || pipe2(pe, O_CLOEXEC)) return -1;
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        dup2(po[1], 1);
        dup2(pe[1], 2);
        int devnull = open("/dev/null", O_RDONLY);
        if (devnull >= 0) dup2(devnull, 0);
        execvp(argv[0], (char *const *)argv);
        fprintf(stderr, "exec %s: %s\n", argv[0], strerror(errno));
        _exit(127);
    }
    close(po[1]);
    close(pe[1]);
    char *ob = calloc(1, 1), *eb = calloc(1, 1);
    size_t ol = 0, el = 0;
    struct pollfd fds[2] = { { po[0], POLLIN, 0 }, { pe[0], POLLIN, 0 } };
    int open_fds = 2;
    double t0 = model_now_s();
    bool timed_out = false;
    while (open_fds > 0) {
        int left_ms = (int)((timeout_s - (model_now_s() - t0)) * 1000);
        if (left_ms <= 0) {
            timed_out = true;
            kill(pid, SIGKILL);
            break;
        }
        if (poll(fds, 2, left_ms) < 0 && errno != EINTR) break;
        for (int i = 0; i < 2; i++) {
            if (fds[i].fd >= 0 && (fds[i].revents & (POLLIN | POLLHUP | POLLERR))) {
                char buf[4096];
                ssize_t n = read(fds[i].fd, buf, sizeof buf);
                if (n <= 0) {
                    close(fds[i].fd);
                    fds[i].fd = -1;
                    open_fds--;
                } else if (i == 0)
                    append(&ob, &ol, buf, n);
                else
                    append(&eb, &el, buf, n);
            }
        }
    }
    for (int i = 0; i < 2; i++)
        if (fds[i].fd >= 0) close(fds[i].fd);
    int status = 0;
    waitpid(pid, &status, 0);
    if (out) *out = ob; else free(ob);
    if (err) *err = eb; else free(eb);
    if (timed_out) return 124;
    if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
    return WEXITSTATUS(status);
}

int test_refl_run(double timeout_s, char **out, char **err, ...)
{
    const char *argv[64];
    int n = 0;
    argv[n++] = test_refl();
    va_list ap;
    va_start(ap, err);
    const char *a;
    while ((a = va_arg(ap, const char *)) && n < 63) argv[n++] = a;
    va_end(ap);
    argv[n] = NULL;
    return test_run(argv, timeout_s, out, err);
}

int test_camera_lock(void)
{
    char path[512];
    snprintf(path, sizeof path, "%s/refl-test-camera-aravis.lock", g_get_tmp_dir());
    int fd = open(path, O_RDONLY | O_CREAT | O_CLOEXEC, 0666);
    for (int i = 0; fd >= 0 && i < 6000; i++) {
        if (flock(fd, LOCK_EX | LOCK_NB) == 0) return fd;
        usleep(50000);
    }
    if (fd >= 0) close(fd);
    test_fail(__FILE__, __LINE__, "cannot lock %s (another test run holds the virtual camera's address)", path);
    return -1;
}

void test_camera_unlock(int fd)
{
    if (fd >= 0) close(fd);
}

int main(int argc, char **argv)
{
    const char *filter = argc > 1 ? argv[1] : NULL;
    int passed = 0, failed = 0;
    model_error_quiet(true);
    double t_all = model_now_s();
    for (int i = 0; i < ntests; i++) {
        if (filter && !strstr(tests[i].name, filter) && !strstr(tests[i].file, filter)) continue;
        cur_failures = 0;
        double t0 = model_now_s();
        tests[i].fn();
        tmp_cleanup();
        double dt = model_now_s() - t0;
        if (cur_failures) {
            failed++;
            printf("FAIL %s (%s, %.2f s)\n", tests[i].name, tests[i].file, dt);
        } else {
            passed++;
            printf("ok   %s (%.2f s)\n", tests[i].name, dt);
        }
        fflush(stdout);
    }
    printf("(%.1f s)\n%d passed, %d failed\n", model_now_s() - t_all, passed, failed);
    return failed ? 1 : 0;
}
