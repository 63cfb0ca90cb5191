//! What A-CycleGAN trains on, read from one pinned dataset version, and the prefetching
//! loader that decodes it on background threads.
//!
//! | role | episodes |
//! |---|---|
//! | human images x | `domain = human`, `kind = demo`, `split = train` |
//! | robot images y, and transitions (y_t, y_t+1, a_t) for π_I | `domain = robot`, `kind = random`, `split = train`, with actions |
//! | aligned pairs (p^h, p^r) for the auxiliary loss | the rows of one `alignments` run |
//!
//! Encoded frames stay encoded in memory (a 128×128 PNG is ~10–20 KB); workers decode
//! the frames of step `s` with an RNG seeded by `(seed, s)` and the consumer takes the
//! steps in order, so a run is reproducible whatever the thread timing, and a resumed
//! run draws the same samples as an uninterrupted one.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;

use milv_data::read::{AlignedPair, AlignmentRun};
use milv_data::{Dataset, Domain, Episode, Kind as EpisodeKind, Split, TableKind, ops};
use rand::{Rng, SeedableRng, rngs::StdRng};

use crate::Error;
use crate::run::image::{Clip, load_clips};

/// The rows of one alignment run: `want` names a run id or a feature kind; without it
/// the table must hold exactly one run.
pub fn load_alignments(
    ds: &Dataset,
    v: u64,
    want: Option<&str>,
) -> Result<(AlignmentRun, Vec<AlignedPair>), Error> {
    Ok(milv_data::read::alignment_run(
        ds,
        v,
        want,
        "run `milv-align` on the paired clips, or train without the auxiliary loss: --lambda-aux 0",
    )?)
}

/// Everything a training run samples from, in memory (encoded).
pub struct TrainingSet {
    pub version: u64,
    pub human: Vec<Clip>,
    /// Robot random videos with actions (robot images and π_I's transitions).
    pub robot: Vec<Clip>,
    pub pair_clips: HashMap<String, Clip>,
    pub pairs: Vec<AlignedPair>,
    pub alignment: Option<AlignmentRun>,
    /// sha256 over the files read and the selection: a resumed run checks it.
    pub digest: String,
    /// Values per action of the robot videos (what π_I predicts).
    pub action_dim: usize,
}

/// What [`TrainingSet::load`] needs to know.
#[derive(Clone, Debug, Default)]
pub struct DataOptions {
    /// Alignment run id or feature kind (see [`load_alignments`]).
    pub alignment: Option<String>,
    /// Skip the alignments (the auxiliary loss is off).
    pub no_alignments: bool,
}

impl TrainingSet {
    pub fn load(ds: &Dataset, v: u64, opts: &DataOptions) -> Result<TrainingSet, Error> {
        let eps = ops::episodes(ds, v)?;
        let pick = |domain: Domain, kind: EpisodeKind| -> BTreeMap<String, Episode> {
            eps.iter()
                .filter(|e| e.domain == domain && e.kind == kind && e.split == Split::Train)
                .map(|e| (e.episode_id.clone(), e.clone()))
                .collect()
        };
        let humans = pick(Domain::Human, EpisodeKind::Demo);
        let robots = pick(Domain::Robot, EpisodeKind::Random);
        if humans.is_empty() {
            return Err(Error::Data(format!(
                "version {v} has no human demonstrations (domain=human, kind=demo, split=train)"
            )));
        }
        if robots.is_empty() {
            return Err(Error::Data(format!(
                "version {v} has no robot random videos (domain=robot, kind=random, split=train): \
                 the inverse-dynamics model learns from them"
            )));
        }
        if let Some(e) = robots.values().find(|e| e.action_dim.unwrap_or(0) < 1) {
            return Err(Error::Data(format!(
                "robot random episode {} ({}) has no actions: the inverse-dynamics model needs them",
                e.episode_id, e.source_uri
            )));
        }
        // π_I has one output per action value, so every robot video must agree on them.
        let action_dim = robots.values().next().and_then(|e| e.action_dim).unwrap_or(0) as usize;
        if let Some(e) = robots.values().find(|e| e.action_dim != Some(action_dim as i32)) {
            return Err(Error::Data(format!(
                "robot random episode {} ({}) has {} action values where the others have {action_dim}",
                e.episode_id,
                e.source_uri,
                e.action_dim.unwrap_or(0)
            )));
        }
        let (alignment, pairs) = if opts.no_alignments {
            (None, Vec::new())
        } else {
            let (run, rows) = load_alignments(ds, v, opts.alignment.as_deref())?;
            (Some(run), rows)
        };
        let pair_eps: BTreeMap<String, Episode> = {
            let ids: BTreeSet<&String> = pairs.iter().flat_map(|p| [&p.human.0, &p.robot.0]).collect();
            eps.iter()
                .filter(|e| ids.contains(&e.episode_id))
                .map(|e| (e.episode_id.clone(), e.clone()))
                .collect()
        };
        let human = load_clips(ds, v, &humans, false)?;
        let robot = load_clips(ds, v, &robots, true)?;
        let pair_clips: HashMap<String, Clip> = load_clips(ds, v, &pair_eps, false)?.into_iter().collect();
        for p in &pairs {
            for (id, f) in [&p.human, &p.robot] {
                let n = pair_clips.get(id).map_or(0, |c| c.frames.len());
                if *f >= n {
                    return Err(Error::Data(format!(
                        "alignment row names frame {f} of episode {id}, which has {n} frames at version {v}"
                    )));
                }
            }
        }
        let mut parts: Vec<String> = vec!["milv-train/data/1".into()];
        parts.extend(ds.files(TableKind::Frames, v)?.into_iter().map(|f| f.info.path));
        parts.extend(human.keys().cloned());
        parts.extend(robot.keys().cloned());
        parts.extend(alignment.iter().map(|a| a.run_id.clone()));
        let digest = milv_data::run_id(&parts);
        let short = |m: BTreeMap<String, Clip>| -> Vec<Clip> {
            m.into_values().filter(|c| c.frames.len() >= 2).collect()
        };
        let robot = short(robot);
        if robot.is_empty() {
            return Err(Error::Data(format!(
                "version {v}: every robot random video has fewer than 2 frames"
            )));
        }
        Ok(TrainingSet {
            version: v,
            human: human.into_values().collect(),
            robot,
            pair_clips,
            pairs,
            alignment,
            digest,
            action_dim,
        })
    }

    pub fn frames(&self) -> (usize, usize) {
        (
            self.human.iter().map(|c| c.frames.len()).sum(),
            self.robot.iter().map(|c| c.frames.len()).sum(),
        )
    }
}

/// One training step's data, CHW f32 images in [-1, 1], `batch` of each.
#[derive(Clone, Debug)]
pub struct Batch {
    pub step: u64,
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    /// Aligned pairs (empty when the set has none).
    pub ph: Vec<f32>,
    pub pr: Vec<f32>,
    pub yt: Vec<f32>,
    pub yt1: Vec<f32>,
    pub actions: Vec<f32>,
}

/// How many samples of each kind a step draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchShape {
    /// Human images, robot images and aligned pairs.
    pub images: usize,
    /// Robot transitions for π_I.
    pub transitions: usize,
}

/// Draws and decodes step `step`'s batch (deterministic in `(seed, step)`).
pub fn make_batch(
    set: &TrainingSet,
    seed: u64,
    step: u64,
    shape: BatchShape,
    size: u32,
) -> Result<Batch, Error> {
    let mut rng = StdRng::seed_from_u64(seed ^ step.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut b = Batch {
        step,
        x: Vec::new(),
        y: Vec::new(),
        ph: Vec::new(),
        pr: Vec::new(),
        yt: Vec::new(),
        yt1: Vec::new(),
        actions: Vec::new(),
    };
    fn any_frame<'a>(clips: &'a [Clip], rng: &mut StdRng) -> (&'a Clip, usize) {
        let c = &clips[rng.random_range(0..clips.len())];
        (c, rng.random_range(0..c.frames.len()))
    }
    for _ in 0..shape.images {
        let (c, t) = any_frame(&set.human, &mut rng);
        b.x.extend(c.tensor_data(t, size)?);
        let (c, t) = any_frame(&set.robot, &mut rng);
        b.y.extend(c.tensor_data(t, size)?);
        if !set.pairs.is_empty() {
            let p = &set.pairs[rng.random_range(0..set.pairs.len())];
            for ((id, f), out) in [(&p.human, &mut b.ph), (&p.robot, &mut b.pr)] {
                let clip = set
                    .pair_clips
                    .get(id)
                    .ok_or_else(|| Error::Data(format!("aligned episode {id} has no frames")))?;
                out.extend(clip.tensor_data(*f, size)?);
            }
        }
    }
    for _ in 0..shape.transitions {
        let c = &set.robot[rng.random_range(0..set.robot.len())];
        let t = rng.random_range(0..c.frames.len() - 1);
        b.yt.extend(c.tensor_data(t, size)?);
        b.yt1.extend(c.tensor_data(t + 1, size)?);
        let a = c.actions.as_ref().map(|a| a[t].clone()).unwrap_or_default();
        b.actions.extend(a);
    }
    Ok(b)
}

/// Background decoding of batches `start, start+1, …` on `workers` threads, handed out
/// in step order; at most `ahead` batches wait decoded.
pub struct Loader {
    rx: crossbeam_channel::Receiver<Result<Batch, Error>>,
    waiting: BTreeMap<u64, Batch>,
    next: u64,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Loader {
    pub fn start(
        set: Arc<TrainingSet>,
        seed: u64,
        start: u64,
        shape: BatchShape,
        size: u32,
        workers: usize,
        ahead: usize,
    ) -> Loader {
        let (tx, rx) = crossbeam_channel::bounded(ahead.max(1));
        let counter = Arc::new(AtomicU64::new(start));
        let stop = Arc::new(AtomicBool::new(false));
        let threads = (0..workers.max(1))
            .map(|_| {
                let (set, tx, counter, stop) = (set.clone(), tx.clone(), counter.clone(), stop.clone());
                std::thread::spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        let s = counter.fetch_add(1, Ordering::Relaxed);
                        if tx.send(make_batch(&set, seed, s, shape, size)).is_err() {
                            break;
                        }
                    }
                })
            })
            .collect();
        Loader {
            rx,
            waiting: BTreeMap::new(),
            next: start,
            stop,
            threads,
        }
    }

    /// The next step's batch, and whether it had to be waited for (the step outran the
    /// loader).
    pub fn next_batch(&mut self) -> Result<(Batch, bool), Error> {
        let mut waited = false;
        loop {
            if let Some(b) = self.waiting.remove(&self.next) {
                self.next += 1;
                return Ok((b, waited));
            }
            let b = match self.rx.try_recv() {
                Ok(b) => b,
                Err(_) => {
                    waited = true;
                    self.rx
                        .recv()
                        .map_err(|_| Error::Data("the data loader stopped".into()))?
                }
            }?;
            self.waiting.insert(b.step, b);
        }
    }
}

impl Drop for Loader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Unblock workers waiting to send, then join them.
        while self.rx.try_recv().is_ok() {}
        for t in self.threads.drain(..) {
            while !t.is_finished() {
                while self.rx.try_recv().is_ok() {}
                std::thread::yield_now();
            }
            let _ = t.join();
        }
    }
}
