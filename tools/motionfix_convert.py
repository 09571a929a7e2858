#!/usr/bin/python3
"""Convert the MotionFix joblib pickle into motionpipe's triplets layout (numpy npz).

MotionFix ships as `motionfix.pth.tar`, a joblib dump of
    {id: {"motion_source": {"rots": [T, 66] axis-angle, "trans": [T, 3], "joint_positions": [T, 22, 3]},
          "motion_target": {...same...},
          "text": "edit instruction"}}
plus `splits.json` ({"train": [ids], "val": [ids], "test": [ids]}). C++ cannot read joblib pickles,
so this runs once with Debian's Python (python3-joblib, python3-numpy; python3-torch as well when the
pickle stores torch tensors). The output is read by motionpipe's ReadTriplets and by numpy.

Usage: /usr/bin/python3 tools/motionfix_convert.py motionfix.pth.tar --splits splits.json --out motionfix.npz
"""
import argparse
import json
import os
import sys

import numpy as np

FORMAT = "motionpipe.triplets/1"
FPS = 30.0


def fail(message):
    print(f"motionfix_convert: error: {message}", file=sys.stderr)
    sys.exit(1)


def as_array(value, where, shape_tail):
    if hasattr(value, "detach"):  # torch tensor
        value = value.detach().cpu().numpy()
    try:
        array = np.asarray(value, dtype=np.float32)
    except (TypeError, ValueError) as error:
        fail(f"{where}: not numeric ({error})")
    if array.ndim != 1 + len(shape_tail) or tuple(array.shape[1:]) != tuple(shape_tail):
        fail(f"{where}: shape {array.shape}, expected (T, {', '.join(map(str, shape_tail))})")
    if array.shape[0] == 0:
        fail(f"{where}: empty motion")
    if not np.all(np.isfinite(array)):
        fail(f"{where}: contains NaN or Inf")
    return array


def motion(entry, key, where):
    if key not in entry:
        fail(f"{where}: no '{key}'")
    side = entry[key]
    rots = as_array(side.get("rots"), f"{where}.{key}.rots", (66,))
    trans = as_array(side.get("trans"), f"{where}.{key}.trans", (3,))
    if len(rots) != len(trans):
        fail(f"{where}.{key}: rots has {len(rots)} frames, trans {len(trans)}")
    joints = side.get("joint_positions")
    if joints is not None:
        joints = as_array(joints, f"{where}.{key}.joint_positions", (22, 3))
        if len(joints) != len(rots):
            fail(f"{where}.{key}: joint_positions has {len(joints)} frames, rots {len(rots)}")
    return rots.reshape(-1, 22, 3), trans, joints


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("pickle", help="motionfix.pth.tar (joblib)")
    parser.add_argument("--splits", help="splits.json with train/val/test id lists")
    parser.add_argument("--out", required=True, help="output .npz")
    parser.add_argument("--compress", action="store_true",
                        help="deflate the arrays (about half the size, but readers must inflate them: "
                             "uncompressed files are used in place from a memory map)")
    args = parser.parse_args()

    try:
        import joblib
    except ImportError:
        fail("python3-joblib is missing (apt install python3-joblib, or run scripts/setup)")
    try:
        data = joblib.load(args.pickle)
    except ModuleNotFoundError as error:
        fail(f"{args.pickle}: the pickle needs module '{error.name}' (for torch tensors: apt install python3-torch)")
    except Exception as error:  # noqa: BLE001 - report any unpickling failure with the file name
        fail(f"{args.pickle}: cannot unpickle: {error}")
    if not isinstance(data, dict) or not data:
        fail(f"{args.pickle}: expected a non-empty dict of triplets")

    split_of = {}
    if args.splits:
        try:
            with open(args.splits) as f:
                splits = json.load(f)
        except (OSError, json.JSONDecodeError) as error:
            fail(f"{args.splits}: {error}")
        for name, ids in splits.items():
            for key in ids:
                split_of[str(key)] = name

    ids, texts, split_names = [], [], []
    sides = {"source": ([], [], [], [0]), "target": ([], [], [], [0])}
    with_joints = True
    for key in sorted(data, key=str):
        entry = data[key]
        where = f"{args.pickle}: triplet '{key}'"
        if not isinstance(entry, dict):
            fail(f"{where}: not a dict")
        text = entry.get("text")
        if isinstance(text, (list, tuple)):
            text = text[0] if text else ""
        if not isinstance(text, str):
            fail(f"{where}: 'text' is not a string")
        ids.append(str(key))
        texts.append(text)
        split_names.append(split_of.get(str(key), "train" if not split_of else "unlisted"))
        for name, field in (("source", "motion_source"), ("target", "motion_target")):
            rots, trans, joints = motion(entry, field, where)
            poses_l, trans_l, joints_l, offsets = sides[name]
            poses_l.append(rots)
            trans_l.append(trans)
            joints_l.append(joints)
            with_joints = with_joints and joints is not None
            offsets.append(offsets[-1] + len(rots))

    n = len(ids)
    arrays = {
        "format": np.array(FORMAT),
        "ids": np.array(ids),
        "texts": np.array(texts),
        "splits": np.array(split_names),
        "fps": np.full(n, FPS, dtype=np.float64),
        "edit_start": np.full(n, -1, dtype=np.int32),
        "edit_end": np.full(n, -1, dtype=np.int32),
    }
    for name, (poses_l, trans_l, joints_l, offsets) in sides.items():
        arrays[f"{name}_offsets"] = np.array(offsets, dtype=np.int64)
        arrays[f"{name}_poses"] = np.concatenate(poses_l).astype(np.float32)
        arrays[f"{name}_trans"] = np.concatenate(trans_l).astype(np.float32)
        if with_joints:
            arrays[f"{name}_joints"] = np.concatenate(joints_l).astype(np.float32)

    tmp = f"{args.out}.tmp.{os.getpid()}.npz"
    (np.savez_compressed if args.compress else np.savez)(tmp, **arrays)
    os.replace(tmp, args.out)
    counts = {s: split_names.count(s) for s in sorted(set(split_names))}
    print(f"motionfix_convert: {n} triplets {counts} -> {args.out}")


if __name__ == "__main__":
    main()
