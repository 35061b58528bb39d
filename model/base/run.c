// model/base/run.c — running an outside tool (mrcal's and mrgingham's
// programs, Python helpers) and keeping what it said.
#include <glib.h>
#include <stdio.h>
#include <string.h>
#include <sys/wait.h>

#include "model/internal.h"

int model_run_tool(const char *cwd, char *const *argv, const char *log_path, char **out, const char *install_hint)
{
    GError *err = NULL;
    char *so = NULL, *se = NULL;
    gint status = 0;
    if (out) *out = NULL;
    fflush(stdout);
    fflush(stderr);
    if (!g_spawn_sync(cwd, (char **)argv, NULL, G_SPAWN_SEARCH_PATH, NULL, NULL, &so, &se, &status, &err)) {
        model_error_set(argv[0], 0, "cannot run: %s%s%s%s", err ? err->message : "?", install_hint ? " (" : "",
                        install_hint ? install_hint : "", install_hint ? ")" : "");
        if (err) g_error_free(err);
        return -1;
    }
    if (log_path) {
        FILE *f = fopen(log_path, "w");
        if (f) {
            fprintf(f, "# %s", argv[0]);
            for (int i = 1; argv[i]; i++) fprintf(f, " '%s'", argv[i]);
            fprintf(f, "\n# (in %s)\n# stdout:\n%s\n# stderr:\n%s\n", cwd ? cwd : ".", so ? so : "", se ? se : "");
            fclose(f);
        }
    }
    int rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    if (rc != 0) {
        size_t n = se ? strlen(se) : 0;
        model_error_set(argv[0], 0, "exit status %d; its last messages:\n%s", rc, se ? se + (n > 1200 ? n - 1200 : 0)
                                                                                   : "(none)");
    }
    if (out) *out = so;
    else g_free(so);
    g_free(se);
    return rc;
}
