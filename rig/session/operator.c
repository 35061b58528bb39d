// rig/session/operator.c — the operator's answers to operator steps (see rig/session/session.h,
// "The operator's answers"): --yes, --operator-input FILE (one answer a line,
// consumed in order by every session of a command), or the terminal.
#define _GNU_SOURCE
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"

struct rig_operator {
    bool  yes;
    char *path;         // --operator-input FILE
    FILE *f;
    int   line;         // lines read from f
    bool  paused;
};

rig_operator_t *rig_operator_open(bool yes, const char *input)
{
    if (yes && input) {
        rig_fail(RIG_ERR_INVALID, "give --yes or --operator-input FILE, not both");
        return NULL;
    }
    rig_operator_t *op = calloc(1, sizeof *op);
    if (!op) {
        rig_fail(RIG_ERR_NO_MEM, "operator: out of memory");
        return NULL;
    }
    op->yes = yes;
    if (input) {
        if (!(op->path = strdup(input))) {
            rig_fail(RIG_ERR_NO_MEM, "operator: out of memory");
            rig_operator_close(op);
            return NULL;
        }
        if (!(op->f = fopen(input, "r"))) {
            rig_fail(RIG_ERR_IO, "--operator-input %s: cannot read it: %s", input, strerror(errno));
            rig_operator_close(op);
            return NULL;
        }
    }
    return op;
}

void rig_operator_close(rig_operator_t *op)
{
    if (!op) return;
    if (op->f) fclose(op->f);
    free(op->path);
    free(op);
}

bool rig_operator_paused(const rig_operator_t *op) { return op && op->paused; }

void rig_operator_set_paused(rig_operator_t *op)
{
    if (op) op->paused = true;
}

// One line without its end of line and surrounding blanks; false at EOF.
static bool read_answer(FILE *f, char *buf, size_t size)
{
    if (!fgets(buf, (int)size, f)) return false;
    size_t n = strlen(buf);
    if (n && buf[n - 1] != '\n' && !feof(f)) {   // longer than buf: keep its start, drop the rest
        int c;
        while ((c = fgetc(f)) != EOF && c != '\n') {}
    }
    char *s = buf;
    while (*s == ' ' || *s == '\t') s++;
    memmove(buf, s, strlen(s) + 1);
    n = strlen(buf);
    while (n && (buf[n - 1] == '\n' || buf[n - 1] == '\r' || buf[n - 1] == ' ' || buf[n - 1] == '\t')) buf[--n] = 0;
    return true;
}

static bool is_done(const char *a)
{
    return !a[0] || !strcasecmp(a, "done") || !strcasecmp(a, "y") || !strcasecmp(a, "yes");
}

static bool is_pause(const char *a)
{
    return !strcasecmp(a, "q") || !strcasecmp(a, "pause") || !strcasecmp(a, "stop");
}

int rig_operator_ask(rig_operator_t *op, int step, const char *instruction, char *how, size_t size)
{
    char now[40];
    model_utc_text(model_realtime_s(), now);
    model_note("OPERATOR STEP %d: %s", step, instruction);
    if (op && op->yes) {
        model_note("answered done (--yes)");
        snprintf(how, size, "done: --yes, %s", now);
        return RIG_OPERATOR_DONE;
    }
    char a[256];
    if (op && op->f) {
        if (!read_answer(op->f, a, sizeof a)) {
            snprintf(how, size, "--operator-input %s: no answer left (end of file after line %d)", op->path,
                     op->line);
            return RIG_OPERATOR_PAUSE;
        }
        op->line++;
        if (is_done(a)) {
            model_note("answered done (--operator-input %s:%d)", op->path, op->line);
            snprintf(how, size, "done: --operator-input %s:%d, %s", op->path, op->line, now);
            return RIG_OPERATOR_DONE;
        }
        if (is_pause(a)) {
            snprintf(how, size, "--operator-input %s:%d answered '%s'", op->path, op->line, a);
            return RIG_OPERATOR_PAUSE;
        }
        return rig_fail(RIG_ERR_INVALID, "%s:%d: '%s' is not an operator answer (empty, done, y or yes: done; q, "
                        "pause or stop: pause)", op->path, op->line, a);
    }
    if (!isatty(STDIN_FILENO)) {
        snprintf(how, size, "stdin is not a terminal (no --yes, no --operator-input)");
        return RIG_OPERATOR_PAUSE;
    }
    for (;;) {
        // the prompt: a progress line stays open on a terminal, the answer is typed after it
        model_progress("press Enter when done, q to pause: ");
        errno = 0;
        bool got = read_answer(stdin, a, sizeof a);
        int read_errno = errno;
        model_progress_end();
        if (!got) {
            snprintf(how, size, "%s",
                     read_errno == EINTR ? "interrupted (Ctrl-C) at the prompt" : "end of input on the terminal");
            clearerr(stdin);
            return RIG_OPERATOR_PAUSE;
        }
        model_utc_text(model_realtime_s(), now);
        if (is_done(a)) {
            snprintf(how, size, "done: terminal, %s", now);
            return RIG_OPERATOR_DONE;
        }
        if (is_pause(a)) {
            snprintf(how, size, "the operator answered '%s' on the terminal", a);
            return RIG_OPERATOR_PAUSE;
        }
        model_note("'%s' is not an answer: Enter (or done, y, yes) when done, q (or pause, stop) to pause", a);
    }
}
