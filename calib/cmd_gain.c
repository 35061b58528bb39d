// calib/cmd_gain.c — `refl calib gain`: parses the options (model/base/opts.h),
// runs calib_gain_run (calib/gain/gain.h) and prints the reference gain's figures.
// Exit: 0 done, 1 error (printed once here), 2 usage, 3 paused (an operator step).
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/gain/gain.h"
#include "model/model.h"
#include "model/base/opts.h"

#define ABOUT                                                                                                  \
    "Sensitivity of a camera, EMVA 1288 Release 4.0 Linear: photon transfer (system gain K, temporal dark\n"  \
    "noise, saturation, SNR, dynamic range), linearity error (Release 4.0's, and Release 3's beside it),\n"    \
    "with --irradiance the photon axis (quantum efficiency, responsivity, absolute sensitivity threshold\n"    \
    "and saturation in photons, SNR against photons), dark current from the mean and the variance, DSNU\n"    \
    "and PRNU split into row, column and pixel parts, spectrograms, profiles, defect pixels, and the\n"       \
    "summary datasheet (gain.json \"emva1288\", DIR/datasheet.html); also the response linearisation (a\n"   \
    "monotone table measured signal -> linear signal) and the response kc per us per unit radiance at\n"     \
    "each gain. Writes DIR/gain.json, DIR/offset_dn.tiff, dsnu_dn.tiff, prnu_gain.tiff (total flat field\n"  \
    "incl. vignetting, mean 1), prnu_highpass.tiff (smooth part removed), defects.tiff (0 good, 1 hot,\n"     \
    "2 dead, 3 bright), DIR/report.html and DIR/datasheet.html; of a rig or sessions of several cameras,\n"  \
    "every camera's into DIR/NAME/ (DIR/gain.json and maps: also the first camera's). The frames come\n"      \
    "from one of:\n"                                                                                          \
    "  --rig RIG -o DIR                          captured here (the sample is a uniform source filling\n"      \
    "                                            the view)\n"                                                   \
    "  --frames MANIFEST.csv -o DIR              lines file,exposure_us,kind; kind dark|light: the sweep\n"    \
    "                                            (light exposures need frame pairs), flat|flat-dark: the\n"    \
    "                                            spatial set, many frames at one level (DSNU, PRNU, defects;\n" \
    "                                            aliases spatial-light|spatial-dark); optional header line;\n"  \
    "                                            paths relative to the manifest; PNG, JPEG or TIFF\n"           \
    "  --session DIR [--session DIR ...] -o DIR  sessions captured elsewhere (light = lamps on, dark = none)\n"    \
    "  --emva-descriptor FILE -o DIR             an EMVA 1288 descriptor (the standard's data exchange: v, n,\n"  \
    "                                            b EXPOSURE_NS PHOTONS, d EXPOSURE_NS and i PATH lines): its\n"   \
    "                                            photon counts are the photon axis, no irradiance needed\n"       \
    "                                            (--pixel-area-um2: the per-area rows too)\n"                    \
    "The datasheet's rows are the standard's definitions (gain.json \"emva1288\", with each row's section);\n" \
    "the top-level figures and \"refl_rows\" are refl's own (the small-signal K, the high-pass PRNU, the\n"  \
    "linearisation). --write-emva-descriptor FILE writes a descriptor of the run's frames for other tools."

#define EPILOG                                                                                                 \
    "kc needs the source's radiance (--radiance); a virtual rig's truth is never read (refl chain\n"         \
    "compares the calibration with it). With --rig each session begins with an operator step (the\n"       \
    "flat-field source in front of the lens; for the dark frames its lamps off, the lens shaded): Enter\n"  \
    "on a terminal, --yes or --operator-input FILE answers it; with stdin not a terminal and neither\n"     \
    "option the command pauses there (exit 3; run it again to continue). Exit: 0 done, 1 error, 2 usage,\n" \
    "3 paused."

// The exit status of an allocation that failed, said once.
static int out_of_memory(void)
{
    model_error_set(NULL, 0, "out of memory");
    return model_error_report("calib gain");
}

// A comma-separated list of numbers (malloc'ed); false when empty or not
// numbers, or out of memory (*oom set).
static bool parse_list(const char *s, double **out, int *n, bool *oom)
{
    *n = 0;
    *out = NULL;
    char *c = strdup(s), *save = NULL;
    bool ok = c != NULL;
    *oom = !c;
    for (char *p = c ? strtok_r(c, ", ", &save) : NULL; p; p = strtok_r(NULL, ", ", &save)) {
        double v, *g;
        if (!model_parse_double(p, &v)) {
            ok = false;
            break;
        }
        if (!(g = realloc(*out, sizeof(double) * (*n + 1)))) {
            ok = false;
            *oom = true;
            break;
        }
        *out = g;
        (*out)[(*n)++] = v;
    }
    free(c);
    return ok && *n > 0;
}

// Whole numbers >= lo and positive numbers, with the command's own messages.
static int numbers(model_cli_t *c, calib_gain_opts_t *o)
{
    static const char *const ints[] = { "--steps", "--flat-frames", "--min-steps", "--max-dn" };
    static const char *const pos[] = { "--probe-exposure-us", "--max-exposure-us", "--radiance", "--quant-dn" };
    int *idst[] = { &o->steps, &o->flat_frames, &o->min_steps, &o->max_dn };
    const int ilo[] = { 2, 2, 6, 1 };
    double *pdst[] = { &o->probe_us, &o->max_us, &o->radiance, &o->quant_dn };
    for (int k = 0; k < 4; k++) {
        const char *v = model_cli_value(c, ints[k]);
        long lv;
        if (v && (!model_parse_int(v, &lv) || lv < ilo[k] || lv > 1000000))
            return model_cli_error(c, "%s '%s' must be an integer >= %d", ints[k], v, ilo[k]);
        if (v) *idst[k] = (int)lv;
        v = model_cli_value(c, pos[k]);
        double dv;
        if (v && (!model_parse_double(v, &dv) || !(dv > 0)))
            return model_cli_error(c, "%s '%s' must be a positive number", pos[k], v);
        if (v) *pdst[k] = dv;
    }
    return 0;
}

// The photon axis (--irradiance with the pixel's area or pitch and the
// wavelength, all or none) and the defect threshold.
static int photon_options(model_cli_t *c, calib_gain_opts_t *o)
{
    static const char *const names[] = { "--irradiance", "--pixel-area-um2", "--pixel-pitch-um", "--wavelength-nm",
                                         "--defect-sigma", "--photodiode-na", "--photodiode-a-per-w",
                                         "--photodiode-mm2" };
    double v[8] = { NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN };
    for (int k = 0; k < 8; k++) {
        const char *s = model_cli_value(c, names[k]);
        if (s && (!model_parse_double(s, &v[k]) || !(v[k] > 0) || !isfinite(v[k])))
            return model_cli_error(c, "%s '%s' must be a positive number", names[k], s);
    }
    if (isfinite(v[1]) && isfinite(v[2]))
        return model_cli_error(c, "give --pixel-area-um2 or --pixel-pitch-um, not both");
    int pd = isfinite(v[5]) + isfinite(v[6]) + isfinite(v[7]);
    if (pd && pd != 3)
        return model_cli_error(c, "a photodiode reading needs all of --photodiode-na, --photodiode-a-per-w and "
                               "--photodiode-mm2");
    if (pd && isfinite(v[0]))
        return model_cli_error(c, "give --irradiance or a photodiode reading (--photodiode-na ...), not both");
    if (pd) v[0] = calib_gain_photodiode_irradiance(v[5], v[6], v[7]);
    o->photodiode_na = v[5];
    o->photodiode_a_per_w = v[6];
    o->photodiode_mm2 = v[7];
    double area = isfinite(v[1]) ? v[1] : v[2] * v[2];
    if (o->descriptor) {   // its photon counts are the photon axis: the area and wavelength only stated
        if (isfinite(v[0]))
            return model_cli_error(c, "--emva-descriptor gives each step's photon count: no --irradiance or "
                                   "photodiode reading");
        o->pixel_area_um2 = area;
        o->wavelength_nm = v[3];
        if (isfinite(v[4])) o->defect_sigma = v[4];
        return 0;
    }
    int given = isfinite(v[0]) + isfinite(area) + isfinite(v[3]);
    if (given && given != 3)
        return model_cli_error(c, "the photon axis needs all of --irradiance, --pixel-area-um2 (or "
                               "--pixel-pitch-um) and --wavelength-nm");
    o->irradiance_uw_cm2 = v[0];
    o->pixel_area_um2 = area;
    o->wavelength_nm = v[3];
    if (isfinite(v[4])) o->defect_sigma = v[4];
    return 0;
}

// The lists, the region and the one source.
static int check_options(model_cli_t *c, calib_gain_opts_t *o, double **gains, double **darks)
{
    int rc = numbers(c, o);
    if (rc) return rc;
    if (!o->out || (!!o->rig + !!o->frames + (o->nsessions > 0) + !!o->descriptor) != 1)
        return model_cli_error(c, "give -o DIR and exactly one of --rig, --frames, --session, --emva-descriptor");
    if (o->descriptor && o->camera)
        return model_cli_error(c, "--camera selects a camera of a rig or sessions, not of --emva-descriptor");
    if (o->frames && o->camera)
        return model_cli_error(c, "--camera selects a camera of a rig or sessions, not of --frames");
    const char *roi = model_cli_value(c, "--roi"), *gs = model_cli_value(c, "--gains");
    const char *ds = model_cli_value(c, "--dark-exposures-us");
    int *r = o->roi;
    if (roi && (sscanf(roi, "%d,%d,%d,%d", &r[0], &r[1], &r[2], &r[3]) != 4 || r[0] < 0 || r[1] < 0 || r[2] < 2 ||
                r[3] < 2))
        return model_cli_error(c, "--roi '%s' must be X,Y,W,H (W, H >= 2)", roi);
    bool oom = false;
    if (gs && !parse_list(gs, gains, &o->ngains, &oom))
        return oom ? out_of_memory() : model_cli_error(c, "--gains '%s' must be a comma-separated list of numbers (dB)",
                                                       gs);
    if (ds && !parse_list(ds, darks, &o->ndark_exposures, &oom))
        return oom ? out_of_memory()
                   : model_cli_error(c, "--dark-exposures-us '%s' must be a comma-separated list of us", ds);
    const char *ls = model_cli_value(c, "--low-steps");
    long lv;
    if (ls && (!model_parse_int(ls, &lv) || lv < 0 || lv > 1000))
        return model_cli_error(c, "--low-steps '%s' must be an integer 0..1000", ls);
    if (ls) o->low_steps = (int)lv;
    const char *lin = model_cli_value(c, "--linearisation");
    if (lin && strcmp(lin, "monotone") && strcmp(lin, "parametric"))
        return model_cli_error(c, "--linearisation '%s' must be monotone or parametric", lin);
    if (lin) o->linearisation = strcmp(lin, "monotone") ? MODEL_LIN_PARAMETRIC : MODEL_LIN_MONOTONE;
    rc = photon_options(c, o);
    if (rc) return rc;
    if (o->write_descriptor && !o->descriptor && !isfinite(o->irradiance_uw_cm2))
        return model_cli_error(c, "--write-emva-descriptor needs each step's photon count: give --irradiance (or a "
                               "photodiode reading), --pixel-area-um2 and --wavelength-nm");
    if (*gains) o->gains_db = *gains;
    if (*darks) o->dark_exposures_us = *darks;
    return 0;
}

int calib_cmd_gain(int argc, char **argv)
{
    calib_gain_opts_t o = calib_gain_defaults();
    bool no_report = false, yes = false;
    const char *operator_input = NULL;
    const char **session_v = calloc((size_t)argc + 1, sizeof *session_v);
    model_opt_list_t sessions = { session_v, 0, argc + 1 };
    if (!session_v) return model_error_report("calib gain");
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--rig", "RIG", "capture on this rig", &o.rig, false),
        MODEL_OPT_STRING("--frames", "MANIFEST.csv", "frames listed in a manifest", &o.frames, false),
        MODEL_OPT_STRING("--emva-descriptor", "FILE", "frames of an EMVA 1288 descriptor file (exposures in ns, each "
                         "step's photon count, image paths relative to the file, '/' or '\\')", &o.descriptor, false),
        MODEL_OPT_STRING("--write-emva-descriptor", "FILE", "also write an EMVA 1288 descriptor of the run's frames "
                         "(the sweep's pairs and the spatial set; paths relative to FILE; needs the photon counts)",
                         &o.write_descriptor, false),
        MODEL_OPT_LIST("--session", "DIR", "a session captured elsewhere; repeat it for more", &sessions, false,
                       false),
        MODEL_OPT_OUT("DIR", "the output directory", &o.out, false, .old = "--output"),
        MODEL_OPT_VALUE("--gains", "LIST", "gains (camera unit, dB) to sweep, comma-separated (default 0); the first "
                        "is the reference (dark current, maps, top-level figures). With --frames: one value, the gain "
                        "the frames were taken at (a label)", false),
        MODEL_OPT_VALUE("--steps", "N", "exposure steps of each sweep (default 50, at least --min-steps)", false),
        MODEL_OPT_VALUE("--low-steps", "N", "more steps at the sweep's low end, geometric from 0.2 % to 12 % of its "
                        "longest exposure (default 16; 0 none): the linearisation's knots there", false),
        MODEL_OPT_STRING("--camera", "NAME", "calibrate this camera of the rig or sessions only (default every "
                         "camera)", &o.camera, false),
        MODEL_OPT_STRING("--sample", "NAME", "the plan's sample (default flat_field)", &o.sample, false),
        MODEL_OPT_STRING("--lamps-on", "NAMES", "lamps feeding the source: NAME,NAME,... (or NAME+NAME, as a "
                         "plan's lamp set) or all (default all)", &o.lamps, false, .old = "--lamps"),
        MODEL_OPT_VALUE("--probe-exposure-us", "US", "first probe exposure (default 1000)", false),
        MODEL_OPT_VALUE("--max-exposure-us", "US", "longest sweep exposure (default 1.2 x the probe's full-scale "
                        "estimate)", false),
        MODEL_OPT_VALUE("--flat-frames", "N", "light and dark frames of the flat field (default 16)", false),
        MODEL_OPT_VALUE("--dark-exposures-us", "LIST", "long dark exposures for the dark current (default 100000,"
                        "500000,1000000,2000000)", false),
        MODEL_OPT_STRING("--pixel-format", "F", "Mono8|Mono12|Mono16 (default Mono12)", &o.pixel_format, false),
        MODEL_OPT_VALUE("--min-steps", "N", "fewest sweep steps accepted (default 50, EMVA 1288)", false),
        MODEL_OPT_VALUE("--radiance", "R", "radiance of the source with the lamps on, in the unit of the lab's "
                        "meter (e.g. W/(sr m^2); a virtual rig's: its truth's radiance units): kc is DN per us per "
                        "that unit, and every kc*I after it; no default: without it, no kc", false),
        MODEL_OPT_VALUE("--roi", "X,Y,W,H", "pixels of the statistics (default the whole frame; maps are whole)",
                        false),
        MODEL_OPT_VALUE("--max-dn", "N", "full scale of manifest frames (default 65535)", false),
        MODEL_OPT_VALUE("--quant-dn", "Q", "quantisation step in DN (default 1; 16 for 12-bit data in Mono16)", false),
        MODEL_OPT_VALUE("--linearisation", "M", "monotone|parametric: the response linearisation every consumer of "
                        "gain.json applies (default monotone: a monotone table of the sweep; parametric: S_m = "
                        "S (1 - a S)); both are written", false),
        MODEL_OPT_VALUE("--irradiance", "E", "irradiance at the sensor in uW/cm^2 during the light frames (constant "
                        "over the sweep): with the pixel area and the wavelength, the photon axis mu_p = A E t lambda "
                        "/ (h c) and from it quantum efficiency, responsivity, sensitivity threshold and saturation "
                        "in photons (without it: \"not measured\")", false),
        MODEL_OPT_VALUE("--pixel-area-um2", "A", "the pixel's light-sensitive area in um^2 (or --pixel-pitch-um)",
                        false),
        MODEL_OPT_VALUE("--pixel-pitch-um", "P", "the pixel pitch in um: area P^2", false),
        MODEL_OPT_VALUE("--wavelength-nm", "L", "the light's (centre) wavelength in nm", false),
        MODEL_OPT_VALUE("--photodiode-na", "I", "instead of --irradiance: the current in nA of a photodiode in the "
                        "sensor's place, with --photodiode-a-per-w (its responsivity at the wavelength, A/W) and "
                        "--photodiode-mm2 (its area): E = I / (R S)", false),
        MODEL_OPT_VALUE("--photodiode-a-per-w", "R", "the photodiode's responsivity at the wavelength, A/W", false),
        MODEL_OPT_VALUE("--photodiode-mm2", "S", "the photodiode's area, mm^2", false),
        MODEL_OPT_VALUE("--defect-sigma", "N", "defect pixels: deviation from the median beyond N robust standard "
                        "deviations (default 6)", false),
        MODEL_OPT_FLAG("--no-report", NULL, "skip the plots and report.html", &no_report),
        RIG_OPERATOR_OPTS(&yes, &operator_input),
    };
    model_cli_t cli = { .cmd = "calib gain", .synopsis = "", .about = ABOUT, .epilog = EPILOG, .opts = opts,
                        .nopts = MODEL_NOPTS(opts), .min_positional = 0, .max_positional = 0, .repeat_ok = true };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) {
        free(session_v);
        return rc;
    }
    double *gains = NULL, *darks = NULL;
    char lamp_set[1024];   // --lamps-on's comma list as the plan's lamp set (NAME+NAME)
    if (o.lamps && strchr(o.lamps, ',') && strlen(o.lamps) < sizeof lamp_set) {
        snprintf(lamp_set, sizeof lamp_set, "%s", o.lamps);
        for (char *p = lamp_set; (p = strchr(p, ',')); p++) *p = '+';
        o.lamps = lamp_set;
    }
    o.sessions = session_v;
    o.nsessions = sessions.n;
    o.report = !no_report;
    o.argc = argc;
    o.argv = argv;
    if (!(rc = check_options(&cli, &o, &gains, &darks)) && !(o.op = rig_operator_open(yes, operator_input)))
        rc = yes ? model_cli_error(&cli, "give --yes or --operator-input FILE, not both")
                 : model_error_report("calib gain");
    if (!rc) {
        static calib_gain_result_t rs[CALIB_GAIN_MAX_CAMERAS];
        int n = 0;
        bool q = model_error_quiet_thread(true);   // the library's message is printed once, here
        bool ok = calib_gain_run(&o, rs, CALIB_GAIN_MAX_CAMERAS, &n);
        model_error_quiet_thread(q);
        for (int k = 0; ok && k < n; k++) {
            const calib_gain_result_t *r = &rs[k];
            if (n > 1) printf("camera %s %s/gain.json\n", r->camera, r->dir);
            printf("system_gain_dn_per_e %.6g\nread_noise_e %.5g\nsaturation_dn %.2f\nlinearity_error_pct %.4f\n"
                   "dsnu_dn %.4f\nprnu_pct %.4f\n", r->system_gain_dn_per_e, r->read_noise_e, r->saturation_dn,
                   r->linearity_error_pct, r->dsnu_dn, r->prnu_pct);
        }
        if (!ok)
            fprintf(stderr, "refl calib gain: failed: %s\n", model_last_error());
        rc = ok ? MODEL_EXIT_OK : rig_operator_paused(o.op) ? MODEL_EXIT_PAUSED : MODEL_EXIT_ERROR;
    }
    rig_operator_close(o.op);
    free(gains);
    free(darks);
    free(session_v);
    return rc;
}
