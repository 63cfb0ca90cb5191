//! Network layers both rooms use.

use tch::Tensor;

/// Expected (x, y) image coordinates in [-1, 1] of each channel's softmax over its pixels:
/// `[B, C, H, W]` → `[B, 2C]` (Levine et al.'s spatial softmax).
pub fn spatial_softmax(x: &Tensor) -> Tensor {
    let (b, c, h, w) = x.size4().unwrap_or((1, 1, 1, 1));
    let k = x.kind();
    let p = x.view([b, c, h * w]).softmax(-1, k).view([b, c, h, w]);
    let opts = (k, x.device());
    let xs = Tensor::linspace(-1.0, 1.0, w, opts).view([1, 1, 1, w]);
    let ys = Tensor::linspace(-1.0, 1.0, h, opts).view([1, 1, h, 1]);
    let ex = (&p * xs).sum_dim_intlist([2i64, 3].as_slice(), false, k);
    let ey = (&p * ys).sum_dim_intlist([2i64, 3].as_slice(), false, k);
    Tensor::cat(&[ex, ey], 1)
}
