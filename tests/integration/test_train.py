"""The train stage and the temos_sinc plugin through real workers: two ranks take the same step as one
rank on the union batch, the exported state dict loads in Python's torch, `motionpipe generate`
writes the requested duration, and a gang that loses a rank resumes from its checkpoint and finishes
on the same loss curve as an uninterrupted run."""
import csv
import glob
import io
import json
import os
import signal
import struct
import subprocess
import sys
import unittest
import zipfile

import numpy as np

from harness import MOTIONPIPE, EngineTest, torch_load

# Rodrigues, the NumPy reference's (one copy in the repository).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench", "reference"))
from similarity_ref import rotation_matrices  # noqa: E402

CMU = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "data", "mocap", "cmu", "131_01.bvh")

PIPELINE = """
name: train_test
output_root: OUT
seed: 1
vars: {world: 1, steps: 2, dropout: 0.0, every: 100, lr: 0.001, split: train, validate: 0}
stages:
  corpus: {kind: corpus, params: {clips: 40, triplets: 0, shard_size: 20}}
  singles: {kind: singles, inputs: [corpus], params: {labeler: lexicon}}
  sinc:
    kind: train
    inputs: [singles]
    world_size: "${vars.world}"
    params:
      model: temos_sinc
      config:
        variant: sinc
        model: {latent: 32, layers: 1, heads: 2, ff: 64, dropout: "${vars.dropout}",
                text_encoder: {layers: 1, vocab: 200}}
      data: {synthetic_p: 0.5, max_frames: 60}
      steps: "${vars.steps}"
      batch_size: 8
      lr: "${vars.lr}"
      warmup: 0
      schedule: constant
      checkpoint_every: "${vars.every}"
      validate_every: "${vars.validate}"
      collective_timeout: 20
  gen:
    kind: generate
    inputs: [sinc, singles]
    params: {model: sinc, split: "${vars.split}", spans: all, limit: 4}
  evaluate:
    kind: eval_generate
    inputs: [sinc, gen, singles]
    params: {evaluator: sinc, generated: gen, batch: 2, synthetic_pairs: 6}
  recon:
    kind: generate
    inputs: [sinc, singles]
    shards: 1
    params: {model: sinc, split: "${vars.split}", spans: all, limit: 4, reconstruct: true}
"""

COMPOSED = """
name: composed_test
output_root: OUT
seed: 1
stages:
  model:
    kind: train
    params:
      model: temos_sinc
      config: {variant: sinc, model: {latent: 16, layers: 1, heads: 2, ff: 32, dropout: 0.0, text_encoder: {layers: 1, vocab: 100}}}
      data: {spans: SPANS/spans.npz, synthetic_p: 0, max_frames: 30}
      steps: 0
  gen:
    kind: generate
    inputs: [model]
    shards: 1
    params: {model: model, singles: SPANS, split: test, spans: pairs}
  composed:
    kind: eval_generate
    inputs: [model, gen]
    params: {evaluator: model, generated: gen, singles: SPANS, batch: 4, composed_truth: true}
"""


def write_spans(path, spans):
    """A `motionpipe.spans/1` file from (id, split, text_a, text_b, parts_a, parts_b, motion) rows, each
    motion a (poses [F, 22, 3], trans [F, 3]) pair at 30 fps. Stored uncompressed with every array's
    data 64-byte aligned in the file, as motionpipe writes it (its reader maps poses and trans in
    place; np.savez does not align them)."""
    column = lambda k: np.array([row[k] for row in spans])
    arrays = {"format": np.array("motionpipe.spans/1"), "ids": column(0), "splits": column(1), "sources": column(0),
              "fps": np.full(len(spans), 30.0),
              "offsets": np.concatenate([[0], np.cumsum([len(m[0]) for *_, m in spans])]).astype(np.int64),
              "poses": np.concatenate([m[0] for *_, m in spans]).astype(np.float32),
              "trans": np.concatenate([m[1] for *_, m in spans]).astype(np.float32),
              "text_a": column(2), "text_b": column(3), "parts_a": column(4).astype(np.uint8),
              "parts_b": column(5).astype(np.uint8), "labeler": np.array("test")}
    with open(path, "wb") as raw, zipfile.ZipFile(raw, "w", zipfile.ZIP_STORED) as z:
        for name, array in arrays.items():
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, array, allow_pickle=False)
            data = buffer.getvalue()
            header = 10 + int.from_bytes(data[8:10], "little")  # npy version 1: magic, version, length
            info = zipfile.ZipInfo(name + ".npy")
            pad = -(raw.tell() + 30 + len(info.filename) + header) % 64
            pad += 64 if 0 < pad < 4 else 0
            info.extra = struct.pack("<HH", 0xCAFE, pad - 4) + bytes(pad - 4) if pad else b""
            z.writestr(info, data)


def losses(job_dir, name="losses.csv"):
    with open(os.path.join(job_dir, "sinc", "task-00000", name)) as f:
        return list(csv.DictReader(f))


class TrainStageTest(EngineTest):
    def run_pipeline(self, name, workers, *overrides):
        pipeline = self.write_pipeline(f"{name}.yaml", PIPELINE.replace("OUT", self.path(name)))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", str(workers), "--threads", "1", *overrides],
                                capture_output=True, text=True, timeout=600)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        jobs = glob.glob(self.path(name, "train_test-*"))
        self.assertEqual(len(jobs), 1)
        return jobs[0]

    def test_two_ranks_take_the_step_of_one_rank_on_the_union_batch(self):
        # Adam's first steps move every parameter by about lr whatever its gradient's size, so float
        # rounding in the all-reduce shows up scaled by lr: a small lr keeps the comparison at 1e-5.
        one = self.run_pipeline("one", 1, "vars.world=1", "vars.lr=0.0001")
        two = self.run_pipeline("two", 2, "vars.world=2", "vars.lr=0.0001")
        a = torch_load(os.path.join(one, "sinc", "task-00000", "state_dict.pt"))
        b = torch_load(os.path.join(two, "sinc", "task-00000", "state_dict.pt"))
        self.assertEqual(sorted(a), sorted(b))
        self.assertTrue(any(k.startswith("decoder.") and k.endswith("linear1.weight") for k in a), sorted(a))
        worst = max(float(np.abs(a[k] - b[k]).max()) for k in a)
        self.assertLess(worst, 1e-5)
        # ... and the parameters did move (the comparison is not of two initialisations).
        with open(os.path.join(two, "sinc", "task-00001", "rank-1.json")) as f:
            self.assertEqual(json.load(f)["world_size"], 2)
        self.assertEqual([r["step"] for r in losses(one)], ["0", "1"])
        for r1, r2 in zip(losses(one), losses(two)):
            self.assertAlmostEqual(float(r1["loss"]), float(r2["loss"]), places=5)

        # The generate and eval_generate stages: 4 spans over 2 tasks, each at its ground truth's
        # length; the TEMOS score in [0, 1], APE/AVE and retrieval.
        generated = {}
        for path in glob.glob(os.path.join(two, "gen", "task-*", "generated.npz")):
            with np.load(path) as z:
                for i, sid in enumerate(z["ids"]):
                    generated[str(sid)] = z["offsets"][i + 1] - z["offsets"][i]
        self.assertEqual(len(generated), 4)
        with open(os.path.join(two, "evaluate", "task-00000", "metrics.json")) as f:
            metrics = json.load(f)
        self.assertEqual(metrics["motions"], 4)
        self.assertTrue(0 <= metrics["temos_score"] <= 1)
        # Each span's own TEMOS score, by id; their mean is the TEMOS score.
        self.assertEqual(sorted(m["id"] for m in metrics["per_motion"]), sorted(generated))
        self.assertAlmostEqual(np.mean([m["temos_score"] for m in metrics["per_motion"]]), metrics["temos_score"], places=9)
        self.assertGreater(metrics["APE"]["mean_global"], 0)
        # synthetic_pairs: 6 pairs of each kind from the training singles, scored text against motion;
        # the two kinds are different draws (labels' parts and random parts), real pairs beside them.
        synthetic = metrics["synthetic_pairs"]
        self.assertEqual(synthetic["split"], "train")
        for kind in ("labels", "random", "labels_first_alone", "random_first_alone", "labels_random_parts"):
            self.assertEqual(synthetic[kind]["motions"], 6)
            self.assertEqual(synthetic[kind]["text_to_motion"]["queries"], 6)
            self.assertTrue(-1 <= synthetic[kind]["text_motion_cosine"] <= 1)
        self.assertNotEqual(synthetic["labels"]["text_motion_cosine"], synthetic["random"]["text_motion_cosine"])
        self.assertLessEqual(synthetic.get("real_pairs", {"motions": 0})["motions"], 6)
        self.assertEqual(metrics["text_to_generated"]["batches"]["queries"], 4)
        self.assertEqual(metrics["generated_to_truth"]["all"]["queries"], 4)
        # reconstruct: each span's ground truth through the motion encoder and the decoder, at its
        # length, named as a reconstruction, and not the text's generation.
        with np.load(os.path.join(two, "recon", "task-00000", "generated.npz")) as z:
            recon = {str(sid): z["poses"][z["offsets"][i]:z["offsets"][i + 1]] for i, sid in enumerate(z["ids"])}
        self.assertEqual({k: len(v) for k, v in recon.items()}, generated)
        for k, v in recon.items():
            self.assertTrue(np.isfinite(v).all(), k)
        with open(os.path.join(two, "recon", "task-00000", "generate.json")) as f:
            self.assertEqual(json.load(f)["model"], "temos_sinc/sinc (reconstruction)")
        texts = {}
        for path in glob.glob(os.path.join(two, "gen", "task-*", "generated.npz")):
            with np.load(path) as z:
                texts.update({str(sid): z["poses"][z["offsets"][i]:z["offsets"][i + 1]] for i, sid in enumerate(z["ids"])})
        self.assertFalse(all(np.array_equal(texts[k], recon[k]) for k in recon))
        # generate: the requested duration, finite, as a clip file and as BVH.
        clip = self.path("walk.npz")
        self.cli("generate", "--model", os.path.join(two, "sinc"), "--text", "walk forward while waving the right hand",
                 "--seconds", "2.5", "--out", clip)
        with np.load(clip) as z:
            self.assertEqual(z["poses"].shape, (75, 22, 3))
            self.assertTrue(np.isfinite(z["poses"]).all() and np.isfinite(z["trans"]).all())
            self.assertEqual(str(z["texts"][0]), "walk forward while waving the right hand")
        # Post-processed: the legs of a real clip's nearest window (a BVH as the database), planted;
        # the upper body and the pelvis's path are the raw generation's, and both plausibilities
        # are printed.
        post = self.path("walk_post.npz")
        printed = self.cli("generate", "--model", os.path.join(two, "sinc"), "--text", "walk forward while waving the right hand",
                           "--seconds", "2.5", "--out", post, "--match-legs", CMU, "--foot-lock").stdout
        self.assertIn("match_legs: database of 1 motions, 249 frames at 30 fps", printed)
        self.assertRegex(printed, r"plausibility, match_legs \+ foot_lock: foot skate \d\.\d{3}")
        feet = [1, 2, 4, 5, 7, 8, 10, 11]  # hips, knees, ankles, toes
        upper = [j for j in range(22) if j not in feet]
        with np.load(clip) as raw, np.load(post) as z:
            self.assertTrue(np.array_equal(z["poses"][:, upper], raw["poses"][:, upper]))
            self.assertFalse(np.array_equal(z["poses"][:, feet], raw["poses"][:, feet]))
            self.assertTrue(np.array_equal(z["trans"][:, :2], raw["trans"][:, :2]))
        bvh = self.path("pair.bvh")
        self.cli("generate", "--model", os.path.join(two, "sinc"), "--text", "walk forward", "--text", "wave the right hand",
                 "--seconds", "2", "--fps", "20", "--out", bvh)
        with open(bvh) as f:
            text = f.read()
        self.assertIn("Frames: 40", text)
        refused = self.cli("generate", "--model", os.path.join(two, "sinc"), "--text", "a", "--compositing", "--out", clip, check=False)
        self.assertEqual(refused.returncode, 1)
        self.assertIn("compositing runs single-action models", refused.stderr)
        missing = self.cli("generate", "--model", self.dir, "--text", "a", "--out", clip, check=False)
        self.assertIn("not a checkpoint", missing.stderr)

    def test_ema_writes_the_moving_average_of_the_steps_weights(self):
        # params.ema: the model written is the average of the initial weights w0 and those after each
        # step, w1 and w2, at the warmed-up decays min(ema, (1 + step) / (10 + step)): 1/10, then 2/11.
        # Training itself is the same (the same losses at every step).
        jobs = [self.run_pipeline(f"w{k}", 1, f"vars.steps={k}") for k in range(3)]
        w = [torch_load(os.path.join(job, "sinc", "task-00000", "state_dict.pt")) for job in jobs]
        averaged_job = self.run_pipeline("ema", 1, "vars.steps=2", "stages.sinc.params.ema=0.999")
        averaged = torch_load(os.path.join(averaged_job, "sinc", "task-00000", "state_dict.pt"))
        self.assertEqual(sorted(averaged), sorted(w[2]))
        moved = [k for k in w[2] if not np.array_equal(w[0][k], w[2][k])]
        self.assertTrue(any(k.startswith("decoder.") for k in moved), moved)
        for k in averaged:
            e1 = 0.1 * w[0][k] + 0.9 * w[1][k]
            expected = (2 / 11) * e1 + (9 / 11) * w[2][k]
            np.testing.assert_allclose(averaged[k], expected, atol=1e-6, err_msg=k)
        self.assertEqual([r["loss"] for r in losses(averaged_job)], [r["loss"] for r in losses(jobs[2])])
        # A decay outside [0, 1) is refused, naming the parameter.
        pipeline = self.write_pipeline("bad.yaml", PIPELINE.replace("OUT", self.path("bad")))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "1", "--threads", "1",
                                 "stages.sinc.params.ema=1"], capture_output=True, text=True, timeout=300)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("params.ema must be in [0, 1)", result.stdout + result.stderr)

    def test_a_model_at_10_fps_generates_at_the_asked_rate_and_length(self):
        # Issue 15: `fps: 10` trains on every third frame; generating and reconstructing come back
        # to the spans' 30 fps at their lengths, and `motionpipe generate` to the asked duration.
        job = self.run_pipeline("tenth", 1, "stages.sinc.params.config.fps=10")
        with open(glob.glob(os.path.join(job, "sinc", "task-*", "model", "model.json"))[0]) as f:
            self.assertEqual(json.load(f)["config"]["fps"], 10)
        lengths = {}
        for stage in ("gen", "recon"):
            lengths[stage] = {}
            for path in glob.glob(os.path.join(job, stage, "task-*", "generated.npz")):
                with np.load(path) as z:
                    self.assertTrue(np.isfinite(z["poses"]).all())
                    for i, sid in enumerate(z["ids"]):
                        lengths[stage][str(sid)] = int(z["offsets"][i + 1] - z["offsets"][i])
        self.assertEqual(len(lengths["gen"]), 4)
        self.assertEqual(lengths["gen"], lengths["recon"])
        with np.load(glob.glob(self.path("tenth", "train_test-*", "singles", "task-*", "spans.npz"))[0]) as z:
            truth = {str(sid): int(z["offsets"][i + 1] - z["offsets"][i]) for i, sid in enumerate(z["ids"])}
        self.assertEqual(lengths["gen"], {k: truth[k] for k in lengths["gen"]})
        self.assertTrue(any(n % 3 != 1 for n in truth.values()))  # lengths a 10-fps grid does not hit
        clip = self.path("tenth.npz")
        self.cli("generate", "--model", os.path.join(job, "sinc"), "--text", "walk forward", "--seconds", "2.5",
                 "--out", clip)
        with np.load(clip) as z:
            self.assertEqual(z["poses"].shape, (75, 22, 3))
            self.assertEqual(float(z["fps"][0]), 30)
        # upsample: cubic brings the same network frames back through a spline: equal to slerp's at
        # every third frame, different between; a name it does not know is refused.
        def generated(run):
            into = {}
            for path in glob.glob(os.path.join(run, "gen", "task-*", "generated.npz")):
                with np.load(path) as z:
                    for i, sid in enumerate(z["ids"]):
                        into[str(sid)] = z["poses"][z["offsets"][i]:z["offsets"][i + 1]].copy()
            return into
        cubic_job = self.run_pipeline("tenth_cubic", 1, "stages.sinc.params.config.fps=10",
                                      "stages.gen.params.options.upsample=cubic")
        linear, cubic = generated(job), generated(cubic_job)
        self.assertEqual(sorted(cubic), sorted(linear))
        for sid in cubic:
            np.testing.assert_allclose(rotation_matrices(cubic[sid][::3]), rotation_matrices(linear[sid][::3]), atol=1e-5)
        self.assertFalse(all(np.array_equal(cubic[sid], linear[sid]) for sid in cubic))
        pipeline = self.write_pipeline("spline.yaml", PIPELINE.replace("OUT", self.path("spline")))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "1", "--threads", "1",
                                 "stages.sinc.params.config.fps=10", "stages.gen.params.options.upsample=spline"],
                                capture_output=True, text=True, timeout=300)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("generate option upsample must be linear or cubic (got 'spline')", result.stdout + result.stderr)

    def test_composed_truth_composes_each_pair_from_the_singles_that_bear_its_texts(self):
        # eval_generate's composed_truth on a spans file made here: two test pairs "walk forward while
        # wave the right hand" whose two singles (training split: none in the pairs' own) share the
        # pairs' very motion, so any composition of them is the truth itself (TEMOS score 1, APE 0),
        # while singles with other motions are there to be matched wrongly; a pair whose second text
        # no single bears (unmatched), and one whose singles' labelled parts overlap (incompatible).
        rng = np.random.default_rng(3)
        walk = (rng.normal(0, 0.2, (40, 22, 3)), np.cumsum(rng.normal(0, 0.01, (40, 3)), axis=0) + [0, 0, 0.9])
        other = (rng.normal(0, 0.2, (40, 22, 3)), np.cumsum(rng.normal(0, 0.01, (40, 3)), axis=0) + [0, 0, 0.9])
        longer = (rng.normal(0, 0.2, (60, 22, 3)), np.cumsum(rng.normal(0, 0.01, (60, 3)), axis=0) + [0, 0, 0.9])
        spans = [("s_walk_long", "train", "walk forward", "", 0b000011, 0, longer),  # first, but farther in length
                 ("s_walk", "train", "walk forward", "", 0b000011, 0, walk),
                 ("s_wave", "train", "wave the right hand", "", 0b110000, 0, walk),
                 ("s_kick", "train", "kick", "", 0b000011, 0, other),
                 ("s_step", "train", "step", "", 0b000001, 0, other),
                 ("p_1", "test", "walk forward", "wave the right hand", 0b000011, 0b110000, walk),
                 ("p_2", "test", "walk forward", "wave the right hand", 0b000011, 0b110000, walk),
                 ("p_unmatched", "test", "walk forward", "jump high", 0b000011, 0b000001, other),
                 ("p_incompatible", "test", "kick", "step", 0b000011, 0b000001, other)]
        os.makedirs(self.path("spans"))
        write_spans(self.path("spans", "spans.npz"), spans)
        pipeline = self.write_pipeline("composed.yaml", COMPOSED.replace("SPANS", self.path("spans")))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "1", "--threads", "1", "-q"],
                                capture_output=True, text=True, timeout=300)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        with open(glob.glob(self.path("out", "composed_test-*", "composed", "task-00000", "metrics.json"))[0]) as f:
            composed = json.load(f)["yardsticks"]["composed"]
        self.assertEqual((composed["pairs"], composed["spans"], composed["unmatched"], composed["incompatible"]), (4, 2, 1, 1))
        self.assertEqual(sorted(composed["ids"]), ["p_1", "p_2"])
        for kind in ("labels", "random", "first_alone"):
            self.assertAlmostEqual(composed[kind]["temos_score"], 1.0, places=5, msg=kind)
            self.assertLess(composed[kind]["APE"]["mean_global"], 1e-4, kind)
        difference = composed["temos_score_difference"]["labels_minus_random"]
        self.assertEqual(difference["n"], 2)
        self.assertAlmostEqual(difference["mean"], 0.0, places=5)
        # A split without two-action spans is refused with the reason.
        refused = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "1", "--threads", "1", "-q", "name=refused",
                                  "stages.composed.params.composed_split=val"], capture_output=True, text=True, timeout=300)
        self.assertNotEqual(refused.returncode, 0)
        self.assertIn("composed_split 'val' has no two-action spans", refused.stdout + refused.stderr)

    def test_bad_model_configs_fail_the_task_with_the_reason(self):
        for overrides, reason in ((["stages.sinc.params.model=no_such_model"], "no model plugin 'no_such_model'"),
                                  (["stages.sinc.params.config.model.heads=3"], "must be divisible by heads"),
                                  (["stages.sinc.params.batch_size=7", "vars.world=2"], "must be divisible by world_size 2"),
                                  (["stages.sinc.params.precision=half"], "params.precision must be float32 or bf16, not 'half'")):
            pipeline = self.write_pipeline("bad.yaml", PIPELINE.replace("OUT", self.path("bad")))
            result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2", "--threads", "1", *overrides],
                                    capture_output=True, text=True, timeout=300)
            self.assertNotEqual(result.returncode, 0)
            self.assertIn(reason, result.stdout + result.stderr)

    def test_a_gang_that_loses_a_rank_resumes_from_its_checkpoint_and_finishes(self):
        # With a moving average of the weights (params.ema), which rank 0 checkpoints, validates and
        # writes as the model: the resumed gang must find it in the checkpoint and write the
        # uninterrupted run's model. (Started afresh at the resume instead, this early in the run the
        # warm-up of its decay would forget the difference: what is checked is that it is carried.)
        overrides = ["vars.world=2", "vars.steps=160", "vars.dropout=0.1", "vars.every=20", "vars.validate=20",
                     "stages.sinc.params.ema=0.99"]
        reference = self.run_pipeline("reference", 2, *overrides)

        self.coordinator()
        workers = {name: self.worker(name, extra=["--threads", "1"]) for name in ("w0", "w1", "w2")}
        pipeline = self.write_pipeline("killed.yaml", PIPELINE.replace("OUT", self.path("killed")))
        job = self.submit(pipeline, *overrides)
        job_dir = None

        def checkpointed():
            nonlocal job_dir
            found = glob.glob(self.path("killed", "train_test-*", "sinc", "state", "latest"))
            if found:
                job_dir = os.path.dirname(os.path.dirname(os.path.dirname(found[0])))
            return bool(found)

        self.wait_until(checkpointed, 240, "the first checkpoint")
        busy = [w["id"] for w in self.status()["workers"] if w.get("running", 0) > 0 and w["id"] in workers]
        self.assertTrue(busy, self.status())
        workers[busy[0]].send(signal.SIGKILL)
        code, out = self.wait_job(job, timeout=400)
        self.assertEqual(code, 0, out)
        ranks = []
        for path in sorted(glob.glob(os.path.join(job_dir, "sinc", "task-*", "rank-*.json"))):
            with open(path) as f:
                ranks.append(json.load(f))
        self.assertEqual(len(ranks), 2)
        self.assertTrue(all(r["resumed_from"] > 0 and r["resumed_from"] % 20 == 0 for r in ranks), ranks)
        # The curve has every step once and continues the uninterrupted run's curve.
        resumed, uninterrupted = losses(job_dir), losses(reference)
        self.assertEqual([int(r["step"]) for r in resumed], list(range(160)))
        for a, b in zip(resumed, uninterrupted):
            self.assertAlmostEqual(float(a["loss"]), float(b["loss"]), places=4, msg=f"step {a['step']}")
        # The validations too, with the training seconds counted across the resume (the attempt
        # before it up to its checkpoint, then this one) and the model's other terms beside the loss.
        val, val_reference = losses(job_dir, "val_losses.csv"), losses(reference, "val_losses.csv")
        self.assertEqual([int(r["step"]) for r in val], list(range(19, 160, 20)))
        for a, b in zip(val, val_reference):
            self.assertAlmostEqual(float(a["val_loss"]), float(b["val_loss"]), places=4, msg=f"step {a['step']}")
            # (32 held-out texts: one that changes its nearest motion moves it by 3.125)
            self.assertAlmostEqual(float(a["val_retrieval_r1"]), float(b["val_retrieval_r1"]), delta=3.2)
            self.assertTrue(0 <= float(a["val_retrieval_r1"]) <= 100, a)
        seconds = [float(r["seconds"]) for r in val]
        self.assertTrue(all(0 < x < y for x, y in zip(seconds, seconds[1:])), seconds)
        # The model written: the same moving average as the uninterrupted run's.
        written, uninterrupted_model = (torch_load(os.path.join(j, "sinc", "task-00000", "state_dict.pt"))
                                        for j in (job_dir, reference))
        for k in written:
            np.testing.assert_allclose(written[k], uninterrupted_model[k], atol=1e-5, err_msg=k)


if __name__ == "__main__":
    unittest.main()
