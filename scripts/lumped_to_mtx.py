#!/usr/bin/env python3
"""Write a lumped tacit model (masses and springs) as a model from matrices.

    python3 scripts/lumped_to_mtx.py data/lanl8dof.toml data/lanl8dof-mtx

writes <dir>/mass.mtx (diagonal), <dir>/stiffness.mtx (the springs
assembled, symmetric storage) and <dir>/model.toml with the point labels
m1..mN (DOF i of the matrices = mass i of the lumped model), the same
damping and the same elements placed by label. Plain Python 3.11+ (tomllib).
"""
import sys
import tomllib
from pathlib import Path


def write_mtx(path, n, entries, symmetric):
    kind = "symmetric" if symmetric else "general"
    with open(path, "w") as f:
        f.write(f"%%MatrixMarket matrix coordinate real {kind}\n")
        f.write(f"{n} {n} {len(entries)}\n")
        for (i, j), v in sorted(entries.items(), key=lambda e: (e[0][1], e[0][0])):
            f.write(f"{i + 1} {j + 1} {v!r}\n")


def main(src, out):
    model = tomllib.loads(Path(src).read_text())
    masses = model["masses"]
    n = len(masses)
    k = {}
    for s in model.get("spring", []):
        d = [x - 1 for x in s["dofs"]]
        ks = s["stiffness"]
        k[(d[0], d[0])] = k.get((d[0], d[0]), 0.0) + ks
        if len(d) == 2:
            i, j = max(d), min(d)  # lower triangle
            k[(d[1], d[1])] = k.get((d[1], d[1]), 0.0) + ks
            k[(i, j)] = k.get((i, j), 0.0) - ks
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_mtx(out / "mass.mtx", n, {(i, i): m for i, m in enumerate(masses)}, True)
    write_mtx(out / "stiffness.mtx", n, k, True)
    lines = [
        f"# {model.get('name', '')} written as matrices by scripts/lumped_to_mtx.py",
        f"name = {model.get('name', '')!r}",
        f"description = {model.get('description', '')!r}",
        "",
        "[matrices]",
        'mass = "mass.mtx"',
        'stiffness = "stiffness.mtx"',
        "",
        "[points]",
    ]
    lines += [f'"m{i + 1}" = {i + 1}' for i in range(n)]
    damping = model.get("damping")
    if damping:
        lines += ["", "[damping]"]
        lines += [f"{key} = {val!r}" for key, val in damping.items()]
    for kind in ("contact", "cubic", "friction"):
        for e in model.get(kind, []):
            lines += ["", f"[[{kind}]]"]
            for key, val in e.items():
                if key == "dofs":
                    val = [f"m{d}" for d in val]
                    lines.append(f"dofs = {val!r}".replace("'", '"'))
                elif key == "dof":
                    lines.append(f'dof = "m{val}"')
                else:
                    lines.append(f"{key} = {val!r}")
    (out / "model.toml").write_text("\n".join(lines).replace("'", '"') + "\n")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
