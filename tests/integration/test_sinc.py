"""SINC's synthetic pairs end to end: the singles and synth stages through workers, determinism of
shards, agreement of the C++ composition + features with the NumPy reference
(bench/reference/sinc_compose_ref.py), exports, composing real CMU clips, and the labelers that need
more than one process (llm against a local HTTP server, learned through its training stage)."""
import http.server
import json
import os
import shutil
import subprocess
import tempfile
import threading
import unittest

import numpy as np

from harness import MOTIONPIPE

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.dirname(os.path.dirname(HERE))
REFERENCE = os.path.join(SOURCE, "bench", "reference", "sinc_compose_ref.py")


def run(args, **kwargs):
    result = subprocess.run(args, capture_output=True, text=True, timeout=600, **kwargs)
    if result.returncode != 0:
        raise AssertionError(f"{args} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return result.stdout


PIPELINE = """name: {name}
output_root: {root}
seed: 3
stages:
  corpus: {{kind: corpus, params: {{clips: 60, triplets: 0, shard_size: 30}}}}
  singles: {{kind: singles, inputs: [corpus], params: {{labeler: lexicon}}}}
  synth:
    kind: synth
    inputs: [singles]
    params: {{pairs: 3000, shard_size: 1000, crop: centre}}
"""


class SincTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="mp-sinc-")
        cls.env = dict(os.environ, MOTIONPIPE_LOG="warn")
        cls.jobs = {}
        for name in ("first", "again"):
            root = os.path.join(cls.tmp, name)
            path = os.path.join(cls.tmp, name + ".yaml")
            with open(path, "w") as f:
                f.write(PIPELINE.format(name=name, root=root))
            run([MOTIONPIPE, "run", path, "--workers", "2", "-q"], env=cls.env)
            cls.jobs[name] = os.path.join(root, name + "-1")

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_shards_are_reproducible_byte_for_byte(self):
        first, again = (os.path.join(self.jobs[k], "synth") for k in ("first", "again"))
        tasks = sorted(d for d in os.listdir(first) if d.startswith("task-"))
        self.assertEqual(len(tasks), 3)
        for task in tasks:
            with open(os.path.join(first, task, "pairs.npz"), "rb") as a, open(os.path.join(again, task, "pairs.npz"), "rb") as b:
                self.assertEqual(a.read(), b.read(), task)
        with open(os.path.join(first, "result", "summary.json")) as f:
            summary = json.load(f)
        self.assertEqual(summary["pairs"], 3000)
        self.assertLess(summary["bytes_per_pair"], 40)
        with np.load(os.path.join(first, "task-00000", "pairs.npz")) as z:
            self.assertTrue(np.all((z["first_parts"] & z["second_parts"]) == 0))
            self.assertTrue(np.all(z["first_parts"] > 0) and np.all(z["second_parts"] > 0))

    def test_features_agree_with_numpy_reference(self):
        job = self.jobs["first"]
        spans = os.path.join(job, "singles", "task-00000", "spans.npz")
        pairs = os.path.join(job, "synth", "task-00001", "pairs.npz")
        out = os.path.join(self.tmp, "features.npz")
        run([MOTIONPIPE, "sinc", "export", pairs, "--spans", spans, "--features", "--limit", "400", "--out", out])
        ref = os.path.join(self.tmp, "ref.npz")
        run(["/usr/bin/python3", REFERENCE, spans, pairs, "--limit", "400", "--out", ref])
        with np.load(out) as a, np.load(ref) as b:
            self.assertTrue(np.array_equal(a["offsets"], b["offsets"]))
            err = np.max(np.abs(a["features"] - b["features"]))
            self.assertLess(err, 1e-6)
            self.assertEqual(a["features"].shape[1], 135)
            self.assertEqual(len(a["texts"]), 400)

    def test_export_motions_and_texts(self):
        out = os.path.join(self.tmp, "pairs.npz")
        text = run([MOTIONPIPE, "sinc", "export", os.path.join(self.jobs["first"], "synth"), "--limit", "25", "--out", out])
        self.assertIn("25 pairs", text)
        with np.load(out) as z:
            self.assertEqual(str(z["format"]), "motionpipe.clips/1")
            self.assertEqual(len(z["ids"]), 25)
            self.assertTrue(all(len(t) > 3 for t in z["texts"]))
            self.assertTrue(np.all(np.isfinite(z["poses"])))
            self.assertEqual(z["seg_parts"].shape, (50, 6))

    def test_random_composition_variant(self):
        path = os.path.join(self.tmp, "random.yaml")
        root = os.path.join(self.tmp, "random")
        with open(path, "w") as f:
            f.write(PIPELINE.format(name="random", root=root))
        run([MOTIONPIPE, "run", path, "stages.synth.params.parts=random", "stages.synth.params.pairs=500", "-q"], env=self.env)
        with np.load(os.path.join(root, "random-1", "synth", "task-00000", "pairs.npz")) as z:
            self.assertTrue(np.all((z["first_parts"] & z["second_parts"]) == 0))
            self.assertGreater(len(set(z["first_parts"].tolist())), 10)  # not the labelled sets

    def test_composing_cmu_clips_exports_bvh(self):
        out = os.path.join(self.tmp, "cmu.bvh")
        cmu = os.path.join(SOURCE, "data", "mocap", "cmu")
        text = run([MOTIONPIPE, "sinc", "compose", os.path.join(cmu, "131_01.bvh"), os.path.join(cmu, "131_02.bvh"),
                    "--text-a", "walk forward", "--text-b", "wave right hand", "--out", out])
        self.assertIn("from B: right arm", text)
        info = run([MOTIONPIPE, "data", "info", out])
        self.assertIn("249 frames", info)

    def test_llm_labeler_retries_and_caches(self):
        calls = {"n": 0}

        class Handler(http.server.BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_POST(self):
                calls["n"] += 1
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                if calls["n"] == 1:  # the first request fails: the labeler must retry
                    self.send_response(503)
                    self.end_headers()
                    return
                prompt = body.get("prompt") or body["messages"][0]["content"]
                action = prompt.rsplit("action of: ", 1)[1].split("?")[0]
                answer = " right arm\nneck" if "wave" in action else " right leg\nleft leg\nbuttocks"
                if "messages" in body:
                    reply = {"choices": [{"message": {"role": "assistant", "content": "Answer:" + answer}}]}
                else:
                    reply = {"choices": [{"text": answer}]}
                data = json.dumps(reply).encode()
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

        server = http.server.HTTPServer(("127.0.0.1", 0), Handler)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        try:
            cache = os.path.join(self.tmp, "llm-cache")
            config = json.dumps({"endpoint": f"http://127.0.0.1:{server.server_port}/v1", "cache_dir": cache, "backoff": 0.01})
            out = run([MOTIONPIPE, "labels", "label", "--labeler", "llm", "--config", config, "wave hello", "walk"])
            self.assertIn("torso+right arm", out)
            self.assertIn("global+left leg+right leg", out)
            self.assertEqual(calls["n"], 3)  # one failure, two answers
            run([MOTIONPIPE, "labels", "label", "--labeler", "llm", "--config", config, "wave hello", "walk"])
            self.assertEqual(calls["n"], 3)  # both answers come from the cache now
            chat = json.dumps({"endpoint": f"http://127.0.0.1:{server.server_port}/v1", "api": "chat",
                               "cache_dir": cache + "-chat", "backoff": 0.01})
            self.assertIn("torso+right arm", run([MOTIONPIPE, "labels", "label", "--labeler", "llm", "--config", chat, "wave"]))
        finally:
            server.shutdown()
        # A server that is not there: a clear error after the retries.
        dead = json.dumps({"endpoint": "http://127.0.0.1:9/v1", "cache_dir": cache + "-dead", "retries": 1, "backoff": 0.01,
                           "timeout": 2})
        result = subprocess.run([MOTIONPIPE, "labels", "label", "--labeler", "llm", "--config", dead, "jump"],
                                capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 1)
        self.assertIn("after 2 attempts", result.stderr)

    def test_learned_labeler_trains_as_a_stage(self):
        path = os.path.join(self.tmp, "labeler.yaml")
        root = os.path.join(self.tmp, "labeler")
        gpt = os.path.join(SOURCE, "data", "text", "babel_action_labels_gpt3.json")
        with open(path, "w") as f:
            f.write(f"name: lab\noutput_root: {root}\nstages:\n  train: {{kind: labeler.train, params: {{gpt: {gpt}, epochs: 3}}}}\n")
        run([MOTIONPIPE, "run", path, "--workers", "1", "-q"], env=self.env)
        model = os.path.join(root, "lab-1", "train", "task-00000")
        self.assertTrue(os.path.exists(os.path.join(model, "learned_labeler.pt")))
        out = run([MOTIONPIPE, "labels", "eval", "--labeler", "learned", "--config", json.dumps({"model": model}),
                   "--gpt", gpt, "--split", "heldout"])
        mean = float(out.strip().splitlines()[-1].split()[-1])
        self.assertGreater(mean, 0.8, out)


if __name__ == "__main__":
    unittest.main()
