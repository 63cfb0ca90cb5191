//! LeRobot v3.0 episodes as ingest inputs: the digests of the dataset's files and one
//! [`Planned`] episode per LeRobot episode (its actions and states in a synthetic sidecar,
//! its frames read through [`milv_lerobot::LeRobotDataset::frames`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::Arc;

use milv_data::InputDigest;
use milv_lerobot::{FrameLocation, LeRobotDataset};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::ingest::{IngestOptions, Planned, episode_id, resolve_meta, source_digest};
use crate::manifest::InputSpec;
use crate::sidecar::{EpisodeMeta, Sidecar};

/// sha256 of every file the planned episodes read (metadata, data, videos), each once.
pub(crate) fn file_digests(lr: &LeRobotDataset) -> Result<BTreeMap<PathBuf, String>> {
    let mut files: BTreeSet<PathBuf> = [
        lr.root.join(milv_lerobot::format::INFO_PATH),
        lr.root.join(milv_lerobot::format::TASKS_PATH),
    ]
    .into();
    for ep in lr.episodes.iter().flatten() {
        files.insert(ep.data_file.clone());
        if let FrameLocation::Video { path, .. } = &ep.frames {
            files.insert(path.clone());
        }
    }
    let files: Vec<PathBuf> = files.into_iter().collect();
    // A file that cannot be read fails only the episodes that need it (at planning).
    Ok(files
        .par_iter()
        .filter_map(|f| source_digest(f).ok().map(|d| (f.clone(), d)))
        .collect())
}

/// Plans LeRobot episode `i`.
pub(crate) fn plan_episode(
    lr: &Arc<LeRobotDataset>,
    i: usize,
    digests: &BTreeMap<PathBuf, String>,
    opts: &IngestOptions,
) -> Result<Planned> {
    let ep = match &lr.episodes[i] {
        Ok(ep) => ep.clone(),
        Err(e) => return Err(Error::input(&lr.root, e.to_string())),
    };
    let digest = |p: &PathBuf| {
        digests
            .get(p)
            .cloned()
            .ok_or_else(|| Error::input(p, format!("episode {}: cannot read this file", ep.index)))
    };
    let frames_file = match &ep.frames {
        FrameLocation::Video { path, .. } => path.clone(),
        FrameLocation::Images { path, .. } => path.clone(),
    };
    let source_sha256 = digest(&frames_file)?;
    let data_sha256 = digest(&ep.data_file)?;
    let info_sha256 = digest(&lr.root.join(milv_lerobot::format::INFO_PATH))?;
    if opts.require_actions && ep.actions.is_none() {
        return Err(Error::input(
            &ep.data_file,
            format!("--require-actions: episode {} has no action feature", ep.index),
        ));
    }
    let uri = lr.episode_uri(&ep);
    let spec = InputSpec {
        path: PathBuf::from(&uri),
        sidecar: None,
        meta: EpisodeMeta {
            task_id: Some(ep.task.clone()),
            split: Some(ep.split.clone()),
            ..Default::default()
        },
    };
    let meta = resolve_meta(&spec, None, &opts.defaults)?;
    let origin = serde_json::json!({
        "lerobot_episode": ep.index,
        "camera": lr.camera.key,
        "info_sha256": info_sha256,
    });
    let episode_id = episode_id(&source_sha256, Some(&data_sha256), &meta, opts, Some(&origin));
    let sidecar = Sidecar {
        path: ep.data_file.clone(),
        meta: EpisodeMeta::default(),
        action_names: lr.action.as_ref().and_then(|f| f.names.clone()),
        state_names: lr.state.as_ref().and_then(|f| f.names.clone()),
        actions: ep.actions.clone(),
        states: ep.states.clone(),
    };
    let mut inputs = vec![
        InputDigest {
            uri: lr
                .root
                .join(milv_lerobot::format::INFO_PATH)
                .display()
                .to_string(),
            sha256: info_sha256,
        },
        InputDigest {
            uri: ep.data_file.display().to_string(),
            sha256: data_sha256.clone(),
        },
    ];
    if frames_file != ep.data_file {
        inputs.push(InputDigest {
            uri: frames_file.display().to_string(),
            sha256: source_sha256.clone(),
        });
    }
    Ok(Planned {
        source: PathBuf::from(uri),
        sidecar: Some(sidecar),
        meta,
        source_sha256,
        episode_id,
        inputs,
        lerobot: Some(Arc::new((lr.clone(), ep))),
    })
}
