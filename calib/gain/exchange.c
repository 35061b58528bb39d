// calib/gain/exchange.c — the standard's data exchange as frames: a run's
// frames from an EMVA 1288 descriptor (its grammar: descriptor.c) and a
// descriptor written for the frames of a run, so that other EMVA 1288 tools
// read refl's measurements (calib/gain/gain.h).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

bool calib_gain_read_descriptor(const char *path, int max_dn, calib_gain_data_t *d)
{
    size_t n;
    char *text = model_read_file(path, &n);
    if (!text) return false;
    calib_gain_descriptor_t ds;
    bool ok = calib_gain_descriptor_parse(text, n, path, &ds);
    free(text);
    if (!ok) return false;
    char *dir = g_path_get_dirname(path);
    const int mdn = ds.n_line ? (int)((1L << ds.bits) - 1) : max_dn;
    for (int i = 0; i < ds.nsets && ok; i++) {
        const calib_gain_desc_set_t *s = &ds.sets[i];
        for (int k = 0; k < s->nimages && ok; k++) {
            const char *p = ds.paths[s->first + k];
            const int line = ds.path_line[s->first + k];
            calib_gain_frame_t f = { .path = p[0] == '/' ? g_strdup(p) : g_build_filename(dir, p, NULL),
                                     .where = g_strdup(path), .line = line, .exposure_us = s->exposure_ns / 1000,
                                     .has_photons = true, .photons = s->photons, .dark = s->photons == 0,
                                     .set = s->spatial ? CALIB_GAIN_SET_FLAT : CALIB_GAIN_SET_SWEEP, .max_dn = mdn,
                                     .nlamps = -1 };
            if (access(f.path, R_OK) != 0) {
                model_error_set(path, line, "image %s: %s", f.path, strerror(errno));
                g_free(f.path);
                g_free(f.where);
                ok = false;
            } else
                ok = gain_add_frame(d, &f);
        }
    }
    // the images' size against the "n" line (the run checks that they agree with each other)
    if (ok && ds.n_line && d->nf > 0) {
        int w = 0, h = 0;
        float *img = gain_frame_load(&d->f[0], &w, &h);
        ok = img != NULL;
        if (ok && (w != ds.width || h != ds.height)) {
            model_error_set(path, d->f[0].line, "image %s is %dx%d pixels, line %d says 'n %d %d %d' (bits, width, "
                            "height)", d->f[0].path, w, h, ds.n_line, ds.bits, ds.width, ds.height);
            ok = false;
        }
        free(img);
    }
    if (ok) snprintf(d->camera, sizeof d->camera, "%s", "");
    g_free(dir);
    calib_gain_descriptor_free(&ds);
    return ok;
}

// The path of a frame relative to the directory dir (both made absolute and
// canonical), "../" where it lies outside; NULL + message when it cannot be
// resolved or holds a blank (a descriptor's fields are blank-separated).
static char *relative_path(const char *dir, const char *file)
{
    char *rd = realpath(dir, NULL), *rf = realpath(file, NULL), *out = NULL;
    if (!rd || !rf) {
        model_error_set(file, 0, "cannot resolve the frame's path: %s", strerror(errno));
        goto done;
    }
    if (strpbrk(rf, " \t\v\f\r\n")) {
        model_error_set(rf, 0, "a blank in the frame's path: an EMVA 1288 descriptor cannot name it (copy the frames "
                        "to a path without blanks)");
        goto done;
    }
    // the longest common prefix ending at a directory boundary: rf[0 .. common), the rest of rd its directories
    size_t common = 0, i = 0, dir_rest;
    for (; rd[i] && rd[i] == rf[i]; i++)
        if (rd[i] == '/') common = i + 1;
    dir_rest = common;
    if (!rd[i] && rf[i] == '/') common = dir_rest = i + 1;   // the file lies under the directory
    if (dir_rest > i) dir_rest = i;
    GString *g = g_string_new("");
    for (const char *p = rd + dir_rest; *p; p++)
        if ((p == rd + dir_rest || p[-1] == '/') && *p != '/') g_string_append(g, "../");
    g_string_append(g, rf + common);
    out = g_string_free(g, FALSE);
done:
    free(rd);
    free(rf);
    return out;
}

// The dark group of a's gain at exposure t with two frames or more (the most), or NULL.
static const calib_gain_group_t *dark_at(const calib_gain_data_t *d, double gain_db, double t, bool spatial)
{
    const calib_gain_group_t *best = NULL;
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db == gain_db && g->dark && g->exposure_us == t && g->n >= 2 &&
            (g->set == CALIB_GAIN_SET_FLAT) == spatial && (!best || g->n > best->n))
            best = g;
    }
    return best;
}

static int cmp_step(const void *a, const void *b)
{
    const calib_gain_group_t *const *x = a, *const *y = b;
    if ((*x)->exposure_us != (*y)->exposure_us) return (*x)->exposure_us < (*y)->exposure_us ? -1 : 1;
    return ((*x)->photons > (*y)->photons) - ((*x)->photons < (*y)->photons);
}

// One set's lines: "d NS" or "b NS PHOTONS" and the first nmax of its frames (0: all).
static bool write_set(GString *s, const char *dir, const calib_gain_data_t *d, const calib_gain_group_t *g,
                      double photons, int nmax)
{
    if (g->dark) g_string_append_printf(s, "d %.15g\n", g->exposure_us * 1000);
    else g_string_append_printf(s, "b %.15g %.15g\n", g->exposure_us * 1000, photons);
    for (int k = 0; k < g->n && (!nmax || k < nmax); k++) {
        char *rel = relative_path(dir, d->f[g->idx[k]].path);
        if (!rel) return false;
        g_string_append_printf(s, "i %s\n", rel);
        g_free(rel);
    }
    return true;
}

bool calib_gain_write_descriptor(const char *path, const calib_gain_opts_t *o, const calib_gain_data_t *d,
                                 const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    const double E = calib_gain_opts_irradiance(o);
    const bool have_e = isfinite(E) && isfinite(o->pixel_area_um2) && isfinite(o->wavelength_nm);
    const calib_gain_group_t **st = malloc(sizeof *st * ((size_t)d->ng + 1));
    if (!st) {
        model_error_set(path, 0, "out of memory for the descriptor");
        return false;
    }
    int ns = 0, skipped = 0, bits = 0;
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db != a->gain_db || g->dark || g->set != CALIB_GAIN_SET_SWEEP || g->n < 2) continue;
        if (!dark_at(d, a->gain_db, g->exposure_us, false)) skipped++;
        else st[ns++] = g;
    }
    qsort(st, ns, sizeof *st, cmp_step);
    while (ns > 0 && bits < 31 && (1L << bits) - 1 < d->f[st[0]->idx[0]].max_dn) bits++;
    char *dir = g_path_get_dirname(path);
    GString *s = g_string_new("");
    g_string_append_printf(s, "# EMVA 1288 descriptor written by refl calib gain %s: the temporal steps (two images "
                           "each), then the spatial set; exposures in ns, photons per pixel\nv 4.0\nn %d %d %d\n",
                           REFL_VERSION, bits, m->w, m->h);
    bool ok = ns > 0;
    if (!ok)
        model_error_set(path, 0, "no sweep step with a pair of light frames and a dark pair at its exposure: nothing "
                        "for a descriptor");
    for (int i = 0; i < ns && ok; i++) {
        const calib_gain_group_t *g = st[i];
        if (!g->has_photons && !have_e) {
            model_error_set(path, 0, "the descriptor needs each step's photon count: give --irradiance (or a "
                            "photodiode reading), --pixel-area-um2 and --wavelength-nm");
            ok = false;
            break;
        }
        double p = g->has_photons ? g->photons : calib_gain_photons(E, o->pixel_area_um2, o->wavelength_nm,
                                                                    g->exposure_us);
        if (i == 0 || st[i - 1]->exposure_us != g->exposure_us)
            ok = write_set(s, dir, d, dark_at(d, a->gain_db, g->exposure_us, false), 0, 2);
        ok = ok && write_set(s, dir, d, g, p, 2);
    }
    const calib_gain_group_t *fl = m->flat_group >= 0 ? &d->g[m->flat_group] : NULL,
                             *fd = m->dark_group >= 0 ? &d->g[m->dark_group] : NULL;
    if (ok && fl && fd && fl->n > 2 && fd->n > 2 && fl->exposure_us == fd->exposure_us) {
        double p = fl->has_photons ? fl->photons : calib_gain_photons(E, o->pixel_area_um2, o->wavelength_nm,
                                                                      fl->exposure_us);
        ok = write_set(s, dir, d, fd, 0, 0) && write_set(s, dir, d, fl, p, 0);
    } else if (ok)
        model_warning("%s: no spatial set written (it needs more than two light and dark frames at one exposure): "
                      "tools that ask for one will refuse the file", path);
    if (ok && skipped)
        model_warning("%s: %d sweep step%s without a dark pair at %s exposure left out (the descriptor needs one per "
                      "exposure)", path, skipped, skipped > 1 ? "s" : "", skipped > 1 ? "their" : "its");
    ok = ok && model_write_file_atomic(path, s->str);
    if (ok) model_note("wrote %s (%d temporal steps, EMVA 1288 descriptor)", path, ns);
    g_string_free(s, TRUE);
    g_free(dir);
    free(st);
    return ok;
}
