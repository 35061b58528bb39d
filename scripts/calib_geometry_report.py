#!/usr/bin/python3
# scripts/calib_geometry_report.py — the mrcal side of `refl calib geometry`
# (calib/geometry.c runs it through calib_python with /usr/bin/python3).
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
#   plots GEOMETRY.json MODEL OUTDIR
#       The report's figures (PNG): residual vectors over the imager,
#       residual histogram, RMS per image, projection uncertainty map, the
#       turntable axis fit (the rotation angle of each board pose about the
#       fitted axis against the turntable angle).
import json
import sys

import numpy as np


def solution(model_path, out_path, distance_mm):
    import mrcal
    m = mrcal.cameramodel(model_path)
    oi = m.optimization_inputs()
    if oi is None:
        sys.exit(f"{model_path}: no optimization_inputs in the model (not written by mrcal-calibrate-cameras?)")
    lensmodel, intrinsics = m.intrinsics()
    W, H = (int(x) for x in m.imagersize())
    obs = oi["observations_board"]                    # (Nobs, Ny, Nx, 3): x, y, weight
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
    images = []
    for i in range(obs.shape[0]):
        o = ok[i]
        rr = ru[i][o]
        images.append({
            "path": str(paths[i]) if paths is not None else f"observation {i}",
            "rt_cam_board": [float(v) for v in frames[idx[i, 0]]],
            "rms_px": float(np.sqrt(np.mean(np.sum(rr * rr, axis=-1)))) if rr.size else None,
            "outliers": int(np.sum(~o)),
            "residuals_px": [[float(a), float(b)] for a, b in ru[i].reshape(-1, 2)],
            "observed_px": [[float(a), float(b)] for a, b in obs[i, ..., :2].reshape(-1, 2)],
        })
    allr = ru[ok]
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
    out = {"lensmodel": lensmodel, "intrinsics": [float(v) for v in intrinsics], "imagersize": [W, H],
           "rms_px": float(np.sqrt(np.mean(np.sum(allr * allr, axis=-1)))),
           "observations": int(obs.shape[0]), "points": int(np.sum(ok)), "outliers": int(np.sum(~ok)),
           "images": images, "uncertainty": unc}
    with open(out_path, "w") as f:
        json.dump(out, f)


def plots(geometry_path, solution_path, outdir):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    g = json.load(open(geometry_path))
    s = json.load(open(solution_path))
    W, H = s["imagersize"]
    obs = np.array([p for im in s["images"] for p in im["observed_px"]])
    res = np.array([p for im in s["images"] for p in im["residuals_px"]])
    # residual vectors
    fig, ax = plt.subplots(figsize=(9, 7.5))
    mag = np.hypot(res[:, 0], res[:, 1])
    scale = 100.0
    ax.quiver(obs[:, 0], obs[:, 1], res[:, 0] * scale, res[:, 1] * scale, mag, angles="xy", scale_units="xy",
              scale=1, cmap="viridis", width=0.002)
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.set_aspect("equal")
    ax.set_title(f"reprojection residuals x{scale:g} (colour: |residual| px), {len(s['images'])} images")
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
    ax.set_title("RMS reprojection residual per image")
    fig.tight_layout()
    fig.savefig(f"{outdir}/residuals_per_image.png", dpi=90)
    plt.close(fig)
    # uncertainty
    u = s["uncertainty"]
    if "stdev_px" in u:
        fig, ax = plt.subplots(figsize=(8, 6.5))
        im = ax.imshow(np.array(u["stdev_px"]), extent=(u["grid_x_px"][0], u["grid_x_px"][-1],
                       u["grid_y_px"][-1], u["grid_y_px"][0]), cmap="magma", interpolation="bilinear")
        fig.colorbar(im, ax=ax, label="px")
        ax.plot(obs[:, 0], obs[:, 1], ",", color="#66ccee", alpha=0.5)
        ax.set_title(f"projection uncertainty at {u['distance_mm']:g} mm (worst direction, 1 sigma)")
        fig.tight_layout()
        fig.savefig(f"{outdir}/uncertainty.png", dpi=90)
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


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "solution":
        solution(sys.argv[2], sys.argv[3], float(sys.argv[4]))
    elif len(sys.argv) == 5 and sys.argv[1] == "plots":
        plots(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        sys.exit("usage: calib_geometry_report.py solution MODEL OUT.json DISTANCE_MM | "
                 "plots GEOMETRY.json SOLUTION.json OUTDIR")
