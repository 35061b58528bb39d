// model/base/paths.c — where refl's own files are (its scripts and examples):
// beside a build tree's binary or under an installation's share/refl/.
#define _GNU_SOURCE
#include <glib.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "model/internal.h"
#include "model/base/report.h"

char *model_share_path(const char *dir, const char *name)
{
    GPtrArray *cands = g_ptr_array_new_with_free_func(g_free);
    const char *env = getenv("REFL_SCRIPTS_DIR");
    if (env && *env) {
        if (!strcmp(dir, "scripts")) g_ptr_array_add(cands, g_build_filename(env, name, NULL));
        else g_ptr_array_add(cands, g_build_filename(env, "..", dir, name, NULL));
    }
    char *exe = g_file_read_link("/proc/self/exe", NULL);
    if (exe) {
        char *d = g_path_get_dirname(exe);
        // a build tree: bin/refl, build-x/bin/refl, deeper test builds; an installation: PREFIX/bin/refl
        g_ptr_array_add(cands, g_build_filename(d, "..", dir, name, NULL));
        g_ptr_array_add(cands, g_build_filename(d, "..", "..", dir, name, NULL));
        g_ptr_array_add(cands, g_build_filename(d, "..", "..", "..", dir, name, NULL));
        g_ptr_array_add(cands, g_build_filename(d, "..", "share", "refl", dir, name, NULL));
        g_free(d);
        g_free(exe);
    }
    char *found = NULL;
    for (guint i = 0; i < cands->len && !found; i++)
        if (access(cands->pdata[i], R_OK) == 0) found = g_strdup(cands->pdata[i]);
    if (!found) {
        GString *s = g_string_new(NULL);
        for (guint i = 0; i < cands->len; i++) g_string_append_printf(s, "%s%s", i ? ", " : "", (char *)cands->pdata[i]);
        model_error_set(NULL, 0, "refl's %s/%s is not where it looked (%s); set REFL_SCRIPTS_DIR to refl's scripts/ "
                        "directory", dir, name, cands->len ? s->str : "no place to look");
        g_string_free(s, TRUE);
    }
    g_ptr_array_free(cands, TRUE);
    return found;
}
