#!/usr/bin/python3
# scripts/fit_material_report.py DIR MODEL P1,P2,... — the plots of `refl fit
# material --report DIR` (fit/material.c): reads DIR/samples.csv (window
# centre px, step, lamp, theta_i/theta_o/theta_h deg, R measured and fitted,
# 1/sr) and writes DIR/lobes.png (R against the half-vector angle, measured
# and fitted, per lamp; the fitted model's in-plane lobes), DIR/residual_maps.png
# (R_meas - R_fit at each window for four frames) and DIR/models.png (the
# chosen model's residuals: histogram, and relative to R against theta_h; the
# table of every model is in the HTML page).
import math
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

d, model, params = sys.argv[1], sys.argv[2], [float(v) for v in sys.argv[3].split(",")]
a = np.genfromtxt(os.path.join(d, "samples.csv"), delimiter=",", skip_header=1, names=True)
lamps = np.unique(a["lamp"]).astype(int)

# ---- lobes: measured and fitted R against theta_h, one panel per lamp ----------
fig, axs = plt.subplots(1, len(lamps), figsize=(4.2 * len(lamps), 3.8), squeeze=False)
for ax, l in zip(axs[0], lamps):
    m = a["lamp"] == l
    sc = ax.scatter(a["theta_h_deg"][m], a["R_meas"][m], s=2, c=a["theta_i_deg"][m], cmap="viridis", label="measured")
    o = np.argsort(a["theta_h_deg"][m])
    ax.plot(a["theta_h_deg"][m][o], a["R_fit"][m][o], "r.", ms=1, alpha=0.5, label=f"fitted ({model})")
    ax.set_yscale("log")
    ax.set_xlabel("half-vector angle theta_h (deg)")
    ax.set_title(f"lamp {l}: {int(m.sum())} samples")
    ax.grid(True, alpha=0.3)
axs[0][0].set_ylabel("R = f_r cos(theta_i) (1/sr)")
axs[0][0].legend(markerscale=5, fontsize=8)
fig.colorbar(sc, ax=axs[0].tolist(), label="incidence theta_i (deg)")
fig.savefig(os.path.join(d, "lobes.png"), dpi=80)
plt.close(fig)

# ---- residual maps for four frames with the most windows -------------------------
steps, counts = np.unique(a["step"], return_counts=True)
pick = steps[np.argsort(-counts)][:4]
fig, axs = plt.subplots(1, len(pick), figsize=(4.2 * len(pick), 3.8), squeeze=False)
res = a["R_meas"] - a["R_fit"]
lim = np.percentile(np.abs(res), 99) or 1e-6
for ax, st in zip(axs[0], pick):
    m = a["step"] == st
    im = ax.scatter(a["x_px"][m], a["y_px"][m], c=res[m], s=30, marker="s", cmap="RdBu_r", vmin=-lim, vmax=lim)
    pad = 20
    ax.set_xlim(a["x_px"][m].min() - pad, a["x_px"][m].max() + pad)
    ax.set_ylim(a["y_px"][m].max() + pad, a["y_px"][m].min() - pad)
    ax.set_aspect("equal")
    ax.set_title(f"step {int(st)}, lamp {int(a['lamp'][m][0])}")
    ax.set_xlabel("x (px)")
axs[0][0].set_ylabel("y (px)")
fig.colorbar(im, ax=axs[0].tolist(), label="R_meas - R_fit (1/sr)")
fig.savefig(os.path.join(d, "residual_maps.png"), dpi=80)
plt.close(fig)

# ---- residuals: histogram relative to R -------------------------------------------
fig, axs = plt.subplots(1, 2, figsize=(10, 3.6))
axs[0].hist(res, bins=100, color="0.3")
axs[0].set_xlabel("R_meas - R_fit (1/sr)")
axs[0].set_ylabel("samples")
axs[0].set_title(f"residuals of {model}: RMS {math.sqrt(np.mean(res ** 2)):.3g} 1/sr")
rel = res / np.maximum(a["R_fit"], 1e-9)
axs[1].scatter(a["theta_h_deg"], rel, s=1, alpha=0.3)
axs[1].set_xlabel("theta_h (deg)")
axs[1].set_ylabel("relative residual")
axs[1].set_ylim(-0.3, 0.3)
axs[1].grid(True, alpha=0.3)
fig.tight_layout()
fig.savefig(os.path.join(d, "models.png"), dpi=80)
print(os.path.join(d, "lobes.png"))
