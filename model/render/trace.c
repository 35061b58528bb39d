// model/render/trace.c — ray casting with Embree 3 over the scene's planar faces
// (thesis ch. 4: Embree replaces the polygon inside/outside test and the
// bounding spheres).
//
// Each face is triangulated in its own plane by ear clipping (non-convex faces
// work); primID -> face index is kept. Hit points are recomputed in double
// precision from the face's plane (Embree works in float), so a hit point lies
// on its face's plane to double precision.
//
// Spheres (D3D @sphere) are one Embree user geometry: bounds, intersection and
// occlusion callbacks solve the ray-sphere quadratic in double precision (in
// the numerically stable form). A primary hit of a sphere is recomputed from
// the double-precision ray, so the point lies on the sphere to rounding and the
// normal is the exact (p - c) / r. A sphere hit reports face = nfaces + k.
#include <embree3/rtcore.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

typedef struct {
    double c[3];    // centre, mm
    double r;       // radius, mm
    int    material;
} sphere_t;

struct model_tracer {
    RTCDevice     device;
    RTCScene      scene;
    int           nfaces;
    int           ntriangles;
    int           nspheres;
    sphere_t     *spheres;
    unsigned      tri_geom, sph_geom;   // Embree geometry ids (RTC_INVALID_GEOMETRY_ID: none)
    int          *prim_face;     // triangle -> face index
    model_vec3_t *face_normal;   // unit (Newell) normal of each face
    double       *face_offset;   // plane: normal . x = offset
    int32_t      *face_material;
    double        eps_mm;
    double        lo[3], hi[3];  // bounding box of the vertices (lo > hi: empty scene)
};

// ---------------------------------------------------------------------------
// Embree errors

static const char *rtc_error_name(enum RTCError e)
{
    switch (e) {
    case RTC_ERROR_NONE: return "no error";
    case RTC_ERROR_UNKNOWN: return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
    }
    return "unrecognised error";
}

static void rtc_error_cb(void *user, enum RTCError code, const char *str)
{
    (void)user;
    model_error("embree", 0, "%s: %s", rtc_error_name(code), str ? str : "");
}

// True (and an error message naming `what`) when the device reports an error.
static bool rtc_failed(RTCDevice dev, const char *what)
{
    enum RTCError e = rtcGetDeviceError(dev);
    if (e == RTC_ERROR_NONE) return false;
    model_error("embree", 0, "%s failed: %s (Embree 3, libembree3; check memory and CPU support)",
                what, rtc_error_name(e));
    return true;
}

// ---------------------------------------------------------------------------
// Triangulation of one planar polygon by ear clipping in its plane.

typedef struct { double u, w; } pt2_t;

static double cross2(pt2_t a, pt2_t b, pt2_t c)   // (b-a) x (c-b)
{
    return (b.u - a.u) * (c.w - b.w) - (b.w - a.w) * (c.u - b.u);
}

// p inside or on the border of the counter-clockwise triangle abc.
static bool in_triangle(pt2_t p, pt2_t a, pt2_t b, pt2_t c, double tol)
{
    double e0 = (b.u - a.u) * (p.w - a.w) - (b.w - a.w) * (p.u - a.u);
    double e1 = (c.u - b.u) * (p.w - b.w) - (c.w - b.w) * (p.u - b.u);
    double e2 = (a.u - c.u) * (p.w - c.w) - (a.w - c.w) * (p.u - c.u);
    return e0 >= -tol && e1 >= -tol && e2 >= -tol;
}

static bool same_pt(pt2_t a, pt2_t b) { return a.u == b.u && a.w == b.w; }

// Triangulates face f (m vertices) into tri (3*(m-2) scene vertex indices at
// most). Returns the number of triangles, or -1 when the polygon has no ear
// (self-intersecting).
static int triangulate_face(const model_scene_t *s, const model_face_t *f, int *local,
                            pt2_t *pts, unsigned *tri)
{
    int m = f->nverts;
    model_vec3_t n = f->normal;
    // An orthonormal basis (a, b) of the face's plane with a x b = n.
    model_vec3_t helper = fabs(n.x) < 0.6 ? v3(1, 0, 0) : v3(0, 1, 0);
    model_vec3_t a = v3_unit(v3_cross(helper, n));
    model_vec3_t b = v3_cross(n, a);
    double umin = INFINITY, umax = -INFINITY, wmin = INFINITY, wmax = -INFINITY;
    for (int k = 0; k < m; k++) {
        model_vec3_t x = s->vertices[f->verts[k]];
        pts[k] = (pt2_t){ v3_dot(x, a), v3_dot(x, b) };
        umin = fmin(umin, pts[k].u); umax = fmax(umax, pts[k].u);
        wmin = fmin(wmin, pts[k].w); wmax = fmax(wmax, pts[k].w);
    }
    double ext = fmax(umax - umin, wmax - wmin);
    double tol = 1e-12 * ext * ext;
    // Orientation: make the local order counter-clockwise in (a, b).
    double area2 = 0;
    for (int k = 0; k < m; k++) {
        pt2_t p = pts[k], q = pts[(k + 1) % m];
        area2 += p.u * q.w - q.u * p.w;
    }
    for (int k = 0; k < m; k++) local[k] = area2 >= 0 ? k : m - 1 - k;
    int count = m, ntri = 0;
    while (count > 3) {
        bool clipped = false;
        for (int i = 0; i < count && !clipped; i++) {
            int ia = local[(i + count - 1) % count], ib = local[i], ic = local[(i + 1) % count];
            pt2_t pa = pts[ia], pb = pts[ib], pc = pts[ic];
            if (cross2(pa, pb, pc) <= tol) continue;   // reflex or collinear
            bool ear = true;
            for (int j = 0; j < count && ear; j++) {
                int ij = local[j];
                if (ij == ia || ij == ib || ij == ic) continue;
                pt2_t pj = pts[ij];
                if (same_pt(pj, pa) || same_pt(pj, pb) || same_pt(pj, pc)) continue;
                if (in_triangle(pj, pa, pb, pc, tol)) ear = false;
            }
            if (!ear) continue;
            tri[3 * ntri + 0] = (unsigned)f->verts[ia];
            tri[3 * ntri + 1] = (unsigned)f->verts[ib];
            tri[3 * ntri + 2] = (unsigned)f->verts[ic];
            ntri++;
            memmove(&local[i], &local[i + 1], (size_t)(count - i - 1) * sizeof *local);
            count--;
            clipped = true;
        }
        if (clipped) continue;
        // No ear: drop a collinear (zero-area) vertex if there is one.
        for (int i = 0; i < count && !clipped; i++) {
            int ia = local[(i + count - 1) % count], ib = local[i], ic = local[(i + 1) % count];
            if (fabs(cross2(pts[ia], pts[ib], pts[ic])) <= tol) {
                memmove(&local[i], &local[i + 1], (size_t)(count - i - 1) * sizeof *local);
                count--;
                clipped = true;
            }
        }
        if (!clipped) return -1;
    }
    if (count == 3 && cross2(pts[local[0]], pts[local[1]], pts[local[2]]) > tol) {
        tri[3 * ntri + 0] = (unsigned)f->verts[local[0]];
        tri[3 * ntri + 1] = (unsigned)f->verts[local[1]];
        tri[3 * ntri + 2] = (unsigned)f->verts[local[2]];
        ntri++;
    }
    return ntri;
}

// ---------------------------------------------------------------------------
// Spheres

// The roots t0 <= t1 of |o + t d - c| = r (d need not be unit). False when the
// line misses the sphere. Stable form: the discriminant from the distance of
// the line to the centre, the far root from the product of the roots.
static bool sphere_roots(const sphere_t *s, const double o[3], const double d[3], double *t0,
                         double *t1)
{
    double oc[3] = { o[0] - s->c[0], o[1] - s->c[1], o[2] - s->c[2] };
    double a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if (!(a > 0)) return false;
    double b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    double l2 = 0, oc2 = 0;
    for (int k = 0; k < 3; k++) {
        double lk = oc[k] - (b / a) * d[k];   // from the centre to the closest point of the line
        l2 += lk * lk;
        oc2 += oc[k] * oc[k];
    }
    double h = s->r * s->r - l2;
    if (!(h >= 0)) return false;
    double sq = sqrt(a * h);
    double q = -(b + copysign(sq, b));
    if (q == 0) {
        *t0 = *t1 = -b / a;
        return true;
    }
    double ta = q / a, tb = (oc2 - s->r * s->r) / q;
    *t0 = fmin(ta, tb);
    *t1 = fmax(ta, tb);
    return true;
}

// Accessors of Embree's ray packets of runtime size N (rtcore_ray.h's helpers
// are C++ only): float slot `field` of lane i.
#define RAYN_F(ray, N, field, i) (((float *)(ray))[(field) * (N) + (i)])
#define RAYN_U(ray, N, field, i) (((unsigned *)(ray))[(field) * (N) + (i)])
enum { RF_ORG = 0, RF_TNEAR = 3, RF_DIR = 4, RF_TFAR = 8 };
enum { HF_NG = 0, HF_U = 3, HF_V = 4, HF_PRIM = 5, HF_GEOM = 6, HF_INST = 7 };

static void sphere_bounds_cb(const struct RTCBoundsFunctionArguments *args)
{
    const model_tracer_t *t = args->geometryUserPtr;
    const sphere_t *s = &t->spheres[args->primID];
    float lo[3], hi[3];
    for (int k = 0; k < 3; k++) {
        lo[k] = nextafterf((float)(s->c[k] - s->r), -INFINITY);
        hi[k] = nextafterf((float)(s->c[k] + s->r), INFINITY);
    }
    args->bounds_o->lower_x = lo[0];
    args->bounds_o->lower_y = lo[1];
    args->bounds_o->lower_z = lo[2];
    args->bounds_o->upper_x = hi[0];
    args->bounds_o->upper_y = hi[1];
    args->bounds_o->upper_z = hi[2];
}

// The root of lane i's ray within [tnear, tfar], nearest first; false if none.
static bool sphere_lane(const sphere_t *s, void *ray, unsigned N, unsigned i, double *t)
{
    double o[3], d[3];
    for (int k = 0; k < 3; k++) {
        o[k] = RAYN_F(ray, N, RF_ORG + k, i);
        d[k] = RAYN_F(ray, N, RF_DIR + k, i);
    }
    double tn = RAYN_F(ray, N, RF_TNEAR, i), tf = RAYN_F(ray, N, RF_TFAR, i);
    double t0, t1;
    if (!sphere_roots(s, o, d, &t0, &t1)) return false;
    if (t0 >= tn && t0 <= tf) *t = t0;
    else if (t1 >= tn && t1 <= tf) *t = t1;
    else return false;
    return true;
}

static void sphere_intersect_cb(const struct RTCIntersectFunctionNArguments *args)
{
    const model_tracer_t *t = args->geometryUserPtr;
    const sphere_t *s = &t->spheres[args->primID];
    unsigned N = args->N;
    void *ray = args->rayhit;
    float *hit = (float *)args->rayhit + 12 * N;
    for (unsigned i = 0; i < N; i++) {
        if (!args->valid[i]) continue;
        double tt;
        if (!sphere_lane(s, ray, N, i, &tt)) continue;
        float tf = (float)tt;
        if (!(tf <= RAYN_F(ray, N, RF_TFAR, i))) continue;
        RAYN_F(ray, N, RF_TFAR, i) = tf;
        for (int k = 0; k < 3; k++)
            RAYN_F(hit, N, HF_NG + k, i) =
                (float)(RAYN_F(ray, N, RF_ORG + k, i) + tt * RAYN_F(ray, N, RF_DIR + k, i) - s->c[k]);
        RAYN_F(hit, N, HF_U, i) = 0.0f;
        RAYN_F(hit, N, HF_V, i) = 0.0f;
        RAYN_U(hit, N, HF_PRIM, i) = args->primID;
        RAYN_U(hit, N, HF_GEOM, i) = args->geomID;
        RAYN_U(hit, N, HF_INST, i) = args->context->instID[0];
    }
}

static void sphere_occluded_cb(const struct RTCOccludedFunctionNArguments *args)
{
    const model_tracer_t *t = args->geometryUserPtr;
    const sphere_t *s = &t->spheres[args->primID];
    unsigned N = args->N;
    for (unsigned i = 0; i < N; i++) {
        if (!args->valid[i]) continue;
        double tt;
        if (sphere_lane(s, args->ray, N, i, &tt)) RAYN_F(args->ray, N, RF_TFAR, i) = -INFINITY;
    }
}

// ---------------------------------------------------------------------------

// The scene's spheres, checked, copied into t->spheres.
static bool tracer_spheres(model_tracer_t *t, const model_scene_t *scene, const char *where)
{
    t->spheres = malloc((size_t)(scene->nspheres + 1) * sizeof *t->spheres);
    if (!t->spheres) {
        model_error(where, 0, "out of memory building the ray tracer");
        return false;
    }
    for (int i = 0; i < scene->nspheres; i++) {
        const model_sphere_t *sp = &scene->spheres[i];
        model_vec3_t c = sp->centre_mm;
        if (!isfinite(c.x) || !isfinite(c.y) || !isfinite(c.z) || !isfinite(sp->radius_mm) ||
            !(sp->radius_mm > 0)) {
            model_error(where, sp->line, "sphere %d: centre (%g, %g, %g) mm, radius %g mm: give a "
                        "finite centre and a radius > 0", i + 1, c.x, c.y, c.z, sp->radius_mm);
            return false;
        }
        t->spheres[i] = (sphere_t){ { c.x, c.y, c.z }, sp->radius_mm, sp->material };
    }
    t->nspheres = scene->nspheres;
    return true;
}

// Every face has at least 3 vertices, all of the scene; *maxv: the most
// vertices of a face (at least 3), *maxtri: the triangles of all faces.
static bool tracer_check_faces(const model_scene_t *scene, const char *where, int *maxv, int *maxtri)
{
    *maxv = 3;
    *maxtri = 0;
    for (int i = 0; i < scene->nfaces; i++) {
        const model_face_t *f = &scene->faces[i];
        if (f->nverts < 3) {
            model_error(where, f->line, "face %d has %d vertices; a face needs at least 3",
                        f->number, f->nverts);
            return false;
        }
        for (int k = 0; k < f->nverts; k++)
            if (f->verts[k] < 0 || f->verts[k] >= scene->nvertices) {
                model_error(where, f->line, "face %d refers to vertex index %d, outside 0..%d",
                            f->number, f->verts[k], scene->nvertices - 1);
                return false;
            }
        if (f->nverts > *maxv) *maxv = f->nverts;
        *maxtri += f->nverts - 2;
    }
    return true;
}

// The bounding box of the vertices and spheres, and from the scene's size
// the epsilon of secondary rays.
static bool tracer_bounds(model_tracer_t *t, const model_scene_t *scene, const char *where)
{
    double lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
    double maxabs = 0;
    for (int i = 0; i < scene->nvertices; i++) {
        model_vec3_t x = scene->vertices[i];
        double c[3] = { x.x, x.y, x.z };
        for (int k = 0; k < 3; k++) {
            if (!isfinite(c[k])) {
                model_error(where, 0, "vertex %d has a non-finite coordinate", i + 1);
                return false;
            }
            lo[k] = fmin(lo[k], c[k]);
            hi[k] = fmax(hi[k], c[k]);
            maxabs = fmax(maxabs, fabs(c[k]));
        }
    }
    for (int i = 0; i < t->nspheres; i++)
        for (int k = 0; k < 3; k++) {
            const sphere_t *sp = &t->spheres[i];
            lo[k] = fmin(lo[k], sp->c[k] - sp->r);
            hi[k] = fmax(hi[k], sp->c[k] + sp->r);
            maxabs = fmax(maxabs, fabs(sp->c[k]) + sp->r);
        }
    double diag = lo[0] <= hi[0] ? sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) +
                                          (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                                          (hi[2] - lo[2]) * (hi[2] - lo[2]))
                                   : 1.0;
    t->eps_mm = 4e-6 * (diag + maxabs) + 1e-9;
    for (int k = 0; k < 3; k++) {
        t->lo[k] = lo[k];
        t->hi[k] = hi[k];
    }
    return true;
}

// Each face's plane and material, and its triangles (3 vertex indices each)
// into tris, t->prim_face their faces; local and pts: scratch of the most
// vertices of a face. The number of triangles, or -1 + message.
static int tracer_triangulate(model_tracer_t *t, const model_scene_t *scene, const char *where, int *local,
                              pt2_t *pts, unsigned *tris)
{
    int ntri = 0;
    for (int i = 0; i < scene->nfaces; i++) {
        const model_face_t *f = &scene->faces[i];
        t->face_normal[i] = f->normal;
        t->face_offset[i] = f->offset_mm;
        t->face_material[i] = f->material;
        if (!(v3_norm(f->normal) > 0.5)) continue;   // degenerate (zero-area) face: nothing to hit
        int k = triangulate_face(scene, f, local, pts, tris + 3 * ntri);
        if (k < 0) {
            model_error(where, f->line,
                        "face %d cannot be triangulated (its outline crosses itself?); "
                        "fix the order of its vertices", f->number);
            return -1;
        }
        for (int j = 0; j < k; j++) t->prim_face[ntri + j] = i;
        ntri += k;
    }
    return ntri;
}

// The Embree device and scene: the triangle mesh (ntri triangles tris over
// the scene's vertices) and the spheres' user geometry, committed.
static bool tracer_embree(model_tracer_t *t, const model_scene_t *scene, const unsigned *tris, int ntri)
{
    RTCGeometry geom = NULL;
    bool ok = false;
    t->device = rtcNewDevice(NULL);
    if (!t->device) {
        model_error("embree", 0, "rtcNewDevice failed: %s (is libembree3 usable on this CPU?)",
                    rtc_error_name(rtcGetDeviceError(NULL)));
        goto done;
    }
    rtcSetDeviceErrorFunction(t->device, rtc_error_cb, NULL);
    t->scene = rtcNewScene(t->device);
    if (!t->scene || rtc_failed(t->device, "rtcNewScene")) goto done;
    rtcSetSceneFlags(t->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(t->scene, RTC_BUILD_QUALITY_HIGH);
    if (ntri > 0) {
        geom = rtcNewGeometry(t->device, RTC_GEOMETRY_TYPE_TRIANGLE);
        if (!geom || rtc_failed(t->device, "rtcNewGeometry")) goto done;
        float *vb = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                            3 * sizeof(float), (size_t)scene->nvertices);
        unsigned *ib = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                               3 * sizeof(unsigned), (size_t)ntri);
        if (!vb || !ib || rtc_failed(t->device, "rtcSetNewGeometryBuffer")) goto done;
        for (int i = 0; i < scene->nvertices; i++) {
            vb[3 * i + 0] = (float)scene->vertices[i].x;
            vb[3 * i + 1] = (float)scene->vertices[i].y;
            vb[3 * i + 2] = (float)scene->vertices[i].z;
        }
        memcpy(ib, tris, (size_t)ntri * 3 * sizeof *ib);
        rtcCommitGeometry(geom);
        t->tri_geom = rtcAttachGeometry(t->scene, geom);
        rtcReleaseGeometry(geom);
        geom = NULL;
        if (rtc_failed(t->device, "building the triangle mesh")) goto done;
    }
    if (t->nspheres > 0) {
        geom = rtcNewGeometry(t->device, RTC_GEOMETRY_TYPE_USER);
        if (!geom || rtc_failed(t->device, "rtcNewGeometry (spheres)")) goto done;
        rtcSetGeometryUserPrimitiveCount(geom, (unsigned)t->nspheres);
        rtcSetGeometryUserData(geom, t);
        rtcSetGeometryBoundsFunction(geom, sphere_bounds_cb, NULL);
        rtcSetGeometryIntersectFunction(geom, sphere_intersect_cb);
        rtcSetGeometryOccludedFunction(geom, sphere_occluded_cb);
        rtcCommitGeometry(geom);
        t->sph_geom = rtcAttachGeometry(t->scene, geom);
        rtcReleaseGeometry(geom);
        geom = NULL;
        if (rtc_failed(t->device, "building the spheres")) goto done;
    }
    rtcCommitScene(t->scene);
    if (rtc_failed(t->device, "rtcCommitScene")) goto done;
    ok = true;
done:
    if (geom) rtcReleaseGeometry(geom);
    return ok;
}

model_tracer_t *model_tracer_new(const model_scene_t *scene)
{
    model_tracer_t *t = NULL;
    int *local = NULL;
    pt2_t *pts = NULL;
    unsigned *tris = NULL;
    bool ok = false;
    const char *where = scene && scene->path ? scene->path : "scene";

    if (!scene || scene->nfaces < 0 || scene->nvertices < 0 || scene->nspheres < 0 ||
        (scene->nspheres > 0 && !scene->spheres)) {
        MODEL_FAIL("model_tracer_new: no scene");
        return NULL;
    }
    t = calloc(1, sizeof *t);
    if (!t) goto oom;
    t->nfaces = scene->nfaces;
    t->tri_geom = t->sph_geom = RTC_INVALID_GEOMETRY_ID;
    if (scene->nspheres > INT32_MAX - scene->nfaces) {
        model_error(where, 0, "too many faces and spheres (%d + %d)", scene->nfaces, scene->nspheres);
        goto done;
    }
    if (!tracer_spheres(t, scene, where)) goto done;
    int maxv, maxtri;
    if (!tracer_check_faces(scene, where, &maxv, &maxtri)) goto done;
    t->face_normal = malloc((size_t)(scene->nfaces + 1) * sizeof *t->face_normal);
    t->face_offset = malloc((size_t)(scene->nfaces + 1) * sizeof *t->face_offset);
    t->face_material = malloc((size_t)(scene->nfaces + 1) * sizeof *t->face_material);
    t->prim_face = malloc((size_t)(maxtri + 1) * sizeof *t->prim_face);
    tris = malloc((size_t)(3 * maxtri + 3) * sizeof *tris);
    local = malloc((size_t)maxv * sizeof *local);
    pts = malloc((size_t)maxv * sizeof *pts);
    if (!t->face_normal || !t->face_offset || !t->face_material || !t->prim_face || !tris ||
        !local || !pts)
        goto oom;
    if (!tracer_bounds(t, scene, where)) goto done;
    int ntri = tracer_triangulate(t, scene, where, local, pts, tris);
    if (ntri < 0) goto done;
    t->ntriangles = ntri;
    ok = tracer_embree(t, scene, tris, ntri);
    goto done;
oom:
    model_error(where, 0, "out of memory building the ray tracer");
done:
    free(local);
    free(pts);
    free(tris);
    if (!ok) {
        model_tracer_free(t);
        return NULL;
    }
    return t;
}

void model_tracer_free(model_tracer_t *t)
{
    if (!t) return;
    if (t->scene) rtcReleaseScene(t->scene);
    if (t->device) rtcReleaseDevice(t->device);
    free(t->prim_face);
    free(t->face_normal);
    free(t->face_offset);
    free(t->face_material);
    free(t->spheres);
    free(t);
}

double model_tracer_epsilon_mm(const model_tracer_t *t) { return t->eps_mm; }

// Fill out from a hit of face f at Embree distance tfar along (o, dir).
static inline void fill_hit(const model_tracer_t *t, model_vec3_t o, model_vec3_t dir, int f,
                            double tfar, model_pixel_info_t *out)
{
    model_vec3_t n = t->face_normal[f];
    double den = v3_dot(n, dir);
    double tt = tfar;
    if (fabs(den) > 1e-9) {
        double tp = (t->face_offset[f] - v3_dot(n, o)) / den;
        if (tp > 0) tt = tp;
    }
    out->face = f;
    out->material = t->face_material[f];
    out->p_mm = v3_add(o, v3_scale(dir, tt));
    out->n = den > 0 ? v3_scale(n, -1) : n;
    out->v = v3_scale(dir, -1);
    out->range_mm = tt;
}

static inline void fill_miss(model_vec3_t dir, model_pixel_info_t *out);

// Fill out from a hit of sphere k at Embree distance tfar along (o, dir): the
// root of the double-precision ray nearest to Embree's (float) one.
static void fill_sphere_hit(const model_tracer_t *t, model_vec3_t o, model_vec3_t dir, int k,
                            double tfar, model_pixel_info_t *out)
{
    const sphere_t *s = &t->spheres[k];
    double od[3] = { o.x, o.y, o.z }, dd[3] = { dir.x, dir.y, dir.z };
    double t0, t1, tt = tfar;
    model_vec3_t c = v3(s->c[0], s->c[1], s->c[2]);
    model_vec3_t p;
    if (sphere_roots(s, od, dd, &t0, &t1)) {
        if (t0 >= 0 && (t1 < 0 || fabs(t0 - tfar) <= fabs(t1 - tfar))) tt = t0;
        else if (t1 >= 0) tt = t1;
        p = v3_add(o, v3_scale(dir, tt));
    } else {
        // Grazing: Embree's float ray touched the sphere, the double one passes by.
        p = v3_add(c, v3_scale(v3_unit(v3_sub(v3_add(o, v3_scale(dir, tt)), c)), s->r));
        tt = v3_dot(v3_sub(p, o), dir);
    }
    model_vec3_t n = v3_scale(v3_sub(p, c), 1.0 / s->r);
    double nn = v3_norm(n);
    if (nn > 0) n = v3_scale(n, 1.0 / nn);
    out->face = t->nfaces + k;
    out->material = s->material;
    out->p_mm = p;
    out->n = v3_dot(n, dir) > 0 ? v3_scale(n, -1) : n;
    out->v = v3_scale(dir, -1);
    out->range_mm = tt;
}

// Fill out from Embree's hit (geomID, primID) at distance tfar.
static inline void fill_any(const model_tracer_t *t, model_vec3_t o, model_vec3_t dir,
                            unsigned geom, unsigned prim, double tfar, model_pixel_info_t *out)
{
    if (geom == RTC_INVALID_GEOMETRY_ID) fill_miss(dir, out);
    else if (geom == t->tri_geom && prim < (unsigned)t->ntriangles)
        fill_hit(t, o, dir, t->prim_face[prim], tfar, out);
    else if (geom == t->sph_geom && prim < (unsigned)t->nspheres)
        fill_sphere_hit(t, o, dir, (int)prim, tfar, out);
    else
        fill_miss(dir, out);
}

static inline void fill_miss(model_vec3_t dir, model_pixel_info_t *out)
{
    out->face = -1;
    out->material = -1;
    out->p_mm = v3(0, 0, 0);
    out->n = v3(0, 0, 0);
    out->v = v3_scale(dir, -1);
    out->range_mm = 0;
}

void model_tracer_cast(const model_tracer_t *t, model_vec3_t origin, model_vec3_t dir,
                       model_pixel_info_t *out)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rh.ray.org_x = (float)origin.x;
    rh.ray.org_y = (float)origin.y;
    rh.ray.org_z = (float)origin.z;
    rh.ray.dir_x = (float)dir.x;
    rh.ray.dir_y = (float)dir.y;
    rh.ray.dir_z = (float)dir.z;
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = INFINITY;
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(t->scene, &ctx, &rh);
    fill_any(t, origin, dir, rh.hit.geomID, rh.hit.primID, rh.ray.tfar, out);
}

// Occlusion of the segment org + s*dir, s in [tnear, tfar].
static bool occluded1(const model_tracer_t *t, model_vec3_t org, model_vec3_t dir, double tnear,
                      double tfar)
{
    if (!(tfar > tnear)) return false;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay r;
    r.org_x = (float)org.x;
    r.org_y = (float)org.y;
    r.org_z = (float)org.z;
    r.dir_x = (float)dir.x;
    r.dir_y = (float)dir.y;
    r.dir_z = (float)dir.z;
    r.tnear = (float)tnear;
    r.tfar = (float)tfar;
    r.time = 0.0f;
    r.mask = 0xffffffffu;
    r.id = 0;
    r.flags = 0;
    rtcOccluded1(t->scene, &ctx, &r);
    return r.tfar == -INFINITY;
}

bool model_tracer_visible(const model_tracer_t *t, model_vec3_t p, model_vec3_t target)
{
    model_vec3_t d = v3_sub(target, p);
    double len = v3_norm(d);
    if (!(len > 2 * t->eps_mm)) return true;
    return !occluded1(t, p, v3_scale(d, 1.0 / len), t->eps_mm, len - t->eps_mm);
}

bool model_tracer_visible_from(const model_tracer_t *t, model_vec3_t p, model_vec3_t nrm,
                               model_vec3_t target)
{
    model_vec3_t o = v3_add(p, v3_scale(nrm, t->eps_mm));
    model_vec3_t d = v3_sub(target, o);
    double len = v3_norm(d);
    if (!(len > t->eps_mm)) return true;
    return !occluded1(t, o, v3_scale(d, 1.0 / len), 0.0, len - t->eps_mm);
}

// True when no ray origin + s dirs[k] (s >= 0, dirs unit) can reach the
// bounding box. Conservative: with c the mean direction and chord = max |dirs[k] - c|,
// ray k at distance s is within s * chord of the central ray's point at s, so
// a ray that meets the box at s <= smax means the central ray meets the box
// grown by smax * chord (smax: farthest box corner from the origin).
bool model_tracer_rays_miss(const model_tracer_t *t, model_vec3_t o, const model_vec3_t *dirs,
                            int n)
{
    if (!(t->lo[0] <= t->hi[0])) return true;   // empty scene
    model_vec3_t c = v3(0, 0, 0);
    for (int k = 0; k < n; k++) c = v3_add(c, dirs[k]);
    double cn = v3_norm(c);
    if (!(cn > 0.5 * n)) return false;   // rays too spread for the test
    c = v3_scale(c, 1.0 / cn);
    double chord2 = 0;
    for (int k = 0; k < n; k++) {
        model_vec3_t e = v3_sub(dirs[k], c);
        double e2 = v3_dot(e, e);
        if (e2 > chord2) chord2 = e2;
    }
    double oc[3] = { o.x, o.y, o.z }, dc[3] = { c.x, c.y, c.z };
    double smax2 = 0;
    for (int k = 0; k < 3; k++) {
        double a = fmax(fabs(oc[k] - t->lo[k]), fabs(oc[k] - t->hi[k]));
        smax2 += a * a;
    }
    double grow = sqrt(smax2 * chord2) * (1 + 1e-6) + t->eps_mm;
    double s0 = 0, s1 = INFINITY;
    for (int k = 0; k < 3; k++) {
        double lo = t->lo[k] - grow, hi = t->hi[k] + grow;
        if (dc[k] == 0) {
            if (oc[k] < lo || oc[k] > hi) return true;
            continue;
        }
        double a = (lo - oc[k]) / dc[k], b = (hi - oc[k]) / dc[k];
        if (a > b) {
            double tmp = a;
            a = b;
            b = tmp;
        }
        if (a > s0) s0 = a;
        if (b < s1) s1 = b;
        if (s0 > s1) return true;
    }
    return false;
}

int model_tracer_cast_packet(const model_tracer_t *t, model_vec3_t origin,
                             const model_vec3_t *dirs, int n, model_pixel_info_t *out)
{
    if (n <= 0) return 0;
    if (n > MODEL_TRACER_PACKET) n = MODEL_TRACER_PACKET;
    if (model_tracer_rays_miss(t, origin, dirs, n)) {
        for (int k = 0; k < n; k++) fill_miss(dirs[k], &out[k]);
        return 0;
    }
    RTC_ALIGN(64) struct RTCRayHit16 rh;
    RTC_ALIGN(64) int valid[16];
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    float ox = (float)origin.x, oy = (float)origin.y, oz = (float)origin.z;
    for (int k = 0; k < 16; k++) {
        int kk = k < n ? k : 0;
        valid[k] = k < n ? -1 : 0;
        rh.ray.org_x[k] = ox;
        rh.ray.org_y[k] = oy;
        rh.ray.org_z[k] = oz;
        rh.ray.dir_x[k] = (float)dirs[kk].x;
        rh.ray.dir_y[k] = (float)dirs[kk].y;
        rh.ray.dir_z[k] = (float)dirs[kk].z;
        rh.ray.tnear[k] = 0.0f;
        rh.ray.tfar[k] = INFINITY;
        rh.ray.time[k] = 0.0f;
        rh.ray.mask[k] = 0xffffffffu;
        rh.ray.id[k] = (unsigned)k;
        rh.ray.flags[k] = 0;
        rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID[k] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect16(valid, t->scene, &ctx, &rh);
    int nhit = 0;
    for (int k = 0; k < n; k++) {
        fill_any(t, origin, dirs[k], rh.hit.geomID[k], rh.hit.primID[k], rh.ray.tfar[k], &out[k]);
        if (out[k].face >= 0) nhit++;
    }
    return nhit;
}

void model_tracer_visible_packet(const model_tracer_t *t, const model_shadow_packet_t *sp,
                                 uint8_t vis[MODEL_TRACER_PACKET])
{
    RTC_ALIGN(64) struct RTCRay16 r;
    RTC_ALIGN(64) int valid[16];
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    int nvalid = 0;
    for (int k = 0; k < 16; k++) {
        bool on = sp->active[k] && sp->tfar[k] > 0;
        valid[k] = on ? -1 : 0;
        nvalid += on;
        r.org_x[k] = sp->org_x[k];
        r.org_y[k] = sp->org_y[k];
        r.org_z[k] = sp->org_z[k];
        r.dir_x[k] = sp->dir_x[k];
        r.dir_y[k] = sp->dir_y[k];
        r.dir_z[k] = sp->dir_z[k];
        r.tnear[k] = 0.0f;
        r.tfar[k] = on ? sp->tfar[k] : -INFINITY;
        r.time[k] = 0.0f;
        r.mask[k] = 0xffffffffu;
        r.id[k] = (unsigned)k;
        r.flags[k] = 0;
    }
    if (nvalid) rtcOccluded16(valid, t->scene, &ctx, &r);
    for (int k = 0; k < 16; k++) vis[k] = valid[k] && r.tfar[k] != -INFINITY;
}

// ---------------------------------------------------------------------------
// pixel_info for a sparse list of pixel positions.

typedef struct {
    const model_tracer_t *t;
    const model_camera_t *cam;
    const model_lamps_t  *lamps;
    const double         *q;
    model_pixel_info_t   *out;
    model_lamp_sample_t  *lamp_out;
    model_vec3_t          centre;
    const model_vec3_t   *table;        // the ray table (model_pixel_info_table), or NULL: exact unprojection
    int                   W, H;
    atomic_bool           failed;
    char                  err[1024];
} pinfo_ctx_t;

// The ray through pixel position (x, y) from the ray table: bilinear between
// the four pixel centres around it (clamped to the imager).
static model_vec3_t table_ray(const model_vec3_t *tab, int W, int H, double x, double y)
{
    int x0 = (int)floor(x), y0 = (int)floor(y);
    if (x0 < 0) x0 = 0;
    if (y0 < 0) y0 = 0;
    if (x0 > W - 2) x0 = W - 2;
    if (y0 > H - 2) y0 = H - 2;
    double fx = x - x0, fy = y - y0;
    const model_vec3_t *r = tab + (size_t)y0 * W + x0;
    return v3_add(v3_add(v3_scale(r[0], (1 - fx) * (1 - fy)), v3_scale(r[1], fx * (1 - fy))),
                  v3_add(v3_scale(r[W], (1 - fx) * fy), v3_scale(r[W + 1], fx * fy)));
}

#define PINFO_CHUNK 256

static void pinfo_worker(void *vctx, int begin, int end, int thread)
{
    pinfo_ctx_t *c = vctx;
    (void)thread;
    model_vec3_t dirs[PINFO_CHUNK];
    int nl = c->lamps ? c->lamps->n : 0;
    for (int b = begin; b < end; b += PINFO_CHUNK) {
        int m = end - b < PINFO_CHUNK ? end - b : PINFO_CHUNK;
        if (atomic_load(&c->failed)) return;
        if (c->table) {
            for (int k = 0; k < m; k++)
                dirs[k] = table_ray(c->table, c->W, c->H, c->q[2 * (size_t)(b + k)], c->q[2 * (size_t)(b + k) + 1]);
        } else if (!model_camera_unproject(c->cam, c->q + 2 * (size_t)b, m, dirs)) {
            if (!atomic_exchange(&c->failed, true))
                snprintf(c->err, sizeof c->err, "%s", model_last_error());
            return;
        }
        for (int k = 0; k < m; k++) {
            int i = b + k;
            model_pixel_info_t *pi = &c->out[i];
            model_tracer_cast(c->t, c->centre, v3_unit(dirs[k]), pi);
            pi->q[0] = c->q[2 * (size_t)i];
            pi->q[1] = c->q[2 * (size_t)i + 1];
            if (!c->lamp_out) continue;
            for (int j = 0; j < nl; j++) {
                model_lamp_sample_t *ls = &c->lamp_out[(size_t)i * nl + j];
                if (pi->face < 0) {
                    *ls = (model_lamp_sample_t){ v3(0, 0, 0), 0.0, 0.0 };
                    continue;
                }
                model_vec3_t L = v3_sub(c->lamps->lamps[j].position_mm, pi->p_mm);
                double d = v3_norm(L);
                ls->d_mm = d;
                ls->l = d > 0 ? v3_scale(L, 1.0 / d) : v3(0, 0, 0);
                ls->V = v3_dot(ls->l, pi->n) > 0 &&
                                model_tracer_visible_from(c->t, pi->p_mm, pi->n,
                                                          c->lamps->lamps[j].position_mm)
                            ? 1.0
                            : 0.0;
            }
        }
    }
}

static bool pixel_info_run(const model_tracer_t *t, const model_camera_t *cam, const model_vec3_t *table,
                           const model_lamps_t *lamps, const double *q_xy, int n, model_pixel_info_t *out,
                           model_lamp_sample_t *lamp_out, int nthreads);

bool model_pixel_info(const model_tracer_t *t, const model_camera_t *cam,
                      const model_lamps_t *lamps, const double *q_xy, int n,
                      model_pixel_info_t *out, model_lamp_sample_t *lamp_out, int nthreads)
{
    return pixel_info_run(t, cam, NULL, lamps, q_xy, n, out, lamp_out, nthreads);
}

bool model_pixel_info_table(const model_tracer_t *t, model_camera_t *cam, const model_lamps_t *lamps,
                            const double *q_xy, int n, model_pixel_info_t *out, model_lamp_sample_t *lamp_out,
                            int nthreads)
{
    const model_vec3_t *table = cam ? model_camera_ray_table(cam, NULL) : NULL;
    if (cam && !table) return false;
    return pixel_info_run(t, cam, table, lamps, q_xy, n, out, lamp_out, nthreads);
}

static bool pixel_info_run(const model_tracer_t *t, const model_camera_t *cam, const model_vec3_t *table,
                           const model_lamps_t *lamps, const double *q_xy, int n, model_pixel_info_t *out,
                           model_lamp_sample_t *lamp_out, int nthreads)
{
    if (!t || !cam || (n > 0 && (!q_xy || !out)) || n < 0) {
        MODEL_FAIL("model_pixel_info: missing tracer, camera, pixel list or output");
        return false;
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(q_xy[2 * (size_t)i]) || !isfinite(q_xy[2 * (size_t)i + 1])) {
            MODEL_FAIL("model_pixel_info: pixel %d has a non-finite coordinate", i);
            return false;
        }
    pinfo_ctx_t *c = calloc(1, sizeof *c);
    if (!c) {
        MODEL_FAIL("out of memory");
        return false;
    }
    c->t = t;
    c->cam = cam;
    c->lamps = lamps;
    c->q = q_xy;
    c->out = out;
    c->lamp_out = lamp_out;
    c->centre = model_camera_centre_world(cam);
    c->table = table;
    c->W = model_camera_width(cam);
    c->H = model_camera_height(cam);
    atomic_init(&c->failed, false);
    if (nthreads <= 0) nthreads = model_default_threads();
    model_parallel_for(n, PINFO_CHUNK, nthreads, pinfo_worker, c);
    bool ok = !atomic_load(&c->failed);
    if (!ok) model_error(NULL, 0, "%s", c->err);
    free(c);
    return ok;
}
