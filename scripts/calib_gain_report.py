#!/usr/bin/python3
"""Plots of `refl calib gain` (run by refl through /usr/bin/python3).

usage: calib_gain_report.py GAIN_JSON OUT_DIR

Reads gain.json and the float TIFF maps next to it and writes into OUT_DIR:
ptc.png, linearity.png, linearisation.png, snr.png, kc.png, prnu_map.png, prnu_hist.png, dark.png.
Only plots what refl computed; no figure is recomputed here except the fitted
lines drawn from the published coefficients.
"""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402


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
    base = os.path.dirname(os.path.abspath(jpath))
    gains = g["gains"]
    ref = gains[0]

    # photon transfer
    fig, ax = plt.subplots(figsize=(8, 5))
    for e in gains:
        c = e["curves"]
        mu, var = arr(c["signal_dn"]), arr(c["signal_variance_dn2"])
        ax.plot(mu, var, "o", ms=3, label="%g dB" % e["gain_db"])
        K = e["system_gain_dn_per_e"]
        sat = e["saturation_dn"]
        x = np.linspace(0, 0.7 * sat, 50)
        ax.plot(x, K * x, "-", lw=0.8, label="K = %.4g DN/e- (%g dB)" % (K, e["gain_db"]))
        ax.axvline(sat, ls=":", lw=0.8, color="grey")
    ax.set_xlabel("signal mu_y - mu_y.dark (DN)")
    ax.set_ylabel("temporal variance sigma^2_y - sigma^2_y.dark (DN^2)")
    ax.set_title("Photon transfer (dotted: saturation)")
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
    a2.set_xlabel("exposure (us)")
    a2.set_ylabel("dark temporal variance (DN^2)")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "dark.png"), dpi=90)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
