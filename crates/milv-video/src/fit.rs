//! Aspect-ratio arithmetic (`fit_plan`) and the single copy from a scaled image into the output canvas.

use crate::{AspectPolicy, Resize};

/// How to turn a `src` image into a `dst` image: scale to `scale_w × scale_h`, then
/// take the window at (`crop_x`, `crop_y`) and place it at (`pad_x`, `pad_y`) in a black canvas.
///
/// At most one of crop/pad is non-zero per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
    pub scale_w: u32,
    pub scale_h: u32,
    pub crop_x: u32,
    pub crop_y: u32,
    pub pad_x: u32,
    pub pad_y: u32,
}

impl Plan {
    /// The identity plan for an unresized `w × h` source.
    pub fn identity(w: u32, h: u32) -> Self {
        Plan {
            scale_w: w,
            scale_h: h,
            crop_x: 0,
            crop_y: 0,
            pad_x: 0,
            pad_y: 0,
        }
    }
}

/// Computes the scale/crop/pad plan for resizing `src_w × src_h` to `dst_w × dst_h`.
///
/// Zero sizes are clamped to 1 so this never divides by zero.
pub fn fit_plan(src_w: u32, src_h: u32, dst_w: u32, dst_h: u32, policy: AspectPolicy) -> Plan {
    let (sw, sh) = (u64::from(src_w.max(1)), u64::from(src_h.max(1)));
    let (dw, dh) = (u64::from(dst_w.max(1)), u64::from(dst_h.max(1)));
    // Source wider than target (compared exactly by cross-multiplying).
    let wider = sw * dh > dw * sh;
    // round(a / b) in integers
    let div_round = |a: u64, b: u64| (a + b / 2) / b;
    let to_u32 = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
    match policy {
        AspectPolicy::Stretch => Plan::identity(to_u32(dw), to_u32(dh)),
        AspectPolicy::Pad => {
            let (w, h) = if wider {
                (dw, div_round(sh * dw, sw).clamp(1, dh))
            } else {
                (div_round(sw * dh, sh).clamp(1, dw), dh)
            };
            Plan {
                scale_w: to_u32(w),
                scale_h: to_u32(h),
                crop_x: 0,
                crop_y: 0,
                pad_x: to_u32((dw - w) / 2),
                pad_y: to_u32((dh - h) / 2),
            }
        }
        AspectPolicy::Crop => {
            let (w, h) = if wider {
                (div_round(sw * dh, sh).max(dw), dh)
            } else {
                (dw, div_round(sh * dw, sw).max(dh))
            };
            Plan {
                scale_w: to_u32(w),
                scale_h: to_u32(h),
                crop_x: to_u32((w - dw) / 2),
                crop_y: to_u32((h - dh) / 2),
                pad_x: 0,
                pad_y: 0,
            }
        }
    }
}

/// Output size and plan for a source frame under an optional resize.
pub(crate) fn plan_for(src_w: u32, src_h: u32, resize: Option<&Resize>) -> (u32, u32, Plan) {
    match resize {
        Some(r) => (
            r.width,
            r.height,
            fit_plan(src_w, src_h, r.width, r.height, r.policy),
        ),
        None => (src_w, src_h, Plan::identity(src_w, src_h)),
    }
}

/// Copies a scaled RGB24 image (`plan.scale_w × plan.scale_h`, rows `stride` bytes apart)
/// into a packed `dst_w × dst_h` canvas, cropping/padding per `plan`.
///
/// Returns `None` if `src` is too short for the plan (never expected from FFmpeg or `image`,
/// but checked rather than trusted).
pub(crate) fn compose(src: &[u8], stride: usize, plan: &Plan, dst_w: u32, dst_h: u32) -> Option<Vec<u8>> {
    let (dst_w, dst_h) = (dst_w as usize, dst_h as usize);
    let (crop_x, crop_y) = (plan.crop_x as usize, plan.crop_y as usize);
    let (pad_x, pad_y) = (plan.pad_x as usize, plan.pad_y as usize);
    let copy_w = (plan.scale_w as usize)
        .saturating_sub(crop_x)
        .min(dst_w.saturating_sub(pad_x));
    let copy_h = (plan.scale_h as usize)
        .saturating_sub(crop_y)
        .min(dst_h.saturating_sub(pad_y));
    let dst_row = dst_w * 3;
    let len = dst_row * dst_h;
    let row_bytes = copy_w * 3;
    let src_row = |y: usize| -> Option<&[u8]> {
        let start = (y + crop_y) * stride + crop_x * 3;
        src.get(start..start + row_bytes)
    };

    if pad_x == 0 && pad_y == 0 && copy_w == dst_w && copy_h == dst_h {
        // Common case: the scaled image fills the canvas; append rows without zeroing first.
        if crop_x == 0 && crop_y == 0 && stride == dst_row {
            return src.get(..len).map(<[u8]>::to_vec);
        }
        let mut out = Vec::with_capacity(len);
        for y in 0..dst_h {
            out.extend_from_slice(src_row(y)?);
        }
        return Some(out);
    }

    let mut out = vec![0u8; len];
    for y in 0..copy_h {
        let start = (y + pad_y) * dst_row + pad_x * 3;
        out.get_mut(start..start + row_bytes)?
            .copy_from_slice(src_row(y)?);
    }
    Some(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn plan(sw: u32, sh: u32, dw: u32, dh: u32, p: AspectPolicy) -> Plan {
        fit_plan(sw, sh, dw, dh, p)
    }

    #[test]
    fn stretch_is_exact() {
        assert_eq!(
            plan(640, 480, 224, 224, AspectPolicy::Stretch),
            Plan::identity(224, 224)
        );
    }

    #[test]
    fn pad_wide_source() {
        let p = plan(640, 480, 224, 224, AspectPolicy::Pad);
        assert_eq!((p.scale_w, p.scale_h), (224, 168));
        assert_eq!((p.pad_x, p.pad_y, p.crop_x, p.crop_y), (0, 28, 0, 0));
    }

    #[test]
    fn pad_tall_source() {
        let p = plan(480, 640, 224, 224, AspectPolicy::Pad);
        assert_eq!((p.scale_w, p.scale_h), (168, 224));
        assert_eq!((p.pad_x, p.pad_y), (28, 0));
    }

    #[test]
    fn crop_wide_source() {
        let p = plan(640, 480, 224, 224, AspectPolicy::Crop);
        assert_eq!((p.scale_w, p.scale_h), (299, 224));
        assert_eq!((p.crop_x, p.crop_y, p.pad_x, p.pad_y), (37, 0, 0, 0));
    }

    #[test]
    fn crop_tall_source() {
        let p = plan(480, 640, 224, 224, AspectPolicy::Crop);
        assert_eq!((p.scale_w, p.scale_h), (224, 299));
        assert_eq!((p.crop_x, p.crop_y), (0, 37));
    }

    #[test]
    fn same_aspect_is_plain_scale() {
        for policy in [AspectPolicy::Pad, AspectPolicy::Crop, AspectPolicy::Stretch] {
            assert_eq!(plan(1280, 720, 640, 360, policy), Plan::identity(640, 360));
        }
    }

    #[test]
    fn extreme_aspect_never_zero() {
        let p = plan(10000, 1, 100, 100, AspectPolicy::Pad);
        assert_eq!((p.scale_w, p.scale_h), (100, 1));
        let p = plan(0, 0, 100, 100, AspectPolicy::Crop);
        assert!(p.scale_w >= 100 && p.scale_h >= 100);
    }

    #[test]
    fn compose_pads_black_and_crops() {
        // 2x2 source, all 255
        let src = vec![255u8; 2 * 2 * 3];
        let p = Plan {
            scale_w: 2,
            scale_h: 2,
            crop_x: 0,
            crop_y: 0,
            pad_x: 1,
            pad_y: 0,
        };
        let out = compose(&src, 6, &p, 4, 2).unwrap();
        assert_eq!(out.len(), 4 * 2 * 3);
        assert_eq!(&out[..3], &[0, 0, 0]);
        assert_eq!(&out[3..9], &[255; 6]);
        assert_eq!(&out[9..12], &[0, 0, 0]);

        // 3x1 source with padded stride, crop the middle pixel
        let src = [1, 1, 1, 2, 2, 2, 3, 3, 3, 9, 9];
        let p = Plan {
            scale_w: 3,
            scale_h: 1,
            crop_x: 1,
            crop_y: 0,
            pad_x: 0,
            pad_y: 0,
        };
        assert_eq!(compose(&src, 11, &p, 1, 1).unwrap(), vec![2, 2, 2]);
        // too-short source is reported, not a panic
        assert!(compose(&src[..5], 11, &p, 1, 1).is_none());
    }
}
