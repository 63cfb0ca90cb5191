//! The fused SSIM kernel: one pass over the rows computes the Gaussian moment maps and
//! the per-pixel SSIM sum, with an 11-row ring of horizontally blurred rows instead of
//! full-size blurred planes. SSIM only needs `σx² + σy²`, so four maps suffice:
//! μx, μy, E[x² + y²] and E[xy] (one blur fewer than the textbook five).
//!
//! Every lane and the scalar tail add in the same order (tap 0 first), and no FMA
//! contraction is used, so every CPU path gives bit-identical results.

use crate::Error;

pub(crate) const RADIUS: usize = 5;
pub(crate) const TAPS: usize = 2 * RADIUS + 1;
/// Moment maps: x, y, x² + y², xy.
const MAPS: usize = 4;
/// Partial sums of the SSIM map: pixel x adds into `sum[x % SUMS]` on every path, so the
/// vector widths LLVM picks for AVX-512, AVX2 or SSE2 all add in the same order.
const SUMS: usize = 8;
/// Output rows blurred together by the vertical pass (see [`vblur_block`]).
const BLOCK: usize = 4;
/// Horizontally blurred rows kept: enough for one block of output rows.
const RING: usize = TAPS + BLOCK - 1;

const C1: f64 = (0.01 * 255.0) * (0.01 * 255.0);
const C2: f64 = (0.03 * 255.0) * (0.03 * 255.0);

/// The 11-tap Gaussian, σ = 1.5, renormalised to sum to 1.
pub(crate) fn gaussian() -> [f64; TAPS] {
    let mut w = [0.0; TAPS];
    for (i, v) in w.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        *v = (-d * d / (2.0 * 1.5 * 1.5)).exp();
    }
    let s: f64 = w.iter().sum();
    w.map(|v| v / s)
}

/// Reusable scratch for [`ssim_planes`]: sized on first use and regrown only when the
/// frame size grows, so scoring a clip allocates nothing per frame.
#[derive(Debug, Default, Clone)]
pub(crate) struct Scratch {
    products: Vec<f64>,
    ring: Vec<f64>,
    moments: Vec<f64>,
}

/// Mean SSIM of two `w×h` planes over the valid `(h−10)×(w−10)` region.
pub(crate) fn ssim_planes(x: &[f64], y: &[f64], w: usize, h: usize, s: &mut Scratch) -> Result<f64, Error> {
    if w < TAPS || h < TAPS {
        return Err(Error::TooSmall {
            width: w,
            height: h,
            min: TAPS,
        });
    }
    debug_assert!(x.len() == w * h && y.len() == w * h);
    let ow = w - 2 * RADIUS;
    s.products.resize(2 * w, 0.0);
    s.ring.resize(RING * MAPS * ow, 0.0);
    s.moments.resize(BLOCK * MAPS * ow, 0.0);
    let g = gaussian();
    let sum = dispatch(x, y, w, h, &g, s);
    Ok(sum / ((h - 2 * RADIUS) * ow) as f64)
}

/// The vector instruction sets the kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Level {
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    Avx512,
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    Avx2,
    Baseline,
}

/// The best level this CPU runs (AVX-512 and AVX2 paths also need FMA).
fn cpu_level() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        let fma = std::arch::is_x86_feature_detected!("fma");
        if fma && std::arch::is_x86_feature_detected!("avx512f") {
            return Level::Avx512;
        }
        if fma && std::arch::is_x86_feature_detected!("avx2") {
            return Level::Avx2;
        }
    }
    Level::Baseline
}

/// Defines `fn $name` that runs `$body` compiled for AVX-512, AVX2 (both with FMA) or
/// the baseline, whichever the CPU has. The body is the same source each time, so the
/// results are the same on every path; only the vector width differs.
macro_rules! multiversion {
    ($(#[$m:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty $body:block) => {
        $(#[$m])*
        #[allow(unsafe_code)]
        $vis fn $name($($arg: $ty),*) -> $ret {
            #[inline(always)]
            fn body($($arg: $ty),*) -> $ret $body
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,fma")]
            fn avx512($($arg: $ty),*) -> $ret {
                body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            fn avx2($($arg: $ty),*) -> $ret {
                body($($arg),*)
            }
            match cpu_level() {
                // SAFETY: `cpu_level` checked that the CPU has AVX-512F and FMA.
                #[cfg(target_arch = "x86_64")]
                Level::Avx512 => unsafe { avx512($($arg),*) },
                // SAFETY: `cpu_level` checked that the CPU has AVX2 and FMA.
                #[cfg(target_arch = "x86_64")]
                Level::Avx2 => unsafe { avx2($($arg),*) },
                _ => body($($arg),*),
            }
        }
    };
}

#[allow(unsafe_code)]
fn dispatch(x: &[f64], y: &[f64], w: usize, h: usize, g: &[f64; TAPS], s: &mut Scratch) -> f64 {
    match cpu_level() {
        // SAFETY: `cpu_level` checked that the CPU has AVX-512F and FMA.
        #[cfg(target_arch = "x86_64")]
        Level::Avx512 => unsafe { x86::fused_avx512(x, y, w, h, g, s) },
        // SAFETY: `cpu_level` checked that the CPU has AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        Level::Avx2 => unsafe { x86::fused_avx2(x, y, w, h, g, s) },
        _ => fused(x, y, w, h, g, s, hblur),
    }
}

/// x86-64 instantiations of [`fused`], and the AVX-512 row blur.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use super::{RADIUS, Scratch, TAPS, fused, hblur};
    use std::arch::x86_64::*;

    #[target_feature(enable = "avx512f,fma")]
    pub(super) fn fused_avx512(
        x: &[f64],
        y: &[f64],
        w: usize,
        h: usize,
        g: &[f64; TAPS],
        s: &mut Scratch,
    ) -> f64 {
        // The closure inherits this function's target features.
        fused(x, y, w, h, g, s, |src, out, g| hblur_avx512(src, out, g))
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn fused_avx2(
        x: &[f64],
        y: &[f64],
        w: usize,
        h: usize,
        g: &[f64; TAPS],
        s: &mut Scratch,
    ) -> f64 {
        fused(x, y, w, h, g, s, hblur)
    }

    /// [`hblur`] with one load per 8 outputs: the 11 shifted windows come from three
    /// neighbouring vectors by `valignq` instead of 11 unaligned (mostly line-splitting)
    /// loads. Same operations in the same order as [`super::tap`], so bit-identical.
    #[target_feature(enable = "avx512f,fma")]
    fn hblur_avx512(src: &[f64], out: &mut [f64], g: &[f64; TAPS]) {
        let n = out.len();
        debug_assert_eq!(src.len(), n + 2 * RADIUS);
        let gv: [__m512d; TAPS] = std::array::from_fn(|k| _mm512_set1_pd(g[k]));
        let load = |i: usize| -> __m512d {
            let v = &src[i..i + 8];
            // SAFETY: `v` is 8 in-bounds f64s (the slice index above checks it).
            unsafe { _mm512_loadu_pd(v.as_ptr()) }
        };
        macro_rules! win {
            ($hi:expr, $lo:expr, $k:literal) => {
                _mm512_castsi512_pd(_mm512_alignr_epi64::<$k>(
                    _mm512_castpd_si512($hi),
                    _mm512_castpd_si512($lo),
                ))
            };
        }
        let mut x0 = 0;
        if src.len() >= 16 {
            let (mut v0, mut v1) = (load(0), load(8));
            // Block x0 reads src[x0 .. x0+24].
            while x0 + 24 <= src.len() && x0 + 8 <= n {
                let v2 = load(x0 + 16);
                let t = [
                    v0,
                    win!(v1, v0, 1),
                    win!(v1, v0, 2),
                    win!(v1, v0, 3),
                    win!(v1, v0, 4),
                    win!(v1, v0, 5),
                    win!(v1, v0, 6),
                    win!(v1, v0, 7),
                    v1,
                    win!(v2, v1, 1),
                    win!(v2, v1, 2),
                ];
                let mut a = _mm512_mul_pd(gv[5], t[5]);
                for (k, gk) in gv.iter().enumerate().take(RADIUS) {
                    a = _mm512_fmadd_pd(*gk, _mm512_add_pd(t[k], t[TAPS - 1 - k]), a);
                }
                let o = &mut out[x0..x0 + 8];
                // SAFETY: `o` is 8 in-bounds f64s.
                unsafe { _mm512_storeu_pd(o.as_mut_ptr(), a) };
                (v0, v1) = (v1, v2);
                x0 += 8;
            }
        }
        hblur(&src[x0..], &mut out[x0..], g);
    }
}

multiversion! {
    /// BT.601 luma of packed RGB24 into `out` (same length in pixels).
    pub(crate) fn luma(rgb: &[u8], out: &mut [f64]) -> () {
        let y = |p: &[u8]| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]);
        // Eight pixels per step so LLVM de-interleaves with vector shuffles.
        let (px, tail) = rgb.as_chunks::<24>();
        let (oc, ot) = out.as_chunks_mut::<8>();
        for (o, p) in oc.iter_mut().zip(px) {
            for i in 0..8 {
                o[i] = y(&p[3 * i..3 * i + 3]);
            }
        }
        for (o, p) in ot.iter_mut().zip(tail.chunks_exact(3)) {
            *o = y(p);
        }
    }
}

/// Forced inline into each `target_feature` wrapper so LLVM vectorises the same loops
/// for that instruction set. The loops are plain element-wise passes over equal-length
/// slices (no bounds checks inside), which LLVM turns into full-width vector code.
#[inline(always)]
fn fused(
    x: &[f64],
    y: &[f64],
    w: usize,
    h: usize,
    g: &[f64; TAPS],
    s: &mut Scratch,
    hblur: impl Fn(&[f64], &mut [f64], &[f64; TAPS]),
) -> f64 {
    let ow = w - 2 * RADIUS;
    let slot_len = MAPS * ow;
    let (sq, xy) = s.products.split_at_mut(w);
    let mut sum = [0.0f64; SUMS];
    let oh = h - 2 * RADIUS;
    let mut next = 0; // first output row not yet summed
    for r in 0..h {
        let xr = &x[r * w..(r + 1) * w];
        let yr = &y[r * w..(r + 1) * w];
        for (((a, b), psq), pxy) in xr.iter().zip(yr).zip(&mut *sq).zip(&mut *xy) {
            *psq = a * a + b * b;
            *pxy = a * b;
        }
        let slot = r % RING;
        let dst = &mut s.ring[slot * slot_len..(slot + 1) * slot_len];
        for (src, out) in [xr, yr, &*sq, &*xy].into_iter().zip(dst.chunks_exact_mut(ow)) {
            hblur(src, out, g);
        }
        // Output row o needs input rows o ..= o+10. Sum BLOCK rows at a time (their
        // input rows overlap, so each loaded vector feeds several outputs), single rows
        // at the bottom edge.
        while next < oh {
            let rows = if next + BLOCK - 1 + 2 * RADIUS <= r {
                BLOCK
            } else if r + 1 == h {
                1
            } else {
                break;
            };
            for m in 0..MAPS {
                let t: [&[f64]; RING] = std::array::from_fn(|k| {
                    let start = ((next + k) % RING) * slot_len + m * ow;
                    s.ring.get(start..start + ow).unwrap_or(&[])
                });
                let out = &mut s.moments[m * BLOCK * ow..(m + 1) * BLOCK * ow];
                if rows == BLOCK {
                    vblur_block(&t, out, g);
                } else {
                    let t1: [&[f64]; TAPS] = std::array::from_fn(|k| t[k]);
                    vblur(&t1, &mut out[..ow], g);
                }
            }
            for j in 0..rows {
                let m: [&[f64]; MAPS] =
                    std::array::from_fn(|m| &s.moments[(m * BLOCK + j) * ow..(m * BLOCK + j + 1) * ow]);
                ssim_row(&m, &mut sum);
            }
            next += rows;
        }
    }
    sum.iter().sum()
}

/// One output of the symmetric 11-tap Gaussian,
/// `g5·t5 + Σ_{k<5} g_k·(t_k + t_{10−k})`, with fused multiply-adds: one rounding per
/// step, the same on every CPU (the baseline path calls the exact software `fma`).
#[inline(always)]
fn tap(g: &[f64; TAPS], t: impl Fn(usize) -> f64) -> f64 {
    let mut a = g[5] * t(5);
    for (k, gk) in g.iter().enumerate().take(RADIUS) {
        a = gk.mul_add(t(k) + t(TAPS - 1 - k), a);
    }
    a
}

/// Valid horizontal blur of one row: `out[x] = g5·s[x+5] + Σ_{k<5} g_k·(s[x+k] + s[x+10−k])`.
#[inline(always)]
fn hblur(src: &[f64], out: &mut [f64], g: &[f64; TAPS]) {
    let n = out.len();
    let t: [&[f64]; TAPS] = std::array::from_fn(|k| &src[k..k + n]);
    for (x, o) in out.iter_mut().enumerate() {
        *o = tap(g, |k| t[k][x]);
    }
}

/// Vertical blur of 11 rows, the same expression as [`hblur`].
#[inline(always)]
fn vblur(t: &[&[f64]; TAPS], out: &mut [f64], g: &[f64; TAPS]) {
    let n = out.len();
    let t: [&[f64]; TAPS] = std::array::from_fn(|k| &t[k][..n]);
    for (x, o) in out.iter_mut().enumerate() {
        *o = tap(g, |k| t[k][x]);
    }
}

/// [`vblur`] for `BLOCK` consecutive output rows from `BLOCK + 10` input rows: each
/// loaded input vector feeds up to `BLOCK` outputs. `out` holds the rows one after another.
#[inline(always)]
fn vblur_block(t: &[&[f64]; RING], out: &mut [f64], g: &[f64; TAPS]) {
    let n = out.len() / BLOCK;
    let t: [&[f64]; RING] = std::array::from_fn(|k| &t[k][..n]);
    let (o0, rest) = out.split_at_mut(n);
    let (o1, rest) = rest.split_at_mut(n);
    let (o2, o3) = rest.split_at_mut(n);
    let o3 = &mut o3[..n];
    for x in 0..n {
        let v: [f64; RING] = std::array::from_fn(|k| t[k][x]);
        o0[x] = tap(g, |k| v[k]);
        o1[x] = tap(g, |k| v[k + 1]);
        o2[x] = tap(g, |k| v[k + 2]);
        o3[x] = tap(g, |k| v[k + 3]);
    }
}

/// Adds one row of the SSIM map into the partial sums.
#[inline(always)]
fn ssim_row(m: &[&[f64]; MAPS], sum: &mut [f64; SUMS]) {
    let ow = m[0].len();
    let (mx, my, esq, exy) = (m[0], &m[1][..ow], &m[2][..ow], &m[3][..ow]);
    let full = ow / SUMS * SUMS;
    for c in (0..full).step_by(SUMS) {
        for (i, acc) in sum.iter_mut().enumerate() {
            let x = c + i;
            *acc += ssim_pixel(mx[x], my[x], esq[x], exy[x]);
        }
    }
    for x in full..ow {
        sum[x % SUMS] += ssim_pixel(mx[x], my[x], esq[x], exy[x]);
    }
}

#[inline(always)]
fn ssim_pixel(mx: f64, my: f64, esq: f64, exy: f64) -> f64 {
    let mxy = mx * my;
    let m2 = mx * mx + my * my;
    // σx² + σy² = E[x² + y²] − (μx² + μy²); σxy = E[xy] − μxμy.
    ((2.0 * mxy + C1) * (2.0 * (exy - mxy) + C2)) / ((m2 + C1) * (esq - m2 + C2))
}

multiversion! {
/// Brenner sums `(S_h, S_v)` of a luma plane; lane-parallel partial sums so LLVM
/// vectorises them, in an order that does not depend on the vector width.
pub(crate) fn brenner_sums(y: &[f64], w: usize, h: usize) -> (f64, f64) {
    let mut sh = [0.0f64; SUMS];
    let mut sv = [0.0f64; SUMS];
    for r in 0..h {
        let row = &y[r * w..(r + 1) * w];
        sq_diff_sum(&row[..w - 2], &row[2..], &mut sh);
        if r + 2 < h {
            sq_diff_sum(row, &y[(r + 2) * w..(r + 3) * w], &mut sv);
        }
    }
    (sh.iter().sum(), sv.iter().sum())
}
}

/// `sum[i % 8] += (b[i] − a[i])²`.
#[inline(always)]
fn sq_diff_sum(a: &[f64], b: &[f64], sum: &mut [f64; SUMS]) {
    let (ac, at) = a.as_chunks::<SUMS>();
    let (bc, bt) = b[..a.len()].as_chunks::<SUMS>();
    for (ca, cb) in ac.iter().zip(bc) {
        for i in 0..SUMS {
            let d = cb[i] - ca[i];
            sum[i] += d * d;
        }
    }
    for (i, (p, q)) in at.iter().zip(bt).enumerate() {
        let d = q - p;
        sum[i] += d * d;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The textbook recipe (five full 2-D blurs, then the per-pixel formula), as a reference
    /// for the fused four-map ring.
    fn reference(x: &[f64], y: &[f64], w: usize, h: usize) -> f64 {
        let g = gaussian();
        let blur = |p: &[f64]| -> Vec<f64> {
            let (ow, oh) = (w - 10, h - 10);
            let mut out = vec![0.0; ow * oh];
            for r in 0..oh {
                for c in 0..ow {
                    let mut a = 0.0;
                    for (i, gi) in g.iter().enumerate() {
                        for (j, gj) in g.iter().enumerate() {
                            a += gi * gj * p[(r + i) * w + c + j];
                        }
                    }
                    out[r * ow + c] = a;
                }
            }
            out
        };
        let prod = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).collect::<Vec<_>>();
        let (mx, my) = (blur(x), blur(y));
        let (exx, eyy, exy) = (blur(&prod(x, x)), blur(&prod(y, y)), blur(&prod(x, y)));
        let n = mx.len();
        (0..n)
            .map(|i| {
                let (vx, vy, vxy) = (
                    exx[i] - mx[i] * mx[i],
                    eyy[i] - my[i] * my[i],
                    exy[i] - mx[i] * my[i],
                );
                ((2.0 * mx[i] * my[i] + C1) * (2.0 * vxy + C2))
                    / ((mx[i] * mx[i] + my[i] * my[i] + C1) * (vx + vy + C2))
            })
            .sum::<f64>()
            / n as f64
    }

    #[test]
    fn fused_ring_matches_the_two_pass_reference_at_odd_sizes() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) % 256) as f64
        };
        let mut s = Scratch::default();
        for (w, h) in [(11, 11), (13, 17), (19, 12), (27, 40), (64, 33)] {
            let x: Vec<f64> = (0..w * h).map(|_| rnd()).collect();
            let y: Vec<f64> = x.iter().map(|v| (v * 0.7 + rnd() * 0.3).round()).collect();
            let got = ssim_planes(&x, &y, w, h, &mut s).unwrap();
            let want = reference(&x, &y, w, h);
            assert!((got - want).abs() < 1e-12, "{w}x{h}: {got} vs {want}");
        }
    }

    #[test]
    fn every_cpu_path_is_bit_identical() {
        let (w, h) = (67, 29);
        let x: Vec<f64> = (0..w * h).map(|i| ((i * 37) % 251) as f64).collect();
        let y: Vec<f64> = (0..w * h).map(|i| ((i * 11) % 241) as f64).collect();
        let mut s = Scratch::default();
        let dispatched = ssim_planes(&x, &y, w, h, &mut s).unwrap();
        let g = gaussian();
        let plain = fused(&x, &y, w, h, &g, &mut s, hblur) / ((h - 10) * (w - 10)) as f64;
        assert_eq!(dispatched.to_bits(), plain.to_bits());
    }
}
