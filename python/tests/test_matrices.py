"""Models from NumPy and SciPy matrices (``tacit.Model.from_matrices``):
the clamped beam of scripts/beam_mtx.py assembled here in NumPy gives the
same reduced model as the shipped Matrix Market files, modes against the
beam's closed form, the stop at the tip simulated, located and diagnosed
by label, and bad matrices raising the file reader's errors."""

from pathlib import Path

import numpy as np
import pytest

import tacit

DATA = Path(__file__).resolve().parents[2] / "data"
POINTS = ["n20:uy", "n40:uy", "n60:uy", "n80:uy", "n100:uy"]


def beam(n_el):
    """K (N/m) and M (kg) of a clamped steel strip, 1 m, 40 x 10 mm, of
    n_el cubic Hermite elements, DOFs (uy, rz) per node (scripts/beam_mtx.py)."""
    e, rho, b, h = 210e9, 7850.0, 0.04, 0.01
    l = 1.0 / n_el
    ei, rho_a = e * b * h**3 / 12.0, rho * b * h
    ke = ei / l**3 * np.array(
        [[12, 6 * l, -12, 6 * l], [6 * l, 4 * l * l, -6 * l, 2 * l * l],
         [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l * l, -6 * l, 4 * l * l]])
    me = rho_a * l / 420.0 * np.array(
        [[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
         [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]])
    n = 2 * (n_el + 1)
    k, m = np.zeros((n, n)), np.zeros((n, n))
    for el in range(n_el):
        d = slice(2 * el, 2 * el + 4)
        k[d, d] += ke
        m[d, d] += me
    return k, m


def labels(n_el):
    """``n<i>:uy`` = DOF 2i + 1, ``n<i>:rz`` = DOF 2i + 2 (from 1)."""
    pts = {}
    for i in range(n_el + 1):
        pts[f"n{i}:uy"] = 2 * i + 1
        pts[f"n{i}:rz"] = 2 * i + 2
    return pts


def beam_model(n_el=100, elements=(), sparse=None):
    k, m = beam(n_el)
    if sparse is not None:
        k, m = sparse(k), sparse(m)
    return tacit.Model.from_matrices(
        m, k, labels(n_el), fixed=["n0:uy", "n0:rz"],
        damping={"kind": "modal", "ratio": 0.01}, elements=elements, name="beam100")


STOP = [{"kind": "contact", "dofs": ["n100:uy"], "gap": 2e-4, "stiffness": 5e4}]


def test_numpy_beam_reduces_as_the_matrix_market_files():
    mine = beam_model().reduce(POINTS, band_top_hz=200.0)
    shipped = tacit.Model.load(DATA / "beam100" / "model.toml").reduce(POINTS, band_top_hz=200.0)
    assert mine.points == POINTS and shipped.points == POINTS
    assert mine.ndof == shipped.ndof
    np.testing.assert_allclose(mine.mass_matrix(), shipped.mass_matrix(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        mine.stiffness_matrix(), shipped.stiffness_matrix(), rtol=1e-9, atol=1e-6)


def test_modes_of_the_reduced_beam_against_the_closed_form():
    model = beam_model(50)
    assert model.unreduced and model.ndof == 102
    with pytest.raises(tacit.TacitError, match="Model.reduce"):
        model.mass_matrix()
    red = model.reduce(["n25:uy", "n50:uy"], band_top_hz=1000.0)
    rep = __import__("json").loads(red.reduction_json())
    assert rep["full_dofs"] == 102 and rep["kept"] == ["n25:uy", "n50:uy"]
    f = tacit.modal(red).freq_hz
    # clamped-free: f_r = (beta_r L)^2 sqrt(EI / rho A) / 2 pi
    for fr, bl in zip(f, [1.875104, 4.694091, 7.854757]):
        exact = bl**2 * np.sqrt(700.0 / 3.14) / (2 * np.pi)
        assert fr == pytest.approx(exact, rel=2e-3)


def test_scipy_sparse_matrices_give_the_dense_model():
    sp = pytest.importorskip("scipy.sparse")
    dense = beam_model(40).reduce(["n40:uy"], band_top_hz=300.0)
    for fmt in (sp.csr_matrix, sp.csc_matrix, sp.coo_matrix):
        sparse = beam_model(40, sparse=fmt).reduce(["n40:uy"], band_top_hz=300.0)
        np.testing.assert_allclose(sparse.mass_matrix(), dense.mass_matrix(), rtol=1e-12)
        np.testing.assert_allclose(
            sparse.stiffness_matrix(), dense.stiffness_matrix(), rtol=1e-12)
    # the lower triangle only is not symmetric: named as such
    k, m = beam(4)
    with pytest.raises(tacit.TacitError, match="stiffness matrix: not symmetric: entry"):
        tacit.Model.from_matrices(m, sp.tril(sp.csr_matrix(k)), labels(4), fixed=["n0:uy", "n0:rz"])


def test_stop_at_the_tip_simulated_located_and_diagnosed_by_label(tmp_path):
    truth = beam_model(elements=STOP)
    opts = dict(points=POINTS, input_point="n20:uy", fs=1024.0, band=(5.0, 200.0), rms=5.0,
                noise=0.01, substeps=20)
    rec = tacit.simulate(truth, seed=7, **opts)
    names = [c[0] for c in rec.outputs()]
    assert names == [f"accel:{p}" for p in POINTS]
    declared = beam_model()
    ident = tacit.identify(declared, rec)
    assert ident.located == [[5]]
    tip = ident.force[4]
    true_tip = rec.truth_force()[4]
    assert np.corrcoef(tip, true_tip)[0, 1] >= 0.9
    val = tacit.simulate(truth, seed=8, **opts)
    d = tacit.diagnose(declared, rec, tmp_path / "out", validation=val)
    assert len(d.effects) == 1, d.verdict
    e = d.effects[0]
    assert e["kind"] == "contact" and e["label"].endswith("(n100:uy)")
    assert e["parameters"]["gap"] == pytest.approx(2e-4, rel=0.1)
    assert e["parameters"]["stiffness"] == pytest.approx(5e4, rel=0.1)
    assert d.report["validation"]["after"]["relative_error"] < 0.03
    assert (tmp_path / "out" / "reduction.json").exists()


def bad(m, k, points, **kw):
    with pytest.raises(tacit.TacitError) as e:
        tacit.Model.from_matrices(m, k, points, **kw)
    return str(e.value)


def test_bad_matrices_raise_the_readers_errors():
    m2, k2 = np.eye(2), np.array([[2.0, -1.0], [-1.0, 1.0]])
    pts = {"a": 1, "b": 2}
    ok = tacit.Model.from_matrices(m2, k2, pts)
    assert ok.points == ["a", "b"]
    e = bad(m2, np.eye(3), pts)
    assert "stiffness matrix" in e and "3 × 3" in e and "2 × 2" in e
    e = bad(m2, np.array([[2.0, -1.0], [-1.5, 1.0]]), pts)
    assert "stiffness matrix: not symmetric: entry (2, 1) = -1.5e0 but (1, 2) = -1e0" in e
    e = bad(m2, np.ones((2, 3)), pts)
    assert "must be square" in e
    e = bad(m2, k2, {"a": 1, "b": 2, "c": 2})
    assert '"c"' in e and '"b"' in e
    e = bad(m2, k2, {"a": 1, "c": 7})
    assert '"c" = 7' in e and "1..=2" in e
    e = bad(m2, k2, pts, elements=[{"kind": "contact", "dofs": ["tip"], "gap": 1e-3, "stiffness": 1e4}])
    assert "contact[0].dofs" in e and '"tip"' in e
    e = bad(np.diag([1.0, 0.0]), k2, pts)
    assert "(2, 2)" in e and '"b"' in e
    e = bad(np.array([[1.0, 2.0], [2.0, 1.0]]), k2, pts)
    assert "singular or indefinite" in e
    e = bad(np.array([[1.0, np.nan], [np.nan, 1.0]]), k2, pts)
    assert "mass matrix" in e and "not finite" in e
    e = bad(m2, k2, pts, fixed=["z"])
    assert '"z"' in e
    e = bad(m2, k2, pts, elements=[{"dofs": ["a"]}])
    assert "elements[0]" in e
    e = bad(np.zeros(3), k2, pts)
    assert "mass matrix M" in e and "2-D" in e
    # a model from matrices needs its points to be simulated
    with pytest.raises(tacit.TacitError, match="input_point"):
        tacit.simulate(ok, points=["a"])
