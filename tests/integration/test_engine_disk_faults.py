"""What a cluster's disks do (issue 17), injected with faultfs (an LD_PRELOAD shim, faultfs.c) in
the spirit of LevelDB's fault-injection tests, each run ending with outputs equal to an undisturbed
run's:
  - the output disk fills during tasks: the tasks fail with the reason, no half-written output is
    committed, and the job completes once space returns;
  - a disk whose fsync fails: no task is committed whose outputs could not be synced;
  - the journal's disk fails its writes under a running coordinator: the coordinator stops with the
    reason instead of running on, and a restart on a writable disk resumes the job.
Not yet here: a simulated power loss (dropping what was never fsynced)."""
import os
import sqlite3
import subprocess
import time
import unittest

from harness import MOTIONPIPE, EngineTest, output_files

FAULTFS = os.environ.get("MOTIONPIPE_FAULTFS", "")

WRITE = """
name: disk
output_root: OUT
seed: 11
defaults: {max_attempts: 1000, retry_backoff: 0.05}
stages:
  w: {kind: test.write, params: {tasks: TASKS, ms: 10, bytes: 4096}}
"""


@unittest.skipUnless(FAULTFS and os.path.exists(FAULTFS), "MOTIONPIPE_FAULTFS (the built faultfs shim) is not set")
class DiskFaults(EngineTest):
    def faulty_env(self, prefix, errno="ENOSPC", ops="write,sync"):
        self.trigger = self.path("disk-fails")
        return dict(os.environ, LD_PRELOAD=FAULTFS, FAULTFS_PREFIX=prefix, FAULTFS_TRIGGER=self.trigger,
                    FAULTFS_ERRNO=errno, FAULTFS_OPS=ops)

    def undisturbed(self, tasks):
        pipeline = self.write_pipeline("ref.yaml", WRITE.replace("TASKS", str(tasks)).replace("OUT", self.path("ref")))
        result = subprocess.run([MOTIONPIPE, "run", pipeline, "-q", "--workers", "1"], capture_output=True, text=True, timeout=120)
        self.assertEqual(result.returncode, 0, result.stderr)
        return output_files(self.path("ref", "disk-1"), "w")

    def test_a_full_output_disk_fails_tasks_cleanly_and_the_job_completes_when_space_returns(self):
        out = self.path("out")
        os.makedirs(out)
        self.coordinator()
        self.worker("full", env=self.faulty_env(out, "ENOSPC", "write"))
        job = self.submit(self.write_pipeline("p.yaml", WRITE.replace("TASKS", "120")))
        self.wait_until(lambda: self.job(job)["stages"][0].get("committed", 0) >= 30, 60, "30 committed tasks")
        open(self.trigger, "w").close()  # the disk is full
        self.wait_until(lambda: len(self.failed_attempts()) >= 5, 30, "tasks failing on the full disk")
        committed_while_full = self.job(job)["stages"][0].get("committed", 0)
        self.assertLess(committed_while_full, 120)
        # The journal keeps each failure's reason, naming the file and the disk's error.
        reasons = self.failed_attempts()
        self.assertTrue(all("No space left on device" in r for r in reasons), reasons[:3])
        self.assertTrue(any("out.txt" in r for r in reasons), reasons[:3])
        # Every task the journal calls committed has its complete output, even now.
        self.check_committed_outputs(job)
        os.remove(self.trigger)  # space returns
        code, text = self.wait_job(job, timeout=120)
        self.assertEqual(code, 0, text)
        self.check_committed_outputs(job)
        self.assertEqual(output_files(self.path("out", "disk-1"), "w"), self.undisturbed(120))
        self.assertEqual([n for n in os.listdir(self.path("out", "disk-1", "w")) if n.startswith(".")], [], "staging left behind")

    def test_outputs_that_cannot_be_synced_are_never_committed(self):
        # The worker fsyncs a task's outputs before reporting them, the coordinator the directories
        # of the rename before journaling it; a disk whose fsync fails commits nothing meanwhile.
        out = self.path("out")
        os.makedirs(out)
        self.coordinator()
        self.worker("nosync", env=self.faulty_env(out, "EIO", "sync"))
        open(self.path("disk-fails"), "w").close()
        # sync: false, as bulk outputs are written: the file's own fsync is skipped, the worker's is not.
        job = self.submit(self.write_pipeline("p.yaml", WRITE.replace("TASKS", "20").replace("bytes: 4096", "bytes: 4096, sync: false")))
        self.wait_until(lambda: len(self.failed_attempts()) >= 5, 30, "tasks failing to sync")
        self.assertEqual(self.job(job)["stages"][0].get("committed", 0), 0)
        reasons = self.failed_attempts()
        self.assertTrue(all("outputs not durable" in r and "fsync failed: Input/output error" in r for r in reasons), reasons[:3])
        os.remove(self.trigger)
        code, text = self.wait_job(job, timeout=120)
        self.assertEqual(code, 0, text)
        self.check_committed_outputs(job)
        self.assertEqual(output_files(self.path("out", "disk-1"), "w"), self.undisturbed(20))

    def test_a_failing_journal_disk_stops_the_coordinator_and_a_restart_resumes(self):
        state = self.path("state")
        os.makedirs(state)
        journal = os.path.join(state, "journal.sqlite")
        coordinator = self.coordinator(journal=journal, env=self.faulty_env(state, "EIO"))
        self.worker("a")
        job = self.submit(self.write_pipeline("p.yaml", WRITE.replace("TASKS", "200")))
        self.wait_until(lambda: self.job(job)["stages"][0].get("committed", 0) >= 30, 60, "30 committed tasks")
        open(self.trigger, "w").close()  # the journal's disk fails
        code = coordinator.wait(30)
        self.assertIsNotNone(code, "the coordinator ran on with a journal it cannot write")
        self.assertNotEqual(code, 0)
        log = coordinator.output()
        self.assertIn("journal: disk I/O error", log)
        self.assertIn("stopped rather than run on a journal it cannot write", log)
        db = sqlite3.connect(journal)
        recorded = db.execute("SELECT COUNT(*) FROM tasks WHERE job=? AND state=1", (job,)).fetchone()[0]
        db.close()
        self.assertLess(recorded, 200)
        os.remove(self.trigger)  # the disk is back: the same command starts the coordinator again
        self.coordinator(journal=journal, port=self.worker_port, control_port=self.control_port)
        code, text = self.wait_job(job, timeout=120)
        self.assertEqual(code, 0, text)
        self.check_committed_outputs(job)
        self.assertEqual(output_files(self.path("out", "disk-1"), "w"), self.undisturbed(200))

    def check_committed_outputs(self, job):
        status = self.job(job)
        out_dir = status["output_dir"]
        for name in sorted(os.listdir(os.path.join(out_dir, "w"))):
            if not name.startswith("task-"):
                continue
            path = os.path.join(out_dir, "w", name, "out.txt")
            self.assertTrue(os.path.exists(path), f"{name} committed without its output")
            self.assertEqual(os.path.getsize(path), 4096, f"{name}: a half-written output was committed")

    def failed_attempts(self):
        db = sqlite3.connect(self.path("journal.sqlite"), timeout=10)
        try:
            return [row[0] for row in db.execute("SELECT message FROM tasks WHERE errors > 0")]
        finally:
            db.close()


if __name__ == "__main__":
    unittest.main()
