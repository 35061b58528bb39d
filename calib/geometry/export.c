// calib/geometry/export.c — camera models out: OpenCV FileStorage YAML and ROS
// camera_info YAML from a .cameramodel (calib/geometry/export.h has the coefficient
// orders and the models each format can hold).
#include <glib.h>
#include <jansson.h>
#include <string.h>

#include "calib/geometry/export.h"
#include "model/model.h"
#include "model/base/report.h"

bool calib_export_format_from_name(const char *name, calib_export_format_t *out)
{
    if (name && !strcmp(name, "opencv")) *out = CALIB_EXPORT_OPENCV;
    else if (name && !strcmp(name, "ros")) *out = CALIB_EXPORT_ROS;
    else return false;
    return true;
}

// The number of OpenCV distortion coefficients of a lens model mrcal names,
// -1 for a model that is not OpenCV's projection.
static int opencv_ncoeffs(const char *lensmodel)
{
    static const struct { const char *name; int n; } known[] = {
        { "LENSMODEL_PINHOLE", 0 }, { "LENSMODEL_OPENCV4", 4 },   { "LENSMODEL_OPENCV5", 5 },
        { "LENSMODEL_OPENCV8", 8 }, { "LENSMODEL_OPENCV12", 12 },
    };
    for (size_t i = 0; i < sizeof known / sizeof known[0]; i++)
        if (!strcmp(lensmodel, known[i].name)) return known[i].n;
    return -1;
}

// "[ a, b, ... ]" with every number in full precision.
static void list(GString *s, const double *v, int n)
{
    g_string_append(s, "[ ");
    for (int i = 0; i < n; i++) g_string_append_printf(s, "%s%.17g", i ? ", " : "", v[i]);
    g_string_append(s, " ]");
}

static void opencv_matrix(GString *s, const char *name, const double *v, int rows, int cols)
{
    g_string_append_printf(s, "%s: !!opencv-matrix\n   rows: %d\n   cols: %d\n   dt: d\n   data: ", name, rows, cols);
    list(s, v, rows * cols);
    g_string_append_c(s, '\n');
}

static void ros_matrix(GString *s, const char *name, const double *v, int rows, int cols)
{
    g_string_append_printf(s, "%s:\n  rows: %d\n  cols: %d\n  data: ", name, rows, cols);
    list(s, v, rows * cols);
    g_string_append_c(s, '\n');
}

// The camera's name for ROS: the file's name without directory and extension.
static char *stem(const char *path)
{
    char *b = g_path_get_basename(path), *dot = strrchr(b, '.');
    if (dot && dot != b) *dot = 0;
    return b;
}

char *calib_export_camera_text(const char *model_path, calib_export_format_t fmt, const char *camera_name)
{
    model_camera_t *cam = model_camera_load(model_path);
    if (!cam) return NULL;
    const char *lm = model_camera_lensmodel(cam);
    int np = 0, nd = opencv_ncoeffs(lm);
    const double *in = model_camera_intrinsics(cam, &np);
    if (nd < 0) {
        model_error(model_path, 0, "lens model %s is not one of OpenCV's (LENSMODEL_PINHOLE, LENSMODEL_OPENCV4/5/8/12): "
                    "refl does not export it as it is, since OpenCV and ROS cannot project with it; give --approximate "
                    "for a fitted LENSMODEL_OPENCV8 with its stated error (or mrcal-convert-lensmodel LENSMODEL_OPENCV8 "
                    "%s), or calibrate with --lensmodel LENSMODEL_OPENCV8", lm, model_path);
        model_camera_free(cam);
        return NULL;
    }
    if (fmt == CALIB_EXPORT_ROS && nd > 8) {
        model_error(model_path, 0, "lens model %s has 12 distortion coefficients: ROS's camera_info knows plumb_bob (5) "
                    "and rational_polynomial (8) only; export it with --format opencv, or calibrate with "
                    "LENSMODEL_OPENCV8", lm);
        model_camera_free(cam);
        return NULL;
    }
    double K[9] = { in[0], 0, in[2], 0, in[1], in[3], 0, 0, 1 }, d[12] = { 0 };
    memcpy(d, in + 4, (size_t)nd * sizeof *d);
    int W = model_camera_width(cam), H = model_camera_height(cam);
    // plumb_bob holds 5 (k3 0 for OPENCV4 and a pinhole), rational_polynomial 8
    int nout = nd <= 5 ? 5 : nd;
    GString *s = g_string_new("");
    if (fmt == CALIB_EXPORT_OPENCV) {
        g_string_append_printf(s, "%%YAML:1.0\n---\n# refl %s: %s (%s); distortion k1 k2 p1 p2 [k3 [k4 k5 k6 "
                               "[s1 s2 s3 s4]]]\n", REFL_VERSION, model_path, lm);
        g_string_append_printf(s, "image_width: %d\nimage_height: %d\n", W, H);
        opencv_matrix(s, "camera_matrix", K, 3, 3);
        opencv_matrix(s, "distortion_coefficients", d, 1, nout);
    } else {
        double R[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 };
        double P[12] = { in[0], 0, in[2], 0, 0, in[1], in[3], 0, 0, 0, 1, 0 };
        char *name = camera_name ? g_strdup(camera_name) : stem(model_path);
        for (char *c = name; *c; c++)   // a YAML double-quoted scalar: no quote, backslash or control
            if (*c == '"' || *c == '\\' || (unsigned char)*c < 0x20) *c = '_';
        g_string_append_printf(s, "# refl %s: %s (%s); ROS camera_info (unrectified camera: rectification identity, "
                               "projection = camera_matrix)\n", REFL_VERSION, model_path, lm);
        g_string_append_printf(s, "image_width: %d\nimage_height: %d\ncamera_name: \"%s\"\n", W, H, name);
        g_free(name);
        ros_matrix(s, "camera_matrix", K, 3, 3);
        g_string_append_printf(s, "distortion_model: %s\n", nout == 5 ? "plumb_bob" : "rational_polynomial");
        ros_matrix(s, "distortion_coefficients", d, 1, nout);
        ros_matrix(s, "rectification_matrix", R, 3, 3);
        ros_matrix(s, "projection_matrix", P, 3, 4);
    }
    model_camera_free(cam);
    return g_string_free(s, FALSE);
}

bool calib_export_camera(const char *model_path, calib_export_format_t fmt, const char *camera_name,
                         const char *out)
{
    char *text = calib_export_camera_text(model_path, fmt, camera_name);
    if (!text) return false;
    bool ok = model_write_file_atomic(out, text);
    g_free(text);
    return ok;
}

bool calib_export_keep_optimization_inputs(const char *mrcal_model, const char *model)
{
    if (model_run_script("calib_cameramodel_merge.py", mrcal_model, model, model, NULL) == 0) return true;
    model_error(model, 0, "could not give it mrcal's optimization_inputs from %s (scripts/calib_cameramodel_merge.py: "
                "its message is above; the model itself is as refl wrote it)", mrcal_model);
    return false;
}

bool calib_export_camera_approx(const char *model_path, calib_export_format_t fmt, const char *camera_name,
                                const char *out, double *rms_px, double *max_px)
{
    *rms_px = *max_px = 0;
    model_camera_t *cam = model_camera_load(model_path);
    if (!cam) return false;
    bool opencv = opencv_ncoeffs(model_camera_lensmodel(cam)) >= 0;
    model_camera_free(cam);
    if (opencv) return calib_export_camera(model_path, fmt, camera_name, out);
    char *fitted = g_strdup_printf("%s.approx.cameramodel", out), *js = g_strdup_printf("%s.approx.json", out);
    char *text = NULL;
    bool ok = model_run_script("calib_export_approx.py", model_path, "LENSMODEL_OPENCV8", fitted, js, NULL) == 0;
    if (!ok) model_error(model_path, 0, "no OpenCV model could be fitted to it (scripts/calib_export_approx.py: its "
                         "message is above)");
    json_error_t je;
    json_t *j = ok ? json_load_file(js, 0, &je) : NULL;
    if (ok && !j) {
        model_error(js, je.line, "not the fit's summary: %s", je.text);
        ok = false;
    }
    if (ok) {
        *rms_px = json_number_value(json_object_get(j, "rms_px"));
        *max_px = json_number_value(json_object_get(j, "max_px"));
        ok = (text = calib_export_camera_text(fitted, fmt, camera_name)) != NULL;
    }
    if (ok) {   // the approximation stated after the first line (OpenCV's %YAML header stays first)
        char *nl = strchr(text, '\n');
        GString *g = g_string_new_len(text, nl ? nl - text + 1 : 0);
        g_string_append_printf(g, "# APPROXIMATION of %s (%s): LENSMODEL_OPENCV8 fitted over the imager, "
                               "reprojection error RMS %.4g px, max %.4g px over %lld pixels (%s)\n", model_path,
                               json_string_value(json_object_get(j, "source_lensmodel")), *rms_px, *max_px,
                               (long long)json_integer_value(json_object_get(j, "points")), js);
        g_string_append(g, nl ? nl + 1 : text);
        ok = model_write_file_atomic(out, g->str);
        g_string_free(g, TRUE);
    }
    json_decref(j);
    g_free(text);
    g_free(fitted);
    g_free(js);
    return ok;
}
