#!/usr/bin/env bash
# `hysar bench encoding --quick`: a row per view set, format, encoding and quality, in the table
# and in the JSON (bytes per eye layer, Mbit/s at 60 Hz, encode and decode ms, CIEDE2000 and
# PSNR); lossless rows have no error, lossy rows keep black black (the bench checks each
# lossless round trip) and cost fewer bytes than LZ4 tiles; bad options exit 2 naming the option.
set -euo pipefail
hysar="$1/hysar"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
HYSAR_VALIDATION=1 "$hysar" bench encoding --quick --repeats 1 --qualities 50,90 --moving-frames 2 \
    --json "$out/enc.json" --plot "$out/enc.png" > "$out/table.txt" 2> "$out/progress.txt"
# The plot of bytes against error: both view sets, ticks where their values belong.
[[ -s "$out/enc.png" ]] || { echo "no plot written"; exit 1; }
python3 "$(dirname "$0")/check_figure_svg.py" "$out/enc.svg" --plots 2
grep -q "moving headset: bytes against error" "$out/enc.svg" || { echo "the plot lacks its title"; exit 1; }
grep -q 'lossy q90' "$out/table.txt"
grep -q '^moving ' "$out/table.txt"
python3 - "$out/enc.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
rows = d["rows"]
keys = {"views", "format", "encoding", "quality", "layers", "bytes_per_eye_layer",
        "mbit_s_per_headset_60hz", "encode_ms_per_eye", "decode_ms_per_eye", "de00_mean",
        "de00_max", "psnr_db"}
for r in rows:
    missing = keys - r.keys()
    assert not missing, f"row {r} lacks {missing}"
    assert r["layers"] > 0 and r["bytes_per_eye_layer"] > 0, r
    assert abs(r["mbit_s_per_headset_60hz"] - r["bytes_per_eye_layer"] * 960 / 1e6) < 1e-6, r
for views in ("fig7", "moving"):
    lz4 = [r for r in rows if r["views"] == views and r["format"] == "rgba8" and r["encoding"] == "tiles+lz4"]
    lossy = {r["quality"]: r for r in rows if r["views"] == views and r["encoding"] == "lossy"}
    assert len(lz4) == 1 and sorted(lossy) == [50, 90], (views, lossy.keys())
    assert lz4[0]["de00_mean"] == 0 and lz4[0]["psnr_db"] is None
    for q, r in lossy.items():
        assert 0 < r["de00_mean"] <= r["de00_max"], r
        assert r["psnr_db"] > 30, r
        assert r["bytes_per_eye_layer"] < lz4[0]["bytes_per_eye_layer"], r
    assert lossy[50]["bytes_per_eye_layer"] < lossy[90]["bytes_per_eye_layer"]
    assert lossy[90]["de00_mean"] < lossy[50]["de00_mean"]
    # The Huffman tables: the server's (fitted to a recent layer), fitted to each layer, and
    # the standard ones code the same pixels; fitting beats the standard tables, and reusing a
    # fit costs little against fitting each layer.
    for q, r in lossy.items():
        by = {x["encoding"]: x for x in rows if x["views"] == views and x["quality"] == q}
        opt, std = by["lossy-opt"], by["lossy-std"]
        assert opt["de00_mean"] == r["de00_mean"] == std["de00_mean"], (r, opt, std)
        assert r["bytes_per_eye_layer"] < std["bytes_per_eye_layer"], (r, std)
        assert opt["bytes_per_eye_layer"] < std["bytes_per_eye_layer"], (opt, std)
        assert r["bytes_per_eye_layer"] < 1.1 * opt["bytes_per_eye_layer"], (r, opt)
# Coding against the previous layer (a reference frame): on the moving headset only, lossless
# (the bench checks each round trip through the held layer).
delta = [r for r in rows if r["encoding"].startswith("delta+")]
assert sorted(r["encoding"] for r in delta) == ["delta+lz4", "delta+zstd"], delta
assert all(r["views"] == "moving" and r["de00_mean"] == 0 and r["layers"] == 4 for r in delta), delta
print(f"bench encoding: {len(rows)} rows")
PY
for bad in "--qualities 0" "--qualities 50,x" "--moving-frames -1" "--repeats 0"; do
    # shellcheck disable=SC2086
    if "$hysar" bench encoding $bad 2> "$out/err.txt"; then echo "'$bad' was accepted"; exit 1; fi
    grep -q -- "${bad%% *}" "$out/err.txt" || { echo "'$bad': the error does not name the option"; cat "$out/err.txt"; exit 1; }
done
echo "bench encoding: rows, JSON and errors as documented"
