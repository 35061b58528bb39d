// model/scene/obj.c — the Wavefront OBJ reader: v, f (v, v/vt, v/vt/vn, v//vn,
// negative indices), usemtl; vn, vt, o, g, s, mtllib, l ignored. Faces are
// checked once every vertex is known (positive indices may refer forward).
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
// OBJ

// One face-vertex reference "v", "v/vt", "v/vt/vn" or "v//vn": the vertex
// index as written (non-zero); vt and vn are checked for syntax only.
static bool obj_ref(scene_tok_t t, long *v)
{
    scene_tok_t part[3];
    int np = 0;
    size_t b = 0;
    for (size_t i = 0; i <= t.n; i++) {
        if (i == t.n || t.p[i] == '/') {
            if (np == 3) return false;
            part[np++] = (scene_tok_t){ t.p + b, i - b };
            b = i + 1;
        }
    }
    long x;
    if (!scene_tok_long(part[0], v) || *v == 0) return false;
    if (np >= 2 && (np == 2 || part[1].n > 0) && (!scene_tok_long(part[1], &x) || x == 0)) return false;
    if (np == 3 && (!scene_tok_long(part[2], &x) || x == 0)) return false;
    return true;
}

model_scene_t *model_scene_parse_obj(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt)
{
    scene_builder_t b;
    scene_lexer_t lx;
    model_scene_t *scene = NULL;
    char q[200];
    if (!scene_setup(&b, &lx, text, len, name, opt)) goto done;
    const char *nm = b.name;

    bool err;
    while (scene_lex_line(&lx, &err)) {
        if (lx.ntoks == 0) continue;
        scene_tok_t kw = lx.toks[0];
        if (scene_tok_is(kw, "v")) {
            if (lx.ntoks != 4 && lx.ntoks != 5) {
                model_error(nm, lx.line, "'v' takes 3 or 4 numbers (v x y z [w]), got %zu",
                            lx.ntoks - 1);
                goto done;
            }
            double xyz[4];
            for (size_t i = 1; i < lx.ntoks; i++) {
                scene_num_t st = scene_tok_double(lx.toks[i], &xyz[i - 1]);
                if (st != SCENE_NUM_OK) {
                    model_error(nm, lx.line, "vertex %d: %s %s", b.nv + 1, scene_quote(lx.toks[i], q),
                                st == SCENE_NUM_NONFINITE
                                    ? "is not a finite number; give coordinates in mm as ordinary numbers"
                                    : "does not parse as a number (v x y z [w])");
                    goto done;
                }
            }
            if (!scene_add_vertex(&b, lx.line, v3(xyz[0], xyz[1], xyz[2]), b.nv + 1)) goto done;
        } else if (scene_tok_is(kw, "f")) {
            if (!scene_begin_face(&b, lx.line)) goto done;
            int number = b.f[b.nf - 1].number;
            for (size_t i = 1; i < lx.ntoks; i++) {
                long v;
                if (!obj_ref(lx.toks[i], &v)) {
                    model_error(nm, lx.line,
                                "face %d: %s is not a vertex reference (v, v/vt, v/vt/vn or v//vn "
                                "with non-zero indices)", number, scene_quote(lx.toks[i], q));
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
                if (!scene_add_ref(&b, lx.line, (int)(v - 1))) goto done;
            }
        } else if (scene_tok_is(kw, "usemtl")) {
            if (!scene_set_material(&b, &lx, "usemtl")) goto done;
        } else if (scene_tok_is(kw, "vn") || scene_tok_is(kw, "vt") || scene_tok_is(kw, "o") ||
                   scene_tok_is(kw, "g") || scene_tok_is(kw, "s") || scene_tok_is(kw, "mtllib") ||
                   scene_tok_is(kw, "l")) {
            continue;
        } else {
            model_error(nm, lx.line,
                        "unsupported OBJ statement %s; refl reads v, f and usemtl and ignores "
                        "vn, vt, o, g, s, mtllib and l", scene_quote(kw, q));
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
        if (!scene_check_face(&b, k, end)) goto done;
    }
    scene = scene_finish(&b, text, len);
done:
    scene_builder_free(&b);
    free(lx.toks);
    return scene;
}
