"""tools/part_swap.py (issue 15: which body parts of an edit the judges read as off its target) on
hand-made edits and triplets whose every value says where it came from, and its errors."""
import json
import os
import subprocess
import tempfile
import unittest

import numpy as np

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "part_swap.py")
LEGS = [1, 2, 4, 5, 7, 8, 10, 11]  # the skeleton's left and right leg


def run(*args):
    return subprocess.run(["/usr/bin/python3", TOOL, *args], capture_output=True, text=True, timeout=60)


class PartSwapTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.addCleanup(self.tmp.cleanup)
        # Two triplets of 3 and 2 frames; the edits' rotations are 1, the targets' 2; the paths
        # differ (the target's starts at x = 5).
        self.lengths = [3, 2]
        frames = sum(self.lengths)
        offsets = np.array([0, 3, 5])
        corpus = os.path.join(self.tmp.name, "corpus", "task-00000", "motionfix")
        os.makedirs(corpus)
        target_trans = np.zeros((frames, 3), np.float32)
        target_trans[:, 0] = [5, 6, 7, 5, 5]
        np.savez(os.path.join(corpus, "triplets-00000.npz"), format=np.array("motionpipe.triplets/1"),
                 ids=np.array(["t1", "t2"]), target_offsets=offsets,
                 target_poses=np.full((frames, 22, 3), 2, np.float32), target_trans=target_trans)
        self.corpus = os.path.dirname(os.path.dirname(corpus))
        self.edits = os.path.join(self.tmp.name, "edit", "task-00000")
        os.makedirs(self.edits)
        edit_trans = np.zeros((frames, 3), np.float32)
        edit_trans[:, 1] = [0, 1, 3, 0, -1]
        np.savez(os.path.join(self.edits, "edited.npz"), format=np.array("motionpipe.clips/1"),
                 ids=np.array(["t1", "t2"]), offsets=offsets, fps=np.array([30.0, 30.0]),
                 poses=np.ones((frames, 22, 3), np.float32), trans=edit_trans)
        with open(os.path.join(self.edits, "edits.json"), "w") as f:
            json.dump({"edited": 2}, f)
        self.edits = os.path.dirname(self.edits)

    def out(self, name):
        return os.path.join(self.tmp.name, name)

    def test_target_with_the_edits_legs_and_path(self):
        result = run(self.edits, self.corpus, self.out("hybrid"), "--base", "target", "--parts", "legs,global")
        self.assertEqual(result.returncode, 0, result.stderr)
        with np.load(os.path.join(self.out("hybrid"), "task-00000", "edited.npz")) as z:
            poses, trans, ids = z["poses"], z["trans"], list(z["ids"])
        self.assertEqual(ids, ["t1", "t2"])
        swapped = [0] + LEGS
        kept = [j for j in range(22) if j not in swapped]
        np.testing.assert_array_equal(poses[:, swapped], 1)
        np.testing.assert_array_equal(poses[:, kept], 2)
        # The edit's path, re-based at the target's first frame of each motion.
        np.testing.assert_array_equal(trans[:, 0], [5, 5, 5, 5, 5])
        np.testing.assert_array_equal(trans[:, 1], [0, 1, 3, 0, -1])
        self.assertTrue(os.path.exists(os.path.join(self.out("hybrid"), "task-00000", "edits.json")))

    def test_edit_with_the_targets_arms_keeps_its_own_path(self):
        result = run(self.edits, self.corpus, self.out("hybrid"), "--base", "edit", "--parts", "arms")
        self.assertEqual(result.returncode, 0, result.stderr)
        with np.load(os.path.join(self.out("hybrid"), "task-00000", "edited.npz")) as z:
            poses, trans = z["poses"], z["trans"]
        arms = [13, 16, 18, 20, 14, 17, 19, 21]
        np.testing.assert_array_equal(poses[:, arms], 2)
        np.testing.assert_array_equal(poses[:, [j for j in range(22) if j not in arms]], 1)
        np.testing.assert_array_equal(trans[:, 1], [0, 1, 3, 0, -1])

    def test_errors_name_the_problem_and_write_nothing(self):
        result = run(self.edits, self.corpus, self.out("a"), "--base", "target", "--parts", "tail")
        self.assertEqual(result.returncode, 2)
        self.assertIn("unknown part 'tail'", result.stderr)
        result = run(self.edits, self.tmp.name + "/nothing", self.out("b"), "--base", "target", "--parts", "legs")
        self.assertIn("no motionpipe.triplets/1 file", result.stderr)
        # An edit whose length is not its target's.
        path = os.path.join(self.edits, "task-00000", "edited.npz")
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["offsets"] = np.array([0, 2, 5])
        np.savez(path, **arrays)
        result = run(self.edits, self.corpus, self.out("c"), "--base", "target", "--parts", "legs")
        self.assertEqual(result.returncode, 2)
        self.assertIn("edit 't1' has 2 frames, its target 3", result.stderr)
        for name in ("a", "b", "c", "c.tmp"):
            self.assertFalse(os.path.exists(self.out(name)), name)
        os.makedirs(self.out("d"))
        result = run(self.edits, self.corpus, self.out("d"), "--base", "target", "--parts", "legs")
        self.assertIn("exists", result.stderr)


if __name__ == "__main__":
    unittest.main()
