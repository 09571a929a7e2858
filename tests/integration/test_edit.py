"""The mdt_editor plugin through real workers: the MDT (with its similarity task on the filter's
classes) and MDM train on filtered corpus triplets, the `edit` stage edits the test split across
workers, and `motionpipe edit` edits a real CMU clip, deterministically under a seed."""
import glob
import json
import os
import sqlite3
import subprocess
import unittest

import numpy as np

from harness import MOTIONPIPE, EngineTest

HERE = os.path.dirname(os.path.abspath(__file__))
CMU = os.path.join(HERE, "..", "..", "data", "mocap", "cmu", "131_01.bvh")

PIPELINE = """
name: edit_test
output_root: OUT
seed: 1
stages:
  corpus: {kind: corpus, params: {clips: 60, triplets: 60, shard_size: 30}}
  filter: {kind: filter, inputs: [corpus], shards: 1, params: {preset: paper}}
  mdt:
    kind: train
    inputs: [filter]
    params:
      model: mdt_editor
      config:
        variant: mdt
        model: &model {dim: 32, cond_layers: 1, layers: 2, heads: 4, ff: 64, sim_hidden: 32, text_encoder: {layers: 1, vocab: 200}}
        aux: {mode: classes, classes: 3}
      data: {max_frames: 60}
      steps: 4
      batch_size: 4
      warmup: 0
  mdm:
    kind: train
    inputs: [filter]
    params: {model: mdt_editor, config: {variant: mdm, model: *model}, data: {max_frames: 60}, steps: 2, batch_size: 4, warmup: 0}
  edit_mdt:
    kind: edit
    inputs: [mdt, corpus]
    shards: 2
    params: {split: test, limit: 3, sampler: ddim, steps: 4, batch: 2}
  singles: {kind: singles, inputs: [corpus], params: {labeler: lexicon}}
  evaluator:
    kind: train
    inputs: [singles]
    params:
      model: temos_sinc
      config: {variant: tmr, model: {latent: 32, layers: 1, heads: 2, ff: 64, text_encoder: {layers: 1, vocab: 200}}}
      data: {real_pairs: false, synthetic_p: 0, max_frames: 60}
      steps: 2
      batch_size: 4
      warmup: 0
  eval_mdt:
    kind: eval_edit
    inputs: [evaluator, edit_mdt, corpus]
    params: {evaluator: evaluator, edits: edit_mdt, batch: 2, history: HISTORY, regression_margin: 0.0}
"""


def rotation_matrices(axis_angle):
    """Rodrigues: [..., 3] axis-angle -> [..., 3, 3] (compared as matrices: axis-angle is not unique)."""
    angle = np.linalg.norm(axis_angle, axis=-1, keepdims=True)
    axis = axis_angle / np.maximum(angle, 1e-12)
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    zero = np.zeros_like(x)
    k = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(axis.shape[:-1] + (3, 3))
    s, c = np.sin(angle)[..., None], np.cos(angle)[..., None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


NIGHTLY = """
name: nightly
output_root: OUT/../nightly
seed: 1
stages:
  corpus: {kind: corpus, params: {clips: 60, triplets: 60, shard_size: 30}}
  edit:
    kind: edit
    inputs: [corpus]
    shards: 1
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 2, batch: 2}
  score:
    kind: eval_edit
    inputs: [edit, corpus]
    params: {evaluator: "JOBS/evaluator", edits: edit, batch: 2, history: HISTORY, fail_on_regression: true}
"""


class EditTest(EngineTest):
    def test_train_edit_stage_and_cli(self):
        # An evaluation history whose best AvgR (0.5) no run can reach: this run is a regression.
        history = self.path("history.sqlite")
        with sqlite3.connect(history) as db:
            db.execute("CREATE TABLE history (id INTEGER PRIMARY KEY, time INTEGER, job TEXT, method TEXT, metric TEXT, "
                       "value REAL, higher_is_better INTEGER, checkpoint TEXT, config_hash TEXT, data_hash TEXT)")
            db.execute("INSERT INTO history (time, method, metric, value, higher_is_better, checkpoint) "
                       "VALUES (0, 'mdt_editor/mdt', 'generated_to_target.all.AvgR', 0.5, 0, 'an-old-checkpoint')")
        pipeline = self.write_pipeline("edit.yaml", PIPELINE.replace("HISTORY", history))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2", "--threads", "1"], capture_output=True, text=True, timeout=900)
        self.assertEqual(result.returncode, 0, result.stdout[-3000:] + result.stderr[-3000:])
        job = glob.glob(self.path("out", "edit_test-*"))[0]
        with open(os.path.join(job, "mdt", "task-00000", "losses.csv")) as f:
            header = f.readline().strip().split(",")
        self.assertIn("aux", header)  # the similarity task trained on the filter's classes
        self.assertIn("aux_accuracy", header)

        # The edit stage: 3 test triplets over 2 tasks, each edit as long as its source, finite.
        edited = {}
        for path in sorted(glob.glob(os.path.join(job, "edit_mdt", "task-*", "edited.npz"))):
            with np.load(path) as z:
                for i, clip in enumerate(z["ids"]):
                    a, b = z["offsets"][i], z["offsets"][i + 1]
                    edited[str(clip)] = z["poses"][a:b]
                    self.assertTrue(np.isfinite(z["poses"][a:b]).all())
        self.assertEqual(len(edited), 3)
        sources = {}
        for path in glob.glob(os.path.join(job, "corpus", "result", "motionfix", "triplets-*.npz")):
            with np.load(path) as z:
                for i, tid in enumerate(z["ids"]):
                    sources[str(tid)] = z["source_offsets"][i + 1] - z["source_offsets"][i]
        for tid, poses in edited.items():
            self.assertEqual(poses.shape, (sources[tid], 22, 3), tid)

        # eval_edit: retrieval of the 3 edits against their targets and sources, plausibility.
        with open(os.path.join(job, "eval_mdt", "task-00000", "metrics.json")) as f:
            metrics = json.load(f)
        self.assertEqual(metrics["motions"], 3)
        self.assertEqual(metrics["method"], "mdt_editor/mdt")
        for key in ("generated_to_target", "generated_to_source"):
            batches, everything = metrics[key]["batches"], metrics[key]["all"]
            self.assertEqual(batches["queries"], 2)  # one batch of 2, the third dropped
            self.assertEqual(everything["queries"], 3)
            self.assertTrue(1 <= everything["AvgR"] <= 3)
            self.assertTrue(0 <= everything["R@1"] <= everything["R@2"] <= everything["R@3"] == 100)
        for who in ("generated", "target"):
            self.assertIn("foot_skate_ratio", metrics["plausibility"][who])
        # The history got this run's metrics with the hashes, and the AvgR regression is reported.
        self.assertEqual([r["metric"] for r in metrics["regressions"]], ["generated_to_target.all.AvgR"])
        self.assertEqual(metrics["regressions"][0]["best_checkpoint"], "an-old-checkpoint")
        with sqlite3.connect(history) as db:
            rows = db.execute("SELECT metric, config_hash, data_hash FROM history WHERE job != ''").fetchall()
        self.assertEqual(sorted(r[0] for r in rows), ["generated_to_target.all.AvgR", "generated_to_target.all.R@1"])
        self.assertTrue(all(len(r[1]) == 16 and len(r[2]) == 16 for r in rows))

        # A scheduled-style evaluation that finds the newest checkpoints by path pattern, with the
        # history: the regression against the seeded AvgR fails the job (exit code 1) with its reason.
        nightly = self.write_pipeline("nightly.yaml", NIGHTLY.replace("JOBS", self.path("out", "edit_test-*")).replace("HISTORY", history))
        result = subprocess.run([MOTIONPIPE, "run", nightly, "--workers", "2", "--threads", "1"], capture_output=True, text=True, timeout=600)
        self.assertEqual(result.returncode, 1, result.stdout[-2000:] + result.stderr[-2000:])
        self.assertIn("regression: mdt_editor/mdt generated_to_target.all.AvgR regressed", result.stdout + result.stderr)
        with open(glob.glob(self.path("nightly", "nightly-*", "edit", "task-00000", "edits.json"))[0]) as f:
            self.assertEqual(json.load(f)["checkpoint"], os.path.join(job, "mdt", "task-00000", "model"))

        # motionpipe edit on a real CMU clip: the source's length, finite, repeatable under a seed.
        model = os.path.join(job, "mdt")
        outs = []
        for name, seed in (("a", "3"), ("b", "3"), ("c", "4")):
            out = self.path(f"{name}.npz")
            self.cli("edit", "--model", model, "--source", CMU, "--text", "raise the right arm higher", "--sampler", "ddim",
                     "--steps", "3", "--seed", seed, "--out", out, timeout=300)
            with np.load(out) as z:
                outs.append(z["poses"].copy())
        self.assertEqual(outs[0].shape, (249, 22, 3))
        self.assertTrue(np.isfinite(outs[0]).all())
        self.assertTrue(np.array_equal(outs[0], outs[1]))
        self.assertFalse(np.array_equal(outs[0], outs[2]))
        # MDM-BP keeps the body parts the text does not involve: the left leg's rotations are the source's.
        bp = self.path("bp.npz")
        self.cli("edit", "--model", os.path.join(job, "mdm"), "--body-parts", "--source", self.path("a.npz"),
                 "--text", "raise the right arm higher", "--sampler", "ddim", "--steps", "3", "--out", bp, timeout=300)
        with np.load(bp) as z, np.load(self.path("a.npz")) as src:
            left_leg = [1, 4, 7, 10]  # SMPL-22 left hip, knee, ankle, foot
            kept = rotation_matrices(z["poses"][:, left_leg]) - rotation_matrices(src["poses"][:, left_leg])
            self.assertLess(np.abs(kept).max(), 1e-3)
            edited_arm = rotation_matrices(z["poses"][:, 17]) - rotation_matrices(src["poses"][:, 17])  # right shoulder
            self.assertGreater(np.abs(edited_arm).max(), 1e-2)
        refused = self.cli("edit", "--model", model, "--body-parts", "--source", CMU, "--text", "x", "--out", bp, check=False)
        self.assertEqual(refused.returncode, 1)
        self.assertIn("body_parts (MDM-BP) runs mdm checkpoints", refused.stderr)


if __name__ == "__main__":
    unittest.main()
