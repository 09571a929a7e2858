"""The similarity filter (SimMotionEdit sec. 3.2.1) against the independent NumPy reference in
bench/reference/similarity_ref.py, its handling of bad triplets, and the `filter` stage through
workers (sharded output identical to the in-process filter)."""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

import numpy as np

from harness import MOTIONPIPE

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.dirname(os.path.dirname(HERE))
REFERENCE = os.path.join(SOURCE, "bench", "reference", "similarity_ref.py")
TOLERANCE = 1e-5


def run(args, **kwargs):
    result = subprocess.run(args, capture_output=True, text=True, timeout=600, **kwargs)
    if result.returncode != 0:
        raise AssertionError(f"{args} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return result.stdout


def read_json(path):
    with open(path) as f:
        return json.load(f)


def load_shards(directory):
    """Concatenates every task's similarity.npz under `directory` (task order)."""
    tasks = sorted(d for d in os.listdir(directory) if d.startswith("task-"))
    merged = {}
    for task in tasks:
        with np.load(os.path.join(directory, task, "similarity.npz")) as z:
            for key in ("ids", "snr", "similarity", "classes", "combined", "raw_rot", "raw_loc"):
                if key in z.files:
                    merged.setdefault(key, []).append(z[key])
            lengths = np.diff(z["offsets"])
            merged.setdefault("lengths", []).append(lengths)
    return {k: np.concatenate(v) for k, v in merged.items()}


class SimilarityTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="mp-similarity-")
        cls.corpus = os.path.join(cls.tmp, "corpus")
        run([MOTIONPIPE, "data", "synth-corpus", "--clips", "30", "--triplets", "90", "--shard-size", "30",
             "--no-amass", "--seed", "7", "--out", cls.corpus])
        cls.files = sorted(os.path.join(cls.corpus, "motionfix", f)
                           for f in os.listdir(os.path.join(cls.corpus, "motionfix")) if f.endswith(".npz"))

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def compare(self, name, cpp_args, ref_args, classes, tolerance=TOLERANCE):
        out = os.path.join(self.tmp, name)
        run([MOTIONPIPE, "data", "filter", self.corpus, "--out", out, "--threads", "2"] + cpp_args)
        ref_path = os.path.join(self.tmp, name + "-ref.npz")
        run(["/usr/bin/python3", REFERENCE, *self.files, "--out", ref_path] + ref_args)
        cpp = load_shards(out)
        dropped = read_json(os.path.join(out, "dropped.json"))
        with np.load(ref_path) as z:
            ref = {k: z[k] for k in z.files}

        # The same triplets are kept, and every SNR agrees (kept and dropped alike).
        ref_kept = [str(i) for i, k in zip(ref["ids"], ref["kept"]) if k]
        self.assertEqual([str(i) for i in cpp["ids"]], ref_kept)
        self.assertGreater(len(ref_kept), 0.5 * len(ref["ids"]))
        cpp_snr = {str(i): s for i, s in zip(cpp["ids"], cpp["snr"])}
        cpp_snr.update({d["id"]: d["snr"] for d in dropped if "snr" in d})
        for tid, snr in zip(ref["ids"], ref["snr"]):
            if np.isfinite(snr):
                self.assertAlmostEqual(cpp_snr[str(tid)] / snr, 1.0, delta=tolerance, msg=f"SNR of {tid}")

        # Curves of the kept triplets: raw branches (eq. 4), combined (eq. 5), normalised (eq. 6).
        ref_rows = {str(t): k for k, t in enumerate(ref["computed_ids"])}
        starts = np.concatenate([[0], np.cumsum(cpp["lengths"])])
        for k, tid in enumerate(cpp["ids"]):
            r = ref_rows[str(tid)]
            a, b = ref["computed_offsets"][r], ref["computed_offsets"][r + 1]
            c0, c1 = starts[k], starts[k + 1]
            for key in ("raw_rot", "raw_loc", "combined"):
                err = np.max(np.abs(cpp[key][c0:c1] - ref[key][a:b]))
                self.assertLess(err, tolerance, f"{key} of {tid}")
        err = np.max(np.abs(cpp["similarity"] - ref["normalized"]))
        self.assertLess(err, tolerance, "normalised curves")

        # Classes (eq. 10) agree wherever the curve is not within the tolerance of a class boundary.
        if classes:
            boundaries = np.arange(1, classes) / classes
            near = np.min(np.abs(ref["normalized"][:, None] - boundaries[None, :]), axis=1) < tolerance
            same = cpp["classes"] == ref["classes"]
            self.assertTrue(np.all(same | near), f"{np.sum(~same & ~near)} frames classed differently")
            self.assertLess(np.sum(near), 0.001 * len(near) + 1)
            self.assertEqual(len(np.unique(cpp["classes"])), classes)
        return out

    def test_paper_constants_agree_with_reference(self):
        out = self.compare("paper", [], [], 3)
        summary = read_json(os.path.join(out, "summary.json"))
        self.assertEqual(summary["triplets"], 90)
        self.assertEqual(summary["options"]["kappa"], 5)
        with open(os.path.join(out, "summary.png"), "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")

    def test_other_constants_agree_with_reference(self):
        self.compare("custom",
                     ["--preset", "reference", "--set", "window=8", "--set", "smooth=4", "--set", "w_rot=0.5",
                      "--set", "classes=5", "--set", "snr_threshold=1.5"],
                     ["--kappa", "10", "--window", "8", "--smooth", "4", "--w-rot", "0.5", "--classes", "5",
                      "--snr-threshold", "1.5"], 5)

    def test_forward_kinematics_locations_agree_with_stored_joints(self):
        # locations: fk recomputes the joints from the poses (float32) instead of reading the stored
        # ones, so the two differ by float rounding (~1e-7 m); on triplets whose curve spans a few
        # millimetres that is a few 1e-6 after min-max normalisation.
        self.compare("fk", ["--set", "locations=fk"], [], 3, tolerance=5e-5)

    def test_bad_triplets_are_dropped_with_reasons(self):
        with np.load(self.files[0]) as z:
            data = {k: z[k] for k in z.files}
        n = len(data["ids"])
        # Rebuild the file with damaged triplets: NaN, an empty source, a one-frame target, a short pair.
        def side_motion(side, row):
            a, b = data[f"{side}_offsets"][row], data[f"{side}_offsets"][row + 1]
            return [data[f"{side}_{k}"][a:b].copy() for k in ("poses", "trans", "joints")]
        rows = {side: [side_motion(side, r) for r in range(n)] for side in ("source", "target")}
        rows["source"][0][0][5, 3, 1] = np.nan                       # NaN in a pose
        rows["source"][1] = [m[:0] for m in rows["source"][1]]       # zero-length source
        rows["target"][2] = [m[:1] for m in rows["target"][2]]       # one-frame target
        rows["source"][3] = [m[:12] for m in rows["source"][3]]      # too short
        rows["target"][4][2][7, 0, 0] = np.inf                       # Inf in the stored joints
        bad = dict(data)
        for side in ("source", "target"):
            lengths = [len(m[0]) for m in rows[side]]
            bad[f"{side}_offsets"] = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
            for k, key in enumerate(("poses", "trans", "joints")):
                bad[f"{side}_{key}"] = np.concatenate([m[k] for m in rows[side]])
        bad_dir = os.path.join(self.tmp, "bad")
        os.makedirs(bad_dir, exist_ok=True)
        np.savez(os.path.join(bad_dir, "triplets-bad.npz"), **bad)
        # A file whose target poses carry 24 joints (SMPL) while the source has 22.
        mismatch = dict(data)
        mismatch["target_poses"] = np.concatenate([data["target_poses"], np.zeros((len(data["target_poses"]), 2, 3), np.float32)], axis=1)
        np.savez(os.path.join(bad_dir, "triplets-mismatch.npz"), **mismatch)

        out = os.path.join(self.tmp, "bad-out")
        run([MOTIONPIPE, "data", "filter", bad_dir, "--out", out])
        dropped = {(os.path.basename(d["file"]), d["row"]): d for d in read_json(os.path.join(out, "dropped.json"))}
        expect = {0: "non_finite", 1: "empty", 2: "one_frame", 3: "too_short", 4: "non_finite"}
        for row, reason in expect.items():
            entry = dropped[("triplets-bad.npz", row)]
            self.assertEqual(entry["reason"], reason, entry)
            self.assertTrue(entry["detail"])
        for row in range(n):
            self.assertEqual(dropped[("triplets-mismatch.npz", row)]["reason"], "bad_shape")
        self.assertIn("24", dropped[("triplets-mismatch.npz", 0)]["detail"])
        summary = read_json(os.path.join(out, "summary.json"))
        self.assertEqual(summary["triplets"], 2 * n)
        self.assertGreater(summary["kept"], 0)
        # The good triplets of the damaged file keep exactly the curves they have in the clean file.
        clean = os.path.join(self.tmp, "clean-first")
        run([MOTIONPIPE, "data", "filter", self.files[0], "--out", clean])
        a, b = load_shards(clean), load_shards(out)
        self.assertEqual(list(b["ids"]), [i for i in a["ids"] if i not in {str(data["ids"][r]) for r in expect}])

    def test_filter_stage_through_workers_matches_in_process(self):
        pipeline = os.path.join(self.tmp, "filter.yaml")
        with open(pipeline, "w") as f:
            f.write(f"""name: filtertest
output_root: {self.tmp}/jobs
stages:
  filter:
    kind: filter
    shards: 3
    params: {{triplets: "{self.corpus}", kappa: 5}}
""")
        env = dict(os.environ, MOTIONPIPE_LOG="warn")
        run([MOTIONPIPE, "run", pipeline, "--workers", "2", "-q"], env=env)
        job = os.path.join(self.tmp, "jobs", "filtertest-1", "filter")
        staged = load_shards(job)
        self.assertEqual(len([d for d in os.listdir(job) if d.startswith("task-")]), 3)
        local = os.path.join(self.tmp, "local")
        run([MOTIONPIPE, "data", "filter", self.corpus, "--out", local, "--threads", "1"])
        single = load_shards(local)
        for key in ("ids", "snr", "similarity", "classes", "combined", "raw_rot", "raw_loc"):
            self.assertTrue(np.array_equal(staged[key], single[key]), key)
        summary = read_json(os.path.join(job, "result", "summary.json"))
        self.assertEqual(summary["triplets"], 90)
        self.assertEqual(summary["shards"], 3)

    def test_bad_options_are_rejected_before_running(self):
        pipeline = os.path.join(self.tmp, "bad.yaml")
        with open(pipeline, "w") as f:
            f.write(f"""name: badfilter
output_root: {self.tmp}/jobs
stages:
  filter: {{kind: filter, params: {{triplets: "{self.corpus}", kappa: 0, windw: 3}}}}
""")
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "-q"], capture_output=True, text=True, timeout=60)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("windw", result.stderr + result.stdout)


if __name__ == "__main__":
    unittest.main()
