// model/scene/mesh.c — mesh scenes: STL (binary and ASCII) and PLY (ASCII and
// binary little-endian; a vertex element with x, y, z and a face element with
// a vertex-index list). Each reader fills a model_mesh_t (internal.h) that
// model_scene_from_mesh_ (scene.c) checks and turns into a scene, like the
// D3D and OBJ readers' faces.
//
// - STL repeats every triangle's corners: equal corners (bit for bit, -0 as 0)
//   become one vertex, numbered in the order of first appearance. The facet
//   normals are ignored (the vertex order, counter-clockwise seen from
//   outside, gives the normal, as for the other formats).
// - Binary STL: 80 header bytes, a little-endian triangle count, 50 bytes per
//   triangle; a file whose size is 84 + 50 x count is binary even when its
//   header begins with "solid" (many writers do that).
// - ASCII STL keywords are read in any case ("FACET NORMAL" too).
// - Errors name the line (ASCII) or the byte offset (binary).
// - Neither format carries refl's materials: every face is "default", as OBJ
//   faces before any usemtl are.
#define _GNU_SOURCE
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "model/internal.h"
#include "model/scene/internal.h"

#define MAXTOK    64   // tokens of an ASCII line: a PLY face of up to 62 vertices

// ---------------------------------------------------------------------------
// The mesh being built

typedef struct {
    model_mesh_t m;
    size_t cap_v, cap_idx, cap_f, cap_loc;
    int *hash;          // STL: open addressing, vertex index or -1
    size_t hcap;
    const char *name;
} mb_t;

void model_mesh_free_(model_mesh_t *m)
{
    free(m->v);
    free(m->idx);
    free(m->fstart);
    free(m->floc);
    memset(m, 0, sizeof *m);
}

static void mb_free(mb_t *b)
{
    model_mesh_free_(&b->m);
    free(b->hash);
}

static bool mb_oom(mb_t *b)
{
    model_error(b->name, 0, "out of memory");
    return false;
}

static bool mb_vertex(mb_t *b, const double p[3], int loc)
{
    if (b->m.nv >= SCENE_MAX_ITEMS) {
        model_error(b->name, b->m.binary ? 0 : loc, "too many vertices (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    if (!scene_grow((void **)&b->m.v, &b->cap_v, 3 * ((size_t)b->m.nv + 1), sizeof(double))) return mb_oom(b);
    memcpy(b->m.v + 3 * (size_t)b->m.nv, p, 3 * sizeof(double));
    b->m.nv++;
    return true;
}

static bool mb_face(mb_t *b, int loc)
{
    if (b->m.nf >= SCENE_MAX_ITEMS) {
        model_error(b->name, b->m.binary ? 0 : loc, "too many faces (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    if (!scene_grow((void **)&b->m.fstart, &b->cap_f, (size_t)b->m.nf + 2, sizeof(size_t)) ||
        !scene_grow((void **)&b->m.floc, &b->cap_loc, (size_t)b->m.nf + 1, sizeof(int)))
        return mb_oom(b);
    b->m.fstart[b->m.nf] = b->m.nidx;
    b->m.floc[b->m.nf] = loc;
    b->m.nf++;
    b->m.fstart[b->m.nf] = b->m.nidx;
    return true;
}

static bool mb_ref(mb_t *b, int index)
{
    if (b->m.nidx >= SCENE_MAX_ITEMS) {
        model_error(b->name, 0, "too many face vertices (more than %d)", SCENE_MAX_ITEMS);
        return false;
    }
    if (!scene_grow((void **)&b->m.idx, &b->cap_idx, b->m.nidx + 1, sizeof(int))) return mb_oom(b);
    b->m.idx[b->m.nidx++] = index;
    b->m.fstart[b->m.nf] = b->m.nidx;
    return true;
}

static uint64_t hash3(const double p[3])
{
    uint64_t h = 1469598103934665603ull;
    for (int i = 0; i < 3; i++) {
        uint64_t u;
        memcpy(&u, &p[i], 8);
        h = (h ^ u) * 1099511628211ull;
        h ^= h >> 29;
    }
    return h;
}

// STL: the index of the vertex at p, added when new.
static int mb_shared_vertex(mb_t *b, double p[3], int loc)
{
    for (int i = 0; i < 3; i++) p[i] += 0.0;   // -0 -> +0
    if (2 * ((size_t)b->m.nv + 1) > b->hcap) {
        size_t nc = b->hcap ? 2 * b->hcap : 1024;
        int *nh = malloc(nc * sizeof *nh);
        if (!nh) return mb_oom(b), -1;
        for (size_t i = 0; i < nc; i++) nh[i] = -1;
        for (int k = 0; k < b->m.nv; k++) {
            size_t j = hash3(b->m.v + 3 * (size_t)k) & (nc - 1);
            while (nh[j] >= 0) j = (j + 1) & (nc - 1);
            nh[j] = k;
        }
        free(b->hash);
        b->hash = nh;
        b->hcap = nc;
    }
    size_t j = hash3(p) & (b->hcap - 1);
    for (; b->hash[j] >= 0; j = (j + 1) & (b->hcap - 1))
        if (!memcmp(b->m.v + 3 * (size_t)b->hash[j], p, 3 * sizeof(double))) return b->hash[j];
    if (!mb_vertex(b, p, loc)) return -1;
    b->hash[j] = b->m.nv - 1;
    return b->m.nv - 1;
}

// ---------------------------------------------------------------------------
// Lines and tokens of the ASCII formats

typedef struct {
    const char *text;
    size_t len, pos;
    int line;
    char buf[4096];      // the current line, NUL-terminated, cut at 4095 bytes
    char *tok[MAXTOK];
    int ntok;            // tokens of the line (at most MAXTOK; more: MAXTOK + 1)
} lines_t;

// The next line with at least one token; false at the end (or on a NUL byte: *err).
static bool next_line(lines_t *L, const char *name, bool *err)
{
    *err = false;
    while (L->pos < L->len) {
        const char *s = L->text + L->pos, *nl = memchr(s, '\n', L->len - L->pos);
        size_t n = nl ? (size_t)(nl - s) : L->len - L->pos;
        L->pos += n + (nl ? 1 : 0);
        if (L->line == INT_MAX) {
            model_error(name, 0, "too many lines");
            return *err = true, false;
        }
        L->line++;
        if (memchr(s, 0, n)) {
            model_error(name, L->line, "the line contains a NUL byte in a text (ASCII) mesh file");
            return *err = true, false;
        }
        if (n >= sizeof L->buf) n = sizeof L->buf - 1;
        memcpy(L->buf, s, n);
        L->buf[n] = 0;
        L->ntok = 0;
        for (char *save = NULL, *t = strtok_r(L->buf, " \t\r\v\f", &save); t; t = strtok_r(NULL, " \t\r\v\f", &save))
            if (L->ntok < MAXTOK) L->tok[L->ntok++] = t;
            else { L->ntok = MAXTOK + 1; break; }
        if (L->ntok > 0) return true;
    }
    return false;
}

static bool num(const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end || !isfinite(v) || fabs(v) > 1e150) return false;
    *out = v;
    return true;
}

// ---------------------------------------------------------------------------
// STL

static bool stl_ascii(mb_t *b, const char *text, size_t len)
{
    lines_t L = { .text = text, .len = len };
    bool err;
    int state = 0, nvert = 0, nsolid = 0;   // state: 0 outside a solid, 1 in it, 2 facet, 3 loop
    int tri[3];
    const char *nm = b->name;
    while (next_line(&L, nm, &err)) {
        const char *k = L.tok[0];
        bool ok = true;
        if (!strcasecmp(k, "solid")) ok = state == 0 && (state = 1, nsolid++, true);
        else if (!strcasecmp(k, "endsolid")) ok = state == 1 && (state = 0, true);
        else if (!strcasecmp(k, "facet")) ok = state == 1 && (state = 2, true) && mb_face(b, L.line);
        else if (!strcasecmp(k, "outer"))
            ok = state == 2 && L.ntok == 2 && !strcasecmp(L.tok[1], "loop") && (state = 3, nvert = 0, true);
        else if (!strcasecmp(k, "endloop")) {
            if (state == 3 && nvert != 3) {
                model_error(nm, L.line, "facet %d has %d vertices; an STL facet is a triangle (3)", b->m.nf, nvert);
                return false;
            }
            ok = state == 3 && (state = 2, true);
        } else if (!strcasecmp(k, "endfacet")) ok = state == 2 && (state = 1, true);
        else if (!strcasecmp(k, "vertex")) {
            double p[3];
            if (state != 3 || L.ntok != 4) ok = false;
            else if (!num(L.tok[1], &p[0]) || !num(L.tok[2], &p[1]) || !num(L.tok[3], &p[2])) {
                model_error(nm, L.line, "facet %d: 'vertex x y z' needs three finite numbers", b->m.nf);
                return false;
            } else if (nvert >= 3) {
                model_error(nm, L.line, "facet %d has more than 3 vertices; an STL facet is a triangle", b->m.nf);
                return false;
            } else if ((tri[nvert++] = mb_shared_vertex(b, p, L.line)) < 0 || !mb_ref(b, tri[nvert - 1])) {
                return false;
            }
        } else {
            model_error(nm, L.line, "'%.40s' is not an ASCII STL keyword (solid, facet normal, outer loop, vertex, "
                        "endloop, endfacet, endsolid)", k);
            return false;
        }
        if (!ok) {
            static const char *where[4] = { "outside a solid", "in a solid, outside a facet",
                                            "in a facet, outside its loop", "in a facet's loop" };
            model_error(nm, L.line, "'%.40s' does not belong here (%s): expected solid > facet normal > outer loop > "
                        "3 x vertex > endloop > endfacet > endsolid", k, where[state]);
            return false;
        }
    }
    if (err) return false;
    if (state != 0 || nsolid == 0) {
        model_error(nm, L.line, "the file ends %s: a truncated ASCII STL?",
                    nsolid == 0 ? "before any 'solid'" : "inside a solid (no 'endsolid')");
        return false;
    }
    return true;
}

static float le_f32(const unsigned char *p)
{
    uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static uint32_t le_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static bool stl_binary(mb_t *b, const unsigned char *d, size_t len)
{
    const char *nm = b->name;
    if (len < 84) {
        model_error(nm, 0, "a truncated binary STL: %zu bytes, less than its 84-byte header (80 bytes, then the "
                    "triangle count)", len);
        return false;
    }
    uint32_t n = le_u32(d + 80);
    uint64_t want = 84 + 50 * (uint64_t)n;
    if (len < want) {
        model_error(nm, 0, "a truncated binary STL: its header announces %u triangles (%llu bytes), the file has "
                    "%zu bytes (it ends inside triangle %zu, at byte offset %zu)",
                    n, (unsigned long long)want, len, (len - 84) / 50 + 1, len);
        return false;
    }
    if (len > want) {
        model_error(nm, 0, "binary STL: its header announces %u triangles (%llu bytes), the file has %zu bytes "
                    "(%llu bytes after the last triangle)", n, (unsigned long long)want, len,
                    (unsigned long long)(len - want));
        return false;
    }
    if (n == 0 || want > INT_MAX) {
        model_error(nm, 0, n ? "binary STL of %u triangles: too large" : "binary STL with %u triangles", n);
        return false;
    }
    for (uint32_t t = 0; t < n; t++) {
        size_t off = 84 + 50 * (size_t)t;
        if (!mb_face(b, (int)off)) return false;
        for (int k = 0; k < 3; k++) {
            double p[3];
            for (int i = 0; i < 3; i++) {
                p[i] = le_f32(d + off + 12 + 12 * k + 4 * i);
                if (!isfinite(p[i])) {
                    model_error(nm, 0, "byte offset %zu: triangle %u, vertex %d: coordinate %d is not a finite number",
                                off + 12 + 12 * k + 4 * i, t + 1, k + 1, i + 1);
                    return false;
                }
            }
            int v = mb_shared_vertex(b, p, (int)off);
            if (v < 0 || !mb_ref(b, v)) return false;
        }
    }
    return true;
}

// ---------------------------------------------------------------------------
// PLY

typedef enum { T_NONE, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_F32, T_F64 } ptype_t;

static ptype_t ptype(const char *s)
{
    static const struct { const char *n; ptype_t t; } k[] = {
        { "char", T_I8 }, { "int8", T_I8 }, { "uchar", T_U8 }, { "uint8", T_U8 }, { "short", T_I16 },
        { "int16", T_I16 }, { "ushort", T_U16 }, { "uint16", T_U16 }, { "int", T_I32 }, { "int32", T_I32 },
        { "uint", T_U32 }, { "uint32", T_U32 }, { "float", T_F32 }, { "float32", T_F32 }, { "double", T_F64 },
        { "float64", T_F64 },
    };
    for (size_t i = 0; i < sizeof k / sizeof k[0]; i++)
        if (!strcmp(s, k[i].n)) return k[i].t;
    return T_NONE;
}

static size_t psize(ptype_t t)
{
    return t == T_I8 || t == T_U8 ? 1 : t == T_I16 || t == T_U16 ? 2 : t == T_F64 ? 8 : 4;
}

static double ply_value(const unsigned char *p, ptype_t t)
{
    switch (t) {
    case T_I8: return (int8_t)p[0];
    case T_U8: return p[0];
    case T_I16: return (int16_t)(p[0] | p[1] << 8);
    case T_U16: return (uint16_t)(p[0] | p[1] << 8);
    case T_I32: return (int32_t)le_u32(p);
    case T_U32: return le_u32(p);
    case T_F32: return le_f32(p);
    default: {
        uint64_t u = (uint64_t)le_u32(p) | (uint64_t)le_u32(p + 4) << 32;
        double d;
        memcpy(&d, &u, 8);
        return d;
    }
    }
}

enum { PLY_MAXPROP = 32, PLY_MAXEL = 16 };

typedef struct {
    char name[32];
    ptype_t type, count_type;   // count_type != T_NONE: a list
} prop_t;

typedef struct {
    char name[32];
    long count;
    int nprop;
    prop_t prop[PLY_MAXPROP];
    int role;    // 0 other, 1 vertex, 2 face
    int px, py, pz, plist;   // vertex: x, y, z; face: the index list
} elem_t;

typedef struct {
    bool binary;
    int nel;
    elem_t el[PLY_MAXEL];
    size_t body;        // byte offset of the body
    int body_line;      // its first line (ASCII)
} ply_t;

static bool ply_header(mb_t *b, const char *text, size_t len, ply_t *h)
{
    const char *nm = b->name;
    lines_t L = { .text = text, .len = len };
    bool err, fmt = false;
    memset(h, 0, sizeof *h);
    while (next_line(&L, nm, &err)) {
        const char *k = L.tok[0];
        if (L.line == 1) {
            if (strcmp(k, "ply") || L.ntok != 1) {
                model_error(nm, 1, "not a PLY file (no 'ply' line first)");
                return false;
            }
        } else if (!strcmp(k, "format")) {
            if (L.ntok != 3 || (strcmp(L.tok[1], "ascii") && strcmp(L.tok[1], "binary_little_endian"))) {
                model_error(nm, L.line, "PLY format '%.40s': refl reads 'ascii' and 'binary_little_endian' (convert "
                            "a big-endian file)", L.ntok > 1 ? L.tok[1] : "");
                return false;
            }
            h->binary = !strcmp(L.tok[1], "binary_little_endian");
            fmt = true;
        } else if (!strcmp(k, "comment") || !strcmp(k, "obj_info")) {
            continue;
        } else if (!strcmp(k, "element")) {
            long c;
            if (L.ntok != 3 || strlen(L.tok[1]) >= 32 || !model_parse_int(L.tok[2], &c) || c < 0 || c > SCENE_MAX_ITEMS)
                return model_error(nm, L.line, "expected 'element NAME COUNT' (a count of 0 to %d)", SCENE_MAX_ITEMS), false;
            if (h->nel == PLY_MAXEL) return model_error(nm, L.line, "more than %d elements", PLY_MAXEL), false;
            elem_t *e = &h->el[h->nel++];
            snprintf(e->name, sizeof e->name, "%s", L.tok[1]);
            e->count = c;
            e->role = !strcmp(e->name, "vertex") ? 1 : !strcmp(e->name, "face") ? 2 : 0;
            for (int i = 0; e->role && i < h->nel - 1; i++)
                if (h->el[i].role == e->role) {
                    model_error(nm, L.line, "a second '%s' element (a PLY scene has one)", e->name);
                    return false;
                }
            e->px = e->py = e->pz = e->plist = -1;
        } else if (!strcmp(k, "property")) {
            elem_t *e = h->nel ? &h->el[h->nel - 1] : NULL;
            bool list = L.ntok == 5 && !strcmp(L.tok[1], "list");
            if (!e || (L.ntok != 3 && !list)) {
                model_error(nm, L.line, e ? "expected 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME'"
                                          : "a property before any 'element'");
                return false;
            }
            if (e->nprop == PLY_MAXPROP) return model_error(nm, L.line, "more than %d properties", PLY_MAXPROP), false;
            prop_t *p = &e->prop[e->nprop];
            p->count_type = list ? ptype(L.tok[2]) : T_NONE;
            p->type = ptype(L.tok[list ? 3 : 1]);
            const char *pn = L.tok[list ? 4 : 2];
            if (p->type == T_NONE || (list && (p->count_type == T_NONE || p->count_type >= T_F32))) {
                model_error(nm, L.line, "unknown PLY property type (char uchar short ushort int uint float double, "
                            "or int8 ... float64; list counts are integers)");
                return false;
            }
            snprintf(p->name, sizeof p->name, "%s", pn);
            int i = e->nprop++;
            if (e->role == 1 && !list) {
                if (!strcmp(pn, "x")) e->px = i;
                if (!strcmp(pn, "y")) e->py = i;
                if (!strcmp(pn, "z")) e->pz = i;
            }
            if (e->role == 2 && list && (!strcmp(pn, "vertex_indices") || !strcmp(pn, "vertex_index")))
                e->plist = i;
        } else if (!strcmp(k, "end_header")) {
            if (!fmt) return model_error(nm, L.line, "no 'format' line before end_header"), false;
            h->body = L.pos;
            h->body_line = L.line;
            for (int i = 0; i < h->nel; i++) {
                elem_t *e = &h->el[i];
                if (e->role == 1 && (e->px < 0 || e->py < 0 || e->pz < 0))
                    return model_error(nm, L.line, "the vertex element lacks property x, y or z"), false;
                if (e->role == 2 && e->plist < 0)
                    return model_error(nm, L.line, "the face element lacks its list 'vertex_indices'"), false;
            }
            return true;
        } else {
            model_error(nm, L.line, "'%.40s' is not a PLY header keyword (format, comment, element, property, "
                        "end_header)", k);
            return false;
        }
    }
    if (!err) model_error(nm, L.line, "the header has no 'end_header' (a truncated PLY file?)");
    return false;
}

// One face index list into the mesh. loc: line or byte offset (for messages).
static bool ply_face(mb_t *b, const long *ix, long n, long nverts, int loc)
{
    if (!mb_face(b, loc)) return false;
    for (long i = 0; i < n; i++) {
        if (ix[i] < 0 || ix[i] >= nverts) {
            char m[200];
            snprintf(m, sizeof m, "face %d: vertex index %ld is out of range (the file has %ld vertices, numbered "
                     "from 0)", b->m.nf, ix[i], nverts);
            if (b->m.binary) model_error(b->name, 0, "byte offset %d: %s", loc, m);
            else model_error(b->name, loc, "%s", m);
            return false;
        }
        if (!mb_ref(b, (int)ix[i])) return false;
    }
    return true;
}

static bool ply_ascii(mb_t *b, const char *text, size_t len, const ply_t *h, long nverts)
{
    lines_t L = { .text = text, .len = len, .pos = h->body, .line = h->body_line };
    const char *nm = b->name;
    bool err;
    long ix[MAXTOK];
    for (int ei = 0; ei < h->nel; ei++) {
        const elem_t *e = &h->el[ei];
        for (long r = 0; r < e->count; r++) {
            if (!next_line(&L, nm, &err)) {
                if (!err) model_error(nm, L.line, "the file ends at %s %ld of %ld (a truncated PLY file?)", e->name,
                                      r + 1, e->count);
                return false;
            }
            int t = 0;
            double p[3] = { 0 };
            long nix = 0;
            for (int pi = 0; pi < e->nprop; pi++) {
                const prop_t *pp = &e->prop[pi];
                long cnt = 1;
                double v;
                if (pp->count_type != T_NONE) {
                    if (t >= L.ntok || L.ntok > MAXTOK || !num(L.tok[t], &v) || v < 0 || v != floor(v) ||
                        v > MAXTOK - 1 - t) {
                        model_error(nm, L.line, "%s %ld: property %s: a list count of 0 to %d values on the line "
                                    "expected", e->name, r + 1, pp->name, MAXTOK - 1 - t);
                        return false;
                    }
                    cnt = (long)v;
                    t++;
                }
                for (long c = 0; c < cnt; c++, t++) {
                    if (t >= L.ntok || !num(L.tok[t], &v)) {
                        model_error(nm, L.line, "%s %ld: property %s: %s", e->name, r + 1, pp->name,
                                    t >= L.ntok ? "missing (the line ends early)" : "not a finite number");
                        return false;
                    }
                    if (e->role == 1 && (pi == e->px || pi == e->py || pi == e->pz))
                        p[pi == e->px ? 0 : pi == e->py ? 1 : 2] = v;
                    if (e->role == 2 && pi == e->plist) {
                        if (v != floor(v)) {
                            model_error(nm, L.line, "face %ld: index %g is not whole", r + 1, v);
                            return false;
                        }
                        ix[nix++] = (long)fmax(-1e15, fmin(1e15, v));
                    }
                }
            }
            if (t != L.ntok) {
                model_error(nm, L.line, "%s %ld: %d values, expected %d (one element per line)", e->name, r + 1,
                            L.ntok, t);
                return false;
            }
            if (e->role == 1 && !mb_vertex(b, p, L.line)) return false;
            if (e->role == 2 && !ply_face(b, ix, nix, nverts, L.line)) return false;
        }
    }
    return true;
}

static bool ply_binary(mb_t *b, const unsigned char *d, size_t len, const ply_t *h, long nverts)
{
    const char *nm = b->name;
    size_t off = h->body;
    long *ix = NULL;
    size_t cap = 0;
    bool ok = false;
    for (int ei = 0; ei < h->nel; ei++) {
        const elem_t *e = &h->el[ei];
        for (long r = 0; r < e->count; r++) {
            size_t start = off;
            double p[3] = { 0 };
            long nix = 0;
            if (start > INT_MAX) {
                model_error(nm, 0, "binary PLY larger than %d bytes", INT_MAX);
                goto done;
            }
            for (int pi = 0; pi < e->nprop; pi++) {
                const prop_t *pp = &e->prop[pi];
                double cnt = 1;
                if (pp->count_type != T_NONE) {
                    if (len - off < psize(pp->count_type)) goto truncated;
                    cnt = ply_value(d + off, pp->count_type);
                    off += psize(pp->count_type);
                    if (cnt < 0 || cnt > 1e6) {
                        model_error(nm, 0, "byte offset %zu: %s %ld: list count %g", off, e->name, r + 1, cnt);
                        goto done;
                    }
                }
                if ((len - off) / psize(pp->type) < (size_t)cnt) goto truncated;
                if (e->role == 2 && pi == e->plist &&
                    !scene_grow((void **)&ix, &cap, (size_t)cnt + 1, sizeof *ix)) {
                    mb_oom(b);
                    goto done;
                }
                for (long c = 0; c < (long)cnt; c++, off += psize(pp->type)) {
                    double v = ply_value(d + off, pp->type);
                    if (!isfinite(v) || fabs(v) > 1e150) {
                        model_error(nm, 0, "byte offset %zu: %s %ld: property %s is not a finite number", off, e->name,
                                    r + 1, pp->name);
                        goto done;
                    }
                    if (e->role == 1 && (pi == e->px || pi == e->py || pi == e->pz))
                        p[pi == e->px ? 0 : pi == e->py ? 1 : 2] = v;
                    if (e->role == 2 && pi == e->plist) ix[nix++] = (long)fmax(-1e15, fmin(1e15, v));
                }
            }
            if (e->role == 1 && !mb_vertex(b, p, (int)start)) goto done;
            if (e->role == 2 && !ply_face(b, ix, nix, nverts, (int)start)) goto done;
            continue;
        truncated:
            model_error(nm, 0, "a truncated binary PLY: the file ends at byte offset %zu, inside %s %ld of %ld", len,
                        e->name, r + 1, e->count);
            goto done;
        }
    }
    if (off != len) model_error(nm, 0, "binary PLY: %zu bytes after the last element (from byte offset %zu)",
                                len - off, off);
    else ok = true;
done:
    free(ix);
    return ok;
}

static bool ply(mb_t *b, const char *text, size_t len)
{
    ply_t h;
    if (!ply_header(b, text, len, &h)) return false;
    long nverts = 0;
    bool faces = false;
    for (int i = 0; i < h.nel; i++) {
        if (h.el[i].role == 1) nverts = h.el[i].count;
        if (h.el[i].role == 2) faces = h.el[i].count > 0;
    }
    if (!faces) {
        model_error(b->name, 0, "no faces (a PLY scene needs a 'face' element with vertex_indices)");
        return false;
    }
    b->m.binary = h.binary;
    return h.binary ? ply_binary(b, (const unsigned char *)text, len, &h, nverts) : ply_ascii(b, text, len, &h, nverts);
}

// ---------------------------------------------------------------------------
// Entry points

// Whether word (lower case) is in text[0..n), in any case.
static bool strcasestr_n(const char *text, size_t n, const char *word)
{
    size_t m = strlen(word);
    for (size_t i = 0; i + m <= n; i++)
        if (!strncasecmp(text + i, word, m)) return true;
    return false;
}

model_mesh_format_t model_mesh_format_(const char *text, size_t len, bool strict)
{
    if (len >= 4 && !memcmp(text, "ply", 3) && (text[3] == '\n' || text[3] == '\r')) return MODEL_MESH_PLY;
    if (len >= 84 && 84 + 50 * (uint64_t)le_u32((const unsigned char *)text + 80) == len) return MODEL_MESH_STL_BINARY;
    size_t i = 0;
    while (i < len && (text[i] == ' ' || text[i] == '\t' || text[i] == '\r' || text[i] == '\n')) i++;
    // "solid" first and no NUL byte near the start (a binary header that begins with
    // "solid" is padded with NULs, or followed by a count with a zero byte)
    if (len - i >= 5 && !strncasecmp(text + i, "solid", 5) && !memchr(text, 0, len < 1024 ? len : 1024) &&
        (!strict || strcasestr_n(text, len < 4096 ? len : 4096, "facet")))
        return MODEL_MESH_STL_ASCII;
    return MODEL_MESH_NONE;
}

bool model_mesh_parse_(const char *text, size_t len, const char *name, bool stl, model_mesh_t *out)
{
    mb_t b = { .name = name };
    memset(out, 0, sizeof *out);
    bool ok;
    if (stl) {
        model_mesh_format_t f = model_mesh_format_(text, len, false);
        b.m.binary = f != MODEL_MESH_STL_ASCII;
        ok = b.m.binary ? stl_binary(&b, (const unsigned char *)text, len) : stl_ascii(&b, text, len);
        if (ok && b.m.nf == 0) ok = (model_error(name, 0, "no facets (an empty STL)"), false);
    } else {
        ok = ply(&b, text, len);
    }
    free(b.hash);
    b.hash = NULL;
    if (!ok) {
        mb_free(&b);
        return false;
    }
    *out = b.m;
    return true;
}

model_scene_t *model_scene_parse_stl(const char *text, size_t len, const char *name, const model_scene_options_t *opt)
{
    model_mesh_t m;
    if (!name) name = "(scene)";
    if (!text && len) return model_error(name, 0, "no text to parse"), NULL;
    if (!model_mesh_parse_(text, len, name, true, &m)) return NULL;
    model_scene_t *s = model_scene_from_mesh_(&m, name, text, len, opt);
    model_mesh_free_(&m);
    return s;
}

model_scene_t *model_scene_parse_ply(const char *text, size_t len, const char *name, const model_scene_options_t *opt)
{
    model_mesh_t m;
    if (!name) name = "(scene)";
    if (!text && len) return model_error(name, 0, "no text to parse"), NULL;
    if (!model_mesh_parse_(text, len, name, false, &m)) return NULL;
    model_scene_t *s = model_scene_from_mesh_(&m, name, text, len, opt);
    model_mesh_free_(&m);
    return s;
}
