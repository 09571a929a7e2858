#!/usr/bin/env python3
"""How many of a split's two-action spans ask for an action pair that the training split already
holds as a real pair (issue 15: why SINC's synthetic pairs add little on the procedural corpus).

SINC's synthetic pairs teach combinations of actions; a test span whose two actions were seen
together in a real training pair leaves them little to teach. The spans' texts are paraphrases,
so each text is mapped to its action through the corpus vocabulary's text templates
(core/src/corpus/vocabulary.cc: every action's short and long texts, `{placeholder}` matching any
words). Usage:

  /usr/bin/python3 tools/pair_coverage.py out/JOB/singles/task-00000/spans.npz [--split test] [--json]
"""
import argparse
import collections
import json
import os
import re
import statistics
import sys

import numpy as np

VOCABULARY = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "core", "src", "corpus", "vocabulary.cc")


class InputError(Exception):
    pass


def template_pattern(template):
    """A text template as a regular expression: ` {x}` may be absent, `{x}` is any words."""
    out, pos = "", 0
    for m in re.finditer(r"( ?)\{\w+\}", template):
        out += re.escape(template[pos:m.start()])
        out += "( .+)?" if m.group(1) else ".+"
        pos = m.end()
    return re.compile("^" + out + re.escape(template[pos:]) + "$")


def read_vocabulary(path):
    """(pattern, action name) for every text template of every action definition `{A::kX, "name", ...}`."""
    try:
        with open(path) as f:
            source = f.read()
    except OSError as e:
        raise InputError(f"{path}: cannot read the vocabulary ({e.strerror})")
    patterns = []
    for entry in re.split(r"\{A::k\w+,", source)[1:]:
        entry = entry.split("\n}")[0]  # the last definition ends with its function
        strings = re.findall(r'"((?:[^"\\]|\\.)*)"', entry)
        if len(strings) < 2:
            raise InputError(f"{path}: an action definition without a name and texts: {entry[:60]!r}")
        patterns += [(template_pattern(t), strings[0]) for t in strings[1:]]
    if not patterns:
        raise InputError(f"{path}: no action definitions ({{A::k...}}) found")
    return patterns


def read_spans(path):
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: cannot read the spans ({e})")
    with z:
        missing = [k for k in ("splits", "text_a", "text_b") if k not in z.files]
        if missing:
            raise InputError(f"{path}: not a singles stage's spans.npz (no {', '.join(missing)})")
        splits, a, b = z["splits"], z["text_a"], z["text_b"]
    if not (len(splits) == len(a) == len(b)):
        raise InputError(f"{path}: splits, text_a and text_b differ in length")
    return [str(s) for s in splits], [str(t) for t in a], [str(t) for t in b]


def coverage(patterns, splits, text_a, text_b, split):
    cache = {}

    def action(text):
        if text not in cache:
            hits = sorted({name for rx, name in patterns if rx.match(text)})
            cache[text] = "|".join(hits) if hits else None
        return cache[text]

    def pair(i):
        return frozenset((action(text_a[i]) or "?" + text_a[i], action(text_b[i]) or "?" + text_b[i]))

    two = [i for i in range(len(splits)) if text_b[i]]
    training = collections.Counter(pair(i) for i in two if splits[i] == "train")
    asked = [i for i in two if splits[i] == split]
    if not asked:
        raise InputError(f"no two-action spans in split '{split}'")
    seen = [training[pair(i)] for i in asked]
    unmatched = sorted({t for i in two for t in (text_a[i], text_b[i]) if action(t) is None})
    return {
        "split": split,
        "spans": len(asked),
        "pair_in_training": sum(n > 0 for n in seen),
        "fraction_in_training": sum(n > 0 for n in seen) / len(asked),
        "median_times_in_training": statistics.median(seen),
        "training_pairs": sum(training.values()),
        "training_distinct_action_pairs": len(training),
        "texts_without_action": unmatched,
    }


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spans", help="a singles stage's spans.npz")
    p.add_argument("--split", default="test")
    p.add_argument("--vocabulary", default=VOCABULARY, help="the corpus vocabulary's source (default: this tree's)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    try:
        result = coverage(read_vocabulary(args.vocabulary), *read_spans(args.spans), args.split)
    except InputError as e:
        print(f"pair_coverage: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(f"{result['spans']} {args.split} two-action spans: {result['pair_in_training']} "
              f"({100 * result['fraction_in_training']:.0f}%) ask for an action pair held by a training pair "
              f"(median {result['median_times_in_training']:g} times); {result['training_pairs']} training pairs, "
              f"{result['training_distinct_action_pairs']} distinct action pairs; "
              f"{len(result['texts_without_action'])} texts without an action")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
