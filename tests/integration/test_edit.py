"""The mdt_editor plugin through real workers: the MDT (with its similarity task on the filter's
classes) and MDM train on filtered corpus triplets, the `edit` stage edits the test split across
workers, and `motionpipe edit` edits a real CMU clip, deterministically under a seed; an editor
trained twice under one seed, on two workers at once, is the same model."""
import base64
import csv
import glob
import html.parser
import http.server
import io
import json
import math
import os
import sqlite3
import statistics
import subprocess
import sys
import threading
import unittest

import numpy as np

from harness import MOTIONPIPE, EngineTest, free_port, torch_load

HERE = os.path.dirname(os.path.abspath(__file__))
# Rodrigues, the NumPy reference's (one copy in the repository; tools/root_stats.py reads it too).
sys.path.insert(0, os.path.join(HERE, "..", "..", "bench", "reference"))
from similarity_ref import rotation_matrices  # noqa: E402

CMU = os.path.join(HERE, "..", "..", "data", "mocap", "cmu", "131_01.bvh")

# The tiny MDT that PIPELINE and JUDGES train (their own YAML documents: put in where TINY_MDT stands).
TINY_MDT = "{dim: 32, cond_layers: 1, layers: 2, heads: 4, ff: 64, sim_hidden: 32, text_encoder: {layers: 1, vocab: 200}}"

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
        model: &model TINY_MDT
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
  showcase:
    kind: showcase
    inputs: [mdt, evaluator, singles]
    params: {clips: CMU_DIR, max_frames: 40, editor: mdt, generator: evaluator, evaluator: evaluator, steps: 2, panel_size: 96,
             clip_text: walk forward, edit_text: raise the right arm higher, clips_label: CMU, editor_label: MDT}
  report:
    kind: report
    inputs: [eval_mdt, showcase]
    params: {history: HISTORY, panel_size: 96}
""".replace("TINY_MDT", TINY_MDT)


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
    params: {evaluator: "JOBS/evaluator", edits: edit, batch: 2, history: HISTORY, fail_on_regression: true, pushgateway: "GATEWAY"}
"""


# A finished job's edits rescored by two evaluators (the first job's and another seed's), and by the
# second alone: an earlier run judged again without editing again.
JUDGES = """
name: judges
output_root: OUT/../judges
seed: 1
stages:
  corpus: {kind: corpus, params: {clips: 60, triplets: 60, shard_size: 30}}
  singles: {kind: singles, inputs: [corpus], params: {labeler: lexicon}}
  evaluator_b:
    kind: train
    inputs: [singles]
    params:
      model: temos_sinc
      config: {variant: tmr, model: {latent: 32, layers: 1, heads: 2, ff: 64, text_encoder: {layers: 1, vocab: 200}}}
      data: {real_pairs: false, synthetic_p: 0, max_frames: 60}
      steps: 2
      batch_size: 4
      warmup: 0
      seed: 2
  eval_b:
    kind: eval_edit
    inputs: [evaluator_b, corpus]
    params: {evaluator: evaluator_b, edits: "JOBS/edit_mdt", batch: 2}
  eval_both:
    kind: eval_edit
    inputs: [evaluator_b, corpus]
    params: {evaluator: ["JOBS/evaluator", evaluator_b], edits: "JOBS/edit_mdt", batch: 2}
  guided:
    kind: edit
    inputs: [corpus]
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2}
  unguided:
    kind: edit
    inputs: [corpus]
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {guidance_motion: 1, guidance_text: 1}}
  guided_from_300:
    kind: edit
    inputs: [corpus]
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {guidance_from_step: 300}}
  guided_from_150:
    kind: edit
    inputs: [corpus]
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {guidance_from_step: 150}}
  planted_never:
    kind: edit
    inputs: [corpus]
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {foot_lock: {below_step: 0}}}
  planted:
    kind: edit
    inputs: [corpus]
    params: {model: "JOBS/mdt", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {foot_lock: {below_step: 300, max_speed: 5}}}
  locked:
    kind: foot_lock
    params: {motions: "JOBS/edit_mdt", max_speed: 5}
  filter: {kind: filter, inputs: [corpus], shards: 1, params: {preset: paper}}
  mdt_contacts:        # with the contact head (loss.contacts)
    kind: train
    inputs: [filter]
    params:
      model: mdt_editor
      config:
        variant: mdt
        model: TINY_MDT
        aux: {mode: classes, classes: 3}
        loss: {contacts: 1}
        fps: 10
      data: {max_frames: 20}
      steps: 4
      batch_size: 4
      warmup: 0
  contacts_raw:
    kind: edit
    inputs: [mdt_contacts, corpus]
    params: {model: mdt_contacts, split: test, limit: 2, sampler: ddim, steps: 4, batch: 2}
  contacts_locked:
    kind: edit
    inputs: [mdt_contacts, corpus]
    params: {model: mdt_contacts, split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {foot_lock: {contacts: predicted}}}
  contacts_near_floor: # the head's calls where the foot is near the floor
    kind: edit
    inputs: [mdt_contacts, corpus]
    params: {model: mdt_contacts, split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {foot_lock: {contacts: predicted_near_floor}}}
  contacts_or_test:    # those, or the height and speed test
    kind: edit
    inputs: [mdt_contacts, corpus]
    params: {model: mdt_contacts, split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {foot_lock: {contacts: predicted_or_test}}}
  contacts_cubic:      # the network's 10-fps frames brought to 30 by a spline
    kind: edit
    inputs: [mdt_contacts, corpus]
    params: {model: mdt_contacts, split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options: {upsample: cubic}}
  eval_locked:
    kind: eval_edit
    inputs: [evaluator_b, locked, corpus]
    params: {evaluator: evaluator_b, edits: locked, batch: 2}
  cleanup:             # the learned leg clean-up (plugins/leg_cleanup), tiny, on the corpus's triplets
    kind: train
    inputs: [corpus]
    params:
      model: leg_cleanup
      config: {width: 16, dilations: [1, 2], height: true, crop: 30, corruption: {shrink: 0.5}}
      steps: 3
      batch_size: 4
      warmup: 0
      validate_every: 3
      keep: best
  cleaned:
    kind: clean_legs
    inputs: [cleanup]
    params: {motions: "JOBS/edit_mdt"}
  cleaned_locked: {kind: foot_lock, inputs: [cleaned], params: {max_speed: 5}}
  matched:             # legs by motion matching (match_legs) from the corpus's training triplets
    kind: match_legs
    params: {motions: "JOBS/edit_mdt", database: "JOBS/corpus"}
""".replace("TINY_MDT", TINY_MDT)


# One editor trained twice under one seed, on two workers at once, and once under another: a claims
# run started again on the same machine trains the same editors (README "Claims runs").
SEEDED = """
name: seeded
output_root: OUT
seed: 1
stages:
  corpus: {kind: corpus, params: {clips: 60, triplets: 60, shard_size: 30}}
  filter: {kind: filter, inputs: [corpus], shards: 1, params: {preset: paper}}
  mdt_a:             # seeds 3 and 4: mdt_a and mdt_a-s2
    kind: train
    inputs: [filter]
    seeds: 2
    params: &train
      model: mdt_editor
      config:
        variant: mdt
        model: {dim: 32, cond_layers: 1, layers: 2, heads: 4, ff: 64, sim_hidden: 32, dropout: 0.1, text_encoder: {layers: 1, vocab: 200}}
        aux: {mode: classes, classes: 3}
        fps: 10
      data: {max_frames: 20}
      steps: 6
      batch_size: 4
      warmup: 2
      validate_every: 3
      keep: best
      seed: 3
  mdt_b: {kind: train, inputs: [filter], params: *train}   # seed 3 again
"""


class ReportParser(html.parser.HTMLParser):
    """Collects a report's tables (caption and rows of cell texts) and its images' data URIs."""

    def __init__(self):
        super().__init__()
        self.tables, self.images, self._cell, self._row, self._in_caption = [], [], None, None, False

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append({"caption": "", "rows": []})
        elif tag == "caption":
            self._in_caption = True
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = ""
        elif tag == "img":
            self.images.append(dict(attrs))

    def handle_endtag(self, tag):
        if tag == "caption":
            self._in_caption = False
        elif tag in ("td", "th") and self._row is not None:
            self._row.append(self._cell.strip())
            self._cell = None
        elif tag == "tr" and self.tables:
            self.tables[-1]["rows"].append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._in_caption and self.tables:
            self.tables[-1]["caption"] += data
        if self._cell is not None:
            self._cell += data


def check_report(test, path):
    """The report validates: every image is an embedded PNG or GIF that decodes with Pillow and has
    pixels of more than one colour; returns the parsed tables by caption."""
    from PIL import Image
    parser = ReportParser()
    with open(path, encoding="utf-8") as f:
        text = f.read()
    parser.feed(text)
    test.assertTrue(text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>"))
    test.assertNotIn('src="http', text)  # self-contained
    for image in parser.images:
        mime, _, data = image["src"].partition(";base64,")
        test.assertIn(mime, ("data:image/png", "data:image/gif"), image.get("alt"))
        decoded = Image.open(io.BytesIO(base64.b64decode(data)))
        decoded.load()
        test.assertGreater(decoded.size[0], 50)
        test.assertGreater(len(set(decoded.convert("RGB").getdata())), 2, image.get("alt"))
    return {t["caption"]: t["rows"] for t in parser.tables}, parser.images


class Gateway(http.server.BaseHTTPRequestHandler):
    """A Pushgateway stand-in on loopback: records each push's method, path and body."""
    pushes = []

    def do_PUT(self):
        body = self.rfile.read(int(self.headers.get("Content-Length", 0))).decode()
        Gateway.pushes.append((self.command, self.path, body))
        self.send_response(202)
        self.end_headers()

    do_POST = do_PUT

    def log_message(self, *args):
        pass


class EditTest(EngineTest):
    def test_train_edit_stage_and_cli(self):
        # An evaluation history whose best AvgR (0.5) no run can reach: this run is a regression.
        history = self.path("history.sqlite")
        with sqlite3.connect(history) as db:
            db.execute("CREATE TABLE history (id INTEGER PRIMARY KEY, time INTEGER, job TEXT, method TEXT, metric TEXT, "
                       "value REAL, higher_is_better INTEGER, checkpoint TEXT, config_hash TEXT, data_hash TEXT)")
            db.execute("INSERT INTO history (time, method, metric, value, higher_is_better, checkpoint) "
                       "VALUES (0, 'mdt_editor/mdt', 'generated_to_target.all.AvgR', 0.5, 0, 'an-old-checkpoint')")
        pipeline = self.write_pipeline("edit.yaml", PIPELINE.replace("HISTORY", history).replace("CMU_DIR", os.path.dirname(CMU)))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2", "--threads", "1"], capture_output=True, text=True, timeout=900)
        self.assertEqual(result.returncode, 0, result.stdout[-3000:] + result.stderr[-3000:])
        job = glob.glob(self.path("out", "edit_test-*"))[0]
        with open(os.path.join(job, "mdt", "task-00000", "losses.csv")) as f:
            header = f.readline().strip().split(",")
        self.assertIn("aux", header)  # the similarity task trained on the filter's classes
        self.assertIn("aux_accuracy", header)

        # The edit stage: 3 test triplets over 2 tasks, each edit as long as its target (the authors'
        # evaluation generates at length_target), finite.
        edited = {}
        for path in sorted(glob.glob(os.path.join(job, "edit_mdt", "task-*", "edited.npz"))):
            with np.load(path) as z:
                for i, clip in enumerate(z["ids"]):
                    a, b = z["offsets"][i], z["offsets"][i + 1]
                    edited[str(clip)] = z["poses"][a:b]
                    self.assertTrue(np.isfinite(z["poses"][a:b]).all())
        self.assertEqual(len(edited), 3)
        targets = {}
        for path in glob.glob(os.path.join(job, "corpus", "result", "motionfix", "triplets-*.npz")):
            with np.load(path) as z:
                for i, tid in enumerate(z["ids"]):
                    targets[str(tid)] = z["target_offsets"][i + 1] - z["target_offsets"][i]
        for tid, poses in edited.items():
            self.assertEqual(poses.shape, (targets[tid], 22, 3), tid)

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
        # The yardsticks in the same batches: the source as the edit retrieves its own source, the
        # target as the edit its own target; "towards the target" is to-target minus to-source R@1.
        copy, target = metrics["yardsticks"]["copy"], metrics["yardsticks"]["target"]
        self.assertEqual(copy["generated_to_source"]["all"]["R@1"], 100)
        self.assertEqual(target["generated_to_target"]["all"]["R@1"], 100)
        self.assertLessEqual(copy["towards_target"]["all"]["R@1"], 0)
        self.assertGreaterEqual(target["towards_target"]["all"]["R@1"], 0)
        # Per edit, by cosine in the evaluator's space: a copy is never closer to its target than to
        # its source, the target always is; every triplet is counted under its edit kind.
        self.assertEqual(copy["closer_to_target"]["fraction"], 0)
        self.assertEqual(target["closer_to_target"]["fraction"], 1)
        self.assertIn("closer_to_target", metrics["yardsticks"]["other_target"])  # chance
        closer = metrics["closer_to_target"]
        self.assertEqual(closer["triplets"], 3)
        self.assertEqual(sum(k["triplets"] for k in closer["by_edit_kind"].values()), 3)
        self.assertAlmostEqual(target["closer_to_target"]["cos_to_target"], 1, places=5)
        for row in (metrics, copy, target):
            self.assertAlmostEqual(row["towards_target"]["all"]["R@1"],
                                   row["generated_to_target"]["all"]["R@1"] - row["generated_to_source"]["all"]["R@1"])
            # Its standard error over the 3 edits (paired per edit); 0 only when every edit agrees.
            self.assertGreaterEqual(row["towards_target"]["all"]["se"], 0)
        # The target as the edit finds its target and, unless its source ranks first, not its source:
        # the paired differences are 0 (source first) or 100, and their standard error is the sample
        # deviation of those over sqrt(3), whatever the number of sources ranked first.
        sources_first = round(target["generated_to_source"]["all"]["R@1"] / 100 * 3)
        differences = [0.0] * sources_first + [100.0] * (3 - sources_first)
        self.assertAlmostEqual(target["towards_target"]["all"]["se"], statistics.stdev(differences) / math.sqrt(3), places=6)
        self.assertIn("fraction_se", closer)
        # The history got this run's metrics with the hashes, and the AvgR regression is reported.
        self.assertEqual([r["metric"] for r in metrics["regressions"]], ["generated_to_target.all.AvgR"])
        self.assertEqual(metrics["regressions"][0]["best_checkpoint"], "an-old-checkpoint")
        with sqlite3.connect(history) as db:
            rows = db.execute("SELECT metric, config_hash, data_hash FROM history WHERE job != ''").fetchall()
        self.assertEqual(sorted(r[0] for r in rows), ["generated_to_target.all.AvgR", "generated_to_target.all.R@1"])
        self.assertTrue(all(len(r[1]) == 16 and len(r[2]) == 16 for r in rows))

        # The CMU showcase: imported, composed with a corpus action, edited, scored, rendered.
        with open(os.path.join(job, "showcase", "task-00000", "showcase.json")) as f:
            showcase = json.load(f)
        rows = showcase["table"]["rows"]
        self.assertEqual([r[0] for r in rows[:3]], ["CMU 131_01 (imported)", "CMU 131_02 (imported)", "CMU 131_03 (imported)"])
        self.assertTrue(rows[-1][0].startswith("MDT edit: raise the right arm higher"))
        self.assertTrue(all(r[1] == 40 for r in rows[:3]))
        self.assertAlmostEqual(rows[0][-1], 1.0, places=5)  # the source's cosine to itself
        with np.load(os.path.join(job, "showcase", "task-00000", "edited.npz")) as z:
            self.assertEqual(z["poses"].shape, (40, 22, 3))

        # The report stage: the tables, every image embedded and decodable, the showcase included.
        tables, images = check_report(self, os.path.join(job, "report", "task-00000", "report.html"))
        table1 = tables["Editing: retrieval of the edits (batches)"]  # batches of 2 here
        # The yardstick rows first, then the method: mdt_editor/mdt is the paper's MDT row.
        self.assertEqual([r[0] for r in table1[2:]], ["source as the edit (copy)", "target as the edit (upper bound)", "another triplet's target as the edit (chance)", "SimMotionEdit (MDT)"])
        self.assertEqual(float(table1[3][2]), 100.0)  # the target as the edit: R@1 100
        self.assertEqual(table1[5][-4:], ["70.62", "82.92", "88.12", "2.38"])  # the paper's numbers beside ours
        self.assertAlmostEqual(float(table1[5][2]), metrics["generated_to_target"]["batches"]["R@1"], delta=0.006)
        self.assertIn("Claims", tables)
        self.assertTrue(any(r[1] == "MDT beats TMED" and r[2] == "not measured" for r in tables["Claims"][1:]))
        alts = [i["alt"] for i in images]
        self.assertIn("editing preview", alts)
        self.assertIn("training curve mdt", alts)
        self.assertIn("history generated_to_target.all.R@1", alts)
        self.assertTrue(any(a.startswith("Composition by body parts: walk forward while ") for a in alts), alts)
        # The same report from the command line, elsewhere.
        out = self.path("cli-report.html")
        printed = self.cli("report", job, "--out", out, "--history", history, "--size", "80").stdout
        self.assertIn("report: 1 edit and 0 generate methods, 3 train stages", printed)
        self.assertEqual(check_report(self, out)[0].keys(), tables.keys())

        # A scheduled-style evaluation that finds the newest checkpoints by path pattern, with the
        # history: the regression against the seeded AvgR fails the job (exit code 1) with its reason,
        # and the metrics and the regression are pushed to the (stand-in) Pushgateway.
        port = free_port()
        server = http.server.HTTPServer(("127.0.0.1", port), Gateway)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        self.addCleanup(server.shutdown)
        nightly = self.write_pipeline("nightly.yaml", NIGHTLY.replace("JOBS", self.path("out", "edit_test-*")).replace("HISTORY", history)
                                      .replace("GATEWAY", f"http://127.0.0.1:{port}"))
        result = subprocess.run([MOTIONPIPE, "run", nightly, "--workers", "2", "--threads", "1"], capture_output=True, text=True, timeout=600)
        self.assertEqual(result.returncode, 1, result.stdout[-2000:] + result.stderr[-2000:])
        self.assertIn("regression: mdt_editor/mdt generated_to_target.all.AvgR regressed", result.stdout + result.stderr)
        self.assertTrue(Gateway.pushes, "nothing was pushed to the gateway")
        method, path, body = Gateway.pushes[-1]
        self.assertEqual((method, path), ("POST", "/metrics/job/motionpipe_eval/pipeline/nightly/stage/score"))
        self.assertIn('motionpipe_eval_regression{method="mdt_editor/mdt",metric="generated_to_target.all.AvgR"} 1', body)
        self.assertIn('motionpipe_eval_regression{method="mdt_editor/mdt",metric="generated_to_target.all.R@1"} 0', body)
        self.assertIn('motionpipe_eval_regressions{method="mdt_editor/mdt"} 1', body)
        with open(glob.glob(self.path("nightly", "nightly-*", "edit", "task-00000", "edits.json"))[0]) as f:
            self.assertEqual(json.load(f)["checkpoint"], os.path.join(job, "mdt", "task-00000", "model"))

        # The first job's edits judged again by two evaluators (its own and another seed's): every
        # score is the mean of the two evaluators' own, the plausibility is the edits', and each
        # one's headline figures are listed.
        judges = JUDGES.replace("JOBS", self.path("out", "edit_test-*"))
        result = subprocess.run([MOTIONPIPE, "run", self.write_pipeline("judges.yaml", judges), "--workers", "2", "--threads", "1"],
                                capture_output=True, text=True, timeout=600)
        self.assertEqual(result.returncode, 0, result.stdout[-2000:] + result.stderr[-2000:])
        judged = {}
        for name in ("eval_b", "eval_both", "eval_locked"):
            with open(glob.glob(self.path("judges", "judges-*", name, "task-00000", "metrics.json"))[0]) as f:
                judged[name] = json.load(f)
        one, two, both = metrics, judged["eval_b"], judged["eval_both"]
        self.assertEqual(both["evaluator"], [one["evaluator"], two["evaluator"]])
        self.assertNotEqual(one["closer_to_target"]["cos_to_target"], two["closer_to_target"]["cos_to_target"])
        for keys in (("generated_to_target", "all", "AvgR"), ("generated_to_source", "all", "AvgR"),
                     ("towards_target", "all", "R@1"), ("closer_to_target", "cos_to_target"),
                     ("yardsticks", "other_target", "closer_to_target", "cos_to_target")):
            a, b, mean = one, two, both
            for key in keys:
                a, b, mean = a[key], b[key], mean[key]
            self.assertAlmostEqual(mean, (a + b) / 2, places=6, msg=keys)  # float32 embeddings
        self.assertEqual(both["closer_to_target"]["triplets"], 3)  # a count stays a count
        self.assertEqual(both["plausibility"], one["plausibility"])
        self.assertEqual([e["evaluator"] for e in both["by_evaluator"]], both["evaluator"])
        self.assertEqual([e["generated_to_target"] for e in both["by_evaluator"]],
                         [m["generated_to_target"]["batches"]["R@1"] for m in (one, two)])
        # The guidance interval: guided from step 300 of 300 is never guided (the same edits as
        # g_m = g_t = 1), from 150 is guided on the noisy half only (edits of their own).
        def edits(stage):
            with np.load(glob.glob(self.path("judges", "judges-*", stage, "task-*", "edited.npz"))[0]) as z:
                return z["poses"].copy()
        self.assertTrue(np.array_equal(edits("guided_from_300"), edits("unguided")))
        for a, b in (("guided", "unguided"), ("guided_from_150", "guided"), ("guided_from_150", "unguided")):
            self.assertFalse(np.array_equal(edits(a), edits(b)), (a, b))
        # Foot locking inside the sampler: below step 0 is never (the guided edits bit for bit);
        # at every step the edits are its own and finite.
        self.assertTrue(np.array_equal(edits("planted_never"), edits("guided")))
        self.assertFalse(np.array_equal(edits("planted"), edits("guided")))
        self.assertTrue(np.isfinite(edits("planted")).all())
        # foot_lock: the same edits with only the legs' rotations changed (hips, knees, ankles) and
        # the pelvis at most 10 cm lower (where a held foot is out of reach), scored as a row of
        # their own, never skating more than the raw edits.
        def by_clip(pattern):
            into = {}
            for path in glob.glob(os.path.join(pattern, "task-*", "edited.npz")):
                with np.load(path) as z:
                    for i, clip in enumerate(z["ids"]):
                        a, b = z["offsets"][i], z["offsets"][i + 1]
                        into[str(clip)] = (z["poses"][a:b].copy(), z["trans"][a:b].copy())
            return into
        legs = [1, 2, 4, 5, 7, 8]
        others = [j for j in range(22) if j not in legs]
        def only_legs_changed(raw, locked):
            self.assertEqual(sorted(locked), sorted(raw))
            for clip, (poses, trans) in locked.items():
                self.assertTrue(np.array_equal(trans[:, :2], raw[clip][1][:, :2]), clip)
                lowered = raw[clip][1][:, 2] - trans[:, 2]
                self.assertTrue(((lowered >= 0) & (lowered <= 0.1 + 1e-6)).all(), (clip, lowered.min(), lowered.max()))
                self.assertLess(np.abs(rotation_matrices(poses[:, others]) - rotation_matrices(raw[clip][0][:, others])).max(), 1e-5)
        raw, locked = by_clip(os.path.join(job, "edit_mdt")), by_clip(self.path("judges", "judges-*", "locked"))
        only_legs_changed(raw, locked)
        # The contact head: trained beside the x0 loss (its term in the log), it plants the edits'
        # feet where it says they stand, changing the legs and nothing else.
        with open(glob.glob(self.path("judges", "judges-*", "mdt_contacts", "task-00000", "losses.csv"))[0]) as f:
            logged = list(csv.DictReader(f))
        self.assertEqual(len(logged), 4)
        self.assertTrue(all(0 < float(row["contacts"]) < 5 for row in logged), logged)
        only_legs_changed(by_clip(self.path("judges", "judges-*", "contacts_raw")),
                          by_clip(self.path("judges", "judges-*", "contacts_locked")))
        only_legs_changed(by_clip(self.path("judges", "judges-*", "contacts_raw")),
                          by_clip(self.path("judges", "judges-*", "contacts_or_test")))
        # What the planting held is written beside the edits; the raw edits hold nothing.
        def counts(stage):
            with open(glob.glob(self.path("judges", "judges-*", stage, "task-00000", "edits.json"))[0]) as f:
                return json.load(f).get("counts")
        self.assertIsNone(counts("contacts_raw"))
        for stage in ("contacts_locked", "contacts_near_floor", "contacts_or_test"):
            self.assertEqual(sorted(counts(stage)), ["planted_foot_frames", "planted_runs", "planted_shift_m",
                                                     "unreached_ankle_frames"], stage)
        # The test's frames added to the calls near the floor hold no fewer frames.
        self.assertGreaterEqual(counts("contacts_or_test")["planted_foot_frames"],
                                counts("contacts_near_floor")["planted_foot_frames"])
        # Upsampled by the spline, the edits pass through the network's own frames (every third at
        # 30 fps, the same as slerp's) and differ between them.
        linear, cubic = by_clip(self.path("judges", "judges-*", "contacts_raw")), by_clip(self.path("judges", "judges-*", "contacts_cubic"))
        self.assertEqual(sorted(cubic), sorted(linear))
        for clip, (poses, trans) in cubic.items():
            np.testing.assert_allclose(rotation_matrices(poses[::3]), rotation_matrices(linear[clip][0][::3]), atol=1e-5)
            np.testing.assert_allclose(trans[::3], linear[clip][1][::3], atol=1e-6)
            self.assertFalse(np.array_equal(poses, linear[clip][0]), clip)
        bad = judges.replace("options: {upsample: cubic}", "options: {upsample: spline}").replace("name: judges", "name: badspline")
        result = subprocess.run([MOTIONPIPE, "run", self.write_pipeline("badspline.yaml", bad), "--workers", "1", "--threads", "1"],
                                capture_output=True, text=True, timeout=600)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("edit option upsample must be linear or cubic (got 'spline')", result.stdout + result.stderr)
        # Only a checkpoint with the head can say where its feet stand.
        headless = judges.replace("model: mdt_contacts, split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options",
                                  'model: "%s", split: test, limit: 2, sampler: ddim, steps: 4, batch: 2, options'
                                  % os.path.join(job, "mdt", "task-00000", "model"))
        result = subprocess.run([MOTIONPIPE, "run", self.write_pipeline("headless.yaml", headless.replace("name: judges", "name: headless")),
                                 "--workers", "1", "--threads", "1"], capture_output=True, text=True, timeout=600)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("foot_lock.contacts predicted needs a checkpoint trained with a contact head", result.stdout + result.stderr)
        # clean_legs: the edits with the legs' rotations and the pelvis height changed by the
        # clean-up, everything else bit for bit; named as the raw edits' model plus the clean-up,
        # and planted after it by foot_lock.
        cleaned = by_clip(self.path("judges", "judges-*", "cleaned"))
        self.assertEqual(sorted(cleaned), sorted(raw))
        for clip, (poses, trans) in cleaned.items():
            self.assertTrue(np.array_equal(poses[:, others], raw[clip][0][:, others]), clip)
            self.assertTrue(np.array_equal(trans[:, :2], raw[clip][1][:, :2]), clip)
            self.assertFalse(np.array_equal(poses[:, legs], raw[clip][0][:, legs]), clip)
            self.assertLess(np.abs(trans[:, 2] - raw[clip][1][:, 2]).max(), 0.05, clip)
        def model_of(stage):
            with open(glob.glob(self.path("judges", "judges-*", stage, "task-00000", "edits.json"))[0]) as f:
                return json.load(f)["model"]
        self.assertEqual(model_of("cleaned"), "mdt_editor/mdt + leg clean-up")
        self.assertEqual(model_of("cleaned_locked"), "mdt_editor/mdt + leg clean-up + foot lock")
        only_legs_changed(cleaned, by_clip(self.path("judges", "judges-*", "cleaned_locked")))
        # Only a leg_cleanup checkpoint cleans legs: an editor's is refused, by name.
        wrong = ("name: wrong\noutput_root: %s\nstages:\n  cleaned: {kind: clean_legs, params: {model: \"%s\", motions: \"%s\"}}\n"
                 % (self.path("judges"), os.path.join(job, "mdt", "task-00000", "model"), os.path.join(job, "edit_mdt")))
        result = subprocess.run([MOTIONPIPE, "run", self.write_pipeline("wrong.yaml", wrong), "--workers", "1", "--threads", "1"],
                                capture_output=True, text=True, timeout=120)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("checkpoint, not a leg_cleanup one", result.stdout + result.stderr)
        # match_legs: the edits with the legs (hips, knees, ankles, toes) of a training motion's
        # window, everything else bit for bit; its summary counts what it matched.
        matched = by_clip(self.path("judges", "judges-*", "matched"))
        self.assertEqual(sorted(matched), sorted(raw))
        feet = legs + [10, 11]
        for clip, (poses, trans) in matched.items():
            self.assertTrue(np.array_equal(poses[:, [j for j in range(22) if j not in feet]],
                                           raw[clip][0][:, [j for j in range(22) if j not in feet]]), clip)
            self.assertTrue(np.array_equal(trans, raw[clip][1]), clip)
        with open(glob.glob(self.path("judges", "judges-*", "matched", "task-00000", "edits.json"))[0]) as f:
            summary = json.load(f)
        self.assertEqual(summary["model"], "mdt_editor/mdt + matched legs")
        counts_matched = summary["match_legs"]
        self.assertEqual(counts_matched["matched"], len(raw))
        self.assertGreaterEqual(counts_matched["windows"], len(raw))
        self.assertTrue(any(not np.array_equal(poses[:, feet], raw[clip][0][:, feet]) for clip, (poses, _) in matched.items()))
        bad = self.write_pipeline("bad_match.yaml", judges.replace('database: "', 'sigma_seconds: -1, database: "'))
        result = subprocess.run([MOTIONPIPE, "run", bad, "--dry-run"], capture_output=True, text=True, timeout=60)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("stages.matched.params.sigma_seconds: must be >= 0 s", result.stdout + result.stderr)
        scored = judged["eval_locked"]
        self.assertEqual(scored["method"], "mdt_editor/mdt + foot lock")
        self.assertEqual(scored["motions"], 3)
        self.assertLessEqual(scored["plausibility"]["generated"]["foot_skate_ratio"],
                             two["plausibility"]["generated"]["foot_skate_ratio"])
        # A list that names what is neither an input nor a path is refused when the job is planned.
        bad = self.write_pipeline("bad.yaml", judges.replace("evaluator: [", "evaluator: [nowhere, "))
        result = subprocess.run([MOTIONPIPE, "run", bad, "--dry-run"], capture_output=True, text=True, timeout=60)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("stages.eval_both.params.evaluator: must name one of the stage's inputs", result.stdout + result.stderr)
        bad = self.write_pipeline("bad_lock.yaml", judges.replace("max_speed: 5", "max_speed: -1"))
        result = subprocess.run([MOTIONPIPE, "run", bad, "--dry-run"], capture_output=True, text=True, timeout=60)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("stages.locked.params.max_speed: must be > 0 m/s", result.stdout + result.stderr)

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
        # The same edit post-processed as the pipeline's stages do it: cleaned by the clean-up's
        # checkpoint, given the legs of the nearest window of the corpus's training triplets,
        # planted; only the legs and the pelvis height change, and the raw and the final
        # plausibility are printed.
        judged = glob.glob(self.path("judges", "judges-*"))[0]
        post = self.path("post.npz")
        printed = self.cli("edit", "--model", model, "--source", CMU, "--text", "raise the right arm higher", "--sampler", "ddim",
                           "--steps", "3", "--seed", "3", "--out", post, "--clean-legs", os.path.join(judged, "cleanup"),
                           "--match-legs", os.path.join(job, "corpus"), "--foot-lock", timeout=300).stdout
        self.assertIn("clean_legs: the legs cleaned by", printed)
        self.assertRegex(printed, r"match_legs: database of \d+ motions")
        self.assertRegex(printed, r"match_legs: \d+ window\(s\), cost \d+\.\d\d per compared frame")
        self.assertRegex(printed, r"foot_lock: \d+ foot-joint frames held")
        self.assertRegex(printed, r"plausibility, raw: foot skate \d\.\d{3} of contact frames")
        self.assertRegex(printed, r"plausibility, clean_legs \+ match_legs \+ foot_lock: foot skate \d\.\d{3}")
        feet = [1, 2, 4, 5, 7, 8, 10, 11]  # hips, knees, ankles, toes
        upper = [j for j in range(22) if j not in feet]
        with np.load(post) as z, np.load(self.path("a.npz")) as raw_edit:
            self.assertEqual(z["poses"].shape, raw_edit["poses"].shape)
            self.assertTrue(np.array_equal(z["poses"][:, upper], raw_edit["poses"][:, upper]))
            self.assertFalse(np.array_equal(z["poses"][:, feet], raw_edit["poses"][:, feet]))
            self.assertTrue(np.array_equal(z["trans"][:, :2], raw_edit["trans"][:, :2]))
            self.assertIn("+ clean_legs + match_legs + foot_lock:", str(z["sources"][0]))
        # Nothing asked, nothing changed: the raw edit and its plausibility.
        plain = self.cli("edit", "--model", model, "--source", CMU, "--text", "raise the right arm higher", "--sampler", "ddim",
                         "--steps", "3", "--seed", "3", "--out", post, timeout=300).stdout
        self.assertRegex(plain, r"plausibility: foot skate \d\.\d{3}")
        with np.load(post) as z, np.load(self.path("a.npz")) as raw_edit:
            self.assertTrue(np.array_equal(z["poses"], raw_edit["poses"]))
        # Wrong post-process inputs are errors that name them, refused before any model is loaded or
        # run (with a model path that does not exist, the post-process's error comes first; the edit
        # took minutes with the default 300-step DDPM on a busy machine), and nothing is written.
        os.remove(post)
        no_model = os.path.join(job, "no_such_model")
        refused = self.cli("edit", "--model", no_model, "--source", CMU, "--text", "x", "--out", post,
                           "--clean-legs", model, check=False)
        self.assertEqual(refused.returncode, 1)
        self.assertIn("is a mdt_editor checkpoint, not a leg_cleanup one", refused.stderr)
        refused = self.cli("edit", "--model", no_model, "--source", CMU, "--text", "x", "--out", post,
                           "--match-legs", self.path("nowhere.bvh"), check=False)
        self.assertEqual(refused.returncode, 1)
        self.assertIn("nowhere.bvh", refused.stderr)
        refused = self.cli("edit", "--model", no_model, "--source", CMU, "--text", "x", "--out", post,
                           "--match-legs", os.path.join(job, "corpus"), "--match-split", "nosuch", check=False)
        self.assertEqual(refused.returncode, 1)
        self.assertIn("no triplets of split 'nosuch'", refused.stderr)
        self.assertFalse(os.path.exists(post))
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


class SeededTrainingTest(EngineTest):
    def test_an_editor_trained_twice_under_one_seed_is_the_same_model(self):
        pipeline = self.write_pipeline("seeded.yaml", SEEDED.replace("OUT", self.path("out")))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2", "--threads", "1"],
                                capture_output=True, text=True, timeout=600)
        self.assertEqual(result.returncode, 0, result.stdout[-3000:] + result.stderr[-3000:])
        job = glob.glob(self.path("out", "seeded-*"))[0]

        def logged(stage):  # the training log, and the validation log without its wall-clock column
            task = os.path.join(job, stage, "task-00000")
            with open(os.path.join(task, "losses.csv")) as f, open(os.path.join(task, "val_losses.csv")) as g:
                validation = [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(g)]
                return f.read(), validation

        a, b, c = logged("mdt_a"), logged("mdt_b"), logged("mdt_a-s2")
        self.assertEqual(len(a[0].splitlines()), 7)  # the header and 6 steps
        self.assertEqual([row["step"] for row in a[1]], ["2", "5"])
        self.assertEqual(a, b)  # every step's losses and every validation, to the printed digit
        self.assertNotEqual(a[0], c[0])  # another seed: other batches, noise and dropout
        weights_a = torch_load(os.path.join(job, "mdt_a", "task-00000", "state_dict.pt"))
        weights_b = torch_load(os.path.join(job, "mdt_b", "task-00000", "state_dict.pt"))
        self.assertEqual(sorted(weights_a), sorted(weights_b))
        for name in weights_a:
            self.assertTrue(np.array_equal(weights_a[name], weights_b[name]), name)


if __name__ == "__main__":
    unittest.main()
