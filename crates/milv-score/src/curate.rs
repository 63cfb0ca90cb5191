//! `milv-score curate`: turn a scoring run into the `curated` view the trainer reads.
//!
//! The weight of a frame is the spec's set normalisation over every row of the run
//! (all partitions together): `(b − b_min)/(b_max − b_min) · (ssim + 1)/2`. A rule keeps
//! frames by weight; an episode left with fewer than `min_episode_fraction` of its frames
//! is dropped whole (a meta-learning task needs most of its demonstration). The view
//! replaces the previous one in the same version; older views stay readable at older
//! versions.

use std::collections::BTreeMap;

use milv_data::{CommitMeta, CuratedRow, Dataset, ScoreRow, ShardOptions, TableKind, score_run};
use serde::Serialize;

use crate::{Error, Result, digest};

/// Which frames to keep.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// Frames with `weight >= x`.
    MinWeight(f64),
    /// The best fraction `f` of the run's frames by weight (ties at the cut are kept).
    TopFraction(f64),
}

#[derive(Clone, Debug)]
pub struct CurateOptions {
    /// The scoring run (default: the most recently committed one).
    pub run_id: Option<String>,
    pub rule: Rule,
    /// Drop an episode whose kept fraction of frames is below this.
    pub min_episode_fraction: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct CurateReport {
    /// The version committed, or the read one when the view already was this curation.
    pub version: u64,
    pub read_version: u64,
    pub run_id: String,
    pub curation_id: String,
    pub rule: Rule,
    pub threshold: f64,
    pub brenner_min: f64,
    pub brenner_max: f64,
    pub frames_scored: usize,
    pub frames_kept: usize,
    pub episodes_scored: usize,
    pub episodes_kept: usize,
    pub mean_weight_kept: f64,
    /// The curated view already was this curation: nothing was committed.
    pub unchanged: bool,
}

use milv_quality::set_weight as weight;

/// Curates the latest version's scores and commits the `curated` view.
pub fn curate(ds: &Dataset, opts: &CurateOptions, mut meta: CommitMeta) -> Result<CurateReport> {
    match opts.rule {
        Rule::MinWeight(x) if !x.is_finite() => {
            return Err(Error::Invalid(format!("--min-weight {x} is not a number")));
        }
        Rule::TopFraction(f) if !(f > 0.0 && f <= 1.0) => {
            return Err(Error::Invalid(format!("--top-fraction {f} must be in (0, 1]")));
        }
        _ => {}
    }
    if !(0.0..=1.0).contains(&opts.min_episode_fraction) {
        return Err(Error::Invalid(format!(
            "--min-episode-fraction {} must be in [0, 1]",
            opts.min_episode_fraction
        )));
    }
    let txn = ds.begin(CommitMeta::default())?;
    let v = txn.base_version();
    drop(txn);
    let (run_id, rows) = score_run(ds, v, opts.run_id.as_deref())?;
    let bmin = rows.iter().map(|r| r.brenner).fold(f64::INFINITY, f64::min);
    let bmax = rows.iter().map(|r| r.brenner).fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = rows
        .iter()
        .map(|r| weight(r.brenner, r.ssim, bmin, bmax))
        .collect();
    let threshold = match opts.rule {
        Rule::MinWeight(x) => x,
        Rule::TopFraction(f) => {
            let mut sorted = w.clone();
            sorted.sort_by(|a, b| b.total_cmp(a));
            let k = ((f * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
            sorted[k - 1]
        }
    };
    let mut by_ep: BTreeMap<&str, Vec<(&ScoreRow, f64)>> = BTreeMap::new();
    for (r, &wt) in rows.iter().zip(&w) {
        by_ep.entry(r.episode_id.as_str()).or_default().push((r, wt));
    }
    let episodes_scored = by_ep.len();
    let kept: BTreeMap<&str, Vec<(&ScoreRow, f64)>> = by_ep
        .into_iter()
        .filter_map(|(id, frames)| {
            let n = frames.len();
            let k: Vec<_> = frames.into_iter().filter(|(_, wt)| *wt >= threshold).collect();
            (!k.is_empty() && k.len() as f64 >= opts.min_episode_fraction * n as f64).then_some((id, k))
        })
        .collect();
    if kept.is_empty() {
        return Err(Error::EmptySelection(format!(
            "no episode keeps enough frames at weight >= {threshold:.6} (min episode fraction {})",
            opts.min_episode_fraction
        )));
    }
    let rule_s = serde_json::to_string(&opts.rule).unwrap_or_default();
    let curation_id = digest(&[
        "milv-score/curate/1",
        &run_id,
        &rule_s,
        &opts.min_episode_fraction.to_string(),
    ]);
    let frames_kept: usize = kept.values().map(Vec::len).sum();
    let mean_weight_kept = kept.values().flatten().map(|(_, w)| w).sum::<f64>() / frames_kept as f64;
    let mut report = CurateReport {
        version: v,
        read_version: v,
        run_id: run_id.clone(),
        curation_id: curation_id.clone(),
        rule: opts.rule,
        threshold,
        brenner_min: bmin,
        brenner_max: bmax,
        frames_scored: rows.len(),
        frames_kept,
        episodes_scored,
        episodes_kept: kept.len(),
        mean_weight_kept,
        unchanged: false,
    };
    // Curating the same run with the same rule again is a no-op.
    if milv_data::read::curations(ds, v)? == [curation_id.clone()].into() {
        report.unchanged = true;
        return Ok(report);
    }
    meta.summary = serde_json::to_value(&report).unwrap_or_default();
    let mut txn = ds.begin(meta)?;
    let old: Vec<String> = ds
        .files(TableKind::Curated, v)?
        .into_iter()
        .map(|f| f.info.path)
        .collect();
    txn.remove_files(TableKind::Curated, old, Vec::new());
    let params = serde_json::json!({"curation_id": curation_id, "run_id": run_id, "threshold": threshold,
        "brenner_min": bmin, "brenner_max": bmax, "rule": opts.rule, "min_episode_fraction": opts.min_episode_fraction});
    let shard = ShardOptions {
        file_metadata: vec![("milv.curation".into(), params.to_string())],
        ..ShardOptions::default()
    };
    report.version = txn.write_and_commit(TableKind::Curated, None, shard, |w| -> Result<()> {
        for (id, frames) in &kept {
            w.group(id, &curated_rows(id, frames, &run_id, &curation_id))?;
        }
        Ok(())
    })?;
    Ok(report)
}

/// The `curated` rows of one episode's kept frames.
fn curated_rows(id: &str, frames: &[(&ScoreRow, f64)], run_id: &str, curation_id: &str) -> Vec<CuratedRow> {
    frames
        .iter()
        .map(|(r, w)| CuratedRow {
            episode_id: id.to_string(),
            frame_index: r.frame_index,
            weight: *w,
            source_table: r.source_table.clone(),
            model_id: r.model_id.clone(),
            run_id: run_id.to_string(),
            curation_id: curation_id.to_string(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_follows_the_spec() {
        assert_eq!(weight(0.5, 1.0, 0.0, 1.0), 0.5);
        assert_eq!(weight(0.25, 0.5, 0.0, 1.0), 0.25 * 0.75);
        assert_eq!(weight(0.01, 0.0, 0.01, 0.03), 0.0);
        assert_eq!(weight(0.03, -1.0, 0.01, 0.03), 0.0);
        assert_eq!(weight(0.02, 0.5, 0.02, 0.02), 0.75);
    }
}
