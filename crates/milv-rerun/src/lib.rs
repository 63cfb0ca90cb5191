//! # milv-rerun — a Rerun recording of what the translation did
//!
//! Logs a [`ViewPlan`] (a pinned dataset version, joined per frame) so the viewer opens
//! on a layout made for judging translations ([`blueprint`]): the human frame, the
//! imagined robot frame, the aligned robot frame and the latent's channel-mean heat map
//! side by side on top, quality and actions plotted below.
//!
//! | entity | what |
//! |---|---|
//! | `human/image`, `imagined/image`, `robot/image` | encoded frames (PNG/JPEG as stored) |
//! | `latent` | channel mean of the latent ẑ^r, as a colour-mapped depth image |
//! | `quality/{brenner,ssim,beta,weight}` | scalar series (`weight` when curated) |
//! | `action/{predicted,true}/<name>` | predicted action â^r and the aligned robot frame's action |
//! | `episode` | a text card per episode (id, task, mean β) |
//!
//! Timelines: `frame` (a running frame counter, episodes end to end) and `time` (their
//! timestamps laid end to end). [`Sink`] picks a `.rrd` file (written under a temporary
//! name and renamed when complete), a spawned viewer or a running one.

use std::path::PathBuf;
use std::time::Duration;

use milv_data::Dataset;
use milv_data::view::{EpisodeView, Image, Latent, ViewPlan};
use rerun::blueprint::{
    Blueprint, Grid, Horizontal, Spatial2DView, TextDocumentView, TimePanel, TimeSeriesView, Vertical,
};
use rerun::{EncodedImage, MediaType, RecordingStream, Scalars, SeriesLines};
use serde::Serialize;

/// Everything that can go wrong in an export. Paths come last in messages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Data(#[from] milv_data::Error),
    #[error("rerun: {0}")]
    Rerun(#[from] rerun::RecordingStreamError),
    #[error("rerun: flushing the recording: {0}")]
    Flush(String),
    #[error("{op}: {source}: {path}")]
    Io {
        op: &'static str,
        #[source]
        source: std::io::Error,
        path: PathBuf,
    },
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, Error>;

/// Where the recording goes.
#[derive(Clone, Debug)]
pub enum Sink {
    /// A `.rrd` file.
    File(PathBuf),
    /// A new viewer (the `rerun` executable on PATH, e.g. from `pip install rerun-sdk`).
    Spawn,
    /// A running viewer: `HOST:PORT` or a full `rerun+http://HOST:PORT/proxy` URL.
    Connect(String),
}

/// What was logged.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Logged {
    pub episodes: usize,
    pub frames: usize,
    /// The `.rrd` written, for a file sink.
    pub path: Option<PathBuf>,
}

pub const APP_ID: &str = "milv";

/// The layout the viewer opens on: the image grid on top, plots below.
pub fn blueprint() -> Blueprint {
    let top = Grid::new([
        Spatial2DView::new("human").with_origin("/human").into(),
        Spatial2DView::new("imagined").with_origin("/imagined").into(),
        Spatial2DView::new("robot").with_origin("/robot").into(),
        Spatial2DView::new("latent (channel mean)")
            .with_origin("/latent")
            .into(),
    ])
    .with_grid_columns(4);
    let bottom = Horizontal::new([
        TimeSeriesView::new("quality").with_origin("/quality").into(),
        TimeSeriesView::new("action").with_origin("/action").into(),
        TextDocumentView::new("episode").with_origin("/episode").into(),
    ])
    .with_column_shares([2.0, 2.0, 1.0]);
    Blueprint::new(Vertical::new([top.into(), bottom.into()]).with_row_shares([3.0, 2.0]))
        .with_auto_views(false)
        .with_time_panel(TimePanel::new().with_timeline("frame"))
}

/// A viewer URL from `HOST:PORT` or a full URL.
pub fn connect_url(addr: &str) -> String {
    if addr.contains("://") {
        addr.to_string()
    } else {
        format!("rerun+http://{addr}/proxy")
    }
}

fn encoded(img: &Image) -> EncodedImage {
    let media = if img.format == "jpeg" {
        MediaType::jpeg()
    } else {
        MediaType::png()
    };
    EncodedImage::new(img.data.clone()).with_media_type(media)
}

/// The channel mean of a (…, C, H, W) latent, and its value range.
pub fn channel_mean(l: &Latent) -> Result<(Vec<f32>, [u32; 2], [f64; 2])> {
    let v = l.to_f32().map_err(Error::Invalid)?;
    let s = &l.shape;
    if s.len() < 3 {
        return Err(Error::Invalid(format!("latent shape {s:?}: expected (C, H, W)")));
    }
    let (h, w) = (s[s.len() - 2] as usize, s[s.len() - 1] as usize);
    let plane = h * w;
    let mut mean = vec![0f32; plane];
    // Leading dimensions (a batch of one) count as channels.
    for ch in v.chunks_exact(plane) {
        for (m, x) in mean.iter_mut().zip(ch) {
            *m += x;
        }
    }
    let k = (v.len() / plane).max(1) as f32;
    mean.iter_mut().for_each(|m| *m /= k);
    let (lo, hi) = mean
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(*x), hi.max(*x))
        });
    let range = if lo < hi {
        [lo as f64, hi as f64]
    } else {
        [lo as f64, lo as f64 + 1.0]
    };
    Ok((mean, [w as u32, h as u32], range))
}

struct Logger {
    rec: RecordingStream,
    action_names: Vec<String>,
    frame: i64,
    offset_ns: u64,
}

impl Logger {
    fn scalar(&self, path: &str, v: f64) -> Result<()> {
        Ok(self.rec.log(path, &Scalars::single(v))?)
    }

    fn actions(&self, kind: &str, a: &[f32]) -> Result<()> {
        for (i, v) in a.iter().enumerate() {
            let name = milv_data::view::component_name(&self.action_names, i);
            self.scalar(&format!("action/{kind}/{name}"), f64::from(*v))?;
        }
        Ok(())
    }

    fn episode(&mut self, ev: &EpisodeView) -> Result<usize> {
        let e = &ev.episode;
        let own = if e.domain == milv_data::Domain::Robot {
            "robot/image"
        } else {
            "human/image"
        };
        let card = format!(
            "episode {}\n{} {} {}\nframes {}\nmean beta {}",
            e.episode_id,
            e.domain,
            e.kind,
            e.task_id.as_deref().unwrap_or("-"),
            ev.frames.len(),
            ev.mean_beta()
                .map(|b| format!("{b:.4}"))
                .unwrap_or_else(|| "-".into())
        );
        for (k, f) in ev.frames.iter().enumerate() {
            let t = self.offset_ns + f.timestamp_ns.max(0) as u64;
            self.rec.set_time_sequence("frame", self.frame);
            self.rec.set_time("time", Duration::from_nanos(t));
            if k == 0 {
                self.rec.log("episode", &rerun::TextDocument::new(card.clone()))?;
            }
            self.rec.log(own, &encoded(&f.image))?;
            if e.domain == milv_data::Domain::Robot
                && let Some(a) = &f.action
            {
                self.actions("true", a)?;
            }
            if let Some(im) = &f.imagined {
                self.rec.log("imagined/image", &encoded(&im.image))?;
                if let Some(l) = &im.latent {
                    let (mean, wh, range) = channel_mean(l)?;
                    let bytes: Vec<u8> = mean.iter().flat_map(|x| x.to_le_bytes()).collect();
                    let heat =
                        rerun::DepthImage::from_data_type_and_bytes(bytes, wh, rerun::ChannelDatatype::F32)
                            .with_colormap(rerun::components::Colormap::Viridis)
                            .with_depth_range(range);
                    self.rec.log("latent", &heat)?;
                }
                if let Some(a) = &im.action {
                    self.actions("predicted", a)?;
                }
            }
            if let Some(q) = &f.quality {
                self.scalar("quality/brenner", q.brenner)?;
                self.scalar("quality/ssim", q.ssim)?;
                self.scalar("quality/beta", q.beta)?;
                if let Some(w) = q.weight {
                    self.scalar("quality/weight", w)?;
                }
            }
            if let Some(r) = &f.aligned {
                self.rec.log("robot/image", &encoded(&r.image))?;
                if let Some(a) = &r.action {
                    self.actions("true", a)?;
                }
            }
            self.frame += 1;
        }
        self.offset_ns += ev.duration_ns();
        Ok(ev.frames.len())
    }
}

/// Logs every episode of `plan` to `sink`, with the [`blueprint`] layout.
pub fn log_recording(
    plan: &mut ViewPlan,
    ds: &Dataset,
    recording_name: &str,
    sink: &Sink,
    progress: &mut dyn FnMut(usize),
) -> Result<Logged> {
    let builder = rerun::RecordingStreamBuilder::new(APP_ID)
        .recording_name(recording_name)
        .with_blueprint(blueprint());
    let mut tmp = None;
    let rec = match sink {
        Sink::File(out) => {
            let t = milv_data::temp_file_beside(out)?.into_temp_path();
            let rec = builder.save(t.to_path_buf())?;
            tmp = Some((t, out.clone()));
            rec
        }
        Sink::Spawn => builder.spawn()?,
        Sink::Connect(addr) => builder.connect_grpc_opts(connect_url(addr))?,
    };
    // A reproducible file: no wall-clock timeline.
    rec.set_log_time_enabled(false);
    let mut lg = Logger {
        rec,
        action_names: plan.action_names.clone(),
        frame: 0,
        offset_ns: 0,
    };
    for kind in ["predicted", "true"] {
        for n in &plan.action_names {
            lg.rec.log_static(
                format!("action/{kind}/{n}"),
                &SeriesLines::new().with_names([format!("{kind} {n}")]),
            )?;
        }
    }
    let mut logged = Logged::default();
    for (k, ev) in plan.views(ds).enumerate() {
        logged.frames += lg.episode(&ev?)?;
        logged.episodes = k + 1;
        progress(k + 1);
    }
    lg.rec.flush_blocking().map_err(|e| Error::Flush(e.to_string()))?;
    // The file sink writes its footer when the last handle goes.
    drop(lg);
    if let Some((t, out)) = tmp {
        t.persist(&out).map_err(|e| Error::Io {
            op: "rename onto",
            source: e.error,
            path: out.clone(),
        })?;
        logged.path = Some(out);
    }
    Ok(logged)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn channel_mean_averages_channels() {
        // 2 channels of 1×2: [1, 2] and [3, 6] → [2, 4].
        let data: Vec<u8> = [1f32, 2., 3., 6.].iter().flat_map(|x| x.to_le_bytes()).collect();
        let l = Latent {
            dtype: "f32".into(),
            shape: vec![2, 1, 2],
            data,
        };
        let (m, wh, range) = channel_mean(&l).unwrap();
        assert_eq!((m, wh, range), (vec![2.0, 4.0], [2, 1], [2.0, 4.0]));
        let bad = Latent {
            dtype: "f32".into(),
            shape: vec![2, 2],
            data: vec![0; 16],
        };
        assert!(channel_mean(&bad).is_err());
    }

    #[test]
    fn addresses_become_proxy_urls() {
        assert_eq!(connect_url("127.0.0.1:9876"), "rerun+http://127.0.0.1:9876/proxy");
        assert_eq!(connect_url("rerun+http://h:1/proxy"), "rerun+http://h:1/proxy");
    }
}
