#!/usr/bin/env bash
# Coverage-guided fuzzing (issue 55): AFL++ through cargo-afl, each target of the kodama-fuzz crate
# (fuzz/src/lib.rs: every reader of a user's file, the RON graph and sweep parsers) for
# FUZZ_SECONDS (default 600), starting from its committed corpus fuzz/corpus/<target>/.
# Prints a line per target: executions, corpus size, edges covered, crashes and hangs.
#
#   scripts/fuzz_afl.sh                          every target, 10 minutes each, FUZZ_JOBS at a time
#   FUZZ_SECONDS=60 scripts/fuzz_afl.sh ply exr  two targets for a minute
#   FUZZ_KEEP=1 scripts/fuzz_afl.sh ...          also keep the minimised corpus (afl-cmin) in
#                                                fuzz/corpus/<target>/, for cargo test to replay
#
# Crash and hang inputs are copied to fuzz/crashes/<target>/ (replayed by cargo test once fixed);
# the run fails if there are any. Needs cargo-afl and its AFL++ build, once per machine:
#   cargo install cargo-afl && cargo afl config --build
# The instrumented build has overflow checks and debug assertions on, so an unchecked size panics.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${FUZZ_SECONDS:-600}"
jobs="${FUZZ_JOBS:-$(nproc)}"
out="${FUZZ_OUT:-$PWD/target/fuzz-afl}"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(ply sionna_xml glb tileset_json views_json measurements_csv las laz geotiff osm_xml
        geojson xyz exr ron_graph ron_sweep)
fi
command -v cargo-afl >/dev/null || {
    echo "fuzz_afl.sh: cargo-afl is missing: cargo install cargo-afl && cargo afl config --build" >&2
    exit 1
}
# Its own target folder: instrumented objects must not replace the ordinary build's.
export CARGO_TARGET_DIR="${FUZZ_TARGET_DIR:-$PWD/target/afl}"
cargo afl build --release -p kodama-fuzz --features afl --bin kodama-fuzz-afl
bin="$CARGO_TARGET_DIR/release/kodama-fuzz-afl"

# A container's core pattern and CPU governor are not ours to change; a small input asking for
# more than 4 GB is a finding (an allocation from a header), and so is one taking 10 s.
export AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1 AFL_NO_UI=1
export AFL_NO_AFFINITY=1

fuzz_one() {
    local t=$1 dir="$out/$1"
    rm -rf "$dir"
    mkdir -p "$dir"
    cargo afl fuzz -i "fuzz/corpus/$t" -o "$dir" -V "$seconds" -t 10000 -m 4096 \
        -- "$bin" "$t" >"$dir/log.txt" 2>&1 || echo "$t: afl-fuzz exited $? (see $dir/log.txt)" >&2
}

running=0
for t in "${targets[@]}"; do
    fuzz_one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
        wait -n || true
        running=$((running - 1))
    fi
done
wait

status=0
printf '| target | executions | per second | corpus | edges | crashes | hangs |\n|---|---:|---:|---:|---:|---:|---:|\n'
for t in "${targets[@]}"; do
    stats="$out/$t/default/fuzzer_stats"
    if [ ! -f "$stats" ]; then
        echo "$t: no fuzzer_stats (see $out/$t/log.txt)" >&2
        status=1
        continue
    fi
    get() { awk -F' *: *' -v k="$1" '$1 == k { print $2 }' "$stats"; }
    crashes=$(get saved_crashes)
    hangs=$(get saved_hangs)
    printf '| %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$(get execs_done)" "$(get execs_per_sec)" \
        "$(get corpus_count)" "$(get bitmap_cvg)" "$crashes" "$hangs"
    for kind in crashes hangs; do
        found=$(find "$out/$t/default/$kind" -type f -name 'id:*' 2>/dev/null | sort)
        if [ -n "$found" ]; then
            mkdir -p "fuzz/crashes/$t"
            i=0
            while read -r f; do
                cp "$f" "fuzz/crashes/$t/$kind-$(date +%Y%m%d)-$i"
                i=$((i + 1))
            done <<<"$found"
            status=1
        fi
    done
    if [ "${FUZZ_KEEP:-0}" = 1 ]; then
        min="$out/$t/min"
        rm -rf "$min"
        cargo afl cmin -i "$out/$t/default/queue" -o "$min" -t 10000 -m 4096 -- "$bin" "$t" \
            >"$out/$t/cmin.txt" 2>&1
        seed=$(ls "fuzz/corpus/$t" | grep '^seed' || true)
        find "fuzz/corpus/$t" -type f ! -name 'seed*' -delete
        # AFL's names carry commas and colons; the corpus keeps its content digest instead.
        for f in "$min"/*; do
            [ -f "$f" ] || continue
            cmp -s "$f" "fuzz/corpus/$t/$seed" && continue
            cp "$f" "fuzz/corpus/$t/$(sha256sum "$f" | cut -c1-16)"
        done
        echo "$t: corpus kept ($(ls "fuzz/corpus/$t" | wc -l) files, seed $seed)" >&2
    fi
done
exit $status
