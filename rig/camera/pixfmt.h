// rig/camera/pixfmt.h — the monochrome pixel formats refl records, by their GenICam
// PFNC names and codes, and their unpacking into 16-bit values.
//
// Unpacked: Mono8 (1 byte), Mono10, Mono12, Mono16 (2 bytes little-endian, the
// value in the low bits). Packed (the bytes of a frame are one bit stream):
// - PFNC Mono10p / Mono12p: least significant bit first: pixel i occupies bits
//   [b*i, b*i + b) of the stream, where byte k holds stream bits 8k .. 8k+7
//   (Mono10p: 4 pixels in 5 bytes; Mono12p: 2 pixels in 3 bytes).
// - GigE Vision Mono10Packed / Mono12Packed: 2 pixels in 3 bytes; byte 0 holds
//   the high 8 bits of pixel 0, byte 2 the high 8 bits of pixel 1, byte 1 their
//   low bits (Mono12Packed: pixel 0 in bits 0-3, pixel 1 in bits 4-7;
//   Mono10Packed: pixel 0 in bits 0-1, pixel 1 in bits 4-5).
// Values come out unscaled: a Mono12p pixel is 0..4095, as the camera sent it.
#pragma once

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RIG_PIXFMT_LIST(X)                                   \
    X(MONO8,          "Mono8",        0x01080001u, 8, 0)    \
    X(MONO10,         "Mono10",       0x01100003u, 10, 0)   \
    X(MONO12,         "Mono12",       0x01100005u, 12, 0)   \
    X(MONO16,         "Mono16",       0x01100007u, 16, 0)   \
    X(MONO10P,        "Mono10p",      0x010a0046u, 10, 1)   \
    X(MONO12P,        "Mono12p",      0x010c0047u, 12, 1)   \
    X(MONO10_PACKED,  "Mono10Packed", 0x010c0004u, 10, 2)   \
    X(MONO12_PACKED,  "Mono12Packed", 0x010c0006u, 12, 2)

typedef enum {
#define X(id, name, pfnc, bits, packing) RIG_PIXFMT_##id,
    RIG_PIXFMT_LIST(X)
#undef X
    RIG_PIXFMT_COUNT
} rig_pixfmt_t;

// The format of a PFNC name ("Mono12p") or code; false when refl does not record it.
bool        rig_pixfmt_from_name(const char *name, rig_pixfmt_t *out);
bool        rig_pixfmt_from_pfnc(uint32_t code, rig_pixfmt_t *out);
const char *rig_pixfmt_name(rig_pixfmt_t f);
uint32_t    rig_pixfmt_pfnc(rig_pixfmt_t f);
// Significant bits of a pixel (8, 10, 12 or 16): full scale 2^bits - 1.
int         rig_pixfmt_bits(rig_pixfmt_t f);
bool        rig_pixfmt_is_packed(rig_pixfmt_t f);
// Bytes of a width x height frame in format f.
size_t      rig_pixfmt_frame_bytes(rig_pixfmt_t f, int width, int height);
// Unpack a frame of size bytes into out[width * height]. false (message set,
// naming the format and both sizes) when size is not the frame's size.
bool        rig_pixfmt_unpack(rig_pixfmt_t f, const uint8_t *data, size_t size, int width, int height,
                              uint16_t *out);
// The inverse, for tests and the virtual camera: pack in[width * height]
// (values above the format's full scale are an error) into out[frame_bytes].
bool        rig_pixfmt_pack(rig_pixfmt_t f, const uint16_t *in, int width, int height, uint8_t *out);

#ifdef __cplusplus
}
#endif
