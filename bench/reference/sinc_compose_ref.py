#!/usr/bin/python3
"""Independent NumPy reference for SINC's body-part composition and the 135-d TEMOS features.

Written from the paper (sec. 3.1, "Body part composition") and docs/REFERENCE.md 4.2 and 4.5, in
float64 NumPy, one pair at a time:
  1. trim both motions to the shorter length ("first": keep the first frames; "centre": centred crop)
  2. order so that B has fewer body parts than A (ties keep the order)
  3. if B uses a leg or the global orientation, B also gives both legs, the global orientation and
     the translation; otherwise A keeps them
  4. parts not taken from B come from A;  5. B's parts override A's
then the features: pelvis height, planar pelvis velocity, 22 joint rotations as 6D (first two
rows), after turning the motion about z so that the first frame's heading is -pi/2.

Usage:
  sinc_compose_ref.py SPANS.npz PAIRS.npz [--limit N] [--out features.npz] [--time]
"""
import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SKELETON = os.path.join(HERE, "..", "..", "data", "skeleton", "smpl22.json")
ORDER = ["global", "torso", "left arm", "right arm", "left leg", "right leg"]
LEGS_AND_GLOBAL = (1 << 0) | (1 << 4) | (1 << 5)


def part_joints():
    with open(SKELETON) as f:
        parts = json.load(f)["sinc_body_parts"]["joints"]
    return [parts[name] for name in ORDER]


PART_JOINTS = part_joints()


def count(parts):
    return bin(int(parts)).count("1")


def compose(a_poses, a_trans, a_parts, b_poses, b_trans, b_parts, crop):
    if count(b_parts) > count(a_parts):  # step 2
        a_poses, a_trans, a_parts, b_poses, b_trans, b_parts = b_poses, b_trans, b_parts, a_poses, a_trans, a_parts
    frames = min(len(a_poses), len(b_poses))  # step 1
    a0 = (len(a_poses) - frames) // 2 if crop == "centre" else 0
    b0 = (len(b_poses) - frames) // 2 if crop == "centre" else 0
    a_poses, a_trans = a_poses[a0:a0 + frames], a_trans[a0:a0 + frames]
    b_poses, b_trans = b_poses[b0:b0 + frames], b_trans[b0:b0 + frames]
    from_b = int(b_parts)
    root_from_b = bool(from_b & LEGS_AND_GLOBAL)  # step 3
    if root_from_b:
        from_b |= LEGS_AND_GLOBAL
    poses = a_poses.copy()  # step 4
    for part in range(6):
        if from_b & (1 << part):
            poses[:, PART_JOINTS[part]] = b_poses[:, PART_JOINTS[part]]  # step 5
    trans = (b_trans if root_from_b else a_trans).copy()
    return poses, trans


def six_d(axis_angle):
    """The first two rows of the Rodrigues rotation matrices, [..., 6]:
    R = cos t I + sin t [k]x + (1 - cos t) k k^T."""
    theta = np.linalg.norm(axis_angle, axis=-1)
    k = axis_angle / np.where(theta < 1e-12, 1.0, theta)[..., None]
    c, s = np.cos(theta), np.sin(theta)
    kx, ky, kz = k[..., 0], k[..., 1], k[..., 2]
    v = 1.0 - c
    return np.stack([c + v * kx * kx, v * kx * ky - s * kz, v * kx * kz + s * ky,
                     v * kx * ky + s * kz, c + v * ky * ky, v * ky * kz - s * kx], axis=-1)


def features(poses, trans, canonical=-np.pi / 2):
    poses = poses.astype(np.float64)
    trans = trans.astype(np.float64)
    six = six_d(poses)  # [T, 22, 6]
    # Turn about z so that the first frame's heading (atan2(R10, R00) of the root) is canonical.
    angle = canonical - np.arctan2(six[0, 0, 3], six[0, 0, 0])
    c, s = np.cos(angle), np.sin(angle)
    r0, r1 = six[:, 0, 0:3].copy(), six[:, 0, 3:6].copy()
    six[:, 0, 0:3] = c * r0 - s * r1
    six[:, 0, 3:6] = s * r0 + c * r1
    x, y = c * trans[:, 0] - s * trans[:, 1], s * trans[:, 0] + c * trans[:, 1]
    velocity = np.zeros((len(trans), 2))
    velocity[1:, 0] = np.diff(x)
    velocity[1:, 1] = np.diff(y)
    return np.concatenate([trans[:, 2:3], velocity, six.reshape(len(trans), 132)], axis=1)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("spans")
    parser.add_argument("pairs")
    parser.add_argument("--limit", type=int)
    parser.add_argument("--out")
    parser.add_argument("--time", action="store_true")
    args = parser.parse_args()
    spans = np.load(args.spans)
    pairs = np.load(args.pairs)
    if str(spans["format"]) != "motionpipe.spans/1" or str(pairs["format"]) != "motionpipe.sinc-pairs/1":
        sys.exit("sinc_compose_ref: expected a motionpipe spans file and a pairs file")
    offsets, all_poses, all_trans = spans["offsets"], spans["poses"], spans["trans"]
    crop = str(pairs["crop"])
    n = len(pairs["first"]) if args.limit is None else min(args.limit, len(pairs["first"]))
    items = []
    for k in range(n):
        i, j = int(pairs["first"][k]), int(pairs["second"][k])
        items.append((all_poses[offsets[i]:offsets[i + 1]], all_trans[offsets[i]:offsets[i + 1]], pairs["first_parts"][k],
                      all_poses[offsets[j]:offsets[j + 1]], all_trans[offsets[j]:offsets[j + 1]], pairs["second_parts"][k]))
    started = time.perf_counter()
    results = [features(*compose(*item, crop)) for item in items]
    seconds = time.perf_counter() - started
    if args.time:
        print(json.dumps({"pairs": n, "seconds": seconds, "pairs_per_second": n / seconds}))
    if args.out:
        lengths = [len(r) for r in results]
        np.savez(args.out, offsets=np.concatenate([[0], np.cumsum(lengths)]), features=np.concatenate(results))


if __name__ == "__main__":
    main()
