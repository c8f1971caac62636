#!/usr/bin/env python3
"""Records outside the imperfect matrix: places, kinds and sensor sets the
matrix (examples/imperfect_matrix.rs) does not use, made with `tacit
simulate` from lanl8dof.toml departed from as real tests do, and diagnosed
with `tacit diagnose` as a user would. Prints the Markdown table of
docs/diagnose.md ("Records outside the matrix").

    python3 scripts/outside_matrix.py [--tacit target/release/tacit] [--out out/outside]
    python3 scripts/outside_matrix.py --table-only   # the table from the reports already written
    python3 scripts/outside_matrix.py --only p4 --variants no   # one record, one variant

Standard library only. Springs are drawn within ±pct of nominal with
Python's random.Random(seed) (the same numbers on every platform).
"""

import argparse
import json
import os
import random
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DECLARED = os.path.join(ROOT, "data", "lanl8dof.toml")


def friction_everywhere(level):
    return "".join(f"[[friction]]\ndof = {d}\nlevel = {level}\n" for d in range(1, 9))


# name: (spring seed, spring spread, damping table, effects, truth in words)
MODELS = {
    "p1": (101, 0.04, '[damping]\nkind = "rayleigh"\nalpha = 2.0\nbeta = 6e-5\n',
           "[[cubic]]\ndofs = [4, 5]\nk3 = 1e12\n", "cubic 4–5 k3 1e12 N/m³"),
    "p2": (202, 0.03, '[damping]\nkind = "modal"\nratio = 0.03\n',
           "[[contact]]\ndofs = [1, 2]\ngap = 3e-4\nstiffness = 2e6\n",
           "contact 1→2 gap 0.3 mm, 2e6 N/m"),
    "p3": (303, 0.05, '[damping]\nkind = "modal"\nratio = 0.025\n',
           "[[relative_friction]]\ndofs = [3, 4]\nlevel = 0.8\n" + friction_everywhere(0.15),
           "relative friction 3–4 0.8 N + friction 0.15 N on every mass"),
    "p4": (404, 0.04, '[damping]\nkind = "modal"\nratio = 0.02\n',
           "[[contact]]\ndofs = [6, 7]\ngap = 2.5e-4\nstiffness = 1.5e6\n[[cubic]]\ndofs = [2]\nk3 = 3e11\n",
           "contact 6→7 gap 0.25 mm, 1.5e6 N/m + cubic 2 to ground k3 3e11 N/m³"),
    "p4c": (404, 0.04, '[damping]\nkind = "modal"\nratio = 0.02\n',
            "[[cubic]]\ndofs = [2]\nk3 = 3e11\n", "cubic 2 to ground k3 3e11 N/m³"),
    "p5": (505, 0.04, '[damping]\nkind = "rayleigh"\nalpha = 3.0\nbeta = 4e-5\n',
           "[[quadratic]]\ndofs = [3, 4]\nk2 = 6e6\n", "quadratic spring 3–4 k2 6e6 N/m²"),
    "p6": (606, 0.03, '[damping]\nkind = "modal"\nratio = 0.025\n',
           "[[cubic_damper]]\ndofs = [4, 5]\nc3 = 2500\n" + friction_everywhere(0.1),
           "cubic damper 4–5 c3 2500 N s³/m³ + friction 0.1 N on every mass"),
    "p7": (707, 0.05, '[damping]\nkind = "modal"\nratio = 0.03\n',
           "[[contact]]\ndofs = [4, 3]\ngap = 3e-4\nstiffness = 1.8e6\n"
           "[[quadratic_damper]]\ndofs = [7, 8]\nc2 = 250\n",
           "contact 4→3 gap 0.3 mm, 1.8e6 N/m + quadratic damper 7–8 c2 250 N s²/m²"),
    "p8": (808, 0.03, '[damping]\nkind = "modal"\nratio = 0.02\n',
           "[[clearance]]\ndofs = [3, 4]\ngap = 5e-4\nstiffness = 5e5\n"
           "[[relative_friction]]\ndofs = [5, 6]\nlevel = 0.5\n",
           "clearance 3–4 ±0.5 mm, 5e5 N/m + relative friction 5–6 0.5 N"),
    "p9": (909, 0.04, '[damping]\nkind = "modal"\nratio = 0.02\n',
           "[[relative_friction]]\ndofs = [2, 3]\nlevel = 1.0\n",
           "relative friction 2–3 1.0 N"),
    "p10": (1010, 0.03, '[damping]\nkind = "rayleigh"\nalpha = 2.5\nbeta = 5e-5\n',
            "[[cubic]]\ndofs = [1, 2]\nk3 = 5e11\n"
            "[[contact]]\ndofs = [8, 7]\ngap = 2e-4\nstiffness = 1.2e6\n",
            "cubic 1–2 k3 5e11 N/m³ + contact 8→7 gap 0.2 mm, 1.2e6 N/m"),
    "p11": (1111, 0.05, '[damping]\nkind = "modal"\nratio = 0.04\n',
            "[[contact]]\ndofs = [3, 2]\ngap = 3.5e-4\nstiffness = 2.5e6\n"
            "[[cubic_damper]]\ndofs = [6, 7]\nc3 = 3000\n",
            "contact 3→2 gap 0.35 mm, 2.5e6 N/m + cubic damper 6–7 c3 3000 N s³/m³"),
    "p12": (1212, 0.05, '[damping]\nkind = "rayleigh"\nalpha = 4.0\nbeta = 8e-5\n',
            "", "none (springs ±5 %, Rayleigh damping)"),
    "p13": (1313, 0.04, '[damping]\nkind = "rayleigh"\nalpha = 2.0\nbeta = 7e-5\n',
            "[[contact]]\ndofs = [2, 1]\ngap = 3e-4\nstiffness = 1.5e6\n"
            "[[contact]]\ndofs = [7, 8]\ngap = 2.5e-4\nstiffness = 2e6\n",
            "contact 2→1 gap 0.3 mm, 1.5e6 N/m + contact 7→8 gap 0.25 mm, 2e6 N/m"),
}

# record: (model, sensors, noise, samples made, kept range, seeds (record, validation, linear))
RECORDS = {
    "p1": ("p1", "1,3,5,7", 0.02, 4096, None, (11, 12, 13)),
    "p2": ("p2", None, 0.005, 5120, "1024..5120", (21, 22, 23)),
    "p3": ("p3", None, 0.01, 4096, None, (31, 32, None)),
    "p4": ("p4", "1,2,6,7,8", 0.015, 4096, None, (41, 42, 43)),
    "p4c": ("p4c", "1,2,6,7,8", 0.015, 4096, None, (41, 42, None)),
    "p5": ("p5", "1,3,4,6,8", 0.02, 4096, None, (51, 52, 53)),
    "p6": ("p6", None, 0.01, 5120, "1024..5120", (61, 62, 63)),
    "p7": ("p7", "2,3,4,7,8", 0.01, 4096, None, (71, 72, 73)),
    "p8": ("p8", None, 0.005, 4096, None, (81, 82, 83)),
    "p9": ("p9", "2,3,6", 0.01, 4096, None, (91, 92, 93)),
    "p10": ("p10", "1,2,7,8", 0.03, 5120, "1024..5120", (101, 102, 103)),
    "p11": ("p11", None, 0.003, 4096, None, (111, 112, 113)),
    "p12": ("p12", "1,4,8", 0.03, 4096, None, (121, 122, None)),
    "p13": ("p13", "1,2,7,8", 0.02, 4096, None, (131, 132, 133)),
}

DIAGNOSES = [("p1", False), ("p2", False), ("p3", False), ("p4", False), ("p4c", False),
             ("p1", True), ("p2", True), ("p4", True),
             ("p5", False), ("p6", False), ("p7", False), ("p8", False),
             ("p9", False), ("p10", False), ("p11", False), ("p12", False),
             ("p13", False)]


def model_text(name, linear):
    seed, spread, damping, effects, _ = MODELS[name]
    rng = random.Random(seed)
    lines = []
    for line in open(DECLARED).read().splitlines():
        if line.startswith('name = "lanl8dof"'):
            line = f'name = "{name}"'
        elif line.startswith("stiffness = 56700.0"):
            line = f"stiffness = {56700 * (1 + rng.uniform(-spread, spread)):.1f}"
        lines.append(line)
    text = "\n".join(lines)
    text = text[: text.index("[damping]")] + damping + "\n"
    return text if linear else text + effects


def run(cmd, log):
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        subprocess.run(cmd, check=True, stdout=f, stderr=subprocess.STDOUT)


def simulate(tacit, out, rec):
    model, sensors, noise, samples, _, seeds = RECORDS[rec]
    log = os.path.join(out, "log.txt")
    for linear in (False, True):
        path = os.path.join(out, f"{model}{'-lin' if linear else ''}.toml")
        with open(path, "w") as f:
            f.write(model_text(model, linear))
    base = [tacit, "simulate", "--input", "random", "--band", "5,200", "--fs", "512",
            "--noise", str(noise)]
    if sensors:
        base += ["--sensors", sensors]
    m = os.path.join(out, model + ".toml")
    for seed, kind in zip(seeds, ("rec", "val", "lin")):
        if seed is None:
            continue
        target = os.path.join(out, f"{rec}-{kind}.h5")
        if kind == "lin":
            cmd = base + ["--model", os.path.join(out, model + "-lin.toml"), "--rms", "5",
                          "--samples", "4096"]
        else:
            cmd = base + ["--model", m, "--rms", "20",
                          "--samples", str(samples if kind == "rec" else 4096)]
        run(cmd + ["--seed", str(seed), "-o", target], log)


def diagnose(tacit, out, rec, linear):
    _, sensors, _, _, kept, _ = RECORDS[rec]
    cmd = [tacit, "diagnose", "--model", DECLARED, "--force",
           "--record", os.path.join(out, f"{rec}-rec.h5"),
           "--validate", os.path.join(out, f"{rec}-val.h5")]
    if sensors:
        cmd += ["--sensors", sensors]
    if kept:
        cmd += ["--samples", kept]
    if linear:
        cmd += ["--linear-record", os.path.join(out, f"{rec}-lin.h5")]
    report = os.path.join(out, f"{rec}-{'yes' if linear else 'no'}")
    t = time.time()
    run(cmd + ["-o", report], os.path.join(out, "log.txt"))
    with open(os.path.join(report, "wall.txt"), "w") as f:
        f.write(f"{time.time() - t:.1f}\n")


KIND_LABEL = {"contact": "contact", "cubic": "cubic", "quadratic": "quadratic",
              "quadratic_damper": "quadratic_damping", "cubic_damper": "cubic_damping",
              "clearance": "clearance", "relative_friction": "relative_friction"}


def expected(model):
    """The localized effects of a model's truth: (label as tacit writes it,
    {parameter: value}); friction on every mass is background, allowed but
    not required."""
    import tomllib
    table = tomllib.loads(MODELS[model][3])
    want = []
    for kind, label in KIND_LABEL.items():
        for e in table.get(kind, []):
            d = e["dofs"]
            if len(d) == 1:
                place = f" @{d[0]}"
            elif kind == "contact":
                place = f" {d[0]}→{d[1]}"
            else:
                place = f" {min(d)}–{max(d)}"
            params = {k: v for k, v in e.items() if k not in ("dofs", "velocity")}
            want.append((label + place, params))
    return want


def check(r, model, noise):
    """The matrix's checks: every localized effect named at its place with
    its parameters within 10 %, nothing else named but friction on every
    mass, the validation error at most 1.5 × the noise (the lower of the
    simulated and the measured level)."""
    found = {e["label"]: e["parameters"] for e in r["effects"]}
    fails = []
    for label, params in expected(model):
        if label not in found:
            fails.append(f"{label} not named")
            continue
        for k, v in params.items():
            got = found[label].get(k)
            if got is None or abs(got / v - 1) > 0.1:
                fails.append(f"{label} {k} {100 * (got / v - 1):+.1f} %" if got else f"{label} {k} missing")
    wanted = {label for label, _ in expected(model)}
    extra = [l for l in found if l not in wanted and not l.startswith("friction @1,2,3,4,5,6,7,8")]
    fails += [f"{l} named" for l in extra]
    level = (r.get("noise") or {}).get("level") or noise
    bound = 1.5 * min(noise, level)
    v = r["validation"]["after"].get("relative_error")
    if v is None or v > bound:
        fails.append(f"validation {pct(v)} > {100 * bound:.2f} %")
    return "pass" if not fails else "**fail**: " + "; ".join(fails)


def pct(x):
    return "—" if x is None else f"{100 * x:.2f} %"


def row(out, rec, linear):
    model, sensors, noise, samples, kept, _ = RECORDS[rec]
    d = os.path.join(out, f"{rec}-{'yes' if linear else 'no'}")
    r = json.load(open(os.path.join(d, "report.json")))
    wall = open(os.path.join(d, "wall.txt")).read().strip() if os.path.exists(
        os.path.join(d, "wall.txt")) else "—"
    params = "; ".join(
        e["label"] + ": " + ", ".join(f"{k} {v:.4e}" for k, v in e["parameters"].items())
        for e in r["effects"]) or "none"
    level = (r.get("noise") or {}).get("level")
    corr = (r.get("calibration") or {}).get("corrections", [])
    sig = ", ".join(f"{c['name']} {100 * c['change']:+.1f} %" for c in corr if c.get("significant"))
    start = f", samples {kept} of {samples} (a running test)" if kept else ""
    return (f"| {rec} | {MODELS[model][4]} | {sensors or '1–8'}{start} | "
            f"{100 * noise:.1f} % ({pct(level)}) | {'yes' if linear else 'no'} | {params} | "
            f"{pct(r['before'].get('relative_error'))} → {pct(r['after'].get('relative_error'))} | "
            f"{pct(r['validation']['before'].get('relative_error'))} → "
            f"{pct(r['validation']['after'].get('relative_error'))} | {sig or '—'} | "
            f"{check(r, model, noise)} | {wall} s |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tacit", default=os.path.join(ROOT, "target", "release", "tacit"))
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "outside"))
    ap.add_argument("--table-only", action="store_true")
    ap.add_argument("--only", nargs="+", choices=sorted(RECORDS), help="only these records")
    ap.add_argument("--variants", choices=["no", "yes"],
                    help="only the diagnoses without (no) or with (yes) the linear record")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    chosen = [(rec, linear) for rec, linear in DIAGNOSES
              if (not a.only or rec in a.only)
              and (a.variants is None or linear == (a.variants == "yes"))]
    if not a.table_only:
        for rec in sorted({rec for rec, _ in chosen}):
            simulate(a.tacit, a.out, rec)
        for rec, linear in chosen:
            diagnose(a.tacit, a.out, rec, linear)
    print("| record | truth | sensors | noise (measured) | linear record | found | "
          "error before → after | validation before → after | corrections significant | checks | time |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for rec, linear in chosen:
        print(row(a.out, rec, linear))


if __name__ == "__main__":
    sys.exit(main())
