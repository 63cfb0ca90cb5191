//! The meta-policy of DAML and MILV (paper section 3.2 and 4.2, eq. 6 and 11, Appendix
//! A.2) and one meta-training step.
//!
//! The policy is written functionally — every layer reads its weights from a slice of
//! tensors — so the inner update θ' = θ − α ∇_θ L_ψ(θ, d_tr) can be applied without
//! touching the stored weights, and the outer loss differentiates through it (second
//! order: the inner gradient is taken with `create_graph`, which is also the only way the
//! learned adaptation loss's weights ψ receive a gradient).
//!
//! Layout of θ: the convolutions (16 filters of 5×5; latents: two strided and one not;
//! images: three strided and three not), each followed by layer norm with a learned
//! per-channel offset, spatial softmax, a learned context vector concatenated to its
//! output (DAML's *bias transformation*), three fully connected layers of 100 units, then
//! two heads: the **pre-update head** (a linear map to [`PolicyConfig::pre_dim`] features
//! per frame, read only by L_ψ) and the **post-update head** (the action). ψ: three
//! temporal convolutions over the sequence of pre-update features (10×1, 10×1, 1×1).
//!
//! The inner step follows DAML's reference code (`tianheyu927/mil`) where the paper is
//! silent: L_ψ is `mean((m · out)²)` with the loss multiplier `m` inside the square (50),
//! each inner gradient entry is clipped to ±10, the context vector is adapted with the
//! rest of θ, and the layer-norm offsets are outer parameters only (not adapted).

use serde::{Deserialize, Serialize};
use tch::nn::{self, Init};
use tch::{Device, Kind, Tensor};

use crate::run::adam::Adam;
use crate::run::layers::spatial_softmax;
use crate::{Error, Result};

/// Which of the paper's methods a policy is trained as.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// Images; inner on a human video, outer on a robot demonstration with true actions.
    Daml,
    /// Imagined latents; inner on one human demo, outer on another with predicted
    /// actions, each frame weighted by its curated β weight (eq. 11).
    Milv,
    /// MILV with every weight 1.
    Wstable,
    /// MILV on the translated images instead of latents.
    Feedimg,
    /// MILV on latents of a decoupled A-CycleGAN.
    Degi,
}

impl Variant {
    pub const ALL: [Variant; 5] = [
        Variant::Daml,
        Variant::Degi,
        Variant::Feedimg,
        Variant::Wstable,
        Variant::Milv,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Variant::Daml => "daml",
            Variant::Milv => "milv",
            Variant::Wstable => "wstable",
            Variant::Feedimg => "feedimg",
            Variant::Degi => "degi",
        }
    }

    /// The paper's spelling, for tables.
    pub fn label(self) -> &'static str {
        match self {
            Variant::Daml => "DAML",
            Variant::Milv => "MILV",
            Variant::Wstable => "WStable",
            Variant::Feedimg => "FeedImg",
            Variant::Degi => "DeGI",
        }
    }

    pub fn input(self) -> Input {
        match self {
            Variant::Daml | Variant::Feedimg => Input::Image,
            Variant::Milv | Variant::Wstable | Variant::Degi => Input::Latent,
        }
    }

    /// Whether the outer loss uses the curated per-frame weights.
    pub fn weighted(self) -> bool {
        matches!(self, Variant::Milv | Variant::Feedimg | Variant::Degi)
    }
}

impl std::str::FromStr for Variant {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Variant::ALL
            .into_iter()
            .find(|v| v.name() == s.to_ascii_lowercase())
            .ok_or_else(|| format!("unknown variant {s:?} (daml | milv | wstable | feedimg | degi)"))
    }
}

/// What the policy sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Input {
    /// Latents of F's encoder, `[C, S/4, S/4]`.
    Latent,
    /// RGB images in [-1, 1], `[3, S, S]`.
    Image,
}

impl std::str::FromStr for Input {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "latent" => Ok(Input::Latent),
            "image" => Ok(Input::Image),
            _ => Err(format!("unknown input {s:?} (latent | image)")),
        }
    }
}

/// The policy network's shape (Appendix A.2 for the defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyConfig {
    pub input: Input,
    /// One observation: channels, height, width.
    pub input_shape: [i64; 3],
    pub filters: i64,
    pub kernel: i64,
    /// Stride of each convolution (their number is the number of conv layers).
    pub strides: Vec<i64>,
    pub hidden: i64,
    pub fc_layers: usize,
    /// Width of the pre-update head.
    pub pre_dim: i64,
    /// Filters of the first two temporal convolutions.
    pub tconv_filters: i64,
    /// Kernel lengths of the three temporal convolutions.
    pub tconv_kernels: [i64; 3],
    pub action_dim: i64,
    /// Actions are learned divided by this (cm), so targets are of order 1.
    pub action_scale: f64,
    /// L_ψ = mean((m · out)²): DAML's loss multiplier, inside the square. (Checkpoints
    /// from before it existed trained with 1.)
    #[serde(default = "one")]
    pub loss_multiplier: f64,
    /// Inner gradients are clipped elementwise to ±this; 0: no clipping.
    #[serde(default)]
    pub inner_clip: f64,
    /// Width of the learned context vector after the spatial softmax (DAML's bias
    /// transformation); 0: none.
    #[serde(default)]
    pub bias_dim: i64,
    /// Layer norm (learned per-channel offset, no scale) after each convolution.
    #[serde(default)]
    pub layer_norm: bool,
    /// A learned temperature divides the last feature maps before the spatial softmax
    /// (DAML's `tf.contrib.layers.spatial_softmax`, trainable, starting at 1): the
    /// keypoints can sharpen without the convolutions' weights growing. An outer
    /// parameter only. (Checkpoints from before it existed have none.)
    #[serde(default)]
    pub learned_temperature: bool,
    /// Width of the robot state appended after the spatial softmax; 0: image-only (the
    /// paper's policy).
    #[serde(default)]
    pub state_dim: i64,
    /// Mean and standard deviation of each state component (cm): the state input is
    /// standardised with them in training and at evaluation.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub state_norm: Vec<[f64; 2]>,
}

/// Robot states (one row per frame) as the state input reads them: `[T, S]`, each
/// component standardised by its `(mean, std)` in `norm` (training and evaluation alike).
pub fn standardised_states<S: AsRef<[f32]>>(states: &[S], norm: &[[f64; 2]]) -> Tensor {
    let flat: Vec<f32> = states
        .iter()
        .flat_map(|s| {
            s.as_ref()
                .iter()
                .zip(norm)
                .map(|(&x, [m, sd])| ((f64::from(x) - m) / sd) as f32)
        })
        .collect();
    Tensor::from_slice(&flat).view([states.len() as i64, norm.len() as i64])
}

fn one() -> f64 {
    1.0
}

impl PolicyConfig {
    /// The paper's network for `input` observations of `shape`.
    pub fn paper(input: Input, input_shape: [i64; 3], action_dim: i64) -> PolicyConfig {
        PolicyConfig {
            input,
            input_shape,
            filters: 16,
            kernel: 5,
            strides: match input {
                Input::Latent => vec![2, 2, 1],
                Input::Image => vec![2, 2, 2, 1, 1, 1],
            },
            hidden: 100,
            fc_layers: 3,
            pre_dim: 20,
            tconv_filters: 10,
            tconv_kernels: [10, 10, 1],
            action_dim,
            action_scale: 5.0,
            loss_multiplier: 50.0,
            inner_clip: 10.0,
            bias_dim: 20,
            layer_norm: true,
            learned_temperature: true,
            state_dim: 0,
            state_norm: Vec::new(),
        }
    }

    /// Small shapes for tests.
    pub fn tiny(input: Input, input_shape: [i64; 3], action_dim: i64) -> PolicyConfig {
        PolicyConfig {
            filters: 3,
            strides: vec![2, 1],
            hidden: 6,
            fc_layers: 2,
            pre_dim: 4,
            tconv_filters: 6,
            tconv_kernels: [3, 3, 1],
            bias_dim: 3,
            ..PolicyConfig::paper(input, input_shape, action_dim)
        }
    }

    /// Frames a sequence needs for the temporal convolutions (no padding).
    pub fn min_frames(&self) -> usize {
        self.tconv_kernels
            .iter()
            .map(|k| (*k - 1) as usize)
            .sum::<usize>()
            + 1
    }

    pub fn validate(&self) -> Result<()> {
        if self.strides.is_empty() || self.fc_layers == 0 || self.input_shape.iter().any(|d| *d < 1) {
            return Err(Error::Config(
                "the policy needs at least one convolution, one hidden layer and a non-empty input".into(),
            ));
        }
        let positive = self.loss_multiplier > 0.0 && self.loss_multiplier.is_finite();
        let clip_ok = self.inner_clip >= 0.0 && self.inner_clip.is_finite();
        if self.state_norm.len() as i64 != self.state_dim && !self.state_norm.is_empty() {
            return Err(Error::Config(format!(
                "state width {} but {} standardisation entries",
                self.state_dim,
                self.state_norm.len()
            )));
        }
        if !positive || !clip_ok || self.bias_dim < 0 || self.state_dim < 0 || self.hidden < 1 {
            return Err(Error::Config(format!(
                "--loss-multiplier must be positive, --inner-clip, --bias-dim and the state width \
                 non-negative, --hidden positive (got {}, {}, {}, {}, {})",
                self.loss_multiplier, self.inner_clip, self.bias_dim, self.state_dim, self.hidden
            )));
        }
        Ok(())
    }
}

/// Meta-training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MetaConfig {
    pub variant: Variant,
    pub steps: u64,
    /// Tasks per meta-batch.
    pub meta_batch: usize,
    /// Inner step size α.
    pub alpha: f64,
    /// Outer Adam learning rate.
    pub lr: f64,
    /// Differentiate through the inner update (MAML's second order). Off: first order,
    /// and ψ learns nothing.
    pub second_order: bool,
    pub seed: u64,
    /// Whose video the inner step watches: a human's (the paper) or, for DAML, another
    /// robot demonstration's frames without actions (DAML's video-only robot → robot).
    #[serde(default = "human")]
    pub inner_domain: milv_data::Domain,
    /// An imagined-data variant imitated the true robot actions instead of π_I's
    /// (`meta --true-actions`, the ladder's R6 diagnostic).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub true_actions: bool,
}

fn human() -> milv_data::Domain {
    milv_data::Domain::Human
}

impl Default for MetaConfig {
    fn default() -> Self {
        MetaConfig {
            variant: Variant::Milv,
            steps: 1000,
            meta_batch: 4,
            alpha: 0.01,
            lr: 1e-3,
            second_order: true,
            seed: 0,
            inner_domain: milv_data::Domain::Human,
            true_actions: false,
        }
    }
}

/// The meta-policy: θ, ψ and the layer-norm offsets in one VarStore.
pub struct PolicyNet {
    pub cfg: PolicyConfig,
    pub vs: nn::VarStore,
    /// θ, in layer order: (weight, bias) per convolution, the context vector (if
    /// `bias_dim` > 0), (weight, bias) per fully connected layer and head; the post-update
    /// head is the last pair.
    pub theta: Vec<Tensor>,
    /// ψ: the temporal convolutions (weight, bias each).
    pub psi: Vec<Tensor>,
    /// Layer-norm offsets, one `[filters]` per convolution (outer parameters only).
    pub norm: Vec<Tensor>,
    /// The spatial softmax's learned temperature `[1]` (outer parameter only).
    pub temperature: Option<Tensor>,
}

/// Variable `layer.name` (tch joins path segments with dots).
fn var(p: &nn::Path, name: &str, dims: &[i64], fan_in: i64) -> Tensor {
    // PyTorch's default for conv and linear layers: U(−1/√fan_in, 1/√fan_in) for weights
    // (kaiming_uniform with a = √5) and biases.
    let b = 1.0 / (fan_in.max(1) as f64).sqrt();
    let (layer, leaf) = name.rsplit_once('.').unwrap_or(("", name));
    let path = layer
        .split('.')
        .filter(|s| !s.is_empty())
        .fold(p.clone(), |p, s| p / s);
    path.var(leaf, dims, Init::Uniform { lo: -b, up: b })
}

impl PolicyNet {
    pub fn new(cfg: PolicyConfig, device: Device) -> Result<PolicyNet> {
        cfg.validate()?;
        let vs = nn::VarStore::new(device);
        let root = vs.root();
        let (k, f) = (cfg.kernel, cfg.filters);
        let mut theta = Vec::new();
        let mut c_in = cfg.input_shape[0];
        for i in 0..cfg.strides.len() {
            let fan = c_in * k * k;
            theta.push(var(&root, &format!("conv{i}.weight"), &[f, c_in, k, k], fan));
            theta.push(var(&root, &format!("conv{i}.bias"), &[f], fan));
            c_in = f;
        }
        let norm = if cfg.layer_norm {
            (0..cfg.strides.len())
                .map(|i| root.var(&format!("norm{i}_offset"), &[f], Init::Const(0.0)))
                .collect()
        } else {
            Vec::new()
        };
        let temperature = cfg
            .learned_temperature
            .then(|| root.var("softmax_temperature", &[1], Init::Const(1.0)));
        if cfg.bias_dim > 0 {
            // Zero at the start, as in DAML: the context is what adaptation writes into.
            theta.push(root.var("context", &[cfg.bias_dim], Init::Const(0.0)));
        }
        let mut d_in = 2 * f + cfg.bias_dim + cfg.state_dim;
        for i in 0..cfg.fc_layers {
            theta.push(var(&root, &format!("fc{i}.weight"), &[cfg.hidden, d_in], d_in));
            theta.push(var(&root, &format!("fc{i}.bias"), &[cfg.hidden], d_in));
            d_in = cfg.hidden;
        }
        for (name, out) in [("pre", cfg.pre_dim), ("post", cfg.action_dim)] {
            theta.push(var(&root, &format!("{name}.weight"), &[out, d_in], d_in));
            theta.push(var(&root, &format!("{name}.bias"), &[out], d_in));
        }
        let mut psi = Vec::new();
        let [k0, k1, k2] = cfg.tconv_kernels;
        let tf = cfg.tconv_filters;
        for (i, (ci, co, kk)) in [(cfg.pre_dim, tf, k0), (tf, tf, k1), (tf, cfg.action_dim, k2)]
            .into_iter()
            .enumerate()
        {
            psi.push(var(&root, &format!("loss.t{i}.weight"), &[co, ci, kk], ci * kk));
            psi.push(var(&root, &format!("loss.t{i}.bias"), &[co], ci * kk));
        }
        Ok(PolicyNet {
            cfg,
            vs,
            theta,
            psi,
            norm,
            temperature,
        })
    }

    /// The θ that the inner step updates (all but the post-update head, which L_ψ does
    /// not read).
    pub fn inner_len(&self) -> usize {
        self.theta.len() - 2
    }

    /// The hidden features `[T, hidden]` of a sequence; `state` `[T, state_dim]` is
    /// appended after the spatial softmax when the policy takes one (zeros if `None`).
    fn trunk(&self, th: &[Tensor], x: &Tensor, state: Option<&Tensor>) -> Tensor {
        let pad = self.cfg.kernel / 2;
        let mut h = x.shallow_clone();
        for (i, &s) in self.cfg.strides.iter().enumerate() {
            h = h.conv2d(&th[2 * i], Some(&th[2 * i + 1]), [s, s], [pad, pad], [1, 1], 1);
            if let Some(offset) = self.norm.get(i) {
                let shape = h.size();
                h = h.layer_norm(&shape[1..], None::<Tensor>, None::<Tensor>, 1e-5, false)
                    + offset.view([1, -1, 1, 1]);
            }
            h = h.relu();
        }
        // Not `h /= temp`: that divides in place the ReLU output autograd still needs.
        let h = match &self.temperature {
            Some(temp) => h / temp,
            None => h,
        };
        let mut h = spatial_softmax(&h);
        let mut base = 2 * self.cfg.strides.len();
        let t = h.size()[0];
        if self.cfg.bias_dim > 0 {
            h = Tensor::cat(&[h, th[base].unsqueeze(0).expand([t, -1], false)], 1);
            base += 1;
        }
        if self.cfg.state_dim > 0 {
            let s = match state {
                Some(s) => s.shallow_clone(),
                None => Tensor::zeros([t, self.cfg.state_dim], (x.kind(), x.device())),
            };
            h = Tensor::cat(&[h, s], 1);
        }
        for j in 0..self.cfg.fc_layers {
            h = h.linear(&th[base + 2 * j], Some(&th[base + 2 * j + 1])).relu();
        }
        h
    }

    fn head(th: &[Tensor], h: &Tensor, from_end: usize) -> Tensor {
        let n = th.len();
        h.linear(&th[n - from_end], Some(&th[n - from_end + 1]))
    }

    /// Pre-update features `[T, pre_dim]` of a sequence `[T, C, H, W]` (the inner
    /// sequence: a video, so no state).
    pub fn pre(&self, th: &[Tensor], x: &Tensor) -> Tensor {
        PolicyNet::head(th, &self.trunk(th, x, None), 4)
    }

    /// Actions `[T, action_dim]` in units of `action_scale`.
    pub fn act(&self, th: &[Tensor], x: &Tensor) -> Tensor {
        self.act_with(th, x, None)
    }

    /// [`PolicyNet::act`] with the robot's state, for a policy that takes one.
    pub fn act_with(&self, th: &[Tensor], x: &Tensor, state: Option<&Tensor>) -> Tensor {
        PolicyNet::head(th, &self.trunk(th, x, state), 2)
    }

    /// L_ψ(θ, d): temporal convolutions over the pre-update features of one sequence,
    /// multiplied by the loss multiplier, squared and averaged (DAML's
    /// `euclidean_loss_layer` against a zero target).
    pub fn adaptation_loss(&self, th: &[Tensor], psi: &[Tensor], x: &Tensor) -> Tensor {
        let mut h = self.pre(th, x).transpose(0, 1).unsqueeze(0);
        for i in 0..3 {
            h = h.conv1d(&psi[2 * i], Some(&psi[2 * i + 1]), [1], [0], [1], 1);
            if i < 2 {
                h = h.relu();
            }
        }
        let kind = h.kind();
        (h * self.cfg.loss_multiplier).square().mean(kind)
    }

    /// θ' = θ − α clip(∇_θ L_ψ(θ, x)), the gradient clipped elementwise to ±`inner_clip`
    /// (when set). With `create_graph` the result stays differentiable in θ and ψ through
    /// the gradient (second order); without, the gradient is a constant.
    pub fn adapt(
        &self,
        th: &[Tensor],
        psi: &[Tensor],
        x: &Tensor,
        alpha: f64,
        create_graph: bool,
    ) -> (Vec<Tensor>, Tensor) {
        let loss = self.adaptation_loss(th, psi, x);
        let k = th.len() - 2;
        let grads = Tensor::run_backward(&[&loss], &th[..k], true, create_graph);
        let clip = self.cfg.inner_clip;
        let mut out: Vec<Tensor> = th[..k]
            .iter()
            .zip(&grads)
            .map(|(t, g)| {
                let g = if clip > 0.0 {
                    g.clamp(-clip, clip)
                } else {
                    g.shallow_clone()
                };
                t - g * alpha
            })
            .collect();
        out.extend(th[k..].iter().map(Tensor::shallow_clone));
        (out, loss)
    }

    /// Behaviour cloning, weighted per frame: (1/T) Σ_t w_t · mean_a (π(x_t) − a_t)². The
    /// weights are not normalised, so a frame's share of the gradient is proportional to
    /// its weight.
    pub fn bc_loss(&self, th: &[Tensor], x: &Tensor, actions: &Tensor, weights: &Tensor) -> Tensor {
        self.bc_loss_with(th, x, None, actions, weights)
    }

    /// [`PolicyNet::bc_loss`] with the robot's state, for a policy that takes one.
    pub fn bc_loss_with(
        &self,
        th: &[Tensor],
        x: &Tensor,
        state: Option<&Tensor>,
        actions: &Tensor,
        weights: &Tensor,
    ) -> Tensor {
        let err = (self.act_with(th, x, state) - actions)
            .square()
            .mean_dim(1, false, x.kind());
        (err * weights).mean(x.kind())
    }

    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        Ok(self.vs.save(path)?)
    }

    pub fn load(&mut self, path: &std::path::Path) -> Result<()> {
        self.vs.load(path).map_err(Error::tensors(path))
    }
}

/// One task of a meta-batch: the inner sequence (no actions) and the outer sequence with
/// its target actions (scaled), per-frame weights and, for a policy that takes one, the
/// robot's state along it.
pub struct MetaTask {
    pub inner: Tensor,
    pub outer: Tensor,
    pub actions: Tensor,
    pub weights: Tensor,
    pub outer_state: Option<Tensor>,
}

/// Mean losses of one meta-step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MetaLosses {
    /// L_ψ before adaptation.
    pub inner: f64,
    /// Weighted behaviour cloning after adaptation (at θ′): what the meta-step minimises.
    pub outer: f64,
    /// The same loss before adaptation (at θ): when it equals `outer`, the inner step
    /// does nothing.
    #[serde(default)]
    pub outer_pre: f64,
}

/// The meta-objective (eq. 6 / 11) averaged over `tasks`, as a differentiable scalar,
/// with the mean L_ψ and the mean outer loss before adaptation.
pub fn meta_objective(
    net: &PolicyNet,
    tasks: &[MetaTask],
    alpha: f64,
    second_order: bool,
) -> (Tensor, f64, f64) {
    let mut total: Option<Tensor> = None;
    let (mut inner, mut pre) = (0.0, 0.0);
    for t in tasks {
        let state = t.outer_state.as_ref();
        // α = 0 is behaviour cloning (the ladder's R0/R1): θ′ = θ exactly, so the inner
        // gradient (and its second-order graph, most of a step's cost) is skipped and the
        // loss before adaptation is the loss after; L_ψ is still evaluated for the log.
        let lo = if alpha == 0.0 {
            inner += tch::no_grad(|| net.adaptation_loss(&net.theta, &net.psi, &t.inner)).double_value(&[]);
            let lo = net.bc_loss_with(&net.theta, &t.outer, state, &t.actions, &t.weights);
            pre += lo.double_value(&[]);
            lo
        } else {
            let (adapted, li) = net.adapt(&net.theta, &net.psi, &t.inner, alpha, second_order);
            inner += li.double_value(&[]);
            pre += tch::no_grad(|| net.bc_loss_with(&net.theta, &t.outer, state, &t.actions, &t.weights))
                .double_value(&[]);
            net.bc_loss_with(&adapted, &t.outer, state, &t.actions, &t.weights)
        };
        total = Some(match total {
            Some(s) => s + lo,
            None => lo,
        });
    }
    let n = tasks.len().max(1) as f64;
    let total = total.unwrap_or_else(|| Tensor::zeros([], (Kind::Float, net.vs.device())));
    (total / n, inner / n, pre / n)
}

/// A meta-training run: the policy, its optimiser and the step count.
pub struct MetaRun {
    pub net: PolicyNet,
    pub cfg: MetaConfig,
    pub adam: Adam,
    pub step: u64,
}

impl MetaRun {
    pub fn new(policy: PolicyConfig, cfg: MetaConfig, device: Device) -> Result<MetaRun> {
        if cfg.meta_batch == 0 || cfg.lr.is_nan() || cfg.lr <= 0.0 {
            return Err(Error::Config(
                "--meta-batch must be at least 1 and --lr positive".into(),
            ));
        }
        tch::manual_seed(cfg.seed as i64);
        let net = PolicyNet::new(policy, device)?;
        let adam = Adam::new(&net.vs, cfg.lr, 0.9);
        Ok(MetaRun {
            net,
            cfg,
            adam,
            step: 0,
        })
    }

    /// One outer Adam step on a meta-batch.
    pub fn step(&mut self, tasks: &[MetaTask]) -> MetaLosses {
        self.adam.zero_grad();
        let (loss, inner, outer_pre) =
            meta_objective(&self.net, tasks, self.cfg.alpha, self.cfg.second_order);
        let outer = loss.double_value(&[]);
        loss.backward();
        self.adam.step();
        self.step += 1;
        MetaLosses {
            inner,
            outer,
            outer_pre,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn tiny_net(kind: Kind) -> PolicyNet {
        let mut net = PolicyNet::new(PolicyConfig::tiny(Input::Latent, [2, 6, 6], 2), Device::Cpu).unwrap();
        if kind == Kind::Double {
            net.vs.double();
        }
        net
    }

    fn task(kind: Kind, t: i64, seed: i64) -> MetaTask {
        tch::manual_seed(seed);
        let o = (kind, Device::Cpu);
        MetaTask {
            inner: Tensor::randn([t, 2, 6, 6], o),
            outer: Tensor::randn([t, 2, 6, 6], o),
            actions: Tensor::randn([t, 2], o),
            weights: Tensor::rand([t], o) + 0.5,
            outer_state: None,
        }
    }

    fn objective(net: &PolicyNet, tasks: &[MetaTask]) -> f64 {
        meta_objective(net, tasks, 0.3, true).0.double_value(&[])
    }

    /// Analytic gradient of the meta-objective (through the inner step) against central
    /// differences, in f64, for entries of θ (trunk and both heads) and ψ.
    #[test]
    fn the_second_order_meta_gradient_equals_finite_differences() {
        let _serial = crate::testing::torch_rng();
        let net = tiny_net(Kind::Double);
        let tasks = [task(Kind::Double, 9, 1), task(Kind::Double, 9, 2)];
        let (loss, _, _) = meta_objective(&net, &tasks, 0.3, true);
        loss.backward();
        let params: Vec<Tensor> = net
            .theta
            .iter()
            .chain(&net.psi)
            .chain(&net.norm)
            .chain(&net.temperature)
            .map(Tensor::shallow_clone)
            .collect();
        let mut checked = 0;
        for p in &params {
            let g = p.grad().flatten(0, -1);
            let flat = p.flatten(0, -1);
            for idx in [0, flat.size()[0] - 1] {
                let h = 1e-6;
                let orig = flat.double_value(&[idx]);
                let set = |v: f64| {
                    tch::no_grad(|| {
                        let _ = flat.get(idx).fill_(v);
                    })
                };
                set(orig + h);
                let up = objective(&net, &tasks);
                set(orig - h);
                let down = objective(&net, &tasks);
                set(orig);
                let fd = (up - down) / (2.0 * h);
                let an = g.double_value(&[idx]);
                assert!(
                    (fd - an).abs() <= 1e-6 + 1e-5 * an.abs().max(fd.abs()),
                    "finite difference {fd} vs analytic {an}"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 2 * params.len());
        // ψ's gradient exists only through the inner step: it must not be zero here, or
        // the comparison above proved nothing for it.
        let psi_grad: f64 = net
            .psi
            .iter()
            .map(|p| p.grad().abs().sum(Kind::Double).double_value(&[]))
            .sum();
        assert!(psi_grad > 1e-9, "ψ has no gradient ({psi_grad})");
    }

    /// α = 0 takes the shortcut (no inner gradient); its loss and θ gradient must be
    /// those of the full path through `adapt` with α = 0.
    #[test]
    fn behaviour_cloning_skips_the_inner_step_and_keeps_the_gradient() {
        let _serial = crate::testing::torch_rng();
        let net = tiny_net(Kind::Double);
        let t = task(Kind::Double, 9, 3);
        let (fast, inner, pre) = meta_objective(&net, std::slice::from_ref(&t), 0.0, true);
        fast.backward();
        // The pre-update head gets no gradient without an inner step: zero in its place.
        let grad_or_zero = |p: &Tensor| {
            let g = p.grad();
            if g.defined() { g.copy() } else { p.zeros_like() }
        };
        let fast_grads: Vec<Tensor> = net.theta.iter().map(grad_or_zero).collect();
        for p in &net.theta {
            let mut g = p.grad();
            if g.defined() {
                let _ = g.zero_();
            }
        }
        let (adapted, li) = net.adapt(&net.theta, &net.psi, &t.inner, 0.0, true);
        let full = net.bc_loss(&adapted, &t.outer, &t.actions, &t.weights);
        full.backward();
        let value = full.double_value(&[]);
        assert!((fast.double_value(&[]) - value).abs() <= 1e-12 * value.abs());
        assert!((pre - value).abs() <= 1e-12 * value.abs(), "{pre} vs {value}");
        assert!((inner - li.double_value(&[])).abs() <= 1e-12 * inner.abs());
        for (g, p) in fast_grads.iter().zip(&net.theta) {
            let diff = (g - grad_or_zero(p)).abs().max().double_value(&[]);
            assert!(diff <= 1e-12, "θ gradient differs by {diff}");
        }
        assert!(
            fast_grads
                .iter()
                .any(|g| g.abs().sum(Kind::Double).double_value(&[]) > 0.0)
        );
    }

    #[test]
    fn psi_learns_only_through_the_second_order_term() {
        let _serial = crate::testing::torch_rng();
        let tasks = [task(Kind::Float, 12, 3)];
        for second in [true, false] {
            let net = tiny_net(Kind::Float);
            let (loss, _, _) = meta_objective(&net, &tasks, 0.1, second);
            loss.backward();
            let norm: f64 = net
                .psi
                .iter()
                .map(|p| {
                    let g = p.grad();
                    if g.defined() {
                        g.abs().sum(Kind::Double).double_value(&[])
                    } else {
                        0.0
                    }
                })
                .sum();
            if second {
                assert!(norm > 1e-8, "ψ got no gradient: {norm}");
            } else {
                assert_eq!(norm, 0.0);
            }
        }
    }

    /// Eq. 11's weights: the outer gradient is linear in each frame's weight, so doubling
    /// one frame's weight adds exactly its share once more.
    #[test]
    fn doubling_a_frames_weight_doubles_its_share_of_the_outer_gradient() {
        let _serial = crate::testing::torch_rng();
        let net = tiny_net(Kind::Double);
        let base = task(Kind::Double, 10, 4);
        let grad_with = |w: &Tensor| -> Tensor {
            net.adam_free_zero_grad();
            let t = MetaTask {
                inner: base.inner.shallow_clone(),
                outer: base.outer.shallow_clone(),
                actions: base.actions.shallow_clone(),
                weights: w.shallow_clone(),
                outer_state: None,
            };
            let (loss, _, _) = meta_objective(&net, &[t], 0.2, true);
            loss.backward();
            Tensor::cat(
                &net.theta
                    .iter()
                    .map(|p| p.grad().flatten(0, -1))
                    .collect::<Vec<_>>(),
                0,
            )
            .copy()
        };
        let w = base.weights.copy();
        let g = grad_with(&w);
        let k = 4;
        let zeroed = w.copy();
        let _ = zeroed.get(k).fill_(0.0);
        let doubled = w.copy();
        let _ = doubled.get(k).fill_(2.0 * w.double_value(&[k]));
        let share = &g - grad_with(&zeroed);
        let twice = grad_with(&doubled) - grad_with(&zeroed);
        assert!(
            share.abs().max().double_value(&[]) > 1e-9,
            "frame {k} has no share"
        );
        let err = (&twice - &share * 2.0).abs().max().double_value(&[]);
        assert!(err < 1e-10, "doubled share differs from twice the share by {err}");
    }

    #[test]
    fn meta_training_lowers_the_outer_loss() {
        let _serial = crate::testing::torch_rng();
        let mut run = MetaRun::new(
            PolicyConfig::tiny(Input::Latent, [2, 6, 6], 2),
            MetaConfig {
                lr: 0.01,
                ..MetaConfig::default()
            },
            Device::Cpu,
        )
        .unwrap();
        let tasks = [task(Kind::Float, 8, 5), task(Kind::Float, 8, 6)];
        let first = run.step(&tasks).outer;
        let mut last = first;
        for _ in 0..150 {
            last = run.step(&tasks).outer;
        }
        assert!(last < first / 2.0, "outer loss {first} → {last}");
    }

    /// DAML's additions get gradients and do what they claim: the context vector and the
    /// layer-norm offsets receive meta-gradients, the context is adapted and the offsets
    /// are not, the multiplier scales L_ψ by its square, and no inner gradient entry moves
    /// θ by more than α · clip.
    #[test]
    fn bias_transformation_layer_norm_multiplier_and_clip_work_as_in_daml() {
        let _serial = crate::testing::torch_rng();
        let net = tiny_net(Kind::Float);
        let ctx = 2 * net.cfg.strides.len();
        assert_eq!(net.theta[ctx].size(), [net.cfg.bias_dim]);
        assert_eq!(net.norm.len(), net.cfg.strides.len());
        let tasks = [task(Kind::Float, 9, 7)];
        let (loss, _, _) = meta_objective(&net, &tasks, 0.1, true);
        loss.backward();
        let grad = |t: &Tensor| t.grad().abs().sum(Kind::Double).double_value(&[]);
        assert!(grad(&net.theta[ctx]) > 0.0, "the context vector got no gradient");
        assert!(
            net.norm.iter().all(|o| grad(o) > 0.0),
            "a layer-norm offset got no gradient"
        );
        let temp = net.temperature.as_ref().unwrap();
        assert!(grad(temp) > 0.0, "the softmax temperature got no gradient");
        let (alpha, clip) = (0.1, net.cfg.inner_clip);
        let (adapted, _) = net.adapt(&net.theta, &net.psi, &tasks[0].inner, alpha, false);
        let moved = |i: usize| (&adapted[i] - &net.theta[i]).abs().max().double_value(&[]);
        assert!(moved(ctx) > 0.0, "the context vector was not adapted");
        let max_move = (0..net.inner_len()).map(moved).fold(0.0, f64::max);
        assert!(max_move <= alpha * clip * (1.0 + 1e-6), "{max_move}");
        let mut unit = PolicyNet::new(
            PolicyConfig {
                loss_multiplier: 1.0,
                ..net.cfg.clone()
            },
            Device::Cpu,
        )
        .unwrap();
        tch::no_grad(|| {
            for (a, b) in unit
                .theta
                .iter_mut()
                .chain(&mut unit.psi)
                .zip(net.theta.iter().chain(&net.psi))
            {
                a.copy_(b);
            }
        });
        let l1 = unit
            .adaptation_loss(&unit.theta, &unit.psi, &tasks[0].inner)
            .double_value(&[]);
        let lm = net
            .adaptation_loss(&net.theta, &net.psi, &tasks[0].inner)
            .double_value(&[]);
        let m = net.cfg.loss_multiplier;
        assert!((lm - m * m * l1).abs() <= 1e-4 * lm.abs(), "{lm} vs {m}² × {l1}");
    }

    /// The logged loss before adaptation is the outer loss at θ; with α = 0 it equals the
    /// one after.
    #[test]
    fn the_pre_adaptation_loss_is_the_loss_at_theta() {
        let _serial = crate::testing::torch_rng();
        let net = tiny_net(Kind::Double);
        let tasks = [task(Kind::Double, 9, 8), task(Kind::Double, 9, 9)];
        let (post, _, pre) = meta_objective(&net, &tasks, 0.3, true);
        let at_theta: f64 = tasks
            .iter()
            .map(|t| {
                net.bc_loss(&net.theta, &t.outer, &t.actions, &t.weights)
                    .double_value(&[])
            })
            .sum::<f64>()
            / 2.0;
        assert!((pre - at_theta).abs() < 1e-12, "{pre} vs {at_theta}");
        assert!(
            (post.double_value(&[]) - pre).abs() > 1e-9,
            "the inner step changed nothing"
        );
        let (post0, _, pre0) = meta_objective(&net, &tasks, 0.0, true);
        assert!((post0.double_value(&[]) - pre0).abs() < 1e-12);
    }

    /// `--state`: the outer sequence's state reaches the actions (and the first hidden
    /// layer's state columns get gradients); the inner step, a video, never reads one.
    #[test]
    fn a_state_input_changes_the_actions_and_gets_gradients() {
        let _serial = crate::testing::torch_rng();
        let cfg = PolicyConfig {
            state_dim: 2,
            state_norm: vec![[30.0, 10.0]; 2],
            ..PolicyConfig::tiny(Input::Latent, [2, 6, 6], 2)
        };
        cfg.validate().unwrap();
        let net = PolicyNet::new(cfg, Device::Cpu).unwrap();
        let mut t = task(Kind::Float, 9, 11);
        let o = (Kind::Float, Device::Cpu);
        t.outer_state = Some(Tensor::randn([9, 2], o));
        let a = net.act_with(&net.theta, &t.outer, t.outer_state.as_ref());
        let b = net.act_with(
            &net.theta,
            &t.outer,
            Some(&(t.outer_state.as_ref().unwrap() + 1.0)),
        );
        assert!(
            (a - b).abs().max().double_value(&[]) > 0.0,
            "the state does not reach the actions"
        );
        let (loss, _, _) = meta_objective(&net, std::slice::from_ref(&t), 0.1, true);
        loss.backward();
        let fc0 = 2 * net.cfg.strides.len() + 1;
        let w = net.theta[fc0].grad();
        let d = w.size()[1];
        let g = w.narrow(1, d - 2, 2).abs().sum(Kind::Double).double_value(&[]);
        assert!(g > 0.0, "the state columns got no gradient");
        let bad = PolicyConfig {
            state_dim: 2,
            state_norm: vec![[0.0, 1.0]],
            ..PolicyConfig::tiny(Input::Latent, [2, 6, 6], 2)
        };
        assert!(bad.validate().is_err());
    }

    impl PolicyNet {
        fn adam_free_zero_grad(&self) {
            for p in self.theta.iter().chain(&self.psi).chain(&self.norm) {
                let mut g = p.grad();
                if g.defined() {
                    let _ = g.detach_().zero_();
                }
            }
        }
    }
}
