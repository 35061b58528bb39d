// model/brdf/brdf.c — reflection models R = f_r * (n.l) with analytic parameter
// derivatives (the imaging model in model/model.h and the README).
//
// Pieces, each with its derivative:
//   D_blinn    = (n.h)^ns                                  (0 when n.h <= 0)
//   G_ts       = min(1, 2(n.h)(n.v)/(v.h), 2(n.h)(n.l)/(v.h))  (no parameters)
//   F_schlick  = F0 + (1-F0)(1-v.h)^5
//   D_beckmann = exp(-tan^2(th_h)/m^2) / (pi m^2 cos^4(th_h))
//   D_ggx      = a^2 / (pi ((n.h)^2 (a^2-1) + 1)^2)
//   G_smith    = 1 / (1 + Lambda(l) + Lambda(v)),  Lambda(w) = (-1 + sqrt(1 + a^2 tan^2(th_w)))/2
//   Ashikhmin-Shirley (2000, isotropic), as f_r:
//     diffuse  = 28 Rd / (23 pi) (1 - Rs) (1 - (1 - n.l/2)^5) (1 - (1 - n.v/2)^5)
//     specular = (ns + 1) / (8 pi) (n.h)^ns / ((v.h) max(n.l, n.v)) F(v.h), F Schlick's with F0 = Rs
//   ggx2: kd/pi + [ks D(alpha) G2(alpha) + ks2 D(alpha2) G2(alpha2)] F / (4 (n.l)(n.v))
#include <string.h>

#include "model/internal.h"

// ---- the tables, from the one list in model.h ------------------------------

#define NAME_(e, name, np, ...) #name,
static const char *const brdf_names[MODEL_BRDF_COUNT] = { MODEL_BRDF_LIST(NAME_) };
#undef NAME_

#define NP_(e, name, np, ...) np,
static const int brdf_nparams[MODEL_BRDF_COUNT] = { MODEL_BRDF_LIST(NP_) };
#undef NP_

#define PNAMES_(e, name, np, ...) { __VA_ARGS__ },
static const char *const brdf_pnames[MODEL_BRDF_COUNT][MODEL_BRDF_MAX_PARAMS] = { MODEL_BRDF_LIST(PNAMES_) };
#undef PNAMES_

// The parameter count of each entry must match its list of names.
#define CHECK_NP_(e, name, np, ...)                                                       \
    _Static_assert(sizeof((const char *[]){ __VA_ARGS__ }) / sizeof(const char *) == (np), \
                   "MODEL_BRDF_LIST: parameter count of " #name);                         \
    _Static_assert((np) <= MODEL_BRDF_MAX_PARAMS, "MODEL_BRDF_MAX_PARAMS too small for " #name);
MODEL_BRDF_LIST(CHECK_NP_)
#undef CHECK_NP_

static bool valid_model(model_brdf_t m) { return (int)m >= 0 && m < MODEL_BRDF_COUNT; }

const char *model_brdf_name(model_brdf_t m) { return valid_model(m) ? brdf_names[m] : "unknown"; }

int model_brdf_from_name(const char *name)
{
    if (!name) return -1;
    for (int m = 0; m < MODEL_BRDF_COUNT; m++)
        if (!strcmp(brdf_names[m], name)) return m;
    return -1;
}

int model_brdf_nparams(model_brdf_t m) { return valid_model(m) ? brdf_nparams[m] : 0; }

const char *model_brdf_param_name(model_brdf_t m, int i)
{
    if (!valid_model(m) || i < 0 || i >= brdf_nparams[m]) return NULL;
    return brdf_pnames[m][i];
}

int model_brdf_param_index(model_brdf_t m, const char *name)
{
    if (!valid_model(m) || !name) return -1;
    for (int i = 0; i < brdf_nparams[m]; i++)
        if (!strcmp(brdf_pnames[m][i], name)) return i;
    return -1;
}

bool model_brdf_is_physical(model_brdf_t m)
{
    return m == MODEL_BRDF_COOK_TORRANCE || m == MODEL_BRDF_GGX || m == MODEL_BRDF_ASHIKHMIN_SHIRLEY ||
           m == MODEL_BRDF_GGX2;
}

void model_brdf_param_range(model_brdf_t m, int i, double *lo, double *hi)
{
    double l = NAN, h = NAN;
    const char *p = model_brdf_param_name(m, i);
    bool phys = model_brdf_is_physical(m);
    if (!p) {
    } else if (!strcmp(p, "kd")) {
        l = 0, h = phys ? 1.0 : 1.0 / M_PI;   // albedo, or albedo/pi
    } else if (!strcmp(p, "ks") || !strcmp(p, "ks2")) {
        l = 0, h = phys ? 1.0 : INFINITY;
    } else if (!strcmp(p, "Rd") || !strcmp(p, "Rs")) {
        l = 0, h = 1;
    } else if (!strcmp(p, "ns")) {
        l = 0, h = 10000;
    } else if (!strcmp(p, "F0")) {
        l = 0, h = 1;
    } else if (!strcmp(p, "m") || !strcmp(p, "alpha") || !strcmp(p, "alpha2")) {
        l = 0.001, h = 1;
    }
    if (lo) *lo = l;
    if (hi) *hi = h;
}

double model_brdf_param_default(model_brdf_t m, int i)
{
    if (m == MODEL_BRDF_THESIS_FIT && i == model_brdf_param_index(m, "kd")) return 0.0;
    return NAN;
}

const char *model_brdf_convention(model_brdf_t m)
{
    switch (m) {
    case MODEL_BRDF_LAMBERT:
        return "lambert: R = kd (n.l); kd: thesis coefficient = albedo/pi (albedo a gives kd = a/pi)";
    case MODEL_BRDF_HALL:
        return "hall: R = kd (n.l) + ks (n.h)^ns; kd: thesis coefficient = albedo/pi; ks: specular weight; "
               "ns: Blinn exponent";
    case MODEL_BRDF_TORRANCE_SPARROW:
        return "torrance_sparrow: R = kd (n.l) + ks D G F/(n.v), D = (n.h)^ns; kd: thesis coefficient = "
               "albedo/pi; ks: specular weight; ns: Blinn exponent; F0: Schlick reflectance at normal incidence";
    case MODEL_BRDF_THESIS_FIT:
        return "thesis_fit: R = ks G (n.h)^ns/(n.v) + kd (n.l); ks: specular weight; ns: Blinn exponent; "
               "kd: thesis coefficient = albedo/pi (default 0)";
    case MODEL_BRDF_COOK_TORRANCE:
        return "cook_torrance: R = [kd/pi + ks D G F/(4 (n.l)(n.v))] (n.l); kd: albedo (divided by pi here); "
               "ks: specular weight; m: Beckmann RMS slope; F0: Schlick reflectance at normal incidence";
    case MODEL_BRDF_GGX:
        return "ggx: R = [kd/pi + ks D G2 F/(4 (n.l)(n.v))] (n.l), height-correlated Smith G2; kd: albedo "
               "(divided by pi here); ks: specular weight; alpha: GGX alpha (alpha = perceptual_roughness^2), "
               "not perceptual roughness; F0: Schlick reflectance at normal incidence";
    case MODEL_BRDF_ASHIKHMIN_SHIRLEY:
        return "ashikhmin_shirley: R = [28 Rd/(23 pi) (1-Rs) (1-(1-n.l/2)^5) (1-(1-n.v/2)^5) + (ns+1)/(8 pi) "
               "(n.h)^ns F/((v.h) max(n.l, n.v))] (n.l) (Ashikhmin & Shirley 2000, isotropic); Rd: diffuse "
               "reflectance (albedo-like, divided by pi here); Rs: specular reflectance at normal incidence, also "
               "Schlick's F0 of F; ns: Phong exponent of (n.h)";
    case MODEL_BRDF_GGX2:
        return "ggx2: R = [kd/pi + (ks D1 G1 + ks2 D2 G2) F/(4 (n.l)(n.v))] (n.l), two GGX lobes "
               "(height-correlated Smith) sharing Schlick's F; kd: albedo (divided by pi here); ks, alpha: the "
               "sharper lobe's weight and GGX alpha; ks2, alpha2: the broader lobe's (alpha <= alpha2 after a "
               "fit); alpha = perceptual_roughness^2; F0: Schlick reflectance at normal incidence";
    default:
        return "unknown reflection model";
    }
}

model_cosines_t model_cosines(model_vec3_t n, model_vec3_t l, model_vec3_t v)
{
    model_cosines_t c = { .nl = v3_dot(n, l), .nv = v3_dot(n, v), .nh = 0, .vh = 0 };
    model_vec3_t s = v3_add(l, v);
    double len = v3_norm(s);
    if (len > 1e-12) {
        model_vec3_t h = v3_scale(s, 1.0 / len);
        c.nh = v3_dot(n, h);
        c.vh = v3_dot(v, h);
    }
    return c;
}

// ---- the pieces ------------------------------------------------------------
// Each returns its value; its derivative output may be NULL (the renderer's
// fast path asks for none).

// x^e: repeated squaring when e is a small whole number (as Blinn exponents in
// material files mostly are), else pow().
static inline double pow_whole(double x, double e)
{
    if (e >= 0 && e <= 256 && e == (double)(int)e) {
        double r = 1, b = x;
        for (int k = (int)e; k; k >>= 1) {
            if (k & 1) r *= b;
            b *= b;
        }
        return r;
    }
    return pow(x, e);
}

// Blinn cosine power and its derivative with respect to ns.
static double d_blinn(double nh, double ns, double *dD_dns)
{
    if (!(nh > 0)) {
        if (dD_dns) *dD_dns = 0;
        return 0;
    }
    double D = pow_whole(nh, ns);
    if (dD_dns) *dD_dns = D * log(nh);
    return D;
}

// Torrance-Sparrow geometric attenuation (V-cavities). Depends on no
// parameter. When v.h <= 0 both ratios are unbounded and G is 1.
static double g_torrance_sparrow(const model_cosines_t *c)
{
    if (!(c->vh > 0)) return 1.0;
    double gv = 2 * c->nh * c->nv / c->vh, gl = 2 * c->nh * c->nl / c->vh;
    double g = 1.0;
    if (gv < g) g = gv;
    if (gl < g) g = gl;
    return g;
}

// Schlick's Fresnel approximation and dF/dF0.
static double f_schlick(double vh, double F0, double *dF_dF0)
{
    double x = 1 - vh, x5 = x * x * x * x * x;
    if (dF_dF0) *dF_dF0 = 1 - x5;
    return F0 + (1 - F0) * x5;
}

// Beckmann distribution and dD/dm.
static double d_beckmann(double nh, double m, double *dD_dm)
{
    if (!(nh > 0)) {
        if (dD_dm) *dD_dm = 0;
        return 0;
    }
    double c2 = nh * nh, t2 = fmax(0.0, (1 - c2) / c2), m2 = m * m;
    double D = exp(-t2 / m2) / (M_PI * m2 * c2 * c2);
    if (dD_dm) *dD_dm = D * (2 * t2 / (m2 * m) - 2 / m);
    return D;
}

// GGX (Trowbridge-Reitz) distribution and dD/dalpha.
static double d_ggx(double nh, double a, double *dD_da)
{
    if (!(nh > 0)) {
        if (dD_da) *dD_da = 0;
        return 0;
    }
    double a2 = a * a, c2 = nh * nh, q = c2 * (a2 - 1) + 1;
    double D = a2 / (M_PI * q * q);
    if (dD_da) *dD_da = 2 * a * (q - 2 * a2 * c2) / (M_PI * q * q * q);
    return D;
}

// Smith Lambda for GGX and dLambda/d(alpha^2).
static double lambda_ggx(double cos_w, double a2, double *dL_da2)
{
    double c2 = cos_w * cos_w, t2 = fmax(0.0, (1 - c2) / c2);
    double s = sqrt(1 + a2 * t2);
    if (dL_da2) *dL_da2 = t2 / (4 * s);
    return (s - 1) / 2;
}

// Height-correlated Smith masking-shadowing for GGX and dG2/dalpha
// (0 when v.h <= 0: the microfacet faces away).
static double g_smith_ggx(const model_cosines_t *c, double a, double *dG_da)
{
    if (!(c->vh > 0)) {
        if (dG_da) *dG_da = 0;
        return 0;
    }
    double a2 = a * a, dll, dlv;
    double ll = lambda_ggx(c->nl, a2, dG_da ? &dll : NULL), lv = lambda_ggx(c->nv, a2, dG_da ? &dlv : NULL);
    double G = 1 / (1 + ll + lv);
    if (dG_da) *dG_da = -G * G * (dll + dlv) * 2 * a;
    return G;
}

// Ashikhmin-Shirley's diffuse shape 28/(23 pi) (1-(1-n.l/2)^5)(1-(1-n.v/2)^5).
static double as_diffuse(const model_cosines_t *c)
{
    double a = 1 - c->nl / 2, b = 1 - c->nv / 2;
    return 28 / (23 * M_PI) * (1 - a * a * a * a * a) * (1 - b * b * b * b * b);
}

// Ashikhmin-Shirley (isotropic): R and dR/d(Rd, Rs, ns) into g (when want).
static double eval_ashikhmin_shirley(const double *p, const model_cosines_t *c, bool want, double *g)
{
    double Rd = p[0], Rs = p[1], ns = p[2], dD = 0, dF = 0;
    double kdiff = as_diffuse(c) * c->nl;
    double D = d_blinn(c->nh, ns, want ? &dD : NULL);
    double F = f_schlick(c->vh, Rs, want ? &dF : NULL);
    double q = c->vh > 0 ? c->nl / (8 * M_PI * c->vh * fmax(c->nl, c->nv)) : 0;   // s = (ns+1) q
    double s = (ns + 1) * q;
    g[0] = (1 - Rs) * kdiff;
    g[1] = -Rd * kdiff + s * D * dF;
    g[2] = (s * dD + q * D) * F;
    return Rd * (1 - Rs) * kdiff + s * D * F;
}

// Two GGX lobes with one Schlick F: R and its 6 derivatives into g (when want).
static double eval_ggx2(const double *p, const model_cosines_t *c, bool want, double *g)
{
    double kd = p[0], ks = p[1], a = p[2], ks2 = p[3], a2 = p[4], F0 = p[5];
    double dD1 = 0, dG1 = 0, dD2 = 0, dG2 = 0, dF = 0;
    double D1 = d_ggx(c->nh, a, want ? &dD1 : NULL), G1 = g_smith_ggx(c, a, want ? &dG1 : NULL);
    double D2 = d_ggx(c->nh, a2, want ? &dD2 : NULL), G2 = g_smith_ggx(c, a2, want ? &dG2 : NULL);
    double F = f_schlick(c->vh, F0, want ? &dF : NULL);
    double s = 1 / (4 * c->nv), L = ks * D1 * G1 + ks2 * D2 * G2;
    g[0] = c->nl / M_PI;
    g[1] = D1 * G1 * F * s;
    g[2] = ks * (dD1 * G1 + D1 * dG1) * F * s;
    g[3] = D2 * G2 * F * s;
    g[4] = ks2 * (dD2 * G2 + D2 * dG2) * F * s;
    g[5] = L * dF * s;
    return kd / M_PI * c->nl + L * F * s;
}

// ---- evaluation ------------------------------------------------------------

double model_brdf_eval(model_brdf_t m, const double *p, const model_cosines_t *c, double *dR_dp)
{
    int np = model_brdf_nparams(m);
    if (dR_dp)
        for (int i = 0; i < np; i++) dR_dp[i] = 0;
    if (!(c->nl > 0) || !(c->nv > 0)) return 0.0;

    // Derivatives of the pieces only when the caller wants dR_dp.
    bool want = dR_dp != NULL;
    double g[MODEL_BRDF_MAX_PARAMS] = { 0 };
    double R = 0;
    switch (m) {
    case MODEL_BRDF_LAMBERT: {
        R = p[0] * c->nl;
        g[0] = c->nl;
        break;
    }
    case MODEL_BRDF_HALL: {
        double kd = p[0], ks = p[1], ns = p[2], dD = 0;
        double D = d_blinn(c->nh, ns, want ? &dD : NULL);
        R = kd * c->nl + ks * D;
        g[0] = c->nl;
        g[1] = D;
        g[2] = ks * dD;
        break;
    }
    case MODEL_BRDF_TORRANCE_SPARROW: {
        double kd = p[0], ks = p[1], ns = p[2], F0 = p[3], dD = 0, dF = 0;
        double D = d_blinn(c->nh, ns, want ? &dD : NULL);
        double G = g_torrance_sparrow(c);
        double F = f_schlick(c->vh, F0, want ? &dF : NULL);
        double s = G / c->nv;
        R = kd * c->nl + ks * D * F * s;
        g[0] = c->nl;
        g[1] = D * F * s;
        g[2] = ks * dD * F * s;
        g[3] = ks * D * dF * s;
        break;
    }
    case MODEL_BRDF_THESIS_FIT: {
        double ks = p[0], ns = p[1], kd = p[2], dD = 0;
        double D = d_blinn(c->nh, ns, want ? &dD : NULL);
        double s = g_torrance_sparrow(c) / c->nv;
        R = ks * D * s + kd * c->nl;
        g[0] = D * s;
        g[1] = ks * dD * s;
        g[2] = c->nl;
        break;
    }
    case MODEL_BRDF_COOK_TORRANCE: {
        double kd = p[0], ks = p[1], mm = p[2], F0 = p[3], dD = 0, dF = 0;
        double D = d_beckmann(c->nh, mm, want ? &dD : NULL);
        double G = g_torrance_sparrow(c);
        double F = f_schlick(c->vh, F0, want ? &dF : NULL);
        double s = G / (4 * c->nv);   // (n.l) of R cancels the one of the denominator
        R = kd / M_PI * c->nl + ks * D * F * s;
        g[0] = c->nl / M_PI;
        g[1] = D * F * s;
        g[2] = ks * dD * F * s;
        g[3] = ks * D * dF * s;
        break;
    }
    case MODEL_BRDF_GGX: {
        double kd = p[0], ks = p[1], a = p[2], F0 = p[3], dD = 0, dG = 0, dF = 0;
        double D = d_ggx(c->nh, a, want ? &dD : NULL);
        double G = g_smith_ggx(c, a, want ? &dG : NULL);
        double F = f_schlick(c->vh, F0, want ? &dF : NULL);
        double s = 1 / (4 * c->nv);
        R = kd / M_PI * c->nl + ks * D * G * F * s;
        g[0] = c->nl / M_PI;
        g[1] = D * G * F * s;
        g[2] = ks * (dD * G + D * dG) * F * s;
        g[3] = ks * D * G * dF * s;
        break;
    }
    case MODEL_BRDF_ASHIKHMIN_SHIRLEY:
        R = eval_ashikhmin_shirley(p, c, want, g);
        break;
    case MODEL_BRDF_GGX2:
        R = eval_ggx2(p, c, want, g);
        break;
    default:
        return NAN;
    }
    if (dR_dp)
        for (int i = 0; i < np; i++) dR_dp[i] = g[i];
    return R;
}

// ---- prepared geometry -----------------------------------------------------
// The same expressions as above with the parameter-free factors read from pc
// (computed there exactly as d_blinn, g_torrance_sparrow, f_schlick, d_ggx
// and lambda_ggx do), and the parameter-dependent ones kept for a repeat.

model_brdf_prep_t model_brdf_prepare(const model_cosines_t *c)
{
    model_brdf_prep_t pc = { .c = *c, .zero = !(c->nl > 0) || !(c->nv > 0), .key = NAN };
    pc.lognh = c->nh > 0 ? log(c->nh) : 0;
    pc.s_ts = pc.zero ? 0 : g_torrance_sparrow(c) / c->nv;
    double x = 1 - c->vh;
    pc.x5 = x * x * x * x * x;
    pc.nh2 = c->nh * c->nh;
    double cl = c->nl * c->nl, cv = c->nv * c->nv;
    pc.t2l = fmax(0.0, (1 - cl) / cl);
    pc.t2v = fmax(0.0, (1 - cv) / cv);
    return pc;
}

// Blinn's D (kept with its ns) and, when wanted, dD/dns from the prepared log(n.h).
static inline double d_blinn_prepared(model_brdf_prep_t *pc, double ns, double *dD_dns)
{
    if (!(pc->c.nh > 0)) {
        if (dD_dns) *dD_dns = 0;
        return 0;
    }
    if (!(ns == pc->key)) {
        // a fitted (non-whole) ns: exp of the stored log instead of pow(), a
        // few ulp from it (relative 1e-13 at ns log(n.h) = -700; whole ns as
        // model_brdf_eval, bit for bit)
        pc->D = ns >= 0 && ns <= 256 && ns == (double)(int)ns ? pow_whole(pc->c.nh, ns) : exp(ns * pc->lognh);
        pc->key = ns;
    }
    double D = pc->D;
    if (dD_dns) *dD_dns = D * pc->lognh;
    return D;
}

// GGX's D and height-correlated G2 and their alpha derivatives (when want),
// kept with their alpha.
static void ggx_prepared(model_brdf_prep_t *pc, double a, bool want)
{
    if (a == pc->key && (pc->kept_d || !want)) return;
    const model_cosines_t *c = &pc->c;
    double a2 = a * a, D = 0, dD = 0, G = 0, dG = 0;
    if (c->nh > 0) {
        double q = pc->nh2 * (a2 - 1) + 1;
        D = a2 / (M_PI * q * q);
        if (want) dD = 2 * a * (q - 2 * a2 * pc->nh2) / (M_PI * q * q * q);
    }
    if (c->vh > 0) {
        double sl = sqrt(1 + a2 * pc->t2l), sv = sqrt(1 + a2 * pc->t2v);
        double ll = (sl - 1) / 2, lv = (sv - 1) / 2;
        G = 1 / (1 + ll + lv);
        if (want) dG = -G * G * (pc->t2l / (4 * sl) + pc->t2v / (4 * sv)) * 2 * a;
    }
    pc->key = a;
    pc->D = D, pc->G = G, pc->dD = dD, pc->dG = dG;
    pc->kept_d = want;
}

static double eval_prepared_ggx(const double *p, model_brdf_prep_t *pc, double *dR_dp)
{
    const model_cosines_t *c = &pc->c;
    double kd = p[0], ks = p[1], F0 = p[3];
    ggx_prepared(pc, p[2], dR_dp != NULL);
    double D = pc->D, G = pc->G, F = F0 + (1 - F0) * pc->x5, s = 1 / (4 * c->nv);
    double R = kd / M_PI * c->nl + ks * D * G * F * s;
    if (dR_dp) {
        dR_dp[0] = c->nl / M_PI;
        dR_dp[1] = D * G * F * s;
        dR_dp[2] = ks * (pc->dD * G + D * pc->dG) * F * s;
        dR_dp[3] = ks * D * G * (1 - pc->x5) * s;
    }
    return R;
}

double model_brdf_eval_prepared(model_brdf_t m, const double *p, model_brdf_prep_t *pc, double *dR_dp)
{
    const model_cosines_t *c = &pc->c;
    if (m != MODEL_BRDF_THESIS_FIT && m != MODEL_BRDF_HALL && m != MODEL_BRDF_TORRANCE_SPARROW && m != MODEL_BRDF_GGX)
        return model_brdf_eval(m, p, c, dR_dp);
    int np = model_brdf_nparams(m);
    if (pc->zero) {
        if (dR_dp)
            for (int i = 0; i < np; i++) dR_dp[i] = 0;
        return 0.0;
    }
    if (m == MODEL_BRDF_GGX) return eval_prepared_ggx(p, pc, dR_dp);
    bool want = dR_dp != NULL;
    double dD = 0, R;
    if (m == MODEL_BRDF_THESIS_FIT) {
        double ks = p[0], ns = p[1], kd = p[2];
        double D = d_blinn_prepared(pc, ns, want ? &dD : NULL), s = pc->s_ts;
        R = ks * D * s + kd * c->nl;
        if (want) {
            dR_dp[0] = D * s;
            dR_dp[1] = ks * dD * s;
            dR_dp[2] = c->nl;
        }
    } else if (m == MODEL_BRDF_HALL) {
        double kd = p[0], ks = p[1], ns = p[2];
        double D = d_blinn_prepared(pc, ns, want ? &dD : NULL);
        R = kd * c->nl + ks * D;
        if (want) {
            dR_dp[0] = c->nl;
            dR_dp[1] = D;
            dR_dp[2] = ks * dD;
        }
    } else {
        double kd = p[0], ks = p[1], ns = p[2], F0 = p[3];
        double D = d_blinn_prepared(pc, ns, want ? &dD : NULL), s = pc->s_ts;
        double F = F0 + (1 - F0) * pc->x5, dF = 1 - pc->x5;
        R = kd * c->nl + ks * D * F * s;
        if (want) {
            dR_dp[0] = c->nl;
            dR_dp[1] = D * F * s;
            dR_dp[2] = ks * dD * F * s;
            dR_dp[3] = ks * D * dF * s;
        }
    }
    return R;
}
