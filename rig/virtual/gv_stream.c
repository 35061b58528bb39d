// rig/virtual/gv_stream.c — the virtual camera's GVSP sender: a frame as GigE
// Vision stream packets (leader, data, trailer) from the render thread.
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>

#include "rig/virtual/internal.h"

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
    guint32 scps = rig_gv_reg_get(g, GVBS_SCPS0) & 0xffff;
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
void rig_gv_send_front(rig_gv_camera_t *g, const rig_frame_meta_t *m, guint32 pf)
{
    g_mutex_lock(&g->lock);
    if (!g->front_ready) {   // taken meanwhile (free running started)
        g_mutex_unlock(&g->lock);
        return;
    }
    g->front_ready = false;   // only this thread swaps front and back: it stays ours
    guint16 block = rig_gv_next_block_id(g);
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
    if (!ok) model_warning("virtual camera %s: frame %u not sent: %s", g->serial, (unsigned)block, err);
}
