#!/usr/bin/python3
"""Plot of refl calib pattern (calib/lamps/pattern.c computes every value; this only draws).

usage: calib_pattern_report.py PATTERN_WINDOWS.csv PATTERN.png

PATTERN_WINDOWS.csv: lamp, angle_from_axis_deg (the window's direction from the lamp against the fitted
emission axis), irradiance_rel (the window's irradiance over the lamp's fitted on-axis value), pattern_rel (the
fitted pattern max(0, cos)^n there), sigma_rel (the window's relative noise) and, when present, cos_power and
cos_power_std (the lamp's fitted n and its 1-sigma) and isotropic (1: refl found the lamp isotropic, n within 3
sigma of 0, so its axis is not determined: the panel says so and names no axis).
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.stderr.write(__doc__)
        return 2
    lamps, fits = {}, {}
    with open(sys.argv[1]) as f:
        for row in csv.DictReader(f):
            d = lamps.setdefault(row["lamp"], ([], [], [], []))
            for k, key in enumerate(("angle_from_axis_deg", "irradiance_rel", "pattern_rel", "sigma_rel")):
                d[k].append(float(row[key]))
            if row.get("cos_power") not in (None, ""):
                fits[row["lamp"]] = (float(row["cos_power"]), float(row["cos_power_std"]), row.get("isotropic") == "1")
    if not lamps:
        sys.stderr.write("calib_pattern_report.py: no fitted lamp in %s\n" % sys.argv[1])
        return 1
    n = len(lamps)
    fig, axes = plt.subplots(2, n, figsize=(3.6 * n + 1, 7), squeeze=False,
                             gridspec_kw={"height_ratios": [2, 1]})
    for k, (name, (ang, y, fit, sig)) in enumerate(lamps.items()):
        ang, y, fit, sig = map(np.asarray, (ang, y, fit, sig))
        order = np.argsort(ang)
        ax = axes[0][k]
        ax.plot(ang, y, ".", ms=2, alpha=0.35, color="tab:blue", label="windows")
        ax.plot(ang[order], fit[order], "-", color="tab:red", lw=2, label="fitted max(0, cos)^n")
        ax.axhline(1.0, color="0.6", lw=0.8, ls=":", label="isotropic")
        lo, hi = np.percentile(y, [0.5, 99.5])
        pad = max(0.1 * (hi - lo), 0.002)
        ax.set_ylim(min(lo, fit.min()) - pad, max(hi, fit.max(), 1.0) + pad)
        n_, sd_, iso = fits.get(name, (None, None, False))
        ax.set_title("lamp %s%s\n(outside the plot: %d of %d)" % (
            name, "" if n_ is None else ": isotropic, n = %.2f ± %.2f" % (n_, sd_) if iso else
            ": n = %.2f ± %.2f" % (n_, sd_), np.sum((y < lo - pad) | (y > hi + pad)), len(y)), fontsize=10)
        ax.set_xlabel("angle from the fitted axis (deg; isotropic: no axis)" if iso else
                      "angle from the emission axis (deg)")
        ax.set_ylabel("irradiance / on-axis (1)")
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(loc="lower left", fontsize=8)
        ax = axes[1][k]
        res = 100.0 * (y / np.where(fit > 0, fit, np.nan) - 1.0)
        ax.plot(ang, res, ".", ms=2, alpha=0.35, color="tab:blue")
        band = 100.0 * np.median(sig)
        ax.axhspan(-band, band, color="tab:green", alpha=0.15, label="median window noise ±1σ")
        ax.axhline(0, color="0.4", lw=0.8)
        ax.set_xlabel("angle from the fitted axis (deg; isotropic: no axis)" if iso else
                      "angle from the emission axis (deg)")
        ax.set_ylabel("residual (%)")
        lim = max(1.0, np.nanpercentile(np.abs(res), 99) * 1.2) if np.isfinite(res).any() else 1.0
        ax.set_ylim(-lim, lim)
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=90)
    return 0


if __name__ == "__main__":
    sys.exit(main())
