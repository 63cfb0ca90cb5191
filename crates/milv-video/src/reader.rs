//! Streaming video decoding with FFmpeg to RGB24 frames with real timestamps.

use std::path::{Path, PathBuf};

use ffmpeg::codec::Context as CodecContext;
use ffmpeg::format::Pixel;
use ffmpeg::{Dictionary, Packet, decoder, format, frame, media};
use ffmpeg_next as ffmpeg;

use crate::fit::{compose, plan_for};
use crate::resample::MaybeResample;
use crate::scaler::{self, Key};
use crate::{DecodeOptions, Error, Frame, FrameSource, Resize, VideoInfo};

/// Decodes a video file frame by frame.
///
/// Holds O(1) frames whatever the video length: one decoded FFmpeg frame, one RGB scratch
/// frame (both reused), plus at most two output frames when resampling.
///
/// Errors end the iteration: after an `Err` item, `next()` returns `None`.
/// A stream that ends without any frame yields [`Error::NoFrames`] as its only item.
pub struct VideoReader {
    frames: MaybeResample<Decoder>,
}

impl VideoReader {
    /// Opens `path` and prepares its best video stream for decoding.
    pub fn open(path: &Path, opts: &DecodeOptions) -> Result<Self, Error> {
        let decoder = Decoder::open(path, opts)?;
        Ok(VideoReader {
            frames: MaybeResample::new(decoder, opts.fps)?,
        })
    }

    /// Source properties, known before decoding.
    pub fn info(&self) -> &VideoInfo {
        &self.frames.inner().info
    }

    /// Positions the decoder at the last keyframe at or before `ns` (stream time) and
    /// switches to absolute timestamps: from here on `pts_ns` is the frame's own
    /// presentation time in the stream (pts × time base), not relative to the first frame.
    /// For reading one episode out of a file that holds many back to back (LeRobot v3):
    /// frames before `ns` still come out, the caller skips them. Only before the first
    /// frame and without resampling.
    pub fn seek_to(&mut self, ns: i64) -> Result<(), Error> {
        match &mut self.frames {
            MaybeResample::Plain(d) => d.seek_to(ns),
            MaybeResample::Resampled(_) => {
                Err(Error::invalid("seek_to cannot be combined with fps resampling"))
            }
        }
    }
}

impl Iterator for VideoReader {
    type Item = Result<Frame, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        self.frames.next()
    }
}

impl FrameSource for VideoReader {
    fn info(&self) -> &VideoInfo {
        VideoReader::info(self)
    }
}

/// FFmpeg's C API takes paths as C strings; ffmpeg-next panics on non-UTF-8 or NUL, so check first.
pub(crate) fn ffmpeg_path(path: &Path) -> Result<&str, Error> {
    match path.to_str() {
        Some(s) if !s.contains('\0') => Ok(s),
        _ => Err(Error::UnsupportedPath {
            path: path.to_path_buf(),
        }),
    }
}

/// The decoding state machine, before optional resampling.
pub(crate) struct Decoder {
    path: PathBuf,
    input: format::context::Input,
    stream_index: usize,
    decoder: decoder::Video,
    /// Stream time base as (num, den); den > 0 and num > 0, or `None` if unusable.
    time_base: Option<(i128, i128)>,
    decoded: frame::Video,
    rgb: frame::Video,
    resize: Option<Resize>,
    /// Size of the first decoded frame; later frames must match unless resizing.
    expected: Option<(u32, u32)>,
    /// (stream timestamp, ns) of the first timestamped frame, the zero point.
    origin: Option<(i64, i64)>,
    last_ns: i64,
    /// Step used for frames without any timestamp.
    fallback_step_ns: i64,
    /// Frames output so far.
    index: u64,
    draining: bool,
    done: bool,
    /// A read error that cut the input short; reported after the frames before it.
    read_error: Option<String>,
    info: VideoInfo,
}

/// Consecutive decoder errors tolerated before giving up (a broken stream must not spin).
const MAX_CONSECUTIVE_ERRORS: u32 = 1000;

impl Decoder {
    fn open(path: &Path, opts: &DecodeOptions) -> Result<Self, Error> {
        crate::init()?;
        opts.validate()?;
        let path_str = ffmpeg_path(path)?;
        let meta = std::fs::metadata(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        if meta.is_dir() {
            return Err(Error::Open {
                path: path.to_path_buf(),
                msg: "is a directory".into(),
            });
        }
        let input = format::input(path_str).map_err(|e| Error::Open {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
        let decoder_err = |msg: String| Error::Decoder {
            path: path.to_path_buf(),
            msg,
        };

        let stream = input
            .streams()
            .best(media::Type::Video)
            .ok_or_else(|| Error::NoVideoStream {
                path: path.to_path_buf(),
            })?;
        let stream_index = stream.index();
        let tb = stream.time_base();
        let time_base = (tb.numerator() > 0 && tb.denominator() > 0)
            .then(|| (i128::from(tb.numerator()), i128::from(tb.denominator())));
        let rate = stream.avg_frame_rate();
        let fps = if rate.numerator() > 0 && rate.denominator() > 0 {
            f64::from(rate)
        } else {
            0.0
        };
        let duration_ns = match (stream.duration(), time_base) {
            (d, Some((num, den))) if d > 0 => Some(ticks_to_ns(i128::from(d), num, den)),
            // Matroska and others only know the container duration (in AV_TIME_BASE = µs).
            _ => (input.duration() > 0).then(|| input.duration().saturating_mul(1000)),
        };
        let frames_declared = (stream.frames() > 0).then(|| stream.frames() as u64);
        let frames_hint = match stream.frames() {
            n if n > 0 => Some(n as u64),
            _ => duration_ns
                .filter(|_| fps > 0.0)
                .map(|d| (d as f64 * fps / 1e9).round() as u64),
        };
        let codec_id = stream.parameters().id();

        let ctx =
            CodecContext::from_parameters(stream.parameters()).map_err(|e| decoder_err(e.to_string()))?;
        let mut dec = ctx.decoder();
        // Lets the decoder compute best_effort_timestamp in the stream's time base.
        dec.set_packet_time_base(tb);
        let codec = decoder::find(codec_id)
            .ok_or_else(|| decoder_err(format!("no decoder for codec {}", codec_id.name())))?;
        let mut dict = Dictionary::new();
        // "threads" via AVOption keeps the codec's default thread_type (frame + slice).
        let threads = match opts.threads {
            0 => "auto".to_string(),
            n => n.to_string(),
        };
        dict.set("threads", &threads);
        let decoder = dec
            .open_as_with(codec, dict)
            .and_then(|d| d.video())
            .map_err(|e| decoder_err(e.to_string()))?;

        let info = VideoInfo {
            width: decoder.width(),
            height: decoder.height(),
            fps,
            duration_ns,
            frames_hint,
            frames_declared,
            codec: codec_id.name().to_string(),
            container: input.format().name().to_string(),
        };
        let fallback_fps = if fps > 0.0 { fps } else { 25.0 };
        Ok(Decoder {
            path: path.to_path_buf(),
            input,
            stream_index,
            decoder,
            time_base,
            decoded: frame::Video::empty(),
            rgb: frame::Video::empty(),
            resize: opts.resize,
            expected: None,
            origin: None,
            last_ns: 0,
            fallback_step_ns: (1e9 / fallback_fps).round() as i64,
            index: 0,
            draining: false,
            done: false,
            read_error: None,
            info,
        })
    }

    fn decode_err(&self, msg: impl Into<String>) -> Error {
        Error::Decode {
            path: self.path.clone(),
            msg: msg.into(),
        }
    }

    fn seek_to(&mut self, ns: i64) -> Result<(), Error> {
        if self.index > 0 {
            return Err(Error::invalid("seek_to must come before the first frame"));
        }
        // Absolute stream time: tick 0 is 0 ns.
        self.origin = Some((0, 0));
        if ns <= 0 {
            return Ok(());
        }
        if self.time_base.is_none() {
            return Err(self.decode_err("cannot seek: the stream has no time base"));
        }
        // AV_TIME_BASE (µs) on the default stream, max_ts = us (ffmpeg-next passes the
        // range end through as is); 1 ms early, so rounding can never land
        // past the keyframe the target needs.
        let us = (ns / 1000 - 1000).max(0);
        self.input
            .seek(us, ..us)
            .map_err(|e| self.decode_err(format!("cannot seek to {:.6} s: {e}", ns as f64 / 1e9)))?;
        self.decoder.flush();
        Ok(())
    }

    /// End of stream: a read error if one cut the input short, NoFrames if nothing decoded.
    fn end(&mut self) -> Option<Result<Frame, Error>> {
        self.done = true;
        if let Some(msg) = self.read_error.take() {
            return Some(Err(self.decode_err(msg)));
        }
        (self.index == 0).then(|| {
            Err(Error::NoFrames {
                path: self.path.clone(),
            })
        })
    }

    /// Reads packets until one for our stream is accepted by the decoder, or signals EOF.
    fn feed(&mut self) {
        loop {
            let mut packet = Packet::empty();
            match packet.read(&mut self.input) {
                // A rejected (corrupt) packet is skipped like the ffmpeg CLI does;
                // if nothing decodes at all the caller gets NoFrames.
                Ok(()) => {
                    if packet.stream() == self.stream_index && self.decoder.send_packet(&packet).is_ok() {
                        return;
                    }
                }
                Err(ffmpeg::Error::Eof) => break,
                // The demuxer resyncs past corrupt data; it is not a sticky error.
                Err(ffmpeg::Error::InvalidData) => {}
                Err(e) => {
                    // I/O errors are sticky in libavformat: retrying would spin, so flush
                    // what was decoded and report the error after those frames.
                    self.read_error = Some(format!("read failed: {e}"));
                    break;
                }
            }
        }
        self.draining = true;
        // Only fails if already draining, which cannot happen here.
        let _ = self.decoder.send_eof();
    }

    /// Converts `self.decoded` into an output frame.
    fn convert(&mut self) -> Result<Frame, Error> {
        let (w, h) = (self.decoded.width(), self.decoded.height());
        if w == 0 || h == 0 {
            return Err(self.decode_err("decoder produced an empty frame"));
        }
        match self.expected {
            None => self.expected = Some((w, h)),
            Some(expected) if expected != (w, h) && self.resize.is_none() => {
                return Err(Error::SizeChanged {
                    path: self.path.clone(),
                    index: self.index,
                    expected,
                    got: (w, h),
                });
            }
            Some(_) => {}
        }
        let (out_w, out_h, plan) = plan_for(w, h, self.resize.as_ref());
        if self.rgb.width() != plan.scale_w || self.rgb.height() != plan.scale_h {
            // Only on the first frame or a mid-stream size change: the scaler allocates it.
            self.rgb = frame::Video::empty();
        }
        let key = Key {
            src_format: self.decoded.format(),
            src_w: w,
            src_h: h,
            dst_format: Pixel::RGB24,
            dst_w: plan.scale_w,
            dst_h: plan.scale_h,
        };
        scaler::scale(key, &self.decoded, &mut self.rgb).map_err(|e| {
            self.decode_err(format!(
                "cannot convert {:?} {w}x{h} to RGB24: {e}",
                self.decoded.format()
            ))
        })?;
        if self.rgb.planes() == 0 {
            return Err(self.decode_err("could not allocate the RGB frame"));
        }
        let data = compose(self.rgb.data(0), self.rgb.stride(0), &plan, out_w, out_h)
            .ok_or_else(|| self.decode_err("RGB frame buffer is smaller than expected"))?;

        let pts_ns = self.timestamp();
        Ok(Frame {
            width: out_w,
            height: out_h,
            data,
            pts_ns,
            source_index: self.index,
        })
    }

    /// Presentation time of `self.decoded` in ns relative to the first timestamped frame.
    fn timestamp(&mut self) -> i64 {
        let ts = self.decoded.timestamp().or_else(|| self.decoded.pts());
        let extrapolated = if self.index == 0 {
            0
        } else {
            self.last_ns.saturating_add(self.fallback_step_ns)
        };
        let ns = match (ts, self.time_base) {
            (Some(ts), Some((num, den))) => {
                let (origin_ts, origin_ns) = *self.origin.get_or_insert((ts, extrapolated));
                let rel = ticks_to_ns(i128::from(ts) - i128::from(origin_ts), num, den);
                origin_ns.saturating_add(rel)
            }
            _ => extrapolated,
        };
        self.last_ns = ns;
        ns
    }
}

/// `ticks × num / den` seconds in ns, rounded to nearest, saturating.
fn ticks_to_ns(ticks: i128, num: i128, den: i128) -> i64 {
    let scaled = ticks * num * 1_000_000_000;
    let half = den / 2;
    let q = if scaled >= 0 {
        (scaled + half) / den
    } else {
        (scaled - half) / den
    };
    i64::try_from(q).unwrap_or(if q < 0 { i64::MIN } else { i64::MAX })
}

impl Iterator for Decoder {
    type Item = Result<Frame, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        let mut errors = 0u32;
        while !self.done {
            match self.decoder.receive_frame(&mut self.decoded) {
                Ok(()) => {
                    let result = self.convert();
                    if result.is_err() {
                        self.done = true;
                    }
                    self.index += 1;
                    return Some(result);
                }
                Err(ffmpeg::Error::Eof) => return self.end(),
                Err(ffmpeg::Error::Other {
                    errno: ffmpeg::error::EAGAIN,
                }) => {
                    if self.draining {
                        // Not expected after EOF was sent, but ending beats spinning.
                        return self.end();
                    }
                    self.feed();
                }
                Err(e) => {
                    // A frame failed to decode; later ones may still be fine.
                    errors += 1;
                    if errors >= MAX_CONSECUTIVE_ERRORS {
                        self.done = true;
                        return Some(Err(self.decode_err(e.to_string())));
                    }
                }
            }
        }
        None
    }
}
