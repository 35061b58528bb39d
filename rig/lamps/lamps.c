// rig/lamps/lamps.c — lamps switched by GPIO lines: the wrappers over
// rig_lamps_ops_t, the common checks of a lamp list, and the safety net that
// switches every open lamp set off on SIGINT/SIGTERM/SIGHUP/SIGQUIT, on the
// crash signals (SIGSEGV/SIGBUS/SIGFPE/SIGABRT) and exit(). The backends:
// rig/lamps/gpiod.c (libgpiod v1), rig/lamps/sim.c (simulated); the lamp-state
// file for deaths no handler sees: rig/lamps/state.c.
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "rig/internal.h"

#define LAMPS_MAX RIG_LAMPS_MAX            // bits of on_mask = size of rig_lamps_t.lamps
#define WAIT_MAX_MS (3600.0 * 1000.0)      // warm-up/settle above an hour is a typo

_Static_assert(sizeof(((rig_lamps_t *)0)->lamps) / sizeof(rig_lamp_line_t) == LAMPS_MAX,
               "on_mask has one bit per lamp");
_Static_assert(ATOMIC_POINTER_LOCK_FREE == 2 && ATOMIC_INT_LOCK_FREE == 2,
               "the signal handler needs lock-free atomics");

static uint32_t mask_of(int n) { return n >= 32 ? 0xffffffffu : ((uint32_t)1 << n) - 1; }

// ---------------------------------------------------------------------------
// Safety registry: every open lamp set, readable from a signal handler.

#define SAFETY_SLOTS RIG_LAMPS_SAFETY_SLOTS
static _Atomic(rig_lamps_t *) safety_slot[SAFETY_SLOTS];
static atomic_int  safety_busy;       // handlers currently walking the registry
static atomic_bool safety_installed;
static const int   safety_signals[] = { SIGINT, SIGTERM, SIGHUP, SIGQUIT,
                                        SIGSEGV, SIGBUS, SIGFPE, SIGABRT };
// A stack overflow's SIGSEGV has no stack left to run the handler on: it runs
// on this one (the installing thread's alternate stack).
static char safety_stack[64 * 1024] __attribute__((aligned(16)));
// The crash signals' handlers before ours (a sanitizer's, a crash reporter's):
// they get the crash once the lamps are off.
static struct sigaction safety_old[65];

static bool is_crash(int sig) { return sig == SIGSEGV || sig == SIGBUS || sig == SIGFPE || sig == SIGABRT; }

bool rig_lamps_safety_register(rig_lamps_t *l)
{
    for (int i = 0; i < SAFETY_SLOTS; i++) {
        rig_lamps_t *expected = NULL;
        if (atomic_compare_exchange_strong(&safety_slot[i], &expected, l)) return true;
    }
    return false;
}

// After this returns no handler is using l (a handler that had already picked
// l up has finished with it), so l may be freed.
static void safety_unregister(rig_lamps_t *l)
{
    for (int i = 0; i < SAFETY_SLOTS; i++) {
        rig_lamps_t *expected = l;
        atomic_compare_exchange_strong(&safety_slot[i], &expected, NULL);
    }
    while (atomic_load(&safety_busy) > 0) {
        struct timespec ts = { 0, 1000000 };
        nanosleep(&ts, NULL);
    }
}

// Async-signal-safe: atomics and the backends' emergency_off only.
static void safety_all_off(void)
{
    atomic_fetch_add(&safety_busy, 1);
    for (int i = 0; i < SAFETY_SLOTS; i++) {
        rig_lamps_t *l = atomic_load(&safety_slot[i]);
        if (l && l->ops && l->ops->emergency_off) l->ops->emergency_off(l);
        if (l) rig_lamps_state_signal_off(l);     // the file says "off" once they are
    }
    atomic_fetch_sub(&safety_busy, 1);
}

static void safety_on_signal(int sig)
{
    int saved_errno = errno;
    safety_all_off();
    // Default action (or, for a crash, the handler there was before ours),
    // then re-raise: the signal stays pending (blocked while this handler
    // runs) and ends the process as soon as the handler returns (with a core
    // where the default makes one). A fault (SIGSEGV from a bad access) would
    // also recur at the faulting instruction, now with that action.
    struct sigaction dfl;
    memset(&dfl, 0, sizeof dfl);
    dfl.sa_handler = SIG_DFL;
    sigemptyset(&dfl.sa_mask);
    const struct sigaction *next = &dfl;
    if (is_crash(sig) && sig < 65 && (safety_old[sig].sa_flags & SA_SIGINFO ? safety_old[sig].sa_sigaction != NULL
                                      : safety_old[sig].sa_handler != SIG_DFL && safety_old[sig].sa_handler != SIG_IGN))
        next = &safety_old[sig];
    sigaction(sig, next, NULL);
    raise(sig);
    errno = saved_errno;
}

static void safety_at_exit(void) { safety_all_off(); }

void rig_safety_install(void)
{
    if (atomic_exchange(&safety_installed, true)) return;
    atexit(safety_at_exit);
    // An alternate stack unless the thread has one (a sanitizer's, say).
    stack_t cur, ss = { .ss_sp = safety_stack, .ss_size = sizeof safety_stack, .ss_flags = 0 };
    bool alt = sigaltstack(NULL, &cur) == 0 && (!(cur.ss_flags & SS_DISABLE) || sigaltstack(&ss, NULL) == 0);
    for (size_t i = 0; i < sizeof safety_signals / sizeof safety_signals[0]; i++) {
        int sig = safety_signals[i];
        struct sigaction old;
        // A signal the process ignores (nohup, background jobs) does not end it:
        // keep ignoring it.
        if (sigaction(sig, NULL, &old) == 0 && old.sa_handler == SIG_IGN) continue;
        if (sig < 65) safety_old[sig] = old;
        struct sigaction sa;
        memset(&sa, 0, sizeof sa);
        sa.sa_handler = safety_on_signal;
        sigfillset(&sa.sa_mask);          // no other signal interrupts the switch-off
        sa.sa_flags = SA_RESTART | (alt ? SA_ONSTACK : 0);
        sigaction(sig, &sa, NULL);
    }
}

// ---------------------------------------------------------------------------
// Common checks and allocation

// Checks the lamp list and allocates the set: *made (also NULL on error).
int rig_lamps_new(rig_lamps_t **out, rig_lamps_t **made, const rig_lamps_ops_t *ops,
                  const rig_lamp_line_t *lamps, int n)
{
    const char *be = ops->backend;
    *made = NULL;
    if (!out) return rig_fail(RIG_ERR_INVALID, "%s lamps: no place for the result (out is NULL)", be);
    *out = NULL;
    if (n < 0 || n > LAMPS_MAX)
        return rig_fail(RIG_ERR_INVALID, "%s lamps: %d lamps given; a lamp set has 0 to %d lamps",
                        be, n, LAMPS_MAX);
    if (n > 0 && !lamps)
        return rig_fail(RIG_ERR_INVALID, "%s lamps: %d lamps announced but no lamp list (NULL)", be, n);
    for (int i = 0; i < n; i++) {
        const rig_lamp_line_t *a = &lamps[i];
        if (!memchr(a->name, 0, sizeof a->name) || !a->name[0])
            return rig_fail(RIG_ERR_INVALID, "%s lamps: lamp %d has no name (or one longer than %zu "
                            "characters); give every lamp a short unique name", be, i, sizeof a->name - 1);
        for (int j = 0; j < i; j++)
            if (!strcmp(lamps[j].name, a->name))
                return rig_fail(RIG_ERR_INVALID, "%s lamps: lamps %d and %d are both named '%s'; "
                                "lamp names must be unique", be, j, i, a->name);
        if (!(a->warmup_ms >= 0 && a->warmup_ms <= WAIT_MAX_MS))
            return rig_fail(RIG_ERR_INVALID, "%s lamps: lamp '%s': warmup_ms %g is not a time "
                            "between 0 and %g ms", be, a->name, a->warmup_ms, WAIT_MAX_MS);
        if (!(a->settle_ms >= 0 && a->settle_ms <= WAIT_MAX_MS))
            return rig_fail(RIG_ERR_INVALID, "%s lamps: lamp '%s': settle_ms %g is not a time "
                            "between 0 and %g ms", be, a->name, a->settle_ms, WAIT_MAX_MS);
    }
    rig_lamps_t *l = calloc(1, sizeof *l);
    if (!l) return rig_fail(RIG_ERR_NO_MEM, "%s lamps: out of memory", be);
    l->ops = ops;
    l->n = n;
    l->state_fd = -1;
    if (n > 0) memcpy(l->lamps, lamps, (size_t)n * sizeof *lamps);
    *made = l;
    return RIG_ERR_OK;
}

// ---------------------------------------------------------------------------
// Wrappers

double rig_lamps_settle_s(const rig_lamps_t *l, uint32_t from, uint32_t to)
{
    if (!l) return 0;
    uint32_t all = mask_of(l->n), turned_on = to & ~from & all, turned_off = from & ~to & all;
    double ms = 0;
    for (int i = 0; i < l->n; i++) {
        if ((turned_on >> i) & 1) ms = fmax(ms, l->lamps[i].warmup_ms);
        if ((turned_off >> i) & 1) ms = fmax(ms, l->lamps[i].settle_ms);
    }
    return ms / 1000.0;
}

static void sleep_s(double s)
{
    if (!(s > 0)) return;
    struct timespec ts = { (time_t)s, (long)((s - floor(s)) * 1e9) };
    if (ts.tv_nsec > 999999999) ts.tv_nsec = 999999999;
    while (nanosleep(&ts, &ts) < 0 && errno == EINTR) {
    }
}

int rig_lamps_set(rig_lamps_t *l, uint32_t on_mask)
{
    if (!l || !l->ops) return rig_fail(RIG_ERR_INVALID, "lamps: no lamp set (NULL)");
    if (on_mask & ~mask_of(l->n))
        return rig_fail(RIG_ERR_INVALID, "%s lamps: on_mask 0x%x switches lamps beyond the %d "
                        "configured (valid bits 0x%x); check the lamp indices", l->ops->backend,
                        on_mask, l->n, mask_of(l->n));
    uint32_t from = l->on_mask;
    // The state file first names every lamp on during the change (on disk
    // before any turns on), and after it those left on.
    int err = RIG_ERR_OK;
    if ((from | on_mask) & ~l->state_mask) err = rig_lamps_state_write(l, l->state_mask | from | on_mask, true);
    if (!err) err = l->ops->set(l, on_mask);
    if (err) {
        // The lines' state is unknown after a failed switch: everything off.
        if (l->ops->emergency_off) l->ops->emergency_off(l);
        l->on_mask = 0;
        rig_lamps_state_write(l, 0, false);
        return err;
    }
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    for (int i = 0; i < l->n; i++)
        if ((on_mask & ~from) >> i & 1)
            __atomic_store_n(&l->on_since_ns[i], (int64_t)now.tv_sec * 1000000000 + now.tv_nsec, __ATOMIC_RELEASE);
    l->on_mask = on_mask;
    // A failure here leaves the file naming more lamps than are on: safe.
    if (l->state_mask != on_mask) rig_lamps_state_write(l, on_mask, false);
    sleep_s(rig_lamps_settle_s(l, from, on_mask));
    return RIG_ERR_OK;
}

int rig_lamps_all_off(rig_lamps_t *l) { return rig_lamps_set(l, 0); }

int rig_lamps_find(const rig_lamps_t *l, const char *name)
{
    if (!l || !name) return -1;
    for (int i = 0; i < l->n; i++)
        if (!strcmp(l->lamps[i].name, name)) return i;
    return -1;
}

void rig_lamps_close(rig_lamps_t *l)
{
    if (!l) return;
    // Off while still registered (a signal now still finds the set), then out
    // of the registry, then release.
    if (l->ops && l->ops->emergency_off) l->ops->emergency_off(l);
    l->on_mask = 0;
    safety_unregister(l);
    if (l->ops && l->ops->close) l->ops->close(l);
    rig_lamps_state_close(l, true);
    free(l);
}

// ---------------------------------------------------------------------------
// Accessors

int rig_lamps_count(const rig_lamps_t *l) { return l ? l->n : 0; }

const rig_lamp_line_t *rig_lamps_line(const rig_lamps_t *l, int i)
{
    return l && i >= 0 && i < l->n ? &l->lamps[i] : NULL;
}

const char *rig_lamps_name(const rig_lamps_t *l, int i)
{
    return l && i >= 0 && i < l->n ? l->lamps[i].name : "";
}

uint32_t    rig_lamps_on_mask(const rig_lamps_t *l) { return l ? l->on_mask : 0; }
int64_t     rig_lamps_on_since_ns(const rig_lamps_t *l, int i)
{
    return l && i >= 0 && i < l->n ? __atomic_load_n(&l->on_since_ns[i], __ATOMIC_ACQUIRE) : 0;
}
const char *rig_lamps_backend(const rig_lamps_t *l) { return l && l->ops ? l->ops->backend : ""; }
