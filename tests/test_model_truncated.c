// tests/test_model_truncated.c — every example file refl reads, cut short, read by its library reader
//
// Each file of examples/ (camera models, rig, truth, lamps, materials, sensor
// and plan INI files, D3D scenes, reflectance CSVs) is cut at up to 1000 points
// (every byte of a file of at most 1000 bytes, else 1000 points spread over
// it; a virtual rig truth file, whose check loads its camera model and scenes,
// at 40) and the cut text (an exact-size allocation) is read in-process by the
// reader refl uses for it: no crash, and each outcome is a successful parse or
// an error naming the file. The whole file reads. The .cameramodel checker's
// own errors are tested below (the file and the line named).
#include <dirent.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "calib/calib.h"
#include "model/cameramodel.h"
#include "model/model.h"
#include "rig/lab.h"
#include "rig/rig.h"
#include "rig/session/session.h"
#include "rig/virtual/virtual.h"
#include "tests/test.h"

typedef enum { R_CAMERAMODEL, R_D3D, R_PLAN, R_RIG, R_TRUTH, R_LAMPS, R_MATERIALS, R_SENSOR, R_WHITE, R_LAB } reader_t;

static bool read_as(reader_t r, const char *text, size_t n, const char *name, const char *examples)
{
    switch (r) {
    case R_CAMERAMODEL: {
        model_camera_t *c = model_camera_parse(text, n, name);
        model_camera_free(c);
        return c != NULL;
    }
    case R_D3D: {
        model_scene_t *s = model_scene_parse_d3d(text, n, name, NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case R_PLAN: {
        rig_plan_t *p = rig_plan_parse(text, n, name);
        rig_plan_free(p);
        return p != NULL;
    }
    case R_RIG: return rig_config_parse(text, n, name) == 0;
    case R_LAB: {
        rig_lab_t *l = rig_lab_parse(text, n, name);
        rig_lab_free(l);
        return l != NULL;
    }
    case R_TRUTH: return rig_virtual_check_truth(text, n, name, examples) == 0;
    case R_LAMPS: {
        model_lamps_t *l = model_lamps_parse(text, n, name);
        model_lamps_free(l);
        return l != NULL;
    }
    case R_MATERIALS: {
        model_materials_t *m = model_materials_parse(text, n, name);
        model_materials_free(m);
        return m != NULL;
    }
    case R_SENSOR: {
        model_sensor_t s;
        return model_sensor_parse(text, n, name, &s);
    }
    default: {
        calib_white_table_t *t = calib_white_table_parse(text, n, name);
        calib_white_table_free(t);
        return t != NULL;
    }
    }
}

static bool ends_with(const char *s, const char *tail)
{
    size_t a = strlen(s), b = strlen(tail);
    return a >= b && !strcmp(s + a - b, tail);
}

// The reader of an example file by its name; false for a file refl does not read.
static bool reader_of(const char *dir, const char *f, reader_t *r)
{
    if (ends_with(f, ".cameramodel")) *r = R_CAMERAMODEL;
    else if (ends_with(f, ".d3d")) *r = R_D3D;
    else if (ends_with(f, ".csv")) *r = R_WHITE;
    else if (strstr(dir, "plans") && ends_with(f, ".ini")) *r = R_PLAN;
    else if (!strncmp(f, "virtual-truth", 13)) *r = R_TRUTH;
    else if (!strcmp(f, "lamps.ini")) *r = R_LAMPS;
    else if (!strcmp(f, "materials.ini")) *r = R_MATERIALS;
    else if (!strcmp(f, "sensor.ini")) *r = R_SENSOR;
    else if (ends_with(f, ".ini")) *r = R_RIG;
    else return false;
    return true;
}

// Every cut of one file; counts into *cuts, *ok. False when a check failed.
static bool cut_file(const char *dir, const char *f, const char *examples, long *cuts, long *ok)
{
    reader_t r;
    if (!reader_of(dir, f, &r)) return true;
    char path[PATH_MAX];
    snprintf(path, sizeof path, "%s/%s", dir, f);
    size_t len = 0;
    char *text = model_read_file(path, &len);
    if (r == R_RIG && text && (!strncmp(text, "[lab]", 5) || strstr(text, "\n[lab]"))) r = R_LAB;   // a lab file
    const char *name = r == R_TRUTH ? f : path;   // a truth file's paths resolve in examples/
    CHECK_MSG(text != NULL, "%s", model_last_error());
    if (!text) return false;
    bool good = true;
    CHECK_MSG(read_as(r, text, len, name, examples), "the whole %s: %s", path, model_last_error());
    size_t most = r == R_TRUTH ? 40 : 1000;   // a truth check loads its camera model and scenes (0.1 s)
    size_t npts = len + 1 <= most ? len + 1 : most;
    for (size_t k = 0; k < npts && good; k++) {
        size_t cut = npts == len + 1 ? k : (size_t)((double)k * (double)len / (double)(npts - 1));
        char *part = malloc(cut ? cut : 1);
        if (!part) break;
        memcpy(part, text, cut);
        model_error(NULL, 0, "-");   // a reader that fails must leave its own message
        bool parsed = read_as(r, part, cut, name, examples);
        free(part);
        (*cuts)++;
        *ok += parsed;
        if (!parsed && !strstr(model_last_error(), name)) {
            CHECK_MSG(false, "%s cut at %zu of %zu bytes: the error does not name the file: %s", path, cut, len,
                      model_last_error());
            good = false;
        }
    }
    free(text);
    return good;
}

TEST(truncated_examples_read_or_fail_cleanly)
{
    char examples[PATH_MAX], sub[2][PATH_MAX + 16];
    snprintf(examples, sizeof examples, "%s/examples", test_srcdir());
    snprintf(sub[0], sizeof sub[0], "%s/examples/plans", test_srcdir());
    snprintf(sub[1], sizeof sub[1], "%s/examples/samples", test_srcdir());
    const char *dirs[] = { examples, sub[0], sub[1] };
    bool quiet = model_error_quiet(true);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    long cuts = 0, ok = 0;
    int files = 0;
    for (size_t d = 0; d < 3; d++) {
        struct dirent **ents = NULL;
        int n = scandir(dirs[d], &ents, NULL, alphasort);
        CHECK_MSG(n > 0, "%s: no files", dirs[d]);
        for (int i = 0; i < n; i++) {
            long before = cuts;
            if (ents[i]->d_name[0] != '.') (void)cut_file(dirs[d], ents[i]->d_name, examples, &cuts, &ok);
            files += cuts > before;
            free(ents[i]);
        }
        free(ents);
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    model_error_quiet(quiet);
    printf("truncated examples: %d files, %ld cut points, %ld of them parsed, %.1f s\n", files, cuts, ok,
           (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec));
    CHECK(files >= 30);
    CHECK(cuts >= 20000);
}

static const char *cm_error(const char *name, const char *text)
{
    bool quiet = model_error_quiet(true);
    mrcal_cameramodel_t *m = model_cameramodel_parse(text, strlen(text), name);
    model_error_quiet(quiet);
    if (!m) return model_last_error();
    mrcal_free_cameramodel(&m);
    return "(parsed)";
}

#define CM_HEAD "{ 'lensmodel': 'LENSMODEL_PINHOLE',\n  'intrinsics': [1000, 1000, 320, 240],\n"
#define CM_TAIL "  'extrinsics': [0, 0, 0, 0, 0, 0],\n  'imagersize': [640, 480] }\n"

// The checker's findings name the file and the line; what mrcal reads parses.
TEST(cameramodel_check_names_file_and_line)
{
    CHECK_CONTAINS(cm_error("a.cameramodel", CM_HEAD CM_TAIL), "(parsed)");
    CHECK_CONTAINS(cm_error("a.cameramodel", "# only a comment, no line break at the end\n" CM_HEAD CM_TAIL
                            "# trailing comment without a line break"), "(parsed)");
    CHECK_CONTAINS(cm_error("a.cameramodel", "{ 'lensmodel': b'LENSMODEL_PINHOLE', 'other': [[1, 2], (3e-5,)],"
                            " 'name': \"x\", 'n': -4.5e+3,\n  'intrinsics': (1000, 1000., .5e3, 240,),\n" CM_TAIL),
                   "(parsed)");
    // cut inside a comment within the dictionary: where mrcal's parser reads past the end
    const char *cut = cm_error("cut.cameramodel", CM_HEAD "  # a comment cut sho");
    CHECK_CONTAINS(cut, "cut.cameramodel:3:");
    CHECK_CONTAINS(cut, "cut short");
    CHECK_CONTAINS(cm_error("c.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0,"), "c.cameramodel:3:");
    CHECK_CONTAINS(cm_error("c.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0,"), "list opened on line 3");
    CHECK_CONTAINS(cm_error("s.cameramodel", "{ 'lensmodel': 'LENSMODEL_PIN"), "s.cameramodel:1:");
    CHECK_CONTAINS(cm_error("s.cameramodel", "{ 'lensmodel': 'LENSMODEL_PIN"), "inside a string");
    CHECK_CONTAINS(cm_error("k.cameramodel", "{ 'lensmodel': 'LENSMODEL_OPENCV4',\n  'intrinsics': [1000, 1000, 320, "
                            "240],\n" CM_TAIL), "k.cameramodel:2: not a readable .cameramodel: 'intrinsics': 4 numbers, "
                   "lens model LENSMODEL_OPENCV4 has 8 parameters");
    CHECK_CONTAINS(cm_error("o.cameramodel", "{ 'intrinsics': [1, 2, 3, 4],\n 'lensmodel': 'LENSMODEL_PINHOLE',\n"
                            CM_TAIL), "'intrinsics' before 'lensmodel'");
    CHECK_CONTAINS(cm_error("d.cameramodel", CM_HEAD "  'intrinsics': [1000, 1000, 320, 240],\n" CM_TAIL),
                   "d.cameramodel:3: not a readable .cameramodel: 'intrinsics' appears twice (first on line 2)");
    CHECK_CONTAINS(cm_error("n.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 1e999],\n  'imagersize': "
                            "[640, 480] }\n"), "1e999 is not a finite number");
    CHECK_CONTAINS(cm_error("n.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, nan],\n  'imagersize': "
                            "[640, 480] }\n"), "expected a decimal number, found 'n'");
    CHECK_CONTAINS(cm_error("i.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 0],\n  'imagersize': "
                            "[640.0, 480] }\n"), "i.cameramodel:4:");
    CHECK_CONTAINS(cm_error("i.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 0],\n  'imagersize': "
                            "[640.0, 480] }\n"), "unsigned integer");
    CHECK_CONTAINS(cm_error("i.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 0],\n  'imagersize': "
                            "[0, 480] }\n"), "width and height must be 1..65535");
    CHECK_CONTAINS(cm_error("b.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 0],\n  'imagersize': "
                            "[640, 480] }\n}"), "b.cameramodel:5: not a readable .cameramodel: '}' after the");
    CHECK_CONTAINS(cm_error("b.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 0]]\n"),
                   "expected ',' or '}' after the value of 'extrinsics', found ']'");
    CHECK_CONTAINS(cm_error("m.cameramodel", CM_HEAD "  'extrinsics': [0, 0, 0, 0, 0, 0] }\n"),
                   "the key 'imagersize' is missing");
    CHECK_CONTAINS(cm_error("l.cameramodel", "{ 'lensmodel': 'LENSMODEL_SPLINED_STEREOGRAPHIC_order=9_Nx=2_Ny=2_"
                            "fov_x_deg=80',\n" CM_TAIL), "a splined model needs order 2 or 3");
    CHECK_CONTAINS(cm_error("l.cameramodel", "{ 'lensmodel': 'LENSMODEL_NONSENSE',\n" CM_TAIL),
                   "'LENSMODEL_NONSENSE' is not a lens model mrcal knows");
    char bin[] = "{ 'lensmodel': 'LENSMODEL_PINHOLE',\n\n x";
    bool quiet = model_error_quiet(true);
    bin[sizeof bin - 3] = '\0';
    CHECK(!model_cameramodel_check(bin, sizeof bin - 1, "z.cameramodel"));
    model_error_quiet(quiet);
    CHECK_CONTAINS(model_last_error(), "z.cameramodel:3:");
    CHECK_CONTAINS(model_last_error(), "NUL byte");
}

// refl calib export and refl edges, given a camera model cut at 300 bytes: the
// error names the file, no crash (mrcal's parser alone crashes on it).
TEST(cameramodel_truncated_commands)
{
    char src[PATH_MAX];
    snprintf(src, sizeof src, "%s/examples/camera.cameramodel", test_srcdir());
    size_t len = 0;
    char *text = model_read_file(src, &len);
    CHECK(text && len > 300);
    if (!text || len <= 300) return;
    text[300] = '\0';
    const char *cut = test_write("cut.cameramodel", text);
    free(text);
    char *err = NULL;
    int rc = test_refl_run(60, NULL, &err, "calib", "export", cut, "--format", "opencv", "-o",
                           test_path("out.yaml"), NULL);
    CHECK_MSG(rc == 1, "refl calib export: exit %d: %s", rc, err ? err : "");
    CHECK_CONTAINS(err, cut);
    CHECK_CONTAINS(err, "cut short");
    free(err);
    err = NULL;
    char scene[PATH_MAX], lamps[PATH_MAX], mats[PATH_MAX];
    snprintf(scene, sizeof scene, "%s/examples/t_stiffener.d3d", test_srcdir());
    snprintf(lamps, sizeof lamps, "%s/examples/lamps.ini", test_srcdir());
    snprintf(mats, sizeof mats, "%s/examples/materials.ini", test_srcdir());
    rc = test_refl_run(60, NULL, &err, "edges", scene, "--camera", cut, "--lamps", lamps, "--materials", mats, NULL);
    CHECK_MSG(rc == 1, "refl edges: exit %d: %s", rc, err ? err : "");
    CHECK_CONTAINS(err, cut);
    CHECK_CONTAINS(err, "cut short");
    free(err);
}
