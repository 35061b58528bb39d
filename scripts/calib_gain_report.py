#!/usr/bin/python3
"""Plots of `refl calib gain` (run by refl through /usr/bin/python3).

usage: calib_gain_report.py GAIN_JSON OUT_DIR

Reads gain.json and the float TIFF maps next to it and writes into OUT_DIR:
ptc.png, linearity.png, linearisation.png, snr.png, kc.png, prnu_map.png, prnu_hist.png, dark.png and,
from gain.json's "emva1288" (EMVA 1288 Release 4.0 Linear), snr_photons.png, spectrogram_h.png,
spectrogram_v.png, profiles.png, log_histograms.png, defect_map.png.
Only plots what refl computed; no figure is recomputed here except the fitted
lines drawn from the published coefficients.
"""
import json
import os
import sys

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402
from report_common import Bad, check_format  # noqa: E402


def arr(v):
    return np.array([np.nan if x is None else x for x in v], dtype=float)


def read_map(path):
    im = Image.open(path)
    return np.array(im, dtype=np.float32)


def main():
    if len(sys.argv) != 3:
        sys.stderr.write(__doc__)
        return 2
    jpath, out = sys.argv[1], sys.argv[2]
    with open(jpath) as f:
        g = json.load(f)
    try:
        check_format(g, jpath, "refl-gain")
    except Bad as b:
        sys.stderr.write(f"calib_gain_report.py: {b.path}: {b.msg}\n")
        return 1
    base = os.path.dirname(os.path.abspath(jpath))
    gains = g["gains"]
    ref = gains[0]

    # photon transfer
    fig, ax = plt.subplots(figsize=(8, 5))
    for e in gains:
        c = e["curves"]
        mu, var = arr(c["signal_dn"]), arr(c["signal_variance_dn2"])
        pts = ax.plot(mu, var, "o", ms=3, label="%g dB" % e["gain_db"])
        K0 = e["system_gain_dn_per_e"]
        sat = e["saturation_dn"]
        x = np.linspace(0, 0.7 * sat, 50)
        std = e.get("emva1288", {})
        K = std.get("system_gain_dn_per_e")
        i_sat = std.get("saturation_step")
        if isinstance(K, (int, float)) and isinstance(i_sat, int) and 0 <= i_sat < len(mu):
            xs = np.linspace(0, 0.7 * mu[i_sat], 50)
            ax.plot(xs, K * xs, "-", lw=1, color=pts[0].get_color(),
                    label="EMVA 1288 K = %.4g DN/e- (%g dB): through the origin, 0..70 %% of saturation"
                    % (K, e["gain_db"]))
        ax.plot(x, K0 * x, "--", lw=0.8, color=pts[0].get_color(),
                label="refl's K0 = %.4g DN/e- (%g dB): small-signal slope of a quadratic" % (K0, e["gain_db"]))
        ax.axvline(sat, ls=":", lw=0.8, color="grey")
    ax.set_xlabel("signal mu_y - mu_y.dark (DN)")
    ax.set_ylabel("temporal variance sigma^2_y - sigma^2_y.dark (DN^2)")
    ax.set_title("Photon transfer (dotted: refl's saturation)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "ptc.png"), dpi=90)
    plt.close(fig)

    # linearity and deviation
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for e in gains:
        c = e["curves"]
        t, mu, dev = arr(c["exposure_us"]), arr(c["signal_dn"]), arr(c["linearity_deviation_pct"])
        a1.plot(t, mu, "o", ms=3, label="%g dB" % e["gain_db"])
        a1.plot(t, e["response_offset_dn"] + e["response_dn_per_us"] * t, "-", lw=0.8)
        a2.plot(t, dev, "o-", ms=3, label="%g dB: LE %.3f %%" % (e["gain_db"], e["linearity_error_pct"]))
    a1.set_ylabel("signal (DN)")
    a1.set_title("Linearity (EMVA 1288 Release 4.0: the line of least squared relative deviations over 5..95 % of saturation)", fontsize=9)
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a2.set_xlabel("exposure (us)")
    a2.set_ylabel("deviation from the line (%)")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "linearity.png"), dpi=90)
    plt.close(fig)

    # the response linearisation of the reference gain: linear / measured at the table's knots, and
    # S(1 - aS)'s inverse from the published a
    lin = g.get("linearisation")
    if lin is not None:
        fig, ax = plt.subplots(figsize=(8, 5))
        if "measured_dn" in lin:
            m, s = arr(lin["measured_dn"]), arr(lin["linear_dn"])
            ok = m > 0
            ax.plot(m[ok], s[ok] / m[ok], "o-", ms=3, lw=0.8, label="monotone table (knots)")
        a = lin.get("a_per_dn") or 0
        x = np.linspace(1, g["saturation_dn"], 200)
        if a > 0:
            ax.plot(x, 2 / (1 + np.sqrt(np.maximum(1 - 4 * a * x, 1e-12))), "--", lw=0.8,
                    label="S(1 - aS), a = %.3g per DN" % a)
        ax.axvline(g["saturation_dn"], ls=":", lw=0.8, color="grey")
        ax.set_xlabel("measured signal above dark (DN)")
        ax.set_ylabel("linear / measured")
        ax.set_title("Response linearisation (applied: %s; LE after: %.3g %%, S(1 - aS): %.3g %%)"
                     % (lin["method"], lin.get("linearity_error_linearised_pct") or float("nan"),
                        lin.get("linearity_error_linearised_parametric_pct") or float("nan")), fontsize=9)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(out, "linearisation.png"), dpi=90)
        plt.close(fig)

    # SNR
    fig, ax = plt.subplots(figsize=(8, 5))
    for e in gains:
        c = e["curves"]
        mu, snr = arr(c["signal_dn"]), arr(c["snr"])
        ok = (mu > 0) & (mu <= e["saturation_dn"])
        ax.loglog(mu[ok], snr[ok], "o", ms=3, label="%g dB (max %.0f)" % (e["gain_db"], e["snr_max"]))
        K = e["system_gain_dn_per_e"]
        x = mu[ok]
        ax.loglog(x, np.sqrt(x / K), "--", lw=0.8, label="shot-noise limit sqrt(mu/K), %g dB" % e["gain_db"])
    ax.set_xlabel("signal (DN)")
    ax.set_ylabel("SNR")
    ax.set_title("Signal-to-noise ratio (up to saturation)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "snr.png"), dpi=90)
    plt.close(fig)

    # kc per exposure and gain
    fig, ax = plt.subplots(figsize=(8, 5))
    have = False
    for e in gains:
        c = e["curves"]
        t, kc = arr(c["exposure_us"]), arr(c["kc"])
        if np.all(np.isnan(kc)):
            kc = arr(c["signal_dn"])
            lab = "signal (DN; radiance unknown)"
        else:
            have = True
            lab = "kc"
        ax.plot(t, kc / t, "o", ms=3, label="%g dB" % e["gain_db"])
    ax.set_xlabel("exposure (us)")
    ax.set_ylabel("kc per us (DN per radiance unit per us)" if have else lab + " per us")
    ax.set_title("Response per unit radiance and microsecond, per gain")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "kc.png"), dpi=90)
    plt.close(fig)

    # PRNU maps and histograms
    maps = g["maps"]
    tot = read_map(os.path.join(base, maps["prnu_gain"]))
    hp = read_map(os.path.join(base, maps["prnu_highpass"]))
    dsnu = read_map(os.path.join(base, maps["dsnu_dn"]))
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.8))
    lo, hi = np.percentile(tot, [0.5, 99.5])
    im = a1.imshow(tot, cmap="viridis", vmin=lo, vmax=hi)
    a1.set_title("g(x,y) total (incl. vignetting), mean 1")
    fig.colorbar(im, ax=a1, shrink=0.8)
    lo, hi = np.percentile(hp, [0.5, 99.5])
    im = a2.imshow(hp, cmap="viridis", vmin=lo, vmax=hi)
    a2.set_title("high-pass PRNU (smooth part removed): %.3f %%" % g["prnu_pct"])
    fig.colorbar(im, ax=a2, shrink=0.8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "prnu_map.png"), dpi=80)
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    a1.hist(100 * (hp.ravel() - 1), bins=200, log=True)
    a1.set_xlabel("high-pass PRNU: g - 1 (%)")
    a1.set_ylabel("pixels")
    a1.set_title("PRNU histogram (%.3f %%)" % g["prnu_pct"])
    a2.hist(dsnu.ravel(), bins=200, log=True, color="tab:orange")
    a2.set_xlabel("dark level minus its mean (DN)")
    a2.set_title("DSNU histogram (%.3f DN)" % g["dsnu_dn"])
    fig.tight_layout()
    fig.savefig(os.path.join(out, "prnu_hist.png"), dpi=80)
    plt.close(fig)

    # dark signal
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    c = ref["curves"]
    t = arr(c["exposure_us"])
    a1.plot(t, arr(c["dark_mean_dn"]), "o", ms=3, label="sweep darks")
    tt = np.linspace(0, max(t.max(), 1), 50)
    a1.plot(tt, ref["dark_level_dn"] + ref["dark_current_dn_per_s"] * 1e-6 * tt, "-",
            label="fit: %.3g e-/s" % ref["dark_current_e_per_s"])
    a1.set_xlabel("exposure (us)")
    a1.set_ylabel("mean dark level (DN)")
    a1.set_title("Dark level against exposure (sweep range)")
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a2.plot(t, arr(c["dark_variance_dn2"]), "o", ms=3)
    a2.axhline(ref["dark_temporal_variance_dn2"], ls="--", lw=0.8, label="sigma^2_y.dark at 0 us")
    dv = ref.get("dark_current_from_variance_e_per_s")
    if isinstance(dv, (int, float)):
        K = ref["system_gain_dn_per_e"]
        a2.plot(tt, ref["dark_temporal_variance_dn2"] + dv * K * K * 1e-6 * tt, "-", lw=0.8,
                label="fit: %.3g e-/s (from the variance)" % dv)
    a2.set_xlabel("exposure (us)")
    a2.set_ylabel("dark temporal variance (DN^2)")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "dark.png"), dpi=90)
    plt.close(fig)
    if "emva1288" in g:
        emva_plots(g, base, out)
    return 0


def num(v):
    return v if isinstance(v, (int, float)) else float("nan")


def row_value(e, symbol, unit):
    for r in e["datasheet"]:
        if r["symbol"] == symbol and r["unit"] == unit:
            return r["value"]
    return None


def save(fig, out, name, dpi=90):
    fig.tight_layout()
    fig.savefig(os.path.join(out, name), dpi=dpi)
    plt.close(fig)


def emva_plots(g, base, out):
    """The EMVA 1288 figures: only what refl computed (gain.json "emva1288")."""
    e = g["emva1288"]
    measured = e["photon_axis"] == "measured"

    # SNR against photons (electrons when the photon axis is not measured)
    c = e["snr_curve"]
    x = arr(c["photons"] if measured else c["electrons"])
    snr = arr(c["snr_measured"])
    # up to saturation (beyond it the variance collapses and the ratio means nothing)
    sat_e = num(row_value(e, "mu_e.sat", "e-"))
    ok = (x > 0) & (snr > 0) & (arr(c["electrons"]) <= sat_e * 1.0001)
    fig, ax = plt.subplots(figsize=(8, 5))
    ax.loglog(x[ok], snr[ok], "o", ms=3, label="measured (mu_y - mu_y.dark) / sigma_y")
    if measured:
        if "grid_photons" in c:
            gx = arr(c["grid_photons"])
            ax.loglog(gx, arr(c["grid_snr_model"]), "-", lw=1,
                      label="linear model, eta = %.3g" % (num(row_value(e, "eta", "%")) / 100))
            ax.loglog(gx, arr(c["grid_snr_ideal"]), "--", lw=0.8, label="ideal sqrt(mu_p)")
            ax.axhline(1, ls=":", lw=0.8, color="grey")
        for sym, lab in (("mu_p.min", "threshold"), ("mu_p.sat", "saturation")):
            v = row_value(e, sym, "photons")
            if isinstance(v, (int, float)):
                ax.axvline(v, ls=":", lw=0.8, color="grey")
                ax.text(v, ax.get_ylim()[0] * 1.5, " %s %.3g" % (lab, v), fontsize=8, rotation=90)
        ax.set_xlabel("photons per pixel mu_p")
    else:
        ax.set_xlabel("electrons per pixel mu_e (photon axis not measured: no --irradiance)")
    ax.set_ylabel("SNR")
    ax.set_title("SNR (EMVA 1288 Release 4.0 Linear)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    save(fig, out, "snr_photons.png")

    # spectrograms
    sp = e["spatial"]
    for key, name, what in (("horizontal", "spectrogram_h.png", "along the rows: column patterns"),
                            ("vertical", "spectrogram_v.png", "along the columns: row patterns")):
        s = e["spectrograms"][key]
        f = arr(s["frequency_cycles_per_px"])
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
        for ax, vals, unit, split, lab in ((a1, arr(s["dark_dn"]), "DN", sp["dsnu_dn"], "dark (DSNU)"),
                                           (a2, arr(s["light_pct"]), "%", sp["prnu_pct"], "light (PRNU)")):
            ax.semilogy(f[1:], vals[1:], "-", lw=0.8)
            # white levels: the pixel part alone, and with the column (horizontal) or row (vertical) part, which
            # is white along that direction too
            pix, other = num(split["pixel"]), num(split["column" if key == "horizontal" else "row"])
            if pix > 0:
                ax.axhline(pix, ls="--", lw=0.8, color="grey", label="pixel part %.3g %s" % (pix, unit))
                both = np.hypot(pix, other)
                ax.axhline(both, ls=":", lw=0.8, color="black",
                           label="pixel and %s parts %.3g %s (white if random)" % (
                               "column" if key == "horizontal" else "row", both, unit))
                ax.legend(fontsize=8)
            fmt = matplotlib.ticker.FormatStrFormatter("%.3g")
            ax.yaxis.set_major_formatter(fmt)
            ax.yaxis.set_minor_formatter(fmt)
            ax.tick_params(axis="y", which="minor", labelsize=7)
            ax.set_xlabel("frequency (cycles per pixel)")
            ax.set_ylabel("standard deviation (%s)" % unit)
            ax.set_title("%s spectrogram, %s" % (key, lab), fontsize=10)
            ax.grid(alpha=0.3, which="both")
        fig.suptitle("%s spectrogram (%s); frequency 0 left out" % (key.capitalize(), what), fontsize=10)
        save(fig, out, name)

    # profiles
    p = e["profiles"]
    fig, axs = plt.subplots(2, 2, figsize=(12, 7))
    for ax, k, xl in ((axs[0][0], "column_dark_dn", "column"), (axs[0][1], "column_signal_dn", "column"),
                      (axs[1][0], "row_dark_dn", "row"), (axs[1][1], "row_signal_dn", "row")):
        v = arr(p[k])
        ax.plot(np.arange(len(v)), v, "-", lw=0.8)
        ax.set_xlabel("%s (pixels from the region's edge)" % xl)
        ax.set_ylabel("mean (DN)")
        ax.set_title("%s profile: %s means" % ("horizontal" if xl == "column" else "vertical", k.replace("_dn", "")
                                                .replace("_", " ")), fontsize=10)
        ax.grid(alpha=0.3)
    save(fig, out, "profiles.png")

    # logarithmic histograms
    d = e["defects"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    for ax, h, thr, lab, col in ((a1, d["histogram_dark"], [d["hot_threshold_dn"]], "dark", "tab:orange"),
                                 (a2, d["histogram_light"],
                                  [-100 * num(d["light_threshold"]) / num(d["light_median"]),
                                   100 * num(d["light_threshold"]) / num(d["light_median"])], "light", "tab:blue")):
        counts = np.array(h["counts"], dtype=float)
        edges = np.linspace(num(h["lo"]), num(h["hi"]), len(counts) + 1)
        ax.stairs(np.where(counts > 0, counts, np.nan), edges, color=col)
        ax.set_yscale("log")
        for t in thr:
            ax.axvline(t, ls="--", lw=0.8, color="red")
        ax.set_xlabel("deviation: %s" % h["unit"])
        ax.set_ylabel("pixels (log)")
        ax.set_title("%s: %s" % (lab, "hot %d" % d["hot"] if lab == "dark" else
                                 "dead %d, bright %d" % (d["dead"], d["bright"])), fontsize=10)
        ax.grid(alpha=0.3, which="both")
    fig.suptitle("Logarithmic histograms (dashed: the defect thresholds, %g robust std)" % d["nsigma"], fontsize=10)
    save(fig, out, "log_histograms.png")

    # the defect map
    m = read_map(os.path.join(base, d["map"]))
    fig, ax = plt.subplots(figsize=(8, 6))
    cmap = matplotlib.colors.ListedColormap(["#f4f4f4", "tab:red", "black", "tab:orange"])
    im = ax.imshow(m, cmap=cmap, vmin=-0.5, vmax=3.5, interpolation="nearest")
    cb = fig.colorbar(im, ax=ax, ticks=[0, 1, 2, 3], shrink=0.8)
    cb.ax.set_yticklabels(["good", "hot", "dead", "bright"])
    for key, mk, col in (("hot_pixels", "o", "tab:red"), ("dead_pixels", "s", "black"),
                         ("bright_pixels", "^", "tab:orange")):
        pts = np.array(d[key], dtype=float).reshape(-1, 2)
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], s=60, facecolors="none", edgecolors=col, marker=mk,
                       label="%s (%d)" % (key.replace("_", " "), d[key.split("_")[0]]))
    if any(len(d[k]) for k in ("hot_pixels", "dead_pixels", "bright_pixels")):
        ax.legend(fontsize=8, loc="upper right")
    ax.set_xlabel("x (pixels)")
    ax.set_ylabel("y (pixels)")
    nd = d["hot"] + d["dead"] + d["bright"]
    ax.set_title("Defect pixels (defects.tiff): hot %d, dead %d, bright %d%s" % (
        d["hot"], d["dead"], d["bright"], "; markers circle the first listed" if nd else ": none"), fontsize=10)
    save(fig, out, "defect_map.png")


if __name__ == "__main__":
    sys.exit(main())
