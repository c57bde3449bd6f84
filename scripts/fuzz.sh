#!/usr/bin/env bash
# Fuzzes the readers by mutation (issue 19): each target of the kodama-fuzz crate reads mutated
# copies of its seed (fuzz/corpus/<target>/seed.*) for FUZZ_SECONDS (default 600) and prints how
# many cases ran and how many panicked; any panic fails the run. The cases live in
# fuzz/tests/mutations.rs (`cargo test` runs 64 per target through proptest). The coverage-guided
# campaign is scripts/fuzz_afl.sh.
#
#   scripts/fuzz.sh                 every target, 10 minutes each
#   FUZZ_SECONDS=60 scripts/fuzz.sh ply glb
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${FUZZ_SECONDS:-600}"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(ply sionna_xml glb tileset_json views_json measurements_csv las laz geotiff osm_xml
        geojson xyz exr ron_graph ron_sweep)
fi
# The test profile keeps overflow checks on, so an unchecked size shows up as a panic.
# The test binary runs from a private copy, so cargo's lock and later builds in target/ do not
# stall or replace it during an hour-long soak.
bin=$(cargo test -p kodama-fuzz --test mutations --no-run --message-format=json 2>/dev/null |
    grep -o '"executable":"[^"]*mutations[^"]*"' | tail -1 | cut -d'"' -f4)
[ -x "$bin" ] || { echo "fuzz.sh: could not build the mutations test binary" >&2; exit 1; }
copy=$(mktemp -d)/mutations
cp "$bin" "$copy"
status=0
for t in "${targets[@]}"; do
    (cd fuzz && FUZZ_TARGET="$t" FUZZ_SECONDS="$seconds" "$copy" soak --ignored --exact --nocapture) \
        | grep -E "cases in|first panicking" || status=1
done
rm -rf "$(dirname "$copy")"
exit $status
