# scripts/adversarial_lens.py — the virtual rig's adversarial lens, written by
# `scripts/make-example-camera --adversarial` (a lens outside the
# OPENCV8 model refl's geometry calibration fits).
#
# The truth lens maps a ray's pinhole coordinates (x, y) = (X/Z, Y/Z) to pixels
# with a distortion OPENCV8 does not contain:
#   - a division-model radial distortion (Fitzgibbon 2001) about a distortion
#     centre e offset from the principal point (a decentred element):
#     r_u = |(x, y) - e|, r_d solves r_u = r_d / (1 + LAMBDA r_d^2),
#     (x, y) -> e + ((x, y) - e) r_d / r_u
#   - Brown's (1966) decentering distortion with its third term P3:
#     dx = (1 + P3 r^2) (P1 (r^2 + 2x^2) + 2 P2 x y),
#     dy = (1 + P3 r^2) (P2 (r^2 + 2y^2) + 2 P1 x y)
#   - thin-prism distortion (Weng, Cohen & Herniou 1992):
#     dx = S1 r^2 + S2 r^4, dy = S3 r^2 + S4 r^4
#   q = (fx xd + cx, fy yd + cy).
# The magnitudes are chosen (not measured): LAMBDA like the example lens's k1,
# the decentering and prism terms of the order 1e-4..1e-3 (normalised units)
# that make a few tenths of a pixel at the imager's corners.
# It is stored as mrcal's LENSMODEL_SPLINED_STEREOGRAPHIC (the rig renders
# through it; its fit to the truth lens is reported), next to the best
# OPENCV8 fit to the same truth lens (OUT-opencv8.cameramodel): their
# difference over the imager is what an OPENCV8 calibration cannot remove.
import numpy as np
import mrcal

LAMBDA = -0.12
E = np.array([0.004, -0.003])        # distortion centre - principal point (normalised)
P1, P2, P3 = 0.0006, -0.0004, 0.5
S1, S2, S3, S4 = 0.0008, -0.0005, -0.0006, 0.0004
SPLINED = "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=18_Ny=15_fov_x_deg=55"


def truth_project(v, fx, fy, cx, cy):
    x, y = v[:, 0] / v[:, 2], v[:, 1] / v[:, 2]
    ux, uy = x - E[0], y - E[1]
    ru = np.hypot(ux, uy)
    disc = np.sqrt(1 - 4 * LAMBDA * ru * ru)
    scale = np.where(ru > 1e-12, (1 - disc) / (2 * LAMBDA * np.maximum(ru, 1e-12) ** 2), 1.0)
    xd, yd = E[0] + ux * scale, E[1] + uy * scale
    r2 = x * x + y * y
    d = 1 + P3 * r2
    xd += d * (P1 * (r2 + 2 * x * x) + 2 * P2 * x * y) + S1 * r2 + S2 * r2 * r2
    yd += d * (P2 * (r2 + 2 * y * y) + 2 * P1 * x * y) + S3 * r2 + S4 * r2 * r2
    return np.column_stack((fx * xd + cx, fy * yd + cy))


def rays(W, H, fx, fy, cx, cy, margin, step):
    # pinhole rays on a grid, kept where the truth lens images them on the
    # imager (+ margin px)
    xs = np.arange(-margin, W + margin, step, dtype=float)
    ys = np.arange(-margin, H + margin, step, dtype=float)
    gx, gy = np.meshgrid((xs - cx) / fx * 1.2, (ys - cy) / fy * 1.2)
    v = np.column_stack((gx.ravel(), gy.ravel(), np.ones(gx.size)))
    q = truth_project(v, fx, fy, cx, cy)
    keep = (q[:, 0] >= -margin) & (q[:, 0] <= W - 1 + margin) & (q[:, 1] >= -margin) & (q[:, 1] <= H - 1 + margin)
    return v[keep], q[keep]


def fit_linear(lensmodel, core, v, q):
    # the spline's control values with the core fixed: q is linear in them
    n = mrcal.lensmodel_num_params(lensmodel)
    i0 = np.concatenate((core, np.zeros(n - 4)))
    q0, _, dq_di = mrcal.project(v, lensmodel, i0, get_gradients=True)
    J = dq_di[:, :, 4:].reshape(-1, n - 4)
    ridge = 1e-4 * np.eye(n - 4)          # knots the data do not reach stay near 0
    A = np.vstack((J, ridge))
    b = np.concatenate(((q - q0).ravel(), np.zeros(n - 4)))
    return np.concatenate((core, np.linalg.lstsq(A, b, rcond=None)[0]))


def fit_gauss_newton(lensmodel, i0, v, q, iterations=30):
    i = np.array(i0, dtype=float)
    for _ in range(iterations):
        qp, _, dq_di = mrcal.project(v, lensmodel, i, get_gradients=True)
        J = dq_di.reshape(-1, i.size)
        r = (q - qp).ravel()
        step = np.linalg.lstsq(J, r, rcond=None)[0]
        i += step
        if np.max(np.abs(step)) < 1e-12:
            break
    return i


def rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def write(out, W, H, fx, fy, cx, cy, opencv8_start, rt_cam_ref, centre, target):
    v, q = rays(W, H, fx, fy, cx, cy, 40, 4)
    spl = fit_linear(SPLINED, np.array([fx, fy, cx, cy]), v, q)
    ocv = fit_gauss_newton("LENSMODEL_OPENCV8", opencv8_start, v, q)
    # over the imager only: every 2 px
    vi, qi = rays(W, H, fx, fy, cx, cy, 0, 2)
    e_spl = rms(mrcal.project(vi, SPLINED, spl), qi)
    e_ocv = rms(mrcal.project(vi, "LENSMODEL_OPENCV8", ocv), qi)
    d = mrcal.project(vi, SPLINED, spl) - mrcal.project(vi, "LENSMODEL_OPENCV8", ocv)
    e_d = float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
    e_max = float(np.max(np.hypot(d[:, 0], d[:, 1])))
    base = out[:-len(".cameramodel")] if out.endswith(".cameramodel") else out
    for path, lm, intr, what in ((out, SPLINED, spl, "the adversarial truth lens (splined)"),
                                 (base + "-opencv8.cameramodel", "LENSMODEL_OPENCV8", ocv,
                                  "the best OPENCV8 fit to the adversarial truth lens")):
        m = mrcal.cameramodel(intrinsics=(lm, intr), imagersize=np.array([W, H]),
                              extrinsics_rt_fromref=rt_cam_ref)
        note = (f"refl example camera: {what}, made by scripts/make-example-camera --adversarial "
                "(scripts/adversarial_lens.py). Units mm. ref frame = rig frame. "
                f"Camera centre {centre.round(3).tolist()} mm, looking at {target.tolist()} mm. "
                f"Over the imager: splined vs truth lens {e_spl:.4f} px RMS; OPENCV8 fit vs truth lens "
                f"{e_ocv:.4f} px RMS; splined vs OPENCV8 fit {e_d:.4f} px RMS, {e_max:.4f} px max.")
        m.write(path, note=note)
    print(f"{out}: splined vs truth {e_spl:.4f} px RMS; OPENCV8 fit vs truth {e_ocv:.4f} px RMS; "
          f"splined vs OPENCV8 fit {e_d:.4f} px RMS, {e_max:.4f} px max over the imager ({len(qi)} points)")
