"""A coordinator and workers as separate processes on separate loopback addresses (the two-host
setup): submit / status / wait / cancel, drain on SIGTERM, and garbage on every socket."""
import os
import signal
import subprocess
import time
import unittest

from harness import GARBAGE, EngineTest, free_port, http_get, metric, output_files

WRITE = """
name: cluster
output_root: OUT
stages:
  write: {kind: test.write, params: {tasks: 200, ms: 5}}
"""


class TwoHosts(EngineTest):
    # No test here loses a worker, and each reads the workers' counts from the status, which drops
    # a lost one: at 300 ms (lost after 0.9 s silent) both workers were once dropped with four
    # heavy processes beside the suite on 2 cores. Lost after 3 s silent instead.
    HEARTBEAT = "1s"

    def test_coordinator_and_workers_on_separate_addresses(self):
        self.coordinator(host="127.0.0.2")  # workers reach it at another loopback address
        for name in ("a", "b"):
            self.worker(name)
        job = self.submit(self.write_pipeline("p.yaml", WRITE))
        code, out = self.wait_job(job)
        self.assertEqual(code, 0, out)
        status = self.status(job)
        stage = status["jobs"][0]["stages"][0]
        self.assertEqual(stage["committed"], 200)
        self.assertEqual(stage["state"], "succeeded")
        self.assertEqual({w["id"] for w in status["workers"]}, {"a", "b"})
        self.assertEqual(sum(int(w.get("tasks_done", 0)) for w in status["workers"]), 200)
        self.assertEqual(len(output_files(status["jobs"][0]["output_dir"], "write")), 200)
        text = self.cli("status", "--control", self.control).stdout
        self.assertIn("write", text)
        self.assertIn("200/200", text)

    def test_several_jobs_at_once_and_cancel(self):
        self.coordinator()
        self.worker("a")
        sleepy = self.write_pipeline("s.yaml", "name: sleepy\noutput_root: OUT\nstages: {s: {kind: sleep, params: {tasks: 50, ms: 200}}}\n")
        quick = self.write_pipeline("q.yaml", WRITE.replace("tasks: 200", "tasks: 20"))
        slow_job = self.submit(sleepy)
        quick_job = self.submit(quick)
        self.cli("cancel", str(slow_job), "--control", self.control)
        code, out = self.wait_job(slow_job, timeout=30)
        self.assertEqual(code, 1)
        self.assertIn("cancelled", out)
        code, out = self.wait_job(quick_job)
        self.assertEqual(code, 0, out)
        again = self.cli("cancel", str(slow_job), "--control", self.control, check=False)
        self.assertEqual(again.returncode, 1)
        self.assertIn("already cancelled", again.stderr)
        missing = self.cli("wait", "999", "--control", self.control, check=False)
        self.assertEqual(missing.returncode, 1)

    def test_long_tasks_queued_on_a_busy_worker_go_to_an_idle_one(self):
        # Issue 17's head-of-line blocking: worker a (credit 2) leases both long tasks before b
        # arrives; the one queued behind a's running task is reclaimed for b, and both run at once.
        self.coordinator()
        self.worker("a", credit=2)
        job = self.submit(self.write_pipeline("l.yaml", "name: long\noutput_root: OUT\nstages: {s: {kind: sleep, params: {tasks: 2, ms: 6000}}}\n"))
        self.wait_until(lambda: any(w["id"] == "a" and w.get("running", 0) == 2 for w in self.status().get("workers", [])), 20, "a to lease both tasks")
        self.worker("b", credit=2)
        self.wait_until(lambda: all(w.get("running", 0) == 1 for w in self.status().get("workers", [])) and len(self.status().get("workers", [])) == 2,
                        10, "one task on each worker")
        code, out = self.wait_job(job, timeout=60)
        self.assertEqual(code, 0, out)
        done = {w["id"]: int(w.get("tasks_done", 0)) for w in self.status()["workers"]}
        self.assertEqual(done, {"a": 2, "b": 1})  # a's results: its task and the hand-back

    def test_a_draining_worker_finishes_or_hands_back(self):
        self.coordinator()
        long = self.write_pipeline("l.yaml", "name: long\noutput_root: OUT\nstages: {s: {kind: sleep, params: {tasks: 4, ms: 1500}}}\n")
        drained = self.worker("drained", extra=["--drain-timeout", "300ms"], credit=4)
        job = self.submit(long)
        self.wait_until(lambda: self.job(job)["stages"][0].get("running", 0) > 0, 20, "a running task")
        drained.send(signal.SIGTERM)  # preemption
        self.assertEqual(drained.wait(20), 0, drained.output())
        self.assertIn("handed back attempt", drained.output())  # the 1.5 s task outlived the 300 ms drain
        self.worker("replacement")
        code, out = self.wait_job(job, timeout=60)
        self.assertEqual(code, 0, out)

    def test_garbage_frames_on_every_socket_are_survived(self):
        metrics_port = free_port()
        self.coordinator(metrics_port=metrics_port)
        self.worker("a")
        job = self.submit(self.write_pipeline("p.yaml", WRITE))
        for endpoint in (self.workers_endpoint, self.control):
            out = subprocess.run([GARBAGE, "--connect", endpoint, "--count", "300"], capture_output=True, text=True, timeout=60)
            self.assertEqual(out.returncode, 0)
        code, out = self.wait_job(job)
        self.assertEqual(code, 0, out)
        text = http_get(f"http://127.0.0.1:{metrics_port}/metrics")
        dropped = metric(text, "motionpipe_coordinator_messages_dropped_total")
        self.assertIsNotNone(dropped)
        self.assertGreater(dropped, 300)
        for reason in ("bad_header", "version", "type", "oversized", "undecodable", "frame_count"):
            self.assertIsNotNone(metric(text, "motionpipe_coordinator_messages_dropped_total", [f'reason="{reason}"']), reason)
        # A worker fed garbage by a fake coordinator survives it, then works for the real one.
        fake_port = free_port()
        fake = subprocess.Popen([GARBAGE, "--bind", f"tcp://127.0.0.1:{fake_port}", "--count", "300", "--seconds", "10"],
                                stdout=subprocess.PIPE, text=True)
        victim = self.worker("victim", endpoint=f"tcp://127.0.0.1:{fake_port}")
        sent = int(fake.communicate(timeout=30)[0].strip())
        self.assertGreater(sent, 0)
        time.sleep(0.5)
        self.assertTrue(victim.alive(), victim.output())
        self.assertIn("dropped", victim.output())


if __name__ == "__main__":
    unittest.main()
