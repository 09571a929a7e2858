"""tools/seed_pairs.py (issue 15: two rows of evaluation stages paired by seed, the report's rule)
on metrics whose differences are known by hand, and its errors."""
import json
import os
import subprocess
import tempfile
import unittest

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "seed_pairs.py")


def run(*args):
    return subprocess.run(["/usr/bin/python3", TOOL, *args], capture_output=True, text=True, timeout=60)


class SeedPairsTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.addCleanup(self.tmp.cleanup)

    def stage(self, name, r1):
        """An evaluation stage directory whose metrics hold gen->target R@1 `r1` in batches."""
        path = os.path.join(self.tmp.name, name)
        os.makedirs(os.path.join(path, "task-00000"))
        with open(os.path.join(path, "task-00000", "metrics.json"), "w") as f:
            json.dump({"generated_to_target": {"batches": {"R@1": r1}}, "temos_score": r1 / 100}, f)
        return path

    def test_pairs_by_seed_and_applies_the_rule(self):
        # Differences 2, 4, 6: mean 4, sd 2, two standard errors 4 / sqrt(3) = 2.309: holds.
        a = [self.stage(f"a{k}", v) for k, v in enumerate([70, 72, 74])]
        b = [self.stage(f"b{k}", v) for k, v in enumerate([68, 68, 68])]
        got = json.loads(run(*a, "--json", "--", *b).stdout)
        self.assertEqual(got["differences"], [2, 4, 6])
        self.assertAlmostEqual(got["two_se"], 4 / 3 ** 0.5)
        self.assertEqual(got["verdict"], "holds")
        # One B stage is compared with every A (an untrained row): the same figures.
        self.assertEqual(json.loads(run(*a, "--json", "--", b[0]).stdout)["differences"], [2, 4, 6])
        # Differences 2, -1, 5: mean 2, sd 3, 2 SE 3.46: not decided.
        c = [self.stage(f"c{k}", v) for k, v in enumerate([70, 67, 73])]
        got = json.loads(run(*c, "--metric", "temos_score", "--json", "--", *b).stdout)
        self.assertAlmostEqual(got["mean"], 0.02)
        self.assertEqual(got["verdict"], "not decided")
        # A single pair decides nothing.
        self.assertEqual(json.loads(run(a[0], "--json", "--", b[0]).stdout)["verdict"], "not decided")

    def test_errors_name_the_file_and_the_problem(self):
        a = self.stage("a", 70)
        result = run(a, a)
        self.assertEqual(result.returncode, 2)
        self.assertIn("with --", result.stderr)
        result = run(a, "--metric", "generated_to_target.all.R@1", "--", a)
        self.assertIn("no 'generated_to_target.all.R@1' (missing 'all')", result.stderr)
        result = run(a, a, a, "--", a, a)
        self.assertIn("3 stages of row A against 2 of row B", result.stderr)
        missing = os.path.join(self.tmp.name, "nothing")
        self.assertIn("cannot read", run(a, "--", missing).stderr)


if __name__ == "__main__":
    unittest.main()
