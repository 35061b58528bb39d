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
//           open   open and close (for error messages)
//     MASK  the on-mask, e.g. 0x5
//     LAMP  NAME=CHIP:LINE or NAME=CHIP:LINE:low (active-low); no warm-up/settle
//
// Exit status 0, 2 on bad usage, 3 when the lamps fail (message on stderr:
// "lamp_child: <rig_strerror>: <model_last_error>").
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"

static int usage(void)
{
    fprintf(stderr, "usage: lamp_child hold|exit|close|open MASK NAME=CHIP:LINE[:low]...\n");
    return 2;
}

static bool parse_lamp(const char *arg, rig_lamp_line_t *out)
{
    memset(out, 0, sizeof *out);
    const char *eq = strchr(arg, '=');
    if (!eq || eq == arg || (size_t)(eq - arg) >= sizeof out->name) return false;
    memcpy(out->name, arg, (size_t)(eq - arg));
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

static int fail(int err)
{
    fprintf(stderr, "lamp_child: %s: %s\n", rig_strerror(err), model_last_error());
    return 3;
}

int main(int argc, char **argv)
{
    if (argc < 4) return usage();
    const char *mode = argv[1];
    if (strcmp(mode, "hold") && strcmp(mode, "exit") && strcmp(mode, "close") && strcmp(mode, "open"))
        return usage();
    char *end;
    unsigned long mask = strtoul(argv[2], &end, 0);
    if (*end || mask > 0xffffffffUL) return usage();
    rig_lamp_line_t lamps[32];
    int n = argc - 3;
    if (n > 32) return usage();
    for (int i = 0; i < n; i++)
        if (!parse_lamp(argv[3 + i], &lamps[i])) return usage();
    model_error_quiet(true);

    bool safety = !strcmp(mode, "hold") || !strcmp(mode, "exit");
    if (safety) rig_safety_install();
    rig_lamps_t *l = NULL;
    int err = rig_lamps_open_gpiod(&l, lamps, n);
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
    for (int i = 0; i < 200; i++) usleep(100000);
    rig_lamps_close(l);
    return 0;
}
