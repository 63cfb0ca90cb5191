//! One-shot evaluation in milv-sim (paper section 5.1): for every held-out task — the 12
//! test shapes, or the 8 test objects — and every trial, the learner watches ONE human
//! video of a fresh instance of the task, adapts, and then acts for 50 steps from the
//! robot camera's frames. Success is milv-sim's: the LCS criterion for drawing, the
//! target's centre in the square at the last step for pushing. A failed push that moved
//! the distractor counts as *wrong object*, any other failure as *control* (Table 2).
//!
//! Trial instances: drawing places the test shape at a random offset (the same place in
//! the demo and the execution); pushing draws a layout for the test object and then, for
//! the execution, swaps the distractor for another test object, as the paper's protocol
//! asks. Everything is seeded by `(seed, task, trial)`. Diagnostics: `split` Train runs the
//! training shapes / objects at fresh positions, [`Instances`] runs instances listed in a
//! file (those a policy trained on) from other start positions of the end-effector.
//!
//! The loop is written against [`OneShot`], so the scripted oracle ([`Oracle`]) runs
//! through exactly the code a trained policy ([`PolicyLearner`]) does.

use rand::{Rng, SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};
use tch::nn::Module;
use tch::{Device, Tensor};

use milv_sim::Vec2;
use milv_sim::env::{
    MOVED_CM, PushOutcome, Sim, Task, another_start, expert_action, pushing_task, rollout, swap_distractor,
};
use milv_sim::push::object_catalog;
use milv_sim::render::Domain;
use milv_sim::shapes::{Shape, test_shapes, training_shapes};

use crate::gan::cyclegan::Nets;
use crate::meta::policy::{Input, PolicyNet, Variant, standardised_states};
use crate::run::image::to_chw;
use crate::{Error, Result};

/// Something that learns a task from one human video and then acts.
pub trait OneShot {
    /// Adapts to one human demonstration (RGB24 frames).
    fn adapt(&mut self, demo: &[Vec<u8>]) -> Result<()>;
    /// The action for the current robot frame (RGB24). `sim` is there for privileged
    /// oracles; a learned policy reads only `frame` (and, trained with `--state`, the
    /// robot's own end-effector position, [`Sim::state`]).
    fn act(&mut self, sim: &Sim, frame: &[u8]) -> Result<Vec2>;
    /// The imitation loss (the outer loss's units) of the policy before and after the last
    /// adaptation, on robot `frames` (robot `states`) whose expert actions are `actions`;
    /// None for a learner without parameters (the oracle).
    fn imitation_loss(
        &mut self,
        _frames: &[Vec<u8>],
        _states: &[[f32; 2]],
        _actions: &[[f32; 2]],
    ) -> Result<Option<[f64; 2]>> {
        Ok(None)
    }
}

/// The scripted expert behind the [`OneShot`] interface: an upper bound, and a check that
/// the evaluator's loop does not lose successes.
pub struct Oracle;

impl OneShot for Oracle {
    fn adapt(&mut self, _demo: &[Vec<u8>]) -> Result<()> {
        Ok(())
    }

    fn act(&mut self, sim: &Sim, _frame: &[u8]) -> Result<Vec2> {
        Ok(expert_action(sim))
    }
}

/// The task family evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Family {
    Drawing,
    Pushing,
}

impl std::str::FromStr for Family {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "drawing" => Ok(Family::Drawing),
            "pushing" => Ok(Family::Pushing),
            _ => Err(format!("unknown task family {s:?} (drawing | pushing)")),
        }
    }
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::Drawing => "drawing",
            Family::Pushing => "pushing",
        }
    }

    /// Names of the held-out tasks.
    pub fn tasks(self) -> Vec<String> {
        self.tasks_of(EvalSplit::Test)
    }

    /// Names of the tasks of `split`: the training shapes / objects, or the held-out ones.
    pub fn tasks_of(self, split: EvalSplit) -> Vec<String> {
        match self {
            Family::Drawing => shapes_of(split).into_iter().map(|s| s.name).collect(),
            Family::Pushing => objects_of(split).into_iter().map(|o| o.name).collect(),
        }
    }
}

/// Which tasks a policy is evaluated on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EvalSplit {
    /// Training shapes / objects at new positions: does the policy fit what it saw?
    Train,
    /// Held-out shapes / objects: does it generalise (the paper's protocol)?
    #[default]
    Test,
}

impl std::str::FromStr for EvalSplit {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "train" => Ok(EvalSplit::Train),
            "test" => Ok(EvalSplit::Test),
            _ => Err(format!("unknown split {s:?} (train | test)")),
        }
    }
}

/// Which demonstration the learner adapts on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DemoSource {
    /// A demo of the task executed (the protocol).
    #[default]
    Own,
    /// A demo of the next task of the split: the drop in success against `own` measures
    /// how much the policy uses the demonstration at all.
    Swap,
}

impl std::str::FromStr for DemoSource {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "own" => Ok(DemoSource::Own),
            "swap" => Ok(DemoSource::Swap),
            _ => Err(format!("unknown demo source {s:?} (own | swap)")),
        }
    }
}

fn shapes_of(split: EvalSplit) -> Vec<Shape> {
    match split {
        EvalSplit::Train => training_shapes(),
        EvalSplit::Test => test_shapes(),
    }
}

fn objects_of(split: EvalSplit) -> Vec<milv_sim::push::ObjSpec> {
    let (train, test) = object_catalog();
    match split {
        EvalSplit::Train => train,
        EvalSplit::Test => test,
    }
}

/// The demonstration and execution instances of trial `trial` of held-out task `task`.
pub fn trial_tasks(family: Family, task: usize, seed: u64, trial: usize) -> Result<(Task, Task)> {
    trial_tasks_of(family, EvalSplit::Test, task, seed, trial)
}

/// [`trial_tasks`] for task `task` of `split`.
pub fn trial_tasks_of(
    family: Family,
    split: EvalSplit,
    task: usize,
    seed: u64,
    trial: usize,
) -> Result<(Task, Task)> {
    let mut rng = StdRng::seed_from_u64(
        seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ ((task as u64) << 32) ^ trial as u64,
    );
    match family {
        Family::Drawing => {
            let mut shape = shapes_of(split)
                .get(task)
                .cloned()
                .ok_or_else(|| Error::Config(format!("no shape {task}")))?;
            let off = Vec2::new(rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0));
            for p in &mut shape.path {
                *p += off;
            }
            let t = Task::Drawing { shape };
            Ok((t.clone(), t))
        }
        Family::Pushing => {
            let objs = objects_of(split);
            let want = objs
                .get(task)
                .map(|o| o.name.clone())
                .ok_or_else(|| Error::Config(format!("no object {task}")))?;
            for _ in 0..10_000 {
                let Some(t) = pushing_task(&objs, &mut rng) else {
                    break;
                };
                if let Task::Pushing { target, .. } = &t
                    && target.name == want
                {
                    let exec = swap_distractor(&t, &objs, &mut rng).unwrap_or_else(|| t.clone());
                    return Ok((t, exec));
                }
            }
            Err(Error::Config(format!(
                "could not lay out a pushing task for {want}"
            )))
        }
    }
}

/// How the evaluator's rendered frames reach the learner.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EvalFrames {
    /// As rendered (what reports from before the choice used).
    #[default]
    Raw,
    /// Through the codec milv-sim gen writes training videos with (H.264, CRF 18, 4:2:0),
    /// so a policy meets the artefacts it trained on: each demo as one stream, each
    /// execution frame as its own one-frame stream (an intra frame: the policy must act
    /// before the later frames exist).
    H264,
}

impl EvalFrames {
    pub fn name(self) -> &'static str {
        match self {
            EvalFrames::Raw => "raw",
            EvalFrames::H264 => "h264",
        }
    }
}

impl std::str::FromStr for EvalFrames {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "raw" => Ok(EvalFrames::Raw),
            "h264" => Ok(EvalFrames::H264),
            _ => Err(format!("unknown frame codec {s:?} (raw | h264)")),
        }
    }
}

/// Applies [`EvalFrames`]; the scratch videos live in a temporary folder.
struct FramePipe {
    dir: Option<tempfile::TempDir>,
    size: u32,
}

impl FramePipe {
    /// The rate milv-sim gen writes its videos at (the codec's rate control sees it).
    const FPS: u32 = 10;

    fn new(kind: EvalFrames, size: u32) -> Result<FramePipe> {
        let dir = match kind {
            EvalFrames::Raw => None,
            EvalFrames::H264 => Some(tempfile::tempdir().map_err(|source| Error::Io {
                op: "creating a scratch folder for evaluation videos",
                source,
                path: std::env::temp_dir(),
            })?),
        };
        Ok(FramePipe { dir, size })
    }

    fn clip(&self, frames: Vec<Vec<u8>>) -> Result<Vec<Vec<u8>>> {
        match &self.dir {
            None => Ok(frames),
            Some(d) => Ok(milv_video::roundtrip(
                &d.path().join("clip.mp4"),
                &frames,
                self.size,
                self.size,
                Self::FPS,
                milv_video::Codec::H264,
            )?),
        }
    }

    fn frame(&self, frame: Vec<u8>) -> Result<Vec<u8>> {
        match &self.dir {
            None => Ok(frame),
            Some(_) => Ok(self.clip(vec![frame])?.pop().unwrap_or_default()),
        }
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    pub family: Family,
    /// Trials per task and seed.
    pub trials: usize,
    pub seeds: Vec<u64>,
    /// Camera frame size.
    pub image_size: u32,
    pub split: EvalSplit,
    pub demo: DemoSource,
    /// Who performs the demonstration: a human (the protocol) or the robot.
    pub demo_domain: milv_data::Domain,
    /// Evaluate on these instances (from other start positions) instead of `split`'s
    /// tasks at fresh positions.
    pub instances: Option<Instances>,
    /// Frames as rendered, or through the training videos' codec.
    pub frames: EvalFrames,
}

/// Outcomes of one held-out task.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TaskOutcome {
    pub task: String,
    pub successes: usize,
    pub trials: usize,
    /// Pushing failures that moved the distractor.
    pub wrong_object: usize,
    /// Other failures.
    pub control: usize,
    /// Drawing: each trial's LCS score out of 50 (success from milv-sim's `SUCCESS_LCS`), so
    /// a near miss reads apart from a policy that never finds the line.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scores: Vec<usize>,
    /// Pushing: what each trial did to the objects.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pushes: Vec<PushOutcome>,
}

/// Pushing trials summed up, so a control failure reads at a glance: a policy that never
/// reaches the target, one that moves it the wrong way, one that pushes it short.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PushSummary {
    /// Trials that moved the target by more than [`MOVED_CM`].
    pub target_moved: usize,
    /// Trials that moved the distractor by more than [`MOVED_CM`].
    pub distractor_moved: usize,
    /// Trials that moved neither.
    pub untouched: usize,
    /// Mean distance of the target's centre to the square's centre at the start and the
    /// end (cm); the square is 12 cm wide.
    pub mean_gap_start_cm: f64,
    pub mean_gap_end_cm: f64,
}

impl PushSummary {
    /// None without pushing trials.
    pub fn of<'a>(pushes: impl IntoIterator<Item = &'a PushOutcome>) -> Option<PushSummary> {
        let mut s = PushSummary::default();
        let mut n = 0usize;
        for p in pushes {
            let (t, d) = (p.target_moved_cm > MOVED_CM, p.distractor_moved_cm > MOVED_CM);
            s.target_moved += usize::from(t);
            s.distractor_moved += usize::from(d);
            s.untouched += usize::from(!t && !d);
            s.mean_gap_start_cm += f64::from(p.target_gap_start_cm);
            s.mean_gap_end_cm += f64::from(p.target_gap_cm);
            n += 1;
        }
        (n > 0).then(|| PushSummary {
            mean_gap_start_cm: s.mean_gap_start_cm / n as f64,
            mean_gap_end_cm: s.mean_gap_end_cm / n as f64,
            ..s
        })
    }
}

/// Success of one learner on one task family.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FamilyResult {
    pub family: Family,
    pub successes: usize,
    pub trials: usize,
    pub rate: f64,
    /// 95 % Wilson score interval of the rate.
    pub wilson95: [f64; 2],
    pub wrong_object: usize,
    pub control: usize,
    pub seeds: Vec<u64>,
    pub trials_per_task: usize,
    /// The tasks evaluated on (reports from before it existed: `test`).
    #[serde(default)]
    pub split: EvalSplit,
    /// The demonstrations adapted on.
    #[serde(default)]
    pub demo: DemoSource,
    /// Who performed the demonstrations.
    #[serde(default = "human_domain")]
    pub demo_domain: milv_data::Domain,
    /// The instances file evaluated on instead of the split's tasks (`--instances`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instances: Option<String>,
    /// How the frames reached the learner (older reports: raw).
    #[serde(default)]
    pub frames: EvalFrames,
    /// Mean imitation loss over the trials before (θ) and after (θ′) adapting on the demo,
    /// on the expert's rollout of each trial's execution instance: how much the inner step
    /// helps on the instances evaluated (absent for the oracle and older reports).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_pre: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_post: Option<f64>,
    /// Pushing: what the trials did to the objects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pushing: Option<PushSummary>,
    pub per_task: Vec<TaskOutcome>,
}

fn human_domain() -> milv_data::Domain {
    milv_data::Domain::Human
}

/// The 95 % Wilson score interval for `k` successes in `n` trials.
pub fn wilson95(k: usize, n: usize) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let z = 1.959_963_984_540_054_f64;
    let (n, p) = (n as f64, k as f64 / n as f64);
    let d = 1.0 + z * z / n;
    let c = (p + z * z / (2.0 * n)) / d;
    let h = z / d * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    // At k = 0 (k = n) the bound is exactly 0 (1); say so rather than leave rounding.
    let lo = if k == 0 { 0.0 } else { (c - h).max(0.0) };
    let hi = if k as f64 == n { 1.0 } else { (c + h).min(1.0) };
    [lo, hi]
}

/// Task instances read from milv-sim's `instances.jsonl` (`milv-sim gen` writes one row
/// per generated instance): evaluating on them from other start positions asks whether the
/// policy reproduces what it trained on (the ladder's R0).
#[derive(Clone, Debug, PartialEq)]
pub struct Instances {
    /// Where they were read from (recorded in the report).
    pub source: String,
    pub tasks: Vec<Task>,
}

#[derive(Deserialize)]
struct InstanceRow {
    task: Task,
}

impl Instances {
    /// Reads `instances.jsonl`; every instance must be of `family`.
    pub fn load(path: &std::path::Path, family: Family) -> Result<Instances> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            op: "reading the instances",
            source,
            path: path.to_path_buf(),
        })?;
        let mut tasks = Vec::new();
        for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
            let row: InstanceRow = serde_json::from_str(line).map_err(|e| {
                Error::Data(format!("{} line {}: not an instance: {e}", path.display(), i + 1))
            })?;
            if row.task.family() != family.name() {
                return Err(Error::Data(format!(
                    "{} line {}: a {} instance, but the evaluation is on {}",
                    path.display(),
                    i + 1,
                    row.task.family(),
                    family.name()
                )));
            }
            tasks.push(row.task);
        }
        if tasks.is_empty() {
            return Err(Error::Data(format!("{}: no instances", path.display())));
        }
        Ok(Instances {
            source: path.display().to_string(),
            tasks,
        })
    }
}

/// One trial: the instance demonstrated, the instance executed, and where the execution's
/// end-effector starts (None: the instance's own start point).
struct Trial {
    demo: Task,
    exec: Task,
    start: Option<Vec2>,
}

/// The trials of every task (name, trials), in the order they run.
fn trial_plan(opts: &EvalOptions) -> Result<Vec<(String, Vec<Trial>)>> {
    let mut plan = Vec::new();
    if let Some(inst) = &opts.instances {
        // Each listed instance from `trials` other start positions per seed; a swapped
        // demo is the next listed instance's.
        let n = inst.tasks.len();
        for (k, task) in inst.tasks.iter().enumerate() {
            let mut trials = Vec::new();
            for &seed in &opts.seeds {
                for trial in 0..opts.trials {
                    let mut rng = StdRng::seed_from_u64(
                        seed.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ ((k as u64) << 32) ^ trial as u64,
                    );
                    let demo = match opts.demo {
                        DemoSource::Own => task.clone(),
                        DemoSource::Swap => inst.tasks[(k + 1) % n].clone(),
                    };
                    let start = Some(another_start(task, &mut rng));
                    trials.push(Trial {
                        demo,
                        exec: task.clone(),
                        start,
                    });
                }
            }
            plan.push((format!("{}#{k}", task.id()), trials));
        }
        return Ok(plan);
    }
    let names = opts.family.tasks_of(opts.split);
    for (k, name) in names.iter().enumerate() {
        let mut trials = Vec::new();
        for &seed in &opts.seeds {
            for trial in 0..opts.trials {
                let (own_demo, exec) = trial_tasks_of(opts.family, opts.split, k, seed, trial)?;
                let demo = match opts.demo {
                    DemoSource::Own => own_demo,
                    DemoSource::Swap => {
                        trial_tasks_of(opts.family, opts.split, (k + 1) % names.len(), seed, trial)?.0
                    }
                };
                trials.push(Trial {
                    demo,
                    exec,
                    start: None,
                });
            }
        }
        plan.push((name.clone(), trials));
    }
    Ok(plan)
}

/// Runs the protocol; `progress(done, total)` after every trial.
pub fn evaluate_one_shot(
    learner: &mut dyn OneShot,
    opts: &EvalOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<FamilyResult> {
    let plan = trial_plan(opts)?;
    let total = plan.iter().map(|(_, t)| t.len()).sum();
    let mut done = 0;
    let mut per_task = Vec::with_capacity(plan.len());
    let (mut pre, mut post, mut measured) = (0.0, 0.0, 0usize);
    let pipe = FramePipe::new(opts.frames, opts.image_size)?;
    let who = match opts.demo_domain {
        milv_data::Domain::Human => Domain::Human,
        milv_data::Domain::Robot => Domain::Robot,
    };
    for (name, trials) in plan {
        let mut o = TaskOutcome {
            task: name.clone(),
            ..TaskOutcome::default()
        };
        let empty = || Error::Config(format!("task {name}: empty instance"));
        for Trial { demo, exec, start } in trials {
            let demo = rollout(
                Sim::reset(demo, who, opts.image_size).ok_or_else(empty)?,
                expert_action,
            );
            learner.adapt(&pipe.clip(demo.frames)?)?;
            let reset = || -> Result<Sim> {
                let sim = Sim::reset(exec.clone(), Domain::Robot, opts.image_size).ok_or_else(empty)?;
                Ok(match start {
                    Some(p) => sim.start_at(p),
                    None => sim,
                })
            };
            let expert = rollout(reset()?, expert_action);
            let expert_frames = pipe.clip(expert.frames)?;
            // The last frame's action is a placeholder (no step follows it).
            let n = expert_frames.len().saturating_sub(1);
            if let Some([a, b]) =
                learner.imitation_loss(&expert_frames[..n], &expert.states[..n], &expert.actions[..n])?
            {
                (pre, post, measured) = (pre + a, post + b, measured + 1);
            }
            let mut sim = reset()?;
            while !sim.done() {
                let frame = pipe.frame(sim.observe())?;
                let a = learner.act(&sim, &frame)?;
                sim.step(a);
            }
            o.trials += 1;
            if opts.family == Family::Drawing {
                o.scores.push(sim.score());
            }
            o.pushes.extend(sim.push_outcome());
            if sim.success() {
                o.successes += 1;
            } else if opts.family == Family::Pushing && sim.distractor_moved() {
                o.wrong_object += 1;
            } else {
                o.control += 1;
            }
            done += 1;
            progress(done, total);
        }
        per_task.push(o);
    }
    let sum = |f: fn(&TaskOutcome) -> usize| per_task.iter().map(f).sum::<usize>();
    let (successes, trials) = (sum(|t| t.successes), sum(|t| t.trials));
    Ok(FamilyResult {
        family: opts.family,
        successes,
        trials,
        rate: successes as f64 / trials.max(1) as f64,
        wilson95: wilson95(successes, trials),
        wrong_object: sum(|t| t.wrong_object),
        control: sum(|t| t.control),
        seeds: opts.seeds.clone(),
        trials_per_task: opts.trials * opts.seeds.len(),
        split: if opts.instances.is_some() {
            EvalSplit::Train
        } else {
            opts.split
        },
        demo: opts.demo,
        demo_domain: opts.demo_domain,
        instances: opts.instances.as_ref().map(|i| i.source.clone()),
        frames: opts.frames,
        loss_pre: (measured > 0).then(|| pre / measured as f64),
        loss_post: (measured > 0).then(|| post / measured as f64),
        pushing: PushSummary::of(per_task.iter().flat_map(|t| &t.pushes)),
        per_task,
    })
}

/// A trained meta-policy as a one-shot learner: the demo (translated and encoded as the
/// variant's training inputs were) drives one inner step, then each robot frame (encoded
/// by F's encoder for latent variants) gives an action.
pub struct PolicyLearner {
    pub net: PolicyNet,
    pub variant: Variant,
    pub alpha: f64,
    /// G and F of the translator (all variants but DAML).
    pub translator: Option<Nets>,
    pub image_size: u32,
    adapted: Option<Vec<Tensor>>,
}

impl PolicyLearner {
    pub fn new(
        net: PolicyNet,
        variant: Variant,
        alpha: f64,
        translator: Option<Nets>,
        image_size: u32,
    ) -> Result<Self> {
        if variant != Variant::Daml && translator.is_none() {
            return Err(Error::Config(format!(
                "variant {} needs its translator (the A-CycleGAN checkpoint)",
                variant.name()
            )));
        }
        Ok(PolicyLearner {
            net,
            variant,
            alpha,
            translator,
            image_size,
            adapted: None,
        })
    }

    fn device(&self) -> Device {
        self.net.vs.device()
    }

    fn images(&self, frames: &[&[u8]]) -> Tensor {
        let s = self.image_size;
        let mut data = Vec::with_capacity(frames.len() * 3 * (s * s) as usize);
        for f in frames {
            data.extend(to_chw(f, s, s, s));
        }
        Tensor::from_slice(&data)
            .view([frames.len() as i64, 3, i64::from(s), i64::from(s)])
            .to_device(self.device())
    }

    /// Robot states `[T, S]` standardised as in training, for a policy with a state input.
    fn states(&self, states: &[[f32; 2]]) -> Option<Tensor> {
        let norm = &self.net.cfg.state_norm;
        (self.net.cfg.state_dim > 0).then(|| standardised_states(states, norm).to_device(self.device()))
    }

    /// Robot frames as the policy reads them: images, or F's latents of them.
    fn observations(&self, frames: &[&[u8]]) -> Tensor {
        let y = self.images(frames);
        match (self.net.cfg.input, &self.translator) {
            (Input::Latent, Some(n)) => tch::no_grad(|| n.f.encode(&y)),
            _ => y,
        }
    }
}

impl OneShot for PolicyLearner {
    fn adapt(&mut self, demo: &[Vec<u8>]) -> Result<()> {
        let frames: Vec<&[u8]> = demo.iter().map(Vec::as_slice).collect();
        let x = self.images(&frames);
        let seq = tch::no_grad(|| match (self.variant, &self.translator) {
            (Variant::Daml, _) | (_, None) => x.shallow_clone(),
            (Variant::Feedimg, Some(n)) => n.g.forward(&x),
            (_, Some(n)) => n.f.encode(&n.g.forward(&x)),
        });
        if seq.size()[0] < self.net.cfg.min_frames() as i64 {
            return Err(Error::Data(format!(
                "the demonstration has {} frames; the adaptation loss needs at least {}",
                seq.size()[0],
                self.net.cfg.min_frames()
            )));
        }
        let (adapted, _) = self
            .net
            .adapt(&self.net.theta, &self.net.psi, &seq, self.alpha, false);
        self.adapted = Some(adapted.iter().map(Tensor::detach).collect());
        Ok(())
    }

    fn act(&mut self, sim: &Sim, frame: &[u8]) -> Result<Vec2> {
        let th = self
            .adapted
            .as_ref()
            .ok_or_else(|| Error::Config("act before adapt".into()))?;
        let obs = self.observations(&[frame]);
        let state = self.states(&[sim.state()]);
        let a = tch::no_grad(|| self.net.act_with(th, &obs, state.as_ref()));
        let s = self.net.cfg.action_scale;
        let v: Vec<f32> = Vec::try_from(a.to_device(Device::Cpu).contiguous().view([-1]))?;
        Ok(Vec2::new(
            v.first().copied().unwrap_or(0.0) * s as f32,
            v.get(1).copied().unwrap_or(0.0) * s as f32,
        ))
    }

    fn imitation_loss(
        &mut self,
        frames: &[Vec<u8>],
        states: &[[f32; 2]],
        actions: &[[f32; 2]],
    ) -> Result<Option<[f64; 2]>> {
        let th = self
            .adapted
            .as_ref()
            .ok_or_else(|| Error::Config("imitation loss before adapt".into()))?;
        let frames: Vec<&[u8]> = frames.iter().map(Vec::as_slice).collect();
        let obs = self.observations(&frames);
        let scale = self.net.cfg.action_scale as f32;
        let flat: Vec<f32> = actions.iter().flat_map(|a| a.map(|x| x / scale)).collect();
        let target = Tensor::from_slice(&flat).view([-1, 2]).to_device(self.device());
        let ones = Tensor::ones([target.size()[0]], (tch::Kind::Float, self.device()));
        let state = self.states(states);
        let loss = |params: &[Tensor]| -> f64 {
            tch::no_grad(|| {
                self.net
                    .bc_loss_with(params, &obs, state.as_ref(), &target, &ones)
            })
            .double_value(&[])
        };
        Ok(Some([loss(&self.net.theta), loss(th)]))
    }
}

/// One evaluated policy: the row of the success table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalRecord {
    pub variant: Variant,
    pub policy: String,
    pub dataset: String,
    pub dataset_version: u64,
    pub translator_model: Option<String>,
    pub meta_steps: u64,
    /// The policy also read the robot's end-effector state (`meta --state`): not the
    /// paper's image-only policy, and its table row says so.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub state_input: bool,
    /// The policy imitated the true robot actions, not π_I's (`meta --true-actions`): a
    /// diagnostic, not the method, and its table row says so.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub true_actions: bool,
    #[serde(flatten)]
    pub result: FamilyResult,
}

impl EvalRecord {
    /// What sets this policy apart from the paper's (empty for the paper's own setting).
    pub fn setting_note(&self) -> String {
        let mut note = String::new();
        if self.state_input {
            note += " (+ robot state input)";
        }
        if self.true_actions {
            note += " (true robot actions as targets)";
        }
        note
    }
}

fn pct(x: f64) -> String {
    format!("{:.1} %", 100.0 * x)
}

/// The paper's Table 1 (success per variant and family, with counts and 95 % Wilson
/// intervals) and Table 2 (failure modes of pushing) as Markdown.
pub fn tables_markdown(records: &[EvalRecord]) -> String {
    let mut fams: Vec<Family> = records.iter().map(|r| r.result.family).collect();
    fams.sort_by_key(|f| f.name());
    fams.dedup();
    let find = |v: Variant, f: Family| records.iter().find(|r| r.variant == v && r.result.family == f);
    let present: Vec<Variant> = Variant::ALL
        .into_iter()
        .filter(|v| records.iter().any(|r| r.variant == *v))
        .collect();
    let mut s = String::from("| Method |");
    for f in &fams {
        s += &format!(" Simulated {} |", f.name());
    }
    s += "\n|---|";
    s += &"---|".repeat(fams.len());
    s += "\n";
    for v in &present {
        // Rows are the paper's protocol (held-out tasks, own demos) unless a record says
        // otherwise.
        let note = records
            .iter()
            .filter(|r| r.variant == *v)
            .map(|r| match (r.result.split, r.result.demo) {
                (EvalSplit::Test, DemoSource::Own) => "",
                (EvalSplit::Train, DemoSource::Own) => " (training tasks)",
                (EvalSplit::Test, DemoSource::Swap) => " (swapped demos)",
                (EvalSplit::Train, DemoSource::Swap) => " (training tasks, swapped demos)",
            })
            .next()
            .unwrap_or("");
        let mine: Vec<&EvalRecord> = records.iter().filter(|r| r.variant == *v).collect();
        s += &format!(
            "| {}{note}{} |",
            v.label(),
            mine.iter().map(|r| r.setting_note()).max().unwrap_or_default()
        );
        for f in &fams {
            s += &match find(*v, *f) {
                Some(r) => {
                    let x = &r.result;
                    format!(
                        " {} ({}/{}; 95 % CI {:.1}–{:.1}) |",
                        pct(x.rate),
                        x.successes,
                        x.trials,
                        100.0 * x.wilson95[0],
                        100.0 * x.wilson95[1]
                    )
                }
                None => " – |".into(),
            };
        }
        s += "\n";
    }
    if fams.contains(&Family::Pushing) {
        s += "\nFailure modes, simulated pushing (share of the failed trials):\n\n";
        s += "| Method | Identify object | Control | failures |\n|---|---|---|---|\n";
        for v in &present {
            if let Some(r) = find(*v, Family::Pushing) {
                let x = &r.result;
                let n = x.wrong_object + x.control;
                let share = |k: usize| {
                    if n == 0 {
                        "–".to_string()
                    } else {
                        pct(k as f64 / n as f64)
                    }
                };
                s += &format!(
                    "| {} | {} ({}) | {} ({}) | {n} |\n",
                    v.label(),
                    share(x.wrong_object),
                    x.wrong_object,
                    share(x.control),
                    x.control
                );
            }
        }
    }
    s += "\nWhat each row trained on and how it was evaluated:\n\n";
    s += "| Method | family | dataset@version | translator | meta steps | trials per task |\n|---|---|---|---|---:|---:|\n";
    for v in &present {
        for f in &fams {
            if let Some(r) = find(*v, *f) {
                s += &format!(
                    "| {} | {} | `{}@{}` | {} | {} | {} (seeds {:?}) |\n",
                    v.label(),
                    f.name(),
                    r.dataset,
                    r.dataset_version,
                    r.translator_model.as_deref().unwrap_or("–"),
                    r.meta_steps,
                    r.result.trials_per_task,
                    r.result.seeds
                );
            }
        }
    }
    s
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn wilson_interval_matches_the_formula_s_known_values() {
        // Worked by hand from Wilson's formula with z = 1.96.
        let [lo, hi] = wilson95(5, 10);
        assert!(
            (lo - 0.236_593).abs() < 1e-5 && (hi - 0.763_407).abs() < 1e-5,
            "{lo} {hi}"
        );
        let [lo, hi] = wilson95(0, 20);
        assert!(lo == 0.0 && (hi - 0.161_129).abs() < 1e-5, "{hi}");
        assert_eq!(wilson95(0, 0), [0.0, 1.0]);
    }

    /// The oracle through the evaluator reaches exactly the success of the scripted
    /// expert run directly by milv-sim on the same execution instances.
    #[test]
    fn the_oracle_through_the_evaluator_reaches_the_expert_s_success() {
        for family in [Family::Drawing, Family::Pushing] {
            let opts = EvalOptions {
                family,
                trials: 2,
                seeds: vec![3],
                image_size: 32,
                split: EvalSplit::Test,
                demo: DemoSource::Own,
                demo_domain: milv_data::Domain::Human,
                instances: None,
                frames: EvalFrames::Raw,
            };
            let got = evaluate_one_shot(&mut Oracle, &opts, &mut |_, _| {}).unwrap();
            let mut expert = 0;
            for k in 0..family.tasks().len() {
                for trial in 0..2 {
                    let (_, exec) = trial_tasks(family, k, 3, trial).unwrap();
                    let r = rollout(Sim::reset(exec, Domain::Robot, 32).unwrap(), expert_action);
                    expert += usize::from(r.success);
                }
            }
            assert_eq!(got.trials, family.tasks().len() * 2);
            assert_eq!(got.successes, expert, "{family:?}");
            assert!(
                got.rate > 0.7,
                "{family:?}: the expert succeeded on {:.2}",
                got.rate
            );
            assert_eq!(got.successes + got.wrong_object + got.control, got.trials);
            match (family, &got.pushing) {
                (Family::Drawing, None) => {}
                (Family::Pushing, Some(p)) => {
                    // The expert moves every target and ends inside the 12 cm square.
                    assert_eq!(p.target_moved, got.trials, "{p:?}");
                    assert_eq!(p.untouched, 0, "{p:?}");
                    assert!(p.mean_gap_start_cm > 10.0 && p.mean_gap_end_cm < 6.0, "{p:?}");
                    let per_trial: usize = got.per_task.iter().map(|t| t.pushes.len()).sum();
                    assert_eq!(per_trial, got.trials);
                }
                (f, p) => panic!("{f:?}: push summary {p:?}"),
            }
        }
    }

    #[test]
    fn the_push_summary_counts_what_each_trial_moved() {
        let p = |t: f32, d: f32, gap: f32| PushOutcome {
            target_moved_cm: t,
            distractor_moved_cm: d,
            target_gap_start_cm: 20.0,
            target_gap_cm: gap,
        };
        let s = PushSummary::of(&[p(5.0, 0.0, 10.0), p(0.5, 3.0, 20.0), p(0.0, 0.2, 30.0)]).unwrap();
        assert_eq!((s.target_moved, s.distractor_moved, s.untouched), (1, 1, 1));
        assert!((s.mean_gap_start_cm - 20.0).abs() < 1e-9 && (s.mean_gap_end_cm - 20.0).abs() < 1e-9);
        assert!(PushSummary::of(&[]).is_none());
    }

    #[test]
    fn pushing_trials_keep_the_target_and_swap_the_distractor() {
        for k in 0..8 {
            let (demo, exec) = trial_tasks(Family::Pushing, k, 1, 0).unwrap();
            let (
                Task::Pushing {
                    target: a,
                    distractor: d1,
                    ..
                },
                Task::Pushing {
                    target: b,
                    distractor: d2,
                    ..
                },
            ) = (&demo, &exec)
            else {
                panic!("not pushing")
            };
            assert_eq!(a.name, Family::Pushing.tasks()[k]);
            assert_eq!(a.name, b.name);
            assert_ne!(d1.name, d2.name);
        }
    }

    /// Records the demonstrations it is shown (their last frames) and where each execution
    /// starts; acts like the expert.
    #[derive(Default)]
    struct Recorder(Vec<Vec<u8>>, Vec<Vec2>);

    impl OneShot for Recorder {
        fn adapt(&mut self, demo: &[Vec<u8>]) -> Result<()> {
            self.0.push(demo.last().cloned().unwrap_or_default());
            Ok(())
        }
        fn act(&mut self, sim: &Sim, _frame: &[u8]) -> Result<Vec2> {
            if sim.steps() == 0 {
                self.1.push(sim.end_effector());
            }
            Ok(expert_action(sim))
        }
    }

    /// `--demo swap` shows each trial the demo the next task's trial gets; `--split
    /// train` runs the training shapes.
    #[test]
    fn demo_swap_adapts_on_another_task_s_demo_and_splits_pick_their_tasks() {
        let run = |split, demo| {
            let mut r = Recorder::default();
            let opts = EvalOptions {
                family: Family::Drawing,
                trials: 1,
                seeds: vec![2],
                image_size: 32,
                split,
                demo,
                demo_domain: milv_data::Domain::Human,
                instances: None,
                frames: EvalFrames::Raw,
            };
            let res = evaluate_one_shot(&mut r, &opts, &mut |_, _| {}).unwrap();
            (r.0, res)
        };
        let (own, res) = run(EvalSplit::Test, DemoSource::Own);
        let (swapped, res_swap) = run(EvalSplit::Test, DemoSource::Swap);
        let n = own.len();
        assert_eq!(n, Family::Drawing.tasks().len());
        for k in 0..n {
            assert_ne!(swapped[k], own[k], "task {k} adapted on its own demo");
            assert_eq!(swapped[k], own[(k + 1) % n]);
        }
        // The expert ignores the demo: the swap changes nothing for it.
        assert_eq!(res.successes, res_swap.successes);
        assert_eq!(res_swap.demo, DemoSource::Swap);
        let (train, res) = run(EvalSplit::Train, DemoSource::Own);
        assert_eq!(train.len(), Family::Drawing.tasks_of(EvalSplit::Train).len());
        assert_eq!(res.split, EvalSplit::Train);
        assert_eq!(res.per_task[0].task, training_shapes()[0].name);
        assert_eq!(res.per_task[0].scores.len(), 1);
        let ok = res
            .per_task
            .iter()
            .flat_map(|t| &t.scores)
            .filter(|&&s| s >= milv_sim::shapes::SUCCESS_LCS);
        assert_eq!(ok.count(), res.successes, "scores and successes disagree");
    }

    /// `--instances`: each listed instance runs from `trials` other start positions per
    /// seed, adapting on that instance's own demo (or the next one's with swap); the
    /// file's bad rows are refused with the file and line named.
    #[test]
    fn listed_instances_run_from_other_start_positions_on_their_own_demo() {
        let mut rng = StdRng::seed_from_u64(4);
        let (train, _) = object_catalog();
        let drawing: Vec<Task> = training_shapes()[..2]
            .iter()
            .map(|s| Task::Drawing { shape: s.clone() })
            .collect();
        let pushing: Vec<Task> = (0..2).filter_map(|_| pushing_task(&train, &mut rng)).collect();
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("instances.jsonl");
        for (family, tasks) in [(Family::Drawing, drawing), (Family::Pushing, pushing)] {
            let rows: String = tasks
                .iter()
                .enumerate()
                .map(|(i, t)| serde_json::json!({"index": i, "task": t}).to_string() + "\n")
                .collect();
            std::fs::write(&file, rows).unwrap();
            let inst = Instances::load(&file, family).unwrap();
            assert_eq!(inst.tasks, tasks);
            let other = if family == Family::Drawing {
                Family::Pushing
            } else {
                Family::Drawing
            };
            let e = Instances::load(&file, other).unwrap_err().to_string();
            assert!(e.contains("instances.jsonl line 1"), "{e}");
            let run = |demo| {
                let mut r = Recorder::default();
                let opts = EvalOptions {
                    family,
                    trials: 3,
                    seeds: vec![0],
                    image_size: 32,
                    split: EvalSplit::Test,
                    demo,
                    demo_domain: milv_data::Domain::Robot,
                    instances: Some(inst.clone()),
                    frames: EvalFrames::Raw,
                };
                let res = evaluate_one_shot(&mut r, &opts, &mut |_, _| {}).unwrap();
                (r.0, r.1, res)
            };
            let (own, starts, res) = run(DemoSource::Own);
            let (swapped, _, _) = run(DemoSource::Swap);
            assert_eq!(res.trials, 6);
            assert_eq!(res.split, EvalSplit::Train);
            assert_eq!(res.instances.as_deref(), Some(inst.source.as_str()));
            assert_eq!(res.per_task[1].task, format!("{}#1", tasks[1].id()));
            // The expert acts from every start; it must still succeed almost always.
            assert!(res.successes >= 5, "{family:?}: {}/6", res.successes);
            let demo_of = |t: &Task| {
                rollout(Sim::reset(t.clone(), Domain::Robot, 32).unwrap(), expert_action)
                    .frames
                    .last()
                    .cloned()
                    .unwrap()
            };
            assert_eq!(own[0], demo_of(&tasks[0]));
            assert_eq!(own[3], demo_of(&tasks[1]));
            assert_eq!(swapped[0], demo_of(&tasks[1]));
            // Three different start positions of instance 0, none its own start point.
            let own_start = Sim::reset(tasks[0].clone(), Domain::Robot, 32)
                .unwrap()
                .end_effector();
            assert_eq!(starts.len(), 6);
            assert!(starts[0] != starts[1] && starts[1] != starts[2] && starts[0] != starts[2]);
            assert!(starts[..3].iter().all(|&p| p != own_start));
        }
        std::fs::write(&file, "{\"task\": 3}\n").unwrap();
        let e = Instances::load(&file, Family::Drawing).unwrap_err().to_string();
        assert!(e.contains("line 1: not an instance"), "{e}");
    }

    /// `--frames h264`: the learner sees the demo through the training videos' codec —
    /// close to the render, not equal to it.
    #[test]
    fn h264_frames_reach_the_learner_encoded() {
        let task = Task::Drawing {
            shape: training_shapes()[0].clone(),
        };
        let inst = Instances {
            source: "mem".into(),
            tasks: vec![task],
        };
        let run = |frames| {
            let mut r = Recorder::default();
            let opts = EvalOptions {
                family: Family::Drawing,
                trials: 1,
                seeds: vec![0],
                image_size: 32,
                split: EvalSplit::Train,
                demo: DemoSource::Own,
                demo_domain: milv_data::Domain::Human,
                instances: Some(inst.clone()),
                frames,
            };
            let res = evaluate_one_shot(&mut r, &opts, &mut |_, _| {}).unwrap();
            (r.0, res)
        };
        let (raw, _) = run(EvalFrames::Raw);
        let (enc, res) = run(EvalFrames::H264);
        assert_eq!(res.frames, EvalFrames::H264);
        assert_eq!(res.successes, 1, "the expert ignores the frames");
        assert_eq!(raw[0].len(), enc[0].len());
        let mad = raw[0]
            .iter()
            .zip(&enc[0])
            .map(|(&a, &b)| (f64::from(a) - f64::from(b)).abs())
            .sum::<f64>()
            / raw[0].len() as f64;
        assert!(mad > 0.0 && mad < 10.0, "mean |raw - h264| {mad}");
    }
}
