//! Dynamic time warping inside a Sakoe–Chiba band, in O(n·band) memory.
//!
//! Rows are the first sequence (human frames), columns the second (robot frames). Each
//! row keeps only the columns of its band: the accumulated cost and a 2-bit back pointer
//! per cell, so a 1,000 × 1,000 alignment with a 10 % band stores ~200 k cells, not 1 M.

use crate::Error;

/// A matrix of per-frame feature vectors, row-major (`n` frames × `d` values).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Features {
    pub n: usize,
    pub d: usize,
    pub data: Vec<f64>,
}

impl Features {
    pub fn new(n: usize, d: usize, data: Vec<f64>) -> Result<Self, Error> {
        if data.len() != n * d {
            return Err(Error::Invalid(format!(
                "features: {} values for {n} frames of {d}",
                data.len()
            )));
        }
        Ok(Features { n, d, data })
    }

    pub fn row(&self, i: usize) -> &[f64] {
        &self.data[i * self.d..(i + 1) * self.d]
    }

    /// Each dimension mapped onto [0, 1] by its range over the clip (a constant dimension
    /// becomes 0). A path's range does not depend on how fast it is travelled, while its
    /// mean and spread do: two clips of one motion at different speeds keep equal values
    /// for equal states.
    pub fn range_normalized(mut self) -> Self {
        for k in 0..self.d {
            let col = || (0..self.n).map(|i| self.data[i * self.d + k]);
            let lo = col().fold(f64::INFINITY, f64::min);
            let span = col().fold(f64::NEG_INFINITY, f64::max) - lo;
            for i in 0..self.n {
                let v = &mut self.data[i * self.d + k];
                *v = if span > 1e-12 { (*v - lo) / span } else { 0.0 };
            }
        }
        self
    }

    /// Each dimension shifted and scaled to mean 0, standard deviation 1 over the clip
    /// (a constant dimension becomes 0).
    pub fn z_normalized(mut self) -> Self {
        let n = self.n.max(1) as f64;
        for k in 0..self.d {
            let col = || (0..self.n).map(|i| self.data[i * self.d + k]);
            let mean = col().sum::<f64>() / n;
            let var = col().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
            let sd = var.sqrt();
            for i in 0..self.n {
                let v = &mut self.data[i * self.d + k];
                *v = if sd > 1e-12 { (*v - mean) / sd } else { 0.0 };
            }
        }
        self
    }
}

/// Which predecessors a cell may come from, and how the local cost is weighted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StepPattern {
    /// `D(i,j) = d(i,j) + min(D(i−1,j−1), D(i−1,j), D(i,j−1))`.
    Symmetric1,
    /// Diagonal steps pay `2·d(i,j)`: not biased towards diagonal shortcuts; cost
    /// normalised by `n + m`.
    Symmetric2,
    /// Every row advances by one: `D(i,j) = d(i,j) + min(D(i−1,j), D(i−1,j−1), D(i−1,j−2))`,
    /// so each human frame gets exactly one robot frame (the robot clip may skip frames).
    Asymmetric,
}

impl std::str::FromStr for StepPattern {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "symmetric1" => Ok(Self::Symmetric1),
            "symmetric2" => Ok(Self::Symmetric2),
            "asymmetric" => Ok(Self::Asymmetric),
            _ => Err(format!(
                "unknown step pattern {s:?} (symmetric1 | symmetric2 | asymmetric)"
            )),
        }
    }
}

/// The allowed columns `lo[i] ..= hi[i]` of each row.
#[derive(Clone, Debug)]
pub struct Band {
    lo: Vec<usize>,
    hi: Vec<usize>,
}

impl Band {
    /// Sakoe–Chiba band of half-width `w` columns around the diagonal from (0, 0) to
    /// (n−1, m−1) (the slope follows the length ratio, so clips of different lengths work).
    pub fn around_diagonal(n: usize, m: usize, w: usize) -> Band {
        let slope = if n > 1 {
            (m - 1) as f64 / (n - 1) as f64
        } else {
            0.0
        };
        // Rows must overlap enough for a connected path: at least the slope's step.
        let w = w.max(slope.ceil() as usize).max(1);
        let (lo, hi) = (0..n)
            .map(|i| {
                let c = (i as f64 * slope).round() as usize;
                (c.saturating_sub(w), (c + w).min(m - 1))
            })
            .unzip();
        Band { lo, hi }
    }

    /// `|i − j| ≤ w` (the classic band for equal lengths, as `dtaidistance`'s `window`).
    pub fn absolute(n: usize, m: usize, w: usize) -> Band {
        let w = w.max(n.abs_diff(m));
        let (lo, hi) = (0..n).map(|i| (i.saturating_sub(w), (i + w).min(m - 1))).unzip();
        Band { lo, hi }
    }

    /// The whole matrix.
    pub fn full(n: usize, m: usize) -> Band {
        Band {
            lo: vec![0; n],
            hi: vec![m - 1; n],
        }
    }

    /// Whether cell (i, j) is on the band's first or last column of row i.
    pub fn on_edge(&self, i: usize, j: usize) -> bool {
        j == self.lo[i] || j == self.hi[i]
    }

    pub fn cells(&self) -> usize {
        self.lo.iter().zip(&self.hi).map(|(l, h)| h + 1 - l).sum()
    }
}

/// The result of aligning two sequences.
#[derive(Clone, Debug, PartialEq)]
pub struct Alignment {
    /// Aligned cells `(i, j)`, from (0, 0) to (n−1, m−1).
    pub path: Vec<(usize, usize)>,
    /// Local cost `d(i, j)` of each path cell.
    pub local: Vec<f64>,
    /// Accumulated cost `D(n−1, m−1)`.
    pub total: f64,
    /// `total` divided by the step pattern's normaliser (path length, or `n + m`).
    pub normalized: f64,
    /// Cells evaluated (the band's area).
    pub cells: usize,
}

/// Squared Euclidean distance of two feature rows (the local cost). Eight partial sums,
/// so the loop vectorises instead of waiting on one chain of additions.
#[inline]
pub fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    let (ac, at) = a.as_chunks::<8>();
    let (bc, bt) = b[..a.len()].as_chunks::<8>();
    let mut acc = [0.0f64; 8];
    for (x, y) in ac.iter().zip(bc) {
        for k in 0..8 {
            let d = x[k] - y[k];
            acc[k] += d * d;
        }
    }
    let tail: f64 = at.iter().zip(bt).map(|(x, y)| (x - y) * (x - y)).sum();
    acc.iter().sum::<f64>() + tail
}

const DIAG: u8 = 0;
const UP: u8 = 1; // from (i−1, j)
const LEFT: u8 = 2; // from (i, j−1)
const SKIP: u8 = 3; // from (i−1, j−2), asymmetric only

/// Refuses an empty clip, features of different widths, or a band of another shape.
fn check_inputs(a: &Features, b: &Features, band: &Band) -> Result<(), Error> {
    let (n, m) = (a.n, b.n);
    if n == 0 || m == 0 {
        return Err(Error::Invalid(format!(
            "cannot align an empty clip ({n} x {m} frames)"
        )));
    }
    if a.d != b.d {
        return Err(Error::Invalid(format!(
            "feature widths differ: {} and {}",
            a.d, b.d
        )));
    }
    if band.lo.len() != n || band.hi.iter().any(|&h| h >= m) {
        return Err(Error::Invalid(format!("band does not fit a {n} x {m} matrix")));
    }
    Ok(())
}

/// Aligns `a` (rows) with `b` (columns) inside `band`; `keep_path` false computes only the
/// cost (O(band) memory). Local cost: squared Euclidean distance of feature rows.
pub fn dtw(
    a: &Features,
    b: &Features,
    band: &Band,
    step: StepPattern,
    keep_path: bool,
) -> Result<Alignment, Error> {
    check_inputs(a, b, band)?;
    let (n, m) = (a.n, b.n);
    let inf = f64::INFINITY;
    // Offsets of each row's band in the back-pointer store.
    let mut offsets = Vec::with_capacity(if keep_path { n + 1 } else { 0 });
    let mut back: Vec<u8> = Vec::new();
    if keep_path {
        let mut o = 0;
        for i in 0..n {
            offsets.push(o);
            o += band.hi[i] + 1 - band.lo[i];
        }
        offsets.push(o);
        back = vec![0; o];
    }
    // Two rows of accumulated cost, indexed by absolute column; reads outside the
    // previous row's band (or left of this row's) count as unreachable.
    let mut prev = vec![inf; m];
    let mut cur = vec![inf; m];
    for i in 0..n {
        let (lo, hi) = (band.lo[i], band.hi[i]);
        let (plo, phi) = if i > 0 {
            (band.lo[i - 1], band.hi[i - 1])
        } else {
            (1, 0)
        };
        let p = |j: usize| if (plo..=phi).contains(&j) { prev[j] } else { inf };
        let ar = a.row(i);
        for j in lo..=hi {
            let d = sq_dist(ar, b.row(j));
            let (best, from) = if i == 0 && j == 0 {
                let first = if step == StepPattern::Symmetric2 {
                    2.0 * d
                } else {
                    d
                };
                (first, DIAG)
            } else {
                let diag = if j > 0 { p(j - 1) } else { inf };
                let up = p(j);
                let left = if j > lo { cur[j - 1] } else { inf };
                match step {
                    StepPattern::Symmetric1 => {
                        let (mut v, mut f) = (diag, DIAG);
                        if up < v {
                            (v, f) = (up, UP);
                        }
                        if left < v {
                            (v, f) = (left, LEFT);
                        }
                        (v + d, f)
                    }
                    StepPattern::Symmetric2 => {
                        let (mut v, mut f) = (diag + 2.0 * d, DIAG);
                        if up + d < v {
                            (v, f) = (up + d, UP);
                        }
                        if left + d < v {
                            (v, f) = (left + d, LEFT);
                        }
                        (v, f)
                    }
                    StepPattern::Asymmetric => {
                        let skip = if j > 1 { p(j - 2) } else { inf };
                        let (mut v, mut f) = (diag, DIAG);
                        if up < v {
                            (v, f) = (up, UP);
                        }
                        if skip < v {
                            (v, f) = (skip, SKIP);
                        }
                        (v + d, f)
                    }
                }
            };
            cur[j] = best;
            if keep_path {
                back[offsets[i] + j - lo] = from;
            }
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    let (llo, lhi) = (band.lo[n - 1], band.hi[n - 1]);
    let total = if (llo..=lhi).contains(&(m - 1)) {
        prev[m - 1]
    } else {
        inf
    };
    if !total.is_finite() {
        return Err(Error::Invalid(format!(
            "no warping path within the band for {n} x {m} frames (widen --band{})",
            if step == StepPattern::Asymmetric && m > 2 * n {
                "; asymmetric steps cannot skip more than every other robot frame"
            } else {
                ""
            }
        )));
    }
    let mut path = Vec::new();
    let mut local = Vec::new();
    if keep_path {
        let (mut i, mut j) = (n - 1, m - 1);
        loop {
            path.push((i, j));
            local.push(sq_dist(a.row(i), b.row(j)));
            if i == 0 && j == 0 {
                break;
            }
            match back[offsets[i] + j - band.lo[i]] {
                DIAG => {
                    i -= 1;
                    j -= 1;
                }
                UP => i -= 1,
                LEFT => j -= 1,
                _ => {
                    i -= 1;
                    j -= 2;
                }
            }
        }
        path.reverse();
        local.reverse();
    }
    let norm = match step {
        StepPattern::Symmetric2 => (n + m) as f64,
        StepPattern::Asymmetric => n as f64,
        StepPattern::Symmetric1 if keep_path => path.len() as f64,
        StepPattern::Symmetric1 => n.max(m) as f64,
    };
    Ok(Alignment {
        path,
        local,
        total,
        normalized: total / norm,
        cells: band.cells(),
    })
}

/// For each row `i`, the column it is aligned to: the rounded mean of the path's
/// columns on that row.
pub fn row_to_col(path: &[(usize, usize)], n: usize) -> Vec<usize> {
    let mut sum = vec![0usize; n];
    let mut cnt = vec![0usize; n];
    for &(i, j) in path {
        sum[i] += j;
        cnt[i] += 1;
    }
    sum.iter()
        .zip(&cnt)
        .map(|(s, c)| ((*s as f64) / (*c).max(1) as f64).round() as usize)
        .collect()
}

/// A monotone path of unit steps from (0, 0) to (n−1, m−1) through `(i, cols[i])` for
/// every row (`cols` non-decreasing, `m` columns): where a row's column moves on, the
/// path steps diagonally into the row and runs along it; the last row runs on to m−1.
pub fn staircase(cols: &[usize], m: usize) -> Vec<(usize, usize)> {
    let n = cols.len();
    let mut path = Vec::with_capacity(n + m);
    let mut j = 0;
    for (i, &c) in cols.iter().enumerate() {
        let c = if i + 1 == n { m.saturating_sub(1) } else { c }.max(j);
        let first = if i > 0 && c > j { j + 1 } else { j };
        path.extend((first..=c).map(|k| (i, k)));
        j = c;
    }
    path
}

/// `ln(eᵃ + eᵇ)` without overflow.
fn log_add(a: f64, b: f64) -> f64 {
    let (hi, lo) = if a >= b { (a, b) } else { (b, a) };
    if lo == f64::NEG_INFINITY {
        hi
    } else {
        hi + (lo - hi).exp().ln_1p()
    }
}

/// Weighted median index and standard deviation (in indices) of log-weights `w` (turned
/// into weights in place): the median is the first index where the running sum reaches
/// half the total.
fn weighted_median_sd(w: &mut [f64]) -> (usize, f64) {
    let top = w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // Every row of a band that holds a path has a reachable cell.
    debug_assert!(top.is_finite(), "a row without a reachable cell");
    w.iter_mut().for_each(|l| *l = (*l - top).exp());
    let total: f64 = w.iter().sum();
    let mean = w.iter().enumerate().map(|(k, v)| k as f64 * v).sum::<f64>() / total;
    let var = w
        .iter()
        .enumerate()
        .map(|(k, v)| (k as f64 - mean).powi(2) * v)
        .sum::<f64>()
        / total;
    let mut cum = 0.0;
    let median = w
        .iter()
        .position(|v| {
            cum += v;
            cum >= 0.5 * total
        })
        .unwrap_or(0);
    (median, var.sqrt())
}

/// What posterior decoding says of each row (human frame).
#[derive(Clone, Debug, PartialEq)]
pub struct Posterior {
    /// The row's median column over all paths, made non-decreasing.
    pub medians: Vec<usize>,
    /// The standard deviation of the columns of the row's cells over all paths (in
    /// columns): how unsure the features are of the row's partner, plus the width of a
    /// path's own run along the row (with symmetric steps, about m/n cells where the
    /// robot clip is the longer; at most one cell per row with asymmetric steps).
    pub sd: Vec<f64>,
}

impl Posterior {
    /// Mean of [`Posterior::sd`] over the rows.
    pub fn mean_sd(&self) -> f64 {
        self.sd.iter().sum::<f64>() / self.sd.len().max(1) as f64
    }
}

/// Posterior decoding of the warping path: for each row, its median column and that
/// column's spread. Every path inside `band` is weighted by `exp(−cost / temperature)`,
/// its cost accumulated as `step` does; forward and backward sums give each cell's
/// probability of lying on the path, and each row takes the median column of its cells
/// (made non-decreasing).
///
/// Why not the single best path: where the features are flat or ambiguous, many paths
/// cost nearly the same and the best one takes an arbitrary corner among them; the
/// median over them minimises the expected |frame error| instead (posterior decoding, as
/// for hidden Markov models).
pub fn posterior(
    a: &Features,
    b: &Features,
    band: &Band,
    step: StepPattern,
    temperature: f64,
) -> Result<Posterior, Error> {
    check_inputs(a, b, band)?;
    let (n, m) = (a.n, b.n);
    if !(temperature > 0.0 && temperature.is_finite()) {
        return Err(Error::Invalid(format!(
            "posterior: temperature {temperature} must be positive"
        )));
    }
    // Moves into a cell, as (rows back, columns back, weight of the cell's local cost).
    let moves: [(usize, usize, f64); 3] = match step {
        StepPattern::Symmetric1 => [(1, 1, 1.0), (1, 0, 1.0), (0, 1, 1.0)],
        StepPattern::Symmetric2 => [(1, 1, 2.0), (1, 0, 1.0), (0, 1, 1.0)],
        StepPattern::Asymmetric => [(1, 0, 1.0), (1, 1, 1.0), (1, 2, 1.0)],
    };
    let mut offsets = Vec::with_capacity(n + 1);
    let mut o = 0;
    for i in 0..n {
        offsets.push(o);
        o += band.hi[i] + 1 - band.lo[i];
    }
    offsets.push(o);
    let at = |i: usize, j: usize| {
        (band.lo[i]..=band.hi[i])
            .contains(&j)
            .then(|| offsets[i] + j - band.lo[i])
    };
    // The band's cells in storage order (rows, then columns): forward in this order,
    // backward in reverse.
    let cells: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (band.lo[i]..=band.hi[i]).map(move |j| (i, j)))
        .collect();
    // Log-weight of each cell's local cost.
    let lw: Vec<f64> = cells
        .iter()
        .map(|&(i, j)| -sq_dist(a.row(i), b.row(j)) / temperature)
        .collect();
    let neg = f64::NEG_INFINITY;
    let mut fwd = vec![neg; o];
    for (c, &(i, j)) in cells.iter().enumerate() {
        fwd[c] = if i == 0 && j == 0 {
            lw[c]
        } else {
            moves
                .iter()
                .filter(|&&(di, dj, _)| i >= di && j >= dj)
                .filter_map(|&(di, dj, w)| at(i - di, j - dj).map(|p| fwd[p] + w * lw[c]))
                .fold(neg, log_add)
        };
    }
    let mut bwd = vec![neg; o];
    for (c, &(i, j)) in cells.iter().enumerate().rev() {
        bwd[c] = if i == n - 1 && j == m - 1 {
            0.0
        } else {
            moves
                .iter()
                .filter(|&&(di, dj, _)| i + di < n && j + dj < m)
                .filter_map(|&(di, dj, w)| at(i + di, j + dj).map(|q| bwd[q] + w * lw[q]))
                .fold(neg, log_add)
        };
    }
    if at(n - 1, m - 1).is_none_or(|c| fwd[c] == neg) {
        return Err(Error::Invalid(format!(
            "posterior: no warping path within the band for {n} x {m} frames"
        )));
    }
    let mut hi = 0;
    let (medians, sd) = (0..n)
        .map(|i| {
            let mut row: Vec<f64> = fwd[offsets[i]..offsets[i + 1]]
                .iter()
                .zip(&bwd[offsets[i]..offsets[i + 1]])
                .map(|(f, b)| f + b)
                .collect();
            let (median, sd) = weighted_median_sd(&mut row);
            hi = hi.max(band.lo[i] + median);
            (hi, sd)
        })
        .unzip();
    Ok(Posterior { medians, sd })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn seq(v: &[f64]) -> Features {
        Features::new(v.len(), 1, v.to_vec()).unwrap()
    }

    /// Plain O(n·m) DTW (symmetric1, squared distance) as a reference.
    fn reference(a: &[f64], b: &[f64]) -> f64 {
        let (n, m) = (a.len(), b.len());
        let mut d = vec![vec![f64::INFINITY; m + 1]; n + 1];
        d[0][0] = 0.0;
        for i in 1..=n {
            for j in 1..=m {
                let c = (a[i - 1] - b[j - 1]).powi(2);
                d[i][j] = c + d[i - 1][j - 1].min(d[i - 1][j]).min(d[i][j - 1]);
            }
        }
        d[n][m]
    }

    #[test]
    fn full_band_equals_the_textbook_recursion() {
        let a: Vec<f64> = (0..23).map(|i| ((i * 7) % 11) as f64).collect();
        let b: Vec<f64> = (0..31).map(|i| ((i * 5) % 13) as f64 * 0.8).collect();
        let al = dtw(
            &seq(&a),
            &seq(&b),
            &Band::full(23, 31),
            StepPattern::Symmetric1,
            true,
        )
        .unwrap();
        assert!((al.total - reference(&a, &b)).abs() < 1e-9);
        assert_eq!(al.path.first(), Some(&(0, 0)));
        assert_eq!(al.path.last(), Some(&(22, 30)));
        assert!((al.local.iter().sum::<f64>() - al.total).abs() < 1e-9);
        let no_path = dtw(
            &seq(&a),
            &seq(&b),
            &Band::full(23, 31),
            StepPattern::Symmetric1,
            false,
        )
        .unwrap();
        assert_eq!(no_path.total, al.total);
        // Steps are unit moves.
        for w in al.path.windows(2) {
            let (di, dj) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
            assert!(di <= 1 && dj <= 1 && di + dj >= 1);
        }
    }

    #[test]
    fn a_time_warp_is_recovered() {
        // b is a slowed-down copy of a: b[j] = a[j * 2 / 3].
        let a: Vec<f64> = (0..40)
            .map(|i| (i as f64 * 0.3).sin() + i as f64 * 0.05)
            .collect();
        let b: Vec<f64> = (0..60).map(|j| a[j * 2 / 3]).collect();
        for step in [
            StepPattern::Symmetric1,
            StepPattern::Symmetric2,
            StepPattern::Asymmetric,
        ] {
            let al = dtw(&seq(&a), &seq(&b), &Band::around_diagonal(40, 60, 6), step, true).unwrap();
            let map = row_to_col(&al.path, 40);
            for (i, &j) in map.iter().enumerate() {
                assert!((b[j] - a[i]).abs() < 0.2, "{step:?}: row {i} -> {j}");
            }
        }
    }

    #[test]
    fn the_band_bounds_memory_and_too_narrow_bands_fail() {
        let band = Band::around_diagonal(1000, 1000, 50);
        assert!(band.cells() < 1000 * 101 + 1);
        let a = seq(&[0.0, 1.0, 2.0]);
        let b = seq(&(0..20).map(f64::from).collect::<Vec<_>>());
        // Asymmetric steps can take at most 2 columns per row.
        assert!(dtw(&a, &b, &Band::full(3, 20), StepPattern::Asymmetric, true).is_err());
        assert!(
            dtw(
                &a,
                &Features::default(),
                &Band::full(3, 1),
                StepPattern::Symmetric1,
                true
            )
            .is_err()
        );
    }

    /// A plateau of 6 human frames against 3 robot frames: every path through it costs
    /// nothing, the best path takes a corner (ties resolve to one side), and the posterior
    /// median spreads the rows evenly over the columns, as the true (proportional) match
    /// within the plateau would.
    #[test]
    fn posterior_spreads_a_flat_stretch_where_the_best_path_takes_a_corner() {
        let a = seq(&[0.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.5, 2.0]);
        let b = seq(&[0.0, 0.5, 1.0, 1.0, 1.0, 1.5, 2.0]);
        let band = Band::full(a.n, b.n);
        let best = dtw(&a, &b, &band, StepPattern::Symmetric2, true).unwrap();
        assert_eq!(row_to_col(&best.path, a.n), [0, 1, 2, 2, 2, 2, 3, 4, 5, 6]);
        for t in [0.01, 0.1, 1.0] {
            let post = posterior(&a, &b, &band, StepPattern::Symmetric2, t).unwrap();
            assert_eq!(post.medians, [0, 1, 2, 2, 3, 3, 4, 4, 5, 6], "temperature {t}");
        }
        // The plateau's rows are unsure of their partner, the rows around it are not.
        let sd = posterior(&a, &b, &band, StepPattern::Symmetric2, 0.01)
            .unwrap()
            .sd;
        assert!(sd[3..=6].iter().all(|&v| v > 0.5), "{sd:?}");
        assert!(sd[..2].iter().chain(&sd[8..]).all(|&v| v < 0.01), "{sd:?}");
    }

    #[test]
    fn posterior_of_a_sequence_against_itself_is_the_identity() {
        let v: Vec<f64> = (0..30).map(|k| (k as f64 * 0.3).sin() + k as f64 * 0.1).collect();
        let a = seq(&v);
        for step in [
            StepPattern::Symmetric1,
            StepPattern::Symmetric2,
            StepPattern::Asymmetric,
        ] {
            let post = posterior(&a, &a, &Band::around_diagonal(30, 30, 6), step, 0.05).unwrap();
            assert_eq!(post.medians, (0..30).collect::<Vec<_>>(), "{step:?}");
            // A colder posterior is surer of each partner.
            let sharp = posterior(&a, &a, &Band::around_diagonal(30, 30, 6), step, 0.005).unwrap();
            assert!(sharp.mean_sd() < 0.5 * post.mean_sd(), "{step:?}");
        }
    }

    #[test]
    fn a_staircase_is_a_connected_monotone_path_through_each_rows_column() {
        assert_eq!(
            staircase(&[0, 2, 2, 3], 6),
            [(0, 0), (1, 1), (1, 2), (2, 2), (3, 3), (3, 4), (3, 5)]
        );
        assert_eq!(staircase(&[1, 1], 2), [(0, 0), (0, 1), (1, 1)]);
        assert_eq!(staircase(&[0], 3), [(0, 0), (0, 1), (0, 2)]);
    }

    #[test]
    fn posterior_refuses_a_bad_temperature_or_band() {
        let a = seq(&[0.0, 1.0, 2.0]);
        for t in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(posterior(&a, &a, &Band::full(3, 3), StepPattern::Symmetric2, t).is_err());
        }
        let long = seq(&[0.0; 9]);
        let err = posterior(&a, &long, &Band::absolute(3, 9, 0), StepPattern::Asymmetric, 1.0);
        assert!(err.unwrap_err().to_string().contains("no warping path"));
    }
}
