//! The dataset store end to end: commits, time travel, crash repair, concurrent writers,
//! maintenance — on real Delta tables in a temp folder.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeSet;

use milv_data::RowBuffer as _;
use milv_data::arrow::array::{Array, Int32Array, StringArray};
use milv_data::{
    CommitMeta, Dataset, Domain, Episode, FrameEncoding, FrameRows, Kind, ShardOptions, TableKind, ops,
};
use milv_fixtures::Frame;

fn meta(op: &str) -> CommitMeta {
    CommitMeta::for_this_process("store-test", op)
}

fn episode(id: &str, n: i64) -> Episode {
    Episode {
        kind: Kind::Random,
        task_id: Some("push/block".into()),
        task_family: Some("pushing".into()),
        frame_encoding: FrameEncoding::Raw,
        action_dim: Some(2),
        action_names: Some(vec!["dx".into(), "dy".into()]),
        source_sha256: "ab".into(),
        ..milv_fixtures::episode(id, Domain::Robot, n as usize, (2, 2))
    }
}

/// Commits episodes with `n` raw 2x2 frames each, as one version.
fn add_episodes(ds: &Dataset, ids: &[&str], n: i64, opts: ShardOptions) -> u64 {
    let eps: Vec<(Episode, Vec<Frame>)> = ids
        .iter()
        .map(|id| {
            let frames = (0..n)
                .map(|i| Frame {
                    action: Some(vec![i as f32, -1.0]),
                    ..Frame::image(vec![i as u8; 12])
                })
                .collect();
            (episode(id, n), frames)
        })
        .collect();
    // Three frames per batch: episodes span several batches.
    milv_fixtures::commit_episodes_with(ds, &eps, meta("ingest"), opts, 3).unwrap()
}

fn frame_ids(ds: &Dataset, v: u64) -> Vec<(String, i32)> {
    let mut out = Vec::new();
    for b in ds
        .scan(TableKind::Frames, v, Some(&["episode_id", "frame_index"]))
        .unwrap()
    {
        let b = b.unwrap();
        let ids = b.column(0).as_any().downcast_ref::<StringArray>().unwrap();
        let idx = b.column(1).as_any().downcast_ref::<Int32Array>().unwrap();
        for i in 0..b.num_rows() {
            out.push((ids.value(i).to_string(), idx.value(i)));
        }
    }
    out.sort();
    out
}

#[test]
fn commits_are_versions_and_old_versions_stay_readable() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    assert_eq!(ds.latest_version().unwrap(), 0);
    assert_eq!(add_episodes(&ds, &["a", "b"], 5, ShardOptions::default()), 1);
    assert_eq!(add_episodes(&ds, &["c"], 4, ShardOptions::default()), 2);
    assert_eq!(frame_ids(&ds, 1).len(), 10);
    assert_eq!(frame_ids(&ds, 2).len(), 14);
    assert_eq!(ops::episodes(&ds, 1).unwrap().len(), 2);
    assert_eq!(ops::episodes(&ds, 0).unwrap().len(), 0);
    // Delta agrees with the log at every version, and commit info carries the command.
    let pinned = ds.pinned_delta_versions(2).unwrap();
    assert_eq!(pinned[&TableKind::Frames], 2); // created at 0, then one commit per version
    let rep = ops::verify(&ds, 2, |_| {}).unwrap();
    assert!(rep.ok(), "{:?}", rep.problems);
    assert_eq!(rep.frames_decoded, 14);
    let e = ds.entry(2).unwrap();
    assert_eq!(e.meta.operation, "ingest");
    assert!(!e.meta.command.is_empty());
    assert!(matches!(
        ds.resolve(Some(7)),
        Err(milv_data::Error::NoSuchVersion { .. })
    ));
}

#[test]
fn long_episodes_stream_to_their_own_file_and_abort_cleans_up() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    let tiny = ShardOptions {
        episode_buffer_bytes: 64,
        max_row_group_bytes: 64,
        ..ShardOptions::default()
    };
    add_episodes(&ds, &["long1", "long2"], 30, tiny.clone());
    let files = ds.files(TableKind::Frames, 1).unwrap();
    assert_eq!(files.len(), 2, "each spilled episode has its own file");
    assert_eq!(frame_ids(&ds, 1).len(), 60);

    let txn = ds.begin(meta("ingest")).unwrap();
    let mut w = txn.shard_writer(TableKind::Frames, tiny).unwrap();
    w.begin_episode().unwrap();
    for i in 0..10 {
        let mut rows = FrameRows::new();
        rows.push("doomed", i, 0, &[0; 12], None, None);
        w.push(rows.finish().unwrap()).unwrap();
    }
    w.abort_episode();
    assert!(w.finish().unwrap().is_empty());
    let parquet = std::fs::read_dir(ds.table_root(TableKind::Frames))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "parquet")
        })
        .count();
    assert_eq!(parquet, 2, "the aborted episode's file is gone");
}

#[test]
fn a_logged_version_missing_from_delta_is_rolled_forward_once() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    add_episodes(&ds, &["a"], 3, ShardOptions::default());
    // Simulate a writer that died after creating entry 2 but before any Delta commit:
    // copy entry 1's changes under a new number with fresh files.
    let mut e = ds.entry(1).unwrap();
    for (t, c) in e.tables.iter_mut() {
        for f in c.add.iter_mut() {
            let root = dir.path().join(t);
            let new = format!("copy-{}", f.path);
            std::fs::copy(root.join(&f.path), root.join(&new)).unwrap();
            f.path = new;
        }
        c.episodes_added = vec!["a-copy".into()];
    }
    e.version = 2;
    e.parent = Some(1);
    let text = serde_json::to_vec(&e).unwrap();
    std::fs::write(dir.path().join("_milv/versions/00000000000000000002.json"), text).unwrap();
    let pending = ds.pending().unwrap();
    assert_eq!(pending.len(), 2, "{pending:?}");
    assert_eq!(ds.roll_forward().unwrap(), 2);
    assert_eq!(ds.roll_forward().unwrap(), 0, "idempotent");
    assert_eq!(ds.pinned_delta_versions(2).unwrap()[&TableKind::Frames], 2);
}

#[test]
fn concurrent_writers_all_land() {
    let dir = tempfile::tempdir().unwrap();
    Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    let threads: Vec<_> = (0..4)
        .map(|t| {
            let root = dir.path().to_path_buf();
            std::thread::spawn(move || {
                let ds = Dataset::open(&root).unwrap();
                for i in 0..5 {
                    let id = format!("w{t}-{i}");
                    add_episodes(&ds, &[&id], 2, ShardOptions::default());
                }
            })
        })
        .collect();
    for t in threads {
        t.join().unwrap();
    }
    let ds = Dataset::open(dir.path()).unwrap();
    assert_eq!(ds.latest_version().unwrap(), 20);
    assert_eq!(ops::episodes(&ds, 20).unwrap().len(), 20);
    assert_eq!(frame_ids(&ds, 20).len(), 40);
    assert!(ds.pending().unwrap().is_empty());
    let rep = ops::verify(&ds, 20, |_| {}).unwrap();
    assert!(rep.ok(), "{:?}", rep.problems);
}

#[test]
fn adding_an_episode_twice_concurrently_conflicts() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    // Plan a transaction, let another writer land the same episode, then commit.
    let mut txn = ds.begin(meta("ingest")).unwrap();
    add_episodes(&ds, &["same"], 2, ShardOptions::default());
    std::fs::write(ds.table_root(TableKind::Frames).join("x.parquet"), b"x").unwrap();
    txn.add_files(TableKind::Episodes, Vec::new(), vec!["same".into()]);
    txn.add_files(
        TableKind::Frames,
        vec![milv_data::FileAdd {
            path: "x.parquet".into(),
            size: 1,
            num_records: 1,
            min_episode: None,
            max_episode: None,
            modification_time_ms: 0,
        }],
        vec!["same".into()],
    );
    let e = txn.commit().unwrap_err();
    assert!(matches!(e, milv_data::Error::Conflict(_)), "{e}");
    assert_eq!(ds.latest_version().unwrap(), 1);
}

#[test]
fn delete_compact_and_vacuum() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    add_episodes(&ds, &["a", "b"], 4, ShardOptions::default());
    add_episodes(&ds, &["c"], 4, ShardOptions::default());
    add_episodes(&ds, &["d"], 4, ShardOptions::default());
    let v = ops::delete_episodes(&ds, &["b".into()], meta("delete-episodes")).unwrap();
    assert_eq!(v, 4);
    let ids: BTreeSet<String> = frame_ids(&ds, v).into_iter().map(|(e, _)| e).collect();
    assert_eq!(ids, ["a", "c", "d"].iter().map(|s| s.to_string()).collect());
    assert_eq!(ops::episodes(&ds, v).unwrap().len(), 3);
    assert_eq!(frame_ids(&ds, 3).len(), 16, "time travel still sees b");
    assert!(ops::delete_episodes(&ds, &["zz".into()], meta("delete-episodes")).is_err());

    let before = frame_ids(&ds, v);
    let (v2, replaced) = ops::compact(&ds, &ShardOptions::default(), meta("compact")).unwrap();
    assert!(replaced >= 3, "{replaced}");
    assert_eq!(ds.files(TableKind::Frames, v2).unwrap().len(), 1);
    assert_eq!(frame_ids(&ds, v2), before);
    let rep = ops::verify(&ds, v2, |_| {}).unwrap();
    assert!(rep.ok(), "{:?}", rep.problems);

    // Retaining 0 hours removes every file the latest version doesn't use.
    let deleted = ops::vacuum(&ds, 0, false).unwrap();
    assert!(!deleted.is_empty());
    assert!(ops::verify(&ds, v2, |_| {}).unwrap().ok());
    assert!(
        ds.scan(TableKind::Frames, 1, None).unwrap().any(|b| b.is_err()),
        "v1's files are gone"
    );
}

#[test]
fn a_version_never_names_a_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::open_or_create(dir.path(), meta("create")).unwrap();
    let mut txn = ds.begin(meta("ingest")).unwrap();
    let gone = milv_data::FileAdd {
        path: "vacuumed.parquet".into(),
        size: 10,
        num_records: 1,
        min_episode: None,
        max_episode: None,
        modification_time_ms: 0,
    };
    txn.add_files(TableKind::Frames, vec![gone], vec!["e".into()]);
    let e = txn.commit().unwrap_err().to_string();
    assert!(e.contains("vacuumed.parquet"), "{e}");
    assert_eq!(ds.latest_version().unwrap(), 0);
}
