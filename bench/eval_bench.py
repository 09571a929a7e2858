#!/usr/bin/python3
"""Evaluation throughput: configs/eval.yaml (edit the test split with every editor, generate the test
pairs with every generator, score them all, write the report) run through 1 and then 2 local workers
on the same trained checkpoints, in the same session.

Prints the wall time of each run and their ratio, and from the stages' own records: motions scored
per second by the eval stages (evaluator loading, encoding and metrics; generated and reference
motions both count), edits per second and generations per second.

  bench/eval_bench.py [--job-edit 'out/claims_edit-*'] [--job-sinc 'out/claims_sinc-*'] [--edit-limit 32] [--ddpm-limit 4]
                      [--gen-limit 64] [--threads 1]

Needs the trained claims jobs (`scripts/demo claims-edit`, `scripts/demo claims-sinc`); --job-edit and
--job-sinc name them by pattern.
"""
import argparse
import glob
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(motionpipe, workers, args, root):
    overrides = [f"output_root={root}", f"vars.job_edit={args.job_edit}", f"vars.job_sinc={args.job_sinc}", f"vars.clips={args.clips}", f"vars.edit_limit={args.edit_limit}",
                 f"vars.edit_steps={args.edit_steps}", f"vars.ddpm_limit={args.ddpm_limit}", f"vars.gen_limit={args.gen_limit}",
                 f"vars.history={root}/history.sqlite"]
    started = time.monotonic()
    threads = ["--threads", str(args.threads)] if args.threads else []
    result = subprocess.run([motionpipe, "run", os.path.join(ROOT, "configs", "eval.yaml"), "--workers", str(workers), "--quiet"] + threads + overrides,
                            capture_output=True, text=True, cwd=ROOT)
    seconds = time.monotonic() - started
    if result.returncode != 0:
        sys.exit(f"eval_bench: the {workers}-worker run failed:\n{result.stdout[-3000:]}{result.stderr[-3000:]}")
    job = sorted(glob.glob(os.path.join(root, "eval-*")))[-1]
    scored, edits, gens = [], [], []
    for path in glob.glob(os.path.join(job, "eval_*", "task-00000", "metrics.json")):
        with open(path) as f:
            m = json.load(f)
        scored.append(m["motions_scored"] / m["seconds"])
    for path in glob.glob(os.path.join(job, "edit_*", "task-*", "edits.json")):
        with open(path) as f:
            edits.append(json.load(f))
    for path in glob.glob(os.path.join(job, "gen_*", "task-*", "generate.json")):
        with open(path) as f:
            gens.append(json.load(f))
    rate = lambda records, key: sum(r[key] for r in records) / max(1e-9, sum(r["seconds"] for r in records))
    return {"seconds": seconds, "scored_per_s": statistics.median(scored), "eval_stages": len(scored),
            "edits": sum(r["edited"] for r in edits), "edits_per_s": rate(edits, "edited"),
            "generated": sum(r.get("generated", 0) for r in gens), "generated_per_s": rate(gens, "generated") if gens else 0.0}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--job-edit", default="out/claims_edit-*", help="pattern of the editors' training job")
    parser.add_argument("--job-sinc", default="out/claims_sinc-*", help="pattern of the generators' training job")
    parser.add_argument("--clips", type=int, default=1500, help="the trained jobs' corpus size (the claims runs': 1500)")
    parser.add_argument("--edit-limit", type=int, default=32)
    parser.add_argument("--edit-steps", type=int, default=20)
    parser.add_argument("--ddpm-limit", type=int, default=4)
    parser.add_argument("--gen-limit", type=int, default=64)
    parser.add_argument("--threads", type=int, default=0, help="threads per worker (default: motionpipe run's, cores / workers)")
    parser.add_argument("--motionpipe", default=os.path.join(ROOT, "build", "cli", "motionpipe"))
    args = parser.parse_args()
    for pattern, stage, command in ((args.job_edit, "mdt", "claims-edit"), (args.job_sinc, "sinc", "claims-sinc")):
        if not glob.glob(os.path.join(ROOT, pattern, stage)):
            sys.exit(f"eval_bench: no trained job matches {pattern} (run scripts/demo {command} first)")
    scratch = tempfile.mkdtemp(prefix="eval_bench-")
    try:
        one = run(args.motionpipe, 1, args, os.path.join(scratch, "w1"))
        two = run(args.motionpipe, 2, args, os.path.join(scratch, "w2"))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    print(f"eval_bench: configs/eval.yaml on {args.job_edit} and {args.job_sinc}: {one['edits']} edits (DDIM {args.edit_steps} / DDPM 300), "
          f"{one['generated']} generations, {one['eval_stages']} eval stages, the report")
    print(f"{'workers':>8} {'wall s':>8} {'scored motions/s':>17} {'edits/s':>8} {'generations/s':>14}")
    for workers, r in ((1, one), (2, two)):
        print(f"{workers:>8} {r['seconds']:>8.1f} {r['scored_per_s']:>17.1f} {r['edits_per_s']:>8.3f} {r['generated_per_s']:>14.1f}")
    print(f"speed-up of 2 workers over 1: {one['seconds'] / two['seconds']:.2f}x (wall time of the whole evaluation; "
          f"threads per worker: {args.threads or 'cores / workers'})")


if __name__ == "__main__":
    main()
