"""What the report scripts verify_report.py, plan_lamps_report.py and verify_study_report.py share: the
input error, the readers of their CSV table, JSON object and float TIFF, the HTML helpers of their pages
(escape, number format, tables, the provenance lines, the page's atomic write) and main's frame.

The scripts import it from their own directory (python puts the script's
directory on sys.path).
"""
import csv
import html
import json
import math
import os
import sys

import numpy as np
from PIL import Image


class Bad(Exception):
    """An input problem: path and message, printed as 'PROG: path: message' (PROG: the script's name)."""

    def __init__(self, path, msg):
        super().__init__(msg)
        self.path, self.msg = path, msg


def read_table(path, columns):
    """The rows of the UTF-8 CSV file at path as (line number, {column: stripped value}) for the names in
    columns, which the header must have (in any order, among others); blank lines are skipped, every other
    line must have as many fields as the header. Any problem, reading included, is a Bad naming path."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rd = csv.reader(f)
            header = next(rd, None)
            if header is None:
                raise Bad(path, "empty file (expected the header " + ",".join(columns) + ")")
            header = [h.strip() for h in header]
            missing = [k for k in columns if k not in header]
            if missing:
                raise Bad(path, "header lacks " + ", ".join(missing) + " (expected " + ",".join(columns) + ")")
            pos = {k: header.index(k) for k in columns}
            for row in rd:
                line = rd.line_num
                if not row or all(not x.strip() for x in row):
                    continue
                if len(row) != len(header):
                    raise Bad(path, f"line {line}: {len(row)} fields, the header has {len(header)}")
                yield line, {k: row[pos[k]].strip() for k in columns}
    except OSError as e:
        raise Bad(path, f"cannot read: {e.strerror or e}")
    except UnicodeDecodeError as e:
        raise Bad(path, f"not UTF-8 text: {e}")
    except csv.Error as e:
        raise Bad(path, f"not valid CSV: {e}")


def load_json(path):
    """The JSON object in the file at path; anything else is a Bad naming path."""
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except OSError as e:
        raise Bad(path, f"cannot read: {e.strerror or e}")
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise Bad(path, f"not valid JSON: {e}")
    if not isinstance(doc, dict):
        raise Bad(path, "expected a JSON object at the top")
    return doc


# The formats refl writes and the newest version of each these pages read
# (the C readers' own limits: calib/gain/gain.h, fit/priors.h, ...).
FORMATS = {
    "refl-geometry": 1, "refl-lamps": 1, "refl-gain": 3, "refl-white": 1, "refl-priors": 1,
    "refl-verify": 1, "refl-chain": 1, "refl-lightplan": 1, "refl-study": 1,
}
# a version-1 priors file may name itself so
FORMAT_ALIASES = {"refl priors 1": ("refl-priors", 1)}


def check_format(doc, path, fmt):
    """The version of the refl file doc (parsed from path) of format fmt: a file naming no format is version 1;
    another format, or a version newer than this refl reads (FORMATS), is a Bad naming path and both."""
    name = doc.get("format")
    if name in FORMAT_ALIASES and FORMAT_ALIASES[name][0] == fmt:
        return FORMAT_ALIASES[name][1]
    if name is None and "version" not in doc:
        return 1
    if name != fmt:
        raise Bad(path, f"a {name} file, not {fmt}")
    v = doc.get("version")
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise Bad(path, f"{fmt}: \"version\" is not a whole number >= 1")
    if v > FORMATS[fmt]:
        raise Bad(path, f"{fmt} version {v}, written by a newer refl (this refl reads versions 1 to {FORMATS[fmt]})")
    return v


def is_num(v):
    """A JSON number: int or float, not bool."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def read_float_tiff(path, why, empty_ok=False):
    """The first page of the TIFF at path as a 2-D float32 array and its ImageDescription ("" without one).
    A missing file is a Bad 'missing (why)'; an unreadable one, one not a single grey channel or (unless
    empty_ok) one without pixels, a Bad naming path."""
    try:
        with Image.open(path) as im:
            im.seek(0)
            a = np.array(im, dtype=np.float32)
            desc = getattr(im, "tag_v2", {}).get(270)   # ImageDescription
    except FileNotFoundError:
        raise Bad(path, f"missing ({why})")
    except (OSError, ValueError) as x:
        raise Bad(path, f"cannot read as a TIFF: {x}")
    if a.ndim != 2 or not (a.size or empty_ok):
        raise Bad(path, f"expected one grey channel, got an array of shape {a.shape}")
    return a, desc if isinstance(desc, str) else ""


# ---------------------------------------------------------------------------
# the page

def e(s):
    """s as HTML text (quotes escaped too)."""
    return html.escape(str(s), quote=True)


def fmt(x, spec=".4g", none="n/a"):
    """x formatted by spec; none for None, NaN and the infinities; a negative zero ("-0.00") without its sign."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return none
    t = format(x, spec)
    return t[1:] if t.startswith("-") and not any(c in "123456789" for c in t.split("e")[0]) else t


def table(header, rows, classes=None, numeric=None):
    """An HTML table. header: plain text (escaped here); rows: lists of HTML cell contents; classes: per row;
    numeric: per column, True for a number (right-aligned, class "n"), a string for that class (e.g. "l":
    text kept on one line), false for none."""
    def td(j, c):
        k = numeric[j] if numeric else False
        return f'<td class="{"n" if k is True else k}">{c}</td>' if k else f"<td>{c}</td>"

    out = ["<table>", "<tr>" + "".join(f"<th>{e(h)}</th>" for h in header) + "</tr>"]
    for i, r in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes and classes[i] else ""
        out.append(f"<tr{cls}>" + "".join(td(j, c) for j, c in enumerate(r)) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def dict_table(o):
    """A key | value table of the JSON object o (strings as they are, other values as JSON)."""
    return table(["key", "value"], [[e(k), e(v if isinstance(v, str) else json.dumps(v))] for k, v in o.items()])


def provenance_head(prov):
    """The line under the title: refl's version and the date, and the command, from the JSON provenance
    prov; None when prov is not an object with a "command" string."""
    if not (isinstance(prov, dict) and isinstance(prov.get("command"), str)):
        return None
    head = ", ".join(e(x) for x in (("refl " + str(prov["refl_version"])) if prov.get("refl_version") else "",
                                     str(prov.get("date_utc") or "")) if x)
    return f"<p>{head + '<br>' if head else ''}<code>{e(prov['command'])}</code></p>"


def provenance_section(prov, name):
    """The page's Provenance section: prov (JSON) as indented JSON, folded (a click opens it), or a sentence
    that the file name has none when prov is None."""
    if prov is None:
        body = f"<p>{e(name)} has no provenance.</p>"
    else:
        n = len(prov.get("inputs") or []) if isinstance(prov, dict) else 0
        body = (f"<details><summary>the command, refl's version and date, and {n} inputs with their sha256 "
                f"(from {e(name)})</summary><pre style=\"white-space: pre-wrap; overflow-wrap: anywhere\">"
                f"{e(json.dumps(prov, indent=2, ensure_ascii=False))}</pre></details>")
    return '<h2 id="provenance">Provenance</h2>\n' + body


def check_headline(rows, prefix):
    """The headline item of the light plan's virtual-rig check: rows (turntable_deg, agreement, target) of the
    views it judged (agreement and target 0..1); each view below its target in words, by how many points, as a
    miss. None without rows."""
    if not rows:
        return None
    miss = [(a, ag, tg) for a, ag, tg in rows if ag < tg]
    tg0 = rows[0][2]
    if miss:
        return (f"!{prefix}: {len(rows) - len(miss)} of {len(rows)} views reach the target {100 * tg0:.0f} % of "
                "segments detected as predicted; "
                + "; ".join(f"{fmt(a, 'g')}°: {100 * ag:.1f} %, {100 * (tg - ag):.1f} points short" for a, ag, tg in miss))
    return (f"{prefix}: every view reaches the target {100 * tg0:.0f} % ("
            + ", ".join(f"{fmt(a, 'g')}°: {100 * ag:.1f} %" for a, ag, _ in rows) + ")")


def headline(items, title="Headline"):
    """The box a page opens with: one line per item (HTML already escaped by the caller); an item that begins
    with "!" is a miss (what missed its target and by how much), drawn in red without the "!". The same look
    as the C reports' (model_html_headline)."""
    li = []
    for it in items:
        if not it:
            continue
        miss = it.startswith("!")
        li.append(('<li style="color:#b00020;font-weight:bold">' if miss else "<li>") + (it[1:] if miss else it)
                  + "</li>")
    return ('<div class="headline" id="headline" style="border:2px solid #888;border-radius:6px;padding:0.4em 1em;'
            f'margin:0.8em 0;background:#fafafa"><h2 style="margin:0.2em 0 0.4em 0">{e(title)}</h2><ul '
            'style="margin:0.2em 0;padding-left:1.3em">' + "\n".join(li) + "</ul></div>")


def write_page(d, lines):
    """Writes the lines, joined by newlines, to DIR/index.html by way of index.html.part (replaced
    atomically); returns the page's path."""
    out = os.path.join(d, "index.html")
    tmp = out + ".part"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
    os.replace(tmp, out)
    return out


# ---------------------------------------------------------------------------
# main

def run_report(prog, usage, make):
    """A report script's main, `prog DIR`: make(DIR) writes the report and returns the page's path, printed
    on stdout (exit status 0). Other arguments: usage on stderr, 2. A Bad or an OSError: 'prog: path:
    message' on stderr, 1."""
    if len(sys.argv) != 2 or sys.argv[1] in ("-h", "--help"):
        sys.stderr.write(usage)
        return 2
    d = sys.argv[1]
    try:
        if not os.path.isdir(d):
            raise Bad(d, "not a directory")
        out = make(d)
    except Bad as b:
        sys.stderr.write(f"{prog}: {b.path}: {b.msg}\n")
        return 1
    except OSError as x:
        sys.stderr.write(f"{prog}: {x.filename or d}: {x.strerror or x}\n")
        return 1
    print(out)
    return 0
