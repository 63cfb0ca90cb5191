//! The environment: `reset`, `step`, `observe`, `success` for one episode of a task in one
//! domain, and the scripted experts.

use serde::{Deserialize, Serialize};

use crate::geom::{EPISODE_STEPS, Vec2, clamp_action, clamp_to_workspace};
use crate::push::{self, Body, ObjSpec, PushWorld, TargetSquare};
use crate::render::{Domain, Randomization, Renderer, SceneItems};
use crate::shapes::{self, Shape};

/// A task instance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "family", rename_all = "lowercase")]
pub enum Task {
    /// Trace the guide shape with the pen, starting at its first point.
    Drawing { shape: Shape },
    /// Push `target` (not the distractor) into the 12×12 cm square at `square`.
    Pushing {
        target: ObjSpec,
        distractor: ObjSpec,
        square: Vec2,
        target_start: Vec2,
        distractor_start: Vec2,
        pusher_start: Vec2,
    },
}

/// The same pushing layout with a different distractor (≠ target, ≠ the current one), as
/// the paper's test protocol asks.
pub fn swap_distractor(task: &Task, objects: &[ObjSpec], rng: &mut impl rand::Rng) -> Option<Task> {
    let Task::Pushing {
        target, distractor, ..
    } = task
    else {
        return None;
    };
    let others: Vec<&ObjSpec> = objects
        .iter()
        .filter(|o| o.name != target.name && o.name != distractor.name)
        .collect();
    let pick = others.get(rng.random_range(0..others.len().max(1)))?;
    let mut t = task.clone();
    if let Task::Pushing { distractor, .. } = &mut t {
        *distractor = (*pick).clone();
    }
    Some(t)
}

/// A random pushing task from an object set (the train or test catalogue): the target
/// starts 14–22 cm from the square, the distractor away from the straight push line.
pub fn pushing_task(objects: &[ObjSpec], rng: &mut impl rand::Rng) -> Option<Task> {
    if objects.len() < 2 {
        return None;
    }
    let ti = rng.random_range(0..objects.len());
    let mut di = rng.random_range(0..objects.len() - 1);
    if di >= ti {
        di += 1;
    }
    let square = Vec2::new(rng.random_range(12.0..48.0), rng.random_range(12.0..48.0));
    let mut target_start = square;
    for _ in 0..100 {
        let a = rng.random_range(0.0..std::f32::consts::TAU);
        let p = square + Vec2::from_angle(a) * rng.random_range(14.0..22.0);
        if (9.0..=51.0).contains(&p.x) && (9.0..=51.0).contains(&p.y) {
            target_start = p;
            break;
        }
    }
    // The distractor sits off the push line and clear of the square and the target.
    let line = (square - target_start).normalized();
    let mut distractor_start = square + line.perp() * 16.0;
    for _ in 0..100 {
        let p = Vec2::new(rng.random_range(8.0..52.0), rng.random_range(8.0..52.0));
        let along = (p - target_start).dot(line);
        let off = (p - target_start).cross(line).abs();
        let on_path = along > -10.0 && along < (square - target_start).len() + 10.0 && off < 11.0;
        if !on_path && p.dist(square) > 14.0 && p.dist(target_start) > 14.0 {
            distractor_start = p;
            break;
        }
    }
    let pusher_start = random_pusher_start(rng);
    Some(Task::Pushing {
        target: objects[ti].clone(),
        distractor: objects[di].clone(),
        square,
        target_start,
        distractor_start,
        pusher_start,
    })
}

/// Where a pushing episode's pusher starts: along the near edge of the table.
pub fn random_pusher_start(rng: &mut impl rand::Rng) -> Vec2 {
    Vec2::new(rng.random_range(5.0..55.0), rng.random_range(3.0..8.0))
}

/// Another start position for the same instance (evaluating a policy on an instance it
/// trained on, the ladder's R0): drawing puts the pen 1–2 cm off the guide's first point
/// (the guide stays), pushing redraws the pusher's start as [`pushing_task`] does. Pass
/// it to [`Sim::start_at`]; the objects and the goal do not move.
pub fn another_start(task: &Task, rng: &mut impl rand::Rng) -> Vec2 {
    match task {
        Task::Drawing { shape } => {
            let first = shape.path.first().copied().unwrap_or(Vec2::ZERO);
            let a = rng.random_range(0.0..std::f32::consts::TAU);
            clamp_to_workspace(first + Vec2::from_angle(a) * rng.random_range(1.0..2.0))
        }
        Task::Pushing { .. } => random_pusher_start(rng),
    }
}

impl Task {
    pub fn family(&self) -> &'static str {
        match self {
            Task::Drawing { .. } => "drawing",
            Task::Pushing { .. } => "pushing",
        }
    }

    /// `family/name`, the `task_id` of generated episodes.
    pub fn id(&self) -> String {
        match self {
            Task::Drawing { shape } => format!("draw/{}", shape.name),
            Task::Pushing { target, .. } => format!("push/{}", target.name),
        }
    }
}

/// How far an object's centroid must move to count as pushed (cm).
pub const MOVED_CM: f32 = 1.0;

/// What a pushing episode did to its objects (cm), from [`Sim::push_outcome`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PushOutcome {
    /// How far the target's centroid moved from its start.
    pub target_moved_cm: f32,
    /// How far the distractor's centroid moved (over [`MOVED_CM`]: a wrong-object push).
    pub distractor_moved_cm: f32,
    /// The target's distance to the square's centre at the start and now.
    pub target_gap_start_cm: f32,
    pub target_gap_cm: f32,
}

/// One episode in progress.
pub struct Sim {
    task: Task,
    domain: Domain,
    renderer: Renderer,
    ee: Vec2,
    trace: Vec<Vec2>,
    steps: usize,
    /// Pushing: the objects (target first, then the distractor) and the pusher.
    world: Option<PushWorld>,
}

impl Sim {
    /// Starts an episode; the end-effector starts at the task's start point.
    pub fn reset(task: Task, domain: Domain, image_size: u32) -> Option<Sim> {
        Sim::reset_with(task, domain, image_size, &Randomization::default())
    }

    /// [`Sim::reset`] with a randomised look (lighting, texture, camera, clutter).
    pub fn reset_with(task: Task, domain: Domain, image_size: u32, look: &Randomization) -> Option<Sim> {
        let (start, world) = match &task {
            Task::Drawing { shape } => (*shape.path.first()?, None),
            Task::Pushing {
                target,
                distractor,
                target_start,
                distractor_start,
                pusher_start,
                ..
            } => {
                let bodies = vec![
                    Body::new(target.clone(), *target_start, 0.0),
                    Body::new(distractor.clone(), *distractor_start, 0.0),
                ];
                (*pusher_start, Some(PushWorld::new(bodies, *pusher_start)))
            }
        };
        Some(Sim {
            task,
            domain,
            renderer: Renderer::with_randomization(domain, image_size, look)?,
            ee: start,
            trace: vec![start],
            steps: 0,
            world,
        })
    }

    /// The episode with the end-effector (pen or pusher) starting at `p` instead of the
    /// task's start point; call it before the first step.
    pub fn start_at(mut self, p: Vec2) -> Sim {
        let p = clamp_to_workspace(p);
        if let Some(w) = &mut self.world {
            w.pusher = p;
        }
        self.ee = p;
        self.trace = vec![p];
        self
    }

    pub fn task(&self) -> &Task {
        &self.task
    }

    pub fn domain(&self) -> Domain {
        self.domain
    }

    pub fn end_effector(&self) -> Vec2 {
        self.ee
    }

    pub fn steps(&self) -> usize {
        self.steps
    }

    pub fn done(&self) -> bool {
        self.steps >= EPISODE_STEPS
    }

    /// Applies an action (clamped to ±5 cm per axis); returns the action actually applied.
    pub fn step(&mut self, action: Vec2) -> Vec2 {
        let before = self.ee;
        self.ee = clamp_to_workspace(self.ee + clamp_action(action));
        if let Some(w) = &mut self.world {
            // The pusher may stop short when an object jams against the edge.
            w.move_pusher(self.ee);
            self.ee = w.pusher;
        }
        self.trace.push(self.ee);
        self.steps += 1;
        self.ee - before
    }

    /// The current frame as packed RGB24.
    pub fn observe(&mut self) -> Vec<u8> {
        let items = match &self.task {
            Task::Drawing { shape } => SceneItems {
                guide: Some(&shape.path),
                trace: &self.trace,
                ..Default::default()
            },
            Task::Pushing { square, .. } => {
                let h = TargetSquare::SIZE / 2.0;
                let c = *square;
                SceneItems {
                    objects: self
                        .world
                        .iter()
                        .flat_map(|w| w.bodies.iter())
                        .map(|b| (b.world_polygon(), b.spec.color))
                        .collect(),
                    target: Some([
                        c + Vec2::new(-h, -h),
                        c + Vec2::new(h, -h),
                        c + Vec2::new(h, h),
                        c + Vec2::new(-h, h),
                    ]),
                    ..Default::default()
                }
            }
        };
        self.renderer.render(self.ee, &items)
    }

    /// The task's score so far (drawing: LCS points out of 50; pushing: 1 when the
    /// target's centre is in the square).
    pub fn score(&self) -> usize {
        match &self.task {
            Task::Drawing { shape } => shapes::drawing_score(&self.trace, &shape.path),
            Task::Pushing { .. } => usize::from(self.success()),
        }
    }

    pub fn success(&self) -> bool {
        match &self.task {
            Task::Drawing { .. } => self.score() >= shapes::SUCCESS_LCS,
            Task::Pushing { square, .. } => self
                .target_body()
                .is_some_and(|b| TargetSquare { center: *square }.contains(b.pos)),
        }
    }

    /// Pushing: the object to push (the other one is the distractor).
    pub fn target_body(&self) -> Option<&Body> {
        self.world.as_ref().and_then(|w| w.bodies.first())
    }

    /// Pushing: whether the distractor was moved by more than 1 cm (a wrong-object push).
    pub fn distractor_moved(&self) -> bool {
        match (&self.task, &self.world) {
            (Task::Pushing { distractor_start, .. }, Some(w)) => w
                .bodies
                .get(1)
                .is_some_and(|b| b.pos.dist(*distractor_start) > MOVED_CM),
            _ => false,
        }
    }

    /// Pushing: what the episode did to the objects so far, so that a failure reads apart
    /// as "never reached the target", "moved it the wrong way" or "pushed the distractor".
    pub fn push_outcome(&self) -> Option<PushOutcome> {
        let Task::Pushing {
            square,
            target_start,
            distractor_start,
            ..
        } = &self.task
        else {
            return None;
        };
        let w = self.world.as_ref()?;
        let (target, distractor) = (w.bodies.first()?, w.bodies.get(1)?);
        Some(PushOutcome {
            target_moved_cm: target.pos.dist(*target_start),
            distractor_moved_cm: distractor.pos.dist(*distractor_start),
            target_gap_start_cm: target_start.dist(*square),
            target_gap_cm: target.pos.dist(*square),
        })
    }

    /// Low-dimensional state for sidecars: end-effector position (cm).
    pub fn state(&self) -> [f32; 2] {
        [self.ee.x, self.ee.y]
    }
}

/// The scripted expert's action from privileged state.
pub fn expert_action(sim: &Sim) -> Vec2 {
    match sim.task() {
        Task::Drawing { shape } => {
            let way = shapes::expert_waypoints(&shape.path);
            let next = way
                .get(sim.steps() + 1)
                .or(way.last())
                .copied()
                .unwrap_or(sim.end_effector());
            next - sim.end_effector()
        }
        Task::Pushing { square, .. } => match sim.target_body() {
            Some(b) => push::expert_action(sim.end_effector(), b, *square, push::PUSHER_RADIUS_CM),
            None => Vec2::ZERO,
        },
    }
}

/// The mean of the expert's actions with each object as the target: where a policy trained
/// with a squared loss lands when it cannot tell the target from the distractor (behaviour
/// cloning that ignores the demo), at least while nothing in the frame says which object
/// the pusher went for. A baseline for that failure; drawing has no such ambiguity and gets
/// the expert's action.
pub fn blind_expert_action(sim: &Sim) -> Vec2 {
    match (&sim.task, sim.world.as_ref().map(|w| w.bodies.as_slice())) {
        (Task::Pushing { square, .. }, Some([target, distractor])) => {
            let a = push::expert_action(sim.ee, target, *square, push::PUSHER_RADIUS_CM);
            let b = push::expert_action(sim.ee, distractor, *square, push::PUSHER_RADIUS_CM);
            (a + b) * 0.5
        }
        _ => expert_action(sim),
    }
}

/// One recorded episode: frames, actions (the action taken *at* each frame; the last
/// frame gets a zero action), states.
pub struct Rollout {
    pub frames: Vec<Vec<u8>>,
    pub actions: Vec<[f32; 2]>,
    pub states: Vec<[f32; 2]>,
    pub success: bool,
    pub score: usize,
}

/// Runs a policy for a full episode, recording `EPISODE_STEPS + 1` frames.
pub fn rollout(sim: Sim, policy: impl FnMut(&Sim) -> Vec2) -> Rollout {
    let steps = EPISODE_STEPS.saturating_sub(sim.steps());
    rollout_steps(sim, steps, policy)
}

/// Runs a policy for `steps` steps, recording `steps + 1` frames (the last frame gets a
/// zero action).
fn rollout_steps(mut sim: Sim, steps: usize, mut policy: impl FnMut(&Sim) -> Vec2) -> Rollout {
    let mut out = Rollout {
        frames: Vec::with_capacity(steps + 1),
        actions: Vec::with_capacity(steps + 1),
        states: Vec::with_capacity(steps + 1),
        success: false,
        score: 0,
    };
    for _ in 0..steps {
        out.frames.push(sim.observe());
        out.states.push(sim.state());
        let a = policy(&sim);
        let applied = sim.step(a);
        out.actions.push([applied.x, applied.y]);
    }
    out.frames.push(sim.observe());
    out.states.push(sim.state());
    out.actions.push([0.0, 0.0]);
    out.success = sim.success();
    out.score = sim.score();
    out
}

/// Smooth random end-effector motion (robot "random" videos for inverse dynamics): the
/// velocity follows a damped random walk, turning back at the workspace edges.
pub struct SmoothRandom {
    rng: rand::rngs::StdRng,
    vel: Vec2,
}

impl SmoothRandom {
    pub fn new(seed: u64) -> Self {
        use rand::SeedableRng;
        SmoothRandom {
            rng: rand::rngs::StdRng::seed_from_u64(seed),
            vel: Vec2::ZERO,
        }
    }

    pub fn act(&mut self, sim: &Sim) -> Vec2 {
        use rand::Rng;
        let kick = Vec2::new(self.rng.random_range(-1.5..1.5), self.rng.random_range(-1.5..1.5));
        self.vel = self.vel * 0.8 + kick;
        // Steer away from the edges so the motion explores the whole table.
        let p = sim.end_effector();
        let margin = 6.0;
        let w = crate::geom::WORKSPACE_CM;
        if p.x < margin {
            self.vel.x = self.vel.x.abs();
        }
        if p.x > w - margin {
            self.vel.x = -self.vel.x.abs();
        }
        if p.y < margin {
            self.vel.y = self.vel.y.abs();
        }
        if p.y > w - margin {
            self.vel.y = -self.vel.y.abs();
        }
        clamp_action(self.vel)
    }
}

/// A random monotone time warp: progress in [0, 1] at each of `len` frames, starting at 0,
/// ending at 1, with per-frame speed varying smoothly between about 0.5× and 1.5× average.
pub fn time_warp(len: usize, rng: &mut impl rand::Rng) -> Vec<f32> {
    if len < 2 {
        return vec![0.0; len];
    }
    let mut speed = 1.0f32;
    let mut acc = vec![0.0f32];
    for _ in 1..len {
        speed = (speed + rng.random_range(-0.25..0.25)).clamp(0.5, 1.5);
        let last = acc.last().copied().unwrap_or(0.0);
        acc.push(last + speed);
    }
    let total = acc.last().copied().unwrap_or(1.0).max(1e-6);
    acc.iter().map(|a| a / total).collect()
}

/// Points of `path` at the given progress values (arc-length parameterised).
pub fn positions_at(path: &[Vec2], progress: &[f32]) -> Vec<Vec2> {
    const FINE: usize = 1001;
    let fine = shapes::resample(path, FINE);
    progress
        .iter()
        .map(|&s| {
            let k = (s.clamp(0.0, 1.0) * (FINE - 1) as f32).round() as usize;
            fine.get(k).copied().unwrap_or(Vec2::ZERO)
        })
        .collect()
}

/// Ground-truth correspondence of two warps of one motion: for each frame of `a`, the
/// frame of `b` at the nearest progress (monotone, since both warps are).
pub fn warp_correspondence(a: &[f32], b: &[f32]) -> Vec<usize> {
    let mut j = 0;
    a.iter()
        .map(|&s| {
            while j + 1 < b.len() && (b[j + 1] - s).abs() <= (b[j] - s).abs() {
                j += 1;
            }
            j
        })
        .collect()
}

/// Replays end-effector positions (`positions[0]` must be the start): one step per
/// position after the first, so the rollout has `positions.len()` frames.
pub fn replay(sim: Sim, positions: &[Vec2]) -> Rollout {
    let steps = positions.len().saturating_sub(1);
    let start = sim.steps();
    rollout_steps(sim, steps, |s| {
        positions
            .get(s.steps() - start + 1)
            .copied()
            .unwrap_or(s.end_effector())
            - s.end_effector()
    })
}

/// The same motion in both domains at different speeds and lengths: the expert's
/// end-effector path, replayed through a random monotone time warp per domain.
pub struct PairedClips {
    pub human: Rollout,
    pub robot: Rollout,
    /// For each human frame, the robot frame showing the same point of the motion.
    pub human_to_robot: Vec<usize>,
}

/// Records the expert's path on `task`, then replays it warped: `human_len` and
/// `robot_len` frames.
pub fn paired_clips(
    task: &Task,
    image_size: u32,
    human_len: usize,
    robot_len: usize,
    rng: &mut impl rand::Rng,
) -> Option<PairedClips> {
    let reference = Sim::reset(task.clone(), Domain::Robot, 8)?;
    let mut path = vec![reference.end_effector()];
    let mut sim = reference;
    while !sim.done() {
        let a = expert_action(&sim);
        sim.step(a);
        path.push(sim.end_effector());
    }
    let wh = time_warp(human_len, rng);
    let wr = time_warp(robot_len, rng);
    let human = replay(
        Sim::reset(task.clone(), Domain::Human, image_size)?,
        &positions_at(&path, &wh),
    );
    let robot = replay(
        Sim::reset(task.clone(), Domain::Robot, image_size)?,
        &positions_at(&path, &wr),
    );
    Some(PairedClips {
        human,
        robot,
        human_to_robot: warp_correspondence(&wh, &wr),
    })
}

/// Success of one task over its trials.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskResult {
    pub task: String,
    pub successes: usize,
    pub trials: usize,
}

/// What [`evaluate`] returns: per task and overall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub per_task: Vec<TaskResult>,
    pub successes: usize,
    pub trials: usize,
}

impl EvalReport {
    pub fn success_rate(&self) -> f64 {
        if self.trials == 0 {
            0.0
        } else {
            self.successes as f64 / self.trials as f64
        }
    }
}

/// The paper's protocol: for every task, `trials` episodes of 50 steps in `domain`, each
/// with a fresh policy from `make_policy(task, trial)` (where a one-shot learner adapts
/// to the task's demonstration).
pub fn evaluate<P: FnMut(&Sim) -> Vec2>(
    tasks: &[Task],
    trials: usize,
    domain: Domain,
    image_size: u32,
    mut make_policy: impl FnMut(&Task, usize) -> P,
) -> Option<EvalReport> {
    let mut per_task = Vec::with_capacity(tasks.len());
    for task in tasks {
        let mut successes = 0;
        for trial in 0..trials {
            let r = rollout(
                Sim::reset(task.clone(), domain, image_size)?,
                make_policy(task, trial),
            );
            successes += usize::from(r.success);
        }
        per_task.push(TaskResult {
            task: task.id(),
            successes,
            trials,
        });
    }
    Some(EvalReport {
        successes: per_task.iter().map(|t| t.successes).sum(),
        trials: per_task.iter().map(|t| t.trials).sum(),
        per_task,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_drawing_expert_succeeds_on_every_shape_in_both_domains() {
        let mut ok = 0;
        let all: Vec<Shape> = shapes::training_shapes()
            .into_iter()
            .chain(shapes::test_shapes())
            .collect();
        for shape in &all {
            let sim = Sim::reset(Task::Drawing { shape: shape.clone() }, Domain::Robot, 32).unwrap();
            let r = rollout(sim, expert_action);
            assert_eq!(r.frames.len(), EPISODE_STEPS + 1);
            ok += usize::from(r.success);
        }
        assert!(
            ok * 100 >= all.len() * 95,
            "expert succeeded on {ok}/{}",
            all.len()
        );
    }

    #[test]
    fn the_blind_expert_averages_the_two_targets() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let (train, _) = push::object_catalog();
        let task = pushing_task(&train, &mut rng).unwrap();
        let sim = Sim::reset(task.clone(), Domain::Robot, 32).unwrap();
        let Task::Pushing { square, .. } = &task else {
            panic!("not pushing")
        };
        let w = sim.world.as_ref().unwrap();
        let mean = (push::expert_action(sim.ee, &w.bodies[0], *square, push::PUSHER_RADIUS_CM)
            + push::expert_action(sim.ee, &w.bodies[1], *square, push::PUSHER_RADIUS_CM))
            * 0.5;
        assert_eq!(blind_expert_action(&sim), mean);
        assert_ne!(mean, expert_action(&sim), "the two targets' experts agree here");
        let drawing = Sim::reset(
            Task::Drawing {
                shape: shapes::training_shapes().remove(0),
            },
            Domain::Robot,
            32,
        )
        .unwrap();
        assert_eq!(blind_expert_action(&drawing), expert_action(&drawing));
    }

    #[test]
    fn the_expert_succeeds_from_other_start_positions() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let (train, _) = push::object_catalog();
        let mut tasks: Vec<Task> = shapes::training_shapes()
            .into_iter()
            .map(|shape| Task::Drawing { shape })
            .collect();
        tasks.extend((0..6).filter_map(|_| pushing_task(&train, &mut rng)));
        let (mut ok, mut n) = (0, 0);
        for task in &tasks {
            for _ in 0..3 {
                let start = another_start(task, &mut rng);
                let sim = Sim::reset(task.clone(), Domain::Robot, 32)
                    .unwrap()
                    .start_at(start);
                assert_eq!(sim.end_effector(), start);
                if let Task::Drawing { shape } = task {
                    let d = start.dist(shape.path[0]);
                    assert!((0.99..=2.01).contains(&d), "pen started {d} cm off the guide");
                }
                ok += usize::from(rollout(sim, expert_action).success);
                n += 1;
            }
        }
        assert!(ok * 100 >= n * 90, "expert succeeded from {ok}/{n} other starts");
    }

    #[test]
    fn a_random_policy_rarely_succeeds() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut ok = 0;
        let all = shapes::training_shapes();
        for shape in &all {
            for _ in 0..3 {
                let sim = Sim::reset(Task::Drawing { shape: shape.clone() }, Domain::Human, 16).unwrap();
                let r = rollout(sim, |_| {
                    Vec2::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0))
                });
                ok += usize::from(r.success);
            }
        }
        assert!(ok * 10 < all.len() * 3, "random succeeded {ok} times");
    }

    #[test]
    fn the_pushing_expert_succeeds_and_random_rarely_does() {
        use rand::SeedableRng;
        let (train, test) = push::object_catalog();
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let (mut expert_ok, mut random_ok, n) = (0, 0, 40);
        for i in 0..n {
            let objs = if i % 2 == 0 { &train } else { &test };
            let task = pushing_task(objs, &mut rng).unwrap();
            let r = rollout(
                Sim::reset(task.clone(), Domain::Robot, 16).unwrap(),
                expert_action,
            );
            expert_ok += usize::from(r.success);
            let mut policy = SmoothRandom::new(i as u64);
            let r = rollout(Sim::reset(task, Domain::Robot, 16).unwrap(), |s| policy.act(s));
            random_ok += usize::from(r.success);
        }
        assert!(
            expert_ok * 100 >= n * 95,
            "expert pushed {expert_ok}/{n} into the square"
        );
        assert!(
            random_ok * 5 <= n,
            "random pushed {random_ok}/{n} into the square"
        );
    }

    #[test]
    fn warps_are_monotone_and_correspondences_recover_them() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(2);
        let w = time_warp(40, &mut rng);
        assert_eq!((w[0], w[39]), (0.0, 1.0));
        assert!(w.windows(2).all(|p| p[1] > p[0]));
        let c = warp_correspondence(&w, &w);
        assert_eq!(c, (0..40).collect::<Vec<_>>());
        let shape = shapes::training_shapes()[5].clone();
        let p = paired_clips(&Task::Drawing { shape }, 16, 51, 37, &mut rng).unwrap();
        assert_eq!((p.human.frames.len(), p.robot.frames.len()), (51, 37));
        assert_eq!(p.human_to_robot.len(), 51);
        assert_eq!((p.human_to_robot[0], p.human_to_robot[50]), (0, 36));
        assert!(p.human_to_robot.windows(2).all(|w| w[1] >= w[0]));
        // Corresponding frames show nearby end-effector positions in both domains.
        for (i, &j) in p.human_to_robot.iter().enumerate() {
            let (h, r) = (p.human.states[i], p.robot.states[j]);
            assert!(
                Vec2::new(h[0], h[1]).dist(Vec2::new(r[0], r[1])) < 3.0,
                "frame {i}->{j}"
            );
        }
    }

    #[test]
    fn evaluate_counts_per_task_and_overall() {
        let tasks: Vec<Task> = shapes::test_shapes()
            .into_iter()
            .take(3)
            .map(|shape| Task::Drawing { shape })
            .collect();
        let expert = evaluate(&tasks, 2, Domain::Robot, 16, |_, _| expert_action).unwrap();
        assert_eq!((expert.successes, expert.trials), (6, 6));
        assert_eq!(expert.per_task.len(), 3);
        let still = evaluate(&tasks, 2, Domain::Robot, 16, |_, _| |_: &Sim| Vec2::ZERO).unwrap();
        assert_eq!(still.successes, 0);
        assert_eq!(still.success_rate(), 0.0);
    }

    #[test]
    fn test_trials_get_another_distractor() {
        use rand::SeedableRng;
        let (_, test) = push::object_catalog();
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let demo = pushing_task(&test, &mut rng).unwrap();
        let trial = swap_distractor(&demo, &test, &mut rng).unwrap();
        let (
            Task::Pushing {
                target: t0,
                distractor: d0,
                ..
            },
            Task::Pushing {
                target: t1,
                distractor: d1,
                ..
            },
        ) = (&demo, &trial)
        else {
            panic!("not pushing tasks");
        };
        assert_eq!(t0, t1);
        assert_ne!(d0.name, d1.name);
        assert_ne!(d1.name, t1.name);
        let drawing = Task::Drawing {
            shape: shapes::training_shapes()[0].clone(),
        };
        assert!(swap_distractor(&drawing, &test, &mut rng).is_none());
    }

    #[test]
    fn same_task_same_frames() {
        let shape = shapes::training_shapes()[4].clone();
        let run = || {
            rollout(
                Sim::reset(Task::Drawing { shape: shape.clone() }, Domain::Human, 32).unwrap(),
                expert_action,
            )
        };
        assert_eq!(run().frames, run().frames);
    }
}
