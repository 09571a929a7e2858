#!/usr/bin/python3
"""Two rows of evaluation stages paired by seed, under the report's rule (issue 15).

Each argument before `--` is one replicate of row A (an eval_edit or eval_generate stage directory,
or its task's metrics.json), each after it the replicate of row B with the same seed, in the same
order; a single B stage is one row compared with every A (an untrained row, as the report's gate).
For a metric (a dotted path into metrics.json, e.g. generated_to_target.batches.R@1), prints each
row's mean and standard deviation, the per-seed differences A - B, their mean and two standard
errors, and the verdict the report gives a claim: "holds" when the mean difference beats two
standard errors of the per-seed differences (at least 2 pairs), "not decided" otherwise.

    /usr/bin/python3 tools/seed_pairs.py out/JOB/eval_a out/JOB/eval_a-s2 ... -- out/JOB/eval_b ...
        [--metric generated_to_target.batches.R@1] [--json]
"""
import argparse
import json
import math
import os
import statistics
import sys


class InputError(Exception):
    pass


def metric_of(path, dotted):
    """The metric at `dotted` of a stage directory's (or a metrics.json file's) metrics."""
    file = path
    if os.path.isdir(path):
        file = os.path.join(path, "task-00000", "metrics.json")
    try:
        with open(file) as f:
            value = json.load(f)
    except OSError as e:
        raise InputError(f"{file}: cannot read ({e.strerror})")
    except json.JSONDecodeError as e:
        raise InputError(f"{file}: not JSON ({e})")
    for key in dotted.split("."):
        if not isinstance(value, dict) or key not in value:
            raise InputError(f"{file}: no '{dotted}' (missing '{key}')")
        value = value[key]
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise InputError(f"{file}: '{dotted}' is not a number")
    return float(value)


def compare(a, b):
    """Per-seed differences, their mean, two standard errors and the verdict."""
    if len(b) == 1:
        b = b * len(a)
    if len(a) != len(b):
        raise InputError(f"{len(a)} stages of row A against {len(b)} of row B: pair them by seed, or give one B")
    diffs = [x - y for x, y in zip(a, b)]
    mean = statistics.mean(diffs)
    two_se = 2 * statistics.stdev(diffs) / math.sqrt(len(diffs)) if len(diffs) > 1 else float("nan")
    holds = len(diffs) > 1 and mean > two_se
    return {"differences": diffs, "mean": mean, "two_se": two_se, "verdict": "holds" if holds else "not decided"}


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     usage="seed_pairs.py A_STAGE... [--metric M] [--json] -- B_STAGE...")
    parser.add_argument("stages", nargs="+", help="row A's stages (then --, then row B's)")
    parser.add_argument("--metric", default="generated_to_target.batches.R@1")
    parser.add_argument("--json", action="store_true")
    if "--" not in argv:
        print("seed_pairs: separate row A's stages from row B's with --", file=sys.stderr)
        return 2
    cut = argv.index("--")
    args = parser.parse_args(argv[:cut])
    try:
        if not argv[cut + 1:]:
            raise InputError("give row B's stages after --")
        a = [metric_of(s, args.metric) for s in args.stages]
        b = [metric_of(s, args.metric) for s in argv[cut + 1:]]
        result = compare(a, b)
    except InputError as e:
        print(f"seed_pairs: {e}", file=sys.stderr)
        return 2
    result.update({"metric": args.metric, "a": a, "b": b})
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    sd = lambda v: statistics.stdev(v) if len(v) > 1 else 0.0  # noqa: E731
    print(f"{args.metric}: A {statistics.mean(a):.3f} ± {sd(a):.3f} (n={len(a)}), "
          f"B {statistics.mean(b):.3f} ± {sd(b):.3f} (n={len(b)})")
    print(f"  A - B {result['mean']:+.3f}, 2 SE {result['two_se']:.3f} (per seed "
          + ", ".join(f"{d:+.3f}" for d in result["differences"]) + f"): {result['verdict']}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
