//! The environment: `reset`, `step`, `observe`, `success` for one episode of a task in one
//! domain, and the scripted experts.

use serde::{Deserialize, Serialize};

use crate::geom::{EPISODE_STEPS, Vec2, clamp_action, clamp_to_workspace};
use crate::render::{Domain, Renderer, SceneItems};
use crate::shapes::{self, Shape};

/// A task instance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "family", rename_all = "lowercase")]
pub enum Task {
    /// Trace the guide shape with the pen, starting at its first point.
    Drawing { shape: Shape },
}

impl Task {
    pub fn family(&self) -> &'static str {
        match self {
            Task::Drawing { .. } => "drawing",
        }
    }

    /// `family/name`, the `task_id` of generated episodes.
    pub fn id(&self) -> String {
        match self {
            Task::Drawing { shape } => format!("draw/{}", shape.name),
        }
    }
}

/// One episode in progress.
pub struct Sim {
    task: Task,
    domain: Domain,
    renderer: Renderer,
    ee: Vec2,
    trace: Vec<Vec2>,
    steps: usize,
}

impl Sim {
    /// Starts an episode; the end-effector starts at the task's start point.
    pub fn reset(task: Task, domain: Domain, image_size: u32) -> Option<Sim> {
        let start = match &task {
            Task::Drawing { shape } => *shape.path.first()?,
        };
        Some(Sim {
            task,
            domain,
            renderer: Renderer::new(domain, image_size)?,
            ee: start,
            trace: vec![start],
            steps: 0,
        })
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
        };
        self.renderer.render(self.ee, &items)
    }

    /// The task's score so far (drawing: LCS points out of 50).
    pub fn score(&self) -> usize {
        match &self.task {
            Task::Drawing { shape } => shapes::drawing_score(&self.trace, &shape.path),
        }
    }

    pub fn success(&self) -> bool {
        match &self.task {
            Task::Drawing { .. } => self.score() >= shapes::SUCCESS_LCS,
        }
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
pub fn rollout(mut sim: Sim, mut policy: impl FnMut(&Sim) -> Vec2) -> Rollout {
    let mut out = Rollout {
        frames: Vec::with_capacity(EPISODE_STEPS + 1),
        actions: Vec::with_capacity(EPISODE_STEPS + 1),
        states: Vec::with_capacity(EPISODE_STEPS + 1),
        success: false,
        score: 0,
    };
    while !sim.done() {
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
