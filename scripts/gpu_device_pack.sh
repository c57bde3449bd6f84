#!/usr/bin/env bash
# Fills .devcarry/ (ignored by git through .git/info/exclude) with what scripts/gpu_device_check.sh
# needs on a GPU machine without Rust: the release build of tests/gpu_device.rs, stripped, and
# Sionna RT's munich scene. Keeps it small (a few tens of MB) for the machine's carry limit.
set -euo pipefail
cd "$(dirname "$0")/.."
munich=${MUNICH_DIR:-../shared/data/sionna-scenes/munich}
[ -f "$munich/munich.xml" ] || munich=/work/shared/data/sionna-scenes/munich
cargo test -p kodama-nodes --release --features cuda --test gpu_device --no-run
bin=$(cargo test -p kodama-nodes --release --features cuda --test gpu_device --no-run \
    --message-format=json 2>/dev/null | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "gpu_device" and m.get("executable"):
        print(m["executable"])')
# The shared data may be read-only: make the old copy writable before removing it.
[ -d .devcarry ] && chmod -R u+w .devcarry
rm -rf .devcarry
mkdir -p .devcarry
cp "$bin" .devcarry/gpu_device
strip .devcarry/gpu_device
cp -r "$munich" .devcarry/munich
chmod -R u+w .devcarry/munich
du -sh .devcarry
