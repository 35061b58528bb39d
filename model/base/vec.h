// model/base/vec.h — small numeric helpers every layer may use: 3-vectors
// (model_vec3_t, mm or unit directions), row-major 3x3 matrices (double[9];
// the output first, as mrcal orders arguments; outputs may alias inputs), an
// orthonormal frame around a unit vector, and counter-based random numbers
// (reproducible per seed, stream and index, whatever the thread schedule).
#pragma once

#include <math.h>
#include <stdbool.h>
#include <stdint.h>

#include "model/model.h"

static inline model_vec3_t v3(double x, double y, double z) { return (model_vec3_t){ x, y, z }; }
static inline model_vec3_t v3_add(model_vec3_t a, model_vec3_t b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline model_vec3_t v3_sub(model_vec3_t a, model_vec3_t b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline model_vec3_t v3_scale(model_vec3_t a, double s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline double       v3_dot(model_vec3_t a, model_vec3_t b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline model_vec3_t v3_cross(model_vec3_t a, model_vec3_t b)
{
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double       v3_norm(model_vec3_t a) { return sqrt(v3_dot(a, a)); }
static inline model_vec3_t v3_unit(model_vec3_t a)
{
    double n = v3_norm(a);
    return n > 0 ? v3_scale(a, 1.0 / n) : a;
}
// Two unit vectors a, b completing the unit vector n to an orthonormal frame.
static inline void frame_of(model_vec3_t n, model_vec3_t *a, model_vec3_t *b)
{
    model_vec3_t h = fabs(n.x) < 0.6 ? v3(1, 0, 0) : v3(0, 1, 0);
    *a = v3_unit(v3_cross(h, n));
    *b = v3_cross(n, *a);
}

// 3x3 matrices, row-major. out = a b; out = a b^T; out = a^T b; out = m v;
// out = m^T; out = m^-1 (false, out untouched, when |det| <= 1e-300).
static inline void m3_mul(double out[9], const double a[9], const double b[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) t[i * 3 + j] = a[i * 3] * b[j] + a[i * 3 + 1] * b[3 + j] + a[i * 3 + 2] * b[6 + j];
    for (int k = 0; k < 9; k++) out[k] = t[k];
}
static inline void m3_mul_bt(double out[9], const double a[9], const double b[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[i * 3 + j] = a[i * 3] * b[j * 3] + a[i * 3 + 1] * b[j * 3 + 1] + a[i * 3 + 2] * b[j * 3 + 2];
    for (int k = 0; k < 9; k++) out[k] = t[k];
}
static inline void m3_mul_at(double out[9], const double a[9], const double b[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) t[i * 3 + j] = a[i] * b[j] + a[3 + i] * b[3 + j] + a[6 + i] * b[6 + j];
    for (int k = 0; k < 9; k++) out[k] = t[k];
}
static inline void m3_vec(double out[3], const double m[9], const double v[3])
{
    double t[3];
    for (int i = 0; i < 3; i++) t[i] = m[i * 3] * v[0] + m[i * 3 + 1] * v[1] + m[i * 3 + 2] * v[2];
    out[0] = t[0], out[1] = t[1], out[2] = t[2];
}
static inline void m3_transpose(double out[9], const double m[9])
{
    double t[9] = { m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8] };
    for (int k = 0; k < 9; k++) out[k] = t[k];
}
static inline bool m3_inv(double out[9], const double m[9])
{
    double c[9] = { m[4] * m[8] - m[5] * m[7], m[2] * m[7] - m[1] * m[8], m[1] * m[5] - m[2] * m[4],
                    m[5] * m[6] - m[3] * m[8], m[0] * m[8] - m[2] * m[6], m[2] * m[3] - m[0] * m[5],
                    m[3] * m[7] - m[4] * m[6], m[1] * m[6] - m[0] * m[7], m[0] * m[4] - m[1] * m[3] };
    double det = m[0] * c[0] + m[1] * c[3] + m[2] * c[6];
    if (!(fabs(det) > 1e-300)) return false;
    for (int k = 0; k < 9; k++) out[k] = c[k] / det;
    return true;
}

// Counter-based random numbers (splitmix64): reproducible per (seed, stream,
// index) whatever the thread schedule.
static inline uint64_t model_mix64(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}
typedef struct { uint64_t s; } model_rng_t;
static inline model_rng_t model_rng(uint64_t seed, uint64_t stream)
{
    return (model_rng_t){ model_mix64(seed ^ model_mix64(stream + 0x632be59bd9b4e019ULL)) };
}
static inline uint64_t model_rng_u64(model_rng_t *r) { r->s += 0x9e3779b97f4a7c15ULL; return model_mix64(r->s); }
// Uniform in [0,1).
static inline double model_rng_uniform(model_rng_t *r) { return (model_rng_u64(r) >> 11) * 0x1.0p-53; }
static inline double model_rng_gauss(model_rng_t *r)
{
    double u1 = model_rng_uniform(r), u2 = model_rng_uniform(r);
    if (u1 < 1e-300) u1 = 1e-300;
    return sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
}
