// rig/virtual/gv_render.c — the virtual camera's frames: the settings of a frame
// read from its registers, the render callback, the tone curve and the packing to
// the wire format, the render thread that watches the trigger, and Aravis's fill
// callback (free running, in-process).
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rig/camera/pixfmt.h"
#include "rig/virtual/internal.h"

// ---------------------------------------------------------------------------
// Registers

guint32 rig_gv_reg_get(rig_gv_camera_t *g, guint32 addr)
{
    guint32 v = 0;
    arv_fake_camera_read_register(g->fake, addr, &v);
    return v;
}

double rig_gv_reg_get_double(rig_gv_camera_t *g, guint32 addr)
{
    guint64 be = 0;
    arv_fake_camera_read_memory(g->fake, addr, sizeof be, &be);
    guint64 u = GUINT64_FROM_BE(be);
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}

void rig_gv_reg_set_double(rig_gv_camera_t *g, guint32 addr, double d)
{
    guint64 u;
    memcpy(&u, &d, sizeof u);
    guint64 be = GUINT64_TO_BE(u);
    arv_fake_camera_write_memory(g->fake, addr, sizeof be, &be);
}

void rig_gv_reg_set_string(rig_gv_camera_t *g, guint32 addr, const char *s, size_t size)
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
    guint32 pf = rig_gv_reg_get(g, ARV_FAKE_CAMERA_REGISTER_PIXEL_FORMAT);
    m->width = (int)rig_gv_reg_get(g, ARV_FAKE_CAMERA_REGISTER_WIDTH);
    m->height = (int)rig_gv_reg_get(g, ARV_FAKE_CAMERA_REGISTER_HEIGHT);
    m->offset_x = (int)rig_gv_reg_get(g, ARV_FAKE_CAMERA_REGISTER_X_OFFSET);
    m->offset_y = (int)rig_gv_reg_get(g, ARV_FAKE_CAMERA_REGISTER_Y_OFFSET);
    rig_pixfmt_t fmt;
    if (rig_pixfmt_from_pfnc(pf, &fmt)) {
        m->bits = rig_pixfmt_bits(fmt);
        snprintf(m->pixel_format, sizeof m->pixel_format, "%s", rig_pixfmt_name(fmt));
    }
    m->exposure_us = rig_gv_reg_get_double(g, REG_EXPOSURE_US);
    m->gain = rig_gv_reg_get_double(g, REG_GAIN_DB);
    m->temperature_c = rig_gv_reg_get_double(g, REG_TEMPERATURE_C);
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
    if (rig_gv_reg_get(g, REG_EXPOSURE_AUTO) != 0) m->exposure_us = fmin(m->exposure_us * AUTO_EXPOSURE_FACTOR, EXPOSURE_MAX_US);
    if (rig_gv_reg_get(g, REG_GAIN_AUTO) != GAIN_AUTO_OFF) m->gain = fmin(m->gain + AUTO_GAIN_DB, GAIN_MAX_DB);
    m->gamma = rig_gv_reg_get(g, REG_GAMMA_ENABLE) ? rig_gv_reg_get_double(g, REG_GAMMA) : 1.0;
    m->black_level = rig_gv_reg_get_double(g, REG_BLACK_LEVEL);
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
    bool lut = rig_gv_reg_get(g, REG_LUT_ENABLE) != 0 || rig_gv_reg_get(g, REG_CONTRAST_AUTO) != 0;
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

// A frame that could not be made: counted, kept for
// rig_gv_camera_last_render_error and told as a warning (the client only sees
// no frame come).
static void note_render_error(rig_gv_camera_t *g, const char *msg)
{
    g_mutex_lock(&g->lock);
    g->stats.render_errors++;
    snprintf(g->render_error, sizeof g->render_error, "%s", msg);
    g_mutex_unlock(&g->lock);
    model_warning("virtual camera %s: no frame: %s", g->serial, msg);
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
guint16 rig_gv_next_block_id(rig_gv_camera_t *g)
{
    g->block_id = (guint16)(g->block_id == 65535 ? 1 : g->block_id + 1);
    return g->block_id;
}

void rig_gv_fill_cb(ArvBuffer *buffer, void *data, guint32 exposure_us_int, guint32 gain_raw, ArvPixelFormat pf)
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
    arv_buffer_set_frame_id(buffer, rig_gv_next_block_id(g));   // the GV thread sends it with this id
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
    bool quiet = model_error_quiet_thread(true);   // Aravis's thread: the error is noted below
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
    model_error_quiet_thread(quiet);
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

gpointer rig_gv_render_thread(gpointer data)
{
    rig_gv_camera_t *g = data;
    model_error_quiet_thread(true);   // a render's error is noted (note_render_error), not printed
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
        if (!acquiring && rig_gv_reg_get(g, REG_TRIGGER) != 0)   // as a real camera: no acquisition, no frame
            arv_fake_camera_write_register(g->fake, REG_TRIGGER, 0);

        if (acquiring && triggered && !ready && rig_gv_reg_get(g, REG_TRIGGER) != 0) {
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
            if (!drop && render_publish(g, &m, &pf) && !g->p.inprocess) rig_gv_send_front(g, &m, pf);
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
