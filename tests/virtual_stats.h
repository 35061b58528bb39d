// tests/virtual_stats.h — the statistic that compares a frame of the virtual
// rig with its noise-free expectation (rig_virtual_expected), shared by
// tests/test_rig_virtual.c (GigE Vision) and tests/test_rig_virtual_inprocess.c.
//
// Over the pixels whose expected value E is at least lit_dn above the dark
// offset, d = frame - E has mean ~0 (within a few standard errors) and the
// variance of the sensor's temporal noise in DN
//   var = K (E - offset) + (read_noise_e K)^2 + 1/12
// (shot noise, read noise, quantisation), so mean(d^2 / var) is ~1; a wrong
// state (another angle, another lamp) gives a ratio far above 1.
#pragma once

#include <math.h>
#include <stddef.h>
#include <stdint.h>

// The [sensor] of examples/virtual-truth.ini at 0 dB: system gain K (DN per
// electron), read noise (electrons), dark offset (DN).
#define VSTAT_K_DN_PER_E   0.25
#define VSTAT_READ_NOISE_E 6.0
#define VSTAT_OFFSET_DN    64.0

typedef struct {
    long   n;          // lit pixels
    double mean;       // mean of frame - expected
    double se;         // its standard error under the noise model
    double z2;         // mean of (frame - expected)^2 / var_model
} vstat_t;

// The same for a sensor of system gain K, read noise read_e and dark offset
// (another camera's sensor, tests/test_rig_cameras.c).
static inline vstat_t vstat_compare_sensor(const uint16_t *pix, const float *E, size_t n, double lit_dn, double K,
                                           double read_e, double offset)
{
    vstat_t c = { 0, 0, 0, 0 };
    double sum = 0, sumvar = 0, z2 = 0;
    for (size_t i = 0; i < n; i++) {
        if (!(E[i] - offset >= lit_dn)) continue;
        double var = K * (E[i] - offset) + read_e * read_e * K * K + 1.0 / 12;
        double d = pix[i] - E[i];
        sum += d;
        sumvar += var;
        z2 += d * d / var;
        c.n++;
    }
    if (c.n) {
        c.mean = sum / c.n;
        c.se = sqrt(sumvar) / c.n;
        c.z2 = z2 / c.n;
    }
    return c;
}

// Compare n frame values (Mono12) with the expected ones, gain 0 dB.
static inline vstat_t vstat_compare(const uint16_t *pix, const float *E, size_t n, double lit_dn)
{
    return vstat_compare_sensor(pix, E, n, lit_dn, VSTAT_K_DN_PER_E, VSTAT_READ_NOISE_E, VSTAT_OFFSET_DN);
}
