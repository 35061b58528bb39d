// tests/test_model_render.c — ray casting (model/render/trace.c) and grey values /
// rendering (model/render/shade.c) against analytic answers.
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"
#include "tests/fixtures.h"
#include "tests/test.h"

// ---------------------------------------------------------------------------
// Helpers (the scene, camera and lamp fixtures are in tests/fixtures.h)

// Segment a -> b meets the box [-50,50]^2 x [0,80] (slab test, open at a).
static bool segment_hits_box(model_vec3_t a, model_vec3_t b)
{
    double lo[3] = { -50, -50, 0 }, hi[3] = { 50, 50, 80 };
    double o[3] = { a.x, a.y, a.z }, d[3] = { b.x - a.x, b.y - a.y, b.z - a.z };
    double s0 = 1e-9, s1 = 1;
    for (int k = 0; k < 3; k++) {
        if (d[k] == 0) {
            if (o[k] < lo[k] || o[k] > hi[k]) return false;
            continue;
        }
        double u = (lo[k] - o[k]) / d[k], v = (hi[k] - o[k]) / d[k];
        if (u > v) { double t = u; u = v; v = t; }
        if (u > s0) s0 = u;
        if (v < s1) s1 = v;
        if (s0 > s1) return false;
    }
    return true;
}

// ---------------------------------------------------------------------------
// (a) Lambertian plane under one point lamp: every pixel analytic to 1e-6.

TEST(render_lambert_plane_every_pixel)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(5000, NULL, NULL),
                        "[material plane]\nmodel = lambert\nkd = 0.2\n",
                        "[lamp a]\nposition_mm = 30 -20 400\nintensity = 1e6\n",
                        160, 120, 150, v3(100, -300, 500), v3(0, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int W = ph.W, H = ph.H;
    float *P = malloc(sizeof(float) * W * H), *g = malloc(sizeof(float) * W * H);
    int32_t *face = malloc(sizeof(int32_t) * W * H);
    uint8_t *lit = malloc((size_t)W * H);
    for (int i = 0; i < W * H; i++) g[i] = (float)(1 + 0.1 * sin(0.37 * i));
    model_shading_t sh = model_shading_default();
    sh.kc = 2.5;
    sh.Pa = 12;
    sh.gain_map = g;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P, face, lit));
    int bad = 0, nface = 0;
    double worst = 0;
    model_vec3_t L = l->lamps[0].position_mm;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int i = y * W + x;
            model_vec3_t d = fx_pinhole_ray(&ph, x, y);
            double tt = -ph.C.z / d.z;
            model_vec3_t p = v3_add(ph.C, v3_scale(d, tt));
            model_vec3_t dl = v3_sub(L, p);
            double dist = v3_norm(dl), cosi = dl.z / dist;
            double expect = sh.Pa + sh.kc * g[i] * 0.2 * 1e6 * cosi / (dist * dist);
            double rel = fabs(P[i] - expect) / expect;
            if (rel > worst) worst = rel;
            if (rel > 1e-6) bad++;
            nface += face[i] == 0 && lit[i] == 1;
        }
    CHECK_MSG(bad == 0, "%d pixels off by more than 1e-6 relative (worst %.3g)", bad, worst);
    CHECK(nface == W * H);
    free(P);
    free(g);
    free(face);
    free(lit);
done:
    fx_render_close(&F);
}

// (b) inverse square law: the point under the lamp at heights h and 2h.

TEST(render_inverse_square_law)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(5000, NULL, NULL),
                        "[material plane]\nmodel = lambert\nkd = 0.1\n",
                        "[lamp a]\nposition_mm = 10 20 300\nintensity = 5e5\n",
                        64, 48, 60, v3(200, -100, 600), v3(0, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    model_vec3_t ground = v3(10, 20, 0);
    double q[2];
    CHECK(model_camera_project(ph.cam, &ground, 1, q));
    double S[2];
    for (int k = 0; k < 2; k++) {
        double h = 300 * (k + 1);
        l->lamps[0].position_mm = v3(10, 20, h);
        model_pixel_info_t pi;
        model_lamp_sample_t ls;
        CHECK(model_pixel_info(t, ph.cam, l, q, 1, &pi, &ls, 1));
        CHECK(pi.face == 0);
        CHECK_NEAR(pi.p_mm.x, 10, 1e-6);
        CHECK_NEAR(pi.p_mm.y, 20, 1e-6);
        CHECK_NEAR(ls.d_mm, h, 1e-6);
        CHECK(ls.V == 1);
        S[k] = model_direct_sum(&pi, &ls, l, mres[0], NULL);
        CHECK_REL(S[k], 0.1 * 5e5 / (h * h), 1e-9);
    }
    CHECK_REL(S[0] / S[1], 4.0, 1e-9);
done:
    fx_render_close(&F);
}

// (c) a box on the plane under an oblique lamp: the lit mask is the analytic
// shadow away from its boundary; box faces are lit when they face the lamp.

TEST(render_box_shadow_analytic)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(2000, fx_box_vertices, fx_box_faces),
                        "[material plane]\nmodel = lambert\nkd = 0.2\n"
                        "[material box]\nmodel = lambert\nkd = 0.1\n",
                        "[lamp a]\nposition_mm = 300 100 250\nintensity = 1e6\n",
                        200, 160, 160, v3(-150, -350, 450), v3(-60, 0, 0)))
        goto done;
    model_scene_t *s = F.s;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int W = ph.W, H = ph.H, n = W * H;
    float *P = malloc(sizeof(float) * n);
    int32_t *face = malloc(sizeof(int32_t) * n);
    uint8_t *lit = malloc((size_t)n), *expect = malloc((size_t)n);
    model_shading_t sh = model_shading_default();
    CHECK(model_render(t, ph.cam, l, mres, &sh, P, face, lit));
    model_vec3_t L = l->lamps[0].position_mm;
    // analytic lit state of the plane point of every pixel (2: not a plane pixel)
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            model_vec3_t d = fx_pinhole_ray(&ph, x, y);
            model_vec3_t p = v3_add(ph.C, v3_scale(d, -ph.C.z / d.z));
            bool hidden = segment_hits_box(ph.C, p);   // the box hides the plane point
            expect[y * W + x] = hidden ? 2 : !segment_hits_box(p, L);
        }
    int compared = 0, bad = 0, nshadow = 0, nlit = 0, boxbad = 0, nbox = 0;
    for (int y = 1; y < H - 1; y++)
        for (int x = 1; x < W - 1; x++) {
            int i = y * W + x;
            if (expect[i] == 2) {
                if (face[i] >= 1) {   // a box face: lit iff it faces the lamp
                    const model_face_t *f = &s->faces[face[i]];
                    model_vec3_t d = fx_pinhole_ray(&ph, x, y);
                    bool cam_side = v3_dot(f->normal, d) < 0;   // normal's side sees the camera
                    model_vec3_t c = s->vertices[f->verts[0]];
                    bool lamp_side = v3_dot(f->normal, v3_sub(L, c)) > 0;
                    boxbad += lit[i] != (cam_side == lamp_side);
                    nbox++;
                }
                continue;
            }
            bool near_boundary = false;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++)
                    if (expect[i + dy * W + dx] != expect[i]) near_boundary = true;
            if (near_boundary) continue;
            compared++;
            CHECK(face[i] == 0);
            bad += lit[i] != expect[i];
            nshadow += !expect[i];
            nlit += expect[i];
        }
    CHECK_MSG(bad == 0, "%d of %d plane pixels disagree with the analytic shadow", bad, compared);
    CHECK_MSG(boxbad == 0, "%d of %d box pixels have the wrong lit state", boxbad, nbox);
    CHECK(nshadow > 500 && nlit > 5000 && nbox > 500);
    // shadowed plane pixels are exactly Pa (no ambient), lit ones are not
    for (int i = 0; i < n; i++)
        if (expect[i] == 0 && face[i] == 0 && !lit[i]) CHECK(P[i] == (float)sh.Pa);
    free(P);
    free(face);
    free(lit);
    free(expect);
done:
    fx_render_close(&F);
}

// (d) model_pixel_info on a sparse list equals the full render (face, lit, and
// P through model_direct_sum) for every reflection model.

TEST(render_pixel_info_matches_render)
{
    static const char *models[] = {
        "model = lambert\nkd = 0.2\n",
        "model = hall\nkd = 0.1\nks = 0.3\nns = 12.5\n",
        "model = torrance_sparrow\nkd = 0.1\nks = 0.4\nns = 20\nF0 = 0.05\n",
        "model = thesis_fit\nks = 0.05\nns = 8\nkd = 0.15\n",
        "model = cook_torrance\nkd = 0.4\nks = 0.5\nm = 0.3\nF0 = 0.04\n",
        "model = ggx\nkd = 0.35\nks = 0.25\nalpha = 0.15\nF0 = 0.04\n",
    };
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(2000, fx_box_vertices, fx_box_faces),
                        NULL,
                        "[lamp a]\nposition_mm = 300 100 250\nintensity = 1e6\n"
                        "[lamp b]\nposition_mm = -200 -300 400\nintensity = 2e6\n"
                        "[lamp c]\nposition_mm = 0 10 120\nintensity = 1e5\n",
                        160, 128, 130, v3(-150, -350, 450), v3(-60, 0, 0)))
        goto done;
    model_scene_t *s = F.s;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    int W = ph.W, H = ph.H, n = W * H, nl = l->n;
    float *P = malloc(sizeof(float) * n);
    int32_t *face = malloc(sizeof(int32_t) * n);
    uint8_t *lit = malloc((size_t)n * nl);
    int nq = 0;
    double *q = malloc(sizeof(double) * 2 * n);
    for (int y = 0; y < H; y += 3)
        for (int x = (y / 3) % 5; x < W; x += 5) {
            q[2 * nq] = x;
            q[2 * nq + 1] = y;
            nq++;
        }
    model_pixel_info_t *pi = malloc(sizeof *pi * nq);
    model_lamp_sample_t *ls = malloc(sizeof *ls * nq * nl);
    for (int k = 0; k < (int)(sizeof models / sizeof *models); k++) {
        char text[512];
        snprintf(text, sizeof text, "[material plane]\n%s[material box]\n%s", models[k],
                 models[(k + 1) % 6]);
        model_materials_t *m = fx_materials_text(text);
        const model_material_t *mres[2];
        CHECK(m && model_resolve_materials(s, m, mres));
        if (!m) continue;
        model_shading_t sh = model_shading_default();
        sh.kc = 1.5;
        sh.Pa = 3;
        CHECK(model_render(t, ph.cam, l, mres, &sh, P, face, lit));
        CHECK(model_pixel_info(t, ph.cam, l, q, nq, pi, ls, 2));
        int bad_face = 0, bad_lit = 0, bad_P = 0, nhit = 0;
        for (int j = 0; j < nq; j++) {
            int i = (int)q[2 * j + 1] * W + (int)q[2 * j];
            bad_face += pi[j].face != face[i];
            if (pi[j].face < 0) continue;
            nhit++;
            for (int a = 0; a < nl; a++) bad_lit += (ls[j * nl + a].V > 0.5) != lit[a * n + i];
            double S = model_direct_sum(&pi[j], &ls[j * nl], l, mres[pi[j].material], NULL);
            double expect = sh.Pa + sh.kc * S;
            if (fabs(P[i] - expect) > 1e-6 * fabs(expect) + 1e-6) bad_P++;
        }
        CHECK_MSG(bad_face == 0 && bad_lit == 0 && bad_P == 0,
                  "model %d: %d face, %d lit, %d P mismatches of %d pixels", k, bad_face,
                  bad_lit, bad_P, nq);
        CHECK(nhit > nq / 2);
        model_materials_free(m);
    }
    free(P);
    free(face);
    free(lit);
    free(q);
    free(pi);
    free(ls);
done:
    fx_render_close(&F);
}

// (e) dS/dp of model_direct_sum against central differences.

TEST(render_direct_sum_derivatives)
{
    model_lamps_t *l = fx_lamps_text("[lamp a]\nposition_mm = 300 100 250\nintensity = 1e6\n"
                                     "[lamp b]\nposition_mm = -200 -300 400\nintensity = 2e6\n");
    model_materials_t *m = fx_materials_text(
        "[material a]\nmodel = torrance_sparrow\nkd = 0.1\nks = 0.4\nns = 20\nF0 = 0.05\n"
        "[material b]\nmodel = ggx\nkd = 0.35\nks = 0.25\nalpha = 0.15\nF0 = 0.04\n"
        "[material c]\nmodel = hall\nkd = 0.1\nks = 0.3\nns = 12.5\n");
    CHECK(l && m);
    if (!l || !m) goto done;
    model_pixel_info_t pi = { .face = 0, .material = 0, .p_mm = v3(10, 5, 0),
                              .n = v3(0, 0, 1), .v = v3_unit(v3(-0.3, -0.5, 0.8)),
                              .range_mm = 500 };
    model_lamp_sample_t ls[2];
    for (int i = 0; i < 2; i++) {
        model_vec3_t d = v3_sub(l->lamps[i].position_mm, pi.p_mm);
        ls[i].d_mm = v3_norm(d);
        ls[i].l = v3_unit(d);
        ls[i].V = i == 0 ? 1.0 : 0.75;
    }
    for (int k = 0; k < m->n; k++) {
        model_material_t mat = m->materials[k];
        int np = model_brdf_nparams(mat.model);
        double dS[MODEL_BRDF_MAX_PARAMS];
        double S = model_direct_sum(&pi, ls, l, &mat, dS);
        CHECK(S > 0);
        for (int j = 0; j < np; j++) {
            double h = 1e-6 * fmax(1.0, fabs(mat.p[j]));
            model_material_t a = mat, b = mat;
            a.p[j] += h;
            b.p[j] -= h;
            double fd = (model_direct_sum(&pi, ls, l, &a, NULL) -
                         model_direct_sum(&pi, ls, l, &b, NULL)) / (2 * h);
            CHECK_NEAR(dS[j], fd, 1e-6 * fmax(fabs(fd), S));
        }
    }
    // a missed pixel contributes nothing
    model_pixel_info_t miss = pi;
    miss.face = -1;
    double dS[MODEL_BRDF_MAX_PARAMS] = { 1, 1, 1, 1 };
    CHECK(model_direct_sum(&miss, ls, l, &m->materials[0], dS) == 0 && dS[0] == 0 && dS[3] == 0);
done:
    model_lamps_free(l);
    model_materials_free(m);
}

// (f) thesis interreflection: rho = 0 is exactly NONE; the term is linear in rho.

TEST(render_thesis_interreflection)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(2000, fx_box_vertices, fx_box_faces),
                        "[material plane]\nmodel = hall\nkd = 0.1\nks = 0.3\nns = 10\n"
                        "[material box]\nmodel = lambert\nkd = 0.25\n",
                        "[lamp a]\nposition_mm = -100 -400 300\nintensity = 1e6\n",
                        120, 96, 100, v3(-150, -350, 450), v3(-60, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int n = ph.W * ph.H;
    float *P0 = malloc(sizeof(float) * n), *P1 = malloc(sizeof(float) * n);
    float *P2 = malloc(sizeof(float) * n), *Pn = malloc(sizeof(float) * n);
    model_shading_t sh = model_shading_default();
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pn, NULL, NULL));
    sh.interreflection = MODEL_INTERREFLECTION_THESIS;
    sh.thesis_samples = 13;
    sh.thesis_cone_deg = 15;
    sh.rho = 0;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P0, NULL, NULL));
    CHECK(memcmp(P0, Pn, sizeof(float) * n) == 0);
    sh.rho = 5;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P1, NULL, NULL));
    sh.rho = 10;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P2, NULL, NULL));
    int changed = 0, bad = 0;
    for (int i = 0; i < n; i++) {
        double d1 = (double)P1[i] - P0[i], d2 = (double)P2[i] - P0[i];
        CHECK(d1 >= 0);
        if (d1 > 1e-4 * P0[i] && d1 > 1e-9) {
            changed++;
            if (fabs(d2 - 2 * d1) > 1e-5 * P2[i] + 1e-6) bad++;
        }
    }
    CHECK_MSG(changed > 100, "only %d pixels get interreflection", changed);
    CHECK_MSG(bad == 0, "%d pixels not linear in rho", bad);
    sh.thesis_samples = 0;
    CHECK(!model_render(t, ph.cam, l, mres, &sh, P1, NULL, NULL));
    CHECK_CONTAINS(model_last_error(), "thesis_samples");
    free(P0);
    free(P1);
    free(P2);
    free(Pn);
done:
    fx_render_close(&F);
}

// (f') THESIS known answer: with a cone of 0 deg and one sample, the term at
// a floor point x is rho * L(y -> x) * R_x(r), y the hit along the mirror
// direction r, L(y -> x) = sum_i V_i(y) I_i R_y / d_i(y)^2 (all Lambertian
// here, so L does not depend on the direction toward x). And on the
// T-stiffener the term stays finite where the web meets the plate.

TEST(render_thesis_known_answer_and_finite_at_joint)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(2000, fx_box_vertices, fx_box_faces),
                        "[material plane]\nmodel = lambert\nkd = 0.2\n"
                        "[material box]\nmodel = lambert\nkd = 0.3\n",
                        "[lamp a]\nposition_mm = -300 -200 400\nintensity = 1e6\n",
                        120, 96, 100, v3(-350, 40, 160), v3(-60, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int n = ph.W * ph.H;
    float *Pn = malloc(sizeof(float) * n), *Pt = malloc(sizeof(float) * n);
    model_shading_t sh = model_shading_default();
    sh.kc = 3;
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pn, NULL, NULL));
    sh.interreflection = MODEL_INTERREFLECTION_THESIS;
    sh.thesis_samples = 1;
    sh.thesis_cone_deg = 0;
    sh.rho = 0.7;
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pt, NULL, NULL));
    int checked = 0;
    for (int py = 0; py < ph.H; py += 3)
        for (int px = 0; px < ph.W; px += 3) {
            double q[2] = { px, py };
            model_pixel_info_t pi;
            CHECK(model_pixel_info(t, ph.cam, NULL, q, 1, &pi, NULL, 1));
            if (pi.face != 0) continue;                    // floor pixels only
            model_vec3_t r = v3_sub(v3_scale(pi.n, 2 * v3_dot(pi.n, pi.v)), pi.v);
            model_pixel_info_t y;
            model_tracer_cast(t, v3_add(pi.p_mm, v3_scale(pi.n, 1e-3)), r, &y);
            double expect = 0;
            if (y.face > 0) {                               // the box
                const model_lamp_t *L = &l->lamps[0];
                model_vec3_t ly = v3_sub(L->position_mm, y.p_mm);
                double d2 = v3_dot(ly, ly), nl = v3_dot(y.n, ly) / sqrt(d2);
                bool vis = model_tracer_visible(t, v3_add(y.p_mm, v3_scale(y.n, 1e-3)), L->position_mm);
                double Ly = vis && nl > 0 ? L->intensity * 0.3 * nl / d2 : 0;
                expect = sh.kc * sh.rho * Ly * 0.2 * v3_dot(pi.n, r);
                if (expect > 0) checked++;
            }
            CHECK_NEAR(Pt[py * ph.W + px] - Pn[py * ph.W + px], expect, 1e-4 * Pn[py * ph.W + px] + 1e-3);
        }
    CHECK_MSG(checked > 20, "only %d floor pixels see the box in the mirror direction", checked);
    free(Pn);
    free(Pt);

    // The T-stiffener: thesis interreflection adds a little, nowhere explodes.
    char path[4][1024];
    const char *names[4] = { "t_stiffener.d3d", "camera.cameramodel", "lamps.ini", "materials.ini" };
    for (int i = 0; i < 4; i++) snprintf(path[i], sizeof path[i], "%s/examples/%s", test_srcdir(), names[i]);
    model_scene_t *ts = model_scene_load(path[0], NULL);
    model_camera_t *cam = model_camera_load(path[1]);
    model_lamps_t *tl = model_lamps_load(path[2]);
    model_materials_t *tm = model_materials_load(path[3]);
    CHECK(ts && cam && tl && tm);
    if (ts && cam && tl && tm) {
        model_tracer_t *tt = model_tracer_new(ts);
        const model_material_t *tmr[8];
        CHECK(ts->nmaterials <= 8 && model_resolve_materials(ts, tm, tmr));
        int N = model_camera_width(cam) * model_camera_height(cam);
        float *A = malloc(sizeof(float) * N), *B = malloc(sizeof(float) * N);
        model_shading_t s2 = model_shading_default();
        CHECK(model_render(tt, cam, tl, tmr, &s2, A, NULL, NULL));
        s2.interreflection = MODEL_INTERREFLECTION_THESIS;
        CHECK(model_render(tt, cam, tl, tmr, &s2, B, NULL, NULL));
        double maxA = 0, maxB = 0, sumd = 0;
        for (int i = 0; i < N; i++) {
            maxA = fmax(maxA, A[i]);
            maxB = fmax(maxB, B[i]);
            CHECK_MSG(B[i] >= A[i] - 1e-3f, "pixel %d: thesis %g < direct %g", i, B[i], A[i]);
            sumd += B[i] - A[i];
        }
        CHECK_MSG(maxB <= 1.25 * maxA, "thesis max %g vs direct max %g", maxB, maxA);
        CHECK(sumd > 0);
        free(A);
        free(B);
        model_tracer_free(tt);
    }
    model_scene_free(ts);
    model_camera_free(cam);
    model_lamps_free(tl);
    model_materials_free(tm);
done:
    fx_render_close(&F);
}

// (g) MC on a single plane: no indirect light is possible, so MC equals the
// direct term (exactly for point lamps, within the lamp-size effect for a
// small sphere lamp).

TEST(render_mc_plane_equals_direct)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(5000, NULL, NULL),
                        "[material plane]\nmodel = ggx\nkd = 0.5\nks = 0.3\n"
                        "alpha = 0.3\nF0 = 0.04\n",
                        "[lamp a]\nposition_mm = 30 -20 400\nintensity = 1e6\n"
                        "radius_mm = 4\n"
                        "[lamp b]\nposition_mm = -300 100 300\nintensity = 1e6\n",
                        64, 48, 60, v3(100, -300, 500), v3(0, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int n = ph.W * ph.H;
    float *Pd = malloc(sizeof(float) * n), *Pm = malloc(sizeof(float) * n);
    model_shading_t sh = model_shading_default();
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pd, NULL, NULL));
    sh.interreflection = MODEL_INTERREFLECTION_MC;
    sh.mc_samples = 8;
    sh.mc_bounces = 3;
    sh.finite_lamps = false;
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pm, NULL, NULL));
    int bad = 0;
    for (int i = 0; i < n; i++) bad += fabs(Pm[i] - Pd[i]) > 1e-6 * Pd[i];
    CHECK_MSG(bad == 0, "%d pixels: MC with point lamps differs from the direct term", bad);
    sh.finite_lamps = true;   // lamp a: a sphere of 4 mm at ~450 mm: (r/d)^2 ~ 1e-4
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pm, NULL, NULL));
    bad = 0;
    double sum_rel = 0;
    for (int i = 0; i < n; i++) {
        bad += fabs(Pm[i] - Pd[i]) > 1e-2 * Pd[i];
        sum_rel += fabs(Pm[i] - Pd[i]) / Pd[i];
    }
    CHECK_MSG(bad == 0, "%d pixels: MC with a small sphere lamp differs from the direct term", bad);
    CHECK(sum_rel / n < 1e-3);
    free(Pd);
    free(Pm);
done:
    fx_render_close(&F);
}

// (h) MC energy check: a point lamp at the centre of a closed sphere of
// radius r (subdivided icosahedron), Lambertian albedo a = pi kd = 0.5: the
// radiance is kd E0 (1 + a + ... + a^B), E0 = I / r^2.

static char *sphere_d3d(double r, int levels)
{
    // icosahedron
    double ph = (1 + sqrt(5)) / 2;
    double iv[12][3] = { { -1, ph, 0 }, { 1, ph, 0 }, { -1, -ph, 0 }, { 1, -ph, 0 },
                         { 0, -1, ph }, { 0, 1, ph }, { 0, -1, -ph }, { 0, 1, -ph },
                         { ph, 0, -1 }, { ph, 0, 1 }, { -ph, 0, -1 }, { -ph, 0, 1 } };
    int ifc[20][3] = { { 0, 11, 5 }, { 0, 5, 1 }, { 0, 1, 7 }, { 0, 7, 10 }, { 0, 10, 11 },
                       { 1, 5, 9 }, { 5, 11, 4 }, { 11, 10, 2 }, { 10, 7, 6 }, { 7, 1, 8 },
                       { 3, 9, 4 }, { 3, 4, 2 }, { 3, 2, 6 }, { 3, 6, 8 }, { 3, 8, 9 },
                       { 4, 9, 5 }, { 2, 4, 11 }, { 6, 2, 10 }, { 8, 6, 7 }, { 9, 8, 1 } };
    int nt = 20;
    for (int k = 0; k < levels; k++) nt *= 4;
    model_vec3_t *tri = malloc(sizeof *tri * 3 * nt), *tmp = malloc(sizeof *tmp * 3 * nt);
    for (int f = 0; f < 20; f++)
        for (int j = 0; j < 3; j++)
            tri[3 * f + j] = v3_unit(v3(iv[ifc[f][j]][0], iv[ifc[f][j]][1], iv[ifc[f][j]][2]));
    int cur = 20;
    for (int k = 0; k < levels; k++) {
        for (int f = 0; f < cur; f++) {
            model_vec3_t a = tri[3 * f], b = tri[3 * f + 1], c = tri[3 * f + 2];
            model_vec3_t ab = v3_unit(v3_add(a, b)), bc = v3_unit(v3_add(b, c)),
                         ca = v3_unit(v3_add(c, a));
            model_vec3_t out[12] = { a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca };
            memcpy(&tmp[12 * f], out, sizeof out);
        }
        cur *= 4;
        model_vec3_t *sw = tri;
        tri = tmp;
        tmp = sw;
    }
    size_t cap = (size_t)nt * 400 + 64;
    char *buf = malloc(cap), *p = buf;
    for (int i = 0; i < 3 * nt; i++)
        p += sprintf(p, "%d %.17g %.17g %.17g\n", i + 1, r * tri[i].x, r * tri[i].y, r * tri[i].z);
    p += sprintf(p, "Faces:\n@material wall\n");
    for (int f = 0; f < nt; f++) p += sprintf(p, "%d %d %d.\n", 3 * f + 3, 3 * f + 2, 3 * f + 1);
    free(tri);
    free(tmp);
    return buf;
}

static double mean_std(const float *P, int n, double expect, double *std)
{
    double s = 0, s2 = 0;
    for (int i = 0; i < n; i++) {
        s += P[i];
        s2 += (P[i] - expect) * (P[i] - expect);
    }
    *std = sqrt(s2 / n);
    return s / n;
}

TEST(render_mc_energy_sphere)
{
    const double r = 100, I = 1e4, a = 0.5, kd = a / M_PI;
    char mt[128];
    snprintf(mt, sizeof mt, "[material wall]\nmodel = lambert\nkd = %.17g\n", kd);
    fx_render_t F;
    if (!fx_render_open(&F, sphere_d3d(r, 4),
                        mt,
                        "[lamp c]\nposition_mm = 0 0 0\nintensity = 1e4\n",
                        48, 40, 30, v3(10, -20, 30), v3(40, 30, -50)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int n = ph.W * ph.H;
    float *P = malloc(sizeof(float) * n), *P2 = malloc(sizeof(float) * n);
    int32_t *face = malloc(sizeof(int32_t) * n);
    double E0 = I / (r * r);
    model_shading_t sh = model_shading_default();
    sh.interreflection = MODEL_INTERREFLECTION_MC;
    sh.finite_lamps = false;
    sh.mc_samples = 16;
    sh.seed = 42;
    for (int B = 0; B <= 3; B++) {
        sh.mc_bounces = B;
        CHECK(model_render(t, ph.cam, l, mres, &sh, P, face, NULL));
        double expect = 0, ak = 1;
        for (int k = 0; k <= B; k++, ak *= a) expect += kd * E0 * ak;
        double sd, mean = mean_std(P, n, expect, &sd);
        CHECK_REL(mean, expect, B == 0 ? 2e-3 : 0.02);
        CHECK(sd < 0.05 * expect);
    }
    for (int i = 0; i < n; i++) CHECK(face[i] >= 0);
    // more samples lower the noise: the spread of the difference of two seeds
    sh.mc_bounces = 2;
    double sd_n[2];
    for (int k = 0; k < 2; k++) {
        sh.mc_samples = k ? 128 : 16;
        sh.seed = 5;
        CHECK(model_render(t, ph.cam, l, mres, &sh, P, NULL, NULL));
        sh.seed = 6;
        CHECK(model_render(t, ph.cam, l, mres, &sh, P2, NULL, NULL));
        double s2 = 0;
        for (int i = 0; i < n; i++) s2 += ((double)P[i] - P2[i]) * ((double)P[i] - P2[i]);
        sd_n[k] = sqrt(s2 / n);
    }
    CHECK(sd_n[0] > 0);
    CHECK_MSG(sd_n[1] < 0.5 * sd_n[0], "noise with 128 samples %.4g, with 16 %.4g", sd_n[1], sd_n[0]);
    // same seed: identical; 1 thread vs 2 threads: identical; another seed: different
    sh.mc_samples = 8;
    sh.nthreads = 1;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P, NULL, NULL));
    sh.nthreads = 2;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P2, NULL, NULL));
    CHECK(memcmp(P, P2, sizeof(float) * n) == 0);
    CHECK(model_render(t, ph.cam, l, mres, &sh, P2, NULL, NULL));
    CHECK(memcmp(P, P2, sizeof(float) * n) == 0);
    sh.seed = 43;
    CHECK(model_render(t, ph.cam, l, mres, &sh, P2, NULL, NULL));
    CHECK(memcmp(P, P2, sizeof(float) * n) != 0);
    free(P);
    free(P2);
    free(face);
done:
    fx_render_close(&F);
}

// MC with finite lamps gives soft shadows: pixels in the penumbra get a
// fractional visibility (P strictly between umbra and full light).
TEST(render_mc_soft_shadow)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(2000, fx_box_vertices, fx_box_faces),
                        "[material plane]\nmodel = lambert\nkd = 0.2\n"
                        "[material box]\nmodel = lambert\nkd = 0.1\n",
                        "[lamp a]\nposition_mm = 300 100 250\nintensity = 1e6\n"
                        "radius_mm = 40\n",
                        100, 80, 80, v3(-150, -350, 450), v3(-60, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    model_tracer_t *t = F.t;
    const model_material_t **mres = F.mres;
    int n = ph.W * ph.H;
    float *Pd = malloc(sizeof(float) * n), *Pm = malloc(sizeof(float) * n);
    int32_t *face = malloc(sizeof(int32_t) * n);
    model_shading_t sh = model_shading_default();
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pd, face, NULL));
    sh.interreflection = MODEL_INTERREFLECTION_MC;
    sh.mc_bounces = 0;
    sh.mc_samples = 64;
    CHECK(model_render(t, ph.cam, l, mres, &sh, Pm, NULL, NULL));
    int penumbra = 0;
    for (int i = 0; i < n; i++) {
        if (face[i] != 0) continue;
        // the unshadowed value from the point model (same lamp, no occluder)
        if (Pm[i] > 0.1 * Pd[i] && Pm[i] < 0.9 * Pd[i]) penumbra++;
        if (Pd[i] == 0 && Pm[i] > 0) penumbra++;
    }
    CHECK_MSG(penumbra > 20, "only %d penumbra pixels", penumbra);
    free(Pd);
    free(Pm);
    free(face);
done:
    fx_render_close(&F);
}

// Ray casting: exact hit points, normals facing the ray, non-convex faces.
TEST(trace_cast_nonconvex_face)
{
    // An L-shaped face in z = 5: [0,100]x[0,100] minus [50,100]x[50,100].
    const char *d3d = "1 0 0 5\n2 100 0 5\n3 100 50 5\n4 50 50 5\n5 50 100 5\n6 0 100 5\n"
                      "Faces:\n1 2 3 4 5 6.\n";
    model_scene_t *s = fx_scene_text(d3d);
    CHECK(s != NULL);
    if (!s) return;
    model_tracer_t *t = model_tracer_new(s);
    CHECK(t != NULL);
    int bad = 0;
    for (int iy = 0; iy < 40; iy++)
        for (int ix = 0; ix < 40; ix++) {
            double x = -10 + 3.1 * ix, y = -10 + 3.1 * iy;
            bool inside = x > 0 && x < 100 && y > 0 && y < 100 && !(x > 50 && y > 50);
            bool near_edge = fabs(x) < 1e-3 || fabs(y) < 1e-3 || fabs(x - 100) < 1e-3 ||
                             fabs(y - 100) < 1e-3 || fabs(x - 50) < 1e-3 || fabs(y - 50) < 1e-3;
            if (near_edge) continue;
            for (int side = 0; side < 2; side++) {   // from above and from below
                model_vec3_t o = v3(x + 7, y - 3, side ? -200 : 300);
                model_vec3_t d = v3_unit(v3_sub(v3(x, y, 5), o));
                model_pixel_info_t pi;
                model_tracer_cast(t, o, d, &pi);
                if ((pi.face == 0) != inside) bad++;
                if (pi.face == 0) {
                    CHECK_NEAR(pi.p_mm.x, x, 1e-9);
                    CHECK_NEAR(pi.p_mm.y, y, 1e-9);
                    CHECK_NEAR(pi.p_mm.z, 5, 1e-9);
                    CHECK(v3_dot(pi.n, d) < 0 && fabs(fabs(pi.n.z) - 1) < 1e-12);
                    CHECK_NEAR(pi.range_mm, v3_norm(v3_sub(pi.p_mm, o)), 1e-9);
                }
            }
        }
    CHECK_MSG(bad == 0, "%d rays disagree with the L-shaped outline", bad);
    // visibility: the face blocks the segment through it, not one beside it
    CHECK(!model_tracer_visible(t, v3(20, 20, 0), v3(20, 20, 10)));
    CHECK(model_tracer_visible(t, v3(80, 80, 0), v3(80, 80, 10)));
    // a point on the face sees a target above it (no self-shadowing)
    CHECK(model_tracer_visible(t, v3(20, 20, 5), v3(30, 60, 500)));
    CHECK(model_tracer_visible_from(t, v3(20, 20, 5), v3(0, 0, 1), v3(300, 60, 5.5)));
    model_tracer_free(t);
    model_scene_free(s);
}

// (i) errors name what is wrong.
TEST(render_errors)
{
    const char *d3d = "1 0 0 0\n2 10 0 0\n3 10 10 0\nFaces:\n@material steel\n1 2 3.\n";
    model_scene_t *s = fx_scene_text(d3d);
    model_materials_t *m = fx_materials_text("[material plywood]\nmodel = lambert\nkd = 0.2\n");
    CHECK(s && m);
    if (!s || !m) goto done;
    const model_material_t *mres[1];
    CHECK(!model_resolve_materials(s, m, mres));
    CHECK_CONTAINS(model_last_error(), "steel");
    CHECK_CONTAINS(model_last_error(), "test_materials.ini");
    CHECK(model_interreflection_from_name("thesis") == MODEL_INTERREFLECTION_THESIS);
    CHECK(model_interreflection_from_name("mc") == MODEL_INTERREFLECTION_MC);
    CHECK(model_interreflection_from_name("none") == MODEL_INTERREFLECTION_NONE);
    CHECK(model_interreflection_from_name("bogus") == -1);
    CHECK(!strcmp(model_interreflection_name(MODEL_INTERREFLECTION_MC), "mc"));
    model_shading_t sh = model_shading_default();
    CHECK(sh.kc == 1 && sh.Pa == 0 && sh.rho == 0.05 && sh.thesis_samples == 9 &&
          sh.thesis_cone_deg == 10 && sh.mc_samples == 16 && sh.mc_bounces == 2 &&
          sh.finite_lamps && sh.seed == 1);
    // an unresolved material in render
    model_tracer_t *t = model_tracer_new(s);
    fx_pinhole_t ph = { 0 };
    CHECK(t && fx_pinhole_look(&ph, 16, 16, 20, v3(5, 3, 50), v3(5, 3, 0)));
    if (t && ph.cam) {
        const model_material_t *none[1] = { NULL };
        float P[256];
        CHECK(!model_render(t, ph.cam, NULL, none, &sh, P, NULL, NULL));
        CHECK_CONTAINS(model_last_error(), "material");
        sh.interreflection = MODEL_INTERREFLECTION_MC;
        sh.mc_samples = 0;
        CHECK(!model_render(t, ph.cam, NULL, none, &sh, P, NULL, NULL));
        CHECK_CONTAINS(model_last_error(), "mc_samples");
    }
    model_camera_free(ph.cam);
    model_tracer_free(t);
done:
    model_scene_free(s);
    model_materials_free(m);
}

// ---------------------------------------------------------------------------
// The lamps' emission pattern (outside the fitters' model, the adversarial rig's): a
// Lambertian plane under a lamp of pattern cos^n about a tilted axis. Every
// pixel's light, over that of the same lamp isotropic, is (a . u)^n, u the
// unit direction from the lamp to the plane point: in the direct renderer, in
// model_direct_sum, and (same seed, same draws) for an MC sphere lamp.

TEST(render_lamp_emission_pattern_cos_power)
{
    const double n = 6.0;
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(5000, NULL, NULL),
                        "[material plane]\nmodel = lambert\nkd = 0.2\n",
                        "[lamp a]\nposition_mm = 30 -20 400\nintensity = 1e6\n"
                        "[lamp b]\nposition_mm = 30 -20 400\nintensity = 1e6\n"
                        "emission_cos_power = 6\nemission_axis = 0.3 0 -1\n",
                        96, 72, 90, v3(100, -300, 500), v3(0, 0, 0)))
        goto done;
    model_lamps_t *l = F.l;
    fx_pinhole_t ph = F.ph;
    int W = ph.W, H = ph.H, npx = W * H;
    model_vec3_t Lp = l->lamps[1].position_mm, a = v3_unit(v3(0.3, 0, -1));
    CHECK_NEAR(v3_dot(l->lamps[1].emission_axis, a), 1.0, 1e-12);
    model_lamps_t iso = *l, pat = *l;
    iso.n = pat.n = 1;
    pat.lamps = &l->lamps[1];
    float *P0 = malloc(sizeof(float) * npx), *P1 = malloc(sizeof(float) * npx);
    model_shading_t sh = model_shading_default();
    CHECK(model_render(F.t, ph.cam, &iso, F.mres, &sh, P0, NULL, NULL));
    CHECK(model_render(F.t, ph.cam, &pat, F.mres, &sh, P1, NULL, NULL));
    int bad = 0;
    double lo = 1, hi = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            model_vec3_t d = fx_pinhole_ray(&ph, x, y);
            model_vec3_t p = v3_add(ph.C, v3_scale(d, -ph.C.z / d.z));
            double expect = pow(v3_dot(a, v3_unit(v3_sub(p, Lp))), n);
            double got = P1[y * W + x] / P0[y * W + x];
            if (fabs(got - expect) > 1e-5 * expect) bad++;
            if (expect < lo) lo = expect;
            if (expect > hi) hi = expect;
        }
    CHECK_MSG(bad == 0, "%d pixels off the analytic cos^n ratio", bad);
    CHECK_MSG(hi - lo > 0.2, "the view spans a ratio of %.3f..%.3f only: the test would not see the pattern", lo, hi);
    // model_direct_sum at a plane point 150 mm off the lamp's foot
    model_vec3_t ground = v3(180, -20, 0);
    double q[2];
    CHECK(model_camera_project(ph.cam, &ground, 1, q));
    model_pixel_info_t pi;
    model_lamp_sample_t ls[2];
    CHECK(model_pixel_info(F.t, ph.cam, l, q, 1, &pi, ls, 1));
    double S0 = model_direct_sum(&pi, &ls[0], &iso, F.mres[0], NULL);
    double S1 = model_direct_sum(&pi, &ls[1], &pat, F.mres[0], NULL);
    CHECK_REL(S1 / S0, pow(v3_dot(a, v3_unit(v3_sub(pi.p_mm, Lp))), n), 1e-9);
    CHECK_REL(S0, 0.2 * 1e6 * 400 / pow(v3_norm(v3_sub(Lp, pi.p_mm)), 3), 1e-6);
    // MC, the lamps spheres of 20 mm: the same draws, the pattern of the centre
    l->lamps[0].radius_mm = l->lamps[1].radius_mm = 20;
    sh.interreflection = MODEL_INTERREFLECTION_MC;
    sh.mc_bounces = 0;
    sh.mc_samples = 4;
    CHECK(model_render(F.t, ph.cam, &iso, F.mres, &sh, P0, NULL, NULL));
    CHECK(model_render(F.t, ph.cam, &pat, F.mres, &sh, P1, NULL, NULL));
    bad = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            model_vec3_t d = fx_pinhole_ray(&ph, x, y);
            model_vec3_t p = v3_add(ph.C, v3_scale(d, -ph.C.z / d.z));
            double expect = pow(v3_dot(a, v3_unit(v3_sub(p, Lp))), n);
            if (fabs(P1[y * W + x] / P0[y * W + x] - expect) > 1e-5 * expect) bad++;
        }
    CHECK_MSG(bad == 0, "MC: %d pixels off the analytic cos^n ratio", bad);
    // behind the lamp's axis nothing arrives; isotropic is exactly 1
    model_lamp_t back = l->lamps[1];
    CHECK(model_lamp_emission(&back, v3_add(Lp, v3_scale(a, -10))) == 0.0);
    CHECK(model_lamp_emission(&l->lamps[0], v3(1e3, 2e3, -5)) == 1.0);
    // default axis: toward the rig origin
    back.emission_axis = v3(0, 0, 0);
    CHECK_NEAR(model_lamp_emission(&back, v3(0, 0, 0)), 1.0, 1e-12);
    free(P0);
    free(P1);
done:
    fx_render_close(&F);
}
