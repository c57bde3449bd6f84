//! Rotations of the provider readers, in glam's f64 types: angle-axis vectors (Rodrigues), the
//! meridian-convergence turn from ENU to the site frame, headings of optical axes, and the
//! conversions to and from the row arrays a [`crate::artifact::Pose`] stores.

use glam::{DMat3, DQuat, DVec3};

/// The matrix of a rotation stored as rows (a [`crate::artifact::Pose`]'s `rotation`).
pub fn from_rows(rows: &[[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols_array_2d(rows).transpose()
}

/// The rows of a matrix, as a [`crate::artifact::Pose`] stores its rotation.
pub fn to_rows(m: DMat3) -> [[f64; 3]; 3] {
    m.transpose().to_cols_array_2d()
}

/// `m · v`, on arrays.
pub fn mat_vec(m: &DMat3, v: [f64; 3]) -> [f64; 3] {
    m.mul_vec3(DVec3::from_array(v)).to_array()
}

/// The rotation matrix of an angle-axis vector (Rodrigues).
pub fn rodrigues(v: [f64; 3]) -> DMat3 {
    DMat3::from_quat(DQuat::from_scaled_axis(DVec3::from_array(v)))
}

/// The angle-axis vector of a rotation matrix.
pub fn angle_axis(m: &DMat3) -> [f64; 3] {
    DQuat::from_mat3(m).to_scaled_axis().to_array()
}

/// The rotation taking ENU vectors into a site frame whose grid north lies `convergence` radians
/// clockwise of true north (the meridian convergence): a turn about z by its negative.
pub fn enu_to_grid(convergence: f64) -> DMat3 {
    DMat3::from_rotation_z(-convergence)
}

/// Heading (degrees clockwise from the frame's y axis, in [0, 360)) of a camera's optical axis,
/// `None` when it points straight up or down.
pub fn heading_deg(camera_to_frame: &DMat3) -> Option<f64> {
    let DVec3 { x, y, .. } = camera_to_frame.z_axis;
    (x.hypot(y) > 1e-9).then(|| x.atan2(y).to_degrees().rem_euclid(360.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rodrigues_and_angle_axis_invert() {
        let v = [0.3, -1.2, 2.0];
        let back = angle_axis(&rodrigues(v));
        assert!(
            v.iter().zip(back).all(|(a, b)| (a - b).abs() < 1e-12),
            "{back:?}"
        );
        // About z by 90 degrees: x -> y.
        let m = rodrigues([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        assert!((mat_vec(&m, [1.0, 0.0, 0.0])[1] - 1.0).abs() < 1e-12);
    }
}
