// rig/virtual/place.c — placement errors and the turntable's axis of the
// virtual rig (see rig/virtual/place.h).
#include <glib.h>
#include <math.h>
#include <string.h>

#include "model/base/vec.h"
#include "rig/virtual/place.h"

static void rot_axis(double ux, double uy, double uz, double a_rad, double R[9])
{
    double c = cos(a_rad), s = sin(a_rad), C = 1 - c;
    double M[9] = { c + ux * ux * C, ux * uy * C - uz * s, ux * uz * C + uy * s,
                    uy * ux * C + uz * s, c + uy * uy * C, uy * uz * C - ux * s,
                    uz * ux * C - uy * s, uz * uy * C + ux * s, c + uz * uz * C };
    memcpy(R, M, sizeof M);
}

static uint64_t name_hash(const char *s)
{
    uint64_t h = 0xcbf29ce484222325ULL;   // FNV-1a
    for (; *s; s++) h = (h ^ (unsigned char)*s) * 0x100000001b3ULL;
    return h;
}

void rig_virtual_place_about_centre(const model_scene_t *scene, double turn_rad, double dx_mm, double dy_mm,
                                    double dR[9], double dt[3])
{
    // the sample's centre: the middle of its bounding box in x and y
    double lo[2] = { INFINITY, INFINITY }, hi[2] = { -INFINITY, -INFINITY };
    for (int i = 0; i < scene->nvertices; i++) {
        lo[0] = fmin(lo[0], scene->vertices[i].x), hi[0] = fmax(hi[0], scene->vertices[i].x);
        lo[1] = fmin(lo[1], scene->vertices[i].y), hi[1] = fmax(hi[1], scene->vertices[i].y);
    }
    for (int k = 0; k < scene->nspheres; k++) {
        model_vec3_t c = scene->spheres[k].centre_mm;
        double rr = scene->spheres[k].radius_mm;
        lo[0] = fmin(lo[0], c.x - rr), hi[0] = fmax(hi[0], c.x + rr);
        lo[1] = fmin(lo[1], c.y - rr), hi[1] = fmax(hi[1], c.y + rr);
    }
    double cx = isfinite(lo[0]) ? (lo[0] + hi[0]) / 2 : 0, cy = isfinite(lo[1]) ? (lo[1] + hi[1]) / 2 : 0;
    rot_axis(0, 0, 1, turn_rad, dR);
    // x' = dR (x - c) + c + d
    dt[0] = cx - (dR[0] * cx + dR[1] * cy) + dx_mm;
    dt[1] = cy - (dR[3] * cx + dR[4] * cy) + dy_mm;
    dt[2] = 0;
}

void rig_virtual_place_error(const rig_virtual_place_t *p, const char *name, long count,
                             const model_scene_t *scene, double dR[9], double dt[3], double err[3])
{
    model_rng_t r = model_rng(p->seed ^ name_hash(name), (uint64_t)count);
    double psi = model_rng_gauss(&r) * p->angle_sigma_deg * M_PI / 180;
    double dx = model_rng_gauss(&r) * p->position_sigma_mm, dy = model_rng_gauss(&r) * p->position_sigma_mm;
    rig_virtual_place_about_centre(scene, psi, dx, dy, dR, dt);
    if (err) err[0] = psi * 180 / M_PI, err[1] = dx, err[2] = dy;
}

void rig_virtual_place_table_R(const rig_virtual_place_t *p, double angle_deg, double R[9])
{
    double phi = p->axis_tilt_azimuth_deg * M_PI / 180;
    double A[9], Z[9], Wb[9];
    // A: z onto the leaning axis, about the hinge (-sin az, cos az, 0)
    rot_axis(-sin(phi), cos(phi), 0, p->axis_tilt_deg * M_PI / 180, A);
    rot_axis(0, 0, 1, angle_deg * M_PI / 180, Z);
    // Wb: the platter's normal leans towards the platter's +x (about its y)
    rot_axis(0, 1, 0, p->wobble_deg * M_PI / 180, Wb);
    m3_mul(R, Z, Wb);
    m3_mul(R, A, R);
}

model_scene_t *rig_virtual_place_rotated(const rig_virtual_place_t *p, const model_scene_t *scene,
                                         double angle_deg)
{
    if (!p->axis_on) return model_scene_rotated_z(scene, angle_deg);
    if (!isfinite(angle_deg)) {
        model_error(scene->path, 0, "rotation angle %g deg is not finite", angle_deg);
        return NULL;
    }
    double R[9];
    static const double t[3] = { 0, 0, 0 };
    rig_virtual_place_table_R(p, angle_deg, R);
    return model_scene_transformed(scene, R, t);
}

model_scene_t *rig_virtual_place_flexed(const model_scene_t *sc, double flex_mm)
{
    double lo[2] = { INFINITY, INFINITY }, hi[2] = { -INFINITY, -INFINITY };
    for (int i = 0; i < sc->nvertices; i++) {
        lo[0] = fmin(lo[0], sc->vertices[i].x), hi[0] = fmax(hi[0], sc->vertices[i].x);
        lo[1] = fmin(lo[1], sc->vertices[i].y), hi[1] = fmax(hi[1], sc->vertices[i].y);
    }
    double cx = (lo[0] + hi[0]) / 2, cy = (lo[1] + hi[1]) / 2;
    double R2 = pow((hi[0] - lo[0]) / 2, 2) + pow((hi[1] - lo[1]) / 2, 2);
    if (sc->nspheres > 0 || !(R2 > 0)) {
        model_error(sc->path, 0, "flex_mm: only a scene of faces with an extent in x and y can bend");
        return NULL;
    }
    GString *s = g_string_new("# flexed copy (rig/virtual/place.c)\n");
    for (int i = 0; i < sc->nvertices; i++) {
        model_vec3_t p = sc->vertices[i];
        double r2 = (p.x - cx) * (p.x - cx) + (p.y - cy) * (p.y - cy);
        double z = p.z + flex_mm * r2 / R2 - fmin(0, flex_mm);   // the lowest point stays
        g_string_append_printf(s, "v %.17g %.17g %.17g\n", p.x, p.y, z);
    }
    int mat = -1;
    for (int k = 0; k < sc->nfaces; k++) {
        const model_face_t *F = &sc->faces[k];
        if (F->material != mat) g_string_append_printf(s, "usemtl %s\n", sc->material_names[mat = F->material]);
        for (int j = 1; j + 1 < F->nverts; j++)   // a fan: each flat
            g_string_append_printf(s, "f %d %d %d\n", F->verts[0] + 1, F->verts[j] + 1, F->verts[j + 1] + 1);
    }
    model_scene_t *r = model_scene_parse_obj(s->str, s->len, sc->path, NULL);
    g_string_free(s, TRUE);
    return r;
}
