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
//! The radio map on the GPU (the shoot-and-bounce megakernel) is not written yet: asking for it
//! is an error that says so, and the CPU path is the default.

use serde::{Deserialize, Serialize};

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

/// Why a radio map cannot be traced on `device` by this build on this machine, or `None` when
/// it can. Callers turn the reason into a user error (exit code 2).
pub fn map_unavailable(device: Device) -> Option<String> {
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
        Device::Cuda => Some(
            "device cuda: the radio map's GPU kernel is not written yet (issue 56, stage 2); \
             only the cast kernel exists; use --device cpu"
                .into(),
        ),
    }
}

#[cfg(feature = "cuda")]
mod backend;
#[cfg(feature = "cuda")]
pub use backend::*;
