//! The GPU backend (issue 56; the research in `shared/notes/gpu.md`): the tracer's closest-hit
//! cast as a CUDA kernel, driven from Rust through the driver API.
//!
//! Why this shape:
//! - One CUDA C++ source (`kernels.cu`) written for two compilers. The driver runs its PTX
//!   (`kernels.ptx`, made by NVRTC from a pinned PyPI wheel with `scripts/gpu_ptx.sh` and checked
//!   in), so a GPU machine needs only the NVIDIA driver: no toolkit, no NVRTC, no Vulkan or
//!   OptiX. g++ compiles the same file for the host (feature `cuda`, `build.rs`), and the tests
//!   check that twin against the Rust tracer on machines without a GPU.
//! - `cudarc` loads `libcuda.so.1` at run time, so the feature builds anywhere; without a driver
//!   [`driver_present`] is false and asking for the GPU is a clear error, not a crash.
//! - Hits are the CPU's to the bit ([`crate::geom::wide_bvh`]): the kernel traverses the same
//!   8-wide tree (uploaded as [`crate::geom::wide_bvh::WideBvh::gpu_words`] writes it) with the
//!   same IEEE operations in the same order, so a GPU map can only differ from the CPU's where
//!   the physics' transcendental functions do.
//!
//! - The radio map is one megakernel, a thread per launched ray (Sionna RT's symbolic loop is
//!   one too), summing into cells as exact fixed-point integers: a GPU map is the same bits on
//!   every run whatever the scheduling, and the same bits as the host twin's where its paths
//!   are specular. It covers the flat plane and terrain-following surfaces, every antenna
//!   (isotropic, dipole, the TR 38.901 sector, either polarisation), reflection, transmission,
//!   diffuse reflection (Lambertian or directive), foliage and first-order edge diffraction (two more kernels: each sample's wedge counted, then the samples, a thread
//!   each, over the wedges the rays lit, which the host picks from the triangles they first
//!   landed on); diffraction in a scene with foliage is refused by name
//!   ([`device_unavailable`], `map_unsupported`), and the CPU path stays the default.
//! - A scene goes up once (`Gpu::upload_scene`) and stays for any number of maps (`Gpu::map`):
//!   per map only its scalars travel, the rays' patch order is computed on the device
//!   (`kodama_order`, `fibonacci::patch_order`'s to the ray) and the cells come back.
//!   [`radio_map_on`] uploads the scene for its one map.
//! - The link search's rays are one kernel too (`link_search`): each thread walks a launched
//!   ray's whole tree of reflected and transmitted branches and adds the surface sequences it
//!   finds to one hash set on the device. The set is the CPU's exactly, so a link trace on the
//!   GPU ([`trace_links_on`](crate::rf::paths::trace_links_on)) is the CPU's to the bit: the
//!   image method and the fields after it run on the CPU from the same sorted sequences.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::artifact::Raster;
use crate::rf::antenna::Antenna;
use crate::rf::map_plane::MapPlane;
use crate::rf::path::TraceOptions;
use crate::rf::scene::RfScene;

/// Where a radio map is traced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Device {
    /// The Rust tracer on every core (the default).
    #[default]
    Cpu,
    /// An NVIDIA GPU through the CUDA driver (feature `cuda`).
    Cuda,
}

impl Device {
    /// True for [`Device::Cpu`] (serde's `skip_serializing_if`: a CPU map's cache key stays what
    /// it was before the device existed).
    pub fn is_cpu(&self) -> bool {
        *self == Device::Cpu
    }

    /// `cpu` or `cuda`.
    pub fn parse(s: &str) -> Result<Device, String> {
        match s {
            "cpu" => Ok(Device::Cpu),
            "cuda" => Ok(Device::Cuda),
            _ => Err(format!("expected cpu or cuda, found {s:?}")),
        }
    }
}

/// True when this build has the GPU backend (feature `cuda`).
pub const BUILT: bool = cfg!(feature = "cuda");

/// Whether the CUDA driver library (`libcuda.so.1`) can be loaded; always false without the
/// feature.
pub fn driver_present() -> bool {
    #[cfg(feature = "cuda")]
    {
        // SAFETY: only tries to open the library by its usual names.
        unsafe { cudarc::driver::sys::is_culib_present() }
    }
    #[cfg(not(feature = "cuda"))]
    {
        false
    }
}

/// Why a radio map or a link trace cannot run on `device` in this build on this machine, or
/// `None` when it can. Callers turn the reason into a user error (exit code 2).
pub fn device_unavailable(device: Device) -> Option<String> {
    match device {
        Device::Cpu => None,
        Device::Cuda if !BUILT => Some(
            "device cuda: this build has no GPU backend; rebuild with `--features cuda` \
             (README, \"GPU backend (optional)\")"
                .into(),
        ),
        Device::Cuda if !driver_present() => Some(
            "device cuda: no CUDA driver found (libcuda.so.1 could not be loaded); install the \
             NVIDIA driver or use --device cpu"
                .into(),
        ),
        Device::Cuda => None,
    }
}

/// [`radio_map`](crate::rf::radiomap::radio_map) on `device`. On the GPU the map is the CPU's
/// within the tolerance `tests/gpu_host.rs` states; a map the kernels do not cover
/// (diffraction in a scene with foliage) is an error saying so, since the user asked for the
/// GPU.
pub fn radio_map_on(
    device: Device,
    scene: &RfScene,
    tx: DVec3,
    antenna: &Antenna,
    plane: &MapPlane,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Result<Raster, String> {
    if let Some(why) = device_unavailable(device) {
        return Err(why);
    }
    match device {
        Device::Cpu => Ok(crate::rf::radiomap::radio_map(
            scene, tx, antenna, plane, opt, freq_hz,
        )),
        Device::Cuda => cuda_map(scene, tx, antenna, plane, opt, freq_hz),
    }
}

#[cfg(feature = "cuda")]
fn cuda_map(
    scene: &RfScene,
    tx: DVec3,
    antenna: &Antenna,
    plane: &MapPlane,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Result<Raster, String> {
    let inputs = MapInputs::new(scene, tx, antenna, plane, opt, freq_hz)
        .map_err(|e| format!("device cuda: {e}; use --device cpu"))?;
    let gpu = shared_gpu().map_err(|e| format!("device cuda: {e}"))?;
    let (map, _) = gpu
        .radio_map(&inputs)
        .map_err(|e| format!("device cuda: {e}"))?;
    Ok(map)
}

/// The process's GPU, opened (and its PTX loaded) on first use: a graph or a trace command
/// that maps or traces many times pays for the context and the module once. A failure to open
/// is not kept, so a later call tries again.
#[cfg(feature = "cuda")]
fn shared_gpu() -> Result<&'static Gpu, String> {
    static GPU: std::sync::OnceLock<Gpu> = std::sync::OnceLock::new();
    if let Some(g) = GPU.get() {
        return Ok(g);
    }
    let g = Gpu::new()?;
    Ok(GPU.get_or_init(|| g))
}

#[cfg(not(feature = "cuda"))]
fn cuda_map(
    _: &RfScene,
    _: DVec3,
    _: &Antenna,
    _: &MapPlane,
    _: &TraceOptions,
    _: f64,
) -> Result<Raster, String> {
    unreachable!("device_unavailable refuses cuda without the feature")
}

/// [`reflection_sequences`](crate::rf::sequences::reflection_sequences) from each of `txs` on
/// `device`: the same sorted sequences either way, the scene uploaded once for all of them.
pub fn reflection_sequences_on(
    device: Device,
    scene: &RfScene,
    txs: &[DVec3],
    opt: &TraceOptions,
) -> Result<Vec<Vec<Vec<u32>>>, String> {
    if let Some(why) = device_unavailable(device) {
        return Err(why);
    }
    match device {
        Device::Cpu => Ok(crate::rf::sequences::reflection_sequences_from(
            scene, txs, opt,
        )),
        Device::Cuda => cuda_sequences(scene, txs, opt).map_err(|e| format!("device cuda: {e}")),
    }
}

#[cfg(feature = "cuda")]
fn cuda_sequences(
    scene: &RfScene,
    txs: &[DVec3],
    opt: &TraceOptions,
) -> Result<Vec<Vec<Vec<u32>>>, String> {
    let params = txs
        .iter()
        .map(|&tx| SearchParams::new(tx, opt))
        .collect::<Result<Vec<_>, String>>()?;
    let gpu = shared_gpu()?;
    let resident = gpu.upload_scene(&MapScene::new(scene)?)?;
    params
        .iter()
        .map(|p| gpu.reflection_sequences(&resident, p).map(|(s, _)| s))
        .collect()
}

#[cfg(not(feature = "cuda"))]
fn cuda_sequences(
    _: &RfScene,
    _: &[DVec3],
    _: &TraceOptions,
) -> Result<Vec<Vec<Vec<u32>>>, String> {
    unreachable!("device_unavailable refuses cuda without the feature")
}

#[cfg(feature = "cuda")]
mod backend;
#[cfg(feature = "cuda")]
pub use backend::*;
#[cfg(feature = "cuda")]
mod link_search;
#[cfg(feature = "cuda")]
pub use link_search::*;
