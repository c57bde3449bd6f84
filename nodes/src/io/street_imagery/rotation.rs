//! Rotations of the provider readers: 3 x 3 matrices as rows (a [`crate::artifact::Pose`]'s
//! `rotation`), angle-axis vectors (Rodrigues), the meridian-convergence turn from ENU to the site
//! frame, and headings of optical axes.

/// A 3 x 3 matrix, rows.
pub type Mat3 = [[f64; 3]; 3];

/// `a · b`.
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

/// `aᵀ`.
pub fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| a[c][r]))
}

/// The rotation matrix of an angle-axis vector (Rodrigues).
pub fn rodrigues(v: [f64; 3]) -> Mat3 {
    let m = glam::DMat3::from_quat(glam::DQuat::from_scaled_axis(glam::DVec3::from_array(v)));
    transpose(&m.to_cols_array_2d())
}

/// The angle-axis vector of a rotation matrix.
pub fn angle_axis(m: &Mat3) -> [f64; 3] {
    let g = glam::DMat3::from_cols_array_2d(&transpose(m));
    glam::DQuat::from_mat3(&g).to_scaled_axis().to_array()
}

/// Heading (degrees clockwise from the frame's y axis, in [0, 360)) of a camera's optical axis,
/// `None` when it points straight up or down.
pub fn heading_deg(camera_to_frame: &Mat3) -> Option<f64> {
    let (x, y) = (camera_to_frame[0][2], camera_to_frame[1][2]);
    (x.hypot(y) > 1e-9).then(|| x.atan2(y).to_degrees().rem_euclid(360.0))
}

/// `m · v`.
pub fn mat_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

/// The rotation taking ENU vectors into a site frame whose grid north lies `convergence` radians
/// clockwise of true north (the meridian convergence): a turn about z by its negative.
pub fn enu_to_grid(convergence: f64) -> Mat3 {
    let (s, c) = convergence.sin_cos();
    [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
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
