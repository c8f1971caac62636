#!/usr/bin/env python3
"""Write a rectangular membrane clamped on its edges (bilinear Q4 finite
elements, consistent mass) as a tacit model from matrices: a large sparse
model for the cost of a model from matrices.

    python3 scripts/membrane_mtx.py OUT_DIR [--nx 316] [--ny 316]
                                    [--stop LABEL,GAP,K]

Plate LX x LY = 1.0 m x 0.8 m, tension T = 1e4 N/m, areal mass 1 kg/m^2
(wave speed 100 m/s: first modes near 80, 113, 140 Hz). Nodes (i, j),
i = 0..NX, j = 0..NY, one DOF per node, label `p<i>_<j>:uz`; the edge
nodes are fixed. Element matrices of the Laplacian on a bilinear element
of sides a x b (Zienkiewicz & Taylor, The Finite Element Method, vol. 1,
ch. 5, Poisson problem):

  K_e = T [ (b/6a) [2,-2,-1,1; ...] + (a/6b) [2,1,-1,-2; ...] ]
  M_e = m a b/36 [4,2,1,2; 2,4,2,1; 1,2,4,2; 2,1,2,4]

Writes OUT_DIR/mass.mtx and OUT_DIR/stiffness.mtx (symmetric storage,
lower triangle) and OUT_DIR/model.toml (every node labelled; with --stop
a one-sided stop against ground at LABEL). Plain Python 3, no packages.
"""
import argparse
from pathlib import Path

LX, LY, T, MU = 1.0, 0.8, 1e4, 1.0


def element(a, b):
    kx = [[2, -2, -1, 1], [-2, 2, 1, -1], [-1, 1, 2, -2], [1, -1, -2, 2]]
    ky = [[2, 1, -1, -2], [1, 2, -2, -1], [-1, -2, 2, 1], [-2, -1, 1, 2]]
    k = [[T * (b / (6 * a) * kx[r][c] + a / (6 * b) * ky[r][c]) for c in range(4)]
         for r in range(4)]
    mm = [[4, 2, 1, 2], [2, 4, 2, 1], [1, 2, 4, 2], [2, 1, 2, 4]]
    m = [[MU * a * b / 36.0 * mm[r][c] for c in range(4)] for r in range(4)]
    return k, m


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--nx", type=int, default=316)
    p.add_argument("--ny", type=int, default=316)
    p.add_argument("--stop", default=None, help="LABEL,GAP,K of a stop to ground")
    a = p.parse_args()
    nx, ny = a.nx, a.ny
    dof = lambda i, j: j * (nx + 1) + i
    n = (nx + 1) * (ny + 1)
    ke, me = element(LX / nx, LY / ny)
    kg, mg = {}, {}
    for ej in range(ny):
        for ei in range(nx):
            nodes = [dof(ei, ej), dof(ei + 1, ej), dof(ei + 1, ej + 1), dof(ei, ej + 1)]
            for r in range(4):
                for c in range(4):
                    i, j = nodes[r], nodes[c]
                    if i >= j:
                        kg[(i, j)] = kg.get((i, j), 0.0) + ke[r][c]
                        mg[(i, j)] = mg.get((i, j), 0.0) + me[r][c]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, e in (("mass.mtx", mg), ("stiffness.mtx", kg)):
        with open(out / name, "w") as f:
            f.write("%%MatrixMarket matrix coordinate real symmetric\n")
            f.write(f"{n} {n} {len(e)}\n")
            for (i, j), v in sorted(e.items(), key=lambda t: (t[0][1], t[0][0])):
                f.write(f"{i + 1} {j + 1} {v!r}\n")
    label = lambda i, j: f"p{i}_{j}:uz"
    edge = [(i, j) for j in range(ny + 1) for i in range(nx + 1)
            if i in (0, nx) or j in (0, ny)]
    lines = [
        f"# Membrane {LX} m x {LY} m clamped on its edges, {nx} x {ny} bilinear",
        "# elements, consistent mass (written by scripts/membrane_mtx.py)",
        f'name = "membrane{nx}x{ny}"',
        "",
        "[matrices]",
        'mass = "mass.mtx"',
        'stiffness = "stiffness.mtx"',
        "fixed = [" + ", ".join(f'"{label(i, j)}"' for i, j in edge) + "]",
        "",
        "[points]",
    ]
    for j in range(ny + 1):
        for i in range(nx + 1):
            lines.append(f'"{label(i, j)}" = {dof(i, j) + 1}')
    lines += ["", "[damping]", 'kind = "modal"', "ratio = 0.01"]
    if a.stop:
        lab, gap, k = a.stop.split(",")
        lines += ["", "[[contact]]", f'dofs = ["{lab}"]', f"gap = {float(gap)!r}",
                  f"stiffness = {float(k)!r}"]
    (out / "model.toml").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
