// rig/main.c — bin/refl: the rig controller's command dispatcher.
#include <stdio.h>
#include <string.h>

#include "model/model.h"
#include "calib/calib.h"
#include "fit/fit.h"
#include "fit/verify.h"
#include "fit/lightplan.h"
#include "rig/rig.h"

typedef struct {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} command_t;

static const command_t commands[] = {
    { "render", model_cmd_render, "render a scene through the imaging model to a PNG/TIFF image" },
    { "edges",  model_cmd_edges,  "list scene edges: visible image segments, lighting per side, contrast" },
    { "workpiece", model_cmd_workpiece, "write the reference workpiece (T/I/no stiffener, shifted, rotated, scaled) as D3D" },
    { "rig",    rig_cmd,          "drive the rig of a rig file: status, home, move, identify, snap, serve" },
    { "capture", rig_cmd_capture, "run a capture plan on the rig into a session directory (journal + frames)" },
    { "session", rig_cmd_session, "check a session's frames against their hashes, export its frame table" },
    { "calib",   calib_cmd,       "calibrate camera geometry and turntable axis, lamp positions, sensitivity" },
    { "fit",     fit_cmd,         "fit reflection models to BRDF samples and write priors" },
    { "verify",  verify_cmd,      "verify a scene description against images: fit within the priors, residue, changes, verdict" },
    { "plan",    lightplan_cmd,   "plan lamps: choose the lamp set and exposure for detectable edges, no glare or saturation" },
};

static void usage(FILE *f)
{
    fprintf(f, "usage: refl COMMAND [ARGS...]   (refl COMMAND --help for its options)\n\ncommands:\n");
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        fprintf(f, "  %-8s %s\n", commands[i].name, commands[i].summary);
    fprintf(f, "\nrefl %s\n", REFL_VERSION);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h") || !strcmp(argv[1], "help")) {
        usage(stdout);
        return 0;
    }
    if (!strcmp(argv[1], "--version")) {
        printf("refl %s\n", REFL_VERSION);
        return 0;
    }
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(argv[1], commands[i].name)) return commands[i].run(argc - 1, argv + 1);
    fprintf(stderr, "refl: unknown command '%s'\n", argv[1]);
    usage(stderr);
    return 2;
}
