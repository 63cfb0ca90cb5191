//! How frames are stored in the `image` column: PNG (lossless, default), JPEG, or raw RGB24.

use std::io::Cursor;

use image::ImageEncoder as _;

/// Encoding of the `image` column of an episode's frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FrameEncoding {
    #[default]
    Png,
    Jpeg {
        quality: u8,
    },
    Raw,
}

impl FrameEncoding {
    pub fn name(self) -> &'static str {
        match self {
            FrameEncoding::Png => "png",
            FrameEncoding::Jpeg { .. } => "jpeg",
            FrameEncoding::Raw => "raw",
        }
    }

    /// Parses a stored name (`jpeg` gets the default quality, 90).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "png" => Some(FrameEncoding::Png),
            "jpeg" | "jpg" => Some(FrameEncoding::Jpeg { quality: 90 }),
            "raw" => Some(FrameEncoding::Raw),
            _ => None,
        }
    }
}

/// Frame codec failures.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    #[error("{0}")]
    Image(#[from] image::ImageError),
    #[error("decoded to {got_w}x{got_h}, expected {want_w}x{want_h}")]
    Size {
        got_w: u32,
        got_h: u32,
        want_w: u32,
        want_h: u32,
    },
    #[error("raw frame has {got} bytes, expected {want}")]
    RawLength { got: usize, want: usize },
}

/// Encodes one packed RGB24 frame, appending to `out`.
pub fn encode(
    enc: FrameEncoding,
    rgb: &[u8],
    width: u32,
    height: u32,
    out: &mut Vec<u8>,
) -> Result<(), CodecError> {
    let want = width as usize * height as usize * 3;
    if rgb.len() != want {
        return Err(CodecError::RawLength { got: rgb.len(), want });
    }
    match enc {
        FrameEncoding::Raw => out.extend_from_slice(rgb),
        FrameEncoding::Png => {
            // Fast deflate + adaptive filter: ingest is usually bound by this encoder.
            image::codecs::png::PngEncoder::new_with_quality(
                Cursor::new(out),
                image::codecs::png::CompressionType::Fast,
                image::codecs::png::FilterType::Adaptive,
            )
            .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)?;
        }
        FrameEncoding::Jpeg { quality } => {
            image::codecs::jpeg::JpegEncoder::new_with_quality(Cursor::new(out), quality).write_image(
                rgb,
                width,
                height,
                image::ExtendedColorType::Rgb8,
            )?;
        }
    }
    Ok(())
}

/// Decodes a stored frame to packed RGB24, checking its size.
pub fn decode(enc: FrameEncoding, bytes: &[u8], width: u32, height: u32) -> Result<Vec<u8>, CodecError> {
    let want = width as usize * height as usize * 3;
    if enc == FrameEncoding::Raw {
        if bytes.len() != want {
            return Err(CodecError::RawLength {
                got: bytes.len(),
                want,
            });
        }
        return Ok(bytes.to_vec());
    }
    let format = match enc {
        FrameEncoding::Png => image::ImageFormat::Png,
        _ => image::ImageFormat::Jpeg,
    };
    let img = image::load_from_memory_with_format(bytes, format)?.into_rgb8();
    if img.width() != width || img.height() != height {
        return Err(CodecError::Size {
            got_w: img.width(),
            got_h: img.height(),
            want_w: width,
            want_h: height,
        });
    }
    Ok(img.into_raw())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32) -> Vec<u8> {
        (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect()
    }

    #[test]
    fn png_and_raw_are_lossless() {
        let rgb = gradient(13, 7);
        for enc in [FrameEncoding::Png, FrameEncoding::Raw] {
            let mut out = Vec::new();
            encode(enc, &rgb, 13, 7, &mut out).unwrap();
            assert_eq!(decode(enc, &out, 13, 7).unwrap(), rgb);
        }
    }

    #[test]
    fn jpeg_is_close_and_sizes_are_checked() {
        let rgb = vec![128u8; 16 * 16 * 3];
        let enc = FrameEncoding::Jpeg { quality: 95 };
        let mut out = Vec::new();
        encode(enc, &rgb, 16, 16, &mut out).unwrap();
        let back = decode(enc, &out, 16, 16).unwrap();
        assert!(back.iter().all(|&v| v.abs_diff(128) <= 2));
        assert!(matches!(decode(enc, &out, 8, 16), Err(CodecError::Size { .. })));
        assert!(decode(FrameEncoding::Png, b"not a png", 1, 1).is_err());
        assert!(encode(FrameEncoding::Png, &rgb, 15, 16, &mut out).is_err());
    }
}
