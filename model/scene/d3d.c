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

model_scene_t *model_scene_parse_d3d(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt)
{
    scene_builder_t b;
    scene_lexer_t lx;
    model_scene_t *scene = NULL;
    GHashTable *numbers = g_hash_table_new(g_direct_hash, g_direct_equal);  // number -> index+1
    GHashTable *lines = g_hash_table_new(g_direct_hash, g_direct_equal);    // number -> line
    bool in_faces = false, open = false;   // open: a face has been started and not ended
    char q[200];
    if (!scene_setup(&b, &lx, text, len, name, opt)) goto done;
    const char *nm = b.name;

    bool err;
    while (scene_lex_line(&lx, &err)) {
        size_t t0 = 0;
        if (!in_faces) {
            if (lx.ntoks == 0) continue;
            if (scene_tok_is_ci(lx.toks[0], "faces:")) {
                in_faces = true;
                t0 = 1;
            } else if (scene_tok_is(lx.toks[0], "@material")) {
                model_error(nm, lx.line, "@material belongs after the 'Faces:' line (it sets the "
                            "material of the faces that follow it)");
                goto done;
            } else if (scene_tok_is(lx.toks[0], "@sphere")) {
                model_error(nm, lx.line, "@sphere belongs after the 'Faces:' line (a sphere is "
                            "a primitive like a face, of the current material)");
                goto done;
            } else if (lx.ntoks != 4) {
                model_error(nm, lx.line,
                            "a vertex line has 4 fields (number x y z), this one has %zu%s", lx.ntoks,
                            scene_tok_is_ci(lx.toks[0], "faces") ? "; the faces start after a line 'Faces:'"
                                                           : "");
                goto done;
            } else {
                long num;
                if (!scene_tok_long(lx.toks[0], &num) || num < 1 || num > INT_MAX) {
                    model_error(nm, lx.line,
                                "vertex number %s does not parse: use a positive integer up to %d "
                                "(a vertex line is 'number x y z'; faces start after 'Faces:')",
                                scene_quote(lx.toks[0], q), INT_MAX);
                    goto done;
                }
                double xyz[3];
                for (int i = 0; i < 3; i++) {
                    scene_num_t st = scene_tok_double(lx.toks[1 + i], &xyz[i]);
                    if (st != SCENE_NUM_OK) {
                        model_error(nm, lx.line, "vertex %ld: coordinate %s %s", num,
                                    scene_quote(lx.toks[1 + i], q),
                                    st == SCENE_NUM_NONFINITE
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
                if (!scene_add_vertex(&b, lx.line, v3(xyz[0], xyz[1], xyz[2]), (int)num)) goto done;
                g_hash_table_insert(numbers, key, GINT_TO_POINTER(b.nv));
                g_hash_table_insert(lines, key, GINT_TO_POINTER(lx.line));
                continue;
            }
        }
        // Faces section.
        if (lx.ntoks > t0 && lx.toks[t0].n > 0 && lx.toks[t0].p[0] == '@') {
            bool sphere = scene_tok_is(lx.toks[t0], "@sphere");
            if (!sphere && !scene_tok_is(lx.toks[t0], "@material")) {
                model_error(nm, lx.line, "unknown directive %s; the directives are '@material NAME' "
                            "and '@sphere cx cy cz radius'", scene_quote(lx.toks[t0], q));
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
            if (sphere ? !scene_add_sphere(&b, &lx) : !scene_set_material(&b, &lx, "@material")) goto done;
            continue;
        }
        for (size_t t = t0; t < lx.ntoks; t++) {
            scene_tok_t tk = lx.toks[t];
            bool ends = tk.n > 0 && tk.p[tk.n - 1] == '.';
            scene_tok_t vt = { tk.p, ends ? tk.n - 1 : tk.n };
            if (!open && !scene_begin_face(&b, lx.line)) goto done;
            open = true;
            model_face_t *f = &b.f[b.nf - 1];
            if (vt.n > 0) {
                if (vt.p[0] == '@') {
                    model_error(nm, lx.line, "%s must be on a line of its own",
                                scene_tok_is(vt, "@sphere") ? "@sphere" : "@material");
                    goto done;
                }
                long num;
                if (!scene_tok_long(vt, &num) || num < 1) {
                    model_error(nm, lx.line,
                                "face %d: %s is not a vertex number; a face is a list of vertex "
                                "numbers ended by '.'", f->number, scene_quote(tk, q));
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
                if (!scene_add_ref(&b, lx.line, GPOINTER_TO_INT(hit) - 1)) goto done;
            }
            if (ends) {
                if (!scene_check_face(&b, b.nf - 1, b.nidx)) goto done;
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
    scene = scene_finish(&b, text, len);
done:
    scene_builder_free(&b);
    free(lx.toks);
    g_hash_table_destroy(numbers);
    g_hash_table_destroy(lines);
    return scene;
}
