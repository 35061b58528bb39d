// rig/virtual/texture.c — the albedo texture and roughness weights of a view:
// value noise in each textured face's own frame (see texture_t in rig/virtual/internal.h).
#include <math.h>
#include <stdlib.h>

#include "model/base/vec.h"
#include "rig/virtual/internal.h"

// Lattice value in [-1, 1).
static inline double lattice(uint64_t seed, int64_t ix, int64_t iy)
{
    uint64_t h = model_mix64(seed ^ ((uint64_t)ix * 0x632be59bd9b4e019ULL) ^ ((uint64_t)iy * 0xd1b54a32d192ed03ULL));
    return (double)(h >> 11) * 0x1.0p-52 - 1.0;
}

static inline double quintic(double t) { return t * t * t * (t * (6 * t - 15) + 10); }

// The lattice values of the cell last used at one octave: neighbouring pixels
// mostly fall in the same cell (a cell of the finest octave spans several
// pixels), so they reuse its corners instead of hashing them again.
typedef struct {
    uint64_t seed;
    int64_t  iu, iw;
    double   a, b, c, d;   // (iu, iw), (iu+1, iw), (iu, iw+1), (iu+1, iw+1)
    bool     set;
} cell_cache_t;

static double value_noise(cell_cache_t *cc, uint64_t seed, double u, double w)
{
    double fu = floor(u), fw = floor(w);
    int64_t iu = (int64_t)fu, iw = (int64_t)fw;
    double su = quintic(u - fu), sw = quintic(w - fw);
    if (!cc->set || cc->seed != seed || cc->iu != iu || cc->iw != iw) {
        *cc = (cell_cache_t){ seed, iu, iw, lattice(seed, iu, iw), lattice(seed, iu + 1, iw),
                              lattice(seed, iu, iw + 1), lattice(seed, iu + 1, iw + 1), true };
    }
    double a = cc->a, b = cc->b, c = cc->c, d = cc->d;
    return (a + su * (b - a)) + sw * ((c + su * (d - c)) - (a + su * (b - a)));
}

// The seed of a face's texture.
static uint64_t texture_seed(const texture_t *tx, int face_number)
{
    return model_mix64(tx->seed ^ model_mix64((uint64_t)face_number));
}

// The texture's noise n(u, w) in [-1, 1] (u, w in mm in the face's frame;
// seed from texture_seed); cc: the caller's cache of 3 cells (one per octave).
static double texture_noise(cell_cache_t cc[3], const texture_t *tx, uint64_t seed, double u, double w)
{
    double sum = 0, amp = 1, f = 1.0 / tx->scale_mm;
    for (int o = 0; o < 3; o++) {
        sum += amp * value_noise(&cc[o], seed + (uint64_t)o, u * f, w * f);
        amp *= 0.5;
        f *= 2;
    }
    return sum / 1.75;
}

// A textured face's frame: origin v0 (its first vertex), unit u axis e1 along
// its first edge, e2 = normal x e1; NULL tx when untextured.
typedef struct {
    const texture_t *tx;
    uint64_t         seed;
    model_vec3_t     v0, e1, e2;
} face_frame_t;

typedef struct {
    rig_virtual_t       *v;
    const tracer_slot_t *slot;
    const int32_t       *face;
    const model_vec3_t  *rays;
    model_vec3_t         c;
    const face_frame_t  *ff;   // per face of the slot's scene
} tex_job_t;

static void texture_rows(void *ctx, int begin, int end, int thread)
{
    const tex_job_t *J = ctx;
    const rig_virtual_t *v = J->v;
    const model_scene_t *sc = J->slot->rot;
    const model_vec3_t c = J->c;
    cell_cache_t cc[3] = { { 0 } }, cr[3] = { { 0 } };
    for (size_t i = (size_t)begin * v->W; i < (size_t)end * v->W; i++) {
        float *out = &J->slot->tex[i];
        *out = 1.0f;
        if (J->slot->rough) J->slot->rough[i] = 0.5f;
        int f = J->face[i];
        if (f < 0 || f >= sc->nfaces || !J->ff[f].tx) continue;
        const model_face_t *F = &sc->faces[f];
        const face_frame_t *fr = &J->ff[f];
        model_vec3_t nn = F->normal, d = J->rays[i];
        double den = nn.x * d.x + nn.y * d.y + nn.z * d.z;
        if (den == 0) continue;
        double t = (F->offset_mm - (nn.x * c.x + nn.y * c.y + nn.z * c.z)) / den;
        model_vec3_t p = { c.x + t * d.x, c.y + t * d.y, c.z + t * d.z };
        model_vec3_t v0 = fr->v0, e1 = fr->e1, e2 = fr->e2;
        model_vec3_t q = { p.x - v0.x, p.y - v0.y, p.z - v0.z };
        double u = q.x * e1.x + q.y * e1.y + q.z * e1.z, w = q.x * e2.x + q.y * e2.y + q.z * e2.z;
        *out = (float)(1.0 + fr->tx->amplitude * texture_noise(cc, fr->tx, fr->seed, u, w));
        if (J->slot->rough && fr->tx->roughness_amplitude > 0)
            J->slot->rough[i] =
                (float)(0.5 + 0.5 * texture_noise(cr, fr->tx, model_mix64(fr->seed ^ 0x70756768ULL), u, w));
    }
}

// The frames of the textured faces of a slot's scene (NULL: out of memory).
static face_frame_t *face_frames(const rig_virtual_t *v, const tracer_slot_t *slot)
{
    const sample_t *sm = &v->samples[slot->sample];
    const model_scene_t *sc = slot->rot;
    face_frame_t *ff = calloc(sc->nfaces > 0 ? (size_t)sc->nfaces : 1, sizeof *ff);
    if (!ff) return NULL;
    for (int f = 0; f < sc->nfaces; f++) {
        const model_face_t *F = &sc->faces[f];
        const texture_t *tx = sm->tex[F->material];
        if (!tx || F->nverts < 2) continue;
        model_vec3_t nn = F->normal;
        model_vec3_t v0 = sc->vertices[F->verts[0]], v1 = sc->vertices[F->verts[1]];
        model_vec3_t e1 = { v1.x - v0.x, v1.y - v0.y, v1.z - v0.z };
        double l1 = sqrt(e1.x * e1.x + e1.y * e1.y + e1.z * e1.z);
        if (!(l1 > 0)) continue;
        e1 = (model_vec3_t){ e1.x / l1, e1.y / l1, e1.z / l1 };
        model_vec3_t e2 = { nn.y * e1.z - nn.z * e1.y, nn.z * e1.x - nn.x * e1.z, nn.x * e1.y - nn.y * e1.x };
        ff[f] = (face_frame_t){ tx, texture_seed(tx, F->number), v0, e1, e2 };
    }
    return ff;
}

// The texture factors of a slot's view from the full-resolution face ids.
bool rig_vtexture_make(rig_virtual_t *v, tracer_slot_t *slot, const int32_t *face)
{
    size_t n = (size_t)v->W * v->H;
    slot->tex = malloc(n * sizeof *slot->tex);
    if (v->samples[slot->sample].rough && slot->tex && !(slot->rough = malloc(n * sizeof *slot->rough))) {
        free(slot->tex);
        slot->tex = NULL;
    }
    if (!slot->tex) {
        model_error(v->truth_path, 0, "out of memory for a texture image");
        return false;
    }
    const model_vec3_t *rays = model_camera_ray_table(v->cam, NULL);
    if (!rays) {
        free(slot->tex);
        slot->tex = NULL;
        return false;
    }
    face_frame_t *ff = face_frames(v, slot);
    if (!ff) {
        free(slot->tex);
        slot->tex = NULL;
        model_error(v->truth_path, 0, "out of memory for a texture image");
        return false;
    }
    tex_job_t J = { v, slot, face, rays, model_camera_centre_world(v->cam), ff };
    model_parallel_for(v->H, 16, model_default_threads(), texture_rows, &J);
    free(ff);
    return true;
}
