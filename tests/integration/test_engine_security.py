"""CurveZMQ with an allow-list: a worker whose key is listed works, one with an unknown key (or no
encryption at all) is refused by the ZAP handler."""
import time
import unittest

from harness import EngineTest, free_port, http_get, metric


class Security(EngineTest):
    def key(self, name):
        path = self.path(f"{name}.key")
        public = self.cli("keys", "generate", "--out", path).stdout.strip()
        self.assertEqual(len(public), 40)
        return path, public

    def test_only_listed_workers_are_admitted(self):
        coordinator_key, coordinator_public = self.key("coordinator")
        good_key, good_public = self.key("good")
        bad_key, _ = self.key("bad")
        allow = self.path("allow.txt")
        with open(allow, "w") as f:
            f.write(f"# workers allowed to connect\n{good_public}\n")
        metrics_port = free_port()
        self.coordinator(extra=["--curve-keys", coordinator_key, "--allow", allow], metrics_port=metrics_port)
        intruder = self.worker("intruder", extra=["--curve-keys", bad_key, "--server-key", coordinator_public])
        plain = self.worker("plain")  # no encryption at all
        job = self.submit(self.write_pipeline("p.yaml", "name: s\noutput_root: OUT\nstages: {w: {kind: test.write, params: {tasks: 20}}}\n"))
        # Wait for the refusal itself, not a fixed time: on a loaded machine the workers may take
        # seconds to start and knock (a fixed 2.5 s once saw no refusal yet).
        def refused():
            return metric(http_get(f"http://127.0.0.1:{metrics_port}/metrics"), "motionpipe_coordinator_workers_refused_total") or 0
        self.wait_until(lambda: refused() >= 1, 60, "the coordinator to refuse the intruder")
        time.sleep(1.0)  # the plain worker's attempts too
        status = self.status(job)
        self.assertEqual(status.get("workers", []), [])
        self.assertEqual(status["jobs"][0]["stages"][0].get("committed", 0), 0)
        self.worker("trusted", extra=["--curve-keys", good_key, "--server-key", coordinator_key])  # key file form
        code, out = self.wait_job(job, timeout=60)
        self.assertEqual(code, 0, out)
        self.assertEqual([w["id"] for w in self.status(job)["workers"]], ["trusted"])
        self.assertTrue(intruder.alive() and plain.alive())  # refused, not crashed

    def test_bad_key_files_are_reported(self):
        bad = self.path("broken.key")
        with open(bad, "w") as f:
            f.write("public-key: not-a-key\n")
        result = self.cli("coordinator", "--curve-keys", bad, "--allow", bad, "--journal", self.path("j.sqlite"), check=False, timeout=20)
        self.assertEqual(result.returncode, 1)
        self.assertIn("broken.key: 'public-key' is not a 40-character Z85 key", result.stderr)


if __name__ == "__main__":
    unittest.main()
