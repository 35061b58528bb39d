// tests/fake_gpiod.c — a fake libgpiod v1 (1.6 API) for LD_PRELOAD: the calls
// rig/lamps/lamps.c makes, and a few neighbours, backed by simulated chips.
//
// Environment
//   FAKE_GPIOCHIP=gpiochip0:32,gpiochip1:8   the chips present (name:lines)
//   FAKE_GPIO_LOG=path          every request/set/release appended, one line each:
//                               "request gpiochip0 5=1 consumer=refl",
//                               "set gpiochip0 5=0", "release gpiochip0 5=1";
//                               the number is the line's PHYSICAL level.
//   FAKE_GPIO_BUSY=3,7          these offsets (on every chip) are held by another
//                               consumer (FAKE_GPIO_BUSY_CONSUMER, default "other-app")
//   FAKE_GPIO_EACCES=1          opening any existing chip fails with EACCES
//   FAKE_GPIO_FAIL_SET=N        the Nth set-values call (from 1) fails with ENODEV
//                               (board unplugged); later calls work again
//
// Errors follow the real library: a missing chip ENOENT; a path that exists but
// is no GPIO chip ENOTTY; an offset out of range EINVAL; a line held elsewhere
// (or already requested) EBUSY; setting a line not requested EPERM.
// Line state is per chip and shared by every handle of the process, like the
// kernel's. Logging uses only open/write/close, so set-values calls stay
// async-signal-safe (the lamps' signal handler calls them).
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <gpiod.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define FAKE_MAX_CHIPS 8
#define FAKE_MAX_LINES 1024

typedef struct {
    bool used;             // requested by anyone (this process or "another")
    char consumer[32];
    int  level;            // physical
} fake_state_t;

typedef struct {
    char          name[32];
    unsigned      nlines;
    fake_state_t *st;
} fake_chip_t;

struct gpiod_line {
    struct gpiod_chip *chip;
    unsigned           offset;
    bool               requested;  // through this handle
    bool               active_low;
    int                direction;
};

struct gpiod_chip {
    fake_chip_t       *fc;
    struct gpiod_line *lines;
};

static fake_chip_t chips[FAKE_MAX_CHIPS];
static int         nchips = -1;
static char        log_path[4096];
static int         fail_set_at, set_calls;

static void fake_init(void)
{
    if (nchips >= 0) return;
    nchips = 0;
    const char *fs = getenv("FAKE_GPIO_FAIL_SET");
    if (fs) fail_set_at = atoi(fs);
    const char *lp = getenv("FAKE_GPIO_LOG");
    if (lp) snprintf(log_path, sizeof log_path, "%s", lp);
    const char *cfg = getenv("FAKE_GPIOCHIP");
    const char *busy = getenv("FAKE_GPIO_BUSY");
    const char *busy_by = getenv("FAKE_GPIO_BUSY_CONSUMER");
    if (!busy_by) busy_by = "other-app";
    while (cfg && *cfg && nchips < FAKE_MAX_CHIPS) {
        fake_chip_t *c = &chips[nchips];
        int used = 0;
        if (sscanf(cfg, "%31[^:,]:%u%n", c->name, &c->nlines, &used) != 2 || c->nlines > FAKE_MAX_LINES) {
            fprintf(stderr, "fake_gpiod: bad FAKE_GPIOCHIP near '%s' (want name:lines,...)\n", cfg);
            break;
        }
        c->st = calloc(c->nlines ? c->nlines : 1, sizeof *c->st);
        for (const char *b = busy; b && *b;) {
            char *end;
            unsigned long off = strtoul(b, &end, 10);
            if (end == b) break;
            if (off < c->nlines) {
                c->st[off].used = true;
                snprintf(c->st[off].consumer, sizeof c->st[off].consumer, "%s", busy_by);
            }
            b = *end == ',' ? end + 1 : end;
        }
        nchips++;
        cfg += used;
        if (*cfg == ',') cfg++;
    }
}

__attribute__((constructor)) static void fake_ctor(void) { fake_init(); }

// ---- async-signal-safe log -------------------------------------------------

static size_t put_str(char *buf, size_t n, size_t cap, const char *s)
{
    while (*s && n + 1 < cap) buf[n++] = *s++;
    return n;
}

static size_t put_uint(char *buf, size_t n, size_t cap, unsigned v)
{
    char tmp[16];
    int k = 0;
    do {
        tmp[k++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (k > 0 && n + 1 < cap) buf[n++] = tmp[--k];
    return n;
}

static void fake_log(const char *op, const struct gpiod_line *line, const char *consumer)
{
    if (!log_path[0]) return;
    const fake_chip_t *fc = line->chip->fc;
    char buf[256];
    size_t n = 0, cap = sizeof buf;
    n = put_str(buf, n, cap, op);
    n = put_str(buf, n, cap, " ");
    n = put_str(buf, n, cap, fc->name);
    n = put_str(buf, n, cap, " ");
    n = put_uint(buf, n, cap, line->offset);
    n = put_str(buf, n, cap, "=");
    n = put_uint(buf, n, cap, (unsigned)fc->st[line->offset].level);
    if (consumer) {
        n = put_str(buf, n, cap, " consumer=");
        n = put_str(buf, n, cap, consumer);
    }
    n = put_str(buf, n, cap, "\n");
    int saved = errno;
    int fd = open(log_path, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
    if (fd >= 0) {
        ssize_t w = write(fd, buf, n);
        (void)w;
        close(fd);
    }
    errno = saved;
}

// ---- chips -----------------------------------------------------------------

static struct gpiod_chip *chip_new(fake_chip_t *fc)
{
    if (getenv("FAKE_GPIO_EACCES") && strcmp(getenv("FAKE_GPIO_EACCES"), "0")) {
        errno = EACCES;
        return NULL;
    }
    struct gpiod_chip *c = calloc(1, sizeof *c);
    if (!c) return NULL;
    c->fc = fc;
    c->lines = calloc(fc->nlines ? fc->nlines : 1, sizeof *c->lines);
    if (!c->lines) {
        free(c);
        errno = ENOMEM;
        return NULL;
    }
    for (unsigned i = 0; i < fc->nlines; i++) {
        c->lines[i].chip = c;
        c->lines[i].offset = i;
    }
    return c;
}

static fake_chip_t *chip_find(const char *name)
{
    fake_init();
    for (int i = 0; i < nchips; i++)
        if (!strcmp(chips[i].name, name)) return &chips[i];
    return NULL;
}

struct gpiod_chip *gpiod_chip_open_by_name(const char *name)
{
    fake_chip_t *fc = name ? chip_find(name) : NULL;
    if (!fc) {
        errno = ENOENT;
        return NULL;
    }
    return chip_new(fc);
}

struct gpiod_chip *gpiod_chip_open(const char *path)
{
    if (!path) {
        errno = EINVAL;
        return NULL;
    }
    if (!strncmp(path, "/dev/", 5)) {
        fake_chip_t *fc = chip_find(path + 5);
        if (fc) return chip_new(fc);
    }
    struct stat sb;
    if (stat(path, &sb) < 0) return NULL;     // errno from stat: ENOENT, EACCES...
    errno = ENOTTY;                           // libgpiod 1.6.3 says so for /dev/null and files too
    return NULL;
}

struct gpiod_chip *gpiod_chip_open_by_number(unsigned num)
{
    char name[32];
    snprintf(name, sizeof name, "gpiochip%u", num);
    return gpiod_chip_open_by_name(name);
}

struct gpiod_chip *gpiod_chip_open_lookup(const char *descr)
{
    if (!descr) {
        errno = EINVAL;
        return NULL;
    }
    if (!strncmp(descr, "/dev/", 5)) return gpiod_chip_open(descr);
    char *end;
    unsigned long num = strtoul(descr, &end, 10);
    if (*descr && !*end) return gpiod_chip_open_by_number((unsigned)num);
    return gpiod_chip_open_by_name(descr);
}

void gpiod_line_release_bulk(struct gpiod_line_bulk *bulk);

void gpiod_chip_close(struct gpiod_chip *chip)
{
    if (!chip) return;
    for (unsigned i = 0; i < chip->fc->nlines; i++) {
        if (chip->lines[i].requested) {
            struct gpiod_line_bulk b;
            gpiod_line_bulk_init(&b);
            gpiod_line_bulk_add(&b, &chip->lines[i]);
            gpiod_line_release_bulk(&b);
        }
    }
    free(chip->lines);
    free(chip);
}

const char *gpiod_chip_name(struct gpiod_chip *chip) { return chip->fc->name; }
const char *gpiod_chip_label(struct gpiod_chip *chip) { return "fake-gpio"; }
unsigned int gpiod_chip_num_lines(struct gpiod_chip *chip) { return chip->fc->nlines; }

struct gpiod_line *gpiod_chip_get_line(struct gpiod_chip *chip, unsigned int offset)
{
    if (offset >= chip->fc->nlines) {
        errno = EINVAL;
        return NULL;
    }
    return &chip->lines[offset];
}

int gpiod_chip_get_lines(struct gpiod_chip *chip, unsigned int *offsets, unsigned int num_offsets,
                         struct gpiod_line_bulk *bulk)
{
    gpiod_line_bulk_init(bulk);
    for (unsigned i = 0; i < num_offsets; i++) {
        struct gpiod_line *line = gpiod_chip_get_line(chip, offsets[i]);
        if (!line) return -1;
        gpiod_line_bulk_add(bulk, line);
    }
    return 0;
}

// ---- lines -----------------------------------------------------------------

unsigned int gpiod_line_offset(struct gpiod_line *line) { return line->offset; }
struct gpiod_chip *gpiod_line_get_chip(struct gpiod_line *line) { return line->chip; }
int gpiod_line_update(struct gpiod_line *line) { return 0; }
bool gpiod_line_is_used(struct gpiod_line *line) { return line->chip->fc->st[line->offset].used; }
bool gpiod_line_is_requested(struct gpiod_line *line) { return line->requested; }
bool gpiod_line_is_free(struct gpiod_line *line) { return !line->requested; }
bool gpiod_line_is_active_low(struct gpiod_line *line) { return line->active_low; }

const char *gpiod_line_consumer(struct gpiod_line *line)
{
    const fake_state_t *s = &line->chip->fc->st[line->offset];
    return s->used && s->consumer[0] ? s->consumer : NULL;
}

int gpiod_line_request_bulk(struct gpiod_line_bulk *bulk, const struct gpiod_line_request_config *config,
                            const int *default_vals)
{
    if (!bulk || !config || bulk->num_lines == 0 || bulk->num_lines > GPIOD_LINE_BULK_MAX_LINES) {
        errno = EINVAL;
        return -1;
    }
    struct gpiod_chip *chip = bulk->lines[0]->chip;
    for (unsigned i = 0; i < bulk->num_lines; i++) {
        struct gpiod_line *line = bulk->lines[i];
        if (line->chip != chip) {
            errno = EINVAL;
            return -1;
        }
        if (line->requested || chip->fc->st[line->offset].used) {
            errno = EBUSY;
            return -1;
        }
    }
    bool out = config->request_type == GPIOD_LINE_REQUEST_DIRECTION_OUTPUT;
    bool al = config->flags & GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW;
    for (unsigned i = 0; i < bulk->num_lines; i++) {
        struct gpiod_line *line = bulk->lines[i];
        fake_state_t *s = &chip->fc->st[line->offset];
        line->requested = true;
        line->active_low = al;
        line->direction = out ? GPIOD_LINE_DIRECTION_OUTPUT : GPIOD_LINE_DIRECTION_INPUT;
        s->used = true;
        snprintf(s->consumer, sizeof s->consumer, "%s", config->consumer ? config->consumer : "");
        if (out) s->level = (default_vals && default_vals[i] ? 1 : 0) != al;
        fake_log("request", line, s->consumer);
    }
    return 0;
}

int gpiod_line_request(struct gpiod_line *line, const struct gpiod_line_request_config *config,
                       int default_val)
{
    struct gpiod_line_bulk b;
    gpiod_line_bulk_init(&b);
    gpiod_line_bulk_add(&b, line);
    return gpiod_line_request_bulk(&b, config, &default_val);
}

int gpiod_line_request_bulk_output_flags(struct gpiod_line_bulk *bulk, const char *consumer, int flags,
                                         const int *default_vals)
{
    struct gpiod_line_request_config cfg = { consumer, GPIOD_LINE_REQUEST_DIRECTION_OUTPUT, flags };
    return gpiod_line_request_bulk(bulk, &cfg, default_vals);
}

int gpiod_line_request_bulk_output(struct gpiod_line_bulk *bulk, const char *consumer,
                                   const int *default_vals)
{
    return gpiod_line_request_bulk_output_flags(bulk, consumer, 0, default_vals);
}

int gpiod_line_request_output(struct gpiod_line *line, const char *consumer, int default_val)
{
    struct gpiod_line_request_config cfg = { consumer, GPIOD_LINE_REQUEST_DIRECTION_OUTPUT, 0 };
    return gpiod_line_request(line, &cfg, default_val);
}

void gpiod_line_release_bulk(struct gpiod_line_bulk *bulk)
{
    for (unsigned i = 0; bulk && i < bulk->num_lines; i++) {
        struct gpiod_line *line = bulk->lines[i];
        if (!line->requested) continue;
        fake_state_t *s = &line->chip->fc->st[line->offset];
        fake_log("release", line, NULL);
        line->requested = false;
        s->used = false;
        s->consumer[0] = 0;
    }
}

void gpiod_line_release(struct gpiod_line *line)
{
    struct gpiod_line_bulk b;
    gpiod_line_bulk_init(&b);
    gpiod_line_bulk_add(&b, line);
    gpiod_line_release_bulk(&b);
}

int gpiod_line_set_value_bulk(struct gpiod_line_bulk *bulk, const int *values)
{
    if (!bulk || bulk->num_lines == 0) {
        errno = EINVAL;
        return -1;
    }
    for (unsigned i = 0; i < bulk->num_lines; i++) {
        const struct gpiod_line *line = bulk->lines[i];
        if (!line->requested || line->direction != GPIOD_LINE_DIRECTION_OUTPUT ||
            line->chip != bulk->lines[0]->chip) {
            errno = EPERM;
            return -1;
        }
    }
    if (++set_calls == fail_set_at) {
        errno = ENODEV;
        return -1;
    }
    for (unsigned i = 0; i < bulk->num_lines; i++) {
        struct gpiod_line *line = bulk->lines[i];
        line->chip->fc->st[line->offset].level = (values && values[i] ? 1 : 0) != line->active_low;
        fake_log("set", line, NULL);
    }
    return 0;
}

int gpiod_line_set_value(struct gpiod_line *line, int value)
{
    struct gpiod_line_bulk b;
    gpiod_line_bulk_init(&b);
    gpiod_line_bulk_add(&b, line);
    return gpiod_line_set_value_bulk(&b, &value);
}

int gpiod_line_get_value_bulk(struct gpiod_line_bulk *bulk, int *values)
{
    for (unsigned i = 0; i < bulk->num_lines; i++) {
        struct gpiod_line *line = bulk->lines[i];
        if (!line->requested) {
            errno = EPERM;
            return -1;
        }
        values[i] = line->chip->fc->st[line->offset].level != line->active_low;
    }
    return 0;
}

int gpiod_line_get_value(struct gpiod_line *line)
{
    struct gpiod_line_bulk b;
    int v = 0;
    gpiod_line_bulk_init(&b);
    gpiod_line_bulk_add(&b, line);
    return gpiod_line_get_value_bulk(&b, &v) < 0 ? -1 : v;
}

const char *gpiod_version_string(void) { return "1.6-fake"; }
