// model/brdf/rgl.c — measured BRDFs in the RGL ".bsdf" format (Dupuy & Jakob
// 2018, "An adaptive parameterization for efficient material acquisition and
// rendering"), the one owner of that format: refl fit brdf reads it here.
//
// The container is a tensor file: the 12 bytes "tensor_file\0", version bytes
// 1 0, a uint32 field count, then per field a uint16 name length and the name,
// a uint16 rank, a uint8 type (1 uint8, 2 int8, 3 uint16, 4 int16, 5 uint32,
// 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32, 11 float64), a uint64
// absolute offset of its data and rank uint64 extents (C order); all
// little-endian. A BRDF holds (float32 unless said):
//   theta_i [Ti], phi_i [Pi]   the incident directions measured (radians);
//                              Pi <= 2: isotropic
//   ndf [H0, W0], sigma [H1, W1]   the microfacet distribution D and the
//                              projected area sigma(w_i), over the unit square
//                              (u_theta, u_phi) = (sqrt(theta / (pi/2)),
//                              (phi + pi) / (2 pi))
//   vndf [Pi, Ti, H, W]        the visible-normal distribution per incident
//                              direction (a density over the same square)
//   rgb [Pi, Ti, 3, H', W'] or spectra [Pi, Ti, L, H', W'] with wavelengths [L]:
//                              the values over the VNDF's warped square
//   jacobian [1] (uint8)       1: the values still lack the parameterisation's
//                              factor D(m) / (4 sigma(w_i))
//   luminance, description     (for sampling; not needed to evaluate)
// Evaluation of (w_i, w_o), both above the surface: m = (w_i + w_o)/|..|;
// u_m = (u_theta(theta_m), u_phi(phi_m - phi_i if isotropic else phi_m)) with
// u_phi wrapped to [0, 1); the VNDF of the incident direction (linear between
// the neighbouring measured (phi_i, theta_i), each normalised to integral 1)
// is a bilinear density p(x, y) on the unit square's grid nodes; the warp's
// inverse maps u_m to s = (F(x | y), F(y)): F(y) the marginal CDF of y,
// F(x | y) the conditional CDF of x in row y. The value is the bilinear
// interpolation of the channel at s (linear in phi_i, theta_i as well),
// times D(u_m) / (4 sigma(u_i)) when jacobian is 1: f_r cos(theta_o), which
// the caller divides back. Incident angles beyond the measured ones are
// clamped to them. Anisotropic files measured over a half or a quarter of
// phi_i (their phi_i span 2 pi / 2 or 4) are evaluated after mirroring w_i
// into that range, as they were meant to be.
#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

static const unsigned char magic[12] = "tensor_file";

struct model_brdf_rgl {
    int      nphi, ntheta, nch;
    double  *phi_i, *theta_i, *lambda;   // lambda: wavelengths (nm), NULL for rgb
    int      ndf_w, ndf_h, sig_w, sig_h, vw, vh, sw, sh;
    double  *ndf, *sigma;
    double  *vndf;                       // [nphi*ntheta][vh][vw], each slice of integral 1
    double  *rowint, *margcdf, *condcdf; // per slice: row integrals [vh], marginal CDF [vh], conditional CDF [vh][vw]
    double  *spec;                       // [nphi*ntheta][nch][sh][sw]
    bool     jacobian, isotropic;
    int      reduction;
    char     sha256[65];
    char     description[256];
};

bool model_brdf_rgl_sniff(const unsigned char *head, size_t n)
{
    return n >= sizeof magic && memcmp(head, magic, sizeof magic) == 0;
}

void model_brdf_rgl_free(model_brdf_rgl_t *r)
{
    if (!r) return;
    free(r->phi_i);
    free(r->theta_i);
    free(r->lambda);
    free(r->ndf);
    free(r->sigma);
    free(r->vndf);
    free(r->rowint);
    free(r->margcdf);
    free(r->condcdf);
    free(r->spec);
    free(r);
}

// ---------------------------------------------------------------------------
// The container

typedef struct {
    char     name[64];
    int      type, rank;
    uint64_t offset, shape[8], count;
} field_t;

static size_t type_size(int t)
{
    static const size_t sz[12] = { 0, 1, 1, 2, 2, 4, 4, 8, 8, 2, 4, 8 };
    return t >= 1 && t <= 11 ? sz[t] : 0;
}

typedef struct {
    const unsigned char *b;
    size_t len, at;
    const char *name;
    bool ok;
} rd_t;

static void take(rd_t *r, void *out, size_t n)
{
    if (!r->ok || r->len - r->at < n) {
        if (r->ok)
            model_error(r->name, 0, "RGL tensor file truncated in its field table at byte %zu (%zu bytes)", r->at, r->len);
        r->ok = false;
        memset(out, 0, n);
        return;
    }
    memcpy(out, r->b + r->at, n);
    r->at += n;
}

// The field table: n fields into f (at most max), each checked to lie in the file.
static int read_fields(rd_t *r, field_t *f, int max)
{
    unsigned char ver[2];
    uint32_t n = 0;
    r->at = sizeof magic;
    take(r, ver, 2);
    take(r, &n, 4);
    if (!r->ok) return -1;
    if (ver[0] != 1 || ver[1] != 0) {
        model_error(r->name, 0, "RGL tensor file version %d.%d (refl reads 1.0)", ver[0], ver[1]);
        return -1;
    }
    if (n > (uint32_t)max) {
        model_error(r->name, 0, "RGL tensor file with %u fields (a BRDF has about 12; at most %d read)", n, max);
        return -1;
    }
    for (uint32_t k = 0; k < n && r->ok; k++) {
        field_t *q = &f[k];
        uint16_t nl = 0, rank = 0;
        uint8_t type = 0;
        take(r, &nl, 2);
        char name[256] = "";
        if (r->ok && nl >= sizeof name) {
            model_error(r->name, 0, "RGL tensor field %u: name of %u bytes", k, nl);
            return -1;
        }
        take(r, name, nl);
        take(r, &rank, 2);
        take(r, &type, 1);
        take(r, &q->offset, 8);
        if (!r->ok) return -1;
        snprintf(q->name, sizeof q->name, "%s", name);
        if (rank > 8 || !type_size(type)) {
            model_error(r->name, 0, "RGL tensor field '%s': rank %u, type %u (rank <= 8, types 1..11)", q->name, rank, type);
            return -1;
        }
        q->rank = rank;
        q->type = type;
        q->count = 1;
        for (int d = 0; d < rank; d++) {
            take(r, &q->shape[d], 8);
            if (!r->ok) return -1;
            if (q->shape[d] > r->len || (q->shape[d] && q->count > r->len / q->shape[d])) q->count = UINT64_MAX;
            else q->count *= q->shape[d];
        }
        uint64_t bytes = q->count == UINT64_MAX ? UINT64_MAX : q->count * type_size(type);
        if (q->count > r->len || q->offset > r->len || bytes > r->len - q->offset) {
            model_error(r->name, 0, "RGL tensor field '%s': its data (offset %llu) runs past the file's end (%zu bytes)",
                        q->name, (unsigned long long)q->offset, r->len);
            return -1;
        }
    }
    return r->ok ? (int)n : -1;
}

static const field_t *find(const field_t *f, int n, const char *name)
{
    for (int k = 0; k < n; k++)
        if (!strcmp(f[k].name, name)) return &f[k];
    return NULL;
}

// A float32 field of the given rank as doubles (finite, or a message).
static double *floats(const rd_t *r, const field_t *q, const char *name, int rank)
{
    if (!q) {
        model_error(r->name, 0, "RGL BRDF file without the field '%s'", name);
        return NULL;
    }
    if (q->type != 10 || q->rank != rank || q->count == 0) {
        model_error(r->name, 0, "RGL field '%s': type %d rank %d, %llu values (expected float32, rank %d)", name,
                    q->type, q->rank, (unsigned long long)q->count, rank);
        return NULL;
    }
    double *v = malloc(q->count * sizeof *v);
    if (!v) {
        model_error(r->name, 0, "out of memory for RGL field '%s'", name);
        return NULL;
    }
    for (uint64_t k = 0; k < q->count; k++) {
        float x;
        memcpy(&x, r->b + q->offset + 4 * k, 4);
        if (!isfinite(x)) {
            model_error(r->name, 0, "RGL field '%s': value %llu is not finite", name, (unsigned long long)k);
            free(v);
            return NULL;
        }
        v[k] = x;
    }
    return v;
}

// ---------------------------------------------------------------------------
// The VNDF warp: per slice, normalise to integral 1 and tabulate the CDFs.

static bool build_cdfs(model_brdf_rgl_t *r, const char *name)
{
    int W = r->vw, H = r->vh, ns = r->nphi * r->ntheta;
    double dx = 1.0 / (W - 1), dy = 1.0 / (H - 1);
    r->rowint = malloc((size_t)ns * H * sizeof(double));
    r->margcdf = malloc((size_t)ns * H * sizeof(double));
    r->condcdf = malloc((size_t)ns * H * W * sizeof(double));
    if (!r->rowint || !r->margcdf || !r->condcdf) {
        model_error(name, 0, "out of memory for the RGL VNDF warp");
        return false;
    }
    for (int s = 0; s < ns; s++) {
        double *v = r->vndf + (size_t)s * H * W, *R = r->rowint + (size_t)s * H, *M = r->margcdf + (size_t)s * H;
        double *C = r->condcdf + (size_t)s * H * W;
        double total = 0;
        for (int i = 0; i < H; i++) {
            double c = 0;
            for (int j = 0; j < W; j++) {
                if (v[i * W + j] < 0) {
                    model_error(name, 0, "RGL field 'vndf': negative density %g (slice %d, row %d, column %d)",
                                v[i * W + j], s, i, j);
                    return false;
                }
                C[i * W + j] = c;
                if (j + 1 < W) c += 0.5 * (v[i * W + j] + v[i * W + j + 1]) * dx;
            }
            R[i] = c;
        }
        for (int i = 0; i < H; i++) {   // row integrals are linear in y between rows: trapezoids are exact
            M[i] = total;
            if (i + 1 < H) total += 0.5 * (R[i] + R[i + 1]) * dy;
        }
        if (!(total > 0)) {
            model_error(name, 0, "RGL field 'vndf': slice %d (phi_i %d, theta_i %d) is zero everywhere", s,
                        s / r->ntheta, s % r->ntheta);
            return false;
        }
        for (int k = 0; k < H * W; k++) {
            v[k] /= total;
            C[k] /= total;
        }
        for (int i = 0; i < H; i++) {
            R[i] /= total;
            M[i] /= total;
        }
    }
    return true;
}

static bool check_grid(const char *name, const char *what, const double *v, int n)
{
    for (int k = 0; k + 1 < n; k++)
        if (!(v[k + 1] > v[k])) {
            model_error(name, 0, "RGL field '%s' is not increasing (%g then %g)", what, v[k], v[k + 1]);
            return false;
        }
    return true;
}

// The 2-D extents (height, width) of a field's last two axes, each >= 2.
static bool extents(const char *name, const field_t *q, int *h, int *w)
{
    uint64_t H = q->shape[q->rank - 2], W = q->shape[q->rank - 1];
    if (H < 2 || W < 2 || H > 65536 || W > 65536) {
        model_error(name, 0, "RGL field '%s': a %llu x %llu grid (each side 2..65536)", q->name,
                    (unsigned long long)H, (unsigned long long)W);
        return false;
    }
    *h = (int)H;
    *w = (int)W;
    return true;
}

static bool read_brdf(model_brdf_rgl_t *r, const rd_t *rd, const field_t *f, int nf)
{
    const char *name = rd->name;
    const field_t *ti = find(f, nf, "theta_i"), *pi = find(f, nf, "phi_i"), *vn = find(f, nf, "vndf");
    const field_t *nd = find(f, nf, "ndf"), *sg = find(f, nf, "sigma"), *jc = find(f, nf, "jacobian");
    const field_t *sp = find(f, nf, "rgb"), *wl = find(f, nf, "wavelengths"), *ds = find(f, nf, "description");
    if (wl) sp = find(f, nf, "spectra");
    if (!(r->theta_i = floats(rd, ti, "theta_i", 1)) || !(r->phi_i = floats(rd, pi, "phi_i", 1))) return false;
    r->ntheta = (int)ti->count;
    r->nphi = (int)pi->count;
    if (!check_grid(name, "theta_i", r->theta_i, r->ntheta) || !check_grid(name, "phi_i", r->phi_i, r->nphi))
        return false;
    if (!(r->ndf = floats(rd, nd, "ndf", 2)) || !(r->sigma = floats(rd, sg, "sigma", 2))) return false;
    if (!extents(name, nd, &r->ndf_h, &r->ndf_w) || !extents(name, sg, &r->sig_h, &r->sig_w)) return false;
    for (uint64_t k = 0; k < sg->count; k++)
        if (!(r->sigma[k] > 0)) {
            model_error(name, 0, "RGL field 'sigma': value %llu is %g (a projected area, > 0)", (unsigned long long)k,
                        r->sigma[k]);
            return false;
        }
    if (!(r->vndf = floats(rd, vn, "vndf", 4)) || !extents(name, vn, &r->vh, &r->vw)) return false;
    if (!(r->spec = floats(rd, sp, wl ? "spectra" : "rgb", 5)) || !extents(name, sp, &r->sh, &r->sw)) return false;
    r->nch = (int)sp->shape[2];
    if (vn->shape[0] != (uint64_t)r->nphi || vn->shape[1] != (uint64_t)r->ntheta || sp->shape[0] != (uint64_t)r->nphi ||
        sp->shape[1] != (uint64_t)r->ntheta) {
        model_error(name, 0, "RGL fields 'vndf' and '%s' must start with phi_i x theta_i = %d x %d", sp->name, r->nphi,
                    r->ntheta);
        return false;
    }
    if (wl) {
        if (!(r->lambda = floats(rd, wl, "wavelengths", 1))) return false;
        if (wl->count != (uint64_t)r->nch) {
            model_error(name, 0, "RGL file: %llu wavelengths for %d spectral channels", (unsigned long long)wl->count,
                        r->nch);
            return false;
        }
    } else if (r->nch != 3) {
        model_error(name, 0, "RGL field 'rgb': %d channels (3 expected)", r->nch);
        return false;
    }
    if (!jc || jc->type != 1 || jc->count != 1) {
        model_error(name, 0, "RGL BRDF file without a one-byte uint8 field 'jacobian'");
        return false;
    }
    r->jacobian = rd->b[jc->offset] != 0;
    if (ds && ds->type == 1) {
        size_t n = ds->count < sizeof r->description ? (size_t)ds->count : sizeof r->description - 1;
        memcpy(r->description, rd->b + ds->offset, n);
        r->description[n] = 0;
    }
    r->isotropic = r->nphi <= 2;
    if (!r->isotropic) {
        double span = r->phi_i[r->nphi - 1] - r->phi_i[0];
        r->reduction = (int)lround(2 * M_PI / span);
    }
    return build_cdfs(r, name);
}

model_brdf_rgl_t *model_brdf_rgl_parse(const void *data, size_t len, const char *name)
{
    rd_t rd = { .b = data, .len = len, .name = name ? name : "RGL data", .ok = true };
    if (!model_brdf_rgl_sniff(data, len)) {
        model_error(rd.name, 0, "not an RGL .bsdf file: it does not start with \"tensor_file\"");
        return NULL;
    }
    enum { MAXF = 64 };
    field_t f[MAXF];
    int nf = read_fields(&rd, f, MAXF);
    if (nf < 0) return NULL;
    model_brdf_rgl_t *r = calloc(1, sizeof *r);
    if (!r) {
        model_error(rd.name, 0, "out of memory");
        return NULL;
    }
    if (!read_brdf(r, &rd, f, nf)) {
        model_brdf_rgl_free(r);
        return NULL;
    }
    model_sha256_hex(data, len, r->sha256);
    return r;
}

model_brdf_rgl_t *model_brdf_rgl_load(const char *path)
{
    size_t len = 0;
    char *b = model_read_file(path, &len);
    if (!b) return NULL;
    model_brdf_rgl_t *r = model_brdf_rgl_parse(b, len, path);
    free(b);
    return r;
}

// ---------------------------------------------------------------------------
// Evaluation

int         model_brdf_rgl_channels(const model_brdf_rgl_t *r) { return r->nch; }
const double *model_brdf_rgl_wavelengths(const model_brdf_rgl_t *r) { return r->lambda; }
int         model_brdf_rgl_ntheta(const model_brdf_rgl_t *r) { return r->ntheta; }
int         model_brdf_rgl_nphi(const model_brdf_rgl_t *r) { return r->nphi; }
double      model_brdf_rgl_theta_i(const model_brdf_rgl_t *r, int k) { return r->theta_i[k]; }
double      model_brdf_rgl_phi_i(const model_brdf_rgl_t *r, int k) { return r->phi_i[k]; }
bool        model_brdf_rgl_isotropic(const model_brdf_rgl_t *r) { return r->isotropic; }
const char *model_brdf_rgl_sha256(const model_brdf_rgl_t *r) { return r->sha256; }
const char *model_brdf_rgl_description(const model_brdf_rgl_t *r) { return r->description; }

// Linear interpolation weights of x on an increasing grid (clamped).
static int interval(const double *g, int n, double x, double *t)
{
    if (n < 2) {
        *t = 0;
        return 0;
    }
    int k = 0;
    while (k < n - 2 && x >= g[k + 1]) k++;
    double a = (x - g[k]) / (g[k + 1] - g[k]);
    *t = a < 0 ? 0 : a > 1 ? 1 : a;
    return k;
}

// Grid cell and fraction of x in [0, 1] on n nodes.
static int cell(double x, int n, double *f)
{
    double p = fmin(1, fmax(0, x)) * (n - 1);
    int k = (int)p;
    if (k > n - 2) k = n - 2;
    *f = p - k;
    return k;
}

static double bilerp(const double *v, int w, int h, double x, double y)
{
    double fx, fy;
    int j = cell(x, w, &fx), i = cell(y, h, &fy);
    const double *a = v + (size_t)i * w + j, *b = a + w;
    return (1 - fy) * ((1 - fx) * a[0] + fx * a[1]) + fy * ((1 - fx) * b[0] + fx * b[1]);
}

// The inverse of the VNDF warp of slices sl[0..ns) with weights ws: the
// point u of the square to its uniform variates s (conditional CDF of x in
// row y, marginal CDF of y), of the slices' weighted bilinear density.
static void invert(const model_brdf_rgl_t *r, const int *sl, const double *ws, int ns, double ux, double uy,
                   double s[2])
{
    int W = r->vw, H = r->vh;
    double fx, fy, dx = 1.0 / (W - 1), dy = 1.0 / (H - 1);
    int j = cell(ux, W, &fx), i = cell(uy, H, &fy);
    double Fy = 0, num = 0, den = 0;
    for (int k = 0; k < ns; k++) {
        const double *v = r->vndf + (size_t)sl[k] * H * W, *R = r->rowint + (size_t)sl[k] * H;
        const double *M = r->margcdf + (size_t)sl[k] * H, *C = r->condcdf + (size_t)sl[k] * H * W;
        Fy += ws[k] * (M[i] + dy * (fy * R[i] + 0.5 * fy * fy * (R[i + 1] - R[i])));
        double v0 = (1 - fy) * v[i * W + j] + fy * v[(i + 1) * W + j];
        double v1 = (1 - fy) * v[i * W + j + 1] + fy * v[(i + 1) * W + j + 1];
        num += ws[k] * ((1 - fy) * C[i * W + j] + fy * C[(i + 1) * W + j] + dx * (fx * v0 + 0.5 * fx * fx * (v1 - v0)));
        den += ws[k] * ((1 - fy) * R[i] + fy * R[i + 1]);
    }
    s[0] = den > 0 ? fmin(1, fmax(0, num / den)) : ux;
    s[1] = fmin(1, fmax(0, Fy));
}

static double elevation(model_vec3_t d)
{
    double dist = sqrt(d.x * d.x + d.y * d.y + (d.z - 1) * (d.z - 1));
    return 2 * asin(fmin(1, 0.5 * dist));
}

static double theta2u(double t) { return sqrt(fmax(0, t) * (2 / M_PI)); }
static double phi2u(double p) { return (p + M_PI) / (2 * M_PI); }

double model_brdf_rgl_eval(const model_brdf_rgl_t *r, model_vec3_t wi, model_vec3_t wo, const double *chw)
{
    if (!(wi.z > 0) || !(wo.z > 0)) return 0;
    if (r->reduction >= 2) {   // mirror w_i into the measured range of phi_i (y <= 0; x <= 0 for a quarter)
        double sy = wi.y, sx = r->reduction == 4 ? wi.x : sy;
        if (sx >= 0) wi.x = -wi.x, wo.x = -wo.x;
        if (sy >= 0) wi.y = -wi.y, wo.y = -wo.y;
    }
    double hx = wi.x + wo.x, hy = wi.y + wo.y, hz = wi.z + wo.z, hn = sqrt(hx * hx + hy * hy + hz * hz);
    model_vec3_t m = { hx / hn, hy / hn, hz / hn };
    double th_i = elevation(wi), ph_i = atan2(wi.y, wi.x), th_m = elevation(m), ph_m = atan2(m.y, m.x);
    double ui[2] = { theta2u(th_i), phi2u(ph_i) };
    double um[2] = { theta2u(th_m), phi2u(r->isotropic ? ph_m - ph_i : ph_m) };
    um[1] -= floor(um[1]);
    double tp, tt;
    int kp = interval(r->phi_i, r->nphi, ph_i, &tp), kt = interval(r->theta_i, r->ntheta, th_i, &tt);
    int sl[4], ns = 0;
    double ws[4];
    for (int a = 0; a < 2; a++)
        for (int b = 0; b < 2; b++) {
            double w = (a ? tp : 1 - tp) * (b ? tt : 1 - tt);
            if (w <= 0 || (a && r->nphi < 2) || (b && r->ntheta < 2)) continue;
            sl[ns] = (kp + a) * r->ntheta + kt + b;
            ws[ns++] = w;
        }
    double s[2];
    invert(r, sl, ws, ns, um[0], um[1], s);
    double v = 0;
    size_t plane = (size_t)r->sh * r->sw;
    for (int k = 0; k < ns; k++)
        for (int c = 0; c < r->nch; c++)
            if (chw[c] != 0)
                v += ws[k] * chw[c] * bilerp(r->spec + ((size_t)sl[k] * r->nch + c) * plane, r->sw, r->sh, s[0], s[1]);
    if (r->jacobian)
        v *= bilerp(r->ndf, r->ndf_w, r->ndf_h, um[0], um[1]) /
             (4 * bilerp(r->sigma, r->sig_w, r->sig_h, ui[0], ui[1]));
    return v;
}

// The root in [0, 1] of a t^2 + b t = c (b >= 0, c >= 0: a cell's cumulative
// of a linear density), the stable form of the quadratic formula.
static double cell_root(double a, double b, double c)
{
    double d = b * b + 4 * a * c;
    double t = d > 0 ? 2 * c / (b + sqrt(d)) : (a != 0 ? -b / (2 * a) : 0);
    return fmin(1, fmax(0, t));
}

// The warp of slice sl forward: the uniform variates s (s[0] the conditional
// CDF of x in row y, s[1] the marginal of y) to the point u of the square,
// inverting the bilinear density's CDFs (invert above) cell by cell.
static void warp(const model_brdf_rgl_t *r, int sl, const double s[2], double u[2])
{
    int W = r->vw, H = r->vh;
    double dx = 1.0 / (W - 1), dy = 1.0 / (H - 1);
    const double *v = r->vndf + (size_t)sl * H * W, *R = r->rowint + (size_t)sl * H;
    const double *M = r->margcdf + (size_t)sl * H, *C = r->condcdf + (size_t)sl * H * W;
    int i = 0;
    while (i < H - 2 && M[i + 1] <= s[1]) i++;
    double fy = cell_root(0.5 * dy * (R[i + 1] - R[i]), dy * R[i], fmax(0, s[1] - M[i]));
    double den = (1 - fy) * R[i] + fy * R[i + 1], t = s[0] * den;
    int j = 0;
    while (j < W - 2 && (1 - fy) * C[i * W + j + 1] + fy * C[(i + 1) * W + j + 1] <= t) j++;
    double v0 = (1 - fy) * v[i * W + j] + fy * v[(i + 1) * W + j];
    double v1 = (1 - fy) * v[i * W + j + 1] + fy * v[(i + 1) * W + j + 1];
    double base = (1 - fy) * C[i * W + j] + fy * C[(i + 1) * W + j];
    double fx = cell_root(0.5 * dx * (v1 - v0), dx * v0, fmax(0, t - base));
    u[0] = (j + fx) * dx;
    u[1] = (i + fy) * dy;
}

int model_brdf_rgl_nodes_max(const model_brdf_rgl_t *r) { return r->sw * r->sh; }

int model_brdf_rgl_nodes(const model_brdf_rgl_t *r, int iphi, int itheta, model_vec3_t *wi, model_vec3_t *wo,
                         double *domega_sr)
{
    double ti = r->theta_i[itheta], pi = r->nphi ? r->phi_i[iphi] : 0;
    *wi = (model_vec3_t){ sin(ti) * cos(pi), sin(ti) * sin(pi), cos(ti) };
    int sl = iphi * r->ntheta + itheta, n = 0, W = r->vw, H = r->vh;
    const double *v = r->vndf + (size_t)sl * H * W;
    for (int a = 0; a < r->sh; a++)
        for (int b = 0; b < r->sw; b++) {
            double s[2] = { (double)b / (r->sw - 1), (double)a / (r->sh - 1) }, u[2];
            warp(r, sl, s, u);
            double p = bilerp(v, W, H, u[0], u[1]);
            double th = 0.5 * M_PI * u[0] * u[0], ph = 2 * M_PI * u[1] - M_PI + (r->isotropic ? pi : 0);
            model_vec3_t m = { sin(th) * cos(ph), sin(th) * sin(ph), cos(th) };
            double im = wi->x * m.x + wi->y * m.y + wi->z * m.z;
            model_vec3_t o = { 2 * im * m.x - wi->x, 2 * im * m.y - wi->y, 2 * im * m.z - wi->z };
            if (!(im > 0) || !(o.z > 0)) continue;
            double cell = (b == 0 || b == r->sw - 1 ? 0.5 : 1) * (a == 0 || a == r->sh - 1 ? 0.5 : 1) /
                          ((double)(r->sw - 1) * (r->sh - 1));
            wo[n] = o;
            domega_sr[n++] = p > 0 ? cell / p * 2 * M_PI * M_PI * u[0] * sin(th) * 4 * im : 0;
        }
    return n;
}

// CIE 1931 y-bar by the multi-lobe Gaussian fit of Wyman, Sloan and Shirley
// (2013), for the luminance of spectral files.
static double ybar(double nm)
{
    double t1 = (nm - 568.8) * (nm < 568.8 ? 0.0213 : 0.0247), t2 = (nm - 530.9) * (nm < 530.9 ? 0.0613 : 0.0322);
    return 0.821 * exp(-0.5 * t1 * t1) + 0.286 * exp(-0.5 * t2 * t2);
}

bool model_brdf_rgl_channel_weights(const model_brdf_rgl_t *r, int ch, double *w, const char *name)
{
    if (!r->lambda) {
        static const double luma[3] = { 0.2126, 0.7152, 0.0722 };
        for (int c = 0; c < 3; c++)
            w[c] = ch == MODEL_CHANNEL_LUMA ? luma[c] : (c == (int)ch - (int)MODEL_CHANNEL_R ? 1 : 0);
        return true;
    }
    if (ch != MODEL_CHANNEL_LUMA) {
        model_error(name, 0, "a spectral RGL file (%d wavelengths): only --channel luma (its CIE Y) is offered",
                    r->nch);
        return false;
    }
    double sum = 0;
    for (int c = 0; c < r->nch; c++) {   // trapezoid weights over the wavelengths, normalised
        double lo = c > 0 ? r->lambda[c - 1] : r->lambda[c], hi = c + 1 < r->nch ? r->lambda[c + 1] : r->lambda[c];
        w[c] = ybar(r->lambda[c]) * (r->nch > 1 ? 0.5 * (hi - lo) : 1);
        sum += w[c];
    }
    if (!(sum > 0)) {
        model_error(name, 0, "spectral RGL file: its wavelengths (%g..%g nm) see no luminance", r->lambda[0],
                    r->lambda[r->nch - 1]);
        return false;
    }
    for (int c = 0; c < r->nch; c++) w[c] /= sum;
    return true;
}
