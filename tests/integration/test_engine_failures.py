"""The failure classes end to end: task errors retried with backoff, bad input failing at once, a
slow worker whose lease expires, and a poison task quarantined after killing workers."""
import os
import signal
import subprocess
import unittest

from harness import MOTIONPIPE, EngineTest, free_port, http_get, metric, output_files


class Failures(EngineTest):
    def test_a_worker_survives_writing_to_a_dead_peer(self):
        # A gang rank whose peer is killed writes into a closed socket (Gloo and c10d's TCPStore do
        # not ask for MSG_NOSIGNAL): the worker must ignore SIGPIPE, or it dies with the peer and
        # the gang cannot restart (seen in train.stage: the surviving rank killed by signal 13).
        self.coordinator()
        worker = self.worker("w0")

        def ignores_sigpipe():
            with open(f"/proc/{worker.proc.pid}/status") as f:
                ignored = next(int(line.split()[1], 16) for line in f if line.startswith("SigIgn:"))
            return bool(ignored & (1 << (signal.SIGPIPE - 1)))  # SigIgn: bit n-1 is signal n

        self.wait_until(ignores_sigpipe, 30, "the worker to ignore SIGPIPE")
        self.assertTrue(worker.alive())

    def test_errors_are_retried_with_backoff_until_they_succeed(self):
        self.coordinator()
        self.worker("a")
        pipeline = self.write_pipeline("f.yaml", """
name: flaky
output_root: OUT
stages:
  f: {kind: test.fail, params: {tasks: 5, fail_times: 2}, max_attempts: 3, retry_backoff: 100ms}
""")
        job = self.submit(pipeline)
        code, out = self.wait_job(job)
        self.assertEqual(code, 0, out)

    def test_too_many_errors_and_bad_input_fail_the_job_with_the_reason(self):
        self.coordinator()
        self.worker("a")
        exhausted = self.submit(self.write_pipeline("e.yaml", """
name: exhausted
output_root: OUT
stages:
  f: {kind: test.fail, params: {tasks: 1, fail_times: 5}, max_attempts: 2, retry_backoff: 50ms}
"""))
        code, out = self.wait_job(exhausted)
        self.assertEqual(code, 1)
        self.assertIn("failed after 2 attempt(s): deliberate failure 2 of 5", out)
        bad = self.submit(self.write_pipeline("b.yaml", """
name: bad
output_root: OUT
stages:
  f: {kind: test.fail, params: {tasks: 1, bad_input: true}, max_attempts: 5}
"""))
        code, out = self.wait_job(bad)
        self.assertEqual(code, 1)
        self.assertIn("rejected its input: params.bad_input is set", out)
        failures = self.job(bad)["stages"][0]["failures"]
        self.assertEqual(len(failures), 1)

    def test_a_slow_workers_lease_expires_and_the_task_moves_on(self):
        metrics_port = free_port()
        self.coordinator(metrics_port=metrics_port)
        self.worker("slow")
        job = self.submit(self.write_pipeline("s.yaml", """
name: slow
output_root: OUT
stages:
  w: {kind: test.write, params: {tasks: 1, first_attempt_ms: 4000}, timeout: 1s, retry_backoff: 100ms}
"""))
        self.worker("fast")
        code, out = self.wait_job(job, timeout=60)
        self.assertEqual(code, 0, out)
        job_dir = self.job(job)["output_dir"]
        self.assertEqual(len(output_files(job_dir, "w")), 1)
        self.wait_until(lambda: (metric(http_get(f"http://127.0.0.1:{metrics_port}/metrics"),
                                        "motionpipe_coordinator_tasks_total", ['outcome="lease_expired"']) or 0) >= 1, 10,
                        "the lease expiry to show in the metrics")

    def test_a_poison_task_is_quarantined(self):
        pipeline = self.write_pipeline("p.yaml", """
name: poison
output_root: OUT
stages:
  ok: {kind: test.write, params: {tasks: 6}}
  crash: {kind: test.crash, params: {tasks: 3, index: 1}, poison_threshold: 3, inputs: [ok]}
""")
        # `run` restarts workers that die, as a cluster scheduler would.
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "--workers", "2", "--heartbeat", "300ms"], capture_output=True,
                                text=True, timeout=120)
        self.assertEqual(result.returncode, 1, result.stdout + result.stderr)
        self.assertIn("quarantined", result.stdout)
        self.assertIn("3 workers died (poison)", result.stdout)


if __name__ == "__main__":
    unittest.main()
