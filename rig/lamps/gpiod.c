// rig/lamps/gpiod.c — the libgpiod v1 lamp backend (the wrappers and the
// safety net are in rig/lamps/lamps.c).
//
// Polarity: lines are requested active-high (no GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW)
// and this file inverts active-low lamps itself: the physical level of a lamp
// is (on != active_low). That keeps lamps of both polarities on one chip in one
// bulk request, and the off levels used by the signal handler are plain
// precomputed physical values.
//
// Lamps on one chip are requested together (one bulk request per chip) and
// switched together; lamps on different chips are switched chip by chip.
#define _GNU_SOURCE
#include <errno.h>
#include <gpiod.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/internal.h"

#define LAMPS_MAX RIG_LAMPS_MAX

_Static_assert(GPIOD_LINE_BULK_MAX_LINES >= LAMPS_MAX, "one bulk holds every lamp of a chip");

// ---------------------------------------------------------------------------
// gpiod backend (libgpiod v1)

typedef struct {
    struct gpiod_chip     *chip;
    struct gpiod_line_bulk bulk;                // the chip's lamp lines, requested together
    int                    nlamps;
    int                    lamp[LAMPS_MAX];      // lamp index of each line of the bulk
    int                    off_level[LAMPS_MAX]; // physical level that means "off"
    bool                   requested;
} gpiod_group_t;

typedef struct {
    int           ngroups;
    gpiod_group_t group[LAMPS_MAX];             // one per distinct chip string
} gpiod_impl_t;

static int phys_level(const rig_lamp_line_t *a, bool on) { return on != a->active_low; }

// Async-signal-safe: one set-values call per chip on already-requested lines.
static void gpiod_emergency_off(rig_lamps_t *l)
{
    gpiod_impl_t *g = l->impl;
    if (!g) return;
    int saved_errno = errno;
    for (int k = 0; k < g->ngroups; k++)
        if (g->group[k].requested) gpiod_line_set_value_bulk(&g->group[k].bulk, g->group[k].off_level);
    l->on_mask = 0;
    errno = saved_errno;
}

static int gpiod_set(rig_lamps_t *l, uint32_t on_mask)
{
    gpiod_impl_t *g = l->impl;
    for (int k = 0; k < g->ngroups; k++) {
        gpiod_group_t *grp = &g->group[k];
        int vals[LAMPS_MAX];
        for (int j = 0; j < grp->nlamps; j++) {
            int i = grp->lamp[j];
            vals[j] = phys_level(&l->lamps[i], (on_mask >> i) & 1);
        }
        if (gpiod_line_set_value_bulk(&grp->bulk, vals) < 0) {
            int e = errno;
            const rig_lamp_line_t *a = &l->lamps[grp->lamp[0]];
            return rig_fail(e == ENODEV ? RIG_ERR_DISCONNECTED : RIG_ERR_IO,
                            "gpiod lamps: cannot switch lamp '%s'%s on GPIO chip '%s': %s; "
                            "every lamp is switched off; check the board and its connection",
                            a->name, grp->nlamps > 1 ? " and the others" : "", a->chip, strerror(e));
        }
    }
    return RIG_ERR_OK;
}

static void gpiod_close(rig_lamps_t *l)
{
    gpiod_impl_t *g = l->impl;
    if (!g) return;
    for (int k = 0; k < g->ngroups; k++) {
        gpiod_group_t *grp = &g->group[k];
        if (grp->requested) {
            gpiod_line_set_value_bulk(&grp->bulk, grp->off_level);
            gpiod_line_release_bulk(&grp->bulk);
            grp->requested = false;
        }
        if (grp->chip) gpiod_chip_close(grp->chip);
        grp->chip = NULL;
    }
    l->on_mask = 0;
    l->impl = NULL;
    free(g);
}

static const rig_lamps_ops_t gpiod_ops = {
    .backend = "gpiod",
    .set = gpiod_set,
    .close = gpiod_close,
    .emergency_off = gpiod_emergency_off,
};

// "lamp 'key'" or "lamp 'key' (and 2 more lamps on that chip)"
static const char *group_who(const rig_lamps_t *l, const gpiod_group_t *grp, char *buf, size_t len)
{
    if (grp->nlamps > 1)
        snprintf(buf, len, "lamp '%s' (and %d more on that chip)", l->lamps[grp->lamp[0]].name,
                 grp->nlamps - 1);
    else
        snprintf(buf, len, "lamp '%s'", l->lamps[grp->lamp[0]].name);
    return buf;
}

static int chip_open_error(const rig_lamps_t *l, const gpiod_group_t *grp, int e)
{
    char who[128];
    const char *chip = l->lamps[grp->lamp[0]].chip;
    group_who(l, grp, who, sizeof who);
    switch (e) {
    case ENOENT:
        return rig_fail(RIG_ERR_NO_DEVICE, "gpiod lamps: %s: no GPIO chip '%s'; is the board connected? "
                        "ls /dev/gpiochip* (or gpiodetect) lists the chips present", who, chip);
    case ENOTTY:
    case ENODEV:
        return rig_fail(RIG_ERR_NO_DEVICE, "gpiod lamps: %s: '%s' is not a GPIO chip (%s); give a chip "
                        "name such as gpiochip0 or a path /dev/gpiochipN (gpiodetect lists them)",
                        who, chip, strerror(e));
    case EACCES:
    case EPERM:
        return rig_fail(RIG_ERR_ACCESS, "gpiod lamps: %s: permission denied opening GPIO chip '%s'; "
                        "add your user to the group owning it (ls -l /dev/gpiochip*; e.g. sudo usermod "
                        "-aG gpio $USER, then log in again) or install a udev rule giving that group "
                        "access", who, chip);
    case ENOMEM:
        return rig_fail(RIG_ERR_NO_MEM, "gpiod lamps: %s: out of memory opening GPIO chip '%s'", who, chip);
    default:
        return rig_fail(RIG_ERR_IO, "gpiod lamps: %s: cannot open GPIO chip '%s': %s", who, chip,
                        strerror(e));
    }
}

static int request_error(const rig_lamps_t *l, gpiod_group_t *grp, int e)
{
    char who[128];
    const char *chip = l->lamps[grp->lamp[0]].chip;
    group_who(l, grp, who, sizeof who);
    if (e == EBUSY) {
        // Find the line another consumer holds; its consumer label names it.
        for (int j = 0; j < grp->nlamps; j++) {
            struct gpiod_line *line = grp->bulk.lines[j];
            const rig_lamp_line_t *a = &l->lamps[grp->lamp[j]];
            if (gpiod_line_update(line) < 0 || !gpiod_line_is_used(line)) continue;
            const char *consumer = gpiod_line_consumer(line);
            bool ours = consumer && !strcmp(consumer, "refl");
            return rig_fail(RIG_ERR_BUSY, "gpiod lamps: lamp '%s' (GPIO chip '%s' line %u) is busy: "
                            "held by %s%s%s; %s (gpioinfo %s shows who holds each line)",
                            a->name, chip, a->line, consumer && *consumer ? "'" : "",
                            consumer && *consumer ? consumer : "another user (no consumer name)",
                            consumer && *consumer ? "'" : "",
                            ours ? "another refl is running, or two lamps name the same line by "
                                   "different chip names"
                                 : "stop that program or move the lamp to a free line",
                            chip);
        }
        return rig_fail(RIG_ERR_BUSY, "gpiod lamps: %s: a line of GPIO chip '%s' is busy (held by "
                        "another user); stop that program or move the lamp (gpioinfo %s)", who, chip, chip);
    }
    if (e == EACCES || e == EPERM)
        return rig_fail(RIG_ERR_ACCESS, "gpiod lamps: %s: permission denied requesting lines of GPIO "
                        "chip '%s' as outputs; add your user to the group owning /dev/gpiochip* or "
                        "install a udev rule", who, chip);
    return rig_fail(e == ENOMEM ? RIG_ERR_NO_MEM : RIG_ERR_IO, "gpiod lamps: %s: cannot request the "
                    "lines of GPIO chip '%s' as outputs: %s", who, chip, strerror(e));
}

static int gpiod_group_open(rig_lamps_t *l, gpiod_group_t *grp)
{
    const char *chip = l->lamps[grp->lamp[0]].chip;
    errno = 0;
    // A path opens that device node; anything else is a chip name (gpiochip0).
    grp->chip = strchr(chip, '/') ? gpiod_chip_open(chip) : gpiod_chip_open_by_name(chip);
    if (!grp->chip) return chip_open_error(l, grp, errno ? errno : ENOENT);

    unsigned nlines = gpiod_chip_num_lines(grp->chip);
    gpiod_line_bulk_init(&grp->bulk);
    for (int j = 0; j < grp->nlamps; j++) {
        const rig_lamp_line_t *a = &l->lamps[grp->lamp[j]];
        errno = 0;
        struct gpiod_line *line = gpiod_chip_get_line(grp->chip, a->line);
        if (!line) {
            int e = errno;
            if (e == EINVAL || a->line >= nlines) {
                if (nlines == 0)
                    return rig_fail(RIG_ERR_INVALID, "gpiod lamps: lamp '%s': GPIO chip '%s' has no "
                                    "lines; check the lamp's chip", a->name, chip);
                return rig_fail(RIG_ERR_INVALID, "gpiod lamps: lamp '%s': line %u is out of range on "
                                "GPIO chip '%s', which has %u lines (0..%u); fix the lamp's line "
                                "(gpioinfo %s lists them)", a->name, a->line, chip, nlines,
                                nlines - 1, chip);
            }
            return rig_fail(e == ENOMEM ? RIG_ERR_NO_MEM : RIG_ERR_IO, "gpiod lamps: lamp '%s': cannot "
                            "get line %u of GPIO chip '%s': %s", a->name, a->line, chip, strerror(e));
        }
        gpiod_line_bulk_add(&grp->bulk, line);
        grp->off_level[j] = phys_level(a, false);
    }
    struct gpiod_line_request_config cfg = {
        .consumer = "refl",
        .request_type = GPIOD_LINE_REQUEST_DIRECTION_OUTPUT,
        .flags = 0,        // active-high; active-low lamps are inverted here
    };
    errno = 0;
    if (gpiod_line_request_bulk(&grp->bulk, &cfg, grp->off_level) < 0)
        return request_error(l, grp, errno ? errno : EIO);
    grp->requested = true;
    return RIG_ERR_OK;
}

int rig_lamps_open_gpiod(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n)
{
    return rig_lamps_open_gpiod_state(out, lamps, n, NULL);
}

int rig_lamps_open_gpiod_state(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n, const char *state_file)
{
    rig_lamps_t *l = NULL;
    int err = rig_lamps_new(out, &l, &gpiod_ops, lamps, n);
    if (err) return err;
    gpiod_impl_t *g = calloc(1, sizeof *g);
    if (!g) {
        err = rig_fail(RIG_ERR_NO_MEM, "gpiod lamps: out of memory");
        goto done;
    }
    l->impl = g;

    // Group the lamps by chip; reject a line named twice.
    for (int i = 0; i < n; i++) {
        const rig_lamp_line_t *a = &l->lamps[i];
        if (!memchr(a->chip, 0, sizeof a->chip) || !a->chip[0]) {
            err = rig_fail(RIG_ERR_INVALID, "gpiod lamps: lamp '%s' has no GPIO chip (or a name longer "
                           "than %zu characters); give e.g. gpiochip0", a->name, sizeof a->chip - 1);
            goto done;
        }
        gpiod_group_t *grp = NULL;
        for (int k = 0; k < g->ngroups && !grp; k++)
            if (!strcmp(l->lamps[g->group[k].lamp[0]].chip, a->chip)) grp = &g->group[k];
        if (!grp) grp = &g->group[g->ngroups++];
        for (int j = 0; j < grp->nlamps; j++) {
            const rig_lamp_line_t *b = &l->lamps[grp->lamp[j]];
            if (b->line == a->line) {
                err = rig_fail(RIG_ERR_INVALID, "gpiod lamps: lamps '%s' and '%s' both use line %u of "
                               "GPIO chip '%s'; give each lamp its own line", b->name, a->name,
                               a->line, a->chip);
                goto done;
            }
        }
        grp->lamp[grp->nlamps++] = i;
    }

    for (int k = 0; k < g->ngroups; k++)
        if ((err = gpiod_group_open(l, &g->group[k]))) goto done;

    // Every line is held and off: now the state file (what a dead refl left on
    // is reported and switched off).
    if ((err = rig_lamps_state_open(l, state_file))) goto done;
    if (!rig_lamps_safety_register(l))
        err = rig_fail(RIG_ERR_NO_MEM, "gpiod lamps: more than %d lamp sets open at once; close one "
                       "first", RIG_LAMPS_SAFETY_SLOTS);
done:
    if (err) {
        gpiod_close(l);    // lines already requested: switched off and released
        rig_lamps_state_close(l, false);
        free(l);
        return err;
    }
    *out = l;
    return RIG_ERR_OK;
}
