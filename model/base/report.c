// model/base/report.c — the output files every layer writes: directories,
// atomic files and JSON, provenance, the plotting scripts and HTML report pages.
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <fcntl.h>
#include <glib.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "model/base/report.h"
#include "model/model.h"

static GMutex     made_lock;
static GPtrArray *made_dirs;   // directories model_mkdir_p made, parents before children

bool model_mkdir_p(const char *path)
{
    // the path's missing prefixes, outermost first, are the directories this call makes
    GPtrArray *missing = g_ptr_array_new_with_free_func(g_free);
    char *p = g_strdup(path);
    for (size_t n = strlen(p); n > 1 && p[n - 1] == '/'; n--) p[n - 1] = 0;
    struct stat st;
    while (*p && strcmp(p, "/") && strcmp(p, ".") && stat(p, &st) != 0 && errno == ENOENT) {
        g_ptr_array_insert(missing, 0, g_strdup(p));
        char *d = g_path_get_dirname(p);
        g_free(p);
        p = d;
    }
    g_free(p);
    bool ok = g_mkdir_with_parents(path, 0755) == 0;
    if (!ok) model_error(path, 0, "cannot make the directory: %s", strerror(errno));
    g_mutex_lock(&made_lock);
    if (!made_dirs) made_dirs = g_ptr_array_new_with_free_func(g_free);
    for (guint i = 0; i < missing->len; i++)
        if (g_file_test(missing->pdata[i], G_FILE_TEST_IS_DIR)) g_ptr_array_add(made_dirs, g_strdup(missing->pdata[i]));
    g_mutex_unlock(&made_lock);
    g_ptr_array_free(missing, TRUE);
    return ok;
}

int model_remove_made_empty_dirs(void)
{
    int n = 0;
    g_mutex_lock(&made_lock);
    for (guint i = made_dirs ? made_dirs->len : 0; i-- > 0;)
        if (rmdir(made_dirs->pdata[i]) == 0) n++;   // fails, and so stays, when not empty
    if (made_dirs) g_ptr_array_set_size(made_dirs, 0);
    g_mutex_unlock(&made_lock);
    return n;
}

bool model_write_file_atomic(const char *path, const char *text)
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

json_t *model_json_number(double x) { return isfinite(x) ? json_real(x) : json_null(); }

void model_json_set_format(json_t *root, const char *format, int version)
{
    json_object_set_new(root, "format", json_string(format));
    json_object_set_new(root, "version", json_integer(version));
}

bool model_json_format_check(const json_t *root, const char *path, const char *format, int max_version,
                             int *version)
{
    if (version) *version = 0;
    if (!json_is_object(root)) {
        model_error_set(path, 0, "not a %s file (its top level is not a JSON object)", format);
        return false;
    }
    const json_t *f = json_object_get(root, "format"), *v = json_object_get(root, "version");
    if (f && (!json_is_string(f) || strcmp(json_string_value(f), format))) {
        model_error_set(path, 0, "a %s file, not %s", json_is_string(f) ? json_string_value(f) : "(format not a "
                        "string)", format);
        return false;
    }
    long ver = 1;
    if (v || f) {
        if (!json_is_integer(v) || json_integer_value(v) < 1) {
            model_error_set(path, 0, "%s: \"version\" is %s (a whole number from 1)", format,
                            v ? "not a whole number >= 1" : "missing");
            return false;
        }
        ver = (long)json_integer_value(v);
    }
    if (ver > max_version) {
        model_error_set(path, 0, "%s version %ld, written by a newer refl (this refl reads versions 1 to %d)", format,
                        ver, max_version);
        return false;
    }
    if (version) *version = (int)ver;
    return true;
}

bool model_write_json(const char *path, json_t *o)
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
    bool ok = model_write_file_atomic(path, t);
    free(t);
    return ok;
}

// ---------------------------------------------------------------------------
// Provenance

json_t *model_provenance(int argc, char **argv)
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

bool model_inputs_add(json_t *inputs, const char *role, const char *path)
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

bool model_provenance_input(json_t *prov, const char *role, const char *path)
{
    return model_inputs_add(json_object_get(prov, "inputs"), role, path);
}

// ---------------------------------------------------------------------------
// Scripts

int model_run_script(const char *script, ...)
{
    char *path = model_share_path("scripts", script);
    if (!path) {
        model_error(NULL, 0, "the plotting script is missing: %s", model_last_error());
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

// Text of a page (paragraphs, headings, captions, table cells): escaped, and a number that prints as
// a negative zero ("-0.00", "-0") without its sign: "-0.00 deg" reads as a direction that is not there.
// A '-' after a letter, digit, '.' or '_' (a name, a date, an exponent) is left alone.
static void esc_text(FILE *f, const char *s)
{
    for (const char *p = s; p && *p; p++) {
        if (*p == '-' && (p == s || !(g_ascii_isalnum(p[-1]) || p[-1] == '.' || p[-1] == '_'))) {
            const char *q = p + 1;
            bool digits = false, zero = true;
            while (*q == '0' || *q == '.' || g_ascii_isdigit(*q)) {
                if (g_ascii_isdigit(*q)) digits = true;
                if (g_ascii_isdigit(*q) && *q != '0') zero = false;
                q++;
            }
            if (digits && zero && !g_ascii_isalpha(*q) && q[-1] != '.') continue;   // drop the sign
        }
        esc(f, (char[]){ *p, 0 });
    }
}

FILE *model_html_begin(const char *path, const char *title, const json_t *prov)
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
          "border:1px solid #ddd}figcaption{font-size:90%;color:#555}code{font-size:90%}"
          ".headline{border:2px solid #888;border-radius:6px;padding:0.4em 1em;margin:0.8em 0;background:#fafafa}"
          ".headline h2{margin:0.2em 0 0.4em 0;font-size:120%}.headline ul{margin:0.2em 0;padding-left:1.3em}"
          ".headline li.miss{color:#b00020;font-weight:bold}summary{cursor:pointer;color:#555}"
          "</style>\n</head><body>\n<h1>", f);
    esc(f, title);
    fputs("</h1>\n", f);
    if (prov) {
        fputs("<p>refl ", f);
        esc(f, json_string_value(json_object_get(prov, "refl_version")));
        fputs(", ", f);
        esc(f, json_string_value(json_object_get(prov, "date_utc")));
        fputs("<br><code>", f);
        esc(f, json_string_value(json_object_get(prov, "command")));
        fputs("</code></p>\n", f);
        // the inputs' paths and hashes folded: the page opens with its headline
        fprintf(f, "<details><summary>%zu inputs: paths and sha256</summary>\n"
                   "<table><tr><th>input</th><th>path</th><th>sha256</th></tr>\n",
                json_array_size(json_object_get(prov, "inputs")));
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
        fputs("</table></details>\n", f);
    }
    return f;
}

void model_html_heading(FILE *f, const char *text)
{
    fputs("<h2>", f);
    esc_text(f, text);
    fputs("</h2>\n", f);
}

void model_html_para(FILE *f, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    char *s = g_strdup_vprintf(fmt, ap);
    va_end(ap);
    fputs("<p>", f);
    esc_text(f, s);
    fputs("</p>\n", f);
    g_free(s);
}

void model_html_headline(FILE *f, const char *title, const char *const *items, int nitems)
{
    fputs("<div class=\"headline\" id=\"headline\"><h2>", f);
    esc_text(f, title);
    fputs("</h2><ul>\n", f);
    for (int i = 0; i < nitems; i++) {
        if (!items[i] || !*items[i]) continue;
        bool miss = items[i][0] == '!';
        fputs(miss ? "<li class=\"miss\">" : "<li>", f);
        esc_text(f, items[i] + miss);
        fputs("</li>\n", f);
    }
    fputs("</ul></div>\n", f);
}

void model_html_figure(FILE *f, const char *src, const char *caption)
{
    fputs("<figure><img src=\"", f);
    esc(f, src);
    fputs("\" alt=\"", f);
    esc(f, caption);
    fputs("\"><figcaption>", f);
    esc_text(f, caption);
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
        esc_text(f, c);
        fprintf(f, "</%s>", tag);
        g_free(c);
        if (!e) break;
        p = e + 1;
    }
    fputs("</tr>\n", f);
}

void model_html_table(FILE *f, const char *header, const char *const *rows, int nrows)
{
    fputs("<table>\n", f);
    if (header) cells(f, header, "th");
    for (int i = 0; i < nrows; i++) cells(f, rows[i], "td");
    fputs("</table>\n", f);
}

bool model_html_end(FILE *f, const char *path)
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
