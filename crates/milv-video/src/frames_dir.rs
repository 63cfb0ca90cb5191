//! Folders of numbered PNG/JPEG frames, read lazily as a video.

use std::path::{Path, PathBuf};

use image::ImageReader;
use image::imageops::{self, FilterType};

use crate::fit::{compose, plan_for};
use crate::resample::MaybeResample;
use crate::types::check_fps;
use crate::{DecodeOptions, Error, Frame, FrameSource, Resize, VideoInfo};

/// Lists the `*.png`, `*.jpg` and `*.jpeg` files of `dir` (extension case-insensitive),
/// ordered numerically by the last run of digits in the file name (`frame_2` before `frame_10`).
///
/// Hidden files (leading `.`, e.g. macOS `._frame_1.png`) are ignored. Errors if there are
/// no frame files, if a frame file has no digits, or if two files share a number.
pub fn list_numbered_frames(dir: &Path) -> Result<Vec<PathBuf>, Error> {
    let io_err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| Error::Io { path, source }
    };
    let mut numbered = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io_err(dir))? {
        let path = entry.map_err(io_err(dir))?.path();
        let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
            continue;
        };
        if name.starts_with('.') {
            continue;
        }
        let Some((stem, ext)) = name.rsplit_once('.') else {
            continue;
        };
        let is_image = ["png", "jpg", "jpeg"].iter().any(|e| ext.eq_ignore_ascii_case(e));
        // metadata() follows symlinks, so linked frames count.
        if !is_image || stem.is_empty() || !std::fs::metadata(&path).is_ok_and(|m| m.is_file()) {
            continue;
        }
        let number = last_number(stem).ok_or_else(|| Error::NoFrameNumber { path: path.clone() })?;
        numbered.push((number, path));
    }
    if numbered.is_empty() {
        return Err(Error::NoFrameFiles {
            path: dir.to_path_buf(),
        });
    }
    numbered.sort();
    for pair in numbered.windows(2) {
        if let [(a, first), (b, second)] = pair
            && a == b
        {
            return Err(Error::DuplicateFrameNumber {
                path: second.clone(),
                other: first.clone(),
                number: *a,
            });
        }
    }
    Ok(numbered.into_iter().map(|(_, p)| p).collect())
}

/// The value of the last run of ASCII digits in `s`, if any (and if it fits in a u128).
fn last_number(s: &str) -> Option<u128> {
    let end = s.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = s[..end].rfind(|c: char| !c.is_ascii_digit()).map_or(0, |i| i + 1);
    s[start..end].parse().ok()
}

/// Reads a folder of numbered frames as a video at a given frame rate.
///
/// Decodes one image per `next()`; frame `i` has `pts_ns = round(i · 1e9 / fps)`.
/// Errors end the iteration.
pub struct FrameDirReader {
    frames: MaybeResample<FrameDir>,
}

impl FrameDirReader {
    /// Lists `dir` (see [`list_numbered_frames`]) and reads the first frame's header for its size.
    pub fn open(dir: &Path, fps: f64, opts: &DecodeOptions) -> Result<Self, Error> {
        check_fps(fps)?;
        opts.validate()?;
        let files = list_numbered_frames(dir)?;
        let first = files.first().ok_or_else(|| Error::NoFrameFiles {
            path: dir.to_path_buf(),
        })?;
        let (width, height) = ImageReader::open(first)
            .map_err(|e| image_err(first, e))?
            .with_guessed_format()
            .map_err(|e| image_err(first, e))?
            .into_dimensions()
            .map_err(|e| image_err(first, e))?;
        let codec = match first.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("png") => "png",
            _ => "jpeg",
        };
        let n = files.len() as u64;
        let info = VideoInfo {
            width,
            height,
            fps,
            duration_ns: Some((n as f64 * 1e9 / fps).round() as i64),
            frames_hint: Some(n),
            frames_declared: Some(n),
            codec: codec.to_string(),
            container: "image_folder".to_string(),
        };
        let dir = FrameDir {
            files,
            fps,
            resize: opts.resize,
            index: 0,
            done: false,
            info,
        };
        Ok(FrameDirReader {
            frames: MaybeResample::new(dir, opts.fps)?,
        })
    }

    /// Folder size and frame count; `fps` is the rate given to `open`.
    pub fn info(&self) -> &VideoInfo {
        &self.frames.inner().info
    }

    /// The frame files in playback order.
    pub fn files(&self) -> &[PathBuf] {
        &self.frames.inner().files
    }
}

impl Iterator for FrameDirReader {
    type Item = Result<Frame, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        self.frames.next()
    }
}

impl FrameSource for FrameDirReader {
    fn info(&self) -> &VideoInfo {
        FrameDirReader::info(self)
    }
}

fn image_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Image {
        path: path.to_path_buf(),
        msg: e.to_string(),
    }
}

/// An RGB image at the output size `resize` asks for (unchanged without one), as packed
/// RGB24; `path` names the source in errors. Shared with readers of images stored
/// elsewhere (LeRobot's inline image features).
pub fn resize_rgb(
    rgb: image::RgbImage,
    resize: Option<&Resize>,
    path: &Path,
) -> Result<(u32, u32, Vec<u8>), Error> {
    let (w, h) = rgb.dimensions();
    let (out_w, out_h, plan) = plan_for(w, h, resize);
    let data = if (plan.scale_w, plan.scale_h) == (w, h) && (out_w, out_h) == (w, h) {
        rgb.into_raw()
    } else {
        let scaled;
        let src = if (plan.scale_w, plan.scale_h) == (w, h) {
            &rgb
        } else {
            scaled = imageops::resize(&rgb, plan.scale_w, plan.scale_h, FilterType::Triangle);
            &scaled
        };
        compose(src.as_raw(), plan.scale_w as usize * 3, &plan, out_w, out_h)
            .ok_or_else(|| image_err(path, "resized image is smaller than expected"))?
    };
    Ok((out_w, out_h, data))
}

/// The folder iterator before optional resampling.
pub(crate) struct FrameDir {
    files: Vec<PathBuf>,
    fps: f64,
    resize: Option<Resize>,
    index: usize,
    done: bool,
    info: VideoInfo,
}

impl FrameDir {
    fn load(&self, path: &Path) -> Result<Frame, Error> {
        let rgb = ImageReader::open(path)
            .map_err(|e| image_err(path, e))?
            // Trust the bytes over the extension (a .png that is really a JPEG still loads).
            .with_guessed_format()
            .map_err(|e| image_err(path, e))?
            .decode()
            .map_err(|e| image_err(path, e))?
            .into_rgb8();
        let (w, h) = rgb.dimensions();
        let expected = (self.info.width, self.info.height);
        if self.resize.is_none() && (w, h) != expected {
            return Err(Error::SizeChanged {
                path: path.to_path_buf(),
                index: self.index as u64,
                expected,
                got: (w, h),
            });
        }
        let (out_w, out_h, data) = resize_rgb(rgb, self.resize.as_ref(), path)?;
        Ok(Frame {
            width: out_w,
            height: out_h,
            data,
            pts_ns: (self.index as f64 * 1e9 / self.fps).round() as i64,
            source_index: self.index as u64,
        })
    }
}

impl Iterator for FrameDir {
    type Item = Result<Frame, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let Some(path) = self.files.get(self.index) else {
            self.done = true;
            return None;
        };
        let result = self.load(path);
        self.done = result.is_err();
        self.index += 1;
        Some(result)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn last_number_picks_last_run() {
        assert_eq!(last_number("frame_10"), Some(10));
        assert_eq!(last_number("cam2_frame_0007"), Some(7));
        assert_eq!(last_number("42"), Some(42));
        assert_eq!(last_number("frame"), None);
        assert_eq!(last_number("a1b"), Some(1));
    }
}
