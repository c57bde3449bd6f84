//! Calibration (issue 57): traced paths replayed with other materials, their analytic
//! derivatives, and a fit that recovers a synthetic truth's materials from its measurements.

use glam::DVec3;
use num_complex::Complex64 as C64;

use kodama_nodes::artifact::Material;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::calibration::{
    LinkModel, Mount, Observation, Parameter, Prior, Setting, State, TraceSetup, fit, fit_offsets,
    rmse_db,
};
use kodama_nodes::rf::em::permittivity;
use kodama_nodes::rf::path::TraceOptions;
use kodama_nodes::rf::paths::trace_links;
use kodama_nodes::rf::scene::RfScene;
use kodama_nodes::rf::test_scenes::street_grid;

const FREQ: f64 = 3.5e9;

/// Receivers 1.5 m up along the street grid's streets (between its blocks), every 6 m.
fn street_receivers() -> Vec<DVec3> {
    let mut out = Vec::new();
    for line in [-56.0, -28.0, 0.0, 28.0, 56.0] {
        for k in 0..31 {
            let s = -90.0 + 6.0 * k as f64;
            out.push(DVec3::new(s, line, 1.5));
        }
    }
    for line in [-60.0, -30.0, 0.0, 30.0, 60.0] {
        for k in 0..31 {
            let s = -87.0 + 6.0 * k as f64;
            out.push(DVec3::new(line, s, 1.5));
        }
    }
    out
}

fn options() -> TraceOptions {
    TraceOptions {
        rays: 100_000,
        max_depth: 3,
        ..Default::default()
    }
}

/// The links tx -> each receiver traced through `scene`, as replayable models, with the traced
/// gains.
fn traced(scene: &RfScene, tx: DVec3, rxs: &[DVec3]) -> Vec<(LinkModel, f64)> {
    let ant = Antenna::default();
    let opt = options();
    let links: Vec<_> = rxs.iter().map(|r| (tx.to_array(), r.to_array())).collect();
    let setup = TraceSetup {
        scene,
        tx_antenna: &ant,
        rx_antenna: &ant,
        opt: &opt,
    };
    trace_links(scene, &links, &ant, &ant, &opt, FREQ)
        .iter()
        .zip(rxs)
        .map(|(lp, &rx)| (LinkModel::new(&setup, tx, rx, lp), lp.gain_db))
        .collect()
}

fn state(scene: &RfScene) -> State {
    State::of_scene(scene, FREQ, &options())
}

/// Replaying the traced paths in the scene's own state gives the traced gains.
#[test]
fn replayed_paths_give_the_traced_gains() {
    let scene = street_grid();
    let s = state(&scene);
    let links = traced(&scene, DVec3::new(-60.0, -56.0, 12.0), &street_receivers());
    let mut worst = 0.0f64;
    let mut reached = 0;
    for (m, g) in &links {
        let (got, _) = m.gain_db(&s, &[], Mount::default());
        if g.is_finite() {
            reached += 1;
            worst = worst.max((got - g).abs());
        } else {
            assert!(!got.is_finite());
        }
    }
    println!("{reached} links reached; largest |replay - trace| {worst:.2e} dB");
    assert!(reached > 100);
    assert!(worst < 1e-9, "replay differs by {worst} dB");
}

/// The analytic derivatives against central differences of the replay.
#[test]
fn gain_derivatives_match_central_differences() {
    let scene = street_grid();
    let s = state(&scene);
    let params = [
        Parameter::Permittivity(Material::Concrete),
        Parameter::Conductivity(Material::Concrete),
        Parameter::Permittivity(Material::MediumDryGround),
        Parameter::Conductivity(Material::MediumDryGround),
    ];
    let links = traced(&scene, DVec3::new(-60.0, -56.0, 12.0), &street_receivers());
    let mut checked = 0;
    for (m, g) in links.iter().filter(|(_, g)| g.is_finite()).step_by(3) {
        let (_, dg) = m.gain_db(&s, &params, Mount::default());
        for (j, p) in params.iter().enumerate() {
            let h = 1e-5;
            let at = |sign: f64| {
                let mut t = s.clone();
                let v = t.get(*p).unwrap() * (sign * h).exp();
                set(&mut t, *p, v);
                m.gain_db(&t, &[], Mount::default()).0
            };
            let fd = (at(1.0) - at(-1.0)) / (2.0 * h);
            assert!(
                (dg[j] - fd).abs() <= 1e-5 * (1.0 + fd.abs()),
                "link at {g} dB, {p:?}: {} vs {fd}",
                dg[j]
            );
            checked += 1;
        }
    }
    assert!(checked > 100);
}

fn set(s: &mut State, p: Parameter, v: f64) {
    let m = match p {
        Parameter::Permittivity(m) | Parameter::Conductivity(m) => m,
        _ => unreachable!("only materials are set here"),
    };
    let e = s.eps_sigma[m as usize].as_mut().unwrap();
    match p {
        Parameter::Permittivity(_) => e.0 = v,
        _ => e.1 = v,
    }
}

/// A synthetic truth whose concrete is not the twin's (ε' x1.3, σ x0.5), measured with 2 dB of
/// Gaussian noise from two transmitters. Fitting the twin's concrete and ground on the first
/// transmitter's links recovers the truth's concrete within 10 %, and the second transmitter's
/// links (not fitted) are predicted better than by the ITU values.
#[test]
fn a_fit_recovers_perturbed_materials_and_carries_to_another_transmitter() {
    let twin = street_grid();
    let itu = permittivity(Material::Concrete, FREQ, false).unwrap();
    let truth =
        street_grid().with_permittivity(Material::Concrete, C64::new(1.3 * itu.re, 0.5 * itu.im));
    let rxs = street_receivers();
    let noise = |i: usize, tx: u64| {
        2.0 * kodama_nodes::rng::gaussian(kodama_nodes::rng::mix(i as u64 ^ (tx << 32)))
    };
    let observe = |tx: DVec3, cell: u64| -> Vec<Observation> {
        let measured = traced(&truth, tx, &rxs);
        traced(&twin, tx, &rxs)
            .into_iter()
            .zip(measured)
            .enumerate()
            .filter(|(_, (_, (_, g)))| g.is_finite())
            .map(|(i, ((model, _), (_, g)))| Observation {
                model,
                cell: 0,
                group: 0,
                loss_db: -g + noise(i, cell),
            })
            .collect()
    };
    let train = observe(DVec3::new(-60.0, -56.0, 12.0), 1);
    let held_out = observe(DVec3::new(30.0, 28.0, 15.0), 2);
    let states = [state(&twin)];
    let params = [
        Parameter::Permittivity(Material::Concrete),
        Parameter::Conductivity(Material::Concrete),
        Parameter::Permittivity(Material::MediumDryGround),
        Parameter::Conductivity(Material::MediumDryGround),
    ];
    let priors: Vec<Prior> = params.iter().map(|&p| Prior::default_for(p)).collect();
    let fitted = fit(&train, 1, &states, &priors, 2.0);
    println!(
        "{} training links, {} iterations: RMSE {:.2} -> {:.2} dB",
        train.len(),
        fitted.iterations,
        fitted.rmse_db.0,
        fitted.rmse_db.1
    );
    println!("| parameter | truth / ITU | fitted / ITU | posterior sd of ln k (prior's) |");
    let truths = [1.3, 0.5, 1.0, 1.0];
    for (((p, k), sd), (truth, prior)) in
        (fitted.values.iter().zip(&fitted.spread)).zip(truths.iter().zip(&priors))
    {
        println!(
            "| {p:?} | {truth:.3} | {k:.3} | {sd:.3} ({:.3}) |",
            prior.width
        );
    }
    let k = |j: usize| fitted.values[j].1;
    assert!((k(0) / 1.3 - 1.0).abs() < 0.10, "ε' factor {}", k(0));
    assert!((k(1) / 0.5 - 1.0).abs() < 0.10, "σ factor {}", k(1));
    // The other transmitter, each state with its own best offset (P2P after the offset).
    let calibrated = [states[0].scaled(&fitted.values)];
    let (plain, tuned) = (Setting::of(&states), Setting::of(&calibrated));
    let before = rmse_db(&held_out, plain, &fit_offsets(&held_out, 1, plain));
    let after = rmse_db(&held_out, tuned, &fit_offsets(&held_out, 1, tuned));
    println!(
        "held-out transmitter, {} links: P2P {:.2} dB with the ITU values, {:.2} dB calibrated",
        before.1, before.0, after.0
    );
    assert!(after.0 < before.0 - 0.2, "{} -> {}", before.0, after.0);
}

/// A truth whose sector antenna points 4° lower and 6° further clockwise than the twin's (the
/// published) one, with 2 dB of noise: the fit of the cell's tilt and bearing over the traced
/// paths recovers both within a degree, with the materials held.
#[test]
fn a_fit_recovers_a_turned_antenna() {
    use kodama_nodes::rf::antenna::{Pattern, Polarization};
    let scene = street_grid();
    let published = Antenna {
        pattern: Pattern::Tr38901,
        polarization: Polarization::V,
        azimuth_deg: 60.0,
        tilt_deg: 2.0,
    };
    let turned = Antenna {
        tilt_deg: published.tilt_deg + 4.0,
        azimuth_deg: published.azimuth_deg + 6.0,
        ..published
    };
    let tx = DVec3::new(-60.0, -56.0, 20.0);
    let rxs = street_receivers();
    let opt = options();
    let iso = Antenna::default();
    let links: Vec<_> = rxs.iter().map(|r| (tx.to_array(), r.to_array())).collect();
    let truth = trace_links(&scene, &links, &turned, &iso, &opt, FREQ);
    let twin = trace_links(&scene, &links, &published, &iso, &opt, FREQ);
    let setup = TraceSetup {
        scene: &scene,
        tx_antenna: &published,
        rx_antenna: &iso,
        opt: &opt,
    };
    let obs: Vec<Observation> = (twin.iter().zip(&truth).zip(&rxs).enumerate())
        .filter(|(_, ((_, t), _))| t.gain_db.is_finite())
        .map(|(i, ((lp, t), &rx))| Observation {
            model: LinkModel::new(&setup, tx, rx, lp),
            cell: 0,
            group: 0,
            loss_db: -t.gain_db
                + 2.0 * kodama_nodes::rng::gaussian(kodama_nodes::rng::mix(i as u64 ^ 0xA17)),
        })
        .collect();
    let states = [state(&scene)];
    let priors = [
        Prior::default_for(Parameter::Tilt(0)),
        Prior::default_for(Parameter::Azimuth(0)),
    ];
    let fitted = fit(&obs, 1, &states, &priors, 2.0);
    let (tilt, bearing) = (fitted.values[0].1, fitted.values[1].1);
    println!(
        "{} links: tilt offset {tilt:.2}° (truth 4), bearing {bearing:.2}° (truth 6); RMSE {:.2} \
         -> {:.2} dB",
        obs.len(),
        fitted.rmse_db.0,
        fitted.rmse_db.1
    );
    assert!((tilt - 4.0).abs() < 1.0, "tilt {tilt}");
    assert!((bearing - 6.0).abs() < 1.0, "bearing {bearing}");
}

/// The antenna's derivative through the replay against central differences of the gain.
#[test]
fn antenna_derivatives_match_central_differences() {
    use kodama_nodes::rf::antenna::{Pattern, Polarization};
    let scene = street_grid();
    let sector = Antenna {
        pattern: Pattern::Tr38901,
        polarization: Polarization::V,
        azimuth_deg: 60.0,
        tilt_deg: 2.0,
    };
    let tx = DVec3::new(-60.0, -56.0, 20.0);
    let rxs = street_receivers();
    let opt = options();
    let iso = Antenna::default();
    let links: Vec<_> = rxs.iter().map(|r| (tx.to_array(), r.to_array())).collect();
    let setup = TraceSetup {
        scene: &scene,
        tx_antenna: &sector,
        rx_antenna: &iso,
        opt: &opt,
    };
    let s = state(&scene);
    let params = [Parameter::Tilt(0), Parameter::Azimuth(0)];
    let mut checked = 0;
    for (lp, &rx) in trace_links(&scene, &links, &sector, &iso, &opt, FREQ)
        .iter()
        .zip(&rxs)
        .step_by(5)
    {
        if !lp.gain_db.is_finite() {
            continue;
        }
        let m = LinkModel::new(&setup, tx, rx, lp);
        let turn = |tilt_deg, azimuth_deg| Mount {
            tilt_deg,
            azimuth_deg,
            height_m: 0.0,
        };
        let (_, dg) = m.gain_db(&s, &params, turn(1.0, -2.0));
        let h = 1e-5;
        let g = |mount| m.gain_db(&s, &[], mount).0;
        let fd = [
            (g(turn(1.0 + h, -2.0)) - g(turn(1.0 - h, -2.0))) / (2.0 * h),
            (g(turn(1.0, -2.0 + h)) - g(turn(1.0, -2.0 - h))) / (2.0 * h),
        ];
        for (d, f) in dg.iter().zip(fd) {
            assert!((d - f).abs() <= 1e-4 * (1.0 + f.abs()), "{d} vs {f}");
        }
        checked += 1;
    }
    assert!(checked > 20);
}

/// A replay with its transmitter raised moves each path by the image method: where a trace from
/// the raised transmitter finds the same paths (the same faces, in order), the replay gives its
/// gain to rounding; the links whose paths changed are what the Calibrate stage retraces for.
#[test]
fn a_raised_replay_gives_the_retraced_gains() {
    let scene = street_grid();
    let s = state(&scene);
    let rxs = street_receivers();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let up = 0.7;
    let replays = traced(&scene, tx, &rxs);
    let ant = Antenna::default();
    let links: Vec<_> = rxs
        .iter()
        .map(|r| ((tx + DVec3::Z * up).to_array(), r.to_array()))
        .collect();
    let before = trace_links(
        &scene,
        &rxs.iter()
            .map(|r| (tx.to_array(), r.to_array()))
            .collect::<Vec<_>>(),
        &ant,
        &ant,
        &options(),
        FREQ,
    );
    let after = trace_links(&scene, &links, &ant, &ant, &options(), FREQ);
    let faces = |lp: &kodama_nodes::rf::path::LinkPaths| {
        let mut v: Vec<Vec<u32>> = lp
            .paths
            .iter()
            .map(|p| p.interactions.iter().map(|i| i.triangle).collect())
            .collect();
        v.sort();
        v
    };
    let raised = Mount {
        height_m: up,
        ..Mount::default()
    };
    let (mut same, mut worst, mut moved) = (0, 0.0f64, 0.0f64);
    for (((m, g0), b), a) in replays.iter().zip(&before).zip(&after) {
        if !(g0.is_finite() && a.gain_db.is_finite()) || faces(b) != faces(a) {
            continue;
        }
        let (got, _) = m.gain_db(&s, &[], raised);
        same += 1;
        worst = worst.max((got - a.gain_db).abs());
        moved = moved.max((a.gain_db - g0).abs());
    }
    println!(
        "{same} of {} links keep their paths when the transmitter rises {up} m: largest \
         |replay - retrace| {worst:.2e} dB (the rise itself moves them by up to {moved:.2} dB)",
        rxs.len()
    );
    assert!(same > 100, "{same} links kept their paths");
    assert!(
        moved > 0.1,
        "the rise moves the links too little to test: {moved} dB"
    );
    assert!(
        worst < 1e-6,
        "replay differs from the retrace by {worst} dB"
    );
}

/// A truth whose surfaces are rougher than the twin's (scattering coefficient 0.5 against the
/// twin's 0.25; diffuse scattering off the last surface on both), measured with 2 dB of noise:
/// the fit of S over the traced paths and their diffuse power split by reflections recovers it
/// within 10 %; the replay at the truth's S gives the truth's trace, and its derivative matches
/// central differences of the replay.
#[test]
fn a_fit_recovers_the_scattering_coefficient() {
    let scene = street_grid();
    let rough = |s: f64| TraceOptions {
        rays: 20_000,
        max_depth: 2,
        diffuse: true,
        scattering_coefficient: s,
        ..Default::default()
    };
    let (twin_opt, truth_opt) = (rough(0.25), rough(0.5));
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let rxs = street_receivers();
    let ant = Antenna::default();
    let links: Vec<_> = rxs.iter().map(|r| (tx.to_array(), r.to_array())).collect();
    let truth = trace_links(&scene, &links, &ant, &ant, &truth_opt, FREQ);
    let twin = trace_links(&scene, &links, &ant, &ant, &twin_opt, FREQ);
    let setup = TraceSetup {
        scene: &scene,
        tx_antenna: &ant,
        rx_antenna: &ant,
        opt: &twin_opt,
    };
    let state = State::of_scene(&scene, FREQ, &twin_opt);
    let (obs, truths): (Vec<Observation>, Vec<f64>) = (twin.iter().zip(&truth).zip(&rxs))
        .enumerate()
        .filter(|(_, ((w, t), _))| t.gain_db.is_finite() && w.gain_db.is_finite())
        .map(|(i, ((lp, t), &rx))| {
            let noise = 2.0 * kodama_nodes::rng::gaussian(kodama_nodes::rng::mix(i as u64 ^ 0x5C));
            let o = Observation {
                model: LinkModel::new(&setup, tx, rx, lp),
                cell: 0,
                group: 0,
                loss_db: -t.gain_db + noise,
            };
            (o, t.gain_db)
        })
        .unzip();
    // The replay at the truth's S gives the truth's gains (before the noise).
    let at_truth = state.scaled(&[(Parameter::Scattering, 2.0)]);
    let mut worst = 0.0f64;
    for (o, t) in obs.iter().zip(&truths) {
        let got = o.model.gain_db(&at_truth, &[], Mount::default()).0;
        worst = worst.max((got - t).abs());
    }
    // Derivative in ln S against central differences, at S 0.3.
    let at = state.scaled(&[(Parameter::Scattering, 1.2)]);
    let h: f64 = 1e-5;
    for o in obs.iter().step_by(7) {
        let (_, dg) = o
            .model
            .gain_db(&at, &[Parameter::Scattering], Mount::default());
        let g = |k: f64| {
            let s = at.scaled(&[(Parameter::Scattering, k)]);
            o.model.gain_db(&s, &[], Mount::default()).0
        };
        let fd = (g(h.exp()) - g((-h).exp())) / (2.0 * h);
        assert!(
            (dg[0] - fd).abs() <= 1e-5 * (1.0 + fd.abs()),
            "{} vs {fd}",
            dg[0]
        );
    }
    let states = [state];
    let priors = [Prior::for_scattering(0.25)];
    let fitted = fit(&obs, 1, &states, &priors, 2.0);
    let k = fitted.values[0].1;
    println!(
        "{} links: replay at the truth's S within {worst:.1e} dB of its trace; S factor {k:.3} \
         (truth 2, posterior sd of ln k {:.3}); RMSE {:.2} -> {:.2} dB",
        obs.len(),
        fitted.spread[0],
        fitted.rmse_db.0,
        fitted.rmse_db.1
    );
    assert!(worst < 1e-9, "replay at the truth's S off by {worst} dB");
    assert!((k / 2.0 - 1.0).abs() < 0.1, "S factor {k}");
}
