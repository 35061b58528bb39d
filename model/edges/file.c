// model/edges/file.c — a scene's predicted edges for a camera and lamps
// (`refl edges`'s work): the inputs loaded and hashed, the edges predicted,
// the table printed, and the JSON written with units and provenance.
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/base/report.h"
#include "model/internal.h"

struct model_edges_file {
    model_inputs_t in;
    model_input_t  inputs[4];
    model_edges_t *edges;
    double         time_s;
};

void model_edges_file_free(model_edges_file_t *f)
{
    if (!f) return;
    model_edges_free(f->edges);
    model_inputs_free(&f->in);
    free(f);
}

model_edges_file_t *model_edges_file_predict(const model_edges_file_opts_t *o)
{
    model_edges_file_t *f = calloc(1, sizeof *f);
    if (!f) {
        MODEL_FAIL("out of memory");
        return NULL;
    }
    const model_input_t inputs[4] = { { "scene", o->scene, "" }, { "camera", o->camera, "" },
                                      { "lamps", o->lamps, "" }, { "materials", o->materials, "" } };
    memcpy(f->inputs, inputs, sizeof inputs);
    if (!model_inputs_load(&f->in, o->scene, o->camera, o->lamps, o->materials, o->planarity_tol_mm, o->scene_unit_mm,
                           o->turntable_deg) ||
        !model_inputs_hash(f->inputs, 4)) {
        model_edges_file_free(f);
        return NULL;
    }
    double t0 = model_now_s();
    f->edges = model_edges_predict(f->in.scene, f->in.tracer, f->in.cam, f->in.lamps, f->in.resolved, &o->shading,
                                   o->feature_angle_deg);
    f->time_s = model_now_s() - t0;
    if (!f->edges) {
        model_edges_file_free(f);
        return NULL;
    }
    return f;
}

static json_t *json_vec2(const double q[2]) { return json_pack("[f,f]", q[0], q[1]); }
static json_t *json_vec3(model_vec3_t p) { return json_pack("[f,f,f]", p.x, p.y, p.z); }

static json_t *json_lamp_list(const model_lamps_t *lamps, uint32_t bits)
{
    json_t *a = json_array();
    for (int i = 0; i < lamps->n && i < 32; i++)
        if (bits & (1u << i)) json_array_append_new(a, json_string(lamps->lamps[i].name));
    return a;
}

static void lamp_letters(const model_lamps_t *lamps, uint32_t bits, char *out, size_t size)
{
    size_t n = 0;
    out[0] = 0;
    for (int i = 0; i < lamps->n && i < 32 && n + 1 < size; i++)
        n += (size_t)snprintf(out + n, size - n, "%s", (bits & (1u << i)) ? "1" : ".");
    if (!lamps->n) snprintf(out, size, "-");
}

void model_edges_file_print(FILE *out, const model_edges_file_t *f, const model_edges_file_opts_t *o)
{
    const model_vec3_t *V = f->in.scene->vertices;
    const model_lamps_t *lamps = f->in.lamps;
    const model_edges_t *E = f->edges;
    int nseg = 0, nvis = 0;
    fprintf(out, "refl edges: %s, camera %s, %d lamps (", o->scene, o->camera, lamps->n);
    for (int i = 0; i < lamps->n; i++) fprintf(out, "%s%s", i ? " " : "", lamps->lamps[i].name);
    fprintf(out, ")\n");
    fprintf(out, "%4s %-38s %-9s %-29s %7s %-9s %8s %8s %8s\n", "edge", "3D end points (mm, rig frame)", "faces",
            "image end points (px)", "len px", "lit 0|1", "P0 DN", "P1 DN", "P0-P1");
    for (int i = 0; i < E->nedges; i++) {
        const model_edge_t *e = &E->edges[i];
        if (e->nsegments) nvis++;
        for (int s = 0; s < e->nsegments; s++, nseg++) {
            const model_edge_segment_t *g = &e->segments[s];
            char ends3[96], faces[32], endsq[48], lit0[40], lit1[40], lit[84];
            snprintf(ends3, sizeof ends3, "(%.5g,%.5g,%.5g)-(%.5g,%.5g,%.5g)", V[e->v0].x, V[e->v0].y, V[e->v0].z,
                     V[e->v1].x, V[e->v1].y, V[e->v1].z);
            if (e->face_b >= 0) snprintf(faces, sizeof faces, "%d/%d", e->face_a, e->face_b);
            else snprintf(faces, sizeof faces, "%d/-", e->face_a);
            snprintf(endsq, sizeof endsq, "(%.1f,%.1f)-(%.1f,%.1f)", g->q0[0], g->q0[1], g->q1[0], g->q1[1]);
            lamp_letters(lamps, g->lit_side[0], lit0, sizeof lit0);
            lamp_letters(lamps, g->lit_side[1], lit1, sizeof lit1);
            snprintf(lit, sizeof lit, "%s|%s", lit0, lit1);
            fprintf(out, "%4d %-38s %-9s %-29s %7.1f %-9s %8.1f %8.1f %8.1f\n", i, ends3, faces, endsq, g->length_px,
                    lit, g->P_side[0], g->P_side[1], g->contrast);
        }
    }
    fprintf(out, "%d edges, %d with visible segments, %d segments (%.2f s)\n", E->nedges, nvis, nseg, f->time_s);
}

// The edges as JSON: each with its segments, the lamps lighting each side.
static json_t *edges_json(const model_edges_file_t *f)
{
    const model_vec3_t *V = f->in.scene->vertices;
    const model_edges_t *E = f->edges;
    json_t *edges = json_array();
    for (int i = 0; i < E->nedges; i++) {
        const model_edge_t *e = &E->edges[i];
        json_t *segs = json_array();
        for (int s = 0; s < e->nsegments; s++) {
            const model_edge_segment_t *g = &e->segments[s];
            json_array_append_new(segs, json_pack(
                "{s:o, s:o, s:f, s:[f,f], s:f, s:[i,i], s:[o,o]}",
                "q0_px", json_vec2(g->q0), "q1_px", json_vec2(g->q1), "length_px", g->length_px,
                "P_side_dn", g->P_side[0], g->P_side[1], "contrast_dn", g->contrast,
                "face_side", g->face_side[0], g->face_side[1],
                "lit_side", json_lamp_list(f->in.lamps, g->lit_side[0]), json_lamp_list(f->in.lamps, g->lit_side[1])));
        }
        json_array_append_new(edges, json_pack(
            "{s:i, s:[i,i], s:o, s:o, s:i, s:o, s:f, s:o}", "id", i, "vertices", e->v0, e->v1,
            "p0_mm", json_vec3(V[e->v0]), "p1_mm", json_vec3(V[e->v1]), "face_a", e->face_a,
            "face_b", e->face_b >= 0 ? json_integer(e->face_b) : json_null(), "dihedral_deg", e->dihedral_deg,
            "segments", segs));
    }
    return edges;
}

bool model_edges_file_write_json(const model_edges_file_t *f, const model_edges_file_opts_t *o, const char *path)
{
    char date[40];
    model_utc_text(model_realtime_s(), date);
    char *conv = model_material_conventions(f->in.scene, f->in.resolved);
    json_t *prov = json_pack("{s:s, s:s, s:s, s:[]}", "refl_version", REFL_VERSION, "date_utc", date,
                             "command_line", o->command_line ? o->command_line : "", "inputs");
    for (int i = 0; i < 4; i++)
        json_array_append_new(json_object_get(prov, "inputs"),
                              json_pack("{s:s, s:s, s:s}", "role", f->inputs[i].role, "path", f->inputs[i].path,
                                        "sha256", f->inputs[i].sha256));
    json_t *lamps = json_array();
    for (int i = 0; i < f->in.lamps->n; i++) json_array_append_new(lamps, json_string(f->in.lamps->lamps[i].name));
    json_t *root = json_pack(
        "{s:s, s:{s:s, s:s, s:s, s:s, s:s, s:s, s:s}, s:s, s:s, s:s, s:{s:f, s:f, s:f, s:f, s:f, s:f}, s:s, s:o, "
        "s:i, s:i, s:o, s:o}",
        "description", "refl edges: visible image segments of the scene's edges, lighting per side, predicted contrast",
        "units",
        "p0_mm, p1_mm", "mm, world = rig frame",
        "q0_px, q1_px, length_px", "pixels (" MODEL_PIXEL_CONV ")",
        "P_side_dn, contrast_dn", MODEL_UNITS_P "; direct term only: Pa + kc * g * sum_i V_i I_i R_i / d_i^2",
        "face_a, face_b, face_side", "index into the scene's faces, 0-based (the file's face number - 1); -1 = background",
        "vertices", "indices into the scene's vertices, 0-based (the file's vertex number - 1)",
        "lit_side", "names of the lamps with V > 0.5 on at least half the side's sample points",
        "dihedral_deg", "angle between the two faces' normals, deg (0 for a boundary edge)",
        "side_convention", "side 0 is 2 px to the right of q0 -> q1 in the displayed image (y down), side 1 2 px to "
        "the left; contrast = P_side[0] - P_side[1]",
        "pixel_convention", MODEL_PIXEL_CONV, "frames", MODEL_FRAMES_TEXT,
        "options", "kc", o->shading.kc, "offset_dn", o->shading.Pa, "feature_angle_deg", o->feature_angle_deg,
        "turntable_deg", o->turntable_deg, "planarity_tol_mm", o->planarity_tol_mm,
        "scene_unit_mm", o->scene_unit_mm ? o->scene_unit_mm : 1,
        "materials", conv, "provenance", prov,
        "image_width", model_camera_width(f->in.cam), "image_height", model_camera_height(f->in.cam),
        "lamps", lamps, "edges", edges_json(f));
    g_free(conv);
    bool ok = root != NULL;
    if (ok) model_json_set_format(root, "refl-edges", 1);
    if (!ok) MODEL_FAIL("cannot build the JSON document");
    if (ok && json_dump_file(root, path, JSON_INDENT(1) | JSON_REAL_PRECISION(10)) != 0) {
        model_error(path, 0, "cannot write the JSON file: check the directory exists and is writable");
        ok = false;
    }
    json_decref(root);
    return ok;
}
