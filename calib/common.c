// calib/common.c — what every calibration shares: running a capture plan
// into a session, reading a session's frames, provenance, atomic JSON, the
// plotting scripts and the HTML report pages.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <glib.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "calib/calib.h"
#include "model/model.h"

bool calib_mkdir_p(const char *path)
{
    if (g_mkdir_with_parents(path, 0755) != 0) {
        model_error(path, 0, "cannot make the directory: %s", strerror(errno));
        return false;
    }
    return true;
}

static bool write_file_atomic(const char *path, const char *text)
{
    char *tmp = g_strdup_printf("%s.part", path);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    bool ok = fd >= 0;
    size_t len = strlen(text), off = 0;
    while (ok && off < len) {
        ssize_t w = write(fd, text + off, len - off);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) ok = false;
        else off += (size_t)w;
    }
    if (ok && fsync(fd) != 0) ok = false;
    int err = errno;
    if (fd >= 0 && close(fd) != 0 && ok) {
        ok = false;
        err = errno;
    }
    if (ok && rename(tmp, path) != 0) {
        ok = false;
        err = errno;
    }
    if (!ok) {
        unlink(tmp);
        model_error(path, 0, "cannot write: %s", strerror(err));
    }
    g_free(tmp);
    return ok;
}

bool calib_write_json(const char *path, json_t *o)
{
    char *s = json_dumps(o, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(10));
    if (!s) {
        model_error(path, 0, "cannot encode the JSON document (out of memory or a non-finite number)");
        return false;
    }
    size_t n = strlen(s);
    char *t = malloc(n + 2);
    if (!t) {
        free(s);
        model_error(path, 0, "out of memory");
        return false;
    }
    memcpy(t, s, n);
    t[n] = '\n';
    t[n + 1] = 0;
    free(s);
    bool ok = write_file_atomic(path, t);
    free(t);
    return ok;
}

// ---------------------------------------------------------------------------
// Capture

int calib_capture(const char *rig_path, const char *dir, const char *name, const char *plan_text, int progress)
{
    if (!calib_mkdir_p(dir)) return -1;
    char *plan_path = g_strdup_printf("%s/%s.plan.ini", dir, name);
    char *sdir = g_strdup_printf("%s/%s", dir, name);
    char *db = g_strdup_printf("%s/session.sqlite", sdir);
    int rc = -1;
    char sha[65];
    model_sha256_hex(plan_text, strlen(plan_text), sha);
    bool exists = access(db, F_OK) == 0;
    if (exists) {
        // the same plan? then reuse or resume it
        rig_journal_t *j = NULL;
        char *ptext = NULL, *psha = NULL, state[32] = "";
        if (rig_journal_open(&j, sdir)) {
            model_error(sdir, 0, "an earlier session is here but its journal cannot be read (%s); move it away",
                        rig_last_error());
            goto done;
        }
        rig_journal_source(j, "plan", NULL, &ptext, &psha);
        rig_journal_state(j, state, sizeof state);
        rig_journal_close(j);
        bool same = psha && !strcmp(psha, sha);
        free(ptext);
        free(psha);
        if (!same) {
            model_error(sdir, 0, "an earlier session with another plan is here; choose another output directory "
                        "or move it away");
            goto done;
        }
        if (!strcmp(state, "complete")) {
            fprintf(stderr, "refl calib: %s is complete; using its frames\n", sdir);
            rc = 0;
            goto done;
        }
        fprintf(stderr, "refl calib: resuming the %s session %s\n", state, sdir);
    } else if (!write_file_atomic(plan_path, plan_text)) {
        goto done;
    }
    rig_capture_opts_t o = { .plan_path = plan_path, .rig_path = rig_path, .dir = sdir, .resume = exists,
                             .progress = progress, .command_line = "refl calib" };
    int ec = rig_capture_run(&o);
    if (ec == 0) rc = 0;
    else if (ec == 3)
        model_error(sdir, 0, "the capture paused (interrupted, or the camera stopped answering); run the same "
                    "command again to resume it");
    else
        model_error(sdir, 0, "the capture failed: %s", rig_last_error());
done:
    g_free(plan_path);
    g_free(sdir);
    g_free(db);
    return rc;
}

// ---------------------------------------------------------------------------
// Sessions

void calib_session_free(calib_session_t *s)
{
    if (!s) return;
    free(s->dir);
    free(s->rows);
    free(s->plan_text);
    json_decref(s->facts);
    free(s);
}

calib_session_t *calib_session_open(const char *dir)
{
    calib_session_t *s = calloc(1, sizeof *s);
    rig_journal_t *j = NULL;
    char *psha = NULL, *rsha = NULL, *facts = NULL;
    if (!s || !(s->dir = strdup(dir))) goto oom;
    bool q = model_error_quiet_thread(true);
    int e = rig_journal_open(&j, dir);
    model_error_quiet_thread(q);
    if (e) {
        model_error(dir, 0, "not a capture session (no readable session.sqlite): %s", rig_last_error());
        goto fail;
    }
    if (rig_journal_source(j, "plan", NULL, &s->plan_text, &psha) ||
        rig_journal_source(j, "rig", NULL, NULL, &rsha) || rig_journal_frames(j, &s->rows, &s->n)) {
        model_error(dir, 0, "cannot read the session's journal: %s", rig_last_error());
        goto fail;
    }
    snprintf(s->plan_sha256, sizeof s->plan_sha256, "%s", psha);
    snprintf(s->rig_sha256, sizeof s->rig_sha256, "%s", rsha);
    if (!rig_journal_facts(j, &facts) && facts[0]) s->facts = json_loads(facts, 0, NULL);
    free(psha);
    free(rsha);
    free(facts);
    rig_journal_close(j);
    return s;
oom:
    model_error(dir, 0, "out of memory");
fail:
    free(psha);
    free(rsha);
    free(facts);
    rig_journal_close(j);
    calib_session_free(s);
    return NULL;
}

float *calib_image_read(const char *path, int *width, int *height)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        model_error(path, 0, "cannot open: %s", strerror(errno));
        return NULL;
    }
    unsigned char sig[4] = { 0 };
    size_t got = fread(sig, 1, 4, f);
    fclose(f);
    if (got == 4 && sig[0] == 0x89 && sig[1] == 'P' && sig[2] == 'N' && sig[3] == 'G') {
        uint16_t *pix = NULL;
        if (!model_png_read(path, width, height, &pix)) return NULL;
        size_t n = (size_t)*width * *height;
        float *out = malloc(n * sizeof *out);
        if (!out) {
            free(pix);
            model_error(path, 0, "out of memory");
            return NULL;
        }
        for (size_t i = 0; i < n; i++) out[i] = pix[i];
        free(pix);
        return out;
    }
    if (got == 4 && ((sig[0] == 'I' && sig[1] == 'I') || (sig[0] == 'M' && sig[1] == 'M'))) {
        float *out = NULL;
        if (!model_tiff_read_float(path, width, height, &out)) return NULL;
        return out;
    }
    model_error(path, 0, "neither a PNG nor a TIFF image (first bytes)");
    return NULL;
}

float *calib_session_frame(const calib_session_t *s, int i, int *width, int *height)
{
    if (i < 0 || i >= s->n) {
        model_error(s->dir, 0, "frame %d of %d does not exist", i, s->n);
        return NULL;
    }
    const rig_frame_row_t *r = &s->rows[i];
    char *path = g_strdup_printf("%s/%s", s->dir, r->file);
    char sha[65];
    float *out = NULL;
    if (!model_sha256_file(path, sha)) goto done;
    if (strcmp(sha, r->sha256)) {
        model_error(path, 0, "sha256 %s differs from the journal's %s (step %d): the frame was changed or "
                    "damaged; refl session check %s", sha, r->sha256, r->step, s->dir);
        goto done;
    }
    out = calib_image_read(path, width, height);
    if (out && (*width != r->width || *height != r->height)) {
        model_error(path, 0, "%dx%d pixels, the journal says %dx%d", *width, *height, r->width, r->height);
        free(out);
        out = NULL;
    }
done:
    g_free(path);
    return out;
}

// ---------------------------------------------------------------------------
// Provenance

json_t *calib_provenance(int argc, char **argv)
{
    json_t *p = json_object();
    char date[40];
    model_utc_text(model_realtime_s(), date);
    json_object_set_new(p, "refl_version", json_string(REFL_VERSION));
    json_object_set_new(p, "date_utc", json_string(date));
    char *cmd = model_command_line(argc, argv);
    json_object_set_new(p, "command", json_string(cmd ? cmd : ""));
    free(cmd);
    json_object_set_new(p, "inputs", json_array());
    return p;
}

bool calib_inputs_add(json_t *inputs, const char *role, const char *path)
{
    struct stat st;
    char sha[65];
    char *file = NULL;
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) file = g_strdup_printf("%s/session.sqlite", path);
    bool ok = model_sha256_file(file ? file : path, sha);
    g_free(file);
    if (!ok) return false;
    json_t *in = json_object();
    json_object_set_new(in, "role", json_string(role));
    json_object_set_new(in, "path", json_string(path));
    json_object_set_new(in, "sha256", json_string(sha));
    json_array_append_new(inputs, in);
    return true;
}

bool calib_provenance_input(json_t *prov, const char *role, const char *path)
{
    return calib_inputs_add(json_object_get(prov, "inputs"), role, path);
}

// ---------------------------------------------------------------------------
// Scripts

static char *script_path(const char *name)
{
    const char *env = getenv("REFL_SCRIPTS_DIR");
    if (env && *env) return g_strdup_printf("%s/%s", env, name);
    char exe[4096];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n <= 0) return g_strdup_printf("scripts/%s", name);
    exe[n] = 0;
    // bin/refl -> ../scripts; a build directory's binary (build-x/bin/refl) -> ../../scripts
    char *d = g_path_get_dirname(exe);
    char *p = NULL;
    for (int up = 1; up <= 3 && !p; up++) {
        GString *s = g_string_new(d);
        for (int k = 0; k < up; k++) g_string_append(s, "/..");
        g_string_append_printf(s, "/scripts/%s", name);
        if (access(s->str, R_OK) == 0) p = g_string_free(s, FALSE);
        else g_string_free(s, TRUE);
    }
    if (!p) p = g_strdup_printf("%s/../scripts/%s", d, name);
    g_free(d);
    return p;
}

int calib_python(const char *script, ...)
{
    char *path = script_path(script);
    if (access(path, R_OK) != 0) {
        model_error(path, 0, "the plotting script is missing (set REFL_SCRIPTS_DIR to refl's scripts/ directory)");
        g_free(path);
        return -1;
    }
    GPtrArray *args = g_ptr_array_new();
    g_ptr_array_add(args, (gpointer) "/usr/bin/python3");
    g_ptr_array_add(args, path);
    va_list ap;
    va_start(ap, script);
    for (const char *a; (a = va_arg(ap, const char *));) g_ptr_array_add(args, (gpointer)a);
    va_end(ap);
    g_ptr_array_add(args, NULL);
    GError *err = NULL;
    gint status = 0;
    fflush(stdout);
    fflush(stderr);
    gboolean ok = g_spawn_sync(NULL, (gchar **)args->pdata, NULL, G_SPAWN_CHILD_INHERITS_STDIN |
                               G_SPAWN_STDOUT_TO_DEV_NULL, NULL, NULL, NULL, NULL, &status, &err);
    int rc = 0;
    if (!ok) {
        model_error(path, 0, "cannot run /usr/bin/python3: %s", err ? err->message : "?");
        rc = -1;
    } else if (!g_spawn_check_wait_status(status, &err)) {
        model_error(path, 0, "the plotting script failed (%s); its messages are above", err ? err->message : "?");
        rc = -1;
    }
    if (err) g_error_free(err);
    g_ptr_array_free(args, TRUE);
    g_free(path);
    return rc;
}

// ---------------------------------------------------------------------------
// HTML

static void esc(FILE *f, const char *s)
{
    for (; s && *s; s++) {
        switch (*s) {
        case '<': fputs("&lt;", f); break;
        case '>': fputs("&gt;", f); break;
        case '&': fputs("&amp;", f); break;
        case '"': fputs("&quot;", f); break;
        default: fputc(*s, f);
        }
    }
}

FILE *calib_html_begin(const char *path, const char *title, const json_t *prov)
{
    char *tmp = g_strdup_printf("%s.part", path);
    FILE *f = fopen(tmp, "w");
    g_free(tmp);
    if (!f) {
        model_error(path, 0, "cannot write: %s", strerror(errno));
        return NULL;
    }
    fputs("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>", f);
    esc(f, title);
    fputs("</title>\n<style>body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;color:#222}"
          "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
          "text-align:left;font-size:90%}th{background:#eee}figure{margin:1em 0}img{max-width:100%;"
          "border:1px solid #ddd}figcaption{font-size:90%;color:#555}code{font-size:90%}</style>\n</head><body>\n<h1>",
          f);
    esc(f, title);
    fputs("</h1>\n", f);
    if (prov) {
        fputs("<p>refl ", f);
        esc(f, json_string_value(json_object_get(prov, "refl_version")));
        fputs(", ", f);
        esc(f, json_string_value(json_object_get(prov, "date_utc")));
        fputs("<br><code>", f);
        esc(f, json_string_value(json_object_get(prov, "command")));
        fputs("</code></p>\n<table><tr><th>input</th><th>path</th><th>sha256</th></tr>\n", f);
        size_t i;
        json_t *in;
        json_array_foreach(json_object_get(prov, "inputs"), i, in) {
            fputs("<tr><td>", f);
            esc(f, json_string_value(json_object_get(in, "role")));
            fputs("</td><td>", f);
            esc(f, json_string_value(json_object_get(in, "path")));
            fputs("</td><td><code>", f);
            esc(f, json_string_value(json_object_get(in, "sha256")));
            fputs("</code></td></tr>\n", f);
        }
        fputs("</table>\n", f);
    }
    return f;
}

void calib_html_heading(FILE *f, const char *text)
{
    fputs("<h2>", f);
    esc(f, text);
    fputs("</h2>\n", f);
}

void calib_html_para(FILE *f, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    char *s = g_strdup_vprintf(fmt, ap);
    va_end(ap);
    fputs("<p>", f);
    esc(f, s);
    fputs("</p>\n", f);
    g_free(s);
}

void calib_html_figure(FILE *f, const char *src, const char *caption)
{
    fputs("<figure><img src=\"", f);
    esc(f, src);
    fputs("\" alt=\"", f);
    esc(f, caption);
    fputs("\"><figcaption>", f);
    esc(f, caption);
    fputs("</figcaption></figure>\n", f);
}

static void cells(FILE *f, const char *row, const char *tag)
{
    fputs("<tr>", f);
    const char *p = row;
    for (;;) {
        const char *e = strchr(p, '|');
        size_t n = e ? (size_t)(e - p) : strlen(p);
        char *c = g_strndup(p, n);
        fprintf(f, "<%s>", tag);
        esc(f, c);
        fprintf(f, "</%s>", tag);
        g_free(c);
        if (!e) break;
        p = e + 1;
    }
    fputs("</tr>\n", f);
}

void calib_html_table(FILE *f, const char *header, const char *const *rows, int nrows)
{
    fputs("<table>\n", f);
    if (header) cells(f, header, "th");
    for (int i = 0; i < nrows; i++) cells(f, rows[i], "td");
    fputs("</table>\n", f);
}

bool calib_html_end(FILE *f, const char *path)
{
    fputs("</body></html>\n", f);
    bool ok = fflush(f) == 0 && fsync(fileno(f)) == 0;
    ok = fclose(f) == 0 && ok;
    char *tmp = g_strdup_printf("%s.part", path);
    if (ok && rename(tmp, path) != 0) ok = false;
    if (!ok) {
        model_error(path, 0, "cannot write: %s", strerror(errno));
        unlink(tmp);
    }
    g_free(tmp);
    return ok;
}
