"""What the report scripts verify_report.py and verify_study_report.py share: the
input error, the readers of their CSV table and JSON object, and main's frame.

The scripts import it from their own directory (python puts the script's
directory on sys.path).
"""
import csv
import json
import os
import sys


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
