// model/cameramodel.c — a .cameramodel file's text checked, then read by libmrcal
//
// The checker walks the text once (model/cameramodel.h states the grammar),
// counting lines for its messages; it allocates nothing and keeps no value but
// the lens model. mrcal then parses a copy of the text with a line break
// appended (a last comment line without one is where mrcal's parser reads past
// the end).
#define _GNU_SOURCE
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/cameramodel.h"
#include "model/internal.h"

#define MAX_TEXT       (64u << 20)   // bytes: a camera model of the largest splined lens is a few 100 kB
#define MAX_NUMBER     64            // characters of one number (mrcal copies each onto its stack)
#define MAX_LENSNAME   200           // characters of the lens model's name
#define MAX_DEPTH      32            // nesting of the lists of other keys
#define MAX_IMAGERSIDE 65535

enum { KEY_LENSMODEL, KEY_INTRINSICS, KEY_EXTRINSICS, KEY_IMAGERSIZE, KEY_OTHER };
static const char *const key_names[] = { "lensmodel", "intrinsics", "extrinsics", "imagersize" };

typedef struct {
    const char       *s, *end, *name;
    int               line;
    int               key_line[KEY_OTHER];   // where each key mrcal needs was seen (0: not yet)
    mrcal_lensmodel_t lm;
    int               nparams;               // the lens model's
    char              lensname[MAX_LENSNAME + 1];
} cm_t;

__attribute__((format(printf, 2, 3))) static bool fail(const cm_t *c, const char *fmt, ...)
{
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    model_error(c->name, c->line, "not a readable .cameramodel: %s", msg);
    return false;
}

// What the cursor is at, for a message.
static const char *here(const cm_t *c, char *buf, size_t cap)
{
    if (c->s >= c->end) return "the end of the file (is the file cut short?)";
    unsigned char ch = (unsigned char)*c->s;
    if (ch >= 0x20 && ch < 0x7f) snprintf(buf, cap, "'%c'", ch);
    else snprintf(buf, cap, "byte 0x%02x", ch);
    return buf;
}

static int peek(const cm_t *c) { return c->s < c->end ? (unsigned char)*c->s : -1; }

// Blanks and '#' comments (to the end of the line or of the file).
static void skip(cm_t *c)
{
    while (c->s < c->end) {
        char ch = *c->s;
        if (ch == '\n') c->line++;
        if (ch == ' ' || ch == '\t' || ch == '\r' || ch == '\n') c->s++;
        else if (ch == '#') {
            while (c->s < c->end && *c->s != '\n') c->s++;
        } else break;
    }
}

// A quoted string ('...' or "...", optionally b'...'); its text into out (cut
// to cap-1 characters; *n its full length) when out is given.
static bool string_value(cm_t *c, const char *what, char *out, size_t cap, size_t *n)
{
    char b[16];
    if (peek(c) == 'b') c->s++;
    int q = peek(c);
    if (q != '\'' && q != '"') return fail(c, "expected %s as a quoted string, found %s", what, here(c, b, sizeof b));
    const char *start = ++c->s;
    while (c->s < c->end && *c->s != q) {
        if (*c->s == '\n' || *c->s == '\'' || *c->s == '"')
            return fail(c, "%s: the string opened by %c is not closed on its line", what, q);
        c->s++;
    }
    if (c->s >= c->end) return fail(c, "%s: the file ends inside a string (is the file cut short?)", what);
    size_t len = (size_t)(c->s - start);
    c->s++;
    if (out) {
        size_t k = len < cap ? len : cap - 1;
        memcpy(out, start, k);
        out[k] = '\0';
    }
    if (n) *n = len;
    return true;
}

static bool is_delim(int ch)
{
    return ch < 0 || strchr(" \t\r\n#,])}", ch) != NULL;
}

// A decimal number: -?digits[.digits][(e|E)[+-]digits], finite. *uint: it is
// an unsigned integer as mrcal reads one ("0" or no leading zero); *plus: its
// exponent has a '+'.
static bool number_value(cm_t *c, const char *what, bool *uint, bool *plus, double *out)
{
    char b[16];
    const char *p = c->s, *start = c->s;
    bool neg = false, dot = false, exp = false;
    int mant = 0;
    *plus = false;
    if (p < c->end && *p == '-') neg = true, p++;
    const char *digits = p;
    while (p < c->end && *p >= '0' && *p <= '9') p++, mant++;
    const char *intend = p;
    if (p < c->end && *p == '.') {
        dot = true;
        p++;
        while (p < c->end && *p >= '0' && *p <= '9') p++, mant++;
    }
    if (mant && p < c->end && (*p == 'e' || *p == 'E')) {
        exp = true;
        p++;
        if (p < c->end && (*p == '+' || *p == '-')) *plus = *p++ == '+';
        const char *e = p;
        while (p < c->end && *p >= '0' && *p <= '9') p++;
        if (p == e) {
            c->s = p;
            return fail(c, "%s: the exponent of a number has no digits", what);
        }
    }
    if (!mant || !is_delim(p < c->end ? (unsigned char)*p : -1)) {
        c->s = p;
        return fail(c, "%s: expected a decimal number, found %s", what, here(c, b, sizeof b));
    }
    if (p - start > MAX_NUMBER) return fail(c, "%s: a number of %d characters (at most %d)", what, (int)(p - start), MAX_NUMBER);
    char tok[MAX_NUMBER + 1];
    memcpy(tok, start, (size_t)(p - start));
    tok[p - start] = '\0';
    char *e = NULL;
    double v = strtod(tok, &e);
    if (e != tok + (p - start) || !isfinite(v)) return fail(c, "%s: %s is not a finite number", what, tok);
    *uint = !neg && !dot && !exp && (intend - digits == 1 || digits[0] != '0');
    *out = v;
    c->s = p;
    return true;
}

// A list of numbers (flat: the keys mrcal needs; *n their count, each an
// unsigned integer when uint, the first cap of them into vals) or, for another
// key, of numbers and lists (no '+' in exponents: mrcal skips those lists by
// their characters).
static bool list_value(cm_t *c, const char *what, bool flat, bool uint, int depth, int *n, double *vals, int cap)
{
    char b[16];
    int open = peek(c);
    if (open != '[' && open != '(') return fail(c, "expected %s as a list '[...]', found %s", what, here(c, b, sizeof b));
    if (depth > MAX_DEPTH) return fail(c, "%s: lists nested deeper than %d", what, MAX_DEPTH);
    int close = open == '[' ? ']' : ')', first_line = c->line;
    c->s++;
    *n = 0;
    for (;;) {
        skip(c);
        int ch = peek(c);
        if (ch == close) break;
        if (ch < 0) return fail(c, "%s: the file ends inside the list opened on line %d (is the file cut short?)", what, first_line);
        if (ch == '[' || ch == '(') {
            if (flat) return fail(c, "%s: a list of numbers, found a nested list", what);
            int m;
            if (!list_value(c, what, false, false, depth + 1, &m, NULL, 0)) return false;
        } else {
            bool u, plus;
            double v;
            if (!number_value(c, what, &u, &plus, &v)) return false;
            if (*n < cap) vals[*n] = v;
            if (uint && !u) return fail(c, "%s: an unsigned integer expected (such as 1280)", what);
            if (!flat && plus) return fail(c, "%s: mrcal reads no '+' in the exponents of this list", what);
        }
        (*n)++;
        skip(c);
        ch = peek(c);
        if (ch == ',') c->s++;
        else if (ch != close) {
            if (ch < 0) return fail(c, "%s: the file ends inside the list opened on line %d (is the file cut short?)", what, first_line);
            return fail(c, "%s: expected ',' or '%c' in the list opened on line %d, found %s", what, close, first_line, here(c, b, sizeof b));
        }
    }
    c->s++;
    return true;
}

static bool lensmodel_value(cm_t *c)
{
    size_t n;
    if (!string_value(c, "'lensmodel'", c->lensname, sizeof c->lensname, &n)) return false;
    if (n > MAX_LENSNAME) return fail(c, "'lensmodel': a name of %zu characters (at most %d)", n, MAX_LENSNAME);
    if (!mrcal_lensmodel_from_name(&c->lm, c->lensname) || !mrcal_lensmodel_type_is_valid(c->lm.type))
        return fail(c, "'lensmodel': '%s' is not a lens model mrcal knows (with its configuration, such as "
                    "LENSMODEL_OPENCV8 or LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=30_Ny=20_fov_x_deg=80)", c->lensname);
    if (c->lm.type == MRCAL_LENSMODEL_SPLINED_STEREOGRAPHIC) {
        const mrcal_LENSMODEL_SPLINED_STEREOGRAPHIC__config_t *k = &c->lm.LENSMODEL_SPLINED_STEREOGRAPHIC__config;
        if ((k->order != 2 && k->order != 3) || k->Nx < 2 || k->Ny < 2 || k->Nx > 1000 || k->Ny > 1000 ||
            k->fov_x_deg < 1 || k->fov_x_deg > 359)
            return fail(c, "'lensmodel': '%s': a splined model needs order 2 or 3, Nx and Ny 2..1000 and fov_x_deg "
                        "1..359", c->lensname);
    }
    c->nparams = mrcal_lensmodel_num_params(&c->lm);
    if (c->nparams < 1 || c->nparams > 2000000)
        return fail(c, "'lensmodel': '%s' has %d parameters", c->lensname, c->nparams);
    return true;
}

static bool key_value(cm_t *c, int key, const char *keytext)
{
    char b[16], what[96];
    int n = 0;
    switch (key) {
    case KEY_LENSMODEL: return lensmodel_value(c);
    case KEY_INTRINSICS:
        if (!c->key_line[KEY_LENSMODEL])
            return fail(c, "'intrinsics' before 'lensmodel' (mrcal reads the lens model first)");
        if (!list_value(c, "'intrinsics'", true, false, 0, &n, NULL, 0)) return false;
        if (n != c->nparams)
            return fail(c, "'intrinsics': %d numbers, lens model %s has %d parameters", n, c->lensname, c->nparams);
        return true;
    case KEY_EXTRINSICS:
        if (!list_value(c, "'extrinsics'", true, false, 0, &n, NULL, 0)) return false;
        if (n != 6) return fail(c, "'extrinsics': %d numbers (rt_cam_ref: 6)", n);
        return true;
    case KEY_IMAGERSIZE: {
        double wh[2];
        if (!list_value(c, "'imagersize'", true, true, 0, &n, wh, 2)) return false;
        if (n != 2) return fail(c, "'imagersize': %d numbers (width, height: 2)", n);
        if (!(wh[0] >= 1 && wh[0] <= MAX_IMAGERSIDE && wh[1] >= 1 && wh[1] <= MAX_IMAGERSIDE))
            return fail(c, "'imagersize': %.0f x %.0f: width and height must be 1..%d pixels", wh[0], wh[1],
                        MAX_IMAGERSIDE);
        return true;
    }
    default:
        snprintf(what, sizeof what, "the value of '%.60s'", keytext);
        int ch = peek(c);
        if (ch == '[' || ch == '(') return list_value(c, what, false, false, 0, &n, NULL, 0);
        if (ch == '\'' || ch == '"' || ch == 'b') return string_value(c, what, NULL, 0, NULL);
        if (ch == '-' || ch == '.' || (ch >= '0' && ch <= '9')) {
            bool u, plus;
            double v;
            return number_value(c, what, &u, &plus, &v);
        }
        return fail(c, "%s: expected a number, a string or a list, found %s", what, here(c, b, sizeof b));
    }
}

bool model_cameramodel_check(const char *text, size_t len, const char *name)
{
    char b[16];
    cm_t c = { .s = text, .end = text + len, .name = name, .line = 1 };
    if (len == 0) return fail(&c, "the file is empty");
    if (len > MAX_TEXT) return fail(&c, "%zu bytes (at most %u)", len, MAX_TEXT);
    const char *nul = memchr(text, '\0', len);
    if (nul) {
        for (const char *p = text; p < nul; p++) c.line += *p == '\n';
        return fail(&c, "a NUL byte (binary data, not an mrcal camera model)");
    }
    skip(&c);
    if (peek(&c) != '{')
        return fail(&c, "expected a '{ ... }' dictionary (an mrcal camera model file), found %s; check the file name",
                    here(&c, b, sizeof b));
    int open_line = c.line;
    c.s++;
    for (;;) {
        skip(&c);
        if (peek(&c) == '}') break;
        char key[64];
        size_t kn;
        if (!string_value(&c, "a key", key, sizeof key, &kn)) return false;
        int k = KEY_OTHER;
        for (int i = 0; i < KEY_OTHER; i++)
            if (kn == strlen(key_names[i]) && !strcmp(key, key_names[i])) k = i;
        if (k != KEY_OTHER && c.key_line[k])
            return fail(&c, "'%s' appears twice (first on line %d)", key, c.key_line[k]);
        if (k != KEY_OTHER) c.key_line[k] = c.line;
        skip(&c);
        if (peek(&c) != ':') return fail(&c, "expected ':' after the key '%s', found %s", key, here(&c, b, sizeof b));
        c.s++;
        skip(&c);
        if (!key_value(&c, k, key)) return false;
        skip(&c);
        int ch = peek(&c);
        if (ch == ',') c.s++;
        else if (ch != '}') {
            if (ch < 0) return fail(&c, "the file ends inside the dictionary opened on line %d (is the file cut short?)", open_line);
            return fail(&c, "expected ',' or '}' after the value of '%s', found %s", key, here(&c, b, sizeof b));
        }
    }
    c.s++;
    skip(&c);
    if (c.s < c.end) return fail(&c, "%s after the dictionary's closing '}'", here(&c, b, sizeof b));
    for (int i = 0; i < KEY_OTHER; i++)
        if (!c.key_line[i])
            return fail(&c, "the key '%s' is missing (needed: lensmodel, intrinsics, extrinsics, imagersize)", key_names[i]);
    return true;
}

mrcal_cameramodel_t *model_cameramodel_parse(const char *text, size_t len, const char *name)
{
    if (!model_cameramodel_check(text, len, name)) return NULL;
    char *copy = malloc(len + 2);
    if (!copy) {
        model_error(name, 0, "out of memory");
        return NULL;
    }
    memcpy(copy, text, len);
    copy[len] = '\n';
    copy[len + 1] = '\0';
    mrcal_cameramodel_t *m = mrcal_read_cameramodel_string(copy, (int)len + 1);
    free(copy);
    if (!m)
        model_error(name, 0, "not a readable .cameramodel: mrcal could not parse it (its reason is printed above)");
    return m;
}

mrcal_cameramodel_t *model_cameramodel_read(const char *path)
{
    size_t len;
    char *text = model_read_file(path, &len);   // reports "path: cannot open: ..."
    if (!text) return NULL;
    mrcal_cameramodel_t *m = model_cameramodel_parse(text, len, path);
    free(text);
    return m;
}
