// model/scene/load.c — a scene file loaded by its format (STL and PLY by
// content, D3D and OBJ by name), the unit of its coordinates (--units), and
// the warning for a mesh small enough to be in metres.
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
// Units, files

bool model_units_parse(const char *s, double *unit_mm)
{
    static const struct { const char *n; double mm; } u[] = { { "mm", 1 }, { "m", 1000 }, { "in", 25.4 } };
    for (size_t i = 0; s && i < sizeof u / sizeof u[0]; i++)
        if (!strcmp(s, u[i].n)) {
            *unit_mm = u[i].mm;
            return true;
        }
    return false;
}

// A mesh whose whole extent is under 5 mm with no unit given was probably
// drawn in metres (or inches): say so.
static void units_warning(model_scene_t *s, const model_scene_options_t *opt)
{
    if (opt && opt->unit_mm != 0) return;
    double lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
    for (int i = 0; i < s->nvertices; i++) {
        const double p[3] = { s->vertices[i].x, s->vertices[i].y, s->vertices[i].z };
        for (int k = 0; k < 3; k++) lo[k] = fmin(lo[k], p[k]), hi[k] = fmax(hi[k], p[k]);
    }
    double ext = fmax(fmax(hi[0] - lo[0], hi[1] - lo[1]), hi[2] - lo[2]);
    if (!(ext < MODEL_SCENE_SMALL_MM)) return;
    snprintf(s->warning, sizeof s->warning, "the whole scene spans %.3g mm (the largest side of its bounding box), "
             "read in mm as no --units was given: if its coordinates are metres or inches, give --units m or "
             "--units in", ext);
    model_warning("%s: %s", s->path, s->warning);
}

model_scene_t *model_scene_load(const char *path, const model_scene_options_t *opt)
{
    if (!path) {
        model_error(NULL, 0, "model_scene_load: no path given");
        return NULL;
    }
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    bool d3d = dot && strcasecmp(dot, ".d3d") == 0, obj = dot && strcasecmp(dot, ".obj") == 0;
    bool stl = dot && strcasecmp(dot, ".stl") == 0, ply = dot && strcasecmp(dot, ".ply") == 0;
    size_t len;
    char *text = model_read_file(path, &len);
    if (!text) return NULL;
    // STL and PLY are told by their content (whatever the name); D3D and OBJ by the name.
    model_mesh_format_t mf = model_mesh_format_(text, len, !stl);
    if (mf == MODEL_MESH_PLY) ply = true, stl = false;
    else if (mf != MODEL_MESH_NONE) stl = true, ply = false;
    model_scene_t *s = NULL;
    if (stl || ply) s = stl ? model_scene_parse_stl(text, len, path, opt) : model_scene_parse_ply(text, len, path, opt);
    else if (d3d || obj)
        s = d3d ? model_scene_parse_d3d(text, len, path, opt) : model_scene_parse_obj(text, len, path, opt);
    else
        model_error(path, 0, "unknown scene format%s%s%s: neither STL nor PLY by its content; name a D3D file .d3d "
                    "and an OBJ file .obj", dot ? " '" : " (no extension)", dot ? dot : "", dot ? "'" : "");
    free(text);
    if (s && !d3d) units_warning(s, opt);
    return s;
}
