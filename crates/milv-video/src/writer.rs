//! A small encoder for writing sample and test videos from RGB24 frames.

use std::path::{Path, PathBuf};

use ffmpeg::codec::Context as CodecContext;
use ffmpeg::format::Pixel;
use ffmpeg::{Dictionary, Packet, Rational, codec, encoder, format, frame};
use ffmpeg_next as ffmpeg;

use crate::Error;
use crate::reader::ffmpeg_path;
use crate::scaler::{self, Key};

/// Video codecs [`VideoWriter`] can produce.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// libx264, preset veryfast, CRF 18, yuv420p.
    H264,
    /// libvpx-vp9, realtime, CRF 20, yuv420p.
    Vp9,
    /// libaom-av1 (realtime, fastest), falling back to libsvtav1; yuv420p.
    ///
    /// libaom is preferred over SVT-AV1 here: SVT-AV1 (Debian 12's 1.4) prints a banner
    /// to stderr that cannot be silenced without `SVT_LOG` (setting env vars needs `unsafe`
    /// in edition 2024) and rejects frames smaller than 64×64.
    Av1,
    /// LeRobot's AV1 settings: libsvtav1 preset 12, CRF 30 (yuv420p), falling back to
    /// libaom-av1. SVT-AV1 needs frames of at least 64×64 and logs a banner unless the
    /// process sets `SVT_LOG=1` before the first encoder opens.
    SvtAv1,
    /// FFmpeg's mjpeg at qscale 2, yuvj420p (best in `.avi`).
    Mjpeg,
}

impl Codec {
    /// Encoder names to try in order, each with its private options.
    fn encoders(self) -> &'static [(&'static str, &'static [(&'static str, &'static str)])] {
        match self {
            Codec::H264 => &[("libx264", &[("preset", "veryfast"), ("crf", "18")])],
            Codec::Vp9 => &[(
                "libvpx-vp9",
                &[
                    ("deadline", "realtime"),
                    ("cpu-used", "8"),
                    ("crf", "20"),
                    ("b", "0"),
                ],
            )],
            Codec::Av1 => &[
                (
                    "libaom-av1",
                    &[
                        ("usage", "realtime"),
                        ("cpu-used", "8"),
                        ("crf", "20"),
                        ("b", "0"),
                    ],
                ),
                ("libsvtav1", &[("preset", "10"), ("crf", "25")]),
            ],
            Codec::SvtAv1 => &[
                ("libsvtav1", &[("preset", "12"), ("crf", "30")]),
                (
                    "libaom-av1",
                    &[
                        ("usage", "realtime"),
                        ("cpu-used", "8"),
                        ("crf", "30"),
                        ("b", "0"),
                    ],
                ),
            ],
            Codec::Mjpeg => &[("mjpeg", &[])],
        }
    }

    fn pixel_format(self) -> Pixel {
        match self {
            // Full-range JPEG colour is what mjpeg decoders expect.
            Codec::Mjpeg => Pixel::YUVJ420P,
            _ => Pixel::YUV420P,
        }
    }
}

/// Muxer name for an output extension.
fn container_for(path: &Path) -> Option<&'static str> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    Some(match ext.as_str() {
        "mp4" => "mp4",
        "mkv" => "matroska",
        "webm" => "webm",
        "avi" => "avi",
        "mov" => "mov",
        _ => return None,
    })
}

/// Encodes RGB24 frames at a constant frame rate into a file; the container comes from
/// the extension (mp4, mkv, webm, avi, mov).
///
/// Frame `i` gets timestamp `i / fps`. Call [`VideoWriter::finish`] to flush the encoder and
/// write the trailer; a writer dropped without it leaves an unplayable file.
pub struct VideoWriter {
    path: PathBuf,
    octx: format::context::Output,
    encoder: encoder::Video,
    stream_index: usize,
    encoder_tb: Rational,
    stream_tb: Rational,
    width: u32,
    height: u32,
    pixel_format: Pixel,
    /// RGB staging frame, reused (swscale only reads it synchronously).
    rgb: frame::Video,
    next_pts: i64,
}

impl VideoWriter {
    /// Creates `path` and writes the container header.
    pub fn create(path: &Path, width: u32, height: u32, fps: u32, codec: Codec) -> Result<Self, Error> {
        Self::create_with_gop(path, width, height, fps, codec, None)
    }

    /// [`VideoWriter::create`] with a keyframe every `gop` frames (`None`: the encoder's
    /// default). Short GOPs make random access cheap: a reader seeking to frame t decodes
    /// from the keyframe before it (LeRobot writes `g=2`).
    pub fn create_with_gop(
        path: &Path,
        width: u32,
        height: u32,
        fps: u32,
        codec: Codec,
        gop: Option<u32>,
    ) -> Result<Self, Error> {
        crate::init()?;
        let enc_err = |msg: String| Error::Encode {
            path: path.to_path_buf(),
            msg,
        };
        if width == 0 || height == 0 || fps == 0 {
            return Err(enc_err(format!(
                "width, height and fps must be positive, got {width}x{height} at {fps} fps"
            )));
        }
        let fps_i32 = i32::try_from(fps).map_err(|_| enc_err(format!("fps {fps} is too large")))?;
        let path_str = ffmpeg_path(path)?;
        let container = container_for(path).ok_or_else(|| Error::UnsupportedContainer {
            path: path.to_path_buf(),
        })?;

        let (enc_codec, options) = codec
            .encoders()
            .iter()
            .find_map(|(name, opts)| encoder::find_by_name(name).map(|c| (c, *opts)))
            .ok_or_else(|| {
                let names: Vec<&str> = codec.encoders().iter().map(|(n, _)| *n).collect();
                enc_err(format!("no encoder available (tried {})", names.join(", ")))
            })?;

        let mut octx = format::output_as(path_str, container).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            source: std::io::Error::other(e.to_string()),
        })?;
        let global_header = octx.format().flags().contains(format::Flags::GLOBAL_HEADER);

        let pixel_format = codec.pixel_format();
        let encoder_tb = Rational::new(1, fps_i32);
        let mut enc = CodecContext::new_with_codec(enc_codec)
            .encoder()
            .video()
            .map_err(|e| enc_err(e.to_string()))?;
        enc.set_width(width);
        enc.set_height(height);
        enc.set_format(pixel_format);
        enc.set_time_base(encoder_tb);
        enc.set_frame_rate(Some(Rational::new(fps_i32, 1)));
        if let Some(g) = gop {
            enc.set_gop(g.max(1));
        }
        let mut flags = codec::Flags::empty();
        if global_header {
            // MP4/MKV want codec headers in extradata rather than in-band.
            flags |= codec::Flags::GLOBAL_HEADER;
        }
        if codec == Codec::Mjpeg {
            // Fixed quantiser (like `-q:v 2`): the default bitrate is far too low for tests.
            flags |= codec::Flags::QSCALE;
            enc.set_global_quality(2 * 118); // FF_QP2LAMBDA = 118
        }
        enc.set_flags(flags);
        let mut dict = Dictionary::new();
        for (k, v) in options {
            dict.set(k, v);
        }
        let encoder = enc
            .open_as_with(enc_codec, dict)
            .map_err(|e| enc_err(format!("cannot open encoder {}: {e}", enc_codec.name())))?;

        let stream_index = {
            let mut ost = octx.add_stream(enc_codec).map_err(|e| enc_err(e.to_string()))?;
            ost.set_parameters(&encoder);
            ost.set_time_base(encoder_tb);
            ost.set_avg_frame_rate(Rational::new(fps_i32, 1));
            ost.index()
        };
        octx.write_header()
            .map_err(|e| enc_err(format!("cannot write header: {e}")))?;
        // The muxer may have picked its own time base (e.g. 1/1000 for Matroska).
        let stream_tb = octx
            .stream(stream_index)
            .map(|s| s.time_base())
            .unwrap_or(encoder_tb);

        Ok(VideoWriter {
            path: path.to_path_buf(),
            octx,
            encoder,
            stream_index,
            encoder_tb,
            stream_tb,
            width,
            height,
            pixel_format,
            rgb: frame::Video::new(Pixel::RGB24, width, height),
            next_pts: 0,
        })
    }

    /// FFmpeg's name of the encoder in use (e.g. `libaom-av1`).
    pub fn encoder_name(&self) -> String {
        self.encoder
            .codec()
            .map(|c| c.name().to_string())
            .unwrap_or_default()
    }

    fn enc_err(&self, msg: impl Into<String>) -> Error {
        Error::Encode {
            path: self.path.clone(),
            msg: msg.into(),
        }
    }

    /// Encodes one frame of packed RGB24 (`width * height * 3` bytes, no row padding).
    pub fn write(&mut self, rgb: &[u8]) -> Result<(), Error> {
        let row = self.width as usize * 3;
        let expected = row * self.height as usize;
        if rgb.len() != expected {
            return Err(self.enc_err(format!(
                "frame has {} bytes, expected {expected} for {}x{} RGB24",
                rgb.len(),
                self.width,
                self.height
            )));
        }
        if self.rgb.planes() == 0 {
            return Err(self.enc_err("could not allocate the RGB frame"));
        }
        let stride = self.rgb.stride(0);
        let dst = self.rgb.data_mut(0);
        for (y, src_row) in rgb.chunks_exact(row).enumerate() {
            let start = y * stride;
            match dst.get_mut(start..start + row) {
                Some(d) => d.copy_from_slice(src_row),
                None => return Err(self.enc_err("RGB frame buffer is smaller than expected")),
            }
        }

        // A fresh YUV frame each time: the encoder may keep a reference to the last one.
        let mut yuv = frame::Video::empty();
        let key = Key {
            src_format: Pixel::RGB24,
            src_w: self.width,
            src_h: self.height,
            dst_format: self.pixel_format,
            dst_w: self.width,
            dst_h: self.height,
        };
        scaler::scale(key, &self.rgb, &mut yuv)
            .map_err(|e| self.enc_err(format!("cannot convert RGB24 to YUV: {e}")))?;
        yuv.set_pts(Some(self.next_pts));
        self.next_pts += 1;
        self.encoder
            .send_frame(&yuv)
            .map_err(|e| self.enc_err(e.to_string()))?;
        self.drain()
    }

    /// Moves every packet the encoder has ready into the muxer.
    fn drain(&mut self) -> Result<(), Error> {
        let mut packet = Packet::empty();
        loop {
            match self.encoder.receive_packet(&mut packet) {
                Ok(()) => {}
                Err(ffmpeg::Error::Other {
                    errno: ffmpeg::error::EAGAIN,
                })
                | Err(ffmpeg::Error::Eof) => return Ok(()),
                Err(e) => return Err(self.enc_err(e.to_string())),
            }
            packet.set_stream(self.stream_index);
            // libx264 leaves durations at 0, which makes MP4s play one frame short.
            if packet.duration() <= 0 {
                packet.set_duration(1);
            }
            packet.rescale_ts(self.encoder_tb, self.stream_tb);
            packet
                .write_interleaved(&mut self.octx)
                .map_err(|e| self.enc_err(format!("cannot write packet: {e}")))?;
        }
    }

    /// Flushes the encoder and writes the container trailer.
    pub fn finish(mut self) -> Result<(), Error> {
        self.encoder.send_eof().map_err(|e| self.enc_err(e.to_string()))?;
        self.drain()?;
        self.octx
            .write_trailer()
            .map_err(|e| self.enc_err(format!("cannot write trailer: {e}")))
    }
}
