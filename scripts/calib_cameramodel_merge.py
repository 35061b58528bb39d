#!/usr/bin/python3
# scripts/calib_cameramodel_merge.py — one .cameramodel with both mrcal's
# optimization_inputs and refl's rig-frame extrinsics (calib/geometry/export.c runs it,
# through model_run_script, for refl calib geometry).
#
#   MRCAL_MODEL REFL_MODEL OUT
#       MRCAL_MODEL: what mrcal-calibrate-cameras wrote (intrinsics and the
#       optimization_inputs of the solve; extrinsics relative to its reference,
#       camera 0). REFL_MODEL: refl's model of the same camera (the same
#       intrinsics, extrinsics rt_cam_rig in mm, its comment lines). OUT gets
#       MRCAL_MODEL with REFL_MODEL's extrinsics and comments: mrcal's
#       documentation allows moving a camera (changing the extrinsics) without
#       invalidating the optimization_inputs, since projection_uncertainty and
#       the other tools take the solve-time poses from the optimization_inputs
#       (the reference frame there stays mrcal's: camera 0 of the solve).
#       Exit 1 with a message when the intrinsics of the two disagree.
import os
import sys

import mrcal
import numpy as np


def main(mrcal_path, refl_path, out):
    m = mrcal.cameramodel(mrcal_path)
    r = mrcal.cameramodel(refl_path)
    if m.optimization_inputs() is None:
        sys.exit(f"{mrcal_path}: has no optimization_inputs (not mrcal-calibrate-cameras' model)")
    lm, im = m.intrinsics()
    lr, ir = r.intrinsics()
    if lm != lr or im.shape != ir.shape or not np.allclose(im, ir, rtol=1e-9, atol=1e-9):
        sys.exit(f"{refl_path}: its intrinsics ({lr}) are not those of {mrcal_path} ({lm}): not the same solve")
    if tuple(m.imagersize()) != tuple(r.imagersize()):
        sys.exit(f"{refl_path}: imager size {r.imagersize()} is not {m.imagersize()} of {mrcal_path}")
    m.extrinsics_rt_fromref(r.extrinsics_rt_fromref())
    note = []
    with open(refl_path) as f:
        for line in f:
            if not line.startswith("#"):
                break
            note.append(line[1:].strip())
    note.append("optimization_inputs: mrcal-calibrate-cameras' solve, its reference frame its camera 0; the "
                "extrinsics above are refl's (moved as mrcal allows: the tools take the solve's poses from them)")
    tmp = out + ".part"
    m.write(tmp, note="\n".join(note))
    os.replace(tmp, out)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit("usage: calib_cameramodel_merge.py MRCAL_MODEL REFL_MODEL OUT")
    main(sys.argv[1], sys.argv[2], sys.argv[3])
