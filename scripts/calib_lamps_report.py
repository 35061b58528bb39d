#!/usr/bin/python3
"""Plots of refl calib lamps (calib/lamps/lamps.c writes the data; nothing is computed here
but the drawing).

usage: calib_lamps_report.py REPORT_DATA.json TRIANGULATION.png DETECTIONS.png

REPORT_DATA.json: {"lamps": [{"name", "position_mm", "std_mm", "rays": [{"p", "d", "used",
"dist_mm", "angle_deg"}]}], "detections":
{"angle_deg", "x0", "y0", "w", "h", "crop" (w*h DN, row-major), "highlights":
[{"lamp", "file", "found", "q"}], "sphere_q", "sphere_radius_px"},
"camera_centre_mm", "sphere_centre_angle0_mm", "sphere_radius_mm", "sphere_joint_fit" (optional:
{"offset_mm", "shift_mm", "tilt_mrad", "std"} of the joint fit of lamps and sphere path; the rays are
then reflected off the fitted path)}.
Units mm (rig frame), pixels. Its root names the format: "format": "refl-lamps-report-data",
"version": 1 (this script reads version 1; a file without the keys is version 1).
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    if len(sys.argv) != 4:
        sys.stderr.write(__doc__)
        return 2
    with open(sys.argv[1]) as f:
        data = json.load(f)
    fmt, ver = data.get("format", "refl-lamps-report-data"), data.get("version", 1)
    if fmt != "refl-lamps-report-data" or not isinstance(ver, int) or ver > 1:
        sys.stderr.write("%s: %s version %s: this script reads refl-lamps-report-data versions 1 to 1\n"
                         % (sys.argv[1], fmt, ver))
        return 2
    lamps = data["lamps"]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    fig = plt.figure(figsize=(15, 10))
    views = [(0, 1, "top view (x-y)"), (0, 2, "side view (x-z)"), (1, 2, "side view (y-z)")]
    for k, (i, j, title) in enumerate(views):
        ax = fig.add_subplot(2, 3, k + 1)
        cam = data["camera_centre_mm"]
        ax.plot(cam[i], cam[j], "ks", ms=7, label="camera")
        c0 = np.array(data["sphere_centre_angle0_mm"])
        rr = np.hypot(c0[0], c0[1])
        t = np.linspace(0, 2 * np.pi, 200)
        circ = np.stack([rr * np.cos(t), rr * np.sin(t), np.full_like(t, c0[2])])
        ax.plot(circ[i], circ[j], "k-", lw=0.6, label="sphere centre path")
        for n, lp in enumerate(lamps):
            col = colours[n % len(colours)]
            x = np.array(lp["position_mm"])
            length = 1.15 * max(np.linalg.norm(x - np.array(r["p"])) for r in lp["rays"]) if lp["rays"] else 100
            for r in lp["rays"]:
                p, d = np.array(r["p"]), np.array(r["d"])
                e = p + length * d
                ax.plot([p[i], e[i]], [p[j], e[j]], "-", color=col if r["used"] else "0.6", lw=0.6,
                        alpha=0.8 if r["used"] else 0.5)
            ax.plot(x[i], x[j], "x", color=col, ms=10, mew=2, label=lp["name"])
        ax.set_xlabel("xyz"[i] + " (mm)")
        ax.set_ylabel("xyz"[j] + " (mm)")
        ax.set_title(title)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, lw=0.3)
        if k == 0:
            ax.legend(fontsize=7, loc="best")
    # residuals per ray
    ax = fig.add_subplot(2, 3, 4)
    for n, lp in enumerate(lamps):
        col = colours[n % len(colours)]
        a = [r["angle_deg"] for r in lp["rays"]]
        dd = [r["dist_mm"] for r in lp["rays"]]
        used = [r["used"] for r in lp["rays"]]
        ax.plot([x for x, u in zip(a, used) if u], [y for y, u in zip(dd, used) if u], "o-", color=col,
                ms=4, lw=0.8, label=lp["name"])
        ax.plot([x for x, u in zip(a, used) if not u], [y for y, u in zip(dd, used) if not u], "o",
                mfc="none", color="0.4", ms=7)
    ax.set_xlabel("turntable angle (deg)")
    ax.set_ylabel("ray distance from the fitted lamp (mm)")
    ax.set_title("per-ray residuals (open: outliers left out)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=7)
    # uncertainty per lamp
    ax = fig.add_subplot(2, 3, 5)
    names = [lp["name"] for lp in lamps]
    xs = np.arange(len(lamps))
    for k, lab in enumerate("xyz"):
        ax.bar(xs + (k - 1) * 0.25, [lp["std_mm"][k] for lp in lamps], 0.25, label="std " + lab)
    ax.set_xticks(xs)
    ax.set_xticklabels(names)
    ax.set_ylabel("mm")
    ax.set_title("uncertainty (1 sigma) per axis")
    jf = data.get("sphere_joint_fit")
    if jf:
        s = jf["std"]
        tx = fig.add_subplot(2, 3, 6)
        tx.axis("off")
        tx.text(0.0, 1.0, "joint fit of lamps and sphere path\n(each lamp's std includes the path's)\n\n"
                "offset %.3f %.3f %.3f mm\n  std %.3f %.3f %.3f\nshift  %.3f %.3f mm\n  std %.3f %.3f\n"
                "tilt   %.3f %.3f mrad\n  std %.3f %.3f"
                % tuple(jf["offset_mm"] + s[0:3] + jf["shift_mm"] + s[3:5] + jf["tilt_mrad"] + s[5:7]),
                transform=tx.transAxes, va="top", fontsize=9, family="monospace")
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", lw=0.3)
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=80)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 7))
    det = data.get("detections")
    if det:
        img = np.array(det["crop"], dtype=float).reshape(det["h"], det["w"])
        x0, y0 = det["x0"], det["y0"]
        vmax = max(1.0, np.percentile(img, 99.9))
        hi = ax.imshow(np.sqrt(np.clip(img, 0, None)), cmap="gray", vmin=0, vmax=np.sqrt(vmax),
                       extent=(x0 - 0.5, x0 + det["w"] - 0.5, y0 + det["h"] - 0.5, y0 - 0.5))
        fig.colorbar(hi, ax=ax, label="sqrt(DN above dark)", shrink=0.8)
        q = det["sphere_q"]
        t = np.linspace(0, 2 * np.pi, 200)
        ax.plot(q[0] + det["sphere_radius_px"] * np.cos(t), q[1] + det["sphere_radius_px"] * np.sin(t), "c-", lw=0.7,
                label="predicted sphere image")
        for n, h in enumerate(det["highlights"]):
            col = colours[n % len(colours)]
            if h["found"]:
                ax.plot(h["q"][0], h["q"][1], "o", mfc="none", mec=col, ms=14, mew=1.5,
                        label="%s (%s, %.0f DN)" % (h["lamp"], h["file"], h["peak_dn"]))
        ax.set_title("highlights at turntable angle %.2f deg (sqrt of DN above dark, max over lamps)"
                     % (round(det["angle_deg"], 2) + 0.0))   # + 0.0: no "-0.00"
        ax.legend(fontsize=7, loc="lower right")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    fig.tight_layout()
    fig.savefig(sys.argv[3], dpi=80)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
