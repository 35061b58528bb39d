// tests/harness.c — the runner behind tests/test.h.
//
// Each test runs in its own child process (fork), in a process group of its
// own: a crash, an abort or a signal fails that test, with the signal named,
// and not the run; a test still running after $REFL_TEST_TIMEOUT seconds
// (default 600) is killed with its group and fails. The child reports its
// failed checks, a skip and its reason, and its temporary directory through a
// shared page; the parent removes the directory after the child has ended.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <glib.h>
#include <sys/file.h>
#include <sys/mman.h>
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
    bool (*only_if)(void);   // NULL: always
} test_t;

static test_t tests[1024];
static int ntests;

// What the child running a test tells the parent (a shared anonymous page).
typedef struct {
    int failures;
    bool finished;       // the test function returned (or skipped)
    bool skipped;
    char reason[512];    // of the skip
    char tmpdir[512];    // made by test_tmpdir(), removed by the parent
} test_result_t;

static test_result_t *cur;
static char tmpdir[512];

void test_register(const char *name, test_fn_t fn, const char *file)
{
    test_register_inner(name, fn, file, NULL);
}

void test_register_inner(const char *name, test_fn_t fn, const char *file, bool (*only_if)(void))
{
    if (ntests < (int)(sizeof tests / sizeof tests[0]))
        tests[ntests++] = (test_t){ name, file, fn, only_if };
}

void test_fail(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "  %s:%d: ", file, line);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    __atomic_add_fetch(&cur->failures, 1, __ATOMIC_SEQ_CST);
}

void test_skip(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cur->reason, sizeof cur->reason, fmt, ap);
    va_end(ap);
    cur->skipped = true;
    cur->finished = true;
    exit(0);
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
        snprintf(cur->tmpdir, sizeof cur->tmpdir, "%s", tmpdir);
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

static void tmp_cleanup(const char *dir)
{
    if (dir[0]) nftw(dir, rm_cb, 16, FTW_DEPTH | FTW_PHYS);
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

// The test being run by the parent: its process group, killed with it when
// the run is interrupted.
static volatile sig_atomic_t child_pgid;

static void on_interrupt(int sig)
{
    if (child_pgid > 0) kill(-child_pgid, SIGKILL);
    signal(sig, SIG_DFL);
    raise(sig);
}

static double timeout_s(void)
{
    const char *s = getenv("REFL_TEST_TIMEOUT");
    char *end;
    double t = s && *s ? strtod(s, &end) : 0;
    return s && *s && *end == 0 && t > 0 ? t : 600;
}

// Run one test in a child process, which fills *r. how: what fails the test
// whatever its checks said (a signal, the time-out, an exit status), else "".
static void run_child(const test_t *t, test_result_t *r, double limit_s, char *how, size_t how_len)
{
    memset(r, 0, sizeof *r);
    how[0] = 0;
    fflush(NULL);
    sigset_t chld, old;
    sigemptyset(&chld);
    sigaddset(&chld, SIGCHLD);
    sigprocmask(SIG_BLOCK, &chld, &old);
    pid_t pid = fork();
    if (pid < 0) {
        snprintf(how, how_len, "fork: %s", strerror(errno));
        sigprocmask(SIG_SETMASK, &old, NULL);
        return;
    }
    if (pid == 0) {
        setpgid(0, 0);
        signal(SIGINT, SIG_DFL);
        signal(SIGTERM, SIG_DFL);
        signal(SIGHUP, SIG_DFL);
        sigprocmask(SIG_SETMASK, &old, NULL);
        int devnull = open("/dev/null", O_RDONLY);
        if (devnull >= 0) dup2(devnull, 0);
        cur = r;
        t->fn();
        r->finished = true;
        exit(0);
    }
    setpgid(pid, pid);
    child_pgid = pid;
    double t0 = model_now_s();
    int status = 0;
    bool timed_out = false;
    for (;;) {
        // Not reaped yet (WNOWAIT): the group's id stays the child's own
        // until the group is killed below.
        siginfo_t info = { 0 };
        int w = waitid(P_PID, pid, &info, WEXITED | WNOHANG | WNOWAIT);
        if (w == 0 && info.si_pid == pid) break;
        if (w < 0 && errno != EINTR) {
            snprintf(how, how_len, "waitid: %s", strerror(errno));
            break;
        }
        double left = limit_s - (model_now_s() - t0);
        if (left <= 0) {
            timed_out = true;
            break;
        }
        if (left > 1) left = 1;
        struct timespec ts = { (time_t)left, (long)((left - (time_t)left) * 1e9) };
        sigtimedwait(&chld, NULL, &ts);
    }
    // The test, when timed out, and whatever it left running in its group end here.
    kill(-pid, SIGKILL);
    waitpid(pid, &status, 0);
    child_pgid = 0;
    sigprocmask(SIG_SETMASK, &old, NULL);
    if (how[0])
        return;
    if (timed_out)
        snprintf(how, how_len, "timed out after %g s", limit_s);
    else if (WIFSIGNALED(status)) {
        int sig = WTERMSIG(status);
        const char *abbrev = sigabbrev_np(sig);
        snprintf(how, how_len, "killed by signal SIG%s (%s)%s", abbrev ? abbrev : "?", strsignal(sig),
                 WCOREDUMP(status) ? ", core dumped" : "");
    } else if (WIFEXITED(status) && WEXITSTATUS(status) != 0)
        snprintf(how, how_len, "exited with status %d%s", WEXITSTATUS(status),
                 r->finished ? "" : " before the test ended");
    else if (!r->finished)
        snprintf(how, how_len, "exited before the test ended");
}

void test_run_isolated(test_fn_t fn, double limit_s, test_outcome_t *out)
{
    test_result_t *r = mmap(NULL, sizeof *r, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    memset(out, 0, sizeof *out);
    if (r == MAP_FAILED) {
        snprintf(out->how, sizeof out->how, "mmap: %s", strerror(errno));
        return;
    }
    const test_t t = { "isolated", __FILE__, fn, NULL };
    run_child(&t, r, limit_s, out->how, sizeof out->how);
    tmp_cleanup(r->tmpdir);
    out->failures = r->failures;
    out->skipped = r->skipped;
    snprintf(out->reason, sizeof out->reason, "%s", r->reason);
    snprintf(out->tmpdir, sizeof out->tmpdir, "%s", r->tmpdir);
    munmap(r, sizeof *r);
}

int main(int argc, char **argv)
{
    const char *filter = argc > 1 ? argv[1] : NULL;
    int passed = 0, failed = 0, skipped = 0, inner = 0;
    double limit_s = timeout_s();
    model_error_quiet(true);
    test_result_t *r = mmap(NULL, sizeof *r, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    if (r == MAP_FAILED) {
        perror("mmap");
        return 2;
    }
    struct sigaction sa = { .sa_handler = on_interrupt };
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    double t_all = model_now_s();
    for (int i = 0; i < ntests; i++) {
        if (filter && !strstr(tests[i].name, filter) && !strstr(tests[i].file, filter)) continue;
        if (tests[i].only_if && !tests[i].only_if()) {
            inner++;
            continue;
        }
        char how[256];
        double t0 = model_now_s();
        run_child(&tests[i], r, limit_s, how, sizeof how);
        tmp_cleanup(r->tmpdir);
        double dt = model_now_s() - t0;
        if (r->failures || how[0]) {
            failed++;
            if (how[0] && r->failures)
                printf("FAIL %s (%s, %s after %d failed check%s, %.2f s)\n", tests[i].name, tests[i].file, how,
                       r->failures, r->failures == 1 ? "" : "s", dt);
            else if (how[0])
                printf("FAIL %s (%s, %s, %.2f s)\n", tests[i].name, tests[i].file, how, dt);
            else
                printf("FAIL %s (%s, %.2f s)\n", tests[i].name, tests[i].file, dt);
        } else if (r->skipped) {
            skipped++;
            printf("skip %s (%s, %.2f s)\n", tests[i].name, r->reason, dt);
        } else {
            passed++;
            printf("ok   %s (%.2f s)\n", tests[i].name, dt);
        }
        fflush(stdout);
    }
    if (inner) printf("(%d tests run only inside the test that hosts them)\n", inner);
    printf("(%.1f s)\n%d passed, %d failed", model_now_s() - t_all, passed, failed);
    if (skipped) printf(", %d skipped", skipped);
    printf("\n");
    return failed ? 1 : 0;
}
