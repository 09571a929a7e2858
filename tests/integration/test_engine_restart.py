"""A coordinator killed with SIGKILL mid-job and restarted on the same journal: the job finishes,
and no task that was committed before the kill runs again."""
import collections
import os
import signal
import sqlite3
import unittest

from harness import EngineTest, output_files


class CoordinatorRestart(EngineTest):
    def test_sigkill_and_restart_resumes_without_rerunning_committed_tasks(self):
        log = self.path("executions.log")
        pipeline = self.write_pipeline("r.yaml", f"""
name: restart
output_root: OUT
stages:
  w: {{kind: test.write, params: {{tasks: 400, ms: 8, log: {log}}}, poison_threshold: 100}}
""")
        coordinator = self.coordinator()
        port, control_port = self.worker_port, self.control_port
        for name in ("a", "b"):
            self.worker(name)
        job = self.submit(pipeline)
        self.wait_until(lambda: self.job(job)["stages"][0].get("committed", 0) >= 120, 60, "120 committed tasks")
        coordinator.stop(signal.SIGKILL)
        # What the journal says was committed when the coordinator died.
        db = sqlite3.connect(self.path("journal.sqlite"))
        committed = {row[0] for row in db.execute("SELECT idx FROM tasks WHERE job=? AND state=1", (job,))}
        db.close()
        self.assertGreater(len(committed), 50)
        self.assertLess(len(committed), 400)
        self.coordinator(port=port, control_port=control_port)  # same journal, same endpoints
        code, out = self.wait_job(job, timeout=120)
        self.assertEqual(code, 0, out)
        self.assertEqual(len(output_files(self.job(job)["output_dir"], "w")), 400)
        runs = collections.Counter()
        with open(log) as f:
            for line in f:
                stage, index, pid = line.split()
                runs[int(index)] += 1
        rerun = sorted(i for i in committed if runs[i] != 1)
        self.assertEqual(rerun, [], "committed tasks ran again after the restart")
        self.assertEqual(set(runs), set(range(400)))


if __name__ == "__main__":
    unittest.main()
