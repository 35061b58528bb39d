#!/usr/bin/python3
# scripts/demo_chain.py OUTDIR TRUTH.ini — the calibration and fitting chain of
# `make demo` against the virtual rig's ground truth: writes OUTDIR/chain.html
# (a page of its own, linked from the demo's index.html: OUTDIR/chain.json's table of every figure with its value,
# truth, stated sigma and z, computed by refl chain; then tables of calibrated
# vs true values by calibration) and OUTDIR/lobes.png
# (the fitted material's in-plane lobes against the truth's, at several
# incidence angles). Reads OUTDIR/calib/{geometry,lamps,gain,white}/*.json,
# OUTDIR/priors_glossy.json and the truth file (INI).
import configparser
import html
import json
import math
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from report_common import Bad, check_format, headline  # noqa: E402

out, truth_path = sys.argv[1], sys.argv[2]
cal = os.path.join(out, "calib")
ini = configparser.ConfigParser(inline_comment_prefixes=None, strict=False)
ini.read(truth_path)


FORMAT_OF = {"geometry.json": "refl-geometry", "lamps.json": "refl-lamps", "gain.json": "refl-gain",
             "white.json": "refl-white", "verify.json": "refl-verify", "chain.json": "refl-chain",
             "plan.json": "refl-lightplan"}


def load(*p):
    """A refl JSON file, checked against its format (report_common.check_format): another format or a newer
    version than this refl reads ends the page with the file's name."""
    path = os.path.join(*p)
    with open(path) as f:
        doc = json.load(f)
    base = os.path.basename(path)
    name = "refl-priors" if base.startswith("priors") else FORMAT_OF.get(base)
    if name and isinstance(doc, dict):
        try:
            check_format(doc, path, name)
        except Bad as b:
            sys.exit(f"demo_chain.py: {b.path}: {b.msg}")
    return doc


def row(cells, head=False):
    t = "th" if head else "td"
    return "<tr>" + "".join(f"<{t}>{html.escape(str(c))}</{t}>" for c in cells) + "</tr>\n"


def f(x, n=4):
    if not isinstance(x, (int, float)):
        return str(x)
    t = f"{x:.{n}g}"
    return t[1:] if t.startswith("-") and not any(c in "123456789" for c in t.split("e")[0]) else t   # no "-0"


parts = []
# ---- every figure against the truth (chain.json, written by refl chain) ------
cj_path = os.path.join(out, "chain.json")
if os.path.exists(cj_path):
    cj = load(cj_path)
    sm = cj["summary"]
    over = sm.get("z_over_3", [])
    zs = sorted((abs(e["z"]), e["name"], e["z"]) for e in cj["entries"] if isinstance(e.get("z"), (int, float)))
    hl = [("!" if over else "") + f"{sm['entries']} figures against the truth, {sm['with_sigma']} with a stated "
          f"1-sigma: " + (f"{len(over)} off by more than 3 sigma ({', '.join(html.escape(n) for n in over)})" if over
                          else "every stated 1-sigma covers its error (|z| &le; 3)"),
          ("!" if sm.get("wrong_verdicts") else "") + f"wrong verdicts: {sm.get('wrong_verdicts', 0)}"]
    if zs:
        hl.append("largest |z|: " + ", ".join(f"{html.escape(n)} {z:+.2f}" for _, n, z in zs[::-1][:3]))
    parts.append(headline(hl))
    parts.append("<h3>Every figure against the truth (<a href=\"chain.json\">chain.json</a>, refl chain)</h3>\n"
                 f"<p>Truth file <code>{html.escape(os.path.basename(cj['truth']))}</code>. "
                 f"{sm['entries']} figures; {sm['with_sigma']} with a stated &sigma; (1-sigma refl states for the "
                 f"value), {sm['without_sigma']} with a truth but no stated &sigma;. z = (value &minus; truth) / "
                 f"&sigma;. <b>{len(over)}</b> stated &sigma; fail to cover their error (|z| &gt; 3)"
                 + (": " + ", ".join(html.escape(n) for n in over) if over else "")
                 + f"; wrong verdicts: {sm.get('wrong_verdicts', 0)}; materials whose fitted model is over 1.2 "
                 f"&times; the best fit's Ngan error against a tabulated truth: "
                 f"{len(sm.get('ngan_ratio_over_1_2', []))}.</p>\n<table>\n")
    # a note several figures share is written once under the table and referred to by its number
    uses = {}
    for e in cj["entries"]:
        uses[e.get("note", "")] = uses.get(e.get("note", ""), 0) + 1
    shared = [n for n in uses if n and uses[n] > 1]
    num = {n: k + 1 for k, n in enumerate(shared)}
    parts.append(row(["figure", "value", "truth", "sigma", "error", "z", "unit", "note"], True))
    for e in cj["entries"]:
        z = e.get("z")
        bad = ((z is not None and abs(z) > 3) or (isinstance(e.get("value"), str) and e.get("error"))
               or (e["name"].endswith(".ngan_error_ratio") and (e.get("value") or 0) > 1.2))
        cells = [e["name"], f(e.get("value"), 6), "" if e.get("truth") is None else f(e["truth"], 6),
                 "" if e.get("sigma") is None else f(e["sigma"], 3),
                 "" if e.get("error") is None else f(e["error"], 3),
                 "" if z is None else f"{z:+.2f}", e.get("unit", ""), e.get("note", "")]
        tr = "<tr style=\"background:#fdd\">" if bad else "<tr>"
        # a long figure name may break after its dots; a shared note is its number
        tds = [html.escape(str(c)).replace('.', '.<wbr>') if k == 0 else html.escape(str(c))
               for k, c in enumerate(cells)]
        if cells[-1] in num:
            tds[-1] = f'<a href="#note{num[cells[-1]]}">note {num[cells[-1]]}</a>'
        parts.append(tr + "".join(f"<td>{c}</td>" for c in tds) + "</tr>\n")
    parts.append("</table>\n")
    if shared:
        parts.append("<p>Notes shared by several figures:</p>\n<ol>\n" + "".join(
            f'<li id="note{num[n]}">{html.escape(n)}</li>\n' for n in shared) + "</ol>\n")

# ---- geometry ---------------------------------------------------------------
geo = load(cal, "geometry", "geometry.json")
import mrcal  # noqa: E402  (python3-mrcal: the truth camera's centre)
tm = mrcal.cameramodel(os.path.join(os.path.dirname(truth_path), ini["camera"]["model"]))
Rt = tm.extrinsics_Rt_fromref()
centre_true = -Rt[:3, :].T @ Rt[3, :]
centre = np.array(geo["camera_centre_rig_mm"])
it, im = tm.intrinsics()[1], np.array(geo["intrinsics"])
parts.append("<h3>Camera geometry (refl calib geometry)</h3>\n<table>\n")
parts.append(row(["figure", "calibrated", "truth", "difference"], True))
for k, name in enumerate(["fx (px)", "fy (px)", "cx (px)", "cy (px)"]):
    parts.append(row([name, f(im[k], 6), f(it[k], 6), f(im[k] - it[k], 3)]))
parts.append(row(["camera centre, rig frame (mm)", np.round(centre, 2).tolist(), np.round(centre_true, 2).tolist(),
                  f"{np.linalg.norm(centre - centre_true):.2f} mm"]))
ax = geo["axis"]
parts.append(row(["turntable axis direction (camera frame)", np.round(ax["direction_cam"], 5).tolist(),
                  np.round(Rt[:3, :] @ np.array([0, 0, 1.0]), 5).tolist(),
                  f"{math.degrees(math.acos(min(1, abs(np.dot(ax['direction_cam'], Rt[:3, :] @ [0, 0, 1.0]))))):.3f} deg"]))
parts.append(row(["RMS reprojection residual (px)", f(geo["rms_residual_px"]), "", ""]))
parts.append(row(["views with a board", f"{geo['views_used']} of {geo['views_total']}", "", ""]))
pu = geo.get("projection_uncertainty", {})
if pu:
    parts.append(row([f"projection uncertainty at {pu.get('distance_mm')} mm (px)",
                      f"median {f(pu.get('median_px'), 3)}, max {f(pu.get('max_px'), 3)}", "", ""]))
parts.append("</table>\n")

# ---- lamps -----------------------------------------------------------------
lj = load(cal, "lamps", "lamps.json")
parts.append("<h3>Lamp positions (refl calib lamps, with the calibrated camera)</h3>\n<table>\n")
parts.append(row(["lamp", "calibrated (mm)", "std (mm)", "truth (mm)", "error (mm)"], True))
errs = []
for l in lj["lamps"]:
    tp = [float(v) for v in ini["lamp " + l["name"]]["position_mm"].split()]
    e = np.linalg.norm(np.array(l["position_mm"]) - tp)
    errs.append(e)
    parts.append(row([l["name"], np.round(l["position_mm"], 1).tolist(), np.round(l["std_mm"], 2).tolist(), tp,
                      f"{e:.2f}"]))
parts.append(row(["RMS", "", "", "", f"{math.sqrt(np.mean(np.square(errs))):.2f}"]))
parts.append("</table>\n")

# ---- gain ------------------------------------------------------------------
gj = load(cal, "gain", "gain.json")
s = ini["sensor"]
parts.append("<h3>Sensitivity (refl calib gain, EMVA 1288 style)</h3>\n<table>\n")
parts.append(row(["figure", "calibrated", "1-sigma (gain.json std)", "truth"], True))
for key, tkey, unit in [("system_gain_dn_per_e", "system_gain_dn_per_e", "DN/e-"), ("read_noise_e", "read_noise_e", "e-"),
                        ("dsnu_dn", "dsnu_dn", "DN"), ("prnu_pct", "prnu_pct", "%"),
                        ("dark_current_e_per_s", "dark_current_e_per_s", "e-/s"),
                        ("linearity_error_pct", "nonlinearity_pct", "% (truth: compression at full well)")]:
    parts.append(row([f"{key} ({unit})", f(gj.get(key)), f((gj.get("std") or {}).get(key, "")), s.get(tkey, "")]))
parts.append("</table>\n")

# ---- reference white ---------------------------------------------------------
wj = load(cal, "white", "white.json")
kc = float(ini["camera"]["kc_per_us"])
parts.append("<h3>Reference white: kc&middot;I per lamp (refl calib white)</h3>\n"
             "<p>Relative to the flat field g(x,y) of the gain calibration (mean 1), so the truth column is "
             "kc_per_us &middot; I &middot; mean(g) with mean(g) from the calibrated response.</p>\n<table>\n")
parts.append(row(["lamp", "kc*I (DN/us per (1/sr)/mm^2)", "1-sigma (%)", "its parts (%)", "truth kc*I*mean(g)",
                  "ratio"], True))
gmean = gj.get("kc_small_signal_per_us", kc) / kc if gj.get("kc_small_signal_per_us") else 1.0
for l in wj["lamps"]:
    t = kc * float(ini["lamp " + l["name"]]["intensity"]) * gmean
    sp = l.get("sigma_parts_rel") or {}
    pt = ", ".join(f"{k} {100 * v:.3g}" for k, v in sp.items() if isinstance(v, (int, float)))
    sr = l.get("std_rel")
    parts.append(row([l["name"], f(l["kc_I_per_us"], 6), f(100 * sr, 3) if isinstance(sr, (int, float)) else "",
                      pt, f(t, 6), f(l["kc_I_per_us"] / t, 4)]))
parts.append("</table>\n")

# ---- material ----------------------------------------------------------------
def choice(m):
    """How a priors entry's model was chosen (its model_choice; older files: the lowest BIC)."""
    c, n = m.get("model_choice") or {}, len(m.get("candidates", []))
    if c.get("criterion") == "cv_rms":
        return (f"the lowest held-out RMS of {n} ({c.get('folds')}-fold cross-validation over {c.get('units')} "
                f"{html.escape(str(c.get('unit')))}s, the simplest within one standard error); lowest BIC: "
                f"{html.escape(str(c.get('lowest_bic')))}")
    return f"lowest BIC of {n}"


pj = load(out, "priors_glossy.json")
m = pj["materials"][0]
tmat = ini["material " + m["name"]] if ("material " + m["name"]) in ini else None
parts.append(f"<h3>Material: {html.escape(m['name'])} (refl fit material &rarr; priors_glossy.json, "
             "<a href=\"fit_glossy/report.html\">fit report</a>)</h3>\n"
             f"<p>Chosen model <b>{html.escape(m['model'])}</b> ({choice(m)}); "
             f"RMS of R {f(m['rms'], 3)} 1/sr over {m['n_samples']} samples"
             + (f"; the sensor's noise alone would give {f(m['noise_rms_expected'], 3)} 1/sr "
                f"(ratio {f(m['rms_over_noise'], 3)}: the narrow lobe is sensitive to the calibrated camera and "
                f"lamp positions, {math.sqrt(np.mean(np.square(errs))):.1f} mm RMS off here; with the truth's camera and lamps it is 1.1 in the tests)" if m.get("noise_rms_expected") else "") + ".</p>\n<table>\n")
parts.append(row(["parameter", "fitted", "std", "prior bounds", "truth", "note"], True))
for p in m["parameters"]:
    tv = tmat.get(p["name"], "") if tmat is not None and tmat.get("model") == m["model"] else ""
    parts.append(row([f"{p['name']} ({p['unit']})", f(p["mean"], 5), f(p["std"], 3),
                      f"{f(p['lo'], 4)} .. {f(p['hi'], 4)}", tv, p.get("held", "")]))
if "ks_times_F0" in m and tmat is not None and "ks" in tmat and "F0" in tmat:
    parts.append(row(["ks*F0", f(m["ks_times_F0"], 5), "", "", f(float(tmat["ks"]) * float(tmat["F0"]), 5),
                      "the product; F0 apart from ks needs a highlight nearer grazing (the rim lamp's, v.h = cos 55 deg)"]))
parts.append("</table>\n<table>\n")
parts.append(row(["model", "RMS (1/sr)", "held-out RMS (1/sr)", "BIC"], True))
for c in m.get("candidates", []):
    parts.append(row([c["model"], f(c["rms"], 4), f(c["cv_rms"], 4) if c.get("cv_rms") is not None else "", f(c["bic"], 7)]))
parts.append("</table>\n<img src=\"lobes.png\" alt=\"fitted vs true lobes\">\n")

# ---- the workpiece's materials: plywood and painted steel ----------------------
for fname in ("priors_plywood.json", "priors_painted_steel.json"):
    if not os.path.exists(os.path.join(out, fname)):
        continue
    for wm in load(out, fname)["materials"]:
        wtmat = ini["material " + wm["name"]] if ("material " + wm["name"]) in ini else None
        parts.append(f"<h3>Material: {html.escape(wm['name'])} (refl fit material &rarr; {fname}, "
                     f"<a href=\"fit_{html.escape(wm['name'])}/report.html\">fit report</a>)</h3>\n"
                     f"<p>Chosen model <b>{html.escape(wm['model'])}</b> ({choice(wm)}; the truth's is "
                     f"<b>{html.escape(wtmat.get('model', '?') if wtmat is not None else '?')}</b>); RMS of R "
                     f"{f(wm['rms'], 3)} 1/sr over {wm['n_samples']} samples"
                     + (f"; {f(wm['rms_over_noise'], 3)} &times; what the sensor's noise alone would leave"
                        if wm.get("rms_over_noise") is not None else "")
                     + (f". Albedo cells of {f(wm['albedo_cells']['cell_mm'], 3)} mm: {wm['albedo_cells']['cells']} "
                        f"cells hold {wm['albedo_cells']['observations_in_cells']} of "
                        f"{wm['albedo_cells']['observations']} observations; the albedo varies by "
                        f"{f(100 * wm['albedo_cells']['factor_rel_std'], 3)} % (std) from place to place "
                        f"(the truth's texture: amplitude "
                        f"{html.escape(ini['texture ' + wm['name']].get('amplitude', '?')) if ('texture ' + wm['name']) in ini else 'none'})"
                        if wm.get("albedo_cells") else "")
                     + ".</p>\n<table>\n")
        parts.append(row(["parameter", "fitted", "std", "prior bounds", "truth", "fitted / truth"], True))
        for wp in wm["parameters"]:
            same = wtmat is not None and wtmat.get("model") == wm["model"]
            tv = wtmat.get(wp["name"], "") if same else ""
            ratio = f(wp["mean"] / float(tv), 4) if tv not in ("", None) and float(tv) != 0 else ""
            parts.append(row([f"{wp['name']} ({wp['unit']})", f(wp["mean"], 5), f(wp["std"], 3),
                              f"{f(wp['lo'], 4)} .. {f(wp['hi'], 4)}", tv, ratio]))
        parts.append("</table>\n")

# ---- light planning ------------------------------------------------------------
pp = os.path.join(out, "plan_lamps", "plan.json")
if os.path.exists(pp) and "views" in load(pp):
    # several views (refl plan lamps --angles-deg): each view's choice, and the capture plan of the views
    pl = load(pp)
    bound = pl.get("capture_plan_binds_to_virtual_rig")
    parts.append("<h3>Light planning for the workpiece's views (refl plan lamps, "
                 "<a href=\"plan_lamps/index.html\">report</a>)</h3>\n"
                 "<p>With the calibrated camera, lamps, white and gain and the fitted priors, each view (turntable "
                 "angle) planned on its own: every set of the calibrated lamps at six exposures, the set and exposure "
                 "that make the most edge length detectable without glare or saturation. The views' choices make the "
                 "capture plan <a href=\"plan_lamps/capture_plan.ini\">capture_plan.ini</a> the verification session "
                 "below captures as it is"
                 + ("" if bound is None else " (checked: it binds to the virtual rig)" if bound
                    else " (it does NOT bind to the virtual rig)") + ".</p>\n<table>\n")
    parts.append(row(["turntable (deg)", "lamps", "exposure (us)", "free of glare and saturation",
                      "detectable segments", "detectable length (px)", "usable points",
                      "Sobel agreement on the rig", "report"], True))
    for v in pl["views"]:
        ag = v.get("check_agreement")
        cells = [f(v["turntable_deg"], 4), v["lamps"], f(v["exposure_us"], 6), "yes" if v["feasible"] else "NO",
                 f"{v['n_detectable']} of {v['n_segments']}", f(v["detectable_length_px"], 5),
                 f(v["usable_points"], 5), "" if ag is None else f"{100 * ag:.1f} %"]
        parts.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
                     + f"<td><a href=\"plan_lamps/{html.escape(v['dir'])}/index.html\">{html.escape(v['dir'])}</a>"
                     "</td></tr>\n")
    parts.append("</table>\n")
elif os.path.exists(pp):
    pl = load(pp)
    c = pl["chosen"]
    chk = pl.get("virtual_rig_check") or {}
    parts.append("<h3>Light planning for the workpiece (refl plan lamps, "
                 "<a href=\"plan_lamps/index.html\">report</a>)</h3>\n"
                 f"<p>With the calibrated camera, lamps, white and gain and the fitted priors, at turntable "
                 f"{f(pl['turntable_deg'], 4)}&deg;: every set of the calibrated lamps at six exposures. Chosen: "
                 f"<b>{html.escape(c['lamps'])}</b> at <b>{f(c['exposure_us'], 6)} &micro;s</b> "
                 f"({'free of glare and saturation' if c['feasible'] else 'not free of glare and saturation'}): "
                 f"{c['n_detectable']} of {c['n_segments']} visible edge segments predicted detectable by a Sobel "
                 f"detector ({f(c['detectable_length_px'], 5)} px), {f(c['usable_points'], 5)} usable reference "
                 f"points.")
    if chk.get("agreement") is not None:
        parts.append(f" On the virtual rig's own frames (the chosen set and each lamp) a Sobel detector agrees "
                     f"with the prediction on <b>{100 * chk['agreement']:.1f} %</b> of the judged segments "
                     f"(target {100 * chk.get('target', 0.95):.0f} %).")
    parts.append("</p>\n")

# ---- verification --------------------------------------------------------------
ver = [("verify_t", "T-stiffener (the correct description)", True),
       ("verify_i", "I-stiffener (wrong)", False),
       ("verify_shift5", "T-stiffener shifted 5 mm (wrong)", False)]
if any(os.path.exists(os.path.join(out, d, "verify.json")) for d, _, _ in ver):
    parts.append("<h3>Verification of the workpiece (refl verify, with the calibrations and priors above)</h3>\n"
                 "<p>Four views of the T-stiffener (turntable 0, 90, 180, 270&deg;, each with its planned lamps and "
                 "exposure) captured on the virtual rig, verified against the correct description and two wrong ones. The residue columns "
                 "are the thesis's (|measured &minus; model| at the reference points, DN); the thesis could not tell "
                 "T from I by them (mean 14.0 vs 17.9). The score sums the excess &chi;&sup2; of connected change "
                 "regions; the verdict is <i>incorrect</i> above the threshold.</p>\n<table>\n")
    parts.append(row(["description", "expected", "verdict", "score", "threshold", "change regions", "points",
                      "max |diff|", "mean |diff|", "std |diff|", "pinned", "report"], True))
    for d, label, expect in ver:
        pth = os.path.join(out, d, "verify.json")
        if not os.path.exists(pth):
            continue
        v = load(pth)
        r = v["residue"]
        ok = (v["verdict"] == "correct") == expect
        cells = [label, "correct" if expect else "incorrect", v["verdict"] + ("" if ok else " (WRONG)"),
                 f(v["score"], 4), f(v["score_threshold"], 3), len(v["change_regions"]), r["n_points"],
                 f(r["max_abs_diff_dn"], 4), f(r["mean_abs_diff_dn"], 4), f(r["std_abs_diff_dn"], 4),
                 v["n_pinned_parameters"]]
        parts.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
                     + f"<td><a href=\"{d}/index.html\">{d}/index.html</a></td></tr>\n")
    parts.append("</table>\n")

HEAD = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>refl demo: the chain against the "
        "truth</title>\n<style>\nbody { font-family: sans-serif; margin: 1.5em; max-width: 1600px; }\n"
        "table { border-collapse: collapse; margin: 1em 0; }\n"
        "td, th { border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }\n"
        "td:last-child { overflow-wrap: anywhere; min-width: 16em; }\n"
        "th { background: #eee; }\nimg { max-width: 100%; border: 1px solid #ccc; }\n</style></head><body>\n"
        "<p><a href=\"index.html\">&larr; the demo's index</a></p>\n"
        "<h1>The chain against the truth: capture &rarr; calibrate &rarr; fit &rarr; priors &rarr; verify</h1>\n"
        f"<p>Every calibrated and fitted figure of the lab day in <code>{html.escape(os.path.abspath(out))}</code> "
        "against the virtual rig's truth "
        f"(<code>{html.escape(os.path.basename(truth_path))}</code>). The virtual rig's physics is richer than the "
        "fitter's (finite lamps, Monte Carlo interreflection, texture, sensor noise and fixed patterns), so the "
        "differences are what the chain costs.</p>\n")
with open(os.path.join(out, "chain.html") + ".part", "w") as fh:
    fh.write(HEAD + "".join(parts) + "</body></html>\n")
os.replace(os.path.join(out, "chain.html") + ".part", os.path.join(out, "chain.html"))


# ---- lobes: GGX (the truth's model) in the plane of incidence -------------
def ggx_R(p, ti, to):
    kd, ks, a, F0 = p
    l = np.array([math.sin(ti), 0, math.cos(ti)])
    v = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], axis=1)
    h = v + l
    h /= np.linalg.norm(h, axis=1)[:, None]
    nl, nv, nh, vh = l[2], v[:, 2], h[:, 2], h @ l
    a2 = a * a
    D = a2 / (np.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    lam = lambda c: (np.sqrt(1 + a2 * np.maximum(0, (1 - c * c) / (c * c))) - 1) / 2  # noqa: E731
    G = 1 / (1 + lam(nl) + lam(nv))
    F = F0 + (1 - F0) * (1 - vh) ** 5
    return kd / np.pi * nl + ks * D * G * F / (4 * nv)


if m["model"] == "ggx" and tmat is not None and tmat.get("model") == "ggx":
    pf = [q["mean"] for q in m["parameters"]]
    pt = [float(tmat[k]) for k in ("kd", "ks", "alpha", "F0")]
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.6))
    to = np.radians(np.linspace(-85, 85, 681))
    for ax_, ti_deg in zip(axs, (20, 40, 60)):
        ti = math.radians(ti_deg)
        # in-plane: viewing angle signed, the mirror direction at +ti
        ax_.semilogy(np.degrees(to), ggx_R(pt, -ti, to), "k-", lw=2, label="truth")
        ax_.semilogy(np.degrees(to), ggx_R(pf, -ti, to), "r--", lw=1.5, label="fitted (priors)")
        ax_.set_title(f"incidence {ti_deg} deg")
        ax_.set_xlabel("viewing angle in the plane of incidence (deg)")
        ax_.set_ylim(1e-2, None)
        ax_.grid(True, alpha=0.3)
    axs[0].set_ylabel("R = f_r cos(theta_i) (1/sr)")
    axs[0].legend()
    fig.suptitle(f"{m['name']}: GGX lobes, fitted from the virtual rig vs the truth")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lobes.png"), dpi=90)
print(os.path.join(out, "chain.html"))
