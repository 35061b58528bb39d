// tests/test_model_scene.c — D3D and OBJ readers, face checks, rotation, loading.
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "tests/test.h"

// Unit cube, faces counter-clockwise seen from outside. Non-consecutive vertex
// numbers, attached and separate '.', a face over two lines, comments, materials.
static const char CUBE_D3D[] =
    "# unit cube\n"
    "10 0 0 0\n"            // line 2
    "20 1 0 0\n"
    "30 1 1 0   # comment\n"
    "40 0 1 0\n"
    "50 0 0 1\n"
    "60 1 0 1\n"
    "70 1 1 1\n"
    "80 0 1 1\n"
    "\n"
    "faces:\n"              // line 11, case-insensitive
    "10 40 30 20.\n"        // 1 bottom (default)
    "@material steel\n"
    "50 60 70 80 .\n"       // 3 -> face 2 top
    "10 20\n"               // line 15: face 3 front, spans two lines
    "  60 50.\n"
    "@material paint.red-2\n"
    "40 80 70 30.\n"        // face 4 back
    "10 50 80 40.\n"        // face 5 left
    "@material steel\n"
    "20 30 70 60.  # right\n";  // face 6 right, line 21

static model_scene_t *d3d(const char *text)
{
    model_error_clear();
    return model_scene_parse_d3d(text, strlen(text), "cube.d3d", NULL);
}

static model_scene_t *obj(const char *text)
{
    model_error_clear();
    return model_scene_parse_obj(text, strlen(text), "cube.obj", NULL);
}

static void check_cube(const model_scene_t *s)
{
    CHECK(s->nvertices == 8);
    CHECK(s->nfaces == 6);
    if (s->nfaces != 6) return;
    // Expected outward normals and plane offsets of bottom, top, front, back, left, right.
    const model_vec3_t n[6] = { { 0, 0, -1 }, { 0, 0, 1 }, { 0, -1, 0 },
                                { 0, 1, 0 },  { -1, 0, 0 }, { 1, 0, 0 } };
    const double off[6] = { 0, 1, 0, 1, 0, 1 };
    for (int k = 0; k < 6; k++) {
        const model_face_t *f = &s->faces[k];
        CHECK(f->nverts == 4);
        CHECK(f->number == k + 1);
        CHECK_NEAR(f->normal.x, n[k].x, 1e-12);
        CHECK_NEAR(f->normal.y, n[k].y, 1e-12);
        CHECK_NEAR(f->normal.z, n[k].z, 1e-12);
        CHECK_NEAR(f->offset_mm, off[k], 1e-12);
        for (int i = 0; i < f->nverts; i++) {
            CHECK(f->verts[i] >= 0 && f->verts[i] < s->nvertices);
            // Every vertex lies on the face's plane.
            model_vec3_t p = s->vertices[f->verts[i]];
            CHECK_NEAR(p.x * f->normal.x + p.y * f->normal.y + p.z * f->normal.z, f->offset_mm, 1e-12);
        }
    }
}

TEST(scene_d3d_cube)
{
    model_scene_t *s = d3d(CUBE_D3D);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (!s) return;
    check_cube(s);
    CHECK(strcmp(s->path, "cube.d3d") == 0);
    // Vertices in file order, coordinates as written.
    CHECK(s->vertices[1].x == 1 && s->vertices[1].y == 0 && s->vertices[1].z == 0);
    CHECK(s->vertices[6].x == 1 && s->vertices[6].y == 1 && s->vertices[6].z == 1);
    // Face 1 is "10 40 30 20": vertex indices 0 3 2 1.
    CHECK(s->faces[0].verts[0] == 0 && s->faces[0].verts[1] == 3 && s->faces[0].verts[2] == 2 &&
          s->faces[0].verts[3] == 1);
    // Lines: where each face starts.
    CHECK(s->faces[0].line == 12);
    CHECK(s->faces[1].line == 14);
    CHECK(s->faces[2].line == 15);
    CHECK(s->faces[5].line == 21);
    // Materials: default, steel, paint.red-2.
    CHECK(s->nmaterials == 3);
    int d = model_scene_material_index(s, "default"), st = model_scene_material_index(s, "steel"),
        p = model_scene_material_index(s, "paint.red-2");
    CHECK(d >= 0 && st >= 0 && p >= 0 && d != st && st != p && d != p);
    CHECK(model_scene_material_index(s, "glass") == -1);
    CHECK(s->faces[0].material == d);
    CHECK(s->faces[1].material == st);
    CHECK(s->faces[2].material == st);
    CHECK(s->faces[3].material == p);
    CHECK(s->faces[4].material == p);
    CHECK(s->faces[5].material == st);
    // sha256 of the text.
    char h[65];
    model_sha256_hex(CUBE_D3D, strlen(CUBE_D3D), h);
    CHECK(strcmp(s->sha256, h) == 0);
    model_scene_free(s);
}

TEST(scene_d3d_newell_normal_of_tilted_pentagon)
{
    // A regular pentagon of radius 10 in the plane z = x + 5 (non-axis normal),
    // vertices counter-clockwise seen from +z: normal (-1, 0, 1)/sqrt(2).
    char buf[512];
    int o = 0;
    for (int i = 0; i < 5; i++) {
        double a = 2 * M_PI * i / 5, x = 10 * cos(a), y = 10 * sin(a);
        o += snprintf(buf + o, sizeof buf - o, "%d %.17g %.17g %.17g\n", i + 1, x, y, x + 5);
    }
    snprintf(buf + o, sizeof buf - o, "Faces:\n1 2 3 4 5.\n");
    model_scene_t *s = d3d(buf);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (!s) return;
    CHECK_NEAR(s->faces[0].normal.x, -sqrt(0.5), 1e-12);
    CHECK_NEAR(s->faces[0].normal.y, 0, 1e-12);
    CHECK_NEAR(s->faces[0].normal.z, sqrt(0.5), 1e-12);
    // Plane through the centroid (0, 0, 5): n.x = 5/sqrt(2).
    CHECK_NEAR(s->faces[0].offset_mm, 5 * sqrt(0.5), 1e-12);
    model_scene_free(s);
}

// Expect a parse error containing each of the given fragments.
static void expect_d3d_error(const char *text, const char *a, const char *b, int line)
{
    model_scene_t *s = d3d(text);
    CHECK_MSG(s == NULL, "expected an error for line %d", line);
    model_scene_free(s);
    CHECK_CONTAINS(model_last_error(), a);
    if (b) CHECK_CONTAINS(model_last_error(), b);
}

#define TRI "1 0 0 0\n2 10 0 0\n3 0 10 0\n"

TEST(scene_d3d_errors)
{
    expect_d3d_error(TRI "4 1 x 0\nFaces:\n1 2 3.\n", "cube.d3d:4: ", "'x' does not parse", __LINE__);
    expect_d3d_error(TRI "4 1 0\nFaces:\n1 2 3.\n", "cube.d3d:4: ", "4 fields (number x y z), this one has 3",
                     __LINE__);
    expect_d3d_error(TRI "x4 1 0 0\nFaces:\n1 2 3.\n", "cube.d3d:4: vertex number 'x4' does not parse",
                     NULL, __LINE__);
    expect_d3d_error(TRI "0 1 0 0\nFaces:\n1 2 3.\n", "cube.d3d:4: vertex number '0'", "positive", __LINE__);
    expect_d3d_error(TRI "2 1 0 0\nFaces:\n1 2 3.\n", "cube.d3d:4: vertex 2 is defined twice (first on line 2)",
                     NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2 3.\n1 2 9 .\n", "cube.d3d:6: face 2 refers to vertex 9, which does not exist",
                     NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2 3.\n2 x 3.\n", "cube.d3d:6: face 2: 'x' is not a vertex number", NULL,
                     __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2 3.\n1 2.\n", "cube.d3d:6: face 2 has 2 vertices; a face needs at least 3",
                     NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n.\n", "cube.d3d:5: face 1 has 0 vertices", NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2 3.\n1 2\n1 3 .\n", "cube.d3d:6: face 2 uses vertex 1 twice", NULL, __LINE__);
    expect_d3d_error(TRI "4 20 0 0\nFaces:\n1 2 3.\n1 2 4.\n", "cube.d3d:7: face 2 is degenerate (zero area",
                     NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2 3.\n1 1e0 3.\n", "face 2: '1e0' is not a vertex number", NULL, __LINE__);
    expect_d3d_error(TRI, "cube.d3d: no 'Faces:' line", NULL, __LINE__);
    expect_d3d_error("", "cube.d3d: no 'Faces:' line", NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n# nothing\n", "cube.d3d: no faces after 'Faces:'", NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2 3.\n3 2\n 1\n", "cube.d3d:6: face 2 is not ended by '.'", NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n1 2\n@material steel\n3.\n", "cube.d3d:6: face 1 (line 5) is not ended by '.' before @material",
                     NULL, __LINE__);
    expect_d3d_error(TRI "4 1e999 0 0\nFaces:\n1 2 3.\n", "cube.d3d:4: vertex 4: coordinate '1e999' is not a finite number",
                     NULL, __LINE__);
    expect_d3d_error(TRI "4 0 nan 0\nFaces:\n1 2 3.\n", "cube.d3d:4: vertex 4: coordinate 'nan' is not a finite number",
                     NULL, __LINE__);
    expect_d3d_error(TRI "4 0 0 -inf\nFaces:\n1 2 3.\n", "cube.d3d:4: vertex 4: coordinate '-inf' is not a finite",
                     NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n@material bad/name\n1 2 3.\n", "cube.d3d:5: invalid material name 'bad/name'",
                     "1 to 63 characters", __LINE__);
    expect_d3d_error(TRI "Faces:\n@material\n1 2 3.\n", "cube.d3d:5: '@material' takes one material name", NULL,
                     __LINE__);
    char longname[200];
    snprintf(longname, sizeof longname, TRI "Faces:\n@material %064d\n1 2 3.\n", 0);
    expect_d3d_error(longname, "cube.d3d:5: invalid material name", NULL, __LINE__);
    expect_d3d_error(TRI "@material steel\nFaces:\n1 2 3.\n", "cube.d3d:4: @material belongs after the 'Faces:' line",
                     NULL, __LINE__);
    expect_d3d_error(TRI "Faces:\n@colour red\n1 2 3.\n", "cube.d3d:5: unknown directive '@colour'", NULL, __LINE__);
    expect_d3d_error(TRI "Faces\n1 2 3.\n", "cube.d3d:4: ", "the faces start after a line 'Faces:'", __LINE__);
    // Large but finite coordinates: an error, not a crash or a NaN normal.
    expect_d3d_error("1 1e308 0 0\n2 -1e308 1e308 0\n3 1e308 1e308 1e308\nFaces:\n1 2 3.\n",
                     "cube.d3d:5: face 1: its plane cannot be computed", NULL, __LINE__);
    // Binary input.
    const char nul[] = "1 0 0 0\n2 1 0\0 0\n";
    model_error_clear();
    CHECK(model_scene_parse_d3d(nul, sizeof nul - 1, "bin.d3d", NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "bin.d3d:2: the line contains a NUL byte");
    const char garbage[] = "\x01\xff\xfe 7\x80 \x1b[0m";
    model_error_clear();
    CHECK(model_scene_parse_d3d(garbage, sizeof garbage - 1, "bin.d3d", NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "bin.d3d:1: a vertex line has 4 fields");
    model_error_clear();
    CHECK(model_scene_parse_d3d("1 0 0 0\n2 1 0 0\n3 0 1 0\nFaces:\n1 2 3 .\n", 0, "empty.d3d", NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "empty.d3d: no 'Faces:' line");
}

// Face 1 a triangle; face 2 a twisted square (z = +-0.35 alternating), whose
// Newell normal is +z through the centroid (5, 5, 0): every vertex 0.35 mm off.
static const char TWISTED_D3D[] =
    "1 0 0 0\n2 10 0 0\n3 0 10 0\n"
    "12 0 0 0.35\n13 10 0 -0.35\n14 10 10 0.35\n15 0 10 -0.35\n"
    "Faces:\n"
    "1 2 3.\n"
    "# the twisted one\n"
    "12 13 14 15.\n";   // line 11

TEST(scene_d3d_planarity_and_tolerance)
{
    expect_d3d_error(TWISTED_D3D,
                     "cube.d3d:11: face 2 is not planar: vertex 12 is 0.35 mm from the face's plane "
                     "(tolerance 0.01 mm)", "raise the planarity tolerance", __LINE__);
    model_scene_options_t opt = { .planarity_tol_mm = 0.3 };
    model_scene_t *s = model_scene_parse_d3d(TWISTED_D3D, strlen(TWISTED_D3D), "t.d3d", &opt);
    CHECK(s == NULL);
    CHECK_CONTAINS(model_last_error(), "(tolerance 0.3 mm)");
    model_scene_free(s);
    opt.planarity_tol_mm = 0.36;
    s = model_scene_parse_d3d(TWISTED_D3D, strlen(TWISTED_D3D), "t.d3d", &opt);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (s) {
        CHECK(s->nfaces == 2);
        CHECK_NEAR(s->faces[1].normal.z, 1, 1e-12);
        CHECK_NEAR(s->faces[1].offset_mm, 0, 1e-12);
    }
    model_scene_free(s);
    opt.planarity_tol_mm = NAN;
    model_error_clear();
    CHECK(model_scene_parse_d3d(TWISTED_D3D, strlen(TWISTED_D3D), "t.d3d", &opt) == NULL);
    CHECK_CONTAINS(model_last_error(), "t.d3d: planarity tolerance nan mm is invalid");
}

static const char CUBE_OBJ[] =
    "# unit cube\n"
    "mtllib cube.mtl\n"
    "o cube\n"
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "v 0 0 1 1.0\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"   // lines 8..11, one with w
    "vt 0 0\nvt 1 0\nvn 0 0 -1\n"
    "g all\ns off\n"
    "f 1 4 3 2\n"                               // line 17, default
    "usemtl steel\n"
    "f 5/1 6/2 7/1 8/2\n"                       // v/vt
    "f 1/1/1 2/2/1 6/1/1 5/2/1\n"               // v/vt/vn
    "usemtl paint\n"
    "f -5//1 -1//1 -2//1 -6//1\n"               // relative: 4 8 7 3
    "f 1 5 8 4\n"
    "l 1 2\n"
    "usemtl steel\n"
    "f 2 3 7 6   # right\n";

TEST(scene_obj_cube)
{
    model_scene_t *s = obj(CUBE_OBJ);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (!s) return;
    check_cube(s);
    CHECK(s->faces[0].line == 17);
    CHECK(s->faces[3].verts[0] == 3 && s->faces[3].verts[1] == 7 && s->faces[3].verts[2] == 6 &&
          s->faces[3].verts[3] == 2);
    CHECK(s->nmaterials == 3);
    int d = model_scene_material_index(s, "default"), st = model_scene_material_index(s, "steel"),
        p = model_scene_material_index(s, "paint");
    CHECK(s->faces[0].material == d && d >= 0);
    CHECK(s->faces[1].material == st && s->faces[2].material == st && s->faces[5].material == st);
    CHECK(s->faces[3].material == p && s->faces[4].material == p && p >= 0);
    model_scene_free(s);
}

static void expect_obj_error(const char *text, const char *a, const char *b)
{
    model_scene_t *s = obj(text);
    CHECK(s == NULL);
    model_scene_free(s);
    CHECK_CONTAINS(model_last_error(), a);
    if (b) CHECK_CONTAINS(model_last_error(), b);
}

#define OTRI "v 0 0 0\nv 10 0 0\nv 0 10 0\n"

TEST(scene_obj_errors)
{
    expect_obj_error(OTRI "vp 1 2\nf 1 2 3\n", "cube.obj:4: unsupported OBJ statement 'vp'", NULL);
    expect_obj_error(OTRI "f 1 2 3\nf 1 2 9\n", "cube.obj:5: face 2 refers to vertex 9, which does not exist", NULL);
    expect_obj_error(OTRI "f 1 2 -4\n", "cube.obj:4: face 1: vertex index -4 refers before the first vertex", NULL);
    expect_obj_error(OTRI "f 1 2 0\n", "cube.obj:4: face 1: '0' is not a vertex reference", NULL);
    expect_obj_error(OTRI "f 1 2/x 3\n", "cube.obj:4: face 1: '2/x' is not a vertex reference", NULL);
    expect_obj_error(OTRI "f 1 2/1/1/1 3\n", "'2/1/1/1' is not a vertex reference", NULL);
    expect_obj_error(OTRI "f 1 2\n", "cube.obj:4: face 1 has 2 vertices", NULL);
    expect_obj_error(OTRI "f 1 2 3 -3\n", "cube.obj:4: face 1 uses vertex 1 twice", NULL);
    expect_obj_error(OTRI "v 20 0 0\nf 1 2 4\n", "cube.obj:5: face 1 is degenerate", NULL);
    expect_obj_error(OTRI "v 1 2\n", "cube.obj:4: 'v' takes 3 or 4 numbers", NULL);
    expect_obj_error(OTRI "v 1 2 zz\n", "cube.obj:4: vertex 4: 'zz' does not parse", NULL);
    expect_obj_error(OTRI "v 1 2 1e400\n", "cube.obj:4: vertex 4: '1e400' is not a finite number", NULL);
    expect_obj_error(OTRI "usemtl a b\nf 1 2 3\n", "cube.obj:4: 'usemtl' takes one material name", NULL);
    expect_obj_error(OTRI "usemtl \xc3\xa9t\xc3\xa9\nf 1 2 3\n", "cube.obj:4: invalid material name '\\xc3\\xa9t", NULL);
    expect_obj_error(OTRI, "cube.obj: no faces", NULL);
    expect_obj_error("v 0 0 0.35\nv 10 0 -0.35\nv 10 10 0.35\nv 0 10 -0.35\n\nf 1 2 3 4\n",
                     "cube.obj:6: face 1 is not planar: vertex 1 is 0.35 mm from the face's plane "
                     "(tolerance 0.01 mm)", NULL);
    // Positive indices may refer to vertices defined later.
    model_scene_t *s = obj("f 1 2 3\n" OTRI);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (s) CHECK_NEAR(s->faces[0].normal.z, 1, 1e-15);
    model_scene_free(s);
}

TEST(scene_rotated_z)
{
    model_scene_t *s = d3d(CUBE_D3D);
    CHECK(s != NULL);
    if (!s) return;
    model_scene_t *r = model_scene_rotated_z(s, 90);
    CHECK(r != NULL);
    if (!r) {
        model_scene_free(s);
        return;
    }
    // Vertex 20 is (1,0,0) -> (0,1,0).
    CHECK_NEAR(r->vertices[1].x, 0, 1e-15);
    CHECK_NEAR(r->vertices[1].y, 1, 1e-15);
    CHECK_NEAR(r->vertices[1].z, 0, 1e-15);
    // The right face's normal (1,0,0) -> (0,1,0); front (0,-1,0) -> (1,0,0).
    CHECK_NEAR(r->faces[5].normal.x, 0, 1e-15);
    CHECK_NEAR(r->faces[5].normal.y, 1, 1e-15);
    CHECK_NEAR(r->faces[2].normal.x, 1, 1e-15);
    CHECK_NEAR(r->faces[2].normal.y, 0, 1e-15);
    CHECK(strcmp(r->sha256, s->sha256) == 0);
    CHECK(strcmp(r->path, s->path) == 0);
    CHECK(r->path != s->path && r->vertices != s->vertices && r->faces[0].verts != s->faces[0].verts);
    CHECK(r->nmaterials == s->nmaterials && strcmp(r->material_names[1], s->material_names[1]) == 0);
    for (int k = 0; k < 6; k++) {
        CHECK(r->faces[k].material == s->faces[k].material);
        CHECK(r->faces[k].nverts == s->faces[k].nverts && r->faces[k].verts[2] == s->faces[k].verts[2]);
        CHECK_NEAR(r->faces[k].offset_mm, s->faces[k].offset_mm, 1e-15);
        // Still on the plane after rotation.
        for (int i = 0; i < r->faces[k].nverts; i++) {
            model_vec3_t p = r->vertices[r->faces[k].verts[i]], n = r->faces[k].normal;
            CHECK_NEAR(p.x * n.x + p.y * n.y + p.z * n.z, r->faces[k].offset_mm, 1e-12);
        }
    }
    // The original is untouched.
    CHECK(s->vertices[1].x == 1 && s->vertices[1].y == 0);
    // A general angle, and 4 x 90 deg back to the start.
    model_scene_t *r30 = model_scene_rotated_z(s, -30);
    CHECK(r30 != NULL);
    if (r30) {
        CHECK_NEAR(r30->vertices[1].x, cos(M_PI / 6), 1e-15);
        CHECK_NEAR(r30->vertices[1].y, -0.5, 1e-15);
    }
    model_scene_free(r30);
    model_scene_t *r450 = model_scene_rotated_z(s, 450);
    CHECK(r450 && r450->vertices[6].x == -1 && r450->vertices[6].y == 1);
    model_scene_free(r450);
    model_scene_free(r);
    model_scene_free(s);
}

TEST(scene_load_by_extension)
{
    const char *pd = test_write("cube.D3D", CUBE_D3D);
    const char *po = test_write("cube.Obj", CUBE_OBJ);
    const char *px = test_write("cube.stl", CUBE_D3D);
    model_scene_t *a = model_scene_load(pd, NULL), *b = model_scene_load(po, NULL);
    CHECK_MSG(a != NULL, "%s", model_last_error());
    CHECK_MSG(b != NULL, "%s", model_last_error());
    if (a && b) {
        check_cube(a);
        check_cube(b);
        CHECK(strcmp(a->path, pd) == 0);
        char h[65];
        CHECK(model_sha256_file(pd, h) && strcmp(h, a->sha256) == 0);
    }
    model_scene_free(a);
    model_scene_free(b);
    model_error_clear();
    CHECK(model_scene_load(px, NULL) == NULL);   // named .stl: read as one, and refused as one
    CHECK_CONTAINS(model_last_error(), "cube.stl: a truncated binary STL: its header announces");
    model_error_clear();
    CHECK(model_scene_load(test_write("noext", CUBE_D3D), NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "unknown scene format (no extension): neither STL nor PLY by its content");
    model_error_clear();
    CHECK(model_scene_load(test_path("missing.d3d"), NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "missing.d3d: cannot open");
    // Errors name the path as given.
    const char *pbad = test_write("bad.d3d", TWISTED_D3D);
    model_error_clear();
    CHECK(model_scene_load(pbad, NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "bad.d3d:11: face 2 is not planar");
    model_scene_free(NULL);
}

TEST_ALONE(scene_hostile_inputs)
{
    // Very long lines, huge numbers, many tokens: errors (or results), never a crash or hang.
    size_t n = 1 << 20;
    char *big = malloc(n + 64);
    memset(big, '9', n);
    memcpy(big + n, " 0 0 0\nFaces:\n", 15);
    model_error_clear();
    CHECK(model_scene_parse_d3d(big, n + 14, "big.d3d", NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "big.d3d:1: vertex number '99999");
    // A face with a million references to 3 vertices: repeated vertex, found fast.
    size_t o = (size_t)sprintf(big, TRI "Faces:\n");
    while (o + 8 < n) o += (size_t)sprintf(big + o, "1 2 3 ");
    big[o++] = '.';
    double t0 = model_now_s();
    model_error_clear();
    CHECK(model_scene_parse_d3d(big, o, "big.d3d", NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "big.d3d:5: face 1 uses vertex 1 twice");
    CHECK(model_now_s() - t0 < 2.0);
    // Only whitespace, only comments, only a '#'.
    const char *odd[] = { " \t\r\n\n", "####", "Faces:", "Faces: .", "1 0 0 0 Faces:", "f", "v", "." };
    for (size_t i = 0; i < sizeof odd / sizeof odd[0]; i++) {
        model_error_clear();
        CHECK(model_scene_parse_d3d(odd[i], strlen(odd[i]), "odd.d3d", NULL) == NULL);
        CHECK(model_last_error()[0] != 0);
        model_error_clear();
        CHECK(model_scene_parse_obj(odd[i], strlen(odd[i]), "odd.obj", NULL) == NULL);
        CHECK(model_last_error()[0] != 0);
    }
    free(big);
}

TEST_ALONE(scene_large_inputs_in_linear_time)
{
    // 100k vertices, 50k faces each with its own material: well under a second
    // (a quadratic step would take minutes, under ASan even more).
    int nv = 100000, nf = 50000;
    size_t cap = (size_t)nv * 40 + (size_t)nf * 60 + 64, o = 0;
    char *t = malloc(cap);
    for (int i = 1; i <= nv; i++) o += (size_t)sprintf(t + o, "%d %d %d 0\n", i, i % 1000, i / 1000);
    o += (size_t)sprintf(t + o, "Faces:\n");
    for (int k = 0; k < nf; k++) {
        int a = 1 + k % (nv - 1001);   // a, a+1, a+1001: a triangle of the grid
        o += (size_t)sprintf(t + o, "@material m%d\n%d %d %d.\n", k, a, a + 1, a + 1001);
    }
    double t0 = model_now_s();
    model_error_clear();
    model_scene_t *s = model_scene_parse_d3d(t, o, "big.d3d", NULL);
    double dt = model_now_s() - t0;
    CHECK_MSG(s != NULL, "%s", model_last_error());
    CHECK_MSG(dt < 3.0, "parsing took %.2f s", dt);
    if (s) {
        CHECK(s->nvertices == nv && s->nfaces == nf && s->nmaterials == nf);
        CHECK(model_scene_material_index(s, "m49999") == s->faces[nf - 1].material);
    }
    model_scene_free(s);
    free(t);
}

// ---------------------------------------------------------------------------
// STL and PLY

// The unit cube's faces as in CUBE_OBJ (0-based): bottom, top, front, back, left, right.
static const double CUBE_V[8][3] = { { 0, 0, 0 }, { 1, 0, 0 }, { 1, 1, 0 }, { 0, 1, 0 },
                                     { 0, 0, 1 }, { 1, 0, 1 }, { 1, 1, 1 }, { 0, 1, 1 } };
static const int CUBE_F[6][4] = { { 0, 3, 2, 1 }, { 4, 5, 6, 7 }, { 0, 1, 5, 4 },
                                  { 3, 7, 6, 2 }, { 0, 4, 7, 3 }, { 1, 2, 6, 5 } };

static void put_f32(GByteArray *a, float f) { g_byte_array_append(a, (const guint8 *)&f, 4); }   // little-endian host
static void put_u32(GByteArray *a, uint32_t u) { g_byte_array_append(a, (const guint8 *)&u, 4); }

// The cube as 12 triangles (each quad a b c d as a b c, a c d), written as
// ASCII STL, binary STL, and an OBJ / ASCII PLY / binary PLY with the
// vertices in the order STL's corners first appear.
typedef struct {
    GString *stl, *obj, *ply;
    GByteArray *stlb, *plyb;
} cube_files_t;

static cube_files_t cube_files(double scale)
{
    int tri[12][3], order[8], pos[8], n = 0;
    for (int k = 0; k < 6; k++) {
        const int *q = CUBE_F[k];
        int a[3] = { q[0], q[1], q[2] }, b[3] = { q[0], q[2], q[3] };
        memcpy(tri[2 * k], a, sizeof a);
        memcpy(tri[2 * k + 1], b, sizeof b);
    }
    for (int i = 0; i < 8; i++) pos[i] = -1;
    for (int t = 0; t < 12; t++)
        for (int c = 0; c < 3; c++)
            if (pos[tri[t][c]] < 0) pos[tri[t][c]] = n, order[n++] = tri[t][c];
    cube_files_t f = { g_string_new("solid cube\n"), g_string_new(""), g_string_new(""), g_byte_array_new(),
                       g_byte_array_new() };
    guint8 header[80] = "solid binary written by the test (a header may begin with solid)";
    g_byte_array_append(f.stlb, header, 80);
    put_u32(f.stlb, 12);
    for (int t = 0; t < 12; t++) {
        g_string_append(f.stl, "  facet normal 0 0 0\n    outer loop\n");
        for (int i = 0; i < 3; i++) put_f32(f.stlb, 0);
        for (int c = 0; c < 3; c++) {
            const double *v = CUBE_V[tri[t][c]];
            g_string_append_printf(f.stl, "      vertex %g %g %g\n", v[0] * scale, v[1] * scale, v[2] * scale);
            for (int i = 0; i < 3; i++) put_f32(f.stlb, (float)(v[i] * scale));
        }
        g_byte_array_append(f.stlb, (const guint8 *)"\0\0", 2);
        g_string_append(f.stl, "    endloop\n  endfacet\n");
    }
    g_string_append(f.stl, "endsolid cube\n");
    const char *ph = "ply\nformat %s 1.0\ncomment the test's cube\nelement vertex 8\nproperty float x\n"
                     "property float y\nproperty float z\nproperty uchar red\nelement face 12\n"
                     "property list uchar int vertex_indices\nend_header\n";
    g_string_append_printf(f.ply, ph, "ascii");
    char *hb = g_strdup_printf(ph, "binary_little_endian");
    g_byte_array_append(f.plyb, (const guint8 *)hb, (guint)strlen(hb));
    g_free(hb);
    for (int i = 0; i < 8; i++) {
        const double *v = CUBE_V[order[i]];
        g_string_append_printf(f.obj, "v %g %g %g\n", v[0] * scale, v[1] * scale, v[2] * scale);
        g_string_append_printf(f.ply, "%g %g %g 200\n", v[0] * scale, v[1] * scale, v[2] * scale);
        for (int c = 0; c < 3; c++) put_f32(f.plyb, (float)(v[c] * scale));
        g_byte_array_append(f.plyb, (const guint8 *)"\xc8", 1);
    }
    for (int t = 0; t < 12; t++) {
        g_string_append_printf(f.obj, "f %d %d %d\n", pos[tri[t][0]] + 1, pos[tri[t][1]] + 1, pos[tri[t][2]] + 1);
        g_string_append_printf(f.ply, "3 %d %d %d\n", pos[tri[t][0]], pos[tri[t][1]], pos[tri[t][2]]);
        g_byte_array_append(f.plyb, (const guint8 *)"\x03", 1);
        for (int c = 0; c < 3; c++) put_u32(f.plyb, (uint32_t)pos[tri[t][c]]);
    }
    return f;
}

static void cube_files_free(cube_files_t *f)
{
    g_string_free(f->stl, TRUE);
    g_string_free(f->obj, TRUE);
    g_string_free(f->ply, TRUE);
    g_byte_array_free(f->stlb, TRUE);
    g_byte_array_free(f->plyb, TRUE);
}

static void check_same_scene(const model_scene_t *a, const model_scene_t *b, const char *what)
{
    CHECK_MSG(a && b, "%s: %s", what, model_last_error());
    if (!a || !b) return;
    CHECK_MSG(a->nvertices == b->nvertices && a->nfaces == b->nfaces, "%s: %d/%d vertices, %d/%d faces", what,
              a->nvertices, b->nvertices, a->nfaces, b->nfaces);
    if (a->nvertices != b->nvertices || a->nfaces != b->nfaces) return;
    for (int i = 0; i < a->nvertices; i++)
        CHECK_MSG(a->vertices[i].x == b->vertices[i].x && a->vertices[i].y == b->vertices[i].y &&
                  a->vertices[i].z == b->vertices[i].z, "%s: vertex %d", what, i + 1);
    for (int k = 0; k < a->nfaces; k++) {
        const model_face_t *f = &a->faces[k], *g = &b->faces[k];
        CHECK_MSG(f->nverts == g->nverts && !memcmp(f->verts, g->verts, (size_t)f->nverts * sizeof(int)),
                  "%s: face %d", what, k + 1);
        CHECK_NEAR(f->normal.x, g->normal.x, 1e-12);
        CHECK_NEAR(f->normal.y, g->normal.y, 1e-12);
        CHECK_NEAR(f->normal.z, g->normal.z, 1e-12);
        CHECK_NEAR(f->offset_mm, g->offset_mm, 1e-12);
        CHECK(!strcmp(a->material_names[f->material], b->material_names[g->material]));
    }
}

TEST(scene_stl_ply_cube_same_as_obj)
{
    cube_files_t f = cube_files(10);
    model_scene_t *o = model_scene_parse_obj(f.obj->str, f.obj->len, "cube.obj", NULL);
    CHECK_MSG(o != NULL, "%s", model_last_error());
    CHECK(o && o->nvertices == 8 && o->nfaces == 12 && o->nmaterials == 1 && !strcmp(o->material_names[0], "default"));
    model_scene_t *sa = model_scene_parse_stl(f.stl->str, f.stl->len, "cube.stl", NULL);
    model_scene_t *sb = model_scene_parse_stl((const char *)f.stlb->data, f.stlb->len, "cubeb.stl", NULL);
    model_scene_t *pa = model_scene_parse_ply(f.ply->str, f.ply->len, "cube.ply", NULL);
    model_scene_t *pb = model_scene_parse_ply((const char *)f.plyb->data, f.plyb->len, "cubeb.ply", NULL);
    check_same_scene(o, sa, "ASCII STL");
    check_same_scene(o, sb, "binary STL");
    check_same_scene(o, pa, "ASCII PLY");
    check_same_scene(o, pb, "binary PLY");
    char *up = g_ascii_strup(f.stl->str, -1);   // keywords in capitals, as some writers have them
    model_scene_t *su = model_scene_parse_stl(up, strlen(up), "CUBE.STL", NULL);
    check_same_scene(o, su, "ASCII STL in capitals");
    model_scene_free(su);
    g_free(up);
    if (sa) CHECK(sa->faces[0].line == 2);   // ASCII: the facet's line
    if (sb) CHECK(sb->faces[0].line == 0);   // binary: no line
    model_scene_free(sa);
    model_scene_free(sb);
    model_scene_free(pa);
    model_scene_free(pb);

    // Loaded from files, told by content: the binary STL named .dat, the PLY named .obj.
    const char *p1 = test_path("cube_bin.dat"), *p2 = test_path("cube_ply.obj"), *p3 = test_write("c.stl", f.stl->str);
    CHECK(g_file_set_contents(p1, (const char *)f.stlb->data, f.stlb->len, NULL));
    CHECK(g_file_set_contents(p2, (const char *)f.plyb->data, f.plyb->len, NULL));
    model_scene_t *l1 = model_scene_load(p1, NULL), *l2 = model_scene_load(p2, NULL), *l3 = model_scene_load(p3, NULL);
    check_same_scene(o, l1, "binary STL file");
    check_same_scene(o, l2, "binary PLY file");
    check_same_scene(o, l3, "ASCII STL file");
    if (l1) CHECK(l1->warning[0] == 0);   // 10 mm: no units warning
    model_scene_free(l1);
    model_scene_free(l2);
    model_scene_free(l3);
    model_scene_free(o);
    cube_files_free(&f);

    // PLY polygons: the quad cube, as the OBJ and D3D cubes
    GString *q = g_string_new("ply\nformat ascii 1.0\nelement vertex 8\nproperty double x\nproperty double y\n"
                              "property double z\nelement face 6\nproperty list uchar uint vertex_index\n"
                              "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n");
    for (int i = 0; i < 8; i++) g_string_append_printf(q, "%g %g %g\n", CUBE_V[i][0], CUBE_V[i][1], CUBE_V[i][2]);
    for (int k = 0; k < 6; k++)
        g_string_append_printf(q, "4 %d %d %d %d\n", CUBE_F[k][0], CUBE_F[k][1], CUBE_F[k][2], CUBE_F[k][3]);
    g_string_append(q, "0 1\n");
    model_scene_t *pq = model_scene_parse_ply(q->str, q->len, "quads.ply", NULL);
    CHECK_MSG(pq != NULL, "%s", model_last_error());
    if (pq) check_cube(pq);
    model_scene_free(pq);
    g_string_free(q, TRUE);
}

TEST(scene_units_scale_and_warning)
{
    double u = 0;
    CHECK(model_units_parse("m", &u) && u == 1000);
    CHECK(model_units_parse("in", &u) && u == 25.4);
    CHECK(model_units_parse("mm", &u) && u == 1);
    CHECK(!model_units_parse("cm", &u));
    cube_files_t f = cube_files(0.1);   // a 100 mm cube drawn in metres
    const char *pstl = test_path("m.stl"), *pply = test_write("m.ply", f.ply->str), *pobj = test_write("m.obj", f.obj->str);
    CHECK(g_file_set_contents(pstl, (const char *)f.stlb->data, f.stlb->len, NULL));
    const char *paths[3] = { pstl, pply, pobj };
    for (int i = 0; i < 3; i++) {
        model_scene_t *d = model_scene_load(paths[i], NULL);   // no unit: read as mm, with the warning
        CHECK_MSG(d != NULL, "%s", model_last_error());
        if (d) {
            CHECK_CONTAINS(d->warning, "spans 0.1 mm");
            CHECK_CONTAINS(d->warning, "--units m");
        }
        model_scene_options_t o = MODEL_SCENE_OPTIONS_DEFAULT;
        o.unit_mm = 1000;
        model_scene_t *m = model_scene_load(paths[i], &o);
        CHECK_MSG(m != NULL, "%s", model_last_error());
        if (d && m) {
            CHECK(m->warning[0] == 0);
            double mx = 0;
            for (int k = 0; k < m->nvertices; k++) {
                CHECK_NEAR(m->vertices[k].x, 1000 * d->vertices[k].x, 1e-9);
                mx = fmax(mx, m->vertices[k].z);
            }
            CHECK_NEAR(mx, 100, 1e-4);   // float STL: 0.1 is not exact
            CHECK_NEAR(m->faces[1].offset_mm, 1000 * d->faces[1].offset_mm, 1e-6);
        }
        o.unit_mm = 25.4;
        model_scene_t *in = model_scene_load(paths[i], &o);
        if (in && d) CHECK_NEAR(in->vertices[1].y, 25.4 * d->vertices[1].y, 1e-9);
        o.unit_mm = 1;   // mm said explicitly: no warning
        model_scene_t *mm = model_scene_load(paths[i], &o);
        if (mm) CHECK(mm->warning[0] == 0);
        model_scene_free(d);
        model_scene_free(m);
        model_scene_free(in);
        model_scene_free(mm);
    }
    model_scene_options_t bad = { .planarity_tol_mm = 0.01, .unit_mm = -1 };
    CHECK(model_scene_load(pobj, &bad) == NULL);
    CHECK_CONTAINS(model_last_error(), "unit");
    cube_files_free(&f);
}

static void expect_mesh_error(bool stl, const void *data, size_t len, const char *a, const char *b)
{
    model_error_clear();
    if (len == 0) len = strlen(data);
    model_scene_t *s = stl ? model_scene_parse_stl(data, len, "bad.stl", NULL)
                           : model_scene_parse_ply(data, len, "bad.ply", NULL);
    CHECK_MSG(s == NULL, "accepted: expected '%s'", a);
    model_scene_free(s);
    CHECK_CONTAINS(model_last_error(), a);
    if (b) CHECK_CONTAINS(model_last_error(), b);
}

TEST(scene_stl_ply_errors)
{
    cube_files_t f = cube_files(10);
    const char *sb = (const char *)f.stlb->data;
    // binary STL: truncated inside triangle 12, a header alone, bytes left over
    expect_mesh_error(true, sb, f.stlb->len - 20, "bad.stl: a truncated binary STL: its header announces 12 triangles",
                      "inside triangle 12, at byte offset 664");
    expect_mesh_error(true, sb, 50, "truncated", NULL);   // 50 bytes of "solid ...": a cut ASCII or binary STL
    GByteArray *more = g_byte_array_new();
    g_byte_array_append(more, f.stlb->data, f.stlb->len);
    g_byte_array_append(more, (const guint8 *)"xyz", 3);
    expect_mesh_error(true, more->data, more->len, "3 bytes after the last triangle", NULL);
    // a non-finite coordinate (triangle 2, vertex 1, x at byte 84 + 50 + 12)
    memcpy(more->data + 146, &(float){ NAN }, 4);
    expect_mesh_error(true, more->data, f.stlb->len, "bad.stl: byte offset 146: triangle 2, vertex 1", "not a finite");
    // a degenerate triangle: its byte offset
    memcpy(more->data, f.stlb->data, f.stlb->len);
    memcpy(more->data + 84 + 50 + 24, more->data + 84 + 50 + 12, 12);   // corner 2 = corner 1
    expect_mesh_error(true, more->data, f.stlb->len, "bad.stl: byte offset 134: face 2 uses vertex", NULL);
    g_byte_array_free(more, TRUE);
    // ASCII STL: line numbers
    expect_mesh_error(true, "solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n"
                      "   vertex 0 1 0\n   vertex 1 1 0\n", 0, "bad.stl:7: facet 1 has more than 3 vertices", NULL);
    expect_mesh_error(true, "solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 zero\n", 0,
                      "bad.stl:4: facet 1: 'vertex x y z' needs three finite numbers", NULL);
    const char *cut = "solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n";
    expect_mesh_error(true, cut, strlen(cut), "the file ends inside a solid", NULL);
    const char *kw = "solid x\n facet normal 0 0 1\n  polygon\n";
    expect_mesh_error(true, kw, strlen(kw), "bad.stl:3: 'polygon' is not an ASCII STL keyword", NULL);
    // PLY: a face index out of range (ASCII: line; binary: byte offset)
    GString *p = g_string_new(f.ply->str);
    char *at = strstr(p->str, "3 0 1 2\n");
    CHECK(at != NULL);
    if (at) at[6] = '9';   // "3 0 1 9": the first face (11 header lines, 8 vertices: line 20)
    expect_mesh_error(false, p->str, p->len, "bad.ply:20: face 1: vertex index 9 is out of range", "8 vertices");
    g_string_free(p, TRUE);
    GByteArray *bp = g_byte_array_new();
    g_byte_array_append(bp, f.plyb->data, f.plyb->len);
    size_t body = (size_t)(strstr((const char *)bp->data, "end_header\n") - (const char *)bp->data) + 11;
    size_t face1 = body + 8 * 13;
    memcpy(bp->data + face1 + 1 + 4, &(uint32_t){ 4000u }, 4);
    expect_mesh_error(false, bp->data, bp->len, "byte offset", "vertex index 4000 is out of range");
    char want[64];
    snprintf(want, sizeof want, "bad.ply: byte offset %zu: face 1", face1);
    expect_mesh_error(false, bp->data, bp->len, want, NULL);
    expect_mesh_error(false, f.plyb->data, f.plyb->len - 3, "a truncated binary PLY", "inside face 12 of 12");
    g_byte_array_free(bp, TRUE);
    const char *be = "ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n";
    expect_mesh_error(false, be, strlen(be), "bad.ply:2: PLY format 'binary_big_endian'", NULL);
    const char *two = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nelement vertex 0\nend_header\n";
    expect_mesh_error(false, two, strlen(two), "bad.ply:5: a second 'vertex' element", NULL);
    const char *nox = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n";
    expect_mesh_error(false, nox, strlen(nox), "bad.ply:6: the vertex element lacks property x", NULL);
    const char *shortp = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                         "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                         "0 0 0\n1 0 0\n";
    expect_mesh_error(false, shortp, strlen(shortp), "bad.ply:11: the file ends at vertex 3 of 3", NULL);
    cube_files_free(&f);
}

// refl render of one box as an OBJ in mm, a PLY in metres (--units m) and a
// binary STL in inches (--units in): the same image; the PLY without --units
// is read as mm with a warning.
TEST(scene_render_units_cli)
{
    GString *objt = g_string_new(""), *plyt = g_string_new("ply\nformat ascii 1.0\nelement vertex 8\nproperty double x\n"
                                                          "property double y\nproperty double z\nelement face 6\n"
                                                          "property list uchar int vertex_indices\nend_header\n");
    GByteArray *stl = g_byte_array_new();
    guint8 header[80] = "box in inches";
    g_byte_array_append(stl, header, 80);
    put_u32(stl, 12);
    double V[8][3];
    for (int i = 0; i < 8; i++) {
        V[i][0] = CUBE_V[i][0] * 100 - 50, V[i][1] = CUBE_V[i][1] * 80 - 40, V[i][2] = CUBE_V[i][2] * 60;
        g_string_append_printf(objt, "v %.17g %.17g %.17g\n", V[i][0], V[i][1], V[i][2]);
        g_string_append_printf(plyt, "%.17g %.17g %.17g\n", V[i][0] / 1000, V[i][1] / 1000, V[i][2] / 1000);
    }
    for (int k = 0; k < 6; k++) {
        const int *q = CUBE_F[k];
        g_string_append_printf(objt, "f %d %d %d %d\n", q[0] + 1, q[1] + 1, q[2] + 1, q[3] + 1);
        g_string_append_printf(plyt, "4 %d %d %d %d\n", q[0], q[1], q[2], q[3]);
        const int tri[2][3] = { { q[0], q[1], q[2] }, { q[0], q[2], q[3] } };
        for (int t = 0; t < 2; t++) {
            for (int i = 0; i < 3; i++) put_f32(stl, 0);
            for (int c = 0; c < 3; c++)
                for (int i = 0; i < 3; i++) put_f32(stl, (float)(V[tri[t][c]][i] / 25.4));
            g_byte_array_append(stl, (const guint8 *)"\0\0", 2);
        }
    }
    const char *pobj = test_write("box.obj", objt->str), *pply = test_write("box.ply", plyt->str);
    const char *pstl = test_path("box.stl");
    CHECK(g_file_set_contents(pstl, (const char *)stl->data, stl->len, NULL));
    char cam[1024], lamps[1024], mats[1024];
    snprintf(cam, sizeof cam, "%s/examples/camera.cameramodel", test_srcdir());
    snprintf(lamps, sizeof lamps, "%s/examples/lamps.ini", test_srcdir());
    snprintf(mats, sizeof mats, "%s/examples/materials.ini", test_srcdir());
    const char *scenes[3] = { pobj, pply, pstl }, *units[3] = { "mm", "m", "in" };
    const char *outs[3] = { test_path("box_obj.png"), test_path("box_ply.png"), test_path("box_stl.png") };
    uint16_t *pix[3] = { NULL, NULL, NULL };
    int w = 0, h = 0;
    for (int i = 0; i < 3; i++) {
        char *out = NULL, *err = NULL;
        int rc = test_refl_run(120, &out, &err, "render", scenes[i], "--units", units[i], "--camera", cam, "--lamps",
                               lamps, "--materials", mats, "--threads", "2", "-o", outs[i], NULL);
        CHECK_MSG(rc == 0, "%s: exit %d: %s", scenes[i], rc, err ? err : "");
        CHECK(err == NULL || strstr(err, "warning") == NULL);
        CHECK(model_png_read(outs[i], &w, &h, &pix[i]));
        free(out);
        free(err);
    }
    if (pix[0] && pix[1] && pix[2]) {
        long lit = 0, diff1 = 0, diff2 = 0;
        for (int k = 0; k < w * h; k++) {
            lit += pix[0][k] > 100;
            diff1 += abs((int)pix[1][k] - (int)pix[0][k]) > 2;
            diff2 += abs((int)pix[2][k] - (int)pix[0][k]) > 2;
        }
        CHECK_MSG(lit > 1000, "the box covers %ld bright pixels", lit);
        CHECK_MSG(diff1 <= lit / 1000 && diff2 <= lit / 1000, "pixels that differ: PLY %ld, STL %ld (of %ld)", diff1,
                  diff2, lit);
    }
    for (int i = 0; i < 3; i++) free(pix[i]);
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "render", pply, "--camera", cam, "--lamps", lamps, "--materials", mats,
                           "--threads", "2", "-o", test_path("box_tiny.png"), NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(err, "refl render: warning: ");
    CHECK_CONTAINS(err, "box.ply: the whole scene spans 0.1 mm");
    CHECK_CONTAINS(err, "--units m");
    free(out);
    free(err);
    rc = test_refl_run(30, &out, &err, "render", pply, "--units", "cm", "--camera", cam, "--lamps", lamps,
                       "--materials", mats, "-o", test_path("box_cm.png"), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--units: 'cm' is none of mm, m, in");
    free(out);
    free(err);
    g_string_free(objt, TRUE);
    g_string_free(plyt, TRUE);
    g_byte_array_free(stl, TRUE);
}

// --units on every command that reads a scene: a unit refl does not know is a usage error.
TEST(scene_units_option_on_every_scene_command)
{
    const char *cmds[][14] = {
        { "edges", "s.ply", "--camera", "c", "--lamps", "l", "--materials", "m", "--units", "ft", NULL },
        { "plan", "lamps", "s.ply", "--camera", "c", "--lamps", "l", "--materials", "m", "-o", "D", "--units", "ft",
          NULL },
        { "fit", "material", "S", "--calib", "C", "--scene", "s.stl", "-o", "p.json", "--units", "ft", NULL },
        { "calib", "white", "S", "--calib", "C", "--scene", "s.stl", "-o", "w.json", "--units", "ft", NULL },
        { "verify", "s.stl", "--images", "i.png", "--priors", "p.json", "-o", "D", "--units", "ft", NULL },
    };
    for (size_t k = 0; k < sizeof cmds / sizeof cmds[0]; k++) {
        const char *argv[16] = { test_refl() };
        int n = 1;
        for (int i = 0; cmds[k][i]; i++) argv[n++] = cmds[k][i];
        argv[n] = NULL;
        char *out = NULL, *err = NULL;
        int rc = test_run(argv, 30, &out, &err);
        CHECK_MSG(rc == 2, "refl %s %s: exit %d: %s", cmds[k][0], cmds[k][1], rc, err ? err : "");
        CHECK_CONTAINS(err, "--units: 'ft' is none of mm, m, in");
        free(out);
        free(err);
    }
}
