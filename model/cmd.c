// model/cmd.c — the `refl render` and `refl edges` commands (refl render's work
// is model_render_file, model/render/file.c).
//
// Both parse their options strictly (an unknown option, a missing value, a
// bad number or a missing required option is a usage error: exit 2), load the
// inputs through the library (whose messages name file and line: exit 1), and
// write outputs that carry their units, conventions and provenance (every
// input path with its sha256, the refl version, the UTC date, the command line).
#define _GNU_SOURCE
#include <ctype.h>
#include <errno.h>
#include <unistd.h>
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include "model/internal.h"
#include "model/base/opts.h"

#define UNITS_P        MODEL_UNITS_P
#define PIXEL_CONV     MODEL_PIXEL_CONV
#define FRAMES_TEXT    MODEL_FRAMES_TEXT

static bool ends_with_ci(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcasecmp(s + n - m, suffix);
}

static bool is_tiff_name(const char *s) { return ends_with_ci(s, ".tif") || ends_with_ci(s, ".tiff"); }

#define SCENE_ABOUT                                                                                              \
    "SCENE: D3D or Wavefront OBJ (told by the name: .d3d, .obj), STL (binary or ASCII) or PLY (ASCII or\n"         \
    "binary little-endian) (told by the content); rig frame, in mm unless --units says m or in."

// Options render and edges share: the scene's inputs, the grey value's
// offset and scale, and the view (rows of a model_opt_t table).
#define SCENE_INPUT_OPTS                                                                                           \
    MODEL_OPT_VALUE("--camera-model", "CAM.cameramodel", "camera model (mrcal); its extrinsics place it in the rig " \
                    "frame", true, .old = "--camera"),                                                             \
    MODEL_OPT_VALUE("--lamps-file", "LAMPS.ini",                                                                   \
                    "lamps: [lamp NAME] position_mm, intensity, radius_mm, emission_cos_power, emission_axis",     \
                    true, .old = "--lamps"),                                                                       \
    MODEL_OPT_VALUE("--materials", "MATS.ini", "materials: [material NAME] model and parameters", true),           \
    MODEL_OPT_UNITS
#define SHADING_OPTS                                                                                               \
    MODEL_OPT_VALUE("--kc", "K", "camera parameter kc, DN per radiance unit (default 1)", false),                  \
    MODEL_OPT_VALUE("--offset", "PA", "offset Pa, DN (default 0)", false)
#define VIEW_OPTS                                                                                                  \
    MODEL_OPT_VALUE("--angle-deg", "A", "turntable angle: the scene is rotated by A deg about the rig's z axis "   \
                    "(default 0)", false, .old = "--turntable-deg"),                                               \
    MODEL_OPT_VALUE("--threads", "N", "worker threads (default 0: REFL_THREADS, else every online CPU)", false),   \
    MODEL_OPT_VALUE("--planarity-tol-mm", "T", "max distance of a face's vertex from its plane, mm (default 0.01)", \
                    false)

// ---------------------------------------------------------------------------
// refl render

int model_cmd_render(int argc, char **argv)
{
    model_opt_t opts[] = {
        SCENE_INPUT_OPTS,
        MODEL_OPT_OUT("OUT", "output image: .png (16-bit, P rounded and clipped to 0..65535) or .tif/.tiff (float32 P)", NULL, true),
        SHADING_OPTS,
        MODEL_OPT_VALUE("--gain-map", "G.tiff", "per-pixel relative sensitivity g(x,y) (float TIFF, camera size, mean 1)", false),
        MODEL_OPT_VALUE("--interreflection", "MODE", "none | thesis | mc (default none)", false),
        MODEL_OPT_VALUE("--rho", "R", "thesis interreflection: weight of the virtual sources (default 0.05)", false),
        MODEL_OPT_VALUE("--mc-samples", "N", "mc: paths per pixel (default 16)", false),
        MODEL_OPT_VALUE("--mc-bounces", "N", "mc: indirect bounces (default 2)", false),
        MODEL_OPT_VALUE("--seed", "N", "mc: random seed (default 1)", false),
        MODEL_OPT_VALUE("--sensor", "SENSOR.ini", "apply the sensor stage (noise, quantisation) after the physics", false),
        VIEW_OPTS,
        MODEL_OPT_VALUE("--info", "INFO.tiff", "multi-page TIFF: ideal P (float32), face id (int32), lit mask per lamp (uint8)", false),
    };
    model_cli_t c = { .cmd = "render", .synopsis = "SCENE", .opts = opts, .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
    c.about = SCENE_ABOUT;
    c.epilog = "P = Pa + kc * g(x,y) * [sum_i V_i I_i R_i / d_i^2 + interreflection], in DN.\n"
               "Pixel convention: " PIXEL_CONV ".";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;

    model_render_file_opts_t o = {
        .scene = c.positional[0], .camera = model_cli_value(&c, "--camera-model"),
        .lamps = model_cli_value(&c, "--lamps-file"),
        .materials = model_cli_value(&c, "--materials"), .gain_map = model_cli_value(&c, "--gain-map"),
        .sensor = model_cli_value(&c, "--sensor"), .out = model_cli_value(&c, "-o"),
        .info = model_cli_value(&c, "--info"), .shading = model_shading_default(),
        .planarity_tol_mm = MODEL_SCENE_OPTIONS_DEFAULT.planarity_tol_mm,
    };
    model_shading_t *sh = &o.shading;
    long mc_samples = sh->mc_samples, mc_bounces = sh->mc_bounces, seed = (long)sh->seed, threads = 0;
    if ((rc = model_cli_double(&c, "--kc", &sh->kc, 0, false, INFINITY, "kc >= 0")) ||
        (rc = model_cli_double(&c, "--offset", &sh->Pa, -INFINITY, false, INFINITY, "finite")) ||
        (rc = model_cli_double(&c, "--rho", &sh->rho, 0, false, 1, "0 <= rho <= 1")) ||
        (rc = model_cli_long(&c, "--mc-samples", &mc_samples, 1, 1000000)) ||
        (rc = model_cli_long(&c, "--mc-bounces", &mc_bounces, 0, 64)) ||
        (rc = model_cli_long(&c, "--seed", &seed, 0, LONG_MAX)) ||
        (rc = model_cli_long(&c, "--threads", &threads, 0, 256)) ||
        (rc = model_cli_double(&c, "--angle-deg", &o.turntable_deg, -1e6, false, 1e6, "|A| <= 1e6 deg")) ||
        (rc = model_cli_double(&c, "--planarity-tol-mm", &o.planarity_tol_mm, 0, false, INFINITY, "T >= 0")) ||
        (rc = model_cli_units(&c, &o.scene_unit_mm)))
        return rc;
    const char *ir = model_cli_value(&c, "--interreflection");
    if (ir) {
        int m = model_interreflection_from_name(ir);
        if (m < 0) return model_cli_error(&c, "option --interreflection: unknown value '%s' (use none, thesis or mc)", ir);
        sh->interreflection = (model_interreflection_t)m;
    }
    sh->mc_samples = (int)mc_samples;
    sh->mc_bounces = (int)mc_bounces;
    sh->seed = (uint64_t)seed;
    if (!ends_with_ci(o.out, ".png") && !is_tiff_name(o.out))
        return model_cli_error(&c, "option -o: '%s' must end in .png, .tif or .tiff", o.out);
    if (o.info && !is_tiff_name(o.info))
        return model_cli_error(&c, "option --info: '%s' must end in .tif or .tiff", o.info);
    if (threads > 0) {
        char buf[24];
        snprintf(buf, sizeof buf, "%ld", threads);
        setenv("REFL_THREADS", buf, 1);   // the camera's ray table and the renderer follow it
        sh->nthreads = (int)threads;
        o.threads_text = model_cli_value(&c, "--threads");
    }
    char *cmdline = model_command_line(argc, argv);
    o.command_line = cmdline;
    model_render_file_result_t r;
    bool ok = model_render_file(&o, &r);
    g_free(cmdline);
    if (!ok) return 1;   // the library's message names the input at fault
    if (r.clipped_low || r.clipped_high || r.clipped_nan)
        fprintf(stderr, "refl render: warning: %zu pixels clipped to [0, 65535] in %s (%zu below 0, %zu above "
                "65535, %zu not a number); write a .tiff to keep the float values\n",
                r.clipped_low + r.clipped_high + r.clipped_nan, o.out, r.clipped_low, r.clipped_high, r.clipped_nan);
    printf("refl render: %s -> %s\n", o.scene, o.out);
    printf("  image %d x %d px, %d faces, %d lamps, interreflection %s%s\n", r.width, r.height, r.nfaces, r.nlamps,
           model_interreflection_name(r.interreflection), o.sensor ? ", sensor stage applied" : "");
    printf("  time %.2f s (render %.2f s)\n", r.time_s, r.render_s);
    printf("  P (DN): min %.1f  mean %.1f  max %.1f;  background %.1f %% of the pixels\n", r.p_min, r.p_mean,
           r.p_max, 100.0 * r.background_frac);
    printf("  wrote %s (%s)\n", o.out, r.png ? "16-bit PNG" : "float32 TIFF");
    if (o.info) printf("  wrote %s (info TIFF: P, face id, lit masks)\n", o.info);
    return 0;
}

// ---------------------------------------------------------------------------
// refl edges

int model_cmd_edges(int argc, char **argv)
{
    model_opt_t opts[] = {
        SCENE_INPUT_OPTS,
        SHADING_OPTS,
        MODEL_OPT_VALUE("--feature-angle-deg", "A", "skip edges between faces whose normals differ by A deg or less (default 1)", false),
        VIEW_OPTS,
        MODEL_OPT_VALUE("--json", "OUT.json", "write the edges, units and provenance as JSON", false),
    };
    model_cli_t c = { .cmd = "edges", .synopsis = "SCENE", .opts = opts, .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
    c.about = SCENE_ABOUT;
    c.epilog = "One line per visible image segment of a scene edge: its 3D end points (mm, rig frame), faces,\n"
               "image end points (px, " PIXEL_CONV "),\nlength, lamps lighting each side (one character per lamp in "
               "file order: 1 lit, . not), the\npredicted grey value 2 px to each side (DN; direct term only) and the "
               "contrast P0 - P1.\nSide 0 lies to the right of q0 -> q1 in the displayed image (y down).";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    model_edges_file_opts_t o = {
        .scene = c.positional[0], .camera = model_cli_value(&c, "--camera-model"),
        .lamps = model_cli_value(&c, "--lamps-file"),
        .materials = model_cli_value(&c, "--materials"), .shading = model_shading_default(),
        .planarity_tol_mm = MODEL_SCENE_OPTIONS_DEFAULT.planarity_tol_mm, .feature_angle_deg = 1,
    };
    long threads = 0;
    if ((rc = model_cli_double(&c, "--kc", &o.shading.kc, 0, false, INFINITY, "kc >= 0")) ||
        (rc = model_cli_double(&c, "--offset", &o.shading.Pa, -INFINITY, false, INFINITY, "finite")) ||
        (rc = model_cli_double(&c, "--feature-angle-deg", &o.feature_angle_deg, 0, false, 179.999, "0 <= A < 180")) ||
        (rc = model_cli_double(&c, "--angle-deg", &o.turntable_deg, -1e6, false, 1e6, "|A| <= 1e6 deg")) ||
        (rc = model_cli_long(&c, "--threads", &threads, 0, 256)) ||
        (rc = model_cli_double(&c, "--planarity-tol-mm", &o.planarity_tol_mm, 0, false, INFINITY, "T >= 0")) ||
        (rc = model_cli_units(&c, &o.scene_unit_mm)))
        return rc;
    if (threads > 0) {
        char buf[24];
        snprintf(buf, sizeof buf, "%ld", threads);
        setenv("REFL_THREADS", buf, 1);
        o.shading.nthreads = (int)threads;
    }
    const char *json_path = model_cli_value(&c, "--json");
    char *cmdline = model_command_line(argc, argv);
    o.command_line = cmdline;
    model_edges_file_t *f = model_edges_file_predict(&o);   // its message names the input at fault
    if (f) model_edges_file_print(stdout, f, &o);
    bool ok = f && (!json_path || model_edges_file_write_json(f, &o, json_path));
    if (ok && json_path) printf("wrote %s\n", json_path);
    model_edges_file_free(f);
    g_free(cmdline);
    return ok ? 0 : 1;
}

// ---------------------------------------------------------------------------
// refl workpiece

int model_cmd_workpiece(int argc, char **argv)
{
    model_opt_t opts[] = {
        MODEL_OPT_VALUE("--kind", "T|I|none", "stiffener: T (web and flange), I (flat bar) or none (plate only); default T", false),
        MODEL_OPT_VALUE("--shift-mm", "DX,DY", "shift the stiffener by DX, DY mm (default 0,0)", false),
        MODEL_OPT_VALUE("--rotate-deg", "A", "rotate the stiffener by A deg about z through its centre (default 0)", false),
        MODEL_OPT_VALUE("--height-scale", "S", "scale the stiffener's height above the plate by S (default 1)", false),
        MODEL_OPT_VALUE("--plate-material", "NAME", "material of the plate (default plywood)", false),
        MODEL_OPT_VALUE("--stiffener-material", "NAME", "material of the stiffener (default painted_steel)", false),
        MODEL_OPT_OUT("OUT.d3d", "the D3D scene to write (required; also accepted as the one argument)", NULL,
                      false),
    };
    model_cli_t c = { .cmd = "workpiece", .synopsis = "", .opts = opts, .nopts = MODEL_NOPTS(opts),
                      .min_positional = 0, .max_positional = 1 };
    c.about = "Writes the reference workpiece of thesis ch. 6 as a D3D scene: a 400 x 300 x 10 mm plate with\n"
              "a stiffener 88 mm high and 260 mm long along y (T: 8 mm web under a 60 x 8 mm flange). The\n"
              "defaults give examples/t_stiffener.d3d; the options make the wrong descriptions the\n"
              "verification is tested with (I-stiffener, none, shifted, rotated, wrong height).";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    const char *out = model_cli_value(&c, "-o");
    if (c.npositional && out) return model_cli_error(&c, "unexpected argument '%s' (-o %s given)", c.positional[0], out);
    if (c.npositional) {   // the old spelling: the output as the argument
        out = c.positional[0];
        model_note("OUT.d3d as an argument: the option is -o, --out (the old spelling still works)");
    }
    if (!out) return model_cli_error(&c, "missing -o OUT.d3d");
    model_stiffener_t p = model_stiffener_default();
    const char *k = model_cli_value(&c, "--kind");
    if (k) {
        int kind = model_stiffener_kind_from_name(k);
        if (kind < 0) return model_cli_error(&c, "option --kind: '%s' is not T, I or none", k);
        p.kind = (model_stiffener_kind_t)kind;
    }
    const char *sh = model_cli_value(&c, "--shift-mm");
    if (sh) {
        char *comma = strchr(sh, ',');
        char a[64] = "", b[64] = "";
        if (comma && (size_t)(comma - sh) < sizeof a && strlen(comma + 1) < sizeof b) {
            memcpy(a, sh, (size_t)(comma - sh));
            strcpy(b, comma + 1);
        }
        if (!comma || !model_parse_double(a, &p.shift_mm[0]) || !model_parse_double(b, &p.shift_mm[1]) ||
            fabs(p.shift_mm[0]) > 1000 || fabs(p.shift_mm[1]) > 1000)
            return model_cli_error(&c, "option --shift-mm: '%s' is not DX,DY in mm (each within +-1000)", sh);
    }
    if ((rc = model_cli_double(&c, "--rotate-deg", &p.rotate_deg, -360, false, 360, "-360..360")) ||
        (rc = model_cli_double(&c, "--height-scale", &p.height_scale, 0, true, 10, "0 < S <= 10")))
        return rc;
    if (model_cli_value(&c, "--plate-material")) p.plate_material = model_cli_value(&c, "--plate-material");
    if (model_cli_value(&c, "--stiffener-material")) p.stiffener_material = model_cli_value(&c, "--stiffener-material");
    char *text = model_stiffener_d3d(&p);
    if (!text) return 1;
    // check that it loads (planarity, outlines) before writing it
    model_scene_t *sc = model_scene_parse_d3d(text, strlen(text), out, NULL);
    if (!sc) {
        free(text);
        return 1;
    }
    model_scene_free(sc);
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", out);
    FILE *f = fopen(tmp, "w");
    bool ok = f && fputs(text, f) >= 0;
    if (f && fclose(f) != 0) ok = false;
    if (ok && rename(tmp, out) != 0) ok = false;
    if (!ok) {
        fprintf(stderr, "refl workpiece: cannot write %s: %s\n", out, strerror(errno));
        unlink(tmp);
        free(text);
        return 1;
    }
    free(text);
    printf("%s: %s-stiffener workpiece\n", out, model_stiffener_kind_name(p.kind));
    return 0;
}
