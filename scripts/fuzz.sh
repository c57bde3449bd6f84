#!/usr/bin/env bash
# Fuzzes the readers (issue 19): each target (PLY, Sionna XML, glb, views.json, measurements CSV,
# LAS and LAZ headers, GeoTIFF tags) reads mutated copies of a valid seed file for FUZZ_SECONDS
# (default 600) and prints how many cases ran and how many panicked; any panic fails the run.
# The cases live in nodes/tests/fuzz_parsers.rs (`cargo test` runs 64 per target through proptest).
#
#   scripts/fuzz.sh                 every target, 10 minutes each
#   FUZZ_SECONDS=60 scripts/fuzz.sh ply glb
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${FUZZ_SECONDS:-600}"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(ply sionna_xml glb views_json measurements_csv las_header laz_header geotiff_tags osm_xml)
fi
# The test profile keeps overflow checks on, so an unchecked size shows up as a panic.
# The test binary runs from a private copy, so cargo's lock and later builds in target/ do not
# stall or replace it during an hour-long soak.
bin=$(cargo test -p kodama-nodes --test fuzz_parsers --no-run --message-format=json 2>/dev/null |
    grep -o '"executable":"[^"]*fuzz_parsers[^"]*"' | tail -1 | cut -d'"' -f4)
[ -x "$bin" ] || { echo "fuzz.sh: could not build the fuzz_parsers test binary" >&2; exit 1; }
copy=$(mktemp -d)/fuzz_parsers
cp "$bin" "$copy"
status=0
for t in "${targets[@]}"; do
    (cd nodes && FUZZ_TARGET="$t" FUZZ_SECONDS="$seconds" "$copy" soak --ignored --exact --nocapture) \
        | grep -E "cases in|first panicking" || status=1
done
rm -rf "$(dirname "$copy")"
exit $status
