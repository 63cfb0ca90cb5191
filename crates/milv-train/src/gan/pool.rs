//! The history of generated images each discriminator is shown (Shrivastava et al.; the
//! CycleGAN reference keeps 50): the discriminator sees old fakes too, so the two players
//! do not chase each other in circles.

use rand::Rng;
use tch::Tensor;

pub struct ImagePool {
    capacity: usize,
    images: Vec<Tensor>,
}

impl ImagePool {
    pub fn new(capacity: usize) -> Self {
        ImagePool {
            capacity,
            images: Vec::new(),
        }
    }

    /// For each image of the batch: while the pool fills, the image itself (and it is
    /// kept); then, with probability ½, a stored image it replaces, else itself.
    pub fn query(&mut self, batch: &Tensor, rng: &mut impl Rng) -> Tensor {
        if self.capacity == 0 {
            return batch.shallow_clone();
        }
        let n = batch.size()[0];
        let out: Vec<Tensor> = (0..n)
            .map(|i| {
                let img = batch.get(i).detach().copy();
                if self.images.len() < self.capacity {
                    self.images.push(img.shallow_clone());
                    img
                } else if rng.random_bool(0.5) {
                    let k = rng.random_range(0..self.images.len());
                    std::mem::replace(&mut self.images[k], img)
                } else {
                    img
                }
            })
            .collect();
        Tensor::stack(&out, 0)
    }

    /// The stored images as one tensor `[n, 3, S, S]` (for checkpoints), if any.
    pub fn state(&self) -> Option<Tensor> {
        (!self.images.is_empty()).then(|| Tensor::stack(&self.images, 0))
    }

    pub fn load_state(&mut self, stacked: Option<&Tensor>) {
        self.images = stacked.map_or_else(Vec::new, |t| (0..t.size()[0]).map(|i| t.get(i).copy()).collect());
    }

    pub fn len(&self) -> usize {
        self.images.len()
    }

    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use tch::{Device, Kind};

    #[test]
    fn fills_then_mixes_history_with_new_images() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let mut pool = ImagePool::new(3);
        let img = |v: f64| Tensor::full([1, 3, 2, 2], v, (Kind::Float, Device::Cpu));
        for v in 0..3 {
            let out = pool.query(&img(f64::from(v)), &mut rng);
            assert_eq!(out.double_value(&[0, 0, 0, 0]), f64::from(v));
        }
        assert_eq!(pool.len(), 3);
        let outs: Vec<f64> = (0..40)
            .map(|_| pool.query(&img(9.0), &mut rng).double_value(&[0, 0, 0, 0]))
            .collect();
        assert!(outs.contains(&9.0) && outs.iter().any(|&v| v < 3.0));
        let mut other = ImagePool::new(3);
        other.load_state(pool.state().as_ref());
        assert_eq!(other.len(), 3);
    }
}
