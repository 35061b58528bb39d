// calib/gain/maps.c — the maps of the reference gain from its flat field
// and dark: offset, DSNU, PRNU (total and high-pass) and their TIFF files
// (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

bool calib_gain_highpass(const float *in, int w, int h, float *out)
{
    double A[36] = { 0 }, b[6] = { 0 };
    const double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1);
    const double sx = cx > 0 ? cx : 1, sy = cy > 0 ? cy : 1;
    for (int y = 0; y < h; y++) {
        double v = (y - cy) / sy;
        // per row: sums over x of the x-dependent terms, then the outer product
        double S[5] = { 0 }, T[3] = { 0 };   // sum u^k (k 0..4), sum u^k * in (k 0..2)
        for (int x = 0; x < w; x++) {
            double u = (x - cx) / sx, f = in[(size_t)y * w + x];
            double u2 = u * u;
            S[0] += 1;
            S[1] += u;
            S[2] += u2;
            S[3] += u2 * u;
            S[4] += u2 * u2;
            T[0] += f;
            T[1] += f * u;
            T[2] += f * u2;
        }
        // basis: 1, u, v, u^2, u v, v^2  = u^a v^b
        static const int pa[6] = { 0, 1, 0, 2, 1, 0 }, pb[6] = { 0, 0, 1, 0, 1, 2 };
        for (int r = 0; r < 6; r++) {
            b[r] += T[pa[r]] * pow(v, pb[r]);
            for (int k = 0; k < 6; k++) A[r * 6 + k] += S[pa[r] + pa[k]] * pow(v, pb[r] + pb[k]);
        }
    }
    if (!model_solve_linear(A, b, 6)) return false;
    for (int y = 0; y < h; y++) {
        double v = (y - cy) / sy;
        for (int x = 0; x < w; x++) {
            double u = (x - cx) / sx;
            double s = b[0] + b[1] * u + b[2] * v + b[3] * u * u + b[4] * u * v + b[5] * v * v;
            size_t i = (size_t)y * w + x;
            out[i] = s != 0 ? (float)(in[i] / s) : NAN;
        }
    }
    return true;
}

void calib_gain_maps_free(calib_gain_maps_t *m)
{
    free(m->offset);
    free(m->dsnu);
    free(m->prnu);
    free(m->prnu_hp);
    calib_gain_spatial_t *sp = &m->sp;
    free(sp->spec_h_dark);   // the four spectrograms' one block
    double *prof[] = { sp->col_dark, sp->row_dark, sp->col_light, sp->row_light };
    for (int i = 0; i < 4; i++) free(prof[i]);
    free(sp->defect_map);
}

static double roi_mean_var(const calib_gain_data_t *d, const float *m, int w, int h, double *var)
{
    int r[4];
    gain_region(w, h, d->roi, r);
    double s = 0, ss = 0;
    long np = (long)r[2] * r[3];
    for (int y = r[1]; y < r[1] + r[3]; y++)
        for (int x = r[0]; x < r[0] + r[2]; x++) {
            double v = m[(size_t)y * w + x];
            s += v;
            ss += v * v;
        }
    double mean = s / np;
    if (var) *var = ss / np - mean * mean;
    return mean;
}

// The flat field of a's gain: the flat set's light group (the most frames),
// else the sweep group with the most frames (ties: nearest 50 % of
// saturation) below saturation. NULL: none.
static const calib_gain_group_t *flat_group(const calib_gain_data_t *d, const calib_gain_an_t *a)
{
    const double sat = a->ptc.saturation_dn;
    const calib_gain_group_t *flat = NULL;
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db == a->gain_db && !g->dark && g->set == CALIB_GAIN_SET_FLAT && (!flat || g->n > flat->n))
            flat = g;
    }
    if (!flat)
        for (int i = 0; i < d->ng; i++) {
            const calib_gain_group_t *g = &d->g[i];
            if (g->gain_db != a->gain_db || g->dark || g->n < 2) continue;
            // the dark-subtracted level of this group
            double lv = g->mean_dn - (a->dark_intercept_dn + a->dark_slope_dn_per_us * g->exposure_us);
            if (lv > 0.9 * sat && g->n <= 2) continue;
            double lf = flat ? flat->mean_dn - (a->dark_intercept_dn + a->dark_slope_dn_per_us * flat->exposure_us)
                             : 0;
            if (!flat || g->n > flat->n || (g->n == flat->n && fabs(lv - 0.5 * sat) < fabs(lf - 0.5 * sat)))
                flat = g;
        }
    return flat;
}

// The flat's dark: the dark group at its exposure (of the flat's set, else
// any) with the most frames (*same true), else the dark group with the most
// frames.
static const calib_gain_group_t *flat_dark_group(const calib_gain_data_t *d, const calib_gain_an_t *a,
                                                 const calib_gain_group_t *flat, bool *same)
{
    const calib_gain_group_t *dark = NULL;
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db != a->gain_db || !g->dark || g->exposure_us != flat->exposure_us) continue;
        bool mine = g->set == flat->set, best_mine = dark && dark->set == flat->set;
        if (!dark || (mine && !best_mine) || (mine == best_mine && g->n > dark->n)) dark = g;
    }
    *same = dark != NULL;
    if (!dark)
        for (int i = 0; i < d->ng; i++) {
            const calib_gain_group_t *g = &d->g[i];
            if (g->gain_db == a->gain_db && g->dark && (!dark || g->n > dark->n)) dark = g;
        }
    return dark;
}

// The flat's level above dark, exposure, saturated fraction and frames into
// m. false + message when it is saturated or below 10 % of saturation.
static bool flat_level(const calib_gain_data_t *d, const calib_gain_an_t *a, const calib_gain_group_t *flat,
                       calib_gain_maps_t *m)
{
    const double sat = a->ptc.saturation_dn;
    char nb[1024];
    double dark_level = a->dark_intercept_dn + a->dark_slope_dn_per_us * flat->exposure_us;
    m->flat_level_dn = flat->mean_dn - dark_level;
    m->flat_exposure_us = flat->exposure_us;
    m->flat_sat_frac = flat->sat_frac;
    m->flat_frames = flat->n;
    // the exposure of 50 % of saturation, from the linearity line
    const double t_half = (0.5 * sat - a->ptc.response_offset_dn) / a->ptc.response_dn_per_us;
    if (flat->sat_frac > 1e-4 || m->flat_level_dn > 0.9 * sat) {
        model_error_set(NULL, 0, "%s: the flat field (%d frames at %.6g us) is saturated: mean %.1f DN above dark "
                        "(%.1f DN grey value), %.3f %% of its pixels at full scale; saturation is at %.1f DN above "
                        "dark: use an exposure near %.0f %% of it (~%.6g us)",
                        gain_frame_name(&d->f[flat->idx[0]], nb, sizeof nb), flat->n, flat->exposure_us,
                        m->flat_level_dn, flat->mean_dn, 100 * flat->sat_frac, sat, 50.0, t_half);
        return false;
    }
    if (m->flat_level_dn < 0.1 * sat) {
        model_error_set(NULL, 0, "%s: the flat field (%d frames at %.6g us) is too dark: mean %.2f DN above dark "
                        "(%.1f DN grey value, dark %.1f DN), below 10 %% of saturation (%.1f DN above dark): use an "
                        "exposure near 50 %% of saturation (~%.6g us)",
                        gain_frame_name(&d->f[flat->idx[0]], nb, sizeof nb), flat->n, flat->exposure_us,
                        m->flat_level_dn, flat->mean_dn, dark_level, sat, t_half);
        return false;
    }
    return true;
}

// One stack averaged (calib_gain_stack_average) into out (floats) with the
// standard's spatial variances over d's region into *sv. false + message.
static bool stack_map(const calib_gain_data_t *d, const calib_gain_group_t *g, int w, int h, double *avg,
                      float *out, calib_gain_stack_var_t *sv)
{
    double stack_var;
    if (!calib_gain_stack_average(d, g, w, h, avg, &stack_var)) return false;
    for (size_t i = 0; i < (size_t)w * h; i++) out[i] = (float)avg[i];
    return calib_gain_stack_variances(avg, w, h, d->roi, g->n, stack_var, sv);
}

// m's four maps allocated (the flat's size); the averaged dark into offset,
// the averaged flat into prnu, the standard's DSNU1288 and PRNU1288 of the
// two stacks (raw) into m->nu. false + message.
static bool average_maps(const calib_gain_data_t *d, const calib_gain_an_t *a, const calib_gain_group_t *flat,
                         const calib_gain_group_t *dark, calib_gain_maps_t *m)
{
    int w = flat->width, h = flat->height;
    size_t n = (size_t)w * h;
    m->w = w;
    m->h = h;
    m->offset = malloc(n * sizeof(float));
    m->dsnu = malloc(n * sizeof(float));
    m->prnu = malloc(n * sizeof(float));
    m->prnu_hp = malloc(n * sizeof(float));
    double *avg = malloc(n * sizeof(double));
    if (!m->offset || !m->dsnu || !m->prnu || !m->prnu_hp || !avg) {
        free(avg);
        model_error_set(NULL, 0, "out of memory for the maps (%dx%d)", w, h);
        return false;
    }
    model_note("flat field: %d light frames at %.6g us (%.0f DN above dark, %.0f %% of saturation), %d dark frames "
               "at %.6g us", flat->n, flat->exposure_us, m->flat_level_dn, 100 * m->flat_level_dn /
               a->ptc.saturation_dn, dark->n, dark->exposure_us);
    bool ok = stack_map(d, dark, w, h, avg, m->offset, &m->nu.dark) && stack_map(d, flat, w, h, avg, m->prnu,
                                                                                    &m->nu.light);
    free(avg);
    if (!ok) return false;
    if (dark->n < 2 || flat->n < 2)
        model_warning("the flat field has %d light and %d dark frames: DSNU1288 and PRNU1288 need two or more of "
                      "each (L >= 2; the standard asks for many)", flat->n, dark->n);
    m->nu.same_exposure = dark->exposure_us == flat->exposure_us;
    calib_gain_nonuniformity(&m->nu);
    m->dark_frames = dark->n;
    m->dark_exposure_us = dark->exposure_us;
    return true;
}

// DSNU (the averaged dark's spatial std, its temporal noise subtracted) and
// the maps: dsnu the dark minus its mean, prnu the flat's signal (minus the
// dark at its exposure), linearised as every consumer linearises it (the
// PRNU of the linear signal: a compressive response would flatten it).
// *slope2: the mean squared slope of the linearisation over the frame.
static void dsnu_and_signal(const calib_gain_data_t *d, const calib_gain_an_t *a, const calib_gain_group_t *flat,
                            const calib_gain_group_t *dark, calib_gain_maps_t *m, double *slope2)
{
    const int w = m->w, h = m->h;
    const size_t n = (size_t)w * h;
    // dark level at the flat's exposure
    double dshift = m->dark_same_exposure ? 0 : a->dark_slope_dn_per_us * (flat->exposure_us - dark->exposure_us);
    double dvar;
    double dmean = roi_mean_var(d, m->offset, w, h, &dvar);
    int roi[4];
    gain_region(w, h, d->roi, roi);
    const double npix = (double)roi[2] * roi[3];
    m->dark_var_dn2 = isfinite(dark->var_dn2) ? dark->var_dn2 : a->var_dark_dn2;
    m->dsnu_total_raw_dn = sqrt(fmax(dvar, 0));
    double dtau = m->dark_var_dn2 / dark->n, d2 = dvar - dtau;
    m->dsnu_dn = sqrt(fmax(d2, 0));
    m->dsnu_std_dn = calib_gain_spatial_std(m->dsnu_dn, dtau, npix);
    bool lin = a->lin.kind != MODEL_LIN_NONE && a->lin.n >= 2;
    double s2 = 0;
    for (size_t i = 0; i < n; i++) {
        double sg = m->prnu[i] - (m->offset[i] + dshift), sl = 1;
        if (lin) sg = model_linearise(&a->lin, sg, 1, &sl);
        s2 += sl * sl;
        m->prnu[i] = (float)sg;   // signal
        m->dsnu[i] = (float)(m->offset[i] - dmean);
    }
    *slope2 = s2 / (double)n;
    m->flat_linearised = lin;
}

// The PRNU of the linear signal scales with the linearisation's log-slope
// d ln S / d ln S_m at the flat's level, which the sweep fixes only as
// well as two linearisations of it agree there (the monotone table in use
// and the parametric S(1 - aS) of the same sweep): their relative
// difference times the PRNU, a systematic part of its 1-sigma.
static void prnu_linearisation_sigma(const calib_gain_an_t *a, calib_gain_maps_t *m)
{
    m->prnu_std_lin_pct = 0;
    if (m->flat_linearised && a->lin.kind == MODEL_LIN_MONOTONE && isfinite(a->lin_a_per_dn) && m->flat_level_dn > 0) {
        model_lin_t par = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = a->lin_a_per_dn };
        double L = m->flat_level_dn, dm, dp;
        double s1 = model_linearise(&a->lin, L, 1, &dm), s2 = model_linearise(&par, L, 1, &dp);
        if (s1 > 0 && s2 > 0 && dm > 0 && dp > 0) {
            m->flat_log_slope = dm * L / s1;
            m->flat_log_slope_parametric = dp * L / s2;
            m->prnu_std_lin_pct = m->prnu_pct * fabs(m->flat_log_slope / m->flat_log_slope_parametric - 1);
        }
    }
}

// PRNU of the signal map (m->prnu): total (vignetting included) and of the
// high-pass map (its quadratic smooth surface removed, m->prnu_hp), the
// temporal noise left in the averages subtracted, with the 1-sigma's parts.
// false + message when the smooth-surface fit is singular.
static bool prnu_figures(const calib_gain_data_t *d, const calib_gain_an_t *a, const calib_gain_group_t *flat,
                         const calib_gain_group_t *dark, double slope2, calib_gain_maps_t *m)
{
    const int w = m->w, h = m->h;
    int roi[4];
    gain_region(w, h, d->roi, roi);
    const double npix = (double)roi[2] * roi[3];
    double svar, smean = roi_mean_var(d, m->prnu, w, h, &svar);
    m->flat_var_dn2 = isfinite(flat->var_dn2) ? flat->var_dn2 : NAN;
    double tvar = ((isfinite(m->flat_var_dn2) ? m->flat_var_dn2 / flat->n : 0) + m->dark_var_dn2 / dark->n) * slope2;
    m->signal_temporal_var_dn2 = tvar;
    m->flat_pixel_std_rel = sqrt(tvar) / smean;
    m->prnu_total_pct = 100 * sqrt(fmax(svar - tvar, 0)) / smean;
    if (!calib_gain_highpass(m->prnu, w, h, m->prnu_hp)) {
        model_error_set(NULL, 0, "flat field: the smooth-surface fit is singular (%dx%d frames)", w, h);
        return false;
    }
    // spatial variance of the high-pass map, in DN^2 of the signal
    double hvar;
    roi_mean_var(d, m->prnu_hp, w, h, &hvar);
    double hp2 = hvar - tvar / (smean * smean);
    m->prnu_pct = 100 * sqrt(fmax(hp2, 0));
    m->prnu_std_stat_pct = 100 * calib_gain_spatial_std(m->prnu_pct / 100, tvar / (smean * smean), npix);
    prnu_linearisation_sigma(a, m);
    m->prnu_std_pct = hypot(m->prnu_std_stat_pct, m->prnu_std_lin_pct);
    return true;
}

bool calib_gain_make_maps(calib_gain_data_t *d, const calib_gain_an_t *a, calib_gain_maps_t *m)
{
    memset(m, 0, sizeof *m);
    const calib_gain_group_t *flat = flat_group(d, a);
    if (!flat) {
        model_error_set(NULL, 0, "gain %g dB: no flat-field frames (light, at least two at one exposure)", a->gain_db);
        return false;
    }
    const calib_gain_group_t *dark = flat_dark_group(d, a, flat, &m->dark_same_exposure);
    m->flat_group = (int)(flat - d->g);
    m->dark_group = dark ? (int)(dark - d->g) : -1;
    if (!dark) {
        model_error_set(NULL, 0, "gain %g dB: no dark frames for the flat field", a->gain_db);
        return false;
    }
    double slope2;
    if (!flat_level(d, a, flat, m) || !average_maps(d, a, flat, dark, m)) return false;
    dsnu_and_signal(d, a, flat, dark, m, &slope2);
    if (!prnu_figures(d, a, flat, dark, slope2, m)) return false;
    // the total map normalised to mean 1 (over the whole frame)
    const size_t n = (size_t)m->w * m->h;
    double s = 0;
    for (size_t i = 0; i < n; i++) s += m->prnu[i];
    s /= n;
    m->prnu_mean_dn = s;
    for (size_t i = 0; i < n; i++) m->prnu[i] = (float)(m->prnu[i] / s);
    return true;
}

static bool write_map(const char *dir, const char *name, const calib_gain_maps_t *m, const float *map, const char *what)
{
    char *path = g_build_filename(dir, name, NULL);
    const char *meta[] = { "content", what, "software", "refl calib gain " REFL_VERSION, NULL };
    bool ok = model_tiff_write_float(path, m->w, m->h, map, meta);
    g_free(path);
    return ok;
}


bool calib_gain_write_maps(const char *dir, const calib_gain_maps_t *m)
{
    return write_map(dir, "offset_dn.tiff", m, m->offset, "dark level (offset) map, DN") &&
           write_map(dir, "dsnu_dn.tiff", m, m->dsnu, "dark signal non-uniformity: dark level minus its mean, DN") &&
           write_map(dir, "prnu_gain.tiff", m, m->prnu,
                     "relative sensitivity g(x,y), mean 1: flat field minus dark, incl. vignetting") &&
           write_map(dir, "prnu_highpass.tiff", m, m->prnu_hp,
                     "PRNU: flat field divided by its quadratic smooth surface (vignetting removed), mean ~1");
}
