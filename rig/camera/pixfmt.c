// rig/camera/pixfmt.c — monochrome pixel formats and their unpacking (rig/camera/pixfmt.h).
#include <string.h>

#include "model/model.h"
#include "rig/camera/pixfmt.h"

static const struct {
    const char *name;
    uint32_t    pfnc;
    int         bits;
    int         packing;   // 0 unpacked, 1 PFNC LSB-first, 2 GigE Vision "Packed"
} formats[RIG_PIXFMT_COUNT] = {
#define X(id, name, pfnc, bits, packing) { name, pfnc, bits, packing },
    RIG_PIXFMT_LIST(X)
#undef X
};

bool rig_pixfmt_from_name(const char *name, rig_pixfmt_t *out)
{
    for (int i = 0; i < RIG_PIXFMT_COUNT; i++)
        if (name && !strcmp(name, formats[i].name)) {
            *out = (rig_pixfmt_t)i;
            return true;
        }
    return false;
}

bool rig_pixfmt_from_pfnc(uint32_t code, rig_pixfmt_t *out)
{
    for (int i = 0; i < RIG_PIXFMT_COUNT; i++)
        if (code == formats[i].pfnc) {
            *out = (rig_pixfmt_t)i;
            return true;
        }
    return false;
}

const char *rig_pixfmt_name(rig_pixfmt_t f) { return formats[f].name; }
uint32_t    rig_pixfmt_pfnc(rig_pixfmt_t f) { return formats[f].pfnc; }
int         rig_pixfmt_bits(rig_pixfmt_t f) { return formats[f].bits; }
bool        rig_pixfmt_is_packed(rig_pixfmt_t f) { return formats[f].packing != 0; }

size_t rig_pixfmt_frame_bytes(rig_pixfmt_t f, int width, int height)
{
    size_t n = (size_t)width * (size_t)height;
    switch (formats[f].packing) {
    case 0: return formats[f].bits == 8 ? n : 2 * n;
    case 1: return (n * (size_t)formats[f].bits + 7) / 8;
    default: return (n / 2) * 3 + (n % 2 ? 2 : 0);   // a lone last pixel takes bytes 0 and 1 of a triple
    }
}

// GigE Vision "Packed": the low bits of pixel k (0 or 1) of a triple sit at
// this shift of its middle byte (Mono10Packed and Mono12Packed alike).
static int packed_low_shift(int k) { return k ? 4 : 0; }

bool rig_pixfmt_unpack(rig_pixfmt_t f, const uint8_t *data, size_t size, int width, int height, uint16_t *out)
{
    size_t n = (size_t)width * (size_t)height, want = rig_pixfmt_frame_bytes(f, width, height);
    if (size != want) {
        model_error(NULL, 0, "a %dx%d %s frame has %zu bytes, not %zu", width, height, formats[f].name, want, size);
        return false;
    }
    int bits = formats[f].bits;
    switch (formats[f].packing) {
    case 0:
        if (bits == 8)
            for (size_t i = 0; i < n; i++) out[i] = data[i];
        else
            for (size_t i = 0; i < n; i++) out[i] = (uint16_t)(data[2 * i] | data[2 * i + 1] << 8);
        return true;
    case 1: {
        uint32_t mask = (1u << bits) - 1;
        for (size_t i = 0; i < n; i++) {
            size_t bit = i * (size_t)bits, byte = bit / 8;
            uint32_t w = data[byte] | (uint32_t)(byte + 1 < size ? data[byte + 1] : 0) << 8 |
                         (uint32_t)(byte + 2 < size ? data[byte + 2] : 0) << 16;
            out[i] = (uint16_t)((w >> (bit % 8)) & mask);
        }
        return true;
    }
    default: {
        int low = bits - 8;
        uint32_t lowmask = (1u << low) - 1;
        for (size_t i = 0; i < n; i++) {
            const uint8_t *t = data + (i / 2) * 3;
            int k = (int)(i % 2);
            uint32_t hi = k ? t[2] : t[0];
            out[i] = (uint16_t)(hi << low | ((uint32_t)t[1] >> packed_low_shift(k) & lowmask));
        }
        return true;
    }
    }
}

bool rig_pixfmt_pack(rig_pixfmt_t f, const uint16_t *in, int width, int height, uint8_t *out)
{
    size_t n = (size_t)width * (size_t)height, nb = rig_pixfmt_frame_bytes(f, width, height);
    int bits = formats[f].bits;
    for (size_t i = 0; i < n; i++)
        if (in[i] >> bits) {
            model_error(NULL, 0, "pixel %zu = %u is above %s's full scale %u", i, in[i], formats[f].name,
                        (1u << bits) - 1);
            return false;
        }
    memset(out, 0, nb);
    switch (formats[f].packing) {
    case 0:
        for (size_t i = 0; i < n; i++) {
            if (bits == 8) {
                out[i] = (uint8_t)in[i];
            } else {
                out[2 * i] = (uint8_t)in[i];
                out[2 * i + 1] = (uint8_t)(in[i] >> 8);
            }
        }
        return true;
    case 1:
        for (size_t i = 0; i < n; i++)
            for (int b = 0; b < bits; b++)
                if (in[i] >> b & 1) {
                    size_t bit = i * (size_t)bits + (size_t)b;
                    out[bit / 8] |= (uint8_t)(1u << (bit % 8));
                }
        return true;
    default: {
        int low = bits - 8;
        for (size_t i = 0; i < n; i++) {
            uint8_t *t = out + (i / 2) * 3;
            int k = (int)(i % 2);
            t[k ? 2 : 0] = (uint8_t)(in[i] >> low);
            t[1] |= (uint8_t)((in[i] & ((1u << low) - 1)) << packed_low_shift(k));
        }
        return true;
    }
    }
}
