#!/usr/bin/env python3
"""How many of a split's two-action spans ask for an action pair that the training split already
holds as a real pair (issue 15: why SINC's synthetic pairs add little on the procedural corpus).

SINC's synthetic pairs teach combinations of actions; a test span whose two actions were seen
together in a real training pair leaves them little to teach. The spans' texts are paraphrases,
so each text is mapped to its action through the corpus vocabulary's text templates
(core/src/corpus/vocabulary.cc: every action's short and long texts, `{placeholder}` matching any
words). Usage:

  /usr/bin/python3 tools/pair_coverage.py out/JOB/singles/task-00000/spans.npz [--split test] [--json]
      [--scores EVAL_GENERATE_DIR ...] [--compare ROW_A ROW_B] [--by pair|texts]

--scores reads eval_generate stages' per-motion TEMOS scores (`per_motion`) and gives each row's
mean on the spans whose action pair a training pair holds and on the others ("new"), per seed;
--compare pairs two rows by seed on each subset (mean difference and two standard errors of the
per-seed differences, as the report's claims).

--by texts groups the spans instead by how many of their two texts occur word for word among the
training split's single actions' texts (the texts a generator trained without a pretrained language
model has learned; a paraphrase it has never read is new to it): both; one, the other a paraphrase
of an action some training single performs (one_paraphrased) or an action no training single
performs (one_action_unseen: synthetic pairs, made of singles, cannot show it); neither.
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
        missing = [k for k in ("ids", "splits", "text_a", "text_b") if k not in z.files]
        if missing:
            raise InputError(f"{path}: not a singles stage's spans.npz (no {', '.join(missing)})")
        ids, splits, a, b = z["ids"], z["splits"], z["text_a"], z["text_b"]
    if not (len(ids) == len(splits) == len(a) == len(b)):
        raise InputError(f"{path}: ids, splits, text_a and text_b differ in length")
    return [str(i) for i in ids], [str(s) for s in splits], [str(t) for t in a], [str(t) for t in b]


def read_scores(stage_dirs, subsets):
    """{row: {seed: (mean TEMOS score on each subset's spans, in order)}} from eval_generate stages."""
    rows = collections.defaultdict(dict)
    for stage in stage_dirs:
        path = os.path.join(stage, "task-00000", "metrics.json")
        try:
            with open(path) as f:
                metrics = json.load(f)
        except (OSError, ValueError) as e:
            raise InputError(f"{path}: cannot read an eval_generate stage's metrics ({e})")
        if "per_motion" not in metrics:
            raise InputError(f"{path}: no per-motion scores (`per_motion`): score it again with this tree's eval_generate")
        score = {m["id"]: m["temos_score"] for m in metrics["per_motion"]}
        means = []
        for name, spans in subsets.items():
            values = [score[i] for i in spans if i in score]
            if not values:
                raise InputError(f"{path}: none of the split's {name.replace('_', ' ')} spans was scored")
            means.append(statistics.mean(values))
        row, seed = metrics.get("row") or metrics.get("method", stage), metrics.get("seed", 0)
        if seed in rows[row]:
            raise InputError(f"{path}: row '{row}' has seed {seed} twice")
        rows[row][seed] = tuple(means)
    return rows


def paired(a, b):
    """Mean of the per-seed differences a - b and two standard errors of it (the seeds both hold)."""
    seeds = sorted(set(a) & set(b))
    if len(seeds) < 2:
        raise InputError("the compared rows share fewer than 2 seeds")
    d = [a[s] - b[s] for s in seeds]
    return statistics.mean(d), 2 * statistics.stdev(d) / len(d) ** 0.5, d


def coverage(patterns, ids, splits, text_a, text_b, split, by="pair"):
    """The split's two-action spans against the training split, and their subsets by `by`: pair
    (held: the action pair occurs among the training pairs; new) or texts (how many of the two texts
    occur word for word among the training singles' texts, and whether the other's action is a
    training single's). Empty subsets are left out."""
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
    if by == "pair":
        subsets = {"held": {ids[i] for i, n in zip(asked, seen) if n > 0},
                   "new": {ids[i] for i, n in zip(asked, seen) if n == 0}}
    else:
        singles = [i for i in range(len(splits)) if not text_b[i] and splits[i] == "train"]
        texts = {text_a[i] for i in singles}
        actions = {action(text_a[i]) for i in singles} - {None}

        def kind(i):
            unseen = [t for t in (text_a[i], text_b[i]) if t not in texts]
            if not unseen:
                return "both_texts_seen"
            if len(unseen) == 2:
                return "no_text_seen"
            return "one_paraphrased" if action(unseen[0]) in actions else "one_action_unseen"

        subsets = {name: set() for name in ("both_texts_seen", "one_paraphrased", "one_action_unseen", "no_text_seen")}
        for i in asked:
            subsets[kind(i)].add(ids[i])
    subsets = {name: spans for name, spans in subsets.items() if spans}
    in_training = sum(n > 0 for n in seen)
    unmatched = sorted({t for i in two for t in (text_a[i], text_b[i]) if action(t) is None})
    return {
        "split": split,
        "spans": len(asked),
        "pair_in_training": in_training,
        "fraction_in_training": in_training / len(asked),
        "median_times_in_training": statistics.median(seen),
        "training_pairs": sum(training.values()),
        "training_distinct_action_pairs": len(training),
        "texts_without_action": unmatched,
        "subsets": {name: len(spans) for name, spans in subsets.items()},
    }, subsets


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spans", help="a singles stage's spans.npz")
    p.add_argument("--split", default="test")
    p.add_argument("--vocabulary", default=VOCABULARY, help="the corpus vocabulary's source (default: this tree's)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--scores", nargs="+", default=[], metavar="EVAL_GENERATE_DIR")
    p.add_argument("--compare", nargs=2, metavar=("ROW_A", "ROW_B"))
    p.add_argument("--by", choices=("pair", "texts"), default="pair",
                   help="subsets: the action pair held by a training pair or not (pair), or how many of "
                        "the two texts occur word for word among the training singles' (texts)")
    args = p.parse_args(argv)
    if args.compare and not args.scores:
        p.error("--compare compares scored rows: give the eval_generate stages with --scores")
    try:
        result, subsets = coverage(read_vocabulary(args.vocabulary), *read_spans(args.spans), args.split, args.by)
        if args.scores:
            rows = read_scores(args.scores, subsets)
            result["rows"] = {row: {**{name: statistics.mean(v[k] for v in by_seed.values())
                                       for k, name in enumerate(subsets)},
                                    "seeds": sorted(by_seed)} for row, by_seed in rows.items()}
            if args.compare:
                for row in args.compare:
                    if row not in rows:
                        raise InputError(f"no row '{row}' among the scored stages ({', '.join(sorted(rows))})")
                a, b = (rows[r] for r in args.compare)
                result["compare"] = {}
                for k, name in enumerate(subsets):
                    mean, two_se, d = paired({s: v[k] for s, v in a.items()}, {s: v[k] for s, v in b.items()})
                    result["compare"][name] = {"difference": mean, "two_standard_errors": two_se, "per_seed": d}
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
        named = {name: name.replace("_", " ") + (" pairs" if args.by == "pair" else "") for name in subsets}
        print("  subsets: " + ", ".join(f"{named[name]} {n}" for name, n in result["subsets"].items()))
        for row, r in result.get("rows", {}).items():
            print(f"  {row}: TEMOS score " + ", ".join(f"{r[name]:.3f} on {named[name]}" for name in subsets)
                  + f" ({len(r['seeds'])} seeds)")
        for name, c in result.get("compare", {}).items():
            print(f"  {args.compare[0]} - {args.compare[1]} on {named[name]}: {c['difference']:+.4f}, "
                  f"2 SE {c['two_standard_errors']:.4f} (per seed {', '.join(f'{x:+.3f}' for x in c['per_seed'])})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
