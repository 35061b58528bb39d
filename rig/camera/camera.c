// rig/camera/camera.c — the camera wrappers over rig_camera_ops_t (the Aravis
// backend: rig/camera/aravis.c).
#include <stdlib.h>

#include "rig/internal.h"

// ---------------------------------------------------------------------------
// Wrappers

void rig_frame_free(rig_frame_t *f)
{
    if (!f) return;
    free(f->pix);
    f->pix = NULL;
}

static int check_cam(rig_camera_t *c, const char *what)
{
    if (!c || !c->ops) return rig_fail(RIG_ERR_INVALID, "camera %s: no camera (NULL)", what);
    return 0;
}

#define CAMERA_OP(c, op, what, ...)                                                          \
    do {                                                                                     \
        int rc_ = check_cam(c, what);                                                        \
        if (rc_) return rc_;                                                                 \
        if (!(c)->ops->op)                                                                   \
            return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: %s is not supported by the %s backend", \
                            (c)->name, what, (c)->ops->backend);                             \
        return (c)->ops->op(__VA_ARGS__);                                                    \
    } while (0)

int rig_camera_set_pixel_format(rig_camera_t *c, const char *format)
{
    if (!format) return rig_fail(RIG_ERR_INVALID, "%s: no pixel format given", c ? c->name : "camera");
    CAMERA_OP(c, set_pixel_format, "setting the pixel format", c, format);
}

int rig_camera_set_exposure_us(rig_camera_t *c, double exposure_us)
{
    CAMERA_OP(c, set_exposure_us, "setting the exposure", c, exposure_us);
}

int rig_camera_set_gain(rig_camera_t *c, double gain)
{
    CAMERA_OP(c, set_gain, "setting the gain", c, gain);
}

int rig_camera_set_region(rig_camera_t *c, int x, int y, int width, int height)
{
    CAMERA_OP(c, set_region, "setting the region", c, x, y, width, height);
}

int rig_camera_set_stream_packets(rig_camera_t *c, long packet_size, long packet_delay)
{
    if (packet_size < -1 || packet_delay < -1)
        return rig_fail(RIG_ERR_INVALID, "%s: packet size %ld / delay %ld: give -1 to leave one unchanged",
                        c ? c->name : "camera", packet_size, packet_delay);
    if (packet_size < 0 && packet_delay < 0) return check_cam(c, "setting the stream packets");
    CAMERA_OP(c, set_stream_packets, "setting the stream packets", c, packet_size, packet_delay);
}

int rig_camera_settings(rig_camera_t *c, rig_frame_meta_t *out)
{
    if (!out) return rig_fail(RIG_ERR_INVALID, "%s: NULL settings output", c ? c->name : "camera");
    CAMERA_OP(c, settings, "reading the settings", c, out);
}

int rig_camera_capture(rig_camera_t *c, double timeout_s, int retries, rig_frame_t *out)
{
    if (!out) return rig_fail(RIG_ERR_INVALID, "%s: NULL frame output", c ? c->name : "camera");
    out->pix = NULL;
    CAMERA_OP(c, capture, "capturing", c, timeout_s, retries, out);
}

void rig_camera_close(rig_camera_t *c)
{
    if (!c) return;
    if (c->ops && c->ops->close) c->ops->close(c);
    free(c);
}

const char *rig_camera_name(const rig_camera_t *c) { return c ? c->name : ""; }
const char *rig_camera_backend(const rig_camera_t *c) { return c && c->ops ? c->ops->backend : ""; }
