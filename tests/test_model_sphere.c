// tests/test_model_sphere.c — the exact sphere primitive: D3D '@sphere' (model/scene/scene.c),
// ray casting, shadows and highlights (model/render/trace.c, model/render/shade.c) against
// analytic answers.
#define _GNU_SOURCE
#include <glib.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"
#include "tests/fixtures.h"
#include "tests/test.h"

static model_scene_t *sph_scene(const char *d3d)
{
    model_scene_t *s = model_scene_parse_d3d(d3d, strlen(d3d), "sph.d3d", NULL);
    if (!s) fprintf(stderr, "  scene: %s\n", model_last_error());
    return s;
}

// The pinhole camera looking at a target: fx_pinhole_camera() (tests/fixtures.h).

// ---------------------------------------------------------------------------
// Scenes

TEST(sphere_d3d_parse_and_rotate)
{
    const char *d3d =
        "1 -100 -100 0\n2 100 -100 0\n3 100 100 0\n4 -100 100 0\n"
        "Faces:\n@material plate\n1 2 3 4.\n"
        "@material chrome\n"
        "@sphere 60 0 40 25   # the ball\n"
        "@sphere -1.5e1 2 3.25 0.5\n";
    model_scene_t *s = sph_scene(d3d);
    CHECK(s);
    if (!s) return;
    CHECK(s->nfaces == 1);
    CHECK(s->nspheres == 2);
    if (s->nspheres == 2) {
        CHECK(s->spheres[0].centre_mm.x == 60 && s->spheres[0].centre_mm.y == 0 &&
              s->spheres[0].centre_mm.z == 40);
        CHECK(s->spheres[0].radius_mm == 25);
        CHECK(s->spheres[0].line == 9);
        CHECK(s->spheres[1].line == 10);
        CHECK(s->spheres[1].centre_mm.x == -15 && s->spheres[1].radius_mm == 0.5);
        CHECK(strcmp(s->material_names[s->spheres[0].material], "chrome") == 0);
        CHECK(strcmp(s->material_names[s->faces[0].material], "plate") == 0);
    }
    // Rotation about z: centres move on circles, radius / material / line kept.
    double angles[3] = { 90, 30, -137.5 };
    for (int a = 0; a < 3; a++) {
        model_scene_t *r = model_scene_rotated_z(s, angles[a]);
        CHECK(r);
        if (!r) continue;
        CHECK(r->nspheres == 2);
        double th = angles[a] * M_PI / 180;
        for (int k = 0; k < 2 && r->nspheres == 2; k++) {
            model_vec3_t c = s->spheres[k].centre_mm, q = r->spheres[k].centre_mm;
            CHECK_NEAR(q.x, cos(th) * c.x - sin(th) * c.y, 1e-12);
            CHECK_NEAR(q.y, sin(th) * c.x + cos(th) * c.y, 1e-12);
            CHECK(q.z == c.z);
            CHECK(r->spheres[k].radius_mm == s->spheres[k].radius_mm);
            CHECK(r->spheres[k].material == s->spheres[k].material);
            CHECK(r->spheres[k].line == s->spheres[k].line);
        }
        if (a == 0) {   // exact at 90 deg
            CHECK(r->spheres[0].centre_mm.x == 0 && r->spheres[0].centre_mm.y == 60);
            // Round trip: back by -90 gives the original centre exactly.
            model_scene_t *b = model_scene_rotated_z(r, -90);
            CHECK(b && b->nspheres == 2 && b->spheres[0].centre_mm.x == 60 &&
                  b->spheres[0].centre_mm.y == 0);
            model_scene_free(b);
        }
        model_scene_free(r);
    }
    CHECK(s->spheres[0].centre_mm.x == 60);   // the original is untouched
    model_scene_free(s);

    // Spheres alone make a valid scene; the default material applies.
    s = sph_scene("Faces:\n@sphere 0 0 0 1\n");
    CHECK(s && s->nfaces == 0 && s->nspheres == 1 &&
          strcmp(s->material_names[s->spheres[0].material], "default") == 0);
    model_scene_free(s);
    // OBJ has no spheres.
    const char *obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    s = model_scene_parse_obj(obj, strlen(obj), "t.obj", NULL);
    CHECK(s && s->nspheres == 0);
    model_scene_free(s);
}

static void expect_error(const char *d3d, const char *msg, int line)
{
    model_error_clear();
    model_scene_t *s = model_scene_parse_d3d(d3d, strlen(d3d), "bad.d3d", NULL);
    if (s) test_fail(__FILE__, line, "parsed, expected \"%s\"", msg);
    model_scene_free(s);
    if (!strstr(model_last_error(), msg))
        test_fail(__FILE__, line, "expected \"%s\" in \"%s\"", msg, model_last_error());
}

TEST(sphere_d3d_errors)
{
#define TRI "1 0 0 0\n2 1 0 0\n3 0 1 0\nFaces:\n1 2 3.\n"
    expect_error(TRI "@sphere 0 0 0 0\n", "bad.d3d:6: @sphere: radius 0 mm must be > 0", __LINE__);
    expect_error(TRI "@sphere 0 0 0 -2\n", "bad.d3d:6: @sphere: radius -2 mm must be > 0", __LINE__);
    expect_error(TRI "@sphere 0 inf 0 1\n", "bad.d3d:6: @sphere: centre y 'inf' is not a finite number",
                 __LINE__);
    expect_error(TRI "@sphere 0 0 0 nan\n", "bad.d3d:6: @sphere: radius 'nan' is not a finite number",
                 __LINE__);
    expect_error(TRI "@sphere 0 0 1e999 1\n", "bad.d3d:6: @sphere: centre z '1e999' is not a finite",
                 __LINE__);
    expect_error(TRI "@sphere 0 0 x 1\n", "bad.d3d:6: @sphere: centre z 'x' does not parse", __LINE__);
    expect_error(TRI "\n@sphere 0 0 0\n", "bad.d3d:7: '@sphere' takes 4 numbers (@sphere cx cy cz radius, "
                 "in mm), got 3", __LINE__);
    expect_error(TRI "@sphere 0 0 0 1 2\n", "bad.d3d:6: '@sphere' takes 4 numbers", __LINE__);
    expect_error(TRI "@sphere 1e200 0 0 1\n", "bad.d3d:6: @sphere: coordinates up to 1e+200 are too large",
                 __LINE__);
    expect_error("@sphere 0 0 0 1\n" TRI, "bad.d3d:1: @sphere belongs after the 'Faces:' line", __LINE__);
    expect_error(TRI "1 2\n@sphere 0 0 0 1\n3.\n", "bad.d3d:7: face 2 (line 6) is not ended by '.' before "
                 "@sphere", __LINE__);
    expect_error(TRI "1 2 3 @sphere 0 0 0 1\n", "bad.d3d:6: @sphere must be on a line of its own", __LINE__);
    expect_error(TRI "@spheres 0 0 0 1\n", "bad.d3d:6: unknown directive '@spheres'", __LINE__);
    expect_error("1 0 0 0\nFaces:\n", "no faces after 'Faces:'", __LINE__);
#undef TRI
}

// ---------------------------------------------------------------------------
// Ray casting

TEST(sphere_ray_hits_analytic_point)
{
    // A plate below the sphere (so rays that miss the sphere hit something)
    // and a second small sphere.
    model_scene_t *s = sph_scene("1 -300 -300 -10\n2 300 -300 -10\n3 300 300 -10\n4 -300 300 -10\n"
                                 "Faces:\n@material plate\n1 2 3 4.\n@material ball\n"
                                 "@sphere 60 -20 40 25\n@sphere -120 80 5 3\n");
    CHECK(s);
    if (!s) return;
    model_tracer_t *t = model_tracer_new(s);
    CHECK(t);
    if (!t) {
        fprintf(stderr, "  tracer: %s\n", model_last_error());
        model_scene_free(s);
        return;
    }
    model_vec3_t c = s->spheres[0].centre_mm;
    double r = s->spheres[0].radius_mm;
    int ball = model_scene_material_index(s, "ball");
    double worst_p = 0, worst_n = 0;
    int bad_face = 0;
    model_rng_t rng = model_rng(7, 1);
    for (int i = 0; i < 2000; i++) {
        // A point on the sphere, and a ray arriving at it from outside.
        double ct = 2 * model_rng_uniform(&rng) - 1, ph = 2 * M_PI * model_rng_uniform(&rng);
        model_vec3_t u = v3(sqrt(1 - ct * ct) * cos(ph), sqrt(1 - ct * ct) * sin(ph), ct);
        model_vec3_t d;
        do {
            d = v3_unit(v3(model_rng_gauss(&rng), model_rng_gauss(&rng), model_rng_gauss(&rng)));
        } while (v3_dot(d, u) > -0.05);
        double dist = 100 + 900 * model_rng_uniform(&rng);
        model_vec3_t p = v3_add(c, v3_scale(u, r));
        model_vec3_t o = v3_sub(p, v3_scale(d, dist));
        // The plate might be in between: skip those rays.
        if (o.z < -10) continue;
        model_pixel_info_t pi;
        model_tracer_cast(t, o, d, &pi);
        if (pi.face != s->nfaces + 0 || pi.material != ball) {
            bad_face++;
            continue;
        }
        worst_p = fmax(worst_p, v3_norm(v3_sub(pi.p_mm, p)));
        worst_n = fmax(worst_n, v3_norm(v3_sub(pi.n, u)));
        CHECK_NEAR(pi.range_mm, dist, 1e-9);
        CHECK_NEAR(v3_norm(v3_sub(pi.v, v3_scale(d, -1))), 0, 1e-15);
    }
    CHECK_MSG(bad_face == 0, "%d rays missed the sphere they aim at", bad_face);
    CHECK_MSG(worst_p <= 1e-9, "hit point off the analytic point by %.3g mm", worst_p);
    CHECK_MSG(worst_n <= 1e-9, "normal off the analytic normal by %.3g", worst_n);

    // Just past the silhouette: the ray misses the sphere and hits the plate.
    model_vec3_t o = v3(c.x - 500, c.y, c.z + r + 1e-3);
    model_pixel_info_t pi;
    model_tracer_cast(t, o, v3(1, 0, 0), &pi);
    CHECK(pi.face == -1);
    model_tracer_cast(t, v3(c.x - 500, c.y, c.z + r - 1e-3), v3(1, 0, 0), &pi);
    CHECK(pi.face == s->nfaces);
    CHECK_NEAR(pi.p_mm.x, c.x - sqrt(r * r - (r - 1e-3) * (r - 1e-3)), 1e-9);
    // From inside: the far side, normal turned toward the origin.
    model_tracer_cast(t, c, v3(0, 0, 1), &pi);
    CHECK(pi.face == s->nfaces);
    CHECK_NEAR(pi.p_mm.z, c.z + r, 1e-12);
    CHECK_NEAR(pi.n.z, -1, 1e-12);
    // The second sphere: face nfaces + 1.
    model_tracer_cast(t, v3(-120, 80, 100), v3(0, 0, -1), &pi);
    CHECK(pi.face == s->nfaces + 1);
    CHECK_NEAR(pi.p_mm.z, 8, 1e-12);
    CHECK_NEAR(pi.n.z, 1, 1e-15);
    // The plate next to the sphere.
    model_tracer_cast(t, v3(200, 200, 100), v3(0, 0, -1), &pi);
    CHECK(pi.face == 0);

    // Packets answer as single rays do (spheres, plate and misses mixed).
    model_vec3_t po = v3(-400, -350, 300), dirs[MODEL_TRACER_PACKET];
    for (int k = 0; k < MODEL_TRACER_PACKET; k++) {
        model_vec3_t target = v3(c.x + (k % 4 - 1.5) * 20, c.y + (k / 4 - 1.5) * 20, c.z);
        if (k == 15) target = v3(-120, 80, 5);
        if (k == 14) target = v3(600, 600, 600);
        dirs[k] = v3_unit(v3_sub(target, po));
    }
    model_pixel_info_t pk[MODEL_TRACER_PACKET], one;
    int nhit = model_tracer_cast_packet(t, po, dirs, MODEL_TRACER_PACKET, pk);
    int nhit1 = 0, nsph = 0;
    for (int k = 0; k < MODEL_TRACER_PACKET; k++) {
        model_tracer_cast(t, po, dirs[k], &one);
        nhit1 += one.face >= 0;
        nsph += one.face >= s->nfaces;
        CHECK(pk[k].face == one.face);
        if (one.face >= 0) CHECK_NEAR(v3_norm(v3_sub(pk[k].p_mm, one.p_mm)), 0, 1e-12);
    }
    CHECK(nhit == nhit1);
    CHECK_MSG(nsph >= 8 && pk[15].face == s->nfaces + 1 && pk[14].face == -1,
              "%d sphere hits, lane 15 face %d, lane 14 face %d", nsph, pk[15].face, pk[14].face);
    model_tracer_free(t);
    model_scene_free(s);
}

// ---------------------------------------------------------------------------
// Shadows

TEST(sphere_shadow_on_plane_is_the_analytic_conic)
{
    model_vec3_t c = v3(10, -5, 40), L = v3(150, 80, 420);
    double r = 25;
    char d3d[512];
    snprintf(d3d, sizeof d3d, "1 -300 -300 0\n2 300 -300 0\n3 300 300 0\n4 -300 300 0\n"
             "Faces:\n@material plate\n1 2 3 4.\n@material ball\n@sphere %.17g %.17g %.17g %.17g\n",
             c.x, c.y, c.z, r);
    model_scene_t *s = sph_scene(d3d);
    model_tracer_t *t = s ? model_tracer_new(s) : NULL;
    CHECK(t);
    if (!t) {
        model_scene_free(s);
        return;
    }
    // A plane point x is in the shadow when the direction from the lamp to x
    // lies in the cone of half-angle asin(r / |c - L|) around c - L: the
    // shadow is that cone's section by the plane (an ellipse here).
    model_vec3_t axis = v3_unit(v3_sub(c, L));
    double half = asin(r / v3_norm(v3_sub(c, L)));
    double eps = model_tracer_epsilon_mm(t);
    int n = 0, nshadow = 0, wrong = 0, wrong_pk = 0;
    model_shadow_packet_t sp;
    memset(&sp, 0, sizeof sp);
    int lane = 0;
    bool expect[MODEL_TRACER_PACKET];
    for (int iy = 0; iy < 160; iy++)
        for (int ix = 0; ix < 160; ix++) {
            model_vec3_t x = v3(-100 + ix * 0.75, -100 + iy * 0.75, 0);
            double ang = acos(fmin(1, v3_dot(v3_unit(v3_sub(x, L)), axis)));
            if (fabs(ang - half) < 1e-5) continue;   // on the border
            bool in = ang < half;
            n++;
            nshadow += in;
            bool vis = model_tracer_visible_from(t, x, v3(0, 0, 1), L);
            if (vis == in) wrong++;
            // The same through a shadow packet (Embree's float layout).
            model_vec3_t o = v3(x.x, x.y, x.z + eps), dd = v3_sub(L, o);
            sp.org_x[lane] = (float)o.x;
            sp.org_y[lane] = (float)o.y;
            sp.org_z[lane] = (float)o.z;
            sp.dir_x[lane] = (float)dd.x;
            sp.dir_y[lane] = (float)dd.y;
            sp.dir_z[lane] = (float)dd.z;
            sp.tfar[lane] = 1.0f - 1e-6f;
            sp.active[lane] = 1;
            expect[lane] = !in;
            if (++lane == MODEL_TRACER_PACKET) {
                uint8_t vis16[MODEL_TRACER_PACKET];
                model_tracer_visible_packet(t, &sp, vis16);
                for (int k = 0; k < lane; k++) wrong_pk += (vis16[k] != 0) != expect[k];
                lane = 0;
            }
        }
    CHECK_MSG(wrong == 0, "%d of %d plane points disagree with the analytic shadow", wrong, n);
    CHECK_MSG(wrong_pk == 0, "%d packet lanes disagree with the analytic shadow", wrong_pk);
    CHECK_MSG(nshadow > 1000 && nshadow < n - 1000, "%d of %d points in the shadow", nshadow, n);
    model_tracer_free(t);
    model_scene_free(s);
}

// ---------------------------------------------------------------------------
// Highlights

// The mirror point of a sphere (c, r) for camera C and lamp L: the normal
// bisects the directions to C and L. Fixed-point iteration on the normal.
static model_vec3_t mirror_point(model_vec3_t c, double r, model_vec3_t C, model_vec3_t L, double *resid)
{
    model_vec3_t n = v3_unit(v3_add(v3_unit(v3_sub(C, c)), v3_unit(v3_sub(L, c))));
    for (int i = 0; i < 500; i++) {
        model_vec3_t p = v3_add(c, v3_scale(n, r));
        n = v3_unit(v3_add(v3_unit(v3_sub(C, p)), v3_unit(v3_sub(L, p))));
    }
    model_vec3_t p = v3_add(c, v3_scale(n, r));
    model_vec3_t h = v3_unit(v3_add(v3_unit(v3_sub(C, p)), v3_unit(v3_sub(L, p))));
    *resid = v3_norm(v3_sub(h, n));
    return p;
}

TEST(sphere_highlight_at_the_mirror_point)
{
    model_vec3_t c = v3(20, 10, 40), C = v3(420, -380, 330);
    double r = 25;
    char d3d[256];
    snprintf(d3d, sizeof d3d, "Faces:\n@material chrome\n@sphere %g %g %g %g\n", c.x, c.y, c.z, r);
    model_scene_t *s = sph_scene(d3d);
    const char *mt = "[material chrome]\nmodel = ggx\nkd = 0\nks = 1\nalpha = 0.02\nF0 = 0.9\n";
    model_materials_t *m = model_materials_parse(mt, strlen(mt), "m.ini");
    int W = 320, H = 320;
    model_camera_t *cam = fx_pinhole_camera(W, H, 3000, C, c);
    model_tracer_t *t = s ? model_tracer_new(s) : NULL;
    const model_material_t *mats[1] = { NULL };
    CHECK(s && m && cam && t && model_resolve_materials(s, m, mats));
    float *P = malloc((size_t)W * H * sizeof *P);
    int32_t *face = malloc((size_t)W * H * sizeof *face);
    static const model_vec3_t lamp_pos[3] = { { -200, -400, 500 }, { 500, 100, 300 }, { 300, -600, -50 } };
    for (int li = 0; li < 3 && t && mats[0] && P && face; li++) {
        model_vec3_t L = lamp_pos[li];
        char lt[160];
        snprintf(lt, sizeof lt, "[lamp a]\nposition_mm = %g %g %g\nintensity = 1e6\n", L.x, L.y, L.z);
        model_lamps_t *lamps = model_lamps_parse(lt, strlen(lt), "l.ini");
        CHECK(lamps);
        if (!lamps) break;
        model_shading_t sh = model_shading_default();
        sh.nthreads = 2;
        CHECK(model_render(t, cam, lamps, mats, &sh, P, face, NULL));
        double resid;
        model_vec3_t pm = mirror_point(c, r, C, L, &resid);
        CHECK(resid < 1e-12);
        double q[2];
        CHECK(model_camera_project(cam, &pm, 1, q));
        // The brightest pixel, then the centroid of the lobe (values above a
        // tenth of the peak within 8 px).
        int best = 0;
        for (int i = 1; i < W * H; i++)
            if (P[i] > P[best]) best = i;
        int bx = best % W, by = best / W;
        double sw = 0, sx = 0, sy = 0, npx = 0;
        for (int y = by - 8; y <= by + 8; y++)
            for (int x = bx - 8; x <= bx + 8; x++) {
                if (x < 0 || y < 0 || x >= W || y >= H) continue;
                double w = P[(size_t)y * W + x] - 0.1 * P[best];
                if (w <= 0) continue;
                sw += w;
                sx += w * x;
                sy += w * y;
                npx++;
            }
        double gx = sx / sw, gy = sy / sw;
        double err = hypot(gx - q[0], gy - q[1]);
        printf("  lamp %d: mirror point (%.3f %.3f %.3f) at (%.3f, %.3f) px; highlight centroid "
               "(%.3f, %.3f), %g px, error %.3f px\n",
               li, pm.x, pm.y, pm.z, q[0], q[1], gx, gy, npx, err);
        CHECK_MSG(err <= 0.5, "lamp %d: highlight %.3f px from the mirror point", li, err);
        CHECK(npx >= 3 && npx < 200);   // a small spot
        CHECK(face[best] == s->nfaces);
        CHECK(face[0] == -1);
        model_lamps_free(lamps);
    }
    free(P);
    free(face);
    model_tracer_free(t);
    model_camera_free(cam);
    model_materials_free(m);
    model_scene_free(s);
}

// Sphere ids in the face images do not upset the edge query (edges come from
// the faces only; a sphere in front of an edge hides it).
TEST(sphere_face_ids_in_edges_and_render)
{
    model_scene_t *s = sph_scene("1 -100 -100 0\n2 100 -100 0\n3 100 100 0\n4 -100 100 0\n"
                                 "Faces:\n@material plate\n1 2 3 4.\n@material ball\n@sphere 0 0 30 25\n");
    const char *mt = "[material plate]\nmodel = lambert\nkd = 0.2\n"
                     "[material ball]\nmodel = lambert\nkd = 0.3\n";
    const char *lt = "[lamp a]\nposition_mm = 100 200 500\nintensity = 1e6\n";
    model_materials_t *m = model_materials_parse(mt, strlen(mt), "m.ini");
    model_lamps_t *lamps = model_lamps_parse(lt, strlen(lt), "l.ini");
    model_camera_t *cam = fx_pinhole_camera(200, 160, 300, v3(300, -200, 400), v3(0, 0, 0));
    model_tracer_t *t = s ? model_tracer_new(s) : NULL;
    const model_material_t *mats[2] = { NULL, NULL };
    CHECK(s && m && lamps && cam && t && model_resolve_materials(s, m, mats));
    if (!t || !mats[1] || !cam || !lamps) goto done;
    model_shading_t sh = model_shading_default();
    sh.nthreads = 2;
    float P[200 * 160];
    int32_t face[200 * 160];
    CHECK(model_render(t, cam, lamps, mats, &sh, P, face, NULL));
    int nsph = 0, bad = 0;
    for (int i = 0; i < 200 * 160; i++) {
        nsph += face[i] == 1;
        bad += face[i] < -1 || face[i] > 1;
    }
    CHECK(nsph > 500 && bad == 0);
    // A Lambertian sphere pixel: P = kd I (n.l) / d^2 at its point (a lit
    // point that the camera sees, projected to its pixel and rounded).
    model_vec3_t u = v3_unit(v3_add(v3_unit(v3(100, 200, 470)), v3_unit(v3(300, -200, 370))));
    model_vec3_t pt = v3_add(v3(0, 0, 30), v3_scale(u, 25));
    double q[2];
    CHECK(model_camera_project(cam, &pt, 1, q));
    q[0] = round(q[0]);
    q[1] = round(q[1]);
    model_pixel_info_t pi;
    model_lamp_sample_t ls;
    CHECK(model_pixel_info(t, cam, lamps, q, 1, &pi, &ls, 1));
    CHECK(pi.face == 1);
    model_vec3_t nn = v3_unit(v3_sub(pi.p_mm, v3(0, 0, 30)));
    CHECK_NEAR(v3_norm(v3_sub(pi.n, nn)), 0, 1e-12);
    CHECK(ls.V == 1);
    double expect = 0.3 * 1e6 * v3_dot(nn, ls.l) / (ls.d_mm * ls.d_mm);
    CHECK_REL(P[(int)q[1] * 200 + (int)q[0]], expect, 1e-5);
    model_edges_t *e = model_edges_predict(s, t, cam, lamps, mats, &sh, 1.0);
    CHECK(e && e->nedges == 4);
    for (int i = 0; e && i < e->nedges; i++)
        for (int k = 0; k < e->edges[i].nsegments; k++)
            for (int j = 0; j < 2; j++) CHECK(e->edges[i].segments[k].face_side[j] <= 1);
    model_edges_free(e);
done:
    model_tracer_free(t);
    model_camera_free(cam);
    model_lamps_free(lamps);
    model_materials_free(m);
    model_scene_free(s);
}

// ---------------------------------------------------------------------------
// The virtual rig's mirror sphere sample (examples/virtual-truth.ini)

#include "rig/rig.h"

TEST(sphere_virtual_rig_mirror_sphere_highlights)
{
    char truth[1024], campath[1024];
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", test_srcdir());
    snprintf(campath, sizeof campath, "%s/examples/camera.cameramodel", test_srcdir());
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.sample = "mirror_sphere";
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, truth, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open: %d %s", rc, model_last_error());
    model_camera_t *cam = model_camera_load(campath);
    model_ini_t *ini = model_ini_load(truth);
    model_lamps_t *lamps = ini ? model_lamps_from_ini(ini) : NULL;
    int W = cam ? model_camera_width(cam) : 0, H = cam ? model_camera_height(cam) : 0;
    float *E = malloc((size_t)(W > 0 ? W : 1) * (H > 0 ? H : 1) * sizeof *E);
    CHECK(cam && lamps && lamps->n == 5 && E);
    if (rc || !cam || !lamps || !E) goto done;
    model_vec3_t C = model_camera_centre_world(cam);
    double worst = 0;
    for (int a = 0; a < 2; a++) {
        double ang = a ? 90 : 0, th = ang * M_PI / 180;
        model_vec3_t c = v3(60 * cos(th), 60 * sin(th), 40);   // the sample's facts
        for (int i = 0; i < lamps->n; i++) {
            // 5 us: the highlights (the lamps' spheres seen in chrome) stay below full scale.
            rc = rig_virtual_expected(v, ang, 1u << i, 5, 0, "Mono12", W, H, E);
            CHECK_MSG(rc == 0, "expected: %d %s", rc, model_last_error());
            if (rc) goto done;
            double resid, q[2];
            model_vec3_t pm = mirror_point(c, 25, C, lamps->lamps[i].position_mm, &resid);
            CHECK(model_camera_project(cam, &pm, 1, q));
            int bx = (int)lround(q[0]), by = (int)lround(q[1]), mx = bx, my = by;
            float best = -1, far_max = 0;
            for (int y = 0; y < H; y++)
                for (int x = 0; x < W; x++) {
                    float e = E[(size_t)y * W + x];
                    if (abs(x - bx) <= 6 && abs(y - by) <= 6) {
                        if (e > best) {
                            best = e;
                            mx = x;
                            my = y;
                        }
                    } else if (e > far_max) {
                        far_max = e;
                    }
                }
            double sw = 0, sx = 0, sy = 0;
            for (int y = my - 6; y <= my + 6; y++)
                for (int x = mx - 6; x <= mx + 6; x++) {
                    if (x < 0 || y < 0 || x >= W || y >= H) continue;
                    double w = E[(size_t)y * W + x] - 64 - 0.2 * (best - 64);
                    if (w > 0) {
                        sw += w;
                        sx += w * x;
                        sy += w * y;
                    }
                }
            double err = sw > 0 ? hypot(sx / sw - q[0], sy / sw - q[1]) : INFINITY;
            worst = fmax(worst, err);
            printf("  angle %g lamp %s: peak %.0f DN, centroid %.2f px from the mirror point\n", ang,
                   lamps->lamps[i].name, best, err);
            CHECK_MSG(best > 64 + 50 && best < 4000, "angle %g lamp %d: highlight peak %.0f DN", ang, i, best);
            CHECK_MSG(far_max < 64 + 0.5 * (best - 64), "angle %g lamp %d: %.0f DN away from the highlight "
                      "(peak %.0f)", ang, i, far_max, best);
            CHECK_MSG(err < 1.0, "angle %g lamp %d: highlight centroid %.2f px from the mirror point", ang, i, err);
        }
    }
    printf("  mirror sphere on the virtual rig: %d highlights within %.2f px of the mirror points\n", 2 * lamps->n, worst);
done:
    free(E);
    model_lamps_free(lamps);
    model_ini_free(ini);
    model_camera_free(cam);
    rig_virtual_close(v);
}

// The sample's facts must agree with its scene's '@sphere'.
TEST(sphere_virtual_rig_facts_checked)
{
    char truth[1024];
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", test_srcdir());
    char *text = model_read_file(truth, NULL);
    CHECK(text);
    if (!text) return;
    // Absolute paths (the copy lives in the test's directory), then a wrong radius.
    GString *g = g_string_new(text);
    char dir[2048], *src = realpath(test_srcdir(), NULL);
    CHECK(src);
    snprintf(dir, sizeof dir, "= %s/examples/samples/", src ? src : ".");
    g_string_replace(g, "= samples/", dir, 0);
    snprintf(dir, sizeof dir, "= %s/examples/t_stiffener.d3d", src ? src : ".");
    g_string_replace(g, "= t_stiffener.d3d", dir, 0);
    snprintf(dir, sizeof dir, "= %s/examples/camera.cameramodel", src ? src : ".");
    free(src);
    g_string_replace(g, "= camera.cameramodel", dir, 0);
    char *good = g_strdup(g->str);
    g_string_replace(g, "sphere_radius_mm = 25", "sphere_radius_mm = 24", 0);
    const char *bad_path = test_write("bad-truth.ini", g->str);
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, bad_path, &o);
    CHECK(rc != 0 && !v);
    CHECK_CONTAINS(model_last_error(), "bad-truth.ini:");
    CHECK_CONTAINS(model_last_error(), "sample 'mirror_sphere': its scene");
    CHECK_CONTAINS(model_last_error(), "has no sphere of centre (60, 0, 40) mm and radius 24 mm");
    rig_virtual_close(v);
    // The facts on another kind are refused.
    g_string_assign(g, good);
    g_string_replace(g, "kind = material_coupon\nscene = " , "kind = material_coupon\nsphere_radius_mm = 3\nscene = ", 1);
    bad_path = test_write("bad-truth2.ini", g->str);
    v = NULL;
    rc = rig_virtual_open(&v, bad_path, &o);
    CHECK(rc != 0 && !v);
    CHECK_CONTAINS(model_last_error(), "sphere_radius_mm is a key of mirror spheres, not of kind material_coupon");
    rig_virtual_close(v);
    g_free(good);
    g_string_free(g, TRUE);
    free(text);
}
