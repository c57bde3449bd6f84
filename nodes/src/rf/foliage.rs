//! Foliage as volumes: closed meshes of `Material::Foliage` that a wave crosses, losing a fixed
//! number of dB per metre inside (ITU-R P.833). Here: how deep a point is in foliage
//! ([`FoliageDepth`]), the length of a segment inside the union of the volumes
//! ([`foliage_length`], the one place that length is measured), the loss it costs, and the
//! default specific attenuation (ITU-R P.833).

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::scene::{EPS, RfScene, SurfaceHit};

/// Digitised points of ITU-R P.833 Figure 2 (woodland, vertical polarisation): frequency in Hz,
/// specific attenuation in dB/m.
pub const P833_FIGURE_2: [(f64, f64); 3] = [(30e6, 0.02), (1e9, 0.2), (30e9, 6.0)];

/// The default specific attenuation of foliage at `freq_hz` (> 0), dB/m: ITU-R P.833 Figure 2
/// (woodland), interpolated log-log through its digitised points (0.02 dB/m at 30 MHz, 0.2 at
/// 1 GHz, 6 at 30 GHz). Below 30 MHz the lowest segment's power law goes on (towards 0); above
/// 30 GHz the value is held at 6 dB/m, the figure being read no further.
pub fn specific_attenuation_db_per_m(freq_hz: f64) -> f64 {
    let [low, mid, high] = P833_FIGURE_2;
    if freq_hz >= high.0 {
        return high.1;
    }
    let ((f0, g0), (f1, g1)) = if freq_hz < mid.0 {
        (low, mid)
    } else {
        (mid, high)
    };
    let slope = (g1 / g0).ln() / (f1 / f0).ln();
    g0 * (freq_hz / f0).powf(slope)
}

/// The amplitude factor of `length_m` metres of foliage at `db_per_m`: 10^(−γ d / 20).
pub fn loss_amplitude(db_per_m: f64, length_m: f64) -> f64 {
    10f64.powf(-db_per_m * length_m / 20.0)
}

/// How the loss grows with the depth of foliage a path runs through.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub enum FoliageLaw {
    /// γ d: the same loss for every metre, the cumulative loss the paper writes (Sec. 4.2.4).
    #[default]
    Linear,
    /// ITU-R P.833 (§2.1, one terminal in woodland): A_m (1 − exp(−γ d / A_m)), the loss of the
    /// first metres γ each, saturating at A_m, with A_m = A1 f^α (f in MHz) from the
    /// recommendation's Mulhouse campaign, A1 = 1.15, α = 0.43 ([`p833_max_attenuation_db`]).
    P833,
    /// P.833's law with this maximum A_m, dB (> 0).
    P833Max(f64),
}

impl FoliageLaw {
    /// The first setting out of its range, as a message.
    pub fn check(self) -> Result<(), &'static str> {
        match self {
            FoliageLaw::P833Max(m) if !(m > 0.0 && m.is_finite()) => {
                Err("expected P833Max with a positive, finite maximum in dB")
            }
            _ => Ok(()),
        }
    }

    /// The law at `freq_hz` with specific attenuation `db_per_m`.
    pub fn at(self, freq_hz: f64, db_per_m: f64) -> FoliageLoss {
        FoliageLoss {
            db_per_m,
            max_db: match self {
                FoliageLaw::Linear => None,
                FoliageLaw::P833 => Some(p833_max_attenuation_db(freq_hz)),
                FoliageLaw::P833Max(m) => Some(m),
            },
        }
    }
}

/// Whether `law` is the default linear law (for params that leave their default out of their
/// encoding).
pub fn is_linear(law: &FoliageLaw) -> bool {
    *law == FoliageLaw::Linear
}

/// ITU-R P.833's maximum attenuation of one terminal in woodland, A_m = A1 f^α dB (f in MHz),
/// with the Mulhouse campaign's A1 = 1.15, α = 0.43: 21.9 dB at 949 MHz, 29.2 dB at 1.85 GHz,
/// 38.4 dB at 3.5 GHz (the recommendation's table, from other campaigns, gives 26.5, 29.0, -).
pub fn p833_max_attenuation_db(freq_hz: f64) -> f64 {
    1.15 * (freq_hz / 1e6).powf(0.43)
}

/// The foliage loss one trace applies: γ dB/m, saturating at `max_db` when set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FoliageLoss {
    /// γ, dB per metre.
    pub db_per_m: f64,
    /// P.833's A_m, dB; `None`: the linear law.
    pub max_db: Option<f64>,
}

impl FoliageLoss {
    /// The loss of `length_m` metres of foliage, dB: γ d, or P.833's A_m (1 − exp(−γ d / A_m)).
    pub fn loss_db(&self, length_m: f64) -> f64 {
        let linear = self.db_per_m * length_m;
        match self.max_db {
            None => linear,
            Some(m) => m * -(-linear / m).exp_m1(),
        }
    }

    /// The amplitude factor of a path's `length_m` metres of foliage in all.
    pub fn amplitude(&self, length_m: f64) -> f64 {
        match self.max_db {
            None => loss_amplitude(self.db_per_m, length_m),
            Some(_) => 10f64.powf(-self.loss_db(length_m) / 20.0),
        }
    }

    /// The amplitude factor of `length_m` more metres for a ray that has run `before_m` metres in
    /// foliage already: what the segment adds to the path's loss.
    pub fn step_amplitude(&self, before_m: f64, length_m: f64) -> f64 {
        match self.max_db {
            None => loss_amplitude(self.db_per_m, length_m),
            Some(_) => {
                let added = self.loss_db(before_m + length_m) - self.loss_db(before_m);
                10f64.powf(-added / 20.0)
            }
        }
    }
}

/// How many foliage volumes a point moving along a ray is inside: each crossing of a foliage
/// triangle against its outward normal enters one (+1), along it leaves one (−1). The point is
/// in foliage while the depth is positive, so overlapping volumes count once.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FoliageDepth(u32);

impl FoliageDepth {
    /// The depth at `p`: the crossings of a ray from `p` out of the scene, each exit one volume
    /// `p` is inside, each entry one it is not (0 for a scene without foliage).
    pub fn at(scene: &RfScene, p: DVec3) -> FoliageDepth {
        if !scene.has_foliage() {
            return FoliageDepth(0);
        }
        // Upwards, where little stands, and off the axes so as not to run along mesh edges.
        let d = DVec3::new(0.1234, 0.0567, 1.0).normalize();
        let (mut net, mut tmin) = (0i64, EPS);
        for _ in 0..10_000 {
            let Some(h) = scene.cast(p, d, tmin, f64::INFINITY) else {
                break;
            };
            net -= step(scene, h.triangle, d).unwrap_or(0);
            tmin = h.t.max(tmin) + EPS;
        }
        FoliageDepth(net.max(0) as u32)
    }

    /// How many canopies the point is inside.
    pub fn canopies(self) -> u32 {
        self.0
    }

    /// Whether the point is in foliage.
    pub fn inside(self) -> bool {
        self.0 > 0
    }

    /// Counts a crossing of triangle `tri` in direction `d`; false (and no change) when `tri` is
    /// no foliage boundary. Never below zero: a leave without an entry means the ray started in
    /// a volume it did not know of.
    pub fn cross(&mut self, scene: &RfScene, tri: u32, d: DVec3) -> bool {
        let Some(s) = step(scene, tri, d) else {
            return false;
        };
        self.add(s);
        true
    }

    fn add(&mut self, s: i64) {
        self.0 = (self.0 as i64 + s).max(0) as u32;
    }
}

/// +1 where `d` enters the foliage volume `tri` bounds, −1 where it leaves; `None` for other
/// surfaces.
fn step(scene: &RfScene, tri: u32, d: DVec3) -> Option<i64> {
    scene.is_foliage(tri).then(|| {
        if d.dot(scene.normals[tri as usize]) < 0.0 {
            1
        } else {
            -1
        }
    })
}

/// The length of the segment `a -> b` inside the union of the foliage volumes (depth > 0), and
/// the depth at `b`, from the depth at `a` and `hits`, the surfaces crossed between them in order
/// ([`RfScene::hits_between`]; non-foliage ones are skipped). Where the crossings leave more
/// volumes than `at_a` holds, `a` was inside those too.
pub fn foliage_length(
    scene: &RfScene,
    a: DVec3,
    b: DVec3,
    hits: &[SurfaceHit],
    at_a: FoliageDepth,
) -> (f64, FoliageDepth) {
    let len = (b - a).length();
    let d = (b - a) / len;
    let steps: Vec<(f64, i64)> = hits
        .iter()
        .filter_map(|h| step(scene, h.triangle, d).map(|s| (h.t, s)))
        .collect();
    let (mut sum, mut unmatched) = (0i64, 0i64);
    for &(_, s) in &steps {
        sum += s;
        unmatched = unmatched.max(-sum);
    }
    let mut depth = FoliageDepth(at_a.0.max(unmatched as u32));
    let (mut inside, mut from) = (0.0, 0.0);
    for (t, s) in steps {
        if depth.inside() {
            inside += t - from;
        }
        depth.add(s);
        from = t;
    }
    if depth.inside() {
        inside += len - from;
    }
    (inside, depth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::{Scene, SceneObject};
    use crate::geom::mesh_build::cuboid;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9 * b.abs().max(1.0)
    }

    /// P.833's one-terminal law at the recommendation's table values (γ, A_m): the worked
    /// values of shared/reference/compute_checks.out, to the hundredth of a dB they are given to.
    #[test]
    fn the_p833_law_gives_the_recommendations_worked_values() {
        for (gamma, am, want) in [
            (0.04, 9.4, [0.39, 1.80, 5.39]),
            (0.12, 18.0, [1.16, 5.10, 13.26]),
            (0.17, 26.5, [1.65, 7.27, 19.15]),
            (0.30, 29.0, [2.85, 11.71, 25.34]),
            (0.34, 34.1, [3.24, 13.39, 29.46]),
        ] {
            let law = FoliageLaw::P833Max(am).at(1e9, gamma);
            for (d, w) in [10.0, 50.0, 200.0].into_iter().zip(want) {
                let got = law.loss_db(d);
                assert!(
                    (got - w).abs() <= 0.005,
                    "γ {gamma} A_m {am} d {d}: {got} vs {w}"
                );
            }
            // Saturation: never past A_m, and the first metre costs γ.
            assert!(law.loss_db(1e6) <= am && law.loss_db(1e6) > am - 1e-9);
            assert!((law.loss_db(1e-3) / 1e-3 - gamma).abs() < 1e-4);
        }
        // A_m = 1.15 f^0.43 at the table's frequencies, against the table's own A_m: the law
        // and the table come from different campaigns (4.6 dB apart at most over 0.9-2.1 GHz).
        for (f_mhz, am) in [(949.0, 26.5), (1852.2, 29.0), (2117.5, 34.1)] {
            let m = p833_max_attenuation_db(f_mhz * 1e6);
            assert!((m - am).abs() < 4.7, "{f_mhz} MHz: {m} vs {am}");
        }
        assert!((p833_max_attenuation_db(3.5e9) - 38.4).abs() < 0.05);
    }

    /// Segment by segment, a ray's steps multiply to the loss of the whole length, for either
    /// law; the linear law's step is the old per-metre factor to the bit.
    #[test]
    fn steps_add_up_to_the_whole_path() {
        for law in [
            FoliageLaw::Linear,
            FoliageLaw::P833,
            FoliageLaw::P833Max(12.0),
        ] {
            let l = law.at(28e9, specific_attenuation_db_per_m(28e9));
            let segments = [0.7, 3.0, 0.25, 6.0];
            let (mut before, mut amp) = (0.0, 1.0);
            for s in segments {
                amp *= l.step_amplitude(before, s);
                before += s;
            }
            let whole = l.amplitude(segments.iter().sum());
            assert!((amp / whole - 1.0).abs() < 1e-12, "{law:?}");
        }
        let l = FoliageLaw::Linear.at(3.5e9, 0.7);
        assert_eq!(l.step_amplitude(5.0, 2.0), loss_amplitude(0.7, 2.0));
        // 10 m of crown at 28 GHz (5.6 dB/m): 56 dB linear, 42.2 dB by P.833's law (A_m 93.9).
        let p = FoliageLaw::P833.at(28e9, specific_attenuation_db_per_m(28e9));
        assert!((p.loss_db(10.0) - 42.2).abs() < 0.05, "{}", p.loss_db(10.0));
        assert!(FoliageLaw::P833Max(f64::NAN).check().is_err());
        assert!(FoliageLaw::P833Max(0.0).check().is_err());
    }

    #[test]
    fn specific_attenuation_passes_through_p833_figure_2() {
        assert!(close(specific_attenuation_db_per_m(30e6), 0.02));
        assert!(close(specific_attenuation_db_per_m(1e9), 0.2));
        assert!(close(specific_attenuation_db_per_m(30e9), 6.0));
        // Log-log midway between 30 MHz and 1 GHz: the geometric mean of the two values.
        let f = (30e6f64 * 1e9).sqrt();
        assert!(close(
            specific_attenuation_db_per_m(f),
            (0.02f64 * 0.2).sqrt()
        ));
        // 1 to 30 GHz is proportional to f: 0.7 dB/m at 3.5 GHz.
        assert!(close(specific_attenuation_db_per_m(3.5e9), 0.7));
        // Held above the figure; lower still below it.
        assert_eq!(specific_attenuation_db_per_m(100e9), 6.0);
        let low = specific_attenuation_db_per_m(10e6);
        assert!(low > 0.0 && low < 0.02, "{low}");
    }

    /// Two 10 m boxes overlapping by 4 m along x (x in [-5, 5] and [1, 11], tops at z = 5 and
    /// z = 6): 16 m of foliage along x, not 20.
    fn two_boxes() -> RfScene {
        let object = |id: &str, x: f64, z0: f64| SceneObject {
            id: id.into(),
            class: crate::artifact::ObjectClass::Vegetation,
            mesh: cuboid([x, 0.0], [10.0, 10.0, 10.0], 0.0, z0, Material::Foliage),
        };
        let scene = Scene {
            objects: vec![object("a", 0.0, -5.0), object("b", 6.0, -4.0)],
        };
        RfScene::new(&scene, 3.5e9, false).unwrap()
    }

    /// Along x: foliage, a wall, foliage, two walls (boxes 2 m deep, 4 m apart), each entered
    /// and left. Stopping past `walls` non-foliage surfaces gives the full list up to the next
    /// non-foliage surface, foliage not counted; the full list when there is none.
    #[test]
    fn hits_stop_at_the_first_wall_past_the_count() {
        let object = |id: &str, x: f64, m: Material| SceneObject {
            id: id.into(),
            class: crate::artifact::ObjectClass::Building,
            mesh: cuboid([x, 0.0], [2.0, 10.0, 10.0], 0.0, -5.0, m),
        };
        let scene = Scene {
            objects: vec![
                object("leaves", 0.0, Material::Foliage),
                object("one", 6.0, Material::Concrete),
                object("more leaves", 12.0, Material::Foliage),
                object("two", 18.0, Material::Concrete),
                object("three", 24.0, Material::Brick),
            ],
        };
        let rf = RfScene::new(&scene, 3.5e9, false).unwrap();
        let (a, b) = (DVec3::new(-10.0, 0.3, 0.2), DVec3::new(40.0, 0.3, 0.2));
        let all = rf.hits_between(a, b, EPS);
        assert_eq!(all.len(), 10);
        // Each box is entered and left: surfaces 0-1 foliage, 2-3 wall one, 4-5 foliage, ...
        for (walls, ends_at) in [(0, 3), (1, 4), (2, 7), (3, 8), (5, 10), (6, 10), (9, 10)] {
            let some = rf.hits_between_until(a, b, EPS, walls);
            assert_eq!(some.len(), ends_at, "{walls} walls");
            let same = |x: &SurfaceHit, y: &SurfaceHit| (x.t, x.triangle) == (y.t, y.triangle);
            assert!(
                some.iter().zip(&all).all(|(x, y)| same(x, y)),
                "{walls} walls"
            );
        }
    }

    #[test]
    fn overlapping_volumes_count_once() {
        let rf = two_boxes();
        let (a, b) = (DVec3::new(-20.0, 0.3, 0.2), DVec3::new(30.0, 0.3, 0.2));
        let hits = rf.hits_between(a, b, EPS);
        assert_eq!(hits.len(), 4);
        let (m, end) = foliage_length(&rf, a, b, &hits, FoliageDepth::default());
        assert!((m - 16.0).abs() < 1e-6, "{m}");
        assert!(!end.inside());
        // From inside both boxes (x = 3): to x = 11 is 8 m, wherever the depth is known.
        let a = DVec3::new(3.0, 0.3, 0.2);
        assert_eq!(FoliageDepth::at(&rf, a), FoliageDepth(2));
        let hits = rf.hits_between(a, b, EPS);
        for start in [FoliageDepth::default(), FoliageDepth::at(&rf, a)] {
            let (m, _) = foliage_length(&rf, a, b, &hits, start);
            assert!((m - 8.0).abs() < 1e-6, "{m}");
        }
        // Ending inside both: from x = -20 to x = 2 is 7 m.
        let b = DVec3::new(2.0, 0.3, 0.2);
        let hits = rf.hits_between(DVec3::new(-20.0, 0.3, 0.2), b, EPS);
        let (m, end) = foliage_length(&rf, DVec3::new(-20.0, 0.3, 0.2), b, &hits, FoliageDepth(0));
        assert!(
            (m - 7.0).abs() < 1e-6 && end == FoliageDepth(2),
            "{m} {end:?}"
        );
    }
}
