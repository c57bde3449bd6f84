#!/usr/bin/env bash
# Rebuilds .sionnacarry/: a small set of wheels that lets Sionna RT 2.2.0 run on the device machine
# (Python 3.12, no internet, no mitsuba/drjit/sionna-rt there) within the 64 MiB that a `run` may carry.
#
#     scripts/sionna_device_pack.sh [OUT_DIR] [EXTRA_VARIANT ...]
#
# OUT_DIR defaults to .sionnacarry (relative to the repository root). EXTRA_VARIANT names more Mitsuba
# variants to keep besides cuda_ad_mono_polarized, e.g. llvm_ad_mono_polarized for a CPU-only test copy:
#     scripts/sionna_device_pack.sh /tmp/sionna-llvmcarry llvm_ad_mono_polarized
#
# Downloads from PyPI (cp312, manylinux x86_64): sionna-rt 2.2.0, mitsuba 3.9.1, drjit 1.5.0,
# importlib_resources, typing_extensions, then
#   - mitsuba: keeps only the cuda_ad_mono_polarized extension (plus EXTRA_VARIANTs), all shared libraries
#     (libmitsuba.so and its NEEDED: libembree3, OpenEXR, png, jpeg, pugixml, struct-jit, nanobind),
#     the Python sources, data/ior; drops the other 12 variants' extensions (scalar_*, llvm_*, other
#     cuda_*), data/srgb.coeff (spectral upsampling: spectral variants only), data/sunsky, C++ headers,
#     cmake and pkgconfig files, and rendering-only plugins: volumetric integrators (volpath,
#     volpathmis, ptracer, aov), media and phase functions, curves/ellipsoids/sdfgrid shapes,
#     sun-sky emitters, projector, thinlens and batch sensors, principled/hair/measured/pplastic BSDFs.
#     Every other plugin stays (shapes incl. ply/obj/serialized/shapegroup/instance/merge, basic BSDFs,
#     path/direct/depth/stokes integrators, emitters, sensors, films, filters, samplers, textures, spectra).
#   - sionna-rt: drops the example scenes other than munich (sionna/rt/scenes/<dir>/).
#   - a tiny stub wheel (kodama_sionna_preview_stubs) for ipywidgets, pythreejs and IPython: sionna.rt
#     imports them at import time only for its notebook viewers (Previewer, Viewer,
#     ScatteringModelViewer); any use of a stubbed name raises ImportError.
# RECORD files of the trimmed wheels list exactly the files kept. Install with
#     python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
#         --target /tmp/site .sionnacarry/*.whl
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-.sionnacarry}
shift || true
EXTRA=("$@")
WORK=$(mktemp -d /tmp/sionna-pack.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 -d "$WORK/whl" \
    sionna-rt==2.2.0 mitsuba==3.9.1 drjit==1.5.0 importlib_resources typing_extensions
mkdir -p "$OUT"
rm -f "$OUT"/*.whl
KEEP_VARIANTS="cuda_ad_mono_polarized ${EXTRA[*]:-}" python3 - "$WORK/whl" "$OUT" <<'EOF'
import base64, glob, hashlib, os, re, shutil, sys, zipfile

src, out = sys.argv[1], sys.argv[2]
keep_variants = set(os.environ["KEEP_VARIANTS"].split())
DROP_PLUGINS = set("""
volpath volpathmis ptracer aov
ellipsoids ellipsoidsmesh bsplinecurve linearcurve sdfgrid
sunsky timed_sunsky projector
thinlens batch
principled principledthin hair measured measured_polarized pplastic
gridvolume homogeneous heterogeneous constvolume
hg rayleigh isotropic sggx tabphase blendphase
""".split())
VARIANTS = ["scalar_rgb", "scalar_spectral", "scalar_spectral_polarized"] + [
    f"{b}_ad_{k}" for b in ("llvm", "cuda")
    for k in ("rgb", "mono", "mono_polarized", "spectral", "spectral_polarized")]


def keep_mitsuba(name):
    base = name.split("/")
    if base[0] != "mitsuba":
        return True  # dist-info, share/doc (licences)
    if len(base) == 2 and base[1].endswith(".so"):
        m = re.match(r"([a-z_]+)\.cpython-", base[1])
        if m and m.group(1) in VARIANTS:
            return m.group(1) in keep_variants
        return True  # libmitsuba, libembree3, ..., mitsuba_ext, mitsuba_alias
    if base[1] in ("include", "cmake", "pkgconfig"):
        return False
    if base[1] == "data":
        return base[2] == "ior"
    if base[1] == "plugins":
        return base[2][:-3] not in DROP_PLUGINS
    return True


def keep_sionna(name):
    p = name.split("/")
    if p[:3] == ["sionna", "rt", "scenes"] and len(p) > 4:
        return p[3] == "munich"
    return True


def rewrite(path, keep, dst):
    zin = zipfile.ZipFile(path)
    names = [i.filename for i in zin.infolist()]
    record = next(n for n in names if n.endswith(".dist-info/RECORD"))
    kept = [n for n in names if keep(n)]
    dropped = [n for n in names if not keep(n)]
    lines = []
    with zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zout:
        for n in kept:
            if n == record:
                continue
            info = zin.getinfo(n)
            data = zin.read(n)
            zi = zipfile.ZipInfo(n, info.date_time)
            zi.external_attr = info.external_attr
            zi.compress_type = zipfile.ZIP_DEFLATED
            zout.writestr(zi, data, compresslevel=9)
            h = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            lines.append(f"{n},sha256={h},{len(data)}")
        lines.append(f"{record},,")
        zout.writestr(zipfile.ZipInfo(record, zin.getinfo(record).date_time), "\n".join(lines) + "\n")
    print(f"{os.path.basename(dst)}: kept {len(kept)} of {len(names)} members, "
          f"{os.path.getsize(path)/1e6:.1f} -> {os.path.getsize(dst)/1e6:.1f} MB")
    return dropped


for whl in sorted(glob.glob(os.path.join(src, "*.whl"))):
    b = os.path.basename(whl)
    dst = os.path.join(out, b)
    if b.startswith("mitsuba-"):
        dropped = rewrite(whl, keep_mitsuba, dst)
        print("  dropped:", " ".join(sorted({d.split("/")[-1] for d in dropped
                                             if "/include/" not in d and "/cmake/" not in d})))
    elif b.startswith("sionna_rt-"):
        dropped = rewrite(whl, keep_sionna, dst)
        print("  dropped scenes:", " ".join(sorted({d.split("/")[3] for d in dropped})))
    else:
        shutil.copy(whl, dst)
        print(f"{b}: as downloaded")

# Stub wheel for the notebook-only imports of sionna.rt (preview.py, viewer.py, rcs viewer).
STUB = '''"""Stub made by scripts/sionna_device_pack.sh: sionna.rt imports this module only for its notebook
viewers. Names resolve (so the import and annotations succeed); using any of them raises ImportError."""


class _Missing:
    def __init__(self, name):
        self._name = name

    def __getattr__(self, attr):
        return _Missing(self._name + "." + attr)

    def __call__(self, *a, **k):
        raise ImportError(f"{self._name}: stub only (no ipywidgets/pythreejs/IPython in this bundle)")

    def __mro_entries__(self, bases):
        raise ImportError(f"{self._name}: stub only")

    def __getitem__(self, item):
        return self


def get_ipython():
    return None


def __getattr__(name):
    if name.startswith("__"):
        raise AttributeError(name)
    return _Missing(__name__ + "." + name)
'''
files = {
    "ipywidgets/__init__.py": STUB,
    "ipywidgets/embed.py": STUB,
    "pythreejs/__init__.py": STUB,
    "IPython/__init__.py": STUB,
    "IPython/display.py": STUB,
}
dist = "kodama_sionna_preview_stubs-0.0.0"
files[f"{dist}.dist-info/METADATA"] = (
    "Metadata-Version: 2.1\nName: kodama-sionna-preview-stubs\nVersion: 0.0.0\n"
    "Summary: import-time stubs of ipywidgets, pythreejs, IPython for sionna.rt without notebooks\n")
files[f"{dist}.dist-info/WHEEL"] = ("Wheel-Version: 1.0\nGenerator: sionna_device_pack.sh\n"
                                    "Root-Is-Purelib: true\nTag: py3-none-any\n")
files[f"{dist}.dist-info/top_level.txt"] = "IPython\nipywidgets\npythreejs\n"
rec = []
for n, t in files.items():
    d = t.encode()
    h = base64.urlsafe_b64encode(hashlib.sha256(d).digest()).rstrip(b"=").decode()
    rec.append(f"{n},sha256={h},{len(d)}")
rec.append(f"{dist}.dist-info/RECORD,,")
files[f"{dist}.dist-info/RECORD"] = "\n".join(rec) + "\n"
with zipfile.ZipFile(os.path.join(out, f"{dist}-py3-none-any.whl"), "w", zipfile.ZIP_DEFLATED) as z:
    for n, t in files.items():
        z.writestr(zipfile.ZipInfo(n, (2026, 1, 1, 0, 0, 0)), t)
print(f"{dist}-py3-none-any.whl: stubs of ipywidgets, ipywidgets.embed, pythreejs, IPython, IPython.display")
EOF
du -sb "$OUT"
