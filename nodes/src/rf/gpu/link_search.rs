//! The link search's sequence search on the GPU (`search` and `kodama_sequences` in
//! kernels.cu): the ray part of [`crate::rf::sequences::reflection_sequences`], which takes most
//! of a deep link trace's time (BENCHMARKS.md, "The GPU tracer against Sionna RT CUDA"). Every
//! launched ray walks its whole tree of branches in one thread and inserts the sequences it
//! finds into one hash set on the device; the host sorts what comes back. The image method, the
//! paths' fields and everything after stay on the CPU, given the same sorted sequences, so a
//! trace is the same bits on either device.

use std::time::Instant;

use cudarc::driver::PushKernelArg;
use glam::DVec3;
use rayon::prelude::*;

use super::backend::{DeviceScene, Gpu, MapScene, driver_err, launch_for};
use crate::artifact::Material;
use crate::rf::path::{MAX_DEPTH, TraceOptions};

/// What one transmitter's search adds to its scene: the kernel's scalars (`S_*` in
/// kernels.cu) and the words a stored sequence takes.
pub struct SearchParams {
    consts: Vec<f64>,
    rays: u32,
    /// Words a sequence takes in the set: its length, then up to `max_depth` triangles.
    stride: u32,
    /// False when the options find no sequences at all (no reflection, or depth 0).
    searches: bool,
}

impl SearchParams {
    /// The search from `tx` under `opt` (its rays, depth and whether rays go through walls);
    /// an error past the kernel's [`MAX_DEPTH`] interactions.
    pub fn new(tx: DVec3, opt: &TraceOptions) -> Result<SearchParams, String> {
        if opt.max_depth > MAX_DEPTH {
            return Err(format!(
                "max_depth {}: the GPU link search follows at most {MAX_DEPTH} interactions",
                opt.max_depth
            ));
        }
        Ok(SearchParams {
            consts: vec![
                tx.x,
                tx.y,
                tx.z,
                opt.rays as f64,
                opt.max_depth as f64,
                if opt.transmission { 1.0 } else { 0.0 },
                Material::Foliage as u32 as f64,
            ],
            rays: opt.rays,
            stride: opt.max_depth + 1,
            searches: opt.reflection && opt.max_depth > 0 && opt.rays > 0,
        })
    }
}

/// The sizes of a set: `seq_cap` sequences, twice as many slots (a power of two), so that a
/// probe rarely runs past a few slots.
#[derive(Clone, Copy, Debug)]
struct SetSize {
    seq_cap: u32,
    slots: u32,
}

impl SetSize {
    /// A first guess from the rays: a search that finds more grows the set and runs again.
    fn first(rays: u32) -> SetSize {
        SetSize::holding((rays as u64 * 2).clamp(1 << 12, 1 << 24) as u32)
    }

    fn holding(seq_cap: u32) -> SetSize {
        SetSize {
            seq_cap,
            slots: (2 * seq_cap as u64).next_power_of_two().min(1 << 31) as u32,
        }
    }

    /// Four times the sequences, or `None` past what u32 indices name.
    fn grown(self) -> Option<SetSize> {
        let cap = self.seq_cap as u64 * 4;
        (cap < 1 << 30).then(|| SetSize::holding(cap as u32))
    }

    /// Bytes the set takes with sequences of `stride` words.
    fn bytes(self, stride: u32) -> u64 {
        4 * (self.slots as u64 + self.seq_cap as u64 * stride as u64)
    }
}

/// The sequences of a set's first `count` entries, sorted, each once (two threads racing to
/// store one sequence can leave a second copy, which the sort folds).
fn sorted_sequences(seqs: &[u32], count: usize, stride: usize) -> Vec<Vec<u32>> {
    let mut all: Vec<Vec<u32>> = seqs[..count * stride]
        .chunks_exact(stride)
        .map(|s| s[1..1 + s[0] as usize].to_vec())
        .collect();
    all.sort_unstable();
    all.dedup();
    all
}

unsafe extern "C" {
    fn kodama_host_sequences(
        nodes: *const u32,
        n_nodes: u32,
        packets: *const u32,
        tri: *const f64,
        material: *const u32,
        consts: *const f64,
        first: u32,
        n: u64,
        slots: *mut u32,
        slot_mask: u32,
        seqs: *mut u32,
        stride: u32,
        seq_cap: u32,
        counters: *mut u32,
    );
}

/// The search kernel's host twin, on every core: chunks of the lattice into sets of their
/// own (each grown until it holds its chunk's), merged and sorted. The CPU's
/// [`reflection_sequences`](crate::rf::sequences::reflection_sequences) exactly; an error when
/// a chunk's set would pass what u32 indices name.
pub fn host_reflection_sequences(
    scene: &MapScene,
    params: &SearchParams,
) -> Result<Vec<Vec<u32>>, String> {
    if !params.searches {
        return Ok(Vec::new());
    }
    const CHUNK: u32 = 4096;
    let stride = params.stride;
    let t = &scene.tree;
    let chunks: Vec<Vec<Vec<u32>>> = (0..params.rays.div_ceil(CHUNK))
        .into_par_iter()
        .map(|k| {
            let first = k * CHUNK;
            let n = CHUNK.min(params.rays - first);
            let mut size = SetSize::first(n);
            loop {
                let mut slots = vec![0u32; size.slots as usize];
                let mut seqs = vec![0u32; size.seq_cap as usize * stride as usize];
                let mut counters = [0u32; 2];
                // SAFETY: the scene's buffers are what `MapScene::new` built (every triangle
                // index in the tree within `tri` and `material`); consts are `SearchParams`'s
                // S_COUNT words; `slots` holds a power of two words and `seqs` seq_cap entries
                // of `stride` words, stride being max_depth + 1; rays first..first + n are
                // within the lattice.
                unsafe {
                    kodama_host_sequences(
                        t.nodes.as_ptr(),
                        t.node_count(),
                        t.packets.as_ptr(),
                        scene.tri.as_ptr(),
                        scene.material.as_ptr(),
                        params.consts.as_ptr(),
                        first,
                        n as u64,
                        slots.as_mut_ptr(),
                        size.slots - 1,
                        seqs.as_mut_ptr(),
                        stride,
                        size.seq_cap,
                        counters.as_mut_ptr(),
                    )
                };
                if counters[1] == 0 {
                    break Ok(sorted_sequences(
                        &seqs,
                        counters[0] as usize,
                        stride as usize,
                    ));
                }
                size = size
                    .grown()
                    .ok_or_else(|| format!("more than {} sequences in one chunk", size.seq_cap))?;
            }
        })
        .collect::<Result<_, String>>()?;
    let mut all: Vec<Vec<u32>> = chunks.into_iter().flatten().collect();
    all.sort_unstable();
    all.dedup();
    Ok(all)
}

/// Times of one device search, seconds.
#[derive(Clone, Copy, Debug)]
pub struct SearchTimes {
    /// The whole call on a resident scene: the patch order, every try of the kernel, the
    /// sequences back, sorted.
    pub call: f64,
    /// Of `call`: the kernel, launch to completion, summed over the tries.
    pub kernel: f64,
    /// Runs of the kernel: more than one when the set had to grow.
    pub tries: u32,
    /// Distinct sequences found.
    pub sequences: usize,
}

impl Gpu {
    /// The sequences rays from `params`' transmitter reflect off, sorted: the host twin's and
    /// the CPU's. An error when the set outgrows the device's free memory.
    pub fn reflection_sequences(
        &self,
        scene: &DeviceScene,
        params: &SearchParams,
    ) -> Result<(Vec<Vec<u32>>, SearchTimes), String> {
        let call = Instant::now();
        let mut times = SearchTimes {
            call: 0.0,
            kernel: 0.0,
            tries: 0,
            sequences: 0,
        };
        let order = match params.searches {
            true => self.order(params.rays)?,
            false => None,
        };
        let Some(order) = order else {
            times.call = call.elapsed().as_secs_f64();
            return Ok((Vec::new(), times));
        };
        let s = &self.stream;
        let consts = s.clone_htod(&params.consts).map_err(driver_err("upload"))?;
        let stride = params.stride;
        let mut size = SetSize::first(params.rays);
        loop {
            let (free, _) = s.context().mem_get_info().map_err(driver_err("memory"))?;
            if size.bytes(stride) > free as u64 {
                return Err(format!(
                    "the link search needs {:.1} GB of GPU memory to hold {} sequences of up to \
                     {} surfaces and the device has {:.1} GB free; use fewer rays or a lower \
                     max_depth",
                    size.bytes(stride) as f64 / 1e9,
                    size.seq_cap,
                    stride - 1,
                    free as f64 / 1e9
                ));
            }
            let mut slots = s
                .alloc_zeros::<u32>(size.slots as usize)
                .map_err(driver_err("alloc"))?;
            let mut seqs = s
                .alloc_zeros::<u32>(size.seq_cap as usize * stride as usize)
                .map_err(driver_err("alloc"))?;
            let mut counters = s.alloc_zeros::<u32>(2).map_err(driver_err("alloc"))?;
            s.synchronize().map_err(driver_err("order kernel"))?;
            let clock = Instant::now();
            let n = params.rays as u64;
            let slot_mask = size.slots - 1;
            let mut launch = s.launch_builder(&self.sequences);
            launch
                .arg(&scene.nodes)
                .arg(&scene.n_nodes)
                .arg(&scene.packets)
                .arg(&scene.tri)
                .arg(&scene.material)
                .arg(&consts)
                .arg(&order)
                .arg(&n)
                .arg(&mut slots)
                .arg(&slot_mask)
                .arg(&mut seqs)
                .arg(&stride)
                .arg(&size.seq_cap)
                .arg(&mut counters);
            // SAFETY: the arguments match `kodama_sequences`'s parameters in kernels.cu, in
            // order and type; `order` holds n lattice indices below the lattice's size, `slots`
            // a power of two words, `seqs` seq_cap entries of stride = max_depth + 1 words, the
            // scene what `MapScene::new` made.
            unsafe { launch.launch(launch_for(n)) }.map_err(driver_err("launch"))?;
            let count = s.clone_dtoh(&counters).map_err(driver_err("readback"))?;
            times.kernel += clock.elapsed().as_secs_f64();
            times.tries += 1;
            if count[1] == 0 {
                let used = count[0] as usize * stride as usize;
                let words = s
                    .clone_dtoh(&seqs.slice(..used))
                    .map_err(driver_err("readback"))?;
                let all = sorted_sequences(&words, count[0] as usize, stride as usize);
                times.sequences = all.len();
                times.call = call.elapsed().as_secs_f64();
                return Ok((all, times));
            }
            size = size.grown().ok_or_else(|| {
                format!(
                    "the link search found more than {} distinct sequences; use fewer rays or a \
                     lower max_depth",
                    size.seq_cap
                )
            })?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_grows_fourfold_and_keeps_twice_the_slots() {
        let s = SetSize::first(100_000);
        assert_eq!(s.seq_cap, 200_000);
        assert_eq!(s.slots, 1 << 19);
        let g = s.grown().unwrap();
        assert_eq!(g.seq_cap, 800_000);
        assert!(g.slots >= 2 * g.seq_cap && g.slots.is_power_of_two());
        assert!(SetSize::holding(1 << 29).grown().is_none());
    }

    #[test]
    fn copies_of_a_sequence_come_back_once() {
        // Stride 3: (len, a, b).
        let seqs = [2, 5, 7, 1, 4, 0, 2, 5, 7, 1, 3, 9];
        assert_eq!(
            sorted_sequences(&seqs, 4, 3),
            vec![vec![3], vec![4], vec![5, 7]]
        );
    }
}
