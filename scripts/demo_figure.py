#!/usr/bin/python3
# scripts/demo_figure.py OUTDIR
#
# The figure of `make demo`: reads the images refl rendered into OUTDIR (float32
# TIFFs of the grey value P in DN, 16-bit PNGs) and the edges JSON, and draws
#   row 1: the T-stiffener rendered three ways (direct; thesis interreflection;
#          Monte Carlo interreflection through the 12-bit sensor model),
#   row 2: the three wrong descriptions (I-stiffener, no stiffener, shifted 5 mm),
#   row 3: the differences correct - wrong (DN), and the predicted edges.
# Writes OUTDIR/figure.png. Plots only: every number comes from refl's outputs.
import json
import os
import sys

import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
from PIL import Image

outdir = sys.argv[1]


def load(name):
    path = os.path.join(outdir, name)
    im = Image.open(path)
    a = np.array(im, dtype=np.float64)
    if a.ndim != 2:
        raise SystemExit(f"{path}: expected a single-channel image, got shape {a.shape}")
    return a


def crop_box(img, bg, margin=40):
    """Bounding box (rows, cols) of the pixels that differ from the background."""
    ys, xs = np.nonzero(np.abs(img - bg) > 1e-3)
    if len(xs) == 0:
        return slice(None), slice(None)
    y0, y1 = max(ys.min() - margin, 0), min(ys.max() + margin, img.shape[0])
    x0, x1 = max(xs.min() - margin, 0), min(xs.max() + margin, img.shape[1])
    return slice(y0, y1), slice(x0, x1)


T = load("t_stiffener_direct.tiff")
rows, cols = crop_box(T, T[0, 0])
extent = (cols.start - 0.5, cols.stop - 0.5, rows.stop - 0.5, rows.start - 0.5)  # mrcal pixel centres
panels = [
    ("T-stiffener, direct light", load("t_stiffener_direct.tiff"), "gray"),
    ("T-stiffener, thesis interreflection", load("t_stiffener_thesis.tiff"), "gray"),
    ("T-stiffener, MC interreflection + 12-bit sensor", load("t_stiffener_mc_sensor.png"), "gray"),
    ("wrong: I-stiffener (flat bar)", load("i_stiffener_direct.tiff"), "gray"),
    ("wrong: no stiffener", load("no_stiffener_direct.tiff"), "gray"),
    ("wrong: T shifted +5 mm in x", load("t_shifted_5mm_direct.tiff"), "gray"),
]
diffs = [
    ("T - I-stiffener", T - panels[3][1]),
    ("T - no stiffener", T - panels[4][1]),
    ("T - T shifted 5 mm", T - panels[5][1]),
]

fig, axes = plt.subplots(3, 4, figsize=(22, 13.5), gridspec_kw={"width_ratios": [1, 1, 1, 1]})
vmax = max(np.percentile(p[1][rows, cols], 99.9) for p in panels)
for k, (title, img, cmap) in enumerate(panels):
    ax = axes[k // 3, k % 3]
    h = ax.imshow(img[rows, cols], cmap=cmap, vmin=0, vmax=vmax, extent=extent, interpolation="nearest")
    ax.set_title(title, fontsize=11)
    fig.colorbar(h, ax=ax, fraction=0.046, pad=0.02, label="P (DN)")
for k, (title, d) in enumerate(diffs):
    ax = axes[2, k]
    lim = max(np.percentile(np.abs(d[rows, cols]), 99.5), 1.0)
    h = ax.imshow(d[rows, cols], cmap="RdBu_r", vmin=-lim, vmax=lim, extent=extent, interpolation="nearest")
    changed = np.abs(d) > 1.0
    ax.set_title(f"{title}: mean |diff| {np.abs(d).mean():.1f} DN,\n"
                 f"{changed.sum()} px differ by > 1 DN", fontsize=11)
    fig.colorbar(h, ax=ax, fraction=0.046, pad=0.02, label="difference (DN)")

# Column 4: the predicted edges over the direct image, and the contrast histogram.
ax = axes[0, 3]
ax.imshow(T[rows, cols], cmap="gray", vmin=0, vmax=vmax, extent=extent, interpolation="nearest")
with open(os.path.join(outdir, "t_stiffener_edges.json")) as f:
    E = json.load(f)
contrasts = []
cm = plt.get_cmap("viridis")
cmax = max([abs(s["contrast_dn"]) for e in E["edges"] for s in e["segments"]] + [1.0])
for e in E["edges"]:
    for s in e["segments"]:
        c = abs(s["contrast_dn"])
        contrasts.append(c)
        ax.plot([s["q0_px"][0], s["q1_px"][0]], [s["q0_px"][1], s["q1_px"][1]], "-", color=cm(c / cmax), lw=2)
ax.set_xlim(extent[0], extent[1])
ax.set_ylim(extent[2], extent[3])
sm = matplotlib.cm.ScalarMappable(cmap=cm, norm=matplotlib.colors.Normalize(0, cmax))
fig.colorbar(sm, ax=ax, fraction=0.046, pad=0.02, label="|contrast| (DN)")
ax.set_title(f"predicted visible edges ({len(contrasts)} segments)", fontsize=11)
ax = axes[1, 3]
ax.hist(contrasts, bins=20, color="tab:blue")
ax.set_xlabel("|P side 0 - P side 1| (DN)")
ax.set_ylabel("segments")
ax.set_title("edge contrast, direct light", fontsize=11)
# Interreflection: what the thesis bounce and MC add to the direct image.
ax = axes[2, 3]
d = panels[1][1] - T
fg = T != T[0, 0]   # pixels of the workpiece
lim = max(np.percentile(np.abs(d[fg]), 99.9), 1.0)
h = ax.imshow(d[rows, cols], cmap="RdBu_r", vmin=-lim, vmax=lim, extent=extent, interpolation="nearest")
ax.set_title(f"thesis interreflection - direct: mean {d[fg].mean():.1f} DN,\n"
             f"median {np.median(d[fg]):.2f} DN, max {d[fg].max():.0f} DN", fontsize=11)
fig.colorbar(h, ax=ax, fraction=0.046, pad=0.02, label="difference (DN)")
for ax in axes.flat:
    ax.tick_params(labelsize=8)
fig.suptitle("refl demo: T-stiffener workpiece (thesis ch. 6) — grey value P in DN, pixel coordinates "
             "(mrcal: (0,0) = centre of the top-left pixel)", fontsize=14)
fig.tight_layout()
out = os.path.join(outdir, "figure.png")
fig.savefig(out, dpi=80)
print(out)
