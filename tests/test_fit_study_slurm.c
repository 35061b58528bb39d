// tests/test_fit_study_slurm.c — scripts/study-slurm on a real Slurm: a
// single-node cluster of its own (munged, slurmctld, slurmd on 127.0.0.1)
// runs the detection study's job array and its merge job.
//
// The cluster lives in the test's temporary directory: a munge key and socket,
// a generated slurm.conf (ports found free on 127.0.0.1, state, spool, logs and
// pid files in the directory), slurmctld and slurmd in the foreground as the
// test's children (they die with the test: PR_SET_PDEATHSIG; the test is the
// subreaper of what they detach). Slurm's plugins that need systemd or cgroups
// are replaced by ones that do not (proctrack/linuxproc, task/none, no
// accounting; tests/README.md). Every
// daemon is stopped by its pid when the test ends, passed or failed, after the
// cluster's jobs are cancelled and gone. Skipped, with the reason, when not
// root (slurmd starts each job as its user) or when a daemon refuses to start.
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <glib.h>
#include <jansson.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/random.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "model/model.h"
#include "tests/test.h"

#define NODE "refl1"
#define PARTITION "refl"

typedef struct {
    char dir[512];     // the cluster's directory
    char conf[600];    // its slurm.conf
    char sock[600];    // munged's socket
    pid_t munged, ctld, slurmd;
    int ctld_port, slurmd_port;
} cluster_t;

static char *slurp(const char *path)
{
    char *t = NULL;
    g_file_get_contents(path, &t, NULL, NULL);
    return t;
}

// The last n lines of a file (g_free), or "(no PATH)".
static char *tail_lines(const char *path, int n)
{
    char *t = slurp(path);
    if (!t) return g_strdup_printf("(no %s)", path);
    size_t len = strlen(t);
    while (len && t[len - 1] == '\n') t[--len] = 0;
    char *p = t + len;
    for (int k = 0; k < n && p > t;) k += *--p == '\n';
    char *r = g_strdup(p + (*p == '\n'));
    g_free(t);
    return r;
}

// A TCP port free on 127.0.0.1 now (the kernel's choice), or -1.
static int free_port(void)
{
    int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
    socklen_t len = sizeof a;
    int port = -1;
    if (fd >= 0 && bind(fd, (struct sockaddr *)&a, sizeof a) == 0 && getsockname(fd, (struct sockaddr *)&a, &len) == 0)
        port = ntohs(a.sin_port);
    if (fd >= 0) close(fd);
    return port;
}

static bool port_answers(int port)
{
    int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
                             .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
    bool ok = fd >= 0 && connect(fd, (struct sockaddr *)&a, sizeof a) == 0;
    if (fd >= 0) close(fd);
    return ok;
}

// argv[0] (a full path) in the background, its output to log; it gets SIGTERM
// when this test's process ends.
static pid_t spawn(const char *const *argv, const char *log)
{
    pid_t parent = getpid(), pid = fork();
    if (pid != 0) return pid;
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(127);
    int fd = open(log, O_WRONLY | O_CREAT | O_APPEND, 0644), in = open("/dev/null", O_RDONLY);
    if (fd >= 0) dup2(fd, 1), dup2(fd, 2);
    if (in >= 0) dup2(in, 0);
    execv(argv[0], (char *const *)argv);
    fprintf(stderr, "exec %s: %s\n", argv[0], strerror(errno));
    _exit(127);
}

// true once pid has exited (reaped), waiting up to s seconds.
static bool reaped(pid_t pid, double s)
{
    double t0 = model_now_s();
    do {
        int st;
        pid_t r = waitpid(pid, &st, WNOHANG);
        if (r == pid || (r < 0 && errno == ECHILD)) return true;
        usleep(50000);
    } while (model_now_s() - t0 < s);
    return false;
}

// Stop a daemon this test started: SIGTERM, then SIGKILL after 20 s.
static void stop(pid_t *pid)
{
    if (*pid <= 0) return;
    kill(*pid, SIGTERM);
    if (!reaped(*pid, 20)) {
        kill(*pid, SIGKILL);
        reaped(*pid, 10);
    }
    *pid = 0;
}

// The TCP sockets pid listens on: how many, or -1 with *where set when one is
// bound to an address other than 127.0.0.1 or ::1.
static int loopback_listeners(pid_t pid, char *where, size_t len)
{
    char fdd[64], link[600], target[256];
    unsigned long ino[512];
    int nino = 0, n = 0;
    snprintf(fdd, sizeof fdd, "/proc/%d/fd", (int)pid);
    DIR *d = opendir(fdd);
    for (struct dirent *e; d && (e = readdir(d)) && nino < 512;) {
        snprintf(link, sizeof link, "%s/%s", fdd, e->d_name);
        ssize_t k = readlink(link, target, sizeof target - 1);
        if (k > 0 && (target[k] = 0, sscanf(target, "socket:[%lu]", &ino[nino]) == 1)) nino++;
    }
    if (d) closedir(d);
    static const char *const tables[2] = { "/proc/net/tcp", "/proc/net/tcp6" };
    for (int t = 0; t < 2; t++) {
        FILE *f = fopen(tables[t], "r");
        char line[512], addr[64];
        unsigned port, state;
        unsigned long inode;
        while (f && fgets(line, sizeof line, f))
            if (sscanf(line, " %*d: %63[0-9A-Fa-f]:%x %*[0-9A-Fa-f]:%*x %x %*x:%*x %*x:%*x %*x %*d %*d %lu", addr,
                       &port, &state, &inode) == 4 && state == 0x0A)
                for (int i = 0; i < nino; i++) {
                    if (ino[i] != inode) continue;
                    if (strcmp(addr, "0100007F") && strcmp(addr, "00000000000000000000000001000000")) {
                        snprintf(where, len, "%s port %u (address %s in %s)", fdd, port, addr, tables[t]);
                        if (f) fclose(f);
                        return -1;
                    }
                    n++;
                }
        if (f) fclose(f);
    }
    return n;
}

// slurm.conf for this cluster: one controller and one node on 127.0.0.1, the
// ports given, everything else in c->dir; plugins that need neither systemd
// nor cgroups.
static void write_conf(const cluster_t *c)
{
    int cpus = (int)sysconf(_SC_NPROCESSORS_ONLN);
    char *text = g_strdup_printf(
        "ClusterName=refltest\n"
        "SlurmctldHost=localhost(127.0.0.1)\n"
        "SlurmctldPort=%d\nSlurmdPort=%d\n"
        "CommunicationParameters=NoCtldInAddrAny,NoInAddrAny\n"
        "AuthType=auth/munge\nCredType=cred/munge\nAuthInfo=socket=%s\n"
        "SlurmUser=root\nSlurmdUser=root\n"
        "StateSaveLocation=%s/state\nSlurmdSpoolDir=%s/spool\n"
        "SlurmctldPidFile=%s/slurmctld.pid\nSlurmdPidFile=%s/slurmd.pid\n"
        "SlurmctldLogFile=%s/slurmctld.log\nSlurmdLogFile=%s/slurmd.log\n"
        "ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nJobAcctGatherType=jobacct_gather/none\n"
        "AccountingStorageType=accounting_storage/none\nJobCompType=jobcomp/none\nSwitchType=switch/none\n"
        "MpiDefault=none\nMailProg=/bin/true\nReturnToService=2\nMinJobAge=600\n"
        "SelectType=select/cons_tres\nSelectTypeParameters=CR_CPU\nSlurmdParameters=config_overrides\n"
        "NodeName=" NODE " NodeAddr=127.0.0.1 NodeHostname=localhost CPUs=%d State=UNKNOWN\n"
        "PartitionName=" PARTITION " Nodes=" NODE " Default=YES MaxTime=INFINITE State=UP\n",
        c->ctld_port, c->slurmd_port, c->sock, c->dir, c->dir, c->dir, c->dir, c->dir, c->dir, cpus < 2 ? 2 : cpus);
    CHECK(g_file_set_contents(c->conf, text, -1, NULL));
    g_free(text);
}

// The node's state as sinfo gives it ("idle", ...; g_free), or NULL.
static char *node_state(void)
{
    char *out = NULL;
    int rc = test_run((const char *const[]){ "sinfo", "-h", "-n", NODE, "-o", "%T", NULL }, 20, &out, NULL);
    if (rc != 0) {
        g_free(out);
        return NULL;
    }
    return g_strstrip(out);
}

// munged on its own key and socket in c->dir. NULL, or why it did not start.
static const char *munged_up(cluster_t *c, char *why, size_t len)
{
    char key[600], log[600], pid[600], seed[600];
    snprintf(key, sizeof key, "%s/munge.key", c->dir);
    snprintf(log, sizeof log, "%s/munged.log", c->dir);
    snprintf(pid, sizeof pid, "%s/munged.pid", c->dir);
    snprintf(seed, sizeof seed, "%s/munged.seed", c->dir);
    unsigned char k[1024];
    size_t got = 0;
    for (ssize_t r; got < sizeof k && (r = getrandom(k + got, sizeof k - got, 0)) > 0;) got += (size_t)r;
    int fd = got == sizeof k ? open(key, O_WRONLY | O_CREAT | O_EXCL, 0400) : -1;
    bool ok = fd >= 0 && write(fd, k, sizeof k) == (ssize_t)sizeof k;
    if (fd >= 0) close(fd);
    if (!ok) return snprintf(why, len, "cannot write the munge key %s", key), why;
    char a_sock[700], a_key[700], a_log[700], a_pid[700], a_seed[700];
    snprintf(a_sock, sizeof a_sock, "--socket=%s", c->sock);
    snprintf(a_key, sizeof a_key, "--key-file=%s", key);
    snprintf(a_log, sizeof a_log, "--log-file=%s", log);
    snprintf(a_pid, sizeof a_pid, "--pid-file=%s", pid);
    snprintf(a_seed, sizeof a_seed, "--seed-file=%s", seed);
    c->munged = spawn((const char *const[]){ "/usr/sbin/munged", "-F", a_sock, a_key, a_log, a_pid, a_seed, NULL },
                      log);
    struct stat st;
    for (double t0 = model_now_s(); model_now_s() - t0 < 20;) {
        if (stat(c->sock, &st) == 0 && S_ISSOCK(st.st_mode)) return NULL;
        if (reaped(c->munged, 0.1)) break;
    }
    char *t = tail_lines(log, 3);
    snprintf(why, len, "munged did not start: %s", t);
    g_free(t);
    return why;
}

// slurmctld, then slurmd, on the ports of c (written into slurm.conf): NULL
// when the node is idle, else why not (*retry: a port was taken meanwhile).
static const char *slurm_daemons_up(cluster_t *c, char *why, size_t len, bool *retry)
{
    char ctld_out[600], slurmd_out[600];
    snprintf(ctld_out, sizeof ctld_out, "%s/slurmctld.out", c->dir);
    snprintf(slurmd_out, sizeof slurmd_out, "%s/slurmd.out", c->dir);
    *retry = false;
    c->ctld = spawn((const char *const[]){ "/usr/sbin/slurmctld", "-D", "-f", c->conf, NULL }, ctld_out);
    double t0 = model_now_s();
    while (!port_answers(c->ctld_port) && model_now_s() - t0 < 30)
        if (reaped(c->ctld, 0.2)) {
            c->ctld = 0;
            break;
        }
    const char *who = NULL, *out = NULL;
    if (c->ctld <= 0 || !port_answers(c->ctld_port)) who = "slurmctld", out = ctld_out;
    if (!who) {
        c->slurmd = spawn((const char *const[]){ "/usr/sbin/slurmd", "-D", "-N", NODE, "-f", c->conf, NULL },
                          slurmd_out);
        char *state = NULL;
        for (t0 = model_now_s(); model_now_s() - t0 < 60; g_free(state), state = NULL) {
            state = node_state();
            if (state && !strcmp(state, "idle")) break;
            if (reaped(c->slurmd, 0.5)) {
                c->slurmd = 0;
                break;
            }
        }
        if (!state || strcmp(state, "idle")) who = "slurmd", out = slurmd_out;
        g_free(state);
    }
    if (!who) return NULL;
    char *t = tail_lines(out, 4), *all = slurp(out);
    *retry = all && strstr(all, "already in use");
    snprintf(why, len, "%s did not start (%s): %s", who, out, t);
    g_free(t);
    g_free(all);
    return why;
}

// The cluster up: NULL, or why it cannot be started here.
static const char *cluster_up(cluster_t *c)
{
    static char why[2048];
    memset(c, 0, sizeof *c);
    chmod(test_tmpdir(), 0711);   // munged wants its socket's directories searchable by all
    snprintf(c->dir, sizeof c->dir, "%s", test_path("slurm"));
    snprintf(c->conf, sizeof c->conf, "%s/slurm.conf", c->dir);
    snprintf(c->sock, sizeof c->sock, "%s/munge.sock", c->dir);
    if (strlen(c->dir) > 60)   // unix sockets (munged's, slurmd's per job step) hold 107 bytes
        return snprintf(why, sizeof why, "the temporary directory %s is too long for Slurm's sockets", c->dir), why;
    char sub[600];
    g_mkdir_with_parents(c->dir, 0755);
    chmod(c->dir, 0755);
    snprintf(sub, sizeof sub, "%s/state", c->dir);
    g_mkdir_with_parents(sub, 0755);
    snprintf(sub, sizeof sub, "%s/spool", c->dir);
    g_mkdir_with_parents(sub, 0755);
    // the processes Slurm detaches (slurmd's slurmstepd) come to this test when their parent ends, not to init:
    // the test reaps them, and knows when the last is gone
    prctl(PR_SET_CHILD_SUBREAPER, 1);
    if (munged_up(c, why, sizeof why)) return why;
    setenv("SLURM_CONF", c->conf, 1);
    for (int attempt = 0; attempt < 3; attempt++) {
        do {
            c->ctld_port = free_port();
            c->slurmd_port = free_port();
        } while (c->ctld_port > 0 && c->ctld_port == c->slurmd_port);
        if (c->ctld_port <= 0 || c->slurmd_port <= 0) return "no free TCP port on 127.0.0.1";
        write_conf(c);
        bool retry;
        if (!slurm_daemons_up(c, why, sizeof why, &retry)) return NULL;
        stop(&c->slurmd);
        stop(&c->ctld);
        if (!retry) return why;
    }
    return why;
}

// This test's environment: no SLURM_* or SBATCH_* of a job this test may run
// in (they would steer sbatch elsewhere).
static void clean_env(void)
{
    extern char **environ;
    GPtrArray *names = g_ptr_array_new_with_free_func(g_free);
    for (char **e = environ; *e; e++)
        if (!strncmp(*e, "SLURM_", 6) || !strncmp(*e, "SBATCH_", 7) || !strncmp(*e, "SQUEUE_", 7) ||
            !strncmp(*e, "STUDY_", 6))
            g_ptr_array_add(names, g_strndup(*e, strcspn(*e, "=")));
    for (guint i = 0; i < names->len; i++) unsetenv(names->pdata[i]);
    g_ptr_array_free(names, TRUE);
}

// squeue's lines (job id and state), "" when no job is left (g_free), NULL
// when squeue fails.
static char *queue(void)
{
    char *out = NULL;
    int rc = test_run((const char *const[]){ "squeue", "-h", "-o", "%i %T %r", NULL }, 20, &out, NULL);
    if (rc != 0) {
        g_free(out);
        return NULL;
    }
    return g_strstrip(out);
}

// Wait until the cluster has no job left (up to s seconds): true when none is.
static bool queue_drains(double s)
{
    for (double t0 = model_now_s(); model_now_s() - t0 < s; usleep(500000)) {
        char *q = queue();
        bool empty = q && !q[0];
        g_free(q);
        if (empty) return true;
    }
    return false;
}

// The processes left that belong to this cluster (not this test's own): a
// command line naming its directory, its SLURM_CONF in the environment (the
// jobs), or a file open inside it.
static int leftovers(const cluster_t *c)
{
    char env_key[700];
    snprintf(env_key, sizeof env_key, "SLURM_CONF=%s", c->conf);
    int n = 0;
    DIR *d = opendir("/proc");
    for (struct dirent *e; d && (e = readdir(d));) {
        int pid = atoi(e->d_name);
        if (pid <= 0 || pid == getpid()) continue;
        char p[64], *buf = NULL;
        gsize len = 0;
        bool ours = false;
        const char *files[2] = { "cmdline", "environ" };
        for (int k = 0; k < 2 && !ours; k++) {
            snprintf(p, sizeof p, "/proc/%d/%s", pid, files[k]);
            if (!g_file_get_contents(p, &buf, &len, NULL)) continue;
            for (gsize i = 0; i < len && !ours; i += strlen(buf + i) + 1)
                ours = strstr(buf + i, c->dir) || !strcmp(buf + i, env_key);
            g_free(buf);
        }
        snprintf(p, sizeof p, "/proc/%d/fd", pid);
        DIR *fd = opendir(p);
        for (struct dirent *f; fd && !ours && (f = readdir(fd));) {
            char link[600], target[600];
            snprintf(link, sizeof link, "%s/%s", p, f->d_name);
            ssize_t k = readlink(link, target, sizeof target - 1);
            ours = k > 0 && (target[k] = 0, !strncmp(target, c->dir, strlen(c->dir)));
        }
        if (fd) closedir(fd);
        if (ours) fprintf(stderr, "  left behind: process %d\n", pid);
        n += ours;
    }
    if (d) closedir(d);
    return n;
}

// Cancel the cluster's jobs, wait for them to go, stop its daemons, reap what
// they detached: false when something of it is still running.
static bool cluster_down(cluster_t *c)
{
    if (c->ctld > 0) {
        test_run((const char *const[]){ "scancel", "-p", PARTITION, NULL }, 30, NULL, NULL);
        if (!queue_drains(90)) fprintf(stderr, "  jobs still in the queue when the cluster was stopped\n");
    }
    stop(&c->slurmd);
    stop(&c->ctld);
    stop(&c->munged);
    for (double t0 = model_now_s();;) {   // the detached processes that came to this test
        int st;
        pid_t r = waitpid(-1, &st, WNOHANG);
        if (r > 0) continue;
        if (r < 0) return true;   // no child left
        if (model_now_s() - t0 > 30) {
            fprintf(stderr, "  processes of the cluster still running 30 s after its daemons stopped\n");
            return false;
        }
        usleep(100000);
    }
}

// scontrol's one-line records of job id (an array: one per task) in *text
// (g_free; may be NULL): how many there are, and in *with how many of them
// contain want (e.g. "JobState=COMPLETED").
static int job_records(const char *id, const char *want, int *with, char **text)
{
    char *out = NULL;
    test_run((const char *const[]){ "scontrol", "-o", "show", "job", id, NULL }, 20, &out, NULL);
    int all = 0;
    *with = 0;
    char **lines = g_strsplit(out ? out : "", "\n", -1);
    for (int i = 0; lines[i]; i++)
        if (lines[i][0]) {
            all++;
            *with += strstr(lines[i], want) != NULL;
        }
    g_strfreev(lines);
    if (text) *text = out;
    else g_free(out);
    return all;
}

// scripts/study-slurm with env (NULL-terminated "NAME=VALUE"s) and args: its
// exit status, stdout and stderr (g_free).
static int study_slurm(const char *const *env, const char *const *args, char **out, char **err)
{
    const char *sd = getenv("REFL_SCRIPTS_DIR");
    char *script = g_strdup_printf("%s/study-slurm", sd ? sd : "scripts");
    const char *argv[48] = { "/usr/bin/env" };
    int n = 1;
    for (int i = 0; env && env[i] && n < 46; i++) argv[n++] = env[i];
    argv[n++] = script;
    for (int i = 0; args[i] && n < 47; i++) argv[n++] = args[i];
    argv[n] = NULL;
    int rc = test_run(argv, 60, out, err);
    g_free(script);
    return rc;
}

// study-slurm submit 2 OUT -- OPTIONS (one CPU a shard): its exit status, the
// array's and the merge job's ids; stderr in *err (g_free).
static int submit(const char *out_dir, const char *const *opts, char array[32], char merge[32], char **err)
{
    char *refl_env = g_strdup_printf("REFL=%s", test_refl());
    const char *env[] = { refl_env, "STUDY_CPUS_PER_TASK=1", NULL };
    const char *args[40] = { "submit", "2", out_dir, "--" };
    int n = 4;
    for (int i = 0; opts[i] && n < 39; i++) args[n++] = opts[i];
    args[n] = NULL;
    char *out = NULL;
    int rc = study_slurm(env, args, &out, err);
    array[0] = merge[0] = 0;
    const char *a = out ? strstr(out, "job array ") : NULL, *m = out ? strstr(out, "merge: job ") : NULL;
    if (a) sscanf(a, "job array %31[0-9]", array);
    if (m) sscanf(m, "merge: job %31[0-9]", merge);
    g_free(out);
    g_free(refl_env);
    return rc;
}

// The merged study in dir equals the unsharded one in whole: study.csv byte
// for byte, study.json's results and design exactly; complete, merged from
// both shards, 2 cases x 17 descriptions.
static void check_equal_studies(const char *dir, const char *whole)
{
    char *p[4] = { g_strdup_printf("%s/study.csv", dir), g_strdup_printf("%s/study.csv", whole),
                   g_strdup_printf("%s/study.json", dir), g_strdup_printf("%s/study.json", whole) };
    char *cm = slurp(p[0]), *cw = slurp(p[1]);
    CHECK_MSG(cm && cw && !strcmp(cm, cw), "%s differs from the unsharded %s", p[0], p[1]);
    int rows = 0;
    for (char *s = cw; s && (s = strchr(s, '\n')); s++) rows += s[1] != 0;
    CHECK_MSG(rows == 2 * 17, "%d rows: want 2 cases x 17 descriptions", rows);
    json_t *jm = json_load_file(p[2], 0, NULL), *jw = json_load_file(p[3], 0, NULL);
    CHECK(jm && jw);
    if (jm && jw) {
        CHECK(json_is_true(json_object_get(jm, "complete")) && json_is_true(json_object_get(jw, "complete")));
        CHECK(json_equal(json_object_get(jm, "results"), json_object_get(jw, "results")));
        CHECK(json_equal(json_object_get(jm, "design"), json_object_get(jw, "design")));
        CHECK(json_array_size(json_object_get(json_object_get(jm, "provenance"), "merged_from")) == 2);
    }
    json_decref(jm);
    json_decref(jw);
    g_free(cm);
    g_free(cw);
    for (int i = 0; i < 4; i++) g_free(p[i]);
}

// Each record of job id is in state want; else the records and the logs named.
static void check_jobs(const char *what, const char *id, int n, const char *want, const char *log1, const char *log2)
{
    int with = 0;
    char *text = NULL;
    int all = job_records(id, want, &with, &text);
    if (all != n || with != n) {
        char *t1 = log1 ? tail_lines(log1, 5) : g_strdup(""), *t2 = log2 ? tail_lines(log2, 5) : g_strdup("");
        test_fail(__FILE__, __LINE__, "%s (job %s): %d of %d records %s, want %d:\n%s\n%s\n%s", what, id, with, all,
                  want, n, text ? text : "", t1, t2);
        g_free(t1);
        g_free(t2);
    }
    g_free(text);
}

// Slurm is here and this test may start it: NULL, or why not.
static const char *slurm_missing(void)
{
    static char why[256];
    if (geteuid() != 0) return "not root: slurmd runs as root to start each job as its user (CI runs as root)";
    static const char *const daemons[] = { "/usr/sbin/munged", "/usr/sbin/slurmctld", "/usr/sbin/slurmd" };
    static const char *const tools[] = { "sbatch", "squeue", "sinfo", "scontrol", "scancel" };
    for (int i = 0; i < 3; i++)
        if (access(daemons[i], X_OK))
            return snprintf(why, sizeof why, "%s is not installed (Debian: slurm-wlm, munge; scripts/install-deps)",
                            daemons[i]), why;
    for (int i = 0; i < 5; i++) {
        char *p = g_find_program_in_path(tools[i]);
        g_free(p);
        if (!p)
            return snprintf(why, sizeof why, "%s is not on PATH (Debian: slurm-client; scripts/install-deps)",
                            tools[i]), why;
    }
    return NULL;
}

// scripts/study-slurm submit on a single-node Slurm of the test's own
// (127.0.0.1, ports found free, daemons as children): the daemons listen on
// 127.0.0.1 only; the job array of 2 shards (one CPU each: side by side on the
// node) and the merge job after it complete, and the merged study equals the
// unsharded one run here (study.csv byte for byte, study.json's results and
// design). A study whose shards fail (a missing truth file) leaves no merge
// job pending: Slurm cancels it. After the test no process of the cluster is
// left.
TEST_LONG(study_slurm_array_and_merge_equal_unsharded)
{
    const char *missing = slurm_missing();
    if (missing) SKIP("%s", missing);
    clean_env();
    cluster_t c;
    const char *why = cluster_up(&c);
    if (why) {
        char reason[2100];
        snprintf(reason, sizeof reason, "a single-node Slurm cannot be started here: %s", why);
        cluster_down(&c);
        SKIP("%s", reason);
    }
    char where[300] = "";
    int nl = loopback_listeners(c.ctld, where, sizeof where), nd = nl < 0 ? 0 : loopback_listeners(c.slurmd, where,
                                                                                                   sizeof where);
    CHECK_MSG(nl >= 1 && nd >= 1, "slurmctld listens on %d, slurmd on %d TCP sockets of 127.0.0.1 %s", nl, nd, where);
    char *study = g_strdup_printf("%s/study", c.dir), *bad = g_strdup_printf("%s/bad", c.dir);
    char *whole = g_strdup(test_path("whole")), *err = NULL;
    char array[32], merge[32], bad_array[32], bad_merge[32];
    const char *opts[] = { "--cases", "2", "--configs", "priors+maps", NULL };
    const char *bad_opts[] = { "--cases", "2", "--configs", "priors+maps", "--truth", "/nonexistent/truth.ini", NULL };
    double t0 = model_now_s();
    int rc = nl >= 1 && nd >= 1 ? submit(study, opts, array, merge, &err) : -1;
    CHECK_MSG(rc == 0 && array[0] && merge[0], "study-slurm submit: exit %d: %s", rc, err);
    g_free(err);
    rc = rc == 0 ? submit(bad, bad_opts, bad_array, bad_merge, &err) : -1;
    CHECK_MSG(rc == 0 && bad_array[0] && bad_merge[0], "study-slurm submit (bad truth): exit %d: %s", rc, err);
    g_free(err);
    err = NULL;
    // meanwhile the unsharded study, here
    double t1 = model_now_s();
    int rw = rc == 0 ? test_refl_run(600, NULL, &err, "verify", "--study", "--cases", "2", "--configs", "priors+maps",
                                     "--threads", "2", "-o", whole, NULL) : -1;
    double t_whole = model_now_s() - t1;
    CHECK_MSG(rw == 0, "the unsharded study: exit %d: %s", rw, err);
    g_free(err);
    if (rc == 0) {
        bool drained = queue_drains(420);
        char *q = drained ? NULL : queue();
        CHECK_MSG(drained, "the jobs did not end within 420 s: %s", q);
        g_free(q);
        double t_slurm = model_now_s() - t0;
        char log1[700], log2[700], mlog[700];
        snprintf(log1, sizeof log1, "%s/shards/slurm-%s_1.log", study, array);
        snprintf(log2, sizeof log2, "%s/shards/slurm-%s_2.log", study, array);
        snprintf(mlog, sizeof mlog, "%s/slurm-merge-%s.log", study, merge);
        check_jobs("the study's shards", array, 2, "JobState=COMPLETED", log1, log2);
        check_jobs("the study's merge", merge, 1, "JobState=COMPLETED", mlog, NULL);
        CHECK_MSG(access(log1, F_OK) == 0 && access(log2, F_OK) == 0 && access(mlog, F_OK) == 0,
                  "the jobs' logs %s, %s, %s", log1, log2, mlog);
        if (rw == 0) check_equal_studies(study, whole);
        check_jobs("the failing study's shards", bad_array, 2, "JobState=FAILED", NULL, NULL);
        check_jobs("the failing study's merge", bad_merge, 1, "JobState=CANCELLED", NULL, NULL);
        char *bj = g_strdup_printf("%s/study.json", bad);
        CHECK_MSG(access(bj, F_OK) != 0, "%s written", bj);
        g_free(bj);
        printf("  slurm: shards (array %s, 2 x 1 CPU) and merge (job %s) done %.0f s after submit; the unsharded "
               "study (2 threads, beside them) %.0f s\n", array, merge, t_slurm, t_whole);
    }
    CHECK_MSG(cluster_down(&c), "processes the cluster started still run");
    CHECK_MSG(leftovers(&c) == 0, "processes of the cluster left behind");
    g_free(study);
    g_free(bad);
    g_free(whole);
}

// study-slurm refuses, before submitting, what it cannot run: N not a
// number, STUDY-OPTIONS that set the output or the shard, CPUs per shard not
// a number, a refl in a directory that does not exist, no sbatch on PATH;
// each with exit status 2 and the reason.
TEST(study_slurm_submit_refuses_with_reason)
{
    char *out = NULL, *err = NULL, *dir = g_strdup(test_path("out"));
    // a PATH with the tools the script uses but no sbatch
    char *bin = g_strdup(test_path("bin")), *path_env = g_strdup_printf("PATH=%s", bin);
    g_mkdir_with_parents(bin, 0755);
    static const char *const tools[] = { "dirname", "basename", "sed", "mkdir" };
    for (int i = 0; i < 4; i++) {
        char *src = g_find_program_in_path(tools[i]), *dst = g_strdup_printf("%s/%s", bin, tools[i]);
        CHECK(src && symlink(src, dst) == 0);
        g_free(src);
        g_free(dst);
    }
    struct {
        const char *env[3], *args[8], *says;
    } cases[] = {
        { { NULL }, { "submit", "x", dir, "--", "--cases", "2", NULL }, "N 'x' is not a positive number" },
        { { NULL }, { "submit", "2", dir, "--", "--cases", "2", "-o", NULL }, "STUDY-OPTIONS give -o" },
        { { NULL }, { "submit", "2", dir, "--", "--shard", "1/2", NULL }, "STUDY-OPTIONS give --shard" },
        { { "STUDY_CPUS_PER_TASK=two", NULL }, { "submit", "2", dir, "--", NULL }, "STUDY_CPUS_PER_TASK 'two'" },
        { { "REFL=no/such/dir/refl", NULL }, { "submit", "2", dir, "--", NULL }, "REFL=no/such/dir/refl: no such" },
        { { path_env, NULL }, { "submit", "2", dir, "--", "--cases", "2", NULL }, "sbatch is not on PATH" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc = study_slurm(cases[i].env, cases[i].args, &out, &err);
        CHECK_MSG(rc == 2 && err && strstr(err, cases[i].says), "case %zu: exit %d, stderr %s (want \"%s\")", i, rc,
                  err, cases[i].says);
        g_free(out);
        g_free(err);
    }
    CHECK_MSG(access(dir, F_OK) != 0, "%s made though nothing was submitted", dir);
    g_free(dir);
    g_free(bin);
    g_free(path_env);
}
