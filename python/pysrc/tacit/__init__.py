"""tacit: find, explain and fix what a linear structural model misses in a
nonlinear vibration test.

Units are SI throughout: masses in kg, stiffnesses in N/m, forces in N,
displacements in m, velocities in m/s, accelerations in m/s^2, time in s,
frequencies in Hz. DOFs are numbered from 1. Arrays are NumPy float64,
one row per DOF or channel and one column per sample.

    >>> import tacit
    >>> model = tacit.Model.load("data/lanl8dof.toml")
    >>> rec = tacit.Record.read("data/lanl8dof-bumper.h5")
    >>> d = tacit.diagnose(model, rec, "out/py-diagnose")
    >>> d.effects[0]["label"]            # doctest: +SKIP
    'contact 5→6'

Every error tacit reports is raised as ``tacit.TacitError`` with tacit's
message, which names the file, channel, key or option at fault.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _tacit
from ._tacit import Model, Record, TacitError

__all__ = [
    "Model",
    "Record",
    "TacitError",
    "Diagnosis",
    "GroupEstimates",
    "Identification",
    "Modes",
    "diagnose",
    "group_estimates",
    "identify",
    "modal",
    "simulate",
    "read_record",
    "load_model",
    "__version__",
]

__version__ = _tacit.__version__

PathLike = Union[str, "os.PathLike[str]"]


def load_model(path: PathLike) -> Model:
    """Read and check a model file (TOML)."""
    return Model.load(os.fspath(path))


def _plain(o: Any) -> Any:
    """NumPy arrays and scalars as lists and numbers (for JSON)."""
    if isinstance(o, (np.ndarray, np.generic)):
        return o.tolist()
    raise TypeError(f"{type(o).__name__} is not a number, list or NumPy array")


def _model_from_dict(d: Dict[str, Any]) -> Model:
    """A model from a dict with the keys of the model file: ``masses`` (kg),
    ``spring`` (list of ``{"dofs": [i, j], "stiffness": N/m}``), ``damping``
    (e.g. ``{"kind": "modal", "ratio": 0.01}``), ``contact``, ``friction``,
    ... Values may be NumPy arrays or scalars (``masses=np.full(8, 0.42)``).
    """
    try:
        text = json.dumps(d, default=_plain)
    except TypeError as e:
        raise TacitError(f"model dict: {e}") from None
    return Model.from_json(text)


def _model_to_dict(self: Model) -> Dict[str, Any]:
    """The model's fields as a dict (the keys of the model file)."""
    return json.loads(self.to_json())


def _triplets(a: Any, what: str) -> tuple:
    """A dense array or a SciPy sparse matrix as (rows, columns, row
    indices, column indices, values) of its non-zero entries, 0-based."""
    if hasattr(a, "tocoo"):  # scipy.sparse, without importing SciPy
        c = a.tocoo()
        rows, cols = c.shape
        return (
            int(rows),
            int(cols),
            np.asarray(c.row, dtype=np.int64).tolist(),
            np.asarray(c.col, dtype=np.int64).tolist(),
            np.asarray(c.data, dtype=np.float64).tolist(),
        )
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise TacitError(f"{what}: not a real matrix ({e})") from None
    if arr.ndim != 2:
        raise TacitError(f"{what}: a 2-D array is needed, got {arr.ndim} dimension(s)")
    r, c = np.nonzero(arr)
    return (arr.shape[0], arr.shape[1], r.tolist(), c.tolist(), arr[r, c].tolist())


def _model_from_matrices(
    M: Any,
    K: Any,
    points: Dict[str, int],
    *,
    damping: Optional[Dict[str, Any]] = None,
    C: Any = None,
    elements: Sequence[Dict[str, Any]] = (),
    fixed: Sequence[str] = (),
    interfaces: Optional[Dict[str, Any]] = None,
    reduction: Optional[Dict[str, Any]] = None,
    name: str = "matrices",
) -> Model:
    """A model from mass and stiffness matrices, as a finite element code
    gives them: ``M`` (kg) and ``K`` (N/m) dense NumPy arrays or SciPy
    sparse matrices of the same size, symmetric; ``C`` (N s/m) an optional
    damping matrix added to ``damping``.

    ``points`` names DOFs: ``{"n12:uy": 25, ...}``, the DOF numbered from
    1 (row 25 of the matrices is row index 24). A DOF without a label can
    be neither measured, driven nor hold an element. ``fixed``: labels of
    DOFs held at zero (clamped). ``damping``: as in a model file, e.g.
    ``{"kind": "modal", "ratio": 0.01}``. ``elements``: the nonlinear
    elements placed by label, each a dict with ``kind`` (``contact``,
    ``clearance``, ``relative_friction``, ``cubic``, ...) and the keys of
    the model file, e.g. ``{"kind": "contact", "dofs": ["n100:uy"], "gap":
    2e-4, "stiffness": 5e4}`` (gap in m, stiffness in N/m).
    ``interfaces``: ``{"points": [...], "pairs": [[a, b], ...]}`` where an
    effect may act that no sensor sees. ``reduction``: ``{"cutoff_hz":
    ..., "band_factor": 2.0, "max_modes": 200}``.

    The checks are those of a model file with ``[matrices]``
    (docs/formats.md): sizes, finite entries, symmetry (the error names the
    entry), labels in range and each DOF labelled once, every label used
    existing, the mass of the free DOFs positive definite; each failure
    raises :class:`TacitError` naming the matrix, the entry or the label.

    The model is reduced (Craig–Bampton) onto the points of a record when
    it is used: :func:`simulate` takes ``points`` and ``input_point``,
    :func:`identify` and :func:`diagnose` the points of the record's
    channels (``accel:n100:uy``); :meth:`Model.reduce` reduces it by hand.
    """
    table: Dict[str, Any] = {"name": name, "points": dict(points), "fixed": list(fixed)}
    if damping is not None:
        table["damping"] = damping
    if interfaces is not None:
        table["interfaces"] = interfaces
    if reduction is not None:
        table["reduction"] = reduction
    for i, e in enumerate(elements):
        e = dict(e)
        kind = e.pop("kind", None)
        if not isinstance(kind, str):
            raise TacitError(f"elements[{i}]: give its kind (\"contact\", \"clearance\", ...)")
        if kind in ("name", "points", "fixed", "damping", "interfaces", "reduction"):
            raise TacitError(f"elements[{i}]: kind {kind!r} is not an element")
        table.setdefault(kind, []).append(e)
    try:
        text = json.dumps(table, default=_plain)
    except TypeError as e:
        raise TacitError(f"model {name}: {e}") from None
    c = None if C is None else _triplets(C, "damping matrix C")
    return Model._from_matrices(
        name, _triplets(M, "mass matrix M"), _triplets(K, "stiffness matrix K"), c, text
    )


Model.from_matrices = staticmethod(_model_from_matrices)  # type: ignore[attr-defined]
Model.from_dict = staticmethod(_model_from_dict)  # type: ignore[attr-defined]
Model.to_dict = _model_to_dict  # type: ignore[attr-defined]


def read_record(path: PathLike) -> Record:
    """Read a record file (.h5, .csv or .mat), converted to SI units."""
    return Record.read(os.fspath(path))


def _as_model(model: Union[Model, PathLike]) -> Model:
    return model if isinstance(model, Model) else load_model(model)


def _as_record(record: Union[Record, PathLike]) -> Record:
    return record if isinstance(record, Record) else read_record(record)


def simulate(model: Union[Model, PathLike], **options: Any) -> Record:
    """Simulate ``model`` (nonlinear elements included) and sample a record
    carrying its truth.

    Options (defaults in brackets): ``samples`` [4096], ``fs`` Hz [512],
    ``input`` [``"random"``; ``"sweep"``, ``"none"``], ``rms`` N [20],
    ``band`` Hz [(5, 200)], ``amplitude`` N [10], ``sweep`` Hz [(5, 150)],
    ``force`` (a force history in N, replaces ``input``), ``input_dof``
    [1], ``sensors`` (DOFs from 1) [all], ``kinds`` [``["accel"]``; also
    ``"disp"``, ``"vel"``], ``noise`` (fraction of each channel's RMS)
    [0], ``seed`` [7], ``substeps`` (Newmark sub-steps per sample)
    [enough for the record to stand for the continuous structure, as
    ``tacit simulate`` chooses them: 302 for a 2e6 N/m contact at 512 Hz].

    A model from matrices (:meth:`Model.from_matrices`) takes ``points``
    (the sensor labels) and ``input_point`` (the label where the force
    acts) instead of ``sensors`` and ``input_dof``; it is reduced onto them
    and its channels are named by point (``accel:n100:uy``).
    """
    if "force" in options and options["force"] is not None:
        options["force"] = np.ascontiguousarray(options["force"], dtype=np.float64)
    return _tacit.simulate(_as_model(model), **options)


@dataclass
class Modes:
    """Modes of the undamped linear part of a model."""

    #: Natural frequencies, Hz, ascending (0 for rigid-body modes).
    freq_hz: np.ndarray
    #: Mass-normalized shapes, one column per mode (ndof x ndof).
    shapes: np.ndarray
    #: True for each rigid-body mode.
    rigid: List[bool]


def modal(model: Union[Model, PathLike]) -> Modes:
    """Natural frequencies (Hz) and mass-normalized mode shapes of the
    linear part of ``model`` (generalized symmetric eigenproblem)."""
    f, phi, rigid = _tacit.modal(_as_model(model))
    return Modes(freq_hz=f, shapes=phi, rigid=list(rigid))


@dataclass
class Identification:
    """The internal force a linear model lacks, identified from a record."""

    #: Internal force per DOF, N (ndof x samples), on the left-hand side of
    #: M a + C v + K u + f = f_ext (a contact closing as u_i - u_j grows gives
    #: f_i >= 0).
    force: np.ndarray
    #: Time of every sample, s.
    time: np.ndarray
    #: The summary ``tacit identify`` writes to summary.json: relative errors
    #: before/after (fractions), per-channel errors, force RMS per DOF (N),
    #: the location found, the comparison with a simulated record's truth.
    summary: Dict[str, Any]

    @property
    def located(self) -> Optional[List[List[int]]]:
        """The force directions found (DOF lists from 1), or None."""
        loc = self.summary.get("settings", {}).get("located")
        return None if loc is None else [d["dofs"] for d in loc["directions"]]


def identify(
    model: Union[Model, PathLike],
    record: Union[Record, PathLike],
    sensors: Optional[Sequence[int]] = None,
    *,
    resolution: int = 8,
    noise: float = 0.01,
    locate: bool = True,
    substeps: int = 10,
) -> Identification:
    """Identify the internal force the linear part of ``model`` lacks from
    ``record``, with accelerometers (or other channels) at ``sensors`` (DOFs
    from 1; default every measured DOF): the located, lifted smoother of
    ``tacit identify``. A model from matrices is reduced onto the record's
    points first and uses all of them (leave ``sensors`` out). ``noise``
    is the assumed channel noise as a fraction of each channel's RMS;
    ``resolution`` the sub-intervals per sample on which the force is
    constant; ``locate=False`` leaves an unknown force at every DOF."""
    s, f, t = _tacit.identify(
        _as_model(model),
        _as_record(record),
        None if sensors is None else list(sensors),
        resolution=resolution,
        noise=noise,
        locate=locate,
        substeps=substeps,
    )
    return Identification(force=f, time=t, summary=json.loads(s))


@dataclass
class Diagnosis:
    """What ``tacit diagnose`` found, with the files it wrote."""

    #: The whole report (report.json) as a dict.
    report: Dict[str, Any]
    #: The files written (report.json, report.md, settings.toml,
    #: model-fitted.toml, figures).
    paths: List[str]
    #: The output directory.
    output: str
    #: The fitted model (declared model + effects found, calibrated).
    model: Model
    #: Convenience views of ``report``.
    effects: List[Dict[str, Any]] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        """One line: what was found."""
        return self.report["verdict"]

    @property
    def errors(self) -> Dict[str, Optional[float]]:
        """Relative and multiple-shooting errors before and after (fractions;
        None where a simulation failed)."""
        b, a = self.report["before"], self.report["after"]
        return {
            "relative_before": b.get("relative_error"),
            "relative_after": a.get("relative_error"),
            "simulation_before": b.get("simulation_error"),
            "simulation_after": a.get("simulation_error"),
        }

    def parameters(self) -> Dict[str, float]:
        """Fitted parameters of every effect found, ``{"<effect> <name>":
        value}`` in SI units (gap in m, stiffness in N/m, level in N)."""
        out = {}
        for e in self.effects:
            for name, value in e.get("parameters", {}).items():
                out[f"{e['label']} {name}"] = value
        return out


def diagnose(
    model: Union[Model, PathLike],
    record: Union[Record, PathLike],
    output: PathLike,
    *,
    validation: Union[Record, PathLike, None] = None,
    sensors: Optional[Sequence[int]] = None,
    linear_records: Sequence[Union[Record, PathLike]] = (),
    trust_linear: bool = False,
    settings: Optional[PathLike] = None,
    force: bool = False,
) -> Diagnosis:
    """What is ``model`` missing? The close-the-loop diagnosis of ``record``
    (``tacit diagnose``): effects found and fitted, errors before and after,
    validated on ``validation`` when given. Files go to ``output`` (refused
    when not empty unless ``force``). ``settings``: a settings file (TOML or
    a report.json to replay)."""
    out = os.fspath(output)
    paths, fitted = _tacit.diagnose(
        _as_model(model),
        _as_record(record),
        out,
        validation=None if validation is None else _as_record(validation),
        sensors=None if sensors is None else list(sensors),
        linear_records=[_as_record(r) for r in linear_records],
        trust_linear=trust_linear,
        settings=None if settings is None else os.fspath(settings),
        force=force,
    )
    with open(os.path.join(out, "report.json"), encoding="utf-8") as f:
        rep = json.load(f)
    return Diagnosis(
        report=rep,
        paths=[os.fspath(p) for p in paths],
        output=out,
        model=fitted,
        effects=rep.get("effects", []),
    )


@dataclass
class GroupEstimates:
    """One set of parameters of one effect fitted to several records of the
    same structure at once (``tacit campaign``'s joint fit), reported
    against each record's own fit."""

    #: The effect whose parameters are shared, e.g. ``"contact 5→6"``.
    effect: str
    #: Per parameter (``gap``, ``stiffness``, ``level``, ``k3``, ...): a dict
    #: with ``value`` (SI: gap in m, stiffness in N/m, level in N, k3 in
    #: N/m^3), ``unit``, ``std`` (noise-only standard deviation, same
    #: unit, or None), ``per_record`` (the values of each record's own fit,
    #: in the order of ``records``) and ``at_bound``.
    parameters: Dict[str, Dict[str, Any]]
    #: Per record: ``name``, ``own`` (multiple-shooting relative error of
    #: its own fitted model, a fraction) and ``joint`` (the same with the
    #: shared parameters).
    records: List[Dict[str, Any]]
    #: How the search ended, in words.
    termination: str
    #: Iterations of the search.
    iterations: int
    #: Wall time of the joint fit, s.
    elapsed_s: float
    #: The first record's fitted model carrying the shared parameters.
    model: Model

    def values(self) -> Dict[str, float]:
        """The shared values, ``{"<effect> <parameter>": value}`` in SI
        units (as :meth:`Diagnosis.parameters` names them)."""
        return {f"{self.effect} {k}": p["value"] for k, p in self.parameters.items()}


def _shared_effect(diagnoses: Sequence[Diagnosis], effect: Optional[str]) -> Dict[str, Any]:
    """The effect dict (label, kind, dofs) to share: ``effect``, or the label
    found in most diagnoses (the first found on a tie)."""
    counts: Dict[str, int] = {}
    first: Dict[str, Dict[str, Any]] = {}
    for d in diagnoses:
        for e in d.effects:
            counts[e["label"]] = counts.get(e["label"], 0) + 1
            first.setdefault(e["label"], e)
    if effect is None:
        if not counts:
            raise TacitError("group_estimates: no diagnosis found an effect to share")
        effect = max(counts, key=lambda k: counts[k])
    if effect not in first:
        found = ", ".join(sorted(counts)) or "none"
        raise TacitError(f"group_estimates: no diagnosis found {effect!r} (found: {found})")
    return first[effect]


def group_estimates(
    model: Union[Model, PathLike],
    records: Sequence[Union[Record, PathLike]],
    diagnoses: Sequence[Diagnosis],
    *,
    effect: Optional[str] = None,
    names: Optional[Sequence[str]] = None,
    sensors: Optional[Sequence[int]] = None,
    settings: Optional[PathLike] = None,
) -> GroupEstimates:
    """Fit one set of parameters of one effect to several records of the
    same structure at once (the same bumper seen at several force levels),
    as ``tacit campaign`` does after diagnosing every record.

    ``diagnoses[i]`` is the :func:`diagnose` of ``records[i]`` against
    ``model`` (with the same ``sensors`` and ``settings``). ``effect`` is
    the label to share (e.g. ``"contact 5→6"``; default: the one found in
    most diagnoses); the records whose diagnosis did not find it are left
    out, and at least two must remain. ``names`` name the records in the
    result (default ``record1``, ``record2``, ...).

    The records are laid end to end into one multiple-shooting problem with
    each record's segments and start states, and the shared parameters are
    fitted by Levenberg–Marquardt from the median of the per-record values
    (docs/cli.md, campaigns). Raises :class:`TacitError` when the fit or the
    model with the shared parameters cannot be simulated on a record.
    """
    if len(records) != len(diagnoses):
        raise TacitError(
            f"group_estimates: {len(records)} records and {len(diagnoses)} diagnoses: give one diagnosis per record"
        )
    names = [f"record{i + 1}" for i in range(len(records))] if names is None else list(names)
    if len(names) != len(records):
        raise TacitError(f"group_estimates: {len(names)} names for {len(records)} records")
    shared = _shared_effect(diagnoses, effect)
    keep = [i for i, d in enumerate(diagnoses) if any(e["label"] == shared["label"] for e in d.effects)]
    js, joint = _tacit.group_estimates(
        _as_model(model),
        [_as_record(records[i]) for i in keep],
        [diagnoses[i].model for i in keep],
        [names[i] for i in keep],
        shared["label"],
        shared["kind"],
        list(shared["dofs"]),
        [int(diagnoses[i].report.get("substeps", [10, 10])[1]) for i in keep],
        sensors=None if sensors is None else list(sensors),
        settings=None if settings is None else os.fspath(settings),
    )
    r = json.loads(js)
    return GroupEstimates(
        effect=r["effect"],
        parameters={p["name"]: {k: v for k, v in p.items() if k != "name"} for p in r["parameters"]},
        records=r["records"],
        termination=r["termination"],
        iterations=r["iterations"],
        elapsed_s=r["elapsed_s"],
        model=joint,
    )
