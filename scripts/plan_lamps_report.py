#!/usr/bin/python3
"""Report of `refl plan lamps` (fit/lightplan/lightplan.c computes every number; this
script only draws and lays out what refl wrote).

usage: plan_lamps_report.py DIR

DIR/plan.json: "scene", "turntable_deg", "units_and_conventions" (text),
"chosen" ({lamps, exposure_us, feasible, detectable_length_px, n_detectable,
n_segments, usable_points, glare_pix, saturated_pix, object_pix, note?}),
"configurations" (every lamp set and exposure tried: {lamps, exposure_us,
feasible, detectable_length_px, n_detectable, usable_points, glare_pix,
saturated_pix}), "faces" (the chosen configuration's grey values per face:
{face, material?, pixels_step2, P_min_dn, P_median_dn, P_max_dn, usable_frac,
glare_pix, saturated_pix}), "segments" (the chosen configuration's visible edge
segments: {edge, q0_px, q1_px, length_px, dP_dn, sobel_factor, sobel_predicted_dn,
detectable, face_side0, face_side1}), "psf" (the blur of the Sobel prediction:
{sigma_px, sigma_std_px, source, model, phase, sobel_factor: {axis_aligned,
diagonal: {best, mean, worst}}}), "options", "sensor", "provenance" and,
with --check-virtual, "virtual_rig_check" ({agreement (0..1 or null), target,
rule, truth, configurations: [{lamps, agreement, segments_judged,
segments_agreeing, segments: as above plus sobel_measured_dn and found, null
where the segment was not judged}]}, the chosen configuration first, all at
the chosen exposure unless an entry has its own exposure_us).
DIR/predicted.tiff: float32, one page, DN: the predicted image of the chosen
configuration (direct light). DIR/check_frame.tiff (with the check): float32,
DN: the virtual rig's frame of the chosen configuration. Pixels in the mrcal
convention: (0,0) the centre of the top-left pixel, x right, y down.

Writes into DIR: predicted.png (the predicted image and the segments by
predicted detectability), check.png (with the check: the virtual rig's frame
and the segments by agreement, and the predicted against the measured Sobel
response; a check.png left by an earlier run is removed when there is no
check), configs.png (detectable edge length and usable reference points
against exposure per lamp set) and index.html.

With several views (refl plan lamps --angles-deg) DIR/plan.json is their
summary instead: "scene", "views" ([{turntable_deg, dir (the view's directory
in DIR, itself a DIR as above), lamps, exposure_us, feasible, n_detectable,
n_segments, detectable_length_px, usable_points, glare_pix, saturated_pix,
check_agreement (0..1 or null)}]), "capture_plan" (its file name in DIR),
"capture_plan_binds_to_virtual_rig" (true/false, null without the check) and
"provenance"; then only DIR/index.html is written: a table of the views with
links to their reports (run the script on each view's directory for those).
DIR/capture_plan.ini, when present, is linked from the page.
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from report_common import (Bad, check_format, check_headline, dict_table, e, fmt, headline, is_num, load_json, provenance_head,  # noqa: E402
                           provenance_section, read_float_tiff, run_report, table, write_page)

PROG = "plan_lamps_report.py"
TOP_N = 15
DETECTABLE = "#1a9850"
NOT_DETECTABLE = "#d73027"
# agreement classes of a checked segment: key -> (label, colour, line style)
AGREEMENT = {
    "hit": ("predicted detectable, found", "#1a9850", "-"),
    "reject": ("predicted not detectable, not found", "#4575b4", "-"),
    "miss": ("predicted detectable, NOT found", "#e7298a", (0, (4, 2))),
    "surprise": ("predicted not detectable, found anyway", "#ff7f00", (0, (5, 2, 1, 2))),
    "unjudged": ("not judged", "#9e9e9e", (0, (1, 2))),
}
SHORT = {"hit": "agrees", "reject": "agrees", "miss": "missed", "surprise": "found anyway",
         "unjudged": "not judged"}
MARKERS = ["o", "s", "^", "D", "v", "P", "X", "<", ">", "h", "*", "p"]


# ---------------------------------------------------------------------------
# inputs

class Plan:
    """Typed reads of plan.json: a value of the wrong type is a Bad naming the key's path in the JSON."""

    def __init__(self, path):
        self.path = path

    def fail(self, where, msg):
        raise Bad(self.path, f"{where}: {msg}" if where else msg)

    def field(self, o, key, where):
        w = f"{where}.{key}" if where else key
        if not isinstance(o, dict):
            self.fail(where, "expected an object")
        if key not in o:
            self.fail(w, "missing")
        return o[key], w

    def num(self, o, key, where, null=False):
        v, w = self.field(o, key, where)
        if v is None and null:
            return math.nan
        if not is_num(v):
            self.fail(w, f"expected a number{' or null' if null else ''}, got {json.dumps(v)}")
        return float(v)

    def int(self, o, key, where):
        v, w = self.field(o, key, where)
        if not is_num(v) or not math.isfinite(v) or float(v) != int(v):
            self.fail(w, f"expected an integer, got {json.dumps(v)}")
        return int(v)

    def str(self, o, key, where):
        v, w = self.field(o, key, where)
        if not isinstance(v, str):
            self.fail(w, f"expected a string, got {json.dumps(v)}")
        return v

    def bool(self, o, key, where, null=False):
        v, w = self.field(o, key, where)
        if v is None and null:
            return None
        if not isinstance(v, bool):
            self.fail(w, f"expected true or false{' or null' if null else ''}, got {json.dumps(v)}")
        return v

    def list(self, o, key, where):
        v, w = self.field(o, key, where)
        if not isinstance(v, list):
            self.fail(w, "expected a list")
        return v

    def obj(self, o, key, where):
        v, w = self.field(o, key, where)
        if not isinstance(v, dict):
            self.fail(w, "expected an object")
        return v

    def point(self, o, key, where):
        v, w = self.field(o, key, where)
        if not (isinstance(v, list) and len(v) == 2 and all(is_num(x) and math.isfinite(x) for x in v)):
            self.fail(w, f"expected [x, y] in px (finite numbers), got {json.dumps(v)}")
        return float(v[0]), float(v[1])


def read_segment(c, o, where, checked):
    s = {"edge": c.int(o, "edge", where), "q0": c.point(o, "q0_px", where), "q1": c.point(o, "q1_px", where),
         "length_px": c.num(o, "length_px", where), "dP_dn": c.num(o, "dP_dn", where),
         "sobel_predicted_dn": c.num(o, "sobel_predicted_dn", where),
         "detectable": c.bool(o, "detectable", where),
         "side0": c.str(o, "face_side0", where), "side1": c.str(o, "face_side1", where)}
    if checked:
        s["sobel_measured_dn"] = c.num(o, "sobel_measured_dn", where, null=True)
        s["found"] = c.bool(o, "found", where, null=True)
        if (s["found"] is None) != (not math.isfinite(s["sobel_measured_dn"])):
            c.fail(where, "found and sobel_measured_dn must both be null (not judged) or both be set")
    return s


def read_config(c, o, where, chosen=False):
    k = {"lamps": c.str(o, "lamps", where), "exposure_us": c.num(o, "exposure_us", where),
         "feasible": c.bool(o, "feasible", where),
         "detectable_length_px": c.num(o, "detectable_length_px", where),
         "n_detectable": c.int(o, "n_detectable", where), "usable_points": c.num(o, "usable_points", where),
         "glare_pix": c.int(o, "glare_pix", where), "saturated_pix": c.int(o, "saturated_pix", where)}
    if not (math.isfinite(k["exposure_us"]) and k["exposure_us"] > 0):
        c.fail(where + ".exposure_us", f"expected a positive exposure in us, got {k['exposure_us']:g}")
    if chosen:
        k["n_segments"] = c.int(o, "n_segments", where)
        k["object_pix"] = c.int(o, "object_pix", where)
        note = o.get("note")
        k["note"] = note if isinstance(note, str) else ""
    return k


def load_plan(d):
    path = os.path.join(d, "plan.json")
    raw = load_json(path)
    check_format(raw, path, "refl-lightplan")
    c = Plan(path)
    p = {"raw": raw}
    p["scene"] = c.str(raw, "scene", "")
    p["turntable_deg"] = c.num(raw, "turntable_deg", "")
    units = raw.get("units_and_conventions")
    p["units"] = units if isinstance(units, str) else ""
    p["chosen"] = read_config(c, c.obj(raw, "chosen", ""), "chosen", chosen=True)
    cfgs = c.list(raw, "configurations", "")
    if not cfgs:
        c.fail("configurations", "empty list: no configuration was tried")
    p["configs"] = [read_config(c, o, f"configurations[{i}]") for i, o in enumerate(cfgs)]
    p["faces"] = []
    for i, o in enumerate(c.list(raw, "faces", "")):
        w = f"faces[{i}]"
        mat = o.get("material") if isinstance(o, dict) else None
        p["faces"].append({"face": c.str(o, "face", w), "material": mat if isinstance(mat, str) else "",
                           "pixels": c.int(o, "pixels_step2", w), "P_min": c.num(o, "P_min_dn", w),
                           "P_median": c.num(o, "P_median_dn", w), "P_max": c.num(o, "P_max_dn", w),
                           "usable_frac": c.num(o, "usable_frac", w), "glare_pix": c.int(o, "glare_pix", w),
                           "saturated_pix": c.int(o, "saturated_pix", w)})
    p["segments"] = [read_segment(c, o, f"segments[{i}]", False)
                     for i, o in enumerate(c.list(raw, "segments", ""))]
    p["options"] = c.obj(raw, "options", "")
    p["sensor"] = c.obj(raw, "sensor", "")
    thr = c.num(p["options"], "sobel_threshold_dn", "options")
    p["threshold"] = thr if math.isfinite(thr) and thr >= 0 else math.nan
    p["saturation_dn"] = c.num(p["sensor"], "saturation_dn", "sensor")
    p["check"] = None
    if "virtual_rig_check" in raw:
        o = c.obj(raw, "virtual_rig_check", "")
        w = "virtual_rig_check"
        chk = {"agreement": c.num(o, "agreement", w, null=True), "target": c.num(o, "target", w),
               "rule": o.get("rule") if isinstance(o.get("rule"), str) else "",
               "truth": o.get("truth") if isinstance(o.get("truth"), str) else "", "configs": []}
        lst = c.list(o, "configurations", w)
        if not lst:
            c.fail(w + ".configurations", "empty list: the chosen configuration's check should come first")
        for i, q in enumerate(lst):
            wq = f"{w}.configurations[{i}]"
            exp = q.get("exposure_us") if isinstance(q, dict) else None
            chk["configs"].append({
                "lamps": c.str(q, "lamps", wq),
                "exposure_us": float(exp) if is_num(exp) else p["chosen"]["exposure_us"],
                "agreement": c.num(q, "agreement", wq, null=True),
                "judged": c.int(q, "segments_judged", wq), "agreeing": c.int(q, "segments_agreeing", wq),
                "segments": [read_segment(c, s, f"{wq}.segments[{k}]", True)
                             for k, s in enumerate(c.list(q, "segments", wq))]})
        p["check"] = chk
    return p


# ---------------------------------------------------------------------------
# derived figures

def same_config(a, b):
    return a["lamps"] == b["lamps"] and abs(a["exposure_us"] - b["exposure_us"]) <= 1e-9 * b["exposure_us"]


def ranked(configs):
    """Indices of configs: feasible first, then the longest detectable edge length, then the most usable points
    (ties keep plan.json's order)."""
    def key(i):
        k = configs[i]
        return (not k["feasible"], -k["detectable_length_px"], -k["usable_points"])
    return sorted(range(len(configs)), key=key)


def agreement_class(s):
    if s["found"] is None:
        return "unjudged"
    if s["detectable"]:
        return "hit" if s["found"] else "miss"
    return "surprise" if s["found"] else "reject"


def grey_limits(a):
    fin = a[np.isfinite(a)]
    if not fin.size:
        return 0.0, 1.0
    lo, hi = (float(x) for x in np.percentile(fin, [0.1, 99.9]))
    return lo, hi if hi > lo else lo + 1.0


# ---------------------------------------------------------------------------
# formatting

def us(x):
    return f"{x:g} µs"


def pct(x, spec=".1f"):
    return "n/a" if x is None or not math.isfinite(x) else f"{100 * x:{spec}} %"


def seg_label(i):
    return f"#{i + 1}"


# ---------------------------------------------------------------------------
# figures

def image_axes(ax, a, title):
    H, W = a.shape
    lo, hi = grey_limits(a)
    h = ax.imshow(a, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
    ax.set_xlim(-0.5, W - 0.5)
    ax.set_ylim(H - 0.5, -0.5)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    return h


def ring(ax, s, col):
    """A hollow circle round the segment's middle: short segments show at the page's scale."""
    ax.plot([0.5 * (s["q0"][0] + s["q1"][0])], [0.5 * (s["q0"][1] + s["q1"][1])], "o", ms=16, mfc="none", mec=col,
            mew=1.8)


def fig_predicted(d, p, img):
    H, W = img.shape
    fig, ax = plt.subplots(figsize=(11.0, 11.0 * H / W * 0.88 + 0.9), layout="constrained")
    ch = p["chosen"]
    nd = sum(1 for s in p["segments"] if s["detectable"])
    h = image_axes(ax, img, f"predicted image (direct light): lamps {ch['lamps']}, {us(ch['exposure_us'])}"
                   f"{'' if ch['feasible'] else ' (not feasible)'}\n{nd} of "
                   f"{len(p['segments'])} edge segments predicted detectable")
    fig.colorbar(h, ax=ax, fraction=0.046, pad=0.02, label="predicted grey value (DN)")
    for i, s in enumerate(p["segments"]):
        col = DETECTABLE if s["detectable"] else NOT_DETECTABLE
        ax.plot([s["q0"][0], s["q1"][0]], [s["q0"][1], s["q1"][1]], color=col, lw=2.2,
                ls="-" if s["detectable"] else (0, (3, 1.5)), solid_capstyle="butt")
        if not s["detectable"]:
            ring(ax, s, col)
        mx, my = 0.5 * (s["q0"][0] + s["q1"][0]), 0.5 * (s["q0"][1] + s["q1"][1])
        ax.text(mx, my, seg_label(i), color="k", fontsize=7, ha="left", va="bottom",
                zorder=5 if col == NOT_DETECTABLE else 4,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": col, "lw": 0.8, "alpha": 0.75})
    ax.legend(handles=[Line2D([], [], color=DETECTABLE, lw=2.2, label=f"predicted detectable ({nd})"),
                       Line2D([], [], color=NOT_DETECTABLE, lw=2.2, ls=(0, (3, 1.5)),
                              label=f"predicted not detectable ({len(p['segments']) - nd})")],
              loc="upper right", fontsize=8, framealpha=0.85)
    fig.savefig(os.path.join(d, "predicted.png"), dpi=100)
    plt.close(fig)


def scatter_floor(thr, vals):
    """The smallest value the log-log scatter shows; smaller ones (0 included) are drawn at it."""
    pos = [v for v in vals if math.isfinite(v) and v > 0]
    if math.isfinite(thr) and thr > 0:
        f = thr / 100.0
    else:
        f = min(pos) if pos else 1.0
    return 10.0 ** math.floor(math.log10(f))


def fig_check(d, p, frame):
    chk = p["check"]
    thr = p["threshold"]
    H, W = frame.shape
    fig = plt.figure(figsize=(19.0, 9.0))
    gs = fig.add_gridspec(1, 2, width_ratios=[1.45, 1.0], left=0.045, right=0.985, bottom=0.08, top=0.9,
                          wspace=0.2)
    ax = fig.add_subplot(gs[0])
    c0 = chk["configs"][0]
    h = image_axes(ax, frame, f"virtual rig's frame: lamps {c0['lamps']}, {us(c0['exposure_us'])}\n"
                   f"{c0['agreeing']} of {c0['judged']} judged segments agree with the prediction")
    fig.colorbar(h, ax=ax, fraction=0.046, pad=0.02, label="grey value (DN)")
    counts = {k: 0 for k in AGREEMENT}
    for s in c0["segments"]:
        k = agreement_class(s)
        counts[k] += 1
        _, col, ls = AGREEMENT[k]
        ax.plot([s["q0"][0], s["q1"][0]], [s["q0"][1], s["q1"][1]], color=col, ls=ls,
                lw=3.0 if k in ("miss", "surprise") else 2.2, solid_capstyle="butt")
        if k in ("miss", "surprise"):
            ring(ax, s, col)
    ax.legend(handles=[Line2D([], [], color=AGREEMENT[k][1], ls=AGREEMENT[k][2], lw=2.4,
                              label=f"{AGREEMENT[k][0]} ({counts[k]})") for k in AGREEMENT if counts[k]],
              loc="upper right", fontsize=8, framealpha=0.85)

    bx = fig.add_subplot(gs[1])
    pts = [(ci, s) for ci, q in enumerate(chk["configs"]) for s in q["segments"] if s["found"] is not None]
    floor = scatter_floor(thr, [s["sobel_predicted_dn"] for _, s in pts] + [s["sobel_measured_dn"] for _, s in pts])
    top = max([thr * 2 if math.isfinite(thr) else 0.0]
              + [max(s["sobel_predicted_dn"], s["sobel_measured_dn"]) for _, s in pts] + [floor * 10])
    lim = (floor / 1.5, 10.0 ** (math.log10(top) + 0.15))
    bx.plot(lim, lim, ":", color="0.5", lw=1)
    if math.isfinite(thr) and thr > 0:
        bx.axvline(thr, color="0.25", ls="--", lw=1)
        bx.axhline(thr, color="0.25", ls="--", lw=1)
    nclip = 0
    for ci, q in enumerate(chk["configs"]):
        for k in AGREEMENT:
            sel = [s for s in q["segments"] if s["found"] is not None and agreement_class(s) == k]
            if not sel:
                continue
            x = np.array([s["sobel_predicted_dn"] for s in sel])
            y = np.array([s["sobel_measured_dn"] for s in sel])
            nclip += int(np.sum((x < floor) | (y < floor)))
            bx.scatter(np.maximum(x, floor), np.maximum(y, floor), s=34, marker=MARKERS[ci % len(MARKERS)],
                       c=AGREEMENT[k][1], edgecolors="k" if ci == 0 else "none", linewidths=0.6,
                       alpha=0.9, zorder=3 if k in ("miss", "surprise") else 2)
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlim(*lim)
    bx.set_ylim(*lim)
    bx.set_aspect("equal")
    bx.set_xlabel("predicted Sobel response (DN, log)")
    bx.set_ylabel("measured Sobel response on the virtual rig (DN, log)")
    bx.grid(alpha=0.3, which="both")
    bx.set_title(f"{len(pts)} judged segments of {len(chk['configs'])} lamp sets"
                 + (f"; {nclip} at or below {floor:g} DN drawn at {floor:g}" if nclip else ""), fontsize=10)
    handles = [Line2D([], [], ls="", marker="o", color=AGREEMENT[k][1], label=AGREEMENT[k][0])
               for k in ("hit", "reject", "miss", "surprise")]
    handles += [Line2D([], [], ls="", marker=MARKERS[ci % len(MARKERS)], color="0.55",
                       mec="k" if ci == 0 else "0.55", label=q["lamps"] + (" (chosen)" if ci == 0 else ""))
                for ci, q in enumerate(chk["configs"])]
    if math.isfinite(thr) and thr > 0:
        handles.append(Line2D([], [], ls="--", color="0.25", label=f"threshold {thr:g} DN"))
    handles.append(Line2D([], [], ls=":", color="0.5", label="measured = predicted"))
    bx.legend(handles=handles, fontsize=7.5, loc="upper left", framealpha=0.85)
    fig.savefig(os.path.join(d, "check.png"), dpi=72)
    plt.close(fig)
    return floor, nclip


def fig_configs(d, p):
    configs, ch = p["configs"], p["chosen"]
    sets = []
    for k in configs:
        if k["lamps"] not in sets:
            sets.append(k["lamps"])
    best = {s: max(k["detectable_length_px"] for k in configs if k["lamps"] == s) for s in sets}
    shown = sets if len(sets) <= 40 else [ch["lamps"]] + [s for s in sorted(sets, key=lambda s: -best[s])
                                                           if s != ch["lamps"]][:9]
    cmap = plt.get_cmap("tab10" if len(sets) <= 10 else "tab20")
    styles = ["-", "--", "-.", ":"]
    total = sum(s["length_px"] for s in p["segments"] if math.isfinite(s["length_px"]))
    fig, axs = plt.subplots(1, 2, figsize=(16.5, 6.4), layout="constrained")
    for j, (ax, key, ylab) in enumerate(((axs[0], "detectable_length_px", "detectable edge length (px)"),
                                         (axs[1], "usable_points", "usable reference points (grid cells)"))):
        for i, s in enumerate(sets):
            ks = sorted((k for k in configs if k["lamps"] == s), key=lambda k: k["exposure_us"])
            x = np.array([k["exposure_us"] for k in ks])
            y = np.array([k[key] for k in ks])
            feas = np.array([k["feasible"] for k in ks], dtype=bool)
            col = cmap(i % cmap.N)
            ls = styles[(i // cmap.N) % len(styles)]
            is_ch = s == ch["lamps"]
            lab = (s + (" (chosen)" if is_ch else "")) if (j == 0 and s in shown) else None
            ax.plot(x, y, ls=ls, color=col, lw=3.0 if is_ch else 1.3, alpha=1.0 if is_ch else 0.85, label=lab,
                    zorder=4 if is_ch else 2)
            ax.scatter(x[feas], y[feas], s=60 if is_ch else 30, color=col, edgecolors=col, zorder=5)
            ax.scatter(x[~feas], y[~feas], s=60 if is_ch else 30, facecolors="white", edgecolors=col,
                       linewidths=1.4, zorder=5)
        ax.scatter([ch["exposure_us"]], [ch[key]], s=380, marker="o", facecolors="none", edgecolors="k",
                   linewidths=2.0, zorder=6)
        ax.annotate("chosen", (ch["exposure_us"], ch[key]), xytext=(12, -16), textcoords="offset points",
                    fontsize=9, fontweight="bold")
        if key == "detectable_length_px" and total > 0:
            ax.axhline(total, color="0.4", ls=":", lw=1)
            ax.text(0.01, total, f" all visible edge segments: {total:.0f} px", color="0.3",
                    fontsize=8, va="bottom", transform=ax.get_yaxis_transform())
        ax.set_xscale("log")
        xs = sorted({k["exposure_us"] for k in configs})
        ax.set_xticks(xs)
        ax.set_xticklabels([f"{x:g}" for x in xs], rotation=45 if len(xs) > 8 else 0)
        ax.minorticks_off()
        ax.set_xlabel("exposure (µs, log)")
        ax.set_ylabel(ylab)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axs[0].set_title("detectable edge length per lamp set (filled: feasible, hollow: glare or saturation)",
                     fontsize=10)
    axs[1].set_title("usable reference points per lamp set (the tie-break)", fontsize=10)
    hs, ls_ = axs[0].get_legend_handles_labels()
    hs += [Line2D([], [], ls="", marker="o", color="0.4", label="feasible"),
           Line2D([], [], ls="", marker="o", mfc="white", mec="0.4", label="not feasible")]
    title = None if shown is sets else f"chosen and 9 best of {len(sets)} sets"
    axs[1].legend(handles=hs, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, title=title,
                  title_fontsize=8, ncol=1 if len(hs) <= 24 else 2)
    fig.savefig(os.path.join(d, "configs.png"), dpi=72)
    plt.close(fig)
    return total


# ---------------------------------------------------------------------------
# page

CSS = ("body{font-family:sans-serif;max-width:1250px;margin:1em auto;padding:0 1em;color:#222}"
       "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
       "text-align:left;font-size:90%}th{background:#eee}td.n{text-align:right;font-variant-numeric:tabular-nums;"
       "white-space:nowrap}td.l{white-space:nowrap}tr.chosen td{background:#fff3b0;font-weight:bold}"
       "tr.sep td{border-top:3px double #888}"
       "tr.miss td{background:#fde0ef}tr.surprise td{background:#ffe8cc}tr.unjudged td{color:#888}"
       "tr.all td{font-weight:bold}figure{margin:1em 0}img{max-width:100%;border:1px solid #ddd}"
       "figcaption{font-size:90%;color:#555}code{font-size:90%}pre{background:#f6f6f6;border:1px solid #ddd;"
       "padding:0.6em;overflow-x:auto;font-size:85%;white-space:pre-wrap}"
       ".banner{font-size:150%;font-weight:bold;color:#fff;padding:0.7em 1em;margin:0.8em 0;border-radius:6px}"
       ".banner small{display:block;font-size:60%;font-weight:normal;margin-top:0.3em}"
       ".good{background:#1e8e3e}.bad{background:#c5221f}.warn{background:#b06000}.none{background:#777}"
       ".note{color:#555}.sw{display:inline-block;width:2.2em;height:0.35em;vertical-align:middle;"
       "margin-right:0.3em}.bar{position:relative;width:220px;height:12px;background:#eee;border:1px solid #ccc}"
       ".bar span{position:absolute;top:0;height:100%;background:#7a9cc6}.bar i{position:absolute;top:-2px;"
       "width:2px;height:16px;background:#222}")


def swatch(colour, dashed=False):
    style = (f"background:repeating-linear-gradient(90deg,{colour} 0 6px,transparent 6px 9px)" if dashed
             else f"background:{colour}")
    return f'<span class="sw" style="{style}"></span>'


def range_bar(f, sat):
    """The face's min..max as a bar on 0..saturation, the median as a tick."""
    if not (math.isfinite(sat) and sat > 0) or not all(math.isfinite(f[k]) for k in ("P_min", "P_median", "P_max")):
        return ""

    def x(v):
        return min(max(v / sat, 0.0), 1.0) * 100

    a, b = x(f["P_min"]), x(f["P_max"])
    return (f'<div class="bar" title="0 .. saturation {sat:.0f} DN"><span style="left:{a:.1f}%;'
            f'width:{max(b - a, 0.4):.1f}%"></span><i style="left:{x(f["P_median"]):.1f}%"></i></div>')


def seg_cells(i, s):
    return [seg_label(i), str(s["edge"]), f"{s['q0'][0]:.1f}, {s['q0'][1]:.1f}",
            f"{s['q1'][0]:.1f}, {s['q1'][1]:.1f}", fmt(s["length_px"], ".1f"), fmt(s["dP_dn"], ".1f"),
            fmt(s["sobel_predicted_dn"], ".1f"), "yes" if s["detectable"] else "no",
            f"{e(s['side0'])} | {e(s['side1'])}"]


def page_head(title, prov):
    """The page's opening lines: title, then the provenance's head."""
    L = [f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{e(title)}</title>\n'
         f"<style>{CSS}</style>\n</head><body>\n<h1>{e(title)}</h1>"]
    head = provenance_head(prov)
    if head:
        L.append(head)
    return L


def fig_views(d, views):
    """views.png: per view (turntable angle) the detectable edge length and the check's agreement."""
    ang = [v[0] for v in views]
    x = np.arange(len(views))
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.6), constrained_layout=True)
    a1.bar(x, [v[1] for v in views], color="#4477aa")
    a1.set_xticks(x, [f"{a:g}°\n{v[3]}" for a, v in zip(ang, views)])
    a1.set_ylabel("detectable edge length (px)")
    a1.set_title("predicted detectable edges per view")
    agr = [100 * v[2] if v[2] is not None else np.nan for v in views]
    a2.bar(x, agr, color=["#228833" if (a == a and a >= 100 * v[4]) else "#cc6677" for a, v in zip(agr, views)])
    if views and views[0][4] is not None:
        a2.axhline(100 * views[0][4], color="k", ls="--", lw=1, label=f"target {100 * views[0][4]:.0f} %")
        a2.legend(loc="lower right")
    a2.set_xticks(x, [f"{a:g}°" for a in ang])
    a2.set_ylim(min([80] + [a for a in agr if a == a]) - 2, 100.5)
    a2.set_ylabel("check agreement (%)")
    a2.set_title("virtual-rig check: measured vs predicted edges")
    fig.savefig(os.path.join(d, "views.png"), dpi=80)
    plt.close(fig)


def edge_warnings(raw, configs, chosen_us):
    """plan.json's "warnings" (sentences), or, in a file without them, the one this script can see itself: the
    chosen exposure at the edge of the searched ones (the best may lie beyond them)."""
    w = raw.get("warnings")
    if isinstance(w, list):
        return [str(x) for x in w]
    ex = sorted({k["exposure_us"] for k in configs})
    if len(ex) > 1 and chosen_us in (ex[0], ex[-1]):
        side = "longest" if chosen_us == ex[-1] else "shortest"
        return [f"the chosen exposure {chosen_us:g} us is the {side} of those searched ({ex[0]:g}..{ex[-1]:g} us): "
                f"a {'longer' if side == 'longest' else 'shorter'} one may be better; search beyond it"]
    return []


def psf_note(raw):
    """The blur the edges' Sobel response was predicted with (plan.json's psf), one paragraph."""
    psf = raw.get("psf")
    if not isinstance(psf, dict) or not is_num(psf.get("sigma_px")):
        return '<p class="note"><b>Edges:</b> plan.json names no PSF (a sharp step: f = 4.0 axis-aligned, 4.24 ' \
               'diagonal).</p>'
    f = psf.get("sobel_factor") if isinstance(psf.get("sobel_factor"), dict) else {}
    ax = f.get("axis_aligned") if isinstance(f.get("axis_aligned"), dict) else {}
    dg = f.get("diagonal") if isinstance(f.get("diagonal"), dict) else {}
    sd = psf.get("sigma_std_px")

    def num(o, k):
        return o.get(k) if is_num(o.get(k)) else None
    return (f'<p class="note"><b>Edges:</b> the predicted Sobel response of a segment is f &times; |dP|, f the '
            f"response per unit contrast of a step blurred by a Gaussian PSF of sigma {fmt(psf['sigma_px'], '.3f')} px"
            + (f" &plusmn; {fmt(sd, '.3f')}" if is_num(sd) else "")
            + f" (from {e(str(psf.get('source', 'an unnamed source')))}) and integrated over the pixel's 1 px "
            f"footprint, at the segment's direction and the best sub-pixel phase: f = {fmt(num(ax, 'best'), '.3f')} "
            f"axis-aligned, {fmt(num(dg, 'best'), '.3f')} diagonal (mean phase {fmt(num(ax, 'mean'), '.3f')} and "
            f"{fmt(num(dg, 'mean'), '.3f')}, worst {fmt(num(ax, 'worst'), '.3f')} and {fmt(num(dg, 'worst'), '.3f')}; "
            "a sharp step: 4.0 and 4.24).</p>")


def write_html(d, p, have):
    raw, ch, chk = p["raw"], p["chosen"], p["check"]
    prov = raw.get("provenance")
    L = page_head(f"refl plan lamps: {p['scene']}", prov)
    L.append(f"<p>Turntable at {fmt(p['turntable_deg'], 'g')} deg; {len(p['configs'])} configurations tried "
             f'(lamp sets &times; exposures). Data: <a href="plan.json">plan.json</a>, '
             f'<a href="predicted.tiff">predicted.tiff</a>'
             + (', <a href="check_frame.tiff">check_frame.tiff</a>' if chk else "")
             + (', the capture plan <a href="capture_plan.ini">capture_plan.ini</a>'
                if os.path.exists(os.path.join(d, "capture_plan.ini")) else "") + ".</p>")

    # the choice
    nseg = ch["n_segments"]
    L.append(f'<div class="banner {"good" if ch["feasible"] else "warn"}">Chosen: lamps {e(ch["lamps"])} at '
             f'{e(us(ch["exposure_us"]))} &mdash; {"feasible" if ch["feasible"] else "NOT feasible"}'
             f"<small>{ch['n_detectable']} of {nseg} edge segments detectable "
             f"({fmt(ch['detectable_length_px'], '.0f')} px of edge); {fmt(ch['usable_points'], '.0f')} usable "
             f"reference points; {ch['glare_pix']} glare and {ch['saturated_pix']} saturated of "
             f"{ch['object_pix']} object pixels (step-2 grid)"
             + (f"<br>{e(ch['note'])}" if ch["note"] else "") + "</small></div>")
    for w in edge_warnings(raw, p["configs"], ch["exposure_us"]):
        L.append(f'<div class="banner warn">Warning<small>{e(w)}.</small></div>')
    notes = []
    ci = [i for i, k in enumerate(p["configs"]) if same_config(k, ch)]
    if not ci:
        notes.append("the chosen configuration is not among plan.json's configurations")
    if nseg != len(p["segments"]):
        notes.append(f"chosen.n_segments is {nseg}, the segments list has {len(p['segments'])}")
    for n in notes:
        L.append(f'<p class="note"><b>Note:</b> {e(n)}.</p>')
    L.append(psf_note(raw))

    # the check
    if chk:
        ag, tg = chk["agreement"], chk["target"]
        if not math.isfinite(ag):
            cls, word = "none", "no segment judged"
        elif ag >= tg:
            cls, word = "good", "PASS"
        else:
            cls, word = "bad", "FAIL"
        cmp = "&ge;" if math.isfinite(ag) and ag >= tg else "&lt;"
        nj = sum(q["judged"] for q in chk["configs"])
        na = sum(q["agreeing"] for q in chk["configs"])
        what = (f"agreement {pct(ag)} {cmp} target {pct(tg, '.0f')}" if math.isfinite(ag) else
                f"target {pct(tg, '.0f')}")
        L.append(f'<div class="banner {cls}">Virtual-rig check: {word} &mdash; {what}'
                 f"<small>{na} of {nj} judged segments over {len(chk['configs'])} lamp sets "
                 f"found as predicted; truth {e(chk['truth'] or 'not named')}</small></div>")
        if chk["rule"]:
            L.append(f'<p class="note">Rule: {e(chk["rule"])}.</p>')
        cnotes = []
        if chk["configs"][0]["lamps"] != ch["lamps"]:
            cnotes.append(f"the check's first configuration is lamps {chk['configs'][0]['lamps']}, not the chosen "
                          f"{ch['lamps']}: the frame and its segments below are that set's")
        if nj and math.isfinite(ag) and abs(na / nj - ag) > 1e-6:
            cnotes.append(f"the overall agreement {ag:.4g} is not the sum of the agreeing over the judged segments "
                          f"({na}/{nj} = {na / nj:.4g})")
        for q in chk["configs"]:
            j = sum(1 for s in q["segments"] if s["found"] is not None)
            a = sum(1 for s in q["segments"] if s["found"] is not None and s["found"] == s["detectable"])
            if (j, a) != (q["judged"], q["agreeing"]):
                cnotes.append(f"lamps {q['lamps']}: the counts say {q['agreeing']} of {q['judged']} agree, "
                              f"the segments {a} of {j}")
        for n in cnotes:
            L.append(f'<p class="note"><b>Note:</b> {e(n)}.</p>')

    # figures
    L.append('<h2 id="figures">Figures</h2>')
    thr = p["threshold"]
    L.append('<figure><img src="predicted.png" alt="predicted image with the edge segments"><figcaption>'
             f"The predicted image of the chosen configuration (lamps {e(ch['lamps'])}, {e(us(ch['exposure_us']))}): "
             "grey values in DN (direct light only, no interreflection; colour bar), pixels in the mrcal convention "
             "(x right, y down). Lines: the visible edge segments, "
             f"{swatch(DETECTABLE)}green solid where the predicted Sobel response (the median along the segment) "
             f"reaches the threshold of {fmt(thr, 'g')} DN, {swatch(NOT_DETECTABLE, True)}red dashed where it does "
             "not; the not detectable ones are also ringed; labels #k are the rows of the segments table."
             "</figcaption></figure>")
    if chk:
        floor, nclip = have["check"]
        L.append('<figure><img src="check.png" alt="virtual rig frame and Sobel responses"><figcaption>'
                 "Left: the virtual rig's frame of the chosen configuration (DN, colour bar) with its segments "
                 f"coloured by agreement: {swatch(AGREEMENT['hit'][1])}green: predicted detectable and found; "
                 f"{swatch(AGREEMENT['reject'][1])}blue: predicted not detectable and not found; "
                 f"{swatch(AGREEMENT['miss'][1], True)}magenta dashed (thicker): predicted detectable but not found; "
                 f"{swatch(AGREEMENT['surprise'][1], True)}orange dash-dot (thicker): predicted not detectable but "
                 f"found; {swatch(AGREEMENT['unjudged'][1], True)}grey dotted: not judged; the disagreements are also "
                 "ringed. Right: the measured "
                 "Sobel response on the virtual rig against the predicted one (both DN, log-log) for every judged "
                 "segment of every checked lamp set (marker shape: the set, black-edged: the chosen one; colour: "
                 "agreement as on the left); dashed: the threshold "
                 f"{fmt(thr, 'g')} DN on both axes, so points in the lower-right and upper-left quadrants disagree; "
                 "dotted: measured = predicted"
                 + (f"; {nclip} values at or below {floor:g} DN (a predicted 0 among them) are drawn at {floor:g} DN"
                    if nclip else "") + ".</figcaption></figure>")
    mbf = p["options"].get("max_bad_frac")
    mbf = float(mbf) if is_num(mbf) else None
    L.append('<figure><img src="configs.png" alt="detectable edge length against exposure"><figcaption>'
             "Left: the detectable edge length (px, summed over the segments predicted detectable) against the "
             "exposure (µs, log axis), one line per lamp set; filled markers: feasible (glare and saturated pixels "
             f"at most max_bad_frac = {e(fmt(mbf, 'g'))} of the object's pixels), hollow: not feasible; "
             "thick line and black ring: the chosen set and "
             "exposure; dotted: the total length of the visible segments. Right: the usable reference points "
             "(grid cells of spacing_px² whose pixels lie in the usable range and off glare), which break ties "
             "between equal lengths.</figcaption></figure>")

    # faces
    L.append('<h2 id="faces">Faces: dynamic range of the chosen configuration</h2>')
    sat = p["saturation_dn"]
    if p["faces"]:
        rows, cls = [], []
        for f in p["faces"]:
            rows.append([e(f["face"]), e(f["material"]), str(f["pixels"]), fmt(f["P_min"], ".1f"),
                         fmt(f["P_median"], ".1f"), fmt(f["P_max"], ".1f"),
                         fmt(f["P_max"] / f["P_min"] if f["P_min"] > 0 else math.nan, ".2f"),
                         pct(f["P_max"] / sat if sat > 0 else math.nan), range_bar(f, sat), pct(f["usable_frac"]),
                         str(f["glare_pix"]), str(f["saturated_pix"])])
            cls.append("miss" if f["glare_pix"] or f["saturated_pix"] else "")
        L.append(table(["face", "material", "pixels (step-2 grid)", "P min (DN)", "P median (DN)", "P max (DN)",
                        "max / min", "P max / saturation", "range on 0 .. saturation", "usable", "glare px",
                        "saturated px"], rows, cls,
                       [False, False, True, True, True, True, True, True, False, True, True, True]))
        L.append(f'<p class="note">Predicted grey values (DN, direct light) over each face\'s pixels on the step-2 '
                 f"grid; the bar spans min .. max on 0 .. the saturation level {fmt(sat, '.0f')} DN, the tick is the "
                 "median; usable: the share of the face's pixels above the noise floor and below saturation_frac "
                 "&times; saturation; rows with glare or saturated pixels are tinted.</p>")
    else:
        L.append("<p>No face is in view.</p>")

    # configurations
    L.append(f'<h2 id="configurations">Configurations: the best {min(TOP_N, len(p["configs"]))} of '
             f'{len(p["configs"])}</h2>')
    order = ranked(p["configs"])
    pick = order[:TOP_N]
    extra = [i for i in ci if i not in pick][:1]
    rows, cls = [], []
    for r, i in enumerate(pick + extra):
        k = p["configs"][i]
        rows.append([str(order.index(i) + 1), e(k["lamps"]), fmt(k["exposure_us"], "g"),
                     "yes" if k["feasible"] else "no", fmt(k["detectable_length_px"], ".1f"), str(k["n_detectable"]),
                     fmt(k["usable_points"], ".1f"), str(k["glare_pix"]), str(k["saturated_pix"])])
        c = "chosen" if i in ci else ""
        if r == len(pick) and extra:
            c = (c + " sep").strip()
        cls.append(c)
    L.append(table(["rank", "lamps", "exposure (µs)", "feasible", "detectable length (px)", "detectable segments",
                    "usable points", "glare px", "saturated px"], rows, cls,
                   [True, False, True, False, True, True, True, True, True]))
    L.append('<p class="note">Ranked feasible first, then by detectable edge length, then by usable reference '
             "points (ties in plan.json's order); the chosen configuration is highlighted"
             + (", shown below the double line as it is not among the best" if extra else "") + ".</p>")
    if ci and order[0] not in ci and ch["feasible"]:
        L.append('<p class="note"><b>Note:</b> the chosen configuration is not the first in this ranking.</p>')
    elif ci and not ch["feasible"]:
        L.append('<p class="note">No configuration is feasible: refl chose the one with the fewest glare and '
                 "saturated pixels, which this ranking (by detectable length) need not put first.</p>")

    # segments
    L.append('<h2 id="segments">Edge segments of the chosen configuration</h2>')
    hdr = ["#", "edge", "from x, y (px)", "to x, y (px)", "length (px)", "dP (DN)", "Sobel predicted (DN)",
           "detectable"]
    num = [False, True, "l", "l", True, True, True, False]
    segs = p["segments"]
    csegs = None
    if chk and len(chk["configs"][0]["segments"]) == len(segs) and chk["configs"][0]["lamps"] == ch["lamps"]:
        csegs = chk["configs"][0]["segments"]
    if csegs:
        hdr += ["Sobel measured (DN)", "found", "agreement"]
        num += [True, False, "l"]
    hdr.append("faces side 0 | side 1")
    num.append(False)
    rows, cls = [], []
    for i, s in enumerate(segs):
        cells = seg_cells(i, s)
        side = cells.pop()
        c = ""
        if csegs:
            t = csegs[i]
            k = agreement_class(t)
            cells += [fmt(t["sobel_measured_dn"], ".1f"), "n/a" if t["found"] is None else
                      ("yes" if t["found"] else "no"), swatch(AGREEMENT[k][1], k in ("miss", "surprise", "unjudged"))
                      + SHORT[k]]
            c = k if k in ("miss", "surprise", "unjudged") else ""
        rows.append(cells + [side])
        cls.append(c)
    if rows:
        L.append(table(hdr, rows, cls, num))
    else:
        L.append("<p>No edge segment is visible.</p>")
    L.append('<p class="note">Segments of the scene\'s edges as seen from the camera (endpoints in px, mrcal '
             "convention); dP: the predicted contrast across the segment (DN, the mean along it of side 0 "
             "&minus; side 1, "
             "2 px to either side, the dark offset excluded); "
             "Sobel predicted: the median along the segment of f |dP| (f = 4 .. 4.24 with the direction); "
             f"detectable when it reaches {fmt(thr, 'g')} DN"
             + ("; Sobel measured: the same median on the virtual rig's frame; rows where the check disagrees are "
                "tinted" if csegs else "") + ".</p>")
    if chk and not csegs:
        L.append('<p class="note">The check\'s first configuration does not match the chosen one segment for '
                 "segment: its results are in the per-configuration table only.</p>")

    # check per configuration
    if chk:
        L.append('<h2 id="check">Virtual-rig check per lamp set</h2>')
        rows, cls = [], []
        for j, q in enumerate(chk["configs"]):
            n = {k: sum(1 for s in q["segments"] if agreement_class(s) == k) for k in AGREEMENT}
            rows.append([e(q["lamps"]) + (" (chosen)" if j == 0 else ""), fmt(q["exposure_us"], "g"), str(q["judged"]),
                         str(q["agreeing"]), pct(q["agreement"] if q["judged"] else math.nan), str(n["hit"]),
                         str(n["reject"]), str(n["miss"]), str(n["surprise"]), str(n["unjudged"])])
            cls.append("chosen" if j == 0 else "")
        tot = {k: sum(1 for q in chk["configs"] for s in q["segments"] if agreement_class(s) == k) for k in AGREEMENT}
        rows.append(["all", "", str(sum(q["judged"] for q in chk["configs"])),
                     str(sum(q["agreeing"] for q in chk["configs"])), pct(chk["agreement"]), str(tot["hit"]),
                     str(tot["reject"]), str(tot["miss"]), str(tot["surprise"]), str(tot["unjudged"])])
        cls.append("all")
        L.append(table(["lamps", "exposure (µs)", "judged", "agreeing", "agreement", "detectable, found",
                        "not detectable, not found", "detectable, not found", "not detectable, found", "not judged"],
                       rows, cls, [False, True, True, True, True, True, True, True, True, True]))
        L.append(f'<p class="note">Each set rendered on the virtual rig at the chosen exposure and compared, segment '
                 f"by segment, with its own prediction; the overall agreement is measured against the target "
                 f"{pct(chk['target'], '.0f')}.</p>")

    # settings
    L.append('<h2 id="options">Options</h2>' + dict_table(p["options"]))
    L.append('<h2 id="sensor">Sensor</h2>' + dict_table(p["sensor"]))
    L.append('<h2 id="units">Units and conventions</h2>')
    L.append(f"<p>{e(p['units'])}</p>" if p["units"] else "<p>plan.json states none.</p>")
    L.append(provenance_section(prov, "plan.json"))
    L.append("</body></html>\n")
    return write_page(d, L)


def views_headline(figv, rows, cls, raw, c):
    """The summary page's headline items: the views' lamps and feasibility, the virtual-rig check against its
    target in words (each view that misses it, by how many points), each distinct warning once with the views
    it concerns."""
    out = []
    infeasible = [fmt(a, "g") + "°" for (a, *_), k in zip(figv, cls) if k == "miss"]
    out.append(f"{len(figv)} views planned: " + "; ".join(f"{fmt(a, 'g')}°: {e(lamps)}" for a, _, _, lamps, _ in figv)
               + (f"; infeasible: {', '.join(infeasible)}" if infeasible else "; every view feasible"))
    checked = [(a, ag, tg) for a, _, ag, _, tg in figv if ag is not None and math.isfinite(ag) and tg is not None]
    out.append(check_headline(checked, "virtual-rig check") or "virtual-rig check: not run (no --check-virtual)")
    seen = {}
    for i, v in enumerate(raw.get("views") or []):
        for w in (v.get("warnings") if isinstance(v, dict) and isinstance(v.get("warnings"), list) else []):
            seen.setdefault(str(w), []).append(fmt(figv[i][0], "g") + "°" if i < len(figv) else "?")
    for w, where in seen.items():
        out.append("!warning (" + ("every view" if len(where) == len(figv) else ", ".join(where)) + f"): {e(w)}")
    return out


def report_views(d, raw):
    """The summary page of several views (plan.json with "views")."""
    path = os.path.join(d, "plan.json")
    c = Plan(path)
    scene = c.str(raw, "scene", "")
    plan = c.str(raw, "capture_plan", "")
    bound = raw.get("capture_plan_binds_to_virtual_rig")
    if bound is not None and not isinstance(bound, bool):
        c.fail("capture_plan_binds_to_virtual_rig", f"expected true, false or null, got {json.dumps(bound)}")
    rows, cls, figv = [], [], []
    for i, v in enumerate(c.list(raw, "views", "")):
        w = f"views[{i}]"
        vd = c.str(v, "dir", w)
        if os.sep in vd or vd in ("", ".", ".."):
            c.fail(f"{w}.dir", f"expected a directory name inside {d}, got {json.dumps(vd)}")
        feasible = c.bool(v, "feasible", w)
        rows.append([fmt(c.num(v, "turntable_deg", w), "g"), e(c.str(v, "lamps", w)), fmt(c.num(v, "exposure_us", w), "g"),
                     "yes" if feasible else "NO",
                     f"{c.int(v, 'n_detectable', w)} of {c.int(v, 'n_segments', w)}",
                     fmt(c.num(v, "detectable_length_px", w), ".0f"), fmt(c.num(v, "usable_points", w), ".0f"),
                     str(c.int(v, "glare_pix", w)), str(c.int(v, "saturated_pix", w)),
                     pct(c.num(v, "check_agreement", w, null=True)),
                     f'<a href="{e(vd)}/index.html">{e(vd)}/</a>'])
        cls.append("" if feasible else "miss")
        vj = load_json(os.path.join(d, vd, "plan.json"))
        vw = v.get("warnings") if isinstance(v.get("warnings"), list) else None
        if vw is None and isinstance(vj, dict) and isinstance(vj.get("configurations"), list):
            vw = edge_warnings(vj, [k for k in vj["configurations"] if isinstance(k, dict) and is_num(k.get("exposure_us"))],
                               c.num(v, "exposure_us", w))
        rows[-1].append("<br>".join(e(x.split(":")[0]) for x in (vw or [])) or "none")
        if vw:
            cls[-1] = cls[-1] or "surprise"
        vchk = vj.get("virtual_rig_check") if isinstance(vj, dict) else None
        target = vchk.get("target") if isinstance(vchk, dict) and is_num(vchk.get("target")) else None
        figv.append((c.num(v, "turntable_deg", w), c.num(v, "detectable_length_px", w),
                     c.num(v, "check_agreement", w, null=True), c.str(v, "lamps", w), target))
    fig_views(d, figv)
    prov = raw.get("provenance")
    L = page_head(f"refl plan lamps: {scene}, {len(rows)} views", prov)
    L.append(headline(views_headline(figv, rows, cls, raw, c)))
    L.append(f'<p>Each view (turntable angle) planned on its own: its lamp set and exposure, its report in its '
             f'directory. The capture plan of the views: <a href="{e(plan)}">{e(plan)}</a> (refl capture takes it '
             f"as it is; a [view N] section per view)"
             + ("" if bound is None else "; it binds to the virtual rig of the check" if bound
                else "; it does NOT bind to the virtual rig of the check") + '. Data: <a href="plan.json">plan.json</a>.</p>')
    L.append(table(["turntable (deg)", "lamps", "exposure (µs)", "feasible", "detectable segments",
                    "detectable length (px)", "usable points", "glare px", "saturated px", "check agreement",
                    "report", "warnings"], rows, cls,
                   [True, False, True, False, True, True, True, True, True, True, False, False]))
    L.append('<img src="views.png" alt="detectable edge length and check agreement per view">')
    L.append('<p class="note">Left: the predicted length of detectable edges per view, with its chosen lamps. Right: '
             'the virtual-rig check (when run): the share of segments whose detection on the rendered frame agrees '
             'with the prediction, against the target (dashed); red below it.</p>')
    L.append(provenance_section(prov, "plan.json"))
    L.append("</body></html>\n")
    return write_page(d, L)


def report(d):
    raw = load_json(os.path.join(d, "plan.json"))
    if isinstance(raw, dict) and "views" in raw:
        return report_views(d, raw)
    p = load_plan(d)
    img = read_float_tiff(os.path.join(d, "predicted.tiff"), "refl plan lamps writes it with plan.json")[0]
    have = {}
    if p["check"]:
        frame = read_float_tiff(os.path.join(d, "check_frame.tiff"), "plan.json has a virtual_rig_check")[0]
        if frame.shape != img.shape:
            raise Bad(os.path.join(d, "check_frame.tiff"), f"{frame.shape[1]} x {frame.shape[0]} px, predicted.tiff "
                      f"is {img.shape[1]} x {img.shape[0]}")
        have["check"] = fig_check(d, p, frame)
        del frame
    else:
        stale = os.path.join(d, "check.png")
        if os.path.exists(stale):
            os.unlink(stale)
    fig_predicted(d, p, img)
    del img
    fig_configs(d, p)
    return write_html(d, p, have)


def main():
    return run_report(PROG, __doc__, report)


if __name__ == "__main__":
    sys.exit(main())
