// tests/test_model_edges.c — the edge query on a box standing on a floor, seen
// obliquely by a pinhole camera with one lamp.
#include <stdlib.h>

#include "model/internal.h"
#include "tests/test.h"

// Box x,y in [-50,50], z in [0,60], turned by BOX_DEG about z; floor 400 x 400 at z = 0.
#define BOX_DEG -25.0
#define HX 50.0
#define HZ 60.0

static model_vec3_t rotz(model_vec3_t p, double deg)
{
    double a = deg * M_PI / 180, c = cos(a), s = sin(a);
    return v3(c * p.x - s * p.y, s * p.x + c * p.y, p.z);
}

static char *box_scene_text(void)
{
    static const double corner[8][3] = {
        { -HX, -HX, 0 }, { HX, -HX, 0 }, { HX, HX, 0 }, { -HX, HX, 0 },
        { -HX, -HX, HZ }, { HX, -HX, HZ }, { HX, HX, HZ }, { -HX, HX, HZ },
    };
    char *buf = malloc(4096);
    int n = snprintf(buf, 4096, "# box on a floor\n1 -200 -200 0\n2 200 -200 0\n3 200 200 0\n4 -200 200 0\n");
    for (int i = 0; i < 8; i++) {
        model_vec3_t p = rotz(v3(corner[i][0], corner[i][1], corner[i][2]), BOX_DEG);
        n += snprintf(buf + n, 4096 - n, "%d %.17g %.17g %.17g\n", 5 + i, p.x, p.y, p.z);
    }
    // faces: 0 floor; 1 top; 2 front (-y); 3 right (+x); 4 back (+y); 5 left (-x) (box frame)
    snprintf(buf + n, 4096 - n,
             "Faces:\n@material floor\n1 2 3 4.\n@material box\n9 10 11 12.\n5 6 10 9.\n6 7 11 10.\n"
             "7 8 12 11.\n8 5 9 12.\n");
    return buf;
}

enum { F_FLOOR, F_TOP, F_FRONT, F_RIGHT, F_BACK, F_LEFT };

typedef struct {
    model_scene_t *scene;
    model_tracer_t *tracer;
    model_camera_t *cam;
    model_lamps_t *lamps;
    model_materials_t *mats;
    const model_material_t *resolved[2];
    model_vec3_t centre, lamp;
} fixture_t;

static bool fixture(fixture_t *f)
{
    memset(f, 0, sizeof *f);
    char *text = box_scene_text();
    f->scene = model_scene_parse_d3d(text, strlen(text), "box.d3d", NULL);
    free(text);
    if (!f->scene) return false;
    f->tracer = model_tracer_new(f->scene);
    // Camera in the y-z plane, 40 deg above the horizontal, 700 mm from (0,0,30),
    // looking at it: a rotation about x by 90 + 40 deg.
    double e = 40 * M_PI / 180, D = 700;
    f->centre = v3(0, -D * cos(e), 30 + D * sin(e));
    double th = M_PI / 2 + e;
    // t = -R C with R = Rx(th)
    double R[3][3] = { { 1, 0, 0 }, { 0, cos(th), -sin(th) }, { 0, sin(th), cos(th) } };
    double rt[6] = { th, 0, 0, 0, 0, 0 };
    for (int i = 0; i < 3; i++)
        rt[3 + i] = -(R[i][0] * f->centre.x + R[i][1] * f->centre.y + R[i][2] * f->centre.z);
    double intr[4] = { 800, 800, 319.5, 239.5 };
    f->cam = model_camera_new("LENSMODEL_PINHOLE", intr, 640, 480, rt);
    // Lamp front-left, above: lights the top and the front, not the right face;
    // the box shadows the floor right of it.
    f->lamp = v3(-300, -250, 250);
    const char *lamps = "[lamp key]\nposition_mm = -300 -250 250\nintensity = 2e7\n";
    f->lamps = model_lamps_parse(lamps, strlen(lamps), "lamps.ini");
    const char *mats = "[material floor]\nmodel = lambert\nkd = 0.2\n[material box]\nmodel = lambert\nkd = 0.12\n";
    f->mats = model_materials_parse(mats, strlen(mats), "mats.ini");
    if (!f->tracer || !f->cam || !f->lamps || !f->mats) return false;
    return model_resolve_materials(f->scene, f->mats, f->resolved);
}

static void fixture_free(fixture_t *f)
{
    model_tracer_free(f->tracer);
    model_camera_free(f->cam);
    model_lamps_free(f->lamps);
    model_materials_free(f->mats);
    model_scene_free(f->scene);
}

static model_shading_t shading(void)
{
    model_shading_t sh = model_shading_default();
    sh.kc = 1.5;
    sh.Pa = 20;
    sh.nthreads = 2;
    return sh;
}

// Index of the edge joining the two given vertices (0-based), or -1.
static int find_edge(const model_edges_t *E, int a, int b)
{
    for (int i = 0; i < E->nedges; i++)
        if ((E->edges[i].v0 == a && E->edges[i].v1 == b) || (E->edges[i].v0 == b && E->edges[i].v1 == a)) return i;
    return -1;
}

// Does the segment p -> q cross the box (analytic slab test in the box frame)?
static bool box_blocks(model_vec3_t p, model_vec3_t q)
{
    p = rotz(p, -BOX_DEG);
    q = rotz(q, -BOX_DEG);
    double t0 = 1e-6, t1 = 1 - 1e-6;
    double lo[3] = { -HX, -HX, 0 }, hi[3] = { HX, HX, HZ };
    double a[3] = { p.x, p.y, p.z }, d[3] = { q.x - p.x, q.y - p.y, q.z - p.z };
    for (int k = 0; k < 3; k++) {
        if (fabs(d[k]) < 1e-15) {
            if (a[k] <= lo[k] || a[k] >= hi[k]) return false;
            continue;
        }
        double u = (lo[k] - a[k]) / d[k], w = (hi[k] - a[k]) / d[k];
        if (u > w) { double tmp = u; u = w; w = tmp; }
        if (u > t0) t0 = u;
        if (w < t1) t1 = w;
    }
    return t0 < t1 - 1e-9;
}

// Bilinear sample of a rendered image.
static double bilinear(const float *img, int W, int H, double x, double y)
{
    int x0 = (int)floor(x), y0 = (int)floor(y);
    double fx = x - x0, fy = y - y0;
    if (x0 < 0 || y0 < 0 || x0 + 1 >= W || y0 + 1 >= H) return NAN;
    const float *r0 = img + (size_t)y0 * W, *r1 = r0 + W;
    return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
}

TEST(edges_box_topology_and_visibility)
{
    fixture_t f;
    CHECK(fixture(&f));
    if (!f.cam) goto out;
    model_shading_t sh = shading();
    model_edges_t *E = model_edges_predict(f.scene, f.tracer, f.cam, f.lamps, f.resolved, &sh, 1.0);
    CHECK(E != NULL);
    if (!E) goto out;
    // 4 floor boundary edges, 4 box bottom boundary edges, 8 edges between box faces.
    CHECK(E->nedges == 16);
    int nboundary = 0, n90 = 0;
    for (int i = 0; i < E->nedges; i++) {
        if (E->edges[i].face_b < 0) nboundary++;
        else if (fabs(E->edges[i].dihedral_deg - 90) < 1e-6) n90++;
    }
    CHECK(nboundary == 8);
    CHECK(n90 == 8);
    // Faces turned away from the camera: back and left. Every edge made only of
    // such faces has no visible segment; every edge of the floor or the visible
    // box faces that lies in view has one.
    int nhidden = 0;
    for (int i = 0; i < E->nedges; i++) {
        const model_edge_t *e = &E->edges[i];
        bool away_a = e->face_a == F_BACK || e->face_a == F_LEFT;
        bool away_b = e->face_b < 0 || e->face_b == F_BACK || e->face_b == F_LEFT;
        // both faces face away from the camera (checked from the normals too)
        model_vec3_t mid = v3_scale(v3_add(f.scene->vertices[e->v0], f.scene->vertices[e->v1]), 0.5);
        model_vec3_t toc = v3_sub(f.centre, mid);
        bool geo_away_a = v3_dot(f.scene->faces[e->face_a].normal, toc) < 0;
        bool geo_away_b = e->face_b < 0 || v3_dot(f.scene->faces[e->face_b].normal, toc) < 0;
        CHECK(away_a == geo_away_a);
        if (e->face_b >= 0) CHECK(away_b == geo_away_b);
        if (away_a && away_b) {
            CHECK_MSG(e->nsegments == 0, "edge %d (faces %d/%d) faces away but has %d segments", i, e->face_a,
                      e->face_b, e->nsegments);
            nhidden++;
        }
    }
    CHECK(nhidden == 3);   // back-left vertical, back bottom, left bottom
    // The back-top edge is seen (the top face is visible) and the front-top edge too.
    int front_top = find_edge(E, 8, 9), back_top = find_edge(E, 10, 11);
    CHECK(front_top >= 0 && back_top >= 0);
    if (front_top >= 0 && back_top >= 0) {
        CHECK(E->edges[back_top].nsegments == 1);
        const model_edge_t *e = &E->edges[front_top];
        CHECK(e->nsegments == 1);
        CHECK((e->face_a == F_TOP && e->face_b == F_FRONT) || (e->face_a == F_FRONT && e->face_b == F_TOP));
        if (e->nsegments == 1) {
            // Its end points are the projections of the 3D end points (within 1 px).
            double q[4];
            model_vec3_t ends[2] = { f.scene->vertices[e->v0], f.scene->vertices[e->v1] };
            CHECK(model_camera_project(f.cam, ends, 2, q));
            const model_edge_segment_t *s = &e->segments[0];
            CHECK_NEAR(s->q0[0], q[0], 1.0);
            CHECK_NEAR(s->q0[1], q[1], 1.0);
            CHECK_NEAR(s->q1[0], q[2], 1.0);
            CHECK_NEAR(s->q1[1], q[3], 1.0);
            CHECK_REL(s->length_px, hypot(q[2] - q[0], q[3] - q[1]), 0.01);
        }
    }
    // The floor's edges are all in view and unoccluded: one full segment each.
    for (int i = 0; i < E->nedges; i++)
        if (E->edges[i].face_a == F_FLOOR) CHECK(E->edges[i].nsegments == 1);
    // A vertical front edge is partly hidden? No: the front-right vertical edge
    // (vertices 5, 9) is fully visible; its end points match too.
    int fr = find_edge(E, 5, 9);
    CHECK(fr >= 0 && E->edges[fr].nsegments == 1);
    model_edges_free(E);
out:
    fixture_free(&f);
}

TEST(edges_box_lighting_and_contrast)
{
    fixture_t f;
    CHECK(fixture(&f));
    if (!f.cam) goto out;
    model_shading_t sh = shading();
    model_edges_t *E = model_edges_predict(f.scene, f.tracer, f.cam, f.lamps, f.resolved, &sh, 1.0);
    CHECK(E != NULL);
    if (!E) goto out;
    int W = model_camera_width(f.cam), H = model_camera_height(f.cam);
    float *P = malloc(sizeof(float) * W * H);
    int32_t *face = malloc(sizeof(int32_t) * W * H);
    CHECK(model_render(f.tracer, f.cam, f.lamps, f.resolved, &sh, P, face, NULL));

    int nsides = 0, nlit = 0, nunlit = 0, nshadow = 0, ncontrast = 0;
    for (int i = 0; i < E->nedges; i++) {
        const model_edge_t *e = &E->edges[i];
        for (int s = 0; s < e->nsegments; s++) {
            const model_edge_segment_t *g = &e->segments[s];
            double dx = g->q1[0] - g->q0[0], dy = g->q1[1] - g->q0[1], L = hypot(dx, dy);
            double nx = -dy / L, ny = dx / L;
            for (int side = 0; side < 2; side++) {
                int fs = g->face_side[side];
                double sign = side == 0 ? 1 : -1;
                // Geometry: the side's points on the plane of its face, lit when
                // the face turns to the lamp and the box does not block it.
                int nlit_geo = 0, npts = 9;
                double sumP = 0;
                int nP = 0;
                for (int j = 0; j < npts; j++) {
                    double u = (j + 0.5) / npts;
                    double q[2] = { g->q0[0] + u * dx + sign * 2 * nx, g->q0[1] + u * dy + sign * 2 * ny };
                    double r = bilinear(P, W, H, q[0], q[1]);
                    if (isfinite(r)) { sumP += r; nP++; }
                    if (fs < 0) continue;
                    model_vec3_t dir;
                    CHECK(model_camera_unproject(f.cam, q, 1, &dir));
                    const model_face_t *fc = &f.scene->faces[fs];
                    double t = (fc->offset_mm - v3_dot(fc->normal, f.centre)) / v3_dot(fc->normal, dir);
                    model_vec3_t X = v3_add(f.centre, v3_scale(dir, t));
                    bool faces_lamp = v3_dot(fc->normal, v3_sub(f.lamp, X)) > 0;
                    if (faces_lamp && !(fs == F_FLOOR && box_blocks(X, f.lamp))) nlit_geo++;
                    if (faces_lamp && fs == F_FLOOR && box_blocks(X, f.lamp)) nshadow++;
                }
                if (fs < 0) continue;   // background side: nothing to light
                nsides++;
                bool lit_geo = 2 * nlit_geo >= npts;
                bool lit = g->lit_side[side] & 1u;
                CHECK_MSG(lit == lit_geo, "edge %d seg %d side %d (face %d): lit %d, geometry says %d (%d/%d)", i, s,
                          side, fs, lit, lit_geo, nlit_geo, npts);
                if (lit) nlit++; else nunlit++;
                // P per side matches the rendered image at the same points.
                if (nP == npts) {
                    double Pr = sumP / nP;
                    CHECK_MSG(fabs(g->P_side[side] - Pr) <= 0.02 * fmax(Pr, 1) + 0.5,
                              "edge %d side %d: predicted %.2f, rendered %.2f", i, side, g->P_side[side], Pr);
                }
            }
            // Contrast against the render, where both sides are in the image.
            double c_r = 0;
            bool ok = true;
            for (int side = 0; side < 2 && ok; side++) {
                double sum = 0, sign = side == 0 ? 1 : -1;
                for (int j = 0; j < 9; j++) {
                    double u = (j + 0.5) / 9;
                    double r = bilinear(P, W, H, g->q0[0] + u * dx + sign * 2 * nx, g->q0[1] + u * dy + sign * 2 * ny);
                    if (!isfinite(r)) ok = false;
                    sum += r;
                }
                c_r += sign * sum / 9;
            }
            if (ok && fabs(c_r) > 5) {
                ncontrast++;
                CHECK_MSG(fabs(g->contrast - c_r) <= 0.03 * fabs(c_r), "edge %d: contrast %.2f, rendered %.2f", i,
                          g->contrast, c_r);
            }
        }
    }
    CHECK(nsides >= 16);
    CHECK(nlit >= 4);
    CHECK(nunlit >= 2);     // the right face, and the floor in the box's shadow
    CHECK(nshadow > 0);     // some side points lie in the box's cast shadow
    CHECK(ncontrast >= 5);

    // The right-bottom edge: right face self-shadowed, floor beside it in the
    // box's shadow (but for a few points near its far end) — both sides
    // unlit, P close to Pa on both (a lit floor is > 26 DN here).
    int rb = find_edge(E, 5, 6);
    CHECK(rb >= 0);
    if (rb >= 0 && E->edges[rb].nsegments == 1) {
        const model_edge_segment_t *g = &E->edges[rb].segments[0];
        CHECK(g->lit_side[0] == 0 && g->lit_side[1] == 0);
        CHECK_NEAR(g->P_side[0], sh.Pa, 1.5);
        CHECK_NEAR(g->P_side[1], sh.Pa, 1.5);
    }
    // The front-top edge: top and front both lit, contrast = difference of
    // Lambertian terms (known answer within the variation along the edge).
    int ft = find_edge(E, 8, 9);
    if (ft >= 0 && E->edges[ft].nsegments == 1) {
        const model_edge_segment_t *g = &E->edges[ft].segments[0];
        CHECK(g->lit_side[0] == 1 && g->lit_side[1] == 1);
        int top_side = g->face_side[0] == F_TOP ? 0 : 1;
        CHECK(g->face_side[top_side] == F_TOP && g->face_side[1 - top_side] == F_FRONT);
        model_vec3_t m = v3_scale(v3_add(f.scene->vertices[8], f.scene->vertices[9]), 0.5);
        model_vec3_t l = v3_sub(f.lamp, m);
        double d2 = v3_dot(l, l);
        l = v3_unit(l);
        double top = sh.Pa + sh.kc * 2e7 * 0.12 * v3_dot(f.scene->faces[F_TOP].normal, l) / d2;
        double front = sh.Pa + sh.kc * 2e7 * 0.12 * v3_dot(f.scene->faces[F_FRONT].normal, l) / d2;
        CHECK_REL(g->P_side[top_side], top, 0.03);
        CHECK_REL(g->P_side[1 - top_side], front, 0.03);
    }
    free(P);
    free(face);
    model_edges_free(E);
out:
    fixture_free(&f);
}

TEST(edges_feature_angle_and_errors)
{
    // Two coplanar triangles (a split square): their shared edge is skipped
    // at feature angle 1 deg, kept at 0 (dihedral 0 is not > 0 either: skipped).
    const char *text = "1 -50 -50 0\n2 50 -50 0\n3 50 50 0\n4 -50 50 0\nFaces:\n1 2 3.\n1 3 4.\n";
    model_scene_t *s = model_scene_parse_d3d(text, strlen(text), "split.d3d", NULL);
    CHECK(s != NULL);
    if (!s) return;
    model_tracer_t *t = model_tracer_new(s);
    double intr[4] = { 500, 500, 99.5, 99.5 };
    double rt[6] = { M_PI, 0, 0, 0, 0, 400 };   // looking down -z from z = 400
    model_camera_t *cam = model_camera_new("LENSMODEL_PINHOLE", intr, 200, 200, rt);
    const char *mt = "[material default]\nmodel = lambert\nkd = 0.2\n";
    model_materials_t *mats = model_materials_parse(mt, strlen(mt), "m.ini");
    const model_material_t *res[1];
    CHECK(cam && mats && model_resolve_materials(s, mats, res));
    model_shading_t sh = shading();
    model_edges_t *E = model_edges_predict(s, t, cam, NULL, res, &sh, 1.0);
    CHECK(E && E->nedges == 4);   // the diagonal is gone
    if (E)
        for (int i = 0; i < E->nedges; i++) {
            CHECK(E->edges[i].face_b < 0);
            CHECK(E->edges[i].nsegments == 1);
            if (E->edges[i].nsegments == 1) {
                // the square spans 100 mm at 400 mm: 125 px
                CHECK_NEAR(E->edges[i].segments[0].length_px, 125, 0.5);
                // one side is the square (face 0 or 1), the other the background
                const model_edge_segment_t *g = &E->edges[i].segments[0];
                CHECK((g->face_side[0] < 0) != (g->face_side[1] < 0));
                CHECK_NEAR(fmin(g->P_side[0], g->P_side[1]), sh.Pa, 1e-9);
            }
        }
    model_edges_free(E);
    model_error_clear();
    CHECK(model_edges_predict(s, t, cam, NULL, res, &sh, 200) == NULL);
    CHECK_CONTAINS(model_last_error(), "feature angle");
    model_edges_free(NULL);
    model_materials_free(mats);
    model_camera_free(cam);
    model_tracer_free(t);
    model_scene_free(s);
}

TEST(edges_weld_duplicate_vertices)
{
    // A ridge of two triangles that repeat the shared vertices under other
    // numbers: the edge is still found as shared, with the dihedral of the normals.
    const char *text = "1 0 0 0\n2 100 0 0\n3 50 50 30\n4 100 0 0\n5 0 0 0\n6 50 -50 30\n"
                       "Faces:\n1 2 3.\n4 5 6.\n";
    model_scene_t *s = model_scene_parse_d3d(text, strlen(text), "ridge.d3d", NULL);
    CHECK(s != NULL);
    if (!s) return;
    model_tracer_t *t = model_tracer_new(s);
    double intr[4] = { 500, 500, 99.5, 99.5 };
    double rt[6] = { M_PI, 0, 0, -50, 0, 400 };   // looking down from (50, 0, 400)
    model_camera_t *cam = model_camera_new("LENSMODEL_PINHOLE", intr, 200, 200, rt);
    const char *mt = "[material default]\nmodel = lambert\nkd = 0.2\n";
    model_materials_t *mats = model_materials_parse(mt, strlen(mt), "m.ini");
    const model_material_t *res[1];
    CHECK(cam && mats && model_resolve_materials(s, mats, res));
    model_shading_t sh = shading();
    model_edges_t *E = model_edges_predict(s, t, cam, NULL, res, &sh, 1.0);
    CHECK(E && E->nedges == 5);
    int nshared = 0;
    double want = acos(v3_dot(s->faces[0].normal, s->faces[1].normal)) * 180 / M_PI;
    for (int i = 0; E && i < E->nedges; i++)
        if (E->edges[i].face_b >= 0) {
            nshared++;
            CHECK_NEAR(E->edges[i].dihedral_deg, want, 1e-9);
            CHECK(E->edges[i].nsegments == 1);   // seen from above along its whole length
            if (E->edges[i].nsegments == 1) CHECK_NEAR(E->edges[i].segments[0].length_px, 500 * 100 / 400.0, 0.5);
        }
    CHECK(nshared == 1);
    CHECK(want > 60 && want < 90);
    // Above the feature angle the ridge is skipped.
    model_edges_free(E);
    E = model_edges_predict(s, t, cam, NULL, res, &sh, want + 1);
    CHECK(E && E->nedges == 4);
    model_edges_free(E);
    model_materials_free(mats);
    model_camera_free(cam);
    model_tracer_free(t);
    model_scene_free(s);
}
