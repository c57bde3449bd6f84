//! The Calibrate stage (issue 57) on a synthetic truth, and a Trace given its output.

use kodama_nodes::artifact::{Material, Measurements, Metrics};
use kodama_nodes::rf::calibration;
use kodama_nodes::stage::{Ctx, Inputs, Stage};
use kodama_nodes::stages::radio::calibrate::{Calibrate, CalibrateParams};

use kodama_nodes::artifact::{Endpoint, Height, Link};
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::em::permittivity;
use kodama_nodes::rf::paths::trace_links;
use kodama_nodes::rf::scene::RfScene;
use kodama_nodes::rf::test_scenes::street_grid_scene;
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::radio::trace::Trace;
use kodama_nodes::{Artifact, Site};
use num_complex::Complex64 as C64;
use std::sync::Arc;

const FREQ: f64 = 3.5e9;

fn site() -> Site {
    Site {
        crs: "EPSG:32618".into(),
        origin: (0.0, 0.0),
        cell_m: 1.0,
    }
}

/// The two transmitters A and B, where the twin mounts them.
const CELLS: [(&str, [f64; 3]); 2] = [("A", [-60.0, -56.0, 12.0]), ("B", [30.0, 28.0, 15.0])];

/// Two transmitters' links to receivers along the street grid's streets, measured through
/// a truth whose concrete has 1.3 x the ITU ε' and 0.5 x its σ, with 2 dB of noise.
fn measured() -> Measurements {
    let itu = permittivity(Material::Concrete, FREQ, false).unwrap();
    let truth = RfScene::new(&street_grid_scene(), FREQ, false)
        .unwrap()
        .with_permittivity(Material::Concrete, C64::new(1.3 * itu.re, 0.5 * itu.im));
    measure(&truth, &Antenna::default(), [0.0, 0.0])
}

/// The links of [`CELLS`] to receivers along the street grid's streets, measured through
/// `truth` with the transmitters' `antenna` raised by `raised` metres (A's, B's) from where the
/// links say they are, with 2 dB of noise.
fn measure(truth: &RfScene, antenna: &Antenna, raised: [f64; 2]) -> Measurements {
    let mut rxs = Vec::new();
    for line in [-56.0, -28.0, 0.0, 28.0, 56.0] {
        for k in 0..31 {
            let s = -90.0 + 6.0 * k as f64;
            rxs.push([s, line, 1.5]);
            rxs.push([line - 4.0 * (line / 28.0), s + 3.0, 1.5]);
        }
    }
    let mut out = Measurements::default();
    let opt = CalibrateParams::default().trace.options.trace_options();
    let opt = kodama_nodes::rf::path::TraceOptions {
        rays: 100_000,
        ..opt
    };
    for ((id, tx), up) in CELLS.into_iter().zip(raised) {
        let at = [tx[0], tx[1], tx[2] + up];
        let pairs: Vec<_> = rxs.iter().map(|&r| (at, r)).collect();
        let traced = trace_links(truth, &pairs, antenna, &Antenna::default(), &opt, FREQ);
        for (k, (r, lp)) in rxs.iter().zip(traced).enumerate() {
            if !lp.gain_db.is_finite() {
                continue;
            }
            let end = |id: &str, p: [f64; 3]| Endpoint {
                id: id.into(),
                x: p[0],
                y: p[1],
                z: Height::Absolute(p[2]),
                azimuth_deg: None,
            };
            let noise = 2.0
                * kodama_nodes::rng::gaussian(kodama_nodes::rng::mix(
                    k as u64 ^ (id.len() as u64 + id.as_bytes()[0] as u64) << 32,
                ));
            out.links.push(Link {
                tx: end(id, tx),
                rx: end("", *r),
                freq_hz: FREQ,
                path_loss_db: Some(-lp.gain_db + noise),
                rx_power_dbm: None,
                tx_eirp_dbm: None,
                los: None,
            });
        }
    }
    out
}

/// The stage inputs: the street grid, `links`, no terrain, and a `calibration` if given.
fn inputs(links: &Measurements, calibration: Option<Metrics>) -> Inputs {
    Inputs::new()
        .with(
            "scene",
            Slot::One(Arc::new(Artifact::Scene(street_grid_scene()))),
        )
        .with(
            "links",
            Slot::One(Arc::new(Artifact::Measurements(links.clone()))),
        )
        .with("terrain", Slot::Optional(None))
        .with(
            "calibration",
            Slot::Optional(calibration.map(|c| Arc::new(Artifact::Metrics(c)))),
        )
}

/// A Trace of `links` with `p`, given `calibration`.
fn trace(
    p: &kodama_nodes::rf::traced_links::TraceParams,
    links: &Measurements,
    calibration: Option<Metrics>,
) -> Measurements {
    Trace::run(p, &inputs(links, calibration), &Ctx::new(&site(), &[])).unwrap()
}

fn params() -> CalibrateParams {
    let mut p = CalibrateParams {
        block_m: 40.0,
        guard_m: 2.0,
        noise_db: 2.0,
        ..Default::default()
    };
    p.trace.options.rays = 100_000;
    p
}

/// The stage recovers the truth's concrete from the training blocks, scores the held-out
/// blocks better than offsets alone, and a Trace given its output traces the calibrated twin.
#[test]
fn calibrate_recovers_the_truths_concrete_and_trace_applies_it() {
    let links = measured();
    let s = site();
    let m = Calibrate::run(&params(), &inputs(&links, None), &Ctx::new(&s, &[])).unwrap();
    let get = |k: &str| m.get(k).unwrap_or_else(|| panic!("{k} missing"));
    let eps = get("calibration/permittivity/concrete");
    let sigma = get("calibration/conductivity/concrete");
    let (before, after) = (
        get("held_out/rmse_offsets_only_db"),
        get("held_out/rmse_calibrated_db"),
    );
    println!(
        "concrete ε' x{eps:.3}, σ x{sigma:.3}; {} training links; held out ({} links): \
         {before:.2} -> {after:.2} dB",
        get("train/links"),
        get("held_out/links")
    );
    // σ is recovered. ε' is only up to the 0.2 m slab's thickness resonances, which alias
    // it: measured, a factor 1.09 fits these training blocks better than the truth's 1.3
    // (RMSE 1.79 against 1.85 dB; held out 2.03 against 1.95 dB), so no ε' is asserted here
    // (tests/calibration.rs recovers it from one transmitter's links). The held-out links
    // come to within a quarter dB of the 2 dB noise.
    assert!((sigma / 0.5 - 1.0).abs() < 0.1, "σ factor {sigma}");
    assert!(
        after < before - 1.0 && after < 2.3,
        "held out {before} -> {after}"
    );
    // Trace with the factors: closer to the measurements than the ITU twin, link by link.
    let traced = |calibration: Option<Metrics>| trace(&params().trace, &links, calibration);
    let rmse = |pred: &Measurements| {
        let e: Vec<f64> = pred
            .links
            .iter()
            .zip(&links.links)
            .filter_map(|(p, l)| Some(p.path_loss_db? - l.path_loss_db?))
            .filter(|e| e.is_finite())
            .collect();
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / e.len() as f64).sqrt()
    };
    let (itu, cal) = (rmse(&traced(None)), rmse(&traced(Some(m.clone()))));
    println!("Trace: {itu:.2} dB with the ITU values, {cal:.2} dB with the calibration");
    assert!(cal < itu - 1.0, "{itu} -> {cal}");
}

/// A calibration naming a material that does not exist, or a factor that is not a positive
/// number, is refused by name.
#[test]
fn a_bad_calibration_input_is_refused_by_name() {
    let mut m = Metrics::default();
    m.set("calibration/permittivity/unobtainium", 1.2);
    let e = calibration::calibration_from(&m).unwrap_err();
    assert!(e.contains("unobtainium"), "{e}");
    let mut m = Metrics::default();
    m.set("calibration/conductivity/concrete", -1.0);
    let e = calibration::calibration_from(&m).unwrap_err();
    assert!(e.contains("positive"), "{e}");
    let mut m = Metrics::default();
    m.set("calibration/tilt_deg/A", 200.0);
    let e = calibration::calibration_from(&m).unwrap_err();
    assert!(e.contains("tilt_deg/A") && e.contains("90"), "{e}");
    let mut m = Metrics::default();
    m.set("calibration/height_m/B", f64::INFINITY);
    let e = calibration::calibration_from(&m).unwrap_err();
    assert!(e.contains("height_m/B"), "{e}");
    let mut m = Metrics::default();
    m.set("train/links", 3.0);
    assert!(
        calibration::calibration_from(&m)
            .unwrap()
            .factors
            .is_empty()
    );
}

/// A Trace given a cell's antenna mount traces that cell's links with the antenna turned and
/// raised, and the other cells' as they were.
#[test]
fn trace_moves_only_the_named_cells_antenna() {
    use kodama_nodes::rf::antenna::{Antenna, Pattern, Polarization};
    let links = measured();
    let mut p = params().trace;
    p.tx_antenna = Antenna {
        pattern: Pattern::Tr38901,
        polarization: Polarization::V,
        azimuth_deg: 90.0,
        tilt_deg: 0.0,
    };
    let mut m = Metrics::default();
    m.set("calibration/tilt_deg/A", 5.0);
    m.set("calibration/azimuth_deg/A", -10.0);
    m.set("calibration/height_m/A", 2.0);
    let turned = trace(&p, &links, Some(m));
    let mut q = p.clone();
    q.tx_antenna.tilt_deg += 5.0;
    q.tx_antenna.azimuth_deg -= 10.0;
    let mut raised = links.clone();
    for l in &mut raised.links {
        if let (Height::Absolute(z), "A") = (&mut l.tx.z, l.tx.id.as_str()) {
            *z += 2.0;
        }
    }
    let (plain, by_hand) = (trace(&p, &links, None), trace(&q, &raised, None));
    let mut changed = 0;
    for ((t, a), (b, l)) in turned
        .links
        .iter()
        .zip(&plain.links)
        .zip(by_hand.links.iter().zip(&links.links))
    {
        let want = if l.tx.id == "A" { b } else { a };
        assert_eq!(t.path_loss_db, want.path_loss_db, "{}", l.tx.id);
        changed += (l.tx.id == "A" && t.path_loss_db != a.path_loss_db) as usize;
    }
    assert!(changed > 50, "{changed} of A's links changed");
}

/// Every param a user sets is checked before anything is traced, the error naming it.
#[test]
fn bad_calibrate_params_are_refused_by_name() {
    let bad: [(&str, fn(&mut CalibrateParams)); 12] = [
        ("scattering", |p| p.scattering = true),
        ("height_scan_m", |p| p.height_scan_m = 0.0),
        ("height_tolerance_m", |p| p.height_tolerance_m = f64::NAN),
        ("height_tolerance_m", |p| p.height_tolerance_m = 0.0),
        ("max_retraces", |p| p.max_retraces = 1000),
        ("noise_db", |p| p.noise_db = f64::NAN),
        ("noise_db", |p| p.noise_db = 0.0),
        ("block_m", |p| p.block_m = f64::INFINITY),
        ("guard_m", |p| p.guard_m = 60.0),
        ("materials", |p| {
            p.materials = Some(vec!["unobtainium".into()])
        }),
        ("trace", |p| p.trace.coherent = true),
        ("permittivity", |p| {
            (p.permittivity, p.conductivity) = (false, false);
        }),
    ];
    for (field, spoil) in bad {
        let mut p = CalibrateParams::default();
        spoil(&mut p);
        let e = Calibrate::validate(&p).expect_err(field);
        assert_eq!(e.field, field, "{e:?}");
    }
    assert!(Calibrate::validate(&CalibrateParams::default()).is_ok());
}

/// Truths whose cell A stands 2.2 m and 3.8 m higher than the twin mounts it (a sector antenna
/// tilted down, so the height moves each link's elevation in the beam as well as its paths;
/// between the two, paths start to clear a roof, which the twin's RMSE shows as a step): the
/// stage scans the heights, fits from the best, traces again where the fit moved an antenna
/// (keeping a move only where the trace confirms it), and lands within half a metre of each
/// truth with B where it is; a Trace given the output fits A's links as well as the noise
/// allows.
#[test]
fn calibrate_finds_a_raised_antenna_by_retracing() {
    use kodama_nodes::rf::antenna::{Pattern, Polarization};
    let sector = Antenna {
        pattern: Pattern::Tr38901,
        polarization: Polarization::V,
        azimuth_deg: 45.0,
        tilt_deg: 10.0,
    };
    let truth = RfScene::new(&street_grid_scene(), FREQ, false).unwrap();
    let mut p = params();
    p.trace.tx_antenna = sector;
    (p.permittivity, p.conductivity, p.height) = (false, false, true);
    for raised in [2.2, 3.8] {
        let links = measure(&truth, &sector, [raised, 0.0]);
        let m = Calibrate::run(&p, &inputs(&links, None), &Ctx::new(&site(), &[])).unwrap();
        let get = |k: &str| m.get(k).unwrap_or_else(|| panic!("{k} missing"));
        let (a, b) = (get("calibration/height_m/A"), get("calibration/height_m/B"));
        let traced = |calibration: Option<Metrics>| trace(&p.trace, &links, calibration);
        let (plain, cal) = (traced(None), traced(Some(m.clone())));
        let rmse = |pred: &Measurements, id: &str| {
            let e: Vec<f64> = (pred.links.iter().zip(&links.links))
                .filter(|(_, l)| l.tx.id == id)
                .filter_map(|(p, l)| Some(p.path_loss_db? - l.path_loss_db?))
                .filter(|e| e.is_finite())
                .collect();
            let mean = e.iter().sum::<f64>() / e.len() as f64;
            (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / e.len() as f64).sqrt()
        };
        let (before, after) = (rmse(&plain, "A"), rmse(&cal, "A"));
        println!(
            "| {raised} | {} | {a:.2} ± {:.2} | {b:.2} ± {:.2} | {} | {} / {} | {before:.2} -> \
             {after:.2} |",
            get("fit/height_m/A/scanned"),
            get("fit/height_m/A/spread_ln"),
            get("fit/height_m/B/spread_ln"),
            get("fit/retraces"),
            get("fit/height_m/A/moves_refused"),
            get("fit/height_m/B/moves_refused"),
        );
        assert!((a - raised).abs() < 0.5, "A raised {a} m, truth {raised}");
        assert!(b.abs() < 0.5, "B raised {b} m, truth 0");
        assert!(
            after < 2.2,
            "A's links, a Trace with the calibration: {before} -> {after} dB"
        );
        assert_eq!(rmse(&plain, "B"), rmse(&cal, "B"), "B moved");
    }
}
