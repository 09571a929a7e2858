"""What a cluster's disks do (issue 17), injected with faultfs (an LD_PRELOAD shim, faultfs.c) in
the spirit of LevelDB's fault-injection tests, each run ending with outputs equal to an undisturbed
run's:
  - the output disk fills during tasks: the tasks fail with the reason, no half-written output is
    committed, and the job completes once space returns;
  - a disk whose fsync fails: no task is committed whose outputs could not be synced;
  - the journal's disk fails its writes under a running coordinator: the coordinator stops with the
    reason instead of running on, and a restart on a writable disk resumes the job;
  - a power loss (faultfs's power-loss mode and powerloss.py drop everything never fsynced) in the
    middle of a job: every output the journal calls committed is there with its sha256, and the
    restarted job's outputs equal an undisturbed run's."""
import hashlib
import os
import signal
import sqlite3
import subprocess
import time
import unittest

from harness import MOTIONPIPE, EngineTest, output_files
from powerloss import power_loss

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

    def test_the_power_loss_model_keeps_only_what_was_synced(self):
        # The simulation itself, on a program whose syncs are known: a test of the tests' power loss.
        root = self.path("disk")
        os.makedirs(os.path.join(root, "staging"))
        log = self.path("sync.log")
        program = """
import os, sys
root = sys.argv[1]
def write(path, data, sync=True):
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.write(fd, data)
    if sync:
        os.fsync(fd)
    os.close(fd)
def sync_dir(path):
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    os.fsync(fd)
    os.close(fd)
write(root + '/kept', b'kept')                   # synced, then its name
write(root + '/empty', b'never synced', sync=False)
write(root + '/cut', b'synced')
write(root + '/staging/moved', b'moved')         # synced under one name, renamed before the dir sync
sync_dir(root + '/staging')
os.rename(root + '/staging/moved', root + '/moved')
os.makedirs(root + '/sub')
write(root + '/sub/inner', b'inner')
sync_dir(root + '/sub')
sync_dir(root)
write(root + '/cut', b' and not synced', sync=False)
write(root + '/late', b'after the last directory sync')
os.makedirs(root + '/unsynced_dir')
"""
        env = dict(os.environ, LD_PRELOAD=FAULTFS, FAULTFS_PREFIX=root, FAULTFS_LOG=log)
        result = subprocess.run(["/usr/bin/python3", "-c", program, root], env=env, capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stderr)
        lost, cut = power_loss(root, log)
        tree = {}
        for d, _, names in os.walk(root):
            for n in names:
                with open(os.path.join(d, n), "rb") as f:
                    tree[os.path.relpath(os.path.join(d, n), root)] = f.read()
        # The rename's old directory was not synced again: its old name survives too (POSIX leaves
        # it open; the coordinator syncs both directories of a commit's rename).
        self.assertEqual(tree, {"kept": b"kept", "empty": b"", "cut": b"synced", "moved": b"moved",
                                "staging/moved": b"moved", "sub/inner": b"inner"})
        self.assertEqual(lost, ["late", "unsynced_dir"])
        self.assertEqual(cut, 2)  # "empty" and "cut"
        self.assertEqual(sorted(os.listdir(root)), ["cut", "empty", "kept", "moved", "staging", "sub"])

    def test_a_power_loss_keeps_every_committed_output_and_the_job_resumes(self):
        out = self.path("out")
        os.makedirs(out)
        log = self.path("sync.log")
        env = dict(os.environ, LD_PRELOAD=FAULTFS, FAULTFS_PREFIX=out, FAULTFS_LOG=log)
        journal = self.path("journal.sqlite")
        coordinator = self.coordinator(journal=journal, env=env)
        workers = [self.worker(name, env=env) for name in ("a", "b")]
        # sync: false, as bulk outputs are written: only the worker's and the coordinator's syncs count.
        job = self.submit(self.write_pipeline("p.yaml", WRITE.replace("TASKS", "150").replace("bytes: 4096", "bytes: 4096, sync: false")))
        self.wait_until(lambda: self.job(job)["stages"][0].get("committed", 0) >= 40, 60, "40 committed tasks")
        for p in workers + [coordinator]:  # the power goes: every process at once
            p.send(signal.SIGKILL)
        for p in workers + [coordinator]:
            p.wait(10)
        lost, cut = power_loss(out, log)
        db = sqlite3.connect(journal)
        committed = db.execute("SELECT idx FROM tasks WHERE job=? AND stage='w' AND state=1", (job,)).fetchall()
        outputs = db.execute("SELECT idx, path, sha256, bytes FROM outputs WHERE job=? AND stage='w'", (job,)).fetchall()
        db.close()
        # The status counts a commit when it happens; the journal records it at its next flush
        # (flush interval), so the journal may hold a few fewer than the 40 the status showed.
        self.assertGreaterEqual(len(committed), 20)
        self.assertLess(len(committed), 150)
        # Every output the journal calls committed survived, complete.
        self.assertEqual(len(outputs), len(committed))
        job_dir = os.path.join(out, "disk-1", "w")
        for idx, path, sha, size in outputs:
            file = os.path.join(job_dir, f"task-{idx:05d}", path)
            self.assertTrue(os.path.exists(file), f"committed task {idx}: {path} lost in the power loss")
            with open(file, "rb") as f:
                data = f.read()
            self.assertEqual((len(data), hashlib.sha256(data).hexdigest()), (size, sha), f"committed task {idx}: {path}")
        # What the power loss takes depends on the moment (an attempt's staging in flight, or
        # nothing); the model's own test above shows it takes what was never synced. Before the
        # job's and the stages' directories were made durable, this test lost every committed task.
        del lost, cut
        self.coordinator(journal=journal, port=self.worker_port, control_port=self.control_port)
        self.worker("c")
        code, text = self.wait_job(job, timeout=120)
        self.assertEqual(code, 0, text)
        self.assertEqual(output_files(self.path("out", "disk-1"), "w"), self.undisturbed(150))

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
