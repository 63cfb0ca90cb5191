//! The per-frame view the exporters (MCAP, Rerun) show: each recorded frame of an episode
//! joined with what later stages made of it — its translation by one model (imagined
//! frame, latent, predicted action), its quality scores and curated weight, and the robot
//! frame it was aligned to (with that frame's true action).
//!
//! [`ViewPlan::new`] checks the selection and reads the small tables (episodes, scores,
//! curated weights, alignments) once; [`ViewPlan::views`] then streams the episodes in
//! groups, one pass over `frames` and `imagined` per group, so memory holds one group's
//! images at a time.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::frame_codec::{self, FrameEncoding};
use crate::read::{
    AlignmentRun, alignment_run, curated_weights, episode_rows, newest_alignment_run, newest_score_run,
    resolve_model, score_run,
};
use crate::rows::{Domain, Episode, ImaginedRecord, Row};
use crate::schema::TableKind;

/// What to show.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Episodes to show (human or robot); default: every human episode the model translated.
    pub episodes: Option<Vec<String>>,
    /// Translation model; default: the only one in the `imagined` table.
    pub model_id: Option<String>,
    /// Scoring run for the quality numbers; default: the newest run over this model.
    pub score_run: Option<String>,
    /// Alignment run (id or feature kind) for the aligned robot frames; default: the newest.
    pub alignment: Option<String>,
    /// Episodes per pass over the frame tables (bounds memory).
    pub group: usize,
}

impl Default for ViewOptions {
    fn default() -> Self {
        ViewOptions {
            episodes: None,
            model_id: None,
            score_run: None,
            alignment: None,
            group: 16,
        }
    }
}

/// An encoded image as viewers take it.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// `png` or `jpeg` (raw frames are re-encoded as PNG).
    pub format: &'static str,
    pub data: Vec<u8>,
}

pub use crate::rows::Latent;

/// One translated frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Imagined {
    pub image: Image,
    pub latent: Option<Latent>,
    pub action: Option<Vec<f32>>,
}

/// Quality of a translated frame (`scores`), with its curated loss weight when a curation
/// of that scoring run exists (0 for frames the curation dropped).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Quality {
    pub brenner: f64,
    pub ssim: f64,
    pub beta: f64,
    pub weight: Option<f64>,
}

/// The robot frame a human frame was aligned to.
#[derive(Clone, Debug, PartialEq)]
pub struct AlignedFrame {
    pub episode_id: String,
    pub frame_index: i32,
    pub image: Image,
    pub action: Option<Vec<f32>>,
}

/// One frame of an episode and what later stages made of it.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameView {
    pub frame_index: i32,
    pub timestamp_ns: i64,
    pub image: Image,
    /// The recorded action (robot episodes).
    pub action: Option<Vec<f32>>,
    pub imagined: Option<Imagined>,
    pub quality: Option<Quality>,
    pub aligned: Option<AlignedFrame>,
}

/// One episode, frame by frame.
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodeView {
    pub episode: Episode,
    pub frames: Vec<FrameView>,
}

impl EpisodeView {
    /// Span of the episode on a timeline: its last timestamp plus one frame period, where
    /// the next episode starts when episodes are laid end to end.
    pub fn duration_ns(&self) -> u64 {
        let period = if self.episode.fps > 0.0 {
            (1e9 / self.episode.fps) as u64
        } else {
            0
        };
        self.frames.last().map_or(0, |f| f.timestamp_ns.max(0) as u64) + period
    }

    /// Mean β over the frames that have one.
    pub fn mean_beta(&self) -> Option<f64> {
        mean(self.frames.iter().filter_map(|f| f.quality.map(|q| q.beta)))
    }
}

fn mean(it: impl Iterator<Item = f64>) -> Option<f64> {
    let (n, s) = it.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x));
    (n > 0).then(|| s / n as f64)
}

type FrameKey = (String, i32);

/// A checked selection, with the small tables read.
#[derive(Debug)]
pub struct ViewPlan {
    pub version: u64,
    /// The translation model shown (None when only robot episodes were selected and the
    /// table has no model).
    pub model_id: Option<String>,
    /// The model's configuration, from the version log entry that translated with it.
    pub model_config: Option<serde_json::Value>,
    /// Names of the action components (from the robot episodes), e.g. `[dx, dy]`.
    pub action_names: Vec<String>,
    pub episodes: Vec<Episode>,
    pub score_run: Option<String>,
    pub alignment: Option<AlignmentRun>,
    /// Shape of every latent of the model (they all share it).
    pub latent_shape: Option<Vec<i32>>,
    quality: HashMap<FrameKey, Quality>,
    aligned: HashMap<FrameKey, FrameKey>,
    group: usize,
}

impl ViewPlan {
    /// Checks the selection against version `v` and reads the small tables.
    pub fn new(ds: &Dataset, v: u64, opts: &ViewOptions) -> Result<ViewPlan> {
        let all = crate::ops::episodes(ds, v)?;
        let by_id: BTreeMap<&str, &Episode> = all.iter().map(|e| (e.episode_id.as_str(), e)).collect();
        let wants_model = opts.episodes.as_ref().is_none_or(|w| {
            w.iter()
                .any(|id| by_id.get(id.as_str()).is_some_and(|e| e.domain == Domain::Human))
        });
        let (model_id, translated) = match resolve_model(ds, v, opts.model_id.as_deref())? {
            Some((m, eps)) => (Some(m), eps),
            None if wants_model => {
                return Err(Error::Invalid(format!(
                    "version {v} has no imagined rows; run `milv-train translate` first"
                )));
            }
            None => (None, BTreeSet::new()),
        };
        let episodes: Vec<Episode> = match &opts.episodes {
            None => all
                .iter()
                .filter(|e| translated.contains(&e.episode_id))
                .cloned()
                .collect(),
            Some(want) => {
                let mut out = Vec::new();
                for id in want {
                    let e = by_id
                        .get(id.as_str())
                        .ok_or_else(|| Error::Invalid(format!("no episode {id} at version {v}")))?;
                    if e.domain == Domain::Human && !translated.contains(id) {
                        return Err(Error::Invalid(format!(
                            "episode {id} has no imagined rows for model {} at version {v}",
                            model_id.as_deref().unwrap_or("?")
                        )));
                    }
                    out.push((*e).clone());
                }
                out
            }
        };
        if episodes.is_empty() {
            return Err(Error::Invalid(format!(
                "nothing to show at version {v}: the selection is empty"
            )));
        }
        let action_names = action_names(&all);
        let model_config = match &model_id {
            Some(m) => ds.entries_until(v)?.into_iter().rev().find_map(|e| {
                let s = &e.meta.summary;
                (s.get("model_id").and_then(|x| x.as_str()) == Some(m.as_str()))
                    .then(|| s.get("model_config").cloned())
                    .flatten()
            }),
            None => None,
        };
        let (score_run, quality) = match &model_id {
            Some(m) => read_quality(ds, v, m, opts.score_run.as_deref())?,
            None => (None, HashMap::new()),
        };
        let (alignment, aligned) = read_aligned(ds, v, opts.alignment.as_deref())?;
        Ok(ViewPlan {
            version: v,
            model_id,
            model_config,
            action_names,
            episodes,
            score_run,
            alignment,
            latent_shape: None,
            quality,
            aligned,
            group: opts.group.max(1),
        })
    }

    /// Puts the episodes with the lowest mean β first (those without scores last).
    pub fn sort_by_beta(&mut self) {
        // One pass over the scores: (sum, count) of β per episode.
        let mut sums: HashMap<&str, (f64, usize)> = HashMap::new();
        for ((id, _), q) in &self.quality {
            let s = sums.entry(id.as_str()).or_default();
            *s = (s.0 + q.beta, s.1 + 1);
        }
        let beta = |e: &Episode| {
            sums.get(e.episode_id.as_str())
                .map_or(f64::INFINITY, |(s, n)| s / *n as f64)
        };
        let mut keyed: Vec<(f64, Episode)> = self.episodes.iter().map(|e| (beta(e), e.clone())).collect();
        keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
        self.episodes = keyed.into_iter().map(|(_, e)| e).collect();
    }

    /// The episodes in plan order, one group of frame-table reads at a time.
    pub fn views<'a>(&'a mut self, ds: &'a Dataset) -> impl Iterator<Item = Result<EpisodeView>> + 'a {
        let groups: Vec<Vec<Episode>> = self
            .episodes
            .chunks(self.group)
            .map(<[Episode]>::to_vec)
            .collect();
        groups.into_iter().flat_map(move |g| match self.load(ds, &g) {
            Ok(views) => views.into_iter().map(Ok).collect::<Vec<_>>(),
            Err(e) => vec![Err(e)],
        })
    }

    /// [`ViewPlan::views`] with the reading on a second thread, so reading the tables and
    /// consuming the views (an exporter's encoding and compression) overlap. `f` gets each
    /// view with its position; the first error (a read's or `f`'s) stops both sides.
    pub fn for_each_prefetched<E: From<Error> + Send>(
        &mut self,
        ds: &Dataset,
        mut f: impl FnMut(usize, EpisodeView) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        std::thread::scope(|s| {
            // Two groups ahead at most: memory stays bounded by a few groups' frames.
            let (tx, rx) = std::sync::mpsc::sync_channel::<Result<EpisodeView>>(2 * self.group);
            let reader = s.spawn(move || {
                for ev in self.views(ds) {
                    if tx.send(ev).is_err() {
                        break;
                    }
                }
            });
            let mut out = Ok(());
            for (k, ev) in rx.iter().enumerate() {
                if let Err(e) = ev.map_err(E::from).and_then(|ev| f(k, ev)) {
                    out = Err(e);
                    break;
                }
            }
            drop(rx);
            let _ = reader.join();
            out
        })
    }

    fn load(&mut self, ds: &Dataset, group: &[Episode]) -> Result<Vec<EpisodeView>> {
        let v = self.version;
        let mut wanted: BTreeSet<String> = group.iter().map(|e| e.episode_id.clone()).collect();
        let own: BTreeSet<String> = wanted.clone();
        wanted.extend(
            self.aligned
                .iter()
                .filter(|((h, _), _)| own.contains(h))
                .map(|(_, (r, _))| r.clone()),
        );
        let frames = episode_rows(
            ds,
            v,
            TableKind::Frames,
            &|id| wanted.contains(id),
            Some("action"),
            None,
        )?;
        let formats: HashMap<String, (FrameEncoding, u32, u32)> = crate::ops::episodes(ds, v)?
            .into_iter()
            .filter(|e| wanted.contains(&e.episode_id))
            .map(|e| (e.episode_id, (e.frame_encoding, e.width as u32, e.height as u32)))
            .collect();
        let image = |id: &str, i: usize, rows: &crate::read::EpisodeRows| -> Result<Image> {
            let f = formats.get(id).copied().unwrap_or((FrameEncoding::Png, 0, 0));
            viewable(f, &rows.images[i], id)
        };
        let mut imagined = match &self.model_id {
            Some(m) => imagined_rows(ds, v, &own, m)?,
            None => HashMap::new(),
        };
        let mut out = Vec::with_capacity(group.len());
        for e in group {
            let id = &e.episode_id;
            let rows = frames
                .get(id)
                .ok_or_else(|| Error::Invalid(format!("episode {id} has no frames at version {v}")))?;
            let mut fv = Vec::with_capacity(rows.frame_index.len());
            for (i, &fi) in rows.frame_index.iter().enumerate() {
                let key = (id.clone(), fi);
                let im = imagined.remove(&key);
                if let Some(l) = im.as_ref().and_then(|x| x.latent.as_ref()) {
                    l.check()
                        .map_err(|m| Error::Invalid(format!("episode {id} frame {fi}: {m}")))?;
                    match &self.latent_shape {
                        Some(s) if s != &l.shape => {
                            return Err(Error::Invalid(format!(
                                "episode {id} frame {fi}: latent shape {:?} differs from the model's {s:?}",
                                l.shape
                            )));
                        }
                        Some(_) => {}
                        None => self.latent_shape = Some(l.shape.clone()),
                    }
                }
                let aligned = match self.aligned.get(&key) {
                    Some((r, rf)) => {
                        let rrows = frames.get(r).ok_or_else(|| {
                            Error::Invalid(format!("aligned robot episode {r} has no frames"))
                        })?;
                        let j = rrows.frame_index.iter().position(|x| x == rf).ok_or_else(|| {
                            Error::Invalid(format!("aligned robot episode {r} has no frame {rf}"))
                        })?;
                        Some(AlignedFrame {
                            episode_id: r.clone(),
                            frame_index: *rf,
                            image: image(r, j, rrows)?,
                            action: rrows.vectors[j].clone(),
                        })
                    }
                    None => None,
                };
                fv.push(FrameView {
                    frame_index: fi,
                    timestamp_ns: rows.timestamp_ns[i],
                    image: image(id, i, rows)?,
                    action: rows.vectors[i].clone(),
                    imagined: im,
                    quality: self.quality.get(&key).copied(),
                    aligned,
                });
            }
            out.push(EpisodeView {
                episode: e.clone(),
                frames: fv,
            });
        }
        Ok(out)
    }
}

/// A stored frame as PNG or JPEG bytes (raw frames are encoded as PNG).
fn viewable((enc, w, h): (FrameEncoding, u32, u32), bytes: &[u8], id: &str) -> Result<Image> {
    match enc {
        FrameEncoding::Png => Ok(Image {
            format: "png",
            data: bytes.to_vec(),
        }),
        FrameEncoding::Jpeg { .. } => Ok(Image {
            format: "jpeg",
            data: bytes.to_vec(),
        }),
        FrameEncoding::Raw => {
            let mut data = Vec::new();
            frame_codec::encode(FrameEncoding::Png, bytes, w, h, &mut data)
                .map_err(|e| Error::Invalid(format!("episode {id}: raw frame: {e}")))?;
            Ok(Image { format: "png", data })
        }
    }
}

/// Name of action component `i`: the dataset's name, or `a<i>` past the named ones.
pub fn component_name(names: &[String], i: usize) -> String {
    names.get(i).cloned().unwrap_or_else(|| format!("a{i}"))
}

fn action_names(all: &[Episode]) -> Vec<String> {
    if let Some(n) = all
        .iter()
        .filter(|e| e.domain == Domain::Robot)
        .find_map(|e| e.action_names.clone())
    {
        return n;
    }
    let dim = all.iter().find_map(|e| e.action_dim).unwrap_or(2);
    (0..dim).map(|i| format!("a{i}")).collect()
}

/// β and the curated weight per frame of the newest (or the named) scoring run of `model`.
fn read_quality(
    ds: &Dataset,
    v: u64,
    model: &str,
    want: Option<&str>,
) -> Result<(Option<String>, HashMap<FrameKey, Quality>)> {
    let run = match want {
        Some(r) => Some(r.to_string()),
        None => newest_score_run(ds, v, model)?,
    };
    let Some(run) = run else {
        return Ok((None, HashMap::new()));
    };
    let (run, rows) = score_run(ds, v, Some(&run))?;
    let weights = curated_weights(ds, v, &run, model)?.map(|(_, w)| w);
    let quality = rows
        .into_iter()
        .filter(|r| r.source_table == "imagined" && r.model_id.as_deref() == Some(model))
        .map(|r| {
            let key = (r.episode_id, r.frame_index);
            let weight = weights.as_ref().map(|w| w.get(&key).copied().unwrap_or(0.0));
            (
                key,
                Quality {
                    brenner: r.brenner,
                    ssim: r.ssim,
                    beta: r.beta,
                    weight,
                },
            )
        })
        .collect();
    Ok((Some(run), quality))
}

/// Human frame → the first robot frame the named (or newest) alignment run paired it with.
fn read_aligned(
    ds: &Dataset,
    v: u64,
    want: Option<&str>,
) -> Result<(Option<AlignmentRun>, HashMap<FrameKey, FrameKey>)> {
    let want = match want {
        Some(w) => Some(w.to_string()),
        None => newest_alignment_run(ds, v)?,
    };
    let Some(want) = want else {
        return Ok((None, HashMap::new()));
    };
    let (run, pairs) = alignment_run(ds, v, Some(&want), "run `milv-align` first")?;
    let mut map: HashMap<FrameKey, FrameKey> = HashMap::new();
    for p in pairs {
        let (h, r) = ((p.human.0, p.human.1 as i32), (p.robot.0, p.robot.1 as i32));
        map.entry(h)
            .and_modify(|x| *x = (*x).clone().min(r.clone()))
            .or_insert(r);
    }
    Ok((Some(run), map))
}

/// The model's imagined rows of the episodes in `keep`, by (episode, frame).
fn imagined_rows(
    ds: &Dataset,
    v: u64,
    keep: &BTreeSet<String>,
    model: &str,
) -> Result<HashMap<FrameKey, Imagined>> {
    let mut out = HashMap::new();
    for b in ds.scan(TableKind::Imagined, v, None)? {
        for r in ImaginedRecord::from_batch(&b?)? {
            if r.model_id != model || !keep.contains(&r.episode_id) {
                continue;
            }
            out.insert(
                (r.episode_id, r.frame_index),
                Imagined {
                    image: Image {
                        format: "png",
                        data: r.image,
                    },
                    latent: r.latent,
                    action: r.action,
                },
            );
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::Latent;

    fn latent(dtype: &str, shape: &[i32], bytes: usize) -> Latent {
        Latent {
            dtype: dtype.into(),
            shape: shape.to_vec(),
            data: vec![0; bytes],
        }
    }

    #[test]
    fn latents_must_match_their_shape() {
        assert!(latent("f16", &[2, 3, 4], 48).check().is_ok());
        let e = latent("f16", &[2, 3, 4], 47).check().unwrap_err();
        assert!(e.contains("47 bytes, expected 48"), "{e}");
        assert!(
            latent("f32", &[2, 0, 4], 0)
                .check()
                .unwrap_err()
                .contains("non-positive")
        );
        assert!(
            latent("i8", &[1], 1)
                .check()
                .unwrap_err()
                .contains("unknown latent dtype")
        );
        // 1.0 and -2.0 in f16, little-endian.
        let l = Latent {
            dtype: "f16".into(),
            shape: vec![2],
            data: vec![0x00, 0x3c, 0x00, 0xc0],
        };
        assert_eq!(l.to_f32().unwrap(), vec![1.0, -2.0]);
    }
}
