"""tools/leg_denoise.py (issue 15: a learned clean-up of generated legs): its kinematics against
root_stats.py's, its heading-free input, the corruption, a model that changes nothing giving the
motions back, the pelvis height correction, a short training on hand-made triplets, and its errors."""
import json
import math
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np
import torch

TOOLS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools")
sys.path.insert(0, TOOLS)
import leg_denoise  # noqa: E402
import root_stats  # noqa: E402


def run(*args):
    return subprocess.run(["/usr/bin/python3", os.path.join(TOOLS, "leg_denoise.py"), *args], capture_output=True,
                          text=True, timeout=120)


def walk(frames, seed=0):
    """A turning, swinging motion: (trans [T, 3], poses [T, 22, 3] axis-angle)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    poses = 0.05 * rng.standard_normal((frames, 22, 3))
    poses[:, 0] = [math.pi / 2, 0, 0]  # the y-up body stood up in the z-up world
    for leg, sign in ((1, 1), (2, -1)):
        poses[:, leg, 0] += 0.5 * sign * np.sin(2 * math.pi * t)
    trans = np.stack([np.cos(t), np.sin(t), 0.9 + 0.02 * np.sin(4 * t)], axis=1)
    return trans.astype(np.float32), poses.astype(np.float32)


class LegDenoiseTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.addCleanup(self.tmp.cleanup)

    def path(self, *parts):
        return os.path.join(self.tmp.name, *parts)

    def write_edits(self, fps=30.0):
        """An edit stage's directory: two motions of 40 and 5 frames (the second too short to clean)."""
        motions = [walk(40, 1), walk(5, 2)]
        task = self.path("edit", "task-00000")
        os.makedirs(task)
        np.savez(os.path.join(task, "edited.npz"), format=np.array("motionpipe.clips/1"), ids=np.array(["a", "b"]),
                 offsets=np.array([0, 40, 45]), fps=np.array([fps, fps]),
                 poses=np.concatenate([p for _, p in motions]), trans=np.concatenate([t for t, _ in motions]),
                 texts=np.array(["walk", "stand"]))
        with open(os.path.join(task, "edits.json"), "w") as f:
            json.dump({"edited": 2}, f)
        return os.path.dirname(task)

    def save_model(self, height=False, dz=0.0):
        torch.manual_seed(0)
        model = leg_denoise.Denoiser(16, height=height)
        with torch.no_grad():
            if height:
                model.out.bias[-1] = dz
        path = self.path("model.pt")
        torch.save({"width": 16, "height": height, "state": model.state_dict()}, path)
        return path

    def test_forward_kinematics_agree_with_root_stats(self):
        trans, poses = walk(12)
        R = leg_denoise.rodrigues(torch.from_numpy(poses))
        offsets = {j: torch.tensor(v, dtype=torch.float32) for j, v in root_stats.leg_offsets().items()}
        legs = R[None, :, list(leg_denoise.LEG)]
        ours = leg_denoise.leg_positions(torch.from_numpy(trans)[None], R[None, :, 0], legs, offsets)[0]
        theirs = root_stats.feet(trans.astype(float), root_stats.rotation_matrices(poses.reshape(-1, 3).astype(float))
                                 .reshape(-1, 22, 3, 3), root_stats.leg_offsets())
        # ours: knee, ankle, foot per leg; theirs: ankle, foot per leg
        np.testing.assert_allclose(ours[:, [1, 2, 4, 5]].numpy(), theirs, atol=1e-5)

    def test_rotations_round_trip(self):
        v = torch.tensor([[0.3, -0.2, 0.1], [0.0, 1.5, 0.2], [2.0, 0.5, -1.0]])
        R = leg_denoise.rodrigues(v)
        np.testing.assert_allclose(leg_denoise.log_map(R).numpy(), v.numpy(), atol=1e-4)
        np.testing.assert_allclose(leg_denoise.from_six_d(leg_denoise.six_d(R)).numpy(), R.numpy(), atol=1e-6)

    def test_root_features_do_not_see_the_heading_or_the_place(self):
        trans, poses = walk(30)
        R = leg_denoise.rodrigues(torch.from_numpy(poses))
        turn = leg_denoise.yaw_matrix(torch.tensor(1.1))
        moved = (turn @ torch.from_numpy(trans)[..., None])[..., 0] + torch.tensor([3.0, -2.0, 0.0])
        a = leg_denoise.root_features(torch.from_numpy(trans)[None], R[None, :, 0], 30.0)
        b = leg_denoise.root_features(moved[None], (turn @ R[:, 0])[None], 30.0)
        np.testing.assert_allclose(a.numpy(), b.numpy(), atol=1e-4)
        # the pelvis speed: the walk goes round a unit circle at 1 rad/s
        np.testing.assert_allclose(a[0, :-1, 1:3].norm(dim=-1).numpy(), 1.0, atol=0.01)

    def test_corruption(self):
        generator = torch.Generator().manual_seed(3)
        legs = leg_denoise.rodrigues(torch.full((4, 60, 6, 3), 0.2))  # the same pose on every frame
        # no noise and the partner the motion itself: the warp and the blend change nothing
        same = leg_denoise.corrupt(legs, legs, generator, 0.0)
        np.testing.assert_allclose(same.numpy(), legs.numpy(), atol=1e-5)
        noisy = leg_denoise.corrupt(legs, legs, generator, 1.0)
        angle = leg_denoise.log_map(legs.transpose(-1, -2) @ noisy).norm(dim=-1)
        self.assertGreater(float(angle.max()), 0.0)
        self.assertLess(float(angle.max()), math.radians(25))
        # shrink: the swing about the window's mean narrows, to 0.2-1 of its range
        swinging = leg_denoise.rodrigues(0.3 * torch.randn(8, 60, 6, 3))
        shrunk = leg_denoise.corrupt(swinging, swinging, generator, 0.0, shrink=1.0)
        spread = lambda legs: leg_denoise.six_d(legs).std(dim=1).mean()  # noqa: E731
        self.assertLess(float(spread(shrunk)), 0.95 * float(spread(swinging)))
        self.assertGreater(float(spread(shrunk)), 0.15 * float(spread(swinging)))
        drift = leg_denoise.height_drift((64, 60), generator)
        self.assertLess(float(drift.abs().max()), 0.05 + 0.075 + 0.05 * 4)

    def test_a_model_that_changes_nothing_gives_the_motions_back(self):
        edits = self.write_edits()
        result = run("apply", self.save_model(), edits, self.path("clean"), "--threads", "1")
        self.assertEqual(result.returncode, 0, result.stderr)
        with np.load(os.path.join(edits, "task-00000", "edited.npz")) as z:
            before = {k: z[k] for k in z.files}
        with np.load(self.path("clean", "task-00000", "edited.npz")) as z:
            after = {k: z[k] for k in z.files}
        self.assertEqual(sorted(before), sorted(after))
        for key in before:
            if key != "poses":
                np.testing.assert_array_equal(after[key], before[key])
        np.testing.assert_allclose(after["poses"], before["poses"], atol=1e-5)  # the zero-initialised output
        others = [j for j in range(22) if j not in leg_denoise.LEG]
        np.testing.assert_array_equal(after["poses"][:, others], before["poses"][:, others])
        with open(self.path("clean", "task-00000", "edits.json")) as f:
            self.assertEqual(json.load(f), {"edited": 2})

    def test_the_height_correction_moves_the_pelvis_alone(self):
        edits = self.write_edits()
        result = run("apply", self.save_model(height=True, dz=0.1), edits, self.path("clean"), "--threads", "1")
        self.assertEqual(result.returncode, 0, result.stderr)
        with np.load(os.path.join(edits, "task-00000", "edited.npz")) as z:
            trans = z["trans"]
        with np.load(self.path("clean", "task-00000", "edited.npz")) as z:
            after = z["trans"]
        np.testing.assert_allclose(after[:40, 2], trans[:40, 2] + 0.1, atol=1e-6)
        np.testing.assert_array_equal(after[:40, :2], trans[:40, :2])
        np.testing.assert_array_equal(after[40:], trans[40:])  # 5 frames: not cleaned

    def write_triplets(self):
        directory = self.path("motionfix")
        os.makedirs(directory)
        sides = {"source": [walk(64, k) for k in range(4)], "target": [walk(70, 10 + k) for k in range(4)]}
        arrays = {"splits": np.array(["train", "train", "val", "test"]), "fps": np.full(4, 30.0)}
        for side, motions in sides.items():
            arrays[side + "_offsets"] = np.cumsum([0] + [len(t) for t, _ in motions])
            arrays[side + "_poses"] = np.concatenate([p for _, p in motions])
            arrays[side + "_trans"] = np.concatenate([t for t, _ in motions])
        np.savez(os.path.join(directory, "triplets-00000.npz"), **arrays)
        return directory

    def test_training_writes_its_best_model(self):
        result = run("train", self.write_triplets(), self.path("m", "model.pt"), "--steps", "4", "--log", "2",
                     "--width", "16", "--batch", "4", "--height", "--threads", "1")
        self.assertEqual(result.returncode, 0, result.stderr)
        self.assertIn("4 training motions", result.stdout)
        self.assertIn("step 4 ", result.stdout)
        saved = torch.load(self.path("m", "model.pt"))
        self.assertEqual((saved["width"], saved["height"]), (16, True))
        self.assertIn(saved["step"], (2, 4))
        self.assertEqual(os.listdir(self.path("m")), ["model.pt"])  # no temporary left

    def test_errors_name_the_input(self):
        empty = self.path("empty")
        os.makedirs(empty)
        result = run("train", empty, self.path("model.pt"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(f"{empty}: no triplet npz files", result.stderr)
        result = run("apply", self.save_model(), empty, self.path("clean"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(f"{empty}: no task-*/edited.npz", result.stderr)
        edits = self.write_edits(fps=20.0)
        result = run("apply", self.save_model(), edits, self.path("clean"))
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("motion 0 at 20 fps (the clean-up is trained at 30)", result.stderr)
        self.assertFalse(os.path.exists(self.path("clean", "task-00000", "edited.npz")))


if __name__ == "__main__":
    unittest.main()
