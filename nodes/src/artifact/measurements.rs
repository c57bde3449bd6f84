//! Radio measurements (drive tests): one link per row, in the site frame.

use serde::{Deserialize, Serialize};

use super::Raster;

/// The height of an endpoint: absolute in the site frame, or above the local ground (resolved
/// against the terrain by the stage that needs it).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Height {
    /// Site-frame z, metres.
    Absolute(f64),
    /// Metres above the terrain at (x, y).
    AboveGround(f64),
}

/// A transmitter or receiver.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Endpoint {
    /// Identifier (a cell or transmitter id; for receivers, may be empty).
    pub id: String,
    /// Site-frame x, metres.
    pub x: f64,
    /// Site-frame y, metres.
    pub y: f64,
    /// Height.
    pub z: Height,
    /// Antenna azimuth, when known: a grid bearing, degrees clockwise from grid north (the site
    /// frame's +y), not from true north (`ReadMeasurements` subtracts the meridian convergence
    /// from the true bearings it reads). The same convention as `Antenna::azimuth_deg`.
    pub azimuth_deg: Option<f64>,
}

impl Endpoint {
    /// Site-frame z, given the ground height under the endpoint (needed only when its height is
    /// above ground; `None` then if the ground is unknown).
    pub fn absolute_z(&self, ground: Option<f64>) -> Option<f64> {
        match self.z {
            Height::Absolute(z) => Some(z),
            Height::AboveGround(h) => ground.map(|g| g + h),
        }
    }

    /// Height above the ground, given the ground height under the endpoint (needed only when its
    /// height is absolute).
    pub fn above_ground(&self, ground: Option<f64>) -> Option<f64> {
        match self.z {
            Height::AboveGround(h) => Some(h),
            Height::Absolute(z) => ground.map(|g| z - g),
        }
    }
}

/// One measured link.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Link {
    /// Transmitter.
    pub tx: Endpoint,
    /// Receiver.
    pub rx: Endpoint,
    /// Carrier frequency, Hz.
    pub freq_hz: f64,
    /// Measured path loss, dB, when known.
    pub path_loss_db: Option<f64>,
    /// Measured received power, dBm, when that is what was measured.
    pub rx_power_dbm: Option<f64>,
    /// Transmit EIRP, dBm, when known (unknown EIRP: metrics fit one offset per transmitter).
    pub tx_eirp_dbm: Option<f64>,
    /// Line of sight, when known.
    pub los: Option<bool>,
}

/// A drive test or any set of measured links.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Measurements {
    /// The links, in file order.
    pub links: Vec<Link>,
}

/// The 3-D distance between a link's ends (at least 1 m); heights above ground stand on
/// `terrain`, or on z = 0 without one.
pub fn link_distance(l: &Link, terrain: Option<&Raster>) -> f64 {
    let z = |e: &crate::artifact::Endpoint| {
        let ground = terrain.and_then(|t| t.bilinear(e.x, e.y)).unwrap_or(0.0);
        e.absolute_z(Some(ground))
            .expect("a ground height is given")
    };
    ((l.tx.x - l.rx.x).powi(2) + (l.tx.y - l.rx.y).powi(2) + (z(&l.tx) - z(&l.rx)).powi(2))
        .sqrt()
        .max(1.0)
}

/// The measured path loss of a link: given, or EIRP − received power, or −received power (an
/// offset per transmitter is then fitted).
pub fn measured_loss(l: &Link) -> Option<f64> {
    l.path_loss_db
        .or_else(|| Some(l.tx_eirp_dbm.unwrap_or(0.0) - l.rx_power_dbm?))
        .filter(|v| v.is_finite())
}
