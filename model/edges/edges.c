// model/edges/edges.c — the edge query (thesis 1.6, PREMIO): which scene edges the
// camera sees, where they lie in the image, how each side is lit and the
// grey-value contrast across them.
//
// 1. Scene edges: vertex pairs used by two faces whose normals differ by more
//    than feature_angle_deg, and boundary edges (one face). Vertices with equal
//    coordinates are treated as one vertex.
// 2. Each 3D edge is cut into cells about 1 px long in the image; the cell
//    centre is visible when it projects inside the image and the camera ray to
//    it is not blocked before it (the nearest hit is one of the edge's own
//    faces, or lies at the same range). Runs of visible cells make the image
//    segments; an end inside the edge is refined by bisection.
// 3. Sides: points along each segment, moved +/- 2 px along the image normal
//    n = (-dy, dx)/|d| of the chord d = q1 - q0 (side 0 = +n: to the right of
//    q0 -> q1 in the displayed image, y down). Their pixel_info is shaded with
//    the direct term: P = Pa + kc * g * model_direct_sum (no interreflection).
//    P_side is the mean, face_side the most frequent face, and lamp i lights a
//    side when V_i > 0.5 on at least half its points.
#define _GNU_SOURCE
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

#define SIDE_OFFSET_PX   2.0
#define CELL_PX          1.0
#define MAX_CELLS        200000
#define MIN_SEGMENT_PX   1.0
#define SIDE_SPACING_PX  4.0
#define MIN_SIDE_SAMPLES 3
#define MAX_SIDE_SAMPLES 64
#define BISECT_STEPS     8

// ---------------------------------------------------------------------------
// Scene edges

typedef struct {
    uint64_t key;      // (min vertex << 32) | max vertex, welded indices
    int      face;
    int      v0, v1;   // original indices in face order
} half_edge_t;

static int cmp_half_edge(const void *a, const void *b)
{
    const half_edge_t *x = a, *y = b;
    if (x->key != y->key) return x->key < y->key ? -1 : 1;
    return x->face - y->face;
}

static int cmp_vertex_index(const void *a, const void *b, void *ctx)
{
    const model_vec3_t *v = ctx;
    model_vec3_t p = v[*(const int *)a], q = v[*(const int *)b];
    if (p.x != q.x) return p.x < q.x ? -1 : 1;
    if (p.y != q.y) return p.y < q.y ? -1 : 1;
    if (p.z != q.z) return p.z < q.z ? -1 : 1;
    return *(const int *)a - *(const int *)b;
}

// weld[i]: the smallest index of a vertex with the same coordinates as i.
static int *weld_vertices(const model_scene_t *s)
{
    int n = s->nvertices;
    int *order = malloc((size_t)(n > 0 ? n : 1) * sizeof *order);
    int *weld = malloc((size_t)(n > 0 ? n : 1) * sizeof *weld);
    if (!order || !weld) {
        free(order);
        free(weld);
        return NULL;
    }
    for (int i = 0; i < n; i++) order[i] = i;
    qsort_r(order, (size_t)n, sizeof *order, cmp_vertex_index, (void *)s->vertices);
    for (int i = 0; i < n;) {
        int j = i;
        while (j < n && s->vertices[order[j]].x == s->vertices[order[i]].x &&
               s->vertices[order[j]].y == s->vertices[order[i]].y &&
               s->vertices[order[j]].z == s->vertices[order[i]].z)
            j++;
        for (int k = i; k < j; k++) weld[order[k]] = order[i];   // order[i] is the smallest (ties by index)
        i = j;
    }
    free(order);
    return weld;
}

static double angle_deg(model_vec3_t a, model_vec3_t b)
{
    double c = v3_dot(a, b);
    c = c > 1 ? 1 : c < -1 ? -1 : c;
    return acos(c) * 180.0 / M_PI;
}

// The list of edges (without segments). NULL on failure.
static model_edges_t *scene_edges(const model_scene_t *s, double feature_angle_deg)
{
    model_edges_t *out = calloc(1, sizeof *out);
    int *weld = weld_vertices(s);
    half_edge_t *he = NULL;
    size_t nhe = 0;
    for (int f = 0; f < s->nfaces; f++) nhe += (size_t)s->faces[f].nverts;
    he = malloc((nhe ? nhe : 1) * sizeof *he);
    if (!out || !weld || !he) {
        MODEL_FAIL("out of memory");
        goto fail;
    }
    nhe = 0;
    for (int f = 0; f < s->nfaces; f++) {
        const model_face_t *fc = &s->faces[f];
        for (int k = 0; k < fc->nverts; k++) {
            int a = fc->verts[k], b = fc->verts[(k + 1) % fc->nverts];
            int wa = weld[a], wb = weld[b];
            if (wa == wb) continue;   // degenerate (repeated vertex)
            uint64_t lo = (uint64_t)(wa < wb ? wa : wb), hi = (uint64_t)(wa < wb ? wb : wa);
            he[nhe++] = (half_edge_t){ (lo << 32) | hi, f, a, b };
        }
    }
    qsort(he, nhe, sizeof *he, cmp_half_edge);
    out->edges = calloc(nhe ? nhe : 1, sizeof *out->edges);
    if (!out->edges) {
        MODEL_FAIL("out of memory");
        goto fail;
    }
    for (size_t i = 0; i < nhe;) {
        size_t j = i;
        while (j < nhe && he[j].key == he[i].key) j++;
        // Distinct faces using this vertex pair.
        int fa = he[i].face, fb = -1;
        double dihedral = 0;
        for (size_t k = i + 1; k < j; k++) {
            if (he[k].face == fa) continue;
            double d = angle_deg(s->faces[fa].normal, s->faces[he[k].face].normal);
            if (fb < 0 || d > dihedral) {   // non-manifold: keep the sharpest pair
                fb = he[k].face;
                dihedral = d;
            }
        }
        if (fb < 0 || dihedral > feature_angle_deg) {
            model_edge_t *e = &out->edges[out->nedges++];
            e->v0 = he[i].v0;
            e->v1 = he[i].v1;
            e->face_a = fa;
            e->face_b = fb;
            e->dihedral_deg = fb < 0 ? 0 : dihedral;
        }
        i = j;
    }
    free(weld);
    free(he);
    return out;
fail:
    free(weld);
    free(he);
    model_edges_free(out);
    return NULL;
}

// ---------------------------------------------------------------------------
// Visibility along each edge

typedef struct {
    const model_tracer_t *t;
    const model_camera_t *cam;
    const model_scene_t  *scene;
    model_edges_t        *edges;
    const model_vec3_t   *vertices;
    model_vec3_t          centre;
    model_vec3_t          axis;    // camera optical axis, world
    int                   width, height;
    // per segment (filled here): 3D parameter range on its edge
    double              **seg_t;   // per edge: 2 * nsegments
    atomic_bool           failed;   // set by any worker
} vis_ctx_t;

// Rotation matrix rows from a Rodrigues vector (R maps world to camera).
static void rodrigues(const double r[3], double R[3][3])
{
    double th = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    if (th < 1e-14) {
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) R[i][j] = i == j;
        return;
    }
    double k[3] = { r[0] / th, r[1] / th, r[2] / th }, c = cos(th), s = sin(th);
    double K[3][3] = { { 0, -k[2], k[1] }, { k[2], 0, -k[0] }, { -k[1], k[0], 0 } };
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) R[i][j] = c * (i == j) + s * K[i][j] + (1 - c) * k[i] * k[j];
}

static bool in_image(const vis_ctx_t *c, const double q[2])
{
    return q[0] >= -0.5 && q[1] >= -0.5 && q[0] <= c->width - 0.5 && q[1] <= c->height - 0.5;
}

// Visibility of the point at parameter u on edge e; q (out) its projection.
static bool point_visible(const vis_ctx_t *c, const model_edge_t *e, double u, double q[2])
{
    model_vec3_t a = c->vertices[e->v0], b = c->vertices[e->v1];
    model_vec3_t p = v3_add(a, v3_scale(v3_sub(b, a), u));
    model_vec3_t d = v3_sub(p, c->centre);
    double range = v3_norm(d);
    if (!(range > 0) || v3_dot(d, c->axis) <= 1e-9 * range) return false;   // behind the camera
    if (!model_camera_project(c->cam, &p, 1, q) || !isfinite(q[0]) || !isfinite(q[1])) return false;
    if (!in_image(c, q)) return false;
    model_pixel_info_t pi;
    model_tracer_cast(c->t, c->centre, v3_scale(d, 1.0 / range), &pi);
    if (pi.face < 0) return true;   // grazing ray slipped past the edge
    if (pi.face == e->face_a || pi.face == e->face_b) return true;
    return pi.range_mm >= range - (0.02 + 2e-5 * range);
}

static void edge_segments(vis_ctx_t *c, model_edge_t *e, int ei)
{
    model_vec3_t a = c->vertices[e->v0], b = c->vertices[e->v1];
    // Image length from a coarse polyline (points in front of the camera only).
    enum { NCOARSE = 17 };
    model_vec3_t pc[NCOARSE];
    double qc[2 * NCOARSE];
    int npc = 0;
    for (int k = 0; k < NCOARSE; k++) {
        model_vec3_t p = v3_add(a, v3_scale(v3_sub(b, a), k / (double)(NCOARSE - 1)));
        if (v3_dot(v3_sub(p, c->centre), c->axis) > 1e-6) pc[npc++] = p;
    }
    if (npc < 2) return;
    if (!model_camera_project(c->cam, pc, npc, qc)) {
        atomic_store(&c->failed, true);
        return;
    }
    double len = 0;
    for (int k = 1; k < npc; k++) len += hypot(qc[2 * k] - qc[2 * k - 2], qc[2 * k + 1] - qc[2 * k - 1]);
    if (!isfinite(len)) return;
    int n = (int)ceil(len / CELL_PX);
    if (n < 2) n = 2;
    if (n > MAX_CELLS) n = MAX_CELLS;

    bool *vis = malloc((size_t)n * sizeof *vis);
    double *qs = malloc((size_t)n * 2 * sizeof *qs);
    if (!vis || !qs) {
        free(vis);
        free(qs);
        atomic_store(&c->failed, true);
        return;
    }
    for (int k = 0; k < n; k++) vis[k] = point_visible(c, e, (k + 0.5) / n, &qs[2 * k]);

    int nseg = 0;
    for (int k = 0; k < n; k++)
        if (vis[k] && (k == 0 || !vis[k - 1])) nseg++;
    model_edge_segment_t *segs = nseg ? calloc((size_t)nseg, sizeof *segs) : NULL;
    double *ts = nseg ? malloc((size_t)nseg * 2 * sizeof *ts) : NULL;
    if (nseg && (!segs || !ts)) {
        free(vis);
        free(qs);
        free(segs);
        free(ts);
        atomic_store(&c->failed, true);
        return;
    }
    int m = 0;
    for (int k = 0; k < n;) {
        if (!vis[k]) {
            k++;
            continue;
        }
        int j = k;
        while (j < n && vis[j]) j++;
        // Run k..j-1. Ends: the edge's end points, or the visibility change
        // found by bisection between a visible and a hidden cell centre.
        double qtmp[2];
        double t0 = 0, t1 = 1;
        if (k > 0) {
            double lo = (k - 0.5) / n, hi = (k + 0.5) / n;   // hidden, visible
            for (int it = 0; it < BISECT_STEPS; it++) {
                double mid = 0.5 * (lo + hi);
                if (point_visible(c, e, mid, qtmp)) hi = mid; else lo = mid;
            }
            t0 = hi;
        }
        if (j < n) {
            double lo = (j - 0.5) / n, hi = (j + 0.5) / n;   // visible, hidden
            for (int it = 0; it < BISECT_STEPS; it++) {
                double mid = 0.5 * (lo + hi);
                if (point_visible(c, e, mid, qtmp)) lo = mid; else hi = mid;
            }
            t1 = lo;
        }
        model_vec3_t ends[2] = { v3_add(a, v3_scale(v3_sub(b, a), t0)),
                                 v3_add(a, v3_scale(v3_sub(b, a), t1)) };
        double qe[4];
        if (!model_camera_project(c->cam, ends, 2, qe)) {
            atomic_store(&c->failed, true);
            break;
        }
        double L = hypot(qs[2 * k] - qe[0], qs[2 * k + 1] - qe[1]) +
                   hypot(qe[2] - qs[2 * (j - 1)], qe[3] - qs[2 * (j - 1) + 1]);
        for (int i = k + 1; i < j; i++)
            L += hypot(qs[2 * i] - qs[2 * i - 2], qs[2 * i + 1] - qs[2 * i - 1]);
        if (L >= MIN_SEGMENT_PX) {
            model_edge_segment_t *sg = &segs[m];
            sg->q0[0] = qe[0];
            sg->q0[1] = qe[1];
            sg->q1[0] = qe[2];
            sg->q1[1] = qe[3];
            sg->length_px = L;
            sg->face_side[0] = sg->face_side[1] = -1;
            ts[2 * m] = t0;
            ts[2 * m + 1] = t1;
            m++;
        }
        k = j;
    }
    free(vis);
    free(qs);
    if (m == 0) {
        free(segs);
        free(ts);
        segs = NULL;
        ts = NULL;
    }
    e->segments = segs;
    e->nsegments = m;
    c->seg_t[ei] = ts;
}

static void vis_worker(void *ctx, int begin, int end, int thread)
{
    vis_ctx_t *c = ctx;
    for (int i = begin; i < end && !atomic_load(&c->failed); i++) edge_segments(c, &c->edges->edges[i], i);
}

// ---------------------------------------------------------------------------
// Sides

static int side_samples(const model_edge_segment_t *s)
{
    int n = (int)(s->length_px / SIDE_SPACING_PX);
    return n < MIN_SIDE_SAMPLES ? MIN_SIDE_SAMPLES : n > MAX_SIDE_SAMPLES ? MAX_SIDE_SAMPLES : n;
}

static bool shade_sides(const model_tracer_t *t, model_camera_t *cam, const model_lamps_t *lamps,
                        const model_material_t *const *mats, const model_shading_t *sh,
                        model_edges_t *E, double **seg_t, const model_vec3_t *vertices,
                        model_vec3_t centre, model_vec3_t axis, int width, int height)
{
    bool ok = false;
    size_t npts = 0;
    for (int i = 0; i < E->nedges; i++)
        for (int s = 0; s < E->edges[i].nsegments; s++) npts += (size_t)side_samples(&E->edges[i].segments[s]);
    if (npts == 0) return true;
    if (npts > (size_t)INT32_MAX / 4) {
        MODEL_FAIL("too many edge samples (%zu)", npts);
        return false;
    }
    int nl = lamps ? lamps->n : 0;
    model_vec3_t *p3 = malloc(npts * sizeof *p3);
    double *q = malloc(npts * 2 * sizeof *q);
    double *qside = malloc(npts * 4 * sizeof *qside);
    model_pixel_info_t *pi = malloc(npts * 2 * sizeof *pi);
    model_lamp_sample_t *ls = nl ? malloc(npts * 2 * (size_t)nl * sizeof *ls) : NULL;
    if (!p3 || !q || !qside || !pi || (nl && !ls)) {
        MODEL_FAIL("out of memory");
        goto done;
    }
    // 3D points along each segment, then their projections.
    size_t k = 0;
    for (int i = 0; i < E->nedges; i++) {
        model_edge_t *e = &E->edges[i];
        model_vec3_t a = vertices[e->v0], b = vertices[e->v1];
        for (int s = 0; s < e->nsegments; s++) {
            int n = side_samples(&e->segments[s]);
            double t0 = seg_t[i][2 * s], t1 = seg_t[i][2 * s + 1];
            // Evenly spaced in the image, not along the 3D edge: with the
            // depths zA, zB of the segment's ends, the image fraction s maps
            // to the 3D fraction s*zA / ((1-s)*zB + s*zA) (exact for a pinhole).
            model_vec3_t A = v3_add(a, v3_scale(v3_sub(b, a), t0)), B = v3_add(a, v3_scale(v3_sub(b, a), t1));
            double zA = v3_dot(v3_sub(A, centre), axis), zB = v3_dot(v3_sub(B, centre), axis);
            for (int j = 0; j < n; j++) {
                double sf = (j + 0.5) / n, den = (1 - sf) * zB + sf * zA;
                double u = den > 0 ? sf * zA / den : sf;
                p3[k++] = v3_add(A, v3_scale(v3_sub(B, A), u));
            }
        }
    }
    if (!model_camera_project(cam, p3, (int)npts, q)) goto done;
    k = 0;
    for (int i = 0; i < E->nedges; i++) {
        model_edge_t *e = &E->edges[i];
        for (int s = 0; s < e->nsegments; s++) {
            model_edge_segment_t *sg = &e->segments[s];
            double dx = sg->q1[0] - sg->q0[0], dy = sg->q1[1] - sg->q0[1], dl = hypot(dx, dy);
            double nx = dl > 0 ? -dy / dl : 0, ny = dl > 0 ? dx / dl : 0;
            int n = side_samples(sg);
            for (int j = 0; j < n; j++, k++) {
                qside[4 * k + 0] = q[2 * k] + SIDE_OFFSET_PX * nx;
                qside[4 * k + 1] = q[2 * k + 1] + SIDE_OFFSET_PX * ny;
                qside[4 * k + 2] = q[2 * k] - SIDE_OFFSET_PX * nx;
                qside[4 * k + 3] = q[2 * k + 1] - SIDE_OFFSET_PX * ny;
            }
        }
    }
    if (!model_pixel_info(t, cam, lamps, qside, (int)(2 * npts), pi, ls, sh->nthreads)) goto done;

    // Shade, average per side.
    k = 0;
    for (int i = 0; i < E->nedges; i++) {
        model_edge_t *e = &E->edges[i];
        for (int s = 0; s < e->nsegments; s++) {
            model_edge_segment_t *sg = &e->segments[s];
            int n = side_samples(sg);
            for (int side = 0; side < 2; side++) {
                double sumP = 0;
                int litcount[32] = { 0 };
                // most frequent face: small n, quadratic count is fine
                int best_face = -1, best_count = 0;
                for (int j = 0; j < n; j++) {
                    size_t idx = 2 * (k + (size_t)j) + (size_t)side;
                    const model_pixel_info_t *p = &pi[idx];
                    double P = sh->Pa;
                    if (p->face >= 0) {
                        const model_material_t *mat = p->material >= 0 ? mats[p->material] : NULL;
                        double S = mat ? model_direct_sum(p, ls ? &ls[idx * (size_t)nl] : NULL, lamps, mat, NULL) : 0;
                        double g = 1;
                        if (sh->gain_map) {
                            long x = lround(p->q[0]), y = lround(p->q[1]);
                            if (x >= 0 && y >= 0 && x < width && y < height) g = sh->gain_map[y * (long)width + x];
                        }
                        P += sh->kc * g * S;
                        for (int l = 0; l < nl && l < 32; l++)
                            if (ls[idx * (size_t)nl + (size_t)l].V > 0.5) litcount[l]++;
                    }
                    sumP += P;
                    int cnt = 0;
                    for (int j2 = 0; j2 < n; j2++)
                        if (pi[2 * (k + (size_t)j2) + (size_t)side].face == p->face) cnt++;
                    if (cnt > best_count) {
                        best_count = cnt;
                        best_face = p->face;
                    }
                }
                sg->P_side[side] = sumP / n;
                sg->face_side[side] = best_face;
                uint32_t bits = 0;
                for (int l = 0; l < nl && l < 32; l++)
                    if (2 * litcount[l] >= n) bits |= 1u << l;
                sg->lit_side[side] = bits;
            }
            sg->contrast = sg->P_side[0] - sg->P_side[1];
            k += (size_t)n;
        }
    }
    ok = true;
done:
    free(p3);
    free(q);
    free(qside);
    free(pi);
    free(ls);
    return ok;
}

// ---------------------------------------------------------------------------

model_edges_t *model_edges_predict(const model_scene_t *scene,
                                   const model_tracer_t *t, model_camera_t *cam,
                                   const model_lamps_t *lamps,
                                   const model_material_t *const *mats,
                                   const model_shading_t *sh, double feature_angle_deg)
{
    if (!scene || !t || !cam || !mats || !sh) {
        MODEL_FAIL("model_edges_predict: scene, tracer, camera, materials and shading are required");
        return NULL;
    }
    if (!(feature_angle_deg >= 0 && feature_angle_deg < 180)) {
        model_error(NULL, 0, "feature angle %g deg out of range: use 0 <= angle < 180", feature_angle_deg);
        return NULL;
    }
    if (lamps && lamps->n > 32) {
        model_error(lamps->path, 0, "%d lamps: the edge query reports at most 32 lamps per side", lamps->n);
        return NULL;
    }
    model_edges_t *E = scene_edges(scene, feature_angle_deg);
    if (!E) return NULL;
    double **seg_t = calloc((size_t)(E->nedges ? E->nedges : 1), sizeof *seg_t);
    bool ok = false;
    if (!seg_t) {
        MODEL_FAIL("out of memory");
        goto done;
    }
    double rt[6], R[3][3];
    model_camera_rt_cam_world(cam, rt);
    rodrigues(rt, R);
    vis_ctx_t c = {
        .t = t, .cam = cam, .scene = scene, .edges = E, .vertices = scene->vertices,
        .centre = model_camera_centre_world(cam),
        .axis = v3(R[2][0], R[2][1], R[2][2]),
        .width = model_camera_width(cam), .height = model_camera_height(cam),
        .seg_t = seg_t,
    };
    int nthreads = sh->nthreads > 0 ? sh->nthreads : model_default_threads();
    model_parallel_for(E->nedges, 1, nthreads, vis_worker, &c);
    if (atomic_load(&c.failed)) {
        MODEL_FAIL("edge visibility: projection failed or out of memory");
        goto done;
    }
    ok = shade_sides(t, cam, lamps, mats, sh, E, seg_t, scene->vertices, c.centre, c.axis, c.width, c.height);
done:
    if (seg_t)
        for (int i = 0; i < E->nedges; i++) free(seg_t[i]);
    free(seg_t);
    if (!ok) {
        model_edges_free(E);
        return NULL;
    }
    return E;
}

void model_edges_free(model_edges_t *e)
{
    if (!e) return;
    if (e->edges)
        for (int i = 0; i < e->nedges; i++) free(e->edges[i].segments);
    free(e->edges);
    free(e);
}
