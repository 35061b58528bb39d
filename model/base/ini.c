// model/base/ini.c — the INI reader behind materials, lamps and sensor files.
//
// The parsed file lives in one allocation: the model_ini_t itself, then the
// entry, section and line arrays, the name, and a copy of the text in which
// every section, key and value is a NUL-terminated, trimmed substring.
// Runs of blanks inside a section header are collapsed to one space, so
// "[lamp   left]" and "[lamp left]" name the same section.
#include <glib.h>
#include <stdalign.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

static bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

static char *trim(char *s)
{
    while (is_blank(*s)) s++;
    size_t n = strlen(s);
    while (n > 0 && is_blank(s[n - 1])) s[--n] = 0;
    return s;
}

static size_t align_up(size_t n) { return (n + alignof(max_align_t) - 1) & ~(alignof(max_align_t) - 1); }

// Collapse runs of blanks to one space (in place; s already trimmed).
static void collapse_blanks(char *s)
{
    char *w = s;
    bool prev_blank = false;
    for (char *r = s; *r; r++) {
        if (is_blank(*r)) {
            if (!prev_blank) *w++ = ' ';
            prev_blank = true;
        } else {
            *w++ = *r;
            prev_blank = false;
        }
    }
    *w = 0;
}

// Cut a trailing comment off a value: '#' at its start or after a blank.
static void cut_comment(char *v)
{
    for (char *p = v; *p; p++)
        if (*p == '#' && (p == v || is_blank(p[-1]))) {
            *p = 0;
            return;
        }
}

// The parsed file's one allocation (see the head of this file) for a text
// of len bytes: the arrays sized for one entry and one section per line,
// the name and the text copied (*buf: the copy). NULL + message when out
// of memory.
static model_ini_t *ini_alloc(const char *text, size_t len, const char *name, char **buf)
{
    size_t nlines = 1;
    for (size_t i = 0; i < len; i++) nlines += text[i] == '\n';

    size_t name_len = strlen(name);
    size_t off_entries = align_up(sizeof(model_ini_t));
    size_t off_sections = align_up(off_entries + nlines * sizeof(model_ini_entry_t));
    size_t off_slines = align_up(off_sections + nlines * sizeof(const char *));
    size_t off_sfirst = off_slines + nlines * sizeof(int);
    size_t off_scount = off_sfirst + nlines * sizeof(int);
    size_t off_name = off_scount + nlines * sizeof(int);
    size_t off_text = off_name + name_len + 1;
    size_t total = off_text + len + 1;

    char *block = malloc(total);
    if (!block) {
        model_error(name, 0, "out of memory reading %zu bytes", len);
        return NULL;
    }
    model_ini_t *ini = (model_ini_t *)block;
    memset(ini, 0, sizeof *ini);
    ini->storage_ = block;
    ini->entries = (model_ini_entry_t *)(block + off_entries);
    ini->sections = (const char **)(block + off_sections);
    ini->section_lines = (int *)(block + off_slines);
    ini->section_first = (int *)(block + off_sfirst);
    ini->section_count = (int *)(block + off_scount);
    ini->path = block + off_name;
    memcpy(ini->path, name, name_len + 1);
    *buf = block + off_text;
    if (len) memcpy(*buf, text, len);
    (*buf)[len] = 0;
    return ini;
}

// Duplicate checks in constant time: section name -> index + 1, and the
// keys of the current section -> entry index + 1 (entries of one section
// are contiguous, so that table restarts at every header).
typedef struct {
    GHashTable *sections_seen;
    GHashTable *keys_seen;
    const char *section;   // the current section (NULL before the first header)
} ini_state_t;

// A section header line s ("[...]", trimmed), cut in place.
static bool ini_section(model_ini_t *ini, ini_state_t *st, const char *name, int line, char *s)
{
    char *close = strchr(s, ']');
    if (!close) {
        model_error(name, line, "unterminated '[' in section header '%s'; write [section] or [kind NAME]", s);
        return false;
    }
    char *rest = trim(close + 1);
    if (*rest && *rest != '#' && *rest != ';') {
        model_error(name, line, "unexpected text '%s' after the section header; put comments on their own line or after '#'", rest);
        return false;
    }
    *close = 0;
    char *sec = trim(s + 1);
    collapse_blanks(sec);
    if (!*sec) {
        model_error(name, line, "empty section name '[]'; write [section] or [kind NAME]");
        return false;
    }
    if (strchr(sec, '[')) {
        model_error(name, line, "'[' inside the section header [%s]", sec);
        return false;
    }
    int first = GPOINTER_TO_INT(g_hash_table_lookup(st->sections_seen, sec));
    if (first) {
        model_error(name, line, "duplicate section [%s] (first at line %d); merge them or rename one",
                    sec, ini->section_lines[first - 1]);
        return false;
    }
    ini->sections[ini->nsections] = sec;
    ini->section_lines[ini->nsections] = line;
    ini->section_first[ini->nsections] = ini->nentries;
    ini->section_count[ini->nsections] = 0;
    ini->nsections++;
    g_hash_table_insert(st->sections_seen, sec, GINT_TO_POINTER(ini->nsections));
    g_hash_table_remove_all(st->keys_seen);
    st->section = sec;
    return true;
}

// A "key = value" line s (trimmed), cut in place.
static bool ini_entry(model_ini_t *ini, ini_state_t *st, const char *name, int line, char *s)
{
    char *eq = strchr(s, '=');
    if (!eq) {
        model_error(name, line, "expected 'key = value' or '[section]', got '%s'", s);
        return false;
    }
    *eq = 0;
    char *key = trim(s);
    char *value = eq + 1;
    cut_comment(value);
    value = trim(value);
    if (!*key) {
        model_error(name, line, "empty key before '='; write 'key = value'");
        return false;
    }
    if (!st->section) {
        model_error(name, line, "key '%s' before any section; put it under a [section] header", key);
        return false;
    }
    int prev = GPOINTER_TO_INT(g_hash_table_lookup(st->keys_seen, key));
    if (prev) {
        model_error(name, line, "duplicate key '%s' in [%s] (first at line %d); keep one",
                    key, st->section, ini->entries[prev - 1].line);
        return false;
    }
    ini->entries[ini->nentries++] = (model_ini_entry_t){ st->section, key, value, line };
    ini->section_count[ini->nsections - 1]++;
    g_hash_table_insert(st->keys_seen, key, GINT_TO_POINTER(ini->nentries));
    return true;
}

model_ini_t *model_ini_parse(const char *text, size_t len, const char *name)
{
    if (!name) name = "<text>";
    if (!text) len = 0;

    // NUL bytes would silently truncate lines: refuse them.
    const char *nul = len ? memchr(text, 0, len) : NULL;
    if (nul) {
        int line = 1;
        for (const char *p = text; p < nul; p++) line += *p == '\n';
        model_error(name, line, "NUL byte in the text (is this a binary file?); INI files are plain text");
        return NULL;
    }

    char *p;
    model_ini_t *ini = ini_alloc(text, len, name, &p);
    if (!ini) return NULL;
    ini_state_t st = { g_hash_table_new(g_str_hash, g_str_equal), g_hash_table_new(g_str_hash, g_str_equal), NULL };
    for (int line = 1; p; line++) {
        char *eol = strchr(p, '\n');
        if (eol) *eol = 0;
        char *s = trim(p);
        p = eol ? eol + 1 : NULL;

        if (!*s || *s == '#' || *s == ';') continue;
        if (!(*s == '[' ? ini_section(ini, &st, name, line, s) : ini_entry(ini, &st, name, line, s))) {
            g_hash_table_destroy(st.sections_seen);
            g_hash_table_destroy(st.keys_seen);
            free(ini->storage_);
            return NULL;
        }
    }
    ini->index_ = st.sections_seen;   // kept for model_ini_get (its keys live in the block)
    g_hash_table_destroy(st.keys_seen);
    return ini;
}

model_ini_t *model_ini_load(const char *path)
{
    size_t len;
    char *text = model_read_file(path, &len);
    if (!text) return NULL;
    model_ini_t *ini = model_ini_parse(text, len, path);
    free(text);
    return ini;
}

void model_ini_free(model_ini_t *ini)
{
    if (!ini) return;
    if (ini->index_) g_hash_table_destroy(ini->index_);
    free(ini->storage_);   // the struct is the start of storage_
}

// The index of section, -1 when there is none.
static int section_index(const model_ini_t *ini, const char *section)
{
    if (ini->index_) return GPOINTER_TO_INT(g_hash_table_lookup(ini->index_, section)) - 1;
    for (int i = 0; i < ini->nsections; i++)
        if (!strcmp(ini->sections[i], section)) return i;
    return -1;
}

const model_ini_entry_t *model_ini_get(const model_ini_t *ini, const char *section, const char *key)
{
    if (!ini || !section || !key) return NULL;
    int s = section_index(ini, section);
    if (s < 0) return NULL;
    // A section's entries are contiguous.
    for (int i = ini->section_first[s]; i < ini->section_first[s] + ini->section_count[s]; i++)
        if (!strcmp(ini->entries[i].key, key)) return &ini->entries[i];
    return NULL;
}

// ---------------------------------------------------------------------------
// Typed getters (see model/model.h)

int model_ini_section_line(const model_ini_t *ini, const char *section)
{
    int s = ini && section ? section_index(ini, section) : -1;
    return s < 0 ? 0 : ini->section_lines[s];
}

const char *model_ini_text(const model_ini_t *ini, const char *section, const char *key, const char *def)
{
    const model_ini_entry_t *e = model_ini_get(ini, section, key);
    return e ? e->value : def;
}

// The entry, or NULL: absent and optional (*ok true), or absent and required
// (*ok false, reported at the section's line).
static const model_ini_entry_t *entry_of(const model_ini_t *ini, const char *sec, const char *key, bool required,
                                         bool *ok)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, key);
    *ok = e || !required;
    if (!e && required) model_error(ini->path, model_ini_section_line(ini, sec), "[%s] lacks '%s'; add it", sec, key);
    return e;
}

bool model_ini_double_in(const model_ini_t *ini, const char *sec, const char *key, double *out, bool required,
                         double lo, bool lo_open, double hi, const char *range_text)
{
    bool ok;
    const model_ini_entry_t *e = entry_of(ini, sec, key, required, &ok);
    if (!e) return ok;
    char range[96];
    if (range_text) snprintf(range, sizeof range, "%s", range_text);
    else snprintf(range, sizeof range, "%s%g..%g", lo_open ? "> " : "", lo, hi);
    double v;
    if (!model_parse_double(e->value, &v)) {
        model_error(ini->path, e->line, "[%s] %s: '%s' is not a number (%s)", sec, key, e->value, range);
        return false;
    }
    if ((lo_open ? !(v > lo) : !(v >= lo)) || !(v <= hi)) {
        model_error(ini->path, e->line, "[%s] %s = %s is out of range (%s)", sec, key, e->value, range);
        return false;
    }
    *out = v;
    return true;
}

bool model_ini_double(const model_ini_t *ini, const char *sec, const char *key, double *out, bool required)
{
    bool ok;
    const model_ini_entry_t *e = entry_of(ini, sec, key, required, &ok);
    if (!e) return ok;
    if (!model_parse_double(e->value, out)) {
        model_error(ini->path, e->line, "[%s] %s: '%s' is not a number", sec, key, e->value);
        return false;
    }
    return true;
}

bool model_ini_int(const model_ini_t *ini, const char *sec, const char *key, long *out, bool required, long lo,
                   long hi)
{
    bool ok;
    const model_ini_entry_t *e = entry_of(ini, sec, key, required, &ok);
    if (!e) return ok;
    long v;
    if (!model_parse_int(e->value, &v)) {
        model_error(ini->path, e->line, "[%s] %s: '%s' is not an integer (%ld..%ld)", sec, key, e->value, lo, hi);
        return false;
    }
    if (v < lo || v > hi) {
        model_error(ini->path, e->line, "[%s] %s = %s is out of range (%ld..%ld)", sec, key, e->value, lo, hi);
        return false;
    }
    *out = v;
    return true;
}

bool model_ini_bool(const model_ini_t *ini, const char *sec, const char *key, bool *out, bool required)
{
    bool ok;
    const model_ini_entry_t *e = entry_of(ini, sec, key, required, &ok);
    if (!e) return ok;
    const char *v = e->value;
    if (!strcmp(v, "true") || !strcmp(v, "yes") || !strcmp(v, "1") || !strcmp(v, "on")) {
        *out = true;
    } else if (!strcmp(v, "false") || !strcmp(v, "no") || !strcmp(v, "0") || !strcmp(v, "off")) {
        *out = false;
    } else {
        model_error(ini->path, e->line, "[%s] %s: '%s' is not a truth value (true/false, yes/no, 1/0)", sec, key, v);
        return false;
    }
    return true;
}

bool model_ini_string(const model_ini_t *ini, const char *sec, const char *key, char *out, size_t size,
                      bool required)
{
    bool ok;
    const model_ini_entry_t *e = entry_of(ini, sec, key, required, &ok);
    if (!e) return ok;
    if (!e->value[0]) {
        model_error(ini->path, e->line, "[%s] %s is empty: give a value or remove the line", sec, key);
        return false;
    }
    if (strlen(e->value) >= size) {
        model_error(ini->path, e->line, "[%s] %s: '%s' is longer than %zu characters", sec, key, e->value, size - 1);
        return false;
    }
    snprintf(out, size, "%s", e->value);
    return true;
}

bool model_ini_vec3(const model_ini_t *ini, const char *sec, const char *key, double out[3], bool required,
                    const char *what)
{
    bool ok;
    const model_ini_entry_t *e = entry_of(ini, sec, key, required, &ok);
    if (!e) return ok;
    double v[3];
    int n = 0;
    gchar **w = g_strsplit_set(e->value, " \t,", -1);
    for (int i = 0; w[i] && n <= 3; i++) {
        if (!w[i][0]) continue;
        if (n == 3 || !model_parse_double(w[i], &v[n])) {
            n = -1;
            break;
        }
        n++;
    }
    g_strfreev(w);
    if (n != 3) {
        model_error(ini->path, e->line, "[%s] %s: '%s' is not three numbers %s", sec, key, e->value,
                    what ? what : "x y z");
        return false;
    }
    memcpy(out, v, sizeof v);
    return true;
}
