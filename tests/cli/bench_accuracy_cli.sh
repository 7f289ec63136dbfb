#!/usr/bin/env bash
# `hysar bench accuracy --quick`: writes a CSV with a row per setting, a PNG and an SVG whose
# tick labels cover the CSV's data (check_figure_svg.py), prints the table; a missing scene and a bad option are refused with a message naming them.
# The motion rows (none, predict, reproject, both on a short head turn): finite errors and
# costs, reprojection's p95 error below none's, and reprojection costing the client more.
# `hysar bench stability`: writes its CSV and markdown table, exits 0 with every case within
# tolerance (the table itself is asserted by the GPU test Stability.*), refuses a folder it
# cannot create.
set -euo pipefail
hysar="$1/hysar"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
HYSAR_VALIDATION=1 "$hysar" bench accuracy --quick --repeats 1 --out "$out/acc" > "$out/table.txt" 2> "$out/progress.txt"
csv="$out/acc/accuracy.csv"
head -1 "$csv" | grep -q '^knob,setting,reference,default,geometric_error_mm,rmse,mean_de00,render_ms,encode_ms,bytes,pareto,p50_px,p95_px,client_ms$'
rows=$(($(wc -l < "$csv") - 1))
[[ $rows -ge 25 ]] || { echo "only $rows rows"; exit 1; }
for knob in tessellation level-of-detail render-scale samples-per-pixel lights format encoding format+encoding motion; do
    grep -q "^$knob," "$csv" || { echo "no $knob rows"; exit 1; }
done
# Every rmse, render and encode figure is a finite number.
awk -F, 'NR > 1 && $1 != "motion" && !($6 ~ /^[0-9.e+-]+$/ && $8 ~ /^[0-9.]+$/ && $9 ~ /^[0-9.]+$/) { print "bad row: " $0; bad = 1 } END { exit bad }' "$csv"
# The motion rows: one per mode, p50 <= p95 pixels and client ms finite; reprojection leaves a
# smaller p95 error than none on the turn and costs the client more.
for mode in none predict reproject both; do
    grep -q "^motion,$mode," "$csv" || { echo "no motion row for $mode"; exit 1; }
done
awk -F, '$1 == "motion" && !($12 ~ /^[0-9.]+$/ && $13 ~ /^[0-9.]+$/ && $14 ~ /^[0-9.]+$/ && $12 + 0 <= $13 + 0) { print "bad motion row: " $0; bad = 1 } END { exit bad }' "$csv"
awk -F, '$1 == "motion" { p95[$2] = $13 + 0; ms[$2] = $14 + 0 }
    END {
        if (!(p95["reproject"] < p95["none"])) { print "reproject p95 " p95["reproject"] " px is not below none " p95["none"]; exit 1 }
        if (!(ms["reproject"] > ms["none"])) { print "reproject costs " ms["reproject"] " ms, none " ms["none"]; exit 1 }
    }' "$csv" || { grep '^motion' "$csv"; exit 1; }
grep -q '^motion .*p95 px\|^knob .*p95 px' "$out/table.txt" || { echo "no motion table"; exit 1; }
grep -q 'pareto' "$out/table.txt"
[[ $(head -c 8 "$out/acc/accuracy.png" | od -An -tx1 | tr -d ' \n') == 89504e470d0a1a0a ]]
python3 "$(dirname "$0")/check_figure_svg.py" "$out/acc/accuracy.svg" --accuracy-csv "$csv" --plots 9
grep -q 'reference: exact hemisphere' "$out/progress.txt"
if "$hysar" bench accuracy --quick --scene /nonexistent.json --out "$out/x" 2> "$out/err.txt"; then
    echo "a missing scene was accepted"; exit 1
fi
grep -q '/nonexistent.json' "$out/err.txt"
if "$hysar" bench accuracy --repeats 0 2> "$out/err.txt"; then echo "--repeats 0 accepted"; exit 1; fi
grep -q -- '--repeats' "$out/err.txt"
echo "bench accuracy: $rows rows, files and errors as documented"

HYSAR_VALIDATION=1 "$hysar" bench stability --out "$out/stab" > "$out/stab.txt"
head -1 "$out/stab/stability.csv" | grep -q '^formula,regime,rel_tolerance,abs_tolerance,'
rows=$(($(wc -l < "$out/stab/stability.csv") - 1))
[[ $rows -ge 60 ]] || { echo "stability: only $rows rows"; exit 1; }
grep -q '^Device: ' "$out/stab/stability.md"
grep -q '| ward | alpha 0.0001 x 0.0001 |' "$out/stab/stability.md"
grep -q ' 0 outside tolerance$' "$out/stab.txt"
if "$hysar" bench stability --out /proc/hysar-no-such-dir 2> "$out/err.txt"; then
    echo "stability: an impossible --out was accepted"; exit 1
fi
grep -q 'cannot create /proc/hysar-no-such-dir' "$out/err.txt"
echo "bench stability: $rows rows, files and errors as documented"
