//! # milv-geom — plane projective maps
//!
//! The simulator's cameras (table plane → image) and the aligner's table rectification
//! (image → table plane) are both homographies fixed by four point correspondences;
//! [`Homography`] is that one computation.

/// A plane projective map, `p ↦ H·[p, 1]` dehomogenised, with `h33 = 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography {
    pub h: [[f64; 3]; 3],
}

impl Homography {
    /// The map taking each `src[k]` to `dst[k]`; `None` when three of the points are
    /// collinear (no unique solution).
    ///
    /// ```
    /// use milv_geom::Homography;
    /// let quad = [(20.0, 10.0), (80.0, 16.0), (90.0, 70.0), (6.0, 64.0)];
    /// let unit = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
    /// let h = Homography::from_points(&quad, &unit).unwrap();
    /// let (u, v) = h.apply((90.0, 70.0));
    /// assert!((u - 1.0).abs() < 1e-12 && (v - 1.0).abs() < 1e-12);
    /// ```
    pub fn from_points(src: &[(f64, f64); 4], dst: &[(f64, f64); 4]) -> Option<Homography> {
        // Direct linear transform with h33 = 1: eight equations, eight unknowns.
        let mut a = [[0.0f64; 9]; 8];
        for (i, ((x, y), (u, v))) in src.iter().zip(dst.iter()).enumerate() {
            a[2 * i] = [*x, *y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, *u];
            a[2 * i + 1] = [0.0, 0.0, 0.0, *x, *y, 1.0, -v * x, -v * y, *v];
        }
        let s = solve8(a)?;
        Some(Homography {
            h: [[s[0], s[1], s[2]], [s[3], s[4], s[5]], [s[6], s[7], 1.0]],
        })
    }

    /// Scales x by `sx` and y by `sy`.
    pub fn scale(sx: f64, sy: f64) -> Homography {
        Homography {
            h: [[sx, 0.0, 0.0], [0.0, sy, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    pub fn apply(&self, (x, y): (f64, f64)) -> (f64, f64) {
        let h = &self.h;
        let w = h[2][0] * x + h[2][1] * y + h[2][2];
        (
            (h[0][0] * x + h[0][1] * y + h[0][2]) / w,
            (h[1][0] * x + h[1][1] * y + h[1][2]) / w,
        )
    }
}

/// Gaussian elimination with partial pivoting on an 8×9 augmented matrix.
fn solve8(mut a: [[f64; 9]; 8]) -> Option<[f64; 8]> {
    for col in 0..8 {
        let piv = (col..8).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, piv);
        let pivot_row = a[col];
        for (row, r) in a.iter_mut().enumerate() {
            if row != col {
                let f = r[col] / pivot_row[col];
                for (x, p) in r.iter_mut().zip(pivot_row.iter()).skip(col) {
                    *x -= f * p;
                }
            }
        }
    }
    Some(std::array::from_fn(|i| a[i][8] / a[i][i]))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn maps_the_four_points_and_rejects_collinear_ones() {
        let src = [(0.0, 0.0), (60.0, 0.0), (60.0, 60.0), (0.0, 60.0)];
        let dst = [(6.0, 122.0), (122.0, 122.0), (104.0, 18.0), (24.0, 18.0)];
        let h = Homography::from_points(&src, &dst).unwrap();
        for (s, d) in src.iter().zip(&dst) {
            let (u, v) = h.apply(*s);
            assert!((u - d.0).abs() < 1e-9 && (v - d.1).abs() < 1e-9);
        }
        let line = [(0.0, 0.0), (1.0, 1.0), (2.0, 2.0), (3.0, 3.0)];
        assert!(Homography::from_points(&line, &dst).is_none());
    }
}
