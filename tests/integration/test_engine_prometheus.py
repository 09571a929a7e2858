"""A real Prometheus server (Debian's `prometheus`) scrapes the coordinator's and a worker's /metrics
with the scrape configuration shipped in deploy/prometheus/."""
import json
import os
import shutil
import subprocess
import time
import unittest
import urllib.parse

from harness import EngineTest, free_port, http_get

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


class PrometheusScrape(EngineTest):
    @unittest.skipUnless(shutil.which("prometheus"), "scripts/setup installs Debian's prometheus")
    def test_prometheus_scrapes_coordinator_and_worker(self):
        shipped = os.path.join(ROOT, "deploy", "prometheus", "prometheus.yml")
        if shutil.which("promtool"):
            check = subprocess.run(["promtool", "check", "config", shipped], capture_output=True, text=True)
            self.assertEqual(check.returncode, 0, check.stdout + check.stderr)
        coordinator_port, worker_port, web_port = free_port(), free_port(), free_port()
        with open(shipped) as f:
            config = f.read()
        config = config.replace("scrape_interval: 15s", "scrape_interval: 1s")
        config = config.replace("coordinator:9100", f"127.0.0.1:{coordinator_port}").replace("worker:9101", f"127.0.0.1:{worker_port}")
        with open(self.path("prometheus.yml"), "w") as f:
            f.write(config)
        self.spawn(["prometheus", f"--config.file={self.path('prometheus.yml')}", f"--storage.tsdb.path={self.path('tsdb')}",
                    f"--web.listen-address=127.0.0.1:{web_port}"], "prometheus")
        self.coordinator(metrics_port=coordinator_port)
        self.worker("a", extra=["--metrics", f"127.0.0.1:{worker_port}"])
        job = self.submit(self.write_pipeline("p.yaml", "name: m\noutput_root: OUT\nstages: {w: {kind: test.write, params: {tasks: 50}}}\n"))
        code, out = self.wait_job(job)
        self.assertEqual(code, 0, out)

        def query(expression):
            url = f"http://127.0.0.1:{web_port}/api/v1/query?query=" + urllib.parse.quote(expression)
            try:
                return json.loads(http_get(url))["data"]["result"]
            except Exception:
                return []

        self.wait_until(lambda: len([r for r in query("up") if r["value"][1] == "1"]) == 2, 60, "both targets up")
        self.wait_until(lambda: any(float(r["value"][1]) >= 50 for r in
                                    query('motionpipe_coordinator_tasks_total{outcome="committed"}')), 60,
                        "the committed tasks in Prometheus")
        self.wait_until(lambda: any(float(r["value"][1]) >= 50 for r in query("sum(motionpipe_worker_tasks_total)")), 60,
                        "the worker's tasks in Prometheus")


if __name__ == "__main__":
    unittest.main()
