//! Is a translator's imagined data worth imitating? A meta-policy trained on imagined
//! actions that do not follow the true ones imitates a constant, whatever the meta-learner
//! does, so this is checked before training:
//! - with ground truth (milv-sim's `ground_truth.jsonl` pairs each human demo with the robot
//!   demo of the same states), the imagined actions must correlate with the true robot
//!   actions (mean over components ≥ [`MIN_CORRELATION`]); below, training is refused;
//! - without, their spread must be at least [`MIN_SPREAD_OF_RANDOM`] of the robot random
//!   videos' (the data π_I trained on); below, a warning.

use std::collections::BTreeMap;
use std::path::Path;

use milv_data::{Dataset, Domain, Episode, Kind as EpisodeKind, Split, ops};
use serde::Serialize;

use crate::Result;
use crate::gan::eval::truth_pairs;
use crate::meta::tasks::MetaSet;
use crate::run::fit::{ActionFit, FitAccumulator, mean};
use crate::run::image::load_clips;

/// Below this mean correlation with the true actions a translator is refused.
pub const MIN_CORRELATION: f64 = 0.5;
/// Below this share of the robot random videos' spread a translator is warned about.
pub const MIN_SPREAD_OF_RANDOM: f64 = 0.25;

#[derive(Clone, Debug, Serialize)]
pub struct ImaginedCheck {
    /// Imagined actions of the training human demos against their true robot actions.
    pub fit: Option<ActionFit>,
    /// Standard deviation per component of the imagined actions the policy trains on.
    pub imagined_std: Vec<f64>,
    /// The same for the robot random videos' actions.
    pub random_std: Vec<f64>,
}

/// What the check found wrong.
#[derive(Clone, Debug, PartialEq)]
pub enum Problem {
    /// Ground truth says the imagined actions do not follow the true ones: refuse.
    Uncorrelated(String),
    /// No ground truth, and the imagined actions barely vary: warn.
    NarrowSpread(String),
}

impl ImaginedCheck {
    pub fn problem(&self) -> Option<Problem> {
        if let Some(fit) = &self.fit {
            return (fit.mean_corr() < MIN_CORRELATION).then(|| {
                Problem::Uncorrelated(format!(
                    "the imagined actions correlate {:.2} with the true robot actions (at least {MIN_CORRELATION} \
                     needed): {}",
                    fit.mean_corr(),
                    fit.summary()
                ))
            });
        }
        let (ours, random) = (mean(&self.imagined_std), mean(&self.random_std));
        (random > 0.0 && ours < MIN_SPREAD_OF_RANDOM * random).then(|| {
            Problem::NarrowSpread(format!(
                "the imagined actions' spread ({ours:.3}) is under {MIN_SPREAD_OF_RANDOM} of the robot random \
                 videos' ({random:.3})"
            ))
        })
    }
}

/// Checks the imagined actions `set` (an imagined-data variant) read from version `v`;
/// `truth` is a ground-truth pairs file (see [`truth_pairs`]).
pub fn check_imagined(ds: &Dataset, v: u64, set: &MetaSet, truth: Option<&Path>) -> Result<ImaginedCheck> {
    let eps = ops::episodes(ds, v)?;
    let pick = |keep: &dyn Fn(&Episode) -> bool| -> BTreeMap<String, Episode> {
        eps.iter()
            .filter(|e| keep(e))
            .map(|e| (e.episode_id.clone(), e.clone()))
            .collect()
    };
    let dim = set.action_dim.max(1) as usize;
    let fit = match truth {
        None => None,
        Some(path) => {
            let imagined: BTreeMap<&str, &crate::meta::tasks::Sequence> =
                set.seqs.iter().map(|s| (s.episode_id.as_str(), s)).collect();
            let pairs: BTreeMap<String, String> = truth_pairs(&eps, path)?
                .into_iter()
                .filter(|(h, _)| imagined.contains_key(h.as_str()))
                .map(|(h, r)| (r, h))
                .collect();
            let robots = load_clips(ds, v, &pick(&|e| pairs.contains_key(&e.episode_id)), true)?;
            let mut acc = FitAccumulator::new(dim);
            for (r, h) in &pairs {
                let (Some(clip), Some(seq)) = (robots.get(r), imagined.get(h.as_str())) else {
                    continue;
                };
                let (Some(truth), Some(pred)) = (&clip.actions, &seq.actions) else {
                    continue;
                };
                let pred: Vec<f32> = Vec::try_from(pred.contiguous().view([-1]))?;
                // The last imagined action compares a frame with itself: skip it.
                let n = truth.len().min(pred.len() / dim).saturating_sub(1);
                for (t, true_action) in truth.iter().enumerate().take(n) {
                    acc.push(&pred[t * dim..(t + 1) * dim], true_action);
                }
            }
            acc.finish()
        }
    };
    let randoms = pick(&|e| {
        e.domain == Domain::Robot
            && e.kind == EpisodeKind::Random
            && e.split == Split::Train
            && e.action_dim.unwrap_or(0) > 0
    });
    let mut spread = FitAccumulator::new(dim);
    for clip in load_clips(ds, v, &randoms, true)?.into_values() {
        for a in clip.actions.iter().flatten() {
            spread.push(a, a);
        }
    }
    Ok(ImaginedCheck {
        fit,
        imagined_std: set.action_std.clone(),
        random_std: spread.finish().map(|f| f.std_true).unwrap_or_default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(corr: f64) -> ActionFit {
        ActionFit {
            frames: 10,
            mae: 0.5,
            mae_zero: 0.8,
            corr: vec![corr, corr],
            std: vec![0.5, 0.5],
            std_true: vec![1.0, 1.0],
        }
    }

    #[test]
    fn ground_truth_refuses_uncorrelated_actions_and_passes_correlated_ones() {
        let check = |f: Option<ActionFit>, imagined: f64| ImaginedCheck {
            fit: f,
            imagined_std: vec![imagined; 2],
            random_std: vec![1.0; 2],
        };
        assert!(matches!(
            check(Some(fit(0.3)), 1.0).problem(),
            Some(Problem::Uncorrelated(_))
        ));
        // Ground truth decides even when the spread looks healthy, and vice versa.
        assert_eq!(check(Some(fit(0.7)), 0.01).problem(), None);
        assert!(matches!(
            check(None, 0.1).problem(),
            Some(Problem::NarrowSpread(_))
        ));
        assert_eq!(check(None, 0.3).problem(), None);
        // No random videos: nothing to compare the spread with.
        let mut no_random = check(None, 0.0);
        no_random.random_std.clear();
        assert_eq!(no_random.problem(), None);
    }
}
