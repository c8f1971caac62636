#!/usr/bin/env python3
"""Write a clamped Euler-Bernoulli beam (cubic Hermite elements, consistent
mass) as a tacit model from matrices.

    python3 scripts/beam_mtx.py OUT_DIR [--elements 100] [--stop GAP,K]
                                [--young-factor 1.0] [--damping-ratio 0.01]

Nodes 0..N along x (length 1 m), two DOFs per node: `n<i>:uy` (transverse
displacement) and `n<i>:rz` (rotation); node 0 is clamped (both DOFs fixed).
Steel strip 40 mm x 10 mm (E = 210 GPa, rho = 7850 kg/m^3). Element matrices
(Przemieniecki, Theory of Matrix Structural Analysis, 1968, ch. 11):

  K_e = EI/l^3 [12, 6l, -12, 6l; 6l, 4l^2, -6l, 2l^2; ...]
  M_e = rho A l/420 [156, 22l, 54, -13l; 22l, 4l^2, 13l, -3l^2; ...]

Writes OUT_DIR/mass.mtx and OUT_DIR/stiffness.mtx (symmetric storage,
lower triangle) and OUT_DIR/model.toml (every node labelled; with --stop a
one-sided stop at the tip, `n<N>:uy` against ground, of gap GAP m and
stiffness K N/m). Plain Python 3, no packages.
"""
import argparse
from pathlib import Path

E, RHO, B, H, L = 210e9, 7850.0, 0.04, 0.01, 1.0


def element(l, ei, rho_a):
    k = [[12, 6 * l, -12, 6 * l],
         [6 * l, 4 * l * l, -6 * l, 2 * l * l],
         [-12, -6 * l, 12, -6 * l],
         [6 * l, 2 * l * l, -6 * l, 4 * l * l]]
    m = [[156, 22 * l, 54, -13 * l],
         [22 * l, 4 * l * l, 13 * l, -3 * l * l],
         [54, 13 * l, 156, -22 * l],
         [-13 * l, -3 * l * l, -22 * l, 4 * l * l]]
    ck, cm = ei / l ** 3, rho_a * l / 420.0
    return ([[ck * v for v in r] for r in k], [[cm * v for v in r] for r in m])


def assemble(n_el, young_factor):
    ei = young_factor * E * B * H ** 3 / 12.0
    ke, me = element(L / n_el, ei, RHO * B * H)
    kg, mg = {}, {}
    for e in range(n_el):
        dofs = [2 * e, 2 * e + 1, 2 * e + 2, 2 * e + 3]
        for a in range(4):
            for b in range(4):
                i, j = dofs[a], dofs[b]
                if i >= j:
                    kg[(i, j)] = kg.get((i, j), 0.0) + ke[a][b]
                    mg[(i, j)] = mg.get((i, j), 0.0) + me[a][b]
    return kg, mg


def write_mtx(path, n, entries):
    with open(path, "w") as f:
        f.write("%%MatrixMarket matrix coordinate real symmetric\n")
        f.write(f"{n} {n} {len(entries)}\n")
        for (i, j), v in sorted(entries.items(), key=lambda t: (t[0][1], t[0][0])):
            f.write(f"{i + 1} {j + 1} {v!r}\n")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--elements", type=int, default=100)
    p.add_argument("--stop", default=None, help="GAP,K of a stop at the tip")
    p.add_argument("--young-factor", type=float, default=1.0)
    p.add_argument("--damping-ratio", type=float, default=0.01)
    a = p.parse_args()
    n_el = a.elements
    n = 2 * (n_el + 1)
    kg, mg = assemble(n_el, a.young_factor)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_mtx(out / "mass.mtx", n, mg)
    write_mtx(out / "stiffness.mtx", n, kg)
    lines = [
        f"# Clamped steel beam, {n_el} Euler-Bernoulli elements, consistent mass",
        "# (written by scripts/beam_mtx.py)",
        f'name = "beam{n_el}"',
        "",
        "[matrices]",
        'mass = "mass.mtx"',
        'stiffness = "stiffness.mtx"',
        'fixed = ["n0:uy", "n0:rz"]',
        "",
        "[points]",
    ]
    for i in range(n_el + 1):
        lines.append(f'"n{i}:uy" = {2 * i + 1}')
        lines.append(f'"n{i}:rz" = {2 * i + 2}')
    lines += ["", "[damping]", 'kind = "modal"', f"ratio = {a.damping_ratio}"]
    if a.stop:
        gap, k = (float(x) for x in a.stop.split(","))
        lines += ["", "[[contact]]", f'dofs = ["n{n_el}:uy"]', f"gap = {gap!r}",
                  f"stiffness = {k!r}"]
    (out / "model.toml").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
