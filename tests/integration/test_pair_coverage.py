"""tools/pair_coverage.py (issue 15: which test action pairs the training's real pairs already hold)
on a vocabulary and spans whose figures are known by hand, on this tree's own vocabulary, and its
error messages for files that are not a vocabulary or a singles stage's spans."""
import json
import os
import subprocess
import tempfile
import unittest

import numpy as np

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "pair_coverage.py")

# Two definitions shaped as core/src/corpus/vocabulary.cc's, the last one ending its function.
VOCABULARY = """
std::vector<ActionDef> Some() {
  return {{A::kWalk, "walk", K::kLocomotion, true, false, G | LL | RL, 2, 4, 0, 0,
           {"walk", "walk forwards {speed}"}, {"a person walks {speed}"}},
          {A::kWave, "wave", K::kArm, false, true, RA, 1, 3, 0, 0,
           {"wave with {hand}", "wave"}, {"someone waves"}}};
}
const char* Other() { return "not a text"; }
"""


def run(*args):
    return subprocess.run(["/usr/bin/python3", TOOL, *args], capture_output=True, text=True, timeout=60)


class PairCoverageTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.addCleanup(self.tmp.cleanup)
        self.vocabulary = os.path.join(self.tmp.name, "vocabulary.cc")
        with open(self.vocabulary, "w") as f:
            f.write(VOCABULARY)

    def spans(self, rows, drop=()):
        path = os.path.join(self.tmp.name, "spans.npz")
        arrays = {"ids": np.array([f"{i}/0" for i in range(len(rows))]), "splits": np.array([r[0] for r in rows]),
                  "text_a": np.array([r[1] for r in rows]), "text_b": np.array([r[2] for r in rows])}
        for key in drop:
            del arrays[key]
        np.savez(path, **arrays)
        return path

    def test_paraphrases_of_a_training_pair_count_as_held(self):
        path = self.spans([
            ("train", "walk", "wave"),                         # the pair walk + wave, twice
            ("train", "a person walks slowly", "someone waves"),
            ("train", "wave with left hand", ""),              # a single: no pair
            ("test", "walk forwards", "wave with right hand"),  # walk + wave: held twice
            ("test", "wave", "a person walks quickly"),        # the same pair in the other order
            ("test", "walk", "jump"),                          # jump is no action of the vocabulary
            ("test", "wave", ""),                              # a single
        ])
        result = run(path, "--vocabulary", self.vocabulary, "--json")
        self.assertEqual(result.returncode, 0, result.stderr)
        got = json.loads(result.stdout)
        self.assertEqual(got["spans"], 3)
        self.assertEqual(got["pair_in_training"], 2)
        self.assertAlmostEqual(got["fraction_in_training"], 2 / 3)
        self.assertEqual(got["median_times_in_training"], 2)
        self.assertEqual((got["training_pairs"], got["training_distinct_action_pairs"]), (2, 1))
        self.assertEqual(got["texts_without_action"], ["jump"])

    def scores(self, name, row, seed, by_id, per_motion=True):
        """An eval_generate stage directory whose metrics hold `by_id`'s per-motion TEMOS scores."""
        stage = os.path.join(self.tmp.name, name)
        os.makedirs(os.path.join(stage, "task-00000"))
        metrics = {"row": row, "seed": seed, "temos_score": float(np.mean(list(by_id.values())))}
        if per_motion:
            metrics["per_motion"] = [{"id": i, "temos_score": v} for i, v in by_id.items()]
        with open(os.path.join(stage, "task-00000", "metrics.json"), "w") as f:
            json.dump(metrics, f)
        return stage

    def test_rows_are_scored_and_paired_by_seed_on_held_and_new_pairs(self):
        # Spans 1/0 and 2/0 (test) ask for walk + wave, held by span 0/0; span 3/0 for walk + sit (no
        # action of the vocabulary), new.
        path = self.spans([("train", "walk", "wave"), ("test", "walk", "wave"), ("test", "wave", "walk"), ("test", "walk", "sit")])
        stages = [self.scores("a1", "A", 1, {"1/0": 0.8, "2/0": 0.6, "3/0": 0.5}),
                  self.scores("a2", "A", 2, {"1/0": 0.9, "2/0": 0.9, "3/0": 0.6, "9/9": 0.0}),  # an id of no test span
                  self.scores("b1", "B", 1, {"1/0": 0.6, "2/0": 0.6, "3/0": 0.5}),
                  self.scores("b2", "B", 2, {"1/0": 0.7, "2/0": 0.7, "3/0": 0.3}),
                  self.scores("b3", "B", 3, {"1/0": 0.0, "2/0": 0.0, "3/0": 0.0})]  # a seed A lacks: not paired
        result = run(path, "--vocabulary", self.vocabulary, "--json", "--scores", *stages, "--compare", "A", "B")
        self.assertEqual(result.returncode, 0, result.stderr)
        got = json.loads(result.stdout)
        self.assertAlmostEqual(got["rows"]["A"]["held"], (0.7 + 0.9) / 2)
        self.assertAlmostEqual(got["rows"]["A"]["new"], (0.5 + 0.6) / 2)
        self.assertEqual(got["rows"]["B"]["seeds"], [1, 2, 3])
        held, new = got["compare"]["held"], got["compare"]["new"]
        self.assertEqual([round(d, 9) for d in held["per_seed"]], [0.1, 0.2])
        self.assertAlmostEqual(held["difference"], 0.15)
        self.assertAlmostEqual(held["two_standard_errors"], 2 * np.std([0.1, 0.2], ddof=1) / np.sqrt(2))
        self.assertEqual([round(d, 9) for d in new["per_seed"]], [0.0, 0.3])
        # A stage scored before `per_motion` existed, and a row not scored, are errors naming them.
        old = self.scores("old", "A", 3, {"1/0": 0.5}, per_motion=False)
        result = run(path, "--vocabulary", self.vocabulary, "--scores", old)
        self.assertEqual(result.returncode, 2)
        self.assertIn(os.path.join(old, "task-00000", "metrics.json"), result.stderr)
        self.assertIn("per_motion", result.stderr)
        result = run(path, "--vocabulary", self.vocabulary, "--scores", *stages[:2], "--compare", "A", "C")
        self.assertIn("no row 'C'", result.stderr)

    def test_by_texts_groups_spans_by_the_training_singles_texts_they_repeat_word_for_word(self):
        # Training singles' texts: "walk", "wave". A paraphrase ("a person walks slowly") of the same
        # action is not seen, nor is a training pair's text or another split's single; "jump" is no
        # action of the vocabulary and "sit" only a test single's: actions no training single performs.
        path = self.spans([
            ("train", "walk", ""), ("train", "wave", ""), ("test", "sit", ""),
            ("train", "a person walks slowly", "someone waves"),  # a pair: its texts do not count
            ("test", "walk", "wave"),                             # 4/0: both seen
            ("test", "wave", "a person walks slowly"),            # 5/0: one, the other paraphrased
            ("test", "sit", "someone waves"),                     # 6/0: none
            ("test", "wave", "walk"),                             # 7/0: both
            ("test", "walk", "jump"),                             # 8/0: one, the other's action unseen
        ])
        stages = [self.scores("a1", "A", 1, {"4/0": 0.8, "5/0": 0.7, "6/0": 0.6, "7/0": 0.6, "8/0": 0.5}),
                  self.scores("a2", "A", 2, {"4/0": 0.9, "5/0": 0.5, "6/0": 0.6, "7/0": 0.9, "8/0": 0.5}),
                  self.scores("b1", "B", 1, {"4/0": 0.6, "5/0": 0.7, "6/0": 0.5, "7/0": 0.6, "8/0": 0.7}),
                  self.scores("b2", "B", 2, {"4/0": 0.6, "5/0": 0.6, "6/0": 0.6, "7/0": 0.6, "8/0": 0.6})]
        result = run(path, "--vocabulary", self.vocabulary, "--json", "--by", "texts", "--scores", *stages,
                     "--compare", "A", "B")
        self.assertEqual(result.returncode, 0, result.stderr)
        got = json.loads(result.stdout)
        self.assertEqual(got["subsets"], {"both_texts_seen": 2, "one_paraphrased": 1, "one_action_unseen": 1,
                                          "no_text_seen": 1})
        self.assertAlmostEqual(got["rows"]["A"]["both_texts_seen"], ((0.8 + 0.6) / 2 + (0.9 + 0.9) / 2) / 2)
        self.assertEqual([round(d, 9) for d in got["compare"]["both_texts_seen"]["per_seed"]], [0.1, 0.3])
        self.assertEqual([round(d, 9) for d in got["compare"]["one_paraphrased"]["per_seed"]], [0.0, -0.1])
        self.assertEqual([round(d, 9) for d in got["compare"]["one_action_unseen"]["per_seed"]], [-0.2, -0.1])
        self.assertEqual([round(d, 9) for d in got["compare"]["no_text_seen"]["per_seed"]], [0.1, 0.0])
        # The default subsets are unchanged by it; the text report names the subsets.
        self.assertEqual(set(json.loads(run(path, "--vocabulary", self.vocabulary, "--json").stdout)["subsets"]),
                         {"held", "new"})
        text = run(path, "--vocabulary", self.vocabulary, "--by", "texts", "--scores", *stages, "--compare", "A", "B")
        self.assertIn("A - B on one paraphrased: -0.0500", text.stdout)

    def test_this_trees_vocabulary_names_every_template(self):
        texts = ["walk forwards", "walking backwards", "put hands on hips", "drink with left hand"]
        path = self.spans([("train", texts[0], texts[1]), ("test", texts[2], texts[3])])
        result = run(path, "--json")
        self.assertEqual(result.returncode, 0, result.stderr)
        got = json.loads(result.stdout)
        self.assertEqual(got["texts_without_action"], [])
        self.assertEqual(got["pair_in_training"], 0)

    def test_bad_inputs_name_the_file(self):
        path = self.spans([("test", "walk", "wave")], drop=("text_b",))
        result = run(path, "--vocabulary", self.vocabulary)
        self.assertEqual(result.returncode, 2)
        self.assertIn(path, result.stderr)
        self.assertIn("text_b", result.stderr)
        result = run(self.spans([("train", "walk", "wave")]), "--vocabulary", self.vocabulary)
        self.assertIn("no two-action spans in split 'test'", result.stderr)
        empty = os.path.join(self.tmp.name, "empty.cc")
        open(empty, "w").close()
        result = run(self.spans([("test", "walk", "wave")]), "--vocabulary", empty)
        self.assertEqual(result.returncode, 2)
        self.assertIn(empty, result.stderr)
        result = run(os.path.join(self.tmp.name, "missing.npz"), "--vocabulary", self.vocabulary)
        self.assertIn("missing.npz", result.stderr)
        result = run(self.spans([("test", "walk", "wave")]), "--vocabulary", self.vocabulary, "--compare", "a", "b")
        self.assertEqual(result.returncode, 2)
        self.assertIn("--scores", result.stderr)


if __name__ == "__main__":
    unittest.main()
