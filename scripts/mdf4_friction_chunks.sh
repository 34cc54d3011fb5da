#!/bin/bash
# fit-friction on MDF4 friction tests stressing its row chunks (scripts/mdf4_friction_chunks.py:
# record counts around 65,536, DZ and transposed DZ lists, unsorted files, invalidation bits,
# integer channels with conversions, MDF 4.00/4.10/4.20, times going back, NaN, values out of
# range, other groups) against the CSV asammdf reads back: the same fit JSON (`files`,
# `wall_s` aside) or the same row and column in the error. Not run by CI.
#   bash scripts/mdf4_friction_chunks.sh OUTDIR [CASE...]     (python3 with asammdf, pandas)
set -u
HILS=${HILS:-target/release/hils}
D=$1; shift
mkdir -p "$D"
"$HILS" bench --reader "$D/base.csv" --write-friction-points 140000 >/dev/null
python3 "$(dirname "$0")/mdf4_friction_chunks.py" "$D/base.csv" "$D/cases" "$@" 2>/dev/null | cut -d' ' -f1 > "$D/names"
for c in $(cat "$D/names"); do
  p=$D/cases/$c
  rm -f "$p.m.json" "$p.c.json"
  /usr/bin/time -f "%M" -o "$p.rss" "$HILS" fit-friction --map "$p.map.toml" --json "$p.m.json" "$p.mf4" >/dev/null 2>"$p.m.err"
  "$HILS" fit-friction --map "$p.map.toml" --json "$p.c.json" "$p.csv" >/dev/null 2>"$p.c.err"
  r=$(python3 - "$p" <<'PY'
import json, re, sys
p = sys.argv[1]
def fit(x):
    try:
        j = json.load(open(x))
    except OSError:
        return None
    j.pop("files"); j.pop("wall_s")
    return j
def err(x):
    e = open(x).read()
    m = re.search(r"(?:data row|at record) (\d+)", e)
    c = re.search(r"column `([^`]*)`", e)
    return (m and m.group(1), c and c.group(1)) if e.startswith("error") else None
a, b = fit(p + ".m.json"), fit(p + ".c.json")
if a is not None and b is not None:
    print("SAME fit" if a == b else "DIFFERENT fit: " + str({k for k in a if a[k] != b.get(k)}))
elif a is None and b is None and err(p + ".m.err") == err(p + ".c.err"):
    print("SAME error (row, column) %s" % (err(p + ".m.err"),))
else:
    print("DIFFERENT: mf4 %s / csv %s" % (err(p + ".m.err"), err(p + ".c.err")))
PY
)
  echo "$c: $r; peak RSS $(tail -1 "$p.rss") KB"
done
