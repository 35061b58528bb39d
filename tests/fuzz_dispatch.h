// tests/fuzz_dispatch.h — one fuzz input through one of refl's text parsers.
//
// The first byte selects the parser: 'p' a capture plan (rig_plan_parse),
// 'r' a rig description file (rig_config_parse), 'v' a virtual rig truth file
// (rig_virtual_check_truth), 'i' an image file's bytes (model_image_decode:
// PNG, JPEG, TIFF by content), 'l' an STL scene (model_scene_parse_stl), 'y' a
// PLY scene (model_scene_parse_ply), 'b' an RGL .bsdf tensor file
// (model_brdf_rgl_parse, evaluated once when it parses), 'e' an EMVA 1288
// descriptor (calib_gain_descriptor_parse), 'c' an mrcal .cameramodel
// (model_camera_parse: the text checked, then mrcal's parser; a point
// projected and a pixel unprojected when it parses); any other byte b selects b % 6: 0 D3D scene,
// 1 OBJ scene, 2 INI, 3 materials, 4 lamps, 5 sensor (seeds use '0'..'5'; the
// corpus was written with that rule, which is why the newer parsers have
// letters). The rest of the input is the text (not NUL-terminated, so reads
// past its end are caught by AddressSanitizer).
//
// A truth file names its camera model and scenes relative to its directory:
// the dispatcher checks it as "fuzz-truth.ini" in the directory
// refl_fuzz_parse_in is given; refl_fuzz_parse uses $REFL_FUZZ_EXAMPLES when
// set, else REFL_FUZZ_EXAMPLES_DIR (the fuzz target defines it as the repo's
// examples/ directory), else "examples" (run from the repo's top directory).
//
// Used by the libFuzzer target (tests/fuzz_parsers.c) and by the corpus replay
// test (tests/test_model_corpus.c).
#pragma once

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "calib/gain/gain.h"
#include "model/model.h"
#include "rig/rig.h"

#ifndef REFL_FUZZ_EXAMPLES_DIR
#define REFL_FUZZ_EXAMPLES_DIR "examples"
#endif

enum { REFL_FUZZ_D3D, REFL_FUZZ_OBJ, REFL_FUZZ_INI, REFL_FUZZ_MATERIALS, REFL_FUZZ_LAMPS,
       REFL_FUZZ_SENSOR, REFL_FUZZ_NMOD,   // selected by first byte % REFL_FUZZ_NMOD
       REFL_FUZZ_PLAN = REFL_FUZZ_NMOD, REFL_FUZZ_RIG, REFL_FUZZ_TRUTH, REFL_FUZZ_IMAGE, REFL_FUZZ_STL,
       REFL_FUZZ_PLY, REFL_FUZZ_RGL, REFL_FUZZ_EMVA, REFL_FUZZ_CAMERAMODEL,
       REFL_FUZZ_NPARSERS };

// The parser a first byte selects (REFL_FUZZ_*).
static inline int refl_fuzz_selector(uint8_t b)
{
    switch (b) {
    case 'p': return REFL_FUZZ_PLAN;
    case 'r': return REFL_FUZZ_RIG;
    case 'v': return REFL_FUZZ_TRUTH;
    case 'i': return REFL_FUZZ_IMAGE;
    case 'l': return REFL_FUZZ_STL;
    case 'y': return REFL_FUZZ_PLY;
    case 'b': return REFL_FUZZ_RGL;
    case 'e': return REFL_FUZZ_EMVA;
    case 'c': return REFL_FUZZ_CAMERAMODEL;
    default: return b % REFL_FUZZ_NMOD;
    }
}

// A .cameramodel text through model_camera_parse; when it parses, one point
// projected and the centre pixel unprojected. true when it parsed.
static inline bool refl_fuzz_cameramodel(const char *text, size_t n)
{
    model_camera_t *c = model_camera_parse(text, n, "fuzz.cameramodel");
    if (c) {
        model_vec3_t p = model_camera_centre_world(c), d;
        p.x += 100;
        p.y += 50;
        p.z -= 20;
        double q[2] = { 0.5 * model_camera_width(c), 0.5 * model_camera_height(c) }, qp[2];
        (void)model_camera_project(c, &p, 1, qp);
        (void)model_camera_unproject(c, q, 1, &d);
    }
    model_camera_free(c);
    return c != NULL;
}

// Parse the input with the parser its first byte selects, free the result;
// examples_dir: where a truth file's relative paths resolve.
// Returns true when the parse succeeded; false (with model_last_error() set)
// when the input was rejected, or false with an error for an empty input.
static inline bool refl_fuzz_parse_in(const uint8_t *data, size_t len, const char *examples_dir)
{
    if (len == 0) {
        model_error(NULL, 0, "empty fuzz input (the first byte selects the parser)");
        return false;
    }
    const char *text = (const char *)data + 1;
    size_t n = len - 1;
    switch (refl_fuzz_selector(data[0])) {
    case REFL_FUZZ_PLAN: {
        rig_plan_t *p = rig_plan_parse(text, n, "fuzz-plan.ini");
        bool ok = p != NULL;
        rig_plan_free(p);
        return ok;
    }
    case REFL_FUZZ_RIG:
        return rig_config_parse(text, n, "fuzz-rig.ini") == 0;
    case REFL_FUZZ_TRUTH:
        return rig_virtual_check_truth(text, n, "fuzz-truth.ini", examples_dir) == 0;
    case REFL_FUZZ_IMAGE: {
        int w = 0, h = 0;
        float *px = model_image_decode(text, n, "fuzz-image", MODEL_CHANNEL_LUMA, &w, &h, NULL);
        free(px);
        return px != NULL;
    }
    case REFL_FUZZ_STL: {
        model_scene_t *s = model_scene_parse_stl(text, n, "fuzz.stl", NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case REFL_FUZZ_PLY: {
        model_scene_t *s = model_scene_parse_ply(text, n, "fuzz.ply", NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case REFL_FUZZ_RGL: {
        model_brdf_rgl_t *r = model_brdf_rgl_parse(text, n, "fuzz.bsdf");
        if (r) {   // one evaluation walks every table the parse built
            double w[3] = { 0.2126, 0.7152, 0.0722 }, *cw = w;
            double *all = model_brdf_rgl_channels(r) > 3 ? calloc((size_t)model_brdf_rgl_channels(r), sizeof *all) : NULL;
            if (all) cw = all;
            model_vec3_t wi = { 0.3, 0.1, 0.95 }, wo = { -0.4, 0.2, 0.89 };
            (void)model_brdf_rgl_eval(r, wi, wo, cw);
            free(all);
        }
        model_brdf_rgl_free(r);
        return r != NULL;
    }
    case REFL_FUZZ_EMVA: {
        calib_gain_descriptor_t d;
        bool ok = calib_gain_descriptor_parse(text, n, "fuzz-descriptor.txt", &d);
        if (ok) calib_gain_descriptor_free(&d);
        return ok;
    }
    case REFL_FUZZ_CAMERAMODEL: return refl_fuzz_cameramodel(text, n);
    case REFL_FUZZ_D3D: {
        model_scene_t *s = model_scene_parse_d3d(text, n, "fuzz.d3d", NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case REFL_FUZZ_OBJ: {
        model_scene_t *s = model_scene_parse_obj(text, n, "fuzz.obj", NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case REFL_FUZZ_INI: {
        model_ini_t *ini = model_ini_parse(text, n, "fuzz.ini");
        model_ini_free(ini);
        return ini != NULL;
    }
    case REFL_FUZZ_MATERIALS: {
        model_materials_t *m = model_materials_parse(text, n, "fuzz-materials.ini");
        model_materials_free(m);
        return m != NULL;
    }
    case REFL_FUZZ_LAMPS: {
        model_lamps_t *l = model_lamps_parse(text, n, "fuzz-lamps.ini");
        model_lamps_free(l);
        return l != NULL;
    }
    default: {
        model_sensor_t s;
        return model_sensor_parse(text, n, "fuzz-sensor.ini", &s);
    }
    }
}

static inline bool refl_fuzz_parse(const uint8_t *data, size_t len)
{
    const char *dir = getenv("REFL_FUZZ_EXAMPLES");
    return refl_fuzz_parse_in(data, len, dir && *dir ? dir : REFL_FUZZ_EXAMPLES_DIR);
}

static inline void refl_fuzz_one(const uint8_t *data, size_t len)
{
    (void)refl_fuzz_parse(data, len);
}
