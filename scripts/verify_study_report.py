#!/usr/bin/python3
"""Summary of `refl verify --study`: how well the score tells wrong descriptions
from the correct one, per fitter configuration and corruption.

usage: verify_study_report.py DIR

DIR/study.csv: config,corruption,case,score,verdict_correct,seconds (one row per
fit; config and corruption are labels, kept in the order they first appear;
corruption "none" is the correct description; rows of the same case share the
images; score >= 0, higher = more likely wrong; verdict_correct 0/1).
DIR/study.json: {"conditions": text, ...}; a "summary" list is added, other keys
are kept.

For each config and each corruption other than "none" (positives: its rows;
negatives: the "none" rows of the same config):
  auc             P(score of a wrong description > score of a correct one), ties 1/2
                  (Mann-Whitney U / (n_pos n_neg))
  threshold_1pct  the 99th percentile of the negatives' scores, as the k-th
                  smallest of n with k = n - floor(n/100): at most 1 % of the
                  negatives lie above it (none when n < 100)
  det_at_1pct_fa  share of positives with score > threshold_1pct
  det_verdict     share of positives with verdict_correct == 0 (flagged)
  fa_verdict      share of negatives with verdict_correct == 0
Rates are fractions in summary.csv and study.json, percent in the page.

Writes DIR/summary.csv, DIR/roc.png, DIR/auc.png, DIR/index.html and rewrites
DIR/study.json (atomically).
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from report_common import Bad, e, load_json, provenance_head, read_table, run_report  # noqa: E402

PROG = "verify_study_report.py"
COLUMNS = ["config", "corruption", "case", "score", "verdict_correct", "seconds"]
SUMMARY = ["config", "corruption", "n_neg", "n_pos", "auc", "det_at_1pct_fa", "threshold_1pct", "det_verdict",
           "fa_verdict"]
NONE = "none"
RULE = ("Detection at 1 % false alarms: per configuration, the threshold is the 99th percentile of the scores of "
        "the correct description (corruption \u201cnone\u201d), taken as the k-th smallest of its n scores with "
        "k = n \u2212 \u230an/100\u230b, so that at most 1 % of the correct cases score above it (none when "
        "n < 100: the threshold is then their maximum); a wrong description counts as detected when its "
        "score > threshold. AUC (Mann\u2013Whitney): the probability that a wrong description of the corruption "
        "scores higher than the correct one, over all pairs of the same configuration, ties counting 1/2. Fixed "
        "verdict: a fit is flagged when refl's verdict says incorrect (verdict_correct = 0); detection = share of "
        "the wrong descriptions flagged, false alarms = share of the correct ones flagged.")


# ---------------------------------------------------------------------------
# inputs

def load_csv(path):
    rows = []
    seen = {}
    for line, t in read_table(path, COLUMNS):
        if not t["config"]:
            raise Bad(path, f"line {line}: empty config")
        if not t["corruption"]:
            raise Bad(path, f"line {line}: empty corruption")
        try:
            case = int(t["case"])
        except ValueError:
            raise Bad(path, f"line {line}: case {t['case']!r} is not an integer")
        vals = {}
        for k in ("score", "seconds"):
            try:
                vals[k] = float(t[k])
            except ValueError:
                raise Bad(path, f"line {line}: {k} {t[k]!r} is not a number")
            if not (math.isfinite(vals[k]) and vals[k] >= 0):
                raise Bad(path, f"line {line}: {k} {t[k]!r} is not a finite number >= 0")
        if t["verdict_correct"] not in ("0", "1"):
            raise Bad(path, f"line {line}: verdict_correct {t['verdict_correct']!r} is not 0 or 1")
        key = (t["config"], t["corruption"], case)
        if key in seen:
            raise Bad(path, f"line {line}: config {key[0]!r}, corruption {key[1]!r}, case {case} "
                      f"already on line {seen[key]}")
        seen[key] = line
        rows.append({"config": t["config"], "corruption": t["corruption"], "case": case,
                     "score": vals["score"], "flagged": t["verdict_correct"] == "0",
                     "seconds": vals["seconds"]})
    if not rows:
        raise Bad(path, "no data rows")
    if not any(r["corruption"] == NONE for r in rows):
        raise Bad(path, f"no row with corruption \"{NONE}\" (the correct description): nothing to compare with")
    if all(r["corruption"] == NONE for r in rows):
        raise Bad(path, "only rows with corruption \"none\": no wrong description to detect")
    return rows


def ordered(values):
    out = []
    for v in values:
        if v not in out:
            out.append(v)
    return out


# ---------------------------------------------------------------------------
# statistics

def auc_mw(neg, pos):
    """Mann-Whitney AUC: P(pos > neg) + P(pos == neg)/2."""
    ns = np.sort(neg)
    less = np.searchsorted(ns, pos, side="left")
    leq = np.searchsorted(ns, pos, side="right")
    return float(np.sum(less + 0.5 * (leq - less))) / (len(pos) * len(neg))


def threshold_1pct(neg):
    ns = np.sort(neg)
    n = len(ns)
    return float(ns[n - 1 - n // 100])


def roc_points(neg, pos):
    """False-alarm and detection rates of the rule score >= t, t over every distinct score (descending),
    from (0, 0) to (1, 1)."""
    ts = np.unique(np.concatenate([neg, pos]))[::-1]
    ns, ps = np.sort(neg), np.sort(pos)
    fa = (len(ns) - np.searchsorted(ns, ts, side="left")) / len(ns)
    tp = (len(ps) - np.searchsorted(ps, ts, side="left")) / len(ps)
    return np.concatenate([[0.0], fa]), np.concatenate([[0.0], tp])


def summarise(rows):
    configs = ordered(r["config"] for r in rows)
    corrs = [c for c in ordered(r["corruption"] for r in rows) if c != NONE]
    out = []
    for cf in configs:
        sel = [r for r in rows if r["config"] == cf]
        neg = np.array([r["score"] for r in sel if r["corruption"] == NONE])
        negf = np.array([r["flagged"] for r in sel if r["corruption"] == NONE], dtype=bool)
        thr = threshold_1pct(neg) if len(neg) else math.nan
        for c in corrs:
            pos = np.array([r["score"] for r in sel if r["corruption"] == c])
            posf = np.array([r["flagged"] for r in sel if r["corruption"] == c], dtype=bool)
            if not len(pos):
                continue
            s = {"config": cf, "corruption": c, "n_neg": int(len(neg)), "n_pos": int(len(pos)),
                 "auc": auc_mw(neg, pos) if len(neg) else math.nan,
                 "det_at_1pct_fa": float(np.mean(pos > thr)) if len(neg) else math.nan,
                 "threshold_1pct": thr,
                 "det_verdict": float(np.mean(posf)),
                 "fa_verdict": float(np.mean(negf)) if len(neg) else math.nan,
                 "_neg": neg, "_pos": pos}
            out.append(s)
    return configs, corrs, out


# ---------------------------------------------------------------------------
# output

def atomic_write(path, text):
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
        os.replace(tmp, path)
    except OSError as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise Bad(path, f"cannot write: {e.strerror or e}")


def jnum(x):
    return None if isinstance(x, float) and not math.isfinite(x) else x


def write_summary_csv(d, summ):
    lines = [",".join(SUMMARY)]
    for s in summ:
        cells = []
        for k in SUMMARY:
            v = s[k]
            if isinstance(v, str):
                cells.append(csv_cell(v))
            elif isinstance(v, int):
                cells.append(str(v))
            else:
                cells.append("nan" if not math.isfinite(v) else f"{v:.6g}")
        lines.append(",".join(cells))
    atomic_write(os.path.join(d, "summary.csv"), "\n".join(lines) + "\n")


def csv_cell(s):
    if any(ch in s for ch in ',"\n\r') or s != s.strip():
        return '"' + s.replace('"', '""') + '"'
    return s


def colours(n):
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20")
    return [cmap(i % cmap.N) for i in range(n)]


def fig_roc(d, configs, corrs, summ):
    n = len(configs)
    ncol = min(2, n)
    nrow = (n + ncol - 1) // ncol
    nneg = max([s["n_neg"] for s in summ if s["n_neg"]] or [1])
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
        for s in summ:
            if s["config"] != cf or not s["n_neg"]:
                continue
            fa, tp = roc_points(s["_neg"], s["_pos"])
            c = col[s["corruption"]]
            ax.plot(np.maximum(fa, xmin), tp, sty[s["corruption"]], color=c, lw=1.4)
            ax.plot(max(s["fa_verdict"], xmin), s["det_verdict"], "o", color=c, ms=5, mec="k", mew=0.6)
            any_ = True
        ax.set_xscale("log")
        ax.set_xlim(xmin / 1.4, 1.0)
        ax.set_ylim(-0.02, 1.02)
        n_neg = next((s["n_neg"] for s in summ if s["config"] == cf), 0)
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
    by = {(s["config"], s["corruption"]): s["auc"] for s in summ}
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
    ax.set_xlabel("corruption of the description")
    ax.set_title("AUC of the score per corruption and configuration")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.savefig(os.path.join(d, "auc.png"), dpi=80)
    plt.close(fig)


CSS = ("body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}"
       "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
       "text-align:left;font-size:90%}th{background:#eee}td.n{text-align:right;font-variant-numeric:tabular-nums}"
       "td.l{white-space:nowrap}tr.first td{border-top:2px solid #888}figure{margin:1em 0}img{max-width:100%;border:1px solid #ddd}"
       "figcaption{font-size:90%;color:#555}code{font-size:90%}pre{background:#f6f6f6;border:1px solid #ddd;"
       "padding:0.6em;overflow-x:auto;font-size:85%;white-space:pre-wrap}.note{color:#555}")


def pct(x):
    return "n/a" if not math.isfinite(x) else f"{100 * x:.1f} %"


def write_html(d, doc, rows, configs, corrs, summ):
    title = "refl verify --study"
    L = [f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{e(title)}: {e(os.path.basename(os.path.abspath(d)))}'
         f"</title>\n<style>{CSS}</style>\n</head><body>\n<h1>{e(title)}</h1>"]
    head = provenance_head(doc.get("provenance"))
    if head:
        L.append(head)
    L.append('<h2 id="conditions">Conditions</h2>')
    cond = doc.get("conditions")
    if isinstance(cond, str):
        L.append(f"<pre>{e(cond)}</pre>")
    elif cond is None:
        L.append("<p>study.json names no conditions.</p>")
    else:
        L.append(f"<pre>{e(json.dumps(cond, indent=2, ensure_ascii=False))}</pre>")
    ncase = len(ordered(r["case"] for r in rows))
    L.append(f"<p>{len(rows)} fits: {len(configs)} configurations &times; {len(corrs)} corruptions and the "
             f"correct description, {ncase} cases (a case number names the same images: noise, lamp and gain "
             "drift).</p>")

    L.append('<h2 id="summary">Summary</h2>')
    by = {(s["config"], s["corruption"]): s for s in summ}
    out = ["<table>", "<tr><th>corruption</th>" + "".join(f"<th>{e(cf)}</th>" for cf in configs) + "</tr>"]
    for c in corrs:
        cells = []
        for cf in configs:
            s = by.get((cf, c))
            cells.append("" if s is None or not math.isfinite(s["auc"]) else
                         f"{s['auc']:.3f} ({pct(s['det_at_1pct_fa'])})")
        out.append(f'<tr><td class="l">{e(c)}</td>' + "".join(f'<td class="n">{x}</td>' for x in cells) + "</tr>")
    out.append("</table>")
    L.append("<p>AUC (and in brackets the detection rate at 1 % false alarms) per corruption and configuration:</p>")
    L.append("\n".join(out))
    L.append("<p>All figures:</p>")
    hdr = ["config", "corruption", "correct cases", "wrong cases", "AUC", "detected at 1 % false alarms",
           "threshold (score)", "detected by the verdict", "false alarms of the verdict"]
    out = ["<table>", "<tr>" + "".join(f"<th>{e(h)}</th>" for h in hdr) + "</tr>"]
    last = None
    for s in summ:
        cls = ' class="first"' if last is not None and s["config"] != last else ""
        last = s["config"]
        cells = [e(s["config"]), e(s["corruption"])]
        num = [str(s["n_neg"]), str(s["n_pos"]), "n/a" if not math.isfinite(s["auc"]) else f"{s['auc']:.3f}",
               pct(s["det_at_1pct_fa"]),
               "n/a" if not math.isfinite(s["threshold_1pct"]) else f"{s['threshold_1pct']:.4g}",
               pct(s["det_verdict"]), pct(s["fa_verdict"])]
        out.append(f"<tr{cls}>" + "".join(f'<td class="l">{c}</td>' for c in cells)
                   + "".join(f'<td class="n">{c}</td>' for c in num) + "</tr>")
    out.append("</table>")
    L.append("\n".join(out))
    L.append(f'<p class="note">{e(RULE)} The cases are paired (the same images under every corruption) but the '
             "rates here do not use the pairing. Machine-readable: <a href=\"summary.csv\">summary.csv</a> "
             "(rates as fractions), and the \u201csummary\u201d list of study.json.</p>")
    if isinstance(doc.get("score_threshold"), (int, float)) and not isinstance(doc.get("score_threshold"), bool):
        L.append(f'<p class="note">The fixed verdict calls a description incorrect when its score &gt; '
                 f'{doc["score_threshold"]:g} (score_threshold of study.json).</p>')
    small = [cf for cf in configs if 0 < sum(1 for r in rows if r["config"] == cf and r["corruption"] == NONE) < 100]
    if small:
        L.append(f'<p class="note">Fewer than 100 correct cases for {e(", ".join(small))}: the 1 % threshold is '
                 "the largest score of the correct description there, so the false-alarm rate it stands for is "
                 "0 of those cases, not 1 %.</p>")
    noneg = [cf for cf in configs if not any(r["config"] == cf and r["corruption"] == NONE for r in rows)]
    if noneg:
        L.append(f'<p class="note">No correct-description rows for {e(", ".join(noneg))}: AUC, threshold and '
                 "false alarms are n/a there.</p>")

    L.append('<h2 id="runtime">Run time</h2>')
    rt = []
    for cf in configs:
        sec = np.array([r["seconds"] for r in rows if r["config"] == cf])
        rt.append(f'<tr><td>{e(cf)}</td><td class="n">{len(sec)}</td><td class="n">{np.median(sec):.3g}</td>'
                  f'<td class="n">{np.mean(sec):.3g}</td><td class="n">{np.max(sec):.3g}</td></tr>')
    L.append("<table><tr><th>config</th><th>fits</th><th>median (s)</th><th>mean (s)</th><th>max (s)</th></tr>"
             + "".join(rt) + "</table>")

    L.append('<h2 id="figures">Figures</h2>')
    L.append('<figure><img src="roc.png" alt="ROC curves per configuration"><figcaption>ROC curves, one panel per '
             "configuration and one curve per corruption: the detection rate (share of the wrong descriptions "
             "whose score reaches a threshold) against the false-alarm rate (share of the correct description's "
             "fits that reach it) as the threshold falls; log false-alarm axis (a rate of 0 is drawn at the left "
             "edge); dotted: chance; dashed: 1 % false alarms; dots: the fixed verdict of refl verify (its false-alarm "
             "and detection rates). The AUCs are in the table and the next figure.</figcaption></figure>")
    L.append('<figure><img src="auc.png" alt="AUC per corruption"><figcaption>ROC AUC of the score per corruption, '
             "one bar per configuration (1: every wrong description scored above every correct one; 0.5, dotted: "
             "no better than chance).</figcaption></figure>")
    other = {k: v for k, v in doc.items() if k not in ("summary", "conditions")}
    if other:
        L.append('<h2 id="study-json">study.json</h2>')
        L.append(f"<pre>{e(json.dumps(other, indent=2, ensure_ascii=False))}</pre>")
    L.append("</body></html>\n")
    out_path = os.path.join(d, "index.html")
    atomic_write(out_path, "\n".join(L))
    return out_path


def report(d):
    rows = load_csv(os.path.join(d, "study.csv"))
    jpath = os.path.join(d, "study.json")
    doc = load_json(jpath)
    configs, corrs, summ = summarise(rows)
    fig_roc(d, configs, corrs, summ)
    fig_auc(d, configs, corrs, summ)
    write_summary_csv(d, summ)
    doc["summary"] = [{k: jnum(s[k]) for k in SUMMARY} for s in summ]
    atomic_write(jpath, json.dumps(doc, indent=2, ensure_ascii=False, allow_nan=False) + "\n")
    return write_html(d, doc, rows, configs, corrs, summ)


def main():
    return run_report(PROG, __doc__, report)


if __name__ == "__main__":
    sys.exit(main())
