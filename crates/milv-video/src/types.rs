//! Plain data types shared by all readers: frames, resize requests, options, stream info.

use std::fmt;
use std::str::FromStr;

use crate::Error;

/// One decoded frame as packed RGB24.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// RGB24, row-major, no row padding: `len == width * height * 3`.
    pub data: Vec<u8>,
    /// Presentation time in nanoseconds; the first source frame is 0.
    pub pts_ns: i64,
    /// Index of the decoded source frame (0-based, presentation order) this output came from.
    /// With fps resampling, repeated frames share an index and dropped indices are skipped.
    pub source_index: u64,
}

/// How to reconcile a source aspect ratio with a different target aspect ratio.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AspectPolicy {
    /// Scale to the exact target size, distorting the aspect ratio.
    Stretch,
    /// Scale to fit inside the target, centre, fill the borders black.
    Pad,
    /// Scale to cover the target, centre-crop the overflow.
    Crop,
}

impl FromStr for AspectPolicy {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self, Error> {
        match s.trim().to_ascii_lowercase().as_str() {
            "stretch" => Ok(AspectPolicy::Stretch),
            "pad" => Ok(AspectPolicy::Pad),
            "crop" => Ok(AspectPolicy::Crop),
            other => Err(Error::invalid(format!(
                "aspect policy must be stretch, pad or crop, got {other:?}"
            ))),
        }
    }
}

impl fmt::Display for AspectPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            AspectPolicy::Stretch => "stretch",
            AspectPolicy::Pad => "pad",
            AspectPolicy::Crop => "crop",
        })
    }
}

/// A requested output size and how to get there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resize {
    pub width: u32,
    pub height: u32,
    pub policy: AspectPolicy,
}

/// Larger targets are almost certainly typos and would allocate gigabytes per frame.
const MAX_DIM: u32 = 16384;

impl Resize {
    /// Checks the size is non-zero and sane.
    pub fn validate(&self) -> Result<(), Error> {
        if self.width == 0 || self.height == 0 || self.width > MAX_DIM || self.height > MAX_DIM {
            return Err(Error::invalid(format!(
                "resize target must be between 1x1 and {MAX_DIM}x{MAX_DIM}, got {}x{}",
                self.width, self.height
            )));
        }
        Ok(())
    }
}

impl FromStr for Resize {
    type Err = Error;

    /// Parses `"WxH"` (policy [`AspectPolicy::Pad`]) or `"WxH:policy"`.
    fn from_str(s: &str) -> Result<Self, Error> {
        let s = s.trim();
        let bad = || {
            Error::invalid(format!(
                "resize must look like 224x224 or 224x224:crop, got {s:?}"
            ))
        };
        let (size, policy) = match s.split_once(':') {
            Some((size, policy)) => (size, policy.parse()?),
            None => (s, AspectPolicy::Pad),
        };
        let (w, h) = size.split_once(['x', 'X']).ok_or_else(bad)?;
        let resize = Resize {
            width: w.trim().parse().map_err(|_| bad())?,
            height: h.trim().parse().map_err(|_| bad())?,
            policy,
        };
        resize.validate()?;
        Ok(resize)
    }
}

impl fmt::Display for Resize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}:{}", self.width, self.height, self.policy)
    }
}

/// Options common to video files and frame folders.
#[derive(Clone, Debug, Default)]
pub struct DecodeOptions {
    /// Output size; `None` keeps the source size (which must then stay constant).
    pub resize: Option<Resize>,
    /// Resample to this frame rate by dropping/repeating frames; `None` keeps every source frame.
    pub fps: Option<f64>,
    /// Decoder threads; 0 lets FFmpeg choose.
    pub threads: usize,
}

impl DecodeOptions {
    pub(crate) fn validate(&self) -> Result<(), Error> {
        if let Some(r) = &self.resize {
            r.validate()?;
        }
        if let Some(fps) = self.fps {
            check_fps(fps)?;
        }
        Ok(())
    }
}

pub(crate) fn check_fps(fps: f64) -> Result<(), Error> {
    if fps.is_finite() && fps > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "fps must be a positive number, got {fps}"
        )))
    }
}

/// What is known about a source before decoding it.
#[derive(Clone, Debug)]
pub struct VideoInfo {
    /// Source size (before any resize).
    pub width: u32,
    pub height: u32,
    /// Source average frame rate, or 0 if unknown (not the resampled rate).
    pub fps: f64,
    pub duration_ns: Option<i64>,
    /// Source frame count as stored or estimated from duration × fps; may be off.
    pub frames_hint: Option<u64>,
    /// Frame count the container itself declares (MP4's sample count), if any: decoding
    /// fewer frames than this means the file is truncated or corrupt.
    pub frames_declared: Option<u64>,
    /// Codec name as FFmpeg spells it (`h264`, `vp9`, `av1`, ...) or `png`/`jpeg` for folders.
    pub codec: String,
    /// Demuxer name (`mov,mp4,m4a,3gp,3g2,mj2`, `matroska,webm`, ...) or `image_folder`.
    pub container: String,
}
