//! End-to-end tests: encode → decode round trips, frame folders, resizing, resampling, bad input.

#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

use crate::*;

const W: u32 = 64;
const H: u32 = 48;

/// A smooth gradient that drifts with `k`, so frames differ but compress well.
fn gradient(w: u32, h: u32, k: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity((w * h * 3) as usize);
    for y in 0..h {
        for x in 0..w {
            out.push((x * 3 + k).min(255) as u8);
            out.push((y * 4 + k).min(255) as u8);
            out.push((128 + x + y).saturating_sub(k).min(255) as u8);
        }
    }
    out
}

fn write_video(path: &Path, codec: Codec, n: u32, fps: u32) {
    let mut w = VideoWriter::create(path, W, H, fps, codec).unwrap();
    for k in 0..n {
        w.write(&gradient(W, H, k)).unwrap();
    }
    w.finish().unwrap();
}

fn mean_abs_error(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let sum: u64 = a.iter().zip(b).map(|(&x, &y)| u64::from(x.abs_diff(y))).sum();
    sum as f64 / a.len() as f64
}

fn ffmpeg_cli(args: &[&str]) {
    let status = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y"])
        .args(args)
        .status()
        .unwrap();
    assert!(status.success(), "ffmpeg {args:?} failed");
}

fn decode_all(path: &Path, opts: &DecodeOptions) -> Result<Vec<Frame>, Error> {
    VideoReader::open(path, opts)?.collect()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn roundtrip(ext: &str, codec: Codec, codec_name: &str) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(format!("clip.{ext}"));
    write_video(&path, codec, 20, 10);

    let reader = VideoReader::open(&path, &DecodeOptions::default()).unwrap();
    let info = reader.info().clone();
    assert_eq!((info.width, info.height), (W, H));
    assert_eq!(info.codec, codec_name);
    assert!((info.fps - 10.0).abs() < 0.01, "fps {}", info.fps);
    let frames: Vec<Frame> = reader.collect::<Result<_, _>>().unwrap();
    assert_eq!(frames.len(), 20, "{ext}");
    for (k, f) in frames.iter().enumerate() {
        assert_eq!((f.width, f.height), (W, H));
        assert_eq!(f.data.len(), (W * H * 3) as usize);
        assert_eq!(f.pts_ns, k as i64 * 100_000_000, "{ext} frame {k}");
        assert_eq!(f.source_index, k as u64);
        let err = mean_abs_error(&f.data, &gradient(W, H, k as u32));
        assert!(err < 6.0, "{ext} frame {k}: mean abs error {err}");
    }
}

#[test]
fn roundtrip_mp4_h264() {
    roundtrip("mp4", Codec::H264, "h264");
}

#[test]
fn roundtrip_mkv_h264() {
    roundtrip("mkv", Codec::H264, "h264");
}

#[test]
fn roundtrip_webm_vp9() {
    roundtrip("webm", Codec::Vp9, "vp9");
}

#[test]
fn roundtrip_mkv_av1() {
    roundtrip("mkv", Codec::Av1, "av1");
}

#[test]
fn roundtrip_avi_mjpeg() {
    roundtrip("avi", Codec::Mjpeg, "mjpeg");
}

#[test]
fn info_duration_and_frame_hint() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.mp4");
    write_video(&path, Codec::H264, 20, 10);
    let reader = VideoReader::open(&path, &DecodeOptions::default()).unwrap();
    let info = reader.info();
    assert_eq!(info.duration_ns, Some(2_000_000_000));
    assert_eq!(info.frames_hint, Some(20));
    assert!(info.container.contains("mp4"), "{}", info.container);
}

#[test]
fn cli_video_with_nonzero_start_begins_at_zero() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("offset.mkv");
    ffmpeg_cli(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=64x48:rate=10",
        "-frames:v",
        "20",
        "-c:v",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        "-output_ts_offset",
        "3",
        s(&path),
    ]);
    let frames = decode_all(&path, &DecodeOptions::default()).unwrap();
    assert_eq!(frames.len(), 20);
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.pts_ns, k as i64 * 100_000_000);
    }
}

#[test]
fn threads_setting_gives_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.mp4");
    write_video(&path, Codec::H264, 12, 10);
    let auto = decode_all(&path, &DecodeOptions::default()).unwrap();
    let one = decode_all(
        &path,
        &DecodeOptions {
            threads: 1,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(auto, one);
}

#[test]
fn resize_policies_on_video() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.mkv");
    write_video(&path, Codec::H264, 5, 10);
    let with = |resize: &str| {
        let opts = DecodeOptions {
            resize: Some(resize.parse().unwrap()),
            ..Default::default()
        };
        decode_all(&path, &opts).unwrap()
    };

    // 64x48 into 32x32 with pad: scaled to 32x24, 4 black rows top and bottom.
    let pad = with("32x32:pad");
    assert_eq!(pad.len(), 5);
    for f in &pad {
        assert_eq!((f.width, f.height, f.data.len()), (32, 32, 32 * 32 * 3));
        let row = 32 * 3;
        assert!(f.data[..4 * row].iter().all(|&v| v == 0), "top border");
        assert!(f.data[28 * row..].iter().all(|&v| v == 0), "bottom border");
        assert!(f.data[4 * row..28 * row].iter().any(|&v| v > 20), "picture");
    }

    // Crop: scale to 43x32, keep the centre 32 columns (x from 5).
    let crop = with("32x32:crop");
    let scaled = image::imageops::resize(
        &image::RgbImage::from_raw(W, H, gradient(W, H, 0)).unwrap(),
        43,
        32,
        image::imageops::FilterType::Triangle,
    );
    let centre = image::imageops::crop_imm(&scaled, 5, 0, 32, 32).to_image();
    for f in &crop {
        assert_eq!((f.width, f.height, f.data.len()), (32, 32, 32 * 32 * 3));
    }
    let err = mean_abs_error(&crop[0].data, centre.as_raw());
    assert!(err < 6.0, "crop error {err}");

    let stretch = with("40x20:stretch");
    for f in &stretch {
        assert_eq!((f.width, f.height, f.data.len()), (40, 20, 40 * 20 * 3));
    }
    // Stretch of the same aspect equals a plain downscale: compare with the scaled source.
    let half = with("32x24");
    let expected = image::imageops::resize(
        &image::RgbImage::from_raw(W, H, gradient(W, H, 0)).unwrap(),
        32,
        24,
        image::imageops::FilterType::Triangle,
    );
    let err = mean_abs_error(&half[0].data, expected.as_raw());
    assert!(err < 6.0, "downscale error {err}");
}

#[test]
fn resample_video_10_to_5_and_20() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.mp4");
    write_video(&path, Codec::H264, 20, 10);
    let at = |fps: f64| {
        decode_all(
            &path,
            &DecodeOptions {
                fps: Some(fps),
                ..Default::default()
            },
        )
        .unwrap()
    };

    let down = at(5.0);
    assert_eq!(down.len(), 10);
    for (k, f) in down.iter().enumerate() {
        assert_eq!(f.pts_ns, k as i64 * 200_000_000);
        assert_eq!(f.source_index, 2 * k as u64);
    }

    let up = at(20.0);
    assert_eq!(up.len(), 39);
    for (k, f) in up.iter().enumerate() {
        assert_eq!(f.pts_ns, k as i64 * 50_000_000);
        assert_eq!(f.source_index, k as u64 / 2);
    }
    assert_eq!(up[0].data, up[1].data);
    assert_ne!(up[1].data, up[2].data);
}

#[test]
fn streaming_long_video() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.mp4");
    ffmpeg_cli(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=64x48:rate=100",
        "-frames:v",
        "2000",
        "-c:v",
        "libx264",
        "-preset",
        "ultrafast",
        "-pix_fmt",
        "yuv420p",
        s(&path),
    ]);
    let reader = VideoReader::open(&path, &DecodeOptions::default()).unwrap();
    assert_eq!(reader.info().frames_hint, Some(2000));
    let mut count = 0u64;
    let mut last_pts = -1;
    for frame in reader {
        let frame = frame.unwrap();
        assert_eq!(frame.data.len(), 64 * 48 * 3);
        assert_eq!(frame.source_index, count);
        assert!(frame.pts_ns > last_pts);
        last_pts = frame.pts_ns;
        count += 1;
    }
    assert_eq!(count, 2000);
    assert_eq!(last_pts, 1999 * 10_000_000);
}

#[test]
fn reader_can_move_between_threads_mid_stream() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.mkv");
    write_video(&path, Codec::H264, 10, 10);
    let mut reader = VideoReader::open(&path, &DecodeOptions::default()).unwrap();
    let first = reader.next().unwrap().unwrap();
    let rest = std::thread::spawn(move || reader.collect::<Result<Vec<_>, _>>())
        .join()
        .unwrap()
        .unwrap();
    assert_eq!(first.source_index, 0);
    assert_eq!(rest.len(), 9);
}

#[test]
fn size_change_mid_stream() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.mkv");
    let b = dir.path().join("b.mkv");
    for (p, size) in [(&a, "64x48"), (&b, "32x24")] {
        ffmpeg_cli(&[
            "-f",
            "lavfi",
            "-i",
            &format!("testsrc2=size={size}:rate=10"),
            "-frames:v",
            "5",
            "-c:v",
            "mjpeg",
            s(p),
        ]);
    }
    let list = dir.path().join("list.txt");
    std::fs::write(&list, format!("file '{}'\nfile '{}'\n", s(&a), s(&b))).unwrap();
    let joined = dir.path().join("joined.mkv");
    ffmpeg_cli(&[
        "-f",
        "concat",
        "-safe",
        "0",
        "-i",
        s(&list),
        "-c",
        "copy",
        s(&joined),
    ]);

    let mut reader = VideoReader::open(&joined, &DecodeOptions::default()).unwrap();
    for _ in 0..5 {
        reader.next().unwrap().unwrap();
    }
    let err = reader.next().unwrap().unwrap_err();
    match &err {
        Error::SizeChanged {
            path,
            index,
            expected,
            got,
        } => {
            assert_eq!(path, &joined);
            assert_eq!((*index, *expected, *got), (5, (64, 48), (32, 24)));
        }
        other => panic!("expected SizeChanged, got {other}"),
    }
    assert!(err.to_string().ends_with(s(&joined)));
    assert!(reader.next().is_none());

    let resized = decode_all(
        &joined,
        &DecodeOptions {
            resize: Some("16x16:stretch".parse().unwrap()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(resized.len(), 10);
    assert!(resized.iter().all(|f| f.data.len() == 16 * 16 * 3));
}

// ---- frame folders ----

fn write_png(path: &Path, w: u32, h: u32, k: u32) -> Vec<u8> {
    let data = gradient(w, h, k);
    image::RgbImage::from_raw(w, h, data.clone())
        .unwrap()
        .save(path)
        .unwrap();
    data
}

#[test]
fn folder_of_numbered_pngs() {
    let dir = tempfile::tempdir().unwrap();
    let mut expected = Vec::new();
    // Written out of order, and unpadded, to exercise numeric sorting.
    for i in (1..=12).rev() {
        let data = write_png(&dir.path().join(format!("frame_{i}.png")), W, H, i * 5);
        expected.push((i, data));
    }
    expected.sort_by_key(|(i, _)| *i);
    std::fs::write(dir.path().join("notes.txt"), "ignored").unwrap();

    let reader = FrameDirReader::open(dir.path(), 10.0, &DecodeOptions::default()).unwrap();
    let names: Vec<String> = reader
        .files()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    let want: Vec<String> = (1..=12).map(|i| format!("frame_{i}.png")).collect();
    assert_eq!(names, want);
    let info = reader.info().clone();
    assert_eq!((info.width, info.height, info.frames_hint), (W, H, Some(12)));
    assert_eq!(info.codec, "png");

    let frames: Vec<Frame> = reader.collect::<Result<_, _>>().unwrap();
    assert_eq!(frames.len(), 12);
    for (k, (f, (_, data))) in frames.iter().zip(&expected).enumerate() {
        assert_eq!(&f.data, data, "frame {k} pixels");
        assert_eq!(f.pts_ns, k as i64 * 100_000_000);
        assert_eq!(f.source_index, k as u64);
    }
}

#[test]
fn folder_jpeg_gray_and_rgba_are_rgb() {
    let dir = tempfile::tempdir().unwrap();
    image::GrayImage::from_pixel(8, 6, image::Luma([77]))
        .save(dir.path().join("f_0.png"))
        .unwrap();
    image::RgbaImage::from_pixel(8, 6, image::Rgba([10, 20, 30, 255]))
        .save(dir.path().join("f_1.png"))
        .unwrap();
    image::RgbImage::from_pixel(8, 6, image::Rgb([200, 100, 50]))
        .save(dir.path().join("f_2.jpg"))
        .unwrap();
    let frames: Vec<Frame> = FrameDirReader::open(dir.path(), 2.0, &DecodeOptions::default())
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(frames.len(), 3);
    assert_eq!(&frames[0].data[..3], &[77, 77, 77]);
    assert_eq!(&frames[1].data[..3], &[10, 20, 30]);
    assert!(
        frames[2].data[..3]
            .iter()
            .zip([200u8, 100, 50])
            .all(|(&a, b)| a.abs_diff(b) < 8)
    );
    assert_eq!(frames[2].pts_ns, 1_000_000_000);
}

#[test]
fn folder_resize_and_resample() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..10 {
        write_png(&dir.path().join(format!("img{i:03}.png")), W, H, i);
    }
    let opts = DecodeOptions {
        resize: Some("32x32".parse().unwrap()),
        fps: Some(5.0),
        threads: 0,
    };
    let frames: Vec<Frame> = FrameDirReader::open(dir.path(), 10.0, &opts)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    // 10 frames at 10 fps -> last at 0.9 s -> floor(0.9 * 5) + 1 = 5
    assert_eq!(frames.len(), 5);
    for (k, f) in frames.iter().enumerate() {
        assert_eq!((f.width, f.height), (32, 32));
        assert_eq!(f.source_index, 2 * k as u64);
        assert_eq!(f.pts_ns, k as i64 * 200_000_000);
        let row = 32 * 3;
        assert!(f.data[..4 * row].iter().all(|&v| v == 0));
        assert!(f.data[28 * row..].iter().all(|&v| v == 0));
    }
}

#[test]
fn folder_mixed_sizes_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    write_png(&dir.path().join("frame_1.png"), W, H, 0);
    write_png(&dir.path().join("frame_2.png"), W, H, 1);
    let odd = dir.path().join("frame_3.png");
    write_png(&odd, 32, 32, 2);
    let mut reader = FrameDirReader::open(dir.path(), 10.0, &DecodeOptions::default()).unwrap();
    assert!(reader.next().unwrap().is_ok());
    assert!(reader.next().unwrap().is_ok());
    let err = reader.next().unwrap().unwrap_err();
    assert!(matches!(err, Error::SizeChanged { index: 2, .. }), "{err}");
    assert!(err.to_string().ends_with(s(&odd)), "{err}");
    assert!(reader.next().is_none());

    // With a resize the sizes may differ.
    let opts = DecodeOptions {
        resize: Some("16x16:crop".parse().unwrap()),
        ..Default::default()
    };
    let frames: Vec<Frame> = FrameDirReader::open(dir.path(), 10.0, &opts)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(frames.len(), 3);
}

#[test]
fn folder_corrupt_png_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    write_png(&dir.path().join("frame_1.png"), W, H, 0);
    let bad = dir.path().join("frame_2.png");
    let mut bytes = std::fs::read(dir.path().join("frame_1.png")).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&bad, &bytes).unwrap();
    let mut reader = open_frames(dir.path(), Some(10.0), &DecodeOptions::default()).unwrap();
    assert!(reader.next().unwrap().is_ok());
    let err = reader.next().unwrap().unwrap_err();
    assert!(matches!(err, Error::Image { .. }), "{err}");
    assert!(err.to_string().ends_with(s(&bad)), "{err}");

    // Garbage as the first file fails at open, also naming it.
    let dir2 = tempfile::tempdir().unwrap();
    let junk = dir2.path().join("0.png");
    std::fs::write(&junk, b"not a png").unwrap();
    let err = FrameDirReader::open(dir2.path(), 10.0, &DecodeOptions::default())
        .err()
        .unwrap();
    assert!(err.to_string().ends_with(s(&junk)), "{err}");
}

#[test]
fn list_numbered_frames_rules() {
    let dir = tempfile::tempdir().unwrap();
    let err = list_numbered_frames(dir.path()).unwrap_err();
    assert!(matches!(err, Error::NoFrameFiles { .. }));

    for name in [
        "cam2_frame_10.JPG",
        "cam2_frame_2.jpeg",
        "cam2_frame_1.png",
        ".hidden_5.png",
    ] {
        std::fs::write(dir.path().join(name), b"x").unwrap();
    }
    std::fs::create_dir(dir.path().join("sub_3.png")).unwrap();
    let names: Vec<String> = list_numbered_frames(dir.path())
        .unwrap()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        ["cam2_frame_1.png", "cam2_frame_2.jpeg", "cam2_frame_10.JPG"]
    );

    std::fs::write(dir.path().join("cam2_frame_0002.png"), b"x").unwrap();
    let err = list_numbered_frames(dir.path()).unwrap_err();
    assert!(
        matches!(err, Error::DuplicateFrameNumber { number: 2, .. }),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cover.png"), b"x").unwrap();
    let err = list_numbered_frames(dir.path()).unwrap_err();
    assert!(matches!(err, Error::NoFrameNumber { .. }), "{err}");

    let missing = dir.path().join("nope");
    let err = list_numbered_frames(&missing).unwrap_err();
    assert!(err.to_string().ends_with(s(&missing)), "{err}");
}

// ---- bad input ----

fn assert_open_error_names(path: &Path) {
    let err = match VideoReader::open(path, &DecodeOptions::default()) {
        Err(e) => e,
        Ok(reader) => {
            let items: Vec<_> = reader.collect();
            items
                .into_iter()
                .find_map(Result::err)
                .expect("bad input decoded without error")
        }
    };
    assert!(err.to_string().ends_with(s(path)), "{err}");
}

#[test]
fn zero_byte_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.mp4");
    std::fs::write(&path, b"").unwrap();
    assert_open_error_names(&path);
}

#[test]
fn text_file_named_mp4_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("notes.mp4");
    std::fs::write(&path, "these are not the frames you are looking for\n".repeat(50)).unwrap();
    assert_open_error_names(&path);
}

#[test]
fn missing_file_is_an_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing.mp4");
    let err = VideoReader::open(&path, &DecodeOptions::default()).err().unwrap();
    assert!(matches!(err, Error::Io { .. }), "{err}");
    assert!(err.to_string().ends_with(s(&path)), "{err}");
    let err = open_frames(&path, None, &DecodeOptions::default()).err().unwrap();
    assert!(err.to_string().ends_with(s(&path)), "{err}");
}

#[test]
fn truncated_mp4_errors_or_decodes_fewer_frames() {
    let dir = tempfile::tempdir().unwrap();
    for faststart in [false, true] {
        let full = dir.path().join(format!("full_{faststart}.mp4"));
        let mut args = vec![
            "-f",
            "lavfi",
            "-i",
            "testsrc2=size=64x48:rate=10",
            "-frames:v",
            "30",
            "-c:v",
            "libx264",
            "-pix_fmt",
            "yuv420p",
        ];
        if faststart {
            args.extend(["-movflags", "+faststart"]);
        }
        args.push(s(&full));
        ffmpeg_cli(&args);
        let bytes = std::fs::read(&full).unwrap();
        let cut = dir.path().join(format!("cut_{faststart}.mp4"));
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 5]).unwrap();
        match VideoReader::open(&cut, &DecodeOptions::default()) {
            Err(e) => assert!(e.to_string().ends_with(s(&cut)), "{e}"),
            Ok(reader) => {
                let mut ok = 0;
                for item in reader {
                    match item {
                        Ok(_) => ok += 1,
                        Err(e) => {
                            assert!(e.to_string().ends_with(s(&cut)), "{e}");
                            break;
                        }
                    }
                }
                assert!(ok < 30, "truncated file decoded all {ok} frames");
            }
        }
    }
}

#[test]
fn audio_only_file_has_no_video_stream() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tone.mkv");
    ffmpeg_cli(&[
        "-f",
        "lavfi",
        "-i",
        "sine=duration=0.5",
        "-c:a",
        "pcm_s16le",
        s(&path),
    ]);
    let err = VideoReader::open(&path, &DecodeOptions::default()).err().unwrap();
    assert!(matches!(err, Error::NoVideoStream { .. }), "{err}");
    assert!(err.to_string().ends_with(s(&path)), "{err}");
}

#[test]
fn open_frames_dispatch() {
    let dir = tempfile::tempdir().unwrap();
    write_png(&dir.path().join("f1.png"), W, H, 0);
    let err = open_frames(dir.path(), None, &DecodeOptions::default())
        .err()
        .unwrap();
    assert!(matches!(err, Error::FpsRequired { .. }), "{err}");
    assert!(err.to_string().ends_with(s(dir.path())), "{err}");
    let src = open_frames(dir.path(), Some(30.0), &DecodeOptions::default()).unwrap();
    assert_eq!(src.info().container, "image_folder");
    assert_eq!(src.count(), 1);

    let video = dir.path().join("v.mkv");
    write_video(&video, Codec::H264, 3, 10);
    let src = open_frames(&video, None, &DecodeOptions::default()).unwrap();
    assert_eq!(src.info().codec, "h264");
    assert_eq!(src.count(), 3);
}

#[test]
fn invalid_options_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("v.mkv");
    write_video(&video, Codec::H264, 2, 10);
    let bad_fps = DecodeOptions {
        fps: Some(0.0),
        ..Default::default()
    };
    assert!(VideoReader::open(&video, &bad_fps).is_err());
    let bad_size = DecodeOptions {
        resize: Some(Resize {
            width: 0,
            height: 10,
            policy: AspectPolicy::Pad,
        }),
        ..Default::default()
    };
    assert!(VideoReader::open(&video, &bad_size).is_err());
    assert!(FrameDirReader::open(dir.path(), -1.0, &DecodeOptions::default()).is_err());
}

#[test]
fn writer_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let err = VideoWriter::create(&dir.path().join("x.gif"), W, H, 10, Codec::H264)
        .err()
        .unwrap();
    assert!(matches!(err, Error::UnsupportedContainer { .. }), "{err}");
    let path = dir.path().join("x.mp4");
    let mut w = VideoWriter::create(&path, W, H, 10, Codec::H264).unwrap();
    assert!(w.write(&[0; 10]).is_err());
    w.write(&gradient(W, H, 0)).unwrap();
    w.finish().unwrap();
    assert_eq!(decode_all(&path, &DecodeOptions::default()).unwrap().len(), 1);
    assert!(VideoWriter::create(&path, 0, H, 10, Codec::H264).is_err());
}

#[test]
fn parse_and_display() {
    let r: Resize = "224x160".parse().unwrap();
    assert_eq!(
        r,
        Resize {
            width: 224,
            height: 160,
            policy: AspectPolicy::Pad
        }
    );
    let r: Resize = "96X64:crop".parse().unwrap();
    assert_eq!((r.width, r.height, r.policy), (96, 64, AspectPolicy::Crop));
    assert_eq!(r.to_string().parse::<Resize>().unwrap(), r);
    for bad in ["", "224", "x224", "0x10", "10x10:zoom", "-1x5", "axb"] {
        assert!(bad.parse::<Resize>().is_err(), "{bad:?}");
    }
    for p in [AspectPolicy::Stretch, AspectPolicy::Pad, AspectPolicy::Crop] {
        assert_eq!(p.to_string().parse::<AspectPolicy>().unwrap(), p);
    }
    assert!("fill".parse::<AspectPolicy>().is_err());
}

#[test]
fn readers_are_send() {
    fn assert_send<T: Send>() {}
    assert_send::<VideoReader>();
    assert_send::<FrameDirReader>();
    assert_send::<Box<dyn FrameSource>>();
}

#[test]
fn video_stream_without_frames_is_no_frames() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zero.avi");
    ffmpeg_cli(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=64x48:rate=10",
        "-frames:v",
        "0",
        "-c:v",
        "mjpeg",
        s(&path),
    ]);
    let mut reader = VideoReader::open(&path, &DecodeOptions::default()).unwrap();
    let err = reader.next().unwrap().unwrap_err();
    assert!(matches!(err, Error::NoFrames { .. }), "{err}");
    assert!(err.to_string().ends_with(s(&path)), "{err}");
    assert!(reader.next().is_none());
    // Resampling forwards the error too.
    let opts = DecodeOptions {
        fps: Some(5.0),
        ..Default::default()
    };
    let items: Vec<_> = VideoReader::open(&path, &opts).unwrap().collect();
    assert!(matches!(items.as_slice(), [Err(Error::NoFrames { .. })]));
}
