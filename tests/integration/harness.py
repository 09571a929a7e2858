"""Helpers for the engine's multi-process tests: start coordinators and workers of the real
`motionpipe` binary on loopback, talk to them with the CLI, and clean up whatever happens."""
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import unittest
import urllib.request

MOTIONPIPE = os.environ.get("MOTIONPIPE_BIN", "motionpipe")
GARBAGE = os.environ.get("MOTIONPIPE_GARBAGE", "motionpipe_garbage")


_HANDED_OUT = set()


def torch_load(path):
    """Loads a state dict with Debian's python3-torch in a subprocess; returns {name: ndarray}."""
    import numpy as np  # only the tests that read checkpoints need it
    code = ("import sys, torch, numpy as np; d = torch.load(sys.argv[1]); "
            "np.savez(sys.argv[2], **{k: v.numpy() for k, v in d.items()})")
    out = path + ".npz"
    subprocess.run(["/usr/bin/python3", "-c", code, path, out], check=True, timeout=120)
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


def free_port(host="127.0.0.1"):
    """A port free now and not handed out before by this process: the kernel can give a port just
    closed to the next bind, and a test that asks for two ports (a coordinator's worker socket and a
    worker's /metrics) must get two."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind((host, 0))
            port = s.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port


class Process:
    """A child process with its output in a log file (shown when a test fails)."""

    def __init__(self, args, log_path, env=None):
        self.args = args
        self.log_path = log_path
        self.log = open(log_path, "ab")
        self.proc = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT, env=env)

    def alive(self):
        return self.proc.poll() is None

    def send(self, sig):
        if self.alive():
            self.proc.send_signal(sig)

    def wait(self, timeout):
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None

    def stop(self, sig=signal.SIGTERM, timeout=10):
        if self.alive():
            self.proc.send_signal(sig)
            if self.wait(timeout) is None:
                self.proc.kill()
                self.proc.wait()
        self.log.close()

    def output(self):
        if not self.log.closed:
            self.log.flush()
        with open(self.log_path, "rb") as f:
            return f.read().decode(errors="replace")


class EngineTest(unittest.TestCase):
    """Base class: a temporary directory and a registry of processes torn down after each test."""

    # The coordinator's and workers' heartbeat: a worker silent for 3 of them is lost. Short, so
    # that tests of loss and restart are quick; a test class that checks no loss may lengthen it.
    HEARTBEAT = "300ms"

    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="motionpipe_engine_")
        self.processes = []

    def tearDown(self):
        # Python 3.11 keeps the outcome in _outcome.result; older versions had _outcome.success.
        result = getattr(self._outcome, "result", None)
        failed = not getattr(self._outcome, "success", True) or bool(
            result is not None and (getattr(result, "failures", None) or getattr(result, "errors", None)))
        for p in self.processes:
            p.stop(signal.SIGKILL, timeout=2)
        if failed:
            for p in self.processes:
                print(f"--- {' '.join(p.args[:3])} ---\n{p.output()[-3000:]}")
        shutil.rmtree(self.dir, ignore_errors=True)

    def path(self, *parts):
        return os.path.join(self.dir, *parts)

    def spawn(self, args, name, env=None):
        p = Process(args, self.path(f"{name}.log"), env=env)
        self.processes.append(p)
        return p

    def coordinator(self, host="127.0.0.1", extra=(), journal=None, port=None, control_port=None, metrics_port=None, env=None):
        self.worker_port = port or free_port(host)
        self.control_port = control_port or free_port()
        self.workers_endpoint = f"tcp://{host}:{self.worker_port}"
        self.control = f"tcp://127.0.0.1:{self.control_port}"
        args = [MOTIONPIPE, "coordinator", "--bind", self.workers_endpoint, "--control", self.control,
                "--journal", journal or self.path("journal.sqlite"), "--heartbeat", self.HEARTBEAT]
        if metrics_port:
            args += ["--metrics", f"127.0.0.1:{metrics_port}"]
        proc = self.spawn(args + list(extra), f"coordinator-{len(self.processes)}", env=env)
        self.wait_until(lambda: self.try_status() is not None, 10, "the coordinator to answer")
        return proc

    def worker(self, name, extra=(), endpoint=None, credit=2, heartbeat=None, env=None):
        args = [MOTIONPIPE, "worker", "--coordinator", endpoint or self.workers_endpoint, "--name", name,
                "--credit", str(credit), "--heartbeat", heartbeat or self.HEARTBEAT]
        return self.spawn(args + list(extra), f"worker-{name}-{len(self.processes)}", env=env)

    def cli(self, *args, check=True, timeout=120):
        result = subprocess.run([MOTIONPIPE, *args], capture_output=True, text=True, timeout=timeout)
        if check and result.returncode != 0:
            raise AssertionError(f"motionpipe {' '.join(args)} exited {result.returncode}:\n{result.stdout}{result.stderr}")
        return result

    def write_pipeline(self, name, text):
        path = self.path(name)
        with open(path, "w") as f:
            f.write(text.replace("OUT", self.path("out")))
        return path

    def submit(self, pipeline, *overrides):
        return int(self.cli("submit", pipeline, *overrides, "--control", self.control).stdout.strip())

    def try_status(self, job=None):
        args = ["status", "--json", "--control", self.control] + ([str(job)] if job else [])
        try:
            result = subprocess.run([MOTIONPIPE, *args], capture_output=True, text=True, timeout=15)
        except subprocess.TimeoutExpired:
            return None
        if result.returncode != 0:
            return None
        return json.loads(result.stdout)

    def status(self, job=None):
        status = self.try_status(job)
        self.assertIsNotNone(status, "status failed")
        return status

    def job(self, job):
        return self.status(job)["jobs"][0]

    def wait_job(self, job, timeout=120):
        result = self.cli("wait", str(job), "--control", self.control, "--timeout", f"{timeout}s", check=False, timeout=timeout + 30)
        return result.returncode, result.stdout

    def wait_until(self, predicate, timeout, what):
        deadline = time.time() + timeout
        while time.time() < deadline:
            if predicate():
                return
            time.sleep(0.1)
        raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def http_get(url, timeout=5):
    with urllib.request.urlopen(url, timeout=timeout) as response:
        return response.read().decode()


def metric(text, name, labels=None):
    """Sum of the samples of a Prometheus metric (optionally with labels as 'key="value"' fragments)."""
    total = 0.0
    found = False
    for line in text.splitlines():
        if line.startswith("#") or not line.startswith(name):
            continue
        head, _, value = line.rpartition(" ")
        if head.split("{")[0] != name:
            continue
        if labels and not all(fragment in head for fragment in labels):
            continue
        total += float(value)
        found = True
    return total if found else None


def output_files(job_dir, stage):
    """{task dir name: sha of out.txt} for a stage of test.write tasks."""
    import hashlib
    result = {}
    stage_dir = os.path.join(job_dir, stage)
    for name in sorted(os.listdir(stage_dir)):
        if name.startswith("."):
            continue
        with open(os.path.join(stage_dir, name, "out.txt"), "rb") as f:
            result[name] = hashlib.sha256(f.read()).hexdigest()
    return result
