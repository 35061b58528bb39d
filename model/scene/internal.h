// model/scene/internal.h — what the files of model/scene/ share: the lexer of
// the text readers (lex.c), the scene builder every reader feeds (scene.c),
// and the mesh readers' STL and PLY meshes (mesh.c).
#pragma once

#include <glib.h>
#include <limits.h>
#include <stdbool.h>
#include <stddef.h>

#include "model/model.h"

#define SCENE_MAX_ITEMS (INT_MAX / 2)   // vertices, faces, face-vertex references

// Make room for need elements of elem bytes in *p (capacity *cap, doubled
// from 64 until it fits). false when out of memory (*p and *cap unchanged).
bool scene_grow(void **p, size_t *cap, size_t need, size_t elem);

// ---------------------------------------------------------------------------
// Tokens and lines (model/scene/lex.c)

typedef struct {
    const char *p;
    size_t      n;
} scene_tok_t;

bool scene_tok_is(scene_tok_t t, const char *word);
bool scene_tok_is_ci(scene_tok_t t, const char *word);
// The token quoted for a message: at most 40 characters, non-printable bytes as \xHH.
const char *scene_quote(scene_tok_t t, char out[200]);
// A decimal integer with optional sign, the whole token. No overflow.
bool scene_tok_long(scene_tok_t t, long *out);

typedef enum { SCENE_NUM_OK, SCENE_NUM_BAD, SCENE_NUM_NONFINITE } scene_num_t;
// A floating-point number, the whole token. Underflow gives the rounded value.
scene_num_t scene_tok_double(scene_tok_t t, double *out);

// Lines of the text, each cut at '#' and split into tokens.
typedef struct {
    const char *text;
    size_t      len, pos;
    int         line;
    const char *name;
    scene_tok_t *toks;
    size_t      ntoks, cap;
} scene_lexer_t;

// Next line: false at the end of the text or on error (*err set).
bool scene_lex_line(scene_lexer_t *lx, bool *err);

// ---------------------------------------------------------------------------
// The scene builder (model/scene/scene.c)

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
} scene_builder_t;

void scene_builder_free(scene_builder_t *b);
// A vertex (scaled by b->unit_mm); number: as the file names it (messages).
bool scene_add_vertex(scene_builder_t *b, int line, model_vec3_t p, int number);
// A reference of the open face to vertex index (0-based).
bool scene_add_ref(scene_builder_t *b, int line, int index);
// Start a face at the current end of idx.
bool scene_begin_face(scene_builder_t *b, int line);
// Close face k (its references are idx[fstart[k] .. end)) and check it.
bool scene_check_face(scene_builder_t *b, int k, size_t end);
// "@material NAME" / "usemtl NAME": set the material of the following faces.
bool scene_set_material(scene_builder_t *b, const scene_lexer_t *lx, const char *keyword);
// "@sphere cx cy cz radius" (mm): a sphere of the current material.
bool scene_add_sphere(scene_builder_t *b, const scene_lexer_t *lx);
// Hand the builder's arrays over to a scene.
model_scene_t *scene_finish(scene_builder_t *b, const char *text, size_t len);
// Start a builder and a lexer on (text, len) with the options (NULL: defaults). false + message.
bool scene_setup(scene_builder_t *b, scene_lexer_t *lx, const char *text, size_t len, const char *name,
                 const model_scene_options_t *opt);

// ---------------------------------------------------------------------------
// Mesh scenes (model/scene/mesh.c reads STL and PLY into a mesh;
// model_scene_from_mesh_ in model/scene/scene.c checks its faces and builds the scene).
typedef struct {
    double *v;         // x, y, z per vertex, in the file's unit
    int     nv;
    int    *idx;       // face-vertex references, 0-based
    size_t  nidx;
    size_t *fstart;    // face k: idx[fstart[k] .. fstart[k + 1]) (nf + 1 entries)
    int    *floc;      // face k's line (text) or byte offset (binary), for messages
    int     nf;
    bool    binary;
} model_mesh_t;
typedef enum { MODEL_MESH_NONE, MODEL_MESH_PLY, MODEL_MESH_STL_BINARY, MODEL_MESH_STL_ASCII } model_mesh_format_t;
// The mesh format of a file's bytes: "ply" first; binary STL (size 84 + 50 x
// its count); ASCII STL ("solid" first, and with strict a "facet" in the
// first 4 KiB); else NONE.
model_mesh_format_t model_mesh_format_(const char *text, size_t len, bool strict);
// stl: STL (binary or ASCII by content), else PLY. false + model_error.
bool model_mesh_parse_(const char *text, size_t len, const char *name, bool stl, model_mesh_t *out);
void model_mesh_free_(model_mesh_t *m);
model_scene_t *model_scene_from_mesh_(const model_mesh_t *m, const char *name, const char *text, size_t len,
                                      const model_scene_options_t *opt);
