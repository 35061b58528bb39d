// model/scene/scene.c — scenes: the D3D and Wavefront OBJ readers, face checks
// (planarity, degeneracy), materials per face, rotation about the turntable
// axis; the scene of an STL or PLY mesh (read by model/scene/mesh.c); the unit
// of the file's coordinates (--units).
//
// Both readers work on (text, len) without assuming a NUL terminator, split the
// text into lines and the lines into blank-separated tokens, and feed one
// builder. A face is checked when it is complete (D3D) or once all vertices are
// known (OBJ, whose positive indices may refer forward): at least 3 vertices,
// no vertex twice, non-zero area, every vertex within the planarity tolerance
// of the face's plane (Newell normal through the centroid). D3D also takes
// exact spheres ('@sphere cx cy cz radius' after 'Faces:', of the current
// material); their centres rotate with the vertices in model_scene_rotated_z.
#define _GNU_SOURCE
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <glib.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "model/internal.h"

#define MAX_ITEMS (INT_MAX / 2)   // vertices, faces, face-vertex references

// ---------------------------------------------------------------------------
// Tokens

typedef struct {
    const char *p;
    size_t      n;
} tok_t;

static bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

static bool tok_is(tok_t t, const char *word)
{
    size_t n = strlen(word);
    return t.n == n && memcmp(t.p, word, n) == 0;
}

static bool tok_is_ci(tok_t t, const char *word)
{
    size_t n = strlen(word);
    return t.n == n && strncasecmp(t.p, word, n) == 0;
}

// The token quoted for a message: at most 40 characters, non-printable bytes as \xHH.
static const char *quote(tok_t t, char out[200])
{
    size_t o = 0;
    out[o++] = '\'';
    for (size_t i = 0; i < t.n && i < 40; i++) {
        unsigned char c = (unsigned char)t.p[i];
        if (c >= 0x20 && c < 0x7f && c != '\\')
            out[o++] = (char)c;
        else
            o += (size_t)snprintf(out + o, 8, "\\x%02x", c);
    }
    if (t.n > 40) {
        memcpy(out + o, "...", 3);
        o += 3;
    }
    out[o++] = '\'';
    out[o] = 0;
    return out;
}

// A decimal integer with optional sign, the whole token. No overflow.
static bool tok_long(tok_t t, long *out)
{
    size_t i = 0;
    bool neg = false;
    if (i < t.n && (t.p[i] == '+' || t.p[i] == '-')) neg = t.p[i++] == '-';
    if (i == t.n) return false;
    long v = 0;
    for (; i < t.n; i++) {
        if (t.p[i] < '0' || t.p[i] > '9') return false;
        int d = t.p[i] - '0';
        if (v > (LONG_MAX - d) / 10) return false;
        v = v * 10 + d;
    }
    *out = neg ? -v : v;
    return true;
}

typedef enum { NUM_OK, NUM_BAD, NUM_NONFINITE } num_status_t;

// A floating-point number, the whole token. Underflow gives the rounded value.
static num_status_t tok_double(tok_t t, double *out)
{
    char buf[256];
    if (t.n == 0 || t.n >= sizeof buf) return NUM_BAD;
    memcpy(buf, t.p, t.n);
    buf[t.n] = 0;
    char *end;
    errno = 0;
    double v = strtod(buf, &end);
    if (end == buf || *end) return NUM_BAD;
    if (!isfinite(v) || (errno == ERANGE && fabs(v) > 1.0)) return NUM_NONFINITE;
    *out = v;
    return NUM_OK;
}

// Lines of the text, each cut at '#' and split into tokens.
typedef struct {
    const char *text;
    size_t      len, pos;
    int         line;
    const char *name;
    tok_t      *toks;
    size_t      ntoks, cap;
} lexer_t;

// Next line: false at the end of the text or on error (*err set).
static bool lex_line(lexer_t *lx, bool *err)
{
    *err = false;
    if (lx->pos >= lx->len) return false;
    if (lx->line == INT_MAX) {
        model_error(lx->name, 0, "too many lines");
        *err = true;
        return false;
    }
    lx->line++;
    const char *s = lx->text + lx->pos;
    const char *nl = memchr(s, '\n', lx->len - lx->pos);
    size_t n = nl ? (size_t)(nl - s) : lx->len - lx->pos;
    lx->pos += n + (nl ? 1 : 0);
    if (memchr(s, 0, n)) {
        model_error(lx->name, lx->line,
                    "the line contains a NUL byte; a scene file must be text (is this a binary file?)");
        *err = true;
        return false;
    }
    const char *hash = memchr(s, '#', n);
    if (hash) n = (size_t)(hash - s);
    lx->ntoks = 0;
    size_t i = 0;
    while (i < n) {
        while (i < n && is_blank(s[i])) i++;
        if (i == n) break;
        size_t b = i;
        while (i < n && !is_blank(s[i])) i++;
        if (lx->ntoks == lx->cap) {
            size_t nc = lx->cap ? 2 * lx->cap : 16;
            tok_t *nt = realloc(lx->toks, nc * sizeof *nt);
            if (!nt) {
                model_error(lx->name, lx->line, "out of memory");
                *err = true;
                return false;
            }
            lx->toks = nt;
            lx->cap = nc;
        }
        lx->toks[lx->ntoks++] = (tok_t){ s + b, i - b };
    }
    return true;
}

// ---------------------------------------------------------------------------
// Scene builder

typedef struct {
    const char   *name;
    double        tol_mm;
    model_vec3_t *v;
    int          *vnum;       // vertex number as the file names it (messages)
    int           nv;
    size_t        cap_v, cap_vnum;
    int          *idx;        // face-vertex references, all faces
    size_t        nidx, cap_idx;
    model_face_t *f;
    size_t       *fstart;     // offset of each face's references in idx
    int           nf;
    size_t        cap_f, cap_fstart;
    char        **mat;
    GHashTable   *mat_index;  // name (owned by mat) -> index + 1
    int           nmat;
    size_t        cap_mat;
    int           cur_mat;    // material of the next faces; -1: "default"
    char          cur_mat_name[64];
    model_sphere_t *sph;      // D3D @sphere
    int           nsph;
    size_t        cap_sph;
    double        unit_mm;    // mm per unit of the file's coordinates
    bool          binary;     // face lines are byte offsets (binary STL / PLY)
} builder_t;

static bool grow(void **p, size_t *cap, size_t need, size_t elem)
{
    if (need <= *cap) return true;
    size_t nc = *cap ? *cap : 64;
    while (nc < need) nc *= 2;
    void *np = realloc(*p, nc * elem);
    if (!np) return false;
    *p = np;
    *cap = nc;
    return true;
}

static void builder_free(builder_t *b)
{
    free(b->v);
    free(b->vnum);
    free(b->idx);
    free(b->f);
    free(b->fstart);
    free(b->sph);
    if (b->mat_index) g_hash_table_destroy(b->mat_index);
    for (int i = 0; i < b->nmat; i++) free(b->mat[i]);
    free(b->mat);
}

static bool add_vertex(builder_t *b, int line, model_vec3_t p, int number)
{
    if (b->nv >= MAX_ITEMS) {
        model_error(b->name, line, "too many vertices (more than %d)", MAX_ITEMS);
        return false;
    }
    if (!grow((void **)&b->v, &b->cap_v, (size_t)b->nv + 1, sizeof *b->v) ||
        !grow((void **)&b->vnum, &b->cap_vnum, (size_t)b->nv + 1, sizeof *b->vnum))
        goto oom;
    b->v[b->nv] = v3_scale(p, b->unit_mm);
    b->vnum[b->nv] = number;
    b->nv++;
    return true;
oom:
    model_error(b->name, line, "out of memory");
    return false;
}

static bool add_ref(builder_t *b, int line, int index)
{
    if (b->nidx >= MAX_ITEMS) {
        model_error(b->name, line, "too many face vertices (more than %d)", MAX_ITEMS);
        return false;
    }
    if (!grow((void **)&b->idx, &b->cap_idx, b->nidx + 1, sizeof *b->idx)) {
        model_error(b->name, line, "out of memory");
        return false;
    }
    b->idx[b->nidx++] = index;
    return true;
}

// Material index of a name, added when new.
static int material_of(builder_t *b, const char *name, int line)
{
    int known = GPOINTER_TO_INT(g_hash_table_lookup(b->mat_index, name));
    if (known > 0) return known - 1;
    if (!grow((void **)&b->mat, &b->cap_mat, (size_t)b->nmat + 1, sizeof *b->mat)) goto oom;
    char *s = strdup(name);
    if (!s) goto oom;
    b->mat[b->nmat] = s;
    g_hash_table_insert(b->mat_index, s, GINT_TO_POINTER(b->nmat + 1));
    return b->nmat++;
oom:
    model_error(b->name, line, "out of memory");
    return -1;
}

// Start a face at the current end of idx.
static bool begin_face(builder_t *b, int line)
{
    if (b->nf >= MAX_ITEMS) {
        model_error(b->name, line, "too many faces (more than %d)", MAX_ITEMS);
        return false;
    }
    if (!grow((void **)&b->f, &b->cap_f, (size_t)b->nf + 1, sizeof *b->f) ||
        !grow((void **)&b->fstart, &b->cap_fstart, (size_t)b->nf + 1, sizeof *b->fstart))
        goto oom;
    int m = b->cur_mat;
    if (m < 0 && (m = material_of(b, "default", line)) < 0) return false;
    b->f[b->nf] = (model_face_t){ .material = m, .line = line, .number = b->nf + 1 };
    b->fstart[b->nf] = b->nidx;
    b->nf++;
    return true;
oom:
    model_error(b->name, line, "out of memory");
    return false;
}

// A face's error at its line, or at its byte offset in a binary file.
__attribute__((format(printf, 3, 4))) static void face_error(const builder_t *b, const model_face_t *f,
                                                             const char *fmt, ...)
{
    char m[600];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(m, sizeof m, fmt, ap);
    va_end(ap);
    if (b->binary) model_error(b->name, 0, "byte offset %d: %s", f->line, m);
    else model_error(b->name, f->line, "%s", m);
}

static int cmp_int(const void *a, const void *b)
{
    int x = *(const int *)a, y = *(const int *)b;
    return (x > y) - (x < y);
}

// Close face k (its references are idx[fstart[k] .. end)) and check it.
static bool check_face(builder_t *b, int k, size_t end)
{
    model_face_t *f = &b->f[k];
    size_t n = end - b->fstart[k];
    if (n < 3) {
        face_error(b, f,
                    "face %d has %zu %s; a face needs at least 3 (list its vertex numbers, then '.')",
                    f->number, n, n == 1 ? "vertex" : "vertices");
        return false;
    }
    f->nverts = (int)n;
    const int *ix = b->idx + b->fstart[k];   // idx is not NULL: n >= 3
    // The same vertex twice.
    int dup = -1;
    if (n <= 32) {
        for (size_t i = 0; i < n && dup < 0; i++)
            for (size_t j = i + 1; j < n; j++)
                if (ix[i] == ix[j]) { dup = ix[i]; break; }
    } else {
        int *s = malloc(n * sizeof *s);
        if (!s) {
            face_error(b, f, "out of memory");
            return false;
        }
        memcpy(s, ix, n * sizeof *s);
        qsort(s, n, sizeof *s, cmp_int);
        for (size_t i = 1; i < n; i++)
            if (s[i] == s[i - 1]) { dup = s[i]; break; }
        free(s);
    }
    if (dup >= 0) {
        face_error(b, f,
                    "face %d uses vertex %d twice; a face lists each of its vertices once",
                    f->number, b->vnum[dup]);
        return false;
    }
    // Centroid, Newell normal (about the centroid, for accuracy), size.
    model_vec3_t c = v3(0, 0, 0);
    for (size_t i = 0; i < n; i++) c = v3_add(c, v3_scale(b->v[ix[i]], 1.0 / (double)n));
    model_vec3_t nn = v3(0, 0, 0);
    double r2 = 0;
    for (size_t i = 0; i < n; i++) {
        model_vec3_t a = v3_sub(b->v[ix[i]], c), d = v3_sub(b->v[ix[(i + 1) % n]], c);
        nn.x += (a.y - d.y) * (a.z + d.z);
        nn.y += (a.z - d.z) * (a.x + d.x);
        nn.z += (a.x - d.x) * (a.y + d.y);
        r2 = fmax(r2, v3_dot(a, a));
    }
    double area2 = v3_norm(nn);   // twice the area
    if (!isfinite(area2) || !isfinite(r2) || !isfinite(c.x + c.y + c.z)) {
        face_error(b, f,
                    "face %d: its plane cannot be computed because its coordinates are too large "
                    "(coordinates are in mm; check the units)", f->number);
        return false;
    }
    if (!(area2 > 1e-12 * r2)) {
        face_error(b, f,
                    "face %d is degenerate (zero area: its vertices coincide or lie on one line); "
                    "remove it or fix its vertices", f->number);
        return false;
    }
    f->normal = v3_scale(nn, 1.0 / area2);
    f->offset_mm = v3_dot(f->normal, c);
    double worst = -1;
    int worst_v = -1;
    for (size_t i = 0; i < n; i++) {
        double d = fabs(v3_dot(f->normal, v3_sub(b->v[ix[i]], c)));
        if (d > worst) { worst = d; worst_v = ix[i]; }
    }
    if (worst > b->tol_mm) {
        face_error(b, f,
                    "face %d is not planar: vertex %d is %.3g mm from the face's plane "
                    "(tolerance %.3g mm); fix its coordinates, split the face into planar parts, "
                    "or raise the planarity tolerance",
                    f->number, b->vnum[worst_v], worst, b->tol_mm);
        return false;
    }
    return true;
}

static bool valid_material_name(tok_t t)
{
    if (t.n < 1 || t.n > 63) return false;
    for (size_t i = 0; i < t.n; i++) {
        char c = t.p[i];
        if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
              c == '_' || c == '.' || c == '-'))
            return false;
    }
    return true;
}

// "@material NAME" / "usemtl NAME": set the material of the following faces.
static bool set_material(builder_t *b, const lexer_t *lx, const char *keyword)
{
    char q[200];
    if (lx->ntoks != 2) {
        model_error(b->name, lx->line, "'%s' takes one material name (%s NAME), got %zu",
                    keyword, keyword, lx->ntoks - 1);
        return false;
    }
    tok_t t = lx->toks[1];
    if (!valid_material_name(t)) {
        model_error(b->name, lx->line,
                    "invalid material name %s: use 1 to 63 characters from A-Z a-z 0-9 _ . -",
                    quote(t, q));
        return false;
    }
    memcpy(b->cur_mat_name, t.p, t.n);
    b->cur_mat_name[t.n] = 0;
    b->cur_mat = material_of(b, b->cur_mat_name, lx->line);
    return b->cur_mat >= 0;
}

// "@sphere cx cy cz radius" (mm): a sphere of the current material.
static bool add_sphere(builder_t *b, const lexer_t *lx)
{
    char q[200];
    if (lx->ntoks != 5) {
        model_error(b->name, lx->line, "'@sphere' takes 4 numbers (@sphere cx cy cz radius, in mm), "
                    "got %zu", lx->ntoks - 1);
        return false;
    }
    static const char *what[4] = { "centre x", "centre y", "centre z", "radius" };
    double x[4];
    for (int i = 0; i < 4; i++) {
        num_status_t st = tok_double(lx->toks[1 + i], &x[i]);
        if (st != NUM_OK) {
            model_error(b->name, lx->line, "@sphere: %s %s %s", what[i], quote(lx->toks[1 + i], q),
                        st == NUM_NONFINITE
                            ? "is not a finite number; give it in mm as an ordinary number"
                            : "does not parse as a number (@sphere cx cy cz radius, in mm)");
            return false;
        }
    }
    if (!(x[3] > 0)) {
        model_error(b->name, lx->line, "@sphere: radius %g mm must be > 0", x[3]);
        return false;
    }
    for (int i = 0; i < 4; i++) x[i] *= b->unit_mm;
    double big = fmax(fmax(fabs(x[0]), fabs(x[1])), fmax(fabs(x[2]), x[3]));
    if (!(big < 1e150)) {
        model_error(b->name, lx->line, "@sphere: coordinates up to %g are too large to trace "
                    "(coordinates are in mm; check the units)", big);
        return false;
    }
    if (b->nsph >= MAX_ITEMS) {
        model_error(b->name, lx->line, "too many spheres (more than %d)", MAX_ITEMS);
        return false;
    }
    int m = b->cur_mat;
    if (m < 0 && (m = material_of(b, "default", lx->line)) < 0) return false;
    if (!grow((void **)&b->sph, &b->cap_sph, (size_t)b->nsph + 1, sizeof *b->sph)) {
        model_error(b->name, lx->line, "out of memory");
        return false;
    }
    b->sph[b->nsph++] = (model_sphere_t){ .centre_mm = v3(x[0], x[1], x[2]), .radius_mm = x[3],
                                          .material = m, .line = lx->line };
    return true;
}

// Hand the builder's arrays over to a scene.
static model_scene_t *finish(builder_t *b, const char *text, size_t len)
{
    model_scene_t *s = calloc(1, sizeof *s);
    if (!s || !(s->path = strdup(b->name))) {
        free(s);
        model_error(b->name, 0, "out of memory");
        return NULL;
    }
    s->nvertices = b->nv;
    s->vertices = b->v;
    s->nfaces = b->nf;
    s->faces = b->f;
    s->nmaterials = b->nmat;
    s->material_names = b->mat;
    s->vert_storage_ = b->idx;
    s->nspheres = b->nsph;
    s->spheres = b->sph;
    for (int k = 0; k < b->nf; k++) {
        s->faces[k].verts = b->idx + b->fstart[k];
        if (b->binary) s->faces[k].line = 0;   // no line in a binary file
    }
    model_sha256_hex(text ? text : "", len, s->sha256);
    free(b->vnum);
    free(b->fstart);
    g_hash_table_destroy(b->mat_index);
    *b = (builder_t){ 0 };
    return s;
}

static bool setup(builder_t *b, lexer_t *lx, const char *text, size_t len, const char *name,
                  const model_scene_options_t *opt)
{
    *b = (builder_t){ .name = name ? name : "(scene)", .cur_mat = -1,
                      .mat_index = g_hash_table_new(g_str_hash, g_str_equal) };
    *lx = (lexer_t){ .text = text, .len = len, .name = b->name };
    model_scene_options_t o = opt ? *opt : MODEL_SCENE_OPTIONS_DEFAULT;
    if (!(o.planarity_tol_mm >= 0) || !isfinite(o.planarity_tol_mm)) {
        model_error(b->name, 0, "planarity tolerance %g mm is invalid; give a finite value >= 0",
                    o.planarity_tol_mm);
        return false;
    }
    b->tol_mm = o.planarity_tol_mm;
    b->unit_mm = o.unit_mm == 0 ? 1 : o.unit_mm;
    if (!(b->unit_mm > 0) || !isfinite(b->unit_mm)) {
        model_error(b->name, 0, "the unit %g mm is invalid; give a finite value > 0 (--units mm, m or in)", o.unit_mm);
        return false;
    }
    if (!text && len > 0) {
        model_error(b->name, 0, "no text to parse");
        return false;
    }
    return true;
}

// ---------------------------------------------------------------------------
// D3D

model_scene_t *model_scene_parse_d3d(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt)
{
    builder_t b;
    lexer_t lx;
    model_scene_t *scene = NULL;
    GHashTable *numbers = g_hash_table_new(g_direct_hash, g_direct_equal);  // number -> index+1
    GHashTable *lines = g_hash_table_new(g_direct_hash, g_direct_equal);    // number -> line
    bool in_faces = false, open = false;   // open: a face has been started and not ended
    char q[200];
    if (!setup(&b, &lx, text, len, name, opt)) goto done;
    const char *nm = b.name;

    bool err;
    while (lex_line(&lx, &err)) {
        size_t t0 = 0;
        if (!in_faces) {
            if (lx.ntoks == 0) continue;
            if (tok_is_ci(lx.toks[0], "faces:")) {
                in_faces = true;
                t0 = 1;
            } else if (tok_is(lx.toks[0], "@material")) {
                model_error(nm, lx.line, "@material belongs after the 'Faces:' line (it sets the "
                            "material of the faces that follow it)");
                goto done;
            } else if (tok_is(lx.toks[0], "@sphere")) {
                model_error(nm, lx.line, "@sphere belongs after the 'Faces:' line (a sphere is "
                            "a primitive like a face, of the current material)");
                goto done;
            } else if (lx.ntoks != 4) {
                model_error(nm, lx.line,
                            "a vertex line has 4 fields (number x y z), this one has %zu%s", lx.ntoks,
                            tok_is_ci(lx.toks[0], "faces") ? "; the faces start after a line 'Faces:'"
                                                           : "");
                goto done;
            } else {
                long num;
                if (!tok_long(lx.toks[0], &num) || num < 1 || num > INT_MAX) {
                    model_error(nm, lx.line,
                                "vertex number %s does not parse: use a positive integer up to %d "
                                "(a vertex line is 'number x y z'; faces start after 'Faces:')",
                                quote(lx.toks[0], q), INT_MAX);
                    goto done;
                }
                double xyz[3];
                for (int i = 0; i < 3; i++) {
                    num_status_t st = tok_double(lx.toks[1 + i], &xyz[i]);
                    if (st != NUM_OK) {
                        model_error(nm, lx.line, "vertex %ld: coordinate %s %s", num,
                                    quote(lx.toks[1 + i], q),
                                    st == NUM_NONFINITE
                                        ? "is not a finite number; give it in mm as an ordinary number"
                                        : "does not parse as a number (give x y z in mm)");
                        goto done;
                    }
                }
                gpointer key = GINT_TO_POINTER((int)num);
                if (g_hash_table_contains(numbers, key)) {
                    model_error(nm, lx.line,
                                "vertex %ld is defined twice (first on line %d); give each vertex "
                                "its own number",
                                num, GPOINTER_TO_INT(g_hash_table_lookup(lines, key)));
                    goto done;
                }
                if (!add_vertex(&b, lx.line, v3(xyz[0], xyz[1], xyz[2]), (int)num)) goto done;
                g_hash_table_insert(numbers, key, GINT_TO_POINTER(b.nv));
                g_hash_table_insert(lines, key, GINT_TO_POINTER(lx.line));
                continue;
            }
        }
        // Faces section.
        if (lx.ntoks > t0 && lx.toks[t0].n > 0 && lx.toks[t0].p[0] == '@') {
            bool sphere = tok_is(lx.toks[t0], "@sphere");
            if (!sphere && !tok_is(lx.toks[t0], "@material")) {
                model_error(nm, lx.line, "unknown directive %s; the directives are '@material NAME' "
                            "and '@sphere cx cy cz radius'", quote(lx.toks[t0], q));
                goto done;
            }
            const char *dname = sphere ? "@sphere" : "@material";
            if (t0 != 0) {
                model_error(nm, lx.line, "%s must be on a line of its own", dname);
                goto done;
            }
            if (open) {
                model_error(nm, lx.line,
                            "face %d (line %d) is not ended by '.' before %s; end each face "
                            "with '.'", b.f[b.nf - 1].number, b.f[b.nf - 1].line, dname);
                goto done;
            }
            if (sphere ? !add_sphere(&b, &lx) : !set_material(&b, &lx, "@material")) goto done;
            continue;
        }
        for (size_t t = t0; t < lx.ntoks; t++) {
            tok_t tk = lx.toks[t];
            bool ends = tk.n > 0 && tk.p[tk.n - 1] == '.';
            tok_t vt = { tk.p, ends ? tk.n - 1 : tk.n };
            if (!open && !begin_face(&b, lx.line)) goto done;
            open = true;
            model_face_t *f = &b.f[b.nf - 1];
            if (vt.n > 0) {
                if (vt.p[0] == '@') {
                    model_error(nm, lx.line, "%s must be on a line of its own",
                                tok_is(vt, "@sphere") ? "@sphere" : "@material");
                    goto done;
                }
                long num;
                if (!tok_long(vt, &num) || num < 1) {
                    model_error(nm, lx.line,
                                "face %d: %s is not a vertex number; a face is a list of vertex "
                                "numbers ended by '.'", f->number, quote(tk, q));
                    goto done;
                }
                gpointer hit = num <= INT_MAX ? g_hash_table_lookup(numbers, GINT_TO_POINTER((int)num))
                                              : NULL;
                if (!hit) {
                    model_error(nm, lx.line,
                                "face %d refers to vertex %ld, which does not exist; define it "
                                "before 'Faces:' or fix the number", f->number, num);
                    goto done;
                }
                if (!add_ref(&b, lx.line, GPOINTER_TO_INT(hit) - 1)) goto done;
            }
            if (ends) {
                if (!check_face(&b, b.nf - 1, b.nidx)) goto done;
                open = false;
            }
        }
    }
    if (err) goto done;
    if (!in_faces) {
        model_error(nm, 0, "no 'Faces:' line; a D3D file lists numbered vertices "
                           "('number x y z'), then a line 'Faces:', then the faces");
        goto done;
    }
    if (open) {
        model_error(nm, b.f[b.nf - 1].line,
                    "face %d is not ended by '.' (the file ends inside it); end each face with '.'",
                    b.f[b.nf - 1].number);
        goto done;
    }
    if (b.nf == 0 && b.nsph == 0) {
        model_error(nm, 0, "no faces after 'Faces:'; list each face's vertex numbers ended by '.' "
                           "(or give a sphere: '@sphere cx cy cz radius')");
        goto done;
    }
    scene = finish(&b, text, len);
done:
    builder_free(&b);
    free(lx.toks);
    g_hash_table_destroy(numbers);
    g_hash_table_destroy(lines);
    return scene;
}

// ---------------------------------------------------------------------------
// OBJ

// One face-vertex reference "v", "v/vt", "v/vt/vn" or "v//vn": the vertex
// index as written (non-zero); vt and vn are checked for syntax only.
static bool obj_ref(tok_t t, long *v)
{
    tok_t part[3];
    int np = 0;
    size_t b = 0;
    for (size_t i = 0; i <= t.n; i++) {
        if (i == t.n || t.p[i] == '/') {
            if (np == 3) return false;
            part[np++] = (tok_t){ t.p + b, i - b };
            b = i + 1;
        }
    }
    long x;
    if (!tok_long(part[0], v) || *v == 0) return false;
    if (np >= 2 && (np == 2 || part[1].n > 0) && (!tok_long(part[1], &x) || x == 0)) return false;
    if (np == 3 && (!tok_long(part[2], &x) || x == 0)) return false;
    return true;
}

model_scene_t *model_scene_parse_obj(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt)
{
    builder_t b;
    lexer_t lx;
    model_scene_t *scene = NULL;
    char q[200];
    if (!setup(&b, &lx, text, len, name, opt)) goto done;
    const char *nm = b.name;

    bool err;
    while (lex_line(&lx, &err)) {
        if (lx.ntoks == 0) continue;
        tok_t kw = lx.toks[0];
        if (tok_is(kw, "v")) {
            if (lx.ntoks != 4 && lx.ntoks != 5) {
                model_error(nm, lx.line, "'v' takes 3 or 4 numbers (v x y z [w]), got %zu",
                            lx.ntoks - 1);
                goto done;
            }
            double xyz[4];
            for (size_t i = 1; i < lx.ntoks; i++) {
                num_status_t st = tok_double(lx.toks[i], &xyz[i - 1]);
                if (st != NUM_OK) {
                    model_error(nm, lx.line, "vertex %d: %s %s", b.nv + 1, quote(lx.toks[i], q),
                                st == NUM_NONFINITE
                                    ? "is not a finite number; give coordinates in mm as ordinary numbers"
                                    : "does not parse as a number (v x y z [w])");
                    goto done;
                }
            }
            if (!add_vertex(&b, lx.line, v3(xyz[0], xyz[1], xyz[2]), b.nv + 1)) goto done;
        } else if (tok_is(kw, "f")) {
            if (!begin_face(&b, lx.line)) goto done;
            int number = b.f[b.nf - 1].number;
            for (size_t i = 1; i < lx.ntoks; i++) {
                long v;
                if (!obj_ref(lx.toks[i], &v)) {
                    model_error(nm, lx.line,
                                "face %d: %s is not a vertex reference (v, v/vt, v/vt/vn or v//vn "
                                "with non-zero indices)", number, quote(lx.toks[i], q));
                    goto done;
                }
                if (v < 0) {
                    // Relative to the vertices defined so far.
                    if (-v > b.nv) {
                        model_error(nm, lx.line,
                                    "face %d: vertex index %ld refers before the first vertex "
                                    "(only %d vertices are defined above this line)", number, v, b.nv);
                        goto done;
                    }
                    v = b.nv + v + 1;
                } else if (v > INT_MAX) {
                    v = INT_MAX;   // cannot exist; reported once all vertices are known
                }
                if (!add_ref(&b, lx.line, (int)(v - 1))) goto done;
            }
        } else if (tok_is(kw, "usemtl")) {
            if (!set_material(&b, &lx, "usemtl")) goto done;
        } else if (tok_is(kw, "vn") || tok_is(kw, "vt") || tok_is(kw, "o") || tok_is(kw, "g") ||
                   tok_is(kw, "s") || tok_is(kw, "mtllib") || tok_is(kw, "l")) {
            continue;
        } else {
            model_error(nm, lx.line,
                        "unsupported OBJ statement %s; refl reads v, f and usemtl and ignores "
                        "vn, vt, o, g, s, mtllib and l", quote(kw, q));
            goto done;
        }
    }
    if (err) goto done;
    if (b.nf == 0) {
        model_error(nm, 0, "no faces ('f' statements)");
        goto done;
    }
    for (int k = 0; k < b.nf; k++) {
        size_t end = k + 1 < b.nf ? b.fstart[k + 1] : b.nidx;
        for (size_t i = b.fstart[k]; i < end; i++) {
            if (b.idx[i] >= b.nv) {
                if (b.idx[i] == INT_MAX - 1)
                    model_error(nm, b.f[k].line, "face %d refers to a vertex index beyond %d, "
                                "which does not exist (the file has %d vertices)",
                                b.f[k].number, INT_MAX - 1, b.nv);
                else
                    model_error(nm, b.f[k].line, "face %d refers to vertex %d, which does not exist "
                                "(the file has %d vertices)", b.f[k].number, b.idx[i] + 1, b.nv);
                goto done;
            }
        }
        if (!check_face(&b, k, end)) goto done;
    }
    scene = finish(&b, text, len);
done:
    builder_free(&b);
    free(lx.toks);
    return scene;
}

// ---------------------------------------------------------------------------
// Files, lookup, rotation

// ---------------------------------------------------------------------------
// Meshes (STL, PLY: model/scene/mesh.c)

model_scene_t *model_scene_from_mesh_(const model_mesh_t *m, const char *name, const char *text, size_t len,
                                      const model_scene_options_t *opt)
{
    builder_t b;
    lexer_t lx;
    model_scene_t *scene = NULL;
    if (!setup(&b, &lx, text, len, name, opt)) goto done;
    b.binary = m->binary;
    for (int i = 0; i < m->nv; i++) {
        const double *p = m->v + 3 * (size_t)i;
        if (!add_vertex(&b, 0, v3(p[0], p[1], p[2]), i + 1)) goto done;
    }
    for (int k = 0; k < m->nf; k++) {
        if (!begin_face(&b, m->floc[k])) goto done;
        for (size_t i = m->fstart[k]; i < m->fstart[k + 1]; i++)
            if (!add_ref(&b, m->floc[k], m->idx[i])) goto done;
        if (!check_face(&b, k, b.nidx)) goto done;
    }
    scene = finish(&b, text, len);
done:
    builder_free(&b);
    free(lx.toks);
    return scene;
}

// ---------------------------------------------------------------------------
// Files, lookup, rotation

bool model_units_parse(const char *s, double *unit_mm)
{
    static const struct { const char *n; double mm; } u[] = { { "mm", 1 }, { "m", 1000 }, { "in", 25.4 } };
    for (size_t i = 0; s && i < sizeof u / sizeof u[0]; i++)
        if (!strcmp(s, u[i].n)) {
            *unit_mm = u[i].mm;
            return true;
        }
    return false;
}

// A mesh whose whole extent is under 5 mm with no unit given was probably
// drawn in metres (or inches): say so.
static void units_warning(model_scene_t *s, const model_scene_options_t *opt)
{
    if (opt && opt->unit_mm != 0) return;
    double lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
    for (int i = 0; i < s->nvertices; i++) {
        const double p[3] = { s->vertices[i].x, s->vertices[i].y, s->vertices[i].z };
        for (int k = 0; k < 3; k++) lo[k] = fmin(lo[k], p[k]), hi[k] = fmax(hi[k], p[k]);
    }
    double ext = fmax(fmax(hi[0] - lo[0], hi[1] - lo[1]), hi[2] - lo[2]);
    if (!(ext < MODEL_SCENE_SMALL_MM)) return;
    snprintf(s->warning, sizeof s->warning, "the whole scene spans %.3g mm (the largest side of its bounding box), "
             "read in mm as no --units was given: if its coordinates are metres or inches, give --units m or "
             "--units in", ext);
    if (!model_error_quiet_global()) fprintf(stderr, "%s: warning: %s\n", s->path, s->warning);
}

model_scene_t *model_scene_load(const char *path, const model_scene_options_t *opt)
{
    if (!path) {
        model_error(NULL, 0, "model_scene_load: no path given");
        return NULL;
    }
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    bool d3d = dot && strcasecmp(dot, ".d3d") == 0, obj = dot && strcasecmp(dot, ".obj") == 0;
    bool stl = dot && strcasecmp(dot, ".stl") == 0, ply = dot && strcasecmp(dot, ".ply") == 0;
    size_t len;
    char *text = model_read_file(path, &len);
    if (!text) return NULL;
    // STL and PLY are told by their content (whatever the name); D3D and OBJ by the name.
    model_mesh_format_t mf = model_mesh_format_(text, len, !stl);
    if (mf == MODEL_MESH_PLY) ply = true, stl = false;
    else if (mf != MODEL_MESH_NONE) stl = true, ply = false;
    model_scene_t *s = NULL;
    if (stl || ply) s = stl ? model_scene_parse_stl(text, len, path, opt) : model_scene_parse_ply(text, len, path, opt);
    else if (d3d || obj)
        s = d3d ? model_scene_parse_d3d(text, len, path, opt) : model_scene_parse_obj(text, len, path, opt);
    else
        model_error(path, 0, "unknown scene format%s%s%s: neither STL nor PLY by its content; name a D3D file .d3d "
                    "and an OBJ file .obj", dot ? " '" : " (no extension)", dot ? dot : "", dot ? "'" : "");
    free(text);
    if (s && !d3d) units_warning(s, opt);
    return s;
}

void model_scene_free(model_scene_t *scene)
{
    if (!scene) return;
    free(scene->vertices);
    free(scene->faces);
    for (int i = 0; i < scene->nmaterials; i++) free(scene->material_names[i]);
    free(scene->material_names);
    free(scene->path);
    free(scene->vert_storage_);
    free(scene->spheres);
    free(scene);
}

int model_scene_material_index(const model_scene_t *scene, const char *name)
{
    if (!scene || !name) return -1;
    for (int i = 0; i < scene->nmaterials; i++)
        if (strcmp(scene->material_names[i], name) == 0) return i;
    return -1;
}

// cos and sin of an angle in degrees, exact at multiples of 90 degrees.
static void sincos_deg(double deg, double *s, double *c)
{
    double r = fmod(deg, 360.0);
    if (r < 0) r += 360.0;
    if (r == 0 || r == 90 || r == 180 || r == 270) {
        int q = (int)(r / 90);
        static const double sn[4] = { 0, 1, 0, -1 }, cs[4] = { 1, 0, -1, 0 };
        *s = sn[q];
        *c = cs[q];
        return;
    }
    *s = sin(r * M_PI / 180.0);
    *c = cos(r * M_PI / 180.0);
}

static model_vec3_t rigid_apply(const double R[9], const double t[3], model_vec3_t p)
{
    return v3(R[0] * p.x + R[1] * p.y + R[2] * p.z + t[0],
              R[3] * p.x + R[4] * p.y + R[5] * p.z + t[1],
              R[6] * p.x + R[7] * p.y + R[8] * p.z + t[2]);
}

model_scene_t *model_scene_transformed(const model_scene_t *scene, const double R[9], const double t[3])
{
    if (!scene) return NULL;
    for (int i = 0; i < 9; i++)
        if (!isfinite(R[i]) || (i < 3 && !isfinite(t[i]))) {
            model_error(scene->path, 0, "scene transform has a non-finite entry");
            return NULL;
        }
    static const double zero[3] = { 0, 0, 0 };
    size_t nrefs = 0;
    for (int k = 0; k < scene->nfaces; k++) nrefs += (size_t)scene->faces[k].nverts;
    model_scene_t *r = calloc(1, sizeof *r);
    if (!r) goto oom;
    r->nvertices = scene->nvertices;
    r->nfaces = scene->nfaces;
    r->vertices = malloc(((size_t)scene->nvertices + 1) * sizeof *r->vertices);
    r->faces = malloc(((size_t)scene->nfaces + 1) * sizeof *r->faces);
    r->vert_storage_ = malloc((nrefs + 1) * sizeof *r->vert_storage_);
    r->material_names = calloc((size_t)scene->nmaterials + 1, sizeof *r->material_names);
    r->path = strdup(scene->path ? scene->path : "");
    r->spheres = malloc(((size_t)(scene->nspheres > 0 ? scene->nspheres : 0) + 1) * sizeof *r->spheres);
    if (!r->vertices || !r->faces || !r->vert_storage_ || !r->material_names || !r->path ||
        !r->spheres)
        goto oom;
    for (int k = 0; k < scene->nspheres; k++) {
        r->spheres[k] = scene->spheres[k];
        r->spheres[k].centre_mm = rigid_apply(R, t, scene->spheres[k].centre_mm);
    }
    r->nspheres = scene->nspheres > 0 ? scene->nspheres : 0;
    for (int i = 0; i < scene->nmaterials; i++) {
        if (!(r->material_names[i] = strdup(scene->material_names[i]))) goto oom;
        r->nmaterials = i + 1;
    }
    memcpy(r->sha256, scene->sha256, sizeof r->sha256);
    for (int i = 0; i < scene->nvertices; i++) r->vertices[i] = rigid_apply(R, t, scene->vertices[i]);
    size_t o = 0;
    for (int k = 0; k < scene->nfaces; k++) {
        model_face_t f = scene->faces[k];
        memcpy(r->vert_storage_ + o, f.verts, (size_t)f.nverts * sizeof(int));
        f.verts = r->vert_storage_ + o;
        o += (size_t)f.nverts;
        f.normal = rigid_apply(R, zero, f.normal);
        // n'.(R x + t) = n.x + n'.t
        f.offset_mm += f.normal.x * t[0] + f.normal.y * t[1] + f.normal.z * t[2];
        r->faces[k] = f;
    }
    return r;
oom:
    model_scene_free(r);
    model_error(scene->path, 0, "out of memory");
    return NULL;
}

// The wedge: R = rotation by tilt about h = (cos az, sin az, 0) (right-handed),
// t = (0, 0, lift) with lift = min z of the scene - min z of the rotated scene.
void model_scene_wedge_pose(const model_scene_t *sc, double tilt_deg, double az_deg, double R[9], double t[3])
{
    double a = tilt_deg * M_PI / 180, b = az_deg * M_PI / 180;
    double hx = cos(b), hy = sin(b), c = cos(a), s_ = sin(a), C = 1 - c;
    double M[9] = { c + hx * hx * C, hx * hy * C, hy * s_,
                    hx * hy * C, c + hy * hy * C, -hx * s_,
                    -hy * s_, hx * s_, c };
    memcpy(R, M, sizeof M);
    double zmin0 = INFINITY, zmin1 = INFINITY;
    for (int i = 0; i < sc->nvertices; i++) {
        model_vec3_t p = sc->vertices[i];
        zmin0 = fmin(zmin0, p.z);
        zmin1 = fmin(zmin1, R[6] * p.x + R[7] * p.y + R[8] * p.z);
    }
    for (int k = 0; k < sc->nspheres; k++) {
        model_vec3_t p = sc->spheres[k].centre_mm;
        double r = sc->spheres[k].radius_mm;
        zmin0 = fmin(zmin0, p.z - r);
        zmin1 = fmin(zmin1, R[6] * p.x + R[7] * p.y + R[8] * p.z - r);
    }
    t[0] = t[1] = 0;
    t[2] = isfinite(zmin0) && isfinite(zmin1) ? zmin0 - zmin1 : 0;
}

model_scene_t *model_scene_rotated_z(const model_scene_t *scene, double angle_deg)
{
    if (!scene) return NULL;
    if (!isfinite(angle_deg)) {
        model_error(scene->path, 0, "rotation angle %g deg is not finite", angle_deg);
        return NULL;
    }
    double s, c;
    sincos_deg(angle_deg, &s, &c);
    const double R[9] = { c, -s, 0, s, c, 0, 0, 0, 1 }, t[3] = { 0, 0, 0 };
    return model_scene_transformed(scene, R, t);
}
