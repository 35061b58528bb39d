// calib/lamps/sphere.c — the mirror sphere seen by the camera: which pixels see it
// (calib_lamps_sphere_image), where a camera ray meets it and the ray it
// reflects (calib_lamps_reflect).
#include <math.h>
#include <stdlib.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"

void calib_lamps_sphere_image_free(calib_lamps_sphere_image_t *s)
{
    if (!s) return;
    free(s->on);
    free(s);
}

double lamps_ray_sphere(model_vec3_t o, model_vec3_t d, model_vec3_t c, double r)
{
    model_vec3_t oc = v3_sub(o, c);
    double b = v3_dot(d, oc), cc = v3_dot(oc, oc) - r * r, disc = b * b - cc;
    if (disc < 0) return NAN;
    double t = -b - sqrt(disc);
    return t > 0 ? t : NAN;
}

calib_lamps_sphere_image_t *calib_lamps_sphere_image(const model_camera_t *cam, model_vec3_t c, double r)
{
    const int W = model_camera_width(cam), H = model_camera_height(cam);
    model_vec3_t C = model_camera_centre_world(cam);
    model_vec3_t cc = v3_sub(c, C);
    double dist = sqrt(v3_dot(cc, cc));
    if (!(dist > r * 1.01)) {
        model_error_set(NULL, 0, "the sphere (centre %.1f %.1f %.1f mm, radius %g mm) contains the camera centre", c.x,
                        c.y, c.z, r);
        return NULL;
    }
    // silhouette: points of the sphere's tangent cone from the camera centre
    model_vec3_t a = v3_scale(cc, 1 / dist);
    model_vec3_t u = fabs(a.z) < 0.9 ? v3(0, 0, 1) : v3(1, 0, 0);
    model_vec3_t e1 = v3_sub(u, v3_scale(a, v3_dot(u, a)));
    e1 = v3_scale(e1, 1 / sqrt(v3_dot(e1, e1)));
    model_vec3_t e2 = v3_cross(a, e1);
    double sa = r / dist, ca = sqrt(1 - sa * sa);
    enum { NS = 72 };
    model_vec3_t pts[NS + 1];
    for (int k = 0; k < NS; k++) {
        double ph = 2 * M_PI * k / NS;
        // a tangent point: centre - r (sa a - ca (cos e1 + sin e2))
        model_vec3_t rad = v3_add(v3_scale(e1, cos(ph)), v3_scale(e2, sin(ph)));
        pts[k] = v3_add(c, v3_scale(v3_sub(v3_scale(rad, ca), v3_scale(a, sa)), r));
    }
    pts[NS] = c;
    double q[2 * (NS + 1)];
    if (!model_camera_project(cam, pts, NS + 1, q)) return NULL;
    double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY, rad_px = 0;
    for (int k = 0; k < NS; k++) {
        xmin = fmin(xmin, q[2 * k]);
        xmax = fmax(xmax, q[2 * k]);
        ymin = fmin(ymin, q[2 * k + 1]);
        ymax = fmax(ymax, q[2 * k + 1]);
        rad_px = fmax(rad_px, hypot(q[2 * k] - q[2 * NS], q[2 * k + 1] - q[2 * NS + 1]));
    }
    int x0 = (int)floor(xmin) - 3, x1 = (int)ceil(xmax) + 3, y0 = (int)floor(ymin) - 3, y1 = (int)ceil(ymax) + 3;
    if (!isfinite(xmin) || x1 < 0 || y1 < 0 || x0 >= W || y0 >= H) {
        model_error_set(NULL, 0, "the sphere (centre %.1f %.1f %.1f mm) is outside the camera's view", c.x, c.y, c.z);
        return NULL;
    }
    x0 = x0 < 0 ? 0 : x0;
    y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= W ? W - 1 : x1;
    y1 = y1 >= H ? H - 1 : y1;
    calib_lamps_sphere_image_t *s = calloc(1, sizeof *s);
    int w = x1 - x0 + 1, h = y1 - y0 + 1;
    double *qq = malloc(sizeof *qq * 2 * (size_t)w * h);
    model_vec3_t *dirs = malloc(sizeof *dirs * (size_t)w * h);
    if (!s || !qq || !dirs || !(s->on = calloc((size_t)w * h, 1))) {
        free(qq);
        free(dirs);
        calib_lamps_sphere_image_free(s);
        model_error_set(NULL, 0, "out of memory");
        return NULL;
    }
    s->x0 = x0;
    s->y0 = y0;
    s->w = w;
    s->h = h;
    s->q_centre[0] = q[2 * NS];
    s->q_centre[1] = q[2 * NS + 1];
    s->radius_px = rad_px;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            qq[2 * (y * w + x)] = x0 + x;
            qq[2 * (y * w + x) + 1] = y0 + y;
        }
    bool ok = model_camera_unproject(cam, qq, w * h, dirs);
    for (int i = 0; ok && i < w * h; i++) s->on[i] = isfinite(lamps_ray_sphere(C, dirs[i], c, r));
    free(qq);
    free(dirs);
    if (!ok) {
        calib_lamps_sphere_image_free(s);
        return NULL;
    }
    return s;
}

bool calib_lamps_reflect(const model_camera_t *cam, const double q[2], model_vec3_t c, double r, model_vec3_t *p,
                         model_vec3_t *dir)
{
    model_vec3_t d;
    if (!model_camera_unproject(cam, q, 1, &d)) return false;
    model_vec3_t C = model_camera_centre_world(cam);
    double t = lamps_ray_sphere(C, d, c, r);
    if (!isfinite(t)) {
        model_error_set(NULL, 0, "the camera ray through (%.2f, %.2f) px misses the sphere (centre %.1f %.1f %.1f mm, "
                        "radius %g mm)", q[0], q[1], c.x, c.y, c.z, r);
        return false;
    }
    *p = v3_add(C, v3_scale(d, t));
    model_vec3_t n = v3_scale(v3_sub(*p, c), 1 / r);
    *dir = v3_sub(d, v3_scale(n, 2 * v3_dot(d, n)));
    *dir = v3_scale(*dir, 1 / sqrt(v3_dot(*dir, *dir)));
    return true;
}
