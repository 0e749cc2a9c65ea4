//! The quadratic error function of dual contouring: accumulation, the eigenvalue-truncated
//! solve towards the mass point, and the minimiser within a box for vertices that would
//! leave their reach.

use super::*;

/// Eigenvalues of the QEF matrix below this fraction of the largest one are truncated
/// (the solution moves only in the well-determined directions from the mass point).
pub(super) const QEF_TRUNCATION: f64 = 0.05;

/// A dual contouring vertex outside its cell is replaced by the minimiser within the cell
/// of its QEF plus this fraction of the QEF matrix's trace times the squared distance to
/// it ([`Qef::solve_in_box`]): small, so that the error decides and the vertex only slides
/// along directions the error leaves free (a crease line).
pub(super) const QEF_BOX_REGULARISATION: f64 = 1e-3;

/// Accumulated quadratic error `sum (n_i . (x - p_i))^2` and the crossings' mass point.
#[derive(Default)]
pub(super) struct Qef {
    pub(super) ata: [[f64; 3]; 3],
    pub(super) atb: DVec3,
    pub(super) count: u32,
    /// Sum of the crossing points (a zero normal adds to the mass point only).
    pub(super) points: DVec3,
    /// Sum of the normals.
    pub(super) normals: DVec3,
}

impl Qef {
    pub(super) fn add(&mut self, p: DVec3, n: DVec3) {
        self.points += p;
        self.normals += n;
        self.count += 1;
        for r in 0..3 {
            for c in 0..3 {
                self.ata[r][c] += n[r] * n[c];
            }
        }
        self.atb += n * n.dot(p);
    }

    /// The minimiser closest to the mass point, with eigenvalues below
    /// [`QEF_TRUNCATION`] times the largest treated as zero, and the number of
    /// eigenvalues kept (the rank: 1 on a smooth sheet, 2 along a crease, 3 at a corner).
    pub(super) fn solve(&self) -> (DVec3, u8) {
        let c = self.points / self.count.max(1) as f64;
        let a = self.ata;
        let ac = DVec3::new(
            a[0][0] * c.x + a[0][1] * c.y + a[0][2] * c.z,
            a[1][0] * c.x + a[1][1] * c.y + a[1][2] * c.z,
            a[2][0] * c.x + a[2][1] * c.y + a[2][2] * c.z,
        );
        let rhs = self.atb - ac;
        let mut x = c;
        let mut rank = 0u8;
        if let Some((dx, r)) = truncated_solve(a, rhs) {
            x += dx;
            rank = r;
        } else {
            let (vals, vecs) = sym_eigen(a);
            let max = vals.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if max > 0.0 {
                for k in 0..3 {
                    if vals[k] > QEF_TRUNCATION * max {
                        x += vecs[k] * (vecs[k].dot(rhs) / vals[k]);
                        rank += 1;
                    }
                }
            }
        }
        if x.is_finite() { (x, rank) } else { (c, 0) }
    }
}

impl Qef {
    /// The minimiser within the box `[lo, hi]` of the quadratic error plus
    /// [`QEF_BOX_REGULARISATION`] times the trace times `|x - target|²` (strictly convex, so
    /// the minimiser is unique and near `target` along directions the error leaves free,
    /// such as a crease line). Exact: every assignment of each coordinate to free, `lo` or
    /// `hi` (27) is solved for its free coordinates, and the feasible candidate with the
    /// least value is the minimiser. `target` clamped when nothing better is found.
    pub(super) fn solve_in_box(&self, target: DVec3, lo: DVec3, hi: DVec3) -> DVec3 {
        let a = self.ata;
        let mu = QEF_BOX_REGULARISATION * (a[0][0] + a[1][1] + a[2][2]);
        if !(mu > 0.0) {
            return target.clamp(lo, hi);
        }
        // Value up to a constant: x'Ax - 2 b'x + mu |x - t|², with b the QEF's right side.
        let value = |x: DVec3| {
            let ax = DVec3::new(
                a[0][0] * x.x + a[0][1] * x.y + a[0][2] * x.z,
                a[1][0] * x.x + a[1][1] * x.y + a[1][2] * x.z,
                a[2][0] * x.x + a[2][1] * x.y + a[2][2] * x.z,
            );
            x.dot(ax) - 2.0 * self.atb.dot(x) + mu * (x - target).length_squared()
        };
        let mut best = target.clamp(lo, hi);
        let mut best_value = value(best);
        for combo in 0..27u32 {
            // Per coordinate: 0 free, 1 at lo, 2 at hi.
            let state = [combo % 3, combo / 3 % 3, combo / 9];
            let mut x = DVec3::ZERO;
            let mut free = [0usize; 3];
            let mut nfree = 0;
            for i in 0..3 {
                match state[i] {
                    0 => {
                        free[nfree] = i;
                        nfree += 1;
                    }
                    1 => x[i] = lo[i],
                    _ => x[i] = hi[i],
                }
            }
            // (A + mu I) x = b + mu t on the free coordinates, the fixed ones moved right.
            let mut m = [[0.0f64; 3]; 3];
            let mut r = [0.0f64; 3];
            for (u, &i) in free[..nfree].iter().enumerate() {
                r[u] = self.atb[i] + mu * target[i];
                for j in 0..3 {
                    if state[j] != 0 {
                        r[u] -= a[i][j] * x[j];
                    }
                }
                for (w, &j) in free[..nfree].iter().enumerate() {
                    m[u][w] = a[i][j] + if i == j { mu } else { 0.0 };
                }
            }
            let Some(sol) = solve_small(&m, &r, nfree) else { continue };
            for (u, &i) in free[..nfree].iter().enumerate() {
                x[i] = sol[u];
            }
            if x.cmpge(lo).all() && x.cmple(hi).all() {
                let v = value(x);
                if v < best_value {
                    (best, best_value) = (x, v);
                }
            }
        }
        best
    }
}

/// Solves the leading `n`×`n` block of `m` (symmetric positive definite) for `r` by
/// Gaussian elimination; `None` when a pivot is not positive.
pub(super) fn solve_small(m: &[[f64; 3]; 3], r: &[f64; 3], n: usize) -> Option<[f64; 3]> {
    let (mut m, mut r) = (*m, *r);
    for k in 0..n {
        if !(m[k][k] > 0.0) {
            return None;
        }
        for i in k + 1..n {
            let (f, mk) = (m[i][k] / m[k][k], m[k]);
            for (mij, mkj) in m[i][k..n].iter_mut().zip(&mk[k..n]) {
                *mij -= f * mkj;
            }
            r[i] -= f * r[k];
        }
    }
    let mut x = [0.0f64; 3];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| m[k][j] * x[j]).sum();
        x[k] = (r[k] - s) / m[k][k];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// `A⁺ rhs` of the symmetric positive semi-definite `a` with eigenvalues at or below
/// [`QEF_TRUNCATION`] times the largest treated as zero, by closed-form eigenvalues
/// (trigonometric method) and eigenvectors of isolated eigenvalues (cross products of
/// the rows of `a - lambda I`). `None` when an eigenvalue is within 20% of the threshold
/// or the matrix is not positive (then [`sym_eigen`] decides). The same result as the
/// truncated sum over [`sym_eigen`]'s eigenpairs up to rounding, at under half the cost.
pub(super) fn truncated_solve(a: [[f64; 3]; 3], rhs: DVec3) -> Option<(DVec3, u8)> {
    let p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let (d0, d1, d2) = (a[0][0] - q, a[1][1] - q, a[2][2] - q);
    let p = ((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1) / 6.0).sqrt();
    if !(q > 0.0) || !p.is_finite() {
        return None;
    }
    if p <= 1e-12 * q {
        // A multiple of the identity (up to rounding): every eigenvalue is kept.
        return Some((rhs / q, 3));
    }
    // B = (A - q I) / p; r = det(B) / 2.
    let b = [
        [d0 / p, a[0][1] / p, a[0][2] / p],
        [a[0][1] / p, d1 / p, a[1][2] / p],
        [a[0][2] / p, a[1][2] / p, d2 / p],
    ];
    let det = b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
        - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
        + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]);
    let phi = (0.5 * det).clamp(-1.0, 1.0).acos() / 3.0;
    let l1 = q + 2.0 * p * phi.cos();
    let l3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let l2 = 3.0 * q - l1 - l3;
    let max = l1.abs().max(l3.abs());
    let t = QEF_TRUNCATION * max;
    let (lo, hi) = (0.8 * t, 1.2 * t);
    if [l1, l2, l3].iter().any(|&l| l > lo && l < hi) || !(l1 > hi) {
        return None;
    }
    // Unit eigenvector of an eigenvalue `l` well apart from the others.
    let eigenvector = |l: f64| -> Option<DVec3> {
        let r = [
            DVec3::new(a[0][0] - l, a[0][1], a[0][2]),
            DVec3::new(a[1][0], a[1][1] - l, a[1][2]),
            DVec3::new(a[2][0], a[2][1], a[2][2] - l),
        ];
        let c = [r[0].cross(r[1]), r[0].cross(r[2]), r[1].cross(r[2])];
        let best = c.into_iter().max_by(|x, y| x.length_squared().total_cmp(&y.length_squared()))?;
        let n2 = best.length_squared();
        (n2 > 0.0 && n2.is_finite()).then(|| best / n2.sqrt())
    };
    let solve3 = |m: [[f64; 3]; 3], v: DVec3| -> Option<DVec3> {
        let (c0, c1, c2) = (
            DVec3::new(m[0][0], m[1][0], m[2][0]),
            DVec3::new(m[0][1], m[1][1], m[2][1]),
            DVec3::new(m[0][2], m[1][2], m[2][2]),
        );
        let det = c0.dot(c1.cross(c2));
        (det != 0.0 && det.is_finite()).then(|| {
            // Cramer's rule.
            DVec3::new(v.dot(c1.cross(c2)), c0.dot(v.cross(c2)), c0.dot(c1.cross(v))) / det
        })
    };
    if l2 <= lo {
        // Rank one: only the largest eigenvalue is kept.
        let v = eigenvector(l1)?;
        Some((v * (v.dot(rhs) / l1), 1))
    } else if l3 <= lo {
        // Rank two: drop the smallest eigenvalue's direction, lift it to l1 to invert.
        let v = eigenvector(l3)?;
        let mut m = a;
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x += (l1 - l3) * v[r] * v[c];
            }
        }
        solve3(m, rhs - v * v.dot(rhs)).map(|x| (x, 2))
    } else {
        solve3(a, rhs).map(|x| (x, 3))
    }
}

/// Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix (cyclic Jacobi).
pub(super) fn sym_eigen(mut a: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for _ in 0..12 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-15 * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() <= 1e-18 * scale {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in &mut v {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
        }
    }
    let vals = [a[0][0], a[1][1], a[2][2]];
    let vecs = std::array::from_fn(|k| DVec3::new(v[0][k], v[1][k], v[2][k]));
    (vals, vecs)
}
