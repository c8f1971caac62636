#!/usr/bin/env bash
# The noise measured on records of data/lanl8dof-contact.toml at 0.3, 1 and
# 3 % noise (4096 samples, 40 sub-steps, seeds 31 and 32), diagnosed against
# data/lanl8dof.toml with the declared linear part trusted: the level
# measured, the level used, and the errors after on the record and the
# validation record. Usage: scripts/noise_levels.sh [TACIT_BINARY]
set -euo pipefail
tacit=${1:-target/release/tacit}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
for noise in 0.003 0.01 0.03; do
  for seed in 31 32; do
    "$tacit" simulate --model data/lanl8dof-contact.toml --noise "$noise" --seed "$seed" \
      --substeps 40 -o "$dir/r$noise-$seed.h5" > /dev/null 2>&1
  done
  "$tacit" diagnose --model data/lanl8dof.toml --record "$dir/r$noise-31.h5" \
    --validate "$dir/r$noise-32.h5" --substeps 40 --trust-linear --output "$dir/d$noise" > /dev/null 2>&1
  python3 - "$dir/d$noise/report.json" "$noise" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
n = r["noise"]
v = r["validation"]["after"]["relative_error"]
print(f"noise {100*float(sys.argv[2]):.1f} %: measured {100*n['level']:.3f} %, used {100*n['used']:.3f} %, "
      f"{n['status']['kind']}; error after {100*r['after']['relative_error']:.2f} %, validation {100*v:.2f} %")
PY
done
