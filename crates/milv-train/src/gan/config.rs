//! Network shapes and training settings, stored with every checkpoint as JSON.

use serde::{Deserialize, Serialize};

/// Shapes of the A-CycleGAN networks (paper Appendix A.2; the defaults are the paper's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    /// Square input and output images (pixels); a multiple of 8.
    pub image_size: i64,
    /// Filters of the generator encoder's three convs (7×7, then 3×3 strided twice).
    pub enc_widths: [i64; 3],
    /// Residual blocks between encoder and decoder.
    pub res_blocks: usize,
    /// Filters of the PatchGAN's first conv (doubled by each of the next three).
    pub disc_width: i64,
    /// Filters of the inverse-dynamics convs (5×5, strided then not).
    pub idm_filters: i64,
    /// Units of each inverse-dynamics hidden layer.
    pub idm_hidden: i64,
    /// Action width: Δx, Δy on milv-sim; a new run takes it from its robot videos.
    pub action_dim: i64,
    /// Negative slope of π_I's conv activations: 0 is a ReLU (the paper's, and every
    /// checkpoint written before this field). A leaky one keeps a gradient when every
    /// unit of a conv is negative: with a ReLU π_I can die for good (its spatial softmax
    /// then sees a flat map, whose expected positions are exactly 0) and predict a constant.
    #[serde(default)]
    pub idm_slope: f64,
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig {
            image_size: 128,
            enc_widths: [16, 32, 64],
            res_blocks: 4,
            disc_width: 64,
            idm_filters: 16,
            idm_hidden: 100,
            action_dim: 2,
            idm_slope: 0.0,
        }
    }
}

impl ModelConfig {
    /// Small shapes for tests (seconds per run on a CPU).
    pub fn tiny(image_size: i64) -> Self {
        ModelConfig {
            image_size,
            enc_widths: [4, 8, 8],
            res_blocks: 1,
            disc_width: 4,
            idm_filters: 4,
            idm_hidden: 16,
            action_dim: 2,
            idm_slope: 0.0,
        }
    }

    /// Shape of one latent (F's encoder output): channels, height, width.
    pub fn latent_shape(&self) -> [i64; 3] {
        [self.enc_widths[2], self.image_size / 4, self.image_size / 4]
    }

    pub fn validate(&self) -> Result<(), crate::Error> {
        // The PatchGAN halves three times and then needs 2×2 for its last two 4×4 convs.
        if self.image_size < 32 || self.image_size % 8 != 0 {
            return Err(crate::Error::Config(format!(
                "image size {} must be a multiple of 8, at least 32",
                self.image_size
            )));
        }
        if !(0.0..1.0).contains(&self.idm_slope) {
            return Err(crate::Error::Config(format!(
                "inverse-dynamics slope {} must be in [0, 1)",
                self.idm_slope
            )));
        }
        if self.enc_widths.iter().any(|&w| w < 1) || self.disc_width < 1 || self.action_dim < 1 {
            return Err(crate::Error::Config("network widths must be positive".into()));
        }
        Ok(())
    }
}

/// The adversarial loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GanLoss {
    /// Least squares (CycleGAN's default; stabler).
    Lsgan,
    /// The log loss of the paper's eq. 1 (binary cross-entropy on logits).
    Log,
}

impl std::str::FromStr for GanLoss {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "lsgan" => Ok(GanLoss::Lsgan),
            "log" => Ok(GanLoss::Log),
            _ => Err(format!("unknown GAN loss {s:?} (lsgan | log)")),
        }
    }
}

fn one() -> i64 {
    1
}

/// Training settings (paper section 4.1 and Appendix A.2 for the defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub steps: u64,
    pub batch: i64,
    /// Robot transitions per step for π_I (the paper trains everything at batch 1).
    #[serde(default = "one")]
    pub idm_batch: i64,
    /// Generators and discriminators: Adam, this rate, β1 = `beta1`.
    pub lr: f64,
    pub beta1: f64,
    /// Inverse dynamics: Adam at this rate (kept constant).
    pub lr_idm: f64,
    /// Weight of the cycle loss (λ).
    pub lambda_cyc: f64,
    /// Weight of the auxiliary loss on aligned pairs (eq. 7).
    pub lambda_aux: f64,
    /// Weight of the inverse-dynamics loss in the generators' objective.
    pub lambda_idm: f64,
    pub gan: GanLoss,
    /// Fake images each discriminator sees from a history of this many.
    pub pool_size: usize,
    /// π_I on its own encoder (the paper's DeGI ablation) instead of F's.
    pub decoupled: bool,
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            steps: 10_000,
            batch: 1,
            idm_batch: 1,
            lr: 2e-4,
            beta1: 0.5,
            lr_idm: 0.01,
            lambda_cyc: 10.0,
            lambda_aux: 1.0,
            lambda_idm: 1.0,
            gan: GanLoss::Lsgan,
            pool_size: 50,
            decoupled: false,
            seed: 0,
        }
    }
}

impl TrainConfig {
    pub fn validate(&self) -> Result<(), crate::Error> {
        if self.batch < 1 || self.idm_batch < 1 {
            return Err(crate::Error::Config(
                "--batch and --idm-batch must be at least 1".into(),
            ));
        }
        if !(self.lr > 0.0 && self.lr_idm > 0.0) {
            return Err(crate::Error::Config("learning rates must be positive".into()));
        }
        Ok(())
    }
}
