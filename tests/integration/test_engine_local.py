"""`motionpipe run`: a local coordinator and worker processes, a pipeline across a built-in stage
kind and a plugin's, the journal, and resuming after an interruption."""
import json
import os
import signal
import subprocess
import time
import unittest

from harness import MOTIONPIPE, EngineTest, output_files

PIPELINE = """
name: local
output_root: OUT
seed: 3
stages:
  write:
    kind: test.write
    params: {tasks: 300, bytes: 128}
  check:
    kind: sample.checksum
    inputs: [write]
"""


def committed_tasks(stage_dir, at_least, timeout=60):
    """The number of committed task directories of a stage, once there are `at_least` (or the timeout)."""
    deadline = time.time() + timeout
    while True:
        count = len([n for n in os.listdir(stage_dir) if n.startswith("task")]) if os.path.isdir(stage_dir) else 0
        if count >= at_least or time.time() >= deadline:
            return count
        time.sleep(0.05)


class LocalRun(EngineTest):
    def test_run_executes_the_pipeline_through_workers(self):
        pipeline = self.write_pipeline("p.yaml", PIPELINE)
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2"], capture_output=True, text=True, timeout=120)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        self.assertIn("succeeded", result.stdout)
        job_dir = self.path("out", "local-1")
        self.assertEqual(len(output_files(job_dir, "write")), 300)
        with open(os.path.join(job_dir, "check", "task-00000", "checksum.json")) as f:
            checksum = json.load(f)
        self.assertEqual(checksum["files"], 300)
        self.assertEqual(checksum["bytes"], 300 * 128)
        self.assertTrue(os.path.exists(self.path("out", ".motionpipe", "journal.sqlite")))

    def test_overrides_and_invalid_pipelines(self):
        pipeline = self.write_pipeline("p.yaml", PIPELINE)
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "-q", "stages.write.params.tasks=7"], capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stderr)
        self.assertEqual(len(output_files(self.path("out", "local-1"), "write")), 7)
        bad = self.write_pipeline("bad.yaml", PIPELINE.replace("inputs: [write]", "inputs: [wirte]"))
        result = subprocess.run([MOTIONPIPE, "run", bad], capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 1)
        self.assertIn("stages.check.inputs[0]: unknown stage 'wirte'", result.stderr)
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "0"], capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 2)  # usage error

    def test_a_dry_run_plans_and_starts_nothing(self):
        pipeline = self.write_pipeline("p.yaml", PIPELINE)
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--dry-run", "stages.write.params.tasks=7"], capture_output=True, text=True,
                                timeout=60)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        self.assertRegex(result.stdout, r"write +test\.write +7 ")
        self.assertRegex(result.stdout, r"check +sample\.checksum +1 +write")
        self.assertIn("8 task(s) in all", result.stdout)
        self.assertFalse(os.path.exists(self.path("out")))  # no job, no journal
        bad = self.write_pipeline("bad.yaml", PIPELINE.replace("inputs: [write]", "inputs: [wirte]"))
        result = subprocess.run([MOTIONPIPE, "run", bad, "--dry-run"], capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 1)
        self.assertIn("stages.check.inputs[0]: unknown stage 'wirte'", result.stderr)

    def test_a_derived_pipeline_runs_as_its_base_with_its_changes(self):
        self.write_pipeline("p.yaml", PIPELINE)
        derived = self.write_pipeline("d.yaml", "base: p.yaml\nname: derived\nstages:\n  write: {params: {tasks: 3}}\n")
        result = subprocess.run([MOTIONPIPE, "run", derived, "--print-resolved"], capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        resolved = json.loads(result.stdout)
        self.assertNotIn("base", resolved)
        self.assertEqual(resolved["name"], "derived")
        self.assertEqual(resolved["seed"], 3)  # the base's
        self.assertEqual(resolved["stages"]["write"], {"kind": "test.write", "params": {"tasks": 3, "bytes": 128}})
        self.assertEqual(resolved["stages"]["check"]["inputs"], ["write"])
        result = subprocess.run([MOTIONPIPE, "run", derived, "--dry-run", "targets=[write]"], capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        self.assertRegex(result.stdout, r"pipeline 'derived': 1 stage\(s\)")
        self.assertRegex(result.stdout, r"write +test\.write +3 ")
        self.assertFalse(os.path.exists(self.path("out")))  # no job, no journal

    def test_an_interrupted_run_resumes(self):
        pipeline = self.write_pipeline("p.yaml", PIPELINE.replace("bytes: 128}", "bytes: 128, ms: 20}"))
        run = subprocess.Popen([MOTIONPIPE, "run", pipeline, "-q", "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        write_dir = self.path("out", "local-1", "write")
        committed_tasks(write_dir, at_least=40)
        run.send_signal(signal.SIGINT)
        out, _ = run.communicate(timeout=60)
        self.assertEqual(run.returncode, 1)
        self.assertIn("run the same command again to resume", out)
        done_before = len([n for n in os.listdir(write_dir) if n.startswith("task")])
        self.assertLess(done_before, 300)
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2"], capture_output=True, text=True, timeout=120)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        self.assertIn("resuming job 1", result.stdout)
        self.assertEqual(len(output_files(self.path("out", "local-1"), "write")), 300)

    def test_a_second_run_on_a_journal_in_use_is_refused(self):
        # Two runs in one output root share its journal. The second used to resume the first one's
        # running job and give its tasks to its own workers: two trainers on one checkpoint.
        pipeline = self.write_pipeline("p.yaml", PIPELINE.replace("bytes: 128}", "bytes: 128, ms: 20}"))
        other = self.write_pipeline("q.yaml", PIPELINE.replace("name: local", "name: other"))
        first = subprocess.Popen([MOTIONPIPE, "run", pipeline, "-q", "--workers", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        committed_tasks(self.path("out", "local-1", "write"), at_least=5)
        journal = self.path("out", ".motionpipe", "journal.sqlite")
        second = subprocess.run([MOTIONPIPE, "run", other, "-q", "--workers", "1"], capture_output=True, text=True, timeout=60)
        self.assertEqual(second.returncode, 1, second.stdout + second.stderr)
        self.assertIn(f"the journal {journal} is in use by another coordinator", second.stderr)
        self.assertIn(f"(pid {first.pid})", second.stderr)
        self.assertIn("--journal", second.stderr)
        self.assertIsNone(first.poll(), "the first run stopped")
        # With its own journal the second run goes ahead beside the first.
        second = subprocess.run([MOTIONPIPE, "run", other, "-q", "--workers", "1", "--journal", self.path("other.sqlite")],
                                capture_output=True, text=True, timeout=120)
        self.assertEqual(second.returncode, 0, second.stdout + second.stderr)
        out, _ = first.communicate(timeout=120)
        self.assertEqual(first.returncode, 0, out)
        self.assertEqual(len(output_files(self.path("out", "local-1"), "write")), 300)
        # Once the first has stopped, the lock is free: a new run on the shared journal starts.
        result = subprocess.run([MOTIONPIPE, "run", other, "-q", "--workers", "1", "stages.write.params.tasks=3"],
                                capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)

    def test_version_and_an_unknown_command(self):
        result = subprocess.run([MOTIONPIPE, "--version"], capture_output=True, text=True, timeout=30)
        self.assertEqual(result.returncode, 0)
        self.assertRegex(result.stdout, r"^motionpipe \d+\.\d+\.\d+")
        result = subprocess.run([MOTIONPIPE, "--log", "warn", "frobnicate"], capture_output=True, text=True, timeout=30)
        self.assertEqual(result.returncode, 2)
        self.assertIn("unknown command 'frobnicate'", result.stderr)
        self.assertIn("run,", result.stderr)

    def test_a_killed_run_takes_its_workers_with_it(self):
        # Issue 17: SIGKILL of `run` (which holds the coordinator) left its workers reconnecting for
        # more than 10 minutes.
        pipeline = self.write_pipeline("p.yaml", PIPELINE.replace("bytes: 128}", "bytes: 128, ms: 50}"))
        run = subprocess.Popen([MOTIONPIPE, "run", pipeline, "-q", "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        children = []
        deadline = time.time() + 30
        while time.time() < deadline and len(children) < 2:
            with open(f"/proc/{run.pid}/task/{run.pid}/children") as f:
                children = [int(p) for p in f.read().split()]
            time.sleep(0.05)
        self.assertEqual(len(children), 2, "run did not start 2 workers")
        run.kill()
        run.wait(timeout=10)

        def alive(pid):
            try:
                with open(f"/proc/{pid}/stat") as f:
                    return f.read().split()[2] != "Z"
            except FileNotFoundError:
                return False

        deadline = time.time() + 10
        while time.time() < deadline and any(alive(p) for p in children):
            time.sleep(0.05)
        left = [p for p in children if alive(p)]
        for p in left:
            os.kill(p, signal.SIGKILL)
        self.assertEqual(left, [], "workers outlived their run")


if __name__ == "__main__":
    unittest.main()
