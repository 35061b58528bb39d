// tests/lamp_child.c — a small program for tests/test_rig_lamps.c: opens lamps on
// the gpiod backend (run it under LD_PRELOAD=libfake_gpiod.so), switches some
// on and then ends in the way MODE says.
//
//   lamp_child MODE MASK LAMP...
//     MODE  hold   install the safety net, switch MASK on, print "ready", then
//                  sleep (at most 20 s, then close and exit 0): the test kills it
//           exit   install the safety net, switch MASK on, print "ready" and
//                  exit(0) without closing: the atexit handler switches off
//           close  switch MASK on, close the set, print "closed", exit 0
//           open   open and close (for error messages and the lamp-state file)
//           segv, bus, fpe, abort   as hold, but after "ready" the child really
//                  faults: a write through a null pointer, a read of a mapped
//                  page beyond its file's end, an integer division by zero, abort()
//     MASK  the on-mask, e.g. 0x5
//     LAMP  NAME=CHIP:LINE or NAME=CHIP:LINE:low (active-low); no warm-up/settle;
//           NAME=sim: a simulated lamp (then every lamp is)
//   LAMP_CHILD_STATE_FILE=PATH in the environment: the lamp-state file to keep
//   (else the gpiod default under $XDG_STATE_HOME/refl, and none for sim).
//   LAMP_CHILD_CRASH_HANDLER=1: a SIGSEGV/SIGABRT handler of its own (as a
//   sanitizer's) installed before the safety net; it exits with status 42.
//
// Exit status 0, 2 on bad usage, 3 when the lamps fail (message on stderr:
// "lamp_child: <rig_strerror>: <model_last_error>").
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"

static int usage(void)
{
    fprintf(stderr, "usage: lamp_child hold|exit|close|open|segv|bus|fpe|abort MASK "
            "NAME=CHIP:LINE[:low]|NAME=sim...\n");
    return 2;
}

static bool parse_lamp(const char *arg, rig_lamp_line_t *out)
{
    memset(out, 0, sizeof *out);
    const char *eq = strchr(arg, '=');
    if (!eq || eq == arg || (size_t)(eq - arg) >= sizeof out->name) return false;
    memcpy(out->name, arg, (size_t)(eq - arg));
    if (!strcmp(eq + 1, "sim")) return true;     // chip "" = simulated
    const char *colon = strchr(eq + 1, ':');
    if (!colon || colon == eq + 1 || (size_t)(colon - eq - 1) >= sizeof out->chip) return false;
    memcpy(out->chip, eq + 1, (size_t)(colon - eq - 1));
    char *end;
    unsigned long line = strtoul(colon + 1, &end, 10);
    if (end == colon + 1 || line > 0xffffffffUL) return false;
    out->line = (unsigned)line;
    if (!strcmp(end, ":low")) out->active_low = true;
    else if (*end) return false;
    return true;
}

// A real fault of the kind mode names (returns only if it did not fault).
// Not instrumented by UBSan (make asan): it would end the process at the null
// store or the division itself, before the fault the test is about.
static volatile int zero = 0;
__attribute__((no_sanitize("undefined"))) static void fault(const char *mode)
{
    if (!strcmp(mode, "segv")) {
        volatile int *p = (volatile int *)(uintptr_t)zero;
        *p = 1;
    } else if (!strcmp(mode, "bus")) {
        char path[] = "/tmp/lamp_child_busXXXXXX";
        int fd = mkstemp(path);
        if (fd < 0) return;
        unlink(path);
        volatile char *m = mmap(NULL, 4096, PROT_READ, MAP_PRIVATE, fd, 0);   // empty file
        if (m != MAP_FAILED) zero = m[0];
    } else if (!strcmp(mode, "fpe")) {
        volatile int n = 7;    // not 1: gcc turns 1 / x into compares, no division
        zero = n / zero;
    } else if (!strcmp(mode, "abort")) {
        abort();
    }
}

static void own_crash_handler(int sig)
{
    (void)sig;
    _exit(42);
}

static int fail(int err)
{
    fprintf(stderr, "lamp_child: %s: %s\n", rig_strerror(err), model_last_error());
    return 3;
}

int main(int argc, char **argv)
{
    if (argc < 4) return usage();
    const char *mode = argv[1];
    static const char *const modes[] = { "hold", "exit", "close", "open", "segv", "bus", "fpe", "abort" };
    bool faults = false, known = false;
    for (int i = 0; i < 8; i++)
        if (!strcmp(mode, modes[i])) known = true, faults = i >= 4;
    if (!known) return usage();
    char *end;
    unsigned long mask = strtoul(argv[2], &end, 0);
    if (*end || mask > 0xffffffffUL) return usage();
    rig_lamp_line_t lamps[32];
    int n = argc - 3;
    if (n > 32) return usage();
    bool sim = false;
    for (int i = 0; i < n; i++) {
        if (!parse_lamp(argv[3 + i], &lamps[i])) return usage();
        if (!lamps[i].chip[0]) sim = true;
        else if (sim) return usage();
    }
    model_error_quiet_thread(true);   // errors: fail() prints them once; notes and warnings show

    bool safety = !strcmp(mode, "hold") || !strcmp(mode, "exit") || faults;
    if (getenv("LAMP_CHILD_CRASH_HANDLER")) {
        signal(SIGSEGV, own_crash_handler);
        signal(SIGABRT, own_crash_handler);
    }
    if (safety) rig_safety_install();
    rig_lamps_t *l = NULL;
    const char *state = getenv("LAMP_CHILD_STATE_FILE");
    int err = sim ? rig_lamps_open_sim_state(&l, lamps, n, state) : rig_lamps_open_gpiod_state(&l, lamps, n, state);
    if (err) return fail(err);
    if (!strcmp(mode, "open")) {
        rig_lamps_close(l);
        return 0;
    }
    if ((err = rig_lamps_set(l, (uint32_t)mask))) {
        rig_lamps_close(l);
        return fail(err);
    }
    if (!strcmp(mode, "close")) {
        rig_lamps_close(l);
        printf("closed\n");
        return 0;
    }
    printf("ready\n");
    fflush(stdout);
    if (!strcmp(mode, "exit")) exit(0);
    if (faults) {
        usleep(100000);
        fault(mode);
    }
    for (int i = 0; i < 200; i++) usleep(100000);
    rig_lamps_close(l);
    return 0;
}
