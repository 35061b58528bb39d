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
// each frame waits up to a period. So its tick is GV_TICK_HZ (it only answers
// GVCP and free running), and a triggered frame leaves as soon as it is made.
// Block ids (16-bit, 0 invalid) are ours for every frame (fill_cb sets them on
// Aravis's free-running frames too), so a client sees one increasing sequence;
// they start at 65400, so clients meet the 16-bit wrap within their first frames.
// In-process (ArvFakeDevice): the client's ArvFakeStream thread calls fill_cb,
//   which waits for the render thread's frame (fill_inprocess).
// `lock` guards front/stats; `render_lock` serialises calls of the render
// callback (the GV thread renders itself only when no frame is ready).
// Registers live in the fake camera's memory: the GV thread writes them on
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/socket.h>
#include <unistd.h>

#include "rig/virtual/internal.h"

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

// The parameters with their defaults, and where the server serves.
typedef struct {
    const char    *address, *serial, *vendor, *model, *firmware, *gain_unit, *refuse_off;
    struct in_addr ia;
} names_t;

// p's parameters checked, their defaults filled in *n.
static int check_params(const rig_gv_camera_params_t *p, names_t *n)
{
    rig_gv_camera_params_t d = rig_gv_camera_defaults();
    *n = (names_t){ p->address ? p->address : d.address, p->serial ? p->serial : d.serial,
                    p->vendor ? p->vendor : d.vendor, p->model ? p->model : d.model,
                    p->firmware ? p->firmware : "refl-gv 1.0", p->gain_unit ? p->gain_unit : "dB",
                    p->refuse_off ? p->refuse_off : "", { 0 } };
    const char *serial = n->serial;
    if (!p->render) return rig_fail(RIG_ERR_INVALID, "gv camera: no render callback given");
    if (!p->inprocess && (inet_pton(AF_INET, n->address, &n->ia) != 1 || (ntohl(n->ia.s_addr) >> 24) != 127))
        return rig_fail(RIG_ERR_INVALID, "gv camera: address '%s' is not a loopback IPv4 address (127.x.y.z); "
                        "the virtual camera only serves on loopback", n->address);
    if (!*serial || strlen(serial) >= 16)
        return rig_fail(RIG_ERR_INVALID, "gv camera: serial '%s' must have 1 to 15 characters", serial);
    if (strlen(n->vendor) >= GVBS_STRING_SIZE || strlen(n->model) >= GVBS_STRING_SIZE)
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: vendor and model must be shorter than %d characters",
                        serial, GVBS_STRING_SIZE);
    if (strlen(n->firmware) >= GVBS_STRING_SIZE || strlen(n->gain_unit) >= 16)
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: firmware must be shorter than %d characters, the gain "
                        "unit than 16", serial, GVBS_STRING_SIZE);
    if (*n->refuse_off && strcmp(n->refuse_off, "ExposureAuto") && strcmp(n->refuse_off, "GainAuto") &&
        strcmp(n->refuse_off, "BalanceWhiteAuto"))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: refuse_off '%s' is not ExposureAuto, GainAuto or "
                        "BalanceWhiteAuto", serial, n->refuse_off);
    if (p->sensor_width < 1 || p->sensor_width > 4096 || p->sensor_height < 1 || p->sensor_height > 4096)
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: sensor size %dx%d outside 1..4096", serial,
                        p->sensor_width, p->sensor_height);
    if (!(p->trigger_poll_hz > 0 && p->trigger_poll_hz <= 100000))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: trigger_poll_hz %g outside (0, 100000]", serial,
                        p->trigger_poll_hz);
    if (!isfinite(p->temperature_c))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: temperature is not finite", serial);
    if (!(p->busy_wait_s >= 0 && p->busy_wait_s <= 3600))
        return rig_fail(RIG_ERR_INVALID, "gv camera %s: busy_wait_s %g outside 0..3600", serial, p->busy_wait_s);
    if (p->inprocess) {
        g_mutex_lock(&registry_lock);
        bool taken = registry_find(serial) != NULL;
        g_mutex_unlock(&registry_lock);
        if (taken)
            return rig_fail(RIG_ERR_BUSY, "gv camera %s: this process already serves an in-process camera with "
                            "serial %s; stop it first or give this one another serial", serial, serial);
    }
    return 0;
}

// Take turns with other refl servers on the address (its lock file, held in
// *lock_fd while serving), and find its GVCP port free.
static int take_address(const names_t *n, double busy_wait_s, int *lock_fd)
{
    char lock_path[512];
    snprintf(lock_path, sizeof lock_path, "%s/refl-gvcam-%s.lock", g_get_tmp_dir(), n->address);
    *lock_fd = open(lock_path, O_RDONLY | O_CREAT | O_CLOEXEC, 0666);
    if (*lock_fd < 0)
        return rig_fail(RIG_ERR_IO, "gv camera %s: cannot open %s: %s", n->serial, lock_path, strerror(errno));
    for (double waited = 0;; waited += 0.05) {
        if (flock(*lock_fd, LOCK_EX | LOCK_NB) == 0) break;
        if (errno != EWOULDBLOCK || waited >= busy_wait_s)
            return rig_fail(RIG_ERR_BUSY, "gv camera %s: another refl virtual camera serves on %s (lock %s%s); "
                            "stop it first", n->serial, n->address, lock_path, busy_wait_s > 0 ? ", waited" : "");
        g_usleep(50000);
    }
    int err_no = 0, rc = probe_port(n->address, &err_no);
    if (rc == RIG_ERR_BUSY)
        rig_fail(rc, "gv camera %s: %s:%d is already in use (another GigE Vision program?); stop it first",
                 n->serial, n->address, GVCP_PORT);
    else if (rc < 0)
        rig_fail(rc, "gv camera %s: cannot bind %s:%d: %s", n->serial, n->address, GVCP_PORT, strerror(err_no));
    return rc;
}

// Our GenICam XML in a temporary file (*xml_path: its name, for the caller to
// unlink and g_free).
static int write_xml(const names_t *n, char **xml_path)
{
    char *xml = rig_gv_xml_make(n->gain_unit, n->refuse_off);
    if (!xml) return RIG_ERR_IO;
    GError *gerr = NULL;
    int rc = 0, fd = g_file_open_tmp("refl-gvcam-XXXXXX.xml", xml_path, &gerr);
    if (fd < 0) {
        rc = rig_fail(RIG_ERR_IO, "gv camera %s: cannot write its GenICam XML: %s", n->serial, gerr->message);
        g_error_free(gerr);
    } else {
        close(fd);
        if (!g_file_set_contents(*xml_path, xml, -1, &gerr)) {
            rc = rig_fail(RIG_ERR_IO, "gv camera %s: cannot write %s: %s", n->serial, *xml_path, gerr->message);
            g_error_free(gerr);
        }
    }
    g_free(xml);
    return rc;
}

// A server of these parameters that serves nothing yet. NULL: out of memory.
static rig_gv_camera_t *new_server(const rig_gv_camera_params_t *p, const names_t *n)
{
    rig_gv_camera_t *g = calloc(1, sizeof *g);
    if (!g) return NULL;
    g->p = *p;
    g->gvsp_fd = -1;
    g->lock_fd = -1;
    g->block_id = 65399;   // the first frame is 65400, as Aravis's fake camera's: clients meet the wrap early
    snprintf(g->address, sizeof g->address, "%s%s", p->inprocess ? RIG_GV_INPROCESS_PREFIX : "",
             p->inprocess ? n->serial : n->address);
    snprintf(g->serial, sizeof g->serial, "%s", n->serial);
    snprintf(g->vendor, sizeof g->vendor, "%s", n->vendor);
    snprintf(g->model, sizeof g->model, "%s", n->model);
    snprintf(g->firmware, sizeof g->firmware, "%s", n->firmware);
    snprintf(g->gain_unit, sizeof g->gain_unit, "%s", n->gain_unit);
    snprintf(g->refuse_off, sizeof g->refuse_off, "%s", n->refuse_off);
    g->p.address = g->address;
    g->p.serial = g->serial;
    g->p.vendor = g->vendor;
    g->p.model = g->model;
    g_mutex_init(&g->lock);
    g_mutex_init(&g->render_lock);
    g_cond_init(&g->cond);
    return g;
}

// The fake camera with our XML: an in-process ArvFakeDevice, or Aravis's
// GigE Vision server on the address (its port then taken) and our GVSP socket.
static int serve(rig_gv_camera_t *g, const names_t *n, const char *xml_path)
{
    if (g->p.inprocess) {
        char msg[512];
        if (!(g->dev = rig_gv_xml_fake_device(n->serial, xml_path, msg, sizeof msg)))
            return rig_fail(RIG_ERR_IO, "gv camera %s: Aravis could not make an in-process fake device: %s",
                            n->serial, msg);
        g->fake = arv_fake_device_get_fake_camera(ARV_FAKE_DEVICE(g->dev));
        return 0;
    }
    g->gv = arv_gv_fake_camera_new_full(n->address, n->serial, xml_path);   // reads the XML file now
    if (!g->gv || !arv_gv_fake_camera_is_running(g->gv))
        return rig_fail(RIG_ERR_IO, "gv camera %s: Aravis could not start a GigE Vision server on %s "
                        "(no network interface with that address?)", n->serial, n->address);
    // Aravis reports running even when its bind failed: check the port is now taken.
    int err_no = 0;
    if (probe_port(n->address, &err_no) != RIG_ERR_BUSY)
        return rig_fail(RIG_ERR_BUSY, "gv camera %s: Aravis did not get %s:%d (taken meanwhile?)", n->serial,
                        n->address, GVCP_PORT);
    g->fake = arv_gv_fake_camera_get_fake_camera(g->gv);
    return open_gvsp_socket(g, &n->ia);
}

// The registers as a camera starts (identity, full sensor, automatics on),
// the trigger check's rate and our fill callback.
static void init_registers(rig_gv_camera_t *g)
{
    const rig_gv_camera_params_t *p = &g->p;
    rig_gv_reg_set_string(g, GVBS_MANUFACTURER_NAME, g->vendor, GVBS_STRING_SIZE);
    rig_gv_reg_set_string(g, GVBS_MODEL_NAME, g->model, GVBS_STRING_SIZE);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_WIDTH, (guint32)p->sensor_width);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_SENSOR_HEIGHT, (guint32)p->sensor_height);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_WIDTH, (guint32)p->sensor_width);
    arv_fake_camera_write_register(g->fake, ARV_FAKE_CAMERA_REGISTER_HEIGHT, (guint32)p->sensor_height);
    arv_fake_camera_write_register(g->fake, REG_TRIGGER, 0);
    arv_fake_camera_write_register(g->fake, GVBS_SCPS0, GVSP_PACKET_SIZE);
    rig_gv_reg_set_double(g, REG_EXPOSURE_US, ARV_FAKE_CAMERA_EXPOSURE_TIME_US_DEFAULT);
    rig_gv_reg_set_double(g, REG_GAIN_DB, 0.0);
    rig_gv_reg_set_double(g, REG_TEMPERATURE_C, p->temperature_c);
    rig_gv_reg_set_string(g, REG_FIRMWARE, g->firmware, GVBS_STRING_SIZE);
    arv_fake_camera_write_register(g->fake, REG_EXPOSURE_AUTO, 2);   // automatics on, as a real camera starts
    arv_fake_camera_write_register(g->fake, REG_GAIN_AUTO, 2);
    arv_fake_camera_write_register(g->fake, REG_BALANCE_WHITE_AUTO, 2);
    arv_fake_camera_write_register(g->fake, REG_CONTRAST_AUTO, 2);
    arv_fake_camera_write_register(g->fake, REG_GAMMA_ENABLE, 1);
    arv_fake_camera_write_register(g->fake, REG_LUT_ENABLE, 1);
    rig_gv_reg_set_double(g, REG_GAMMA, GAMMA_DEFAULT);
    rig_gv_reg_set_double(g, REG_BLACK_LEVEL, 0.0);
    arv_fake_camera_write_register(g->fake, GVBS_SCPD0, 0);
    // In-process, the stream thread looks for a queued buffer at this rate;
    // over GigE Vision the GV thread's trigger check is not used (see the top).
    arv_fake_camera_set_trigger_frequency(g->fake, p->inprocess ? p->trigger_poll_hz : GV_TICK_HZ);
#if ARAVIS_CHECK_VERSION(0, 9, 1)
    arv_fake_camera_set_fill_pattern(g->fake, rig_gv_fill_cb, g, NULL);
#else
    arv_fake_camera_set_fill_pattern(g->fake, rig_gv_fill_cb, g);
#endif
}

// The render thread, and an in-process server's entry in the registry.
static int start_threads(rig_gv_camera_t *g)
{
    GError *gerr = NULL;
    g->thread = g_thread_try_new("refl-gvcam-render", rig_gv_render_thread, g, &gerr);
    if (!g->thread) {
        int rc = rig_fail(RIG_ERR_IO, "gv camera %s: cannot start its render thread: %s", g->serial, gerr->message);
        g_error_free(gerr);
        return rc;
    }
    int rc = g->p.inprocess ? registry_add(g) : 0;
    if (rc)
        rig_fail(rc, "gv camera %s: %s", g->serial, rc == RIG_ERR_BUSY ? "another in-process camera of this "
                 "process took the serial meanwhile" : "too many in-process cameras (16) in this process");
    return rc;
}

int rig_gv_camera_start(rig_gv_camera_t **out, const rig_gv_camera_params_t *p)
{
    if (!out || !p) return rig_fail(RIG_ERR_INVALID, "gv camera: NULL argument");
    *out = NULL;
    names_t n;
    int rc = check_params(p, &n), lock_fd = -1;
    if (rc) return rc;
    char *xml_path = NULL;
    rig_gv_camera_t *g = NULL;
    if (!p->inprocess) rc = take_address(&n, p->busy_wait_s, &lock_fd);   // in-process: no socket, no lock file
    if (!rc) rc = write_xml(&n, &xml_path);
    if (!rc && !(g = new_server(p, &n))) rc = rig_fail(RIG_ERR_NO_MEM, "gv camera %s: out of memory", n.serial);
    if (g) {
        g->lock_fd = lock_fd;   // the server holds the lock now
        lock_fd = -1;
    }
    if (!rc && !(rc = serve(g, &n, xml_path))) {
        init_registers(g);
        rc = start_threads(g);
    }
    if (xml_path) {
        unlink(xml_path);
        g_free(xml_path);
    }
    if (lock_fd >= 0) close(lock_fd);   // releases the lock
    if (rc) {
        rig_gv_camera_stop(g);
        return rc;
    }
    *out = g;
    return 0;
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
    if (g && isfinite(temperature_c)) rig_gv_reg_set_double(g, REG_TEMPERATURE_C, temperature_c);
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
