"""Chaos: 5,000 small tasks on 3 workers while a random worker is SIGKILLed every few hundred
milliseconds and started again. Every task completes, every output exists exactly once, and the
outputs' checksums equal those of an undisturbed run."""
import os
import random
import signal
import time
import unittest

from harness import EngineTest, output_files

TASKS = int(os.environ.get("MOTIONPIPE_CHAOS_TASKS", "5000"))
PIPELINE = f"""
name: chaos
output_root: OUT
seed: 99
stages:
  w: {{kind: test.write, params: {{tasks: {TASKS}, ms: 1, bytes: 256}}, poison_threshold: 1000}}
"""


class Chaos(EngineTest):
    def run_job(self, kill):
        self.coordinator()
        workers = {name: self.worker(name) for name in ("a", "b", "c")}
        job = self.submit(self.write_pipeline("chaos.yaml", PIPELINE))
        rng = random.Random(4)
        kills = 0
        start = time.time()
        while True:
            state = self.job(job)["state"]
            if state != "running":
                break
            self.assertLess(time.time() - start, 400, "the job did not finish")
            if kill:
                time.sleep(rng.uniform(0.2, 0.4))
                name = rng.choice(sorted(workers))
                workers[name].send(signal.SIGKILL)
                workers[name].wait(5)
                kills += 1
                workers[name] = self.worker(name)
            else:
                time.sleep(0.2)
        self.assertEqual(state, "succeeded", self.job(job))
        job_dir = self.job(job)["output_dir"]
        return job_dir, kills

    def test_outputs_survive_killed_workers_exactly_once(self):
        calm_dir, _ = self.run_job(kill=False)
        calm = output_files(calm_dir, "w")
        for p in self.processes:
            p.stop(signal.SIGKILL, timeout=2)
        self.processes = []
        # The chaos run starts on a fresh journal, whose first job is numbered 1 again: its directory
        # must be free (a coordinator refuses another journal's).
        os.rename(self.path("journal.sqlite"), self.path("calm.sqlite"))
        os.rename(calm_dir, calm_dir + ".calm")
        chaos_dir, kills = self.run_job(kill=True)
        chaos = output_files(chaos_dir, "w")
        print(f"chaos: {TASKS} tasks, {kills} workers killed")
        self.assertGreater(kills, 5)
        self.assertEqual(len(chaos), TASKS)
        self.assertEqual(chaos, calm)  # same names, same checksums
        stage_dir = os.path.join(chaos_dir, "w")
        leftovers = [n for n in os.listdir(stage_dir) if not n.startswith("task-")]
        staging = os.path.join(stage_dir, ".staging")
        self.assertTrue(leftovers == [] or (leftovers == [".staging"] and os.path.isdir(staging)))
        stray = os.listdir(staging) if os.path.isdir(staging) else []
        # Attempts of killed workers may leave their staging directories; nothing was committed twice.
        for name in stray:
            self.assertIn(".attempt-", name)


if __name__ == "__main__":
    unittest.main()
