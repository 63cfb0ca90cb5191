//! The A-CycleGAN networks as tch modules (paper Appendix A.2, layers as in the CycleGAN
//! reference implementation: reflection padding, instance norm without affine terms,
//! biases on).
//!
//! Images are `[B, 3, S, S]` in [-1, 1]; latents `[B, C, S/4, S/4]`.

use tch::Tensor;
use tch::nn::{self, Module};

use crate::gan::config::ModelConfig;
use crate::run::layers::spatial_softmax;

fn instance_norm(x: &Tensor) -> Tensor {
    x.instance_norm::<Tensor>(None, None, None, None, true, 0.1, 1e-5, false)
}

fn conv(p: nn::Path, c_in: i64, c_out: i64, k: i64, stride: i64, reflect: bool) -> nn::Conv2D {
    let cfg = nn::ConvConfig {
        stride,
        padding: k / 2,
        padding_mode: if reflect {
            nn::PaddingMode::Reflect
        } else {
            nn::PaddingMode::Zeros
        },
        ..Default::default()
    };
    nn::conv2d(p, c_in, c_out, k, cfg)
}

/// The generator's encoder: 7×7 conv, then two strided 3×3 convs, each followed by
/// instance norm and ReLU. Its output is the latent state.
#[derive(Debug)]
pub struct Encoder {
    convs: Vec<nn::Conv2D>,
}

impl Encoder {
    pub fn new(p: &nn::Path, cfg: &ModelConfig) -> Encoder {
        let [a, b, c] = cfg.enc_widths;
        Encoder {
            convs: vec![
                conv(p / "conv0", 3, a, 7, 1, true),
                conv(p / "conv1", a, b, 3, 2, false),
                conv(p / "conv2", b, c, 3, 2, false),
            ],
        }
    }
}

impl Module for Encoder {
    fn forward(&self, x: &Tensor) -> Tensor {
        self.convs
            .iter()
            .fold(x.shallow_clone(), |h, c| instance_norm(&h.apply(c)).relu())
    }
}

#[derive(Debug)]
struct ResBlock {
    a: nn::Conv2D,
    b: nn::Conv2D,
}

impl Module for ResBlock {
    fn forward(&self, x: &Tensor) -> Tensor {
        let h = instance_norm(&x.apply(&self.a)).relu();
        x + instance_norm(&h.apply(&self.b))
    }
}

/// Residual blocks and the decoder: two strided transposed convs back to the input size,
/// then a 7×7 conv to RGB and tanh.
#[derive(Debug)]
pub struct Decoder {
    blocks: Vec<ResBlock>,
    up: Vec<nn::ConvTranspose2D>,
    out: nn::Conv2D,
}

impl Decoder {
    pub fn new(p: &nn::Path, cfg: &ModelConfig) -> Decoder {
        let [a, b, c] = cfg.enc_widths;
        let blocks = (0..cfg.res_blocks)
            .map(|i| ResBlock {
                a: conv(p / format!("res{i}a"), c, c, 3, 1, true),
                b: conv(p / format!("res{i}b"), c, c, 3, 1, true),
            })
            .collect();
        let tcfg = nn::ConvTransposeConfig {
            stride: 2,
            padding: 1,
            output_padding: 1,
            ..Default::default()
        };
        Decoder {
            blocks,
            up: vec![
                nn::conv_transpose2d(p / "up0", c, b, 3, tcfg),
                nn::conv_transpose2d(p / "up1", b, a, 3, tcfg),
            ],
            out: conv(p / "out", a, 3, 7, 1, true),
        }
    }
}

impl Module for Decoder {
    fn forward(&self, z: &Tensor) -> Tensor {
        let h = self.blocks.iter().fold(z.shallow_clone(), |h, b| b.forward(&h));
        let h = self.up.iter().fold(h, |h, u| instance_norm(&h.apply(u)).relu());
        h.apply(&self.out).tanh()
    }
}

/// A generator (G: human → robot, or F: robot → human).
#[derive(Debug)]
pub struct Generator {
    pub encoder: Encoder,
    pub decoder: Decoder,
}

impl Generator {
    pub fn new(p: &nn::Path, cfg: &ModelConfig) -> Generator {
        Generator {
            encoder: Encoder::new(&(p / "enc"), cfg),
            decoder: Decoder::new(&(p / "dec"), cfg),
        }
    }

    pub fn encode(&self, x: &Tensor) -> Tensor {
        self.encoder.forward(x)
    }
}

impl Module for Generator {
    fn forward(&self, x: &Tensor) -> Tensor {
        self.decoder.forward(&self.encoder.forward(x))
    }
}

/// PatchGAN discriminator: three strided 4×4 convs and two non-strided ones; one logit
/// per overlapping patch.
#[derive(Debug)]
pub struct Discriminator {
    convs: Vec<nn::Conv2D>,
}

impl Discriminator {
    pub fn new(p: &nn::Path, cfg: &ModelConfig) -> Discriminator {
        let w = cfg.disc_width;
        let k4 = |name: &str, i: i64, o: i64, stride: i64| {
            let c = nn::ConvConfig {
                stride,
                padding: 1,
                ..Default::default()
            };
            nn::conv2d(p / name, i, o, 4, c)
        };
        Discriminator {
            convs: vec![
                k4("c0", 3, w, 2),
                k4("c1", w, 2 * w, 2),
                k4("c2", 2 * w, 4 * w, 2),
                k4("c3", 4 * w, 8 * w, 1),
                k4("c4", 8 * w, 1, 1),
            ],
        }
    }
}

impl Module for Discriminator {
    fn forward(&self, x: &Tensor) -> Tensor {
        let last = self.convs.len() - 1;
        self.convs
            .iter()
            .enumerate()
            .fold(x.shallow_clone(), |h, (i, c)| {
                let h = h.apply(c);
                match i {
                    0 => h.leaky_relu_with(0.2),
                    i if i == last => h,
                    _ => instance_norm(&h).leaky_relu_with(0.2),
                }
            })
    }
}

trait LeakyRelu {
    fn leaky_relu_with(&self, slope: f64) -> Tensor;
}

impl LeakyRelu for Tensor {
    fn leaky_relu_with(&self, slope: f64) -> Tensor {
        self.maximum(&(self * slope))
    }
}

/// Inverse dynamics π_I: the latents of two consecutive frames (concatenated on channels)
/// → a strided and a non-strided 5×5 conv, spatial softmax, two hidden layers → action.
#[derive(Debug)]
pub struct InverseDynamics {
    c0: nn::Conv2D,
    c1: nn::Conv2D,
    fc: Vec<nn::Linear>,
    /// Negative slope of the conv activations ([`ModelConfig::idm_slope`]).
    slope: f64,
}

impl InverseDynamics {
    pub fn new(p: &nn::Path, cfg: &ModelConfig) -> InverseDynamics {
        let z = cfg.enc_widths[2];
        let (f, hdim) = (cfg.idm_filters, cfg.idm_hidden);
        InverseDynamics {
            c0: conv(p / "c0", 2 * z, f, 5, 2, false),
            c1: conv(p / "c1", f, f, 5, 1, false),
            fc: vec![
                nn::linear(p / "fc0", 2 * f, hdim, Default::default()),
                nn::linear(p / "fc1", hdim, hdim, Default::default()),
                nn::linear(p / "out", hdim, cfg.action_dim, Default::default()),
            ],
            slope: cfg.idm_slope,
        }
    }

    /// Action from the latents of frames t and t+1.
    pub fn forward(&self, z_t: &Tensor, z_next: &Tensor) -> Tensor {
        let h = Tensor::cat(&[z_t, z_next], 1)
            .apply(&self.c0)
            .leaky_relu_with(self.slope)
            .apply(&self.c1)
            .leaky_relu_with(self.slope);
        let last = self.fc.len() - 1;
        self.fc.iter().enumerate().fold(spatial_softmax(&h), |h, (i, l)| {
            let h = h.apply(l);
            if i == last { h } else { h.relu() }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::{Device, Kind};

    #[test]
    fn every_net_has_the_documented_shapes() {
        let _serial = crate::testing::torch_rng();
        for size in [32i64, 64] {
            let cfg = ModelConfig {
                image_size: size,
                ..ModelConfig::tiny(size)
            };
            let vs = nn::VarStore::new(Device::Cpu);
            let g = Generator::new(&(vs.root() / "g"), &cfg);
            let d = Discriminator::new(&(vs.root() / "d"), &cfg);
            let idm = InverseDynamics::new(&(vs.root() / "i"), &cfg);
            let x = Tensor::rand([2, 3, size, size], (Kind::Float, Device::Cpu)) * 2.0 - 1.0;
            let z = g.encode(&x);
            let [c, h, w] = cfg.latent_shape();
            assert_eq!(z.size(), [2, c, h, w]);
            let y = g.forward(&x);
            assert_eq!(y.size(), [2, 3, size, size]);
            assert!(y.abs().max().double_value(&[]) <= 1.0);
            // PatchGAN: three halvings, then two 4×4 convs with padding 1 (−1 each).
            assert_eq!(d.forward(&x).size(), [2, 1, size / 8 - 2, size / 8 - 2]);
            assert_eq!(idm.forward(&z, &z).size(), [2, cfg.action_dim]);
        }
        let p = spatial_softmax(&Tensor::zeros([1, 3, 4, 5], (Kind::Float, Device::Cpu)));
        assert_eq!(p.size(), [1, 6]);
        // A uniform map's expected position is the centre.
        assert!(p.abs().max().double_value(&[]) < 1e-6);
    }

    /// A π_I whose first conv is all negative (its units dead) gets no gradient into its
    /// conv weights with a ReLU — it predicts a constant for ever — and does with a
    /// leaky activation.
    #[test]
    fn a_dead_inverse_dynamics_recovers_only_with_a_leaky_activation() {
        let _serial = crate::testing::torch_rng();
        let grad_of_c0 = |slope: f64| -> f64 {
            let cfg = ModelConfig {
                idm_slope: slope,
                ..ModelConfig::tiny(32)
            };
            let vs = nn::VarStore::new(Device::Cpu);
            let idm = InverseDynamics::new(&(vs.root() / "i"), &cfg);
            tch::no_grad(|| {
                if let Some(b) = &idm.c0.bs {
                    let _ = b.shallow_clone().fill_(-100.0);
                }
            });
            let [c, h, w] = cfg.latent_shape();
            let z = Tensor::rand([4, c, h, w], (Kind::Float, Device::Cpu));
            let loss = (idm.forward(&z, &(&z * 0.5)) - 1.0).square().mean(Kind::Float);
            loss.backward();
            idm.c0.ws.grad().abs().sum(Kind::Float).double_value(&[])
        };
        assert_eq!(grad_of_c0(0.0), 0.0);
        assert!(grad_of_c0(0.2) > 0.0);
    }
}
