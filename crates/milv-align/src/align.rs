//! Aligning every pair of a dataset version and committing the `alignments` table.

use std::collections::{BTreeMap, BTreeSet};

use milv_data::{
    AlignmentRow, CommitMeta, Dataset, Domain, Episode, Partition, ShardOptions, TableKind, ops,
};
use rayon::prelude::*;
use serde::Serialize;

use crate::dtw::{Alignment, Band, StepPattern, dtw, posterior, row_to_col, staircase};
use crate::features::{Clip, ClipSource, FeatureKind, Stage};
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct AlignOptions {
    /// Sakoe–Chiba half-width as a fraction of the longer clip.
    pub band: f64,
    /// Widest band a pair is re-aligned in, [`BAND_STEP`] wider at a time, while its path
    /// runs along the band's edge (at most `band`: never widened).
    pub max_band: f64,
    pub step: StepPattern,
    /// Translation model for `translated` features (default: the only one).
    pub model_id: Option<String>,
    /// Only these pairs.
    pub pairs: Option<BTreeSet<String>>,
    pub partition: Option<Partition>,
    /// A pair is flagged untrusted above this normalised cost per feature dimension
    /// (default: [`FeatureKind::untrusted_cost`] of the kind that aligned the pair).
    pub max_cost: Option<f64>,
    /// Ground truth per pair (human frame → robot frame), e.g. milv-sim's warps.jsonl.
    pub truth: BTreeMap<String, Vec<usize>>,
    /// Each frame's partner is its median over warping paths weighted by
    /// `exp(−cost / T)`, with `T` this many times the best path's mean local cost
    /// ([`posterior`]); 0 takes the best path's cells (classic DTW).
    pub temperature: f64,
    /// A pair whose decoded warp lies within this many posterior standard deviations of
    /// the proportional warp (both averaged over the human frames) takes the proportional
    /// warp: its features cannot tell the two apart. 0 (the default): never. It trades
    /// mean accuracy for matching the proportional warp where unsure (measured in
    /// BENCHMARKS.md, "The proportional warp where the features cannot tell").
    pub proportional_within: f64,
}

impl AlignOptions {
    /// The widest band a pair may be aligned in: `max_band`, or `band` if that is wider.
    pub fn widest_band(&self) -> f64 {
        self.max_band.max(self.band)
    }

    /// Refuses a band or temperature outside its range, naming the option.
    pub fn validate(&self) -> Result<()> {
        if !(self.band > 0.0 && self.band <= 1.0) {
            return Err(Error::Invalid(format!("--band {} must be in (0, 1]", self.band)));
        }
        if !(self.max_band > 0.0 && self.max_band <= 1.0) {
            return Err(Error::Invalid(format!(
                "--max-band {} must be in (0, 1]",
                self.max_band
            )));
        }
        if !(self.temperature >= 0.0 && self.temperature.is_finite()) {
            return Err(Error::Invalid(format!(
                "--temperature {} must be 0 (the best path) or positive",
                self.temperature
            )));
        }
        if !(self.proportional_within >= 0.0 && self.proportional_within.is_finite()) {
            return Err(Error::Invalid(format!(
                "--proportional-within {} must be 0 (never) or positive",
                self.proportional_within
            )));
        }
        Ok(())
    }
}

/// Default [`AlignOptions::max_band`]: on the MuJoCo set, where warps reach 28 frames of
/// 80, the paths of 16 of 80 pairs ran along the edge of a band of 0.2; widened, 13 of them
/// align better (BENCHMARKS.md, "A band that widens where the path runs along its edge").
pub const MAX_BAND: f64 = 0.4;
/// How much wider each re-alignment's band is.
pub const BAND_STEP: f64 = 0.1;
/// Share of a path's cells on the band's edge above which the band may have cut it off.
pub const EDGE_MAX: f64 = 0.1;

/// Default [`AlignOptions::temperature`]: a path whose cost exceeds the best one's by 20
/// of its average cells weighs 1/e as much. Chosen on the design seeds (BENCHMARKS.md).
pub const POSTERIOR_TEMPERATURE: f64 = 20.0;

impl Default for AlignOptions {
    fn default() -> Self {
        AlignOptions {
            band: 0.2,
            max_band: MAX_BAND,
            step: StepPattern::Symmetric2,
            model_id: None,
            pairs: None,
            partition: None,
            max_cost: None,
            truth: BTreeMap::new(),
            temperature: POSTERIOR_TEMPERATURE,
            proportional_within: 0.0,
        }
    }
}

/// How one pair aligned.
#[derive(Clone, Debug, Serialize)]
pub struct PairSummary {
    pub pair_id: String,
    pub human_episode_id: String,
    pub robot_episode_id: String,
    pub human_frames: usize,
    pub robot_frames: usize,
    /// The kind of features that aligned the pair (for `auto`, the one it picked).
    pub features: String,
    /// Accumulated cost over the step pattern's normaliser.
    pub normalized_cost: f64,
    /// `normalized_cost` per feature dimension (comparable across feature kinds).
    pub cost_per_dim: f64,
    pub path_length: usize,
    /// Share of path cells on the band's edge (the band may have cut off the true path).
    pub band_edge_fraction: f64,
    /// The band the pair was aligned in: `--band`, widened up to `--max-band` while the
    /// path ran along its edge.
    pub band: f64,
    /// False when the cost is high or the path hugs the band: do not train on it blindly.
    pub trusted: bool,
    /// Against ground truth, when given: mean and max |recovered − true| robot frame.
    pub mean_frame_error: Option<f64>,
    pub max_frame_error: Option<usize>,
    /// The baseline beside them: the same errors of the proportional warp (robot frame
    /// `round(i · (m − 1) / (n − 1))`), which any feature has to beat.
    pub proportional_mean_error: Option<f64>,
    pub proportional_max_error: Option<usize>,
    /// Mean over the human frames of the posterior standard deviation of each frame's
    /// partner (robot frames; [`crate::Posterior::sd`]); none where the best path was
    /// decoded (`--temperature 0`, or a best path that costs nothing).
    pub posterior_sd: Option<f64>,
    /// Whether the pair took the proportional warp ([`AlignOptions::proportional_within`]).
    pub proportional: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct PairError {
    pub pair_id: String,
    pub message: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct AlignReport {
    pub read_version: u64,
    pub version: u64,
    pub run_id: String,
    pub features: String,
    pub pairs: Vec<PairSummary>,
    pub failed: Vec<PairError>,
    pub rows: u64,
    /// Mean of the pairs' mean frame errors (with ground truth).
    pub mean_frame_error: Option<f64>,
    pub max_frame_error: Option<usize>,
    /// The proportional warp's mean error over the same pairs (the baseline).
    pub proportional_mean_error: Option<f64>,
    /// Trusted pairs that came out worse than the proportional warp: what a user would
    /// train on without being warned.
    pub trusted_worse_than_proportional: Vec<String>,
    /// Pairs this run had already aligned (a re-run is a no-op).
    pub already_aligned: usize,
}

/// The two episodes of each pair, or why the pair is unusable.
fn pairs_of(episodes: &[Episode]) -> BTreeMap<String, std::result::Result<(Episode, Episode), String>> {
    let mut by_pair: BTreeMap<String, Vec<&Episode>> = BTreeMap::new();
    for e in episodes {
        if let Some(p) = &e.pair_id {
            by_pair.entry(p.clone()).or_default().push(e);
        }
    }
    by_pair
        .into_iter()
        .map(|(p, eps)| {
            let r = match eps.as_slice() {
                [a, b] => {
                    let (h, r) = if a.domain == Domain::Human { (a, b) } else { (b, a) };
                    if h.domain != Domain::Human || r.domain != Domain::Robot {
                        Err(format!(
                            "both episodes are {} (a pair needs one human and one robot)",
                            a.domain
                        ))
                    } else {
                        Ok(((*h).clone(), (*r).clone()))
                    }
                }
                [one] => Err(format!(
                    "only a {} episode ({}): its {} episode is missing",
                    one.domain,
                    one.episode_id,
                    one.domain.other()
                )),
                many => Err(format!(
                    "{} episodes share this pair id (a pair needs exactly 2)",
                    many.len()
                )),
            };
            (p, r)
        })
        .collect()
}

/// Reads the clips of `wanted` episodes from `table` (frames, or imagined of `model`).
fn load_clips(
    ds: &Dataset,
    v: u64,
    table: TableKind,
    model: Option<&str>,
    wanted: &BTreeMap<String, &Episode>,
) -> Result<BTreeMap<String, Clip>> {
    let imagined = table == TableKind::Imagined;
    let vector = (!imagined).then_some("state");
    let rows = milv_data::episode_rows(ds, v, table, &|id| wanted.contains_key(id), vector, model)?;
    Ok(rows
        .into_iter()
        .map(|(id, r)| {
            let ep = wanted[&id];
            let clip = Clip {
                episode_id: id.clone(),
                domain: ep.domain,
                encoding: ep.frame_encoding,
                // Imagined frames are PNGs of the model's size: decode without a size check.
                width: if imagined { 0 } else { ep.width as u32 },
                height: if imagined { 0 } else { ep.height as u32 },
                states: r.all_vectors(),
                images: r.images,
                motion_cache: Default::default(),
                points_cache: Default::default(),
            };
            (id, clip)
        })
        .collect())
}

/// The only translation model of the imagined table, or the one asked for.
fn resolve_model(ds: &Dataset, v: u64, wanted: Option<&str>) -> Result<String> {
    match milv_data::resolve_model(ds, v, wanted)? {
        Some((m, _)) => Ok(m),
        None => Err(Error::Invalid(format!(
            "--features translated needs translated human frames, and version {v} has no imagined rows \
             (run `milv-train translate` first)"
        ))),
    }
}

/// The Sakoe–Chiba band for clips of `n` and `m` frames, its half-width `band` of the
/// longer clip.
fn band_for(n: usize, m: usize, band: f64) -> Band {
    Band::around_diagonal(n, m, (band * n.max(m) as f64).ceil() as usize)
}

/// DTW of two feature matrices in a band `band` wide, with the run's step pattern.
fn banded_dtw(a: &crate::Features, b: &crate::Features, band: f64, opts: &AlignOptions) -> Result<Alignment> {
    dtw(a, b, &band_for(a.n, b.n, band), opts.step, true)
}

/// One pair aligned: the best path, both clips' features (the robot's fitted to the
/// human's), the share of path cells on the band's edge, and the kind that aligned it.
pub struct PairFit<'k> {
    /// The best warping path (its cost rates the pair).
    pub alignment: Alignment,
    pub human: crate::Features,
    pub robot: crate::Features,
    pub band_edge: f64,
    /// The band it was aligned in (fraction of the longer clip).
    pub band: f64,
    pub kind: &'k dyn FeatureKind,
}

impl PairFit<'_> {
    /// Normalised cost per feature dimension (comparable across feature kinds).
    pub fn cost_per_dim(&self) -> f64 {
        self.alignment.normalized / self.human.d.max(1) as f64
    }

    /// Whether the features explain the pair: cost within `max_cost` (default: its kind's).
    pub fn explained(&self, max_cost: Option<f64>) -> bool {
        self.cost_per_dim() <= max_cost.unwrap_or_else(|| self.kind.untrusted_cost())
    }

    /// Whether the alignment can be trusted: explained, and its path off the band's edge
    /// (a path along the edge may have been cut short by the band).
    pub fn trusted(&self, max_cost: Option<f64>) -> bool {
        self.explained(max_cost) && self.band_edge <= EDGE_MAX
    }

    /// Each frame's partner, decoded from the best path by posterior medians at
    /// `opts.temperature`, or the proportional warp where that lies within
    /// `opts.proportional_within` posterior standard deviations of them; when the
    /// temperature is 0, or the best path costs nothing (it explains the pair exactly), the
    /// best path itself with each row's rounded mean column. (Only for the fit a run
    /// keeps: `auto` discards the others undecoded.)
    pub fn correspondence(&self, opts: &AlignOptions) -> Result<Correspondence> {
        let (h, r, al) = (&self.human, &self.robot, &self.alignment);
        let mean_local = al.local.iter().sum::<f64>() / al.local.len().max(1) as f64;
        let t = opts.temperature * mean_local;
        if !(t > 0.0 && t.is_finite()) {
            return Ok(Correspondence {
                human_to_robot: row_to_col(&al.path, h.n),
                cells: al
                    .path
                    .iter()
                    .zip(&al.local)
                    .map(|(&(i, j), &c)| (i, j, c))
                    .collect(),
                posterior_sd: None,
                proportional: false,
            });
        }
        let post = posterior(h, r, &band_for(h.n, r.n, self.band), opts.step, t)?;
        let sd = post.mean_sd();
        let prop = proportional_warp(h.n, r.n);
        let proportional = frame_errors(&post.medians, &prop)
            .0
            .is_some_and(|gap| gap < opts.proportional_within * sd);
        let rows = if proportional { prop } else { post.medians };
        let cells = staircase(&rows, r.n)
            .into_iter()
            .map(|(i, j)| (i, j, crate::dtw::sq_dist(h.row(i), r.row(j))))
            .collect();
        Ok(Correspondence {
            human_to_robot: rows,
            cells,
            posterior_sd: Some(sd),
            proportional,
        })
    }
}

/// Aligns one pair's clips with `kind`, or, for a kind that picks per pair
/// ([`FeatureKind::cascade`]), with the first of its stages whose cost stays within its
/// bound and explains the pair ([`PairFit::explained`]), replaced by its
/// [`unless_trusted`](crate::features::Stage::unless_trusted) kinds' lowest-cost trusted
/// alignment, if any, else by its [`aligned_by`](crate::features::Stage::aligned_by) kind's
/// where trusted; when no stage's kind explains the pair within its bound, the first that
/// explains it (again by its `aligned_by` kind's where trusted), else the last that aligned
/// it at all (so a pair is not flagged for the sake of a kind that explains it worse). The band's edge plays no part in the cascade:
/// a strong warp puts any kind's path near the edge (each kind widens its own band).
fn align_pair<'k>(
    kind: &'k dyn FeatureKind,
    human: &Clip,
    robot: &Clip,
    opts: &AlignOptions,
) -> std::result::Result<PairFit<'k>, String> {
    let cascade = kind.cascade();
    if cascade.is_empty() {
        return align_with(kind, human, robot, opts);
    }
    // A kept stage's alignment, replaced by its aligned_by kind's where that is trusted.
    let again = |stage: &Stage, fit: PairFit<'k>| {
        stage
            .aligned_by
            .and_then(|k| align_with(k, human, robot, opts).ok())
            .filter(|f| f.trusted(opts.max_cost))
            .unwrap_or(fit)
    };
    let (mut fits, mut errors) = (Vec::new(), Vec::new());
    for stage in cascade {
        match align_with(stage.kind, human, robot, opts) {
            Ok(fit) if fit.cost_per_dim() <= stage.keep_below && fit.explained(opts.max_cost) => {
                let better = stage
                    .unless_trusted
                    .iter()
                    .filter_map(|&k| align_with(k, human, robot, opts).ok())
                    .filter(|f| f.trusted(opts.max_cost))
                    .min_by(|a, b| a.cost_per_dim().total_cmp(&b.cost_per_dim()));
                return Ok(better.unwrap_or_else(|| again(stage, fit)));
            }
            Ok(fit) => fits.push((stage, fit)),
            Err(e) => errors.push(format!("{}: {e}", stage.kind.name())),
        }
    }
    match fits.iter().position(|(_, f)| f.explained(opts.max_cost)) {
        Some(i) => {
            let (stage, fit) = fits.swap_remove(i);
            Ok(again(stage, fit))
        }
        None => fits.pop().map(|(_, f)| f).ok_or_else(|| errors.join("; ")),
    }
}

/// What a pair's alignment says about its frames.
#[derive(Clone, Debug, PartialEq)]
pub struct Correspondence {
    /// Each human frame's robot frame.
    pub human_to_robot: Vec<usize>,
    /// A monotone path of unit steps from the first frames to the last through every
    /// human frame's robot frame, each cell with its local cost: the rows of the
    /// `alignments` table (every frame of both clips has a partner).
    pub cells: Vec<(usize, usize, f64)>,
    /// [`PairSummary::posterior_sd`].
    pub posterior_sd: Option<f64>,
    /// [`PairSummary::proportional`].
    pub proportional: bool,
}

/// Aligns one pair's clips on one kind of features, in the run's band or, where the path
/// runs along its edge, a wider one (up to [`AlignOptions::max_band`]).
fn align_with<'k>(
    kind: &'k dyn FeatureKind,
    human: &Clip,
    robot: &Clip,
    opts: &AlignOptions,
) -> std::result::Result<PairFit<'k>, String> {
    for c in [human, robot] {
        if c.images.len() < 2 {
            return Err(format!(
                "episode {} has {} frame(s); aligning needs at least 2",
                c.episode_id,
                c.images.len()
            ));
        }
    }
    let h = kind.extract(human).map_err(|e| e.to_string())?;
    let r = kind.extract(robot).map_err(|e| e.to_string())?;
    // A path along the band's edge may have been cut short by it: the clips' warp is
    // stronger than the band allows, so the pair is aligned again in a wider one.
    let mut fit = fit_in_band(kind, &h, r.clone(), opts.band, opts)?;
    loop {
        // Rounded: 0.2 + 0.1 is 0.30000000000000004 in floating point, a column more than
        // 0.3 of 80 frames.
        let wider = (((fit.band + BAND_STEP) * 1e9).round() / 1e9).min(opts.widest_band());
        if fit.band_edge <= EDGE_MAX || wider <= fit.band + 1e-9 {
            return Ok(fit);
        }
        // A wider band that cannot be aligned in leaves the narrower one's fit.
        match fit_in_band(kind, &h, r.clone(), wider, opts) {
            Ok(next) => fit = next,
            Err(_) => return Ok(fit),
        }
    }
}

/// Fits the robot's features to the human's and aligns them in a band `band` wide.
fn fit_in_band<'k>(
    kind: &'k dyn FeatureKind,
    h: &crate::Features,
    r: crate::Features,
    band: f64,
    opts: &AlignOptions,
) -> std::result::Result<PairFit<'k>, String> {
    let h = h.clone();
    let r = kind.fit_pair(&h, r, &|a, b| {
        banded_dtw(a, b, band, opts)
            .ok()
            .map(|al| row_to_col(&al.path, a.n))
    });
    if h.d != r.d {
        return Err(format!("feature widths differ: human {} and robot {}", h.d, r.d));
    }
    let b = band_for(h.n, r.n, band);
    let al = dtw(&h, &r, &b, opts.step, true).map_err(|e| e.to_string())?;
    // The first and last columns are every path's, not the band's limit.
    let edge = al
        .path
        .iter()
        .filter(|&&(i, j)| b.on_edge(i, j) && j != 0 && j != r.n - 1)
        .count() as f64
        / al.path.len() as f64;
    Ok(PairFit {
        alignment: al,
        human: h,
        robot: r,
        band_edge: edge,
        band,
        kind,
    })
}

/// Loads and aligns one pair (for `milv-align show`).
pub fn load_pair<'k>(
    ds: &Dataset,
    version: Option<u64>,
    pair_id: &str,
    kind: &'k dyn FeatureKind,
    opts: &AlignOptions,
) -> Result<PairFit<'k>> {
    opts.validate()?;
    let v = ds.resolve(version)?;
    let eps = ops::episodes(ds, v)?;
    let pairs = pairs_of(&eps);
    let (h, r) = pairs
        .get(pair_id)
        .ok_or_else(|| Error::Invalid(format!("no pair {pair_id} at version {v}")))?
        .clone()
        .map_err(|m| Error::Invalid(format!("pair {pair_id}: {m}")))?;
    let model = match kind.human_source() {
        ClipSource::Imagined => Some(resolve_model(ds, v, opts.model_id.as_deref())?),
        ClipSource::Frames => None,
    };
    let (hc, rc) = clips_for(ds, v, kind, model.as_deref(), &[(&h, &r)])?;
    let (hc, rc) = (
        hc.get(&h.episode_id)
            .ok_or_else(|| Error::Invalid(format!("episode {} has no frames", h.episode_id)))?,
        rc.get(&r.episode_id)
            .ok_or_else(|| Error::Invalid(format!("episode {} has no frames", r.episode_id)))?,
    );
    align_pair(kind, hc, rc, opts).map_err(|m| Error::Invalid(format!("pair {pair_id}: {m}")))
}

type ClipMaps = (BTreeMap<String, Clip>, BTreeMap<String, Clip>);

fn clips_for(
    ds: &Dataset,
    v: u64,
    kind: &dyn FeatureKind,
    model: Option<&str>,
    pairs: &[(&Episode, &Episode)],
) -> Result<ClipMaps> {
    let humans: BTreeMap<String, &Episode> = pairs.iter().map(|(h, _)| (h.episode_id.clone(), *h)).collect();
    let robots: BTreeMap<String, &Episode> = pairs.iter().map(|(_, r)| (r.episode_id.clone(), *r)).collect();
    let h = match kind.human_source() {
        ClipSource::Frames => load_clips(ds, v, TableKind::Frames, None, &humans)?,
        ClipSource::Imagined => load_clips(ds, v, TableKind::Imagined, model, &humans)?,
    };
    let r = load_clips(ds, v, TableKind::Frames, None, &robots)?;
    Ok((h, r))
}

/// Aligns every selected pair of `version` (default latest) and commits the alignments
/// of the pairs that aligned; the others are listed in the report with their reason.
pub fn align_dataset(
    ds: &Dataset,
    version: Option<u64>,
    kind: &dyn FeatureKind,
    opts: &AlignOptions,
    mut meta: CommitMeta,
    progress: &(dyn Fn() + Sync),
) -> Result<AlignReport> {
    opts.validate()?;
    let v = ds.resolve(version)?;
    let eps = ops::episodes(ds, v)?;
    let mut pairs = pairs_of(&eps);
    if let Some(want) = &opts.pairs {
        if let Some(missing) = want.iter().find(|p| !pairs.contains_key(*p)) {
            return Err(Error::Invalid(format!("no pair {missing} at version {v}")));
        }
        pairs.retain(|p, _| want.contains(p));
    }
    let model = match kind.human_source() {
        ClipSource::Imagined if !pairs.is_empty() => Some(resolve_model(ds, v, opts.model_id.as_deref())?),
        _ => None,
    };
    // The run is named by what it reads and its options, before partitioning, so the
    // workers of a partitioned run share it, and a re-run finds its pairs done.
    let mut parts = vec![
        "milv-align/1".to_string(),
        kind.name().into(),
        format!("{:?}", opts.step),
        opts.band.to_string(),
        format!("max band {}", opts.widest_band()),
        format!("posterior {}", opts.temperature),
    ];
    // Only when on, so the runs of the default keep the ids they had before the option.
    if opts.proportional_within > 0.0 {
        parts.push(format!("proportional within {}", opts.proportional_within));
    }
    parts.extend(model.clone());
    parts.extend(ds.files(TableKind::Frames, v)?.into_iter().map(|f| f.info.path));
    parts.extend(pairs.keys().cloned());
    let run_id = milv_data::run_id(&parts);
    pairs.retain(|p, _| opts.partition.is_none_or(|part| part.contains_key(p)));
    if pairs.is_empty() {
        return Err(Error::Invalid(format!(
            "no paired episodes (pair_id) to align at version {v}"
        )));
    }
    let done = milv_data::run_groups(ds, ds.latest_version()?, TableKind::Alignments, &run_id)?;
    let selected = pairs.len();
    pairs.retain(|p, _| !done.contains(p));
    let already_aligned = selected - pairs.len();
    let mut failed: Vec<PairError> = Vec::new();
    let mut good: Vec<(&String, &Episode, &Episode)> = Vec::new();
    for (p, r) in &pairs {
        match r {
            Ok((h, rb)) => good.push((p, h, rb)),
            Err(m) => failed.push(PairError {
                pair_id: p.clone(),
                message: m.clone(),
            }),
        }
    }
    let refs: Vec<(&Episode, &Episode)> = good.iter().map(|(_, h, r)| (*h, *r)).collect();
    let (hclips, rclips) = clips_for(ds, v, kind, model.as_deref(), &refs)?;
    type PairResult = std::result::Result<(PairSummary, Correspondence), String>;
    let results: Vec<(String, PairResult)> = good
        .par_iter()
        .map(|(p, h, r)| {
            let res = (|| {
                let hc = hclips.get(&h.episode_id).ok_or_else(|| {
                    format!(
                        "human episode {} has no rows in the {} table",
                        h.episode_id,
                        match kind.human_source() {
                            ClipSource::Frames => "frames",
                            ClipSource::Imagined => "imagined",
                        }
                    )
                })?;
                let rc = rclips
                    .get(&r.episode_id)
                    .ok_or_else(|| format!("robot episode {} has no frames", r.episode_id))?;
                let fit = align_pair(kind, hc, rc, opts)?;
                let (per_dim, trusted) = (fit.cost_per_dim(), fit.trusted(opts.max_cost));
                let corr = fit.correspondence(opts).map_err(|e| e.to_string())?;
                let (al, edge, band) = (fit.alignment, fit.band_edge, fit.band);
                let ((mean_err, max_err), (prop_mean, prop_max)) = match opts.truth.get(*p) {
                    Some(t) if t.len() == hc.images.len() => {
                        let got = &corr.human_to_robot;
                        let prop = proportional_warp(hc.images.len(), rc.images.len());
                        (frame_errors(got, t), frame_errors(&prop, t))
                    }
                    Some(t) => {
                        return Err(format!(
                            "ground truth has {} frames, the human clip {}",
                            t.len(),
                            hc.images.len()
                        ));
                    }
                    None => ((None, None), (None, None)),
                };
                Ok((
                    PairSummary {
                        pair_id: (*p).clone(),
                        human_episode_id: h.episode_id.clone(),
                        robot_episode_id: r.episode_id.clone(),
                        human_frames: hc.images.len(),
                        robot_frames: rc.images.len(),
                        features: fit.kind.name().to_string(),
                        normalized_cost: al.normalized,
                        cost_per_dim: per_dim,
                        path_length: al.path.len(),
                        band_edge_fraction: edge,
                        band,
                        trusted,
                        mean_frame_error: mean_err,
                        max_frame_error: max_err,
                        proportional_mean_error: prop_mean,
                        proportional_max_error: prop_max,
                        posterior_sd: corr.posterior_sd,
                        proportional: corr.proportional,
                    },
                    corr,
                ))
            })();
            progress();
            ((*p).clone(), res)
        })
        .collect();
    let mut aligned = Vec::new();
    for (p, r) in results {
        match r {
            Ok(x) => aligned.push(x),
            Err(message) => failed.push(PairError { pair_id: p, message }),
        }
    }
    failed.sort_by(|a, b| a.pair_id.cmp(&b.pair_id));
    let with_truth: Vec<&PairSummary> = aligned
        .iter()
        .map(|(s, _)| s)
        .filter(|s| s.mean_frame_error.is_some())
        .collect();
    let mut report = AlignReport {
        read_version: v,
        version: ds.latest_version()?,
        run_id: run_id.clone(),
        features: kind.name().into(),
        pairs: aligned.iter().map(|(s, _)| s.clone()).collect(),
        failed,
        rows: aligned.iter().map(|(_, c)| c.cells.len() as u64).sum(),
        mean_frame_error: mean_over(&with_truth, |s| s.mean_frame_error),
        max_frame_error: with_truth.iter().filter_map(|s| s.max_frame_error).max(),
        proportional_mean_error: mean_over(&with_truth, |s| s.proportional_mean_error),
        trusted_worse_than_proportional: with_truth
            .iter()
            .filter(|s| s.trusted && s.mean_frame_error > s.proportional_mean_error)
            .map(|s| s.pair_id.clone())
            .collect(),
        already_aligned,
    };
    if aligned.is_empty() {
        return Ok(report);
    }
    meta.summary = serde_json::json!({
        "run_id": run_id, "features": kind.name(), "band": opts.band, "max_band": opts.widest_band(), "step": opts.step,
        "temperature": opts.temperature, "model_id": model,
        "pairs": report.pairs.len(), "failed": report.failed.len(), "rows": report.rows,
        "untrusted": report.pairs.iter().filter(|p| !p.trusted).map(|p| &p.pair_id).collect::<Vec<_>>(),
        "proportional_within": opts.proportional_within,
        "proportional": report.pairs.iter().filter(|p| p.proportional).map(|p| &p.pair_id).collect::<Vec<_>>(),
        "features_per_pair": report.pairs.iter().fold(BTreeMap::<&str, usize>::new(), |mut m, p| {
            *m.entry(p.features.as_str()).or_default() += 1;
            m
        }),
    });
    report.version = ds.begin(meta)?.write_and_commit(
        TableKind::Alignments,
        Some(&run_id),
        ShardOptions::default(),
        |w| -> Result<()> {
            for (s, corr) in &aligned {
                w.group(&s.pair_id, &alignment_rows(s, corr, kind.name(), &run_id))?;
            }
            Ok(())
        },
    )?;
    Ok(report)
}

/// Robot frame of each of `n` human frames when the robot clip (`m` frames) is simply
/// stretched onto the human one.
pub fn proportional_warp(n: usize, m: usize) -> Vec<usize> {
    (0..n)
        .map(|i| {
            if n > 1 {
                (i as f64 * (m.saturating_sub(1)) as f64 / (n - 1) as f64).round() as usize
            } else {
                0
            }
        })
        .collect()
}

/// Mean of one per-pair error over the pairs with ground truth; `None` without any.
fn mean_over(pairs: &[&PairSummary], err: fn(&PairSummary) -> Option<f64>) -> Option<f64> {
    (!pairs.is_empty()).then(|| pairs.iter().filter_map(|s| err(s)).sum::<f64>() / pairs.len() as f64)
}

/// Mean and max |got − truth| over the frames.
fn frame_errors(got: &[usize], truth: &[usize]) -> (Option<f64>, Option<usize>) {
    let errs: Vec<usize> = got.iter().zip(truth).map(|(a, b)| a.abs_diff(*b)).collect();
    if errs.is_empty() {
        return (None, None);
    }
    (
        Some(errs.iter().sum::<usize>() as f64 / errs.len() as f64),
        errs.iter().max().copied(),
    )
}

/// The `alignments` rows of one aligned pair: every frame with its partner and their
/// local cost.
fn alignment_rows(s: &PairSummary, corr: &Correspondence, features: &str, run_id: &str) -> Vec<AlignmentRow> {
    corr.cells
        .iter()
        .map(|&(h, r, cost)| AlignmentRow {
            pair_id: s.pair_id.clone(),
            human_episode_id: s.human_episode_id.clone(),
            human_frame: h as i32,
            robot_episode_id: s.robot_episode_id.clone(),
            robot_frame: r as i32,
            cost,
            features: features.to_string(),
            run_id: run_id.to_string(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::Stage;

    #[test]
    fn the_proportional_warp_stretches_one_clip_onto_the_other() {
        assert_eq!(proportional_warp(5, 9), [0, 2, 4, 6, 8]);
        assert_eq!(proportional_warp(3, 2), [0, 1, 1]);
        assert_eq!(proportional_warp(1, 7), [0]);
        assert_eq!(frame_errors(&[0, 2, 4], &[0, 3, 7]), (Some(4.0 / 3.0), Some(3)));
        assert_eq!(frame_errors(&[], &[]), (None, None));
    }

    /// A kind whose robot features are the human's (a ramp, and 0) with `offset` in place
    /// of the 0: its cost per dimension is about `offset² / 2`.
    struct Offset {
        name: &'static str,
        offset: f64,
        untrusted: f64,
    }

    impl FeatureKind for Offset {
        fn name(&self) -> &'static str {
            self.name
        }
        fn extract(&self, clip: &Clip) -> Result<crate::Features> {
            if self.offset.is_nan() {
                return Err(Error::Invalid(format!("{} cannot", self.name)));
            }
            let n = clip.images.len();
            let shift = if clip.domain == milv_data::Domain::Robot {
                self.offset
            } else {
                0.0
            };
            let rows = (0..n).flat_map(|t| [t as f64 / (n - 1) as f64, shift]);
            crate::Features::new(n, 2, rows.collect())
        }
        fn untrusted_cost(&self) -> f64 {
            self.untrusted
        }
    }

    const fn offset(name: &'static str, offset: f64, untrusted: f64) -> Offset {
        Offset {
            name,
            offset,
            untrusted,
        }
    }

    static FAR: Offset = offset("far", 0.2, 0.1);
    static FAR_UNTRUSTED: Offset = offset("far-untrusted", 0.2, 0.01);
    static FARTHER: Offset = offset("farther", 0.3, 0.01);
    static NEAR: Offset = offset("near", 0.01, 0.1);
    static BROKEN: Offset = offset("broken", f64::NAN, 0.1);
    static EXACT: Offset = offset("exact", 0.0, 0.1);

    struct Cascade(&'static [Stage]);

    impl FeatureKind for Cascade {
        fn name(&self) -> &'static str {
            "cascade"
        }
        fn extract(&self, _: &Clip) -> Result<crate::Features> {
            unreachable!("a cascade extracts through its kinds")
        }
        fn cascade(&self) -> &'static [Stage] {
            self.0
        }
    }

    fn picked(cascade: &[(&'static dyn FeatureKind, f64)]) -> std::result::Result<&'static str, String> {
        picked_unless(cascade, &[])
    }

    /// The kind `auto`-like stages pick, the first stage replaced by one of `unless` where
    /// trusted.
    fn picked_unless(
        cascade: &[(&'static dyn FeatureKind, f64)],
        unless: &[&'static dyn FeatureKind],
    ) -> std::result::Result<&'static str, String> {
        picked_with(cascade, unless, None)
    }

    /// [`picked_unless`], the first stage aligned again by `aligned_by`.
    fn picked_with(
        cascade: &[(&'static dyn FeatureKind, f64)],
        unless: &[&'static dyn FeatureKind],
        aligned_by: Option<&'static dyn FeatureKind>,
    ) -> std::result::Result<&'static str, String> {
        // A kind's cascade is static; a test's may leak.
        let unless: &'static [&'static dyn FeatureKind] = Box::leak(unless.to_vec().into_boxed_slice());
        let stages: Vec<Stage> = cascade
            .iter()
            .enumerate()
            .map(|(i, &(kind, keep_below))| Stage {
                kind,
                keep_below,
                unless_trusted: if i == 0 { unless } else { &[] },
                aligned_by: if i == 0 { aligned_by } else { None },
            })
            .collect();
        let cascade = Box::leak(stages.into_boxed_slice());
        let (h, r) = (
            blank(milv_data::Domain::Human, 12),
            blank(milv_data::Domain::Robot, 15),
        );
        align_pair(&Cascade(cascade), &h, &r, &AlignOptions::default()).map(|f| f.kind.name())
    }

    /// A clip of `n` blank 1×1 frames (the test kinds make up their features).
    fn blank(domain: milv_data::Domain, n: usize) -> Clip {
        Clip {
            episode_id: format!("{domain:?}"),
            domain,
            encoding: milv_data::FrameEncoding::Raw,
            width: 1,
            height: 1,
            images: vec![vec![0; 3]; n],
            states: None,
            motion_cache: Default::default(),
            points_cache: Default::default(),
        }
    }

    /// One feature per frame: the robot's progress runs evenly through its clip, the
    /// human's as `human` maps the share of the clip gone by.
    struct Progress {
        name: &'static str,
        human: fn(f64) -> f64,
    }

    impl FeatureKind for Progress {
        fn name(&self) -> &'static str {
            self.name
        }
        fn extract(&self, clip: &Clip) -> Result<crate::Features> {
            let n = clip.images.len();
            let share = (0..n).map(|t| t as f64 / (n - 1) as f64);
            let values = if clip.domain == milv_data::Domain::Human {
                share.map(self.human).collect()
            } else {
                share.collect()
            };
            crate::Features::new(n, 1, values)
        }
        fn untrusted_cost(&self) -> f64 {
            0.1
        }
    }

    /// A strong warp: the human's progress grows with the cube of time, so the true path
    /// strays up to 0.38 of the clip from the diagonal.
    const CUBIC: Progress = Progress {
        name: "cubic",
        human: |u| u.powi(3),
    };

    /// The true warp is the identity; the human's progress runs ahead of the robot's by a
    /// bump of 1.5 % of the clip mid-way (a feature's embodiment bias).
    const BIASED: Progress = Progress {
        name: "biased",
        human: |u| u + 0.015 * (std::f64::consts::PI * u).sin(),
    };

    #[test]
    fn a_warp_within_the_posteriors_spread_of_the_proportional_one_takes_that() {
        let (h, r) = (
            blank(milv_data::Domain::Human, 40),
            blank(milv_data::Domain::Robot, 40),
        );
        let identity: Vec<usize> = (0..40).collect();
        let decode = |kind: &dyn FeatureKind, within: f64| {
            let opts = AlignOptions {
                proportional_within: within,
                ..AlignOptions::default()
            };
            align_pair(kind, &h, &r, &opts)
                .expect("aligned")
                .correspondence(&opts)
                .expect("decoded")
        };
        // The bias moves the posterior medians off the (true) proportional warp by less
        // than the posterior's spread: the proportional warp is taken, and is exact.
        let own = decode(&BIASED, 0.0);
        let sd = own.posterior_sd.expect("posterior decoding");
        let gap = frame_errors(&own.human_to_robot, &identity).0.expect("frames");
        assert!(!own.proportional && gap > 0.3 && gap < sd, "gap {gap}, sd {sd}");
        let taken = decode(&BIASED, 1.0);
        assert!(taken.proportional);
        assert_eq!(taken.human_to_robot, identity);
        assert!(
            taken
                .cells
                .iter()
                .map(|&(i, j, _)| (i, j))
                .eq(staircase(&identity, 40))
        );
        // A strong warp lies far outside the spread: the features' warp is kept.
        let cubic = decode(&CUBIC, 1.0);
        assert!(!cubic.proportional);
        assert_ne!(cubic.human_to_robot, proportional_warp(40, 40));
    }

    #[test]
    fn bands_outside_their_range_are_refused_by_name() {
        for (band, max_band, named) in [
            (0.0, 0.4, "--band 0"),
            (0.2, 1.5, "--max-band 1.5"),
            (0.2, 0.0, "--max-band 0"),
        ] {
            let opts = AlignOptions {
                band,
                max_band,
                ..AlignOptions::default()
            };
            let err = opts.validate().expect_err("refused").to_string();
            assert!(err.contains(named), "{err}");
        }
        // At most the band (never widened) and the widest, 1, are fine.
        for max_band in [0.1, 1.0] {
            let opts = AlignOptions {
                max_band,
                ..AlignOptions::default()
            };
            assert!(opts.validate().is_ok(), "{max_band}");
        }
        for within in [-1.0, f64::NAN, f64::INFINITY] {
            let opts = AlignOptions {
                proportional_within: within,
                ..AlignOptions::default()
            };
            let err = opts.validate().expect_err("refused").to_string();
            assert!(err.contains("--proportional-within"), "{err}");
        }
    }

    #[test]
    fn a_path_along_the_band_edge_is_aligned_again_in_a_wider_band() {
        let (h, r) = (
            blank(milv_data::Domain::Human, 40),
            blank(milv_data::Domain::Robot, 40),
        );
        let truth: Vec<usize> = (0..40)
            .map(|i| (39.0 * (i as f64 / 39.0).powi(3)).round() as usize)
            .collect();
        let error = |opts: &AlignOptions| {
            let fit = align_pair(&CUBIC, &h, &r, opts).expect("aligned");
            let got = fit.correspondence(opts).expect("decoded").human_to_robot;
            (
                fit.band,
                fit.trusted(None),
                frame_errors(&got, &truth).0.expect("frames"),
            )
        };
        // Never widened: the band cuts the path short, and the pair is flagged.
        let narrow = AlignOptions {
            band: 0.1,
            max_band: 0.1,
            ..AlignOptions::default()
        };
        let (band, trusted, err) = error(&narrow);
        assert!(band == 0.1 && !trusted && err > 3.0, "{band} {trusted} {err}");
        // A max_band below the band: never widened either.
        let below = AlignOptions {
            max_band: 0.05,
            ..narrow.clone()
        };
        assert_eq!(error(&below).0, 0.1);
        // Widened 0.1 at a time, up to max_band: still on the edge at 0.3, flagged ...
        let (band, trusted, _) = error(&AlignOptions {
            max_band: 0.3,
            ..narrow.clone()
        });
        assert!(band == 0.3 && !trusted, "{band} {trusted}");
        // ... off it at 0.4, where widening stops below max_band.
        let (band, trusted, err) = error(&AlignOptions {
            max_band: 0.6,
            ..narrow
        });
        assert_eq!(band, 0.4);
        assert!(trusted && err < 0.5, "{trusted} {err}");
    }

    #[test]
    fn a_cascade_keeps_the_first_kind_within_its_bound_else_the_first_that_explains_the_pair() {
        // Within its bound: kept, the next kind is not needed.
        assert_eq!(picked(&[(&NEAR, 0.01), (&FAR, f64::INFINITY)]), Ok("near"));
        // Above its bound (cost ≈ 0.02): the next kind's alignment.
        assert_eq!(picked(&[(&FAR, 0.01), (&NEAR, f64::INFINITY)]), Ok("near"));
        // No kind within its bound: the first one within its trust bound ...
        assert_eq!(picked(&[(&FAR, 0.01), (&FARTHER, 0.01)]), Ok("far"));
        // ... else the last that aligned at all, also when a later kind fails.
        assert_eq!(picked(&[(&FAR_UNTRUSTED, 0.05), (&FARTHER, 0.01)]), Ok("farther"));
        assert_eq!(picked(&[(&FAR_UNTRUSTED, 0.01), (&FARTHER, 0.01)]), Ok("farther"));
        assert_eq!(
            picked(&[(&FAR_UNTRUSTED, 0.01), (&BROKEN, 0.01)]),
            Ok("far-untrusted")
        );
        // Nothing aligns: every kind's error, by name.
        assert_eq!(
            picked(&[(&BROKEN, 0.01), (&BROKEN, 0.01)]),
            Err("broken: broken cannot; broken: broken cannot".to_string())
        );
    }

    #[test]
    fn a_kept_stage_gives_way_to_its_unless_kind_only_where_that_is_trusted() {
        let cascade: &[(&'static dyn FeatureKind, f64)] = &[(&NEAR, 0.01), (&FAR, f64::INFINITY)];
        assert_eq!(picked_unless(cascade, &[&EXACT]), Ok("exact"));
        // Not trusted (cost ≈ 0.02 above its 0.01), or cannot align: the stage's own.
        assert_eq!(picked_unless(cascade, &[&FAR_UNTRUSTED]), Ok("near"));
        assert_eq!(picked_unless(cascade, &[&BROKEN]), Ok("near"));
        // Of several trusted, the lowest cost, in whichever order they come; the untrusted
        // and the broken are passed over.
        assert_eq!(picked_unless(cascade, &[&FAR, &EXACT]), Ok("exact"));
        assert_eq!(picked_unless(cascade, &[&EXACT, &FAR]), Ok("exact"));
        assert_eq!(
            picked_unless(cascade, &[&BROKEN, &FAR_UNTRUSTED, &FAR]),
            Ok("far")
        );
        // Only a kept stage is replaced: past its bound, the next stage decides.
        let past: &[(&'static dyn FeatureKind, f64)] = &[(&FAR, 0.01), (&NEAR, f64::INFINITY)];
        assert_eq!(picked_unless(past, &[&EXACT]), Ok("near"));
    }

    #[test]
    fn a_kept_stage_is_aligned_again_by_its_aligned_by_kind_where_trusted() {
        let cascade: &[(&'static dyn FeatureKind, f64)] = &[(&NEAR, 0.01), (&FAR, f64::INFINITY)];
        assert_eq!(picked_with(cascade, &[], Some(&FAR)), Ok("far"));
        // Untrusted, or cannot align: the kept alignment stands.
        assert_eq!(picked_with(cascade, &[], Some(&FAR_UNTRUSTED)), Ok("near"));
        assert_eq!(picked_with(cascade, &[], Some(&BROKEN)), Ok("near"));
        // A trusted unless kind comes first.
        assert_eq!(picked_with(cascade, &[&EXACT], Some(&FAR)), Ok("exact"));
        assert_eq!(picked_with(cascade, &[&FAR_UNTRUSTED], Some(&FAR)), Ok("far"));
        // Past its bound, the next stage decides.
        let past: &[(&'static dyn FeatureKind, f64)] = &[(&FAR, 0.01), (&NEAR, f64::INFINITY)];
        assert_eq!(picked_with(past, &[], Some(&EXACT)), Ok("near"));
        // No stage within its bound, the first kept as the one that explains the pair: it
        // is aligned again too (where trusted), as when kept within its bound.
        let none: &[(&'static dyn FeatureKind, f64)] = &[(&FAR, 0.01), (&FARTHER, 0.01)];
        assert_eq!(picked_with(none, &[], Some(&EXACT)), Ok("exact"));
        assert_eq!(picked_with(none, &[], Some(&FAR_UNTRUSTED)), Ok("far"));
    }
}
