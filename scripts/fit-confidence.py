#!/usr/bin/env python3
"""Fits and evaluates refloc's confidence model (refloc::confidence) from the
JSON Lines of `mapc localize --truth` (docs/confidence.md).

  scripts/fit-confidence.py --train KIND:FILE ... [--test KIND:FILE ...]
                            [--threshold 0.8] [--l2 1e-3]

KIND says how an answer is labelled right (within 0.3 m and 5 degrees):
  real   against `truth_refined` (the given pose corrected locally against
         the map: real logs, whose given poses come from another SLAM run)
  sim    against `truth` (simulated scans from `mapc eval --dump`)
  wrong  never (scans of another map)

Prints the fitted coefficients (bias, then the weights of the evidence
ratio, the margin, ln support, the through share and, when the answers'
candidates carry it (`mapc localize` since the spread feature; all files
of one run alike), the spread, as refloc::confidence::Decision), then per file: answers, selected-correct,
accepted-and-correct / false accepts at the threshold with the model (an
ambiguous answer capped at 0.5, as the runtime does) and with the file's own
`accepted` field, the Brier score, and a reliability table over the test
files. Pure Python, no dependencies.
"""
import argparse
import json
import math

HIT = 4.5
POS, TH = 0.3, math.radians(5.0)
DIST, DHEAD = 1.0, math.radians(20.0)
AMBIGUOUS_CAP = 0.5


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def near(a, t):
    return math.hypot(a["x"] - t[0], a["y"] - t[1]) < POS and abs(wrap(a["theta"] - t[2])) < TH


def distinct(a, b):
    return math.hypot(a["x"] - b["x"], a["y"] - b["y"]) > DIST or abs(wrap(a["theta"] - b["theta"])) > DHEAD


def rows(path, kind):
    out = []
    for line in open(path):
        r = json.loads(line)
        if r.get("x") is None or not isinstance(r.get("candidates"), list):
            continue
        t = r.get("truth_refined" if kind == "real" else "truth")
        if t is None and kind != "wrong":
            continue
        cs = [c for c in r["candidates"] if c["has_pose"]]
        best = next((c for c in cs if c["rank"] == r["coarse_rank"]), None)
        if best is None:
            continue
        n = max(best["pairs"], 1)
        alt = max([c["evidence"] for c in cs if distinct(c, best) and c["free_space_ok"]] + [0.0])
        support = sum(1 for c in cs if not distinct(c, best))
        x = [r["evidence"] / (HIT * n), (r["evidence"] - alt) / (HIT * n),
             math.log(max(support, 1)), r["through_beams"] / n]
        if "spread" in best:
            x.append(best["spread"])
        y = 0 if kind == "wrong" else int(near(r, t[:3] if isinstance(t, list) else [t["x"], t["y"], t["theta"]]))
        out.append((x, y, bool(r["ambiguous"]), bool(r["accepted"])))
    return out


def prob(w, x):
    z = w[0] + sum(a * b for a, b in zip(w[1:], x))
    return 1.0 / (1.0 + math.exp(-max(-40.0, min(40.0, z))))


def fit(data, l2, iters=60):
    d = len(data[0][0]) + 1
    w = [0.0] * d
    for _ in range(iters):
        g = [0.0] * d
        h = [[0.0] * d for _ in range(d)]
        for x, y, _, _ in data:
            v = [1.0] + x
            p = prob(w, x)
            for i in range(d):
                g[i] += (p - y) * v[i]
                for j in range(d):
                    h[i][j] += p * (1 - p) * v[i] * v[j]
        for i in range(d):
            g[i] += l2 * w[i]
            h[i][i] += l2
        a = [h[i][:] + [g[i]] for i in range(d)]
        for i in range(d):
            piv = max(range(i, d), key=lambda r: abs(a[r][i]))
            a[i], a[piv] = a[piv], a[i]
            for r in range(d):
                if r != i:
                    m = a[r][i] / a[i][i]
                    for c in range(i, d + 1):
                        a[r][c] -= m * a[i][c]
        w = [wi - a[i][d] / a[i][i] for i, wi in enumerate(w)]
    return w


def confidence(w, x, amb):
    p = prob(w, x)
    return min(p, AMBIGUOUS_CAP) if amb else p


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--train", nargs="+", required=True, metavar="KIND:FILE")
    ap.add_argument("--test", nargs="*", default=[], metavar="KIND:FILE")
    ap.add_argument("--threshold", type=float, default=0.8)
    ap.add_argument("--l2", type=float, default=1e-3)
    a = ap.parse_args()
    sets = {}
    for role in ("train", "test"):
        for spec in getattr(a, role):
            kind, _, path = spec.partition(":")
            if kind not in ("real", "sim", "wrong"):
                ap.error(f"{spec}: KIND must be real, sim or wrong")
            sets[path] = (role, rows(path, kind))
    train = [r for role, rs in sets.values() if role == "train" for r in rs]
    w = fit(train, a.l2)
    print("bias %.3f weights [%s]" % (w[0], ", ".join("%.3f" % v for v in w[1:])))
    print("%-44s %5s %6s %13s %13s %7s %s" % ("file", "n", "sel-ok", "model ok/false", "file ok/false", "brier", "role"))
    test = []
    for path, (role, rs) in sets.items():
        n = len(rs)
        if n == 0:
            print(f"{path}: no answers")
            continue
        acc = [(confidence(w, x, amb) >= a.threshold, y) for x, y, amb, _ in rs]
        ok = sum(1 for s, y in acc if s and y)
        bad = sum(1 for s, y in acc if s and not y)
        fok = sum(1 for _, y, _, f in rs if f and y)
        fbad = sum(1 for _, y, _, f in rs if f and not y)
        brier = sum((confidence(w, x, amb) - y) ** 2 for x, y, amb, _ in rs) / n
        sel = sum(y for _, y, _, _ in rs)
        print("%-44s %5d %6.1f %6.1f / %4.1f %6.1f / %4.1f %7.4f %s" % (
            path[-44:], n, 100 * sel / n, 100 * ok / n, 100 * bad / n, 100 * fok / n, 100 * fbad / n, brier, role))
        if role == "test":
            test += rs
    if test:
        print("reliability over the test files (%d answers):" % len(test))
        edges = [0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.99, 1.0000001]
        for lo, hi in zip(edges, edges[1:]):
            s = [(confidence(w, x, amb), y) for x, y, amb, _ in test if lo <= confidence(w, x, amb) < hi]
            if s:
                print("  [%.2f, %.2f)  n %5d  mean confidence %.3f  observed right %.3f" % (
                    lo, min(hi, 1.0), len(s), sum(p for p, _ in s) / len(s), sum(y for _, y in s) / len(s)))
        print("Brier score over the test files: %.4f" % (sum((confidence(w, x, amb) - y) ** 2 for x, y, amb, _ in test) / len(test)))


if __name__ == "__main__":
    main()
