//! Applying version-log entries to the Delta tables, and reading Delta's side back.
//!
//! Each entry becomes exactly one Delta commit per table it touches, carrying the
//! application transaction `(milv, N)`. Commits are attempted without Delta's automatic
//! retry: on a lost race we reload and look at the table's `milv` transaction version
//! again, so two processes rolling the same entry forward never apply it twice.

use std::collections::{BTreeMap, HashMap};

use deltalake::kernel::engine::arrow_conversion::TryIntoKernel as _;
use deltalake::kernel::transaction::{CommitBuilder, CommitProperties, TransactionError};
use deltalake::kernel::{Action, Add, Remove, StructType, Transaction};
use deltalake::protocol::{DeltaOperation, SaveMode};
use deltalake::{DeltaTable, DeltaTableBuilder, DeltaTableError};
use futures::TryStreamExt as _;
use serde_json::{Value, json};

use crate::error::{Error, Result};
use crate::log::{FileAdd, VersionEntry};
use crate::schema::TableKind;
use crate::store::Root;

/// Application id of MILV's Delta transactions.
pub const APP_ID: &str = "milv";

pub(crate) fn table_url(root: &Root, table: TableKind) -> Result<url::Url> {
    root.table_url(table.name())
}

/// A table exists once its first commit does (a crash mid-creation leaves a bare folder).
pub(crate) fn has_delta_log(root: &Root, table: TableKind) -> Result<bool> {
    Ok(root
        .size(&format!("{}/_delta_log/00000000000000000000.json", table.name()))?
        .is_some())
}

/// How errors name a table: its folder or URL.
fn label(root: &Root, table: TableKind) -> String {
    root.label_of(table.name()).display().to_string()
}

/// Opens a table at its latest version, creating it (empty, Delta version 0) if needed.
pub(crate) async fn open_or_create(root: &Root, table: TableKind) -> Result<DeltaTable> {
    let url = table_url(root, table)?;
    if !has_delta_log(root, table)? {
        let schema: StructType =
            table
                .arrow_schema()
                .as_ref()
                .try_into_kernel()
                .map_err(|e| Error::Schema {
                    table: table.name().into(),
                    msg: e.to_string(),
                })?;
        let created = deltalake::operations::create::CreateBuilder::new()
            .with_location(url.as_str())
            .with_table_name(table.name())
            .with_comment(table.description())
            .with_columns(schema.fields().cloned())
            .with_save_mode(SaveMode::ErrorIfExists)
            .await;
        match created {
            Ok(t) => return Ok(t),
            // Lost a creation race to another process: fine, open theirs.
            Err(DeltaTableError::VersionAlreadyExists(_)) => {}
            Err(_) if has_delta_log(root, table).unwrap_or(false) => {}
            Err(e) => return Err(Error::delta(&label(root, table))(e)),
        }
    }
    DeltaTableBuilder::from_url(url)
        .map_err(Error::delta(&label(root, table)))?
        .load()
        .await
        .map_err(Error::delta(&label(root, table)))
}

/// The table's `milv` application transaction version: the last dataset version applied.
pub(crate) async fn applied_version(root: &Root, table: &DeltaTable, kind: TableKind) -> Result<Option<u64>> {
    let v = table
        .snapshot()
        .map_err(Error::delta(&label(root, kind)))?
        .transaction_version(table.log_store().as_ref(), APP_ID)
        .await
        .map_err(Error::delta(&label(root, kind)))?;
    Ok(v.and_then(|v| u64::try_from(v).ok()))
}

fn add_action(f: &FileAdd, data_change: bool) -> Action {
    let mut stats = json!({ "numRecords": f.num_records });
    if let (Some(lo), Some(hi)) = (&f.min_episode, &f.max_episode) {
        stats["minValues"] = json!({ "episode_id": lo });
        stats["maxValues"] = json!({ "episode_id": hi });
        stats["nullCount"] = json!({ "episode_id": 0 });
    }
    Action::Add(Add {
        path: f.path.clone(),
        partition_values: HashMap::new(),
        size: f.size as i64,
        modification_time: f.modification_time_ms,
        data_change,
        stats: Some(stats.to_string()),
        tags: None,
        deletion_vector: None,
        base_row_id: None,
        default_row_commit_version: None,
        clustering_provider: None,
    })
}

fn remove_action(path: &str, now_ms: i64, data_change: bool) -> Action {
    Action::Remove(Remove {
        path: path.to_string(),
        data_change,
        deletion_timestamp: Some(now_ms),
        extended_file_metadata: None,
        partition_values: None,
        size: None,
        tags: None,
        deletion_vector: None,
        base_row_id: None,
        default_row_commit_version: None,
    })
}

/// Applies one entry to one table unless the table already has it.
pub(crate) async fn apply(root: &Root, kind: TableKind, entry: &VersionEntry) -> Result<()> {
    let Some(change) = entry.tables.get(kind.name()) else {
        return Ok(());
    };
    let mut table = open_or_create(root, kind).await?;
    loop {
        if applied_version(root, &table, kind).await? >= Some(entry.version) {
            return Ok(());
        }
        let read_version = table.version().unwrap_or(0);
        let now_ms = chrono_now_ms();
        // Compaction rewrites rows without changing them: streaming readers may skip it.
        let data_change = entry.meta.operation != "compact";
        let mut actions: Vec<Action> = change.add.iter().map(|f| add_action(f, data_change)).collect();
        actions.extend(
            change
                .remove
                .iter()
                .map(|p| remove_action(p, now_ms, data_change)),
        );
        let operation = if change.remove.is_empty() {
            DeltaOperation::Write {
                mode: SaveMode::Append,
                partition_by: None,
                predicate: None,
            }
        } else {
            DeltaOperation::Delete {
                predicate: Some(format!("milv {}", entry.meta.operation)),
            }
        };
        let app_metadata: HashMap<String, Value> = [
            ("milv.dataset_version", json!(entry.version)),
            ("milv.table_version", json!(read_version + 1)),
            ("milv.operation", json!(entry.meta.operation)),
            ("milv.command", json!(entry.meta.command)),
            ("milv.tool_version", json!(entry.meta.tool_version)),
            ("milv.inputs", json!(entry.meta.inputs)),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        let snapshot = table.snapshot().map_err(Error::delta(&label(root, kind)))?;
        let props = CommitProperties::default()
            .with_metadata(app_metadata)
            .with_application_transaction(Transaction::new_with_last_update(
                APP_ID,
                entry.version as i64,
                Some(now_ms),
            ))
            // No automatic retry: a lost race is re-examined above (was it our entry?).
            .with_max_retries(0)
            // Old dataset versions map to Delta versions through this history: keep it.
            .with_cleanup_expired_logs(Some(false));
        let result = CommitBuilder::from(props)
            .with_actions(actions)
            .build(Some(snapshot), table.log_store(), operation)
            .await;
        match result {
            Ok(_) => return Ok(()),
            // Someone else committed that table version first; look again.
            Err(DeltaTableError::VersionAlreadyExists(_))
            | Err(DeltaTableError::Transaction {
                source: TransactionError::MaxCommitAttempts(_) | TransactionError::VersionAlreadyExists(_),
            }) => {
                table
                    .update_state()
                    .await
                    .map_err(Error::delta(&label(root, kind)))?;
            }
            Err(e) => return Err(Error::delta(&label(root, kind))(e)),
        }
    }
}

fn chrono_now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// Dataset version -> Delta version of the commit that applied it, from the table history.
pub(crate) async fn version_map(root: &Root, kind: TableKind) -> Result<BTreeMap<u64, u64>> {
    if !has_delta_log(root, kind)? {
        return Ok(BTreeMap::new());
    }
    let table = open_or_create(root, kind).await?;
    let infos: Vec<_> = table
        .history(None)
        .try_collect()
        .await
        .map_err(Error::delta(&label(root, kind)))?;
    let mut out = BTreeMap::new();
    for info in infos {
        let dv = info.info.get("milv.dataset_version").and_then(Value::as_u64);
        let tv = info.info.get("milv.table_version").and_then(Value::as_u64);
        if let (Some(dv), Some(tv)) = (dv, tv) {
            out.insert(dv, tv);
        }
    }
    Ok(out)
}

/// Relative paths of the files of a table at a Delta version.
pub(crate) async fn files_at(root: &Root, kind: TableKind, delta_version: u64) -> Result<Vec<String>> {
    let url = table_url(root, kind)?;
    let table = DeltaTableBuilder::from_url(url)
        .map_err(Error::delta(&label(root, kind)))?
        .with_version(delta_version)
        .load()
        .await
        .map_err(Error::delta(&label(root, kind)))?;
    let snapshot = table.snapshot().map_err(Error::delta(&label(root, kind)))?;
    let mut paths: Vec<String> = snapshot.log_data().iter().map(|f| f.path().to_string()).collect();
    paths.sort();
    Ok(paths)
}

/// Delta's vacuum in full mode (also removes files no commit ever referenced).
pub(crate) async fn vacuum(
    root: &Root,
    table: DeltaTable,
    kind: TableKind,
    retain_hours: u64,
    dry_run: bool,
) -> Result<Vec<String>> {
    let (_, metrics) = table
        .vacuum()
        .with_mode(deltalake::operations::vacuum::VacuumMode::Full)
        .with_retention_period(chrono::Duration::hours(retain_hours as i64))
        .with_enforce_retention_duration(false)
        .with_dry_run(dry_run)
        .await
        .map_err(Error::delta(&label(root, kind)))?;
    Ok(metrics.files_deleted)
}
