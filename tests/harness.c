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
    bool alone;              // runs with no other test beside it (TEST_ALONE)
    bool long_;              // a minute or more: started before the others (TEST_LONG)
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
        tests[ntests++] = (test_t){ name, file, fn, only_if, false, false };
}

void test_register_alone(const char *name, test_fn_t fn, const char *file)
{
    test_register_full(name, fn, file, NULL, TEST_FLAG_ALONE);
}

void test_register_long(const char *name, test_fn_t fn, const char *file)
{
    test_register_full(name, fn, file, NULL, TEST_FLAG_LONG);
}

void test_register_full(const char *name, test_fn_t fn, const char *file, bool (*only_if)(void), int flags)
{
    if (ntests < (int)(sizeof tests / sizeof tests[0]))
        tests[ntests++] = (test_t){ name, file, fn, only_if, flags & TEST_FLAG_ALONE, flags & TEST_FLAG_LONG };
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

// REFL_TEST_KEEP=1 keeps every test's directory (its path is printed) to
// look into after the run.
static void tmp_cleanup(const char *dir)
{
    const char *keep = getenv("REFL_TEST_KEEP");
    if (keep && *keep && strcmp(keep, "0")) {
        if (dir[0]) fprintf(stderr, "  (kept %s)\n", dir);
        return;
    }
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

// The process groups of the tests being run, killed with the run when it is
// interrupted.
#define MAX_JOBS 16
static volatile sig_atomic_t child_pgids[MAX_JOBS];

static void on_interrupt(int sig)
{
    for (int i = 0; i < MAX_JOBS; i++)
        if (child_pgids[i] > 0) kill(-child_pgids[i], SIGKILL);
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

// How many tests run at once: $REFL_TEST_JOBS (1 to 16), default 2. Tests
// marked TEST_ALONE run with no other test beside them.
static int jobs(void)
{
    const char *s = getenv("REFL_TEST_JOBS");
    char *end;
    long n = s && *s ? strtol(s, &end, 10) : 0;
    if (s && *s && (*end || n < 1 || n > MAX_JOBS)) {
        fprintf(stderr, "REFL_TEST_JOBS=%s: want a whole number from 1 to %d; running 1 test at a time\n", s,
                MAX_JOBS);
        return 1;
    }
    return n > 0 ? (int)n : 2;
}

// A test being run: its child process, its shared page, and (when several
// run at once) the file that holds what it prints until it has ended.
typedef struct {
    const test_t *t;
    test_result_t *r;
    pid_t pid;           // 0: slot free
    double t0;
    int out_fd;          // -1: the test prints to the runner's own stdout/stderr
    char state_dir[600]; // its $XDG_STATE_HOME ("" to leave it as it is)
} slot_t;

// Start t in a child process (its own process group) filling s->r. Returns
// false, with how set, when it cannot be started. SIGCHLD is blocked here.
static bool start_child(slot_t *s, char *how, size_t how_len)
{
    memset(s->r, 0, sizeof *s->r);
    how[0] = 0;
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) {
        snprintf(how, how_len, "fork: %s", strerror(errno));
        return false;
    }
    if (pid == 0) {
        setpgid(0, 0);
        signal(SIGINT, SIG_DFL);
        signal(SIGTERM, SIG_DFL);
        signal(SIGHUP, SIG_DFL);
        sigset_t none;
        sigemptyset(&none);
        sigprocmask(SIG_SETMASK, &none, NULL);
        int devnull = open("/dev/null", O_RDONLY);
        if (devnull >= 0) dup2(devnull, 0);
        if (s->out_fd >= 0) {
            dup2(s->out_fd, 1);
            dup2(s->out_fd, 2);
            setvbuf(stdout, NULL, _IOLBF, 0);
        }
        // Lamp-state files (rig/lamps/state.c) of tests running side by side
        // never meet, nor touch the user's own.
        if (s->state_dir[0]) setenv("XDG_STATE_HOME", s->state_dir, 1);
        cur = s->r;
        s->t->fn();
        s->r->finished = true;
        exit(0);
    }
    setpgid(pid, pid);
    s->pid = pid;
    s->t0 = model_now_s();
    return true;
}

// The child has ended (not reaped yet, WNOWAIT: the group's id stays the
// child's own until the group is killed in end_child).
static bool child_ended(pid_t pid, char *how, size_t how_len)
{
    siginfo_t info = { 0 };
    int w = waitid(P_PID, pid, &info, WEXITED | WNOHANG | WNOWAIT);
    if (w == 0 && info.si_pid == pid) return true;
    if (w < 0 && errno != EINTR) {
        snprintf(how, how_len, "waitid: %s", strerror(errno));
        return true;
    }
    return false;
}

// End the test's process group (the test itself when timed out, and whatever
// it left running), reap it and say in how what alone fails it.
static void end_child(slot_t *s, bool timed_out, double limit_s, char *how, size_t how_len)
{
    int status = 0;
    kill(-s->pid, SIGKILL);
    waitpid(s->pid, &status, 0);
    s->pid = 0;
    if (how[0]) return;
    test_result_t *r = s->r;
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

// Run one test in a child process, which fills *r, and wait for it. how:
// what fails the test whatever its checks said (a signal, the time-out, an
// exit status), else "".
static void run_child(const test_t *t, test_result_t *r, double limit_s, char *how, size_t how_len)
{
    sigset_t chld, old;
    sigemptyset(&chld);
    sigaddset(&chld, SIGCHLD);
    sigprocmask(SIG_BLOCK, &chld, &old);
    slot_t s = { .t = t, .r = r, .out_fd = -1 };
    if (!start_child(&s, how, how_len)) {
        sigprocmask(SIG_SETMASK, &old, NULL);
        return;
    }
    child_pgids[0] = s.pid;
    bool timed_out = false;
    while (!child_ended(s.pid, how, how_len)) {
        double left = limit_s - (model_now_s() - s.t0);
        if (left <= 0) {
            timed_out = true;
            break;
        }
        if (left > 1) left = 1;
        struct timespec ts = { (time_t)left, (long)((left - (time_t)left) * 1e9) };
        sigtimedwait(&chld, NULL, &ts);
    }
    end_child(&s, timed_out, limit_s, how, how_len);
    child_pgids[0] = 0;
    sigprocmask(SIG_SETMASK, &old, NULL);
}

void test_run_isolated(test_fn_t fn, double limit_s, test_outcome_t *out)
{
    test_result_t *r = mmap(NULL, sizeof *r, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    memset(out, 0, sizeof *out);
    if (r == MAP_FAILED) {
        snprintf(out->how, sizeof out->how, "mmap: %s", strerror(errno));
        return;
    }
    const test_t t = { "isolated", __FILE__, fn, NULL, false, false };
    run_child(&t, r, limit_s, out->how, sizeof out->how);
    tmp_cleanup(r->tmpdir);
    out->failures = r->failures;
    out->skipped = r->skipped;
    snprintf(out->reason, sizeof out->reason, "%s", r->reason);
    snprintf(out->tmpdir, sizeof out->tmpdir, "%s", r->tmpdir);
    munmap(r, sizeof *r);
}

// Print what a test printed (when it ran beside others) and its result line;
// count it.
static void report(slot_t *s, const char *how, double dt, int *passed, int *failed, int *skipped)
{
    if (s->out_fd >= 0) {
        char buf[8192];
        ssize_t n;
        fflush(stdout);
        lseek(s->out_fd, 0, SEEK_SET);
        while ((n = read(s->out_fd, buf, sizeof buf)) > 0)
            if (fwrite(buf, 1, (size_t)n, stderr) != (size_t)n) break;
        fflush(stderr);
        if (ftruncate(s->out_fd, 0) != 0 || lseek(s->out_fd, 0, SEEK_SET) != 0) {
            close(s->out_fd);   // what the next test prints goes to the runner's own output
            s->out_fd = -1;
        }
    }
    const test_t *t = s->t;
    test_result_t *r = s->r;
    if (r->failures || how[0]) {
        (*failed)++;
        if (how[0] && r->failures)
            printf("FAIL %s (%s, %s after %d failed check%s, %.2f s)\n", t->name, t->file, how, r->failures,
                   r->failures == 1 ? "" : "s", dt);
        else if (how[0])
            printf("FAIL %s (%s, %s, %.2f s)\n", t->name, t->file, how, dt);
        else
            printf("FAIL %s (%s, %.2f s)\n", t->name, t->file, dt);
    } else if (r->skipped) {
        (*skipped)++;
        printf("skip %s (%s, %.2f s)\n", t->name, r->reason, dt);
    } else {
        (*passed)++;
        printf("ok   %s (%.2f s)\n", t->name, dt);
    }
    fflush(stdout);
}

// Which tests run by their length: $REFL_TEST_SET = short (all but the
// TEST_LONG ones: make check), long (only those: make check-long) or all (the
// default). 0 all, 1 short, 2 long; -1: not one of these (said).
static int test_set(void)
{
    const char *s = getenv("REFL_TEST_SET");
    if (!s || !*s || !strcmp(s, "all")) return 0;
    if (!strcmp(s, "short")) return 1;
    if (!strcmp(s, "long")) return 2;
    fprintf(stderr, "REFL_TEST_SET=%s: want short, long or all\n", s);
    return -1;
}

int main(int argc, char **argv)
{
    const char *filter = argc > 1 ? argv[1] : NULL;
    int passed = 0, failed = 0, skipped = 0, inner = 0, other_set = 0;
    double limit_s = timeout_s();
    int njobs = jobs(), set = test_set();
    if (set < 0) return 2;
    model_error_quiet(true);

    // The tests to run, in order.
    static const test_t *todo[1024];
    int ntodo = 0;
    for (int i = 0; i < ntests; i++) {
        if (filter && !strstr(tests[i].name, filter) && !strstr(tests[i].file, filter)) continue;
        if (tests[i].only_if && !tests[i].only_if()) {
            inner++;
            continue;
        }
        if ((set == 1 && tests[i].long_) || (set == 2 && !tests[i].long_)) {
            other_set++;
            continue;
        }
        todo[ntodo++] = &tests[i];
    }
    if (njobs > ntodo) njobs = ntodo > 0 ? ntodo : 1;

    // The run's own directory: each slot's $XDG_STATE_HOME below it.
    char rundir[512] = "";
    const char *base = getenv("TMPDIR");
    snprintf(rundir, sizeof rundir, "%s/refl-tests-XXXXXX", base && *base ? base : "/tmp");
    if (!mkdtemp(rundir)) {
        perror(rundir);
        return 2;
    }
    slot_t slots[MAX_JOBS];
    memset(slots, 0, sizeof slots);
    for (int j = 0; j < njobs; j++) {
        slots[j].r = mmap(NULL, sizeof *slots[j].r, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
        if (slots[j].r == MAP_FAILED) {
            perror("mmap");
            return 2;
        }
        slots[j].out_fd = njobs > 1 ? memfd_create("refl-test-output", MFD_CLOEXEC) : -1;
        snprintf(slots[j].state_dir, sizeof slots[j].state_dir, "%s/state-%d", rundir, j);
    }
    struct sigaction sa = { .sa_handler = on_interrupt };
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    sigset_t chld, old;
    sigemptyset(&chld);
    sigaddset(&chld, SIGCHLD);
    sigprocmask(SIG_BLOCK, &chld, &old);
    if (njobs > 1)
        printf("(%d tests, %d at a time; what a test prints follows it when it has ended)\n", ntodo, njobs);
    fflush(stdout);

    double t_all = model_now_s();
    struct { const char *name; double dt; } slow[6] = { { 0 } };
    bool started[1024] = { false };
    int next = 0, running = 0, alone_running = 0;
    while (next < ntodo || running > 0) {
        // Start what may start: the first tests not started, in order; a
        // TEST_ALONE test only when nothing runs, and nothing beside it.
        for (int j = 0; j < njobs && !alone_running; j++) {
            if (slots[j].pid) continue;
            // the long tests first (in order), so that the short ones fill in beside them
            int pick = -1;
            for (int i = next; i < ntodo && pick < 0; i++)
                if (!started[i] && todo[i]->long_) pick = i;
            for (int i = next; i < ntodo && pick < 0; i++)
                if (!started[i] && (!todo[i]->alone || running == 0)) pick = i;
            if (pick < 0) break;
            started[pick] = true;
            while (next < ntodo && started[next]) next++;
            slots[j].t = todo[pick];
            char how[256];
            if (!start_child(&slots[j], how, sizeof how)) {
                report(&slots[j], how, 0, &passed, &failed, &skipped);
                continue;
            }
            child_pgids[j] = slots[j].pid;
            running++;
            if (todo[pick]->alone) alone_running = 1;
        }
        // Wait for one to end (or a second to pass).
        struct timespec ts = { 1, 0 };
        sigtimedwait(&chld, NULL, &ts);
        for (int j = 0; j < njobs; j++) {
            if (!slots[j].pid) continue;
            char how[256] = "";
            double dt = model_now_s() - slots[j].t0;
            bool ended = child_ended(slots[j].pid, how, sizeof how);
            if (!ended && dt < limit_s) continue;
            end_child(&slots[j], !ended, limit_s, how, sizeof how);
            child_pgids[j] = 0;
            tmp_cleanup(slots[j].r->tmpdir);
            tmp_cleanup(slots[j].state_dir);
            running--;
            if (slots[j].t->alone) alone_running = 0;
            report(&slots[j], how, dt, &passed, &failed, &skipped);
            // the slowest five, for the time budget (README: tests)
            for (int k = 0; k < 5; k++)
                if (!slow[k].name || dt > slow[k].dt) {
                    memmove(&slow[k + 1], &slow[k], (size_t)(4 - k) * sizeof slow[0]);
                    slow[k].name = slots[j].t->name, slow[k].dt = dt;
                    break;
                }
        }
    }
    sigprocmask(SIG_SETMASK, &old, NULL);
    tmp_cleanup(rundir);
    if (inner) printf("(%d tests run only inside the test that hosts them)\n", inner);
    if (other_set)
        printf(set == 1 ? "(%d long tests left to make check-long)\n" : "(%d short tests left to make check)\n",
               other_set);
    if (slow[0].name) {
        printf("(slowest:");
        for (int k = 0; k < 5 && slow[k].name; k++) printf("%s %s %.0f s", k ? "," : "", slow[k].name, slow[k].dt);
        printf(")\n");
    }
    printf("(%.1f s)\n%d passed, %d failed", model_now_s() - t_all, passed, failed);
    if (skipped) printf(", %d skipped", skipped);
    printf("\n");
    return failed ? 1 : 0;
}
