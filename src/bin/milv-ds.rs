//! `milv-ds`: inspect and maintain a MILV dataset.

use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use milv::cli;
use milv::data::{CommitMeta, Dataset, DatasetRef, ShardOptions, TableKind, ops};

/// Inspect and maintain a versioned MILV dataset.
///
/// DATASET is a folder; DATASET@N names version N (time travel). Commands that change the
/// dataset (delete-episodes, compact) add one version each; vacuum deletes files only old
/// versions need.
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Tables, versions, episode and frame counts per domain/kind/task.
    Info {
        dataset: DatasetRef,
        #[arg(long)]
        json: bool,
    },
    /// LeRobot's statistics of a pinned version (min, max, mean, std, count, q01, q10,
    /// q50, q90, q99 per feature; images per channel over /255), as JSON — exactly what
    /// `milv-export lerobot` writes to meta/stats.json for the same version and table, so
    /// normalisation constants can never be stale.
    Stats {
        dataset: DatasetRef,
        /// Which rows: frames (recorded), imagined (one model's translations) or curated.
        #[arg(long, default_value = "frames", value_parser = ["frames", "imagined", "curated"])]
        table: String,
        /// Translation model for --table imagined (default: the only one).
        #[arg(long)]
        model_id: Option<String>,
    },
    /// Versions with their command lines, and the Delta table versions each pins.
    Log {
        dataset: DatasetRef,
        #[arg(long)]
        json: bool,
    },
    /// Reads every file: row counts against the log, frames decode, Delta agrees.
    /// Exit code 1 if anything is wrong.
    Verify {
        dataset: DatasetRef,
        /// First commit logged versions that a crashed writer left uncommitted in Delta.
        #[arg(long)]
        repair: bool,
        #[arg(long)]
        json: bool,
    },
    /// Removes episodes (all their rows in every table) as a new version.
    DeleteEpisodes {
        dataset: DatasetRef,
        /// Episode ids.
        #[arg(required = true)]
        episode_ids: Vec<String>,
        #[arg(long)]
        json: bool,
    },
    /// Merges small Parquet files into shards of the target size, as a new version.
    Compact {
        dataset: DatasetRef,
        #[arg(long, default_value_t = 128)]
        target_mb: u64,
        #[arg(long)]
        json: bool,
    },
    /// Deletes data files that no version younger than --retain-hours needs, files left by
    /// writers that died before committing, and their stale resume journals. Older
    /// versions become unreadable. A retention shorter than a running ingest can delete
    /// that ingest's new files: it then fails its commit (nothing half-committed) and must
    /// be re-run.
    Vacuum {
        dataset: DatasetRef,
        #[arg(long, default_value_t = 168)]
        retain_hours: u64,
        #[arg(long)]
        dry_run: bool,
        #[arg(long)]
        json: bool,
    },
}

fn open(r: &DatasetRef) -> anyhow::Result<(Dataset, u64)> {
    let ds = Dataset::open(&r.root).with_context(|| format!("opening {r}"))?;
    let v = ds.resolve(r.version)?;
    Ok((ds, v))
}

fn writable(r: &DatasetRef) -> anyhow::Result<Dataset> {
    if r.version.is_some() {
        anyhow::bail!("{r}: changes always apply to the latest version; drop the @N");
    }
    Dataset::open(&r.root).with_context(|| format!("opening {r}"))
}

fn print_info(i: &ops::Info) {
    println!(
        "dataset {} @ version {} (latest {})",
        i.path, i.version, i.latest_version
    );
    println!(
        "{:<10} {:>6} {:>10} {:>12} {:>6}",
        "table", "files", "rows", "size", "delta"
    );
    for (name, t) in &i.tables {
        let dv = t.delta_version.map_or_else(|| "-".into(), |v| v.to_string());
        println!(
            "{:<10} {:>6} {:>10} {:>12} {:>6}",
            name,
            t.files,
            t.rows,
            cli::human_bytes(t.bytes),
            dv
        );
    }
    println!("episodes {} frames {}", i.episodes, i.frames);
    for (k, n) in &i.by_domain_kind {
        println!("  {k:<16} {n:>6} episodes");
    }
    println!("by task:");
    for (t, (e, f)) in &i.by_task {
        println!("  {t:<24} {e:>6} episodes {f:>8} frames");
    }
    if i.pending_delta_commits > 0 {
        println!(
            "note: {} logged table commits not yet in Delta (any write or `verify --repair` completes them)",
            i.pending_delta_commits
        );
    }
}

#[derive(serde::Serialize)]
struct LogRow {
    version: u64,
    parent: Option<u64>,
    timestamp_ms: i64,
    operation: String,
    command: String,
    tool_version: String,
    tables: std::collections::BTreeMap<String, u64>,
    changes: std::collections::BTreeMap<String, (usize, usize)>,
}

fn log_rows(ds: &Dataset) -> anyhow::Result<Vec<LogRow>> {
    let maps = ds.delta_versions()?;
    let latest = ds.latest_version()?;
    let mut rows = Vec::new();
    for e in ds.entries_until(latest)? {
        let tables = maps
            .iter()
            .filter_map(|(t, m)| {
                m.range(..=e.version)
                    .next_back()
                    .map(|(_, tv)| (t.name().to_string(), *tv))
            })
            .collect();
        let changes = e
            .tables
            .iter()
            .map(|(t, c)| (t.clone(), (c.add.len(), c.remove.len())))
            .collect();
        rows.push(LogRow {
            version: e.version,
            parent: e.parent,
            timestamp_ms: e.timestamp_ms,
            operation: e.meta.operation.clone(),
            command: e.meta.command.join(" "),
            tool_version: e.meta.tool_version.clone(),
            tables,
            changes,
        });
    }
    Ok(rows)
}

fn run(args: Args) -> anyhow::Result<u8> {
    match args.cmd {
        Cmd::Info { dataset, json } => {
            let (ds, v) = open(&dataset)?;
            let info = ops::info(&ds, v)?;
            if json {
                cli::print_json(&info)?
            } else {
                print_info(&info)
            }
        }
        Cmd::Stats {
            dataset,
            table,
            model_id,
        } => {
            let (ds, v) = open(&dataset)?;
            let opts = milv::lerobot::ExportOptions {
                source: table.parse().map_err(anyhow::Error::msg)?,
                video: false,
                gop: milv::lerobot::write::DEFAULT_GOP,
                model_id,
            };
            cli::print_json(&milv::lerobot::write::stats(&ds, v, &opts)?)?;
        }
        Cmd::Log { dataset, json } => {
            let (ds, _) = open(&dataset)?;
            let rows = log_rows(&ds)?;
            if json {
                cli::print_json(&rows)?;
            } else {
                for r in rows {
                    let t: Vec<String> = r.tables.iter().map(|(k, v)| format!("{k}@{v}")).collect();
                    println!(
                        "v{:<4} {:<16} [{}]  {}",
                        r.version,
                        r.operation,
                        t.join(" "),
                        r.command
                    );
                }
            }
        }
        Cmd::Verify {
            dataset,
            repair,
            json,
        } => {
            let (ds, v) = open(&dataset)?;
            if repair {
                let n = ds.roll_forward()?;
                if n > 0 && !json {
                    println!("repaired: committed {n} pending table versions to Delta");
                }
            }
            let total: u64 = ds
                .files(TableKind::Frames, v)?
                .iter()
                .map(|f| f.info.num_records)
                .sum();
            let pb = cli::bar(total, "frames");
            let rep = ops::verify(&ds, v, |n| pb.inc(n))?;
            pb.finish_and_clear();
            if json {
                cli::print_json(&rep)?;
            } else {
                for p in &rep.problems {
                    println!("problem: {p}");
                }
                for d in &rep.duplicates {
                    println!("warning: {d}");
                }
                println!(
                    "{}@{}: {} files, {} rows, {} frames decoded: {}",
                    ds.root().display(),
                    v,
                    rep.files_checked,
                    rep.rows_checked,
                    rep.frames_decoded,
                    if rep.ok() { "OK" } else { "PROBLEMS FOUND" }
                );
            }
            return Ok(if rep.ok() { cli::EXIT_OK } else { cli::EXIT_FATAL });
        }
        Cmd::DeleteEpisodes {
            dataset,
            episode_ids,
            json,
        } => {
            let ds = writable(&dataset)?;
            let v = ops::delete_episodes(
                &ds,
                &episode_ids,
                CommitMeta::for_this_process("milv-ds", "delete-episodes"),
            )?;
            if json {
                cli::print_json(&serde_json::json!({"version": v, "deleted": episode_ids}))?;
            } else {
                println!(
                    "{}@{v}: deleted {} episodes",
                    ds.root().display(),
                    episode_ids.len()
                );
            }
        }
        Cmd::Compact {
            dataset,
            target_mb,
            json,
        } => {
            let ds = writable(&dataset)?;
            let opts = ShardOptions {
                target_file_bytes: target_mb << 20,
                ..ShardOptions::default()
            };
            let (v, n) = ops::compact(&ds, &opts, CommitMeta::for_this_process("milv-ds", "compact"))?;
            if json {
                cli::print_json(&serde_json::json!({"version": v, "files_replaced": n}))?;
            } else {
                println!("{}@{v}: replaced {n} small files", ds.root().display());
            }
        }
        Cmd::Vacuum {
            dataset,
            retain_hours,
            dry_run,
            json,
        } => {
            let ds = writable(&dataset)?;
            let deleted = ops::vacuum(&ds, retain_hours, dry_run)?;
            if json {
                cli::print_json(&serde_json::json!({"dry_run": dry_run, "deleted": deleted}))?;
            } else {
                for d in &deleted {
                    println!("{} {d}", if dry_run { "would delete" } else { "deleted" });
                }
                println!("{} files", deleted.len());
            }
        }
    }
    Ok(cli::EXIT_OK)
}

fn main() -> ExitCode {
    cli::finish("milv-ds", run(Args::parse()))
}
