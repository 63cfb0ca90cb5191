//! How well predicted actions follow the true ones. An inverse-dynamics model that has
//! collapsed to a constant can still score an error near the zero predictor's, so next to
//! the error this keeps what exposes a collapse: the correlation with the truth and the
//! spread of the predictions against the spread of the truth.

use serde::{Deserialize, Serialize};

/// Predictions and truths, component by component.
#[derive(Clone, Debug, Default)]
pub struct FitAccumulator {
    pred: Vec<Vec<f64>>,
    truth: Vec<Vec<f64>>,
}

/// The fit of predicted actions to true ones (action units, e.g. cm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActionFit {
    /// Action vectors compared.
    pub frames: usize,
    /// Mean absolute error over frames and components.
    pub mae: f64,
    /// The same for always predicting 0.
    pub mae_zero: f64,
    /// Pearson correlation per component; 0 where either side is constant (a constant
    /// prediction carries no information about the truth).
    pub corr: Vec<f64>,
    /// Standard deviation of the predictions per component.
    pub std: Vec<f64>,
    /// Standard deviation of the truth per component.
    pub std_true: Vec<f64>,
}

impl FitAccumulator {
    pub fn new(dim: usize) -> FitAccumulator {
        FitAccumulator {
            pred: vec![Vec::new(); dim],
            truth: vec![Vec::new(); dim],
        }
    }

    /// One predicted action and its truth (the shorter of the two sets the components).
    pub fn push(&mut self, pred: &[f32], truth: &[f32]) {
        for (j, (p, t)) in pred.iter().zip(truth).enumerate().take(self.pred.len()) {
            self.pred[j].push(f64::from(*p));
            self.truth[j].push(f64::from(*t));
        }
    }

    /// None before anything was pushed.
    pub fn finish(&self) -> Option<ActionFit> {
        let frames = self.pred.first().map_or(0, Vec::len);
        if frames == 0 {
            return None;
        }
        let (mut abs, mut zero, mut n) = (0.0, 0.0, 0usize);
        for (p, t) in self.pred.iter().zip(&self.truth) {
            for (a, b) in p.iter().zip(t) {
                abs += (a - b).abs();
                zero += b.abs();
                n += 1;
            }
        }
        let moments = |x: &[f64]| {
            let m = x.iter().sum::<f64>() / x.len() as f64;
            let var = x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64;
            (m, var.sqrt())
        };
        let (mut corr, mut std, mut std_true) = (Vec::new(), Vec::new(), Vec::new());
        for (p, t) in self.pred.iter().zip(&self.truth) {
            let ((mp, sp), (mt, st)) = (moments(p), moments(t));
            let cov = p.iter().zip(t).map(|(a, b)| (a - mp) * (b - mt)).sum::<f64>() / p.len() as f64;
            // Below this the side is constant up to f32 rounding.
            let tiny = 1e-9;
            corr.push(if sp > tiny && st > tiny {
                cov / (sp * st)
            } else {
                0.0
            });
            std.push(sp);
            std_true.push(st);
        }
        Some(ActionFit {
            frames,
            mae: abs / n as f64,
            mae_zero: zero / n as f64,
            corr,
            std,
            std_true,
        })
    }
}

/// Mean of `x`; 0 when empty.
pub(crate) fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}

impl ActionFit {
    /// Mean correlation over the components.
    pub fn mean_corr(&self) -> f64 {
        mean(&self.corr)
    }

    /// Mean predicted spread over mean true spread (1: as varied as the truth).
    pub fn spread_ratio(&self) -> f64 {
        let t = mean(&self.std_true);
        if t > 0.0 { mean(&self.std) / t } else { 0.0 }
    }

    /// One line for logs: `MAE 0.41 (zero 0.82), corr [0.71, 0.64], spread 0.83× the truth`.
    pub fn summary(&self) -> String {
        let corr: Vec<String> = self.corr.iter().map(|c| format!("{c:.2}")).collect();
        format!(
            "MAE {:.3} (zero {:.3}), corr [{}], spread {:.2}× the truth, {} frames",
            self.mae,
            self.mae_zero,
            corr.join(", "),
            self.spread_ratio(),
            self.frames
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(pairs: &[([f32; 2], [f32; 2])]) -> ActionFit {
        let mut acc = FitAccumulator::new(2);
        for (p, t) in pairs {
            acc.push(p, t);
        }
        acc.finish().expect("pushed")
    }

    const TRUTH: [[f32; 2]; 4] = [[1.0, -2.0], [-1.0, 0.5], [2.0, 1.0], [0.0, -1.0]];

    #[test]
    fn a_perfect_prediction_correlates_fully_and_has_no_error() {
        let f = fit(&TRUTH.map(|t| (t, t)));
        assert_eq!(f.frames, 4);
        assert!(f.mae.abs() < 1e-12);
        assert!((f.mae_zero - 8.5 / 8.0).abs() < 1e-9);
        assert!(f.corr.iter().all(|c| (c - 1.0).abs() < 1e-9), "{:?}", f.corr);
        assert!((f.spread_ratio() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_constant_prediction_has_no_correlation_and_no_spread() {
        let f = fit(&TRUTH.map(|t| ([0.3, 0.3], t)));
        assert_eq!(f.corr, vec![0.0, 0.0]);
        assert_eq!(f.spread_ratio(), 0.0);
        assert!(f.mae > 0.5);
    }

    #[test]
    fn a_negated_scaled_prediction_correlates_minus_one_with_its_spread() {
        let f = fit(&TRUTH.map(|t| ([-0.5 * t[0], -0.5 * t[1]], t)));
        assert!(f.corr.iter().all(|c| (c + 1.0).abs() < 1e-6), "{:?}", f.corr);
        assert!((f.spread_ratio() - 0.5).abs() < 1e-6);
        assert!(f.mean_corr() < -0.99);
    }

    #[test]
    fn nothing_pushed_is_no_fit() {
        assert!(FitAccumulator::new(2).finish().is_none());
    }
}
