//! The second moments of a set of points in the plane: their centre, spread and main axis.

/// Points' centroid and second moments about it (sums of dx², dy², dx dy).
pub(super) struct Spread {
    pub(super) centre: [f64; 2],
    pub(super) sxx: f64,
    pub(super) syy: f64,
    pub(super) sxy: f64,
}

impl Spread {
    pub(super) fn of(points: impl Iterator<Item = [f64; 2]> + Clone) -> Spread {
        let n = points.clone().count() as f64;
        let centre = [
            points.clone().map(|p| p[0]).sum::<f64>() / n,
            points.clone().map(|p| p[1]).sum::<f64>() / n,
        ];
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for p in points {
            let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
            sxx += dx * dx;
            syy += dy * dy;
            sxy += dx * dy;
        }
        Spread {
            centre,
            sxx,
            syy,
            sxy,
        }
    }

    /// Direction of the principal axis, radians.
    pub(super) fn axis_angle(&self) -> f64 {
        0.5 * (2.0 * self.sxy).atan2(self.sxx - self.syy)
    }
}
