//! The tracer against closed forms (rf.md): free space, the two-ray ground reflection, a wall's
//! slab transmission loss.

use glam::DVec3;
use num_complex::Complex64 as C64;

use kodama_nodes::artifact::{Mesh, ObjectClass, PodVec, Scene, SceneObject};
use kodama_nodes::rf::materials::Material;
use kodama_nodes::rf::antenna::{Antenna, Pattern, Polarization};
use kodama_nodes::rf::em::{fspl_db, permittivity, slab};
use kodama_nodes::rf::paths::{InteractionKind, TraceOptions, trace_links};
use kodama_nodes::rf::scene::RfScene;
use kodama_nodes::rf::wavelength;

const F: f64 = 3.5e9;

fn quad(id: &str, corners: [[f32; 3]; 4], m: Material) -> SceneObject {
    SceneObject {
        id: id.into(),
        class: ObjectClass::Unsegmented,
        mesh: Mesh {
            positions: PodVec(corners.to_vec()),
            triangles: PodVec(vec![[0, 1, 2], [0, 2, 3]]),
            materials: PodVec(vec![m as u8; 2]),
        },
    }
}

fn options(max_depth: u32) -> TraceOptions {
    TraceOptions {
        max_depth,
        rays: 20_000,
        ..Default::default()
    }
}

fn horizontal() -> Antenna {
    Antenna {
        pattern: Pattern::Isotropic,
        polarization: Polarization::H,
        ..Default::default()
    }
}

#[test]
fn free_space_is_friis_exactly() {
    let scene = RfScene::new(&Scene::default(), F, false).unwrap();
    let links = [([0.0, 0.0, 10.0], [300.0, 40.0, 1.5])];
    let r = &trace_links(
        &scene,
        &links,
        &Antenna::default(),
        &Antenna::default(),
        &options(3),
        F,
    )[0];
    let d = (DVec3::from(links[0].0) - DVec3::from(links[0].1)).length();
    assert_eq!(r.paths.len(), 1);
    // Vertical polarisation on both ends, tilted link: the θ̂ vectors at both ends are parallel.
    assert!(
        (r.gain_db + fspl_db(d, F)).abs() < 1e-9,
        "{} vs {}",
        r.gain_db,
        -fspl_db(d, F)
    );
}

#[test]
fn two_ray_ground_reflection_matches_the_closed_form() {
    // A 2 km metal ground plane; horizontal polarisation across the plane of incidence is pure TE.
    let g = 1000.0;
    let ground = quad(
        "ground",
        [[-g, -g, 0.0], [g, -g, 0.0], [g, g, 0.0], [-g, g, 0.0]],
        Material::MediumDryGround,
    );
    let scene_in = Scene {
        objects: vec![ground],
    };
    let scene = RfScene::new(&scene_in, F, false).unwrap();
    let eta = permittivity(Material::MediumDryGround, F, false).unwrap();
    let k = 2.0 * std::f64::consts::PI / wavelength(F);
    for (ht, hr, dist) in [(30.0, 1.5, 50.0), (30.0, 1.5, 400.0), (10.0, 2.0, 150.0)] {
        let links = [([0.0, 0.0, ht], [dist, 0.0, hr])];
        let r = &trace_links(&scene, &links, &horizontal(), &horizontal(), &options(1), F)[0];
        assert_eq!(r.paths.len(), 2, "{:?}", r.paths);
        assert_eq!(r.paths[1].interactions[0].kind, InteractionKind::Reflection);
        let d1 = (dist * dist + (ht - hr) * (ht - hr)).sqrt();
        let d2 = (dist * dist + (ht + hr) * (ht + hr)).sqrt();
        let cos_theta = (ht + hr) / d2;
        let ((r_te, _), _) = slab(cos_theta, eta, 0.1, wavelength(F));
        let amp = wavelength(F) / (4.0 * std::f64::consts::PI);
        let total =
            amp * (C64::from_polar(1.0, -k * d1) / d1 + r_te * C64::from_polar(1.0, -k * d2) / d2);
        let expected = 10.0 * total.norm_sqr().log10();
        assert!(
            (r.coherent_gain_db - expected).abs() < 1e-6,
            "ht {ht} hr {hr} d {dist}: traced {} dB, two-ray {expected} dB",
            r.coherent_gain_db
        );
        let incoherent =
            10.0 * (amp * amp * (1.0 / (d1 * d1) + r_te.norm_sqr() / (d2 * d2))).log10();
        assert!((r.gain_db - incoherent).abs() < 1e-6);
    }
}

#[test]
fn a_concrete_wall_costs_its_slab_transmission_loss() {
    // A 0.1 m concrete slab (one surface, as Sionna models walls) across the link at normal
    // incidence: rf.md §8 gives |T| = -10.36 dB at 3.5 GHz.
    let wall = quad(
        "wall",
        [
            [50.0, -20.0, -20.0],
            [50.0, 20.0, -20.0],
            [50.0, 20.0, 20.0],
            [50.0, -20.0, 20.0],
        ],
        Material::Concrete,
    );
    let scene = RfScene::new(
        &Scene {
            objects: vec![wall],
        },
        F,
        false,
    )
    .unwrap();
    let links = [([0.0, 0.0, 0.0], [100.0, 0.0, 0.0])];
    let r = &trace_links(
        &scene,
        &links,
        &Antenna::default(),
        &Antenna::default(),
        &options(1),
        F,
    )[0];
    assert_eq!(r.paths.len(), 1);
    assert_eq!(
        r.paths[0].interactions[0].kind,
        InteractionKind::Transmission
    );
    assert!(
        (r.gain_db - (-fspl_db(100.0, F) - 10.36)).abs() < 0.01,
        "{}",
        r.gain_db
    );
    // Without transmission the wall blocks the only path.
    let blocked = TraceOptions {
        transmission: false,
        ..options(1)
    };
    let r = &trace_links(
        &scene,
        &links,
        &Antenna::default(),
        &Antenna::default(),
        &blocked,
        F,
    )[0];
    assert!(r.paths.is_empty());
    assert_eq!(r.gain_db, f64::NEG_INFINITY);
}

/// A sharp metal wedge (a vertical blade, 2.3° interior angle, so n ≈ 2: nearly a half-plane)
/// between the ends: the first-order UTD path round its edge against the Fresnel-Kirchhoff knife
/// edge (the exact half-plane solution in the scalar approximation, rf.md §3.2), across the
/// shadow. Vertical polarisation runs along the edge (soft).
#[test]
fn diffraction_round_a_blade_matches_the_knife_edge() {
    use kodama_nodes::artifact::Polygon;
    use kodama_nodes::geom::mesh_build::prism;
    use kodama_nodes::rf::utd::{fresnel_kirchhoff_db, knife_edge_v};
    let blade = Polygon::normalized(vec![[0.0, 0.0], [-20.0, -0.4], [-20.0, 0.4]], vec![]).unwrap();
    let mesh = prism(&blade, -400.0, 400.0, Material::Metal, Material::Metal).unwrap();
    let scene = Scene {
        objects: vec![SceneObject {
            id: "blade".into(),
            class: ObjectClass::Unsegmented,
            mesh,
        }],
    };
    let rf = RfScene::new(&scene, F, false).unwrap();
    let opt = TraceOptions {
        max_depth: 1,
        los: true,
        reflection: false,
        transmission: false,
        diffraction: true,
        rays: 1000,
        foliage_db_per_m: None,
        ..Default::default()
    };
    let lambda = wavelength(F);
    for h in [1.0, 2.0, 5.0] {
        // The ends sit h metres behind the tip's line, 60 m and 40 m from it.
        let (tx, rx) = ([-h, -60.0, 0.0], [-h, 40.0, 0.0]);
        let r = &trace_links(
            &rf,
            &[(tx, rx)],
            &Antenna::default(),
            &Antenna::default(),
            &opt,
            F,
        )[0];
        assert_eq!(r.paths.len(), 1, "h {h}: {:?}", r.paths);
        assert_eq!(
            r.paths[0].interactions[0].kind,
            InteractionKind::Diffraction
        );
        let (d1, d2) = ((h * h + 3600.0f64).sqrt(), (h * h + 1600.0f64).sqrt());
        let v = knife_edge_v(h, 60.0, 40.0, lambda);
        let expected = -fspl_db(d1 + d2, F) - fresnel_kirchhoff_db(v);
        println!(
            "blade, h {h} m (v {v:.2}): UTD {:.2} dB, knife edge {expected:.2} dB",
            r.gain_db
        );
        assert!(
            (r.gain_db - expected).abs() < 1.0,
            "h {h} (v {v:.2}): UTD {:.2} dB, knife edge {expected:.2} dB",
            r.gain_db
        );
    }
}

/// Diffuse scattering off a ground plane (S = 1, Lambertian) against the surface integral it
/// estimates, done here by quadrature: P = (λ/4π)² ∫ |R_TM|² (cos θ_s / π) cos θ_i / (r_i² r_s²) dA
/// (a vertically polarised wave meets horizontal ground as TM).
#[test]
fn diffuse_ground_scattering_matches_its_surface_integral() {
    use kodama_nodes::rf::scattering::ScatteringPattern;
    let g = 2000.0;
    let ground = quad(
        "ground",
        [[-g, -g, 0.0], [g, -g, 0.0], [g, g, 0.0], [-g, g, 0.0]],
        Material::MediumDryGround,
    );
    let scene = RfScene::new(
        &Scene {
            objects: vec![ground],
        },
        F,
        false,
    )
    .unwrap();
    let (tx, rx) = ([0.0, 0.0, 20.0], [60.0, 0.0, 5.0]);
    let opt = TraceOptions {
        max_depth: 1,
        los: false,
        reflection: true,
        transmission: false,
        diffuse: true,
        scattering_coefficient: 1.0,
        scattering_pattern: ScatteringPattern::Lambertian,
        rays: 1_000_000,
        ..Default::default()
    };
    let r = &trace_links(
        &scene,
        &[(tx, rx)],
        &Antenna::default(),
        &Antenna::default(),
        &opt,
        F,
    )[0];
    assert!(r.paths.is_empty(), "S = 1 leaves no specular path");
    let eta = permittivity(Material::MediumDryGround, F, false).unwrap();
    let lam = wavelength(F);
    let step = 0.5;
    let mut sum = 0.0;
    let (mut x, x1): (f64, f64) = (-400.0 + step / 2.0, 460.0);
    while x < x1 {
        let mut y: f64 = -400.0 + step / 2.0;
        while y < 400.0 {
            let ri2 = x * x + y * y + 400.0;
            let rs2 = (x - 60.0) * (x - 60.0) + y * y + 25.0;
            let (cos_i, cos_s) = (20.0 / ri2.sqrt(), 5.0 / rs2.sqrt());
            let ((_, r_tm), _) = slab(cos_i, eta, 0.1, lam);
            sum +=
                r_tm.norm_sqr() * cos_s / std::f64::consts::PI * cos_i / (ri2 * rs2) * step * step;
            y += step;
        }
        x += step;
    }
    let expected = 10.0 * ((lam / (4.0 * std::f64::consts::PI)).powi(2) * sum).log10();
    println!(
        "diffuse ground: traced {:.3} dB, quadrature {expected:.3} dB",
        r.diffuse_gain_db
    );
    assert!(
        (r.diffuse_gain_db - expected).abs() < 0.2,
        "{} vs {expected}",
        r.diffuse_gain_db
    );
    assert!((r.gain_db - r.diffuse_gain_db).abs() < 1e-9);
}
