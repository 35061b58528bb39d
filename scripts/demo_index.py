#!/usr/bin/python3
# scripts/demo_index.py OUTDIR [VERSION] — the demo's summary page, OUTDIR/index.html: what was done, one line a
# step with its headline figure and a link to its report (geometry, lamps, gain, white, every material's fit
# report, the light plan, every verification, the chain against the truth in chain.html), then the files. The
# command log stays in OUTDIR/demo.log (linked, not copied in). Only what exists in OUTDIR is listed: a step
# whose output is missing reads "missing". Written by scripts/demo after its last step; runs on any OUTDIR.
import glob
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from report_common import Bad, check_format, check_headline, e, fmt, headline, table  # noqa: E402

STYLE = """<style>
body { font-family: sans-serif; margin: 1.5em; max-width: 1400px; }
table { border-collapse: collapse; margin: 1em 0; }
td, th { border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #eee; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
tr.bad td { background: #fdd; }
img { max-width: 100%; border: 1px solid #ccc; }
</style>"""


# refl's file names and their formats (report_common.FORMATS)
FORMAT_OF = {"geometry.json": "refl-geometry", "lamps.json": "refl-lamps", "gain.json": "refl-gain",
             "white.json": "refl-white", "verify.json": "refl-verify", "chain.json": "refl-chain",
             "plan.json": "refl-lightplan", "study.json": "refl-study"}


def jload(out, rel):
    """The JSON object OUTDIR/rel, or None when it is missing, not JSON, or of another format or a newer version
    than this refl reads (the page says "missing")."""
    try:
        with open(os.path.join(out, rel), encoding="utf-8") as f:
            o = json.load(f)
        if not isinstance(o, dict):
            return None
        base = os.path.basename(rel)
        fmt_name = "refl-priors" if base.startswith("priors") else FORMAT_OF.get(base)
        if fmt_name:
            check_format(o, rel, fmt_name)
        return o
    except (OSError, ValueError, Bad):
        return None


def link(out, rel, text=None):
    if not os.path.exists(os.path.join(out, rel)):
        return f"{e(text or rel)} (missing)"
    return f'<a href="{e(rel)}">{e(text or rel)}</a>'


def emva_row(gain, symbol):
    """The value of gain.json's EMVA 1288 datasheet row of that symbol, or None."""
    rows = ((gain or {}).get("emva1288") or {}).get("datasheet") or []
    for r in rows:
        if isinstance(r, dict) and r.get("symbol") == symbol and isinstance(r.get("value"), (int, float)):
            return r["value"]
    return None


def calib_rows(out):
    rows = []
    g = jload(out, "calib/geometry/geometry.json")
    c = jload(out, "chain.json")
    ent = {x.get("name"): x for x in (c or {}).get("entries", []) if isinstance(x, dict)}
    truth = ent.get("camera.projection_error_rms")
    worst = ent.get("camera.projection_error_worst")
    vs_truth = (f"; projection against the truth's lens {fmt(truth.get('value'), '.3f')} px RMS"
                + (f", {fmt(worst.get('value'), '.3f')} px worst" if worst else "") if truth else "")
    rows.append(["camera geometry (refl calib geometry)", link(out, "calib/geometry/report.html", "geometry report"),
                 f"{fmt(g.get('rms_residual_px'), '.3f')} px RMS residual, {g.get('views_used')} of "
                 f"{g.get('views_total')} views, {g.get('outliers')} outliers{vs_truth}" if g else "missing"])
    lp = jload(out, "calib/lamps/lamps.json")
    lamps = lp.get("lamps") if lp else None
    rows.append(["lamp positions (refl calib lamps)", link(out, "calib/lamps/report.html", "lamps report"),
                 f"{len(lamps)} lamps: " + ", ".join(e(str(m.get("name"))) for m in lamps if isinstance(m, dict))
                 if isinstance(lamps, list) else "missing"])
    pats = [m for m in lamps if isinstance(m, dict) and "emission_cos_power" in m] if isinstance(lamps, list) else []
    rows.append(["lamp emission patterns (refl calib pattern)",
                 link(out, "calib/lamps/pattern/report.html", "pattern report"),
                 ", ".join(f"{e(str(m.get('name')))} n {fmt(m.get('emission_cos_power'), '.2f')}" for m in pats)
                 if pats else "missing"])
    gn = jload(out, "calib/gain/gain.json")
    kst = emva_row(gn, "K")
    rows.append(["sensitivity, EMVA 1288 (refl calib gain)", link(out, "calib/gain/report.html", "gain report"),
                 (f"EMVA 1288 K {fmt(kst, '.4g')} DN/e-; " if kst is not None else "")
                 + f"refl's small-signal K {fmt(gn.get('system_gain_dn_per_e'), '.4g')} DN/e-, read noise "
                 f"{fmt(gn.get('read_noise_e'), '.3g')} e-, PRNU {fmt(gn.get('prnu_pct'), '.3g')} %" if gn else "missing"])
    w = jload(out, "calib/white/white.json")
    rows.append(["absolute scale kc&middot;I (refl calib white)", link(out, "calib/white/white.json"),
                 "written" if w else "missing"])
    return rows


def material_rows(out):
    rows = []
    for p in sorted(glob.glob(os.path.join(out, "priors_*.json"))):
        name = os.path.basename(p)[len("priors_"):-len(".json")]
        d = jload(out, os.path.basename(p))
        m = (d.get("materials") or [None])[0] if d else None
        rep = f"fit_{name}/report.html"
        if not isinstance(m, dict):
            rows.append([e(name), link(out, rep, "fit report"), link(out, os.path.basename(p)), "not a priors file"])
            continue
        ron = m.get("rms_over_noise")
        cells = m.get("albedo_cells")
        fig = (f"model <b>{e(m.get('model'))}</b>, RMS of R {fmt(m.get('rms'), '.3g')} 1/sr"
               + (f" = {fmt(ron, '.2f')} &times; the noise" if ron is not None else "")
               + (f"; albedo spread {fmt(100 * cells['factor_rel_std'], '.2g')} % over {cells.get('cells')} cells"
                  if isinstance(cells, dict) and cells.get("factor_rel_std") is not None else ""))
        rows.append([e(m.get("name", name)), link(out, rep, "fit report"), link(out, os.path.basename(p)), fig])
    return rows


def verify_rows(out):
    rows, classes = [], []
    for d in sorted(glob.glob(os.path.join(out, "verify_*"))):
        if not os.path.isdir(d):
            continue
        rel = os.path.basename(d)
        v = jload(out, rel + "/verify.json")
        scene = os.path.basename(str(v.get("scene"))) if v else "?"
        fig = (f"verdict <b>{e(v.get('verdict'))}</b>, score {fmt(v.get('score'), '.4g')} (threshold "
               f"{fmt(v.get('score_threshold'), '.4g')})" if v else "missing")
        rows.append([e(scene), link(out, rel + "/index.html", rel + " report"), fig])
        classes.append(None if v else "bad")
    return rows, classes


def headline_verdicts(out, ent):
    """The verdicts, each against the expected one where chain.json has it (a wrong one is a miss)."""
    items = []
    for d in sorted(glob.glob(os.path.join(out, "verify_*"))):
        rel = os.path.basename(d)
        v = jload(out, rel + "/verify.json") if os.path.isdir(d) else None
        if not v:
            continue
        x = ent.get(rel + ".verdict") or {}
        want = x.get("truth")
        right = want is None or want == v.get("verdict")
        items.append(("" if right else "!") + f"{e(os.path.basename(str(v.get('scene'))))}: verdict "
                     f"<b>{e(v.get('verdict'))}</b> (score {fmt(v.get('score'), '.4g')}, threshold "
                     f"{fmt(v.get('score_threshold'), '.4g')})"
                     + ("" if want is None else ", as expected" if right else f", expected {e(want)}"))
    return items


def headline_calib(out):
    """The calibrations' figures with their 1-sigma."""
    items = []
    g = jload(out, "calib/geometry/geometry.json")
    if g:
        pu = g.get("projection_uncertainty") if isinstance(g.get("projection_uncertainty"), dict) else {}
        items.append(f"camera: residual {fmt(g.get('rms_residual_px'), '.3f')} px RMS over {g.get('views_used')} "
                     f"views; projection 1-sigma at {fmt(pu.get('distance_mm'), 'g')} mm {fmt(pu.get('centre_px'), '.3f')}"
                     f" px at the centre, {fmt(pu.get('max_px'), '.3f')} px worst")
    lp = jload(out, "calib/lamps/lamps.json")
    lamps = [m for m in (lp or {}).get("lamps", []) if isinstance(m, dict)]
    sds = [max(m["std_mm"]) for m in lamps if isinstance(m.get("std_mm"), list) and m["std_mm"]]
    if lamps:
        items.append(f"lamps: {len(lamps)} positions, 1-sigma at most {fmt(max(sds), '.2f')} mm per axis" if sds
                     else f"lamps: {len(lamps)} positions")
    gn = jload(out, "calib/gain/gain.json")
    if gn:
        sd = gn.get("std") if isinstance(gn.get("std"), dict) else {}
        kst = emva_row(gn, "K")
        items.append((f"sensor: EMVA 1288 K {fmt(kst, '.4g')} DN/e-; " if kst is not None else "sensor: ")
                     + f"refl's small-signal K {fmt(gn.get('system_gain_dn_per_e'), '.4g')} ± "
                     f"{fmt(sd.get('system_gain_dn_per_e'), '.2g')} DN/e-, read noise {fmt(gn.get('read_noise_e'), '.3g')}"
                     f" ± {fmt(sd.get('read_noise_e'), '.2g')} e-")
    w = jload(out, "calib/white/white.json")
    wl = [m for m in (w or {}).get("lamps", []) if isinstance(m, dict)]
    if wl:
        items.append("absolute scale kc·I: " + ", ".join(
            f"{e(m.get('name'))} {fmt(m.get('kc_I_per_us'), '.4g')} ± {fmt(100 * (m.get('std_rel') or float('nan')), '.2g')} %"
            for m in wl) + " (DN/µs at 0 dB per (1/sr)/mm²)")
    return items


def headline_materials(out):
    """Each material's model and residual; a parameter the priors flag barely constrained (their
    "barely_constrained", refl's rule: 1-sigma over 30 % of the value or of the bounds' width) is a miss."""
    items = []
    for p in sorted(glob.glob(os.path.join(out, "priors_*.json"))):
        d = jload(out, os.path.basename(p))
        m = (d.get("materials") or [None])[0] if d else None
        if not isinstance(m, dict):
            continue
        ron = m.get("rms_over_noise")
        items.append(f"{e(m.get('name'))}: model {e(m.get('model'))}"
                     + (f", residual {fmt(ron, '.2f')} × the noise" if ron is not None else ""))
        for q in m.get("parameters") or []:
            if not isinstance(q, dict) or q.get("barely_constrained") is not True:
                continue
            try:
                mean, sd, width = float(q["mean"]), float(q["std"]), float(q["hi"]) - float(q["lo"])
            except (KeyError, TypeError, ValueError):
                mean, sd, width = float("nan"), float("nan"), float("nan")
            items.append(f"!{e(m.get('name'))}: {e(q.get('name'))} = {mean:.4g} ± {sd:.2g} barely constrained "
                         f"(1-sigma {100 * sd / abs(mean) if mean else float('inf'):.0f} % of the value, "
                         f"{100 * sd / width if width > 0 else float('nan'):.0f} % of the bounds' width; the rule: "
                         "over 30 % of either)")
    return items


def headline_plan(out):
    """The light plan's virtual-rig check against its target, each view that misses it in words."""
    pl = jload(out, "plan_lamps/plan.json")
    rows = []
    for v in (pl or {}).get("views", []):
        if not isinstance(v, dict) or not isinstance(v.get("check_agreement"), (int, float)):
            continue
        vj = jload(out, f"plan_lamps/{v.get('dir')}/plan.json") or {}
        ck = vj.get("virtual_rig_check") if isinstance(vj.get("virtual_rig_check"), dict) else {}
        if isinstance(ck.get("target"), (int, float)):
            rows.append((v.get("turntable_deg"), v["check_agreement"], ck["target"]))
    item = check_headline(rows, "light plan's virtual-rig check")
    return [item] if item else []


def headline_items(out):
    c = jload(out, "chain.json")
    ent = {x.get("name"): x for x in (c or {}).get("entries", []) if isinstance(x, dict)}
    items = headline_verdicts(out, ent)
    if c and isinstance(c.get("summary"), dict):
        s = c["summary"]
        z3 = s.get("z_over_3") or []
        items.append(("!" if z3 or s.get("wrong_verdicts") else "")
                     + f"against the truth: {s.get('entries')} figures, {s.get('with_sigma')} with a stated 1-sigma; "
                     + (f"{len(z3)} off by more than 3 sigma ({', '.join(e(x) for x in z3)})" if z3
                        else "none off by more than 3 sigma")
                     + f"; {s.get('wrong_verdicts')} wrong verdicts")
    elif c is None:
        items.append("!against the truth: chain.json missing")
    return items + headline_calib(out) + headline_materials(out) + headline_plan(out)


def chain_line(out):
    c = jload(out, "chain.json")
    if not c or not isinstance(c.get("summary"), dict):
        return f"<p>The comparison with the truth: {link(out, 'chain.html', 'chain.html')}.</p>"
    s = c["summary"]
    z3 = s.get("z_over_3") or []
    return (f"<p>{link(out, 'chain.html', 'The chain against the truth')}: {s.get('entries')} figures compared, "
            f"{s.get('with_sigma')} with a stated sigma; {len(z3)} off by more than 3 sigma"
            + (" (" + ", ".join(e(n) for n in z3) + ")" if z3 else "")
            + f"; {s.get('wrong_verdicts')} wrong verdicts.</p>")


FILES = [
    ("virtual-rig-demo.ini", "the rig file of the demo"),
    ("session/session.sqlite", "the capture session's journal"),
    ("session_frames.csv", "its frame table (refl session export)"),
    ("calib/geometry/camera.cameramodel", "the calibrated camera (mrcal format)"),
    ("calib/lamps/lamps.json", "lamp positions with std"),
    ("calib/gain/gain.json", "EMVA 1288 figures"),
    ("plan_lamps/capture_plan.ini", "the verification's capture plan"),
    ("t_stiffener_direct.tiff", "rendered T-stiffener, P in DN (float32)"),
    ("t_stiffener_info.tiff", "per-pixel ground truth (P, face id, lit masks)"),
    ("t_stiffener_edges.txt", "predicted visible edges (refl edges)"),
    ("demo.log", "every command and its summary"),
]


def make(out, version):
    title = "refl demo: the T-stiffener workpiece"
    L = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">', f"<title>{e(title)}</title>", STYLE,
         "</head><body>", f"<h1>{e(title)}</h1>",
         f"<p>refl {e(version)}, {time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}. A lab day on the virtual rig: "
         "calibrate the camera, the lamps, the sensor and the absolute scale, fit the materials on coupons, plan "
         "the lamps of four views of the T-stiffener, capture them and verify the correct description and wrong "
         "ones. Lengths mm in the rig frame (origin at the turntable top centre, z up); pixels as mrcal's; grey "
         f"values DN. The commands and their output: {link(out, 'demo.log')}.</p>"]
    L.append(headline(headline_items(out)))
    if os.path.exists(os.path.join(out, "figure.png")):
        L.append('<img src="figure.png" alt="rendered images, wrong descriptions and differences" '
                 'style="max-width: 900px">')
    L.append("<h2>Calibrations</h2>")
    L.append(table(["step", "report", "result"], calib_rows(out)))
    L.append("<h2>Materials</h2>")
    mr = material_rows(out)
    L.append(table(["material", "report", "priors", "fit"], mr) if mr else "<p>No priors_*.json.</p>")
    L.append("<h2>Light plan and verification</h2>")
    pl = jload(out, "plan_lamps/plan.json")
    views = [v for v in (pl or {}).get("views", []) if isinstance(v, dict)]
    pv = "; ".join(f"{fmt(v.get('turntable_deg'), 'g')}°: {e(v.get('lamps'))} at {fmt(v.get('exposure_us'), 'g')} µs"
                   for v in views)
    warn = sorted({str(w).split(":")[0] for v in views for w in (v.get("warnings") or [])})
    L.append(f"<p>{link(out, 'plan_lamps/index.html', 'Light plan')} of the views (each view's lamps and exposure)"
             + (f": {pv}" if pv else "") + ".</p>")
    if warn:
        L.append("<p><b>Light plan warnings:</b> " + "; ".join(e(w) for w in warn) + ".</p>")
    vr, vc = verify_rows(out)
    L.append(table(["description", "report", "result"], vr, classes=vc) if vr else "<p>No verification.</p>")
    L.append("<h2>Against the truth</h2>")
    L.append(chain_line(out))
    L.append("<h2>Files</h2>")
    L.append(table(["file", "what"], [[link(out, f), e(w)] for f, w in FILES if os.path.exists(os.path.join(out, f))]))
    L.append("</body></html>")
    path = os.path.join(out, "index.html")
    with open(path + ".part", "w", encoding="utf-8") as f:
        f.write("\n".join(L) + "\n")
    os.replace(path + ".part", path)
    return path


def main():
    if len(sys.argv) not in (2, 3) or sys.argv[1] in ("-h", "--help"):
        sys.stderr.write("usage: demo_index.py OUTDIR [VERSION]\n")
        return 2
    out = sys.argv[1]
    try:
        if not os.path.isdir(out):
            raise Bad(out, "not a directory")
        print(make(out, sys.argv[2] if len(sys.argv) == 3 else "?"))
    except Bad as b:
        sys.stderr.write(f"demo_index.py: {b.path}: {b.msg}\n")
        return 1
    except OSError as x:
        sys.stderr.write(f"demo_index.py: {x.filename or out}: {x.strerror or x}\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
