// rig/virtual/gv_camera.c — a virtual GigE Vision camera: Aravis's ArvGvFakeCamera with
// our GenICam XML and a render thread (see rig/virtual/gv_camera.h).
//
// Threads
//   Aravis GV thread: answers GVCP; in free running it calls fill_cb (with
//     Aravis's fill mutex held) at the frame rate and sends the GVSP packets.
//   render thread:    watches our TriggerSoftware register (REG_TRIGGER), renders,
//     packs to the wire format, publishes the frame as `front`; over GigE Vision
//     it then sends that frame's GVSP packets itself (send_gvsp), at once.
// Why not hand triggered frames to the GV thread (write the fake camera's own
// trigger register): it looks for them only once per period of its trigger
// frequency, polling its sockets with a timeout in whole milliseconds, so it
// spins through the last millisecond of every period. At a 1 kHz check that is
// a whole core spinning while frames render on the others; at a lower rate
// each frame waits up to a period. Its tick is now GV_TICK_HZ (it only answers
// GVCP and free running), and a triggered frame leaves as soon as it is made.
// Block ids (16-bit, 0 invalid) are ours for every frame (fill_cb sets them on
// Aravis's free-running frames too), so a client sees one increasing sequence;
// they start at 65400, so clients meet the 16-bit wrap within their first frames.
// In-process (ArvFakeDevice): the client's ArvFakeStream thread calls fill_cb,
//   which waits for the render thread's frame (fill_inprocess).
// `lock` guards front/stats; `render_lock` serialises calls of the render
// callback (the GV thread renders itself only when no frame is ready).
// Registers live in the fake camera's memory: the GV thread writes them on
// GVCP requests, we read them with arv_fake_camera_read_* (4/8-byte copies).
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <arv.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "rig/virtual/gv_camera.h"
#include "rig/camera/pixfmt.h"

// GigE Vision bootstrap registers (GigE Vision 2.0, table 28).
#define GVBS_MANUFACTURER_NAME 0x0048   // 32 bytes
#define GVBS_MODEL_NAME        0x0068   // 32 bytes
#define GVBS_STRING_SIZE       32
#define GVBS_SCPS0             0x0d04   // stream channel 0 packet size (bits 0-15)
#define GVSP_PACKET_SIZE       8192     // loopback has a 64 KiB MTU: jumbo packets
#define GVCP_PORT              3956
#define GV_TICK_HZ             10.0     // Aravis's GV thread's trigger check (see above)

// Registers our XML adds (inside the fake camera's 64 KiB register memory).
#define REG_TRIGGER            0xa000   // TriggerSoftware as the client sees it
#define REG_EXPOSURE_US        0xa008   // float64 big-endian
#define REG_GAIN_DB            0xa010   // float64 big-endian
#define REG_TEMPERATURE_C      0xa018   // float64 big-endian, read-only to clients
#define REG_EXPOSURE_AUTO      0xa020   // ExposureAuto: 0 Off, 1 Once, 2 Continuous
#define REG_BALANCE_WHITE_AUTO 0xa024   // BalanceWhiteAuto: the same values (a mono sensor ignores it)
#define REG_GAMMA_ENABLE       0xa028   // GammaEnable: 0 / 1
#define REG_LUT_ENABLE         0xa02c   // LUTEnable: 0 / 1
#define REG_GAMMA              0xa030   // float64 big-endian
#define REG_BLACK_LEVEL        0xa038   // float64 big-endian, DN added to every pixel
#define REG_FIRMWARE           0xa040   // DeviceFirmwareVersion, 32 bytes (to 0xa05f)
#define REG_CONTRAST_AUTO      0xa060   // ContrastAuto, a vendor automatic: 0 Off, 1 Once, 2 Continuous
#define REG_GAIN_AUTO          0x0114   // GainAuto of Aravis's fake camera XML: 1 Off, 3 Once, 2 Continuous
#define GAIN_AUTO_OFF          1
#define GVBS_SCPD0             0x0d08   // stream channel 0 packet delay, timestamp ticks

#define EXPOSURE_MIN_US 10.0
#define EXPOSURE_MAX_US 10e6
#define GAIN_MAX_DB     24.0
// What the camera's own automatics do while on (so a client that leaves them on
// gets frames unlike the settings it asked for): ExposureAuto 1.5 x the set
// exposure, GainAuto 6 dB more than the set gain (within the ranges).
#define AUTO_EXPOSURE_FACTOR 1.5
#define AUTO_GAIN_DB         6.0
#define GAMMA_DEFAULT        0.45

struct rig_gv_camera {
    rig_gv_camera_params_t p;
    char address[64], serial[16], vendor[GVBS_STRING_SIZE], model[GVBS_STRING_SIZE];
    char gain_unit[16], firmware[GVBS_STRING_SIZE], refuse_off[32];
    ArvGvFakeCamera *gv;
    ArvDevice       *dev;         // in-process: the ArvFakeDevice (our reference)
    ArvFakeCamera   *fake;
    GThread         *thread;
    atomic_bool      stop;
    int              lock_fd;     // flock on the address's lock file, -1 when none
    int              gvsp_fd;     // our GVSP sender (UDP, bound to address:0); -1 in-process

    GMutex lock;                 // front frame, stats, drop counter, render_error
    GCond  cond;
    uint8_t *front;              // packed wire-format frame ready to send
    size_t   front_cap, front_size;
    int      front_w, front_h;
    guint32  front_pf;
    bool     front_ready;
    rig_gv_camera_stats_t stats;
    guint16  block_id;           // of the last frame sent (GVSP)
    int      drop_triggers;
    char     render_error[512];

    GMutex    render_lock;       // the render callback and the scratch buffers below
    uint16_t *pix;
    size_t    pix_cap;
    uint8_t  *back;
    size_t    back_cap;
    uint64_t  n_renders;
};

rig_gv_camera_params_t rig_gv_camera_defaults(void)
{
    return (rig_gv_camera_params_t){
        .address = "127.0.0.1",
        .serial = "REFL-GV01",
        .vendor = "refl",
        .model = "virtual camera",
        .sensor_width = 1280,
        .sensor_height = 1024,
        .temperature_c = 35.0,
        .trigger_poll_hz = 1000.0,
    };
}

// ---------------------------------------------------------------------------
// Registers

static guint32 reg_get(rig_gv_camera_t *g, guint32 addr)
{
    guint32 v = 0;
    arv_fake_camera_read_register(g->fake, addr, &v);
    return v;
}

static double reg_get_double(rig_gv_camera_t *g, guint32 addr)
{
    guint64 be = 0;
    arv_fake_camera_read_memory(g->fake, addr, sizeof be, &be);
    guint64 u = GUINT64_FROM_BE(be);
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}

static void reg_set_double(rig_gv_camera_t *g, guint32 addr, double d)
{
    guint64 u;
    memcpy(&u, &d, sizeof u);
    guint64 be = GUINT64_TO_BE(u);
    arv_fake_camera_write_memory(g->fake, addr, sizeof be, &be);
}

static void reg_set_string(rig_gv_camera_t *g, guint32 addr, const char *s, size_t size)
{
    char buf[64] = { 0 };
    snprintf(buf, size < sizeof buf ? size : sizeof buf, "%s", s);
    arv_fake_camera_write_memory(g->fake, addr, (guint32)size, buf);
}

// Bytes of a w x h frame in PFNC format pf; 0 when it is not a format of rig/camera/pixfmt.h.
static size_t format_frame_bytes(guint32 pf, int w, int h)
{
    rig_pixfmt_t f;
    return rig_pixfmt_from_pfnc(pf, &f) ? rig_pixfmt_frame_bytes(f, w, h) : 0;
}

static double now_realtime_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

// The settings a frame is taken with, from the registers. false (and a message
// in *err) when they are unusable.
static bool snapshot_settings(rig_gv_camera_t *g, rig_frame_meta_t *m, guint32 *pf_out, char *err, size_t errsize)
{
    memset(m, 0, sizeof *m);
    guint32 pf = reg_get(g, ARV_FAKE_CAMERA_REGISTER_PIXEL_FORMAT);
    m->width = (int)reg_get(g, ARV_FAKE_CAMERA_REGISTER_WIDTH);
    m->height = (int)reg_get(g, ARV_FAKE_CAMERA_REGISTER_HEIGHT);
    m->offset_x = (int)reg_get(g, ARV_FAKE_CAMERA_REGISTER_X_OFFSET);
    m->offset_y = (int)reg_get(g, ARV_FAKE_CAMERA_REGISTER_Y_OFFSET);
    rig_pixfmt_t fmt;
    if (rig_pixfmt_from_pfnc(pf, &fmt)) {
        m->bits = rig_pixfmt_bits(fmt);
        snprintf(m->pixel_format, sizeof m->pixel_format, "%s", rig_pixfmt_name(fmt));
    }
    m->exposure_us = reg_get_double(g, REG_EXPOSURE_US);
    m->gain = reg_get_double(g, REG_GAIN_DB);
    m->temperature_c = reg_get_double(g, REG_TEMPERATURE_C);
    m->system_time_s = now_realtime_s();
    m->timestamp_ns = (uint64_t)(m->system_time_s * 1e9);
    snprintf(m->vendor, sizeof m->vendor, "%s", g->vendor);
    snprintf(m->model, sizeof m->model, "%s", g->model);
    snprintf(m->serial, sizeof m->serial, "%s", g->serial);
    *pf_out = pf;
    if (!m->bits) {
        snprintf(err, errsize, "pixel format register holds 0x%08x, not a format of rig/camera/pixfmt.h (Mono8, Mono10, "
                 "Mono12, Mono16, Mono10p, Mono12p, Mono10Packed, Mono12Packed)", pf);
        return false;
    }
    if (m->width < 1 || m->height < 1 || m->offset_x < 0 || m->offset_y < 0 ||
        m->offset_x + m->width > g->p.sensor_width || m->offset_y + m->height > g->p.sensor_height) {
        snprintf(err, errsize, "region %dx%d at (%d,%d) does not fit the %dx%d sensor", m->width, m->height,
                 m->offset_x, m->offset_y, g->p.sensor_width, g->p.sensor_height);
        return false;
    }
    if (!isfinite(m->exposure_us) || m->exposure_us < EXPOSURE_MIN_US || m->exposure_us > EXPOSURE_MAX_US) {
        snprintf(err, errsize, "ExposureTime %g us outside %g..%g us", m->exposure_us, EXPOSURE_MIN_US, EXPOSURE_MAX_US);
        return false;
    }
    if (!isfinite(m->gain) || m->gain < 0 || m->gain > GAIN_MAX_DB) {
        snprintf(err, errsize, "Gain %g dB outside 0..%g dB", m->gain, GAIN_MAX_DB);
        return false;
    }
    // The camera's automatics and tone curve: the settings the frame is really taken with.
    if (reg_get(g, REG_EXPOSURE_AUTO) != 0) m->exposure_us = fmin(m->exposure_us * AUTO_EXPOSURE_FACTOR, EXPOSURE_MAX_US);
    if (reg_get(g, REG_GAIN_AUTO) != GAIN_AUTO_OFF) m->gain = fmin(m->gain + AUTO_GAIN_DB, GAIN_MAX_DB);
    m->gamma = reg_get(g, REG_GAMMA_ENABLE) ? reg_get_double(g, REG_GAMMA) : 1.0;
    m->black_level = reg_get_double(g, REG_BLACK_LEVEL);
    snprintf(m->gain_unit, sizeof m->gain_unit, "%s", g->gain_unit);
    if (!(m->gamma > 0 && m->gamma <= 4) || !(m->black_level >= 0 && m->black_level <= 4095)) {
        snprintf(err, errsize, "Gamma %g outside (0, 4] or BlackLevel %g outside 0..4095", m->gamma, m->black_level);
        return false;
    }
    return true;
}

// The tone curve after the sensor (the render callback's values): BlackLevel
// added, then the gamma v = max (v / max)^gamma, then, with LUTEnable, the
// camera's LUT v = sqrt(v max). Values stay within 0..max.
static void tone_curve(rig_gv_camera_t *g, const rig_frame_meta_t *m, uint16_t *pix, size_t n)
{
    double maxv = (double)((1u << m->bits) - 1);
    bool lut = reg_get(g, REG_LUT_ENABLE) != 0 || reg_get(g, REG_CONTRAST_AUTO) != 0;
    if (m->gamma == 1.0 && !lut && m->black_level == 0) return;
    for (size_t i = 0; i < n; i++) {
        double v = fmin((double)pix[i] + m->black_level, maxv);
        if (m->gamma != 1.0) v = maxv * pow(v / maxv, m->gamma);
        if (lut) v = sqrt(v * maxv);
        pix[i] = (uint16_t)lround(fmin(v, maxv));
    }
}

static bool grow(void **buf, size_t *cap, size_t need)
{
    if (*cap >= need) return true;
    void *nb = realloc(*buf, need);
    if (!nb) return false;
    *buf = nb;
    *cap = need;
    return true;
}

// Render with the callback (render_lock held) and pack into dst (size bytes).
static int render_and_pack(rig_gv_camera_t *g, rig_frame_meta_t *m, uint8_t *dst)
{
    size_t n = (size_t)m->width * (size_t)m->height;
    if (!grow((void **)&g->pix, &g->pix_cap, n * sizeof *g->pix))
        return rig_fail(RIG_ERR_NO_MEM, "gv camera %s: out of memory for a %dx%d frame", g->serial, m->width, m->height);
    m->frame_id = ++g->n_renders;
    double t0 = now_realtime_s();
    int rc = g->p.render(g->p.render_ctx, m, g->pix);
    double dt = now_realtime_s() - t0;
    g_mutex_lock(&g->lock);
    g->stats.render_s_total += dt;
    g_mutex_unlock(&g->lock);
    if (rc < 0) return rc;
    uint16_t maxv = (uint16_t)((1u << m->bits) - 1);
    for (size_t i = 0; i < n; i++) g->pix[i] = g->pix[i] > maxv ? maxv : g->pix[i];   // the ADC saturates first
    tone_curve(g, m, g->pix, n);
    rig_pixfmt_t fmt;
    if (!rig_pixfmt_from_name(m->pixel_format, &fmt))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: pixel format %s", g->serial, m->pixel_format);
    if (rig_pixfmt_is_packed(fmt)) {   // saturate, then the packed bit stream of rig/camera/pixfmt.h
        for (size_t i = 0; i < n; i++) g->pix[i] = g->pix[i] > maxv ? maxv : g->pix[i];
        if (!rig_pixfmt_pack(fmt, g->pix, m->width, m->height, dst))
            return rig_fail(RIG_ERR_INVALID, "gv camera %s: %s", g->serial, model_last_error());
    } else if (m->bits == 8) {
        for (size_t i = 0; i < n; i++) dst[i] = (uint8_t)(g->pix[i] > maxv ? maxv : g->pix[i]);
    } else {
        // GVSP pixel data is little-endian: on a little-endian host a clamped
        // copy of whole samples (vectorised), else byte by byte.
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
        for (size_t i = 0; i < n; i++) {
            uint16_t v = g->pix[i] > maxv ? maxv : g->pix[i];
            memcpy(dst + 2 * i, &v, sizeof v);
        }
#else
        for (size_t i = 0; i < n; i++) {
            uint16_t v = g->pix[i] > maxv ? maxv : g->pix[i];
            dst[2 * i] = (uint8_t)(v & 0xff);
            dst[2 * i + 1] = (uint8_t)(v >> 8);
        }
#endif
    }
    return 0;
}

static void note_render_error(rig_gv_camera_t *g, const char *msg)
{
    g_mutex_lock(&g->lock);
    g->stats.render_errors++;
    snprintf(g->render_error, sizeof g->render_error, "%s", msg);
    g_mutex_unlock(&g->lock);
}

// ---------------------------------------------------------------------------
// Aravis GV thread: copy the finished frame (fast path), or render now.

// In-process (ArvFakeStream thread, one buffer at a time): the stream offers
// a buffer as soon as one is queued, whatever the trigger, so wait here for the
// frame the render thread makes of the next trigger (or of free running), as a
// triggered camera holds its buffers until a trigger comes. Give up when the
// acquisition stops (the client closes its stream: Aravis joins this thread)
// or the server stops; the buffer then holds zeros and nobody takes it.
static void fill_inprocess(rig_gv_camera_t *g, uint8_t *dst, int w, int h, guint32 pf, size_t size)
{
    g_mutex_lock(&g->lock);
    for (;;) {
        if (g->front_ready && g->front_w == w && g->front_h == h && g->front_pf == pf && g->front_size == size) {
            memcpy(dst, g->front, size);
            g->front_ready = false;
            g->stats.frames_sent++;
            g_cond_broadcast(&g->cond);
            break;
        }
        if (g->front_ready) {   // rendered for other settings: useless now
            g->front_ready = false;
            g_cond_broadcast(&g->cond);
        }
        if (atomic_load(&g->stop) || arv_fake_camera_get_acquisition_status(g->fake) == 0) {
            memset(dst, 0, size);
            break;
        }
        // Register writes do not signal: look again every 2 ms.
        g_cond_wait_until(&g->cond, &g->lock, g_get_monotonic_time() + 2000);
    }
    g_mutex_unlock(&g->lock);
}

// The next GVSP block id (g->lock held): 1, 2, ... 65535, 1, ...
static guint16 next_block_id(rig_gv_camera_t *g)
{
    g->block_id = (guint16)(g->block_id == 65535 ? 1 : g->block_id + 1);
    return g->block_id;
}

static void fill_cb(ArvBuffer *buffer, void *data, guint32 exposure_us_int, guint32 gain_raw, ArvPixelFormat pf)
{
    rig_gv_camera_t *g = data;
    int w = arv_buffer_get_image_width(buffer), h = arv_buffer_get_image_height(buffer);
    uint8_t *dst = (uint8_t *)arv_buffer_get_data(buffer, NULL);
    // fill_buffer checked that the buffer holds the payload of the current
    // registers, Width * Height * bits per pixel (PFNC bits 16-23) / 8.
    size_t size = w < 1 || h < 1 ? 0 : format_frame_bytes((guint32)pf, w, h);
    size_t cap = w < 1 || h < 1 ? 0 : (size_t)w * (size_t)h * ARV_PIXEL_FORMAT_BIT_PER_PIXEL(pf) / 8;
    if (!dst || !size || size > cap) return;
    if (g->p.inprocess) {
        fill_inprocess(g, dst, w, h, (guint32)pf, size);
        return;
    }

    g_mutex_lock(&g->lock);
    arv_buffer_set_frame_id(buffer, next_block_id(g));   // the GV thread sends it with this id
    if (g->front_ready && g->front_w == w && g->front_h == h && g->front_pf == (guint32)pf &&
        g->front_size == size) {
        memcpy(dst, g->front, size);
        g->front_ready = false;
        g->stats.frames_sent++;
        g_cond_broadcast(&g->cond);
        g_mutex_unlock(&g->lock);
        return;
    }
    if (g->front_ready) {   // rendered for other settings: useless now
        g->front_ready = false;
        g_cond_broadcast(&g->cond);
    }
    g_mutex_unlock(&g->lock);

    // No matching frame ready (free running faster than the renderer, or the
    // settings changed since the trigger): render here.
    rig_frame_meta_t m;
    guint32 pf_reg;
    char err[256] = "";
    int rc = RIG_ERR_INVALID;
    g_mutex_lock(&g->render_lock);
    if (!snapshot_settings(g, &m, &pf_reg, err, sizeof err)) {
        // err says why
    } else if (m.width != w || m.height != h || pf_reg != (guint32)pf) {
        snprintf(err, sizeof err, "settings changed while a frame was being sent");
    } else {
        rc = render_and_pack(g, &m, dst);
        if (rc < 0) snprintf(err, sizeof err, "%s", model_last_error());
    }
    g_mutex_unlock(&g->render_lock);
    if (rc < 0) {
        memset(dst, 0, size);
        note_render_error(g, err);
        return;
    }
    g_mutex_lock(&g->lock);
    g->stats.late_frames++;
    g->stats.frames_sent++;
    g_mutex_unlock(&g->lock);
}

// ---------------------------------------------------------------------------
// GVSP sender (GigE Vision 2.0 stream protocol, standard 16-bit block ids)
//
// Every packet starts with: status (u16, 0 = success), block id (u16),
// packet format << 24 | packet id (u32). Then
//   leader  (format 1, packet id 0): reserved (u16), payload type (u16, 1 =
//           image), timestamp (u64 as two u32: ns, the trigger time),
//           pixel format, width, height, x offset, y offset (u32 each),
//           x padding, y padding (u16 each);
//   data    (format 3, packet ids 1..n): the payload in order, each packet as
//           long as the stream channel's packet size (SCPS0) allows: that
//           size counts the IP (20), UDP (8) and GVSP (8) headers too;
//   trailer (format 2, packet id n + 1): reserved (u16), payload type (u16),
//           the image height (u32).
// All fields big-endian. Sent from our own UDP socket bound to the camera's
// address (clients filter by the device's address, not its port).

enum { GVSP_LEADER = 1, GVSP_TRAILER = 2, GVSP_DATA = 3, GVSP_HEADER = 8, GVSP_IP_UDP = 28, GVSP_BATCH = 64 };

static void be16(uint8_t *p, unsigned v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)v;
}

static void be32(uint8_t *p, uint32_t v)
{
    be16(p, v >> 16);
    be16(p + 2, v & 0xffff);
}

static void gvsp_header(uint8_t *p, guint16 block, unsigned format, uint32_t packet_id)
{
    be16(p, 0);
    be16(p + 2, block);
    be32(p + 4, (uint32_t)format << 24 | (packet_id & 0xffffff));
}

// Send `data` (size bytes, the frame of m) as GVSP block `block` to the client's
// stream channel. false with a message in err on failure.
static bool send_gvsp(rig_gv_camera_t *g, guint16 block, const rig_frame_meta_t *m, guint32 pf,
                      const uint8_t *data, size_t size, char *err, size_t errsize)
{
    struct sockaddr_in to;
    GSocketAddress *sa = arv_fake_camera_get_stream_address(g->fake);
    bool have = sa && g_socket_address_to_native(sa, &to, sizeof to, NULL);
    if (sa) g_object_unref(sa);
    if (!have || to.sin_family != AF_INET || to.sin_port == 0) {
        snprintf(err, errsize, "no stream channel is open (the client set no stream destination)");
        return false;
    }
    // GevSCPSPacketSize as the client set it (Aravis places each packet's data
    // by that size); jumbo packets on loopback unless it set another
    guint32 scps = reg_get(g, GVBS_SCPS0) & 0xffff;
    size_t chunk = scps > GVSP_IP_UDP + GVSP_HEADER + 64 ? scps - GVSP_IP_UDP - GVSP_HEADER : 512;
    size_t ndata = (size + chunk - 1) / chunk;
    if (ndata + 1 > 0xffffff) {
        snprintf(err, errsize, "a %zu-byte frame needs more than 2^24 packets of %zu bytes", size, chunk);
        return false;
    }
    uint8_t leader[GVSP_HEADER + 36], trailer[GVSP_HEADER + 8];
    gvsp_header(leader, block, GVSP_LEADER, 0);
    uint8_t *b = leader + GVSP_HEADER;
    be16(b, 0);
    be16(b + 2, 1);
    be32(b + 4, (uint32_t)(m->timestamp_ns >> 32));
    be32(b + 8, (uint32_t)m->timestamp_ns);
    be32(b + 12, pf);
    be32(b + 16, (uint32_t)m->width);
    be32(b + 20, (uint32_t)m->height);
    be32(b + 24, (uint32_t)m->offset_x);
    be32(b + 28, (uint32_t)m->offset_y);
    be16(b + 32, 0);
    be16(b + 34, 0);
    gvsp_header(trailer, block, GVSP_TRAILER, (uint32_t)ndata + 1);
    be16(trailer + GVSP_HEADER, 0);
    be16(trailer + GVSP_HEADER + 2, 1);
    be32(trailer + GVSP_HEADER + 4, (uint32_t)m->height);

    // packets 0 .. ndata + 1 in batches of sendmmsg
    uint8_t hdr[GVSP_BATCH][GVSP_HEADER];
    struct iovec iov[GVSP_BATCH][2];
    struct mmsghdr msg[GVSP_BATCH];
    size_t total = ndata + 2;
    for (size_t first = 0; first < total;) {
        unsigned n = 0;
        for (size_t k = first; k < total && n < GVSP_BATCH; k++, n++) {
            int nio = 1;
            if (k == 0) {
                iov[n][0] = (struct iovec){ leader, sizeof leader };
            } else if (k == total - 1) {
                iov[n][0] = (struct iovec){ trailer, sizeof trailer };
            } else {
                size_t off = (k - 1) * chunk, len = size - off < chunk ? size - off : chunk;
                gvsp_header(hdr[n], block, GVSP_DATA, (uint32_t)k);
                iov[n][0] = (struct iovec){ hdr[n], GVSP_HEADER };
                iov[n][1] = (struct iovec){ (void *)(data + off), len };
                nio = 2;
            }
            msg[n] = (struct mmsghdr){ .msg_hdr = { .msg_name = &to, .msg_namelen = sizeof to,
                                                    .msg_iov = iov[n], .msg_iovlen = (size_t)nio } };
        }
        int sent = sendmmsg(g->gvsp_fd, msg, n, 0);
        if (sent < 0 && errno == EINTR) continue;
        if (sent <= 0) {
            char host[INET_ADDRSTRLEN] = "?";
            inet_ntop(AF_INET, &to.sin_addr, host, sizeof host);
            snprintf(err, errsize, "sending GVSP packet %zu of %zu to %s:%u failed: %s", first, total, host,
                     ntohs(to.sin_port), sent < 0 ? strerror(errno) : "nothing sent");
            return false;
        }
        first += (size_t)sent;
    }
    return true;
}

// Send the published frame (render thread): it leaves `front` at once.
static void send_front(rig_gv_camera_t *g, const rig_frame_meta_t *m, guint32 pf)
{
    g_mutex_lock(&g->lock);
    if (!g->front_ready) {   // taken meanwhile (free running started)
        g_mutex_unlock(&g->lock);
        return;
    }
    g->front_ready = false;   // only this thread swaps front and back: it stays ours
    guint16 block = next_block_id(g);
    g_mutex_unlock(&g->lock);
    char err[400];
    bool ok = send_gvsp(g, block, m, pf, g->front, g->front_size, err, sizeof err);
    g_mutex_lock(&g->lock);
    if (ok) g->stats.frames_sent++;
    else {
        g->stats.send_errors++;
        snprintf(g->render_error, sizeof g->render_error, "frame %u: %s", (unsigned)block, err);
    }
    g_cond_broadcast(&g->cond);
    g_mutex_unlock(&g->lock);
}

// ---------------------------------------------------------------------------
// Render thread

// Render a frame into `back`, then publish it as `front` (its settings in *m,
// its pixel format in *pf). false on failure.
static bool render_publish(rig_gv_camera_t *g, rig_frame_meta_t *mp, guint32 *pfp)
{
    rig_frame_meta_t m;
    guint32 pf;
    char err[512];
    if (!snapshot_settings(g, &m, &pf, err, sizeof err)) {
        note_render_error(g, err);
        return false;
    }
    size_t size = format_frame_bytes(pf, m.width, m.height);
    g_mutex_lock(&g->render_lock);
    int rc = grow((void **)&g->back, &g->back_cap, size) ? render_and_pack(g, &m, g->back)
             : rig_fail(RIG_ERR_NO_MEM, "gv camera %s: out of memory", g->serial);
    if (rc < 0) snprintf(err, sizeof err, "%s", model_last_error());
    g_mutex_unlock(&g->render_lock);
    if (rc < 0) {
        note_render_error(g, err);
        return false;
    }
    g_mutex_lock(&g->lock);
    // swap back and front (front is not in use: fill_cb copies under the lock)
    uint8_t *t = g->front;
    size_t tc = g->front_cap;
    g->front = g->back;
    g->front_cap = g->back_cap;
    g->back = t;
    g->back_cap = tc;
    g->front_size = size;
    g->front_w = m.width;
    g->front_h = m.height;
    g->front_pf = pf;
    g->front_ready = true;
    g->stats.frames_rendered++;
    g_cond_broadcast(&g->cond);   // an in-process fill waits for it
    g_mutex_unlock(&g->lock);
    if (mp) *mp = m;
    if (pfp) *pfp = pf;
    return true;
}

static gpointer render_thread(gpointer data)
{
    rig_gv_camera_t *g = data;
    gint64 period_us = (gint64)(1e6 / g->p.trigger_poll_hz);
    if (period_us < 10) period_us = 10;
    while (!atomic_load(&g->stop)) {
        bool acquiring = arv_fake_camera_get_acquisition_status(g->fake) != 0;
        bool triggered = arv_fake_camera_is_in_software_trigger_mode(g->fake);
        bool free_running = arv_fake_camera_is_in_free_running_mode(g->fake);

        g_mutex_lock(&g->lock);
        bool ready = g->front_ready;
        if (!acquiring && ready) {        // acquisition stopped before the frame went out
            g->front_ready = false;
            ready = false;
        }
        g_mutex_unlock(&g->lock);
        if (!acquiring && reg_get(g, REG_TRIGGER) != 0)   // as a real camera: no acquisition, no frame
            arv_fake_camera_write_register(g->fake, REG_TRIGGER, 0);

        if (acquiring && triggered && !ready && reg_get(g, REG_TRIGGER) != 0) {
            arv_fake_camera_write_register(g->fake, REG_TRIGGER, 0);
            g_mutex_lock(&g->lock);
            g->stats.triggers++;
            bool drop = g->drop_triggers > 0;
            if (drop) {
                g->drop_triggers--;
                g->stats.dropped_triggers++;
            }
            g_mutex_unlock(&g->lock);
            // Send the frame now (in-process, the waiting fill takes it).
            rig_frame_meta_t m;
            guint32 pf;
            if (!drop && render_publish(g, &m, &pf) && !g->p.inprocess) send_front(g, &m, pf);
            continue;
        }
        if (acquiring && free_running && !triggered && !ready) {
            render_publish(g, NULL, NULL);
            continue;
        }
        g_mutex_lock(&g->lock);
        if (!atomic_load(&g->stop))
            g_cond_wait_until(&g->cond, &g->lock, g_get_monotonic_time() + period_us);
        g_mutex_unlock(&g->lock);
    }
    return NULL;
}

// ---------------------------------------------------------------------------
// GenICam XML: Aravis's built-in fake camera description, edited.

// Replace the first `find` after the first `after` (NULL: from the start).
static bool xml_edit(GString *x, const char *after, const char *find, const char *repl)
{
    const char *from = x->str;
    if (after) {
        from = strstr(x->str, after);
        if (!from) return false;
    }
    const char *at = strstr(from, find);
    if (!at) return false;
    gssize pos = at - x->str;
    g_string_erase(x, pos, (gssize)strlen(find));
    g_string_insert(x, pos, repl);
    return true;
}

// Remove from `start` through the next `end`, plus the whitespace before start.
static bool xml_cut(GString *x, const char *start, const char *end)
{
    const char *s = strstr(x->str, start);
    if (!s) return false;
    const char *e = strstr(s, end);
    if (!e) return false;
    while (s > x->str && (s[-1] == ' ' || s[-1] == '\t' || s[-1] == '\n')) s--;
    g_string_erase(x, s - x->str, (e + strlen(end)) - s);
    return true;
}

static const char xml_added[] =
    "\n\t<!-- Added by refl rig/virtual/gv_camera.c -->\n"
    "\t<StringReg Name=\"DeviceSerialNumber\" NameSpace=\"Standard\">\n"
    "\t\t<DisplayName>Serial Number</DisplayName>\n"
    "\t\t<Address>0xd8</Address>\n\t\t<Length>16</Length>\n\t\t<AccessMode>RO</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t</StringReg>\n\n"
    "\t<Float Name=\"DeviceTemperature\" NameSpace=\"Standard\">\n"
    "\t\t<Description>Sensor temperature, degrees Celsius.</Description>\n"
    "\t\t<pValue>DeviceTemperatureReg</pValue>\n\t\t<Unit>C</Unit>\n\t</Float>\n\n"
    "\t<FloatReg Name=\"DeviceTemperatureReg\" NameSpace=\"Custom\">\n"
    "\t\t<Address>0xa018</Address>\n\t\t<Length>8</Length>\n\t\t<AccessMode>RO</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n"
    "\t<Float Name=\"ExposureTime\" NameSpace=\"Standard\">\n"
    "\t\t<Description>Exposure time, in microseconds.</Description>\n"
    "\t\t<pValue>ExposureTimeReg</pValue>\n\t\t<Min>10.0</Min>\n\t\t<Max>10000000.0</Max>\n"
    "\t\t<Unit>us</Unit>\n\t</Float>\n\n"
    "\t<FloatReg Name=\"ExposureTimeReg\" NameSpace=\"Custom\">\n"
    "\t\t<Address>0xa008</Address>\n\t\t<Length>8</Length>\n\t\t<AccessMode>RW</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n"
    "\t<Float Name=\"Gain\" NameSpace=\"Standard\">\n"
    "\t\t<Description>Analog gain, in dB.</Description>\n"
    "\t\t<pValue>GainReg</pValue>\n\t\t<Min>0.0</Min>\n\t\t<Max>24.0</Max>\n"
    "\t\t<Unit>dB</Unit>\n\t</Float>\n\n"
    "\t<FloatReg Name=\"GainReg\" NameSpace=\"Custom\">\n"
    "\t\t<Address>0xa010</Address>\n\t\t<Length>8</Length>\n\t\t<AccessMode>RW</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n";

// The radiometric features (auto functions on by default, as on real cameras)
// and the transport's packet size and delay.
#define XML_AUTO_ENUM(name, desc, addr)                                                                 \
    "\t<Enumeration Name=\"" name "\" NameSpace=\"Standard\">\n"                                     \
    "\t\t<Description>" desc "</Description>\n"                                                       \
    "\t\t<EnumEntry Name=\"Off\" NameSpace=\"Standard\">\n\t\t\t<Value>0</Value>\n\t\t</EnumEntry>\n"     \
    "\t\t<EnumEntry Name=\"Once\" NameSpace=\"Standard\">\n\t\t\t<Value>1</Value>\n\t\t</EnumEntry>\n"    \
    "\t\t<EnumEntry Name=\"Continuous\" NameSpace=\"Standard\">\n\t\t\t<Value>2</Value>\n\t\t</EnumEntry>\n" \
    "\t\t<pValue>" name "Register</pValue>\n\t</Enumeration>\n\n"                                      \
    XML_INT_REG(name "Register", addr, "RW")
#define XML_INT_REG(name, addr, access)                                                                 \
    "\t<IntReg Name=\"" name "\" NameSpace=\"Custom\">\n\t\t<Address>" addr "</Address>\n"              \
    "\t\t<Length>4</Length>\n\t\t<AccessMode>" access "</AccessMode>\n\t\t<pPort>Device</pPort>\n"        \
    "\t\t<Sign>Unsigned</Sign>\n\t\t<Endianess>BigEndian</Endianess>\n\t</IntReg>\n\n"
#define XML_BOOL(name, desc, addr)                                                                      \
    "\t<Boolean Name=\"" name "\" NameSpace=\"Standard\">\n\t\t<Description>" desc "</Description>\n"   \
    "\t\t<pValue>" name "Register</pValue>\n\t\t<OnValue>1</OnValue>\n\t\t<OffValue>0</OffValue>\n"     \
    "\t</Boolean>\n\n" XML_INT_REG(name "Register", addr, "RW")
#define XML_FLOAT(name, desc, addr, min, max)                                                           \
    "\t<Float Name=\"" name "\" NameSpace=\"Standard\">\n\t\t<Description>" desc "</Description>\n"     \
    "\t\t<pValue>" name "Reg</pValue>\n\t\t<Min>" min "</Min>\n\t\t<Max>" max "</Max>\n\t</Float>\n\n"    \
    "\t<FloatReg Name=\"" name "Reg\" NameSpace=\"Custom\">\n\t\t<Address>" addr "</Address>\n"          \
    "\t\t<Length>8</Length>\n\t\t<AccessMode>RW</AccessMode>\n\t\t<pPort>Device</pPort>\n"               \
    "\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n"
#define XML_INT(name, desc, reg, min, max, unit)                                                        \
    "\t<Integer Name=\"" name "\" NameSpace=\"Standard\">\n\t\t<Description>" desc "</Description>\n"   \
    "\t\t<pValue>" reg "</pValue>\n\t\t<Min>" min "</Min>\n\t\t<Max>" max "</Max>\n\t\t<Unit>" unit       \
    "</Unit>\n\t</Integer>\n\n"

static const char xml_radiometric[] =
    XML_AUTO_ENUM("ExposureAuto", "Automatic exposure: while on, frames are exposed 1.5 x ExposureTime.", "0xa020")
    XML_AUTO_ENUM("BalanceWhiteAuto", "Automatic white balance (a mono sensor ignores it).", "0xa024")
    XML_AUTO_ENUM("ContrastAuto", "A vendor's own automatic (not in the SFNC): found by a client only in the "
                  "feature tree; while on, frames get the LUT as with LUTEnable.", "0xa060")
    XML_BOOL("GammaEnable", "Gamma curve on the pixel values.", "0xa028")
    XML_FLOAT("Gamma", "The gamma of the curve v = max (v / max)^Gamma.", "0xa030", "0.1", "4.0")
    XML_BOOL("LUTEnable", "The camera's look-up table v = sqrt(v max) on the pixel values.", "0xa02c")
    XML_FLOAT("BlackLevel", "Black level, DN added to every pixel.", "0xa038", "0.0", "4095.0")
    "\t<StringReg Name=\"DeviceFirmwareVersion\" NameSpace=\"Standard\">\n\t\t<Address>0xa040</Address>\n"
    "\t\t<Length>32</Length>\n\t\t<AccessMode>RO</AccessMode>\n\t\t<pPort>Device</pPort>\n\t</StringReg>\n\n"
    XML_INT("GevSCPSPacketSize", "Stream channel 0 packet size, bytes (IP and UDP headers included).",
            "GevSCPSPacketSizeRegister", "576", "9000", "B")
    XML_INT_REG("GevSCPSPacketSizeRegister", "0xd04", "RW")
    XML_INT("GevSCPD", "Stream channel 0 delay between packets, timestamp ticks.", "GevSCPDRegister", "0",
            "1000000", "")
    XML_INT_REG("GevSCPDRegister", "0xd08", "RW");

// Guards Aravis's process-wide fake camera XML file name, which every new
// ArvFakeCamera reads (arv_set_fake_camera_genicam_filename is not thread safe).
static GMutex xml_name_lock;

// PixelFormat entries after Mono16: the formats of rig/camera/pixfmt.h the built-in
// XML lacks (Mono12 goes after Mono8, as before). false when Mono16 is missing.
static bool xml_add_formats(GString *x)
{
    GString *e = g_string_new("</EnumEntry>");
    for (int f = 0; f < RIG_PIXFMT_COUNT; f++) {
        if (f == RIG_PIXFMT_MONO8 || f == RIG_PIXFMT_MONO12 || f == RIG_PIXFMT_MONO16) continue;
        g_string_append_printf(e, "\n\t\t<EnumEntry Name=\"%s\" NameSpace=\"Standard\">\n\t\t\t<Value>%u</Value>"
                               "\n\t\t</EnumEntry>", rig_pixfmt_name((rig_pixfmt_t)f),
                               (unsigned)rig_pixfmt_pfnc((rig_pixfmt_t)f));
    }
    bool ok = xml_edit(x, "<EnumEntry Name=\"Mono16\"", "</EnumEntry>", e->str);
    g_string_free(e, TRUE);
    return ok;
}

// The variants of the XML a camera's parameters ask for: the Gain's unit, an
// auto feature that cannot be switched off (no Off entry). false
// when the XML lacks what is edited.
static bool xml_variants(GString *x, const char *gain_unit, const char *refuse_off)
{
    if (strcmp(gain_unit, "dB")) {
        char unit[48] = "";
        if (*gain_unit) snprintf(unit, sizeof unit, "<Unit>%s</Unit>", gain_unit);
        if (!xml_edit(x, "<Float Name=\"Gain\"", "<Unit>dB</Unit>", unit)) return false;
    }
    if (*refuse_off) {   // its Off entry removed: it cannot be switched off
        char en[64];
        snprintf(en, sizeof en, "<Enumeration Name=\"%s\"", refuse_off);
        const char *e = strstr(x->str, en);
        const char *off = e ? strstr(e, "<EnumEntry Name=\"Off\"") : NULL;
        const char *end = off ? strstr(off, "</EnumEntry>") : NULL;
        const char *next = e ? strstr(e, "</Enumeration>") : NULL;
        if (!end || end > next) return false;
        g_string_erase(x, off - x->str, end + strlen("</EnumEntry>") - off);
    }
    return true;
}

// Our XML as a new string, or NULL with a message.
static char *make_genicam_xml(const char *gain_unit, const char *refuse_off)
{
    g_mutex_lock(&xml_name_lock);
    ArvFakeCamera *tmp = arv_fake_camera_new("REFL-XML");   // no network: just the built-in XML
    g_mutex_unlock(&xml_name_lock);
    size_t size = 0;
    const char *base = tmp ? arv_fake_camera_get_genicam_xml(tmp, &size) : NULL;
    if (!base || !size) {
        if (tmp) g_object_unref(tmp);
        rig_fail(RIG_ERR_IO, "gv camera: Aravis's built-in fake camera XML is not available");
        return NULL;
    }
    GString *x = g_string_new_len(base, (gssize)size);
    g_object_unref(tmp);

    char mono12[160];
    snprintf(mono12, sizeof mono12,
             "</EnumEntry>\n\t\t<EnumEntry Name=\"Mono12\" NameSpace=\"Standard\">\n\t\t\t<Value>%u</Value>\n\t\t</EnumEntry>",
             (unsigned)ARV_PIXEL_FORMAT_MONO_12);
    const char *bad = NULL;
    // Root: make sure AnalogControl is reachable (0.8.26 leaves it out).
    {
        const char *root = strstr(x->str, "<Category Name=\"Root\"");
        const char *end = root ? strstr(root, "</Category>") : NULL;
        if (!end) bad = "Root category";
        else if (!g_strstr_len(root, end - root, "AnalogControl") &&
                 !xml_edit(x, "<Category Name=\"Root\"", "<pFeature>TransportLayerControl</pFeature>",
                           "<pFeature>AnalogControl</pFeature>\n\t\t<pFeature>TransportLayerControl</pFeature>"))
            bad = "Root/TransportLayerControl";
    }
    if (!bad && !xml_edit(x, NULL, "<pFeature>DeviceID</pFeature>",
                          "<pFeature>DeviceID</pFeature>\n\t\t<pFeature>DeviceSerialNumber</pFeature>"
                          "\n\t\t<pFeature>DeviceTemperature</pFeature>\n\t\t<pFeature>DeviceFirmwareVersion</pFeature>"))
        bad = "DeviceID feature";
    if (!bad && !xml_edit(x, "<Category Name=\"TransportLayerControl\"", "<pFeature>PayloadSize</pFeature>",
                          "<pFeature>PayloadSize</pFeature>\n\t\t<pFeature>GevSCPSPacketSize</pFeature>"
                          "\n\t\t<pFeature>GevSCPD</pFeature>"))
        bad = "TransportLayerControl/PayloadSize";
    if (!bad && !xml_edit(x, "<Category Name=\"AnalogControl\"", "<pFeature>GainAuto</pFeature>",
                          "<pFeature>GainAuto</pFeature>\n\t\t<pFeature>BalanceWhiteAuto</pFeature>"
                          "\n\t\t<pFeature>BlackLevel</pFeature>\n\t\t<pFeature>GammaEnable</pFeature>"
                          "\n\t\t<pFeature>Gamma</pFeature>\n\t\t<pFeature>LUTEnable</pFeature>"
                          "\n\t\t<pFeature>ContrastAuto</pFeature>"))
        bad = "AnalogControl/GainAuto";
    // Binning is not simulated: do not advertise it.
    if (!bad && !xml_cut(x, "<pFeature>BinningHorizontal</pFeature>", "</pFeature>")) bad = "BinningHorizontal";
    if (!bad && !xml_cut(x, "<pFeature>BinningVertical</pFeature>", "</pFeature>")) bad = "BinningVertical";
    // Monochrome formats only: those of rig/camera/pixfmt.h (Mono12 unpacked, the packed ones).
    static const char *const colour[] = { "BayerBG8", "BayerGB8", "BayerGR8", "BayerRG8", "RGB8" };
    for (size_t i = 0; !bad && i < sizeof colour / sizeof colour[0]; i++) {
        char start[64];
        snprintf(start, sizeof start, "<EnumEntry Name=\"%s\"", colour[i]);
        if (!xml_cut(x, start, "</EnumEntry>")) bad = colour[i];
    }
    if (!bad && !xml_edit(x, "<EnumEntry Name=\"Mono8\"", "</EnumEntry>", mono12)) bad = "Mono8 entry";
    if (!bad && !xml_add_formats(x)) bad = "Mono16 entry";
    // ExposureTime (float, us) replaces ExposureTimeAbs, which stays as an alias.
    if (!bad && !xml_edit(x, "<Category Name=\"AcquisitionControl\"", "<pFeature>ExposureTimeAbs</pFeature>",
                          "<pFeature>ExposureTime</pFeature>"))
        bad = "AcquisitionControl/ExposureTimeAbs";
    if (!bad && !xml_edit(x, "<Category Name=\"AcquisitionControl\"", "<pFeature>ExposureTime</pFeature>",
                          "<pFeature>ExposureTime</pFeature>\n\t\t<pFeature>ExposureAuto</pFeature>"))
        bad = "AcquisitionControl/ExposureTime";
    if (!bad && !xml_edit(x, "<Float Name=\"ExposureTimeAbs\"", "<pValue>ExposureTimeAbsConverter</pValue>",
                          "<pValue>ExposureTimeReg</pValue>"))
        bad = "ExposureTimeAbs";
    // TriggerSoftware goes to our register; the render thread forwards it.
    if (!bad && !xml_edit(x, "<IntReg Name=\"TriggerSoftwareCommandRegister\"", "<Address>0x30c</Address>",
                          "<Address>0xa000</Address>"))
        bad = "TriggerSoftwareCommandRegister";
    // Gain (float, dB) replaces GainRaw in AnalogControl.
    if (!bad && !xml_edit(x, "<Category Name=\"AnalogControl\"", "<pFeature>GainRaw</pFeature>",
                          "<pFeature>Gain</pFeature>"))
        bad = "AnalogControl/GainRaw";
    const char *end = bad ? NULL : strstr(x->str, "</RegisterDescription>");
    if (end) {
        gssize pos = end - x->str;
        g_string_insert(x, pos, xml_radiometric);
        g_string_insert(x, pos, xml_added);
    } else if (!bad) bad = "</RegisterDescription>";
    if (!bad && !xml_variants(x, gain_unit, refuse_off)) bad = "Gain unit or the register of the feature to refuse";
    if (bad) {
        g_string_free(x, TRUE);
        rig_fail(RIG_ERR_IO, "gv camera: Aravis %d.%d.%d's built-in fake camera XML has no %s where expected; "
                 "rig/virtual/gv_camera.c needs updating for this Aravis version",
                 arv_get_major_version(), arv_get_minor_version(), arv_get_micro_version(), bad);
        return NULL;
    }
    return g_string_free(x, FALSE);
}

// ---------------------------------------------------------------------------
// In-process servers of this process, by serial (rig_camera_open_aravis
// opens "inprocess:SERIAL" through rig_gv_camera_inprocess_device).

#define MAX_INPROCESS 16

static GMutex registry_lock;
static rig_gv_camera_t *registry[MAX_INPROCESS];

static rig_gv_camera_t *registry_find(const char *serial)   // registry_lock held
{
    for (int i = 0; i < MAX_INPROCESS; i++)
        if (registry[i] && !strcmp(registry[i]->serial, serial)) return registry[i];
    return NULL;
}

// 0, or RIG_ERR_BUSY (serial taken) / RIG_ERR_NO_MEM (registry full).
static int registry_add(rig_gv_camera_t *g)
{
    int rc = RIG_ERR_NO_MEM;
    g_mutex_lock(&registry_lock);
    if (registry_find(g->serial)) {
        rc = RIG_ERR_BUSY;
    } else {
        for (int i = 0; i < MAX_INPROCESS && rc; i++)
            if (!registry[i]) {
                registry[i] = g;
                rc = 0;
            }
    }
    g_mutex_unlock(&registry_lock);
    return rc;
}

static void registry_remove(rig_gv_camera_t *g)
{
    g_mutex_lock(&registry_lock);
    for (int i = 0; i < MAX_INPROCESS; i++)
        if (registry[i] == g) registry[i] = NULL;
    g_mutex_unlock(&registry_lock);
}

void *rig_gv_camera_inprocess_device(const char *serial)
{
    if (!serial) return NULL;
    g_mutex_lock(&registry_lock);
    rig_gv_camera_t *g = registry_find(serial);
    ArvDevice *dev = g ? g_object_ref(g->dev) : NULL;
    g_mutex_unlock(&registry_lock);
    return dev;
}

bool rig_gv_camera_inprocess_alive(const void *device)
{
    bool alive = false;
    g_mutex_lock(&registry_lock);
    for (int i = 0; i < MAX_INPROCESS && device; i++)
        if (registry[i] && (const void *)registry[i]->dev == device) alive = true;
    g_mutex_unlock(&registry_lock);
    return alive;
}

// After the server stopped, a client that still holds the device gets frames
// from this (they stay as they are; rig_gv_camera_inprocess_alive says why).
static void fill_gone(ArvBuffer *buffer, void *data, guint32 exposure_us_int, guint32 gain_raw, ArvPixelFormat pf)
{
}

// The ArvFakeDevice of an in-process server, with our XML.
static ArvDevice *new_fake_device(const char *serial, const char *xml_path, char *err, size_t errsize)
{
    GError *e = NULL;
    g_mutex_lock(&xml_name_lock);
    arv_set_fake_camera_genicam_filename(xml_path);   // read when the camera is made
    ArvDevice *dev = arv_fake_device_new(serial, &e);
    arv_set_fake_camera_genicam_filename(NULL);
    g_mutex_unlock(&xml_name_lock);
    if (!dev) snprintf(err, errsize, "%s", e ? e->message : "unknown error");
    g_clear_error(&e);
    return dev;
}

// ---------------------------------------------------------------------------

// 0 when address:3956 is free, RIG_ERR_BUSY when taken, other codes on failure.
// *err_no: errno of a failure.
static int probe_port(const char *address, int *err_no)
{
    int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    *err_no = errno;
    if (fd < 0) return RIG_ERR_IO;
    struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons(GVCP_PORT) };
    inet_pton(AF_INET, address, &sa.sin_addr);
    int rc = 0;
    if (bind(fd, (struct sockaddr *)&sa, sizeof sa) != 0) {
        *err_no = errno;
        rc = errno == EADDRINUSE ? RIG_ERR_BUSY : RIG_ERR_IO;
    }
    close(fd);
    return rc;
}

// Our GVSP socket: UDP from address:0, a send buffer for whole frames.
static int open_gvsp_socket(rig_gv_camera_t *g, const struct in_addr *ia)
{
    int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = 0, .sin_addr = *ia };
    if (fd < 0 || bind(fd, (struct sockaddr *)&sa, sizeof sa) != 0) {
        int e = errno;
        if (fd >= 0) close(fd);
        return rig_fail(RIG_ERR_IO, "gv camera %s: cannot open its stream socket on %s: %s", g->serial,
                        g->address, strerror(e));
    }
    int buf = 4 << 20;   // the kernel caps it (net.core.wmem_max); sends then block briefly
    setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &buf, sizeof buf);
    g->gvsp_fd = fd;
    return 0;
}

int rig_gv_camera_start(rig_gv_camera_t **out, const rig_gv_camera_params_t *p)
{
    int rc = 0, lock_fd = -1;
    char *xml = NULL, *xml_path = NULL;
    rig_gv_camera_t *g = NULL;
    if (!out || !p) return rig_fail(RIG_ERR_INVALID, "gv camera: NULL argument");
    *out = NULL;
    rig_gv_camera_params_t d = rig_gv_camera_defaults();
    const char *address = p->address ? p->address : d.address;
    const char *serial = p->serial ? p->serial : d.serial;
    const char *vendor = p->vendor ? p->vendor : d.vendor;
    const char *model = p->model ? p->model : d.model;
    const char *firmware = p->firmware ? p->firmware : "refl-gv 1.0";
    const char *gain_unit = p->gain_unit ? p->gain_unit : "dB";
    const char *refuse_off = p->refuse_off ? p->refuse_off : "";
    struct in_addr ia;
    if (!p->render) return rig_fail(RIG_ERR_INVALID, "gv camera: no render callback given");
    if (!p->inprocess && (inet_pton(AF_INET, address, &ia) != 1 || (ntohl(ia.s_addr) >> 24) != 127))
        return rig_fail(RIG_ERR_INVALID, "gv camera: address '%s' is not a loopback IPv4 address (127.x.y.z); "
                        "the virtual camera only serves on loopback", address);
    if (!*serial || strlen(serial) >= 16)
        return rig_fail(RIG_ERR_INVALID, "gv camera: serial '%s' must have 1 to 15 characters", serial);
    if (strlen(vendor) >= GVBS_STRING_SIZE || strlen(model) >= GVBS_STRING_SIZE)
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: vendor and model must be shorter than %d characters",
                        serial, GVBS_STRING_SIZE);
    if (strlen(firmware) >= GVBS_STRING_SIZE || strlen(gain_unit) >= 16)
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: firmware must be shorter than %d characters, the gain "
                        "unit than 16", serial, GVBS_STRING_SIZE);
    if (*refuse_off && strcmp(refuse_off, "ExposureAuto") && strcmp(refuse_off, "GainAuto") &&
        strcmp(refuse_off, "BalanceWhiteAuto"))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: refuse_off '%s' is not ExposureAuto, GainAuto or "
                        "BalanceWhiteAuto", serial, refuse_off);
    if (p->sensor_width < 1 || p->sensor_width > 4096 || p->sensor_height < 1 || p->sensor_height > 4096)
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: sensor size %dx%d outside 1..4096", serial,
                        p->sensor_width, p->sensor_height);
    if (!(p->trigger_poll_hz > 0 && p->trigger_poll_hz <= 100000))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: trigger_poll_hz %g outside (0, 100000]", serial, p->trigger_poll_hz);
    if (!isfinite(p->temperature_c))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: temperature is not finite", serial);
    if (!(p->busy_wait_s >= 0 && p->busy_wait_s <= 3600))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: busy_wait_s %g outside 0..3600", serial, p->busy_wait_s);
    if (p->inprocess) {
        bool taken;
        g_mutex_lock(&registry_lock);
        taken = registry_find(serial) != NULL;
        g_mutex_unlock(&registry_lock);
        if (taken)
            return rig_fail(RIG_ERR_BUSY, "gv camera %s: this process already serves an in-process camera with "
                            "serial %s; stop it first or give this one another serial", serial, serial);
    }

    int err_no = 0;
    if (p->inprocess) goto make_xml;   // no socket, no lock file
    // Take turns with other refl servers on this address.
    char lock_path[512];
    snprintf(lock_path, sizeof lock_path, "%s/refl-gvcam-%s.lock", g_get_tmp_dir(), address);
    lock_fd = open(lock_path, O_RDONLY | O_CREAT | O_CLOEXEC, 0666);
    if (lock_fd < 0)
        return rig_fail(RIG_ERR_IO, "gv camera %s: cannot open %s: %s", serial, lock_path, strerror(errno));
    for (double waited = 0;; waited += 0.05) {
        if (flock(lock_fd, LOCK_EX | LOCK_NB) == 0) break;
        if (errno != EWOULDBLOCK || waited >= p->busy_wait_s) {
            rc = rig_fail(RIG_ERR_BUSY, "gv camera %s: another refl virtual camera serves on %s (lock %s%s); "
                          "stop it first", serial, address, lock_path, p->busy_wait_s > 0 ? ", waited" : "");
            goto done;
        }
        g_usleep(50000);
    }
    rc = probe_port(address, &err_no);
    if (rc == RIG_ERR_BUSY) {
        rig_fail(rc, "gv camera %s: %s:%d is already in use (another GigE Vision program?); stop it first",
                 serial, address, GVCP_PORT);
        goto done;
    }
    if (rc < 0) {
        rig_fail(rc, "gv camera %s: cannot bind %s:%d: %s", serial, address, GVCP_PORT, strerror(err_no));
        goto done;
    }
make_xml:
    if (!(xml = make_genicam_xml(gain_unit, refuse_off))) {
        rc = RIG_ERR_IO;
        goto done;
    }
    GError *gerr = NULL;
    int fd = g_file_open_tmp("refl-gvcam-XXXXXX.xml", &xml_path, &gerr);
    if (fd < 0) {
        rc = rig_fail(RIG_ERR_IO, "gv camera %s: cannot write its GenICam XML: %s", serial, gerr->message);
        g_error_free(gerr);
        goto done;
    }
    close(fd);
    if (!g_file_set_contents(xml_path, xml, -1, &gerr)) {
        rc = rig_fail(RIG_ERR_IO, "gv camera %s: cannot write %s: %s", serial, xml_path, gerr->message);
        g_error_free(gerr);
        goto done;
    }

    g = calloc(1, sizeof *g);
    if (!g) {
        rc = rig_fail(RIG_ERR_NO_MEM, "gv camera %s: out of memory", serial);
        goto done;
    }
    g->p = *p;
    g->gvsp_fd = -1;
    g->block_id = 65399;   // the first frame is 65400, as Aravis's fake camera's: clients meet the wrap early
    g->lock_fd = lock_fd;
    lock_fd = -1;
    snprintf(g->address, sizeof g->address, "%s%s", p->inprocess ? RIG_GV_INPROCESS_PREFIX : "",
             p->inprocess ? serial : address);
    snprintf(g->serial, sizeof g->serial, "%s", serial);
    snprintf(g->vendor, sizeof g->vendor, "%s", vendor);
    snprintf(g->model, sizeof g->model, "%s", model);
    snprintf(g->firmware, sizeof g->firmware, "%s", firmware);
    snprintf(g->gain_unit, sizeof g->gain_unit, "%s", gain_unit);
    snprintf(g->refuse_off, sizeof g->refuse_off, "%s", refuse_off);
    g->p.address = g->address;
    g->p.serial = g->serial;
    g->p.vendor = g->vendor;
    g->p.model = g->model;
    g_mutex_init(&g->lock);
    g_mutex_init(&g->render_lock);
    g_cond_init(&g->cond);

    if (p->inprocess) {
        char msg[512];
        if (!(g->dev = new_fake_device(serial, xml_path, msg, sizeof msg))) {
            rc = rig_fail(RIG_ERR_IO, "gv camera %s: Aravis could not make an in-process fake device: %s", serial, msg);
            goto done;
        }
        g->fake = arv_fake_device_get_fake_camera(ARV_FAKE_DEVICE(g->dev));
        goto registers;
    }
    g->gv = arv_gv_fake_camera_new_full(address, serial, xml_path);   // reads the XML file now
    if (!g->gv || !arv_gv_fake_camera_is_running(g->gv)) {
        rc = rig_fail(RIG_ERR_IO, "gv camera %s: Aravis could not start a GigE Vision server on %s "
                      "(no network interface with that address?)", serial, address);
        goto done;
    }
    // Aravis reports running even when its bind failed: check the port is now taken.
    if (probe_port(address, &err_no) != RIG_ERR_BUSY) {
        rc = rig_fail(RIG_ERR_BUSY, "gv camera %s: Aravis did not get %s:%d (taken meanwhile?)", serial,
                      address, GVCP_PORT);
        goto done;
    }
    g->fake = arv_gv_fake_camera_get_fake_camera(g->gv);
    if ((rc = open_gvsp_socket(g, &ia))) goto done;
registers:
    reg_set_string(g, GVBS_MANUFACTURER_NAME, g->vendor, GVBS_STRING_SIZE);
    reg_set_string(g, GVBS_MODEL_NAME, g->model, GVBS_STRING_SIZE);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_WIDTH, (guint32)p->sensor_width);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_HEIGHT, (guint32)p->sensor_height);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_WIDTH, (guint32)p->sensor_width);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_HEIGHT, (guint32)p->sensor_height);
    arv_fake_camera_write_register(g->fake, REG_TRIGGER, 0);
    arv_fake_camera_write_register(g->fake, GVBS_SCPS0, GVSP_PACKET_SIZE);
    reg_set_double(g, REG_EXPOSURE_US, ARV_FAKE_CAMERA_EXPOSURE_TIME_US_DEFAULT);
    reg_set_double(g, REG_GAIN_DB, 0.0);
    reg_set_double(g, REG_TEMPERATURE_C, p->temperature_c);
    reg_set_string(g, REG_FIRMWARE, g->firmware, GVBS_STRING_SIZE);
    arv_fake_camera_write_register(g->fake, REG_EXPOSURE_AUTO, 2);   // automatics on, as a real camera starts
    arv_fake_camera_write_register(g->fake, REG_GAIN_AUTO, 2);
    arv_fake_camera_write_register(g->fake, REG_BALANCE_WHITE_AUTO, 2);
    arv_fake_camera_write_register(g->fake, REG_CONTRAST_AUTO, 2);
    arv_fake_camera_write_register(g->fake, REG_GAMMA_ENABLE, 1);
    arv_fake_camera_write_register(g->fake, REG_LUT_ENABLE, 1);
    reg_set_double(g, REG_GAMMA, GAMMA_DEFAULT);
    reg_set_double(g, REG_BLACK_LEVEL, 0.0);
    arv_fake_camera_write_register(g->fake, GVBS_SCPD0, 0);
    // In-process, the stream thread looks for a queued buffer at this rate;
    // over GigE Vision the GV thread's trigger check is not used (see the top).
    arv_fake_camera_set_trigger_frequency(g->fake, p->inprocess ? p->trigger_poll_hz : GV_TICK_HZ);
#if ARAVIS_CHECK_VERSION(0, 9, 1)
    arv_fake_camera_set_fill_pattern(g->fake, fill_cb, g, NULL);
#else
    arv_fake_camera_set_fill_pattern(g->fake, fill_cb, g);
#endif
    g->thread = g_thread_try_new("refl-gvcam-render", render_thread, g, &gerr);
    if (!g->thread) {
        rc = rig_fail(RIG_ERR_IO, "gv camera %s: cannot start its render thread: %s", serial, gerr->message);
        g_error_free(gerr);
        goto done;
    }
    if (p->inprocess && (rc = registry_add(g))) {
        rig_fail(rc, "gv camera %s: %s", serial, rc == RIG_ERR_BUSY ? "another in-process camera of this process "
                 "took the serial meanwhile" : "too many in-process cameras (16) in this process");
        goto done;
    }
    *out = g;
    g = NULL;
done:
    if (xml_path) {
        unlink(xml_path);
        g_free(xml_path);
    }
    g_free(xml);
    rig_gv_camera_stop(g);
    if (lock_fd >= 0) close(lock_fd);   // releases the lock
    return rc;
}

void rig_gv_camera_stop(rig_gv_camera_t *g)
{
    if (!g) return;
    if (g->dev) registry_remove(g);   // no new in-process opens; clients see it gone
    if (g->thread) {
        atomic_store(&g->stop, true);
        g_mutex_lock(&g->lock);
        g_cond_broadcast(&g->cond);
        g_mutex_unlock(&g->lock);
        g_thread_join(g->thread);
    }
    if (g->gv) g_object_unref(g->gv);   // joins Aravis's thread, closes the sockets
    if (g->dev) {
        // Clients may hold the device longer: no more calls into g (taking the
        // fill mutex waits for a fill in progress, released by stop).
        atomic_store(&g->stop, true);
        g_mutex_lock(&g->lock);
        g_cond_broadcast(&g->cond);
        g_mutex_unlock(&g->lock);
#if ARAVIS_CHECK_VERSION(0, 9, 1)
        arv_fake_camera_set_fill_pattern(g->fake, fill_gone, NULL, NULL);
#else
        arv_fake_camera_set_fill_pattern(g->fake, fill_gone, NULL);
#endif
        g_object_unref(g->dev);
    }
    g_mutex_clear(&g->lock);
    g_mutex_clear(&g->render_lock);
    g_cond_clear(&g->cond);
    if (g->gvsp_fd >= 0) close(g->gvsp_fd);
    free(g->front);
    free(g->back);
    free(g->pix);
    if (g->lock_fd >= 0) close(g->lock_fd);   // after the sockets are closed: the next server may start
    free(g);
}

void rig_gv_camera_set_temperature(rig_gv_camera_t *g, double temperature_c)
{
    if (g && isfinite(temperature_c)) reg_set_double(g, REG_TEMPERATURE_C, temperature_c);
}

void rig_gv_camera_drop_triggers(rig_gv_camera_t *g, int n)
{
    if (!g) return;
    g_mutex_lock(&g->lock);
    g->drop_triggers = n > 0 ? n : 0;
    g_mutex_unlock(&g->lock);
}

void rig_gv_camera_stats(rig_gv_camera_t *g, rig_gv_camera_stats_t *out)
{
    if (!out) return;
    memset(out, 0, sizeof *out);
    if (!g) return;
    g_mutex_lock(&g->lock);
    *out = g->stats;
    g_mutex_unlock(&g->lock);
}

void rig_gv_camera_last_render_error(rig_gv_camera_t *g, char *buf, size_t size)
{
    if (!buf || !size) return;
    buf[0] = 0;
    if (!g) return;
    g_mutex_lock(&g->lock);
    snprintf(buf, size, "%s", g->render_error);
    g_mutex_unlock(&g->lock);
}
