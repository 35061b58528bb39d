// model/base/notice.c — notes, warnings and progress lines from library code,
// sent to the sink the command chose (stderr by default, named by the command).
#include <glib.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "model/internal.h"

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static char prefix[128] = "refl";
static model_notice_fn sink_fn;
static void *sink_ctx;
static bool progress_open;   // a progress line without its newline is on the terminal

void model_notice_prefix(const char *p)
{
    pthread_mutex_lock(&lock);
    snprintf(prefix, sizeof prefix, "%s", p && *p ? p : "refl");
    pthread_mutex_unlock(&lock);
}

const char *model_notice_prefix_text(void) { return prefix; }

void model_notice_sink(model_notice_fn fn, void *ctx)
{
    pthread_mutex_lock(&lock);
    sink_fn = fn;
    sink_ctx = ctx;
    pthread_mutex_unlock(&lock);
}

// The default sink: "PREFIX: text" lines on stderr; a progress line
// overwrites itself on a terminal.
static void to_stderr(model_notice_kind_t kind, const char *text)
{
    bool tty = isatty(2);
    if (kind == MODEL_NOTICE_PROGRESS_END) {
        if (progress_open) fputc('\n', stderr);
        progress_open = false;
        return;
    }
    if (kind == MODEL_NOTICE_PROGRESS && tty) {
        fprintf(stderr, "\r%s: %s\033[K", prefix, text);
        progress_open = true;
        fflush(stderr);
        return;
    }
    if (progress_open) fputc('\n', stderr);
    progress_open = false;
    const char *w = kind == MODEL_NOTICE_WARNING ? "warning: " : "";
    // the first line carries the prefix; later lines are printed as they are
    const char *nl = strchr(text, '\n');
    if (!nl) {
        fprintf(stderr, "%s: %s%s\n", prefix, w, text);
    } else {
        fprintf(stderr, "%s: %s%.*s\n", prefix, w, (int)(nl - text), text);
        fprintf(stderr, "%s%s", nl + 1, *(nl + 1) && text[strlen(text) - 1] != '\n' ? "\n" : "");
    }
    fflush(stderr);
}

static void emit(model_notice_kind_t kind, const char *fmt, va_list ap)
{
    if (model_error_quiet_global()) return;
    char *text = fmt ? g_strdup_vprintf(fmt, ap) : g_strdup("");
    pthread_mutex_lock(&lock);
    if (sink_fn) sink_fn(sink_ctx, kind, text);
    else to_stderr(kind, text);
    pthread_mutex_unlock(&lock);
    g_free(text);
}

void model_note(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit(MODEL_NOTICE_NOTE, fmt, ap);
    va_end(ap);
}

void model_warning(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit(MODEL_NOTICE_WARNING, fmt, ap);
    va_end(ap);
}

void model_progress(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    emit(MODEL_NOTICE_PROGRESS, fmt, ap);
    va_end(ap);
}

void model_progress_end(void)
{
    if (model_error_quiet_global()) return;
    pthread_mutex_lock(&lock);
    if (sink_fn) sink_fn(sink_ctx, MODEL_NOTICE_PROGRESS_END, "");
    else to_stderr(MODEL_NOTICE_PROGRESS_END, "");
    pthread_mutex_unlock(&lock);
}
