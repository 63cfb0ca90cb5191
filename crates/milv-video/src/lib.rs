//! MILV video I/O: turns robot-learning videos and frame folders into RGB24 frames with
//! real timestamps. It knows nothing about tables.
//!
//! Map of the crate:
//!
//! - [`VideoReader`] (`reader.rs`): streams any video FFmpeg can decode (mp4/H.264, mkv,
//!   webm/VP9, AV1, avi, ...) as [`Frame`]s; timestamps come from the stream, relative to
//!   the first frame.
//! - [`FrameDirReader`] and [`list_numbered_frames`] (`frames_dir.rs`): folders of numbered
//!   PNG/JPEG frames at a given frame rate, decoded lazily with the `image` crate.
//! - [`open_frames`] picks one of the two for a path and returns a boxed [`FrameSource`].
//! - [`Resize`], [`AspectPolicy`] and [`fit_plan`] (`fit.rs`): output size and the
//!   stretch/pad/crop arithmetic shared by both readers.
//! - [`Resample`] (`resample.rs`): fps resampling as an iterator adapter (drop/repeat frames).
//! - [`VideoWriter`] (`writer.rs`): encodes RGB24 frames to H.264/VP9/AV1/MJPEG, for samples
//!   and tests.
//! - [`roundtrip`] (`roundtrip.rs`): frames through a codec and back (what a learner trained
//!   on encoded video sees at evaluation).
//! - `scaler.rs`: a per-thread cache of swscale contexts (they are not `Send`; readers are).
//!
//! Colour conversion uses swscale's defaults (BT.601 matrix, range from the pixel format).

use std::path::Path;
use std::sync::OnceLock;

use ffmpeg_next as ffmpeg;

mod error;
mod fit;
mod frames_dir;
mod reader;
mod resample;
mod roundtrip;
mod scaler;
mod types;
mod writer;

#[cfg(test)]
mod tests;

pub use error::Error;
pub use fit::{Plan, fit_plan};
pub use frames_dir::{FrameDirReader, list_numbered_frames, resize_rgb};
pub use reader::VideoReader;
pub use resample::Resample;
pub use roundtrip::roundtrip;
pub use types::{AspectPolicy, DecodeOptions, Frame, Resize, VideoInfo};
pub use writer::{Codec, VideoWriter};

/// Initialises FFmpeg once per process and lowers its log level to errors only.
///
/// Readers and the writer call this themselves; calling it again is cheap.
pub fn init() -> Result<(), Error> {
    static INIT: OnceLock<Result<(), String>> = OnceLock::new();
    INIT.get_or_init(|| {
        ffmpeg::init().map_err(|e| e.to_string())?;
        ffmpeg::log::set_level(ffmpeg::log::Level::Error);
        Ok(())
    })
    .clone()
    .map_err(|msg| Error::Init { msg })
}

/// A stream of frames with known source properties: a video file or a frame folder.
pub trait FrameSource: Iterator<Item = Result<Frame, Error>> + Send {
    fn info(&self) -> &VideoInfo;
}

/// Opens `path` as a frame source: a directory becomes a [`FrameDirReader`] at `fps`
/// (required: [`Error::FpsRequired`] otherwise), a file a [`VideoReader`] (`fps` is ignored;
/// the file's own timestamps are used; resample with `opts.fps`).
pub fn open_frames(
    path: &Path,
    fps: Option<f64>,
    opts: &DecodeOptions,
) -> Result<Box<dyn FrameSource>, Error> {
    let meta = std::fs::metadata(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if meta.is_dir() {
        let fps = fps.ok_or_else(|| Error::FpsRequired {
            path: path.to_path_buf(),
        })?;
        Ok(Box::new(FrameDirReader::open(path, fps, opts)?))
    } else {
        Ok(Box::new(VideoReader::open(path, opts)?))
    }
}
