#!/usr/bin/env bash
# The GPU check (issue 56), run once on a GPU machine from the repository root, with the folder
# .devcarry/ that scripts/gpu_device_pack.sh fills on the build machine (that machine needs no
# GPU; this one needs no Rust, toolkit or internet, only the NVIDIA driver):
#   1. the driver, CUDA and graphics (Vulkan ICD, OptiX) libraries present;
#   2. the cast kernel against the Rust tracer, to the bit (street grid and munich);
#   2b. the map kernel against its host twin, to the bit, thrice (twice on a resident scene), and
#       the device's patch order against patch_order, to the ray;
#   3. munich radio maps on the GPU against radio_map on every CPU core, 10^6 and 10^7 rays at
#      depth 3 and 5 (the scene's upload once, then the warm whole call and the kernel+readback
#      alone, M rays/s, median |dB| difference, run-to-run identity), and
#      munich casts/s (lattice + specular bounces, hits compared to the bit): markdown tables;
#   4. the link search's sequence search on the GPU against the CPU's, the same set, and its
#      time on munich at depth 5, 9 and 12 (10^5 and 10^6 rays): a markdown table.
set -uo pipefail
cd "$(dirname "$0")/.."
carry=.devcarry
say() { printf '\n## %s\n\n' "$1"; }

say "machine"
date -u
uname -a
nproc
say "nvidia-smi"
nvidia-smi 2>&1 || echo "nvidia-smi not found or failed"
say "libraries (ldconfig -p | grep -E 'libcuda|GLX_nvidia|nvoptix')"
ldconfig -p 2>/dev/null | grep -E 'libcuda|GLX_nvidia|nvoptix' || echo "none listed"
say "Vulkan ICDs"
for d in /usr/share/vulkan/icd.d /etc/vulkan/icd.d; do
    echo "$d:"; ls -l "$d" 2>&1 | sed 's/^/  /'
done
command -v nvcc >/dev/null 2>&1 && nvcc --version | tail -n 2

if [ ! -x "$carry/gpu_device" ]; then
    echo "$carry/gpu_device missing: run scripts/gpu_device_pack.sh on the build machine" >&2
    exit 1
fi
export KODAMA_MUNICH_XML="$PWD/$carry/munich/munich.xml"
export RAYON_NUM_THREADS="${RAYON_NUM_THREADS:-$(nproc)}"

say "kernels = Rust tracer: casts to the bit, maps = host twin to the bit, order = patch_order, sequences = CPU's (tests/gpu_device.rs)"
"$carry/gpu_device" --test-threads=1 --nocapture device_casts_are_the_cpu_casts device_maps_are_the_host_maps device_order_is_patch_order device_sequences_are_the_cpus
rc1=$?

say "munich maps: GPU vs CPU ($RAYON_NUM_THREADS threads), 5 m cells at 1.5 m, tx 8.5,21,27, 3.5 GHz"
"$carry/gpu_device" --test-threads=1 --nocapture --ignored device_map_speed_on_munich
rc2=$?

say "munich casts: GPU vs CPU ($RAYON_NUM_THREADS threads), lattice + specular bounces"
"$carry/gpu_device" --test-threads=1 --nocapture --ignored device_cast_speed_on_munich
rc3=$?

say "munich link search (sequences): GPU vs CPU ($RAYON_NUM_THREADS threads), tx 8.5,21,27, with transmission"
"$carry/gpu_device" --test-threads=1 --nocapture --ignored device_link_search_speed_on_munich
rc4=$?

say "result"
echo "bit-exact tests rc=$rc1, map timing rc=$rc2, cast timing rc=$rc3, link search timing rc=$rc4"
[ "$rc1" = 0 ] && [ "$rc2" = 0 ] && [ "$rc3" = 0 ] && [ "$rc4" = 0 ]
