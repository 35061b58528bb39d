#!/usr/bin/python3
"""The page of `refl verify --study` (or --study-merge): figures and tables of the
summary that refl computed (scripts only plot).

usage: verify_study_report.py DIR

DIR/study.json (written by refl, fit/eval/study_files.c; format "refl-study", version 1,
a file without "format" and "version" being version 1): "units", "conditions", "design"
(cases, configurations, descriptions with their expected class: correct, wrong,
placed), "complete", and when complete "results": "summary" (one entry per
configuration and description other than the correct one: auc, threshold_1pct,
det_at_1pct_fa or flagged_at_1pct_fa, det_verdict or flagged_verdict, fa_verdict,
n, n_correct) and "roc" (false_alarm, detection, threshold lists per configuration
and description); "timing"; "provenance".

Writes DIR/roc.png, DIR/auc.png, DIR/placed.png and DIR/index.html.
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from report_common import Bad, e, load_json, provenance_head, run_report  # noqa: E402

PROG = "verify_study_report.py"
RULE = ("Detection at 1 % false alarms: per configuration, the threshold is the 99th percentile of the scores of "
        "the correct description, taken as the k-th smallest of its n scores with k = n \u2212 \u230an/100\u230b, "
        "so that at most 1 % of the correct cases score above it (when n < 100 it is their maximum); a wrong "
        "description counts as detected when its score > threshold. AUC (Mann\u2013Whitney): the probability "
        "that a description scores higher than the correct one on the part as placed, over all pairs of the same "
        "configuration, ties counting 1/2. Fixed verdict: a fit is flagged when refl's verdict says incorrect. "
        "All figures are computed by refl (study.json \u201cresults\u201d); this page only shows them.")


def load(d):
    doc = load_json(os.path.join(d, "study.json"))
    fmt, ver = doc.get("format", "refl-study"), doc.get("version", 1)
    if fmt != "refl-study":
        raise Bad(os.path.join(d, "study.json"), f"a {fmt} file, not refl-study")
    if not isinstance(ver, int) or isinstance(ver, bool) or not 1 <= ver <= 1:
        raise Bad(os.path.join(d, "study.json"), f"refl-study version {ver}: this script reads version 1")
    if not isinstance(doc.get("design"), dict):
        raise Bad(os.path.join(d, "study.json"), "no design: not a study of refl verify --study")
    if not doc.get("complete") or not isinstance(doc.get("results"), dict):
        raise Bad(os.path.join(d, "study.json"), "not complete (a shard?): merge the shards with "
                  "refl verify --study-merge DIR... -o OUT first")
    res = doc["results"]
    summ, roc = res.get("summary"), res.get("roc")
    if not isinstance(summ, list) or not isinstance(roc, list) or not summ:
        raise Bad(os.path.join(d, "study.json"), "results without a summary or ROC")
    for s in summ:
        for k in ("config", "description", "expected"):
            if not isinstance(s.get(k), str):
                raise Bad(os.path.join(d, "study.json"), f"a summary entry without {k}")
    configs = [c for c in doc["design"].get("configurations", []) if isinstance(c, str)]
    return doc, configs, summ, roc


def num(x):
    return x if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else math.nan


def colours(n):
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20")
    return [cmap(i % cmap.N) for i in range(n)]


def fig_roc(d, configs, corrs, summ, roc):
    n = len(configs)
    ncol = min(2, n)
    nrow = (n + ncol - 1) // ncol
    nneg = max([s.get("n_correct") or 0 for s in summ] or [1]) or 1
    xmin = min(1e-3, 10.0 ** math.floor(math.log10(0.5 / nneg)))
    col = dict(zip(corrs, colours(len(corrs))))
    # tab20 pairs a dark and a light shade of each hue: tell the pair apart by the line style too
    sty = {c: ("-", "--", "-.")[(i // 2) % 3] if len(corrs) > 10 else "-" for i, c in enumerate(corrs)}
    nleg = (len(corrs) + 3 + 5) // 6
    fig_h = 5.2 * nrow + 0.25 * nleg + 0.3
    fig, axs = plt.subplots(nrow, ncol, figsize=(7.2 * ncol, fig_h), squeeze=False)
    for k in range(nrow * ncol):
        ax = axs[k // ncol][k % ncol]
        if k >= n:
            ax.axis("off")
            continue
        cf = configs[k]
        x = np.logspace(math.log10(xmin), 0, 200)
        ax.plot(x, x, ":", color="0.5", lw=1, label="chance (diagonal)")
        ax.axvline(0.01, color="0.3", ls="--", lw=0.8)
        ax.text(0.0105, 0.02, "1 % false alarms", fontsize=7, color="0.3", rotation=90, va="bottom")
        any_ = False
        by = {(r.get("config"), r.get("description")): r for r in roc}
        for s in summ:
            r = by.get((cf, s["description"]))
            if s["config"] != cf or s["expected"] != "wrong" or r is None:
                continue
            fa = np.array([num(x) for x in r.get("false_alarm", [])], dtype=float)
            tp = np.array([num(x) for x in r.get("detection", [])], dtype=float)
            if len(fa) != len(tp) or not len(fa):
                continue
            c = col[s["description"]]
            ax.plot(np.maximum(fa, xmin), tp, sty[s["description"]], color=c, lw=1.4)
            ax.plot(max(num(s.get("fa_verdict")), xmin), num(s.get("det_verdict")), "o", color=c, ms=5, mec="k",
                    mew=0.6)
            any_ = True
        ax.set_xscale("log")
        ax.set_xlim(xmin / 1.4, 1.0)
        ax.set_ylim(-0.02, 1.02)
        n_neg = next((s.get("n_correct") or 0 for s in summ if s["config"] == cf), 0)
        ax.set_title(f"{cf}: {n_neg} correct cases" + ("" if any_ else " (no ROC: no correct cases)"), fontsize=10)
        ax.set_xlabel("false-alarm rate (correct description called wrong), log; 0 drawn at the left edge")
        ax.set_ylabel("detection rate (wrong description detected)")
        ax.grid(alpha=0.3, which="both")
    handles = [plt.Line2D([], [], ls=sty[c], color=col[c], lw=1.6, label=c) for c in corrs]
    handles += [plt.Line2D([], [], ls=":", color="0.5", label="chance (diagonal)"),
                plt.Line2D([], [], ls="--", color="0.3", lw=0.8, label="1 % false alarms"),
                plt.Line2D([], [], ls="", marker="o", color="0.7", mec="k", label="fixed verdict")]
    fig.tight_layout(rect=(0, (0.25 * nleg + 0.3) / fig_h, 1, 1))
    fig.legend(handles=handles, loc="lower center", ncol=min(6, len(handles)), fontsize=8, frameon=False)
    fig.savefig(os.path.join(d, "roc.png"), dpi=80)
    plt.close(fig)


def fig_auc(d, configs, corrs, summ):
    by = {(s["config"], s["description"]): num(s.get("auc")) for s in summ}
    nc = len(configs)
    w = 0.8 / nc
    x = np.arange(len(corrs))
    fig, ax = plt.subplots(figsize=(min(22.0, max(9.0, 0.3 * len(corrs) * nc + 2.5)), 5.4), layout="constrained")
    for i, (cf, c) in enumerate(zip(configs, colours(nc))):
        vals = np.array([by.get((cf, k), math.nan) for k in corrs], dtype=float)
        xs = x - 0.4 + w * (i + 0.5)
        ok = np.isfinite(vals)
        ax.bar(xs[ok], vals[ok], width=w * 0.95, color=c, label=cf)
        for xx, vv in zip(xs[ok], vals[ok]):
            ax.text(xx, min(vv, 1.0) - 0.01, f"{vv:.3f}", rotation=90, ha="center", va="top", fontsize=6,
                    color="white" if vv > 0.2 else "k")
    ax.axhline(0.5, color="0.3", ls=":", lw=1, label="chance (0.5)")
    ax.set_xticks(x)
    ax.set_xticklabels(corrs, rotation=35, ha="right")
    ax.set_ylim(0, 1.0)
    ax.set_ylabel("ROC AUC (1 = always scored above the correct description)")
    ax.set_xlabel("description (wrong ones; placed: the correct one, the part placed off)")
    ax.set_title("AUC of the score against the correct description, per description and configuration")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.savefig(os.path.join(d, "auc.png"), dpi=80)
    plt.close(fig)


CSS = ("body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}"
       "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
       "text-align:left;font-size:90%}th{background:#eee}td.n{text-align:right;font-variant-numeric:tabular-nums}"
       "td.l{white-space:nowrap}tr.first td{border-top:2px solid #888}figure{margin:1em 0}img{max-width:100%;"
       "border:1px solid #ddd}figcaption{font-size:90%;color:#555}code{font-size:90%}pre{background:#f6f6f6;"
       "border:1px solid #ddd;padding:0.6em;overflow-x:auto;font-size:85%;white-space:pre-wrap}.note{color:#555}")


def pct(x):
    x = num(x)
    return "n/a" if not math.isfinite(x) else f"{100 * x:.1f} %"


def f3(x):
    x = num(x)
    return "n/a" if not math.isfinite(x) else f"{x:.3f}"


def grid(configs, descs, by, cell):
    out = ["<table>", "<tr><th>description</th>" + "".join(f"<th>{e(cf)}</th>" for cf in configs) + "</tr>"]
    for c in descs:
        cells = [cell(by.get((cf, c))) if by.get((cf, c)) else "" for cf in configs]
        out.append(f'<tr><td class="l">{e(c)}</td>' + "".join(f'<td class="n">{x}</td>' for x in cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def fig_placed(d, configs, placed, by):
    fig, ax = plt.subplots(figsize=(9.0, 4.2), layout="constrained")
    nc = len(configs)
    w = 0.8 / max(nc, 1)
    x = np.arange(len(placed))
    for i, (cf, c) in enumerate(zip(configs, colours(nc))):
        vals = np.array([num(by[(cf, p)].get("flagged_verdict")) if (cf, p) in by else math.nan for p in placed])
        ok = np.isfinite(vals)
        ax.bar((x - 0.4 + w * (i + 0.5))[ok], 100 * vals[ok], width=w * 0.95, color=c, label=cf)
    ax.set_xticks(x)
    ax.set_xticklabels(placed)
    ax.set_ylim(0, 100)
    ax.set_ylabel("correct description flagged by the verdict (%)")
    ax.set_xlabel("the part placed off (shift, turn)")
    ax.set_title("Placed-off parts called wrong (within the registration's tolerance they should pass)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.savefig(os.path.join(d, "placed.png"), dpi=80)
    plt.close(fig)


def write_html(d, doc, configs, summ):
    title = "refl verify --study"
    L = [f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{e(title)}: '
         f'{e(os.path.basename(os.path.abspath(d)))}</title>\n<style>{CSS}</style>\n</head><body>\n<h1>{e(title)}</h1>']
    head = provenance_head(doc.get("provenance"))
    if head:
        L.append(head)
    des = doc["design"]
    L.append('<h2 id="conditions">Conditions</h2>')
    L.append(f"<pre>{e(str(doc.get('conditions', '')))}</pre>")
    L.append(f"<p>Calibrations: {e(str(des.get('calibrations')))}; priors: {e(str(des.get('priors')))}; "
             f"{des.get('cases')} cases (a case number names the same drifts and noise under every description); "
             f"units: {e(str(doc.get('units', '')))}.</p>")
    wrong = []
    placed = []
    for s in summ:
        lst = placed if s["expected"] == "placed" else wrong
        if s["description"] not in lst:
            lst.append(s["description"])
    by = {(s["config"], s["description"]): s for s in summ}
    L.append('<h2 id="summary">Wrong descriptions</h2>')
    L.append("<p>AUC (and in brackets the detection rate at 1 % false alarms) per description and configuration:</p>")
    L.append(grid(configs, wrong, by, lambda s: f"{f3(s.get('auc'))} ({pct(s.get('det_at_1pct_fa'))})"))
    L.append('<h2 id="placed">The correct description, the part placed off</h2>')
    L.append("<p>AUC against the part as placed (0.5: placement makes no difference to the score), and the share "
             "called wrong at the 1 % threshold / by the verdict:</p>")
    L.append(grid(configs, placed, by, lambda s: f"{f3(s.get('auc'))} ({pct(s.get('flagged_at_1pct_fa'))} / "
                                                  f"{pct(s.get('flagged_verdict'))})"))
    zc = (doc.get("results") or {}).get("z_calibration") or []
    if zc:
        L.append('<h2 id="zcal">The stated sigma, checked</h2>')
        L.append("<p>Over the cases, each fit's RMS z and median |z| at its used reference points, z = (measured "
                 "&minus; model)/&sigma;: 1 and 0.674 when the stated &sigma; is right (smaller: &sigma; too large, "
                 "larger: too small).</p>")
        rows = ["<table>", "<tr><th>config</th><th>description</th><th>cases</th><th>RMS z (mean)</th>"
                "<th>range</th><th>median |z| (mean)</th><th>range</th></tr>"]
        for z in zc:
            rr, mr = z.get("rms_z_range") or [math.nan] * 2, z.get("median_abs_z_range") or [math.nan] * 2
            rows.append(f'<tr><td class="l">{e(z.get("config"))}</td><td class="l">{e(z.get("description"))}</td>'
                        f'<td class="n">{z.get("n")}</td><td class="n">{f3(z.get("rms_z_mean"))}</td>'
                        f'<td class="n">{f3(rr[0])}..{f3(rr[1])}</td><td class="n">{f3(z.get("median_abs_z_mean"))}</td>'
                        f'<td class="n">{f3(mr[0])}..{f3(mr[1])}</td></tr>')
        rows.append("</table>")
        L.append("\n".join(rows))
    L.append("<h2 id=\"all\">All figures</h2>")
    hdr = ["config", "description", "expected", "correct cases", "cases", "AUC", "above the 1 % threshold",
           "threshold (score)", "flagged by the verdict", "false alarms of the verdict"]
    out = ["<table>", "<tr>" + "".join(f"<th>{e(h)}</th>" for h in hdr) + "</tr>"]
    last = None
    for s in summ:
        cls = ' class="first"' if last is not None and s["config"] != last else ""
        last = s["config"]
        above = s.get("det_at_1pct_fa", s.get("flagged_at_1pct_fa"))
        flag = s.get("det_verdict", s.get("flagged_verdict"))
        cells = [e(s["config"]), e(s["description"]), e(s["expected"])]
        nums = [str(s.get("n_correct")), str(s.get("n")), f3(s.get("auc")), pct(above),
                "n/a" if not math.isfinite(num(s.get("threshold_1pct"))) else f"{num(s['threshold_1pct']):.4g}",
                pct(flag), pct(s.get("fa_verdict"))]
        out.append(f"<tr{cls}>" + "".join(f'<td class="l">{c}</td>' for c in cells)
                   + "".join(f'<td class="n">{c}</td>' for c in nums) + "</tr>")
    out.append("</table>")
    L.append("\n".join(out))
    L.append(f'<p class="note">{e(RULE)} The fixed verdict calls a description incorrect when its score &gt; '
             f'{num(des.get("score_threshold")):g}.</p>')
    if isinstance(des.get("cases"), int) and des["cases"] < 100:
        L.append('<p class="note">Fewer than 100 cases: the 1 % threshold is the largest score of the correct '
                 "description, so the false-alarm rate it stands for is 0 of those cases, not 1 %.</p>")
    t = doc.get("timing") or {}
    L.append('<h2 id="runtime">Run time</h2>')
    L.append(f"<p>{t.get('fits')} fits, {num(t.get('fit_seconds_sum')):.0f} s of fitting summed over the threads "
             f"(mean {num(t.get('mean_iterations')):.1f} solver iterations a fit); per fit: timing.csv.</p>")
    L.append('<h2 id="figures">Figures</h2>')
    L.append('<figure><img src="roc.png" alt="ROC curves per configuration"><figcaption>ROC curves of the wrong '
             "descriptions, one panel per configuration: the detection rate against the false-alarm rate (the "
             "correct description's fits above the threshold) as the threshold falls; log false-alarm axis (0 at "
             "the left edge); dotted: chance; dashed: 1 % false alarms; dots: the fixed verdict.</figcaption></figure>")
    L.append('<figure><img src="auc.png" alt="AUC per description"><figcaption>ROC AUC per description (wrong ones '
             "and the placed-off part), one bar per configuration (0.5, dotted: no better than chance)."
             "</figcaption></figure>")
    if placed:
        L.append('<figure><img src="placed.png" alt="placed-off parts flagged"><figcaption>The correct description '
                 "of a part placed off by the amounts shown: the share of cases the verdict calls wrong."
                 "</figcaption></figure>")
    L.append('<h2 id="design">Design and provenance</h2>')
    L.append(f"<pre>{e(json.dumps({'design': des, 'provenance': doc.get('provenance')}, indent=2, ensure_ascii=False))}</pre>")
    L.append("</body></html>\n")
    out_path = os.path.join(d, "index.html")
    tmp = out_path + ".part"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write("\n".join(L))
    os.replace(tmp, out_path)
    return out_path


def report(d):
    doc, configs, summ, roc = load(d)
    descs = []
    for s in summ:
        if s["description"] not in descs:
            descs.append(s["description"])
    wrong = [c for c in descs if any(s["description"] == c and s["expected"] == "wrong" for s in summ)]
    placed = [c for c in descs if c not in wrong]
    fig_roc(d, configs, wrong, summ, roc)
    fig_auc(d, configs, descs, summ)
    if placed:
        fig_placed(d, configs, placed, {(s["config"], s["description"]): s for s in summ})
    return write_html(d, doc, configs, summ)


def main():
    return run_report(PROG, __doc__, report)


if __name__ == "__main__":
    sys.exit(main())
