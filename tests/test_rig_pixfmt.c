// tests/test_rig_pixfmt.c — the pixel formats refl records (rig/camera/pixfmt.h):
// hand-packed buffers unpack bit-exactly, pack is their inverse, and a frame of
// the wrong size is refused with its sizes named.
#include <stdlib.h>

#include "model/model.h"
#include "rig/camera/pixfmt.h"
#include "tests/test.h"

TEST(pixfmt_names_and_codes)
{
    rig_pixfmt_t f;
    CHECK(rig_pixfmt_from_name("Mono12p", &f) && f == RIG_PIXFMT_MONO12P);
    CHECK(rig_pixfmt_pfnc(f) == 0x010c0047u);
    CHECK(rig_pixfmt_from_pfnc(0x010a0046u, &f) && f == RIG_PIXFMT_MONO10P);
    CHECK(rig_pixfmt_from_pfnc(0x01100005u, &f) && f == RIG_PIXFMT_MONO12);
    CHECK(!rig_pixfmt_from_name("BayerRG8", &f));
    CHECK(!rig_pixfmt_from_pfnc(0x01080009u, &f));
    CHECK(rig_pixfmt_bits(RIG_PIXFMT_MONO10_PACKED) == 10);
    CHECK(rig_pixfmt_frame_bytes(RIG_PIXFMT_MONO10P, 4, 1) == 5);
    CHECK(rig_pixfmt_frame_bytes(RIG_PIXFMT_MONO12P, 2, 1) == 3);
    CHECK(rig_pixfmt_frame_bytes(RIG_PIXFMT_MONO12_PACKED, 3, 1) == 5);
    CHECK(rig_pixfmt_frame_bytes(RIG_PIXFMT_MONO16, 3, 2) == 12);
}

// Bytes written out by hand from each format's description (pixfmt.h).
TEST(pixfmt_unpack_hand_packed)
{
    uint16_t out[4];
    // Mono12p, pixels 0xABC, 0x123: stream bits LSB first -> bytes BC 3A 12
    static const uint8_t m12p[] = { 0xbc, 0x3a, 0x12 };
    CHECK(rig_pixfmt_unpack(RIG_PIXFMT_MONO12P, m12p, 3, 2, 1, out));
    CHECK(out[0] == 0xabc && out[1] == 0x123);
    // Mono10p, pixels 0x3FF, 0x001, 0x2AA, 0x155:
    // bits 0-9 = 3FF, 10-19 = 001, 20-29 = 2AA, 30-39 = 155
    // byte0 = FF; byte1 = 0x03 | (0x001 << 2) = 0x07; byte2 = (0x001 >> 6) | (0x2AA << 4 & 0xF0) = 0xA0;
    // byte3 = (0x2AA >> 4) | (0x155 << 6 & 0xC0) = 0x2A | 0x40 = 0x6A; byte4 = 0x155 >> 2 = 0x55
    static const uint8_t m10p[] = { 0xff, 0x07, 0xa0, 0x6a, 0x55 };
    CHECK(rig_pixfmt_unpack(RIG_PIXFMT_MONO10P, m10p, 5, 4, 1, out));
    CHECK(out[0] == 0x3ff && out[1] == 0x001 && out[2] == 0x2aa && out[3] == 0x155);
    // Mono12Packed (GigE Vision), pixels 0xABC, 0x123: AB, (3 << 4) | C = 3C, 12
    static const uint8_t m12g[] = { 0xab, 0x3c, 0x12 };
    CHECK(rig_pixfmt_unpack(RIG_PIXFMT_MONO12_PACKED, m12g, 3, 2, 1, out));
    CHECK(out[0] == 0xabc && out[1] == 0x123);
    // Mono10Packed, pixels 0x2AD (10 1010 1101), 0x156 (01 0101 0110):
    // byte0 = 0x2AD >> 2 = 0xAB, byte1 = (0x2AD & 3) | (0x156 & 3) << 4 = 0x01 | 0x20 = 0x21, byte2 = 0x156 >> 2 = 0x55
    static const uint8_t m10g[] = { 0xab, 0x21, 0x55 };
    CHECK(rig_pixfmt_unpack(RIG_PIXFMT_MONO10_PACKED, m10g, 3, 2, 1, out));
    CHECK(out[0] == 0x2ad && out[1] == 0x156);
    // Mono16 / Mono12 little-endian, Mono8
    static const uint8_t m16[] = { 0x34, 0x12, 0xff, 0x0f };
    CHECK(rig_pixfmt_unpack(RIG_PIXFMT_MONO12, m16, 4, 2, 1, out));
    CHECK(out[0] == 0x1234 && out[1] == 0x0fff);
    static const uint8_t m8[] = { 7, 250 };
    CHECK(rig_pixfmt_unpack(RIG_PIXFMT_MONO8, m8, 2, 2, 1, out));
    CHECK(out[0] == 7 && out[1] == 250);
}

TEST(pixfmt_pack_roundtrip_and_errors)
{
    enum { W = 7, H = 5, N = W * H };
    uint16_t in[N], back[N];
    uint8_t buf[2 * N];
    for (int f = 0; f < RIG_PIXFMT_COUNT; f++) {
        int bits = rig_pixfmt_bits((rig_pixfmt_t)f);
        for (int i = 0; i < N; i++) in[i] = (uint16_t)((i * 2654435761u >> 7) & ((1u << bits) - 1));
        in[0] = (uint16_t)((1u << bits) - 1);   // full scale
        in[1] = 0;
        size_t nb = rig_pixfmt_frame_bytes((rig_pixfmt_t)f, W, H);
        CHECK(rig_pixfmt_pack((rig_pixfmt_t)f, in, W, H, buf));
        CHECK(rig_pixfmt_unpack((rig_pixfmt_t)f, buf, nb, W, H, back));
        CHECK_MSG(!memcmp(in, back, sizeof in), "%s: unpack(pack(x)) != x", rig_pixfmt_name((rig_pixfmt_t)f));
        // a short frame is refused with both sizes named
        CHECK(!rig_pixfmt_unpack((rig_pixfmt_t)f, buf, nb - 1, W, H, back));
        CHECK_CONTAINS(model_last_error(), rig_pixfmt_name((rig_pixfmt_t)f));
        if (bits < 16) {
            in[2] = (uint16_t)(1u << bits);   // above full scale
            CHECK(!rig_pixfmt_pack((rig_pixfmt_t)f, in, W, H, buf));
            CHECK_CONTAINS(model_last_error(), "full scale");
        }
    }
}
