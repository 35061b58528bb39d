// calib/gain/gain.c — `refl calib gain`'s top level, calib_gain_run: the
// frames of a rig, sessions or a manifest; per camera the analysis of every
// gain, the maps, gain.json and the report (the stages: calib/gain/gain.h;
// the command: calib/cmd_gain.c).
//
// Input: frames of a uniform source (a flat field) at known exposures, light
// (lamps on) and dark (lamps off), from
//   --rig RIG          captured here: per gain a probe, an exposure sweep
//                      (frame pairs, light and dark, up to beyond saturation),
//                      at the first gain also long dark frames (dark current)
//                      and a flat field (many frames at ~50 % of saturation)
//   --session DIR      a session captured elsewhere (light = lamps on, dark = "none")
//   --frames CSV       a manifest "file,exposure_us,kind" (kind dark|light)
//   --emva-descriptor F  an EMVA 1288 descriptor (exposures, photon counts, images)
// Analysis per gain (EMVA 1288 definitions, see calib/gain/gain.h): photon transfer
// (K, read noise, saturation, SNR, dynamic range), linearity error, response
// (DN/us, and kc per us per unit radiance when the source's radiance is
// given; a virtual rig's truth of it is never read here: refl chain compares
// with it); at the first gain also the dark current, the offset and DSNU
// maps and the PRNU map (flat field).
// Output: DIR/gain.json, DIR/offset_dn.tiff, DIR/dsnu_dn.tiff,
// DIR/prnu_gain.tiff (total: vignetting included, mean 1),
// DIR/prnu_highpass.tiff (smooth part removed, mean 1), DIR/report.html + PNGs,
// DIR/datasheet.html (EMVA 1288 by the standard's definitions); with
// --write-emva-descriptor an EMVA 1288 descriptor of the frames.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

calib_gain_opts_t calib_gain_defaults(void)
{
    static const double gains[] = { 0 }, darks[] = { 100000, 500000, 1000000, 2000000 };
    return (calib_gain_opts_t){ .gains_db = gains, .ngains = 1, .dark_exposures_us = darks, .ndark_exposures = 4,
                                .sample = "flat_field", .lamps = "all", .pixel_format = "Mono12", .steps = 50,
                                .flat_frames = 16, .progress = -1, .probe_us = 1000, .max_us = NAN,
                                .min_steps = 50, .radiance = NAN, .max_dn = 65535, .quant_dn = 1, .report = true,
                                .linearisation = MODEL_LIN_MONOTONE, .low_steps = 16, .irradiance_uw_cm2 = NAN,
                                .pixel_area_um2 = NAN, .wavelength_nm = NAN, .defect_sigma = 6,
                                .photodiode_na = NAN, .photodiode_a_per_w = NAN, .photodiode_mm2 = NAN };
}

// The frames of a manifest into d (and the provenance).
static bool manifest_frames(const calib_gain_opts_t *o, calib_gain_data_t *d, json_t *prov)
{
    if (!calib_gain_read_manifest(o->frames, o->max_dn, d) || !model_provenance_input(prov, "manifest", o->frames))
        return false;
    if (o->ngains != 1) {
        model_error_set(o->frames, 0, "a manifest holds frames of one gain: give at most one --gains value (its "
                        "label)");
        return false;
    }
    snprintf(d->gain_unit, sizeof d->gain_unit, "dB");
    for (int i = 0; i < d->nf; i++) d->f[i].gain_db = o->gains_db[0];
    // the frames themselves
    for (int i = 0; i < d->nf; i++) {
        char role[64];
        snprintf(role, sizeof role, "frame line %d", d->f[i].line);
        if (!model_provenance_input(prov, role, d->f[i].path)) {
            char *m = g_strdup(model_last_error());
            model_error_set(o->frames, d->f[i].line, "frame %s: %s", d->f[i].path, m);
            g_free(m);
            return false;
        }
    }
    return true;
}

// The frames of an EMVA 1288 descriptor into d (and the provenance: the file
// and every frame).
static bool descriptor_frames(const calib_gain_opts_t *o, calib_gain_data_t *d, json_t *prov)
{
    if (!calib_gain_read_descriptor(o->descriptor, o->max_dn, d) ||
        !model_provenance_input(prov, "emva1288 descriptor", o->descriptor))
        return false;
    if (o->ngains != 1) {
        model_error_set(o->descriptor, 0, "a descriptor holds frames of one gain: give at most one --gains value (its "
                        "label)");
        return false;
    }
    snprintf(d->gain_unit, sizeof d->gain_unit, "dB");
    for (int i = 0; i < d->nf; i++) {
        char role[64];
        d->f[i].gain_db = o->gains_db[0];
        snprintf(role, sizeof role, "image line %d", d->f[i].line);
        if (!model_provenance_input(prov, role, d->f[i].path)) {
            char *m = g_strdup(model_last_error());
            model_error_set(o->descriptor, d->f[i].line, "image %s: %s", d->f[i].path, m);
            g_free(m);
            return false;
        }
    }
    return true;
}

// path with "-NAME" before its extension (a camera's descriptor of several).
static char *camera_path(const char *path, const char *name)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash)) return g_strdup_printf("%s-%s", path, name);
    return g_strdup_printf("%.*s-%s%s", (int)(dot - path), path, name, dot);
}

// The sessions of the run: captured on o->rig, or given (and the provenance).
static bool gather_sources(const calib_gain_opts_t *o, json_t *prov, calib_gain_source_t **src, int *nsrc)
{
    if (o->rig) return calib_gain_capture(o, prov, src, nsrc);
    *src = calloc(o->nsessions ? o->nsessions : 1, sizeof **src);
    *nsrc = 0;
    if (!*src) {
        model_error_set(NULL, 0, "out of memory for %d sessions", o->nsessions);
        return false;
    }
    for (int i = 0; i < o->nsessions; i++) {
        (*src)[(*nsrc)++] = (calib_gain_source_t){ g_strdup(o->sessions[i]), CALIB_GAIN_SET_ANY, "session" };
        if (!model_provenance_input(prov, "session", o->sessions[i])) return false;
    }
    return true;
}

// The cameras to calibrate (names[], at most CALIB_GAIN_MAX_CAMERAS): those
// of the first session, or o->camera when it has frames there. 0 on error.
static int run_cameras(const calib_gain_opts_t *o, const calib_gain_source_t *src, int nsrc,
                       char names[][32])
{
    rig_session_t *s = nsrc ? rig_session_open(src[0].dir) : NULL;
    if (!s) {
        if (!nsrc) model_error_set(NULL, 0, "no session to read");
        return 0;
    }
    const char *nm[CALIB_GAIN_MAX_CAMERAS];
    int nc = rig_session_cameras(s, nm, CALIB_GAIN_MAX_CAMERAS), n = 0;
    GString *list = g_string_new("");
    for (int k = 0; k < nc && k < CALIB_GAIN_MAX_CAMERAS; k++) {
        g_string_append_printf(list, "%s%s", k ? ", " : "", nm[k]);
        if (!o->camera || !strcmp(o->camera, nm[k])) snprintf(names[n++], 32, "%s", nm[k]);
    }
    if (nc > CALIB_GAIN_MAX_CAMERAS && !o->camera) {
        model_error_set(src[0].dir, 0, "%d cameras: refl calib gain calibrates at most %d at once (give --camera "
                        "NAME)", nc, CALIB_GAIN_MAX_CAMERAS);
        n = 0;
    } else if (!n && nc)
        model_error_set(src[0].dir, 0, "no camera '%s' in the session (its cameras: %s)", o->camera, list->str);
    else if (!nc)
        model_error_set(src[0].dir, 0, "the session has no frames");
    g_string_free(list, TRUE);
    rig_session_free(s);
    return n;
}

// Every gain present (rig: in the order asked; else in order of appearance):
// *an gets *ngains analyses (even on failure: the ones made).
static bool analyse_all(const calib_gain_opts_t *o, calib_gain_data_t *d, calib_gain_an_t **an, int *ngains)
{
    double *gl = malloc(sizeof(double) * (d->ng + o->ngains + 1));
    int ng = 0;
    *an = NULL;
    if (!gl) {
        model_error_set(NULL, 0, "out of memory for the gains");
        return false;
    }
    if (o->rig)
        for (int i = 0; i < o->ngains; i++) gl[ng++] = o->gains_db[i];
    else
        for (int i = 0; i < d->ng; i++) {
            bool seen = false;
            for (int k = 0; k < ng; k++) seen |= gl[k] == d->g[i].gain_db;
            if (!seen) gl[ng++] = d->g[i].gain_db;
        }
    *an = calloc(ng ? ng : 1, sizeof **an);
    bool ok = *an != NULL;
    if (!ok) model_error_set(NULL, 0, "out of memory for the analyses of %d gains", ng);
    for (int i = 0; i < ng && ok; i++) {
        calib_gain_an_t *a = &(*an)[i];
        *ngains = i + 1;
        if (!(ok = calib_gain_analyse(d, gl[i], o->min_steps, o->quant_dn, a))) break;
        a->radiance = o->radiance;   // of the light frames, as given (NAN: unknown)
        a->kc_per_us = a->ptc.response_dn_per_us / a->radiance;
        a->kc0_per_us = a->response0_dn_per_us / a->radiance;
        if (!(ok = calib_gain_an_photons(o, a))) {
            char *m = g_strdup(model_last_error());
            model_error_set(NULL, 0, "gain %g dB: %s", gl[i], m);
            g_free(m);
            break;
        }
        if (!(ok = calib_gain_an_emva(d, o->quant_dn, a))) break;
        model_note("gain %g dB: EMVA 1288 K %.5g DN/e-, sigma_d %.4g e-, mu_e.sat %.6g e-, LE %.3f %%; refl's "
                   "small-signal K %.5g DN/e-, saturation %.1f DN; %d steps", gl[i], a->emva.K, a->emva.sigma_d_e,
                   a->emva.mu_e_sat, a->emva.le_pct, a->ptc.system_gain_dn_per_e, a->ptc.saturation_dn, a->n);
    }
    free(gl);
    return ok;
}

// One camera's frames (d) analysed into dir: gain.json, the maps and the
// report; top (may be NULL): gain.json and the maps also there; desc (may be
// NULL): an EMVA 1288 descriptor of the frames there.
static bool run_one(const calib_gain_opts_t *o, calib_gain_data_t *d, json_t *prov, const char *dir, const char *top,
                    const char *desc, calib_gain_result_t *r)
{
    calib_gain_an_t *an = NULL;
    int ngains = 0;
    calib_gain_maps_t maps = { 0 };
    json_t *root = NULL;
    bool ok = false;
    if (!model_mkdir_p(dir) || !calib_gain_make_groups(d)) return false;
    model_note("analysing %d frames (%d exposure groups)%s%s", d->nf, d->ng, d->camera[0] ? " of camera " : "",
               d->camera);
    if (!calib_gain_frame_stats(d) || !analyse_all(o, d, &an, &ngains)) goto done;
    if (!calib_gain_make_maps(d, &an[0], &maps) || !calib_gain_make_spatial(d, &maps, o->defect_sigma, o->quant_dn) ||
        !calib_gain_write_maps(dir, &maps) || !calib_gain_write_defects(dir, &maps))
        goto done;
    if (top && !(calib_gain_write_maps(top, &maps) && calib_gain_write_defects(top, &maps))) goto done;
    root = calib_gain_json(o, d, an, ngains, &maps, prov);
    ok = root != NULL;
    for (int k = 0; k < (top ? 2 : 1) && ok; k++) {
        char *jp = g_build_filename(k ? top : dir, "gain.json", NULL);
        ok = model_write_json(jp, root);
        g_free(jp);
    }
    if (ok && o->report)
        ok = calib_gain_report(dir, an, ngains, &maps, prov) &&
             calib_gain_datasheet_html(dir, json_object_get(root, "emva1288"), prov);
    if (ok && desc) ok = calib_gain_write_descriptor(desc, o, d, &an[0], &maps);
    if (!ok) goto done;
    *r = (calib_gain_result_t){ .system_gain_dn_per_e = an[0].ptc.system_gain_dn_per_e,
                                .read_noise_e = an[0].ptc.read_noise_e, .saturation_dn = an[0].ptc.saturation_dn,
                                .linearity_error_pct = an[0].ptc.linearity_error_pct, .dsnu_dn = maps.dsnu_dn,
                                .prnu_pct = maps.prnu_pct };
    snprintf(r->camera, sizeof r->camera, "%s", d->camera);
    snprintf(r->dir, sizeof r->dir, "%s", dir);
done:
    for (int i = 0; an && i < ngains; i++) calib_gain_an_free(&an[i]);
    free(an);
    calib_gain_maps_free(&maps);
    json_decref(root);
    return ok;
}

bool calib_gain_run(const calib_gain_opts_t *o, calib_gain_result_t *r, int max, int *n)
{
    *n = 0;
    if (o->rig && o->steps < o->min_steps) {
        model_error_set(NULL, 0, "too few sweep steps: --steps %d, EMVA 1288 asks for at least %d (--min-steps)",
                        o->steps, o->min_steps);
        return false;
    }
    calib_gain_source_t *src = NULL;
    int nsrc = 0, nc = 0;
    char names[CALIB_GAIN_MAX_CAMERAS][32];
    json_t *prov = NULL;
    bool ok = false;
    double t_start = model_now_s();
    if (!model_mkdir_p(o->out)) return false;
    prov = model_provenance(o->argc, o->argv);
    if (o->frames || o->descriptor) {
        calib_gain_data_t d = { 0 };
        memcpy(d.roi, o->roi, sizeof d.roi);
        ok = (o->frames ? manifest_frames(o, &d, prov) : descriptor_frames(o, &d, prov)) && max > 0 &&
             run_one(o, &d, prov, o->out, NULL, o->write_descriptor, &r[0]);
        calib_gain_data_free(&d);
        *n = ok;
        goto done;
    }
    if (!gather_sources(o, prov, &src, &nsrc) || !(nc = run_cameras(o, src, nsrc, names))) goto done;
    ok = true;
    for (int k = 0; k < nc && ok; k++) {
        calib_gain_data_t d = { 0 };
        memcpy(d.roi, o->roi, sizeof d.roi);
        for (int i = 0; i < nsrc && ok; i++) ok = calib_gain_add_session(&d, src[i].dir, names[k], src[i].set, NULL);
        char *dir = nc > 1 ? g_build_filename(o->out, names[k], NULL) : g_strdup(o->out);
        char *desc = o->write_descriptor && nc > 1 ? camera_path(o->write_descriptor, names[k])
                                                   : g_strdup(o->write_descriptor);
        calib_gain_result_t rk;
        ok = ok && run_one(o, &d, prov, dir, nc > 1 && k == 0 ? o->out : NULL, desc, &rk);
        g_free(desc);
        if (ok && *n < max) r[(*n)++] = rk;
        g_free(dir);
        calib_gain_data_free(&d);
    }
done:
    if (ok) model_note("wrote %s/gain.json (%.1f s)", o->out, model_now_s() - t_start);
    calib_gain_sources_free(src, nsrc);
    json_decref(prov);
    return ok;
}
