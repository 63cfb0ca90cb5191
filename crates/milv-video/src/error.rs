//! The crate's single error type.

use std::path::PathBuf;

/// Everything that can go wrong while opening, decoding or encoding.
///
/// Messages name the offending path last so they read well in logs that
/// process thousands of files.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// FFmpeg could not be initialised.
    #[error("cannot initialise FFmpeg: {msg}")]
    Init { msg: String },

    /// A file or folder could not be read or written.
    #[error("i/o error ({source}) on {}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// FFmpeg could not open the file as media (not a media file, empty, truncated header).
    #[error("cannot open as video ({msg}): {}", .path.display())]
    Open { path: PathBuf, msg: String },

    /// FFmpeg's C API takes UTF-8 paths without NUL bytes; anything else is rejected up front.
    #[error("path is not valid UTF-8 or contains a NUL byte: {}", .path.display())]
    UnsupportedPath { path: PathBuf },

    /// The container holds no video stream.
    #[error("no video stream in {}", .path.display())]
    NoVideoStream { path: PathBuf },

    /// No decoder for the codec, or the decoder refused to open.
    #[error("cannot open decoder ({msg}) for {}", .path.display())]
    Decoder { path: PathBuf, msg: String },

    /// Decoding or pixel conversion failed mid-stream.
    #[error("decode error ({msg}) in {}", .path.display())]
    Decode { path: PathBuf, msg: String },

    /// The stream ended without a single decodable frame.
    #[error("no decodable frames in {}", .path.display())]
    NoFrames { path: PathBuf },

    /// The frame size changed mid-stream and no resize was requested.
    #[error(
        "frame {index} is {}x{} but earlier frames are {}x{} (request a resize to allow this) in {}",
        .got.0, .got.1, .expected.0, .expected.1, .path.display()
    )]
    SizeChanged {
        path: PathBuf,
        index: u64,
        expected: (u32, u32),
        got: (u32, u32),
    },

    /// An image in a frame folder could not be decoded.
    #[error("cannot decode image ({msg}): {}", .path.display())]
    Image { path: PathBuf, msg: String },

    /// A frame folder was given without a frame rate.
    #[error("a frame rate is required to read the image folder {}", .path.display())]
    FpsRequired { path: PathBuf },

    /// A frame folder holds no PNG/JPEG files.
    #[error("no numbered .png/.jpg/.jpeg frames in {}", .path.display())]
    NoFrameFiles { path: PathBuf },

    /// A frame file name has no digits to order it by.
    #[error("no frame number in the file name of {}", .path.display())]
    NoFrameNumber { path: PathBuf },

    /// Two frame files carry the same number, so their order is ambiguous.
    #[error("frame number {number} is also used by {} in {}", .other.display(), .path.display())]
    DuplicateFrameNumber {
        path: PathBuf,
        other: PathBuf,
        number: u128,
    },

    /// The output extension maps to no supported container.
    #[error("unsupported container extension (use mp4, mkv, webm, avi or mov) for {}", .path.display())]
    UnsupportedContainer { path: PathBuf },

    /// Encoding or muxing failed.
    #[error("encode error ({msg}) for {}", .path.display())]
    Encode { path: PathBuf, msg: String },

    /// A caller-supplied value is out of range or malformed.
    #[error("invalid argument: {msg}")]
    InvalidArgument { msg: String },
}

impl Error {
    pub(crate) fn invalid(msg: impl Into<String>) -> Self {
        Error::InvalidArgument { msg: msg.into() }
    }
}
