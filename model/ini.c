// model/ini.c — the INI reader behind materials, lamps and sensor files.
//
// The parsed file lives in one allocation: the model_ini_t itself, then the
// entry, section and line arrays, the name, and a copy of the text in which
// every section, key and value is a NUL-terminated, trimmed substring.
// Runs of blanks inside a section header are collapsed to one space, so
// "[lamp   left]" and "[lamp left]" name the same section.
#include <glib.h>
#include <stdalign.h>
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
    char *buf = block + off_text;
    if (len) memcpy(buf, text, len);
    buf[len] = 0;

    const char *section = NULL;
    // Duplicate checks in constant time: section name -> index + 1, and the
    // keys of the current section -> entry index + 1 (entries of one section
    // are contiguous, so that table restarts at every header).
    GHashTable *sections_seen = g_hash_table_new(g_str_hash, g_str_equal);
    GHashTable *keys_seen = g_hash_table_new(g_str_hash, g_str_equal);
    char *p = buf;
    for (int line = 1; p; line++) {
        char *eol = strchr(p, '\n');
        if (eol) *eol = 0;
        char *s = trim(p);
        p = eol ? eol + 1 : NULL;

        if (!*s || *s == '#' || *s == ';') continue;

        if (*s == '[') {
            char *close = strchr(s, ']');
            if (!close) {
                model_error(name, line, "unterminated '[' in section header '%s'; write [section] or [kind NAME]", s);
                goto fail;
            }
            char *rest = trim(close + 1);
            if (*rest && *rest != '#' && *rest != ';') {
                model_error(name, line, "unexpected text '%s' after the section header; put comments on their own line or after '#'", rest);
                goto fail;
            }
            *close = 0;
            char *sec = trim(s + 1);
            collapse_blanks(sec);
            if (!*sec) {
                model_error(name, line, "empty section name '[]'; write [section] or [kind NAME]");
                goto fail;
            }
            if (strchr(sec, '[')) {
                model_error(name, line, "'[' inside the section header [%s]", sec);
                goto fail;
            }
            int first = GPOINTER_TO_INT(g_hash_table_lookup(sections_seen, sec));
            if (first) {
                model_error(name, line, "duplicate section [%s] (first at line %d); merge them or rename one",
                            sec, ini->section_lines[first - 1]);
                goto fail;
            }
            ini->sections[ini->nsections] = sec;
            ini->section_lines[ini->nsections] = line;
            ini->section_first[ini->nsections] = ini->nentries;
            ini->section_count[ini->nsections] = 0;
            ini->nsections++;
            g_hash_table_insert(sections_seen, sec, GINT_TO_POINTER(ini->nsections));
            g_hash_table_remove_all(keys_seen);
            section = sec;
            continue;
        }

        char *eq = strchr(s, '=');
        if (!eq) {
            model_error(name, line, "expected 'key = value' or '[section]', got '%s'", s);
            goto fail;
        }
        *eq = 0;
        char *key = trim(s);
        char *value = eq + 1;
        cut_comment(value);
        value = trim(value);
        if (!*key) {
            model_error(name, line, "empty key before '='; write 'key = value'");
            goto fail;
        }
        if (!section) {
            model_error(name, line, "key '%s' before any section; put it under a [section] header", key);
            goto fail;
        }
        int prev = GPOINTER_TO_INT(g_hash_table_lookup(keys_seen, key));
        if (prev) {
            model_error(name, line, "duplicate key '%s' in [%s] (first at line %d); keep one",
                        key, section, ini->entries[prev - 1].line);
            goto fail;
        }
        ini->entries[ini->nentries++] = (model_ini_entry_t){ section, key, value, line };
        ini->section_count[ini->nsections - 1]++;
        g_hash_table_insert(keys_seen, key, GINT_TO_POINTER(ini->nentries));
    }
    g_hash_table_destroy(sections_seen);
    g_hash_table_destroy(keys_seen);
    return ini;

fail:
    g_hash_table_destroy(sections_seen);
    g_hash_table_destroy(keys_seen);
    free(block);
    return NULL;
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
    if (ini) free(ini->storage_);   // the struct is the start of storage_
}

const model_ini_entry_t *model_ini_get(const model_ini_t *ini, const char *section, const char *key)
{
    if (!ini || !section || !key) return NULL;
    for (int i = 0; i < ini->nentries; i++)
        if (!strcmp(ini->entries[i].section, section) && !strcmp(ini->entries[i].key, key))
            return &ini->entries[i];
    return NULL;
}
