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
//! asks. Everything is seeded by `(seed, task, trial)`.
//!
//! The loop is written against [`OneShot`], so the scripted oracle ([`Oracle`]) runs
//! through exactly the code a trained policy ([`PolicyLearner`]) does.

use rand::{Rng, SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};
use tch::nn::Module;
use tch::{Device, Tensor};

use milv_sim::Vec2;
use milv_sim::env::{Sim, Task, expert_action, pushing_task, rollout, swap_distractor};
use milv_sim::push::object_catalog;
use milv_sim::render::Domain;
use milv_sim::shapes::{Shape, test_shapes, training_shapes};

use crate::gan::cyclegan::Nets;
use crate::meta::policy::{Input, PolicyNet, Variant};
use crate::run::image::to_chw;
use crate::{Error, Result};

/// Something that learns a task from one human video and then acts.
pub trait OneShot {
    /// Adapts to one human demonstration (RGB24 frames).
    fn adapt(&mut self, demo: &[Vec<u8>]) -> Result<()>;
    /// The action for the current robot frame (RGB24). `sim` is there for privileged
    /// oracles; a learned policy reads only `frame`.
    fn act(&mut self, sim: &Sim, frame: &[u8]) -> Result<Vec2>;
    /// The imitation loss (the outer loss's units) of the policy before and after the last
    /// adaptation, on robot `frames` whose expert actions are `actions`; None for a
    /// learner without parameters (the oracle).
    fn imitation_loss(&mut self, _frames: &[Vec<u8>], _actions: &[[f32; 2]]) -> Result<Option<[f64; 2]>> {
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
    /// Mean imitation loss over the trials before (θ) and after (θ′) adapting on the demo,
    /// on the expert's rollout of each trial's execution instance: how much the inner step
    /// helps on the instances evaluated (absent for the oracle and older reports).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_pre: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_post: Option<f64>,
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

/// Runs the protocol; `progress(done, total)` after every trial.
pub fn evaluate_one_shot(
    learner: &mut dyn OneShot,
    opts: &EvalOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<FamilyResult> {
    let names = opts.family.tasks_of(opts.split);
    let total = names.len() * opts.seeds.len() * opts.trials;
    let mut done = 0;
    let mut per_task = Vec::with_capacity(names.len());
    let (mut pre, mut post, mut measured) = (0.0, 0.0, 0usize);
    for (k, name) in names.iter().enumerate() {
        let mut o = TaskOutcome {
            task: name.clone(),
            ..TaskOutcome::default()
        };
        for &seed in &opts.seeds {
            for trial in 0..opts.trials {
                let (own_demo, exec_task) = trial_tasks_of(opts.family, opts.split, k, seed, trial)?;
                let demo_task = match opts.demo {
                    DemoSource::Own => own_demo,
                    DemoSource::Swap => {
                        trial_tasks_of(opts.family, opts.split, (k + 1) % names.len(), seed, trial)?.0
                    }
                };
                let empty = || Error::Config(format!("task {name}: empty instance"));
                let who = match opts.demo_domain {
                    milv_data::Domain::Human => Domain::Human,
                    milv_data::Domain::Robot => Domain::Robot,
                };
                let demo = rollout(
                    Sim::reset(demo_task, who, opts.image_size).ok_or_else(empty)?,
                    expert_action,
                );
                learner.adapt(&demo.frames)?;
                let expert = rollout(
                    Sim::reset(exec_task.clone(), Domain::Robot, opts.image_size).ok_or_else(empty)?,
                    expert_action,
                );
                // The last frame's action is a placeholder (no step follows it).
                let n = expert.frames.len().saturating_sub(1);
                if let Some([a, b]) = learner.imitation_loss(&expert.frames[..n], &expert.actions[..n])? {
                    (pre, post, measured) = (pre + a, post + b, measured + 1);
                }
                let mut sim = Sim::reset(exec_task, Domain::Robot, opts.image_size).ok_or_else(empty)?;
                while !sim.done() {
                    let frame = sim.observe();
                    let a = learner.act(&sim, &frame)?;
                    sim.step(a);
                }
                o.trials += 1;
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
        split: opts.split,
        demo: opts.demo,
        demo_domain: opts.demo_domain,
        loss_pre: (measured > 0).then(|| pre / measured as f64),
        loss_post: (measured > 0).then(|| post / measured as f64),
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

    fn act(&mut self, _sim: &Sim, frame: &[u8]) -> Result<Vec2> {
        let th = self
            .adapted
            .as_ref()
            .ok_or_else(|| Error::Config("act before adapt".into()))?;
        let obs = self.observations(&[frame]);
        let a = tch::no_grad(|| self.net.act(th, &obs));
        let s = self.net.cfg.action_scale;
        let v: Vec<f32> = Vec::try_from(a.to_device(Device::Cpu).contiguous().view([-1]))?;
        Ok(Vec2::new(
            v.first().copied().unwrap_or(0.0) * s as f32,
            v.get(1).copied().unwrap_or(0.0) * s as f32,
        ))
    }

    fn imitation_loss(&mut self, frames: &[Vec<u8>], actions: &[[f32; 2]]) -> Result<Option<[f64; 2]>> {
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
        let loss = |params: &[Tensor]| -> f64 {
            tch::no_grad(|| self.net.bc_loss(params, &obs, &target, &ones)).double_value(&[])
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
    #[serde(flatten)]
    pub result: FamilyResult,
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
        s += &format!("| {}{note} |", v.label());
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
        }
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

    /// Records the demonstrations it is shown; acts like the expert.
    #[derive(Default)]
    struct Recorder(Vec<Vec<u8>>);

    impl OneShot for Recorder {
        fn adapt(&mut self, demo: &[Vec<u8>]) -> Result<()> {
            self.0.push(demo.last().cloned().unwrap_or_default());
            Ok(())
        }
        fn act(&mut self, sim: &Sim, _frame: &[u8]) -> Result<Vec2> {
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
    }
}
