// rig/lamps/state.c — the lamp-state file, the one owner of its format: which
// lamps of a lamp set are on, kept on disk for what no signal handler can
// catch (SIGKILL, the OOM killer, a power cut). The next open of the same
// lamps finds a record of lamps on left by a dead process, reports it and
// switches them off.
//
// The file (text, one "key = value" a line; '#' comments):
//   # refl lamp state ...
//   format_version = 1                      (this layout; a file without it is version 1)
//   pid = 4242
//   started = 2026-11-24T23:14:30.123Z      (when that process opened the lamps)
//   hardware = gpiod gpiochip0:3 gpiochip0:5 gpiochip1:2
//   on = key, fill                          (names of the lamps on; empty: none)
// Rules: it is written (and flushed to disk) before a lamp turns on and after
// one turns off, so it never says "off" while a lamp is on. The open set holds
// an exclusive flock(2) on it for its lifetime: the kernel drops the lock when
// the process dies however it dies, so a locked file belongs to a live refl
// (not to be touched) and an unlocked one with lamps on to a dead one. The
// file is never removed (removing a locked file would let a third process lock
// a new one beside it); a clean close leaves "on =" empty.
// The reader reads version 1; a file of a higher format_version is refused
// (the lamps are not opened: it may record lamps on that only the refl that
// wrote it reads).
// Where: [lamps] state_file in the rig file, else $XDG_STATE_HOME/refl (default
// ~/.local/state/refl) / <backend>-<chip>-<lines>....state, named after the
// hardware (the sim backend keeps a file only when given one).
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "model/base/report.h"
#include "rig/internal.h"

#define STATE_MAX 16384    // a record is below 3 KB (32 names of 63 characters)
#define STATE_FORMAT_VERSION 1

// ---------------------------------------------------------------------------
// The default path: named after the hardware

typedef struct { const char *chip; unsigned line; } hw_line_t;

static const char *chip_short(const char *chip)
{
    return strncmp(chip, "/dev/", 5) ? chip : chip + 5;
}

static int cmp_hw(const void *a, const void *b)
{
    const hw_line_t *x = a, *y = b;
    int c = strcmp(chip_short(x->chip), chip_short(y->chip));
    return c ? c : (x->line > y->line) - (x->line < y->line);
}

// "gpiod-gpiochip0-3-5-gpiochip1-2": chips in name order, each with its lines
// ascending ("/dev/" dropped: a chip's name and its path are one chip); any
// other character than [A-Za-z0-9._-] becomes '_'. Over 160 characters: cut,
// with a hash of the whole name appended.
static void hardware_name(const rig_lamps_t *l, char *out, size_t size)
{
    hw_line_t hw[RIG_LAMPS_MAX];
    for (int i = 0; i < l->n; i++) hw[i] = (hw_line_t){ l->lamps[i].chip, l->lamps[i].line };
    qsort(hw, (size_t)l->n, sizeof hw[0], cmp_hw);
    char name[RIG_LAMPS_MAX * 80 + 16];
    size_t n = (size_t)snprintf(name, sizeof name, "%s", l->ops->backend);
    for (int i = 0; i < l->n && n < sizeof name; i++) {
        if (i == 0 || strcmp(chip_short(hw[i].chip), chip_short(hw[i - 1].chip)))
            n += (size_t)snprintf(name + n, sizeof name - n, "-%s", chip_short(hw[i].chip));
        if (n < sizeof name) n += (size_t)snprintf(name + n, sizeof name - n, "-%u", hw[i].line);
    }
    for (char *p = name; *p; p++)
        if (!(('a' <= *p && *p <= 'z') || ('A' <= *p && *p <= 'Z') || ('0' <= *p && *p <= '9') ||
              *p == '.' || *p == '-' || *p == '_'))
            *p = '_';
    if (strlen(name) > 160) {
        unsigned long long h = 1469598103934665603ULL;   // FNV-1a
        for (const char *p = name; *p; p++) h = (h ^ (unsigned char)*p) * 1099511628211ULL;
        snprintf(name + 140, sizeof name - 140, "-%016llx", h);
    }
    snprintf(out, size, "%s", name);
}

static int default_path(const rig_lamps_t *l, char *out, size_t size)
{
    const char *xdg = getenv("XDG_STATE_HOME"), *home = getenv("HOME");
    char dir[PATH_MAX], hw[200];
    if (xdg && xdg[0] == '/') snprintf(dir, sizeof dir, "%s/refl", xdg);
    else if (home && home[0] == '/') snprintf(dir, sizeof dir, "%s/.local/state/refl", home);
    else
        return rig_fail(RIG_ERR_INVALID, "%s lamps: no place for the lamp-state file (neither "
                        "XDG_STATE_HOME nor HOME is an absolute path); set one, or give the rig file's "
                        "[lamps] state_file = PATH", l->ops->backend);
    bool q = model_error_quiet_thread(true);
    bool made = model_mkdir_p(dir);
    model_error_quiet_thread(q);
    if (!made)
        return rig_fail(RIG_ERR_IO, "%s lamps: cannot create the lamp-state directory %s: %s; make it "
                        "writable or give the rig file's [lamps] state_file = PATH", l->ops->backend, dir,
                        strerror(errno));
    hardware_name(l, hw, sizeof hw);
    if ((size_t)snprintf(out, size, "%s/%s.state", dir, hw) >= size)
        return rig_fail(RIG_ERR_INVALID, "%s lamps: the lamp-state path %s/%s.state is too long; give the "
                        "rig file's [lamps] state_file = PATH", l->ops->backend, dir, hw);
    return RIG_ERR_OK;
}

// ---------------------------------------------------------------------------
// Records

static size_t format_record(const rig_lamps_t *l, uint32_t on, char *out, size_t size)
{
    size_t n = (size_t)snprintf(out, size,
                                "# refl lamp state (rig/lamps/state.c): the lamps this process has on. "
                                "Locked while it runs;\n# a later refl that finds lamps on here switches "
                                "them off.\nformat_version = %d\npid = %ld\nstarted = %s\nhardware = %s",
                                STATE_FORMAT_VERSION, (long)l->state_pid, l->state_started, l->ops->backend);
    for (int i = 0; i < l->n && n < size; i++)
        n += l->lamps[i].chip[0]
                 ? (size_t)snprintf(out + n, size - n, " %s:%u", l->lamps[i].chip, l->lamps[i].line)
                 : (size_t)snprintf(out + n, size - n, " %s", l->lamps[i].name);
    if (n < size) n += (size_t)snprintf(out + n, size - n, "\non =");
    const char *sep = " ";
    for (int i = 0; i < l->n && n < size; i++)
        if ((on >> i) & 1) {
            n += (size_t)snprintf(out + n, size - n, "%s%s", sep, l->lamps[i].name);
            sep = ", ";
        }
    if (n < size) n += (size_t)snprintf(out + n, size - n, "\n");
    return n < size ? n : size - 1;
}

// Whole record at offset 0, then cut to its length: async-signal-safe.
static bool put_record(int fd, const char *rec, size_t len)
{
    size_t done = 0;
    while (done < len) {
        ssize_t w = pwrite(fd, rec + done, len - done, (off_t)done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return false;
        done += (size_t)w;
    }
    return ftruncate(fd, (off_t)len) == 0;
}

int rig_lamps_state_write(rig_lamps_t *l, uint32_t on, bool durable)
{
    if (!l || l->state_fd < 0) return RIG_ERR_OK;
    char rec[STATE_MAX];
    size_t len = format_record(l, on, rec, sizeof rec);
    int saved = errno;
    if (!put_record(l->state_fd, rec, len) || (durable && fdatasync(l->state_fd) != 0)) {
        int e = errno;
        errno = saved;
        return rig_fail(RIG_ERR_IO, "%s lamps: cannot record the lamp state in %s: %s; no lamp is switched "
                        "on without it (free the disk, or give the rig file's [lamps] state_file = PATH)",
                        l->ops->backend, l->state_path, strerror(e));
    }
    l->state_mask = on;
    return RIG_ERR_OK;
}

void rig_lamps_state_signal_off(rig_lamps_t *l)
{
    if (l->state_fd >= 0 && l->state_off) put_record(l->state_fd, l->state_off, l->state_off_len);
}

// The value of "key = " in a record, copied to out ("" when absent).
static bool record_value(const char *text, const char *key, char *out, size_t size)
{
    size_t k = strlen(key);
    out[0] = 0;
    for (const char *p = text; p && *p; p = strchr(p, '\n'), p = p ? p + 1 : NULL) {
        if (strncmp(p, key, k) || (p[k] != ' ' && p[k] != '=')) continue;
        const char *v = p + k;
        while (*v == ' ') v++;
        if (*v != '=') continue;
        v++;
        while (*v == ' ') v++;
        size_t m = strcspn(v, "\n");
        if (m >= size) m = size - 1;
        memcpy(out, v, m);
        out[m] = 0;
        return true;
    }
    return false;
}

// A record of a newer format_version is refused (a value that is no whole
// number: the record is damaged, and recover switches every lamp off).
static int check_version(const rig_lamps_t *l, const char *text)
{
    char v[32];
    if (!record_value(text, "format_version", v, sizeof v)) return RIG_ERR_OK;   // version 1
    char *end;
    long n = strtol(v, &end, 10);
    if (end == v || *end || n <= STATE_FORMAT_VERSION) return RIG_ERR_OK;
    return rig_fail(RIG_ERR_PROTOCOL, "%s lamps: the lamp-state file %s has format_version %ld, written by a newer "
                    "refl (this refl reads version %d): its lamps may be on; open them with that refl, or give the "
                    "rig file's [lamps] state_file = PATH", l->ops->backend, l->state_path, n, STATE_FORMAT_VERSION);
}

// A dead process's record with lamps on: report it and switch every lamp off.
static int recover(rig_lamps_t *l, const char *text)
{
    char pid[32], started[64], on[STATE_MAX];
    bool has_on = record_value(text, "on", on, sizeof on);
    if (has_on && !on[0]) return RIG_ERR_OK;     // the last session ended with every lamp off
    if (!record_value(text, "pid", pid, sizeof pid) || !pid[0]) snprintf(pid, sizeof pid, "unknown");
    if (!record_value(text, "started", started, sizeof started) || !started[0])
        snprintf(started, sizeof started, "unknown");
    if (has_on)
        model_warning("the last session (pid %s, started %s) died with lamps %s on; switching them off", pid, started,
                      on);
    else
        model_warning("the lamp-state file %s is unreadable (the last session, pid %s, started %s, may have died "
                      "while writing it); switching every lamp off", l->state_path, pid, started);
    int err = l->ops->set(l, 0);
    if (err && l->ops->emergency_off) l->ops->emergency_off(l);
    l->on_mask = 0;
    return err;
}

// ---------------------------------------------------------------------------
// Open and close

static int state_busy(rig_lamps_t *l, int fd)
{
    char text[STATE_MAX] = { 0 }, pid[32], started[64];
    ssize_t r = pread(fd, text, sizeof text - 1, 0);
    if (r < 0) r = 0;
    text[r] = 0;
    if (!record_value(text, "pid", pid, sizeof pid) || !pid[0]) snprintf(pid, sizeof pid, "unknown");
    if (!record_value(text, "started", started, sizeof started) || !started[0])
        snprintf(started, sizeof started, "unknown");
    return rig_fail(RIG_ERR_BUSY, "%s lamps: these lamps are in use by another refl (pid %s, started %s; "
                    "it holds the lock on %s); wait for it to end or stop it", l->ops->backend, pid,
                    started, l->state_path);
}

int rig_lamps_state_open(rig_lamps_t *l, const char *path)
{
    char buf[PATH_MAX];
    int err;
    if (!path || !*path) {
        if ((err = default_path(l, buf, sizeof buf))) return err;
        path = buf;
    }
    if (!(l->state_path = strdup(path))) return rig_fail(RIG_ERR_NO_MEM, "lamps: out of memory");
    int fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) {
        int e = errno;
        return rig_fail(e == EACCES || e == EPERM ? RIG_ERR_ACCESS : RIG_ERR_IO, "%s lamps: cannot open the "
                        "lamp-state file %s: %s; make its directory writable or give the rig file's [lamps] "
                        "state_file = PATH", l->ops->backend, path, strerror(e));
    }
    while (flock(fd, LOCK_EX | LOCK_NB) < 0) {
        if (errno == EINTR) continue;
        int e = errno;
        err = e == EWOULDBLOCK ? state_busy(l, fd)
                               : rig_fail(RIG_ERR_IO, "%s lamps: cannot lock the lamp-state file %s: %s",
                                          l->ops->backend, path, strerror(e));
        close(fd);
        return err;
    }
    l->state_fd = fd;
    char text[STATE_MAX];
    ssize_t r = pread(fd, text, sizeof text - 1, 0);
    text[r > 0 ? r : 0] = 0;
    if (r > 0 && ((err = check_version(l, text)) || (err = recover(l, text)))) return err;

    l->state_pid = getpid();
    model_utc_text(model_realtime_s(), l->state_started);
    char rec[STATE_MAX];
    size_t len = format_record(l, 0, rec, sizeof rec);
    if (!(l->state_off = malloc(len + 1))) return rig_fail(RIG_ERR_NO_MEM, "lamps: out of memory");
    memcpy(l->state_off, rec, len + 1);
    l->state_off_len = len;
    return rig_lamps_state_write(l, 0, true);
}

void rig_lamps_state_close(rig_lamps_t *l, bool lamps_off)
{
    if (l->state_fd >= 0) {
        if (lamps_off) rig_lamps_state_signal_off(l);
        close(l->state_fd);      // drops the lock
    }
    l->state_fd = -1;
    free(l->state_path);
    free(l->state_off);
    l->state_path = l->state_off = NULL;
}

const char *rig_lamps_state_file(const rig_lamps_t *l) { return l && l->state_path ? l->state_path : ""; }
