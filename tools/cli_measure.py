#!/usr/bin/python3
"""The command line's post-processes measured on a demo job's models (README "Post-processes from
the command line"): `motionpipe generate` of the first N test two-action spans' texts at their
lengths (seeds 1..N), raw against `--match-legs JOB/corpus --foot-lock`; `motionpipe edit` of the
CMU clips in data/mocap/cmu (DDIM 20), raw against `--foot-lock` and against `--clean-legs
JOB/cleanup --foot-lock`. Reads the plausibility lines the commands print; prints each command's
figures and their means over the motions (foot skate, GMD's ratio, frames floating, jerk).

    /usr/bin/python3 tools/cli_measure.py out/demo-1 32
"""
import argparse
import glob
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
MOTIONPIPE = os.environ.get("MOTIONPIPE_BIN", os.path.join(ROOT, "build", "cli", "motionpipe"))
LINE = re.compile(r"plausibility(?:, ([^:]+))?: foot skate (\d\.\d+) of contact frames \(GMD's ratio (\d\.\d+)\), "
                  r"floating (\d\.\d+), jerk (\d+)")


def plausibility(args):
    """{"raw" | what ran: (skate, gmd, floating, jerk)} from one command's output."""
    result = subprocess.run([MOTIONPIPE, *args], capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"motionpipe {' '.join(args)} exited {result.returncode}:\n{result.stderr}")
    return {(m.group(1) or "raw"): tuple(float(x) for x in m.groups()[1:]) for m in LINE.finditer(result.stdout)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("job", help="a demo job's directory (sinc, mdt, cleanup, corpus, gen_sinc)")
    parser.add_argument("n", type=int, nargs="?", default=32, help="test spans generated")
    a = parser.parse_args()
    generated = os.path.join(a.job, "gen_sinc", "task-00000", "generated.npz")
    if not os.path.isfile(generated):
        sys.exit(f"{generated}: not found (not a demo job?)")
    rows = {}
    with tempfile.TemporaryDirectory() as tmp, np.load(generated) as z:
        for i in range(min(a.n, len(z["ids"]))):
            text = str(z["texts"][z["text_offsets"][i]])
            seconds = (z["offsets"][i + 1] - z["offsets"][i]) / float(z["fps"][i])
            got = plausibility(["generate", "--model", os.path.join(a.job, "sinc"), "--text", text, "--seconds",
                                f"{seconds:.4f}", "--seed", str(i + 1), "--match-legs", os.path.join(a.job, "corpus"),
                                "--foot-lock", "--out", os.path.join(tmp, "g.npz")])
            for k, v in got.items():
                rows.setdefault("SINC, " + k, []).append(v)
            print(i, text, got, flush=True)
        for clip in sorted(glob.glob(os.path.join(ROOT, "data", "mocap", "cmu", "*.bvh"))):
            for name, extra in (("foot_lock", ["--foot-lock"]),
                                ("clean_legs + foot_lock", ["--clean-legs", os.path.join(a.job, "cleanup"), "--foot-lock"])):
                got = plausibility(["edit", "--model", os.path.join(a.job, "mdt"), "--source", clip, "--text",
                                    "raise the left arm higher", "--sampler", "ddim", "--steps", "20", "--out",
                                    os.path.join(tmp, "e.npz"), *extra])
                if name == "foot_lock":
                    rows.setdefault("MDT, CMU clips, raw", []).append(got["raw"])
                rows.setdefault("MDT, CMU clips, " + name, []).append(got[name])
                print(os.path.basename(clip), got, flush=True)
    for k, v in rows.items():
        m = np.array(v).mean(axis=0)
        print(f"{k:45s} n={len(v):3d}  foot skate {m[0]:.3f}  GMD's {m[1]:.3f}  floating {m[2]:.2f}  jerk {m[3]:.0f}")


if __name__ == "__main__":
    main()
