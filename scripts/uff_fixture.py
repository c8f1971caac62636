"""Write tests/data/bumper-512.uff with pyuff (a development tool only; tacit
reads universal files itself): the first 512 samples of the shipped bumper
record, the force at DOF 1 in N (real double) and the accelerations at DOFs
1, 5 and 6 in g (real single), the one at DOF 6 written along -X.
tests/record_uff.rs reads it back against the HDF5 record.

    pip install pyuff numpy tacit   # tacit: make python
    python scripts/uff_fixture.py
"""

from pathlib import Path

import numpy as np
import pyuff

import tacit

ROOT = Path(__file__).resolve().parents[1]
G0 = 9.80665
N = 512

rec = tacit.read_record(ROOT / "data" / "lanl8dof-bumper.h5")
dt = 1.0 / rec.fs
x = np.arange(N) * dt
sets = []
(_, dof, _, force), = rec.inputs()
channels = [(dof, 1, 13, "N", 4, force[:N])]
for name, dof, _, data in rec.outputs():
    if dof in (1, 5, 6):
        sign = -1 if dof == 6 else 1
        channels.append((dof, sign, 12, "g", 2, sign * data[:N] / G0))
for node, direction, spec, unit, ordtype, data in channels:
    sets.append(
        pyuff.prepare_58(
            id1=f"tacit fixture node {node}",
            func_type=1,
            rsp_node=node,
            rsp_dir=direction,
            ref_node=1,
            ref_dir=1,
            ord_data_type=ordtype,
            num_pts=N,
            abscissa_spacing=1,
            abscissa_min=0.0,
            abscissa_inc=dt,
            abscissa_spec_data_type=17,
            abscissa_axis_units_lab="s",
            ordinate_spec_data_type=spec,
            ordinate_axis_units_lab=unit,
            orddenom_spec_data_type=0,
            orddenom_axis_units_lab="NONE",
            z_axis_spec_data_type=0,
            z_axis_axis_units_lab="NONE",
            data=np.asarray(data, dtype=float),
            x=x,
        )
    )
out = ROOT / "tests" / "data" / "bumper-512.uff"
if out.exists():
    out.unlink()
uff = pyuff.UFF(str(out))
uff.write_sets(sets, mode="add")
print(f"wrote {out} ({out.stat().st_size} bytes, {len(sets)} datasets)")
