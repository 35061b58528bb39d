// model/render/shade.c — grey values and the renderer (thesis eq. 19 with
// interreflection, thesis 3.4 / 4.5).
//
//   P(x,y) = Pa + kc * g(x,y) * [ sum_i V_i I_i R_i / d_i^2  + interreflection ]
//
// The full-image renderer casts primary rays from the camera's ray table in
// Embree packets of 4x4 pixels, shadow rays per lamp in packets too, and
// shades in the same pass; block rows of the image are shared between threads.
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE__)
#include <pmmintrin.h>
#include <xmmintrin.h>
#endif

#include "model/internal.h"

model_shading_t model_shading_default(void)
{
    return (model_shading_t){
        .kc = 1.0,
        .Pa = 0.0,
        .gain_map = NULL,
        .interreflection = MODEL_INTERREFLECTION_NONE,
        .rho = 0.05,
        .thesis_samples = 9,
        .thesis_cone_deg = 10.0,
        .mc_samples = 16,
        .mc_bounces = 2,
        .finite_lamps = true,
        .seed = 1,
        .nthreads = 0,
    };
}

static const char *const interreflection_names[] = { "none", "thesis", "mc" };

const char *model_interreflection_name(model_interreflection_t m)
{
    if ((int)m < 0 || (int)m >= 3) return "unknown";
    return interreflection_names[m];
}

int model_interreflection_from_name(const char *name)
{
    if (!name) return -1;
    for (int i = 0; i < 3; i++)
        if (!strcmp(name, interreflection_names[i])) return i;
    return -1;
}

bool model_resolve_materials(const model_scene_t *scene, const model_materials_t *mats,
                             const model_material_t **out)
{
    if (!scene || !mats || !out) {
        MODEL_FAIL("model_resolve_materials: missing scene, materials or output");
        return false;
    }
    for (int k = 0; k < scene->nmaterials; k++) {
        out[k] = model_materials_find(mats, scene->material_names[k]);
        if (!out[k]) {
            model_error(mats->path ? mats->path : "materials", 0,
                        "no material \"%s\", which the scene %s uses; add a [material %s] "
                        "section (with model = ... and its parameters)",
                        scene->material_names[k], scene->path ? scene->path : "",
                        scene->material_names[k]);
            return false;
        }
    }
    return true;
}

double model_lamp_emission(const model_lamp_t *L, model_vec3_t p)
{
    if (!(L->emission_cos_power > 0)) return 1.0;
    model_vec3_t u = v3_sub(p, L->position_mm), a = L->emission_axis;
    double d = v3_norm(u);
    if (a.x == 0 && a.y == 0 && a.z == 0) a = v3_scale(L->position_mm, -1.0 / v3_norm(L->position_mm));
    double c = d > 0 ? v3_dot(a, u) / d : 0;
    return c > 0 ? pow(c, L->emission_cos_power) : 0.0;
}

double model_material_eval(const model_material_t *mat, const model_cosines_t *c)
{
    return mat->table ? model_brdf_table_eval(mat->table, c) : model_brdf_eval(mat->model, mat->p, c, NULL);
}

double model_direct_sum(const model_pixel_info_t *pi, const model_lamp_sample_t *ls,
                        const model_lamps_t *lamps, const model_material_t *mat, double *dS_dp)
{
    int np = mat ? model_brdf_nparams(mat->model) : 0;
    if (dS_dp)
        for (int k = 0; k < np; k++) dS_dp[k] = 0;
    if (!pi || pi->face < 0 || !ls || !lamps || !mat) return 0.0;
    double S = 0, dR[MODEL_BRDF_MAX_PARAMS];
    for (int i = 0; i < lamps->n; i++) {
        if (!(ls[i].V > 0) || !(ls[i].d_mm > 0)) continue;
        model_cosines_t c = model_cosines(pi->n, ls[i].l, pi->v);
        double w = ls[i].V * lamps->lamps[i].intensity / (ls[i].d_mm * ls[i].d_mm);
        if (lamps->lamps[i].emission_cos_power > 0)
            w *= model_lamp_emission(&lamps->lamps[i], pi->p_mm);
        double R = mat->table ? model_brdf_table_eval(mat->table, &c)
                              : model_brdf_eval(mat->model, mat->p, &c, dS_dp ? dR : NULL);
        if (mat->table && dS_dp)
            for (int k = 0; k < np; k++) dR[k] = 0;   // a table has no parameters
        S += w * R;
        if (dS_dp)
            for (int k = 0; k < np; k++) dS_dp[k] += w * dR[k];
    }
    return S;
}

// ---------------------------------------------------------------------------
// Renderer

typedef struct {
    const model_tracer_t *t;
    const model_vec3_t *rays;
    int W, H, tw, th;
    model_vec3_t o;
    const model_lamps_t *lamps;
    int nl;
    const model_material_t *const *mats;
    const model_shading_t *sh;
    float *P;
    int32_t *face;
    uint8_t *lit;
    double eps;
    // thesis cone pattern: unit directions in a local frame, z = the mirror direction
    int ncone;
    model_vec3_t *cone;
    bool mc_finite;            // MC: some lamps are sampled on their sphere
    atomic_bool bad_material;
    atomic_int bad_material_index;
} render_ctx_t;

#define BLK 4    // packets of BLK x BLK pixels
#define TILE 8   // tiles of TILE x TILE pixels (culled as a whole)

// An orthonormal frame (a, b, n) around the unit vector n.
static inline const model_material_t *material_of(render_ctx_t *c, int32_t m)
{
    const model_material_t *mat = m >= 0 ? c->mats[m] : NULL;
    if (!mat && !atomic_exchange(&c->bad_material, true)) atomic_store(&c->bad_material_index, m);
    return mat;
}

// R of a material from the cosines, without derivatives (model/brdf/brdf.c is the
// one source of the formulas).
static inline double brdf_value(const model_material_t *mat, const model_cosines_t *c)
{
    return model_material_eval(mat, c);
}

static inline double brdf(const model_material_t *mat, model_vec3_t n, model_vec3_t l,
                          model_vec3_t v)
{
    model_cosines_t cs = model_cosines(n, l, v);
    return brdf_value(mat, &cs);
}

// Cosines when n.l is known and l, v, n are unit (h = (l+v)/|l+v|).
static inline model_cosines_t cosines_fast(model_vec3_t n, model_vec3_t l, model_vec3_t v,
                                           double nl, double nv)
{
    model_cosines_t c = { .nl = nl, .nv = nv, .nh = 0, .vh = 0 };
    model_vec3_t s = v3_add(l, v);
    double len2 = v3_dot(s, s);
    if (len2 > 1e-24) {
        double inv = 1.0 / sqrt(len2);
        c.nh = v3_dot(n, s) * inv;
        c.vh = v3_dot(v, s) * inv;
    }
    return c;
}

// Direct light of point lamps (lamp centres) at surface point (p, n, v):
// sum_i V_i I_i R / d_i^2, with V_i from a shadow ray.
static double direct_point(render_ctx_t *c, const model_material_t *mat, model_vec3_t p,
                           model_vec3_t n, model_vec3_t v)
{
    double S = 0;
    for (int i = 0; i < c->nl; i++) {
        const model_lamp_t *L = &c->lamps->lamps[i];
        model_vec3_t dl = v3_sub(L->position_mm, p);
        double d2 = v3_dot(dl, dl);
        if (!(d2 > 0)) continue;
        model_vec3_t l = v3_scale(dl, 1.0 / sqrt(d2));
        if (v3_dot(l, n) <= 0) continue;
        double R = brdf(mat, n, l, v);
        if (R == 0) continue;
        if (!model_tracer_visible_from(c->t, p, n, L->position_mm)) continue;
        S += L->intensity * R / d2 * (L->emission_cos_power > 0 ? model_lamp_emission(L, p) : 1.0);
    }
    return S;
}

// One sample of lamp i's light at (p, n, v) for the MC renderer. A lamp of
// radius r > 0 is a sphere of uniform radiance Le = I / (pi r^2) (intensity I
// in every direction; with an emission pattern, I that toward p); a direction w is drawn uniformly in the cone of solid
// angle Omega = 2 pi (1 - cos theta_max) the sphere subtends, and the estimate is
//   V(p -> sphere point along w) * Le * Omega * R(w, v, n)
// (-> I R / d^2 as r -> 0).
// lamp_draw draws the direction: it returns the weight (Le Omega, or I / d^2
// for a point lamp or a point inside the sphere) and the unit direction w and
// the point `target` the shadow ray goes to; 0 when nothing can arrive.
// Stratified when a pixel takes several (ns > 1, this is draw k of them): the
// cone is cut into nr x (ns / nr) cells of equal solid angle (nr = the largest
// divisor of ns up to sqrt(ns); 1 - cos theta by nr, the azimuth by ns / nr),
// one jittered draw in cell k. The estimate stays unbiased, and a narrow lobe's
// value over the lamp's disc (a smooth integrand) is integrated with far less
// noise than by independent draws (16 independent draws of a 15 mm lamp left
// a glossy coupon's highlight at grazing ~1 % noisy per 5x5-pixel window).
static double lamp_draw(render_ctx_t *c, int i, model_vec3_t p, model_rng_t *rng, int k, int ns,
                        model_vec3_t *w_out, model_vec3_t *target)
{
    const model_lamp_t *L = &c->lamps->lamps[i];
    model_vec3_t dl = v3_sub(L->position_mm, p);
    double d2 = v3_dot(dl, dl), d = sqrt(d2), r = L->radius_mm;
    if (!(d > 0)) return 0;
    model_vec3_t axis = v3_scale(dl, 1.0 / d);
    // the emission pattern toward p (a finite lamp's whole sphere by that of its centre)
    double I = L->emission_cos_power > 0 ? L->intensity * model_lamp_emission(L, p) : L->intensity;
    if (!c->sh->finite_lamps || !(r > 0) || d <= r * (1 + 1e-9)) {
        *w_out = axis;
        *target = L->position_mm;
        return I / d2;
    }
    double s2max = r * r / d2;                          // sin^2 theta_max
    double one_m_cos = s2max / (1 + sqrt(1 - s2max));   // 1 - cos theta_max, stable
    double u1 = model_rng_uniform(rng), cx, cy, inv_r = 1;
    if (ns > 1) {
        int nr = 1;
        for (int q = 1; q * q <= ns; q++)
            if (ns % q == 0) nr = q;
        int na = ns / nr, kr = (k % ns) / na, ka = (k % ns) % na;
        u1 = (kr + u1) / nr;
        double phi = 2 * M_PI * (ka + model_rng_uniform(rng)) / na;
        cx = cos(phi);
        cy = sin(phi);
    } else {
        // a uniform direction (cos phi, sin phi) in the plane, by rejection from
        // the square (no trigonometry: this is the renderer's inner loop)
        double r2;
        do {
            cx = 2 * model_rng_uniform(rng) - 1;
            cy = 2 * model_rng_uniform(rng) - 1;
            r2 = cx * cx + cy * cy;
        } while (r2 > 1 || r2 < 1e-12);
        inv_r = 1 / sqrt(r2);
    }
    double one_m_ct = u1 * one_m_cos;
    double ct = 1 - one_m_ct, st = sqrt(fmax(0.0, one_m_ct * (2 - one_m_ct)));
    model_vec3_t a, b;
    frame_of(axis, &a, &b);
    model_vec3_t w = v3_add(v3_scale(axis, ct),
                            v3_add(v3_scale(a, st * cx * inv_r), v3_scale(b, st * cy * inv_r)));
    // distance to the sphere's near surface along w
    double disc = r * r - d2 * st * st;
    double tt = d * ct - sqrt(fmax(0.0, disc));
    *w_out = w;
    *target = v3_add(p, v3_scale(w, tt));
    return I / (M_PI * r * r) * (2 * M_PI * one_m_cos);
}

// lamp_draw plus the shadow ray and R: one estimate; *V its visibility (0 or 1).
static double lamp_sample(render_ctx_t *c, int i, const model_material_t *mat, model_vec3_t p,
                          model_vec3_t n, model_vec3_t v, model_rng_t *rng, double *V)
{
    model_vec3_t w, target;
    *V = 0;
    double weight = lamp_draw(c, i, p, rng, 0, 1, &w, &target);
    if (!(weight > 0) || v3_dot(w, n) <= 0) return 0;
    double R = brdf(mat, n, w, v);
    if (!(R > 0)) return 0;
    if (!model_tracer_visible_from(c->t, p, n, target)) return 0;
    *V = 1;
    return weight * R;
}

// Thesis interreflection at x = (p, n, v) (thesis 3.4 / 4.5, eq. 18):
//   rays w_k, k = 1..N, in a cone of half-angle thesis_cone_deg around the
//   mirror direction r = 2 (n.v) n - v; the nearest hit y_k is a virtual point
//   source of intensity toward x
//       I_r(y) = rho_k sum_i V_i(y) I_i R_y(l_i(y), -w_k, n_y) / d_i(y)^2
//   where rho_k weighs the area of surface the sample stands for (eq. 18).
//   The rays sample directions: a cone of fixed solid angle meets an area that
//   grows as |y_k - x|^2, so rho_k = rho |y_k - x|^2 and the point-source law
//   I_r R_x / |y_k - x|^2 leaves
//       rho / N * sum_k L(y_k -> x) R_x(w_k, v, n),
//   L(y -> x) = sum_i V_i(y) I_i R_y / d_i(y)^2 the radiance of y toward x.
//   rho is a solid angle (sr); the thesis's literal 1/|y - x|^2 with a constant
//   rho diverges where two faces meet (the web/plate joint of the T-stiffener).
static double thesis_term(render_ctx_t *c, const model_material_t *mat, model_vec3_t p,
                          model_vec3_t n, model_vec3_t v)
{
    model_vec3_t r = v3_unit(v3_sub(v3_scale(n, 2 * v3_dot(n, v)), v));
    model_vec3_t a, b;
    frame_of(r, &a, &b);
    model_vec3_t org = v3_add(p, v3_scale(n, c->eps));
    double sum = 0;
    for (int k = 0; k < c->ncone; k++) {
        model_vec3_t lw = c->cone[k];
        model_vec3_t w = v3_add(v3_scale(r, lw.z), v3_add(v3_scale(a, lw.x), v3_scale(b, lw.y)));
        if (v3_dot(w, n) <= 0) continue;
        model_pixel_info_t y;
        model_tracer_cast(c->t, org, w, &y);
        if (y.face < 0) continue;
        const model_material_t *maty = material_of(c, y.material);
        if (!maty) continue;
        double Ir = direct_point(c, maty, y.p_mm, y.n, y.v);
        if (Ir == 0) continue;
        sum += Ir * brdf(mat, n, w, v);
    }
    return c->sh->rho / c->ncone * sum;
}

// MC indirect light at the primary hit x0 = pi: mc_samples paths of
// mc_bounces indirect bounces with direct light at every vertex, divided by
// mc_samples (the direct light at x0 itself is the caller's: point lamps exact,
// finite lamps sampled in shadow packets). rng: the pixel's stream.
//   Indirect: w from the cosine-weighted hemisphere about n, pdf = (n.w)/pi;
//   throughput *= f_r (n.w) / pdf = R(w, v, n) pi / (n.w), f_r = R / (n.w).
static double mc_term(render_ctx_t *c, const model_material_t *mat0,
                      const model_pixel_info_t *pi, model_rng_t *rngp)
{
    const model_shading_t *sh = c->sh;
    model_rng_t rng = *rngp;
    double sum = 0;
    for (int s = 0; s < sh->mc_samples; s++) {
        model_vec3_t p = pi->p_mm, n = pi->n, v = pi->v;
        const model_material_t *mat = mat0;
        double beta = 1;
        for (int bnc = 0; bnc < sh->mc_bounces; bnc++) {
            double u1 = model_rng_uniform(&rng), u2 = model_rng_uniform(&rng);
            double rr = sqrt(u1), phi = 2 * M_PI * u2;
            double cz = sqrt(fmax(0.0, 1 - u1));
            if (!(cz > 0)) break;
            model_vec3_t a, b;
            frame_of(n, &a, &b);
            model_vec3_t w = v3_add(v3_scale(n, cz),
                                    v3_add(v3_scale(a, rr * cos(phi)), v3_scale(b, rr * sin(phi))));
            double R = brdf(mat, n, w, v);
            if (!(R > 0)) break;
            beta *= R * M_PI / cz;
            model_pixel_info_t y;
            model_tracer_cast(c->t, v3_add(p, v3_scale(n, c->eps)), w, &y);
            if (y.face < 0) break;
            mat = material_of(c, y.material);
            if (!mat) break;
            p = y.p_mm;
            n = y.n;
            v = y.v;
            double D = 0;
            for (int i = 0; i < c->nl; i++) {
                double V;
                D += lamp_sample(c, i, mat, p, n, v, &rng, &V);
            }
            sum += beta * D;
        }
    }
    *rngp = rng;
    return sum / sh->mc_samples;
}

// The pixels [x0, x1) x [y0, y1) see the background.
static void fill_background(render_ctx_t *c, int x0, int x1, int y0, int y1)
{
    const size_t npix = (size_t)c->W * c->H;
    for (int y = y0; y < y1; y++)
        for (int x = x0; x < x1; x++) {
            size_t i = (size_t)y * c->W + x;
            if (c->sh->pixel_mask && !c->sh->pixel_mask[i]) continue;
            c->P[i] = (float)c->sh->Pa;
            if (c->face) c->face[i] = -1;
            if (c->lit)
                for (int a = 0; a < c->nl; a++) c->lit[a * npix + i] = 0;
        }
}

// Scratch space of one packet (per thread, no allocation per pixel).
typedef struct {
    model_vec3_t dirs[16], pts[16], nrm[16], l[16];
    double nl[16], nv[16], w[16], S[16];
    model_shadow_packet_t sp;
    model_pixel_info_t pi[16];
    model_rng_t rng[16];
    size_t pix[16];
    int hit[16];
    uint8_t vis[16];
    const model_material_t *mat[16];
} packet_t;

// Lane k's shadow segment from the surface point p (normal n) along dl to
// about eps short of its end (inv = 1 / |dl|): from p + eps n to p + dl.
static void shadow_lane(model_shadow_packet_t *sp, int k, model_vec3_t p, model_vec3_t n, model_vec3_t dl,
                        double eps, double inv)
{
    sp->org_x[k] = (float)(p.x + eps * n.x);
    sp->org_y[k] = (float)(p.y + eps * n.y);
    sp->org_z[k] = (float)(p.z + eps * n.z);
    sp->dir_x[k] = (float)(dl.x - eps * n.x);
    sp->dir_y[k] = (float)(dl.y - eps * n.y);
    sp->dir_z[k] = (float)(dl.z - eps * n.z);
    sp->tfar[k] = (float)(1 - eps * inv);
    sp->active[k] = 1;
}

// The pixels of block (bx, by) to render (the mask's), their indices and
// rays into the packet; returns their number.
static int packet_gather(const render_ctx_t *c, packet_t *pk, int bx, int by)
{
    const model_shading_t *sh = c->sh;
    const int W = c->W, H = c->H;
    int m = 0;
    for (int y = by * BLK; y < by * BLK + BLK && y < H; y++)
        for (int x = bx * BLK; x < bx * BLK + BLK && x < W; x++) {
            if (sh->pixel_mask && !sh->pixel_mask[(size_t)y * W + x]) continue;
            pk->pix[m] = (size_t)y * W + x;
            pk->dirs[m] = c->rays[pk->pix[m]];
            m++;
        }
    return m;
}

// After the primary packet: each lane's material (hit: a face with a known
// material), point, normal and n.v, the face ids written; S cleared.
// Returns the number of lanes that hit.
static int packet_hits(render_ctx_t *c, packet_t *pk, int m)
{
    const model_pixel_info_t *pi = pk->pi;
    int nhit = 0;
    for (int k = 0; k < 16; k++) {
        pk->S[k] = 0;
        pk->mat[k] = k < m && pi[k].face >= 0 ? material_of(c, pi[k].material) : NULL;
        pk->hit[k] = pk->mat[k] != NULL;
        nhit += pk->hit[k];
        if (k >= m) continue;
        pk->pts[k] = pi[k].p_mm;
        pk->nrm[k] = pi[k].n;
        pk->nv[k] = v3_dot(pi[k].n, pi[k].v);
        if (c->face) c->face[pk->pix[k]] = pi[k].face;
    }
    return nhit;
}

// Direct light of the lamps' centres (point lamps; finite lamps under MC are
// sampled by packet_finite_lamps), a shadow packet per lamp, added to S.
static void packet_point_lamps(render_ctx_t *c, packet_t *pk, int m, int nhit)
{
    const size_t npix = (size_t)c->W * c->H;
    const double eps = c->eps;
    const model_pixel_info_t *pi = pk->pi;
    for (int i = 0; i < c->nl; i++) {
        const model_lamp_t *L = &c->lamps->lamps[i];
        bool sampled = c->mc_finite && L->radius_mm > 0;   // done by mc_term
        if (!nhit || sampled) {
            if (c->lit && !sampled)
                for (int k = 0; k < m; k++) c->lit[i * npix + pk->pix[k]] = 0;
            continue;
        }
        // lamp direction, distance and shadow segment of the lanes that see the lamp
        const model_vec3_t Lp = L->position_mm;
        const double I = L->intensity;
        model_shadow_packet_t *sp = &pk->sp;
        int nact = 0;
        for (int k = 0; k < 16; k++) {
            sp->active[k] = 0;
            if (!pk->hit[k]) continue;
            model_vec3_t dl = v3_sub(Lp, pk->pts[k]), n = pk->nrm[k];
            double ndl = v3_dot(n, dl);
            if (!(ndl > 0)) continue;   // the face itself hides the lamp
            double inv = 1.0 / sqrt(v3_dot(dl, dl));
            pk->l[k] = v3_scale(dl, inv);
            pk->nl[k] = ndl * inv;
            pk->w[k] = I * inv * inv;
            if (L->emission_cos_power > 0) pk->w[k] *= model_lamp_emission(L, pk->pts[k]);
            shadow_lane(sp, k, pk->pts[k], n, dl, eps, inv);
            nact++;
        }
        if (nact)
            model_tracer_visible_packet(c->t, sp, pk->vis);
        else
            memset(pk->vis, 0, sizeof pk->vis);
        for (int k = 0; k < m; k++) {
            if (c->lit) c->lit[i * npix + pk->pix[k]] = pk->vis[k];
            if (!pk->vis[k]) continue;
            model_cosines_t cs = cosines_fast(pk->nrm[k], pk->l[k], pi[k].v, pk->nl[k], pk->nv[k]);
            pk->S[k] += pk->w[k] * brdf_value(pk->mat[k], &cs);
        }
    }
}

// Finite lamps (MC): mc_samples directions per lamp and pixel, drawn from
// the pixel's own random stream (model_rng(seed, pixel index)), shadow rays
// in packets, added to S.
static void packet_finite_lamps(render_ctx_t *c, packet_t *pk, int m, int nhit)
{
    const model_shading_t *sh = c->sh;
    const size_t npix = (size_t)c->W * c->H;
    const double eps = c->eps;
    const model_pixel_info_t *pi = pk->pi;
    if (sh->interreflection == MODEL_INTERREFLECTION_MC)
        for (int k = 0; k < m; k++) pk->rng[k] = model_rng(sh->seed, pk->pix[k]);
    for (int i = 0; c->mc_finite && nhit && i < c->nl; i++) {
        if (!(c->lamps->lamps[i].radius_mm > 0)) continue;
        model_shadow_packet_t *sp = &pk->sp;
        int nvis[16] = { 0 };
        const double inv_samples = 1.0 / sh->mc_samples;
        for (int smp = 0; smp < sh->mc_samples; smp++) {
            int nact = 0;
            for (int k = 0; k < 16; k++) {
                sp->active[k] = 0;
                if (!pk->hit[k]) continue;
                model_vec3_t w, target;
                double wt = lamp_draw(c, i, pk->pts[k], &pk->rng[k], smp, sh->mc_samples, &w, &target);
                double nw = v3_dot(pk->nrm[k], w);
                if (!(wt > 0) || !(nw > 0)) continue;
                model_cosines_t cs = cosines_fast(pk->nrm[k], w, pi[k].v, nw, pk->nv[k]);
                double R = brdf_value(pk->mat[k], &cs);
                if (!(R > 0)) continue;
                pk->w[k] = wt * R * inv_samples;
                model_vec3_t n = pk->nrm[k], dl = v3_sub(target, pk->pts[k]);
                double inv = 1.0 / sqrt(v3_dot(dl, dl));
                shadow_lane(sp, k, pk->pts[k], n, dl, eps, inv);
                nact++;
            }
            if (!nact) continue;
            model_tracer_visible_packet(c->t, sp, pk->vis);
            for (int k = 0; k < m; k++)
                if (sp->active[k] && pk->vis[k]) {
                    pk->S[k] += pk->w[k];
                    nvis[k]++;
                }
        }
        if (c->lit)
            for (int k = 0; k < m; k++) c->lit[i * npix + pk->pix[k]] = 2 * nvis[k] > sh->mc_samples;
    }
}

// Each pixel's grey value: S with the interreflection term, Pa + kc g S; a
// lane without a material is background.
static void packet_finish(render_ctx_t *c, packet_t *pk, int m)
{
    const model_shading_t *sh = c->sh;
    const size_t npix = (size_t)c->W * c->H;
    for (int k = 0; k < m; k++) {
        size_t i = pk->pix[k];
        if (!pk->mat[k]) {
            c->P[i] = (float)sh->Pa;
            if (c->lit && c->mc_finite)
                for (int a = 0; a < c->nl; a++) c->lit[a * npix + i] = 0;
            continue;
        }
        double S = pk->S[k];
        if (sh->interreflection == MODEL_INTERREFLECTION_THESIS && sh->rho != 0) {
            S += thesis_term(c, pk->mat[k], pk->pts[k], pk->nrm[k], pk->pi[k].v);
        } else if (sh->interreflection == MODEL_INTERREFLECTION_MC && sh->mc_bounces > 0) {
            S += mc_term(c, pk->mat[k], &pk->pi[k], &pk->rng[k]);
        }
        double g = sh->gain_map ? sh->gain_map[i] : 1.0;
        c->P[i] = (float)(sh->Pa + sh->kc * g * S);
    }
}

// Render the BLK x BLK pixels of block (bx, by): one primary packet, one
// shadow packet per lamp, then the sums (and the interreflection terms).
static void render_packet(render_ctx_t *c, packet_t *pk, int bx, int by)
{
    const int W = c->W, H = c->H;
    int m = packet_gather(c, pk, bx, by);
    if (!m) return;
    if (!model_tracer_cast_packet(c->t, c->o, pk->dirs, m, pk->pi)) {
        fill_background(c, bx * BLK, bx * BLK + BLK < W ? bx * BLK + BLK : W, by * BLK,
                        by * BLK + BLK < H ? by * BLK + BLK : H);
        return;
    }
    int nhit = packet_hits(c, pk, m);
    packet_point_lamps(c, pk, m, nhit);
    packet_finite_lamps(c, pk, m, nhit);
    packet_finish(c, pk, m);
}

// Rows of tiles [begin, end): a tile whose cone of rays misses the scene's
// bounding box is background as a whole, the others go by packets.
static void render_rows(void *vctx, int begin, int end, int thread)
{
    render_ctx_t *c = vctx;
    (void)thread;
#if defined(__SSE__)
    unsigned csr = _mm_getcsr();   // Embree's advice: flush denormals to zero
    _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
    _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
#endif
    const int W = c->W, H = c->H;
    packet_t pk;
    memset(&pk, 0, sizeof pk);
    model_vec3_t tdirs[TILE * TILE];
    for (int ty = begin; ty < end; ty++)
        for (int tx = 0; tx < c->tw; tx++) {
            int x0 = tx * TILE, y0 = ty * TILE;
            int x1 = x0 + TILE < W ? x0 + TILE : W, y1 = y0 + TILE < H ? y0 + TILE : H;
            int tm = 0;
            for (int y = y0; y < y1; y++)
                for (int x = x0; x < x1; x++)
                    if (!c->sh->pixel_mask || c->sh->pixel_mask[(size_t)y * W + x])
                        tdirs[tm++] = c->rays[(size_t)y * W + x];
            if (!tm) continue;   // no pixel of the mask
            if (model_tracer_rays_miss(c->t, c->o, tdirs, tm)) {
                fill_background(c, x0, x1, y0, y1);
                continue;
            }
            for (int sb = 0; sb < (TILE / BLK) * (TILE / BLK); sb++)
                render_packet(c, &pk, tx * (TILE / BLK) + sb % (TILE / BLK),
                              ty * (TILE / BLK) + sb / (TILE / BLK));
        }
#if defined(__SSE__)
    _mm_setcsr(csr);
#endif
}

// Deterministic cone pattern: the centre, then rings at half-angles
// cone * j / nrings with about 6 j samples each (rotated by the golden angle).
static model_vec3_t *cone_pattern(int N, double cone_rad)
{
    model_vec3_t *d = malloc((size_t)N * sizeof *d);
    if (!d) return NULL;
    d[0] = v3(0, 0, 1);
    int rest = N - 1;
    if (rest <= 0) return d;
    int nrings = 1;
    while (3 * nrings * (nrings + 1) < rest) nrings++;   // 6 * (1+...+nrings) >= rest
    int k = 1;
    double weight_total = nrings * (nrings + 1) / 2.0;
    for (int j = 1; j <= nrings; j++) {
        int cnt = j == nrings ? N - k : (int)lround(rest * j / weight_total);
        if (cnt > N - k) cnt = N - k;
        double th = cone_rad * j / nrings;
        for (int s = 0; s < cnt; s++) {
            double ph = 2 * M_PI * s / cnt + 2.39996322972865332 * j;
            d[k++] = v3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th));
        }
    }
    return d;
}

bool model_render(const model_tracer_t *t, model_camera_t *cam, const model_lamps_t *lamps,
                  const model_material_t *const *mats, const model_shading_t *sh,
                  float *P_out, int32_t *face_out, uint8_t *lit_out)
{
    render_ctx_t *c = NULL;
    bool ok = false;
    if (!t || !cam || !mats || !sh || !P_out) {
        MODEL_FAIL("model_render: missing tracer, camera, materials, shading or output image");
        return false;
    }
    int nl = lamps ? lamps->n : 0;
    if (!isfinite(sh->kc) || !isfinite(sh->Pa)) {
        MODEL_FAIL("model_render: kc (%g) and Pa (%g) must be finite", sh->kc, sh->Pa);
        return false;
    }
    switch (sh->interreflection) {
    case MODEL_INTERREFLECTION_NONE: break;
    case MODEL_INTERREFLECTION_THESIS:
        if (!(sh->rho >= 0 && isfinite(sh->rho)) || sh->thesis_samples < 1 ||
            sh->thesis_samples > 100000 || !(sh->thesis_cone_deg >= 0 && sh->thesis_cone_deg < 90)) {
            MODEL_FAIL("model_render: thesis interreflection needs rho >= 0 (got %g), "
                       "1 <= thesis_samples <= 100000 (got %d), 0 <= thesis_cone_deg < 90 (got %g)",
                       sh->rho, sh->thesis_samples, sh->thesis_cone_deg);
            return false;
        }
        break;
    case MODEL_INTERREFLECTION_MC:
        if (sh->mc_samples < 1 || sh->mc_samples > 1000000 || sh->mc_bounces < 0 ||
            sh->mc_bounces > 1000) {
            MODEL_FAIL("model_render: MC needs 1 <= mc_samples <= 1e6 (got %d) and "
                       "0 <= mc_bounces <= 1000 (got %d)", sh->mc_samples, sh->mc_bounces);
            return false;
        }
        if (nl > 64) {
            MODEL_FAIL("model_render: MC supports at most 64 lamps (got %d)", nl);
            return false;
        }
        break;
    default:
        MODEL_FAIL("model_render: unknown interreflection mode %d", (int)sh->interreflection);
        return false;
    }
    for (int i = 0; i < nl; i++) {
        const model_lamp_t *L = &lamps->lamps[i];
        if (!isfinite(L->position_mm.x) || !isfinite(L->position_mm.y) ||
            !isfinite(L->position_mm.z) || !isfinite(L->intensity) || !(L->radius_mm >= 0)) {
            model_error(lamps->path, L->line, "lamp %s has a non-finite position or intensity "
                        "or a negative radius", L->name);
            return false;
        }
    }
    const model_vec3_t *rays = model_camera_ray_table(cam, NULL);
    if (!rays) return false;
    c = calloc(1, sizeof *c);
    if (!c) {
        MODEL_FAIL("out of memory");
        return false;
    }
    c->t = t;
    c->rays = rays;
    c->W = model_camera_width(cam);
    c->H = model_camera_height(cam);
    c->tw = (c->W + TILE - 1) / TILE;
    c->th = (c->H + TILE - 1) / TILE;
    c->o = model_camera_centre_world(cam);
    c->lamps = lamps;
    c->nl = nl;
    c->mats = mats;
    c->sh = sh;
    c->P = P_out;
    c->face = face_out;
    c->lit = lit_out;
    c->eps = model_tracer_epsilon_mm(t);
    c->mc_finite = false;
    if (sh->interreflection == MODEL_INTERREFLECTION_MC && sh->finite_lamps)
        for (int i = 0; i < nl; i++)
            if (lamps->lamps[i].radius_mm > 0) c->mc_finite = true;
    if (sh->interreflection == MODEL_INTERREFLECTION_THESIS) {
        c->ncone = sh->thesis_samples;
        c->cone = cone_pattern(c->ncone, sh->thesis_cone_deg * M_PI / 180);
        if (!c->cone) {
            MODEL_FAIL("out of memory");
            goto done;
        }
    }
    atomic_init(&c->bad_material, false);
    atomic_init(&c->bad_material_index, -1);
    int nthreads = sh->nthreads > 0 ? sh->nthreads : model_default_threads();
    int chunk = sh->interreflection == MODEL_INTERREFLECTION_NONE ? 2 : 1;
    model_parallel_for(c->th, chunk, nthreads, render_rows, c);
    if (atomic_load(&c->bad_material)) {
        MODEL_FAIL("model_render: scene material %d has no resolved material "
                   "(use model_resolve_materials)", atomic_load(&c->bad_material_index));
        goto done;
    }
    ok = true;
done:
    if (c) free(c->cone);
    free(c);
    return ok;
}

bool model_lamp_disc_dirs(model_vec3_t l, double d_mm, double radius_mm, model_vec3_t out[4])
{
    if (!(radius_mm > 0) || !(d_mm > radius_mm)) return false;
    double t = tan(asin(radius_mm / d_mm) / sqrt(2));
    model_vec3_t e[2];
    frame_of(l, &e[0], &e[1]);
    for (int k = 0; k < 4; k++)
        out[k] = v3_unit(v3_add(l, v3_scale(e[k / 2], k % 2 ? -t : t)));
    return true;
}
