#!/usr/bin/python3
"""The pelvis trajectory of an edit (or generate) stage's motions, beside another's (issue 15: where plausibility is lost).

The 207-d editing feature stores the pelvis as a velocity (REFERENCE.md section 2), so its height is
integrated when a generated motion is decoded: an edit whose height drifts floats above or sinks
into the floor, and its feet slide. Per motion: |z(end) - z(0)|, the standard deviation of z, the
mean vertical speed and the mean horizontal acceleration of the pelvis, and how much of the height
change the pelvis's tilt carries: the velocity is stored in the previous frame's full pelvis frame,
so a height change is R[z, up] v_up + R[z, other axes] v_other, and the second term is |dz| through
the tilt (the up axis being the pelvis axis nearest the world's z over the motion); the means over
the motions. Beside them, the feet's skate as the evaluation computes it (per motion, the fraction of
foot-frames within 5 cm of the floor in both frames whose horizontal speed exceeds 0.15 m/s; the
mean over the motions), and the same with every frame moved vertically so that its lowest foot
joint stands on the floor: if the height's drift made the feet skate (a sunken swing foot counted
as a sliding contact), the second would fall to the targets' level. Then, on those grounded
contact foot-frames, the root mean square horizontal speed of the feet, of the pelvis and of the
feet relative to the pelvis: a planted foot has the first near 0 while the other two cancel. Last,
whether the legs step at all: the knees' swing (the standard deviation over a motion of each knee's
flexion angle, the angle of its local rotation, in degrees; the mean over both knees and the
motions) and their mean angular speed (degrees/s). With --truth SINGLES_DIR, each generate stage's
row is followed by one for the ground truth of the same span ids (the singles stage's spans.npz).

    /usr/bin/python3 tools/root_stats.py out/demo-1/edit_mdt_untrained out/demo-1/edit_mdt
    /usr/bin/python3 tools/root_stats.py --truth out/demo-1/singles out/demo-1/gen_sinc
    /usr/bin/python3 tools/root_stats.py --against PROBE_DIR/target_roundtrip PROBE_DIR/estimate_t0

With --against STAGE_DIR, each stage's hips, knees and ankles are also compared with those of the
motions of the same ids in STAGE_DIR: the mean and median geodesic angle between their local
rotations, over joints and frames. Then which part of each stage's error makes the feet skate: the
error (per frame, the leg joints' local rotations relative to the reference's, and the pelvis's
orientation and translation) is put back on the reference's motions whole, for the legs alone and
the pelvis alone, and split in time by a Gaussian of 0.1, 0.33 and 1 s into its slower part (the
smoothed error) and its faster part (the rest); the skate (as the evaluation's) of each.

With --unlocked STAGE_DIR, each stage is a foot_lock stage's output and STAGE_DIR its input: its
sliding contact foot-frames (the evaluation's count, pooled), for the ankles and the toes, split by
the lock's runs of contact on the unlocked motions (core's test with the default options): both
frames inside one run (held, yet the leg did not bring the joint to its place), one frame in a run
(the run's edge, where the hold fades), neither (the test took the joint for a swing: faster than
1 m/s or above 5 cm); and the toes' frames inside a run whose ankle was not held.

    /usr/bin/python3 tools/root_stats.py --unlocked out/demo-29/match_sinc out/demo-29/lock_match_sinc

With --seeds (and --against REF), the stages are one estimate made by models that differ only in
their training seed (e.g. mdt_probe --write's estimate_t0 of each): is the legs' error each model's
own (training noise: an average of models would cancel it) or the recipe's (the same in every
seed)? For each stage the root mean square angle of the leg joints' error and of its faster part
(the error minus its Gaussian smoothing by 0.1 s); the cosine between two stages' errors (1: the same
error, 0: unrelated, -1: opposite) and between their faster parts, pooled and as the median over
motions, averaged over the pairs of stages; and the skate of the stages' mean
motion (the rotations' chordal mean, the translations' mean) beside each stage's. With --toward
SOURCE_DIR (mdt_probe --write's source_aligned) also how far each estimate's legs lean towards the
source: per motion the least-squares fraction of the error along the source's leg rotations minus
the reference's (0 keeps nothing of the source, 1 is the source), and the skate of the reference
carrying only that lean or only the rest of the error.

    /usr/bin/python3 tools/root_stats.py --seeds --against P1/target_roundtrip --toward P1/source_aligned P1/estimate_t0 P2/estimate_t0 P3/estimate_t0
"""
import argparse
import glob
import json
import os
import sys

import numpy as np

# Rodrigues, the NumPy reference's (one copy in the repository).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bench", "reference"))
from similarity_ref import rotation_matrices  # noqa: E402

SKELETON = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "skeleton", "smpl22.json")
LEGS = ((1, 4, 7, 10), (2, 5, 8, 11))  # hip, knee, ankle, foot (SMPL-22); the feet are 7, 10, 8, 11
KNEES = tuple(leg[1] for leg in LEGS)
# The joints whose rotations move the feet (a foot joint's own rotation moves no joint feet() places).
LEG_JOINTS = [joint for leg in LEGS for joint in leg[:3]]  # hips, knees, ankles
CONTACT_HEIGHT, SKATE_SPEED = 0.05, 0.15  # core's PlausibilityOptions


def leg_offsets():
    """Rest offsets (y-up, metres) of the leg joints, from the skeleton file."""
    with open(SKELETON) as f:
        doc = json.load(f)
    offsets = {}
    for joint in sum(LEGS, ()):
        direction = np.asarray(doc["rest_offset_directions_yup"][joint], float)
        offsets[joint] = doc["bone_lengths_m"][joint] * direction / np.linalg.norm(direction)
    return offsets


def feet(trans, rotations, offsets):
    """World positions [T, 4, 3] of the ankles and feet (forward kinematics along the legs)."""
    out = []
    for leg in LEGS:
        world, position = rotations[:, 0], trans + rotations[:, 0] @ offsets[leg[0]]
        for k in range(1, len(leg)):
            world = world @ rotations[:, leg[k - 1]]
            position = position + world @ offsets[leg[k]]
            if k >= 2:
                out.append(position)
    return np.stack(out, axis=1)


def contact(positions, grounded):
    """Foot-frames [T - 1, 4] within CONTACT_HEIGHT of the floor in both frames (grounded: of the
    frame's lowest foot joint)."""
    z = positions[..., 2] - (positions[..., 2].min(axis=1, keepdims=True) if grounded else 0)
    return (z[1:] < CONTACT_HEIGHT) & (z[:-1] < CONTACT_HEIGHT)


def contact_speeds(trans, positions, fps):
    """Sums of squared horizontal speeds (feet, pelvis, feet relative to the pelvis) over the grounded
    contact foot-frames, and their count."""
    touching = contact(positions, grounded=True)
    def speed(xy):
        return np.linalg.norm(np.diff(xy, axis=0), axis=-1) * fps
    pelvis = np.repeat(speed(trans[:, :2])[:, None], positions.shape[1], axis=1)
    relative = speed(positions[..., :2] - trans[:, None, :2])
    return np.array([(speed(positions[..., :2])[touching] ** 2).sum(), (pelvis[touching] ** 2).sum(),
                     (relative[touching] ** 2).sum()]), touching.sum()


def skate(positions, fps, grounded):
    """Fraction of contact foot-frames that slide (0 without contact)."""
    touching = contact(positions, grounded)
    speed = np.linalg.norm(np.diff(positions[..., :2], axis=0), axis=-1) * fps
    return (speed[touching] > SKATE_SPEED).sum() / touching.sum() if touching.any() else 0.0


def tilt_height(trans, pelvis):
    """|height change carried by the pelvis axes other than its up axis| over a motion."""
    previous = pelvis[:-1]
    velocity = np.einsum("nji,nj->ni", previous, np.diff(trans, axis=0))  # R_{i-1}^T (t_i - t_{i-1})
    up = int(np.argmax(np.abs(previous[:, 2, :]).mean(axis=0)))
    return abs(sum((previous[:, 2, k] * velocity[:, k]).sum() for k in range(3) if k != up))


def angle_of_trace(trace):
    """The angle (degrees) of rotations with these traces."""
    return np.degrees(np.arccos(np.clip((trace - 1) / 2, -1.0, 1.0)))


def knee_swing(rotations, fps):
    """(sd of the flexion angle, mean |angular speed|) in degrees and degrees/s, over both knees."""
    angle = angle_of_trace(np.trace(rotations[:, list(KNEES)], axis1=-2, axis2=-1))  # [T, 2]
    return angle.std(axis=0).mean(), np.abs(np.diff(angle, axis=0)).mean() * fps


def against_motions(stage_dir, stage_motions, against_dir):
    """{id: (trans, rotations, fps)} of against_dir's motions with the ids of the stage's."""
    found = same_ids(stage_dir, stage_motions, against_dir, stage_files(against_dir),
                     "--against matches motions by id", "motion")
    return {i: (trans, rotations, fps) for i, trans, rotations, fps in found}


def leg_angle_error(stage_motions, reference):
    """Mean and median geodesic angle (degrees) between the hips', knees' and ankles' local rotations
    of each motion and those of the reference motion with the same id (against_motions), frame by
    frame (the shorter's frames): how far an estimate's legs are from the answer's (issue 15)."""
    reference = {i: rotations for i, (_, rotations, _) in reference.items()}
    angles = []
    for i, _, rotations, _ in stage_motions:
        frames = min(len(rotations), len(reference[i]))
        relative = np.einsum("tjab,tjab->tj", rotations[:frames, LEG_JOINTS], reference[i][:frames, LEG_JOINTS])
        angles.append(angle_of_trace(relative).ravel())
    angles = np.concatenate(angles)
    return angles.mean(), np.median(angles)


BAND_SECONDS = (0.1, 0.33, 1.0)


def log_rotation(rotations):
    """Rotation vectors [..., 3] of rotation matrices [..., 3, 3] (angles below pi)."""
    angle = np.radians(angle_of_trace(np.trace(rotations, axis1=-2, axis2=-1)))
    axis = np.stack([rotations[..., 2, 1] - rotations[..., 1, 2], rotations[..., 0, 2] - rotations[..., 2, 0],
                     rotations[..., 1, 0] - rotations[..., 0, 1]], axis=-1)
    sine = np.sin(angle)[..., None]
    return axis * np.where(sine > 1e-8, angle[..., None] / (2 * np.maximum(sine, 1e-8)), 0.5)


def smoothed(x, sigma):
    """x [T, ...] filtered along time by a Gaussian of sigma frames (the ends repeated)."""
    radius = int(np.ceil(3 * sigma))
    kernel = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    padded = np.concatenate([np.repeat(x[:1], radius, axis=0), x, np.repeat(x[-1:], radius, axis=0)])
    return sum(w * padded[k:k + len(x)] for k, w in enumerate(kernel / kernel.sum()))


def skate_carrying(trans, rotations, fps, joints, error, shift, offsets):
    """The skate of a motion (trans [T, 3], rotations [T, J, 3, 3]) with `joints` turned by `error`
    [T, len(joints), 3] (R exp(e)) and its translation moved by `shift` (grounded=False)."""
    carried = rotations.copy()
    carried[:, joints] = rotations[:, joints] @ rotation_matrices(error.reshape(-1, 3)).reshape(error.shape + (3,))
    return skate(feet(trans + shift, carried, offsets), fps, grounded=False)


def error_band_skates(stage_dir, stage_motions, reference):
    """The skate of the reference's motions carrying this stage's error: whole, legs alone, pelvis
    alone, then the slower and the faster part for each of BAND_SECONDS (means over the motions)."""
    offsets, columns, joints = leg_offsets(), [], [0] + LEG_JOINTS
    for i, trans, rotations, fps in stage_motions:
        ref_trans, ref_rotations, ref_fps = reference[i]
        if fps != ref_fps:
            sys.exit(f"{stage_dir}: motion {i} at {fps:g} fps, the reference's at {ref_fps:g}")
        frames = min(len(trans), len(ref_trans))
        ref_trans, ref_rotations = ref_trans[:frames], ref_rotations[:frames]
        # R = R_ref exp(e): the error e of the pelvis (joint 0) and the leg joints, and of the translation.
        error = log_rotation(np.einsum("tjba,tjbc->tjac", ref_rotations[:, joints], rotations[:frames, joints]))
        shift = trans[:frames] - ref_trans

        def skate_with(e, d):
            return skate_carrying(ref_trans, ref_rotations, fps, joints, e, d, offsets)

        legs, pelvis = error.copy(), np.zeros_like(error)
        legs[:, 0], pelvis[:, 0] = 0, error[:, 0]
        row = [skate_with(error, shift), skate_with(legs, 0 * shift), skate_with(pelvis, shift)]
        for seconds in BAND_SECONDS:
            slow_error, slow_shift = smoothed(error, seconds * fps), smoothed(shift, seconds * fps)
            row += [skate_with(slow_error, slow_shift), skate_with(error - slow_error, shift - slow_shift)]
        columns.append(row)
    return np.mean(columns, axis=0)


def stage_files(stage_dir):
    """The stage's task-*/edited.npz (an edit or foot_lock stage) or task-*/generated.npz (a generate stage)."""
    files = sorted(glob.glob(os.path.join(stage_dir, "task-*", "edited.npz")) or
                   glob.glob(os.path.join(stage_dir, "task-*", "generated.npz")))
    if not files:
        sys.exit(f"{stage_dir}: no task-*/edited.npz (is it an edit stage's output directory?)")
    return files


def motions(files, only_ids=None):
    """(id, trans [T, 3], local rotations [T, 22, 3, 3], fps) of every motion in the npz files (with
    only_ids, of those ids alone, in the files' order)."""
    for path in files:
        with np.load(path) as z:
            missing = [k for k in ("trans", "poses", "offsets", "fps") if k not in z.files]
            if missing:
                sys.exit(f"{path}: not a motion file (no {', '.join(missing)})")
            offsets, trans, poses, fps = z["offsets"], z["trans"], z["poses"], z["fps"]
            ids = [str(i) for i in z["ids"]] if "ids" in z.files else [None] * (len(offsets) - 1)
        for i in range(len(offsets) - 1):
            if only_ids is not None and ids[i] not in only_ids:
                continue
            frames = slice(offsets[i], offsets[i + 1])
            rotations = rotation_matrices(poses[frames].reshape(-1, 3)).reshape(-1, 22, 3, 3)
            yield ids[i], trans[frames], rotations, float(fps[i])


def same_ids(stage_dir, stage_motions, other_dir, other_files, why, noun):
    """The motions of other_files (other_dir's) with the ids of stage_dir's motions; every id must be
    there (`why` says why ids are needed, `noun` names a motion of other_dir in the error)."""
    ids = {i for i, *_ in stage_motions}
    if None in ids:
        sys.exit(f"{stage_dir}: its motions carry no ids ({why})")
    found = list(motions(other_files, only_ids=ids))
    absent = ids - {i for i, *_ in found}
    if absent:
        sys.exit(f"{other_dir}: no {noun} {sorted(absent)[0]} (of {len(absent)} ids of {stage_dir} not found)")
    return found


def truth_of(stage_dir, stage_motions, singles_dir):
    """The ground truth (singles_dir's spans.npz) of the span ids of a generate stage's motions."""
    if None in {i for i, *_ in stage_motions}:
        sys.exit(f"{stage_dir}: its motions carry no ids (--truth needs a generate stage)")
    files = sorted(glob.glob(os.path.join(singles_dir, "task-*", "spans.npz")))
    if not files:
        sys.exit(f"{singles_dir}: no task-*/spans.npz (is it a singles stage's output directory?)")
    return same_ids(stage_dir, stage_motions, singles_dir, files, "--truth needs a generate stage", "span")


def row(stage_dir, motion_list):
    drift, spread, vertical, accel, tilt, skating, grounded = [], [], [], [], [], [], []
    offsets = leg_offsets()
    squares, contacts = np.zeros(3), 0
    knees = []
    for _, trans, rotations, fps in motion_list:
        if len(trans) < 3:
            continue
        z = trans[:, 2]
        drift.append(abs(z[-1] - z[0]))
        spread.append(z.std())
        vertical.append(np.abs(np.diff(z)).mean() * fps)
        accel.append(np.linalg.norm(np.diff(trans[:, :2], n=2, axis=0), axis=1).mean() * fps * fps)
        tilt.append(tilt_height(trans, rotations[:, 0]))
        positions = feet(trans, rotations, offsets)
        skating.append(skate(positions, fps, grounded=False))
        grounded.append(skate(positions, fps, grounded=True))
        sums, count = contact_speeds(trans, positions, fps)
        squares, contacts = squares + sums, contacts + count
        knees.append(knee_swing(rotations, fps))
    if not drift:
        sys.exit(f"{stage_dir}: no motion of 3 frames or more")
    return (len(drift), np.mean(drift), np.mean(spread), np.mean(vertical), np.mean(accel), np.mean(tilt),
            np.mean(skating), np.mean(grounded), *np.sqrt(squares / max(contacts, 1)), *np.mean(knees, axis=0))


LOCK_MAX_SPEED, LOCK_MIN_FRAMES = 1.0, 2  # core's FootLockOptions defaults
RESIDUAL_KINDS = ("both frames in one held run", "one frame held (a run's edge)", "neither frame held")


def held_runs(path, fps):
    """Per frame [T] the index of the foot_lock test's run of contact holding the joint (-1: none):
    below CONTACT_HEIGHT, slower than LOCK_MAX_SPEED by a central difference, runs of at least
    LOCK_MIN_FRAMES frames (core's FindHold with the default options)."""
    frames = len(path)
    a, b = np.maximum(np.arange(frames) - 1, 0), np.minimum(np.arange(frames) + 1, frames - 1)
    speed = np.linalg.norm(path[b, :2] - path[a, :2], axis=-1) * fps / np.maximum(b - a, 1)
    tested = (path[:, 2] < CONTACT_HEIGHT) & (speed < LOCK_MAX_SPEED)
    run, count, begin = -np.ones(frames, int), 0, 0
    while begin < frames:
        end = begin
        while end < frames and tested[end]:
            end += 1
        if end - begin >= LOCK_MIN_FRAMES:
            run[begin:end], count = count, count + 1
        begin = end + 1 if end == begin else end
    return run


def lock_residual(stage_dir, stage_motions, unlocked):
    """Where a foot_lock stage's sliding contact foot-frames are (pooled fractions of its contact
    foot-frames, as the evaluation counts them): per joint (ankle, toe) by the lock's runs on the
    unlocked motions (paired by id), and of the toes' frames inside a run, those whose ankle is
    outside a run of its own at either frame."""
    offsets = leg_offsets()
    counts, contacts, toes_alone = np.zeros((len(RESIDUAL_KINDS), 2)), 0, 0
    unlocked = {i: (trans, rotations) for i, trans, rotations, _ in unlocked}
    for i, trans, rotations, fps in stage_motions:
        after, before = feet(trans, rotations, offsets), feet(*unlocked[i], offsets)
        touching = contact(after, grounded=False)
        sliding = touching & (np.linalg.norm(np.diff(after[..., :2], axis=0), axis=-1) * fps > SKATE_SPEED)
        contacts += touching.sum()
        runs = [held_runs(before[:, joint], fps) for joint in range(before.shape[1])]
        for joint in range(before.shape[1]):  # feet()'s order: left ankle, left foot, right ankle, right foot
            run, is_toe = runs[joint], joint % 2
            for f in np.flatnonzero(sliding[:, joint]):
                kind = 0 if run[f] >= 0 and run[f] == run[f + 1] else (1 if max(run[f], run[f + 1]) >= 0 else 2)
                counts[kind, is_toe] += 1
                toes_alone += kind == 0 and is_toe and min(runs[joint - 1][f], runs[joint - 1][f + 1]) < 0
    if contacts == 0:
        sys.exit(f"{stage_dir}: no contact foot-frame")
    return counts / contacts, toes_alone / contacts


def chordal_mean(rotations):
    """The rotation nearest (Frobenius) the mean of rotation matrices [K, ..., 3, 3] over K."""
    u, _, vt = np.linalg.svd(np.mean(rotations, axis=0))
    u[..., :, -1] *= np.sign(np.linalg.det(u @ vt))[..., None]
    return u @ vt


def leg_errors(stage_dir, stage_motions, reference):
    """{id: the leg joints' error [T, 6, 3]}, rotation vectors of R_ref^T R, on the shorter's frames."""
    out = {}
    for i, _, rotations, fps in stage_motions:
        ref_rotations, ref_fps = reference[i][1], reference[i][2]
        if fps != ref_fps:
            sys.exit(f"{stage_dir}: motion {i} at {fps:g} fps, the reference's at {ref_fps:g}")
        frames = min(len(rotations), len(ref_rotations))
        out[i] = log_rotation(np.einsum("tjba,tjbc->tjac", ref_rotations[:frames, LEG_JOINTS],
                                        rotations[:frames, LEG_JOINTS]))
    return out


def carrying_leg_error(reference, i, error, offsets):
    """The skate of reference motion i with its leg joints turned by `error` [T, 6, 3]."""
    trans, rotations, fps = reference[i]
    frames = len(error)
    return skate_carrying(trans[:frames], rotations[:frames], fps, LEG_JOINTS, error, 0, offsets)


def seed_agreement(stages, loaded, reference):
    """--seeds: per stage (rms error, rms faster part, skate), the mean over pairs of stages of the
    cosine between their errors (1: the same error, 0: unrelated, -1: opposite; errors pooled, faster
    parts pooled, faster parts' median over motions) and the skate of the mean motion."""
    errors = [leg_errors(stage, loaded[stage], reference) for stage in stages]
    ids = sorted(set.intersection(*(set(e) for e in errors)))
    fast = [{i: e[i] - smoothed(e[i], 0.1 * reference[i][2]) for i in ids} for e in errors]
    offsets = leg_offsets()
    per_stage = []
    for stage, e, f in zip(stages, errors, fast):
        whole, faster = np.concatenate([e[i].ravel() for i in ids]), np.concatenate([f[i].ravel() for i in ids])
        skates = [skate(feet(t, r, offsets), fps, grounded=False) for k, t, r, fps in loaded[stage] if k in ids]
        # the root mean square angle over joints and frames (3 components each)
        per_stage.append((np.degrees(np.sqrt(3 * np.mean(whole ** 2))), np.degrees(np.sqrt(3 * np.mean(faster ** 2))),
                          np.mean(skates)))
    pairs = [(a, b) for a in range(len(stages)) for b in range(a + 1, len(stages))]
    def cosine(x, y):
        return (x @ y) / max(np.sqrt((x @ x) * (y @ y)), 1e-30)
    def pooled(parts, a, b):
        return cosine(np.concatenate([parts[a][i].ravel() for i in ids]), np.concatenate([parts[b][i].ravel() for i in ids]))
    correlations = (np.mean([pooled(errors, a, b) for a, b in pairs]), np.mean([pooled(fast, a, b) for a, b in pairs]),
                    np.median([np.mean([cosine(fast[a][i].ravel(), fast[b][i].ravel()) for a, b in pairs]) for i in ids]))
    by_id = [{i: (t, r) for i, t, r, _ in loaded[stage]} for stage in stages]
    mean_skates = []
    for i in ids:
        frames = min(len(m[i][0]) for m in by_id)
        trans = np.mean([m[i][0][:frames] for m in by_id], axis=0)
        rotations = chordal_mean(np.stack([m[i][1][:frames] for m in by_id]))
        mean_skates.append(skate(feet(trans, rotations, offsets), reference[i][2], grounded=False))
    return per_stage, correlations, np.mean(mean_skates)


def source_lean(stage_dir, stage_motions, reference, sources):
    """--toward: the mean over motions of the legs' lean towards the source (the least-squares
    fraction of the error along the source's leg rotations minus the reference's), and the skate of
    the reference carrying the lean alone and the rest alone."""
    errors = leg_errors(stage_dir, stage_motions, reference)
    away = leg_errors(stage_dir + " (its sources)", [(i, *sources[i]) for i in errors], reference)
    offsets, rows = leg_offsets(), []
    for i, e in errors.items():
        d = away[i][:len(e)]
        lean = (e * d).sum() / max((d * d).sum(), 1e-12)
        rows.append((lean, carrying_leg_error(reference, i, lean * d, offsets),
                     carrying_leg_error(reference, i, e - lean * d, offsets)))
    return np.mean(rows, axis=0)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stages", nargs="+", help="edit, generate or foot_lock stage output directories (out/JOB/STAGE)")
    parser.add_argument("--truth", metavar="SINGLES_DIR",
                        help="after each generate stage, its spans' ground truth from this singles stage")
    parser.add_argument("--against", metavar="STAGE_DIR",
                        help="also the leg joints' angle to the motions of the same ids in this stage "
                             "(e.g. mdt_probe --write's target_roundtrip), and the skate of those "
                             "motions carrying each stage's error, by body part and by speed")
    parser.add_argument("--unlocked", metavar="STAGE_DIR",
                        help="each stage is a foot_lock stage and STAGE_DIR its input: where its "
                             "sliding contact foot-frames lie relative to the lock's runs of contact "
                             "(found as core's test does with the default options)")
    parser.add_argument("--seeds", action="store_true",
                        help="with --against: the stages are one estimate from models of different "
                             "training seeds; how much of their legs' error they share")
    parser.add_argument("--toward", metavar="SOURCE_DIR",
                        help="with --seeds: also how far each stage's legs lean towards these "
                             "motions of the same ids (mdt_probe --write's source_aligned)")
    args = parser.parse_args()
    if args.seeds and (not args.against or len(args.stages) < 2):
        parser.error("--seeds needs --against and at least two stages")
    if args.toward and not args.seeds:
        parser.error("--toward goes with --seeds")
    print(f"{'stage':<40} {'motions':>7} {'|dz| end (m)':>12} {'z sd (m)':>9} {'|vz| (m/s)':>10} "
          f"{'accel xy (m/s2)':>15} {'|dz| tilt (m)':>13} {'skate':>6} {'skate grounded':>14} "
          f"{'contact speed: feet':>19} {'pelvis':>6} {'feet - pelvis (m/s)':>19} {'knee sd (deg)':>13} "
          f"{'knee speed (deg/s)':>18}")
    rows, loaded = [], {}
    for stage in args.stages:
        stage_motions = loaded[stage] = list(motions(stage_files(stage)))
        rows.append((stage, stage_motions))
        if args.truth:
            rows.append((stage + " (truth)", truth_of(stage, stage_motions, args.truth)))
    for name, motion_list in rows:
        (n, drift, spread, vertical, accel, tilt, skating, grounded, feet_speed, pelvis_speed, relative,
         knee_sd, knee_speed) = row(name, motion_list)
        print(f"{name:<40} {n:>7} {drift:>12.3f} {spread:>9.3f} {vertical:>10.3f} {accel:>15.2f} {tilt:>13.3f} "
              f"{skating:>6.3f} {grounded:>14.3f} {feet_speed:>19.3f} {pelvis_speed:>6.3f} {relative:>19.3f} "
              f"{knee_sd:>13.2f} {knee_speed:>18.1f}")
    if args.against:
        references = {stage: against_motions(stage, loaded[stage], args.against) for stage in args.stages}
        print(f"{'stage':<40} leg joints' angle to {args.against} (deg): mean, median")
        for stage in args.stages:
            mean, median = leg_angle_error(loaded[stage], references[stage])
            print(f"{stage:<40} {mean:>7.2f} {median:>7.2f}")
        bands = " ".join(f"slower/faster than {seconds:g} s" for seconds in BAND_SECONDS)
        print(f"{'stage':<40} skate of {args.against}'s motions with the stage's error: whole, legs, "
              f"pelvis, {bands}")
        for stage in args.stages:
            figures = error_band_skates(stage, loaded[stage], references[stage])
            print(f"{stage:<40} " + " ".join(f"{x:>6.3f}" for x in figures))
    if args.seeds:
        per_stage, (whole, faster, median), mean_skate = seed_agreement(
            args.stages, loaded, {i: m for found in references.values() for i, m in found.items()})
        print(f"{'stage':<40} legs' error against {args.against}: rms (deg), its faster-than-0.1 s part "
              f"rms (deg), skate")
        for stage, (rms, fast_rms, skating) in zip(args.stages, per_stage):
            print(f"{stage:<40} {rms:>7.2f} {fast_rms:>7.2f} {skating:>7.3f}")
        print(f"cosine between the stages' errors {whole:.3f}, their faster parts {faster:.3f} "
              f"(median over motions {median:.3f}); skate of the stages' mean motion {mean_skate:.3f}")
        if args.toward:
            print(f"{'stage':<40} legs' lean towards {args.toward}, skate with the lean alone, "
                  f"with the rest alone")
            for stage in args.stages:
                sources = against_motions(stage, loaded[stage], args.toward)
                lean, lean_skate, rest_skate = source_lean(stage, loaded[stage], references[stage], sources)
                print(f"{stage:<40} {lean:>7.3f} {lean_skate:>7.3f} {rest_skate:>7.3f}")
    if args.unlocked:
        print(f"{'stage':<40} sliding, of the contact foot-frames, by the lock's runs on {args.unlocked}: "
              f"ankles / toes; then toes held without their ankle")
        for stage in args.stages:
            unlocked = same_ids(stage, loaded[stage], args.unlocked, stage_files(args.unlocked),
                                "--unlocked pairs motions by id", "motion")
            by_kind, toes_alone = lock_residual(stage, loaded[stage], unlocked)
            print(f"{stage:<40} " + "  ".join(f"{kind}: {a:.3f} / {t:.3f}" for kind, (a, t) in
                                              zip(RESIDUAL_KINDS, by_kind)) + f"  toe alone: {toes_alone:.3f}")


if __name__ == "__main__":
    main()
