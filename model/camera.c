// model/camera.c — cameras: an mrcal camera model (libmrcal 2.2) plus a cached
// ray table.
//
// Frames: the world frame is mrcal's "ref" frame, so the model's rt_cam_ref is
// rt_cam_world (translation in mm): p_cam = R_cam_world p_world + t_cam_world.
//
// The ray table (model_camera_ray_table)
// - The exact unprojection (mrcal_unproject, an iterative solve per pixel) is
//   evaluated on a coarse grid of nodes spanning the imager exactly: nx x ny
//   cells from pixel 0 to width-1 and from 0 to height-1 (node spacing
//   (width-1)/nx, at most INITIAL_STEP_PX to start with).
// - Interpolated quantity: a smooth 2D function of the pixel. For models built on
//   a pinhole projection (pinhole, OpenCV, CAHVOR) the normalised image
//   coordinates (x/z, y/z) of the camera-frame ray, which are exactly linear in
//   the pixel for a pinhole lens; for the others (stereographic, splined
//   stereographic, lon/lat) the stereographic coordinates 2 (x,y) / (1 + z) of
//   the unit ray. It is interpolated with a tensor-product Catmull-Rom cubic
//   (C1, error O(step^3)); nodes beyond the imager are extrapolated
//   quadratically from the three nearest nodes, never unprojected. The result
//   is turned back into a unit ray and rotated to the world frame.
// - Refinement: the interpolated rays are projected back with the lens model
//   (mrcal_project, cheap) at the points of a grid four times finer than the
//   nodes (cell centres, edge midpoints, quarter points); while the largest
//   reprojection error there exceeds 0.8 RAY_TOL_PX the node spacing is halved (the
//   new nodes are unprojected exactly). When it passes, the table is filled and
//   the reprojection error of EVERY pixel of the table is measured; its maximum
//   is the bound returned through *err_px. Should that exceed the tolerance the
//   refinement continues. If the spacing would drop below 1 px the table is the
//   exact unprojection of every pixel (and the bound its measured error).
// - Everything runs on model_default_threads() threads; the table is built once
//   per camera under a mutex and kept until model_camera_free().
#define _GNU_SOURCE
#include <errno.h>
#include <limits.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/cameramodel.h"
#include "model/internal.h"

#define RAY_TOL_PX      0.005   // required reprojection error of the ray table
#define INITIAL_STEP_PX 32.0    // largest node spacing of the first grid
#define MAX_IMAGER_SIDE 65535   // sanity limit on width and height

struct model_camera {
    mrcal_cameramodel_t *m;          // our copy (header + intrinsics)
    int                  nintrinsics;
    char                 lensmodel[256];   // the configured mrcal name
    char                 sha256[65];
    char                *name;       // the file, or a description, for messages
    double               R_cam_world[9];   // row-major; R_world_cam is its transpose
    double               R_world_cam[9];
    double               t_cam_world[3];   // mm
    model_vec3_t         centre_world;     // camera centre, mm
    bool                 stereographic;    // ray table: interpolate stereographic coordinates

    pthread_mutex_t      lock;       // guards the ray table
    model_vec3_t        *rays;       // width*height, or NULL until built
    double               rays_err_px;
};

// ---------------------------------------------------------------------------
// Construction

// Checks and derived quantities common to load and new. Takes ownership of m.
static model_camera_t *camera_from_model(mrcal_cameramodel_t *m, const char *name,
                                         const char *sha256)
{
    model_camera_t *cam = NULL;
    mrcal_lensmodel_t *lm = &m->lensmodel;
    char lname[256];

    if (!mrcal_lensmodel_type_is_valid(lm->type) ||
        !mrcal_lensmodel_name(lname, sizeof lname, lm)) {
        model_error(name, 0, "invalid lens model (see mrcal's list of lens models)");
        goto fail;
    }
    if (lm->type == MRCAL_LENSMODEL_CAHVORE) {
        model_error(name, 0, "lens model %s is not supported: mrcal cannot unproject it; "
                    "recalibrate with LENSMODEL_OPENCV8 or a splined model", lname);
        goto fail;
    }
    if (m->imagersize[0] == 0 || m->imagersize[1] == 0 ||
        m->imagersize[0] > MAX_IMAGER_SIDE || m->imagersize[1] > MAX_IMAGER_SIDE) {
        model_error(name, 0, "imager size %ux%u: width and height must be 1..%d pixels",
                    m->imagersize[0], m->imagersize[1], MAX_IMAGER_SIDE);
        goto fail;
    }
    int np = mrcal_lensmodel_num_params(lm);
    for (int i = 0; i < np; i++)
        if (!isfinite(m->intrinsics[i])) {
            model_error(name, 0, "intrinsics[%d] is not a finite number", i);
            goto fail;
        }
    for (int i = 0; i < 6; i++)
        if (!isfinite(m->rt_cam_ref[i])) {
            model_error(name, 0, "extrinsics (rt_cam_world)[%d] is not a finite number", i);
            goto fail;
        }
    mrcal_lensmodel_metadata_t meta = mrcal_lensmodel_metadata(lm);
    if (meta.has_core && !(m->intrinsics[0] > 0 && m->intrinsics[1] > 0)) {
        model_error(name, 0, "focal lengths fx %g, fy %g: both must be > 0",
                    m->intrinsics[0], m->intrinsics[1]);
        goto fail;
    }

    cam = calloc(1, sizeof *cam);
    if (!cam || !(cam->name = strdup(name))) {
        model_error(name, 0, "out of memory");
        free(cam);
        cam = NULL;
        goto fail;
    }
    cam->m = m;
    cam->nintrinsics = np;
    snprintf(cam->lensmodel, sizeof cam->lensmodel, "%s", lname);
    memcpy(cam->sha256, sha256, 65);
    cam->stereographic = meta.can_project_behind_camera;

    double Rt[12];   // R (3x3) then t, mrcal's Rt layout
    mrcal_Rt_from_rt(Rt, NULL, m->rt_cam_ref);
    memcpy(cam->R_cam_world, Rt, 9 * sizeof(double));
    memcpy(cam->t_cam_world, Rt + 9, 3 * sizeof(double));
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) cam->R_world_cam[3 * r + c] = cam->R_cam_world[3 * c + r];
    // centre = -R^T t
    const double *R = cam->R_cam_world, *t = cam->t_cam_world;
    cam->centre_world = v3(-(R[0] * t[0] + R[3] * t[1] + R[6] * t[2]),
                           -(R[1] * t[0] + R[4] * t[1] + R[7] * t[2]),
                           -(R[2] * t[0] + R[5] * t[1] + R[8] * t[2]));
    pthread_mutex_init(&cam->lock, NULL);
    return cam;

fail:
    free(m);
    return NULL;
}

model_camera_t *model_camera_parse(const char *text, size_t len, const char *name)
{
    mrcal_cameramodel_t *mm = model_cameramodel_parse(text, len, name);   // checked first
    if (!mm) return NULL;
    // Our own copy, so that every camera owns the same kind of allocation.
    int np = mrcal_lensmodel_type_is_valid(mm->lensmodel.type)
                 ? mrcal_lensmodel_num_params(&mm->lensmodel) : 0;
    if (np < 0) np = 0;
    mrcal_cameramodel_t *m = malloc(sizeof *m + (size_t)np * sizeof(double));
    if (!m) {
        mrcal_free_cameramodel(&mm);
        model_error(name, 0, "out of memory");
        return NULL;
    }
    memcpy(m, mm, sizeof *m + (size_t)np * sizeof(double));
    mrcal_free_cameramodel(&mm);
    char sha[65];
    model_sha256_hex(text, len, sha);
    return camera_from_model(m, name, sha);
}

model_camera_t *model_camera_load(const char *path)
{
    size_t len;
    char *text = model_read_file(path, &len);   // reports "path: cannot open: ..."
    if (!text) return NULL;
    model_camera_t *cam = model_camera_parse(text, len, path);
    free(text);
    return cam;
}

model_camera_t *model_camera_new(const char *lensmodel, const double *intrinsics,
                                 int width, int height, const double rt_cam_world[6])
{
    char name[320];
    snprintf(name, sizeof name, "camera (%s %dx%d)", lensmodel ? lensmodel : "(null)",
             width, height);
    if (!lensmodel || !intrinsics || !rt_cam_world) {
        model_error(name, 0, "model_camera_new: lens model, intrinsics and rt_cam_world are required");
        return NULL;
    }
    mrcal_lensmodel_t lm;
    if (!mrcal_lensmodel_from_name(&lm, lensmodel) || !mrcal_lensmodel_type_is_valid(lm.type)) {
        model_error(name, 0, "unknown or unconfigured lens model '%s' (use an mrcal name such as "
                    "LENSMODEL_OPENCV8 or LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=30_Ny=20_fov_x_deg=80)",
                    lensmodel);
        return NULL;
    }
    if (width <= 0 || height <= 0) {
        model_error(name, 0, "imager size %dx%d: width and height must be positive", width, height);
        return NULL;
    }
    int np = mrcal_lensmodel_num_params(&lm);
    mrcal_cameramodel_t *m = calloc(1, sizeof *m + (size_t)np * sizeof(double));
    if (!m) {
        model_error(name, 0, "out of memory");
        return NULL;
    }
    m->lensmodel = lm;
    m->imagersize[0] = (unsigned)width;
    m->imagersize[1] = (unsigned)height;
    memcpy(m->rt_cam_ref, rt_cam_world, 6 * sizeof(double));
    memcpy(m->intrinsics, intrinsics, (size_t)np * sizeof(double));

    // sha256 of a canonical text of the parameters
    size_t cap = 256 + (size_t)(np + 6) * 32, n = 0;
    char *txt = malloc(cap);
    if (!txt) {
        free(m);
        model_error(name, 0, "out of memory");
        return NULL;
    }
    n += (size_t)snprintf(txt + n, cap - n, "%s %d %d", lensmodel, width, height);
    for (int i = 0; i < np; i++) n += (size_t)snprintf(txt + n, cap - n, " %.17g", intrinsics[i]);
    for (int i = 0; i < 6; i++) n += (size_t)snprintf(txt + n, cap - n, " %.17g", rt_cam_world[i]);
    char sha[65];
    model_sha256_hex(txt, n, sha);
    free(txt);
    return camera_from_model(m, name, sha);
}

// Written by hand rather than with mrcal_write_cameramodel_file(), which prints
// only 6 decimals; %.17g round-trips every double exactly. The format is
// mrcal's (a Python dict literal), read by both the C and the Python mrcal.
bool model_camera_save(const model_camera_t *cam, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        model_error(path, 0, "cannot create: %s", strerror(errno));
        return false;
    }
    const mrcal_cameramodel_t *m = cam->m;
    fprintf(f, "# generated by refl %s from %s\n", REFL_VERSION, cam->name);
    fprintf(f, "# extrinsics are rt_cam_world (world = mrcal's ref frame = the rig frame), mm\n");
    fprintf(f, "{\n    'lensmodel':  '%s',\n    'intrinsics': [", cam->lensmodel);
    for (int i = 0; i < cam->nintrinsics; i++)
        fprintf(f, "%s%.17g,", i % 4 == 0 ? "\n        " : " ", m->intrinsics[i]);
    fprintf(f, "\n    ],\n    'imagersize': [ %u, %u ],\n    'extrinsics': [", m->imagersize[0],
            m->imagersize[1]);
    for (int i = 0; i < 6; i++) fprintf(f, " %.17g,", m->rt_cam_ref[i]);
    fprintf(f, " ],\n}\n");
    bool ok = !ferror(f);
    if (fclose(f) != 0) ok = false;
    if (!ok) model_error(path, 0, "write error: %s", strerror(errno));
    return ok;
}

void model_camera_free(model_camera_t *cam)
{
    if (!cam) return;
    pthread_mutex_destroy(&cam->lock);
    free(cam->rays);
    free(cam->m);
    free(cam->name);
    free(cam);
}

int         model_camera_width(const model_camera_t *cam) { return (int)cam->m->imagersize[0]; }
int         model_camera_height(const model_camera_t *cam) { return (int)cam->m->imagersize[1]; }
const char *model_camera_lensmodel(const model_camera_t *cam) { return cam->lensmodel; }
const char *model_camera_sha256(const model_camera_t *cam) { return cam->sha256; }
const double *model_camera_intrinsics(const model_camera_t *cam, int *n)
{
    if (n) *n = cam->nintrinsics;
    return cam->m->intrinsics;
}
void        model_camera_rt_cam_world(const model_camera_t *cam, double rt[6])
{
    memcpy(rt, cam->m->rt_cam_ref, 6 * sizeof(double));
}
model_vec3_t model_camera_centre_world(const model_camera_t *cam) { return cam->centre_world; }

// ---------------------------------------------------------------------------
// Projection and exact unprojection

static inline void mat_vec(const double *R, const double *x, double *out)
{
    out[0] = R[0] * x[0] + R[1] * x[1] + R[2] * x[2];
    out[1] = R[3] * x[0] + R[4] * x[1] + R[5] * x[2];
    out[2] = R[6] * x[0] + R[7] * x[1] + R[8] * x[2];
}

#define CHUNK 256

// Points at or behind the camera plane (z <= 0 in the camera frame) get NaN
// pixel coordinates for lens models built on a pinhole projection (pinhole,
// OpenCV, CAHVOR), which would otherwise mirror them into the image.
bool model_camera_project(const model_camera_t *cam, const model_vec3_t *p_world, int n,
                          double *q_xy)
{
    if (n < 0 || (n > 0 && (!p_world || !q_xy))) {
        MODEL_FAIL("model_camera_project: bad arguments (n %d)", n);
        return false;
    }
    mrcal_point3_t p[CHUNK];
    mrcal_point2_t q[CHUNK];
    for (int b = 0; b < n; b += CHUNK) {
        int m = n - b < CHUNK ? n - b : CHUNK;
        for (int i = 0; i < m; i++) {
            double x[3] = { p_world[b + i].x, p_world[b + i].y, p_world[b + i].z };
            mat_vec(cam->R_cam_world, x, p[i].xyz);
            for (int k = 0; k < 3; k++) p[i].xyz[k] += cam->t_cam_world[k];
        }
        if (!mrcal_project(q, NULL, NULL, p, m, &cam->m->lensmodel, cam->m->intrinsics)) {
            model_error(cam->name, 0, "mrcal_project failed");
            return false;
        }
        for (int i = 0; i < m; i++) {
            bool behind = !cam->stereographic && !(p[i].z > 0);
            q_xy[2 * (b + i)]     = behind ? NAN : q[i].x;
            q_xy[2 * (b + i) + 1] = behind ? NAN : q[i].y;
        }
    }
    return true;
}

bool model_camera_unproject(const model_camera_t *cam, const double *q_xy, int n,
                            model_vec3_t *dir_world)
{
    if (n < 0 || (n > 0 && (!q_xy || !dir_world))) {
        MODEL_FAIL("model_camera_unproject: bad arguments (n %d)", n);
        return false;
    }
    mrcal_point2_t q[CHUNK];
    mrcal_point3_t v[CHUNK];
    for (int b = 0; b < n; b += CHUNK) {
        int m = n - b < CHUNK ? n - b : CHUNK;
        for (int i = 0; i < m; i++) {
            q[i].x = q_xy[2 * (b + i)];
            q[i].y = q_xy[2 * (b + i) + 1];
        }
        if (!mrcal_unproject(v, q, m, &cam->m->lensmodel, cam->m->intrinsics)) {
            model_error(cam->name, 0, "mrcal_unproject failed");
            return false;
        }
        for (int i = 0; i < m; i++) {
            double nn = sqrt(v[i].x * v[i].x + v[i].y * v[i].y + v[i].z * v[i].z);
            if (!(nn > 0) || !isfinite(nn)) {
                model_error(cam->name, 0, "cannot unproject pixel (%g, %g): outside the domain "
                            "of the lens model", q[i].x, q[i].y);
                return false;
            }
            double u[3] = { v[i].x / nn, v[i].y / nn, v[i].z / nn }, w[3];
            mat_vec(cam->R_world_cam, u, w);
            dir_world[b + i] = v3(w[0], w[1], w[2]);
        }
    }
    return true;
}

// ---------------------------------------------------------------------------
// Ray table

// Camera-frame ray (any length) -> the interpolated 2D quantity. false if the
// ray is outside the quantity's domain.
static inline bool ray_to_uv(bool stereo, const double *v, double *uv)
{
    if (stereo) {
        double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        double d = n + v[2];
        if (!(d > 1e-12 * n) || !isfinite(n)) return false;
        uv[0] = 2.0 * v[0] / d;
        uv[1] = 2.0 * v[1] / d;
        return true;
    }
    if (!(v[2] > 0) || !isfinite(v[0] + v[1] + v[2])) return false;
    uv[0] = v[0] / v[2];
    uv[1] = v[1] / v[2];
    return true;
}

// The 2D quantity -> camera-frame unit ray.
static inline void uv_to_ray(bool stereo, const double *uv, double *v)
{
    double s = uv[0] * uv[0] + uv[1] * uv[1];
    if (stereo) {
        double k = 1.0 / (4.0 + s);
        v[0] = 4.0 * uv[0] * k;
        v[1] = 4.0 * uv[1] * k;
        v[2] = (4.0 - s) * k;
    } else {
        double k = 1.0 / sqrt(1.0 + s);
        v[0] = uv[0] * k;
        v[1] = uv[1] * k;
        v[2] = k;
    }
}

static inline void catmull_rom(double t, double w[4])
{
    double t2 = t * t, t3 = t2 * t;
    w[0] = 0.5 * (-t3 + 2.0 * t2 - t);
    w[1] = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0);
    w[2] = 0.5 * (-3.0 * t3 + 4.0 * t2 + t);
    w[3] = 0.5 * (t3 - t2);
}

// A grid level: (nx+1) x (ny+1) nodes, node (i,j) at pixel (i*sx, j*sy); the
// padded copy has one ghost node on every side.
typedef struct {
    int     nx, ny;
    double  sx, sy;
    double *uv;      // (ny+1)*(nx+1)*2, exact
    double *pad;     // (ny+3)*(nx+3)*2, with ghost nodes
} grid_t;

static void grid_free(grid_t *g)
{
    free(g->uv);
    free(g->pad);
    g->uv = g->pad = NULL;
}

// Ghost value beyond a line of nodes a (nearest), b, c: quadratic extrapolation
// (linear when only two nodes exist).
static inline double ghost(int have, double a, double b, double c)
{
    return have >= 3 ? 3.0 * a - 3.0 * b + c : 2.0 * a - b;
}

static bool grid_pad(grid_t *g)
{
    int W = g->nx + 3, H = g->ny + 3, n = g->nx + 1, m = g->ny + 1;
    g->pad = malloc((size_t)W * H * 2 * sizeof(double));
    if (!g->pad) return false;
#define P(i, j, k) g->pad[(((size_t)(j) + 1) * W + (i) + 1) * 2 + (k)]
#define U(i, j, k) g->uv[(((size_t)(j)) * n + (i)) * 2 + (k)]
    for (int j = 0; j < m; j++)
        for (int k = 0; k < 2; k++) {
            for (int i = 0; i < n; i++) P(i, j, k) = U(i, j, k);
            P(-1, j, k) = ghost(n, U(0, j, k), U(1, j, k), n >= 3 ? U(2, j, k) : 0);
            P(n, j, k)  = ghost(n, U(n - 1, j, k), U(n - 2, j, k), n >= 3 ? U(n - 3, j, k) : 0);
        }
    for (int i = -1; i <= n; i++)
        for (int k = 0; k < 2; k++) {
            P(i, -1, k) = ghost(m, P(i, 0, k), P(i, 1, k), m >= 3 ? P(i, 2, k) : 0);
            P(i, m, k)  = ghost(m, P(i, m - 1, k), P(i, m - 2, k), m >= 3 ? P(i, m - 3, k) : 0);
        }
#undef P
#undef U
    return true;
}

// Cell index and fraction of coordinate x on a level with n cells of size s.
static inline int cell_of(double x, double s, int n, double *t)
{
    double f = x / s;
    int i = (int)floor(f);
    if (i < 0) i = 0;
    if (i > n - 1) i = n - 1;
    *t = f - i;
    return i;
}

// Interpolated quantity at pixel (x, y).
static inline void grid_eval(const grid_t *g, double x, double y, double *uv)
{
    double tx, ty, wx[4], wy[4];
    int i = cell_of(x, g->sx, g->nx, &tx), j = cell_of(y, g->sy, g->ny, &ty);
    catmull_rom(tx, wx);
    catmull_rom(ty, wy);
    int W = g->nx + 3;
    double a0 = 0, a1 = 0;
    for (int b = 0; b < 4; b++) {
        const double *row = g->pad + ((size_t)(j + b) * W + i) * 2;   // node (i-1, j-1+b)
        double r0 = 0, r1 = 0;
        for (int a = 0; a < 4; a++) {
            r0 += wx[a] * row[2 * a];
            r1 += wx[a] * row[2 * a + 1];
        }
        a0 += wy[b] * r0;
        a1 += wy[b] * r1;
    }
    uv[0] = a0;
    uv[1] = a1;
}

typedef struct {
    const model_camera_t *cam;
    const mrcal_point2_t *q;
    double               *uv;     // out, 2 per point
    atomic_int            bad;    // index+1 of a point that failed, or 0
} unproj_job_t;

static void unproj_worker(void *ctx, int begin, int end, int thread)
{
    unproj_job_t *J = ctx;
    mrcal_point3_t v[CHUNK];
    for (int b = begin; b < end; b += CHUNK) {
        int m = end - b < CHUNK ? end - b : CHUNK;
        bool ok = mrcal_unproject(v, J->q + b, m, &J->cam->m->lensmodel, J->cam->m->intrinsics);
        for (int i = 0; i < m; i++)
            if (!ok || !ray_to_uv(J->cam->stereographic, v[i].xyz, J->uv + 2 * (b + i))) {
                atomic_store(&J->bad, b + i + 1);
                J->uv[2 * (b + i)] = J->uv[2 * (b + i) + 1] = NAN;
            }
    }
}

// Unproject n pixels exactly into the interpolated quantity, in parallel.
static bool unproject_uv(const model_camera_t *cam, const mrcal_point2_t *q, int n, double *uv)
{
    unproj_job_t J = { .cam = cam, .q = q, .uv = uv };
    atomic_init(&J.bad, 0);
    model_parallel_for(n, 512, model_default_threads(), unproj_worker, &J);
    int bad = atomic_load(&J.bad);
    if (bad) {
        model_error(cam->name, 0, "cannot unproject pixel (%g, %g) of the imager: outside the "
                    "domain of lens model %s", q[bad - 1].x, q[bad - 1].y, cam->lensmodel);
        return false;
    }
    return true;
}

// The next level: twice the nodes in each direction; the even nodes are copied
// from `from` (may be NULL for the first level), the others unprojected.
static bool grid_make(const model_camera_t *cam, const grid_t *from, int nx, int ny, grid_t *g)
{
    int W = model_camera_width(cam), H = model_camera_height(cam);
    *g = (grid_t){ .nx = nx, .ny = ny,
                   .sx = (W > 1 ? W - 1 : 1) / (double)nx, .sy = (H > 1 ? H - 1 : 1) / (double)ny };
    size_t nn = (size_t)(nx + 1) * (ny + 1);
    g->uv = malloc(nn * 2 * sizeof(double));
    mrcal_point2_t *q = malloc(nn * sizeof *q);
    int *idx = malloc(nn * sizeof *idx);
    double *uvq = malloc(nn * 2 * sizeof(double));
    bool ok = false;
    if (!g->uv || !q || !idx || !uvq) {
        model_error(cam->name, 0, "out of memory for the ray table grid");
        goto done;
    }
    int m = 0;
    for (int j = 0; j <= ny; j++)
        for (int i = 0; i <= nx; i++) {
            size_t k = (size_t)j * (nx + 1) + i;
            if (from && i % 2 == 0 && j % 2 == 0) {
                size_t kf = (size_t)(j / 2) * (from->nx + 1) + i / 2;
                g->uv[2 * k]     = from->uv[2 * kf];
                g->uv[2 * k + 1] = from->uv[2 * kf + 1];
            } else {
                q[m] = (mrcal_point2_t){ .x = i * g->sx, .y = j * g->sy };
                idx[m++] = (int)k;
            }
        }
    if (!unproject_uv(cam, q, m, uvq)) goto done;
    for (int k = 0; k < m; k++) {
        g->uv[2 * idx[k]]     = uvq[2 * k];
        g->uv[2 * idx[k] + 1] = uvq[2 * k + 1];
    }
    if (!grid_pad(g)) {
        model_error(cam->name, 0, "out of memory for the ray table grid");
        goto done;
    }
    ok = true;
done:
    free(q);
    free(idx);
    free(uvq);
    if (!ok) grid_free(g);
    return ok;
}

// Largest reprojection error of the interpolated rays on a grid 4x finer than
// the nodes (rows of check points in parallel).
typedef struct {
    const model_camera_t *cam;
    const grid_t         *g;
    double                err[64];   // per thread
} check_job_t;

static void check_worker(void *ctx, int begin, int end, int thread)
{
    check_job_t *J = ctx;
    const grid_t *g = J->g;
    int n = 4 * g->nx + 1;
    mrcal_point3_t *v = malloc((size_t)n * sizeof *v);
    mrcal_point2_t *q = malloc((size_t)n * sizeof *q);
    if (!v || !q) {
        J->err[thread] = INFINITY;
        goto done;
    }
    for (int r = begin; r < end; r++) {
        double y = r * g->sy / 4.0;
        for (int c = 0; c < n; c++) {
            double uv[2];
            grid_eval(g, c * g->sx / 4.0, y, uv);
            uv_to_ray(J->cam->stereographic, uv, v[c].xyz);
        }
        mrcal_project(q, NULL, NULL, v, n, &J->cam->m->lensmodel, J->cam->m->intrinsics);
        for (int c = 0; c < n; c++) {
            double ex = q[c].x - c * g->sx / 4.0, ey = q[c].y - y, e = sqrt(ex * ex + ey * ey);
            if (!(e <= J->err[thread])) J->err[thread] = isnan(e) ? INFINITY : e;
        }
    }
done:
    free(v);
    free(q);
}

static double grid_check(const model_camera_t *cam, const grid_t *g)
{
    check_job_t J = { .cam = cam, .g = g };
    model_parallel_for(4 * g->ny + 1, 4, model_default_threads(), check_worker, &J);
    double e = 0;
    for (int t = 0; t < 64; t++) e = fmax(e, J.err[t]);
    return e;
}

// Fill the table from a grid (g != NULL) or by exact unprojection (g == NULL),
// measuring the reprojection error of every pixel.
typedef struct {
    model_camera_t *cam;
    const grid_t   *g;
    model_vec3_t   *rays;
    double          err[64];
    atomic_bool     failed;
} fill_job_t;

static void fill_worker(void *ctx, int begin, int end, int thread)
{
    fill_job_t *J = ctx;
    model_camera_t *cam = J->cam;
    const grid_t *g = J->g;
    int W = model_camera_width(cam);
    mrcal_point3_t *v = malloc((size_t)W * sizeof *v);
    mrcal_point2_t *q = malloc((size_t)W * sizeof *q);
    double *row = g ? malloc((size_t)(g->nx + 3) * 2 * sizeof(double)) : NULL;
    double *wx = g ? malloc((size_t)W * 4 * sizeof(double)) : NULL;
    int *ix = g ? malloc((size_t)W * sizeof(int)) : NULL;
    if (!v || !q || (g && (!row || !wx || !ix))) {
        atomic_store(&J->failed, true);
        goto done;
    }
    if (g)
        for (int x = 0; x < W; x++) {
            double t;
            ix[x] = cell_of(x, g->sx, g->nx, &t);
            catmull_rom(t, wx + 4 * x);
        }
    for (int y = begin; y < end; y++) {
        if (g) {
            // interpolate along y for every node column, then along x per pixel
            double ty, wy[4];
            int j = cell_of(y, g->sy, g->ny, &ty), Wp = g->nx + 3;
            catmull_rom(ty, wy);
            for (int i = 0; i < Wp; i++) {
                double a0 = 0, a1 = 0;
                for (int b = 0; b < 4; b++) {
                    const double *p = g->pad + ((size_t)(j + b) * Wp + i) * 2;
                    a0 += wy[b] * p[0];
                    a1 += wy[b] * p[1];
                }
                row[2 * i] = a0;
                row[2 * i + 1] = a1;
            }
            for (int x = 0; x < W; x++) {
                const double *w = wx + 4 * x, *p = row + 2 * ix[x];
                double uv[2] = { w[0] * p[0] + w[1] * p[2] + w[2] * p[4] + w[3] * p[6],
                                 w[0] * p[1] + w[1] * p[3] + w[2] * p[5] + w[3] * p[7] };
                uv_to_ray(cam->stereographic, uv, v[x].xyz);
            }
        } else {
            for (int x = 0; x < W; x++) q[x] = (mrcal_point2_t){ .x = x, .y = y };
            if (!mrcal_unproject(v, q, W, &cam->m->lensmodel, cam->m->intrinsics)) {
                atomic_store(&J->failed, true);
                goto done;
            }
            for (int x = 0; x < W; x++) {
                double n = sqrt(v[x].x * v[x].x + v[x].y * v[x].y + v[x].z * v[x].z);
                if (!(n > 0) || !isfinite(n)) {
                    atomic_store(&J->failed, true);
                    goto done;
                }
                for (int k = 0; k < 3; k++) v[x].xyz[k] /= n;
            }
        }
        mrcal_project(q, NULL, NULL, v, W, &cam->m->lensmodel, cam->m->intrinsics);
        double emax = J->err[thread];
        model_vec3_t *out = J->rays + (size_t)y * W;
        for (int x = 0; x < W; x++) {
            double ex = q[x].x - x, ey = q[x].y - y, e = sqrt(ex * ex + ey * ey);
            if (!(e <= emax)) emax = isnan(e) ? INFINITY : e;
            double w[3];
            mat_vec(cam->R_world_cam, v[x].xyz, w);
            out[x] = v3(w[0], w[1], w[2]);
        }
        J->err[thread] = emax;
    }
done:
    free(v);
    free(q);
    free(row);
    free(wx);
    free(ix);
}

static bool fill_table(model_camera_t *cam, const grid_t *g, model_vec3_t *rays, double *err)
{
    fill_job_t J = { .cam = cam, .g = g, .rays = rays };
    atomic_init(&J.failed, false);
    model_parallel_for(model_camera_height(cam), 8, model_default_threads(), fill_worker, &J);
    if (atomic_load(&J.failed)) {
        model_error(cam->name, 0, g ? "out of memory for the ray table"
                                    : "cannot unproject every pixel of the imager (lens model %s)",
                    cam->lensmodel);
        return false;
    }
    *err = 0;
    for (int t = 0; t < 64; t++) *err = fmax(*err, J.err[t]);
    return true;
}

static bool build_ray_table(model_camera_t *cam)
{
    int W = model_camera_width(cam), H = model_camera_height(cam);
    model_vec3_t *rays = malloc((size_t)W * H * sizeof *rays);
    grid_t g = { 0 }, next = { 0 };
    bool ok = false;
    if (!rays) {
        model_error(cam->name, 0, "out of memory for a %dx%d ray table", W, H);
        goto done;
    }
    int nx = (int)ceil((W - 1) / INITIAL_STEP_PX), ny = (int)ceil((H - 1) / INITIAL_STEP_PX);
    if (nx < 1) nx = 1;
    if (ny < 1) ny = 1;
    if (!grid_make(cam, NULL, nx, ny, &g)) goto done;
    double err = INFINITY;
    for (;;) {
        // the check grid slightly underestimates the all-pixel error: keep a margin
        if (grid_check(cam, &g) <= 0.8 * RAY_TOL_PX) {
            if (!fill_table(cam, &g, rays, &err)) goto done;
            if (err <= RAY_TOL_PX) break;
        }
        if (g.sx / 2 < 1.0 && g.sy / 2 < 1.0) {   // finer than the pixels: exact
            if (!fill_table(cam, NULL, rays, &err)) goto done;
            break;
        }
        int nx2 = g.sx / 2 < 1.0 ? g.nx : 2 * g.nx, ny2 = g.sy / 2 < 1.0 ? g.ny : 2 * g.ny;
        if (nx2 != 2 * g.nx || ny2 != 2 * g.ny) {   // refine one direction only: exact instead
            if (!fill_table(cam, NULL, rays, &err)) goto done;
            break;
        }
        if (!grid_make(cam, &g, nx2, ny2, &next)) goto done;
        grid_free(&g);
        g = next;
        next = (grid_t){ 0 };
    }
    cam->rays = rays;
    cam->rays_err_px = err;
    rays = NULL;
    ok = true;
done:
    grid_free(&g);
    grid_free(&next);
    free(rays);
    return ok;
}

const model_vec3_t *model_camera_ray_table(model_camera_t *cam, double *err_px)
{
    pthread_mutex_lock(&cam->lock);
    if (!cam->rays) build_ray_table(cam);
    const model_vec3_t *r = cam->rays;
    if (r && err_px) *err_px = cam->rays_err_px;
    pthread_mutex_unlock(&cam->lock);
    return r;
}
