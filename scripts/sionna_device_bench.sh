#!/usr/bin/env bash
# Times Sionna RT 2.2.0's radio map of munich on the device machine's GPU (cuda_ad_mono_polarized),
# with scripts/sionna_radiomap_bench.py, for (rays, depth) = (1e6, 3) (1e7, 3) (1e6, 5) (1e7, 5),
# the paper's settings (1e6, 12) (1e7, 12) with diffuse reflection at S 0.3, and (1e6, 3) (1e7, 3)
# with first-order edge diffraction, warm best of 3
# runs each. Run from the repository root, carrying .sionnacarry:
#
#     run(command="bash scripts/sionna_device_bench.sh", carry=[".sionnacarry"], timeout_s=600)
#
# .sionnacarry/ holds wheels from PyPI, trimmed to fit the 64 MiB a run may carry: mitsuba 3.9.1
# (cp312 manylinux_2_28, only the cuda_ad_mono_polarized variant, no srgb.coeff, no volumetric /
# curve / sun-sky / principled-style plugins), drjit 1.5.0, sionna-rt 2.2.0 (example scenes other
# than munich removed), importlib_resources, typing_extensions, and a stub wheel for ipywidgets,
# pythreejs and IPython (imported by sionna.rt only for its notebook viewers; any use raises).
# Rebuild it with `scripts/sionna_device_pack.sh` (needs PyPI; see its header for what is trimmed).
# The device machine has Python 3.12, numpy, scipy, matplotlib; Mitsuba's CUDA variants also need
# the driver's OptiX library (libnvoptix.so.1), which is reported below.
set -uo pipefail
cd "$(dirname "$0")/.."
SITE=/tmp/site
echo "== gpu: $(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1 | head -1)"
echo "== optix: $( (ldconfig -p 2>/dev/null | grep -o 'libnvoptix[^ ]*' | head -1) || true)" \
     "$(ls /usr/lib/x86_64-linux-gnu/libnvoptix* /usr/lib64/libnvoptix* 2>/dev/null | head -2 | tr '\n' ' ')"
echo "== bundle: $(du -sb .sionnacarry | cut -f1) bytes: $(cd .sionnacarry && ls *.whl | tr '\n' ' ')"
t0=$(date +%s)
if python3 -m pip --version >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" \
        .sionnacarry/*.whl || { echo "== pip install failed"; exit 1; }
else  # no pip: the wheels have no .data/ or scripts, so unpacking them is the same install
    echo "== no pip; unpacking the wheels into $SITE"
    python3 -c 'import sys, zipfile; [zipfile.ZipFile(w).extractall(sys.argv[1]) for w in sys.argv[2:]]' \
        "$SITE" .sionnacarry/*.whl || { echo "== unpacking failed"; exit 1; }
fi
echo "== installed in $(( $(date +%s) - t0 )) s"
export PYTHONPATH="$SITE:$PWD/scripts" KODAMA_MI_VARIANT=cuda_ad_mono_polarized PYTHONUNBUFFERED=1
python3 -c 'import sys, drjit, mitsuba; print("== versions: python", sys.version.split()[0], "drjit", drjit.__version__, "mitsuba", mitsuba.__version__); mitsuba.set_variant("cuda_ad_mono_polarized"); print("== variant:", mitsuba.variant())' 2>&1 | tail -5
MUNICH="$SITE/sionna/rt/scenes/munich/munich.xml"
[ -f "$MUNICH" ] || MUNICH=$(find "$SITE" -name munich.xml | head -1)
echo "== scene: $MUNICH"
rc=0
# Then the paper's settings: depth 12 with diffuse reflection (S 0.3); then first-order edge
# diffraction at depth 3 (the fourth field: 1 adds --diffraction).
for nd in "1e6 3 0 0" "1e7 3 0 0" "1e6 5 0 0" "1e7 5 0 0" "1e6 12 0.3 0" "1e7 12 0.3 0" "1e6 3 0 1" "1e7 3 0 1"; do
    set -- $nd
    extra=""
    [ "$4" = 1 ] && extra="--diffraction"
    t=$(date +%s)
    timeout 150 python3 scripts/sionna_radiomap_bench.py "$MUNICH" - --rays "$1" --depth "$2" --diffuse "$3" $extra --runs 3 2>&1 \
        | sed "s/^/[rays $1 depth $2 diffuse $3 diffraction $4] /" | tail -15
    r=${PIPESTATUS[0]}
    echo "[rays $1 depth $2 diffuse $3 diffraction $4] exit $r, $(( $(date +%s) - t )) s including import, scene load, first (compiling) call"
    [ "$r" = 0 ] || rc=$r
done
exit $rc
