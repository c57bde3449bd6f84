//! The track the views were taken along: the streets the cameras drove, as lines fitted to
//! their positions near a point.

use crate::artifact::ViewHead;

use super::spread::Spread;

/// Where the cameras drove: street-view cars drive on roads, so the camera positions trace the
/// road axes.
pub struct Track {
    positions: Vec<[f64; 2]>,
}

impl Track {
    /// The views' positions.
    pub fn new(views: &[ViewHead]) -> Track {
        Track {
            positions: views
                .iter()
                .map(|v| [v.pose.position[0], v.pose.position[1]])
                .collect(),
        }
    }

    /// The road at `p`: of the streets the cameras drove within 30 m of it ([`Track::roads`]),
    /// the one whose axis passes nearest, as (unit axis, `p`'s distance from that axis).
    pub fn road(&self, p: [f64; 2]) -> Option<([f64; 2], f64)> {
        self.roads(p).into_iter().min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The streets the cameras drove within 30 m of `p`: lines through the camera positions
    /// there, each holding at least three of them (within `ROAD_TOL_M` of it) spread over 5 m
    /// along it, found strongest first, each with `p`'s distance from it. At a crossing the
    /// positions of both streets are in reach, and one axis fitted to them all runs
    /// diagonally between the two (a lamp post on a corner's pavement read as standing in the
    /// carriageway): each street is a line of its own.
    pub fn roads(&self, p: [f64; 2]) -> Vec<([f64; 2], f64)> {
        let mut near: Vec<[f64; 2]> = self
            .positions
            .iter()
            .copied()
            .filter(|q| (q[0] - p[0]).hypot(q[1] - p[1]) < 30.0)
            .collect();
        // Bounded work however dense the views: the nearest positions speak for the roads.
        if near.len() > ROAD_MAX_POSITIONS {
            near.sort_by(|a, b| {
                let da = (a[0] - p[0]).hypot(a[1] - p[1]);
                let db = (b[0] - p[0]).hypot(b[1] - p[1]);
                da.total_cmp(&db)
                    .then(a[0].total_cmp(&b[0]))
                    .then(a[1].total_cmp(&b[1]))
            });
            near.truncate(ROAD_MAX_POSITIONS);
        }
        let mut roads = Vec::new();
        while near.len() >= 3 && roads.len() < 4 {
            let Some((axis, centre, inliers)) = strongest_line(&near) else {
                break;
            };
            let (lo, hi) = inliers
                .iter()
                .map(|&k| (near[k][0] - centre[0]) * axis[0] + (near[k][1] - centre[1]) * axis[1])
                .fold((f64::MAX, f64::MIN), |(lo, hi), s| (lo.min(s), hi.max(s)));
            if hi - lo < 5.0 {
                break;
            }
            let lateral = ((p[0] - centre[0]) * -axis[1] + (p[1] - centre[1]) * axis[0]).abs();
            roads.push((axis, lateral));
            near = near
                .into_iter()
                .enumerate()
                .filter(|(k, _)| !inliers.contains(k))
                .map(|(_, q)| q)
                .collect();
        }
        roads
    }
}

/// Camera positions this close to a street's line are on it, metres: street-view cars keep
/// their lane, and a reported position is off by a metre or less.
const ROAD_TOL_M: f64 = 1.5;

/// Most camera positions a road query looks at (the nearest).
const ROAD_MAX_POSITIONS: usize = 48;

/// The line through two of `points` at least 5 m apart that the most points lie within
/// `ROAD_TOL_M` of (the first such pair on ties), refitted to those points: its unit axis, the
/// inliers' centroid and their indices; None with fewer than three on any line.
fn strongest_line(points: &[[f64; 2]]) -> Option<([f64; 2], [f64; 2], Vec<usize>)> {
    let inliers_of = |a: [f64; 2], axis: [f64; 2]| -> Vec<usize> {
        (0..points.len())
            .filter(|&k| {
                let (dx, dy) = (points[k][0] - a[0], points[k][1] - a[1]);
                (dx * -axis[1] + dy * axis[0]).abs() <= ROAD_TOL_M
            })
            .collect()
    };
    let mut best: Option<Vec<usize>> = None;
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            let (dx, dy) = (points[j][0] - points[i][0], points[j][1] - points[i][1]);
            let len = dx.hypot(dy);
            if len < 5.0 {
                continue;
            }
            let inl = inliers_of(points[i], [dx / len, dy / len]);
            if best.as_ref().is_none_or(|b| inl.len() > b.len()) {
                best = Some(inl);
            }
        }
    }
    let inliers = best.filter(|b| b.len() >= 3)?;
    let spread = Spread::of(inliers.iter().map(|&k| points[k]));
    let a = spread.axis_angle();
    Some(([a.cos(), a.sin()], spread.centre, inliers))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crossing_is_two_streets_not_one_axis_between_them() {
        // Cameras every 5 m along y = 9 and along x = 200, a few centimetres off their lines.
        let mut positions = Vec::new();
        for k in -6..=6 {
            let s = 5.0 * k as f64;
            let wobble = 0.05 * ((k * 7) % 3) as f64;
            positions.push([200.0 + s, 9.0 + wobble]);
            if k != 0 {
                positions.push([200.0 + wobble, 9.0 + s]);
            }
        }
        let track = Track { positions };
        // A lamp post on the corner's pavement: 6.3 m from one axis, 8.5 m from the other.
        let (axis, lateral) = track.road([206.3, 17.5]).unwrap();
        assert!((lateral - 6.3).abs() < 0.1, "lateral {lateral}");
        assert!(axis[0].abs() < 0.02, "axis {axis:?}");
        assert_eq!(track.roads([206.3, 17.5]).len(), 2);
        // A post in the middle of the crossing street's carriageway.
        let (_, lateral) = track.road([199.6, 94.6 - 85.0]).unwrap();
        assert!(lateral < 0.7, "lateral {lateral}");
        // One straight street: one road, the distance from its axis.
        let straight = Track {
            positions: (0..12).map(|k| [5.0 * k as f64, 3.0]).collect(),
        };
        let roads = straight.roads([20.0, 11.5]);
        assert_eq!(roads.len(), 1);
        assert!((roads[0].1 - 8.5).abs() < 1e-9);
        // Too few positions, or all at one place: no road.
        let parked = Track {
            positions: vec![[0.0, 0.0]; 10],
        };
        assert!(parked.road([0.0, 5.0]).is_none());
    }
}
