#!/usr/bin/python3
"""Independent NumPy reference for SimMotionEdit's motion similarity, MotionSNR and classes.

Written straight from the paper (sec. 3.2.1, eqs. 4-10) and docs/REFERENCE.md section 3.1, in plain
float64 NumPy with a Python loop over source frames: the obvious implementation, used to check the
C++ filter and as the speed baseline of bench/filter_bench.

  eq. 4   S_i^Rr = -min_j mean|x_i - m_j|,  j in [max(c-W, 0), min(c+W, T_m)),  c = floor(i T_m / T_x)
          rotation branch: 6D (first two rows) of joints 1..21; location branch: joints - translation
          each branch smoothed: np.convolve(s, ones(10)/10, 'same')
  eq. 5   S = w1 S^Rr + w2 S^Rl
  eq. 9   SNR = mean(kappa largest distances) / mean(kappa smallest),  distances = -S
  eq. 6   S^N = (S - min S) / (max S - min S)
  eq. 10  class = min(K - 1, floor(K S^N))

Usage:
  similarity_ref.py TRIPLETS.npz [...] [--limit N] [--kappa 5] [--out ref.npz] [--time]
"""
import argparse
import json
import sys
import time

import numpy as np


def rotation_matrices(axis_angle):
    """Rodrigues: [..., 3] axis-angle -> [..., 3, 3] (float64): R = cos t I + sin t [k]x + (1 - cos t) k k^T."""
    theta = np.linalg.norm(axis_angle, axis=-1)
    k = axis_angle / np.where(theta < 1e-12, 1.0, theta)[..., None]
    c, s = np.cos(theta)[..., None, None], np.sin(theta)[..., None, None]
    kx, ky, kz = k[..., 0], k[..., 1], k[..., 2]
    zero = np.zeros_like(kx)
    skew = np.stack([zero, -kz, ky, kz, zero, -kx, -ky, kx, zero], axis=-1).reshape(k.shape[:-1] + (3, 3))
    return c * np.eye(3) + s * skew + (1.0 - c) * (k[..., :, None] * k[..., None, :])


def branches(poses, trans, joints):
    """Per-frame vectors of the two branches: rotation [T, 126], location [T, 66]."""
    poses = poses.astype(np.float64)
    frames = poses.shape[0]
    rot = rotation_matrices(poses[:, 1:22])[:, :, :2, :].reshape(frames, 126)
    loc = (joints[:, :22].astype(np.float64) - trans.astype(np.float64)[:, None, :]).reshape(frames, 66)
    return rot, loc


def raw_similarity(source, target, window):
    """Eq. 4 for both branches: source/target = (rotation [T, 126], location [T, 66])."""
    ts, tt = len(source[0]), len(target[0])
    src = np.concatenate(source, axis=1)
    tgt = np.concatenate(target, axis=1)
    split = source[0].shape[1]
    raw_rot, raw_loc = np.empty(ts), np.empty(ts)
    for i in range(ts):
        c = i * tt // ts
        lo, hi = max(c - window, 0), min(c + window, tt)
        diff = np.abs(src[i] - tgt[lo:hi])
        raw_rot[i] = -diff[:, :split].sum(axis=1).min() / split
        raw_loc[i] = -diff[:, split:].sum(axis=1).min() / (src.shape[1] - split)
    return raw_rot, raw_loc


def similarity(src, tgt, opts):
    """Everything for one triplet; src/tgt = (poses, trans, joints)."""
    result = {"kept": False, "reason": "", "snr": float("nan")}
    if len(src[0]) < opts.min_frames or len(tgt[0]) < opts.min_frames:
        result["reason"] = "too_short"
        return result
    raw_rot, raw_loc = raw_similarity(branches(*src), branches(*tgt), opts.window)
    kernel = np.ones(opts.smooth) / opts.smooth
    combined = opts.w_rot * np.convolve(raw_rot, kernel, mode="same") + opts.w_loc * np.convolve(raw_loc, kernel, mode="same")
    distances = np.sort(-combined)
    snr = distances[-opts.kappa:].mean() / distances[:opts.kappa].mean()
    result.update(snr=float(snr), raw_rot=raw_rot, raw_loc=raw_loc, combined=combined)
    if snr < opts.snr_threshold:
        result["reason"] = "low_snr"
        return result
    normalized = (combined - combined.min()) / (combined.max() - combined.min())
    classes = np.minimum(np.floor(normalized * opts.classes), opts.classes - 1).astype(np.uint8)
    result.update(kept=True, normalized=normalized, classes=classes)
    return result


def load(path):
    data = np.load(path)
    if str(data["format"]) != "motionpipe.triplets/1":
        sys.exit(f"{path}: not a motionpipe triplets file")
    if "source_joints" not in data.files:
        sys.exit(f"{path}: the reference needs stored joint positions (source_joints)")
    return data


def triplets(paths, limit):
    """Yields (id, (poses, trans, joints) source, ... target) in file order."""
    count = 0
    for path in paths:
        data = load(path)
        sides = {}
        for side in ("source", "target"):
            sides[side] = (data[f"{side}_offsets"], data[f"{side}_poses"], data[f"{side}_trans"], data[f"{side}_joints"])
        for row, triplet_id in enumerate(data["ids"]):
            if limit is not None and count >= limit:
                return
            motions = []
            for side in ("source", "target"):
                offsets, poses, trans, joints = sides[side]
                a, b = offsets[row], offsets[row + 1]
                motions.append((poses[a:b], trans[a:b], joints[a:b]))
            yield str(triplet_id), motions[0], motions[1]
            count += 1


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="+")
    parser.add_argument("--limit", type=int)
    parser.add_argument("--window", type=int, default=15)
    parser.add_argument("--smooth", type=int, default=10)
    parser.add_argument("--w-rot", type=float, default=1.0)
    parser.add_argument("--w-loc", type=float, default=1.0)
    parser.add_argument("--kappa", type=int, default=5)
    parser.add_argument("--snr-threshold", type=float, default=2.0)
    parser.add_argument("--min-frames", type=int, default=20)
    parser.add_argument("--classes", type=int, default=3)
    parser.add_argument("--out", help="npz with every triplet's results")
    parser.add_argument("--time", action="store_true", help="print a JSON line with the compute throughput")
    opts = parser.parse_args()

    # Load first so that the timing covers the computation only (as the C++ side measures it).
    items = list(triplets(opts.files, opts.limit))
    started = time.perf_counter()
    results = [(tid, similarity(src, tgt, opts)) for tid, src, tgt in items]
    seconds = time.perf_counter() - started
    if opts.time:
        print(json.dumps({"triplets": len(results), "seconds": seconds, "triplets_per_second": len(results) / seconds}))
    if opts.out:
        ids = [tid for tid, _ in results]
        kept = np.array([r["kept"] for _, r in results])
        snr = np.array([r["snr"] for _, r in results])
        computed = [r for _, r in results if "combined" in r]
        offsets = np.cumsum([0] + [len(r["combined"]) for r in computed])
        kept_rows = [r for _, r in results if r["kept"]]
        kept_offsets = np.cumsum([0] + [len(r["normalized"]) for r in kept_rows])
        cat = lambda rows, key, dtype: np.concatenate([r[key] for r in rows]).astype(dtype) if rows else np.zeros(0, dtype)
        np.savez(opts.out, ids=np.array(ids), kept=kept, snr=snr,
                 reasons=np.array([r["reason"] for _, r in results]),
                 computed_ids=np.array([tid for tid, r in results if "combined" in r]), computed_offsets=offsets,
                 raw_rot=cat(computed, "raw_rot", np.float64), raw_loc=cat(computed, "raw_loc", np.float64),
                 combined=cat(computed, "combined", np.float64),
                 kept_offsets=kept_offsets, normalized=cat(kept_rows, "normalized", np.float64),
                 classes=cat(kept_rows, "classes", np.uint8))


if __name__ == "__main__":
    main()
