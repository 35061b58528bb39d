// calib/white.c — the reference white: kc*I per lamp from observations of a
// Lambertian standard of known albedo (`refl calib white`).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "model/report.h"
#include "model/vec.h"
#include "rig/rig.h"


bool calib_white(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo, const char *out_json,
               json_t *prov)
{
    double kd = albedo / M_PI;
    json_t *top = json_object();
    json_object_set_new(top, "calibration", json_string("reference white: kc*I per lamp"));
    json_object_set_new(top, "units", json_string("kc_I_per_us: DN per microsecond of exposure at 0 dB gain per "
                                                  "(R in 1/sr / d^2 in mm^2), so P - Pa = kc_I_per_us * t_us * "
                                                  "10^(gain_dB/20) * g(x,y) * R / d^2"));
    json_object_set_new(top, "albedo", json_real(albedo));
    if (cal->camera[0]) json_object_set_new(top, "camera", json_string(cal->camera));
    json_object_set_new(top, "sample", json_string(obs->sample));
    json_t *arr = json_array();
    double *v = malloc((size_t)obs->n * sizeof *v);
    bool ok = v != NULL;
    for (int l = 0; ok && l < cal->lamps->n; l++) {
        int n = 0;
        for (int i = 0; i < obs->n; i++)
            if (obs->o[i].lamp == l) v[n++] = obs->o[i].s_dn_per_us * obs->o[i].d_mm * obs->o[i].d_mm / (kd * obs->o[i].c.nl);
        if (n < 10) {
            model_error(out_json, 0, "lamp %s: %d observations of the reference white (need 10): capture it with "
                        "that lamp alone", cal->lamps->lamps[l].name, n);
            ok = false;
            break;
        }
        qsort(v, (size_t)n, sizeof *v, model_cmp_double);
        double med = v[n / 2];
        for (int i = 0; i < n; i++) v[i] = fabs(v[i] - med);
        qsort(v, (size_t)n, sizeof *v, model_cmp_double);
        double mad = 1.4826 * v[n / 2];
        json_t *e = json_object();
        json_object_set_new(e, "name", json_string(cal->lamps->lamps[l].name));
        json_object_set_new(e, "kc_I_per_us", json_real(med));
        json_object_set_new(e, "spread_rel", json_real(mad / med));
        json_object_set_new(e, "std_of_median_rel", json_real(1.2533 * mad / med / sqrt(n)));
        json_object_set_new(e, "n_observations", json_integer(n));
        json_array_append_new(arr, e);
        printf("  %-12s kc*I = %.6g DN/us per (1/sr)/mm^2  (spread %.2f %%, %d windows)\n", cal->lamps->lamps[l].name,
               med, 100 * mad / med, n);
    }
    free(v);
    json_object_set_new(top, "lamps", arr);
    if (prov) json_object_set_new(top, "provenance", json_incref(prov));
    if (ok) {
        char *d = g_path_get_dirname(out_json);
        ok = model_mkdir_p(d) && model_write_json(out_json, top);
        g_free(d);
    }
    json_decref(top);
    return ok;
}

