"""Loads every URDF under a directory with sodyn and with Pinocchio (fixed base) and compares
them: the joint tables (python/tests/conftest.py's PinMap), then rnea, crba and the RNEA
derivatives at two random states. Prints a Markdown report (docs/urdf-corpus.md is one).

    python scripts/urdf_corpus.py DIR [--label NAME]

Needs the sodyn package, numpy and pin==4.1.0 (python/tests/requirements.txt)."""

import argparse
import collections
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import sodyn

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python" / "tests"))
from conftest import PinMap, random_state, rel_err, sym_from_upper  # noqa: E402

TOL = 1e-9


def fresh(pmodel, fn, *args):
    data = pin.Data(pmodel)
    out = fn(pmodel, data, *args)
    if isinstance(out, tuple):
        return tuple(np.array(x, dtype=float, copy=True) for x in out)
    return np.array(out, dtype=float, copy=True)


def kind(warning):
    """The class of a loader warning."""
    for needle, k in (("lower > upper", "reversed limits"), ("triangle inequality",
                      "inertia violates the triangle inequality"), ("<mimic>", "mimic")):
        if needle in warning:
            return k
    return warning


def compare(path):
    """(class, detail) of one file."""
    try:
        pmodel = pin.buildModelFromUrdf(str(path))
        pin_err = None
    except Exception as e:  # noqa: BLE001 - urdfdom's failures come as various types
        pmodel, pin_err = None, " ".join(str(e).split())[:160]
    try:
        model = sodyn.Model.from_urdf(str(path))
    except sodyn.SodynError as e:
        msg = str(e).replace(str(path), Path(path).name)
        return ("refused by both" if pmodel is None else "refused by sodyn only"), msg
    if pmodel is None:
        return "loaded by sodyn only", pin_err
    try:
        pmap = PinMap(model, pmodel)
    except AssertionError as e:
        return "mismatch", f"joint table: {e}"
    data = model.create_data()
    worst = 0.0
    for s in (0, 1):
        q, v, a, _ = random_state(model, s)
        pq, pv, pa = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a)
        pairs = [
            (sodyn.rnea(model, data, q, v, a), pmap.vec(fresh(pmodel, pin.rnea, pq, pv, pa))),
            (sodyn.crba(model, data, q), pmap.mat(sym_from_upper(fresh(pmodel, pin.crba, pq)))),
        ]
        if model.nv:
            dq, dv = sodyn.id_derivatives(model, data, q, v, a)
            pdq, pdv, _ = fresh(pmodel, pin.computeRNEADerivatives, pq, pv, pa)
            pairs += [(dq, pmap.mat(pdq)), (dv, pmap.mat(pdv))]
        for ours, theirs in pairs:
            worst = max(worst, rel_err(ours, theirs)[0])
    kinds = sorted({kind(w) for w in model.warnings})
    warn = f"; {len(model.warnings)} warning(s): {', '.join(kinds)}" if kinds else ""
    raw = Path(path).read_bytes().removeprefix(b"\xef\xbb\xbf")
    if raw[:1].isspace() and raw.lstrip().startswith(b"<?xml"):
        warn += "; XML declaration after whitespace"
    if worst > TOL:
        return "mismatch", f"relative error {worst:.2e}{warn}"
    return "match", f"nv {model.nv}, worst {worst:.1e}{warn}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--label", default=None)
    o = ap.parse_args()
    root = Path(o.dir)
    files = sorted(root.rglob("*.urdf"))
    results = {f: compare(f) for f in files}
    counts = collections.Counter(c for c, _ in results.values())
    warned = collections.Counter()
    for f, (c, d) in results.items():
        if "warning" in d or "XML declaration" in d:
            warned[c] += 1
    print(f"Corpus: {o.label or root}, {len(files)} URDF files, fixed base.\n")
    print("| outcome | files | of which with warnings or a late XML declaration |\n|---|---|---|")
    for c in ("match", "mismatch", "refused by sodyn only", "loaded by sodyn only",
              "refused by both"):
        print(f"| {c} | {counts.get(c, 0)} | {warned.get(c, 0)} |")
    errs = [float(d.split("worst ")[1].split(";")[0]) for c, d in results.values() if c == "match"]
    if errs:
        print(f"\nWorst relative error over the files that match: {max(errs):.1e}.")
    for c in ("mismatch", "refused by sodyn only", "loaded by sodyn only", "refused by both"):
        rows = [(f, d) for f, (k, d) in results.items() if k == c]
        if rows:
            print(f"\n### {c}\n\n| file | detail |\n|---|---|")
            for f, d in rows:
                print(f"| `{f.relative_to(root)}` | {d.replace('|', '/')} |")
    rows = [(f, d) for f, (k, d) in results.items()
            if k == "match" and ("warning" in d or "XML declaration" in d)]
    if rows:
        print("\n### match, with warnings or a late XML declaration\n\n| file | detail |\n|---|---|")
        for f, d in rows:
            print(f"| `{f.relative_to(root)}` | {d} |")


if __name__ == "__main__":
    main()
