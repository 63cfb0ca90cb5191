//! Frames as they come out of a codec: what a learner trained on encoded video sees.

use std::path::Path;

use crate::{Codec, DecodeOptions, Error, VideoReader, VideoWriter};

/// Encodes `frames` (RGB24, `width`×`height`) as one stream at `fps` into the file `path`,
/// decodes it back and removes the file: the same frames with the codec's artefacts
/// (chroma subsampling, quantisation). `path`'s extension picks the container.
pub fn roundtrip(
    path: &Path,
    frames: &[Vec<u8>],
    width: u32,
    height: u32,
    fps: u32,
    codec: Codec,
) -> Result<Vec<Vec<u8>>, Error> {
    let mut w = VideoWriter::create(path, width, height, fps, codec)?;
    for f in frames {
        w.write(f)?;
    }
    w.finish()?;
    let out = VideoReader::open(path, &DecodeOptions::default())
        .and_then(|r| r.map(|f| f.map(|f| f.data)).collect::<Result<Vec<_>, Error>>());
    // The file is scratch: a failed decode is the error worth reporting, not the removal.
    let _ = std::fs::remove_file(path);
    let out = out?;
    if out.len() != frames.len() {
        return Err(Error::Encode {
            path: path.to_path_buf(),
            msg: format!("{} frames written, {} decoded back", frames.len(), out.len()),
        });
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// H.264 at CRF 18 keeps a smooth image close but not exact; the count is kept.
    #[test]
    fn a_roundtrip_keeps_every_frame_close_but_not_bit_exact() {
        let (w, h) = (32u32, 32u32);
        let frames: Vec<Vec<u8>> = (0..5u32)
            .map(|t| {
                (0..w * h)
                    .flat_map(|i| {
                        let (x, y) = (i % w, i / w);
                        // Smooth gradients (no wrap-around edges) moving with t.
                        [(x * 6 + t) as u8, (y * 6) as u8, ((x + y) * 3) as u8]
                    })
                    .collect()
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rt.mp4");
        let out = roundtrip(&path, &frames, w, h, 10, Codec::H264).unwrap();
        assert_eq!(out.len(), frames.len());
        assert!(!path.exists(), "the scratch file is removed");
        let mad = |a: &[u8], b: &[u8]| {
            a.iter()
                .zip(b)
                .map(|(&x, &y)| (f64::from(x) - f64::from(y)).abs())
                .sum::<f64>()
                / a.len() as f64
        };
        for (a, b) in frames.iter().zip(&out) {
            assert_eq!(a.len(), b.len());
            let d = mad(a, b);
            assert!(d > 0.0 && d < 8.0, "mean |difference| {d}");
        }
    }
}
