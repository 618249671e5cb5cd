#!/usr/bin/env python3
"""Replays stop rules of the fine stage on full-search candidate lists
(docs/performance.md, "Stopping on a settled answer").

Each candidate's fine stage does not depend on the others, so a rule that
examines a prefix of the ranked list can be evaluated exactly from the
records of a search that examined every candidate. Make those records with
a database whose early stops are off and the log's truth:

  mapc build MAP.yaml -o full.refdb --early-accept 0
  mapc localize full.refdb LOG --truth POSES > full.jsonl

  scripts/replay-stops.py full-intel.jsonl full-aces.jsonl ...

For every rule it prints, per file: accepted and correct / false accepts
(percent, against `truth_refined`, the locally corrected truth), and the
candidates examined (median / mean / 95th percentile). The answer, its
confidence (the stored default model of refloc::confidence, with the
ambiguity cap) and the confirmation after a stop (the next candidates
within 0.05 of the stopping candidate's coarse score, at most 6) follow
refloc::select; the confirmation's skip of sites within 2 m of the best
pose is not replayed (site positions are not in the records), so the
runtime examines slightly fewer candidates. Pure Python.
"""
import importlib.util
import json
import math
import os
import sys

# The labelling and the model's pieces are those of fit-confidence.py.
_spec = importlib.util.spec_from_file_location(
    "fit_confidence", os.path.join(os.path.dirname(os.path.abspath(__file__)), "fit-confidence.py"))
fc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fc)

# refloc::Decision::DEFAULT: bias, then the weights of the evidence ratio,
# the margin, ln support, the through share and the spread; the threshold.
MODEL, THRESHOLD = [-0.129, 0.039, 3.514, 1.496, -22.390, -4.782], 0.8
AMBIGUITY_RATIO = 0.97
CONFIRM_GAMMA, CONFIRM_MAX, MIN_CANDIDATES = 0.05, 6, 6


def better(a, b):
    if a["free_space_ok"] != b["free_space_ok"]:
        return a["free_space_ok"]
    return a["evidence"] > b["evidence"]


def confidence(examined, c):
    per = 1.0 / (fc.HIT * c["pairs"]) if c["pairs"] else 0.0
    alt, support, ambiguous = 0.0, 0, False
    for o in examined:
        if not o["has_pose"]:
            continue
        if fc.distinct(o, c):
            if o["free_space_ok"]:
                alt = max(alt, o["evidence"])
                ambiguous |= o["evidence"] >= AMBIGUITY_RATIO * c["evidence"]
        else:
            support += 1
    x = [c["evidence"] * per, (c["evidence"] - alt) * per, math.log(max(support, 1)),
         c["through_beams"] / c["pairs"] if c["pairs"] else 0.0, c["spread"]]
    return fc.confidence(MODEL, x, ambiguous)


def replay(cands, rule):
    """The answer, candidates examined and confidence under `rule(i, since,
    p)`: i the index of the candidate just examined (with a pose), since the
    candidates examined after the best one, p the best one's confidence."""
    examined, best, bi, floor, confirmed = [], None, 0, None, 0
    for i, c in enumerate(cands):
        if floor is not None:
            if c["gamma"] < floor or confirmed >= CONFIRM_MAX:
                break
            confirmed += 1
        examined.append(c)
        if not c["has_pose"]:
            continue
        if best is None or better(c, best):
            best, bi = c, i
        if floor is None and i + 1 >= MIN_CANDIDATES and rule(i, i - bi, confidence(examined, best)):
            floor = c["gamma"] - CONFIRM_GAMMA
    return best, len(examined), (confidence(examined, best) if best else 0.0)


RULES = {
    "all candidates": lambda i, s, p: False,
    "C 0.98": lambda i, s, p: p >= 0.98,
}
for c, k in [(0.8, 12), (0.9, 12), (0.9, 16), (0.9, 20), (0.95, 12)]:
    RULES[f"C 0.98 or C {c} settled {k}"] = (lambda c, k: lambda i, s, p: p >= 0.98 or (s >= k and p >= c))(c, k)
# The settled stop with a firm one beside it (refloc::select::FIRM_*: 0.95
# after 10 since 2026-12-06, sixth session).
for k in [8, 10, 12]:
    RULES[f"C 0.98 or C 0.9 settled 20 or C 0.95 settled {k}"] = (
        lambda k: lambda i, s, p: p >= 0.98 or (s >= 20 and p >= 0.9) or (s >= k and p >= 0.95))(k)


def main():
    files = sys.argv[1:]
    if not files:
        sys.exit(__doc__)
    data = {f: [json.loads(line) for line in open(f)] for f in files}
    for name, rule in RULES.items():
        out = []
        for f, rows in data.items():
            good = bad = 0
            counts = []
            for r in rows:
                best, k, p = replay(r["candidates"], rule)
                counts.append(k)
                if best is not None and p >= THRESHOLD:
                    t = r.get("truth_refined")
                    right = t is not None and fc.near(best, t)
                    good += right
                    bad += not right
            n = len(rows)
            counts.sort()
            out.append("%s %.1f / %.1f, %d / %.0f / %d" % (
                f.rsplit("/", 1)[-1], 100 * good / n, 100 * bad / n,
                counts[n // 2], sum(counts) / n, counts[int(0.95 * n)]))
        print("%-32s %s" % (name, " | ".join(out)))


if __name__ == "__main__":
    main()
