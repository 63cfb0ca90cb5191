//! Scoring, curation and reports on real dataset tables in a temp folder, checked against
//! the kernels applied directly to the same frames.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeSet;

use milv_data::frame_codec::{self, FrameEncoding};
use milv_data::{CommitMeta, CuratedRow, Dataset, Domain, Episode, Partition, ScoreRow, TableKind};
use milv_fixtures::{Frame, ImaginedFrame};
use milv_quality::{Rgb, beta_video};
use milv_score::{CurateOptions, Error, Rule, RunOptions, Source, curate, score_dataset, summarize};

const W: usize = 24;
const H: usize = 20;

fn meta(op: &str) -> CommitMeta {
    CommitMeta::for_this_process("score-test", op)
}

/// Frame `t` of episode `seed`: a drifting pattern with some blur-free edges.
fn frame(seed: u32, t: u32, w: usize, h: usize) -> Vec<u8> {
    let mut v = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let u = (x as u32 + t * (seed + 1)) % 17;
            let c = ((u * 15 + y as u32 * seed * 7) % 256) as u8;
            v.extend_from_slice(&[c, c.wrapping_add(40), (u * 9) as u8]);
        }
    }
    v
}

fn episode(id: &str, domain: Domain, n: usize, enc: FrameEncoding) -> Episode {
    Episode {
        frame_encoding: enc,
        source_sha256: "ab".into(),
        ..milv_fixtures::episode(id, domain, n, (W as u32, H as u32))
    }
}

struct Ep {
    id: &'static str,
    domain: Domain,
    enc: FrameEncoding,
    frames: Vec<Vec<u8>>,
    /// Replace frame k's stored bytes with garbage.
    corrupt: Option<usize>,
}

fn ep(id: &'static str, domain: Domain, seed: u32, n: u32, enc: FrameEncoding) -> Ep {
    Ep {
        id,
        domain,
        enc,
        frames: (0..n).map(|t| frame(seed, t, W, H)).collect(),
        corrupt: None,
    }
}

fn commit_episodes(ds: &Dataset, eps: &[Ep]) -> u64 {
    let eps: Vec<(Episode, Vec<Frame>)> = eps
        .iter()
        .map(|e| {
            let frames = e
                .frames
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    let mut bytes = Vec::new();
                    frame_codec::encode(e.enc, f, W as u32, H as u32, &mut bytes).unwrap();
                    if e.corrupt == Some(i) {
                        bytes = b"\x89PNG\r\n\x1a\ngarbage".to_vec();
                    }
                    Frame::image(bytes)
                })
                .collect();
            (episode(e.id, e.domain, e.frames.len(), e.enc), frames)
        })
        .collect();
    milv_fixtures::commit_episodes(ds, &eps, meta("ingest")).unwrap()
}

/// Imagined rows (PNG) for an episode, of one model; `sizes` gives each frame's size.
fn commit_imagined(ds: &Dataset, id: &str, model: &str, sizes: &[(usize, usize)]) -> u64 {
    let frames: Vec<ImaginedFrame> = sizes
        .iter()
        .enumerate()
        .map(|(t, &(fw, fh))| ImaginedFrame {
            image: milv_fixtures::png(&frame(9, t as u32, fw, fh), fw as u32, fh as u32),
            ..ImaginedFrame::default()
        })
        .collect();
    milv_fixtures::commit_imagined(ds, model, &[(id, frames)], meta("translate")).unwrap()
}

fn opts(source: Source) -> RunOptions {
    RunOptions {
        source,
        model_id: None,
        episodes: None,
        domain: None,
        jobs: 2,
        partition: None,
        skip_bad: false,
    }
}

/// (episode, frame) → (beta, brenner, ssim, weight) of the scores table at `v`.
type Row = (String, i32, f64, f64, f64, Option<f64>, String);

fn score_rows(ds: &Dataset, v: u64) -> Vec<Row> {
    let mut out: Vec<Row> = milv_data::read::rows::<ScoreRow>(ds, v)
        .unwrap()
        .into_iter()
        .map(|r| {
            (
                r.episode_id,
                r.frame_index,
                r.beta,
                r.brenner,
                r.ssim,
                r.weight,
                r.run_id,
            )
        })
        .collect();
    out.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    out
}

fn good_dataset() -> (tempfile::TempDir, Dataset, Vec<Ep>) {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    let eps = vec![
        ep("h1", Domain::Human, 1, 6, FrameEncoding::Png),
        ep("h2", Domain::Human, 2, 5, FrameEncoding::Png),
        ep("r1", Domain::Robot, 3, 7, FrameEncoding::Raw),
    ];
    commit_episodes(&ds, &eps);
    (dir, ds, eps)
}

#[test]
fn scores_equal_the_kernels_and_runs_are_idempotent_and_partitionable() {
    let (_dir, ds, eps) = good_dataset();
    let rep = score_dataset(&ds, None, &opts(Source::Frames), meta("score"), &|_| {}).unwrap();
    assert_eq!((rep.version, rep.episodes_scored, rep.frames_scored), (2, 3, 18));
    let rows = score_rows(&ds, 2);
    assert_eq!(rows.len(), 18);
    let (bmin, bmax) = (rep.brenner_min.unwrap(), rep.brenner_max.unwrap());
    for e in &eps {
        let imgs: Vec<Rgb<'_>> = e.frames.iter().map(|f| Rgb::new(f, W, H).unwrap()).collect();
        let want = beta_video(&imgs).unwrap();
        let got: Vec<&Row> = rows.iter().filter(|r| r.0 == e.id).collect();
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(
                (g.2, g.3, g.4),
                (w.beta, w.brenner.normalized, w.ssim),
                "{}",
                e.id
            );
            let wt = milv_quality::set_weight(w.brenner.normalized, w.ssim, bmin, bmax);
            assert_eq!(g.5, Some(wt));
        }
    }
    // The normalisation is in every file's footer.
    let f = &ds.files(TableKind::Scores, 2).unwrap()[0];
    let kv = milv_data::read::file_metadata(&ds, f).unwrap();
    let params: serde_json::Value =
        serde_json::from_str(&kv.iter().find(|(k, _)| k == "milv.scores").unwrap().1).unwrap();
    assert_eq!(params["brenner_min"].as_f64(), Some(bmin));
    assert_eq!(params["run_id"].as_str(), Some(rep.run_id.as_str()));

    // Running it again finds it done.
    let again = score_dataset(&ds, None, &opts(Source::Frames), meta("score"), &|_| {}).unwrap();
    assert_eq!(
        (again.version, again.frames_scored, again.episodes_already_scored),
        (2, 0, 3)
    );
    assert_eq!(again.run_id, rep.run_id);

    // The same run as two partitions on a copy of the dataset at v1: same run id, the
    // union of the rows, weights left to curation, which reproduces them exactly.
    let (_d2, ds2, _) = good_dataset();
    let mut ids = BTreeSet::new();
    for i in 0..2 {
        let o = RunOptions {
            partition: Some(Partition { index: i, count: 2 }),
            ..opts(Source::Frames)
        };
        let r = score_dataset(&ds2, Some(1), &o, meta("score"), &|_| {}).unwrap();
        assert!(!r.weights_written);
        ids.insert(r.run_id);
    }
    assert_eq!(ids.len(), 1);
    let latest = ds2.latest_version().unwrap();
    let part_rows = score_rows(&ds2, latest);
    assert_eq!(part_rows.len(), 18);
    assert!(part_rows.iter().all(|r| r.5.is_none()));
    let c = CurateOptions {
        run_id: None,
        rule: Rule::MinWeight(0.0),
        min_episode_fraction: 0.0,
    };
    let cr = curate(&ds2, &c, meta("curate")).unwrap();
    assert_eq!(cr.frames_kept, 18);
    let curated = read_curated(&ds2, cr.version);
    for (r, c) in rows.iter().zip(&curated) {
        assert_eq!((&r.0, r.1), (&c.0, c.1));
        assert_eq!(r.5, Some(c.2), "{} {}", r.0, r.1);
    }
}

fn read_curated(ds: &Dataset, v: u64) -> Vec<(String, i32, f64)> {
    let mut out: Vec<(String, i32, f64)> = milv_data::read::rows::<CuratedRow>(ds, v)
        .unwrap()
        .into_iter()
        .map(|r| (r.episode_id, r.frame_index, r.weight))
        .collect();
    out.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    out
}

#[test]
fn curation_keeps_the_best_frames_and_replaces_the_previous_view() {
    let (_dir, ds, _) = good_dataset();
    score_dataset(&ds, None, &opts(Source::Frames), meta("score"), &|_| {}).unwrap();
    let c = |rule, frac| CurateOptions {
        run_id: None,
        rule,
        min_episode_fraction: frac,
    };
    let half = curate(&ds, &c(Rule::TopFraction(0.5), 0.0), meta("curate")).unwrap();
    assert_eq!(half.frames_kept, 9, "{half:?}");
    let rows = read_curated(&ds, half.version);
    assert_eq!(rows.len(), 9);
    assert!(rows.iter().all(|r| r.2 >= half.threshold));
    let all = curate(&ds, &c(Rule::MinWeight(0.0), 0.0), meta("curate")).unwrap();
    assert_eq!(
        read_curated(&ds, all.version).len(),
        18,
        "the new view replaces the old"
    );
    assert_eq!(
        read_curated(&ds, half.version).len(),
        9,
        "the old view stays readable"
    );
    // An episode keeping too few of its frames is dropped whole.
    let strict = curate(&ds, &c(Rule::TopFraction(0.5), 0.9), meta("curate")).unwrap();
    for id in read_curated(&ds, strict.version)
        .iter()
        .map(|r| r.0.clone())
        .collect::<BTreeSet<_>>()
    {
        let n = read_curated(&ds, strict.version)
            .iter()
            .filter(|r| r.0 == id)
            .count();
        assert!(
            n as f64
                >= 0.9
                    * if id == "h2" {
                        5.0
                    } else if id == "h1" {
                        6.0
                    } else {
                        7.0
                    }
        );
    }
    assert!(matches!(
        curate(&ds, &c(Rule::TopFraction(1.5), 0.0), meta("curate")),
        Err(Error::Invalid(_))
    ));
    let s = summarize(&ds, None, None, 3).unwrap();
    assert_eq!((s.frames, s.episodes.len(), s.worst_frames.len()), (18, 3, 3));
    assert!(s.episodes.windows(2).all(|w| w[0].beta_mean <= w[1].beta_mean));
    assert!(s.worst_frames.iter().all(|f| f.beta >= s.beta_min));
}

#[test]
fn bad_episodes_fail_the_run_clearly_and_nothing_is_committed() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    let mut bad = ep("bad", Domain::Human, 4, 6, FrameEncoding::Png);
    bad.corrupt = Some(3);
    let eps = vec![
        ep("good", Domain::Human, 1, 6, FrameEncoding::Png),
        bad,
        ep("one", Domain::Robot, 2, 1, FrameEncoding::Png),
    ];
    let v = commit_episodes(&ds, &eps);
    let err = score_dataset(&ds, None, &opts(Source::Frames), meta("score"), &|_| {}).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("episode bad: frame 3: undecodable image"), "{msg}");
    assert!(msg.contains("episode one: 1 frame(s)"), "{msg}");
    assert!(!msg.contains("episode good"), "{msg}");
    assert_eq!(ds.latest_version().unwrap(), v, "nothing committed");
    assert!(ds.files(TableKind::Scores, v).unwrap().is_empty());

    // --skip-bad commits the good episode and reports the others.
    let o = RunOptions {
        skip_bad: true,
        ..opts(Source::Frames)
    };
    let r = score_dataset(&ds, None, &o, meta("score"), &|_| {}).unwrap();
    assert_eq!((r.episodes_scored, r.failed.len()), (1, 2));
    assert_eq!(score_rows(&ds, r.version).len(), 6);

    // Empty selections.
    let o = RunOptions {
        domain: Some(Domain::Robot),
        episodes: Some(["good".to_string()].into()),
        ..opts(Source::Frames)
    };
    assert!(matches!(
        score_dataset(&ds, None, &o, meta("score"), &|_| {}),
        Err(Error::EmptySelection(_))
    ));
    assert!(matches!(
        score_dataset(&ds, None, &opts(Source::Imagined), meta("score"), &|_| {}),
        Err(Error::EmptySelection(_))
    ));
    let o = RunOptions {
        episodes: Some(["nope".to_string()].into()),
        ..opts(Source::Frames)
    };
    assert!(
        score_dataset(&ds, None, &o, meta("score"), &|_| {})
            .unwrap_err()
            .to_string()
            .contains("nope")
    );
}

#[test]
fn imagined_frames_are_scored_per_model_and_mixed_sizes_are_rejected() {
    let (_dir, ds, _) = good_dataset();
    commit_imagined(&ds, "h1", "model-a", &[(W, H); 4]);
    commit_imagined(&ds, "h2", "model-a", &[(W, H), (W, H), (W + 2, H), (W, H)]);
    commit_imagined(&ds, "h1", "model-b", &[(16, 16); 3]);
    let err = score_dataset(&ds, None, &opts(Source::Imagined), meta("score"), &|_| {}).unwrap_err();
    assert!(err.to_string().contains("2 models"), "{err}");
    let with = |m: &str| RunOptions {
        model_id: Some(m.into()),
        ..opts(Source::Imagined)
    };
    assert!(
        score_dataset(&ds, None, &with("model-z"), meta("score"), &|_| {})
            .unwrap_err()
            .to_string()
            .contains("model-z")
    );
    let v = ds.latest_version().unwrap();
    let err = score_dataset(&ds, None, &with("model-a"), meta("score"), &|_| {}).unwrap_err();
    assert!(
        err.to_string()
            .contains("episode h2: frame 2 is 26x20, frame 0 is 24x20"),
        "{err}"
    );
    assert_eq!(ds.latest_version().unwrap(), v);
    let r = score_dataset(&ds, None, &with("model-b"), meta("score"), &|_| {}).unwrap();
    assert_eq!((r.episodes_scored, r.frames_scored), (1, 3));
    assert_eq!(r.model_id.as_deref(), Some("model-b"));
}
