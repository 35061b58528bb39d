// model/scene/workpiece.c — the reference workpiece of thesis ch. 6 as D3D text: a
// base plate with a welded stiffener (T, I or none), and the corruptions the
// verification is tested with (shift, rotation, height). See model.h.
#define _GNU_SOURCE
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

model_stiffener_t model_stiffener_default(void)
{
    return (model_stiffener_t){
        .kind = MODEL_STIFFENER_T,
        .plate_mm = { 400, 300, 10 },
        .web_thickness_mm = 8,
        .length_mm = 260,
        .height_mm = 88,
        .flange_width_mm = 60,
        .flange_thickness_mm = 8,
        .height_scale = 1,
        .plate_material = "plywood",
        .stiffener_material = "painted_steel",
    };
}

const char *model_stiffener_kind_name(model_stiffener_kind_t k)
{
    return k == MODEL_STIFFENER_T ? "T" : k == MODEL_STIFFENER_I ? "I" : k == MODEL_STIFFENER_NONE ? "none" : "?";
}

int model_stiffener_kind_from_name(const char *s)
{
    if (!s) return -1;
    if (!strcasecmp(s, "T")) return MODEL_STIFFENER_T;
    if (!strcasecmp(s, "I")) return MODEL_STIFFENER_I;
    if (!strcasecmp(s, "none")) return MODEL_STIFFENER_NONE;
    return -1;
}

typedef struct {
    char  *buf;
    size_t len;
    FILE  *f;
} text_t;

// A box's vertices (x0..x1, y0..y1, z0..z1) moved by the stiffener's pose;
// first vertex number `base`. Order: bottom 4 (counter-clockwise from above
// starting at (x0,y0)), then top 4.
static void box_vertices(FILE *f, int base, double x0, double x1, double y0, double y1, double z0, double z1,
                         double c, double s, double tx, double ty)
{
    const double xy[4][2] = { { x0, y0 }, { x1, y0 }, { x1, y1 }, { x0, y1 } };
    for (int level = 0; level < 2; level++)
        for (int k = 0; k < 4; k++) {
            double x = xy[k][0], y = xy[k][1];
            fprintf(f, "%4d  %.9g %.9g %.9g\n", base + level * 4 + k, c * x - s * y + tx, s * x + c * y + ty,
                    level ? z1 : z0);
        }
}

// The faces of a box whose vertices start at `b` (as box_vertices), outward
// normals by the right-hand rule; bottom/top left out when asked.
static void box_faces(FILE *f, int b, bool bottom, bool top, const char *what)
{
    if (bottom) fprintf(f, "# %s bottom\n%d %d %d %d.\n", what, b, b + 3, b + 2, b + 1);
    if (top) fprintf(f, "# %s top\n%d %d %d %d.\n", what, b + 4, b + 5, b + 6, b + 7);
    fprintf(f, "# %s -y\n%d %d %d %d.\n", what, b, b + 1, b + 5, b + 4);
    fprintf(f, "# %s +x\n%d %d %d %d.\n", what, b + 1, b + 2, b + 6, b + 5);
    fprintf(f, "# %s +y\n%d %d %d %d.\n", what, b + 2, b + 3, b + 7, b + 6);
    fprintf(f, "# %s -x\n%d %d %d %d.\n", what, b + 3, b, b + 4, b + 7);
}

char *model_stiffener_d3d(const model_stiffener_t *p)
{
    const double px = p->plate_mm[0], py = p->plate_mm[1], pz = p->plate_mm[2];
    double H = p->height_mm * p->height_scale;
    if (!(px > 0 && py > 0 && pz > 0 && p->web_thickness_mm > 0 && p->length_mm > 0 && H > 0 &&
          p->length_mm <= py && p->flange_width_mm >= p->web_thickness_mm && p->flange_thickness_mm > 0 &&
          (p->kind != MODEL_STIFFENER_T || p->flange_thickness_mm < H) && p->plate_material &&
          p->stiffener_material && p->plate_material[0] && p->stiffener_material[0])) {
        model_error(NULL, 0, "stiffener workpiece: sizes must be positive, the length within the plate's %g mm, "
                    "the flange wider than the web and thinner than the stiffener's height, materials named", py);
        return NULL;
    }
    text_t t = { 0 };
    t.f = open_memstream(&t.buf, &t.len);
    if (!t.f) {
        MODEL_FAIL("open_memstream failed");
        return NULL;
    }
    FILE *f = t.f;
    double ang = p->rotate_deg * M_PI / 180, c = cos(ang), s = sin(ang);
    double w = p->web_thickness_mm / 2, L = p->length_mm / 2, fw = p->flange_width_mm / 2;
    double tz = p->flange_thickness_mm;
    fprintf(f, "# %s-stiffener workpiece (refl model_stiffener_d3d): %s\n", model_stiffener_kind_name(p->kind),
            p->kind == MODEL_STIFFENER_NONE ? "base plate only" : "base plate with a welded stiffener");
    fprintf(f, "# Format: D3D (Ammeraal 1988) with '@material NAME' lines; faces counter-clockwise seen from\n"
               "# outside. Units: mm. Frame: rig frame, origin at the turntable top centre, z up.\n");
    fprintf(f, "# Plate %g x %g x %g (z 0..%g, %s).", px, py, pz, pz, p->plate_material);
    if (p->kind == MODEL_STIFFENER_T)
        fprintf(f, " Web %g thick, %g long, flange %g x %g; top at z %.6g (%s).", p->web_thickness_mm,
                p->length_mm, p->flange_width_mm, tz, pz + H, p->stiffener_material);
    else if (p->kind == MODEL_STIFFENER_I)
        fprintf(f, " Flat bar %g thick, %g long, top at z %.6g (%s).", p->web_thickness_mm, p->length_mm, pz + H,
                p->stiffener_material);
    fprintf(f, "\n# Stiffener pose: shifted (%g, %g) mm, rotated %g deg about z through its centre, height x %g.\n\n",
            p->shift_mm[0], p->shift_mm[1], p->rotate_deg, p->height_scale);
    box_vertices(f, 1, -px / 2, px / 2, -py / 2, py / 2, 0, pz, 1, 0, 0, 0);
    if (p->kind == MODEL_STIFFENER_T) {
        box_vertices(f, 9, -w, w, -L, L, pz, pz + H - tz, c, s, p->shift_mm[0], p->shift_mm[1]);
        box_vertices(f, 17, -fw, fw, -L, L, pz + H - tz, pz + H, c, s, p->shift_mm[0], p->shift_mm[1]);
    } else if (p->kind == MODEL_STIFFENER_I) {
        box_vertices(f, 9, -w, w, -L, L, pz, pz + H, c, s, p->shift_mm[0], p->shift_mm[1]);
    }
    fprintf(f, "\nFaces:\n@material %s\n", p->plate_material);
    box_faces(f, 1, true, true, "plate");
    if (p->kind != MODEL_STIFFENER_NONE) {
        fprintf(f, "@material %s\n", p->stiffener_material);
        // the web's bottom stands on the plate; a T's web top is under the flange
        box_faces(f, 9, false, p->kind == MODEL_STIFFENER_I, p->kind == MODEL_STIFFENER_T ? "web" : "flat bar");
        if (p->kind == MODEL_STIFFENER_T) box_faces(f, 17, true, true, "flange");
    }
    if (fclose(f) != 0) {
        free(t.buf);
        MODEL_FAIL("writing the workpiece text failed");
        return NULL;
    }
    return t.buf;
}

model_scene_t *model_stiffener_scene(const model_stiffener_t *p, const char *name)
{
    char *text = model_stiffener_d3d(p);
    if (!text) return NULL;
    model_scene_t *sc = model_scene_parse_d3d(text, strlen(text), name ? name : "(stiffener workpiece)", NULL);
    free(text);
    return sc;
}
