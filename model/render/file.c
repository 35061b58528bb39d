// model/render/file.c — a scene rendered to an image file (`refl render`'s
// work): the inputs loaded and hashed, the imaging model, the optional sensor
// stage, and a 16-bit PNG or float TIFF whose metadata carry the units, the
// conventions and the provenance; plus the inputs every file command shares.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "model/internal.h"

// ---------------------------------------------------------------------------
// Provenance and metadata



void model_meta_add_inputs(model_meta_t *m, const model_input_t *in, int nin)
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
char *model_material_conventions(const model_scene_t *scene, const model_material_t *const *mats)
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


void model_inputs_free(model_inputs_t *in)
{
    model_tracer_free(in->tracer);
    free(in->resolved);
    model_materials_free(in->mats);
    model_lamps_free(in->lamps);
    model_camera_free(in->cam);
    model_scene_free(in->scene);
    memset(in, 0, sizeof *in);
}

bool model_inputs_load(model_inputs_t *in, const char *scene_path, const char *cam_path,
                        const char *lamps_path, const char *mats_path, double planarity_tol_mm,
                        double scene_unit_mm, double turntable_deg)
{
    model_scene_options_t so = MODEL_SCENE_OPTIONS_DEFAULT;
    so.planarity_tol_mm = planarity_tol_mm;
    so.unit_mm = scene_unit_mm;
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

bool model_inputs_hash(model_input_t *in, int n)
{
    for (int i = 0; i < n; i++)
        if (in[i].path && !model_sha256_file(in[i].path, in[i].sha256)) return false;
    return true;
}

// ---------------------------------------------------------------------------
// refl render's work

typedef struct {
    model_inputs_t in;
    model_sensor_t sensor;
    float         *P, *gain, *P_ideal;
    int32_t       *face;
    uint8_t       *lit;
    uint16_t      *pix;
    model_meta_t  *meta;
    int            W, H;
} render_job_t;

static void job_free(render_job_t *j)
{
    model_inputs_free(&j->in);
    free(j->P);
    free(j->P_ideal);
    free(j->gain);
    free(j->face);
    free(j->lit);
    free(j->pix);
    model_meta_free(j->meta);
}

static bool is_png_name(const char *s)
{
    size_t n = strlen(s);
    return n >= 4 && !strcasecmp(s + n - 4, ".png");
}

// The gain map g(x,y): camera-sized, finite and >= 0.
static bool load_gain_map(render_job_t *j, const model_render_file_opts_t *o)
{
    int gw, gh;
    if (!model_tiff_read_float(o->gain_map, &gw, &gh, &j->gain)) return false;
    if (gw != j->W || gh != j->H) {
        model_error(o->gain_map, 0, "gain map is %d x %d pixels but the camera %s is %d x %d: "
                    "use the gain map calibrated for this camera", gw, gh, o->camera, j->W, j->H);
        return false;
    }
    size_t npix = (size_t)j->W * (size_t)j->H;
    for (size_t i = 0; i < npix; i++)
        if (!isfinite(j->gain[i]) || j->gain[i] < 0) {
            model_error(o->gain_map, 0, "gain map pixel (%zu, %zu) is %g: gains must be finite and >= 0",
                        i % (size_t)j->W, i / (size_t)j->W, (double)j->gain[i]);
            return false;
        }
    return true;
}

// Render (and the sensor stage) into j->P, j->face, j->lit.
static bool render_image(render_job_t *j, const model_render_file_opts_t *o, const model_shading_t *sh,
                         model_render_file_result_t *r)
{
    size_t npix = (size_t)j->W * (size_t)j->H;
    j->P = malloc(npix * sizeof *j->P);
    j->face = malloc(npix * sizeof *j->face);
    if (o->info) j->lit = malloc(npix * (size_t)(j->in.lamps->n > 0 ? j->in.lamps->n : 1));
    if (!j->P || !j->face || (o->info && !j->lit)) {
        MODEL_FAIL("out of memory for a %d x %d image", j->W, j->H);
        return false;
    }
    double t = model_now_s();
    if (!model_render(j->in.tracer, j->in.cam, j->in.lamps, j->in.resolved, sh, j->P, j->face, j->lit)) return false;
    r->render_s = model_now_s() - t;
    if (!o->sensor) return true;
    if (o->info) {
        if (!(j->P_ideal = malloc(npix * sizeof *j->P_ideal))) {
            MODEL_FAIL("out of memory");
            return false;
        }
        memcpy(j->P_ideal, j->P, npix * sizeof *j->P);
    }
    model_sensor_apply(&j->sensor, j->W, j->H, j->P);
    return true;
}

// The image's metadata: units, conventions, options, materials, inputs, provenance.
static void add_metadata(render_job_t *j, const model_render_file_opts_t *o, const model_shading_t *sh,
                         const model_input_t *inputs, int ninputs)
{
    char date[40];
    model_utc_text(model_realtime_s(), date);
    char *conv = model_material_conventions(j->in.scene, j->in.resolved);
    char *optstr = g_strdup_printf(
        "kc=%.9g offset_dn=%.9g gain_map=%s interreflection=%s rho=%.6g thesis_samples=%d thesis_cone_deg=%.6g "
        "mc_samples=%d mc_bounces=%d finite_lamps=%s seed=%llu sensor=%s turntable_deg=%.9g threads=%s "
        "planarity_tol_mm=%.6g scene_unit_mm=%.6g",
        sh->kc, sh->Pa, o->gain_map ? o->gain_map : "none", model_interreflection_name(sh->interreflection), sh->rho,
        sh->thesis_samples, sh->thesis_cone_deg, sh->mc_samples, sh->mc_bounces, sh->finite_lamps ? "yes" : "no",
        (unsigned long long)sh->seed, o->sensor ? o->sensor : "none", o->turntable_deg,
        o->threads_text ? o->threads_text : "default", o->planarity_tol_mm,
        o->scene_unit_mm ? o->scene_unit_mm : 1);
    model_meta_t *m = j->meta;
    model_meta_add(m, "Software", "refl %s (refl render)", REFL_VERSION);
    model_meta_add(m, "units", "%s", MODEL_UNITS_P);
    model_meta_add(m, "image", "%s", o->sensor
             ? "P after the sensor stage (shot/read noise, DSNU, PRNU, vignetting, non-linearity, quantisation)"
             : "P from the imaging model (ideal, no sensor noise)");
    model_meta_add(m, "model", "P = Pa + kc * g(x,y) * [sum_i V_i I_i R_i / d_i^2 + interreflection]; "
             "pixels whose ray misses the scene get Pa");
    model_meta_add(m, "pixel_convention", "%s", MODEL_PIXEL_CONV);
    model_meta_add(m, "frames", "%s", MODEL_FRAMES_TEXT);
    model_meta_add(m, "options", "%s", optstr);
    model_meta_add(m, "materials", "%s", conv);
    model_meta_add_inputs(m, inputs, ninputs);
    model_meta_add(m, "refl_version", "%s", REFL_VERSION);
    model_meta_add(m, "date_utc", "%s", date);
    model_meta_add(m, "command_line", "%s", o->command_line ? o->command_line : "");
    g_free(conv);
    g_free(optstr);
}

// The output image: a 16-bit PNG (P rounded, clipped and counted) or a float TIFF.
static bool write_image(render_job_t *j, const model_render_file_opts_t *o, model_render_file_result_t *r)
{
    size_t npix = (size_t)j->W * (size_t)j->H;
    if (!r->png) {
        model_meta_add(j->meta, "encoding", "float32 TIFF: P in DN, not rounded or clipped");
        return model_tiff_write_float(o->out, j->W, j->H, j->P, model_meta_list(j->meta));
    }
    if (!(j->pix = malloc(npix * sizeof *j->pix))) {
        MODEL_FAIL("out of memory");
        return false;
    }
    for (size_t i = 0; i < npix; i++) {
        double v = j->P[i];
        if (isnan(v)) {
            r->clipped_nan++;
            j->pix[i] = 0;
        } else if (v < -0.5) {
            r->clipped_low++;
            j->pix[i] = 0;
        } else if (v >= 65535.5) {
            r->clipped_high++;
            j->pix[i] = 65535;
        } else {
            long q = lround(v);
            j->pix[i] = (uint16_t)(q < 0 ? 0 : q > 65535 ? 65535 : q);
        }
    }
    model_meta_add(j->meta, "encoding", "16-bit grey PNG: P rounded to the nearest integer, clipped to [0, 65535]; "
             "%zu pixels clipped", r->clipped_low + r->clipped_high + r->clipped_nan);
    return model_png16_write(o->out, j->W, j->H, j->pix, model_meta_list(j->meta));
}

// The info TIFF: ideal P, face ids, lit masks per lamp.
static bool write_info(render_job_t *j, const model_render_file_opts_t *o)
{
    const model_lamps_t *lamps = j->in.lamps;
    const char **names = malloc((size_t)(lamps->n > 0 ? lamps->n : 1) * sizeof *names);
    if (!names) {
        MODEL_FAIL("out of memory");
        return false;
    }
    for (int i = 0; i < lamps->n; i++) names[i] = lamps->lamps[i].name;
    model_meta_add(j->meta, "info", "page 0: P (float32, DN, %s); page 1: face id (int32, index into the scene's "
             "faces, 0-based; nfaces + k for the scene's sphere k; -1 = background); pages 2..: lit mask per lamp "
             "(uint8, 1 where V > 0.5), in the order of the lamps file",
             o->sensor ? "ideal, before the sensor stage" : "as in the output image");
    bool ok = model_tiff_write_info(o->info, j->W, j->H, j->P_ideal ? j->P_ideal : j->P, j->face, j->lit, lamps->n,
                                    (const char *const *)names, model_meta_list(j->meta));
    free(names);
    return ok;
}

static void image_stats(const render_job_t *j, model_render_file_result_t *r)
{
    size_t npix = (size_t)j->W * (size_t)j->H, nbg = 0;
    double pmin = INFINITY, pmax = -INFINITY, psum = 0;
    for (size_t i = 0; i < npix; i++) {
        double v = j->P[i];
        if (v < pmin) pmin = v;
        if (v > pmax) pmax = v;
        psum += v;
        if (j->face[i] < 0) nbg++;
    }
    r->p_min = pmin;
    r->p_max = pmax;
    r->p_mean = psum / (double)npix;
    r->background_frac = (double)nbg / (double)npix;
}

bool model_render_file(const model_render_file_opts_t *o, model_render_file_result_t *r)
{
    memset(r, 0, sizeof *r);
    double t_start = model_now_s();
    render_job_t j = { .meta = model_meta_new() };
    model_shading_t sh = o->shading;
    model_input_t inputs[] = {
        { "scene", o->scene, "" }, { "camera", o->camera, "" }, { "lamps", o->lamps, "" },
        { "materials", o->materials, "" }, { "gain_map", o->gain_map, "" }, { "sensor", o->sensor, "" },
    };
    const int ninputs = (int)(sizeof inputs / sizeof inputs[0]);
    r->png = is_png_name(o->out);
    bool ok = j.meta &&
              model_inputs_load(&j.in, o->scene, o->camera, o->lamps, o->materials, o->planarity_tol_mm, o->scene_unit_mm,
                                o->turntable_deg) &&
              (!o->sensor || model_sensor_load(o->sensor, &j.sensor));
    if (ok) {
        j.W = model_camera_width(j.in.cam);
        j.H = model_camera_height(j.in.cam);
        ok = !o->gain_map || load_gain_map(&j, o);
    }
    if (ok) {
        sh.gain_map = j.gain;
        ok = model_inputs_hash(inputs, ninputs) && render_image(&j, o, &sh, r);
    }
    if (ok) {
        add_metadata(&j, o, &sh, inputs, ninputs);
        image_stats(&j, r);
        ok = write_image(&j, o, r) && (!o->info || write_info(&j, o));
    }
    if (ok) {
        r->width = j.W;
        r->height = j.H;
        r->nfaces = j.in.scene->nfaces;
        r->nlamps = j.in.lamps->n;
        r->interreflection = sh.interreflection;
        r->time_s = model_now_s() - t_start;
    }
    job_free(&j);
    return ok;
}
