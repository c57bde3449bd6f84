#!/usr/bin/env bash
# Regenerates nodes/src/rf/gpu/kernels.ptx from kernels.cu with NVRTC from the pinned PyPI wheel
# (nvidia-cuda-nvrtc-cu12==12.0.76, installed into a venv under target/ci-nvrtc): the oldest
# 12.x NVRTC, whose PTX ISA 8.0 every driver from 525 on loads. No CUDA toolkit is needed.
#   scripts/gpu_ptx.sh           write kernels.ptx
#   scripts/gpu_ptx.sh --check   write to target/ and compare with the checked-in file (CI)
# Exit 3 when NVRTC cannot be had (no python3/venv/pip or no PyPI): callers skip, saying so.
set -euo pipefail
cd "$(dirname "$0")/.."
src=nodes/src/rf/gpu/kernels.cu
want=nodes/src/rf/gpu/kernels.ptx
venv=target/ci-nvrtc
out=$want
[ "${1:-}" = --check ] && out=target/gpu-kernels.ptx
mkdir -p target
if [ ! -x "$venv/bin/python" ]; then
    command -v python3 >/dev/null 2>&1 || { echo "gpu_ptx: python3 not found" >&2; exit 3; }
    python3 -m venv "$venv" >/dev/null 2>&1 || { echo "gpu_ptx: python3 -m venv failed" >&2; exit 3; }
fi
if ! "$venv/bin/python" -c "import nvidia.cuda_nvrtc" >/dev/null 2>&1; then
    if ! pip_out=$("$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        nvidia-cuda-nvrtc-cu12==12.0.76 2>&1); then
        echo "gpu_ptx: pip install nvidia-cuda-nvrtc-cu12==12.0.76 failed: $(printf '%s\n' "$pip_out" | tail -n 1)" >&2
        exit 3
    fi
fi
"$venv/bin/python" - "$src" "$out" <<'PY'
import ctypes, glob, os, sys
import nvidia.cuda_nvrtc as pkg
base = os.path.dirname(pkg.__file__) if pkg.__file__ else list(pkg.__path__)[0]
lib = sorted(glob.glob(os.path.join(base, "lib", "libnvrtc.so*")))
lib = [l for l in lib if "builtins" not in l][0]
nvrtc = ctypes.CDLL(lib)
src = open(sys.argv[1], "rb").read()
prog = ctypes.c_void_p()
def check(r, what):
    if r != 0:
        raise SystemExit(f"gpu_ptx: {what} failed: {nvrtc.nvrtcGetErrorString(r)}")
nvrtc.nvrtcGetErrorString.restype = ctypes.c_char_p
check(nvrtc.nvrtcCreateProgram(ctypes.byref(prog), src, b"kernels.cu", 0, None, None), "nvrtcCreateProgram")
# Bit-exact with the CPU: no fused multiply-adds, IEEE division and square root, subnormals kept.
opts = [b"-arch=compute_80", b"--fmad=false", b"-prec-div=true", b"-prec-sqrt=true", b"-ftz=false", b"-std=c++14"]
arr = (ctypes.c_char_p * len(opts))(*opts)
r = nvrtc.nvrtcCompileProgram(prog, len(opts), arr)
size = ctypes.c_size_t()
nvrtc.nvrtcGetProgramLogSize(prog, ctypes.byref(size))
log = ctypes.create_string_buffer(size.value)
nvrtc.nvrtcGetProgramLog(prog, log)
if r != 0:
    sys.stderr.write(log.value.decode(errors="replace"))
    check(r, "nvrtcCompileProgram")
nvrtc.nvrtcGetPTXSize(prog, ctypes.byref(size))
ptx = ctypes.create_string_buffer(size.value)
check(nvrtc.nvrtcGetPTX(prog, ptx), "nvrtcGetPTX")
open(sys.argv[2], "wb").write(ptx.value)
v = [ctypes.c_int(), ctypes.c_int()]
nvrtc.nvrtcVersion(ctypes.byref(v[0]), ctypes.byref(v[1]))
print(f"gpu_ptx: NVRTC {v[0].value}.{v[1].value} wrote {sys.argv[2]} ({len(ptx.value)} bytes)")
PY
if [ "${1:-}" = --check ]; then
    if cmp -s "$out" "$want"; then
        echo "gpu_ptx: kernels.ptx is what kernels.cu compiles to"
    else
        echo "gpu_ptx: kernels.ptx differs from what kernels.cu compiles to: run scripts/gpu_ptx.sh and commit it" >&2
        exit 1
    fi
fi
