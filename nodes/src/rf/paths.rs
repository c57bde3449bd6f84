//! The link tracer's entry point: [`trace_links`] finds paths the way Sionna RT does (what it
//! follows and what it finds are in `path`). Per transmitter: rays find the sequences of surfaces they bounce off (`sequences`), whose
//! images (`image_method`) solve every sequence exactly for each receiver; the field is then
//! evaluated along each path (`path_field`), to which diffracted paths (`diffracted`) and diffuse
//! power (`diffuse`) are added.

use std::convert::Infallible;

use glam::DVec3;
use num_complex::Complex64 as C64;
use rayon::prelude::*;

use super::antenna::Antenna;
use super::diffraction_search::diffraction_sequences;
use super::foliage::FoliageDepth;
use super::gpu::{Device, reflection_sequences_on};
use super::path::{LinkEnds, LinkPaths, Path, TraceOptions, Tracer};
use super::scene::RfScene;
use super::{diffracted, diffuse, image_method, path_field, sequences};

/// What the links from one transmitter share.
struct FromTx {
    /// The ray-found surface sequences, each with the transmitter's images in its surfaces.
    sequences: image_method::Candidates,
    /// The candidate diffracted paths (empty without diffraction).
    diffractions: diffracted::DiffractionCandidates,
    /// How deep in foliage the transmitter stands.
    foliage: FoliageDepth,
}

/// Traces every link (`tx`, `rx` pairs). Links sharing a transmitter share its ray search.
pub fn trace_links(
    scene: &RfScene,
    links: &[LinkEnds],
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Vec<LinkPaths> {
    let search = |txs: &[DVec3]| -> Result<_, Infallible> {
        Ok(sequences::reflection_sequences_from(scene, txs, opt))
    };
    let ends = (tx_antenna, rx_antenna);
    match trace_links_searched(scene, links, ends, opt, freq_hz, search) {
        Ok(paths) => paths,
        Err(never) => match never {},
    }
}

/// [`trace_links`] with the rays of its sequence search on `device`: the same paths to the bit
/// (the GPU's sequences are the CPU's; `rf::gpu`). An error when the device cannot be used.
pub fn trace_links_on(
    device: Device,
    scene: &RfScene,
    links: &[LinkEnds],
    (tx_antenna, rx_antenna): (&Antenna, &Antenna),
    opt: &TraceOptions,
    freq_hz: f64,
) -> Result<Vec<LinkPaths>, String> {
    let search = |txs: &[DVec3]| reflection_sequences_on(device, scene, txs, opt);
    trace_links_searched(scene, links, (tx_antenna, rx_antenna), opt, freq_hz, search)
}

/// [`trace_links`] with each transmitter's sorted sequences from `search`.
fn trace_links_searched<E: Send>(
    scene: &RfScene,
    links: &[LinkEnds],
    (tx_antenna, rx_antenna): (&Antenna, &Antenna),
    opt: &TraceOptions,
    freq_hz: f64,
    search: impl FnOnce(&[DVec3]) -> Result<Vec<Vec<Vec<u32>>>, E> + Send,
) -> Result<Vec<LinkPaths>, E> {
    let tracer = Tracer {
        scene,
        tx_antenna,
        rx_antenna,
        opt,
        foliage: opt.foliage_loss(freq_hz),
    };
    let mut txs: Vec<[u64; 3]> = links.iter().map(|l| l.0.map(f64::to_bits)).collect();
    txs.sort_unstable();
    txs.dedup();
    let tx_of = |l: &LinkEnds| {
        txs.binary_search(&l.0.map(f64::to_bits))
            .expect("every tx was listed")
    };
    let tx_points: Vec<DVec3> = txs
        .iter()
        .map(|t| DVec3::from(t.map(f64::from_bits)))
        .collect();
    // The scene's wedges do not depend on the rays: built on one thread while the rest search.
    let (all_wedges, found) = rayon::join(
        || {
            if opt.diffraction && opt.max_depth > 0 {
                super::diffraction::wedges_for(scene, opt)
            } else {
                super::diffraction::Wedges::default()
            }
        },
        || search(&tx_points),
    );
    let found = found?;
    let from_tx: Vec<FromTx> = tx_points
        .iter()
        .zip(found)
        .map(|(&tx, seqs)| {
            let diffractions = diffraction_sequences(scene, &all_wedges, tx, &seqs, opt);
            FromTx {
                sequences: image_method::Candidates::new(scene, tx, seqs),
                diffractions: diffracted::DiffractionCandidates::new(scene, tx, diffractions),
                foliage: FoliageDepth::at(scene, tx),
            }
        })
        .collect();
    // Diffuse power per link, computed per transmitter for all its receivers.
    let mut diffuse = vec![0.0; links.len()];
    let mut diffuse_split = vec![Vec::new(); links.len()];
    if opt.diffuse && opt.scattering_coefficient > 0.0 && opt.max_depth > 0 {
        for (k, t) in txs.iter().enumerate() {
            let idx: Vec<usize> = (0..links.len())
                .filter(|&i| tx_of(&links[i]) == k)
                .collect();
            let rxs: Vec<DVec3> = idx.iter().map(|&i| DVec3::from(links[i].1)).collect();
            let tx = DVec3::from(t.map(f64::from_bits));
            let (p, split) = diffuse::diffuse_power(&tracer, tx, from_tx[k].foliage, &rxs);
            for ((&i, v), split) in idx.iter().zip(p).zip(split) {
                diffuse[i] = v;
                diffuse_split[i] = split;
            }
        }
    }
    Ok(links
        .par_iter()
        .zip(diffuse.par_iter().zip(diffuse_split))
        .map(|(link, (&diffuse_power, diffuse_by_reflections))| {
            let shared = &from_tx[tx_of(link)];
            let (tx, rx) = (DVec3::from(link.0), DVec3::from(link.1));
            let mut paths = link_paths(&tracer, tx, rx, shared);
            if !shared.diffractions.is_empty() {
                paths.extend(shared.diffractions.paths(&tracer, tx, rx, shared.foliage));
            }
            let mut summary = summarize(paths, freq_hz, diffuse_power);
            summary.diffuse_by_reflections = diffuse_by_reflections;
            summary
        })
        .collect())
}

/// The direct path and every sequence solved, of one receiver.
fn link_paths(tracer: &Tracer, tx: DVec3, rx: DVec3, shared: &FromTx) -> Vec<Path> {
    let mut paths = Vec::new();
    if tracer.opt.los
        && let Some(p) = path_field::evaluate(tracer, &[tx, rx], &[], shared.foliage)
    {
        paths.push(p);
    }
    for (seq, points) in shared.sequences.solve(tracer.scene, tx, rx) {
        if let Some(p) = path_field::evaluate(tracer, &points, seq, shared.foliage) {
            paths.push(p);
        }
    }
    paths
}

/// Paths by delay, with the gains they add up to.
fn summarize(mut paths: Vec<Path>, freq_hz: f64, diffuse_power: f64) -> LinkPaths {
    paths.sort_by(|a, b| {
        a.delay_s
            .total_cmp(&b.delay_s)
            .then(a.interactions.len().cmp(&b.interactions.len()))
    });
    let incoherent: f64 = paths
        .iter()
        .map(|p| p.a[0] * p.a[0] + p.a[1] * p.a[1])
        .sum();
    let k = 2.0 * std::f64::consts::PI * freq_hz;
    let coherent: C64 = paths
        .iter()
        .map(|p| C64::new(p.a[0], p.a[1]) * C64::from_polar(1.0, -k * p.delay_s))
        .sum();
    LinkPaths {
        paths,
        gain_db: 10.0 * (incoherent + diffuse_power).log10(),
        coherent_gain_db: 10.0 * (coherent.norm_sqr() + diffuse_power).log10(),
        diffuse_gain_db: 10.0 * diffuse_power.log10(),
        diffuse_by_reflections: Vec::new(),
    }
}
