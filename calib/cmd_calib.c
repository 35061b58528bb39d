// calib/cmd_calib.c — `refl calib geometry|lamps|gain`: dispatches to the
// calibrations (calib/geometry.c, calib/lamps.c, calib/gain.c).
#include <stdio.h>
#include <string.h>

#include "calib/calib.h"
#include "fit/material.h"
#include "model/model.h"

static const struct {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} subs[] = {
    { "geometry", calib_cmd_geometry, "camera model (mrgingham + mrcal) and turntable axis from chessboard views" },
    { "lamps",    calib_cmd_lamps,    "lamp positions from mirror-sphere highlights, with uncertainty in mm" },
    { "white",    fit_cmd_white,      "kc*I per lamp from a reference-white session (fit/material.c)" },
    { "gain",     calib_cmd_gain,     "sensitivity (EMVA 1288): dark, photon transfer, linearity, PRNU/DSNU maps" },
};

static void usage(FILE *f)
{
    fprintf(f, "usage: refl calib geometry|lamps|gain|white [ARGS...]   (refl calib NAME --help for its options)\n\n");
    for (size_t i = 0; i < sizeof subs / sizeof subs[0]; i++) fprintf(f, "  %-9s %s\n", subs[i].name, subs[i].summary);
    fprintf(f, "\nrefl %s\n", REFL_VERSION);
}

int calib_cmd(int argc, char **argv)
{
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        usage(stdout);
        return 0;
    }
    for (size_t i = 0; i < sizeof subs / sizeof subs[0]; i++)
        if (!strcmp(argv[1], subs[i].name)) return subs[i].run(argc - 1, argv + 1);
    fprintf(stderr, "refl calib: unknown calibration '%s'\n", argv[1]);
    usage(stderr);
    return 2;
}
