"""`train_bench --quality` (bench/tmr_quality.cc) on a small corpus: the PyTorch-Python TMR
(bench/reference/tmr_ref.py) computes the same loss as plugins/temos_sinc from the weights and batch
the C++ side exports (the premise of its time-to-quality comparison), both trainers are scored at
every checkpoint, and a damaged export or spans file is an error that names the file."""
import os
import re
import shutil
import subprocess
import tempfile
import textwrap
import unittest

from harness import MOTIONPIPE

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.dirname(os.path.dirname(HERE))
TRAIN_BENCH = os.environ.get("MOTIONPIPE_TRAIN_BENCH", "train_bench")
REFERENCE = os.path.join(SOURCE, "bench", "reference", "tmr_ref.py")


def run(args, expect_ok=True, **kwargs):
    result = subprocess.run(args, capture_output=True, text=True, timeout=600, **kwargs)
    if expect_ok and result.returncode != 0:
        raise AssertionError(f"{args} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return result


class TmrReference(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="motionpipe_tmr_reference_")
        pipeline = os.path.join(cls.tmp, "corpus.yaml")
        with open(pipeline, "w") as f:
            f.write(textwrap.dedent(f"""\
                name: tmr_reference
                output_root: {cls.tmp}/job
                seed: 1
                stages:
                  corpus: {{kind: corpus, params: {{clips: 200, triplets: 0, shard_size: 100, manner_words: 1}}}}
                  singles: {{kind: singles, inputs: [corpus], params: {{labeler: lexicon}}}}
                """))
        run([MOTIONPIPE, "run", pipeline, "--workers", "1", "--threads", "1", "-q"])
        found = [os.path.join(d, "spans.npz") for d, _, files in os.walk(cls.tmp) if "spans.npz" in files]
        assert len(found) == 1, found
        cls.spans = found[0]
        cls.dir = os.path.join(cls.tmp, "bench")
        cls.out = run([TRAIN_BENCH, "--quality", "--spans", cls.spans, "--quality-steps", "4", "--every", "2",
                       "--dir", cls.dir]).stdout

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def assert_same_loss(self, out):
        match = re.search(r"dropout off, initial weights: C\+\+ ([0-9.]+), Python ([0-9.]+); "
                          r"C\+\+ first training loss ([0-9.]+)", out)
        self.assertIsNotNone(match, out)
        cpp, python, first = (float(g) for g in match.groups())
        self.assertGreater(cpp, 0.1, out)  # a real loss, not an empty batch's
        self.assertAlmostEqual(cpp, python, delta=1e-4 * cpp, msg=out)
        self.assertNotEqual(cpp, first, "training has dropout on: its loss differs from eval mode's")

    def test_the_reference_computes_the_same_loss_from_the_same_weights_and_batch(self):
        self.assertIn("at demo size (latent 128, 2 layers, feed-forward 512, 1 text layer(s))", self.out)
        self.assert_same_loss(self.out)

    def test_at_the_papers_size_too(self):
        out = run([TRAIN_BENCH, "--quality", "--quality-size", "paper", "--spans", self.spans,
                   "--quality-steps", "1", "--every", "1", "--dir", os.path.join(self.tmp, "paper")]).stdout
        self.assertIn("at paper size (latent 256, 6 layers, feed-forward 1024, 2 text layer(s))", out)
        self.assert_same_loss(out)

    def test_an_unknown_size_is_refused(self):
        result = run([TRAIN_BENCH, "--quality", "--quality-size", "huge", "--spans", self.spans,
                      "--dir", os.path.join(self.tmp, "huge")], expect_ok=False)
        self.assertEqual(result.returncode, 2)
        self.assertIn("--quality-size huge: not a size (demo, paper)", result.stderr)

    def test_both_trainers_are_scored_before_training_and_at_every_checkpoint(self):
        rows = re.findall(r"^\s+(\d+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)$", self.out, re.M)
        self.assertEqual([int(r[0]) for r in rows], [0, 2, 4], self.out)
        queries = int(re.search(r"(\d+) test singles", self.out).group(1))
        # Step 0, the untrained yardstick: the same weights encode the same test set, so both read
        # the same R@1 (within one query, should two cosines tie to float precision).
        _, cpp_s, cpp_r1, py_s, py_r1 = rows[0]
        self.assertEqual((float(cpp_s), float(py_s)), (0.0, 0.0))
        self.assertLessEqual(abs(float(cpp_r1) - float(py_r1)), 100 / queries + 1e-9, self.out)
        for _, cpp_s, cpp_r1, py_s, py_r1 in rows[1:]:
            self.assertGreater(float(cpp_s), 0)
            self.assertGreater(float(py_s), 0)
            for r1 in (float(cpp_r1), float(py_r1)):
                self.assertTrue(0 <= r1 <= 100, self.out)
        self.assertRegex(self.out, r"minutes of training to R@1 40: C\+\+ .*, Python ")

    def test_bf16_trains_both_sides_under_autocast_where_the_cpu_has_bf16_products(self):
        out = run([TRAIN_BENCH, "--quality", "--quality-precision", "bf16", "--spans", self.spans,
                   "--quality-steps", "2", "--every", "2", "--dir", os.path.join(self.tmp, "bf16")]).stdout
        precision = re.search(r"seed \d+, (float32|bf16), \d+ thread", out)
        self.assertIsNotNone(precision, out)
        with open("/proc/cpuinfo") as f:
            flags = f.read()
        native = "avx512_bf16" in flags or "amx_bf16" in flags
        self.assertEqual(precision.group(1), "bf16" if native else "float32", out)
        self.assert_same_loss(out)  # the eval-mode loss is float32 on both sides
        rows = re.findall(r"^\s+(\d+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)$", out, re.M)
        self.assertEqual([int(r[0]) for r in rows], [0, 2], out)
        bad = run([TRAIN_BENCH, "--quality", "--quality-precision", "fp8", "--spans", self.spans],
                  expect_ok=False)
        self.assertEqual(bad.returncode, 2)
        self.assertIn("--quality-precision float32|bf16", bad.stderr)

    def test_a_missing_initial_weight_is_named(self):
        damaged = os.path.join(self.tmp, "damaged")
        shutil.copytree(self.dir, damaged)
        os.remove(os.path.join(damaged, "init", "decoder.out.weight.npy"))
        result = run(["/usr/bin/python3", REFERENCE, "--dir", damaged, "--steps", "2", "--every", "2"],
                     expect_ok=False)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("no initial value for decoder.out.weight", result.stderr)
        self.assertIn(os.path.join(damaged, "init"), result.stderr)

    def test_more_steps_than_exported_is_refused(self):
        result = run(["/usr/bin/python3", REFERENCE, "--dir", self.dir, "--steps", "5", "--every", "5"],
                     expect_ok=False)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(os.path.join(self.dir, "features.npy") + ": 4 steps written, 5 asked", result.stderr)

    def test_an_unreadable_spans_file_is_named(self):
        bad = os.path.join(self.tmp, "bad_spans.npz")
        with open(bad, "w") as f:
            f.write("not an npz")
        result = run([TRAIN_BENCH, "--quality", "--spans", bad, "--quality-steps", "1", "--every", "1",
                      "--dir", os.path.join(self.tmp, "bad")], expect_ok=False)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn(bad, result.stderr)


if __name__ == "__main__":
    unittest.main()
