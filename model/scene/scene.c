// model/scene/scene.c — the scene builder every reader feeds (D3D and OBJ:
// model/scene/d3d.c, obj.c; STL and PLY meshes: model/scene/mesh.c): vertices,
// faces checked (planarity, degeneracy), materials per face, spheres; the
// scene it hands over, its lookup and its release.
//
// A face is checked when it is complete (D3D) or once all vertices are
// known (OBJ, whose positive indices may refer forward): at least 3 vertices,
// no vertex twice, non-zero area, every vertex within the planarity tolerance
// of the face's plane (Newell normal through the centroid). D3D also takes
// exact spheres ('@sphere cx cy cz radius' after 'Faces:', of the current
// material).
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
#include "model/scene/internal.h"

// ---------------------------------------------------------------------------
// Scene builder

bool scene_grow(void **p, size_t *cap, size_t need, size_t elem)
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

void scene_builder_free(scene_builder_t *b)
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

bool scene_add_vertex(scene_builder_t *b, int line, model_vec3_t p, int number)
{
    if (b->nv >= SCENE_MAX_ITEMS) {
        model_error(b->name, line, "too many vertices (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    if (!scene_grow((void **)&b->v, &b->cap_v, (size_t)b->nv + 1, sizeof *b->v) ||
        !scene_grow((void **)&b->vnum, &b->cap_vnum, (size_t)b->nv + 1, sizeof *b->vnum))
        goto oom;
    b->v[b->nv] = v3_scale(p, b->unit_mm);
    b->vnum[b->nv] = number;
    b->nv++;
    return true;
oom:
    model_error(b->name, line, "out of memory");
    return false;
}

bool scene_add_ref(scene_builder_t *b, int line, int index)
{
    if (b->nidx >= SCENE_MAX_ITEMS) {
        model_error(b->name, line, "too many face vertices (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    if (!scene_grow((void **)&b->idx, &b->cap_idx, b->nidx + 1, sizeof *b->idx)) {
        model_error(b->name, line, "out of memory");
        return false;
    }
    b->idx[b->nidx++] = index;
    return true;
}

// Material index of a name, added when new.
static int material_of(scene_builder_t *b, const char *name, int line)
{
    int known = GPOINTER_TO_INT(g_hash_table_lookup(b->mat_index, name));
    if (known > 0) return known - 1;
    if (!scene_grow((void **)&b->mat, &b->cap_mat, (size_t)b->nmat + 1, sizeof *b->mat)) goto oom;
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
bool scene_begin_face(scene_builder_t *b, int line)
{
    if (b->nf >= SCENE_MAX_ITEMS) {
        model_error(b->name, line, "too many faces (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    if (!scene_grow((void **)&b->f, &b->cap_f, (size_t)b->nf + 1, sizeof *b->f) ||
        !scene_grow((void **)&b->fstart, &b->cap_fstart, (size_t)b->nf + 1, sizeof *b->fstart))
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
__attribute__((format(printf, 3, 4))) static void face_error(const scene_builder_t *b, const model_face_t *f,
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
bool scene_check_face(scene_builder_t *b, int k, size_t end)
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

static bool valid_material_name(scene_tok_t t)
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
bool scene_set_material(scene_builder_t *b, const scene_lexer_t *lx, const char *keyword)
{
    char q[200];
    if (lx->ntoks != 2) {
        model_error(b->name, lx->line, "'%s' takes one material name (%s NAME), got %zu",
                    keyword, keyword, lx->ntoks - 1);
        return false;
    }
    scene_tok_t t = lx->toks[1];
    if (!valid_material_name(t)) {
        model_error(b->name, lx->line,
                    "invalid material name %s: use 1 to 63 characters from A-Z a-z 0-9 _ . -",
                    scene_quote(t, q));
        return false;
    }
    memcpy(b->cur_mat_name, t.p, t.n);
    b->cur_mat_name[t.n] = 0;
    b->cur_mat = material_of(b, b->cur_mat_name, lx->line);
    return b->cur_mat >= 0;
}

// "@sphere cx cy cz radius" (mm): a sphere of the current material.
bool scene_add_sphere(scene_builder_t *b, const scene_lexer_t *lx)
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
        scene_num_t st = scene_tok_double(lx->toks[1 + i], &x[i]);
        if (st != SCENE_NUM_OK) {
            model_error(b->name, lx->line, "@sphere: %s %s %s", what[i], scene_quote(lx->toks[1 + i], q),
                        st == SCENE_NUM_NONFINITE
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
    if (b->nsph >= SCENE_MAX_ITEMS) {
        model_error(b->name, lx->line, "too many spheres (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    int m = b->cur_mat;
    if (m < 0 && (m = material_of(b, "default", lx->line)) < 0) return false;
    if (!scene_grow((void **)&b->sph, &b->cap_sph, (size_t)b->nsph + 1, sizeof *b->sph)) {
        model_error(b->name, lx->line, "out of memory");
        return false;
    }
    b->sph[b->nsph++] = (model_sphere_t){ .centre_mm = v3(x[0], x[1], x[2]), .radius_mm = x[3],
                                          .material = m, .line = lx->line };
    return true;
}

// Hand the builder's arrays over to a scene.
model_scene_t *scene_finish(scene_builder_t *b, const char *text, size_t len)
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
    *b = (scene_builder_t){ 0 };
    return s;
}

bool scene_setup(scene_builder_t *b, scene_lexer_t *lx, const char *text, size_t len, const char *name,
                 const model_scene_options_t *opt)
{
    *b = (scene_builder_t){ .name = name ? name : "(scene)", .cur_mat = -1,
                            .mat_index = g_hash_table_new(g_str_hash, g_str_equal) };
    *lx = (scene_lexer_t){ .text = text, .len = len, .name = b->name };
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
// Meshes (STL, PLY: model/scene/mesh.c)

model_scene_t *model_scene_from_mesh_(const model_mesh_t *m, const char *name, const char *text, size_t len,
                                      const model_scene_options_t *opt)
{
    scene_builder_t b;
    scene_lexer_t lx;
    model_scene_t *scene = NULL;
    if (!scene_setup(&b, &lx, text, len, name, opt)) goto done;
    b.binary = m->binary;
    for (int i = 0; i < m->nv; i++) {
        const double *p = m->v + 3 * (size_t)i;
        if (!scene_add_vertex(&b, 0, v3(p[0], p[1], p[2]), i + 1)) goto done;
    }
    for (int k = 0; k < m->nf; k++) {
        if (!scene_begin_face(&b, m->floc[k])) goto done;
        for (size_t i = m->fstart[k]; i < m->fstart[k + 1]; i++)
            if (!scene_add_ref(&b, m->floc[k], m->idx[i])) goto done;
        if (!scene_check_face(&b, k, b.nidx)) goto done;
    }
    scene = scene_finish(&b, text, len);
done:
    scene_builder_free(&b);
    free(lx.toks);
    return scene;
}

// ---------------------------------------------------------------------------
// Lookup, release

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
