// fit/cmd_plan.c — `refl plan lamps`: choose lamps and exposure for a view
// (fit/lightplan.h), optionally checked on the virtual rig.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fit/lightplan.h"
#include "fit/material.h"
#include "fit/verify.h"
#include "fit/verify_lab.h"
#include "model/report.h"
#include "model/vec.h"

static void usage(FILE *f)
{
    fprintf(f,
            "usage: refl plan lamps SCENE --camera CAM.cameramodel --lamps CANDIDATES.ini --materials MATS\n"
            "                       (--kc-per-us X | --white WHITE.json) [--gain-calib DIR] [options] -o DIR\n"
            "\n"
            "Predicts, for every set of the candidate lamps and every exposure, the grey values of each face\n"
            "against the camera's usable range, the specular glare and the contrast across every visible scene\n"
            "edge, and chooses the set and exposure that make the most edge length detectable by a Sobel\n"
            "detector and leave the most usable reference points, without glare or saturation.\n"
            "\ninputs:\n"
            "  SCENE                    D3D or OBJ description (rig frame, mm)\n"
            "  --camera CAM             camera model (mrcal; extrinsics in the rig frame)\n"
            "  --lamps FILE             candidates: a lamps INI ([lamp NAME] position_mm, intensity) with\n"
            "                           --kc-per-us X (kc*I = X * intensity), or lamps.json with --white\n"
            "  --materials FILE...      a materials INI, or priors JSON files (their means)\n"
            "  --gain-calib DIR         gain.json (K, read noise, saturation) + offset_dn.tiff, prnu_gain.tiff;\n"
            "                           without: --saturation-dn S (4095), --offset-dn O (0), SNR floor off\n"
            "\noptions:\n"
            "  --angle-deg A            turntable angle of the view (0)\n"
            "  --exposures-us LIST      comma list to try (500,1000,2000,4000,8000,16000)\n"
            "  --glare-cone-deg G (15), --sobel-threshold T (250 DN), --floor-snr S (10), --floor-dn D (20)\n"
            "  --saturation-frac F (0.95), --max-bad-frac F (0.001), --max-lamps N (all), --spacing-px N (8)\n"
            "  --check-virtual TRUTH.ini  render the chosen configuration and each single lamp at its exposure on\n"
            "                           the virtual rig (in process) and compare a Sobel detector with the prediction\n"
            "  --sample NAME            the virtual rig's sample for the check (t_stiffener)\n"
            "  --threads N, --no-report\n"
            "\nOutputs in DIR: plan.json (every configuration, the chosen one, faces, edge segments; the check),\n"
            "predicted.tiff (DN, direct light), glare.tiff (where each candidate would glare), index.html\n"
            "(scripts/plan_lamps_report.py).\n"
            "\nrefl %s\n", REFL_VERSION);
}

#define uerr(...) model_usage_error("plan lamps", __VA_ARGS__)

typedef struct {
    const char *scene, *camera, *lamps, *materials, *gain, *white, *out, *truth, *sample, *exposures;
    const char *matfiles[8];
    int nmat;
    double kc_per_us, angle_deg, saturation_dn, offset_dn;
    bool no_report;
    lightplan_options_t opt;
} pa_t;

static int parse(int argc, char **argv, pa_t *a)
{
    a->opt = lightplan_defaults();
    a->saturation_dn = 4095;
    a->sample = "t_stiffener";
    for (int i = 1; i < argc; i++) {
        const char *o = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        double d;
        if (!strcmp(o, "--help") || !strcmp(o, "-h")) {
            usage(stdout);
            return -1;
        }
#define STR(flag, field)                                                 \
    if (!strcmp(o, flag)) {                                              \
        if (!v) return uerr("%s needs a value", flag);                  \
        a->field = v;                                                    \
        i++;                                                             \
        continue;                                                        \
    }
#define NUM(flag, lo, hi, dst)                                                                            \
    if (!strcmp(o, flag)) {                                                                               \
        if (!v || !model_parse_double(v, &d) || d < (lo) || d > (hi))                                     \
            return uerr("%s: '%s' is not a number in %g..%g", flag, v ? v : "", (double)(lo), (double)(hi)); \
        dst;                                                                                              \
        i++;                                                                                              \
        continue;                                                                                         \
    }
        STR("--camera", camera)
        STR("--lamps", lamps)
        if (!strcmp(o, "--materials")) {
            while (i + 1 < argc && !(argv[i + 1][0] == '-' && argv[i + 1][1])) {
                if (a->nmat >= 8) return uerr("--materials: at most 8 files");
                a->matfiles[a->nmat++] = argv[++i];
            }
            if (!a->nmat) return uerr("--materials needs a value");
            a->materials = a->matfiles[0];
            continue;
        }
        STR("--gain-calib", gain)
        STR("--white", white)
        STR("-o", out)
        STR("--out", out)
        STR("--check-virtual", truth)
        STR("--sample", sample)
        STR("--exposures-us", exposures)
        NUM("--kc-per-us", 1e-300, 1e300, a->kc_per_us = d)
        NUM("--angle-deg", -1e4, 1e4, a->angle_deg = d)
        NUM("--saturation-dn", 1, 1e9, a->saturation_dn = d)
        NUM("--offset-dn", -1e9, 1e9, a->offset_dn = d)
        NUM("--glare-cone-deg", 0, 90, a->opt.glare_cone_deg = d)
        NUM("--sobel-threshold", 0, 1e9, a->opt.sobel_threshold = d)
        NUM("--floor-snr", 0, 1e6, a->opt.floor_snr = d)
        NUM("--floor-dn", 0, 1e9, a->opt.floor_dn = d)
        NUM("--saturation-frac", 0.01, 1, a->opt.saturation_frac = d)
        NUM("--max-bad-frac", 0, 1, a->opt.max_bad_frac = d)
        NUM("--max-lamps", 1, 16, a->opt.max_lamps = (int)d)
        NUM("--spacing-px", 1, 1000, a->opt.spacing_px = (int)d)
        NUM("--threads", 0, 1024, a->opt.threads = (int)d)
#undef STR
#undef NUM
        if (!strcmp(o, "--no-report")) {
            a->no_report = true;
            continue;
        }
        if (o[0] == '-' && o[1]) return uerr("unknown option '%s'", o);
        if (a->scene) return uerr("unexpected argument '%s' (one SCENE only)", o);
        a->scene = o;
    }
    if (!a->scene) return uerr("missing SCENE");
    if (!a->camera) return uerr("missing --camera CAM.cameramodel");
    if (!a->lamps) return uerr("missing --lamps CANDIDATES");
    if (!a->materials) return uerr("missing --materials MATS");
    if (!a->out) return uerr("missing -o DIR");
    if (!a->white && !(a->kc_per_us > 0)) return uerr("give --kc-per-us X (lamps INI) or --white WHITE.json");
    return 0;
}

static const char *face_name(const model_scene_t *s, int f, char *buf, size_t n)
{
    if (f < 0) snprintf(buf, n, "background");
    else if (f < s->nfaces) snprintf(buf, n, "%d", s->faces[f].number);
    else snprintf(buf, n, "sphere %d", f - s->nfaces);
    return buf;
}

static json_t *segments_json(const lightplan_segment_t *sg, int n, const model_scene_t *s, const bool *found,
                             const double *measured)
{
    json_t *arr = json_array();
    char b0[32], b1[32];
    for (int k = 0; k < n; k++) {
        const lightplan_segment_t *g = &sg[k];
        json_t *e = json_pack("{s:i,s:i,s:i,s:[f,f],s:[f,f],s:f,s:f,s:f,s:b,s:s,s:s}", "index", k, "edge", g->edge,
                              "edge_segment", g->segment, "q0_px", g->q0[0],
                              g->q0[1], "q1_px", g->q1[0], g->q1[1], "length_px", g->length_px, "dP_dn", g->dP,
                              "sobel_predicted_dn", g->gradient, "detectable", g->detectable, "face_side0",
                              face_name(s, g->face_side[0], b0, sizeof b0), "face_side1",
                              face_name(s, g->face_side[1], b1, sizeof b1));
        if (found && measured) {
            json_object_set_new(e, "sobel_measured_dn", isfinite(measured[k]) ? json_real(measured[k]) : json_null());
            json_object_set_new(e, "found", isfinite(measured[k]) ? json_boolean(found[k]) : json_null());
        }
        json_array_append_new(arr, e);
    }
    return arr;
}

static void mask_names(const model_lamps_t *l, uint32_t m, char *buf, size_t n)
{
    buf[0] = 0;
    for (int i = 0; i < l->n; i++)
        if ((m >> i) & 1) snprintf(buf + strlen(buf), n - strlen(buf), "%s%s", buf[0] ? "+" : "", l->lamps[i].name);
}

int lightplan_cmd(int argc, char **argv)
{
    if (argc < 2 || strcmp(argv[1], "lamps")) {
        if (argc >= 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
            usage(stdout);
            return 0;
        }
        fprintf(stderr, "usage: refl plan lamps SCENE ... (refl plan lamps --help)\n");
        return 2;
    }
    argc--;
    argv++;
    pa_t a = { 0 };
    int rc = parse(argc, argv, &a);
    if (rc) return rc < 0 ? 0 : rc;
    int exit_code = 1;
    json_t *prov = model_provenance(argc, argv);
    model_scene_t *scene = NULL, *rot = NULL;
    model_camera_t *cam = NULL;
    model_lamps_t *lamps = NULL;
    model_materials_t *mfile = NULL;
    model_material_t *mm = NULL;
    const model_material_t **mats = NULL;
    calib_set_t *gc = NULL, *wc = NULL;
    verify_priors_t pr = { 0 };
    lightplan_result_t res = { 0 };
    verify_lab_t *lab = NULL;
    float *frame = NULL;
    json_t *check = NULL;
    bool *found = NULL;
    double *meas = NULL;
    double A[16], exps[64];
    int nexp = 0;
    const char *ex = a.exposures ? a.exposures : "500,1000,2000,4000,8000,16000";
    {
        char *dup = strdup(ex), *save = NULL;
        for (char *t = strtok_r(dup, ", ", &save); t; t = strtok_r(NULL, ", ", &save)) {
            double v;
            if (nexp >= 64 || !model_parse_double(t, &v) || !(v > 0)) {
                free(dup);
                json_decref(prov);
                return uerr("--exposures-us: '%s' is not a list of up to 64 positive exposures in us", ex);
            }
            exps[nexp++] = v;
        }
        free(dup);
    }
    if (!(scene = model_scene_load(a.scene, NULL)) || !(cam = model_camera_load(a.camera))) goto done;
    model_provenance_input(prov, "scene", a.scene);
    model_provenance_input(prov, "camera", a.camera);
    if (g_str_has_suffix(a.lamps, ".json")) {
        if (!a.white) {
            model_error(a.lamps, 0, "a lamps.json has positions only: give --white WHITE.json for kc*I");
            goto done;
        }
        if (!(wc = calib_set_load_files(a.camera, a.lamps, NULL, a.white))) goto done;
        lamps = wc->lamps;
        for (int i = 0; i < lamps->n && i < 16; i++) A[i] = wc->kcI_per_us[i];
        model_provenance_input(prov, "white", a.white);
    } else {
        if (!(lamps = model_lamps_load(a.lamps))) goto done;
        if (!(a.kc_per_us > 0)) {
            model_error(a.lamps, 0, "a lamps INI needs --kc-per-us X (kc*I = X * intensity)");
            goto done;
        }
        for (int i = 0; i < lamps->n && i < 16; i++) A[i] = a.kc_per_us * lamps->lamps[i].intensity;
    }
    model_provenance_input(prov, "lamps", a.lamps);
    if (lamps->n > 16) {
        model_error(a.lamps, 0, "%d candidate lamps: at most 16", lamps->n);
        goto done;
    }
    // materials: INI or priors (means)
    mats = calloc((size_t)scene->nmaterials + 1, sizeof *mats);
    mm = calloc((size_t)scene->nmaterials + 1, sizeof *mm);
    if (!mats || !mm) goto done;
    if (g_str_has_suffix(a.materials, ".json")) {
        for (int k = 0; k < a.nmat; k++) {
            if (!verify_priors_load(&pr, a.matfiles[k])) goto done;
            model_provenance_input(prov, "materials", a.matfiles[k]);
        }
        for (int k = 0; k < scene->nmaterials; k++) {
            const verify_prior_t *p = verify_priors_find(&pr, scene->material_names[k]);
            if (!p) {
                model_error(a.materials, 0, "no priors for the scene's material '%s'", scene->material_names[k]);
                goto done;
            }
            snprintf(mm[k].name, sizeof mm[k].name, "%s", p->name);
            mm[k].model = p->model;
            memcpy(mm[k].p, p->mean, sizeof mm[k].p);
            mats[k] = &mm[k];
        }
    } else {
        if (a.nmat > 1) {
            model_error(a.materials, 0, "one materials INI (several files: priors JSON)");
            goto done;
        }
        if (!(mfile = model_materials_load(a.materials))) goto done;
        if (!model_resolve_materials(scene, mfile, mats)) goto done;
        model_provenance_input(prov, "materials", a.materials);
    }
    lightplan_sensor_t sensor = { .offset_dn = a.offset_dn, .saturation_dn = a.saturation_dn };
    if (a.gain) {
        char *gj = g_strdup_printf("%s/gain.json", a.gain);
        // the loader wants lamps.json: a minimal one
        model_mkdir_p(a.out);
        char *tl = g_strdup_printf("%s/.lamps.json", a.out);
        json_t *lj = json_pack("{s:[{s:s,s:[f,f,f]}]}", "lamps", "name", "x", "position_mm", 0.0, 0.0, 1000.0);
        model_write_json(tl, lj);
        json_decref(lj);
        gc = calib_set_load_files(a.camera, tl, gj, NULL);
        unlink(tl);
        g_free(tl);
        if (gc) model_provenance_input(prov, "gain", gj);
        g_free(gj);
        if (!gc) goto done;
        sensor.K_dn_per_e = gc->gain_dn_per_e;
        sensor.read_noise_e = gc->read_noise_e;
        if (gc->saturation_dn > 0) sensor.saturation_dn = gc->saturation_dn;
        if (gc->offset_dn) {
            double s = 0;
            for (size_t p = 0; p < (size_t)gc->W * gc->H; p++) s += gc->offset_dn[p];
            sensor.offset_dn = s / ((double)gc->W * gc->H);
        }
        sensor.flat = gc->flat;
    }
    if (!(rot = model_scene_rotated_z(scene, a.angle_deg))) goto done;
    fprintf(stderr, "refl plan lamps: %d candidate lamps, %d exposures\n", lamps->n, nexp);
    if (!lightplan_run(rot, cam, lamps, A, mats, &sensor, exps, nexp, &a.opt, &res)) goto done;
    const lightplan_config_t *b = &res.configs[res.best];
    char names[512];
    mask_names(lamps, b->mask, names, sizeof names);
    // the check on the virtual rig
    if (a.truth) {
        fprintf(stderr, "refl plan lamps: checking on the virtual rig (%s)\n", a.truth);
        lab = verify_lab_open(a.truth, a.sample, &a.angle_deg, 1, b->exposure_us, 0, false);
        if (!lab) goto done;
        const model_lamps_t *tl = verify_lab_lamps(lab);
        int map[16];
        for (int i = 0; i < lamps->n; i++) {
            map[i] = model_lamps_find(tl, lamps->lamps[i].name);
            if (map[i] < 0) {
                model_error(a.truth, 0, "candidate lamp '%s' is not one of the virtual rig's lamps: the check renders "
                            "the rig's own lamps", lamps->lamps[i].name);
                goto done;
            }
        }
        int W = res.W, H = res.H, ns = res.nsegments;
        frame = malloc((size_t)W * H * sizeof *frame);
        found = calloc((size_t)(ns ? ns : 1), sizeof *found);
        meas = calloc((size_t)(ns ? ns : 1), sizeof *meas);
        lightplan_segment_t *sg = malloc((size_t)(ns ? ns : 1) * sizeof *sg);
        if (!frame || !found || !meas || !sg) {
            free(sg);
            goto done;
        }
        check = json_object();
        json_t *cfgs = json_array();
        long agree = 0, judged = 0;
        // the chosen set, then each single lamp, at the chosen exposure
        for (int c = -1; c < lamps->n; c++) {
            uint32_t m = c < 0 ? b->mask : 1u << c, tm = 0;
            if (c >= 0 && m == b->mask) continue;
            for (int i = 0; i < lamps->n; i++)
                if ((m >> i) & 1) tm |= 1u << map[i];
            if (!verify_lab_image(lab, 0, tm, NULL, 1, 4242 + (uint64_t)(c + 1), frame)) {
                free(sg);
                goto done;
            }
            lightplan_segments_for(&res, m, b->exposure_us, &a.opt, sg);
            double rate = lightplan_sobel_check(sg, ns, frame, W, H, a.opt.sobel_threshold, found, meas);
            int nj = 0, na = 0;
            for (int s = 0; s < ns; s++)
                if (isfinite(meas[s])) {
                    nj++;
                    na += found[s] == sg[s].detectable;
                }
            agree += na;
            judged += nj;
            char nm[512];
            mask_names(lamps, m, nm, sizeof nm);
            json_t *e = json_pack("{s:s,s:f,s:o,s:i,s:i}", "lamps", nm, "exposure_us", b->exposure_us, "agreement",
                                  isfinite(rate) ? json_real(rate) : json_null(), "segments_judged", nj,
                                  "segments_agreeing", na);
            json_object_set_new(e, "segments", segments_json(sg, ns, scene, found, meas));
            if (c < 0) {
                char *fp = g_strdup_printf("%s/check_frame.tiff", a.out);
                model_mkdir_p(a.out);
                model_meta_t *mt = model_meta_new();
                model_meta_add(mt, "units", "DN (12-bit sensor values as float)");
                model_meta_add(mt, "image", "the virtual rig's frame of the chosen configuration (lamps %s, %g us)", nm,
                               b->exposure_us);
                bool wok = model_tiff_write_float(fp, W, H, frame, model_meta_list(mt));
                model_meta_free(mt);
                g_free(fp);
                if (!wok) {
                    free(sg);
                    goto done;
                }
            }
            json_array_append_new(cfgs, e);
            printf("check: lamps %-28s agreement %5.1f %% (%d of %d segments)\n", nm, 100 * (isfinite(rate) ? rate : 0),
                   na, nj);
        }
        free(sg);
        double overall = judged ? (double)agree / judged : NAN;
        json_object_set_new(check, "configurations", cfgs);
        json_object_set_new(check, "agreement", isfinite(overall) ? json_real(overall) : json_null());
        json_object_set_new(check, "target", json_real(0.95));
        json_object_set_new(check, "rule",
                            json_string("a segment is found when the median, over points every 2 px along it (2 px "
                                        "kept from its ends), of the largest Sobel magnitude within 1.5 px across "
                                        "reaches the threshold; segments under 8 px are not judged; agreement = "
                                        "found == predicted detectable"));
        json_object_set_new(check, "truth", json_string(a.truth));
        model_provenance_input(prov, "virtual_rig_truth", a.truth);
        printf("check: agreement %.1f %% over %ld segments (target 95 %%)\n", 100 * overall, judged);
    }
    // outputs
    if (!model_mkdir_p(a.out)) goto done;
    json_t *doc = json_object();
    json_object_set_new(doc, "scene", json_string(a.scene));
    json_object_set_new(doc, "turntable_deg", json_real(a.angle_deg));
    json_object_set_new(doc, "units_and_conventions",
                        json_string("grey values DN; exposure us; pixels as mrcal ((0,0) the centre of the top-left "
                                    "pixel, x right, y down); rig frame mm; predicted.tiff and the faces' P_* are grey "
                                    "values with the dark offset (sensor.offset_dn), direct light only; dP_dn = the "
                                    "signal (offset excluded, direct light plus one diffuse bounce) 2 px to side 0 "
                                    "minus side 1 of a segment, side 0 to the right of q0 -> q1 (y down), mean along "
                                    "it; sobel_predicted_dn = the median along it of f |dP|, f = 4.0 axis-aligned .. "
                                    "4.24 diagonal"));
    json_t *chosen = json_pack("{s:s,s:f,s:b,s:f,s:i,s:i,s:f,s:i,s:i,s:i}", "lamps", names, "exposure_us",
                               b->exposure_us, "feasible", b->feasible, "detectable_length_px",
                               b->detectable_length_px, "n_detectable", b->n_detectable, "n_segments", b->n_segments,
                               "usable_points", b->usable_points, "glare_pix", b->glare_pix, "saturated_pix",
                               b->saturated_pix, "object_pix", b->object_pix);
    if (!b->feasible)
        json_object_set_new(chosen, "note", json_string("no configuration is free of glare and saturation; this one "
                                                        "has the fewest such pixels"));
    json_object_set_new(chosen, "index", json_integer(res.best));
    {
        // the detector's response to the sensor's noise alone at the object's median signal (the check's rule:
        // the largest |Sobel| of 7 positions across, median along: about 8.7 sigma)
        double *sv = malloc((size_t)res.W * res.H * sizeof *sv);
        int n = 0;
        for (size_t p = 0; sv && p < (size_t)res.W * res.H; p += 4)
            if (res.face_id[p] >= 0) sv[n++] = res.predicted[p] - sensor.offset_dn;
        double med = 0;
        if (n) {
            qsort(sv, (size_t)n, sizeof *sv, model_cmp_double);
            med = sv[n / 2];
        }
        free(sv);
        double sig = sensor.K_dn_per_e > 0
                         ? sqrt(sensor.K_dn_per_e * fmax(med, 0) + pow(sensor.K_dn_per_e * sensor.read_noise_e, 2) + 1.0 / 12)
                         : NAN;
        double nr = 8.7 * sig;
        json_object_set_new(chosen, "median_object_signal_dn", json_real(med));
        json_object_set_new(chosen, "sobel_noise_response_dn", isfinite(nr) ? json_real(nr) : json_null());
        if (isfinite(nr) && a.opt.sobel_threshold < 1.5 * nr)
            fprintf(stderr, "refl plan lamps: warning: the Sobel threshold %.0f DN is close to the detector's response "
                    "to the sensor's noise alone (%.0f DN at the median signal %.0f DN): edges will be found in noise; "
                    "raise --sobel-threshold\n", a.opt.sobel_threshold, nr, med);
    }
    json_object_set_new(doc, "chosen", chosen);
    json_object_set_new(doc, "chosen_index", json_integer(res.best));
    json_t *cf = json_array();
    for (int c = 0; c < res.nconfigs; c++) {
        const lightplan_config_t *k = &res.configs[c];
        char nm[512];
        mask_names(lamps, k->mask, nm, sizeof nm);
        json_array_append_new(cf, json_pack("{s:s,s:f,s:b,s:f,s:i,s:f,s:i,s:i}", "lamps", nm, "exposure_us",
                                            k->exposure_us, "feasible", k->feasible, "detectable_length_px",
                                            k->detectable_length_px, "n_detectable", k->n_detectable, "usable_points",
                                            k->usable_points, "glare_pix", k->glare_pix, "saturated_pix",
                                            k->saturated_pix));
    }
    json_object_set_new(doc, "configurations", cf);
    json_t *gl = json_array();
    for (int i = 0; i < lamps->n; i++) {
        long n = 0;
        for (size_t p = 0; p < (size_t)res.W * res.H; p += 1) n += (res.glare[p] >> i) & 1;
        json_array_append_new(gl, json_pack("{s:s,s:I}", "lamp", lamps->lamps[i].name, "glare_pixels", (json_int_t)n));
    }
    json_object_set_new(doc, "glare_per_lamp", gl);
    json_t *fa = json_array();
    char fb[32];
    for (int f = 0; f < res.nfaces; f++) {
        const lightplan_face_t *F = &res.faces[f];
        if (!F->npix) continue;
        json_t *e = json_pack("{s:s,s:i,s:f,s:f,s:f,s:f,s:i,s:i}", "face", face_name(scene, f, fb, sizeof fb),
                              "pixels_step2", F->npix, "P_min_dn", F->P_min, "P_median_dn", F->P_median, "P_max_dn",
                              F->P_max, "usable_frac", F->usable_frac, "glare_pix", F->glare_pix, "saturated_pix",
                              F->saturated_pix);
        if (f < scene->nfaces)
            json_object_set_new(e, "material", json_string(scene->material_names[scene->faces[f].material]));
        json_array_append_new(fa, e);
    }
    json_object_set_new(doc, "faces", fa);
    json_object_set_new(doc, "segments", segments_json(res.segments, res.nsegments, scene, NULL, NULL));
    if (check) json_object_set_new(doc, "virtual_rig_check", json_incref(check));
    json_t *op = json_pack("{s:f,s:f,s:f,s:f,s:f,s:f,s:i,s:i}", "glare_cone_deg", a.opt.glare_cone_deg,
                           "sobel_threshold_dn", a.opt.sobel_threshold, "floor_snr", a.opt.floor_snr, "floor_dn",
                           a.opt.floor_dn, "saturation_frac", a.opt.saturation_frac, "max_bad_frac",
                           a.opt.max_bad_frac, "max_lamps", a.opt.max_lamps, "spacing_px", a.opt.spacing_px);
    json_object_set_new(doc, "options", op);
    json_object_set_new(doc, "sensor", json_pack("{s:f,s:f,s:f,s:f,s:b}", "offset_dn", sensor.offset_dn,
                                                 "saturation_dn", sensor.saturation_dn, "K_dn_per_e",
                                                 sensor.K_dn_per_e, "read_noise_e", sensor.read_noise_e, "flat_field",
                                                 sensor.flat != NULL));
    json_object_set_new(doc, "provenance", json_incref(prov));
    char *jp = g_strdup_printf("%s/plan.json", a.out);
    bool wok = model_write_json(jp, doc);
    g_free(jp);
    json_decref(doc);
    char *tp = g_strdup_printf("%s/predicted.tiff", a.out);
    model_meta_t *mt = model_meta_new();
    model_meta_add(mt, "units", "DN (predicted grey value, direct light, clipped at saturation)");
    model_meta_add(mt, "image", "lamps %s, %g us", names, b->exposure_us);
    wok = wok && model_tiff_write_float(tp, res.W, res.H, res.predicted, model_meta_list(mt));
    model_meta_free(mt);
    g_free(tp);
    // where each candidate would glare: bit i of the value for lamp i (file order)
    float *gm = wok ? malloc((size_t)res.W * res.H * sizeof *gm) : NULL;
    if (gm) {
        for (size_t p = 0; p < (size_t)res.W * res.H; p++) gm[p] = (float)res.glare[p];
        char *gp = g_strdup_printf("%s/glare.tiff", a.out);
        model_meta_t *gmt = model_meta_new();
        char order[512];
        mask_names(lamps, lamps->n >= 32 ? 0xffffffffu : (1u << lamps->n) - 1, order, sizeof order);
        model_meta_add(gmt, "units", "bit mask as a number: bit i set where candidate lamp i (order: %s) lies within "
                       "%g deg of the mirror direction of the view ray on a non-Lambertian face (specular glare)",
                       order, a.opt.glare_cone_deg);
        wok = model_tiff_write_float(gp, res.W, res.H, gm, model_meta_list(gmt));
        model_meta_free(gmt);
        g_free(gp);
        free(gm);
    }
    if (!wok) goto done;
    printf("refl plan lamps: %s: chosen lamps %s at %g us%s: %d of %d edge segments detectable (%.0f px), "
           "%.0f usable reference points, %d glare and %d saturated pixels (step-2 grid)\n",
           a.scene, names, b->exposure_us, b->feasible ? "" : " (no configuration is free of glare and saturation)",
           b->n_detectable, b->n_segments, b->detectable_length_px, b->usable_points, b->glare_pix, b->saturated_pix);
    if (!a.no_report) {
        if (model_run_script("plan_lamps_report.py", a.out, NULL) != 0) goto done;
        printf("report: %s/index.html\n", a.out);
    }
    exit_code = 0;
done:
    json_decref(check);
    free(found);
    free(meas);
    free(frame);
    verify_lab_free(lab);
    lightplan_result_free(&res);
    verify_priors_free(&pr);
    free(mm);
    free(mats);
    model_materials_free(mfile);
    if (wc) calib_set_free(wc);
    else model_lamps_free(lamps);
    calib_set_free(gc);
    model_scene_free(rot);
    model_scene_free(scene);
    model_camera_free(cam);
    json_decref(prov);
    return exit_code;
}
