"""tools/root_stats.py (issue 15's pelvis diagnostic) on edit outputs whose figures are known by hand,
and its error messages for directories and files that are not edit outputs."""
import os
import subprocess
import tempfile
import unittest

import numpy as np

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "root_stats.py")


def write_edits(stage_dir, motions, fps=10.0, drop=(), pelvis=None, knees=None, ids=None, name="edited.npz"):
    """One task-00000/edited.npz (or `name`) holding `motions` (each [T, 3] pelvis translations, z up),
    the pelvis at the axis-angle `pelvis` (identity by default), both knees bent about x by `knees`
    (radians, one per frame of all motions; none by default), the other joints at rest; `ids` if given."""
    os.makedirs(os.path.join(stage_dir, "task-00000"))
    offsets = np.cumsum([0] + [len(m) for m in motions])
    poses = np.zeros((offsets[-1], 22, 3), np.float32)
    if pelvis is not None:
        poses[:, 0] = pelvis
    if knees is not None:
        poses[:, 4, 0] = poses[:, 5, 0] = knees
    arrays = {"trans": np.concatenate(motions).astype(np.float32), "offsets": offsets.astype(np.int64),
              "poses": poses, "fps": np.full(len(motions), fps, np.float32)}
    if ids is not None:
        arrays["ids"] = np.array(ids)
    for key in drop:
        del arrays[key]
    np.savez(os.path.join(stage_dir, "task-00000", name), **arrays)


def run(*stages):
    return subprocess.run(["/usr/bin/python3", TOOL, *stages], capture_output=True, text=True, timeout=60)


class RootStatsTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.addCleanup(self.tmp.cleanup)

    def path(self, name):
        return os.path.join(self.tmp.name, name)

    def test_against_gives_the_leg_joints_angle_to_the_same_ids(self):
        # Both knees bent 12 degrees more than the reference's, in every frame; hips and ankles equal:
        # 2 of the 6 leg joints off by 12 degrees, so the mean is 4 and the median 0. Ids are matched,
        # not places: the reference stores them in the other order.
        # (Matched by place, a's 42 degrees against b's 50 and b's 62 against a's 30 would give 6.67.)
        still = np.zeros((4, 3))
        a_knee, b_knee = np.full(4, np.radians(30.0)), np.full(4, np.radians(50.0))
        write_edits(self.path("estimate"), [still, still],
                    knees=np.concatenate([a_knee, b_knee]) + np.radians(12.0), ids=["a", "b"])
        write_edits(self.path("answer"), [still, still], knees=np.concatenate([b_knee, a_knee]), ids=["b", "a"])
        result = run("--against", self.path("answer"), self.path("estimate"))
        self.assertEqual(result.returncode, 0, result.stderr)
        lines = result.stdout.splitlines()
        header = next(k for k, line in enumerate(lines) if "leg joints' angle" in line)
        mean, median = map(float, lines[header + 1].split()[1:3])
        self.assertAlmostEqual(mean, 4.0, places=3)
        self.assertAlmostEqual(median, 0.0, places=3)
        # An id the reference lacks is named.
        write_edits(self.path("other"), [still], ids=["c"])
        result = run("--against", self.path("other"), self.path("estimate"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("no motion a", result.stderr)

    def test_against_splits_the_error_that_skates_by_its_speed(self):
        # A body standing upright on the floor for 3 s at 30 fps (as in the skate test below) is the
        # reference. One estimate sways its pelvis slowly along x (0.3 m at a 4 s period: up to 0.47
        # m/s), the other jitters it by +-1 cm a frame (0.6 m/s every frame). The slow error skates
        # smoothed by 0.1 s as it does whole, its faster part not at all; the jitter skates on every
        # contact frame whole and as its faster part, smoothed not at all. Neither turns a leg joint
        # or the pelvis, so the legs alone never skate and the pelvis alone skates as the whole.
        legs, frames, fps = 0.3936 + 0.4324, 90, 30.0
        stand = np.zeros((frames, 3))
        stand[:, 2] = legs + 0.01
        sway, jitter = stand.copy(), stand.copy()
        sway[:, 0] = 0.3 * np.sin(2 * np.pi * np.arange(frames) / fps / 4.0)
        jitter[:, 0] = 0.01 * (-1.0) ** np.arange(frames)
        upright = [np.pi / 2, 0.0, 0.0]
        write_edits(self.path("stand"), [stand, stand], fps=fps, pelvis=upright, ids=["sway", "jitter"])
        write_edits(self.path("estimate"), [sway, jitter], fps=fps, pelvis=upright, ids=["sway", "jitter"])
        write_edits(self.path("sway"), [sway], fps=fps, pelvis=upright, ids=["sway"])
        write_edits(self.path("jitter"), [jitter], fps=fps, pelvis=upright, ids=["jitter"])
        result = run("--against", self.path("stand"), self.path("sway"), self.path("jitter"))
        self.assertEqual(result.returncode, 0, result.stderr)
        sway_row, jitter_row = ([float(x) for x in line.split()[1:]] for line in result.stdout.splitlines()[-2:])
        whole, legs_alone, pelvis_alone, slow, fast = sway_row[:5]
        self.assertGreater(whole, 0.5)
        self.assertEqual((legs_alone, pelvis_alone), (0.0, whole))
        self.assertAlmostEqual(slow, whole, delta=0.05)
        self.assertLess(fast, 0.02)  # the ends, where the smoothing repeats the first and last frames
        self.assertEqual(jitter_row[:3], [1.0, 0.0, 1.0])
        self.assertEqual(jitter_row[3:], [0.0, 1.0] * 3)
        # Motions of another rate than the reference's are refused, naming the motion.
        write_edits(self.path("slow_rate"), [sway], fps=10.0, pelvis=upright, ids=["sway"])
        result = run("--against", self.path("stand"), self.path("slow_rate"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("motion sway at 10 fps, the reference's at 30", result.stderr)

    def test_seeds_tell_a_shared_error_from_one_that_averages_out(self):
        # The upright body of the test above, standing; three "seeds" bend both knees by 4 degrees
        # every other frame: a and b on the even frames (the same error: cosine 1, their mean slides
        # as each), c on the odd ones (errors on other frames: cosine 0; their faster parts, +-2
        # degrees about the 2 degrees' mean, opposite: -1). The mean of a and c bends the knees 2
        # degrees on every frame: it stands (skate 0). Each jitter moves the ankle about 3 cm a
        # frame, so every contact frame slides.
        legs, frames, fps = 0.3936 + 0.4324, 60, 30.0
        stand = np.zeros((frames, 3))
        stand[:, 2] = legs + 0.01
        upright = [np.pi / 2, 0.0, 0.0]
        even = np.radians(4.0) * (np.arange(frames) % 2 == 0)
        write_edits(self.path("stand"), [stand], fps=fps, pelvis=upright, ids=["m"])
        for name, knees in (("a", even), ("b", even), ("c", np.radians(4.0) - even)):
            write_edits(self.path(name), [stand], fps=fps, pelvis=upright, knees=knees, ids=["m"])

        def agreement(*stages):
            result = run("--seeds", "--against", self.path("stand"), *map(self.path, stages))
            self.assertEqual(result.returncode, 0, result.stderr)
            line = result.stdout.splitlines()[-1]
            self.assertTrue(line.startswith("cosine"), line)
            words = line.replace(",", "").replace(")", "").split()
            return float(words[5]), float(words[9]), float(words[-1]), result.stdout

        whole, faster, mean_skate, out = agreement("a", "b")
        self.assertAlmostEqual(whole, 1.0, places=6)
        self.assertAlmostEqual(faster, 1.0, places=6)
        self.assertEqual(mean_skate, 1.0)
        whole, faster, mean_skate, out = agreement("a", "c")
        self.assertAlmostEqual(whole, 0.0, places=6)
        self.assertAlmostEqual(faster, -1.0, delta=0.01)  # the ends, where the smoothing repeats a frame
        self.assertEqual(mean_skate, 0.0)
        rows = [line.split() for line in out.splitlines() if line.startswith(self.path("a"))]
        rms, fast_rms, skating = map(float, rows[-1][1:4])
        self.assertAlmostEqual(rms, np.sqrt(2 * 4.0 ** 2 / 6 / 2), places=2)  # 2 of 6 leg joints, half the frames
        self.assertEqual(skating, 1.0)
        # --toward: knees bent 6 degrees where the source bends them 12: half way to the source, a
        # constant lean that leaves the feet standing; the rest is nothing.
        write_edits(self.path("source"), [stand], fps=fps, pelvis=upright, knees=np.full(frames, np.radians(12.0)), ids=["m"])
        for name in ("d", "e"):
            write_edits(self.path(name), [stand], fps=fps, pelvis=upright, knees=np.full(frames, np.radians(6.0)), ids=["m"])
        result = run("--seeds", "--against", self.path("stand"), "--toward", self.path("source"),
                     self.path("d"), self.path("e"))
        self.assertEqual(result.returncode, 0, result.stderr)
        lean, lean_skate, rest_skate = map(float, result.stdout.splitlines()[-1].split()[1:4])
        self.assertAlmostEqual(lean, 0.5, places=4)
        self.assertEqual((lean_skate, rest_skate), (0.0, 0.0))
        # --seeds without a reference, or with one stage, is refused.
        result = run("--seeds", self.path("a"), self.path("b"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("--seeds needs --against", result.stderr)

    def test_figures_of_known_trajectories(self):
        rising = np.zeros((5, 3))
        rising[:, 2] = [1.0, 1.1, 1.2, 1.3, 1.4]  # drift 0.4, sd 0.1414, |vz| 0.1 m a frame
        accelerating = np.zeros((4, 3))
        accelerating[:, 0] = 0.01 * np.arange(4) ** 2  # second difference 0.02 m a frame^2
        accelerating[:, 2] = 0.9
        too_short = np.zeros((2, 3))  # left out: fewer than 3 frames
        write_edits(self.path("stage"), [rising, too_short, accelerating], fps=10.0)
        result = run(self.path("stage"))
        self.assertEqual(result.returncode, 0, result.stderr)
        fields = result.stdout.splitlines()[1].split()
        self.assertEqual(fields[0], self.path("stage"))
        n, drift, spread, vertical, accel, tilt = int(fields[1]), *map(float, fields[2:7])
        self.assertEqual(n, 2)
        self.assertAlmostEqual(drift, 0.2, places=3)                  # (0.4 + 0) / 2
        self.assertAlmostEqual(spread, np.std([1.0, 1.1, 1.2, 1.3, 1.4]) / 2, places=3)
        self.assertAlmostEqual(vertical, 0.5, places=3)               # (0.1 x 10 fps + 0) / 2
        self.assertAlmostEqual(accel, 1.0, places=2)                  # (0 + 0.02 x 10^2) / 2
        self.assertAlmostEqual(tilt, 0.0, places=6)                   # an upright pelvis

    def test_a_tilted_pelvis_carries_height_that_its_up_axis_gives_back(self):
        # The pelvis's y axis is up (SMPL's), tilted 10 degrees about x; it walks 0.1 m a frame along
        # world y on level ground. In its own frame the step has a component along its z axis,
        # worth 0.1 sin 10 cos 10 m of height a frame, which its y component cancels.
        walk = np.zeros((5, 3))
        walk[:, 1] = 0.1 * np.arange(5)
        write_edits(self.path("tilted"), [walk], pelvis=[np.radians(100.0), 0.0, 0.0])
        result = run(self.path("tilted"))
        self.assertEqual(result.returncode, 0, result.stderr)
        fields = result.stdout.splitlines()[1].split()
        drift, tilt = float(fields[2]), float(fields[6])
        self.assertAlmostEqual(drift, 0.0, places=5)
        self.assertAlmostEqual(tilt, 4 * 0.1 * np.sin(np.radians(10)) * np.cos(np.radians(10)), places=3)

    def test_skate_counts_sliding_contact_feet_and_grounding_finds_them_at_any_height(self):
        # Upright (the pelvis turned 90 degrees about x: the rest pose's y axis up), the legs
        # straight: the lowest foot joint is 0.3936 + 0.4324 m below the pelvis (the left ankle and
        # foot; the right's are 1 cm higher). Sliding along x at 0.5 m/s on the floor, every contact
        # foot-frame skates; 2 m up nothing touches the floor, unless each frame is grounded.
        legs = 0.3936 + 0.4324
        def slide(height, speed):
            walk = np.zeros((6, 3))
            walk[:, 0] = speed / 10.0 * np.arange(6)
            walk[:, 2] = height
            return walk
        for name, height, speed, expected in [("floor", legs + 0.01, 0.5, (1.0, 1.0)),
                                              ("air", 2.0, 0.5, (0.0, 1.0)),
                                              ("still", legs + 0.01, 0.0, (0.0, 0.0))]:
            write_edits(self.path(name), [slide(height, speed)], pelvis=[np.pi / 2, 0.0, 0.0])
            result = run(self.path(name))
            self.assertEqual(result.returncode, 0, result.stderr)
            fields = result.stdout.splitlines()[1].split()
            self.assertEqual((float(fields[7]), float(fields[8])), expected, name)
            # On the grounded contact frames the rigid body's feet move with its pelvis.
            self.assertEqual([float(x) for x in fields[9:12]], [speed, speed, 0.0], name)

    def test_knee_swing_and_the_ground_truth_of_generated_spans(self):
        # Knees alternating 0 and 0.2 rad at 10 fps: sd 0.1 rad (5.73 deg), 0.2 rad a frame (114.6 deg/s).
        still = np.zeros((4, 3))
        write_edits(self.path("gen"), [still], knees=[0.0, 0.2, 0.0, 0.2], ids=["b"], name="generated.npz")
        # The singles stage's spans: "a" (not generated, knees still) and "b" (knees 0, 0.4, 0, 0.4).
        write_edits(self.path("singles"), [still, still], knees=[0.3] * 4 + [0.0, 0.4, 0.0, 0.4], ids=["a", "b"],
                    name="spans.npz")
        result = run("--truth", self.path("singles"), self.path("gen"))
        self.assertEqual(result.returncode, 0, result.stderr)
        generated, truth = result.stdout.splitlines()[1:3]
        self.assertEqual([float(x) for x in generated.split()[12:14]], [5.73, 114.6])
        self.assertTrue(truth.startswith(self.path("gen") + " (truth)"), truth)
        self.assertEqual(truth.split()[2], "1")  # span "b" alone
        self.assertEqual([float(x) for x in truth.split()[13:15]], [11.46, 229.2])
        # Without --truth, no truth row; a generated id the singles stage lacks is named.
        self.assertEqual(len(run(self.path("gen")).stdout.splitlines()), 2)
        write_edits(self.path("gen_c"), [still], ids=["c"], name="generated.npz")
        result = run("--truth", self.path("singles"), self.path("gen_c"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(self.path("singles") + ": no span c", result.stderr)

    def test_unlocked_places_the_sliding_foot_frames_by_the_locks_runs(self):
        # Upright and rigid on the floor (as above): every foot joint is in contact. Slower than the
        # lock's 1 m/s, the whole motion is one run of contact for each joint, and a lock output
        # that still slides does so inside its runs; at 2 m/s the lock's test holds nothing.
        legs = 0.3936 + 0.4324
        def slide(speed):
            walk = np.zeros((6, 3))
            walk[:, 0] = speed / 10.0 * np.arange(6)
            walk[:, 2] = legs + 0.01
            return walk
        upright = [np.pi / 2, 0.0, 0.0]
        for name, speed, kind in [("slow", 0.5, "both frames in one held run"), ("fast", 2.0, "neither frame held")]:
            # Beside it a body standing still (contact, never sliding), in the other order in the
            # unlocked stage: motions pair by id, and half the contact frames are its.
            write_edits(self.path(name + "_before"), [slide(0.0), slide(speed)], pelvis=upright, ids=["z", "a"])
            write_edits(self.path(name + "_after"), [slide(speed), slide(0.0)], pelvis=upright, ids=["a", "z"])
            result = run("--unlocked", self.path(name + "_before"), self.path(name + "_after"))
            self.assertEqual(result.returncode, 0, result.stderr)
            line = result.stdout.splitlines()[-1]
            self.assertTrue(line.startswith(self.path(name + "_after")), line)
            for other in ("both frames in one held run", "one frame held (a run's edge)", "neither frame held"):
                expected = "0.250 / 0.250" if other == kind else "0.000 / 0.000"  # ankles / toes
                self.assertIn(f"{other}: {expected}", line, name)
            self.assertTrue(line.endswith("toe alone: 0.000"), line)
        # The motions are paired by id: an id the unlocked stage lacks is named.
        write_edits(self.path("other"), [slide(0.5)], pelvis=upright, ids=["b"])
        result = run("--unlocked", self.path("other"), self.path("slow_after"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(self.path("other") + ": no motion a", result.stderr)

    def test_what_is_not_an_edit_output_is_named(self):
        os.makedirs(self.path("empty"))
        result = run(self.path("empty"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(self.path("empty") + ": no task-*/edited.npz", result.stderr)

        write_edits(self.path("nofps"), [np.zeros((4, 3))], drop=("fps",))
        result = run(self.path("nofps"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(os.path.join(self.path("nofps"), "task-00000", "edited.npz") + ": not a motion file (no fps)",
                      result.stderr)

        write_edits(self.path("short"), [np.zeros((2, 3))])
        result = run(self.path("short"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(self.path("short") + ": no motion of 3 frames or more", result.stderr)


if __name__ == "__main__":
    unittest.main()
