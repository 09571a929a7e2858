"""The Kubernetes manifests in deploy/k8s, validated against the Kubernetes API's schema by a real
validator (kubernetes-models, installed by scripts/setup into tools/k8s-validate), and the same
validator rejecting manifests broken the ways a hand edit breaks them."""
import glob
import os
import subprocess
import tempfile
import unittest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
TOOL = os.path.join(ROOT, "tools", "k8s-validate")
MANIFESTS = sorted(glob.glob(os.path.join(ROOT, "deploy", "k8s", "*.yaml")))


def validate(*files):
    return subprocess.run(["node", os.path.join(TOOL, "validate.mjs"), *files], capture_output=True, text=True, timeout=120)


class KubernetesManifests(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        if not os.path.isdir(os.path.join(TOOL, "node_modules", "kubernetes-models")):
            raise AssertionError(f"{TOOL}/node_modules is missing: scripts/setup installs the validator (npm ci)")

    def test_every_manifest_is_valid(self):
        self.assertGreaterEqual(len(MANIFESTS), 4)
        result = validate(*MANIFESTS)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        kinds = [line.split("] ")[1].split(" ")[0] for line in result.stdout.splitlines() if line.endswith(": valid")]
        self.assertEqual(sorted(kinds), ["Deployment", "Deployment", "Job", "NetworkPolicy", "PersistentVolumeClaim", "Service"])

    def test_broken_manifests_are_rejected_with_the_field(self):
        with open(os.path.join(ROOT, "deploy", "k8s", "workers.yaml")) as f:
            workers = f.read()
        self.assertIn("containerPort:", workers)
        cases = {
            "replicas.yaml": (workers.replace("replicas: ", "replicas: two #", 1), "replicas must be integer"),
            "port.yaml": (workers.replace("containerPort:", "containerPrt:", 1), "must have required property containerPort"),
            "kind.yaml": ("apiVersion: apps/v9\nkind: Deployment\nmetadata: {name: x}\n", "no schema for apps/v9 Deployment"),
            "yaml.yaml": ("kind: [\n", "not YAML"),
        }
        with tempfile.TemporaryDirectory() as tmp:
            for name, (text, expected) in cases.items():
                path = os.path.join(tmp, name)
                with open(path, "w") as f:
                    f.write(text)
                result = validate(path)
                self.assertEqual(result.returncode, 1, f"{name}: {result.stdout}")
                self.assertIn(path, result.stdout)
                self.assertIn(expected, result.stdout, name)


if __name__ == "__main__":
    unittest.main()
