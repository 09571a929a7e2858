#!/usr/bin/python3
"""Edits with body parts swapped between each edit and its target (issue 15: which parts of an edit
the judges read as off the target).

An edit stage's motions have their targets' lengths, frame for frame, so a body part can be moved
between an edit and its target. This writes a stage in the edit stage's own layout
(`task-*/edited.npz` and `edits.json`), which `eval_edit` scores as any edit stage, where every
motion is its base (the edit, or its target from the triplets) with the named parts taken from the
other. Parts are the skeleton's SINC body parts (data/skeleton/smpl22.json `sinc_body_parts`):
`global` (the pelvis's orientation and its path, the path re-based at the base's first frame),
`torso`, `left_arm`, `right_arm`, `left_leg`, `right_leg`, and `arms`, `legs` for both sides.
Only local joint rotations move, so the hybrid is a valid pose sequence; it is not a plausible
motion (the feet of a swapped leg slide), so read the judges' scores of it, not its plausibility.

    /usr/bin/python3 tools/part_swap.py out/demo-2/edit_mdt out/demo-2/corpus OUT --base target --parts global,legs

OUT must not exist; it is written under a temporary name and renamed when complete.
"""
import argparse
import glob
import json
import os
import shutil
import sys

import numpy as np

SKELETON = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "skeleton", "smpl22.json")


class InputError(Exception):
    pass


def part_joints(names):
    """Joint indices of the named parts (the skeleton file's SINC body parts, spaces as underscores)."""
    with open(SKELETON) as f:
        parts = {k.replace(" ", "_"): v for k, v in json.load(f)["sinc_body_parts"]["joints"].items()}
    parts["arms"] = parts["left_arm"] + parts["right_arm"]
    parts["legs"] = parts["left_leg"] + parts["right_leg"]
    joints = []
    for name in names:
        if name not in parts:
            raise InputError(f"--parts: unknown part '{name}' (known: {', '.join(sorted(parts))})")
        joints += parts[name]
    return sorted(set(joints))


def read_targets(triplets_dir):
    """id -> (poses, trans) of every triplet's target under triplets_dir (a corpus stage or its files)."""
    files = sorted(glob.glob(os.path.join(triplets_dir, "**", "*.npz"), recursive=True))
    targets = {}
    for path in files:
        with np.load(path) as z:
            if "format" not in z.files or str(z["format"]) != "motionpipe.triplets/1":
                continue
            poses, trans, offsets = z["target_poses"], z["target_trans"], z["target_offsets"]
            for i, triplet in enumerate(z["ids"]):
                targets[str(triplet)] = (poses[offsets[i]:offsets[i + 1]], trans[offsets[i]:offsets[i + 1]])
    if not targets:
        raise InputError(f"{triplets_dir}: no motionpipe.triplets/1 file found")
    return targets


def swap(edit_poses, edit_trans, target_poses, target_trans, joints, base):
    """One motion: the base's poses and path with `joints` from the other (joint 0 brings its path)."""
    if base == "target":
        (poses, trans), (other_poses, other_trans) = (target_poses, target_trans), (edit_poses, edit_trans)
    else:
        (poses, trans), (other_poses, other_trans) = (edit_poses, edit_trans), (target_poses, target_trans)
    poses, new_trans = poses.copy(), trans.copy()
    poses[:, joints] = other_poses[:, joints]
    if 0 in joints:
        new_trans = other_trans - other_trans[:1] + trans[:1]
    return poses, new_trans


def write_stage(edit_dir, targets, joints, base, out):
    tasks = sorted(glob.glob(os.path.join(edit_dir, "task-*", "edited.npz")))
    if not tasks:
        raise InputError(f"{edit_dir}: no task-*/edited.npz (an edit stage's output directory)")
    if os.path.exists(out):
        raise InputError(f"{out}: exists; give a new directory")
    tmp = out.rstrip("/") + ".tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        for path in tasks:
            write_task(path, targets, joints, base, tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    os.rename(tmp, out)
    return len(tasks)


def write_task(path, targets, joints, base, tmp):
    """One edit task's motions, swapped, into tmp/task-N."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    poses, trans, offsets = arrays["poses"].copy(), arrays["trans"].copy(), arrays["offsets"]
    for i, motion_id in enumerate(arrays["ids"]):
        motion_id = str(motion_id)
        if motion_id not in targets:
            raise InputError(f"{path}: edit '{motion_id}' has no triplet in the triplets given")
        target_poses, target_trans = targets[motion_id]
        frames = slice(offsets[i], offsets[i + 1])
        if offsets[i + 1] - offsets[i] != len(target_poses):
            raise InputError(f"{path}: edit '{motion_id}' has {offsets[i + 1] - offsets[i]} frames, its "
                             f"target {len(target_poses)} (only edits at their targets' lengths can swap parts)")
        poses[frames], trans[frames] = swap(poses[frames], trans[frames], target_poses, target_trans, joints, base)
    arrays["poses"], arrays["trans"] = poses, trans
    task = os.path.basename(os.path.dirname(path))
    os.makedirs(os.path.join(tmp, task))
    np.savez(os.path.join(tmp, task, "edited.npz"), **arrays)
    summary = os.path.join(os.path.dirname(path), "edits.json")
    if os.path.exists(summary):
        shutil.copy(summary, os.path.join(tmp, task, "edits.json"))


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("edits", help="an edit stage's output directory")
    parser.add_argument("triplets", help="the triplets the edits were made from (a corpus stage's directory)")
    parser.add_argument("out", help="the new stage directory to write")
    parser.add_argument("--base", choices=("target", "edit"), required=True,
                        help="the motion kept, whose listed parts are replaced by the other's")
    parser.add_argument("--parts", required=True, help="comma-separated: global, torso, left_arm, right_arm, "
                        "left_leg, right_leg, arms, legs")
    args = parser.parse_args(argv)
    try:
        joints = part_joints([p.strip() for p in args.parts.split(",") if p.strip()])
        tasks = write_stage(args.edits, read_targets(args.triplets), joints, args.base, args.out)
    except InputError as e:
        print(f"part_swap: {e}", file=sys.stderr)
        return 2
    print(f"{args.out}: {tasks} task(s), base {args.base}, joints {joints} from the other")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
