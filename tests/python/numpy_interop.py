#!/usr/bin/python3
"""Interop checks driven by tests/unit/interop_test.cc, run with Debian's numpy.

  numpy_interop.py write DIR          numpy writes files for C++ to read (every dtype, both zip
                                      methods, Fortran order, big-endian, unicode)
  numpy_interop.py check-clips FILE   numpy loads a clip file written by C++ and checks its layout
  numpy_interop.py check-arrays FILE  numpy loads an npz of every dtype written by C++
  numpy_interop.py motionfix-pickle DIR  writes a tiny MotionFix-style joblib pickle + splits.json
"""
import json
import os
import sys

import numpy as np


def expect(condition, message):
    if not condition:
        print(f"numpy_interop: FAILED: {message}", file=sys.stderr)
        sys.exit(1)


def write(directory):
    os.makedirs(directory, exist_ok=True)
    arange = np.arange(24, dtype=np.float32).reshape(2, 3, 4)
    arrays = {
        "f32": arange,
        "f64": np.array([1.5, -2.25, 1e300]),
        "i32": np.array([-3, 0, 2**31 - 1], dtype=np.int32),
        "i64": np.array([-(2**60), 5], dtype=np.int64),
        "u8": np.array([0, 7, 255], dtype=np.uint8),
        "b": np.array([True, False, True]),
        "u": np.array(["walk", "wave — right hand", ""]),
        "scalar": np.array(29.97),
        "fortran": np.asfortranarray(np.arange(6, dtype=np.int16).reshape(2, 3)),
        "bigendian": np.arange(4, dtype=">f8"),
        "empty": np.zeros((0, 3), dtype=np.float32),
    }
    np.savez(os.path.join(directory, "stored.npz"), **arrays)
    np.savez_compressed(os.path.join(directory, "deflated.npz"), **arrays)
    np.save(os.path.join(directory, "plain.npy"), arange)


def check_clips(path):
    with np.load(path) as z:
        expect(str(z["format"]) == "motionpipe.clips/1", "format string")
        offsets = z["offsets"]
        n = len(z["ids"])
        expect(offsets.shape == (n + 1,) and offsets[0] == 0, "offsets shape")
        expect(z["poses"].shape == (offsets[-1], 22, 3) and z["poses"].dtype == np.float32, "poses")
        expect(z["trans"].shape == (offsets[-1], 3), "trans")
        expect(z["seg_parts"].dtype == np.bool_ and z["seg_parts"].shape[1] == 6, "seg_parts")
        expect(z["texts"].dtype.kind == "U", "texts are unicode")
        expect(np.all(np.isfinite(z["poses"])), "finite poses")
        first = z["poses"][offsets[0]:offsets[1]]
        expect(abs(float(first[0, 0, 0]) - 1.5707964) < 1e-5, f"first root rotation {first[0, 0, 0]}")
        expect(list(z["ids"]) == ["upright", "second"], f"ids {list(z['ids'])}")
        expect(z["texts"][0] == "a person waves — with the right hand", "unicode text")
    print(f"numpy loaded {path}: {n} clips, {offsets[-1]} frames")


def check_arrays(path):
    with np.load(path) as z:
        expect(z["f32"].dtype == np.float32 and z["f32"].shape == (2, 3), "f32")
        expect(np.array_equal(z["f32"], np.array([[1, 2, 3], [4, 5, -6.5]], dtype=np.float32)), "f32 values")
        expect(z["f64"].dtype == np.float64 and z["f64"][2] == 1e300, "f64")
        expect(z["i32"].dtype == np.int32 and z["i32"][1] == 2**30, "i32")
        expect(z["i64"].dtype == np.int64 and z["i64"][0] == -(2**50), "i64")
        expect(z["b"].dtype == np.bool_ and list(z["b"]) == [True, False, False, True], "bool")
        expect(z["u8"].dtype == np.uint8 and z["u8"][1] == 255, "uint8")
        expect(list(z["s"]) == ["walk", "wave — right hand", ""], f"strings {list(z['s'])}")
        expect(z["scalar"].shape == () and float(z["scalar"]) == 29.97, "scalar")
    print(f"numpy loaded {path}: all dtypes match")


def motionfix_pickle(directory):
    import joblib

    rng = np.random.default_rng(0)
    data = {}
    for k, (n_src, n_tgt) in enumerate([(40, 35), (25, 30), (50, 50)]):
        def side(n):
            return {"rots": rng.normal(0, 0.3, (n, 66)).astype(np.float32),
                    "trans": np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0).astype(np.float32),
                    "joint_positions": rng.normal(0, 0.5, (n, 22, 3)).astype(np.float32)}
        data[f"00{k}"] = {"motion_source": side(n_src), "motion_target": side(n_tgt),
                          "text": ["raise the right arm higher", "walk faster", "do not turn at the end"][k]}
    os.makedirs(directory, exist_ok=True)
    joblib.dump(data, os.path.join(directory, "motionfix.pth.tar"))
    with open(os.path.join(directory, "splits.json"), "w") as f:
        json.dump({"train": ["000", "002"], "test": ["001"]}, f)
    np.save(os.path.join(directory, "expected_rots_001.npy"), data["001"]["motion_source"]["rots"])


if __name__ == "__main__":
    command, target = sys.argv[1], sys.argv[2]
    {"write": write, "check-clips": check_clips, "check-arrays": check_arrays,
     "motionfix-pickle": motionfix_pickle}[command](target)
