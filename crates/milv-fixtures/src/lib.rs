//! # milv-fixtures — small datasets for tests
//!
//! The crates' tests build their datasets through these helpers, which write through
//! milv-data's own writers ([`milv_data::Transaction::write_groups`]), so every test
//! dataset has the layout the real stages produce. A dev-dependency only.
//!
//! | helper | what |
//! |---|---|
//! | [`episode`] | an [`Episode`] row with test defaults, to adjust with struct update syntax |
//! | [`png`] | a PNG of packed RGB |
//! | [`commit_episodes`] | episodes and their frames as one version (what an ingest commits) |
//! | [`commit_imagined`] | one model's translated frames as one version (what `translate` commits) |
//!
//! ```
//! use milv_data::{CommitMeta, Dataset, Domain};
//! use milv_fixtures::{Frame, commit_episodes, episode};
//! let dir = tempfile::tempdir().unwrap();
//! let ds = Dataset::open_or_create(dir.path(), CommitMeta::for_this_process("doc", "create")).unwrap();
//! let frames = vec![Frame::image(vec![7; 12]); 3];
//! let ep = milv_data::Episode { frame_encoding: milv_data::FrameEncoding::Raw, ..episode("e", Domain::Robot, 3, (2, 2)) };
//! assert_eq!(commit_episodes(&ds, &[(ep, frames)], CommitMeta::default()).unwrap(), 1);
//! ```

use milv_data::RowBuffer as _;
use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::{
    CommitMeta, Dataset, Domain, Episode, FrameRows, ImaginedRow, ImaginedRows, Kind, Result, ShardOptions,
    Split, TableKind,
};

/// Frame period of fixture episodes (10 fps).
pub const FRAME_NS: i64 = 100_000_000;

/// An episode row: a training `demo` of `draw/circle` at 10 fps with PNG frames of
/// `size`, no actions or states, source `<id>.mp4`.
pub fn episode(id: &str, domain: Domain, n_frames: usize, (width, height): (u32, u32)) -> Episode {
    Episode {
        episode_id: id.into(),
        domain,
        kind: Kind::Demo,
        task_id: Some("draw/circle".into()),
        task_family: Some("drawing".into()),
        pair_id: None,
        split: Split::Train,
        n_frames: n_frames as i64,
        fps: 10.0,
        width: width as i32,
        height: height as i32,
        frame_encoding: FrameEncoding::Png,
        action_dim: None,
        state_dim: None,
        action_names: None,
        state_names: None,
        source_uri: format!("{id}.mp4"),
        source_sha256: "00".into(),
        sidecar_uri: None,
        duration_ns: n_frames as i64 * FRAME_NS,
        ingested_at_us: 0,
    }
}

/// PNG bytes of a packed RGB24 image.
pub fn png(rgb: &[u8], width: u32, height: u32) -> Vec<u8> {
    let mut out = Vec::new();
    frame_codec::encode(FrameEncoding::Png, rgb, width, height, &mut out)
        .unwrap_or_else(|e| panic!("fixture PNG {width}x{height}: {e}"));
    out
}

/// One stored frame of a fixture episode (its image already encoded).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Frame {
    pub image: Vec<u8>,
    pub action: Option<Vec<f32>>,
    pub state: Option<Vec<f32>>,
}

impl Frame {
    pub fn image(image: Vec<u8>) -> Frame {
        Frame {
            image,
            ..Frame::default()
        }
    }
}

/// Commits the episodes and their frames (timestamps `k · FRAME_NS`) as one version.
pub fn commit_episodes(ds: &Dataset, eps: &[(Episode, Vec<Frame>)], meta: CommitMeta) -> Result<u64> {
    commit_episodes_with(ds, eps, meta, ShardOptions::default(), usize::MAX)
}

/// [`commit_episodes`] with shard options and at most `batch_rows` frames per batch
/// handed to the writer (to exercise multi-batch episodes).
pub fn commit_episodes_with(
    ds: &Dataset,
    eps: &[(Episode, Vec<Frame>)],
    meta: CommitMeta,
    opts: ShardOptions,
    batch_rows: usize,
) -> Result<u64> {
    let mut txn = ds.begin(meta)?;
    txn.write_groups(TableKind::Frames, None, opts, |w| -> Result<()> {
        for (e, frames) in eps {
            w.begin(&e.episode_id)?;
            let mut rows = FrameRows::new();
            for (k, f) in frames.iter().enumerate() {
                rows.push(
                    &e.episode_id,
                    k as i32,
                    k as i64 * FRAME_NS,
                    &f.image,
                    f.action.as_deref(),
                    f.state.as_deref(),
                );
                if rows.len() >= batch_rows {
                    w.push(&mut rows)?;
                }
            }
            w.push(&mut rows)?;
            w.end()?;
        }
        Ok(())
    })?;
    let rows: Vec<Episode> = eps.iter().map(|(e, _)| e.clone()).collect();
    txn.add_episode_rows(&rows)?;
    txn.commit()
}

/// One translated frame of a fixture episode.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImaginedFrame {
    /// PNG of the imagined robot frame.
    pub image: Vec<u8>,
    /// Raw latent bytes, dtype (`f16` | `f32`) and shape.
    pub latent: Option<(Vec<u8>, String, Vec<i32>)>,
    pub action: Option<Vec<f32>>,
}

/// Commits `model`'s translation of each episode (frames in order) as one version;
/// `meta.summary` may carry the model's config as `translate` records it.
pub fn commit_imagined(
    ds: &Dataset,
    model: &str,
    eps: &[(&str, Vec<ImaginedFrame>)],
    meta: CommitMeta,
) -> Result<u64> {
    let mut txn = ds.begin(meta)?;
    txn.write_groups(
        TableKind::Imagined,
        Some(model),
        ShardOptions::default(),
        |w| -> Result<()> {
            for (id, frames) in eps {
                w.begin(id)?;
                let mut rows = ImaginedRows::new();
                for (k, f) in frames.iter().enumerate() {
                    rows.push(&ImaginedRow {
                        episode_id: id,
                        frame_index: k as i32,
                        timestamp_ns: k as i64 * FRAME_NS,
                        model_id: model,
                        image: &f.image,
                        latent: f
                            .latent
                            .as_ref()
                            .map(|(b, d, s)| (b.as_slice(), d.as_str(), s.as_slice())),
                        action: f.action.as_deref(),
                    });
                }
                w.push(&mut rows)?;
                w.end()?;
            }
            Ok(())
        },
    )?;
    txn.commit()
}
