"""deploy/slurm/motionpipe.sbatch on a real one-node Slurm cluster (Debian's slurmctld, slurmd and
munge, installed by scripts/setup): brought up on loopback by the test in a temporary directory (its
own slurm.conf, state, spool and munge socket and key), submitted to with sbatch, watched through
scontrol, and stopped again, nothing left running. Four runs of the script:
  - a pipeline runs to COMPLETED, its outputs byte for byte those of a local `motionpipe run`, and
    its worker step drains instead of being killed;
  - `scontrol requeue` in the middle: the requeued allocation resumes the same motionpipe job from
    the journal, no task committed before the requeue runs again, nothing is lost;
  - preemption, `scancel --batch --signal=TERM` (what `--signal=B:TERM@120` sends before the time
    limit): the workers drain and hand back their tasks, the Slurm job ends, and a resubmission of
    the same command completes the same motionpipe job;
  - workers that cannot start (their /metrics port taken): the Slurm job ends FAILED with the
    reason instead of waiting until its time limit.
Where the cluster cannot run here the test skips with the exact reason; there is no fake scheduler."""
import glob
import hashlib
import os
import random
import shutil
import signal
import socket
import sqlite3
import subprocess
import tempfile
import time
import unittest

from harness import MOTIONPIPE

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SBATCH = os.path.join(ROOT, "deploy", "slurm", "motionpipe.sbatch")
DAEMONS = ("munged", "slurmctld", "slurmd")
ENDED = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY", "BOOT_FAIL", "DEADLINE"}


def port_is_free(port):
    with socket.socket() as s:
        try:
            s.bind(("0.0.0.0", port))
            return True
        except OSError:
            return False


def free_port(taken=(), span=1):
    """A port p with p .. p+span-1 all free and none in `taken`. Below Linux's ephemeral range
    (32768-60999), where loopback clients take their ports. A port is released when this returns,
    so the ports a test needs at once are drawn together (see `taken`), never twice."""
    for _ in range(200):
        port = random.randint(20000, 32000 - span)
        block = range(port, port + span)
        if not any(p in taken for p in block) and all(port_is_free(p) for p in block):
            return port
    raise RuntimeError("no free port in 20000-32000")


def wait_for(predicate, timeout, what, explain=None):
    """`explain`, when given, says on a timeout what the cluster and the job were doing."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    detail = ""
    if explain is not None:
        try:
            detail = "\n" + explain()
        except Exception as e:  # the explanation must not hide the timeout
            detail = f"\n(could not explain: {e})"
    raise AssertionError(f"timed out after {timeout} s waiting for {what}{detail}")


class Cluster:
    """A one-node Slurm cluster on loopback, in `root`, with its own munge."""

    def __init__(self, root):
        self.root = root
        self.conf = os.path.join(root, "slurm.conf")
        self.env = dict(os.environ, SLURM_CONF=self.conf)
        self.pids = {}

    def start(self):
        for d in ("state", "spool", "log"):
            os.makedirs(os.path.join(self.root, d))
        os.chmod(self.root, 0o700)
        key = os.path.join(self.root, "munge.key")
        with open(key, "wb") as f:
            f.write(os.urandom(1024))
        os.chmod(key, 0o400)
        self.socket = os.path.join(self.root, "munge.socket")
        subprocess.run(["munged", f"--socket={self.socket}", f"--key-file={key}", f"--pid-file={self.root}/munged.pid",
                        f"--log-file={self.root}/log/munged.log", f"--seed-file={self.root}/munge.seed", "--force"],
                       check=True, capture_output=True, timeout=30)
        self.pids["munged"] = self.pid("munged")
        host = socket.gethostname().split(".")[0]
        ports = [free_port()]
        ports.append(free_port(taken=ports))
        self.ports = ports
        with open(self.conf, "w") as f:
            f.write(f"""ClusterName=motionpipe-test
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ports[0]}
SlurmdPort={ports[1]}
AuthType=auth/munge
AuthInfo=socket={self.socket}
CredType=cred/munge
StateSaveLocation={self.root}/state
SlurmdSpoolDir={self.root}/spool
SlurmctldPidFile={self.root}/slurmctld.pid
SlurmdPidFile={self.root}/slurmd.pid
SlurmctldLogFile={self.root}/log/slurmctld.log
SlurmdLogFile={self.root}/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SlurmUser=root
SlurmdUser=root
ReturnToService=2
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName={host} NodeAddr=127.0.0.1 CPUs={os.cpu_count()} RealMemory=1000 State=UNKNOWN
PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP
""")
        subprocess.run(["slurmctld", "-i", "-f", self.conf], check=True, env=self.env, capture_output=True, timeout=30)
        self.pids["slurmctld"] = wait_for(lambda: self.pid("slurmctld"), 20, "slurmctld's pid file")
        subprocess.run(["slurmd", "-f", self.conf], check=True, env=self.env, capture_output=True, timeout=30)
        self.pids["slurmd"] = wait_for(lambda: self.pid("slurmd"), 20, "slurmd's pid file")
        wait_for(lambda: self.run("sinfo", "-h", "-o", "%T").stdout.strip() == "idle", 60, "the node to be idle")

    def pid(self, daemon):
        try:
            with open(os.path.join(self.root, f"{daemon}.pid")) as f:
                return int(f.read().strip() or 0)
        except (FileNotFoundError, ValueError):
            return 0

    def stop(self):
        if self.pids.get("slurmctld"):
            self.run("scancel", "--state=RUNNING", "--signal=KILL", "--full", "-u", "root", check=False)
            self.run("scancel", "-u", "root", check=False)
        for daemon in reversed(DAEMONS):
            pid = self.pids.get(daemon, 0)
            if not pid:
                continue
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
            deadline = time.time() + 15
            while time.time() < deadline and os.path.exists(f"/proc/{pid}"):
                time.sleep(0.1)
            if os.path.exists(f"/proc/{pid}"):
                os.kill(pid, signal.SIGKILL)

    def run(self, *args, check=True, timeout=60):
        result = subprocess.run(list(args), capture_output=True, text=True, env=self.env, timeout=timeout)
        if check and result.returncode != 0:
            raise AssertionError(f"{' '.join(args)} exited {result.returncode}: {result.stdout}{result.stderr}")
        return result

    def job(self, job_id):
        out = self.run("scontrol", "show", "job", str(job_id), "-o").stdout
        return dict(field.split("=", 1) for field in out.split() if "=" in field)

    def log(self, name):
        with open(os.path.join(self.root, "log", name), errors="replace") as f:
            return f.read()


def skip_reason():
    if os.geteuid() != 0:
        return f"slurmd runs as root in this test (SlurmdUser=root, proctrack/linuxproc); uid is {os.geteuid()}"
    missing = [b for b in ("munged", "slurmctld", "slurmd", "sbatch", "scontrol", "squeue") if shutil.which(b) is None]
    if missing:
        return f"not installed: {', '.join(missing)} (scripts/setup installs slurmctld slurmd slurm-client munge)"
    host = socket.gethostname().split(".")[0]
    try:
        socket.gethostbyname(host)  # the script's workers reach the coordinator by the node's name
    except OSError as e:
        return f"this host's name {host!r} does not resolve ({e}); Slurm's node name is the host name"
    return None


@unittest.skipIf(skip_reason(), skip_reason())
class SlurmScript(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(prefix="motionpipe_slurm_")
        cls.cluster = Cluster(os.path.join(cls.dir, "cluster"))
        try:
            cls.cluster.start()
        except Exception:
            cls.cluster.stop()
            for name in ("slurmctld.log", "slurmd.log", "munged.log"):
                try:
                    print(f"--- {name} ---\n{cls.cluster.log(name)[-3000:]}")
                except FileNotFoundError:
                    pass
            shutil.rmtree(cls.dir, ignore_errors=True)
            raise

    @classmethod
    def tearDownClass(cls):
        cls.cluster.stop()
        left = [d for d, pid in cls.cluster.pids.items() if pid and os.path.exists(f"/proc/{pid}")]
        shutil.rmtree(cls.dir, ignore_errors=True)
        assert not left, f"still running: {left}"

    def setUp(self):
        self.work = tempfile.mkdtemp(dir=self.dir)
        # The coordinator's workers', control and metrics ports; the worker serves /metrics on the
        # metrics port + 1 (motionpipe.sbatch), so that one is drawn free as well. None is Slurm's.
        taken = list(self.cluster.ports)
        workers_port = free_port(taken)
        control_port = free_port(taken + [workers_port])
        metrics_port = free_port(taken + [workers_port, control_port], span=2)
        self.ports = [workers_port, control_port, metrics_port]
        self.state = os.path.join(self.work, "state")
        self.exec_log = os.path.join(self.work, "executions.log")

    def pipeline(self, tasks, ms, name="p.yaml", output_root=None):
        path = os.path.join(self.work, name)
        with open(path, "w") as f:
            f.write(f"name: slurmtest\noutput_root: {output_root or os.path.join(self.work, 'out')}\nseed: 5\nstages:\n"
                    f"  w: {{kind: test.write, params: {{tasks: {tasks}, ms: {ms}, bytes: 256, log: {self.exec_log}}}}}\n")
        return path

    def sbatch(self, pipeline, **extra_env):
        env = dict(self.cluster.env, **extra_env, MOTIONPIPE=MOTIONPIPE, MOTIONPIPE_LOG="info", MOTIONPIPE_STATE=self.state,
                   MOTIONPIPE_PORT=str(self.ports[0]), MOTIONPIPE_CONTROL_PORT=str(self.ports[1]),
                   MOTIONPIPE_METRICS_PORT=str(self.ports[2]))
        out = subprocess.run(["sbatch", "--parsable", "--nodes=1", "--cpus-per-task=1", "--time=10",
                              f"--output={self.work}/slurm-%j.log", SBATCH, pipeline],
                             capture_output=True, text=True, env=env, cwd=self.work, timeout=60)
        self.assertEqual(out.returncode, 0, out.stderr)
        return int(out.stdout.strip().split(";")[0])

    def wait_state(self, job_id, states, timeout=120):
        def reached():
            info = self.cluster.job(job_id)
            if info.get("JobState") in states:
                return info
            if info.get("JobState") in ENDED:  # it will not get there: say why now
                raise AssertionError(f"Slurm job {job_id} ended before reaching {states}\n{self.explain(job_id)}")
            return None

        return wait_for(reached, timeout, f"Slurm job {job_id} to reach {states}", lambda: self.explain(job_id))

    def explain(self, job_id):
        """What Slurm says of the job, the job's own log and the tails of the daemons' logs."""
        info = self.cluster.job(job_id)
        parts = [f"Slurm: JobState={info.get('JobState')} Reason={info.get('Reason')} Restarts={info.get('Restarts')} "
                 f"ports={self.ports} committed={len(self.committed())}"]
        try:
            parts.append(f"--- slurm-{job_id}.log ---\n{self.slurm_log(job_id)[-4000:]}")
        except FileNotFoundError:
            parts.append(f"--- slurm-{job_id}.log: not written ---")
        for name in ("slurmd.log", "slurmctld.log"):
            try:
                parts.append(f"--- {name} (tail) ---\n{self.cluster.log(name)[-2000:]}")
            except FileNotFoundError:
                pass
        return "\n".join(parts)

    def slurm_log(self, job_id):
        with open(os.path.join(self.work, f"slurm-{job_id}.log"), errors="replace") as f:
            return f.read()

    def committed(self):
        path = os.path.join(self.state, "journal.sqlite")
        if not os.path.exists(path):  # the script has not started its coordinator yet
            return set()
        try:
            db = sqlite3.connect(path, timeout=10)
            try:
                return {row[0] for row in db.execute("SELECT idx FROM tasks WHERE job=1 AND state=1")}
            finally:
                db.close()
        except sqlite3.OperationalError:  # created but not yet initialised
            return set()

    def executions(self):
        runs = {}
        with open(self.exec_log) as f:
            for line in f:
                index = int(line.split()[1])
                runs[index] = runs.get(index, 0) + 1
        return runs

    def outputs(self, root):
        digests = {}
        for path in sorted(glob.glob(os.path.join(root, "slurmtest-1", "w", "task-*", "out.txt"))):
            with open(path, "rb") as f:
                digests[os.path.relpath(path, root)] = hashlib.sha256(f.read()).hexdigest()
        return digests

    def test_a_pipeline_runs_to_completed_as_a_local_run_does(self):
        job = self.sbatch(self.pipeline(tasks=20, ms=20))
        info = self.wait_state(job, ENDED)
        log = self.slurm_log(job)
        self.assertEqual(info["JobState"], "COMPLETED", log)
        self.assertEqual(info["ExitCode"], "0:0", log)
        self.assertIn("job 1 succeeded", log)
        self.assertIn("stopped", log)  # the worker drained and stopped ...
        self.assertNotIn("Killed", log)  # ... instead of srun's SIGKILL
        self.assertFalse(os.path.exists(os.path.join(self.state, "job_id")))
        # Secure by default: CurveZMQ with the workers' key on the allow-list, keys private.
        self.assertIn("CurveZMQ on", log)
        self.assertEqual(os.stat(os.path.join(self.state, "keys")).st_mode & 0o777, 0o700)
        local_root = os.path.join(self.work, "local")
        local = subprocess.run([MOTIONPIPE, "run", self.pipeline(tasks=20, ms=0, name="local.yaml", output_root=local_root), "-q",
                                "--workers", "1"], capture_output=True, text=True, timeout=120)
        self.assertEqual(local.returncode, 0, local.stderr)
        slurm_outputs = self.outputs(os.path.join(self.work, "out"))
        self.assertEqual(len(slurm_outputs), 20)
        self.assertEqual(slurm_outputs, self.outputs(local_root))

    def test_plaintext_only_when_asked(self):
        job = self.sbatch(self.pipeline(tasks=3, ms=0), MOTIONPIPE_PLAINTEXT="1")
        info = self.wait_state(job, ENDED)
        log = self.slurm_log(job)
        self.assertEqual(info["JobState"], "COMPLETED", log)
        self.assertIn("MOTIONPIPE_PLAINTEXT=1", log)
        self.assertNotIn("CurveZMQ on", log)
        self.assertFalse(os.path.exists(os.path.join(self.state, "keys")))

    def test_a_requeued_allocation_resumes_the_same_job(self):
        job = self.sbatch(self.pipeline(tasks=60, ms=250))
        self.wait_state(job, {"RUNNING"})
        wait_for(lambda: len(self.committed()) >= 10, 60, "10 committed tasks", lambda: self.explain(job))
        before = self.committed()
        self.cluster.run("scontrol", "requeue", str(job))
        wait_for(lambda: int(self.cluster.job(job).get("Restarts", 0)) == 1 and self.cluster.job(job)["JobState"] == "PENDING", 60,
                 "the job to be requeued", lambda: self.explain(job))
        # Slurm holds a requeued job for about 2 minutes (its BeginTime); release it now.
        self.cluster.run("scontrol", "update", f"JobId={job}", "StartTime=now")
        info = self.wait_state(job, ENDED, timeout=180)
        log = self.slurm_log(job)
        self.assertEqual(info["JobState"], "COMPLETED", log)
        self.assertIn("resuming job 1", log)
        self.assertEqual(len(self.outputs(os.path.join(self.work, "out"))), 60)
        self.assertGreater(len(before), 0)
        self.assertLess(len(before), 60)
        runs = self.executions()
        self.assertEqual(sorted(runs), list(range(60)), "a task never ran")
        self.assertEqual(sorted(i for i in before if runs[i] != 1), [], "tasks committed before the requeue ran again")

    def test_a_job_whose_workers_cannot_start_ends_instead_of_waiting(self):
        # The worker serves /metrics on the metrics port + 1: held here, the worker exits at once.
        with socket.socket() as held:
            held.bind(("0.0.0.0", self.ports[2] + 1))
            held.listen()
            job = self.sbatch(self.pipeline(tasks=5, ms=0))
            info = self.wait_state(job, ENDED, timeout=90)
        log = self.slurm_log(job)
        self.assertEqual(info["JobState"], "FAILED", log)
        self.assertIn("every worker exited before job 1 finished", log)
        self.assertIn("cannot serve /metrics", log)
        self.assertEqual(self.committed(), set())
        with open(os.path.join(self.state, "job_id")) as f:
            self.assertEqual(f.read().strip(), "1")  # kept for a resubmission

    def test_preemption_drains_and_a_resubmission_completes(self):
        pipeline = self.pipeline(tasks=60, ms=250)
        job = self.sbatch(pipeline)
        self.wait_state(job, {"RUNNING"})
        wait_for(lambda: len(self.committed()) >= 10, 60, "10 committed tasks", lambda: self.explain(job))
        # What --signal=B:TERM@120 sends before the time limit, and a preempting scheduler sends.
        self.cluster.run("scancel", "--batch", "--signal=TERM", str(job))
        info = self.wait_state(job, ENDED)
        log = self.slurm_log(job)
        self.assertIn("draining the workers", log)
        self.assertIn("draining (signal)", log)
        self.assertNotIn("Killed", log)
        self.assertEqual(info["ExitCode"], "143:0", log)
        before = self.committed()
        self.assertLess(len(before), 60)
        with open(os.path.join(self.state, "job_id")) as f:
            self.assertEqual(f.read().strip(), "1")  # kept for the resubmission
        again = self.sbatch(pipeline)
        info = self.wait_state(again, ENDED, timeout=180)
        log = self.slurm_log(again)
        self.assertEqual(info["JobState"], "COMPLETED", log)
        self.assertIn("resuming job 1", log)
        self.assertEqual(len(self.outputs(os.path.join(self.work, "out"))), 60)
        runs = self.executions()
        self.assertEqual(sorted(runs), list(range(60)))
        self.assertEqual(sorted(i for i in before if runs[i] != 1), [], "tasks committed before the preemption ran again")


if __name__ == "__main__":
    unittest.main()
