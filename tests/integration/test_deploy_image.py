"""deploy/docker/Dockerfile, checked without a Docker engine (this machine has none): what its runtime
stage installs must run what its build stage builds. Every library that the CLI and each plugin
name (readelf's NEEDED entries) must come from a package the runtime stage installs, from one of
their dependencies (dpkg's records, followed recursively), or from the base image's required set;
and the build stage must build and copy every plugin. Both are read from the Dockerfile's own
lines, so an edit that drops a package or a plugin fails here, as a binary that gains a library
does."""
import glob
import os
import re
import subprocess
import unittest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
DOCKERFILE = os.path.join(ROOT, "deploy", "docker", "Dockerfile")
BIN = os.environ.get("MOTIONPIPE_BIN", os.path.join(ROOT, "build", "cli", "motionpipe"))
PLUGINS = os.environ.get("MOTIONPIPE_PLUGIN_PATH", os.path.join(ROOT, "build", "plugins"))


def stages(text):
    """The Dockerfile's stages, each its RUN commands with continuations joined."""
    joined = re.sub(r"\\\n", " ", text)
    out = []
    for line in joined.splitlines():
        line = line.strip()
        if line.startswith("FROM "):
            out.append({"from": line.split()[1], "run": []})
        elif line.startswith("RUN ") and out:
            out[-1]["run"].append(line[4:])
    return out


def installed(run_lines):
    """The packages an `apt-get install` of these RUN lines names."""
    packages = []
    for command in " ".join(run_lines).split("&&"):
        words = command.split()
        if words[:2] == ["apt-get", "install"]:
            packages += [w for w in words[2:] if not w.startswith("-")]
    return packages


def needed(binary):
    dynamic = subprocess.run(["readelf", "-d", binary], capture_output=True, text=True, check=True).stdout
    return re.findall(r"\(NEEDED\)\s+Shared library: \[(.+?)\]", dynamic)


def library_paths():
    """soname -> path for this machine's x86-64 libraries (ldconfig's cache)."""
    out = {}
    for line in subprocess.run(["ldconfig", "-p"], capture_output=True, text=True, check=True).stdout.splitlines():
        m = re.match(r"\s*(\S+) \((.+?)\) => (\S+)", line)
        if m and "x86-64" in m.group(2):
            out.setdefault(m.group(1), m.group(3))
    return out


def owner(path):
    """The package that ships a file (merged /usr: either spelling)."""
    real = os.path.realpath(path)
    for candidate in {path, real, "/usr" + path if not path.startswith("/usr") else path[4:],
                      "/usr" + real if not real.startswith("/usr") else real[4:]}:
        result = subprocess.run(["dpkg", "-S", candidate], capture_output=True, text=True)
        if result.returncode == 0:
            return result.stdout.split(":")[0].strip()
    return None


def depends_closure(packages):
    """The packages and, recursively, what dpkg records they depend on (alternatives: every one)."""
    rows = subprocess.run(["dpkg-query", "-W", "-f=${Package}\t${Depends}, ${Pre-Depends}, ${Provides}\n"],
                          capture_output=True, text=True, check=True).stdout.splitlines()
    depends = {}
    for row in rows:
        name, _, deps = row.partition("\t")
        depends.setdefault(name, []).extend(
            d.strip().split(" ")[0].split(":")[0] for d in re.split(r"[,|]", deps) if d.strip())
    seen, todo = set(), list(packages)
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo += depends.get(name, [])
    return seen


def required_packages():
    rows = subprocess.run(["dpkg-query", "-W", "-f=${Package} ${Priority} ${Essential}\n"],
                          capture_output=True, text=True, check=True).stdout.splitlines()
    return [r.split()[0] for r in rows if " required" in r or r.endswith(" yes")]


class ContainerImage(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        with open(DOCKERFILE) as f:
            cls.stages = stages(f.read())

    def test_two_stages_from_debian_bookworm(self):
        self.assertEqual([s["from"] for s in self.stages], ["debian:bookworm", "debian:bookworm-slim"])

    def test_the_build_stage_builds_and_copies_every_plugin(self):
        build = " ".join(self.stages[0]["run"])
        ninja = re.search(r"ninja -C build ([^&]+)", build)
        self.assertIsNotNone(ninja, build)
        self.assertIn("motionpipe_plugins", ninja.group(1).split(), "the build stage builds only " + ninja.group(1))
        self.assertIn("cp build/plugins/*.so", build)

    def test_the_build_stage_installs_what_the_build_needs_and_leaves_the_host_tree_out(self):
        # `scripts/setup --build-only`: the packages every find_package of a build without tests
        # and benchmarks needs, and no npm step (whose registry certificate a builder may not
        # trust: the first build of this image here failed there). The context leaves a host's
        # build tree out: its CMakeCache.txt names another source directory, which `cmake -S . -B
        # build` in the image refuses.
        build = " ".join(self.stages[0]["run"])
        self.assertIn("scripts/setup --build-only", build)
        with open(os.path.join(ROOT, "scripts", "setup")) as f:
            setup = f.read()
        listed = re.search(r"BUILD_PACKAGES=\(\n(.*?)\n\)", setup, re.S)
        self.assertIsNotNone(listed)
        packages = set(re.sub(r"#.*", "", listed.group(1)).split())
        for package in ("libtorch-dev", "libzmq3-dev", "cppzmq-dev", "libprotobuf-dev", "protobuf-compiler",
                        "libyaml-cpp-dev", "prometheus-cpp-dev", "libsqlite3-dev", "libcli11-dev", "libcurl4-openssl-dev",
                        "nlohmann-json3-dev", "zlib1g-dev"):
            self.assertIn(package, packages)
        self.assertFalse(packages & {"libgtest-dev", "nodejs", "npm", "slurmd", "prometheus", "python3-torch"}, packages)
        with open(os.path.join(ROOT, ".dockerignore")) as f:
            ignored = {line.strip().rstrip("/") for line in f if line.strip() and not line.startswith("#")}
        for path in ("build", "out", "tools/k8s-validate/node_modules"):
            self.assertIn(path, ignored)

    def test_the_runtime_stage_has_every_library_the_binaries_need(self):
        plugins = sorted(glob.glob(os.path.join(PLUGINS, "*.so")))
        self.assertGreaterEqual(len(plugins), 6, PLUGINS)
        runtime = installed(self.stages[1]["run"])
        self.assertIn("libzmq5", runtime)
        available = depends_closure(runtime + required_packages())
        paths = library_paths()
        missing = {}
        for binary in [BIN] + plugins:
            for soname in needed(binary):
                path = paths.get(soname)
                self.assertIsNotNone(path, f"{binary}: {soname} is not a library of this machine")
                package = owner(path)
                self.assertIsNotNone(package, f"{binary}: no package ships {path}")
                if package not in available:
                    missing.setdefault(package, []).append(f"{os.path.basename(binary)} ({soname})")
        self.assertEqual(missing, {}, "the runtime stage of deploy/docker/Dockerfile lacks packages: " +
                         "; ".join(f"{p} for {', '.join(w)}" for p, w in sorted(missing.items())))

    def test_the_check_is_not_vacuous(self):
        # The base image alone has neither ZeroMQ nor LibTorch, and the check knows which package
        # ships each. (A single dropped package can come back through another's dependencies:
        # LibTorch's pull in libzmq5, so the check asks what the binaries need, not the list.)
        base = depends_closure(required_packages())
        for package in ("libzmq5", "libtorch1.13", "libprometheus-cpp-push1.0"):
            self.assertNotIn(package, base)
        paths = library_paths()
        self.assertEqual(owner(paths["libzmq.so.5"]), "libzmq5")
        self.assertEqual(owner(paths["libtorch_cpu.so.1.13"]), "libtorch1.13")

if __name__ == "__main__":
    unittest.main()
