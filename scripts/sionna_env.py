"""Sets up Sionna RT on a CPU-only machine (see shared/data/README.md): LLVM 19 for Dr.Jit and the
LLVM Mitsuba variant (KODAMA_MI_VARIANT names another, e.g. cuda_ad_mono_polarized on a GPU).
Import this module before anything from sionna.rt."""
import os

os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so")
import mitsuba as mi  # noqa: E402

mi.set_variant(os.environ.get("KODAMA_MI_VARIANT", "llvm_ad_mono_polarized"))
