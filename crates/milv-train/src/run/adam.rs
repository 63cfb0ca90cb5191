//! Adam with its state in named tensors, so a checkpoint can hold the moments and a
//! resumed run continues exactly where it stopped (tch's optimizers keep theirs in C++,
//! out of reach of a safetensors file).

use std::collections::BTreeMap;

use tch::{Tensor, nn};

/// Adam (Kingma & Ba) over the trainable variables of one VarStore, as `torch.optim.Adam`
/// computes it (bias-corrected moments, ε added after the square root).
pub struct Adam {
    params: Vec<(String, Tensor)>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    pub steps: i64,
}

impl Adam {
    pub fn new(vs: &nn::VarStore, lr: f64, beta1: f64) -> Adam {
        let mut params: Vec<(String, Tensor)> = vs
            .variables()
            .into_iter()
            .filter(|(_, t)| t.requires_grad())
            .collect();
        // A fixed order, so state tensors line up with their names.
        params.sort_by(|a, b| a.0.cmp(&b.0));
        let zeros = |p: &[(String, Tensor)]| p.iter().map(|(_, t)| t.zeros_like()).collect();
        Adam {
            m: zeros(&params),
            v: zeros(&params),
            params,
            lr,
            beta1,
            beta2: 0.999,
            eps: 1e-8,
            steps: 0,
        }
    }

    pub fn zero_grad(&mut self) {
        for (_, p) in &mut self.params {
            let mut g = p.grad();
            if g.defined() {
                let _ = g.detach_().zero_();
            }
        }
    }

    /// One update from the gradients the last backward pass left (parameters without a
    /// gradient are skipped, as in PyTorch).
    pub fn step(&mut self) {
        self.steps += 1;
        let bc1 = 1.0 - self.beta1.powi(self.steps as i32);
        let bc2 = 1.0 - self.beta2.powi(self.steps as i32);
        tch::no_grad(|| {
            for (((_, p), m), v) in self.params.iter_mut().zip(&mut self.m).zip(&mut self.v) {
                let g = p.grad();
                if !g.defined() {
                    continue;
                }
                let _ = m.g_mul_scalar_(self.beta1).g_add_(&(&g * (1.0 - self.beta1)));
                let _ = v
                    .g_mul_scalar_(self.beta2)
                    .g_add_(&(&g * &g * (1.0 - self.beta2)));
                let denom = (&*v / bc2).sqrt() + self.eps;
                let _ = p.g_sub_(&(&*m / &denom * (self.lr / bc1)));
            }
        });
    }

    /// The moments and step count as named tensors (`m.<var>`, `v.<var>`, `steps`).
    pub fn state(&self) -> Vec<(String, Tensor)> {
        let mut out: Vec<(String, Tensor)> = Vec::with_capacity(2 * self.params.len() + 1);
        for ((name, _), (m, v)) in self.params.iter().zip(self.m.iter().zip(&self.v)) {
            out.push((format!("m.{name}"), m.shallow_clone()));
            out.push((format!("v.{name}"), v.shallow_clone()));
        }
        out.push(("steps".into(), Tensor::from_slice(&[self.steps])));
        out
    }

    /// Restores what [`Adam::state`] wrote; every variable must be there, same shapes.
    pub fn load_state(&mut self, state: Vec<(String, Tensor)>) -> Result<(), crate::Error> {
        let mut by_name: BTreeMap<String, Tensor> = state.into_iter().collect();
        let missing = |k: &str| crate::Error::State(format!("optimizer state lacks {k}"));
        for ((name, p), (m, v)) in self.params.iter().zip(self.m.iter_mut().zip(self.v.iter_mut())) {
            for (prefix, slot) in [("m", &mut *m), ("v", &mut *v)] {
                let key = format!("{prefix}.{name}");
                let t = by_name.remove(&key).ok_or_else(|| missing(&key))?;
                if t.size() != p.size() {
                    return Err(crate::Error::State(format!(
                        "optimizer state {key} has shape {:?}, the variable {:?}",
                        t.size(),
                        p.size()
                    )));
                }
                *slot = t.to_device(p.device());
            }
        }
        let steps = by_name.remove("steps").ok_or_else(|| missing("steps"))?;
        self.steps = steps.int64_value(&[0]);
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use tch::{Device, Kind};

    #[test]
    fn matches_the_adam_update_rule() {
        let vs = nn::VarStore::new(Device::Cpu);
        let w = vs.root().var("w", &[3], nn::Init::Const(1.0));
        let mut opt = Adam::new(&vs, 0.1, 0.9);
        // Loss Σ c·w with c = (1, 2, 3): the gradient is c at every step.
        let c = Tensor::from_slice(&[1.0f32, 2.0, 3.0]);
        for _ in 0..2 {
            opt.zero_grad();
            (&w * &c).sum(Kind::Float).backward();
            opt.step();
        }
        // With a constant gradient the bias-corrected m̂ = g and v̂ = g², so each step moves
        // every weight by lr·g/(|g| + ε) ≈ lr.
        let got: Vec<f32> = Vec::try_from(&w).unwrap();
        for v in got {
            assert!((v - 0.8).abs() < 1e-5, "{v}");
        }
        // State round trip.
        let mut other = Adam::new(&vs, 0.1, 0.9);
        other.load_state(opt.state()).unwrap();
        assert_eq!(other.steps, 2);
        assert!(other.load_state(vec![]).is_err());
    }
}
