#!/usr/bin/env python3
"""Write two clamped Euler-Bernoulli beams facing each other, joined at
their free tips by a linear joint spring, as a tacit model from matrices;
with --joint, the tips are also joined by Coulomb friction and a two-sided
clearance (the nonlinear interface).

    python3 scripts/two_beams_mtx.py OUT_DIR [--elements 50] [--spring 1000]
                                     [--joint LEVEL,GAP,K] [--b-stiffness 0.7]

Each beam is the steel strip of scripts/beam_mtx.py (1 m, 40 mm x 10 mm,
cubic Hermite elements, consistent mass); beam B's bending stiffness is
B-STIFFNESS times A's (two identical beams have repeated eigenvalues, which
the single-vector Krylov eigensolver of the reduction cannot separate). Beam A: nodes a0..aN, clamped at
a0; beam B: nodes b0..bN, clamped at b0; labels `a<i>:uy`, `a<i>:rz`,
`b<i>:uy`, `b<i>:rz`. The joint spring (N/m) acts between `aN:uy` and
`bN:uy` and is part of the stiffness matrix. The pair `aN:uy`-`bN:uy` is
listed under [interfaces]. With --joint: [[relative_friction]] of LEVEL N
(regularisation velocity 1e-3 m/s) and [[clearance]] of gap GAP m and
stiffness K N/m between the tips. Plain Python 3, no packages.
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from beam_mtx import assemble, write_mtx  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--elements", type=int, default=50)
    p.add_argument("--spring", type=float, default=1000.0)
    p.add_argument("--joint", default=None, help="LEVEL,GAP,K of the interface")
    p.add_argument("--b-stiffness", type=float, default=0.7)
    a = p.parse_args()
    ne = a.elements
    nb = 2 * (ne + 1)
    kg, mg = assemble(ne, 1.0)
    kb, mb = assemble(ne, a.b_stiffness)
    k, m = dict(kg), dict(mg)
    for (i, j), v in kb.items():
        k[(i + nb, j + nb)] = v
    for (i, j), v in mb.items():
        m[(i + nb, j + nb)] = v
    ta, tb = 2 * ne, nb + 2 * ne  # the tips' uy, 0-based
    k[(ta, ta)] += a.spring
    k[(tb, tb)] += a.spring
    k[(tb, ta)] = k.get((tb, ta), 0.0) - a.spring
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_mtx(out / "mass.mtx", 2 * nb, m)
    write_mtx(out / "stiffness.mtx", 2 * nb, k)
    lines = [
        f"# Two clamped steel beams of {ne} elements joined at their tips",
        "# (written by scripts/two_beams_mtx.py)",
        f'name = "two-beams{ne}"',
        "",
        "[matrices]",
        'mass = "mass.mtx"',
        'stiffness = "stiffness.mtx"',
        'fixed = ["a0:uy", "a0:rz", "b0:uy", "b0:rz"]',
        "",
        "[interfaces]",
        f'pairs = [["a{ne}:uy", "b{ne}:uy"]]',
        "",
        "[points]",
    ]
    for s, off in (("a", 0), ("b", nb)):
        for i in range(ne + 1):
            lines.append(f'"{s}{i}:uy" = {off + 2 * i + 1}')
            lines.append(f'"{s}{i}:rz" = {off + 2 * i + 2}')
    lines += ["", "[damping]", 'kind = "modal"', "ratio = 0.01"]
    if a.joint:
        level, gap, kc = (float(x) for x in a.joint.split(","))
        pair = f'["a{ne}:uy", "b{ne}:uy"]'
        lines += ["", "[[relative_friction]]", f"dofs = {pair}", f"level = {level!r}",
                  "velocity = 0.001", "", "[[clearance]]", f"dofs = {pair}",
                  f"gap = {gap!r}", f"stiffness = {kc!r}"]
    (out / "model.toml").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
