//! The 3×3 geometry the spatial description checks need when the macro
//! runs: vectors, the eigenvalues of a symmetric matrix (inertia tensors),
//! and rotations (link frames) as matrices and unit quaternions.

/// The 3×3 identity (a link frame aligned with the world).
pub const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// a·b.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a` scaled to unit length without overflow; `None` for a zero vector.
pub fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let s = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if s == 0.0 {
        return None;
    }
    let b = a.map(|x| x / s);
    let n = dot(b, b).sqrt();
    Some(b.map(|x| x / n))
}

/// Eigenvalues of a symmetric 3×3 matrix (trigonometric closed form).
pub fn eigenvalues(m: &[[f64; 3]; 3]) -> [f64; 3] {
    let p1 = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
    let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
    if p1 == 0.0 {
        return [m[0][0], m[1][1], m[2][2]];
    }
    let p2 = (m[0][0] - q).powi(2) + (m[1][1] - q).powi(2) + (m[2][2] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let b: Vec<Vec<f64>> = (0..3)
        .map(|i| {
            (0..3)
                .map(|j| (m[i][j] - if i == j { q } else { 0.0 }) / p)
                .collect()
        })
        .collect();
    let det = b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
        - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
        + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]);
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let e1 = q + 2.0 * p * phi.cos();
    let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    [e1, 3.0 * q - e1 - e3, e3]
}

/// The unit quaternion (w, x, y, z), w ≥ 0, of a rotation matrix.
pub fn matrix_to_quaternion(m: &[[f64; 3]; 3]) -> [f64; 4] {
    let t = m[0][0] + m[1][1] + m[2][2];
    let q = if t > 0.0 {
        let s = (t + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|x| sign * x / n)
}

/// Aᵀ·B.
pub fn mul_tn(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[k][i] * b[k][j]).sum();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalues_of_a_rotated_diagonal_matrix() {
        // R diag(1, 2, 3) Rᵀ for a rotation about (1, 1, 1)/√3 by 0.7
        let (s, c) = 0.7f64.sin_cos();
        let a = [1.0 / 3f64.sqrt(); 3];
        let r: Vec<Vec<f64>> = (0..3)
            .map(|i| {
                (0..3)
                    .map(|j| {
                        let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
                        let kk: f64 = (0..3).map(|l| k[i][l] * k[l][j]).sum();
                        f64::from(u8::from(i == j)) + s * k[i][j] + (1.0 - c) * kk
                    })
                    .collect()
            })
            .collect();
        let d = [1.0, 2.0, 3.0];
        let mut m = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = (0..3).map(|l| r[i][l] * d[l] * r[j][l]).sum();
            }
        }
        let mut e = eigenvalues(&m);
        e.sort_by(f64::total_cmp);
        for (x, y) in e.iter().zip(d) {
            assert!((x - y).abs() < 1e-12, "{e:?}");
        }
    }

    #[test]
    fn quaternion_of_a_rotation_matrix() {
        // rotation by π/2 about z: (cos π/4, 0, 0, sin π/4)
        let m = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let q = matrix_to_quaternion(&m);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        for (x, y) in q.iter().zip([h, 0.0, 0.0, h]) {
            assert!((x - y).abs() < 1e-15);
        }
        // rotation by π about x: trace −1 branch
        let m = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        let q = matrix_to_quaternion(&m);
        assert!((q[1].abs() - 1.0).abs() < 1e-15);
    }
}
