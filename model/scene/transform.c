// model/scene/transform.c — scenes moved rigidly: any rotation and
// translation, the turntable's rotation about world z, and the pose of a
// scene standing on the sample wedge. Sphere centres move with the vertices.
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

// cos and sin of an angle in degrees, exact at multiples of 90 degrees.
static void sincos_deg(double deg, double *s, double *c)
{
    double r = fmod(deg, 360.0);
    if (r < 0) r += 360.0;
    if (r == 0 || r == 90 || r == 180 || r == 270) {
        int q = (int)(r / 90);
        static const double sn[4] = { 0, 1, 0, -1 }, cs[4] = { 1, 0, -1, 0 };
        *s = sn[q];
        *c = cs[q];
        return;
    }
    *s = sin(r * M_PI / 180.0);
    *c = cos(r * M_PI / 180.0);
}

static model_vec3_t rigid_apply(const double R[9], const double t[3], model_vec3_t p)
{
    return v3(R[0] * p.x + R[1] * p.y + R[2] * p.z + t[0],
              R[3] * p.x + R[4] * p.y + R[5] * p.z + t[1],
              R[6] * p.x + R[7] * p.y + R[8] * p.z + t[2]);
}

model_scene_t *model_scene_transformed(const model_scene_t *scene, const double R[9], const double t[3])
{
    if (!scene) return NULL;
    for (int i = 0; i < 9; i++)
        if (!isfinite(R[i]) || (i < 3 && !isfinite(t[i]))) {
            model_error(scene->path, 0, "scene transform has a non-finite entry");
            return NULL;
        }
    static const double zero[3] = { 0, 0, 0 };
    size_t nrefs = 0;
    for (int k = 0; k < scene->nfaces; k++) nrefs += (size_t)scene->faces[k].nverts;
    model_scene_t *r = calloc(1, sizeof *r);
    if (!r) goto oom;
    r->nvertices = scene->nvertices;
    r->nfaces = scene->nfaces;
    r->vertices = malloc(((size_t)scene->nvertices + 1) * sizeof *r->vertices);
    r->faces = malloc(((size_t)scene->nfaces + 1) * sizeof *r->faces);
    r->vert_storage_ = malloc((nrefs + 1) * sizeof *r->vert_storage_);
    r->material_names = calloc((size_t)scene->nmaterials + 1, sizeof *r->material_names);
    r->path = strdup(scene->path ? scene->path : "");
    r->spheres = malloc(((size_t)(scene->nspheres > 0 ? scene->nspheres : 0) + 1) * sizeof *r->spheres);
    if (!r->vertices || !r->faces || !r->vert_storage_ || !r->material_names || !r->path ||
        !r->spheres)
        goto oom;
    for (int k = 0; k < scene->nspheres; k++) {
        r->spheres[k] = scene->spheres[k];
        r->spheres[k].centre_mm = rigid_apply(R, t, scene->spheres[k].centre_mm);
    }
    r->nspheres = scene->nspheres > 0 ? scene->nspheres : 0;
    for (int i = 0; i < scene->nmaterials; i++) {
        if (!(r->material_names[i] = strdup(scene->material_names[i]))) goto oom;
        r->nmaterials = i + 1;
    }
    memcpy(r->sha256, scene->sha256, sizeof r->sha256);
    for (int i = 0; i < scene->nvertices; i++) r->vertices[i] = rigid_apply(R, t, scene->vertices[i]);
    size_t o = 0;
    for (int k = 0; k < scene->nfaces; k++) {
        model_face_t f = scene->faces[k];
        memcpy(r->vert_storage_ + o, f.verts, (size_t)f.nverts * sizeof(int));
        f.verts = r->vert_storage_ + o;
        o += (size_t)f.nverts;
        f.normal = rigid_apply(R, zero, f.normal);
        // n'.(R x + t) = n.x + n'.t
        f.offset_mm += f.normal.x * t[0] + f.normal.y * t[1] + f.normal.z * t[2];
        r->faces[k] = f;
    }
    return r;
oom:
    model_scene_free(r);
    model_error(scene->path, 0, "out of memory");
    return NULL;
}

// The wedge: R = rotation by tilt about h = (cos az, sin az, 0) (right-handed),
// t = (0, 0, lift) with lift = min z of the scene - min z of the rotated scene.
void model_scene_wedge_pose(const model_scene_t *sc, double tilt_deg, double az_deg, double R[9], double t[3])
{
    double a = tilt_deg * M_PI / 180, b = az_deg * M_PI / 180;
    double hx = cos(b), hy = sin(b), c = cos(a), s_ = sin(a), C = 1 - c;
    double M[9] = { c + hx * hx * C, hx * hy * C, hy * s_,
                    hx * hy * C, c + hy * hy * C, -hx * s_,
                    -hy * s_, hx * s_, c };
    memcpy(R, M, sizeof M);
    double zmin0 = INFINITY, zmin1 = INFINITY;
    for (int i = 0; i < sc->nvertices; i++) {
        model_vec3_t p = sc->vertices[i];
        zmin0 = fmin(zmin0, p.z);
        zmin1 = fmin(zmin1, R[6] * p.x + R[7] * p.y + R[8] * p.z);
    }
    for (int k = 0; k < sc->nspheres; k++) {
        model_vec3_t p = sc->spheres[k].centre_mm;
        double r = sc->spheres[k].radius_mm;
        zmin0 = fmin(zmin0, p.z - r);
        zmin1 = fmin(zmin1, R[6] * p.x + R[7] * p.y + R[8] * p.z - r);
    }
    t[0] = t[1] = 0;
    t[2] = isfinite(zmin0) && isfinite(zmin1) ? zmin0 - zmin1 : 0;
}

model_scene_t *model_scene_rotated_z(const model_scene_t *scene, double angle_deg)
{
    if (!scene) return NULL;
    if (!isfinite(angle_deg)) {
        model_error(scene->path, 0, "rotation angle %g deg is not finite", angle_deg);
        return NULL;
    }
    double s, c;
    sincos_deg(angle_deg, &s, &c);
    const double R[9] = { c, -s, 0, s, c, 0, 0, 0, 1 }, t[3] = { 0, 0, 0 };
    return model_scene_transformed(scene, R, t);
}
