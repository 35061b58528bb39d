#!/usr/bin/python3
"""scripts/session_figure.py SESSION_DIR OUT.png — contact sheet of a capture session.

Reads the session's journal (session.sqlite: the frames table written by
`refl capture`) and its 16-bit PNG frames, and draws every frame with its
turntable angle, lamps and exposure. Grey values are the camera's DN (for the
virtual rig's Mono12: 0..4095). Draws only: no numbers are computed here that
refl does not already journal.
"""
import os
import sqlite3
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: session_figure.py SESSION_DIR OUT.png")
    sdir, out = sys.argv[1], sys.argv[2]
    db = sqlite3.connect("file:%s?mode=ro" % os.path.join(sdir, "session.sqlite"), uri=True)
    sample, plan = db.execute("select sample, plan_path from session").fetchone()
    rows = db.execute("select step, file, measured_deg, lamps, exposure_us, pixel_format, mean, max "
                      "from frames order by step").fetchall()
    if not rows:
        sys.exit("session_figure.py: %s has no frames" % sdir)
    ncol = 4
    nrow = (len(rows) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.4 * nrow), squeeze=False,
                             constrained_layout=True)
    vmax = max(r[7] for r in rows)
    im = None
    for ax, (step, f, ang, lamps, exp_us, fmt, mean, mx) in zip(axes.flat, rows):
        pix = np.asarray(Image.open(os.path.join(sdir, f)))
        im = ax.imshow(pix, cmap="gray", vmin=0, vmax=vmax)
        ax.set_title("step %d: %.1f deg, lamps %s\n%g us, %s, mean %.0f DN" %
                     (step, round(ang, 1) + 0.0, lamps or "none", exp_us, fmt, mean), fontsize=9)   # no "-0.0"
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[len(rows):]:
        ax.axis("off")
    fig.suptitle("refl capture session: sample %s, plan %s — frames in DN (camera pixel format)"
                 % (sample, os.path.basename(plan or "?")))
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.6, label="grey value (DN)")
    fig.savefig(out, dpi=80)


if __name__ == "__main__":
    main()
