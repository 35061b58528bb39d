// calib/gain/descriptor.c — the EMVA 1288 descriptor file, the standard's
// data exchange: its grammar and parser (text only: what the fuzzer runs;
// its frames and the writer are exchange.c) (calib/gain/gain.h).
//
// The grammar is the EMVA 1288 working group's reference implementation's
// (github.com/EMVA1288/emva1288, ParseEmvaDescriptorFile and LoadImageData):
// blank lines and lines beginning with '#' are skipped; a line is
// whitespace-separated fields, at least two; "v VERSION"; "n BITS WIDTH
// HEIGHT" (once); "b EXPOSURE_NS PHOTONS" a bright set, "d EXPOSURE_NS" a
// dark one (photons 0), each followed by its "i PATH" lines, at least two;
// numbers may have a decimal comma; paths are relative to the file's
// directory, '\' and '/' both separate. A set of two images is a temporal
// step, of more the spatial set; one set per kind, exposure and photon count;
// every temporal exposure has a dark set and a bright one; the spatial sets
// are one dark and one bright at one exposure. refl refuses an image line
// outside a set (the reference warns) and warns of an unknown line.
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/gain.h"
#include "model/model.h"

void calib_gain_descriptor_free(calib_gain_descriptor_t *d)
{
    for (int i = 0; i < d->npaths; i++) free(d->paths[i]);
    free(d->paths);
    free(d->path_line);
    free(d->sets);
    memset(d, 0, sizeof *d);
}

// A number of a field: decimal commas as points, finite, >= 0.
static bool field_number(const char *s, double *v)
{
    char buf[64];
    if (strlen(s) >= sizeof buf) return false;
    strcpy(buf, s);
    for (char *p = buf; *p; p++)
        if (*p == ',') *p = '.';
    return model_parse_double(buf, v) && *v >= 0;
}

static bool add_path(calib_gain_descriptor_t *d, const char *p, int line)
{
    if (d->npaths % 64 == 0) {
        char **np = realloc(d->paths, sizeof *np * (d->npaths + 64));
        if (np) d->paths = np;
        int *nl = np ? realloc(d->path_line, sizeof *nl * (d->npaths + 64)) : NULL;
        if (nl) d->path_line = nl;
        if (!np || !nl) return false;
    }
    while (*p == '\\') p++;   // a leading '\' is relative: the reference joins the parts to the file's directory
    char *c = strdup(p);
    if (!c) return false;
    for (char *q = c; *q; q++)
        if (*q == '\\') *q = '/';
    d->paths[d->npaths] = c;
    d->path_line[d->npaths++] = line;
    return true;
}

static bool add_set(calib_gain_descriptor_t *d, double exposure_ns, double photons, int line)
{
    if (d->nsets % 64 == 0) {
        calib_gain_desc_set_t *ns = realloc(d->sets, sizeof *ns * (d->nsets + 64));
        if (!ns) return false;
        d->sets = ns;
    }
    d->sets[d->nsets++] = (calib_gain_desc_set_t){ exposure_ns, photons, line, d->npaths, 0, false };
    return true;
}

// The set just read is complete: two images or more, one set per kind, exposure and photon count.
static bool close_set(calib_gain_descriptor_t *d, const char *path)
{
    calib_gain_desc_set_t *s = &d->sets[d->nsets - 1];
    if (s->nimages < 2) {
        model_error_set(path, s->line, "each image set needs at least two images ('i PATH' lines after its 'b' or "
                        "'d' line), this one has %d", s->nimages);
        return false;
    }
    s->spatial = s->nimages > 2;
    for (int k = 0; k < d->nsets - 1; k++) {
        const calib_gain_desc_set_t *o = &d->sets[k];
        if (o->spatial == s->spatial && o->exposure_ns == s->exposure_ns && o->photons == s->photons) {
            model_error_set(path, s->line, "a second %s set at exposure %.6g ns and %.6g photons (the first is at line "
                            "%d): one set each", s->spatial ? "spatial" : "temporal", s->exposure_ns, s->photons,
                            o->line);
            return false;
        }
    }
    return true;
}

// The fields of a line (at most 8 kept; *n counts them all).
static void split_fields(char *s, char **f, int *n)
{
    *n = 0;
    for (char *save = NULL, *p = strtok_r(s, " \t\v\f", &save); p; p = strtok_r(NULL, " \t\v\f", &save)) {
        if (*n < 8) f[*n] = p;
        (*n)++;
    }
}

// One line's fields into d. *in_set: the lines since the last 'b' or 'd' were its images.
static bool parse_line(calib_gain_descriptor_t *d, const char *path, int line, char **f, int nf, bool *in_set)
{
    const char c = f[0][1] ? 0 : f[0][0];
    if (c == 'i') {
        if (!*in_set) {
            model_error_set(path, line, "an image line 'i' outside a set: images follow their 'b EXPOSURE PHOTONS' "
                            "or 'd EXPOSURE' line");
            return false;
        }
        if (nf != 2) {
            model_error_set(path, line, "'i' takes one path (no blanks in it), found %d fields", nf - 1);
            return false;
        }
        if (!f[1][strspn(f[1], "\\")]) {
            model_error_set(path, line, "'i %s': an empty path", f[1]);
            return false;
        }
        if (!add_path(d, f[1], line)) goto oom;
        d->sets[d->nsets - 1].nimages++;
        return true;
    }
    if (*in_set && !close_set(d, path)) return false;
    *in_set = false;
    if (c == 'v') {
        snprintf(d->version, sizeof d->version, "%s", f[1]);
        return true;
    }
    if (c == 'n') {
        long v[3];
        if (nf != 4) {
            model_error_set(path, line, "'n' takes three fields, 'n BITS WIDTH HEIGHT', found %d", nf - 1);
            return false;
        }
        if (d->n_line) {
            model_error_set(path, line, "a second 'n' line (the first is line %d): one per file", d->n_line);
            return false;
        }
        for (int k = 0; k < 3; k++)
            if (!model_parse_int(f[k + 1], &v[k]) || v[k] < 1 || v[k] > (k ? 1000000 : 31)) {
                model_error_set(path, line, "'n BITS WIDTH HEIGHT': %s '%s' is not a whole number in 1..%d",
                                k == 0 ? "BITS" : k == 1 ? "WIDTH" : "HEIGHT", f[k + 1], k ? 1000000 : 31);
                return false;
            }
        d->bits = (int)v[0];
        d->width = (int)v[1];
        d->height = (int)v[2];
        d->n_line = line;
        return true;
    }
    if (c == 'b' || c == 'd') {
        double e, p = 0;
        if (nf != (c == 'b' ? 3 : 2)) {
            model_error_set(path, line, "%s, found %d fields", c == 'b' ? "'b EXPOSURE_NS PHOTONS' (a bright set)"
                            : "'d EXPOSURE_NS' (a dark set)", nf - 1);
            return false;
        }
        if (!field_number(f[1], &e) || !(e > 0) || (c == 'b' && !field_number(f[2], &p))) {
            model_error_set(path, line, "'%s %s%s%s': the exposure (ns) must be a positive number%s", f[0], f[1],
                            c == 'b' ? " " : "", c == 'b' ? f[2] : "", c == 'b' ? ", the photons >= 0" : "");
            return false;
        }
        if (!add_set(d, e, p, line)) goto oom;
        *in_set = true;
        return true;
    }
    model_warning("%s:%d: unknown line '%s ...' skipped (EMVA 1288 descriptors have v, n, b, d and i lines)", path, line,
                  f[0]);
    return true;
oom:
    model_error_set(path, line, "out of memory");
    return false;
}

// The sets as the reference's loader needs them: a bright temporal step,
// each temporal exposure with a dark and a bright set, the spatial sets one
// dark and one bright at one exposure.
static bool check_sets(const calib_gain_descriptor_t *d, const char *path)
{
    int nbright = 0, sdark = -1, sbright = -1;
    for (int i = 0; i < d->nsets; i++) {
        const calib_gain_desc_set_t *s = &d->sets[i];
        if (s->spatial) {
            int *slot = s->photons == 0 ? &sdark : &sbright;
            int other = s->photons == 0 ? sbright : sdark;
            if (*slot >= 0 || (other >= 0 && d->sets[other].exposure_ns != s->exposure_ns)) {
                model_error_set(path, s->line, "the spatial sets (more than two images) are one dark and one bright "
                                "at one exposure; this one is another (the first is at line %d)",
                                d->sets[*slot >= 0 ? *slot : other].line);
                return false;
            }
            *slot = i;
            continue;
        }
        nbright += s->photons > 0;
        bool dark = false, bright = false;
        for (int k = 0; k < d->nsets; k++) {
            const calib_gain_desc_set_t *o = &d->sets[k];
            if (o->spatial || o->exposure_ns != s->exposure_ns) continue;
            dark |= o->photons == 0;
            bright |= o->photons > 0;
        }
        if (!dark || !bright) {
            model_error_set(path, s->line, "exposure %.6g ns has %s: every temporal exposure needs a dark set ('d') "
                            "and a bright one ('b')", s->exposure_ns, dark ? "no bright set" : "no dark set");
            return false;
        }
    }
    if ((sdark >= 0) != (sbright >= 0)) {
        model_error_set(path, d->sets[sdark >= 0 ? sdark : sbright].line, "a spatial %s set without its %s one at the "
                        "same exposure", sdark >= 0 ? "dark" : "bright", sdark >= 0 ? "bright" : "dark");
        return false;
    }
    if (!nbright) {
        model_error_set(path, 0, "no bright temporal step ('b EXPOSURE_NS PHOTONS' with two images)");
        return false;
    }
    return true;
}

bool calib_gain_descriptor_parse(const char *text, size_t n, const char *path, calib_gain_descriptor_t *d)
{
    memset(d, 0, sizeof *d);
    char *buf = malloc(n + 1);
    if (!buf) {
        model_error_set(path, 0, "out of memory for %zu bytes", n);
        return false;
    }
    memcpy(buf, text, n);
    buf[n] = 0;
    bool ok = true, in_set = false;
    int line = 0;
    for (char *l = buf, *end = buf + n; ok && l <= end; line++) {
        char *e = l;
        while (e < end && *e != '\n' && *e != '\r' && *e) e++;
        if (e < end && !*e) {
            model_error_set(path, line + 1, "a NUL byte: not a text file");
            ok = false;
            break;
        }
        char *next = e + 1;
        if (e < end && *e == '\r' && e + 1 < end && e[1] == '\n') next++;
        *e = 0;
        char *s = l;
        while (*s == ' ' || *s == '\t' || *s == '\v' || *s == '\f') s++;
        l = next;
        if (!*s || *s == '#') continue;
        char *f[8];
        int nf;
        split_fields(s, f, &nf);
        if (nf < 2) {
            model_error_set(path, line + 1, "'%s': a line needs a key and a value (v, n, b, d or i lines)", s);
            ok = false;
        } else
            ok = parse_line(d, path, line + 1, f, nf, &in_set);
    }
    if (ok && in_set) ok = close_set(d, path);
    ok = ok && check_sets(d, path);
    free(buf);
    if (!ok) calib_gain_descriptor_free(d);
    return ok;
}
