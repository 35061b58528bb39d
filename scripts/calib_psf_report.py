#!/usr/bin/python3
"""The lens blur's figure of `refl calib geometry`'s report (calib/geometry/psf.c computes; this only plots):
scripts/calib_geometry_report.py plots imports it and calls plot(plt, outdir).

Reads OUTDIR/psf_esf.csv (camera,u_px,samples,esf_measured,esf_model,lsf_measured_per_px,lsf_model_per_px:
the supersampled edge spread function of the used edges, normalised 0..1 between each edge's fitted levels,
against the distance u from the fitted edge in px, and its line spread function, measured and modelled) and
OUTDIR/psf_edges.csv (one row per edge fitted: its sigma_px, used) and writes OUTDIR/psf.png for the first
camera (the rows whose camera is the first row's). Without psf_esf.csv (no estimate) it writes nothing.
"""
import csv
import math
import os


def _rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def plot(plt, outdir):
    esf_path, edges_path = os.path.join(outdir, "psf_esf.csv"), os.path.join(outdir, "psf_edges.csv")
    if not os.path.exists(esf_path):
        return
    rows = _rows(esf_path)
    if not rows:
        return
    cam = rows[0]["camera"]
    rows = [r for r in rows if r["camera"] == cam]
    u = [float(r["u_px"]) for r in rows]
    em, ed = [float(r["esf_measured"]) for r in rows], [float(r["esf_model"]) for r in rows]
    lm, ld = [float(r["lsf_measured_per_px"]) for r in rows], [float(r["lsf_model_per_px"]) for r in rows]
    sig = []
    if os.path.exists(edges_path):
        sig = [float(r["sigma_px"]) for r in _rows(edges_path)
               if r["camera"] == cam and r["used"] == "1" and math.isfinite(float(r["sigma_px"]))]
    fig, axs = plt.subplots(1, 3, figsize=(15, 4.4))
    axs[0].plot(u, em, ".", ms=3, color="#4477aa", label="measured (1/8 px bins)")
    axs[0].plot(u, ed, "-", color="#ee6677", label="model")
    axs[0].set_xlabel("distance from the fitted edge (px)")
    axs[0].set_ylabel("edge spread (0: one level, 1: the other)")
    axs[0].set_title("edge spread function", fontsize=10)
    axs[0].legend(fontsize=8)
    axs[1].plot(u, lm, ".", ms=3, color="#4477aa", label="measured (central differences)")
    axs[1].plot(u, ld, "-", color="#ee6677", label="model")
    axs[1].set_xlabel("distance from the fitted edge (px)")
    axs[1].set_ylabel("line spread (1/px)")
    axs[1].set_title("line spread function", fontsize=10)
    axs[1].legend(fontsize=8)
    if sig:
        s = sorted(sig)
        med = s[len(s) // 2] if len(s) % 2 else 0.5 * (s[len(s) // 2 - 1] + s[len(s) // 2])
        axs[2].hist(sig, bins=40, color="#4477aa")
        axs[2].axvline(med, color="#ee6677", label=f"median {med:.3f} px")
        axs[2].legend(fontsize=8)
    axs[2].set_xlabel("sigma of one edge (px)")
    axs[2].set_ylabel("edges")
    axs[2].set_title(f"the edges' Gaussian sigma ({len(sig)} used)", fontsize=10)
    fig.suptitle("lens blur from the board's edges: step * Gaussian PSF * the pixel's 1 px footprint"
                 + (f" (camera {cam})" if cam else ""), fontsize=11)
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "psf.png"), dpi=90)
    plt.close(fig)
