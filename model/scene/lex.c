// model/scene/lex.c — the scene readers' lexer: lines of a text (given as
// text, len, without assuming a NUL terminator), each cut at '#' and split
// into blank-separated tokens; tokens as words, integers, numbers, and quoted
// for messages.
#define _GNU_SOURCE
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <glib.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "model/internal.h"
#include "model/scene/internal.h"

// ---------------------------------------------------------------------------
// Tokens

static bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

bool scene_tok_is(scene_tok_t t, const char *word)
{
    size_t n = strlen(word);
    return t.n == n && memcmp(t.p, word, n) == 0;
}

bool scene_tok_is_ci(scene_tok_t t, const char *word)
{
    size_t n = strlen(word);
    return t.n == n && strncasecmp(t.p, word, n) == 0;
}

// The token quoted for a message: at most 40 characters, non-printable bytes as \xHH.
const char *scene_quote(scene_tok_t t, char out[200])
{
    size_t o = 0;
    out[o++] = '\'';
    for (size_t i = 0; i < t.n && i < 40; i++) {
        unsigned char c = (unsigned char)t.p[i];
        if (c >= 0x20 && c < 0x7f && c != '\\')
            out[o++] = (char)c;
        else
            o += (size_t)snprintf(out + o, 8, "\\x%02x", c);
    }
    if (t.n > 40) {
        memcpy(out + o, "...", 3);
        o += 3;
    }
    out[o++] = '\'';
    out[o] = 0;
    return out;
}

// A decimal integer with optional sign, the whole token. No overflow.
bool scene_tok_long(scene_tok_t t, long *out)
{
    size_t i = 0;
    bool neg = false;
    if (i < t.n && (t.p[i] == '+' || t.p[i] == '-')) neg = t.p[i++] == '-';
    if (i == t.n) return false;
    long v = 0;
    for (; i < t.n; i++) {
        if (t.p[i] < '0' || t.p[i] > '9') return false;
        int d = t.p[i] - '0';
        if (v > (LONG_MAX - d) / 10) return false;
        v = v * 10 + d;
    }
    *out = neg ? -v : v;
    return true;
}

// A floating-point number, the whole token. Underflow gives the rounded value.
scene_num_t scene_tok_double(scene_tok_t t, double *out)
{
    char buf[256];
    if (t.n == 0 || t.n >= sizeof buf) return SCENE_NUM_BAD;
    memcpy(buf, t.p, t.n);
    buf[t.n] = 0;
    char *end;
    errno = 0;
    double v = strtod(buf, &end);
    if (end == buf || *end) return SCENE_NUM_BAD;
    if (!isfinite(v) || (errno == ERANGE && fabs(v) > 1.0)) return SCENE_NUM_NONFINITE;
    *out = v;
    return SCENE_NUM_OK;
}

// Next line: false at the end of the text or on error (*err set).
bool scene_lex_line(scene_lexer_t *lx, bool *err)
{
    *err = false;
    if (lx->pos >= lx->len) return false;
    if (lx->line == INT_MAX) {
        model_error(lx->name, 0, "too many lines");
        *err = true;
        return false;
    }
    lx->line++;
    const char *s = lx->text + lx->pos;
    const char *nl = memchr(s, '\n', lx->len - lx->pos);
    size_t n = nl ? (size_t)(nl - s) : lx->len - lx->pos;
    lx->pos += n + (nl ? 1 : 0);
    if (memchr(s, 0, n)) {
        model_error(lx->name, lx->line,
                    "the line contains a NUL byte; a scene file must be text (is this a binary file?)");
        *err = true;
        return false;
    }
    const char *hash = memchr(s, '#', n);
    if (hash) n = (size_t)(hash - s);
    lx->ntoks = 0;
    size_t i = 0;
    while (i < n) {
        while (i < n && is_blank(s[i])) i++;
        if (i == n) break;
        size_t b = i;
        while (i < n && !is_blank(s[i])) i++;
        if (lx->ntoks == lx->cap) {
            size_t nc = lx->cap ? 2 * lx->cap : 16;
            scene_tok_t *nt = realloc(lx->toks, nc * sizeof *nt);
            if (!nt) {
                model_error(lx->name, lx->line, "out of memory");
                *err = true;
                return false;
            }
            lx->toks = nt;
            lx->cap = nc;
        }
        lx->toks[lx->ntoks++] = (scene_tok_t){ s + b, i - b };
    }
    return true;
}
