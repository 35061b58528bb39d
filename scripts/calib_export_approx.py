#!/usr/bin/python3
# scripts/calib_export_approx.py — an OpenCV lens model fitted to a camera model
# OpenCV cannot hold (a splined one), for `refl calib export --approximate`
# (calib/geometry/export.c runs it through model_run_script).
#
#   SRC.cameramodel LENSMODEL OUT.cameramodel OUT.json
#       Unprojects a grid of 48 x 40 pixels spanning the whole imager (corners
#       included) with SRC, fits LENSMODEL's intrinsics (an OpenCV model) to
#       project those rays back onto the same pixels (least squares, mrcal's
#       analytic gradients; the distortion coefficients held small by a light
#       ridge of 0.01 px per unit), in the same camera frame: no rotation is
#       absorbed.
#       Writes the fitted model (SRC's extrinsics and imager size) and its error
#       over the grid: {"lensmodel", "rms_px", "max_px", "points", "dropped"}
#       (rays more than 80 deg off the axis cannot be projected by a pinhole
#       model and are dropped, counted).
import json
import sys

import mrcal
import numpy as np
from scipy.optimize import least_squares

REG = 0.01


def main(src, lensmodel, out_model, out_json):
    m = mrcal.cameramodel(src)
    W, H = m.imagersize()
    lm, intr = m.intrinsics()
    gx, gy = np.meshgrid(np.linspace(0, W - 1, 48), np.linspace(0, H - 1, 40))
    q = np.stack((gx.ravel(), gy.ravel()), axis=-1)
    v = mrcal.unproject(q, lm, intr, normalize=True)
    keep = np.isfinite(v).all(axis=-1) & (v[:, 2] > np.cos(np.radians(80)))
    q, v = q[keep], v[keep]
    n = mrcal.lensmodel_num_params(lensmodel)
    x0 = np.zeros(n)
    x0[:4] = intr[:4]   # the source's core (fx fy cx cy) as the seed

    # the rational model's numerator and denominator can grow together without
    # changing the projection: a light ridge (REG px per unit coefficient)
    # keeps the distortion coefficients at their smallest values that fit
    reg = np.r_[np.zeros(4), np.full(n - 4, REG)]

    def resid(x):
        return np.r_[(mrcal.project(v, lensmodel, x) - q).ravel(), reg * x]

    def jac(x):
        return np.r_[mrcal.project(v, lensmodel, x, get_gradients=True)[2].reshape(-1, n), np.diag(reg)]

    sol = least_squares(resid, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    e = np.linalg.norm((mrcal.project(v, lensmodel, sol.x) - q), axis=-1)
    fitted = mrcal.cameramodel(intrinsics=(lensmodel, sol.x), imagersize=m.imagersize(),
                               extrinsics_rt_fromref=m.extrinsics_rt_fromref())
    fitted.write(out_model, note=f"{lensmodel} fitted to {src} ({lm}) over the imager: RMS {np.sqrt(np.mean(e**2)):.4g} "
                 f"px, max {e.max():.4g} px")
    with open(out_json, "w") as f:
        json.dump({"lensmodel": lensmodel, "source_lensmodel": lm, "rms_px": float(np.sqrt(np.mean(e ** 2))),
                   "max_px": float(e.max()), "points": int(len(e)), "dropped": int((~keep).sum())}, f)


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit("usage: calib_export_approx.py SRC.cameramodel LENSMODEL OUT.cameramodel OUT.json")
    main(*sys.argv[1:])
