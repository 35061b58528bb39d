#!/usr/bin/python3
# scripts/fit_material_report.py DIR MODEL P1,P2,... — the plots of `refl fit
# material --report DIR` (fit/material/material.c): reads DIR/samples.csv (window
# centre px, step, lamp and its name, theta_i/theta_o/theta_h and the azimuth
# phi in deg, R measured and fitted and the expected noise sigma_R, 1/sr, the
# albedo cell's factor and the sample point at angle 0, mm) and writes
#   DIR/polar.png: the lobes in the plane of incidence, one polar panel per band
#     of incidence: measured R (mean ± spread per view-angle bin, ± sigma), the
#     fitted model at the same samples and its lobe at the band's mean incidence
#     (DIR/lobes_fit.csv: theta_i_deg, theta_o_deg signed, R_fit, written by refl);
#   DIR/lobes.png: R against the half-vector angle, measured and fitted, per lamp (by name);
#   DIR/residual_maps.png: R_meas - R_fit at each window for four frames;
#   DIR/albedo_cells.png: each albedo cell's factor on the sample, and their histogram
#     (only when the fit had cells: a factor other than 1);
#   DIR/models.png: the chosen model's residuals: histogram, and relative to R against theta_h.
# The table of every model is in the HTML page. Older samples.csv files without the new
# columns still give every plot but the polar one and the cells'.
import math
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np

plt.rcParams.update({"font.size": 11, "axes.titlesize": 12, "axes.labelsize": 11})

d, model, params = sys.argv[1], sys.argv[2], [float(v) for v in sys.argv[3].split(",")]
a = np.genfromtxt(os.path.join(d, "samples.csv"), delimiter=",", skip_header=1, names=True, dtype=None,
                  encoding="utf-8")
cols = a.dtype.names
lamps = np.unique(a["lamp"]).astype(int)


def lamp_label(lamp):
    if "lamp_name" in cols:
        n = a["lamp_name"][a["lamp"] == lamp]
        if len(n) and str(n[0]):
            return f"lamp {n[0]}"
    return f"lamp {lamp}"


def save(fig, name):
    fig.savefig(os.path.join(d, name), dpi=90)
    plt.close(fig)



# ---- polar: the plane of incidence -------------------------------------------------------
if "phi_deg" in cols:
    cp = os.path.join(d, "lobes_fit.csv")
    curves = np.genfromtxt(cp, delimiter=",", names=True) if os.path.exists(cp) else None
    phi = a["phi_deg"]
    fwd = np.abs(phi - 180) < 15        # the view on the far side of the normal (toward the mirror direction)
    back = phi < 15                     # the view on the incidence's side
    inplane = fwd | back
    signed = np.where(fwd, a["theta_o_deg"], -a["theta_o_deg"])
    ti = a["theta_i_deg"]
    # bands of incidence: 10 deg wide, the four most populated with in-plane samples
    edges = np.arange(0, 90, 10)
    counts = [int(np.sum(inplane & (ti >= b) & (ti < b + 10))) for b in edges]
    bands = sorted([b for b, c in sorted(zip(edges, counts), key=lambda t: -t[1])[:4] if c >= 20])
    n = max(len(bands), 1)
    pc = min(n, 2)
    pr = (n + pc - 1) // pc
    fig, axs = plt.subplots(pr, pc, figsize=(6.2 * pc, 4.6 * pr + 0.8), subplot_kw={"projection": "polar"},
                            squeeze=False)
    for i in range(len(bands), pr * pc):
        if i:
            axs.flat[i].set_axis_off()
    if not bands:
        axs.flat[0].set_axis_off()
        axs.flat[0].text(0.5, 0.5, "no samples within 15 deg of the plane of incidence", ha="center",
                       transform=axs.flat[0].transAxes)
    for ax, b in zip(axs.flat, bands):
        m = inplane & (ti >= b) & (ti < b + 10)
        x, y, yf = signed[m], a["R_meas"][m], a["R_fit"][m]
        sg = a["sigma_R"][m] if "sigma_R" in cols else np.zeros_like(y)
        bins = np.arange(-90, 91, 4)
        k = np.digitize(x, bins)
        cx, mu, sd, fi, ns = [], [], [], [], []
        for j in np.unique(k):
            s = k == j
            if s.sum() < 3:
                continue
            cx.append(np.mean(x[s]))
            mu.append(np.mean(y[s]))
            sd.append(np.std(y[s]))
            fi.append(np.mean(yf[s]))
            ns.append(np.sqrt(np.mean(sg[s] ** 2)))
        cx, mu, sd, fi, ns = map(np.array, (cx, mu, sd, fi, ns))
        th = np.radians(cx)
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        ax.set_thetamin(-90)
        ax.set_thetamax(90)
        if len(cx):
            ax.errorbar(th, mu, yerr=sd, fmt="o", ms=3, color="k", ecolor="0.45", capsize=2,
                        label="measured: mean ± spread")
            if np.any(ns > 0):
                ax.fill_between(th, np.maximum(mu - ns, 0), mu + ns, color="tab:blue", alpha=0.25,
                                label="± expected noise σ")
            ax.plot(th, fi, "x", color="tab:red", ms=5, label=f"fitted {model} at the samples")
            # the scale of the measurements: a glossy lobe's peak where nothing was measured is cut off (said so)
            top = float(np.max(np.concatenate([mu + sd, fi]))) * 1.25
            peak = None
            if curves is not None:   # the model's in-plane lobe at the band's mean incidence
                c = curves[curves["theta_i_deg"] == int(round(float(np.mean(ti[m]))))]
                ax.plot(np.radians(c["theta_o_deg"]), c["R_fit"], "-", color="tab:red", lw=1.8,
                        label=f"fitted {model} at the mean incidence")
                if len(c) and float(np.max(c["R_fit"])) > top:
                    peak = float(np.max(c["R_fit"]))
            if peak is not None:
                ax.text(0.5, 0.02, f"the fitted lobe's peak {peak:.3g} 1/sr is off this scale",
                        transform=ax.transAxes, ha="center", fontsize=9, color="tab:red")
        else:
            top = 1.0
        tim = float(np.mean(ti[m]))
        ax.plot([-math.radians(tim)] * 2, [0, top], "--", color="orange", lw=1.5,
                label="incidence direction (the band's mean)")
        ax.set_autoscale_on(False)
        ax.set_ylim(0, top if top > 0 else 1)
        ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
        ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%.3g"))
        ax.set_rlabel_position(75)
        ax.tick_params(axis="y", labelsize=9)
        ax.set_title(f"incidence {b}–{b + 10}°: {int(m.sum())} samples in the plane")
        ax.set_xlabel("view angle θo (deg; negative: the incidence's side); radius: R (1/sr)", labelpad=-50)
    h, lab = axs.flat[0].get_legend_handles_labels()
    fig.legend(h, lab, loc="lower center", ncol=4, fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    save(fig, "polar.png")

# ---- lobes: measured and fitted R against theta_h, one panel per lamp ----------
nc = min(3, len(lamps))
nr = (len(lamps) + nc - 1) // nc
fig, axs = plt.subplots(nr, nc, figsize=(5.4 * nc + 1, 4.4 * nr), squeeze=False, constrained_layout=True)
for i in range(nr * nc):
    if i >= len(lamps):
        axs.flat[i].set_axis_off()
for ax, lamp in zip(axs.flat, lamps):
    m = a["lamp"] == lamp
    sc = ax.scatter(a["theta_h_deg"][m], a["R_meas"][m], s=3, c=a["theta_i_deg"][m], cmap="viridis", vmin=0,
                    vmax=90, label="measured")
    o = np.argsort(a["theta_h_deg"][m])
    ax.plot(a["theta_h_deg"][m][o], a["R_fit"][m][o], "r.", ms=1.5, alpha=0.5, label=f"fitted ({model})")
    ax.set_yscale("log")
    ax.set_xlabel("half-vector angle θh (deg)")
    ax.set_ylabel("R = f_r cos θi (1/sr)")
    ax.set_title(f"{lamp_label(lamp)}: {int(m.sum())} samples")
    ax.grid(True, alpha=0.3)
axs[0][0].legend(markerscale=5, fontsize=9)
fig.colorbar(sc, ax=axs.ravel().tolist(), label="incidence θi (deg)")
save(fig, "lobes.png")

# ---- residual maps for four frames with the most windows -------------------------
steps, counts = np.unique(a["step"], return_counts=True)
pick = steps[np.argsort(-counts)][:4]
fig, axs = plt.subplots(1, len(pick), figsize=(4.6 * len(pick) + 1, 4.4), squeeze=False,
                        constrained_layout=True)
res = a["R_meas"] - a["R_fit"]
lim = np.percentile(np.abs(res), 99) or 1e-6
for ax, st in zip(axs[0], pick):
    m = a["step"] == st
    im = ax.scatter(a["x_px"][m], a["y_px"][m], c=res[m], s=30, marker="s", cmap="RdBu_r", vmin=-lim, vmax=lim)
    pad = 20
    ax.set_xlim(a["x_px"][m].min() - pad, a["x_px"][m].max() + pad)
    ax.set_ylim(a["y_px"][m].max() + pad, a["y_px"][m].min() - pad)
    ax.set_aspect("equal")
    ax.set_title(f"step {int(st)}, {lamp_label(int(a['lamp'][m][0]))}")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
fig.colorbar(im, ax=axs[0].tolist(), label="R_meas − R_fit (1/sr)")
save(fig, "residual_maps.png")

# ---- albedo cells: the factors on the sample ------------------------------------------
if "albedo_factor" in cols and np.any(a["albedo_factor"] != 1):
    key = np.round(np.stack([a["x0_mm"], a["y0_mm"], a["z0_mm"]], 1), 2)
    _, first = np.unique(key, axis=0, return_index=True)
    f = a["albedo_factor"][first]
    x0, y0 = a["x0_mm"][first], a["y0_mm"][first]
    inc = f != 1
    fig, axs = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1.5, 1]})
    lo, hi = np.percentile(f[inc], [1, 99]) if inc.any() else (0.9, 1.1)
    span = max(abs(lo - 1), abs(hi - 1), 1e-3)
    im = axs[0].scatter(x0[inc], y0[inc], c=f[inc], s=6, marker="s", cmap="RdBu_r", vmin=1 - span, vmax=1 + span)
    if (~inc).any():
        axs[0].scatter(x0[~inc], y0[~inc], s=4, c="0.8", marker="s", label="no cell (too few observations)")
        axs[0].legend(fontsize=9, loc="upper right")
    axs[0].set_aspect("equal")
    axs[0].set_xlabel("x at angle 0 (mm, rig frame)")
    axs[0].set_ylabel("y at angle 0 (mm, rig frame)")
    axs[0].set_title(f"albedo factor per cell ({int(inc.sum())} points in cells)")
    fig.colorbar(im, ax=axs[0], label="albedo factor (mean 1)")
    cf = np.unique(a["albedo_factor"][a["albedo_factor"] != 1])
    axs[1].hist(cf, bins=60, color="0.35")
    axs[1].set_xlabel("albedo factor")
    axs[1].set_ylabel("cells")
    axs[1].set_title(f"{len(cf)} cells: spread {100 * np.std(cf):.2g} %")
    fig.tight_layout()
    save(fig, "albedo_cells.png")

# ---- residuals: histogram relative to R -------------------------------------------
fig, axs = plt.subplots(1, 2, figsize=(12, 4.2))
lim = float(np.percentile(np.abs(res), 99.9)) or 1e-6
axs[0].hist(np.clip(res, -lim, lim), bins=100, range=(-lim, lim), color="0.3")
axs[0].locator_params(axis="x", nbins=6)
axs[0].ticklabel_format(axis="x", style="sci", scilimits=(-2, 2))
axs[0].set_xlabel("R_meas − R_fit (1/sr; the outer 0.1 % in the end bins)")
axs[0].set_ylabel("samples")
axs[0].set_title(f"residuals of {model}: RMS {math.sqrt(np.mean(res ** 2)):.3g} 1/sr")
rel = res / np.maximum(a["R_fit"], 1e-9)
axs[1].scatter(a["theta_h_deg"], rel, s=1, alpha=0.3)
axs[1].set_xlabel("half-vector angle θh (deg)")
axs[1].set_ylabel("relative residual (R_meas − R_fit) / R_fit")
axs[1].set_ylim(-0.3, 0.3)
axs[1].grid(True, alpha=0.3)
fig.tight_layout()
save(fig, "models.png")
print(os.path.join(d, "lobes.png"))
