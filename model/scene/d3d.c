// model/scene/d3d.c — the D3D reader (Ammeraal 1988, the thesis's format):
// numbered vertices, then 'Faces:', faces ended by '.', '@material NAME' and
// '@sphere cx cy cz radius' lines; read by the lexer into the scene builder.
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
// D3D

// The reader's state.
typedef struct {
    scene_builder_t b;
    scene_lexer_t   lx;
    GHashTable     *numbers;    // vertex number -> index + 1
    GHashTable     *lines;      // vertex number -> line
    bool            in_faces;   // after the 'Faces:' line
    bool            open;       // a face has been started and not ended
} d3d_t;

// A vertex line 'number x y z' (4 tokens).
static bool d3d_vertex(d3d_t *r)
{
    scene_builder_t *b = &r->b;
    const scene_lexer_t *lx = &r->lx;
    const char *nm = b->name;
    char q[200];
    long num;
    if (!scene_tok_long(lx->toks[0], &num) || num < 1 || num > INT_MAX) {
        model_error(nm, lx->line,
                    "vertex number %s does not parse: use a positive integer up to %d "
                    "(a vertex line is 'number x y z'; faces start after 'Faces:')",
                    scene_quote(lx->toks[0], q), INT_MAX);
        return false;
    }
    double xyz[3];
    for (int i = 0; i < 3; i++) {
        scene_num_t st = scene_tok_double(lx->toks[1 + i], &xyz[i]);
        if (st != SCENE_NUM_OK) {
            model_error(nm, lx->line, "vertex %ld: coordinate %s %s", num,
                        scene_quote(lx->toks[1 + i], q),
                        st == SCENE_NUM_NONFINITE
                            ? "is not a finite number; give it in mm as an ordinary number"
                            : "does not parse as a number (give x y z in mm)");
            return false;
        }
    }
    gpointer key = GINT_TO_POINTER((int)num);
    if (g_hash_table_contains(r->numbers, key)) {
        model_error(nm, lx->line,
                    "vertex %ld is defined twice (first on line %d); give each vertex "
                    "its own number",
                    num, GPOINTER_TO_INT(g_hash_table_lookup(r->lines, key)));
        return false;
    }
    if (!scene_add_vertex(b, lx->line, v3(xyz[0], xyz[1], xyz[2]), (int)num)) return false;
    g_hash_table_insert(r->numbers, key, GINT_TO_POINTER(b->nv));
    g_hash_table_insert(r->lines, key, GINT_TO_POINTER(lx->line));
    return true;
}

// A line (with tokens) before 'Faces:': a vertex, or the 'Faces:' line,
// whose further tokens are the faces section's (*t0 = 1). -1 on error, 0
// when the line is done, 1 when its tokens from *t0 on are faces.
static int d3d_head_line(d3d_t *r, size_t *t0)
{
    const scene_lexer_t *lx = &r->lx;
    const char *nm = r->b.name;
    if (scene_tok_is_ci(lx->toks[0], "faces:")) {
        r->in_faces = true;
        *t0 = 1;
        return 1;
    } else if (scene_tok_is(lx->toks[0], "@material")) {
        model_error(nm, lx->line, "@material belongs after the 'Faces:' line (it sets the "
                    "material of the faces that follow it)");
        return -1;
    } else if (scene_tok_is(lx->toks[0], "@sphere")) {
        model_error(nm, lx->line, "@sphere belongs after the 'Faces:' line (a sphere is "
                    "a primitive like a face, of the current material)");
        return -1;
    } else if (lx->ntoks != 4) {
        model_error(nm, lx->line,
                    "a vertex line has 4 fields (number x y z), this one has %zu%s", lx->ntoks,
                    scene_tok_is_ci(lx->toks[0], "faces") ? "; the faces start after a line 'Faces:'"
                                                          : "");
        return -1;
    }
    return d3d_vertex(r) ? 0 : -1;
}

// A directive of the faces section ('@material NAME', '@sphere cx cy cz
// radius'): token t0 starts with '@'.
static bool d3d_directive(d3d_t *r, size_t t0)
{
    scene_builder_t *b = &r->b;
    const scene_lexer_t *lx = &r->lx;
    const char *nm = b->name;
    char q[200];
    bool sphere = scene_tok_is(lx->toks[t0], "@sphere");
    if (!sphere && !scene_tok_is(lx->toks[t0], "@material")) {
        model_error(nm, lx->line, "unknown directive %s; the directives are '@material NAME' "
                    "and '@sphere cx cy cz radius'", scene_quote(lx->toks[t0], q));
        return false;
    }
    const char *dname = sphere ? "@sphere" : "@material";
    if (t0 != 0) {
        model_error(nm, lx->line, "%s must be on a line of its own", dname);
        return false;
    }
    if (r->open) {
        model_error(nm, lx->line,
                    "face %d (line %d) is not ended by '.' before %s; end each face "
                    "with '.'", b->f[b->nf - 1].number, b->f[b->nf - 1].line, dname);
        return false;
    }
    return sphere ? scene_add_sphere(b, lx) : scene_set_material(b, lx, "@material");
}

// The tokens t0.. of a line in the faces section: vertex numbers; a token
// ending in '.' ends its face, which is then checked.
static bool d3d_face_tokens(d3d_t *r, size_t t0)
{
    scene_builder_t *b = &r->b;
    const scene_lexer_t *lx = &r->lx;
    const char *nm = b->name;
    char q[200];
    for (size_t t = t0; t < lx->ntoks; t++) {
        scene_tok_t tk = lx->toks[t];
        bool ends = tk.n > 0 && tk.p[tk.n - 1] == '.';
        scene_tok_t vt = { tk.p, ends ? tk.n - 1 : tk.n };
        if (!r->open && !scene_begin_face(b, lx->line)) return false;
        r->open = true;
        model_face_t *f = &b->f[b->nf - 1];
        if (vt.n > 0) {
            if (vt.p[0] == '@') {
                model_error(nm, lx->line, "%s must be on a line of its own",
                            scene_tok_is(vt, "@sphere") ? "@sphere" : "@material");
                return false;
            }
            long num;
            if (!scene_tok_long(vt, &num) || num < 1) {
                model_error(nm, lx->line,
                            "face %d: %s is not a vertex number; a face is a list of vertex "
                            "numbers ended by '.'", f->number, scene_quote(tk, q));
                return false;
            }
            gpointer hit = num <= INT_MAX ? g_hash_table_lookup(r->numbers, GINT_TO_POINTER((int)num))
                                          : NULL;
            if (!hit) {
                model_error(nm, lx->line,
                            "face %d refers to vertex %ld, which does not exist; define it "
                            "before 'Faces:' or fix the number", f->number, num);
                return false;
            }
            if (!scene_add_ref(b, lx->line, GPOINTER_TO_INT(hit) - 1)) return false;
        }
        if (ends) {
            if (!scene_check_face(b, b->nf - 1, b->nidx)) return false;
            r->open = false;
        }
    }
    return true;
}

// At the end of the text: the 'Faces:' line was there, no face is left
// open, and there is a face or a sphere.
static bool d3d_complete(const d3d_t *r)
{
    const scene_builder_t *b = &r->b;
    const char *nm = b->name;
    if (!r->in_faces) {
        model_error(nm, 0, "no 'Faces:' line; a D3D file lists numbered vertices "
                           "('number x y z'), then a line 'Faces:', then the faces");
        return false;
    }
    if (r->open) {
        model_error(nm, b->f[b->nf - 1].line,
                    "face %d is not ended by '.' (the file ends inside it); end each face with '.'",
                    b->f[b->nf - 1].number);
        return false;
    }
    if (b->nf == 0 && b->nsph == 0) {
        model_error(nm, 0, "no faces after 'Faces:'; list each face's vertex numbers ended by '.' "
                           "(or give a sphere: '@sphere cx cy cz radius')");
        return false;
    }
    return true;
}

model_scene_t *model_scene_parse_d3d(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt)
{
    d3d_t r = { .numbers = g_hash_table_new(g_direct_hash, g_direct_equal),
                .lines = g_hash_table_new(g_direct_hash, g_direct_equal) };
    model_scene_t *scene = NULL;
    if (!scene_setup(&r.b, &r.lx, text, len, name, opt)) goto done;

    bool err;
    while (scene_lex_line(&r.lx, &err)) {
        size_t t0 = 0;
        if (!r.in_faces) {
            if (r.lx.ntoks == 0) continue;
            int head = d3d_head_line(&r, &t0);
            if (head < 0) goto done;
            if (head == 0) continue;
        }
        // Faces section.
        const scene_tok_t *tk = r.lx.ntoks > t0 ? &r.lx.toks[t0] : NULL;
        if (tk && tk->n > 0 && tk->p[0] == '@' ? !d3d_directive(&r, t0) : !d3d_face_tokens(&r, t0)) goto done;
    }
    if (err || !d3d_complete(&r)) goto done;
    scene = scene_finish(&r.b, text, len);
done:
    scene_builder_free(&r.b);
    free(r.lx.toks);
    g_hash_table_destroy(r.numbers);
    g_hash_table_destroy(r.lines);
    return scene;
}
