"""The Python package against numbers that could come out wrong: modes
against NumPy's eigenvalues, records written and read back, the shipped
bumper record's identified force against its truth, a diagnosis of a
simulated bumper record against the simulated gap and stiffness, and
tacit's errors as Python exceptions."""

from pathlib import Path

import numpy as np
import pytest

import tacit

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(scope="module")
def lanl():
    return tacit.Model.load(DATA / "lanl8dof.toml")


@pytest.fixture(scope="module")
def contact():
    return tacit.load_model(DATA / "lanl8dof-contact.toml")


def test_model_matrices_and_modes_agree_with_numpy(lanl):
    m, k = lanl.mass_matrix(), lanl.stiffness_matrix()
    assert m.shape == (8, 8) and np.allclose(k, k.T)
    assert m[0, 0] == pytest.approx(0.5593)
    modes = tacit.modal(lanl)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(m, k)).real)
    expected = np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)
    assert modes.rigid == [True] + [False] * 7
    np.testing.assert_allclose(modes.freq_hz[1:], expected[1:], rtol=1e-9)
    # mass-normalized shapes
    phi = modes.shapes
    np.testing.assert_allclose(phi.T @ m @ phi, np.eye(8), atol=1e-9)


def test_model_from_dict_round_trip(lanl):
    d = lanl.to_dict()
    d["spring"][4]["stiffness"] *= 0.5
    half = tacit.Model.from_dict(d)
    k = half.stiffness_matrix()
    assert k[4, 5] == pytest.approx(-0.5 * 56700.0)
    assert tacit.Model.from_toml(half.to_toml()).to_dict() == half.to_dict()
    # NumPy arrays and scalars as values
    d["masses"] = np.full(8, 0.5)
    d["spring"][0]["stiffness"] = np.float64(1.0e5)
    arr = tacit.Model.from_dict(d)
    assert arr.mass_matrix()[7, 7] == 0.5 and arr.stiffness_matrix()[0, 0] == 1.0e5
    with pytest.raises(tacit.TacitError, match="model dict: object is not a number"):
        tacit.Model.from_dict({"masses": [object()]})


def test_record_from_arrays_round_trips_through_hdf5_and_csv(tmp_path):
    t = np.arange(256) / 256.0
    f = np.sin(2 * np.pi * 10 * t)
    a = np.cos(2 * np.pi * 10 * t)[::-1]  # a non-contiguous view
    rec = tacit.Record(256.0, [(1, f)], [("accel", 3, a)])
    assert len(rec) == 256 and rec.fs == 256.0
    for name in ["r.h5", "r.csv"]:
        rec.write(tmp_path / name)
        back = tacit.read_record(tmp_path / name)
        (iname, idof, iunit, idata), = back.inputs()
        (oname, odof, ounit, odata), = back.outputs()
        assert (iname, idof, iunit) == ("force_1", 1, "N")
        assert (oname, odof, ounit) == ("accel_3", 3, "m/s^2")
        np.testing.assert_allclose(idata, f, rtol=1e-12)
        np.testing.assert_allclose(odata, a, rtol=1e-12)
        np.testing.assert_allclose(back.time(), t, atol=1e-12)


def test_simulate_is_reproducible_and_records_the_truth(lanl):
    r1 = tacit.simulate(lanl, samples=512, sensors=[2, 7], seed=3)
    r2 = tacit.simulate(lanl, samples=512, sensors=[2, 7], seed=3)
    r3 = tacit.simulate(lanl, samples=512, sensors=[2, 7], seed=4)
    a1 = np.array([c[3] for c in r1.outputs()])
    a2 = np.array([c[3] for c in r2.outputs()])
    a3 = np.array([c[3] for c in r3.outputs()])
    assert a1.shape == (2, 512)
    np.testing.assert_array_equal(a1, a2)
    assert not np.allclose(a1, a3)
    # a linear model: no internal force
    assert np.abs(r1.truth_force()).max() == 0.0
    # a given force history: the input channel holds it
    force = np.linspace(0.0, 1.0, 300)
    r4 = tacit.simulate(lanl, samples=300, force=force, sensors=[1])
    np.testing.assert_allclose(r4.inputs()[0][3], force)


def test_identify_finds_the_contact_force_of_the_shipped_record(lanl):
    rec = tacit.read_record(DATA / "lanl8dof-bumper.h5")
    idn = tacit.identify(lanl, rec, [1, 5, 6])
    assert idn.located == [[5, 6]]
    assert idn.force.shape == (8, len(rec))
    truth = rec.truth_force()
    for d in (4, 5):
        c = np.corrcoef(idn.force[d], truth[d])[0, 1]
        assert c >= 0.9, (d + 1, c)
    others = np.delete(np.arange(8), [4, 5])
    assert np.abs(idn.force[others]).max() < 1.0
    assert idn.summary["error_after"] < 0.05 < idn.summary["error_before"]


def test_diagnose_finds_the_simulated_contact(lanl, contact, tmp_path):
    truth = contact.to_dict()["contact"][0]
    rec = tacit.simulate(
        contact, sensors=[1, 5, 6], noise=0.01, seed=11, substeps=40
    )
    d = tacit.diagnose(lanl, rec, tmp_path / "diag")
    assert d.verdict == "found contact 5→6", d.verdict
    p = d.parameters()
    gap, k = p["contact 5→6 gap"], p["contact 5→6 stiffness"]
    assert gap == pytest.approx(truth["gap"], rel=0.03)
    assert k == pytest.approx(truth["stiffness"], rel=0.10)
    e = d.errors
    assert e["relative_before"] > 0.5 and e["relative_after"] < 0.03
    assert (tmp_path / "diag" / "report.md").exists()
    assert any(p.endswith("model-fitted.toml") for p in d.paths)
    fitted = d.model.to_dict()["contact"][0]
    assert fitted["gap"] == pytest.approx(gap)
    # the output directory is not overwritten without force=True
    with pytest.raises(tacit.TacitError, match="not empty"):
        tacit.diagnose(lanl, rec, tmp_path / "diag")


def test_errors_are_python_exceptions_with_tacit_messages(lanl, tmp_path):
    with pytest.raises(tacit.TacitError, match="missing.toml"):
        tacit.load_model(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nmasses = [1.0, -2.0]\n')
    with pytest.raises(tacit.TacitError, match="masses"):
        tacit.load_model(bad)
    with pytest.raises(tacit.TacitError, match="quantity"):
        tacit.Record(100.0, [(1, np.zeros(10))], [("strain", 1, np.zeros(10))])
    with pytest.raises(tacit.TacitError):
        tacit.Record(100.0, [(1, np.zeros(10))], [("accel", 1, np.zeros(9))])
    with pytest.raises(tacit.TacitError, match="sensor DOF 9"):
        rec = tacit.read_record(DATA / "lanl8dof-bumper.h5")
        tacit.identify(lanl, rec, [1, 9])


def test_diagnose_runs_the_record_checks_against_the_model(lanl, tmp_path):
    """The checks of ``tacit diagnose`` against the model: accelerations
    in g are a warning in the report; a dead channel that is used is an
    error naming it."""
    rec = tacit.read_record(DATA / "lanl8dof-bumper.h5")
    n = 2048
    inputs = [(dof, data[:n]) for (_, dof, _, data) in rec.inputs()]
    outputs = [("accel", dof, data[:n]) for (_, dof, _, data) in rec.outputs()]
    in_g = [(q, dof, data / 9.80665) for (q, dof, data) in outputs]
    d = tacit.diagnose(lanl, tacit.Record(rec.fs, inputs, in_g), tmp_path / "g",
                       trust_linear=True)
    (w,) = d.report["warnings"]
    assert w.startswith("<memory>: the measured responses") and "in g" in w, w
    dead = [(q, dof, 0.0 * data if dof == 6 else data) for (q, dof, data) in outputs]
    with pytest.raises(tacit.TacitError, match="<memory>: cannot be used as it is: channel accel_6 is dead"):
        tacit.diagnose(lanl, tacit.Record(rec.fs, inputs, dead), tmp_path / "dead")


def test_group_estimates_share_one_contact_across_force_levels(lanl, contact, tmp_path):
    """The bumper simulated at 10, 20 and 40 N RMS, each record diagnosed,
    then one gap and one stiffness fitted to the three records at once
    (the campaign's joint fit)."""
    truth = contact.to_dict()["contact"][0]
    records, diagnoses = [], []
    for rms in (10.0, 20.0, 40.0):
        rec = tacit.simulate(contact, rms=rms, sensors=[1, 5, 6], noise=0.01,
                             seed=11, substeps=40)
        records.append(rec)
        diagnoses.append(tacit.diagnose(lanl, rec, tmp_path / f"d{rms:.0f}",
                                        sensors=[1, 5, 6], trust_linear=True))
    g = tacit.group_estimates(lanl, records, diagnoses, names=["low", "mid", "high"],
                              sensors=[1, 5, 6])
    assert g.effect == "contact 5→6"
    gap, k = g.parameters["gap"], g.parameters["stiffness"]
    assert (gap["unit"], k["unit"]) == ("m", "N/m")
    assert gap["value"] == pytest.approx(truth["gap"], rel=0.01)
    assert k["value"] == pytest.approx(truth["stiffness"], rel=0.05)
    assert 0.0 < gap["std"] < 0.01 * gap["value"]
    # the per-record values are those of each record's own diagnosis
    own = [d.parameters()["contact 5→6 gap"] for d in diagnoses]
    np.testing.assert_allclose(gap["per_record"], own, rtol=1e-12)
    assert g.values()["contact 5→6 stiffness"] == k["value"]
    # one parameter set explains every level about as well as its own fit
    assert [r["name"] for r in g.records] == ["low", "mid", "high"]
    for r in g.records:
        assert r["joint"] < 0.03 and r["joint"] < 1.5 * r["own"], r
    assert g.model.to_dict()["contact"][0]["gap"] == pytest.approx(gap["value"])
    # errors as exceptions naming what is wrong
    with pytest.raises(tacit.TacitError, match="no diagnosis found 'friction @1'"):
        tacit.group_estimates(lanl, records, diagnoses, effect="friction @1")
    with pytest.raises(tacit.TacitError, match="at least two are needed"):
        tacit.group_estimates(lanl, records[:1], diagnoses[:1], sensors=[1, 5, 6])
    with pytest.raises(tacit.TacitError, match="one diagnosis per record"):
        tacit.group_estimates(lanl, records, diagnoses[:2])
