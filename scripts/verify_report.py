#!/usr/bin/python3
"""Report of `refl verify` (fit/verify/verify.c computes every number; this script only
draws and lays out what refl wrote).

usage: verify_report.py DIR

DIR/verify.json ("format" "refl-verify", "version" 1): "verdict" (correct|incorrect), "score", "score_threshold",
"residue" and "residue_per_image" (|measured - model| at the reference points,
DN, and z), "reference_points" (counts per status), "change_regions" ({image,
n_points, area_px, excess_chi2, max_abs_z, bbox_px [x0,y0,x1,y1], faces}),
"parameters", "warnings", "images" ([{name, file, actual_tiff, synthetic_tiff,
turntable_deg, lamps_on, exposure_us}]; the TIFFs are single-page float32, DN,
relative to DIR; the synthetic one is the fitted model, NaN where the
description has no surface), "scene", "provenance", "options" (z_flag,
spacing_px), "fit".
DIR/points.csv: image,x_px,y_px,face,status,flag,region,measured_dn,model_dn,
sigma_dn,z,footprint (image: index into "images"; pixels in the mrcal
convention, (0,0) the centre of the top-left pixel, y down; measured_dn ..
z empty where nothing was measured; footprint 1: a window near an edge,
modelled with the pixels' footprint and the blur).

Writes into DIR: views.png (actual | synthetic | actual - synthetic per image),
zmap.png (z at the reference points), residue.png (histogram of z) and
index.html (verdict, tables, figures, provenance).
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from report_common import (Bad, dict_table, e, fmt, is_num, load_json, provenance_head,  # noqa: E402
                           provenance_section, read_float_tiff, read_table, run_report, table, write_page)

PROG = "verify_report.py"
STATUS_MEANING = {
    "used": "in the fit and the judgement",
    "background": "the ray misses the description",
    "near_edge": "within edge_margin_px of a predicted edge",
    "boundary": "the window's corners see another face or another shadow state",
    "saturated": "the window reaches the saturation level",
    "edge_measured": "the window's spread says edge where none is predicted (a flag)",
}
POINT_COLUMNS = ["image", "x_px", "y_px", "face", "status", "flag", "region",
                 "measured_dn", "model_dn", "sigma_dn", "z", "footprint"]
Z_CLIP = 8.0
DIFF_CLIP = 5.0
BOX_COLOUR = "#00b000"
NAN_SYNTH = "#3b7dd8"
NAN_DIFF = "#b0b0b0"


# ---------------------------------------------------------------------------
# inputs

class Checker:
    """Typed access to verify.json; any mismatch is a Bad naming the JSON path."""

    def __init__(self, path):
        self.path = path

    def bad(self, where, msg):
        raise Bad(self.path, f"{where}: {msg}" if where else msg)

    def get(self, o, key, where, kind, optional=False, default=None):
        w = f"{where}.{key}" if where else key
        if not isinstance(o, dict):
            self.bad(where, "expected an object")
        if key not in o:
            if optional:
                return default
            self.bad(w, "missing")
        v = o[key]
        if kind == "num":
            if v is None and optional:
                return math.nan
            if not is_num(v):
                self.bad(w, f"expected a number, got {json.dumps(v)}")
            return float(v)
        if kind == "num|null":
            if v is None:
                return math.nan
            if not is_num(v):
                self.bad(w, f"expected a number or null, got {json.dumps(v)}")
            return float(v)
        if kind == "int":
            if not is_num(v) or float(v) != int(v):
                self.bad(w, f"expected an integer, got {json.dumps(v)}")
            return int(v)
        if kind == "str":
            if not isinstance(v, str):
                self.bad(w, f"expected a string, got {json.dumps(v)}")
            return v
        if kind == "bool":
            if not isinstance(v, bool):
                self.bad(w, f"expected true or false, got {json.dumps(v)}")
            return v
        if kind == "list":
            if not isinstance(v, list):
                self.bad(w, "expected a list")
            return v
        if kind == "dict":
            if not isinstance(v, dict):
                self.bad(w, "expected an object")
            return v
        return v


STAT_KEYS = [("n_points", "int"), ("max_abs_diff_dn", "num|null"), ("mean_abs_diff_dn", "num|null"),
             ("std_abs_diff_dn", "num|null"), ("robust_sigma_dn", "num|null"), ("rms_z", "num|null"),
             ("median_abs_z", "num|null")]


def load_verify(d):
    jpath = os.path.join(d, "verify.json")
    raw = load_json(jpath)
    c = Checker(jpath)
    # "format": "refl-verify", "version" 1 (a file without the keys is version 1)
    fmt_, ver = raw.get("format"), raw.get("version", 1 if "format" not in raw else None)
    if fmt_ is not None and fmt_ != "refl-verify":
        c.bad("format", f"a {json.dumps(fmt_)} file, not refl-verify")
    if not isinstance(ver, int) or isinstance(ver, bool) or ver < 1:
        c.bad("version", f"expected a whole number from 1, got {json.dumps(ver)}")
    if ver > 1:
        c.bad("version", f"refl-verify version {ver}, written by a newer refl (this script reads version 1)")
    v = {"raw": raw}
    v["verdict"] = c.get(raw, "verdict", "", "str")
    if v["verdict"] not in ("correct", "incorrect"):
        c.bad("verdict", f"expected \"correct\" or \"incorrect\", got {json.dumps(v['verdict'])}")
    v["score"] = c.get(raw, "score", "", "num")
    v["score_threshold"] = c.get(raw, "score_threshold", "", "num")

    def stats(o, where):
        return {k: c.get(o, k, where, kind) for k, kind in STAT_KEYS}

    v["residue"] = stats(c.get(raw, "residue", "", "dict"), "residue")
    images = c.get(raw, "images", "", "list")
    if not images:
        c.bad("images", "empty list: no images to show")
    v["images"] = []
    for i, im in enumerate(images):
        w = f"images[{i}]"
        v["images"].append({
            "name": c.get(im, "name", w, "str"),
            "file": c.get(im, "file", w, "str", optional=True, default=""),
            "actual_tiff": c.get(im, "actual_tiff", w, "str"),
            "synthetic_tiff": c.get(im, "synthetic_tiff", w, "str"),
            "turntable_deg": c.get(im, "turntable_deg", w, "num"),
            "lamps_on": im.get("lamps_on"),
            "exposure_us": c.get(im, "exposure_us", w, "num", optional=True, default=math.nan),
        })
    rpi = c.get(raw, "residue_per_image", "", "list")
    if len(rpi) != len(images):
        c.bad("residue_per_image", f"{len(rpi)} entries for {len(images)} images")
    v["residue_per_image"] = []
    for i, o in enumerate(rpi):
        s = stats(o, f"residue_per_image[{i}]")
        s["image"] = c.get(o, "image", f"residue_per_image[{i}]", "str")
        s["turntable_deg"] = c.get(o, "turntable_deg", f"residue_per_image[{i}]", "num", optional=True,
                                   default=v["images"][i]["turntable_deg"])
        v["residue_per_image"].append(s)
    rp = c.get(raw, "reference_points", "", "dict")
    v["reference_points"] = {k: c.get(rp, k, "reference_points", "int") for k in rp}

    names = [im["name"] for im in v["images"]]
    v["regions"] = []
    for i, o in enumerate(c.get(raw, "change_regions", "", "list")):
        w = f"change_regions[{i}]"
        r = {"image": c.get(o, "image", w, "str")}
        idx = c.get(o, "image_index", w, "int", optional=True, default=None)
        if idx is None:
            if r["image"] not in names:
                c.bad(w + ".image", f"{json.dumps(r['image'])} is not the name of one of the images")
            idx = names.index(r["image"])
        elif not 0 <= idx < len(names):
            c.bad(w + ".image_index", f"{idx} is not an index into the {len(names)} images")
        r["index"] = idx
        r["n_points"] = c.get(o, "n_points", w, "int")
        r["area_px"] = c.get(o, "area_px", w, "num|null")
        r["excess_chi2"] = c.get(o, "excess_chi2", w, "num|null")
        r["max_abs_z"] = c.get(o, "max_abs_z", w, "num|null")
        bb = c.get(o, "bbox_px", w, "list")
        if len(bb) != 4 or not all(is_num(x) for x in bb):
            c.bad(w + ".bbox_px", "expected [x0, y0, x1, y1] in px")
        r["bbox"] = [float(x) for x in bb]
        r["faces"] = []
        for k, fe in enumerate(c.get(o, "faces", w, "list", optional=True, default=[])):
            wf = f"{w}.faces[{k}]"
            if not isinstance(fe, dict):
                c.bad(wf, "expected an object")
            r["faces"].append({"face": fe.get("face"), "sphere": fe.get("sphere"), "line": fe.get("line"),
                               "material": fe.get("material"),
                               "n_points": c.get(fe, "n_points", wf, "int", optional=True, default=None)})
        v["regions"].append(r)

    v["parameters"] = []
    for i, o in enumerate(c.get(raw, "parameters", "", "list")):
        w = f"parameters[{i}]"
        v["parameters"].append({
            "name": c.get(o, "name", w, "str"),
            "value": c.get(o, "value", w, "num|null"),
            "std": c.get(o, "std", w, "num|null", optional=True, default=math.nan),
            "prior_mean": c.get(o, "prior_mean", w, "num|null", optional=True, default=math.nan),
            "prior_std": c.get(o, "prior_std", w, "num|null", optional=True, default=math.nan),
            "lo": c.get(o, "lo", w, "num|null", optional=True, default=math.nan),
            "hi": c.get(o, "hi", w, "num|null", optional=True, default=math.nan),
            "fixed": c.get(o, "fixed", w, "bool", optional=True, default=False),
            "pinned": c.get(o, "pinned", w, "bool", optional=True, default=False),
        })
    warns = c.get(raw, "warnings", "", "list", optional=True, default=[])
    v["warnings"] = [x if isinstance(x, str) else json.dumps(x) for x in warns]
    scene = raw.get("scene")
    v["scene"] = scene if isinstance(scene, str) and scene else "(scene not named in verify.json)"
    opts = raw.get("options") if isinstance(raw.get("options"), dict) else {}
    zf = opts.get("z_flag")
    v["z_flag"] = float(zf) if is_num(zf) and zf > 0 else None
    sp = opts.get("spacing_px")
    v["spacing_px"] = float(sp) if is_num(sp) and sp > 0 else None
    return v


def load_points(d, nimages):
    ppath = os.path.join(d, "points.csv")
    cols = {k: [] for k in POINT_COLUMNS}
    for line, row in read_table(ppath, POINT_COLUMNS):
        val = {}
        for k in POINT_COLUMNS:
            if k == "status":
                continue
            t = row[k]
            if not t and k in ("measured_dn", "model_dn", "sigma_dn", "z"):
                val[k] = math.nan   # refl leaves them empty at points without a measurement
                continue
            try:
                val[k] = int(t) if k in ("image", "face", "flag", "region", "footprint") else float(t)
            except ValueError:
                kind = "an integer" if k in ("image", "face", "flag", "region", "footprint") else "a number"
                raise Bad(ppath, f"line {line}: {k} {t!r} is not {kind}")
        img, x, y, flag = val["image"], val["x_px"], val["y_px"], val["flag"]
        status = row["status"]
        if not 0 <= img < nimages:
            raise Bad(ppath, f"line {line}: image {img} is not an index into the {nimages} images of verify.json")
        if status not in STATUS_MEANING:
            raise Bad(ppath, f"line {line}: unknown status {status!r} (expected one of "
                      + ", ".join(STATUS_MEANING) + ")")
        if flag not in (0, 1):
            raise Bad(ppath, f"line {line}: flag {flag} is not 0 or 1")
        if not (math.isfinite(x) and math.isfinite(y)):
            raise Bad(ppath, f"line {line}: x_px, y_px must be finite")
        val["status"] = status
        for k in POINT_COLUMNS:
            cols[k].append(val[k])
    p = {k: np.array(cols[k], dtype=object if k == "status" else float) for k in POINT_COLUMNS}
    p["image"] = p["image"].astype(int)
    p["flag"] = p["flag"].astype(bool)
    p["status"] = p["status"].astype(str) if len(p["status"]) else np.array([], dtype=str)
    return p


def read_tiff(path, want_desc=False):
    a, desc = read_float_tiff(path, 'named in verify.json "images"', empty_ok=True)
    if want_desc:
        # refl's TIFF metadata: "key: value" lines; "image:" says what the pixels are
        what = ""
        for line in desc.splitlines():
            if line.startswith("image:"):
                what = line[len("image:"):].strip()
        return a, what
    return a


# ---------------------------------------------------------------------------
# formatting

def robust_sigma(a):
    a = a[np.isfinite(a)]
    if not a.size:
        return math.nan
    return 1.4826 * float(np.median(np.abs(a - np.median(a))))


def z_sign_text(p):
    """The z convention as the data shows it (fit/verify/verify.h: z = (model - measured)/sigma)."""
    ok = np.isfinite(p["z"]) & np.isfinite(p["model_dn"]) & np.isfinite(p["measured_dn"])
    s = float(np.sum(p["z"][ok] * (p["model_dn"][ok] - p["measured_dn"][ok]))) if ok.any() else 1.0
    return "z = (model &minus; measured)/&sigma;" if s >= 0 else "z = (measured &minus; model)/&sigma;"


def box_pad(v):
    return 0.5 * v["spacing_px"] if v["spacing_px"] else 2.0


def draw_boxes(ax, v, m, label=True):
    pad = box_pad(v)
    for k, r in enumerate(v["regions"]):
        if r["index"] != m:
            continue
        x0, y0, x1, y1 = r["bbox"]
        ax.add_patch(Rectangle((x0 - pad, y0 - pad), x1 - x0 + 2 * pad, y1 - y0 + 2 * pad, fill=False,
                               ec=BOX_COLOUR, lw=1.5))
        if label:
            ax.text(x0 - pad, y0 - pad, f"R{k + 1}", color=BOX_COLOUR, fontsize=8, fontweight="bold",
                    ha="left", va="bottom")


# ---------------------------------------------------------------------------
# figures

def fig_views(d, v):
    """Actual | synthetic | difference per image; returns per image (W, H, sigma, small actual)."""
    n = len(v["images"])
    info = []
    fig = None
    for m, im in enumerate(v["images"]):
        act, act_desc = read_tiff(os.path.join(d, im["actual_tiff"]), True)
        syn, syn_desc = read_tiff(os.path.join(d, im["synthetic_tiff"]), True)
        if act.shape != syn.shape:
            raise Bad(os.path.join(d, im["synthetic_tiff"]),
                      f"{syn.shape[1]} x {syn.shape[0]} px, the actual image {im['actual_tiff']} is "
                      f"{act.shape[1]} x {act.shape[0]}")
        H, W = act.shape
        if fig is None:
            row_h = 5.0 * H / W + 0.9
            fig, axs = plt.subplots(n, 3, figsize=(17, row_h * n), squeeze=False)
        both = np.concatenate([act[np.isfinite(act)], syn[np.isfinite(syn)]])
        lo, hi = (np.percentile(both, [0.5, 99.8]) if both.size else (0.0, 1.0))
        if not hi > lo:
            hi = lo + 1.0
        grey = plt.get_cmap("gray").copy()
        grey.set_bad(NAN_SYNTH)
        diff = act - syn
        sig = robust_sigma(diff)
        if not (math.isfinite(sig) and sig > 0):
            sig = v["residue_per_image"][m]["robust_sigma_dn"]
        if not (math.isfinite(sig) and sig > 0):
            sig = 1.0
        lim = DIFF_CLIP * sig
        div = plt.get_cmap("RdBu_r").copy()
        div.set_bad(NAN_DIFF)
        a0, a1, a2 = axs[m]
        title = f"{os.path.basename(im['name'])}, turntable {fmt(im['turntable_deg'], '.2f')} deg"
        h0 = a0.imshow(act, cmap=grey, vmin=lo, vmax=hi)
        a0.set_title(f"{title}\nactual", fontsize=10)
        h1 = a1.imshow(syn, cmap=grey, vmin=lo, vmax=hi)
        a1.set_title(f"{title}\nsynthetic (fitted model)", fontsize=10)
        h2 = a2.imshow(diff, cmap=div, vmin=-lim, vmax=lim)
        a2.set_title(f"{title}\nactual - synthetic, clipped at ±5σ = ±{lim:.3g} DN", fontsize=10)
        for ax, h in ((a0, h0), (a1, h1), (a2, h2)):
            fig.colorbar(h, ax=ax, fraction=0.046, pad=0.02, label="DN")
            ax.set_xlabel("x (px)")
        a0.set_ylabel("y (px)")
        draw_boxes(a0, v, m)
        draw_boxes(a2, v, m)
        step = max(1, int(math.ceil(max(W, H) / 640)))
        info.append({"W": W, "H": H, "sigma": sig, "lim": lim, "small": act[::step, ::step], "step": step,
                     "act_desc": act_desc, "syn_desc": syn_desc})
        del act, syn, diff
    fig.tight_layout()
    fig.savefig(os.path.join(d, "views.png"), dpi=72)
    plt.close(fig)
    return info


def fig_zmap(d, v, p, info):
    n = len(v["images"])
    ncol = min(3, n)
    nrow = (n + ncol - 1) // ncol
    W0, H0 = info[0]["W"], info[0]["H"]
    pw = 5.2
    fig, axs = plt.subplots(nrow, ncol, figsize=(pw * ncol + 1.4, (pw * H0 / W0 + 0.9) * nrow), squeeze=False,
                            layout="constrained")
    sc = None
    for m in range(nrow * ncol):
        ax = axs[m // ncol][m % ncol]
        if m >= n:
            ax.axis("off")
            continue
        W, H, step = info[m]["W"], info[m]["H"], info[m]["step"]
        sm = info[m]["small"]
        fin = sm[np.isfinite(sm)]
        lo, hi = (np.percentile(fin, [0.5, 99.8]) if fin.size else (0.0, 1.0))
        ax.imshow(sm, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1, alpha=0.45,
                  extent=(-0.5, -0.5 + sm.shape[1] * step, -0.5 + sm.shape[0] * step, -0.5))
        sel = p["image"] == m
        zok = sel & np.isfinite(p["z"])
        other = sel & ~np.isfinite(p["z"])
        # marker side about 0.9 grid steps on the page
        px_pt = pw * 72 / W
        side = 0.9 * (v["spacing_px"] or 8.0) * px_pt
        s = float(np.clip(side * side, 1.0, 120.0))
        ax.scatter(p["x_px"][other], p["y_px"][other], s=max(s / 6, 0.5), c="0.55", marker=".", lw=0)
        sc = ax.scatter(p["x_px"][zok], p["y_px"][zok], s=s, c=np.clip(p["z"][zok], -Z_CLIP, Z_CLIP),
                        cmap="RdBu_r", vmin=-Z_CLIP, vmax=Z_CLIP, marker="s", lw=0)
        fl = sel & p["flag"]
        ax.scatter(p["x_px"][fl], p["y_px"][fl], s=max(3 * s, 12), facecolors="none", edgecolors="k", lw=0.8)
        draw_boxes(ax, v, m)
        ax.set_xlim(-0.5, W - 0.5)
        ax.set_ylim(H - 0.5, -0.5)
        ax.set_aspect("equal")
        im = v["images"][m]
        ax.set_title(f"{os.path.basename(im['name'])}, turntable {fmt(im['turntable_deg'], '.2f')} deg\n"
                     f"{int(zok.sum())} points with z, {int(fl.sum())} flagged", fontsize=9)
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
    if sc is not None:
        fig.colorbar(sc, ax=axs.ravel().tolist(), label=f"z (clipped to ±{Z_CLIP:g})", shrink=0.9)
    fig.savefig(os.path.join(d, "zmap.png"), dpi=72)
    plt.close(fig)


def fig_residue(d, v, p):
    z = p["z"][(p["status"] == "used") & np.isfinite(p["z"])] if len(p["z"]) else np.array([])
    fig, ax = plt.subplots(figsize=(9, 4.8))
    zf = v["z_flag"]
    if z.size:
        R = max(6.0, 1.5 * zf if zf else 0.0, float(np.percentile(np.abs(z), 99.5)) * 1.05)
        R = min(R, 60.0)
        nb = int(np.clip(2 * R / 0.25, 40, 240))
        bins = np.linspace(-R, R, nb + 1)
        bw = bins[1] - bins[0]
        cnt, _, _ = ax.hist(z, bins=bins, color="0.35", label="used reference points")
        x = np.linspace(-R, R, 600)
        g = z.size * bw * np.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)
        g[g < 0.05] = np.nan
        ax.plot(x, g, "k-", lw=1.2, label="standard normal, same count")
        out = int(np.sum(np.abs(z) > R))
        ax.set_yscale("log")
        ax.set_ylim(0.5, 2.0 * max(float(cnt.max()), float(np.nanmax(g))))
        ax.set_xlim(-R, R)
        rms = math.sqrt(float(np.mean(z * z)))
        ax.set_title(f"z of the {z.size} used points: rms {rms:.3g}, median |z| {np.median(np.abs(z)):.3g}"
                     + (f"; {out} beyond ±{R:.3g} not drawn" if out else ""), fontsize=10)
    else:
        ax.text(0.5, 0.5, "no used reference point with a finite z", transform=ax.transAxes, ha="center")
    if zf:
        for sgn in (-1, 1):
            ax.axvline(sgn * zf, color="tab:red", ls="--", lw=1, label=f"flag threshold ±{zf:g}" if sgn > 0 else None)
    ax.set_xlabel("z (sigma units)")
    ax.set_ylabel("points (log)")
    ax.grid(alpha=0.3)
    if z.size or zf:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(d, "residue.png"), dpi=80)
    plt.close(fig)
    return int(z.size)


# ---------------------------------------------------------------------------
# page

CSS = ("body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}"
       "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
       "text-align:left;font-size:90%}th{background:#eee}td.n{text-align:right;font-variant-numeric:tabular-nums}"
       "tr.all td{font-weight:bold}tr.pinned td{background:#ffe08a}tr.fixed td{color:#777}"
       "figure{margin:1em 0}img{max-width:100%;border:1px solid #ddd}figcaption{font-size:90%;color:#555}"
       "code{font-size:90%}pre{background:#f6f6f6;border:1px solid #ddd;padding:0.6em;overflow-x:auto;"
       "font-size:85%}.verdict{font-size:160%;font-weight:bold;color:#fff;padding:0.7em 1em;margin:0.8em 0;"
       "border-radius:6px}.verdict small{display:block;font-size:55%;font-weight:normal;margin-top:0.3em}"
       "td.path{overflow-wrap:anywhere;font-size:80%}"
       ".correct{background:#1e8e3e}.incorrect{background:#c5221f}ul.warn li{color:#8a4b00}.note{color:#555}")


def pm(a, b, spec=".6g"):
    if not (isinstance(a, float) and math.isfinite(a)):
        return "n/a"
    if isinstance(b, float) and math.isfinite(b):
        return f"{a:{spec}} &plusmn; {b:{spec}}"
    return f"{a:{spec}}"


def face_text(fe):
    n = f": {fe['n_points']}" if fe["n_points"] is not None else ""
    if fe["face"] == "background":
        return "background" + n
    if fe["sphere"] is not None and fe["face"] is None:
        return f"sphere {e(fe['sphere'])}" + n
    s = f"face {e(fe['face'])}"
    extra = [e(fe["material"])] if fe["material"] else []
    if fe["line"] is not None:
        extra.append(f"line {e(fe['line'])}")
    return s + (f" ({', '.join(extra)})" if extra else "") + n


def write_html(d, v, p, info, nused):
    raw = v["raw"]
    L = []
    title = f"refl verify: {v['scene']}"
    L.append(f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{e(title)}</title>\n'
             f"<style>{CSS}</style>\n</head><body>\n<h1>{e(title)}</h1>")
    prov = raw.get("provenance")
    head = provenance_head(prov)
    if head:
        L.append(head)
    score, thr = v["score"], v["score_threshold"]
    cmp = "&gt;" if score > thr else "&le;"
    word = "CORRECT" if v["verdict"] == "correct" else "INCORRECT"
    L.append(f'<div class="verdict {v["verdict"]}">The description is {word}'
             f"<small>score {score:.5g} {cmp} threshold {thr:.5g} (incorrect when score &gt; threshold)"
             "</small></div>")
    if (v["verdict"] == "incorrect") != (score > thr):
        L.append('<p class="note"><b>Note:</b> the verdict in verify.json does not follow from score and '
                 "threshold as written there.</p>")
    if isinstance(raw.get("score_definition"), str):
        L.append(f'<p class="note">Score: {e(raw["score_definition"])}.</p>')

    # images by their file names where those tell them apart (the full paths in the Images table)
    bases = [os.path.basename(str(im["name"])) for im in v["images"]]
    short = ({str(im["name"]): b for im, b in zip(v["images"], bases)} if len(set(bases)) == len(bases) else {})

    # residue
    L.append('<h2 id="residue">Residue</h2>')
    hdr = ["image", "turntable (deg)", "n points", "max |diff| (DN)", "mean |diff| (DN)", "std |diff| (DN)",
           "robust σ (DN)", "rms z", "median |z|"]
    rows, cls = [], []
    for s in v["residue_per_image"] + [dict(v["residue"], image="all", turntable_deg=math.nan)]:
        rows.append([e(short.get(str(s["image"]), s["image"])), fmt(s["turntable_deg"], ".2f", ""), str(s["n_points"]),
                     fmt(s["max_abs_diff_dn"], ".4g"), fmt(s["mean_abs_diff_dn"], ".4g"),
                     fmt(s["std_abs_diff_dn"], ".4g"), fmt(s["robust_sigma_dn"], ".4g"), fmt(s["rms_z"], ".3g"),
                     fmt(s["median_abs_z"], ".3g")])
        cls.append("")
    cls[-1] = "all"
    L.append(table(hdr, rows, cls, [False, True, True, True, True, True, True, True, True]))
    units = raw.get("residue_units")
    units = e(units) if isinstance(units, str) else "diff = measured &minus; model at the used reference points"
    L.append(f'<p class="note">|diff|: {units}. Robust σ = 1.4826 × MAD of diff.</p>')

    # images
    L.append('<h2 id="images">Images</h2>')
    rows = []
    for im in v["images"]:
        lamps = im["lamps_on"]
        lamps = ", ".join(map(str, lamps)) if isinstance(lamps, list) else ("" if lamps is None else str(lamps))
        rows.append([e(short.get(str(im["name"]), im["name"])), e(im["file"]),
                     fmt(im["turntable_deg"], ".2f"), e(lamps),
                     fmt(im["exposure_us"], "g"), f'<a href="{e(im["actual_tiff"])}">{e(im["actual_tiff"])}</a>',
                     f'<a href="{e(im["synthetic_tiff"])}">{e(im["synthetic_tiff"])}</a>'])
    L.append(table(["image", "file", "turntable (deg)", "lamps on", "exposure (us)", "actual (float32 TIFF, DN)",
                    "synthetic (float32 TIFF, DN)"], rows, numeric=[False, "path", True, False, True, False, False]))

    # reference points
    L.append('<h2 id="reference-points">Reference points</h2>')
    rp = v["reference_points"]
    tot = sum(rp.values())
    keys = list(STATUS_MEANING) + [k for k in rp if k not in STATUS_MEANING]
    rows = []
    for k in keys:
        if k not in rp and not np.any(p["status"] == k):
            continue
        cnt = rp.get(k)
        rows.append([e(k), "n/a" if cnt is None else str(cnt),
                     fmt(100.0 * cnt / tot, ".1f") + " %" if cnt is not None and tot else "n/a",
                     str(int(np.sum(p["status"] == k))), e(STATUS_MEANING.get(k, ""))])
    rows.append(["all", str(tot), "100 %" if tot else "n/a", str(len(p["status"])), ""])
    L.append(table(["status", "points", "share", "rows in points.csv", "meaning"], rows,
                   [""] * (len(rows) - 1) + ["all"], [False, True, True, True, False]))
    L.append(f'<p class="note">{int(np.sum(p["flag"]))} of the points in points.csv are flagged; '
             f'{int(np.sum(p["footprint"]))} of the used ones are windows near edges, modelled with the pixels\' '
             f'footprint and the camera\'s blur.</p>')

    # parameters
    L.append('<h2 id="parameters">Parameters</h2>')
    rows, cls = [], []
    for q in v["parameters"]:
        state = ", ".join(s for s, b in (("fixed", q["fixed"]), ("pinned at a bound", q["pinned"])) if b)
        prior = ("none" if not math.isfinite(q["prior_mean"]) else
                 pm(q["prior_mean"], q["prior_std"]) + ("" if math.isfinite(q["prior_std"]) else " (no std)"))
        rows.append([e(q["name"]), pm(q["value"], q["std"]), prior,
                     f"[{fmt(q['lo'], '.6g')}, {fmt(q['hi'], '.6g')}]", state])
        cls.append("pinned" if q["pinned"] else ("fixed" if q["fixed"] else ""))
    if rows:
        L.append(table(["parameter", "value ± std", "prior mean ± std", "bounds [lo, hi]", "fixed / pinned"], rows,
                       cls))
    else:
        L.append("<p>verify.json lists no parameters.</p>")
    npin = sum(q["pinned"] for q in v["parameters"])
    L.append(f'<p class="note">{npin} pinned (highlighted): at a bound, within 1e-3 of its range. '
             "std n/a: no covariance for it.</p>")
    if isinstance(raw.get("parameter_conventions"), str):
        L.append(f'<p class="note">{e(raw["parameter_conventions"])}.</p>')
    if isinstance(raw.get("fit"), dict):
        L.append("<h3>Fit</h3>" + dict_table(raw["fit"]))

    # warnings
    L.append('<h2 id="warnings">Warnings</h2>')
    if v["warnings"]:
        L.append('<ul class="warn">' + "".join(f"<li>{e(w)}</li>" for w in v["warnings"]) + "</ul>")
    else:
        L.append("<p>none</p>")

    # change regions
    L.append('<h2 id="change-regions">Change regions</h2>')
    if v["regions"]:
        rows = []
        for k, r in enumerate(v["regions"]):
            x0, y0, x1, y1 = r["bbox"]
            rows.append([f"R{k + 1}", e(r["image"]), str(r["n_points"]), fmt(r["area_px"], ".6g"),
                         fmt(r["excess_chi2"], ".5g"), fmt(r["max_abs_z"], ".3g"),
                         f"{x0:.0f}, {y0:.0f} &ndash; {x1:.0f}, {y1:.0f}",
                         "<br>".join(face_text(fe) for fe in r["faces"]) or "n/a"])
        L.append(table(["#", "image", "points", "area (px²)", "excess chi²", "max |z|", "bbox x0, y0 – x1, y1 (px)",
                        "faces: points"], rows, numeric=[False, False, True, True, True, True, False, False]))
        L.append('<p class="note">Regions of at least min_region flagged grid points (8-connected); excess chi² = '
                 "Σ (z² − z_flag²) over their flags; their sum is the score.</p>")
    else:
        L.append("<p>none: no group of flagged points large enough to count.</p>")

    # figures
    L.append('<h2 id="figures">Figures</h2>')
    sig = "; ".join(f"{os.path.basename(im['name'])}: σ = {info[m]['sigma']:.3g} DN"
                    for m, im in enumerate(v["images"]))
    L.append('<figure><img src="views.png" alt="actual, synthetic and difference images"><figcaption>'
             "One row per image: the actual image, the synthetic image of the fitted model under the description "
             "(same grey scale, DN; blue: no surface in the description, NaN), and the difference actual &minus; "
             "synthetic in DN, blue negative, red positive, clipped at ±5 σ with σ the robust spread (1.4826 MAD) "
             f"of that image's pixel differences ({e(sig)}; grey: NaN). Green rectangles: the change regions' "
             "bounding boxes of grid points, padded by half the grid spacing, numbered as in the table."
             + "".join(f" The TIFFs describe the {what} image as: \u201c{e(info[0][k].strip())}\u201d."
                       for what, k in (("actual", "act_desc"), ("synthetic", "syn_desc")) if info[0][k].strip())
             + "</figcaption></figure>")
    zf = v["z_flag"]
    L.append('<figure><img src="zmap.png" alt="z at the reference points"><figcaption>'
             f"The reference points of each image over its faint actual image (pixels, y down), coloured by "
             f"{z_sign_text(p)} clipped to ±{Z_CLIP:g}; black rings: flagged points "
             f"(|z| &gt; z_flag{' = ' + format(zf, 'g') if zf else ''} or an edge where none is predicted); "
             "small grey dots: points without z (background, near an edge, boundary, saturated); "
             "green rectangles: change regions.</figcaption></figure>")
    L.append('<figure><img src="residue.png" alt="histogram of z"><figcaption>'
             f"Histogram of z at the {nused} used reference points (log count, z in units of each point's σ: "
             "sensor noise and model tolerance); black: a standard normal scaled to the same count and bin "
             "width, what a correct description and pure noise would give"
             + (f"; red dashed: the flag threshold ±{zf:g}" if zf else "") + ".</figcaption></figure>")

    if isinstance(raw.get("options"), dict):
        L.append('<h2 id="options">Options</h2>' + dict_table(raw["options"]))
    L.append(provenance_section(prov, "verify.json"))
    L.append("</body></html>\n")
    return write_page(d, L)


def report(d):
    v = load_verify(d)
    p = load_points(d, len(v["images"]))
    info = fig_views(d, v)
    fig_zmap(d, v, p, info)
    nused = fig_residue(d, v, p)
    return write_html(d, v, p, info, nused)


def main():
    return run_report(PROG, __doc__, report)


if __name__ == "__main__":
    sys.exit(main())
