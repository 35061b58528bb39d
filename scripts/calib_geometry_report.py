#!/usr/bin/python3
# scripts/calib_geometry_report.py — the mrcal side of `refl calib geometry`
# (calib/geometry/geometry.c runs it through calib_python with /usr/bin/python3).
#
#   solution MODEL OUT.json DISTANCE_MM
#       Reads the camera model mrcal-calibrate-cameras wrote (with its
#       optimization_inputs) and writes what refl needs from mrcal's solve:
#       lens model, intrinsics, imager size, per observation (image path) the
#       board pose rt_cam_board (mrcal's frames_rt_toref; camera 0 is mrcal's
#       reference), the RMS of the reprojection residual (px, outliers
#       excluded) and the outlier count; the projection uncertainty from
#       mrcal.projection_uncertainty (worst-direction standard deviation, px)
#       at a grid over the imager, for points DISTANCE_MM from the camera.
#       With several cameras (mrcal-calibrate-cameras given one glob per
#       camera; camera 0 is mrcal's reference) each observation also names its
#       camera, its rt_cam_board is composed from mrcal's extrinsics of that
#       camera and the frame's pose, and "cameras" gives per camera the
#       intrinsics, imager size, RMS residual, projection uncertainty and the
#       pose rt_cam_cam0 (mrcal's extrinsics) with its standard deviation (from
#       the solve's J^T J and the residuals' RMS per component).
#       A corner the detector did not see (a partial view: "nan nan -" in
#       the corners file, which mrcal keeps as NaN with a negative weight) is
#       neither a point nor an outlier; observed_px and residuals_px list the
#       corners seen, corner_index their index in the board's order.
#   align CORNERS_IN CORNERS_OUT OUT.json N|WxH SPACING_MM DIR:W:H:FOCAL...
#       Several cameras: mrgingham orders a square board's corners up to a
#       quarter turn (OpenCV a W x H chessboard's up to a half turn),
#       independently in each camera's image, while a joint solve
#       needs one order per frame (DIR/fNNN.png of every camera: one frame).
#       Estimates each view's board pose (pinhole seed, every quarter turn of
#       its corner order; the corners it saw), camera k's pose relative to camera 0 as the one most
#       shared frames agree on, and turns each view's corners so that its pose
#       agrees with the first camera seeing that frame; a view no turn makes
#       agree (within 5 deg) is left out. Writes CORNERS_OUT and, per view, the
#       camera, frame, quarter turns and mismatch into OUT.json.
#   plots GEOMETRY.json MODEL OUTDIR
#       The report's figures (PNG): residual vectors over the imager,
#       residual histogram, RMS per image, projection uncertainty map, the
#       turntable axis fit (the rotation angle of each board pose about the
#       fitted axis against the turntable angle), the cross-validation's
#       projection difference (px) and |difference| / (s0 + s1) maps
#       (crossvalidation.png), the worst images' residuals over the image
#       (worst_views.png) and the lens distortion against the pinhole with
#       the valid-intrinsics region (distortion.png); the lens blur's ESF and
#       LSF (psf.png, scripts/calib_psf_report.py).
#   compare MODEL_A MODEL_B OUT.json DISTANCE_MM
#       Two models of one lens differenced over A's imager (see compare()).
import json
import sys

import numpy as np


def finite(x):
    """x for JSON: every NaN or infinity (mrcal's uncertainty where no corner constrains it) as null."""
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite(v) for v in x]
    return x


def solution(model_path, out_path, distance_mm):
    import mrcal
    m = mrcal.cameramodel(model_path)
    oi = m.optimization_inputs()
    if oi is None:
        sys.exit(f"{model_path}: no optimization_inputs in the model (not written by mrcal-calibrate-cameras?)")
    lensmodel, intrinsics = m.intrinsics()
    W, H = (int(x) for x in m.imagersize())
    obs = oi["observations_board"]                    # (Nobs, Ny, Nx, 3): x, y, weight
    # a corner not seen: (-1, -1) or NaN with weight -1 (refl writes "nan nan -"); an outlier keeps its x, y with
    # a weight <= 0
    unseen_xy = ((obs[..., 0] == -1.0) & (obs[..., 1] == -1.0)) | ~np.isfinite(obs[..., 0]) | ~np.isfinite(obs[..., 1])
    seen = ~(unseen_xy & (obs[..., 2] <= 0))
    idx = oi["indices_frame_camintrinsics_camextrinsics"]
    frames = oi["frames_rt_toref"]
    paths = oi.get("imagepaths")
    x = mrcal.optimizer_callback(**oi, no_jacobian=True, no_factorization=True)[1]
    nb = mrcal.num_measurements_boards(**oi)
    r = x[:nb].reshape(obs.shape[:-1] + (2,))
    w = obs[..., 2]
    ok = w > 0
    ru = np.zeros_like(r)
    ru[ok] = r[ok] / w[ok][:, None]                  # unweighted residuals, px
    extr = oi.get("extrinsics_rt_fromref")
    ncam = int(np.max(idx[:, 1])) + 1
    images = []
    for i in range(obs.shape[0]):
        o = ok[i]
        rr = ru[i][o]
        sv = seen[i].ravel()
        rt = frames[idx[i, 0]]
        if idx[i, 2] >= 0:
            rt = mrcal.compose_rt(extr[idx[i, 2]], rt)
        im = {
            "path": str(paths[i]) if paths is not None else f"observation {i}",
            "rt_cam_board": [float(v) for v in rt],
            "rms_px": float(np.sqrt(np.mean(np.sum(rr * rr, axis=-1)))) if rr.size else None,
            "outliers": int(np.sum(~o & seen[i])),
            "residuals_px": [[float(a), float(b)] for a, b in ru[i].reshape(-1, 2)[sv]],
            "observed_px": [[float(a), float(b)] for a, b in obs[i, ..., :2].reshape(-1, 2)[sv]],
            "corner_index": [int(k) for k in np.flatnonzero(sv)],
        }
        if ncam > 1:
            im["camera"] = int(idx[i, 1])
        images.append(im)
    allr = ru[ok]
    core_sd = None
    try:                                              # the intrinsics core's 1-sigma (fx, fy, cx, cy), camera 0
        J = mrcal.optimizer_callback(**oi, no_factorization=True)[2]
        sig = float(np.sqrt(np.mean(allr * allr)))
        cov = np.linalg.inv((J.T @ J).toarray()) * sig * sig
        scale = np.ones(cov.shape[0])
        mrcal.unpack_state(scale, **oi)
        i0 = mrcal.state_index_intrinsics(0, **oi)
        core_sd = [float(np.sqrt(max(cov[i0 + k, i0 + k], 0)) * scale[i0 + k]) for k in range(4)]
    except Exception:                                  # noqa: BLE001 — optional figure
        core_sd = None
    out = {"lensmodel": lensmodel, "intrinsics": [float(v) for v in intrinsics], "imagersize": [W, H],
           "intrinsics_core_stdev": core_sd,
           "rms_px": float(np.sqrt(np.mean(np.sum(allr * allr, axis=-1)))),
           "observations": int(obs.shape[0]), "points": int(np.sum(ok)), "outliers": int(np.sum(~ok & seen)),
           "not_seen": int(np.sum(~seen)),
           "images": images, "uncertainty": uncertainty(m, distance_mm)}
    if ncam > 1:
        out["cameras"] = cameras(model_path, oi, idx, ru, ok, ncam, distance_mm)
    with open(out_path, "w") as f:
        json.dump(finite(out), f)


def cameras(model_path, oi, idx, ru, ok, ncam, distance_mm):
    """Per camera of a joint solve: intrinsics, residuals, uncertainty, pose to camera 0 (+- 1 sigma)."""
    import os
    import mrcal
    J = mrcal.optimizer_callback(**oi, no_factorization=True)[2]
    JtJ = (J.T @ J).toarray()
    allr = ru[ok]
    sigma = float(np.sqrt(np.mean(allr * allr)))     # per residual component, px
    try:
        cov = np.linalg.inv(JtJ) * sigma * sigma
    except np.linalg.LinAlgError:
        cov = None
    scale = np.ones(JtJ.shape[0])
    mrcal.unpack_state(scale, **oi)                   # in place: the packed state's scale
    res = []
    for k in range(ncam):
        mk = mrcal.cameramodel(os.path.join(os.path.dirname(model_path), f"camera-{k}.cameramodel"))
        lk, ik = mk.intrinsics()
        sel = idx[:, 1] == k
        rk = ru[sel][ok[sel]]
        c = {"intrinsics": [float(v) for v in ik], "lensmodel": lk,
             "imagersize": [int(v) for v in mk.imagersize()],
             "observations": int(np.sum(sel)),
             "rms_px": float(np.sqrt(np.mean(np.sum(rk * rk, axis=-1)))) if rk.size else None,
             "rt_cam_cam0": [float(v) for v in mk.extrinsics_rt_fromref()],
             "uncertainty": uncertainty(mk, distance_mm)}
        if k > 0 and cov is not None:
            i0 = mrcal.state_index_extrinsics(k - 1, **oi)
            s6 = scale[i0:i0 + 6]
            ck = cov[i0:i0 + 6, i0:i0 + 6] * np.outer(s6, s6)
            sd = np.sqrt(np.maximum(np.diag(ck), 0))
            c["rt_cam_cam0_stdev"] = [float(v) for v in sd]
            c["rotation_stdev_deg"] = float(np.sqrt(max(np.trace(ck[:3, :3]), 0)) * 180 / np.pi)
            c["translation_stdev_mm"] = float(np.sqrt(max(np.trace(ck[3:, 3:]), 0)))
        res.append(c)
    return res


def uncertainty(m, distance_mm):
    """mrcal.projection_uncertainty of model m at a grid over its imager."""
    import mrcal
    lensmodel, intrinsics = m.intrinsics()
    W, H = (int(x) for x in m.imagersize())
    # projection uncertainty at a grid over the imager
    gx = np.linspace(0, W - 1, 17)
    gy = np.linspace(0, H - 1, 14)
    q = np.array([[a, b] for b in gy for a in gx])
    v = mrcal.unproject(q, lensmodel, intrinsics, normalize=True)
    try:
        s = mrcal.projection_uncertainty(v * distance_mm, m, what="worstdirection-stdev")
        unc = {"distance_mm": distance_mm, "grid_x_px": gx.tolist(), "grid_y_px": gy.tolist(),
               "stdev_px": s.reshape(len(gy), len(gx)).tolist(),
               "max_px": float(np.max(s)), "median_px": float(np.median(s)), "mean_px": float(np.mean(s)),
               "centre_px": float(mrcal.projection_uncertainty(
                   mrcal.unproject(np.array([(W - 1) / 2, (H - 1) / 2]), lensmodel, intrinsics,
                                   normalize=True) * distance_mm, m, what="worstdirection-stdev")),
               "what": "worst-direction standard deviation of the projection, px (mrcal.projection_uncertainty)",
               "observed_pixel_uncertainty_px": "from the residuals (mrcal's default)"}
    except Exception as e:                             # noqa: BLE001 — reported, not fatal
        unc = {"error": f"mrcal.projection_uncertainty failed: {e}"}
    return unc


def observed_near(m, q, step):
    """Which of the pixels q (N x 2) lie within step px of a corner model m's camera observed (outliers out)."""
    oi = m.optimization_inputs()
    if oi is None:
        return np.ones(len(q), dtype=bool)
    obs = oi["observations_board"]
    sel = oi["indices_frame_camintrinsics_camextrinsics"][:, 1] == m.icam_intrinsics()
    o = obs[sel].reshape(-1, 3)
    o = o[o[:, 2] > 0][:, :2]
    near = np.zeros(len(q), dtype=bool)
    for k in range(0, len(o), 4096):
        d2 = np.sum((q[:, None, :] - o[None, k:k + 4096, :]) ** 2, axis=-1)
        near |= np.min(d2, axis=1) <= step * step
    return near


def compare(model_a, model_b, out_path, distance_mm):
    """Two models of one lens (the two halves of a cross-validation, or two lens models fitted to the same views)
    compared over a's imager the way mrcal differences models: pixels on a 33 x 27 grid unprojected with a to
    DISTANCE_MM, the rigid transform of a's camera frame onto b's fitted (weighted by 1 / (sa^2 + sb^2), mrcal's
    projection uncertainties, so the regions the calibrations saw decide it), every point projected with b; the
    difference at each point against the predicted sa + sb (worst-direction standard deviations). Figures over
    the whole grid and over the points within one grid step of a corner each model observed ("observed")."""
    import mrcal
    ma, mb = mrcal.cameramodel(model_a), mrcal.cameramodel(model_b)
    la, ia = ma.intrinsics()
    lb, ib = mb.intrinsics()
    W, H = (int(x) for x in ma.imagersize())
    gx, gy = np.linspace(0, W - 1, 33), np.linspace(0, H - 1, 27)
    q = np.array([[a, b] for b in gy for a in gx])
    pa = mrcal.unproject(q, la, ia, normalize=True) * distance_mm
    sa = mrcal.projection_uncertainty(pa, ma, what="worstdirection-stdev")
    pb0 = mrcal.unproject(q, lb, ib, normalize=True) * distance_mm
    sb = mrcal.projection_uncertainty(pb0, mb, what="worstdirection-stdev")
    w = 1.0 / np.sqrt(sa * sa + sb * sb)
    rt = np.zeros(6)
    for _ in range(20):                               # Gauss-Newton on the 6 pose parameters
        x, dx_drt, _ = mrcal.transform_point_rt(rt, pa, get_gradients=True)
        qb, dq_dx, _ = mrcal.project(x, lb, ib, get_gradients=True)
        r = ((qb - q) * w[:, None]).ravel()
        J = (np.einsum("nij,njk->nik", dq_dx, dx_drt) * w[:, None, None]).reshape(-1, 6)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        rt = rt + step
        if np.max(np.abs(step)) < 1e-12:
            break
    qb = mrcal.project(mrcal.transform_point_rt(rt, pa), lb, ib)
    d = np.linalg.norm(qb - q, axis=-1)
    pred = sa + sb
    ratio = d / pred
    near = observed_near(ma, q, gx[1] - gx[0]) & observed_near(mb, q, gx[1] - gx[0])
    rms = lambda v: float(np.sqrt(np.mean(v * v))) if v.size else None

    def figures(m):
        return {"npoints": int(np.sum(m)), "diff_rms_px": rms(d[m]),
                "diff_worst_px": float(np.max(d[m])) if m.any() else None,
                "predicted_rms_px": rms(pred[m]), "predicted_worst_px": float(np.max(pred[m])) if m.any() else None,
                "ratio_rms": rms(ratio[m]), "ratio_median": float(np.median(ratio[m])) if m.any() else None,
                "ratio_worst": float(np.max(ratio[m])) if m.any() else None}
    out = {"distance_mm": distance_mm, "grid": [33, 27], "lensmodel_a": la, "lensmodel_b": lb,
           "observed": figures(near), "imager": figures(np.ones(len(d), dtype=bool)),
           "rt_a_to_b": [float(v) for v in rt], "grid_x_px": gx.tolist(), "grid_y_px": gy.tolist(),
           "diff_px": d.reshape(len(gy), len(gx)).tolist(), "predicted_px": pred.reshape(len(gy), len(gx)).tolist(),
           "observed_mask": near.reshape(len(gy), len(gx)).astype(int).tolist()}
    with open(out_path, "w") as f:
        json.dump(finite(out), f)


def align(corners_in, corners_out, out_path, size, spacing, camspecs):
    import re
    import mrcal
    cams = []
    for spec in camspecs:
        d, w, h, f = spec.rsplit(":", 3)
        cams.append((d, int(w), int(h), float(f)))
    order, rows = [], {}
    for line in open(corners_in):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        name, rest = line.split(None, 1)
        if name not in rows:
            rows[name] = []
            order.append(name)
        rows[name].append(line.rstrip("\n"))
    Wn, Hn = (int(x) for x in (size.lower().split("x") * 2)[:2])
    turns_ok = [0, 1, 2, 3] if Wn == Hn else [0, 2]  # the turns that map the grid onto itself
    views = []                                     # (name, icam, frame, obs Hn x Wn x 3)
    for name in order:
        d, _, base = name.rpartition("/")
        icam = next((k for k, c in enumerate(cams) if c[0] == d), None)
        digits = re.sub(r"\D", "", base)
        if icam is None or not digits or len(rows[name]) != Wn * Hn:
            continue
        q = []
        for line in rows[name]:
            f = line.split()
            seen = f[1] != "-" and f[2] != "-" and (len(f) < 4 or f[3] != "-")
            # NaN for a corner not seen: estimate_monocular_calobject_poses_Rt_tocam drops NaN, not weight -1
            q.append([float(f[1]), float(f[2]), 1.0] if seen else [np.nan, np.nan, -1.0])
        views.append((name, icam, int(digits), np.array(q).reshape(Hn, Wn, 3)))
    # every view's pose for each quarter turn of its corner order (a turn that does not map the grid onto itself:
    # a copy of the unturned one, never chosen)
    ifc = np.array([[4 * i + j, v[1]] for i, v in enumerate(views) for j in range(4)], dtype=np.int32)
    ob = np.array([np.rot90(v[3], j if j in turns_ok else 0, axes=(0, 1)) for v in views for j in range(4)])
    seeds = [("LENSMODEL_PINHOLE", np.array([c[3], c[3], (c[1] - 1) / 2, (c[2] - 1) / 2])) for c in cams]
    Rt = mrcal.estimate_monocular_calobject_poses_Rt_tocam(ifc, ob, spacing, seeds)
    rt = mrcal.rt_from_Rt(Rt).reshape(len(views), 4, 6)
    byframe = {}
    for i, v in enumerate(views):
        byframe.setdefault(v[2], {})[v[1]] = i

    def rdiff(a, b):                               # rotation between two rt, deg (0..180)
        x = float(np.linalg.norm(mrcal.compose_r(a[:3], -b[:3]))) % (2 * np.pi)   # compose_r may exceed pi
        return min(x, 2 * np.pi - x) * 180 / np.pi

    # rt_camk_cam0: the candidate most shared frames agree with
    T = [np.zeros(6)] + [None] * (len(cams) - 1)
    err = None
    for k in range(1, len(cams)):
        cand = []
        for f, vs in byframe.items():
            if 0 in vs and k in vs:
                cand.append([mrcal.compose_rt(rt[vs[k], j], mrcal.invert_rt(rt[vs[0], 0])) for j in turns_ok])
        if not cand:
            err = f"camera {k} ({cams[k][0]}) sees the board in no frame that camera 0 ({cams[0][0]}) sees: " \
                  "the joint solve needs views of the board by both"
            break
        best, bscore = None, -1
        for cf in cand:
            for c in cf:
                score = sum(1 for other in cand if min(rdiff(c, o) for o in other) < 5)
                if score > bscore:
                    best, bscore = c, score
        T[k] = best
    res = {"cameras": [c[0] for c in cams], "views": {}}
    if err:
        res["error"] = err
    else:
        turns = {}
        for f, vs in sorted(byframe.items()):
            ref = min(vs)
            turns[vs[ref]] = (0, 0.0)
            rref = mrcal.compose_rt(mrcal.invert_rt(T[ref]), rt[vs[ref], 0])   # the board in camera 0's frame
            for k, i in vs.items():
                if k == ref:
                    continue
                pred = mrcal.compose_rt(T[k], rref)
                d = [rdiff(pred, rt[i, j]) for j in turns_ok]
                j = int(np.argmin(d))
                turns[i] = (turns_ok[j], d[j])
        for i, v in enumerate(views):
            j, d = turns[i]
            res["views"][v[0]] = {"camera": v[1], "frame": v[2], "quarter_turns": j, "mismatch_deg": d,
                                  "dropped": bool(d > 5)}
        res["rt_cam_cam0_seed"] = [[float(x) for x in t] for t in T]
    with open(corners_out, "w") as fo:
        for name in order:
            r = rows[name]
            info = res["views"].get(name)
            if info and info["dropped"]:
                continue
            if info and info["quarter_turns"]:
                perm = np.rot90(np.arange(Wn * Hn).reshape(Hn, Wn), info["quarter_turns"]).ravel()
                r = [r[p] for p in perm]
            fo.write("\n".join(r) + "\n")
    with open(out_path, "w") as f:
        json.dump(finite(res), f)


def worst_views(plt, s, W, H, outdir, n=3):
    """worst_views.png: the n images with the largest RMS residual, each over its image (when the copy in
    OUTDIR/images is readable): the observed corners and their residual vectors, coloured by |residual|."""
    ims = sorted((im for im in s["images"] if im.get("residuals_px")), key=lambda im: -float(im.get("rms_px") or 0))[:n]
    if not ims:
        return
    fig, axs = plt.subplots(1, len(ims), figsize=(6.2 * len(ims) + 1, 5.4), squeeze=False, constrained_layout=True)
    allmag = np.concatenate([np.hypot(*np.array(im["residuals_px"], dtype=float).T) for im in ims])
    vmax = float(np.percentile(allmag, 99)) or 1e-3
    scale = 0.05 * max(W, H) / vmax   # the largest arrows 5 % of the imager
    for a, im in zip(axs[0], ims):
        q = np.array(im["observed_px"], dtype=float)
        r = np.array(im["residuals_px"], dtype=float)
        try:
            from PIL import Image
            img = np.asarray(Image.open(f"{outdir}/images/{im['path']}"), dtype=float)
            if img.ndim == 3:
                img = img[..., :3].mean(axis=2)
            a.imshow(img, cmap="gray", vmin=np.percentile(img, 1), vmax=np.percentile(img, 99.5), alpha=0.6,
                     extent=(-0.5, img.shape[1] - 0.5, img.shape[0] - 0.5, -0.5))
        except (OSError, ValueError, ImportError):
            pass
        qv = a.quiver(q[:, 0], q[:, 1], r[:, 0] * scale, r[:, 1] * scale, np.hypot(r[:, 0], r[:, 1]), angles="xy",
                      scale_units="xy", scale=1, cmap="plasma", clim=(0, vmax), width=0.004)
        a.plot(q[:, 0], q[:, 1], ".", ms=2, color="c")
        pad = 60
        a.set_xlim(max(q[:, 0].min() - pad, 0), min(q[:, 0].max() + pad, W))
        a.set_ylim(min(q[:, 1].max() + pad, H), max(q[:, 1].min() - pad, 0))
        a.set_aspect("equal")
        a.set_title(f"{im['path']}: RMS {float(im['rms_px']):.3f} px, {im.get('outliers', 0)} outliers", fontsize=10)
        a.set_xlabel("x (px)")
        a.set_ylabel("y (px)")
    fig.colorbar(qv, ax=axs[0].tolist(), label=f"|residual| (px); arrows x{scale:.0f}")
    fig.savefig(f"{outdir}/worst_views.png", dpi=90)
    plt.close(fig)


def distortion(plt, s, W, H, outdir, step=16):
    """distortion.png: how far the lens model moves each pixel from the pinhole of the same fx, fy, cx, cy
    (|q - q_pinhole| over the imager, arrows), with the valid-intrinsics region: mrcal's (the model's) when it
    has one, and where the projection uncertainty stays under 1 px (solution.json's grid)."""
    try:
        import mrcal
    except ImportError:
        return
    lens, intr = s["lensmodel"], np.array(s["intrinsics"], dtype=float)
    xs, ys = np.arange(0, W, step, dtype=float), np.arange(0, H, step, dtype=float)
    q = np.stack(np.meshgrid(xs, ys), axis=-1)
    v = mrcal.unproject(np.ascontiguousarray(q), lens, intr)
    q0 = mrcal.project(v, "LENSMODEL_PINHOLE", intr[:4])
    d = q - q0
    mag = np.hypot(d[..., 0], d[..., 1])
    fig, ax = plt.subplots(figsize=(9.5, 7.2))
    im = ax.imshow(mag, extent=(-0.5, W - 0.5, H - 0.5, -0.5), cmap="viridis", interpolation="bilinear")
    fig.colorbar(im, ax=ax, label="distortion |q − q_pinhole| (px)")
    k = max(1, int(round(64 / step)))
    ax.quiver(q[::k, ::k, 0], q[::k, ::k, 1], d[::k, ::k, 0], d[::k, ::k, 1], color="w", angles="xy",
              scale_units="xy", scale=max(mag.max() / 40.0, 1e-9), width=0.002)
    u = s.get("uncertainty") or {}
    label = []
    if "stdev_px" in u:
        st = np.array(u["stdev_px"], dtype=float)
        if np.nanmin(st) < 1.0 < np.nanmax(st):
            ax.contour(np.array(u["grid_x_px"]), np.array(u["grid_y_px"]), st, levels=[1.0], colors="r", linewidths=1.5)
            label.append("red: projection uncertainty 1 px")
        elif np.nanmax(st) <= 1.0:
            label.append(f"projection uncertainty under 1 px everywhere (max {np.nanmax(st):.2f} px)")
    try:
        r = mrcal.cameramodel(f"{outdir}/camera.cameramodel").valid_intrinsics_region()
    except Exception:
        r = None
    if r is not None and len(r) > 2:
        ax.plot(r[:, 0], r[:, 1], "m-", lw=1.5)
        label.append("magenta: mrcal's valid-intrinsics region")
    ax.set_xlim(-0.5, W - 0.5)
    ax.set_ylim(H - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    ax.set_title(f"{lens.replace('LENSMODEL_', '')}: distortion against the pinhole, max {mag.max():.1f} px"
                 + ("\n" + "; ".join(label) if label else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(f"{outdir}/distortion.png", dpi=90)
    plt.close(fig)


def plots(geometry_path, solution_path, outdir):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    g = json.load(open(geometry_path))
    from report_common import Bad, check_format
    try:
        check_format(g, geometry_path, "refl-geometry")
    except Bad as b:
        sys.exit(f"calib_geometry_report.py: {b.path}: {b.msg}")
    s = json.load(open(solution_path))
    W, H = s["imagersize"]
    obs = np.array([p for im in s["images"] for p in im["observed_px"]])
    res = np.array([p for im in s["images"] for p in im["residuals_px"]])
    # residual vectors
    fig, ax = plt.subplots(figsize=(9, 7.5))
    mag = np.hypot(res[:, 0], res[:, 1])
    scale = 100.0
    qv = ax.quiver(obs[:, 0], obs[:, 1], res[:, 0] * scale, res[:, 1] * scale, mag, angles="xy", scale_units="xy",
                   scale=1, cmap="viridis", width=0.002)
    fig.colorbar(qv, ax=ax, label="|residual| (px)", shrink=0.8)
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.set_aspect("equal")
    ax.set_title(f"reprojection residuals, arrows x{scale:g}, {len(s['images'])} images")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    fig.tight_layout()
    fig.savefig(f"{outdir}/residuals_vectors.png", dpi=90)
    plt.close(fig)
    # histogram
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.hist(res.ravel(), bins=60, color="#4477aa")
    ax.set_xlabel("residual component (px)")
    ax.set_ylabel("count")
    ax.set_title(f"reprojection residuals: RMS {s['rms_px']:.3f} px, {s['outliers']} outliers")
    fig.tight_layout()
    fig.savefig(f"{outdir}/residuals_histogram.png", dpi=90)
    plt.close(fig)
    # per image
    fig, ax = plt.subplots(figsize=(9, 4))
    names = [im["image"] for im in g["images"] if im.get("rms_residual_px") is not None]
    vals = [im["rms_residual_px"] for im in g["images"] if im.get("rms_residual_px") is not None]
    ax.bar(range(len(vals)), vals, color="#4477aa")
    ax.set_xticks(range(len(vals)))
    ax.set_xticklabels(names, rotation=90, fontsize=6)
    ax.set_ylabel("RMS residual (px)")
    ax.set_xlabel("image")
    ax.set_title("RMS reprojection residual per image")
    fig.tight_layout()
    fig.savefig(f"{outdir}/residuals_per_image.png", dpi=90)
    plt.close(fig)
    worst_views(plt, s, W, H, outdir)
    distortion(plt, s, W, H, outdir)
    # uncertainty
    u = s["uncertainty"]
    if "stdev_px" in u:
        fig, ax = plt.subplots(figsize=(8, 6.5))
        im = ax.imshow(np.array(u["stdev_px"], dtype=float), extent=(u["grid_x_px"][0], u["grid_x_px"][-1],
                       u["grid_y_px"][-1], u["grid_y_px"][0]), cmap="magma", interpolation="bilinear")
        fig.colorbar(im, ax=ax, label="projection uncertainty, 1 sigma (px)")
        ax.plot(obs[:, 0], obs[:, 1], ",", color="#66ccee", alpha=0.5)
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
        ax.set_title(f"projection uncertainty at {u['distance_mm']:g} mm (worst direction, 1 sigma)")
        fig.tight_layout()
        fig.savefig(f"{outdir}/uncertainty.png", dpi=90)
        plt.close(fig)
    # cross-validation: each comparison's |difference| / (s0 + s1) over the imager
    xv = g.get("cross_validation") or {}
    comps = [(r.get("lensmodel", ""), c) for r in xv.get("runs", []) if r.get("done") for c in r.get("cameras", [])[:1]]
    comps += [("lean against splined", c) for c in (xv.get("lean_vs_splined") or {}).get("cameras", [])[:1]]
    comps = [(n, json.load(open(c["details"]))) for n, c in comps if c.get("details")]
    if comps:
        fig, axs = plt.subplots(2, len(comps), figsize=(6.4 * len(comps), 9.4), squeeze=False)
        for a, (name, c) in zip(axs[1], comps):
            d = np.array(c["diff_px"], dtype=float)
            im = a.imshow(d, extent=(c["grid_x_px"][0], c["grid_x_px"][-1], c["grid_y_px"][-1], c["grid_y_px"][0]),
                          cmap="magma", vmin=0, interpolation="nearest")
            a.contour(np.array(c["grid_x_px"]), np.array(c["grid_y_px"]), np.array(c["observed_mask"]), levels=[0.5],
                      colors="c", linewidths=0.8)
            short = name.replace("LENSMODEL_", "").split("_order")[0]
            a.set_title(f"{short}: projection difference of the two halves at {c['distance_mm']:g} mm\n"
                        f"RMS {c['observed']['diff_rms_px']:.3f} px observed (inside the cyan line), "
                        f"{c['imager']['diff_rms_px']:.3f} px imager", fontsize=9)
            a.set_xlabel("x (px)")
            a.set_ylabel("y (px)")
            fig.colorbar(im, ax=a, label="|difference| (px)")
        for a, (name, c) in zip(axs[0], comps):
            a.set_xlabel("x (px)")
            a.set_ylabel("y (px)")
            ratio = np.array(c["diff_px"], dtype=float) / np.array(c["predicted_px"], dtype=float)
            im = a.imshow(ratio, extent=(c["grid_x_px"][0], c["grid_x_px"][-1], c["grid_y_px"][-1], c["grid_y_px"][0]),
                          cmap="viridis", vmin=0, vmax=3, interpolation="nearest")
            a.contour(np.array(c["grid_x_px"]), np.array(c["grid_y_px"]), np.array(c["observed_mask"]), levels=[0.5],
                      colors="w", linewidths=0.8)
            short = name.replace("LENSMODEL_", "").split("_order")[0]
            a.set_title(f"{short}: ratio RMS {c['observed']['ratio_rms']:.2f} (judged inside the white line)",
                        fontsize=9)
            fig.colorbar(im, ax=a, label="|difference| / (s0 + s1)")
        fig.tight_layout()
        fig.savefig(f"{outdir}/crossvalidation.png", dpi=90)
        plt.close(fig)
    # axis fit
    ax_ = g.get("axis")
    if ax_ and ax_.get("fit"):
        fig, ax = plt.subplots(figsize=(8, 4.5))
        for grp in ax_["fit"]:
            a = np.array(grp["angle_deg"])
            rot = np.array(grp["rotation_about_axis_deg"])
            dev = (rot - a + 180.0) % 360.0 - 180.0
            ax.plot(a, dev * 1000.0, "o-", label=f"tilt {grp['tilt_deg']:g} deg @ {grp['tilt_azimuth_deg']:g}")
        ax.set_xlabel("turntable angle (deg)")
        ax.set_ylabel("rotation about the axis - turntable (mdeg)")
        ax.set_title(f"board rotation about the fitted axis vs the turntable angle (first view of each tilt = 0);\n"
                     f"rotation off the axis: RMS {ax_['off_axis_rms_deg']:.4f} deg", fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(f"{outdir}/axis_fit.png", dpi=90)
        plt.close(fig)
    import calib_psf_report   # the lens blur's figure (psf.png), when the run estimated it (calib/geometry/psf.c)
    calib_psf_report.plot(plt, outdir)


if __name__ == "__main__":
    if len(sys.argv) >= 8 and sys.argv[1] == "align":
        align(sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5], float(sys.argv[6]), sys.argv[7:])
    elif len(sys.argv) == 5 and sys.argv[1] == "solution":
        solution(sys.argv[2], sys.argv[3], float(sys.argv[4]))
    elif len(sys.argv) == 6 and sys.argv[1] == "compare":
        compare(sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5]))
    elif len(sys.argv) == 5 and sys.argv[1] == "plots":
        plots(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        sys.exit("usage: calib_geometry_report.py solution MODEL OUT.json DISTANCE_MM | "
                 "plots GEOMETRY.json SOLUTION.json OUTDIR | compare MODEL_A MODEL_B OUT.json DISTANCE_MM | "
                 "align CORNERS_IN CORNERS_OUT OUT.json N|WxH SPACING_MM DIR:W:H:FOCAL...")
