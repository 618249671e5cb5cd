#!/usr/bin/env python3
"""Accepted-and-correct and false-accept shares of `mapc localize --truth`
answers (JSON Lines): correct within 0.3 m and 5 degrees of the truth.

  scripts/score-answers.py [--truth given|corrected] NAME=FILE ...

--truth given scores against `truth` (the file's poses), corrected (the
default) against `truth_refined` (those poses corrected locally against
the map). Prints one line per file: name, answers, accepted and correct /
false accepts (per cent).
"""
import argparse
import json
import math


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--truth", choices=("given", "corrected"), default="corrected")
    ap.add_argument("files", nargs="+", metavar="NAME=FILE")
    a = ap.parse_args()
    key = "truth" if a.truth == "given" else "truth_refined"
    print(f"{'set':28} {'scans':>5}  accepted and correct / false accepts "
          f"(%, {a.truth} truth; 0.3 m, 5 deg)")
    for spec in a.files:
        name, _, path = spec.partition("=")
        rows = [json.loads(line) for line in open(path or name)]
        ok = bad = 0
        for r in rows:
            if not r.get("accepted"):
                continue
            t = r[key]
            if math.hypot(r["x"] - t[0], r["y"] - t[1]) < 0.3 and abs(wrap(r["theta"] - t[2])) < math.radians(5):
                ok += 1
            else:
                bad += 1
        n = max(len(rows), 1)
        print(f"{name:28} {len(rows):5}  {100 * ok / n:5.1f} / {100 * bad / n:4.1f}")


if __name__ == "__main__":
    main()
