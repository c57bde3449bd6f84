#!/usr/bin/env bash
# Fetches the three.js build the report's 3D view embeds (nodes/assets/three/), from the npm
# registry, with its licence. The checked-in copy is exactly this file, unmodified; the report
# writer turns its ES-module export list into a plain object when it inlines it (so report.html
# works from file://, where browsers refuse to load module files).
set -euo pipefail
version=${1:-0.170.0}
dest="$(dirname "$0")/../nodes/assets/three"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm pack --silent "three@$version" >/dev/null && tar xzf "three-$version.tgz")
mkdir -p "$dest"
cp "$tmp/package/build/three.module.min.js" "$tmp/package/LICENSE" "$dest/"
echo "three.js $version -> $dest"
