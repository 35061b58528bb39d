// rig/error.c — the RIG_ERR_* codes' names and rig_fail, which records a
// device's message through model_error (see rig/devices.h).
#include <stdarg.h>
#include <stdio.h>

#include "model/model.h"
#include "rig/devices.h"

// ---------------------------------------------------------------------------
// Errors

const char *rig_strerror(int err)
{
    switch (err) {
#define RIG_ERR_CASE_(name, value, desc) case value: return desc;
        RIG_ERR_LIST(RIG_ERR_CASE_)
#undef RIG_ERR_CASE_
    }
    return "unknown error";
}

// The one message store is model_error's (model_last_error): rig keeps none of its own.
int rig_fail(int err, const char *fmt, ...)
{
    char msg[1536];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    // model_error prints unless quiet mode is on, and keeps the message for model_last_error.
    model_error(NULL, 0, "%s", msg);
    return err;
}
