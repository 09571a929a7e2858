#!/usr/bin/python3
"""The pelvis trajectory of an edit stage's motions, beside another's (issue 15: where plausibility is lost).

The 207-d editing feature stores the pelvis as a velocity (REFERENCE.md section 2), so its height is
integrated when a generated motion is decoded: an edit whose height drifts floats above or sinks
into the floor, and its feet slide. Per motion: |z(end) - z(0)|, the standard deviation of z, the
mean vertical speed and the mean horizontal acceleration of the pelvis, and how much of the height
change the pelvis's tilt carries: the velocity is stored in the previous frame's full pelvis frame,
so a height change is R[z, up] v_up + R[z, other axes] v_other, and the second term is |dz| through
the tilt (the up axis being the pelvis axis nearest the world's z over the motion); the means over
the motions.

    /usr/bin/python3 tools/root_stats.py out/demo-1/edit_mdt_untrained out/demo-1/edit_mdt
"""
import argparse
import glob
import os
import sys

import numpy as np

# Rodrigues, the NumPy reference's (one copy in the repository).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bench", "reference"))
from similarity_ref import rotation_matrices  # noqa: E402


def tilt_height(trans, pelvis):
    """|height change carried by the pelvis axes other than its up axis| over a motion."""
    previous = pelvis[:-1]
    velocity = np.einsum("nji,nj->ni", previous, np.diff(trans, axis=0))  # R_{i-1}^T (t_i - t_{i-1})
    up = int(np.argmax(np.abs(previous[:, 2, :]).mean(axis=0)))
    return abs(sum((previous[:, 2, k] * velocity[:, k]).sum() for k in range(3) if k != up))


def motions(stage_dir):
    """(trans [T, 3], pelvis rotations [T, 3, 3], fps) of every motion in the stage's task-*/edited.npz."""
    files = sorted(glob.glob(os.path.join(stage_dir, "task-*", "edited.npz")))
    if not files:
        sys.exit(f"{stage_dir}: no task-*/edited.npz (is it an edit stage's output directory?)")
    for path in files:
        with np.load(path) as z:
            missing = [k for k in ("trans", "poses", "offsets", "fps") if k not in z.files]
            if missing:
                sys.exit(f"{path}: not an edit output (no {', '.join(missing)})")
            offsets, trans, poses, fps = z["offsets"], z["trans"], z["poses"], z["fps"]
        for i in range(len(offsets) - 1):
            frames = slice(offsets[i], offsets[i + 1])
            yield trans[frames], rotation_matrices(poses[frames, 0]), float(fps[i])


def row(stage_dir):
    drift, spread, vertical, accel, tilt = [], [], [], [], []
    for trans, pelvis, fps in motions(stage_dir):
        if len(trans) < 3:
            continue
        z = trans[:, 2]
        drift.append(abs(z[-1] - z[0]))
        spread.append(z.std())
        vertical.append(np.abs(np.diff(z)).mean() * fps)
        accel.append(np.linalg.norm(np.diff(trans[:, :2], n=2, axis=0), axis=1).mean() * fps * fps)
        tilt.append(tilt_height(trans, pelvis))
    if not drift:
        sys.exit(f"{stage_dir}: no motion of 3 frames or more")
    return len(drift), np.mean(drift), np.mean(spread), np.mean(vertical), np.mean(accel), np.mean(tilt)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stages", nargs="+", help="edit stage output directories (out/JOB/STAGE)")
    args = parser.parse_args()
    print(f"{'stage':<40} {'motions':>7} {'|dz| end (m)':>12} {'z sd (m)':>9} {'|vz| (m/s)':>10} "
          f"{'accel xy (m/s2)':>15} {'|dz| tilt (m)':>13}")
    for stage in args.stages:
        n, drift, spread, vertical, accel, tilt = row(stage)
        print(f"{stage:<40} {n:>7} {drift:>12.3f} {spread:>9.3f} {vertical:>10.3f} {accel:>15.2f} {tilt:>13.3f}")


if __name__ == "__main__":
    main()
