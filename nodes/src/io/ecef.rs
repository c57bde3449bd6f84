//! WGS84 geodetic <-> Earth-centred, Earth-fixed (EPSG:4978) coordinates, and local east-north-up
//! frames: what OGC 3D Tiles place their content in.
//!
//! # References
//! NIMA TR8350.2 (WGS84: a = 6378137 m, 1/f = 298.257223563); the inverse uses Bowring's
//! iteration, which converges to sub-millimetre in three steps for terrestrial heights.

const A: f64 = 6_378_137.0;
const F: f64 = 1.0 / 298.257_223_563;
const E2: f64 = F * (2.0 - F);

/// ECEF (x, y, z) of longitude, latitude (degrees) and ellipsoidal height (metres).
pub fn to_ecef(lon_deg: f64, lat_deg: f64, h: f64) -> [f64; 3] {
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    let n = A / (1.0 - E2 * lat.sin().powi(2)).sqrt();
    [
        (n + h) * lat.cos() * lon.cos(),
        (n + h) * lat.cos() * lon.sin(),
        (n * (1.0 - E2) + h) * lat.sin(),
    ]
}

/// Longitude, latitude (degrees) and ellipsoidal height of an ECEF point.
pub fn from_ecef(p: [f64; 3]) -> (f64, f64, f64) {
    let lon = p[1].atan2(p[0]);
    let r = p[0].hypot(p[1]);
    let mut lat = p[2].atan2(r * (1.0 - E2));
    let mut h = 0.0;
    for _ in 0..5 {
        let n = A / (1.0 - E2 * lat.sin().powi(2)).sqrt();
        h = r / lat.cos() - n;
        lat = p[2].atan2(r * (1.0 - E2 * n / (n + h)));
    }
    (lon.to_degrees(), lat.to_degrees(), h)
}

/// The east, north and up unit vectors at a geodetic position, in ECEF.
pub fn enu_axes(lon_deg: f64, lat_deg: f64) -> [[f64; 3]; 3] {
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    [
        [-lon.sin(), lon.cos(), 0.0],
        [-lat.sin() * lon.cos(), -lat.sin() * lon.sin(), lat.cos()],
        [lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_points_and_round_trip() {
        let p = to_ecef(0.0, 0.0, 0.0);
        assert!((p[0] - A).abs() < 1e-6 && p[1].abs() < 1e-6 && p[2].abs() < 1e-6);
        // The pole: semi-minor axis b = a (1 - f) = 6356752.3142 m.
        assert!((to_ecef(0.0, 90.0, 0.0)[2] - 6_356_752.314_245).abs() < 1e-5);
        for (lon, lat, h) in [
            (-74.0, 40.7, 35.0),
            (4.37, 52.0, -2.0),
            (139.7, -35.6, 3000.0),
        ] {
            let (lo, la, hh) = from_ecef(to_ecef(lon, lat, h));
            assert!(
                (lo - lon).abs() < 1e-10 && (la - lat).abs() < 1e-10 && (hh - h).abs() < 1e-4,
                "{lo} {la} {hh}"
            );
        }
    }
}
