// model/cmd.c — the `refl render` and `refl edges` commands.
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
#include "model/opts.h"

#define UNITS_P        "P: grey value, DN"
#define PIXEL_CONV     "mrcal: (0,0) is the centre of the top-left pixel, x to the right, y down"
#define FRAMES_TEXT    "world = rig frame (origin at the turntable top centre, z up along the rotation axis, " \
                       "right-handed), mm; the camera model's rt_cam_ref is rt_cam_world; the scene is " \
                       "rotated by the turntable angle about world z before rendering"

static bool ends_with_ci(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcasecmp(s + n - m, suffix);
}

static bool is_tiff_name(const char *s) { return ends_with_ci(s, ".tif") || ends_with_ci(s, ".tiff"); }

// ---------------------------------------------------------------------------
// Provenance and metadata

// An input file: role, path and its sha256.
typedef struct {
    const char *role;
    const char *path;
    char        sha256[65];
} input_t;


static void meta_add_inputs(model_meta_t *m, const input_t *in, int nin)
{
    for (int i = 0; i < nin; i++) {
        if (!in[i].path) continue;
        char key[80];
        snprintf(key, sizeof key, "input_%s", in[i].role);
        model_meta_add(m, key, "%s", in[i].path);
        snprintf(key, sizeof key, "input_%s_sha256", in[i].role);
        model_meta_add(m, key, "%s", in[i].sha256);
    }
}

// BRDF conventions of the materials the scene uses ("name: model (convention); ...").
static char *material_conventions(const model_scene_t *scene, const model_material_t *const *mats)
{
    GString *s = g_string_new("");
    for (int k = 0; k < scene->nmaterials; k++) {
        const model_material_t *mt = mats[k];
        g_string_append_printf(s, "%s%s: %s(", k ? "; " : "", scene->material_names[k], model_brdf_name(mt->model));
        for (int i = 0; i < model_brdf_nparams(mt->model); i++)
            g_string_append_printf(s, "%s%s=%.6g", i ? ", " : "", model_brdf_param_name(mt->model, i), mt->p[i]);
        g_string_append_printf(s, ") [%s]", model_brdf_convention(mt->model));
    }
    return g_string_free(s, FALSE);
}

// ---------------------------------------------------------------------------
// Shared loading

typedef struct {
    model_scene_t           *scene;     // the (possibly rotated) scene
    model_camera_t          *cam;
    model_lamps_t           *lamps;
    model_materials_t       *mats;
    const model_material_t **resolved;  // scene->nmaterials
    model_tracer_t          *tracer;
} inputs_t;

static void inputs_free(inputs_t *in)
{
    model_tracer_free(in->tracer);
    free(in->resolved);
    model_materials_free(in->mats);
    model_lamps_free(in->lamps);
    model_camera_free(in->cam);
    model_scene_free(in->scene);
    memset(in, 0, sizeof *in);
}

static bool inputs_load(inputs_t *in, const char *scene_path, const char *cam_path,
                        const char *lamps_path, const char *mats_path, double planarity_tol_mm,
                        double turntable_deg)
{
    model_scene_options_t so = MODEL_SCENE_OPTIONS_DEFAULT;
    so.planarity_tol_mm = planarity_tol_mm;
    in->scene = model_scene_load(scene_path, &so);
    if (!in->scene) return false;
    if (turntable_deg != 0) {
        model_scene_t *r = model_scene_rotated_z(in->scene, turntable_deg);
        if (!r) return false;
        model_scene_free(in->scene);
        in->scene = r;
    }
    if (!(in->cam = model_camera_load(cam_path))) return false;
    if (!(in->lamps = model_lamps_load(lamps_path))) return false;
    if (!(in->mats = model_materials_load(mats_path))) return false;
    in->resolved = calloc((size_t)(in->scene->nmaterials > 0 ? in->scene->nmaterials : 1), sizeof *in->resolved);
    if (!in->resolved) {
        MODEL_FAIL("out of memory");
        return false;
    }
    if (!model_resolve_materials(in->scene, in->mats, in->resolved)) return false;
    if (!(in->tracer = model_tracer_new(in->scene))) return false;
    return true;
}

static bool hash_inputs(input_t *in, int n)
{
    for (int i = 0; i < n; i++)
        if (in[i].path && !model_sha256_file(in[i].path, in[i].sha256)) return false;
    return true;
}

// Options render and edges share: the scene's inputs, the grey value's
// offset and scale, and the view (rows of a model_opt_t table).
#define SCENE_INPUT_OPTS                                                                                           \
    MODEL_OPT_VALUE("--camera", "CAM.cameramodel", "camera model (mrcal); its extrinsics place it in the rig frame", \
                    true),                                                                                         \
    MODEL_OPT_VALUE("--lamps", "LAMPS.ini", "lamps: [lamp NAME] position_mm, intensity, radius_mm", true),         \
    MODEL_OPT_VALUE("--materials", "MATS.ini", "materials: [material NAME] model and parameters", true)
#define SHADING_OPTS                                                                                               \
    MODEL_OPT_VALUE("--kc", "K", "camera parameter kc, DN per radiance unit (default 1)", false),                  \
    MODEL_OPT_VALUE("--offset", "PA", "offset Pa, DN (default 0)", false)
#define VIEW_OPTS                                                                                                  \
    MODEL_OPT_VALUE("--turntable-deg", "A",                                                                        \
                    "turntable angle: the scene is rotated by A deg about the rig's z axis (default 0)", false),   \
    MODEL_OPT_VALUE("--threads", "N", "worker threads (default: REFL_THREADS or the online CPUs)", false),         \
    MODEL_OPT_VALUE("--planarity-tol-mm", "T", "max distance of a face's vertex from its plane, mm (default 0.01)", \
                    false)

// ---------------------------------------------------------------------------
// refl render

int model_cmd_render(int argc, char **argv)
{
    model_opt_t opts[] = {
        SCENE_INPUT_OPTS,
        MODEL_OPT_VALUE("-o", "OUT", "output image: .png (16-bit, P rounded and clipped to 0..65535) or .tif/.tiff (float32 P)", true),
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
    c.epilog = "P = Pa + kc * g(x,y) * [sum_i V_i I_i R_i / d_i^2 + interreflection], in DN.\n"
               "Pixel convention: " PIXEL_CONV ".";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;

    model_shading_t sh = model_shading_default();
    double planarity = MODEL_SCENE_OPTIONS_DEFAULT.planarity_tol_mm, turntable_deg = 0;
    long mc_samples = sh.mc_samples, mc_bounces = sh.mc_bounces, seed = (long)sh.seed, threads = 0;
    if ((rc = model_cli_double(&c, "--kc", &sh.kc, 0, false, INFINITY, "kc >= 0")) ||
        (rc = model_cli_double(&c, "--offset", &sh.Pa, -INFINITY, false, INFINITY, "finite")) ||
        (rc = model_cli_double(&c, "--rho", &sh.rho, 0, false, 1, "0 <= rho <= 1")) ||
        (rc = model_cli_long(&c, "--mc-samples", &mc_samples, 1, 1000000)) ||
        (rc = model_cli_long(&c, "--mc-bounces", &mc_bounces, 0, 64)) ||
        (rc = model_cli_long(&c, "--seed", &seed, 0, LONG_MAX)) ||
        (rc = model_cli_long(&c, "--threads", &threads, 1, 256)) ||
        (rc = model_cli_double(&c, "--turntable-deg", &turntable_deg, -1e6, false, 1e6, "|A| <= 1e6 deg")) ||
        (rc = model_cli_double(&c, "--planarity-tol-mm", &planarity, 0, false, INFINITY, "T >= 0")))
        return rc;
    const char *ir = model_cli_value(&c, "--interreflection");
    if (ir) {
        int m = model_interreflection_from_name(ir);
        if (m < 0) return model_cli_error(&c, "option --interreflection: unknown value '%s' (use none, thesis or mc)", ir);
        sh.interreflection = (model_interreflection_t)m;
    }
    sh.mc_samples = (int)mc_samples;
    sh.mc_bounces = (int)mc_bounces;
    sh.seed = (uint64_t)seed;
    const char *out_path = model_cli_value(&c, "-o"), *info_path = model_cli_value(&c, "--info");
    bool out_png = ends_with_ci(out_path, ".png");
    if (!out_png && !is_tiff_name(out_path))
        return model_cli_error(&c, "option -o: '%s' must end in .png, .tif or .tiff", out_path);
    if (info_path && !is_tiff_name(info_path))
        return model_cli_error(&c, "option --info: '%s' must end in .tif or .tiff", info_path);
    if (threads > 0) {
        char buf[24];
        snprintf(buf, sizeof buf, "%ld", threads);
        setenv("REFL_THREADS", buf, 1);   // the camera's ray table and the renderer follow it
        sh.nthreads = (int)threads;
    }

    rc = 1;
    double t_start = model_now_s();
    inputs_t in = { 0 };
    float *P = NULL, *gain = NULL, *P_ideal = NULL;
    int32_t *face = NULL;
    uint8_t *lit = NULL;
    uint16_t *pix = NULL;
    char *cmdline = model_command_line(argc, argv), *conv = NULL, *optstr = NULL;
    model_meta_t *meta = model_meta_new();
    model_sensor_t sensor;
    const char *sensor_path = model_cli_value(&c, "--sensor"), *gain_path = model_cli_value(&c, "--gain-map");
    input_t inputs[] = {
        { "scene", c.positional[0], "" }, { "camera", model_cli_value(&c, "--camera"), "" },
        { "lamps", model_cli_value(&c, "--lamps"), "" }, { "materials", model_cli_value(&c, "--materials"), "" },
        { "gain_map", gain_path, "" }, { "sensor", sensor_path, "" },
    };
    const int ninputs = (int)(sizeof inputs / sizeof inputs[0]);

    if (!inputs_load(&in, c.positional[0], model_cli_value(&c, "--camera"), model_cli_value(&c, "--lamps"), model_cli_value(&c, "--materials"),
                     planarity, turntable_deg))
        goto done;
    if (sensor_path && !model_sensor_load(sensor_path, &sensor)) goto done;
    int W = model_camera_width(in.cam), H = model_camera_height(in.cam);
    size_t npix = (size_t)W * (size_t)H;
    if (gain_path) {
        int gw, gh;
        if (!model_tiff_read_float(gain_path, &gw, &gh, &gain)) goto done;
        if (gw != W || gh != H) {
            model_error(gain_path, 0, "gain map is %d x %d pixels but the camera %s is %d x %d: "
                        "use the gain map calibrated for this camera", gw, gh, model_cli_value(&c, "--camera"), W, H);
            goto done;
        }
        for (size_t i = 0; i < npix; i++)
            if (!isfinite(gain[i]) || gain[i] < 0) {
                model_error(gain_path, 0, "gain map pixel (%zu, %zu) is %g: gains must be finite and >= 0",
                            i % (size_t)W, i / (size_t)W, (double)gain[i]);
                goto done;
            }
        sh.gain_map = gain;
    }
    if (!hash_inputs(inputs, ninputs)) goto done;

    P = malloc(npix * sizeof *P);
    face = malloc(npix * sizeof *face);
    if (info_path) lit = malloc(npix * (size_t)(in.lamps->n > 0 ? in.lamps->n : 1));
    if (!P || !face || (info_path && !lit)) {
        MODEL_FAIL("out of memory for a %d x %d image", W, H);
        goto done;
    }
    double t_render = model_now_s();
    if (!model_render(in.tracer, in.cam, in.lamps, in.resolved, &sh, P, face, lit)) goto done;
    t_render = model_now_s() - t_render;
    if (sensor_path) {
        if (info_path) {
            P_ideal = malloc(npix * sizeof *P_ideal);
            if (!P_ideal) {
                MODEL_FAIL("out of memory");
                goto done;
            }
            memcpy(P_ideal, P, npix * sizeof *P);
        }
        model_sensor_apply(&sensor, W, H, P);
    }

    // Metadata.
    char date[40];
    model_utc_text(model_realtime_s(), date);
    conv = material_conventions(in.scene, in.resolved);
    optstr = g_strdup_printf(
        "kc=%.9g offset_dn=%.9g gain_map=%s interreflection=%s rho=%.6g thesis_samples=%d thesis_cone_deg=%.6g "
        "mc_samples=%d mc_bounces=%d finite_lamps=%s seed=%llu sensor=%s turntable_deg=%.9g threads=%s "
        "planarity_tol_mm=%.6g",
        sh.kc, sh.Pa, gain_path ? gain_path : "none", model_interreflection_name(sh.interreflection), sh.rho,
        sh.thesis_samples, sh.thesis_cone_deg, sh.mc_samples, sh.mc_bounces, sh.finite_lamps ? "yes" : "no",
        (unsigned long long)sh.seed, sensor_path ? sensor_path : "none", turntable_deg,
        threads > 0 ? model_cli_value(&c, "--threads") : "default", planarity);
    model_meta_add(meta, "Software", "refl %s (refl render)", REFL_VERSION);
    model_meta_add(meta, "units", "%s", UNITS_P);
    model_meta_add(meta, "image", "%s", sensor_path
             ? "P after the sensor stage (shot/read noise, DSNU, PRNU, vignetting, non-linearity, quantisation)"
             : "P from the imaging model (ideal, no sensor noise)");
    model_meta_add(meta, "model", "P = Pa + kc * g(x,y) * [sum_i V_i I_i R_i / d_i^2 + interreflection]; "
             "pixels whose ray misses the scene get Pa");
    model_meta_add(meta, "pixel_convention", "%s", PIXEL_CONV);
    model_meta_add(meta, "frames", "%s", FRAMES_TEXT);
    model_meta_add(meta, "options", "%s", optstr);
    model_meta_add(meta, "materials", "%s", conv);
    meta_add_inputs(meta, inputs, ninputs);
    model_meta_add(meta, "refl_version", "%s", REFL_VERSION);
    model_meta_add(meta, "date_utc", "%s", date);
    model_meta_add(meta, "command_line", "%s", cmdline);

    // Statistics of the output image.
    double pmin = INFINITY, pmax = -INFINITY, psum = 0;
    size_t nbg = 0;
    for (size_t i = 0; i < npix; i++) {
        double v = P[i];
        if (v < pmin) pmin = v;
        if (v > pmax) pmax = v;
        psum += v;
        if (face[i] < 0) nbg++;
    }

    if (out_png) {
        pix = malloc(npix * sizeof *pix);
        if (!pix) {
            MODEL_FAIL("out of memory");
            goto done;
        }
        size_t nlo = 0, nhi = 0, nnan = 0;
        for (size_t i = 0; i < npix; i++) {
            double v = P[i];
            if (isnan(v)) {
                nnan++;
                pix[i] = 0;
            } else if (v < -0.5) {
                nlo++;
                pix[i] = 0;
            } else if (v >= 65535.5) {
                nhi++;
                pix[i] = 65535;
            } else {
                long r = lround(v);
                pix[i] = (uint16_t)(r < 0 ? 0 : r > 65535 ? 65535 : r);
            }
        }
        if (nlo || nhi || nnan)
            fprintf(stderr, "refl render: warning: %zu pixels clipped to [0, 65535] in %s (%zu below 0, %zu above "
                    "65535, %zu not a number); write a .tiff to keep the float values\n",
                    nlo + nhi + nnan, out_path, nlo, nhi, nnan);
        model_meta_add(meta, "encoding", "16-bit grey PNG: P rounded to the nearest integer, clipped to [0, 65535]; "
                 "%zu pixels clipped", nlo + nhi + nnan);
        if (!model_png16_write(out_path, W, H, pix, model_meta_list(meta))) goto done;
    } else {
        model_meta_add(meta, "encoding", "float32 TIFF: P in DN, not rounded or clipped");
        if (!model_tiff_write_float(out_path, W, H, P, model_meta_list(meta))) goto done;
    }
    if (info_path) {
        const char **names = malloc((size_t)(in.lamps->n > 0 ? in.lamps->n : 1) * sizeof *names);
        if (!names) {
            MODEL_FAIL("out of memory");
            goto done;
        }
        for (int i = 0; i < in.lamps->n; i++) names[i] = in.lamps->lamps[i].name;
        model_meta_add(meta, "info", "page 0: P (float32, DN, %s); page 1: face id (int32, index into the scene's faces, "
                 "0-based; nfaces + k for the scene's sphere k; -1 = background); pages 2..: lit mask per lamp (uint8, 1 where V > 0.5), in the "
                 "order of the lamps file", sensor_path ? "ideal, before the sensor stage" : "as in the output image");
        bool ok = model_tiff_write_info(info_path, W, H, P_ideal ? P_ideal : P, face, lit, in.lamps->n,
                                        (const char *const *)names, model_meta_list(meta));
        free(names);
        if (!ok) goto done;
    }

    printf("refl render: %s -> %s\n", c.positional[0], out_path);
    printf("  image %d x %d px, %d faces, %d lamps, interreflection %s%s\n", W, H, in.scene->nfaces, in.lamps->n,
           model_interreflection_name(sh.interreflection), sensor_path ? ", sensor stage applied" : "");
    printf("  time %.2f s (render %.2f s)\n", model_now_s() - t_start, t_render);
    printf("  P (DN): min %.1f  mean %.1f  max %.1f;  background %.1f %% of the pixels\n", pmin,
           psum / (double)npix, pmax, 100.0 * (double)nbg / (double)npix);
    printf("  wrote %s (%s)\n", out_path, out_png ? "16-bit PNG" : "float32 TIFF");
    if (info_path) printf("  wrote %s (info TIFF: P, face id, lit masks)\n", info_path);
    rc = 0;
done:
    inputs_free(&in);
    free(P);
    free(P_ideal);
    free(gain);
    free(face);
    free(lit);
    free(pix);
    g_free(cmdline);
    g_free(conv);
    g_free(optstr);
    model_meta_free(meta);
    return rc;
}

// ---------------------------------------------------------------------------
// refl edges

static json_t *json_vec2(const double q[2]) { return json_pack("[f,f]", q[0], q[1]); }
static json_t *json_vec3(model_vec3_t p) { return json_pack("[f,f,f]", p.x, p.y, p.z); }

static json_t *json_lamp_list(const model_lamps_t *lamps, uint32_t bits)
{
    json_t *a = json_array();
    for (int i = 0; i < lamps->n && i < 32; i++)
        if (bits & (1u << i)) json_array_append_new(a, json_string(lamps->lamps[i].name));
    return a;
}

static void lamp_letters(const model_lamps_t *lamps, uint32_t bits, char *out, size_t size)
{
    size_t n = 0;
    out[0] = 0;
    for (int i = 0; i < lamps->n && i < 32 && n + 1 < size; i++)
        n += (size_t)snprintf(out + n, size - n, "%s", (bits & (1u << i)) ? "1" : ".");
    if (!lamps->n) snprintf(out, size, "-");
}

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
    c.epilog = "One line per visible image segment of a scene edge: its 3D end points (mm, rig frame), faces,\n"
               "image end points (px, " PIXEL_CONV "),\nlength, lamps lighting each side (one character per lamp in "
               "file order: 1 lit, . not), the\npredicted grey value 2 px to each side (DN; direct term only) and the "
               "contrast P0 - P1.\nSide 0 lies to the right of q0 -> q1 in the displayed image (y down).";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    model_shading_t sh = model_shading_default();
    double planarity = MODEL_SCENE_OPTIONS_DEFAULT.planarity_tol_mm, turntable_deg = 0, feature_deg = 1;
    long threads = 0;
    if ((rc = model_cli_double(&c, "--kc", &sh.kc, 0, false, INFINITY, "kc >= 0")) ||
        (rc = model_cli_double(&c, "--offset", &sh.Pa, -INFINITY, false, INFINITY, "finite")) ||
        (rc = model_cli_double(&c, "--feature-angle-deg", &feature_deg, 0, false, 179.999, "0 <= A < 180")) ||
        (rc = model_cli_double(&c, "--turntable-deg", &turntable_deg, -1e6, false, 1e6, "|A| <= 1e6 deg")) ||
        (rc = model_cli_long(&c, "--threads", &threads, 1, 256)) ||
        (rc = model_cli_double(&c, "--planarity-tol-mm", &planarity, 0, false, INFINITY, "T >= 0")))
        return rc;
    if (threads > 0) {
        char buf[24];
        snprintf(buf, sizeof buf, "%ld", threads);
        setenv("REFL_THREADS", buf, 1);
        sh.nthreads = (int)threads;
    }
    const char *json_path = model_cli_value(&c, "--json");

    rc = 1;
    inputs_t in = { 0 };
    model_edges_t *E = NULL;
    json_t *root = NULL;
    char *cmdline = model_command_line(argc, argv), *conv = NULL;
    input_t inputs[] = {
        { "scene", c.positional[0], "" }, { "camera", model_cli_value(&c, "--camera"), "" },
        { "lamps", model_cli_value(&c, "--lamps"), "" }, { "materials", model_cli_value(&c, "--materials"), "" },
    };
    const int ninputs = (int)(sizeof inputs / sizeof inputs[0]);
    if (!inputs_load(&in, c.positional[0], model_cli_value(&c, "--camera"), model_cli_value(&c, "--lamps"), model_cli_value(&c, "--materials"),
                     planarity, turntable_deg))
        goto done;
    if (!hash_inputs(inputs, ninputs)) goto done;
    double t0 = model_now_s();
    E = model_edges_predict(in.scene, in.tracer, in.cam, in.lamps, in.resolved, &sh, feature_deg);
    if (!E) goto done;
    double dt = model_now_s() - t0;

    const model_vec3_t *V = in.scene->vertices;
    int nseg = 0, nvis = 0;
    printf("refl edges: %s, camera %s, %d lamps (", c.positional[0], model_cli_value(&c, "--camera"), in.lamps->n);
    for (int i = 0; i < in.lamps->n; i++) printf("%s%s", i ? " " : "", in.lamps->lamps[i].name);
    printf(")\n");
    printf("%4s %-38s %-9s %-29s %7s %-9s %8s %8s %8s\n", "edge", "3D end points (mm, rig frame)", "faces",
           "image end points (px)", "len px", "lit 0|1", "P0 DN", "P1 DN", "P0-P1");
    for (int i = 0; i < E->nedges; i++) {
        const model_edge_t *e = &E->edges[i];
        if (e->nsegments) nvis++;
        for (int s = 0; s < e->nsegments; s++, nseg++) {
            const model_edge_segment_t *g = &e->segments[s];
            char ends3[96], faces[32], endsq[48], lit0[40], lit1[40], lit[84];
            snprintf(ends3, sizeof ends3, "(%.5g,%.5g,%.5g)-(%.5g,%.5g,%.5g)", V[e->v0].x, V[e->v0].y, V[e->v0].z,
                     V[e->v1].x, V[e->v1].y, V[e->v1].z);
            if (e->face_b >= 0) snprintf(faces, sizeof faces, "%d/%d", e->face_a, e->face_b);
            else snprintf(faces, sizeof faces, "%d/-", e->face_a);
            snprintf(endsq, sizeof endsq, "(%.1f,%.1f)-(%.1f,%.1f)", g->q0[0], g->q0[1], g->q1[0], g->q1[1]);
            lamp_letters(in.lamps, g->lit_side[0], lit0, sizeof lit0);
            lamp_letters(in.lamps, g->lit_side[1], lit1, sizeof lit1);
            snprintf(lit, sizeof lit, "%s|%s", lit0, lit1);
            printf("%4d %-38s %-9s %-29s %7.1f %-9s %8.1f %8.1f %8.1f\n", i, ends3, faces, endsq, g->length_px, lit,
                   g->P_side[0], g->P_side[1], g->contrast);
        }
    }
    printf("%d edges, %d with visible segments, %d segments (%.2f s)\n", E->nedges, nvis, nseg, dt);

    if (json_path) {
        char date[40];
        model_utc_text(model_realtime_s(), date);
        conv = material_conventions(in.scene, in.resolved);
        json_t *prov = json_pack("{s:s, s:s, s:s, s:[]}", "refl_version", REFL_VERSION, "date_utc", date,
                                 "command_line", cmdline, "inputs");
        for (int i = 0; i < ninputs; i++)
            json_array_append_new(json_object_get(prov, "inputs"),
                                  json_pack("{s:s, s:s, s:s}", "role", inputs[i].role, "path", inputs[i].path,
                                            "sha256", inputs[i].sha256));
        json_t *lamps = json_array();
        for (int i = 0; i < in.lamps->n; i++) json_array_append_new(lamps, json_string(in.lamps->lamps[i].name));
        json_t *edges = json_array();
        for (int i = 0; i < E->nedges; i++) {
            const model_edge_t *e = &E->edges[i];
            json_t *segs = json_array();
            for (int s = 0; s < e->nsegments; s++) {
                const model_edge_segment_t *g = &e->segments[s];
                json_array_append_new(segs, json_pack(
                    "{s:o, s:o, s:f, s:[f,f], s:f, s:[i,i], s:[o,o]}",
                    "q0_px", json_vec2(g->q0), "q1_px", json_vec2(g->q1), "length_px", g->length_px,
                    "P_side_dn", g->P_side[0], g->P_side[1], "contrast_dn", g->contrast,
                    "face_side", g->face_side[0], g->face_side[1],
                    "lit_side", json_lamp_list(in.lamps, g->lit_side[0]), json_lamp_list(in.lamps, g->lit_side[1])));
            }
            json_array_append_new(edges, json_pack(
                "{s:i, s:[i,i], s:o, s:o, s:i, s:o, s:f, s:o}", "id", i, "vertices", e->v0, e->v1,
                "p0_mm", json_vec3(V[e->v0]), "p1_mm", json_vec3(V[e->v1]), "face_a", e->face_a,
                "face_b", e->face_b >= 0 ? json_integer(e->face_b) : json_null(), "dihedral_deg", e->dihedral_deg,
                "segments", segs));
        }
        root = json_pack(
            "{s:s, s:{s:s, s:s, s:s, s:s, s:s, s:s, s:s}, s:s, s:s, s:s, s:{s:f, s:f, s:f, s:f, s:f}, s:s, s:o, "
            "s:i, s:i, s:o, s:o}",
            "description", "refl edges: visible image segments of the scene's edges, lighting per side, predicted contrast",
            "units",
            "p0_mm, p1_mm", "mm, world = rig frame",
            "q0_px, q1_px, length_px", "pixels (" PIXEL_CONV ")",
            "P_side_dn, contrast_dn", UNITS_P "; direct term only: Pa + kc * g * sum_i V_i I_i R_i / d_i^2",
            "face_a, face_b, face_side", "index into the scene's faces, 0-based (the file's face number - 1); -1 = background",
            "vertices", "indices into the scene's vertices, 0-based (the file's vertex number - 1)",
            "lit_side", "names of the lamps with V > 0.5 on at least half the side's sample points",
            "dihedral_deg", "angle between the two faces' normals, deg (0 for a boundary edge)",
            "side_convention", "side 0 is 2 px to the right of q0 -> q1 in the displayed image (y down), side 1 2 px to the left; "
            "contrast = P_side[0] - P_side[1]",
            "pixel_convention", PIXEL_CONV, "frames", FRAMES_TEXT,
            "options", "kc", sh.kc, "offset_dn", sh.Pa, "feature_angle_deg", feature_deg, "turntable_deg", turntable_deg,
            "planarity_tol_mm", planarity,
            "materials", conv, "provenance", prov,
            "image_width", model_camera_width(in.cam), "image_height", model_camera_height(in.cam),
            "lamps", lamps, "edges", edges);
        if (!root) {
            MODEL_FAIL("cannot build the JSON document");
            goto done;
        }
        if (json_dump_file(root, json_path, JSON_INDENT(1) | JSON_REAL_PRECISION(10)) != 0) {
            model_error(json_path, 0, "cannot write the JSON file: check the directory exists and is writable");
            goto done;
        }
        printf("wrote %s\n", json_path);
    }
    rc = 0;
done:
    json_decref(root);
    model_edges_free(E);
    inputs_free(&in);
    g_free(cmdline);
    g_free(conv);
    return rc;
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
    };
    model_cli_t c = { .cmd = "workpiece", .synopsis = "OUT.d3d", .opts = opts, .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
    c.about = "Writes the reference workpiece of thesis ch. 6 as a D3D scene: a 400 x 300 x 10 mm plate with\n"
              "a stiffener 88 mm high and 260 mm long along y (T: 8 mm web under a 60 x 8 mm flange). The\n"
              "defaults give examples/t_stiffener.d3d; the options make the wrong descriptions the\n"
              "verification is tested with (I-stiffener, none, shifted, rotated, wrong height).";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
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
    model_scene_t *sc = model_scene_parse_d3d(text, strlen(text), c.positional[0], NULL);
    if (!sc) {
        free(text);
        return 1;
    }
    model_scene_free(sc);
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", c.positional[0]);
    FILE *f = fopen(tmp, "w");
    bool ok = f && fputs(text, f) >= 0;
    if (f && fclose(f) != 0) ok = false;
    if (ok && rename(tmp, c.positional[0]) != 0) ok = false;
    if (!ok) {
        fprintf(stderr, "refl workpiece: cannot write %s: %s\n", c.positional[0], strerror(errno));
        unlink(tmp);
        free(text);
        return 1;
    }
    free(text);
    printf("%s: %s-stiffener workpiece\n", c.positional[0], model_stiffener_kind_name(p.kind));
    return 0;
}
