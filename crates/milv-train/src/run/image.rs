//! Tensors ↔ images, and clips of a pinned dataset version decoded into them.

use std::collections::BTreeMap;

use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::{Dataset, Episode, TableKind};
use tch::Tensor;

use crate::{Error, Result};

/// CHW f32 in [-1, 1] → RGB24.
pub fn to_rgb(t: &Tensor) -> Result<Vec<u8>> {
    let (c, h, w) = t.size3()?;
    let v: Vec<f32> = Vec::try_from(t.to_device(tch::Device::Cpu).contiguous().view([-1]))?;
    let n = (h * w) as usize;
    let mut out = vec![0u8; n * 3];
    for i in 0..n {
        for ch in 0..c.min(3) as usize {
            out[i * 3 + ch] = ((v[ch * n + i] + 1.0) * 127.5).round().clamp(0.0, 255.0) as u8;
        }
    }
    Ok(out)
}

/// One stored episode: encoded frames and, for robot random videos, actions.
#[derive(Clone, Debug)]
pub struct Clip {
    pub episode_id: String,
    pub encoding: FrameEncoding,
    pub width: u32,
    pub height: u32,
    pub frames: Vec<Vec<u8>>,
    pub timestamps: Vec<i64>,
    pub actions: Option<Vec<Vec<f32>>>,
}

impl Clip {
    /// Frame `t` as CHW f32 in [-1, 1] at `size`×`size` (resized when stored otherwise).
    pub fn tensor_data(&self, t: usize, size: u32) -> Result<Vec<f32>> {
        let rgb = self.rgb(t)?;
        Ok(to_chw(&rgb, self.width, self.height, size))
    }

    pub fn rgb(&self, t: usize) -> Result<Vec<u8>> {
        frame_codec::decode(self.encoding, &self.frames[t], self.width, self.height)
            .map_err(|e| Error::Data(format!("episode {}: frame {t}: {e}", self.episode_id)))
    }
}

/// RGB24 → CHW f32 in [-1, 1], resized (triangle filter) to `size`×`size` if needed.
pub fn to_chw(rgb: &[u8], w: u32, h: u32, size: u32) -> Vec<f32> {
    let resized;
    let px: &[u8] = if (w, h) == (size, size) {
        rgb
    } else {
        let img = image::RgbImage::from_raw(w, h, rgb.to_vec()).unwrap_or_default();
        resized = image::imageops::resize(&img, size, size, image::imageops::FilterType::Triangle).into_raw();
        &resized
    };
    let n = (size * size) as usize;
    let mut out = vec![0.0f32; 3 * n];
    for (i, p) in px.chunks_exact(3).enumerate() {
        for c in 0..3 {
            out[c * n + i] = f32::from(p[c]) / 127.5 - 1.0;
        }
    }
    out
}

/// Reads the frames (and actions) of `wanted` episodes at version `v`.
pub fn load_clips(
    ds: &Dataset,
    v: u64,
    wanted: &BTreeMap<String, Episode>,
    with_actions: bool,
) -> Result<BTreeMap<String, Clip>> {
    let vector = with_actions.then_some("action");
    let rows = milv_data::episode_rows(
        ds,
        v,
        TableKind::Frames,
        &|id| wanted.contains_key(id),
        vector,
        None,
    )?;
    rows.into_iter()
        .map(|(id, r)| {
            let actions = if with_actions {
                let missing = r.vectors.iter().position(Option::is_none);
                if let Some(t) = missing {
                    return Err(Error::Data(format!("episode {id}: frame {t} has no action")));
                }
                r.all_vectors()
            } else {
                None
            };
            let ep = &wanted[&id];
            let clip = Clip {
                episode_id: id.clone(),
                encoding: ep.frame_encoding,
                width: ep.width as u32,
                height: ep.height as u32,
                frames: r.images,
                timestamps: r.timestamp_ns,
                actions,
            };
            Ok((id, clip))
        })
        .collect()
}
