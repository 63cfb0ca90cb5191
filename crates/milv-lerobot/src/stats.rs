//! LeRobot's per-feature statistics (`meta/stats.json`): min, max, mean, std, count and
//! the quantiles q01, q10, q50, q90, q99.
//!
//! Unlike LeRobot, which averages per-episode histogram quantiles, the quantiles here are
//! exact over the whole selection (numpy's default linear interpolation), and mean/std
//! are the population values in f64. Image features follow LeRobot: per channel over the
//! sampled frames' pixels, divided by 255, shaped `[3, 1, 1]`.

use std::collections::BTreeMap;

use serde_json::{Value, json};

/// The quantiles LeRobot stores, with their keys.
pub const QUANTILES: [(f64, &str); 5] = [
    (0.01, "q01"),
    (0.10, "q10"),
    (0.50, "q50"),
    (0.90, "q90"),
    (0.99, "q99"),
];

/// Numpy's `quantile(..., method="linear")` of sorted values.
fn quantile_sorted(sorted: &[f32], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    let (a, b) = (f64::from(sorted[lo]), f64::from(sorted[hi]));
    a + (b - a) * (pos - lo as f64)
}

/// Statistics of a vector feature (a scalar one is a vector of width 1).
#[derive(Clone, Debug, Default)]
pub struct VectorStats {
    /// Per component, every value (for exact quantiles; a few bytes per frame).
    values: Vec<Vec<f32>>,
    sum: Vec<f64>,
    sumsq: Vec<f64>,
    count: u64,
}

impl VectorStats {
    pub fn push(&mut self, v: &[f32]) {
        if self.values.is_empty() {
            self.values = vec![Vec::new(); v.len()];
            self.sum = vec![0.0; v.len()];
            self.sumsq = vec![0.0; v.len()];
        }
        for (i, &x) in v.iter().enumerate().take(self.values.len()) {
            self.values[i].push(x);
            self.sum[i] += f64::from(x);
            self.sumsq[i] += f64::from(x) * f64::from(x);
        }
        self.count += 1;
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    /// The LeRobot JSON object (`{"min": [...], ..., "count": [n]}`).
    pub fn to_json(&self) -> Value {
        let n = self.count.max(1) as f64;
        let mean: Vec<f64> = self.sum.iter().map(|s| s / n).collect();
        let std: Vec<f64> = self
            .sumsq
            .iter()
            .zip(&mean)
            .map(|(sq, m)| (sq / n - m * m).max(0.0).sqrt())
            .collect();
        let mut sorted = self.values.clone();
        for s in &mut sorted {
            s.sort_by(f32::total_cmp);
        }
        let mut o = serde_json::Map::new();
        o.insert(
            "min".into(),
            json!(
                sorted
                    .iter()
                    .map(|s| s.first().map_or(0.0, |&x| f64::from(x)))
                    .collect::<Vec<_>>()
            ),
        );
        o.insert(
            "max".into(),
            json!(
                sorted
                    .iter()
                    .map(|s| s.last().map_or(0.0, |&x| f64::from(x)))
                    .collect::<Vec<_>>()
            ),
        );
        o.insert("mean".into(), json!(mean));
        o.insert("std".into(), json!(std));
        o.insert("count".into(), json!([self.count]));
        for (q, key) in QUANTILES {
            o.insert(
                key.into(),
                json!(sorted.iter().map(|s| quantile_sorted(s, q)).collect::<Vec<_>>()),
            );
        }
        Value::Object(o)
    }
}

/// Statistics of an RGB image feature: a 256-bin histogram per channel, which gives every
/// statistic exactly.
#[derive(Clone, Debug)]
pub struct ImageStats {
    hist: [[u64; 256]; 3],
    frames: u64,
}

impl Default for ImageStats {
    fn default() -> Self {
        ImageStats {
            hist: [[0; 256]; 3],
            frames: 0,
        }
    }
}

impl ImageStats {
    /// Adds one RGB24 frame.
    pub fn push(&mut self, rgb: &[u8]) {
        for px in rgb.chunks_exact(3) {
            for (h, &v) in self.hist.iter_mut().zip(px) {
                h[v as usize] += 1;
            }
        }
        self.frames += 1;
    }

    pub fn merge(&mut self, other: &ImageStats) {
        for (a, b) in self.hist.iter_mut().zip(&other.hist) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
        self.frames += other.frames;
    }

    /// The value of order statistic `k` (0-based) of channel `c`.
    fn order_stat(&self, c: usize, k: u64) -> f64 {
        let mut cum = 0;
        for (v, &n) in self.hist[c].iter().enumerate() {
            cum += n;
            if cum > k {
                return v as f64;
            }
        }
        255.0
    }

    pub fn to_json(&self) -> Value {
        let per_channel =
            |f: &dyn Fn(usize) -> f64| json!((0..3).map(|c| vec![vec![f(c) / 255.0]]).collect::<Vec<_>>());
        let n = |c: usize| self.hist[c].iter().sum::<u64>();
        let mean = |c: usize| {
            let s: f64 = self.hist[c]
                .iter()
                .enumerate()
                .map(|(v, &k)| v as f64 * k as f64)
                .sum();
            s / n(c).max(1) as f64
        };
        let std = |c: usize| {
            let m = mean(c);
            let s: f64 = self.hist[c]
                .iter()
                .enumerate()
                .map(|(v, &k)| (v as f64 - m).powi(2) * k as f64)
                .sum();
            (s / n(c).max(1) as f64).sqrt()
        };
        let quantile = |c: usize, q: f64| {
            let total = n(c);
            if total == 0 {
                return 0.0;
            }
            let pos = q * (total - 1) as f64;
            let (lo, hi) = (pos.floor() as u64, pos.ceil() as u64);
            let (a, b) = (self.order_stat(c, lo), self.order_stat(c, hi));
            a + (b - a) * (pos - lo as f64)
        };
        let mut o = serde_json::Map::new();
        o.insert("min".into(), per_channel(&|c| self.order_stat(c, 0)));
        o.insert(
            "max".into(),
            per_channel(&|c| self.order_stat(c, n(c).saturating_sub(1))),
        );
        o.insert("mean".into(), per_channel(&mean));
        o.insert("std".into(), per_channel(&std));
        o.insert("count".into(), json!([self.frames]));
        for (q, key) in QUANTILES {
            o.insert(key.into(), per_channel(&|c| quantile(c, q)));
        }
        Value::Object(o)
    }
}

/// LeRobot's choice of frames for image statistics (`compute_stats.sample_indices`): every
/// frame of a short episode, about `len^0.75` (100..=10000) spread evenly otherwise.
pub fn sample_indices(len: usize) -> Vec<usize> {
    if len == 0 {
        return Vec::new();
    }
    let min = len.min(100);
    let n = ((len as f64).powf(0.75) as usize).clamp(min, 10_000).min(len);
    if n == 1 {
        return vec![0];
    }
    (0..n)
        .map(|i| (i as f64 * (len - 1) as f64 / (n - 1) as f64).round() as usize)
        .collect()
}

/// Statistics of every feature of an export, keyed by feature name.
#[derive(Clone, Debug, Default)]
pub struct DatasetStats {
    pub vectors: BTreeMap<String, VectorStats>,
    pub images: BTreeMap<String, ImageStats>,
}

impl DatasetStats {
    pub fn vector(&mut self, key: &str) -> &mut VectorStats {
        self.vectors.entry(key.to_string()).or_default()
    }

    pub fn image(&mut self, key: &str) -> &mut ImageStats {
        self.images.entry(key.to_string()).or_default()
    }

    /// `meta/stats.json`.
    pub fn to_json(&self) -> Value {
        let mut o = serde_json::Map::new();
        for (k, v) in &self.vectors {
            o.insert(k.clone(), v.to_json());
        }
        for (k, v) in &self.images {
            o.insert(k.clone(), v.to_json());
        }
        Value::Object(o)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn vector_stats_match_numpy() {
        let mut s = VectorStats::default();
        for x in [3.0f32, 1.0, 4.0, 1.0, 5.0] {
            s.push(&[x, -x]);
        }
        let j = s.to_json();
        assert_eq!(j["min"], json!([1.0, -5.0]));
        assert_eq!(j["max"], json!([5.0, -1.0]));
        assert_eq!(j["mean"], json!([2.8, -2.8]));
        // np.std([3,1,4,1,5]) = 1.6
        assert!((j["std"][0].as_f64().unwrap() - 1.6).abs() < 1e-12);
        // np.quantile([1,1,3,4,5], 0.1) = 1.0; 0.9 -> 4.6
        assert!((j["q10"][0].as_f64().unwrap() - 1.0).abs() < 1e-12);
        assert!((j["q90"][0].as_f64().unwrap() - 4.6).abs() < 1e-6);
        assert_eq!(j["count"], json!([5]));
    }

    #[test]
    fn image_stats_are_per_channel_over_255() {
        let mut s = ImageStats::default();
        s.push(&[0, 255, 10, 255, 255, 30]);
        let j = s.to_json();
        assert_eq!(j["min"], json!([[[0.0]], [[1.0]], [[10.0 / 255.0]]]));
        assert_eq!(j["mean"][0][0][0].as_f64().unwrap(), 127.5 / 255.0);
        assert_eq!(j["q50"][2][0][0].as_f64().unwrap(), 20.0 / 255.0);
        assert_eq!(j["count"], json!([1]));
    }

    #[test]
    fn samples_like_lerobot() {
        assert_eq!(sample_indices(5), vec![0, 1, 2, 3, 4]);
        let s = sample_indices(1000);
        // int(1000 ** 0.75) = 177
        assert_eq!((s.len(), s[0], *s.last().unwrap()), (177, 0, 999));
    }
}
