//! Writing a table group by group: the one path by which stages add rows.
//!
//! A *group* is the unit a stage produces and a table is keyed by (an episode's frames,
//! scores or translation; a pair's alignment cells). A *run* names what produced the
//! rows (a scoring run, an alignment run, a translation model); see
//! [`TableKind::run_column`]. [`Transaction::write_groups`] skips the groups the same run
//! already holds at the transaction's base version, so re-running a stage on the same
//! inputs writes nothing and commits nothing: idempotence is a property of the writer,
//! not of each stage.

use std::collections::BTreeSet;

use crate::dataset::Transaction;
use crate::error::{Error, Result};
use crate::read::run_groups;
use crate::rows::{Episode, Row, RowBuffer};
use crate::schema::TableKind;
use crate::shard::{ShardOptions, ShardWriter};

/// What [`Transaction::write_groups`] added.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Written {
    /// Groups written, in order.
    pub groups: Vec<String>,
    /// Groups the run already held, left alone.
    pub skipped: Vec<String>,
}

/// Writes the groups of one table inside [`Transaction::write_groups`].
pub struct GroupWriter {
    table: TableKind,
    shard: ShardWriter,
    /// Groups of this run already in the table (at the transaction's base version).
    present: BTreeSet<String>,
    open: Option<String>,
    written: Written,
}

impl GroupWriter {
    /// The run already holds this group (a re-run skips it).
    pub fn contains(&self, group: &str) -> bool {
        self.present.contains(group) || self.written.groups.iter().any(|g| g == group)
    }

    /// Writes one whole group; `false` (and nothing written) when the run already has it.
    pub fn group<R: Row>(&mut self, group: &str, rows: &[R]) -> Result<bool> {
        self.check_table(R::TABLE)?;
        if let Some(r) = rows.iter().find(|r| r.group() != group) {
            return Err(Error::Invalid(format!(
                "{} group {group}: a row of group {} was handed in",
                self.table,
                r.group()
            )));
        }
        if !self.begin(group)? {
            return Ok(false);
        }
        self.shard.push(R::to_batch(rows)?)?;
        self.end()?;
        Ok(true)
    }

    /// Starts a group whose rows are streamed with [`GroupWriter::push`]; `false` when
    /// the run already has it (then nothing is open and nothing may be pushed).
    pub fn begin(&mut self, group: &str) -> Result<bool> {
        if let Some(open) = &self.open {
            return Err(Error::Invalid(format!(
                "{} group {group} begun while group {open} is open",
                self.table
            )));
        }
        if self.contains(group) {
            self.written.skipped.push(group.to_string());
            return Ok(false);
        }
        self.shard.begin_episode()?;
        self.open = Some(group.to_string());
        Ok(true)
    }

    /// Adds the buffered rows to the open group.
    pub fn push<B: RowBuffer>(&mut self, rows: &mut B) -> Result<()> {
        self.check_table(B::TABLE)?;
        if self.open.is_none() {
            return Err(Error::Invalid(format!(
                "{} rows pushed outside a group",
                self.table
            )));
        }
        if rows.is_empty() {
            return Ok(());
        }
        self.shard.push(rows.finish()?)
    }

    /// Ends the open group: its rows become part of the change.
    pub fn end(&mut self) -> Result<()> {
        let group = self
            .open
            .take()
            .ok_or_else(|| Error::Invalid(format!("{}: end of a group that was not begun", self.table)))?;
        self.shard.end_episode()?;
        self.written.groups.push(group);
        Ok(())
    }

    fn check_table(&self, table: TableKind) -> Result<()> {
        if table == self.table {
            Ok(())
        } else {
            Err(Error::Invalid(format!(
                "{table} rows handed to the writer of table {}",
                self.table
            )))
        }
    }
}

impl Transaction<'_> {
    /// Writes the groups `fill` hands to the writer into new files of `table` and adds
    /// them to this change. With a `run` (the value of the table's
    /// [`run_column`](TableKind::run_column)), groups that run already holds at the base
    /// version are skipped. On an error nothing is added and the files written so far
    /// are deleted.
    pub fn write_groups<E: From<Error>>(
        &mut self,
        table: TableKind,
        run: Option<&str>,
        opts: ShardOptions,
        fill: impl FnOnce(&mut GroupWriter) -> std::result::Result<(), E>,
    ) -> std::result::Result<Written, E> {
        let present = match run {
            Some(r) => run_groups(self.dataset(), self.base_version(), table, r)?,
            None => BTreeSet::new(),
        };
        let mut w = GroupWriter {
            table,
            shard: self.shard_writer(table, opts)?,
            present,
            open: None,
            written: Written::default(),
        };
        if let Err(e) = fill(&mut w) {
            w.shard.abort();
            return Err(e);
        }
        if let Some(open) = &w.open {
            let e = Error::Invalid(format!("{table} group {open} was begun and never ended"));
            w.shard.abort();
            return Err(e.into());
        }
        let files = w.shard.finish()?;
        self.add_files(table, files, w.written.groups.clone());
        Ok(w.written)
    }

    /// [`Transaction::write_groups`], then the commit: the new version, or the base
    /// version when the run already held every group. On an error nothing is committed
    /// and every file this transaction wrote is deleted.
    pub fn write_and_commit<E: From<Error>>(
        mut self,
        table: TableKind,
        run: Option<&str>,
        opts: ShardOptions,
        fill: impl FnOnce(&mut GroupWriter) -> std::result::Result<(), E>,
    ) -> std::result::Result<u64, E> {
        if let Err(e) = self.write_groups(table, run, opts, fill) {
            self.abort();
            return Err(e);
        }
        Ok(self.commit()?)
    }

    /// Adds these rows to the `episodes` table, one group per episode.
    pub fn add_episode_rows(&mut self, episodes: &[Episode]) -> Result<Written> {
        self.write_groups(
            TableKind::Episodes,
            None,
            ShardOptions::default(),
            |w| -> Result<()> {
                for e in episodes {
                    w.group(&e.episode_id, std::slice::from_ref(e))?;
                }
                Ok(())
            },
        )
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::log::CommitMeta;
    use crate::rows::{AlignmentRow, ScoreRow};
    use crate::{Dataset, read};

    fn cells(pair: &str, run: &str, n: i32) -> Vec<AlignmentRow> {
        (0..n)
            .map(|k| AlignmentRow {
                pair_id: pair.into(),
                human_episode_id: format!("{pair}-h"),
                human_frame: k,
                robot_episode_id: format!("{pair}-r"),
                robot_frame: k,
                cost: 0.0,
                features: "state".into(),
                run_id: run.into(),
            })
            .collect()
    }

    /// Commits the pairs' cells as one version; `run` None bypasses the run check, as
    /// writers before it did.
    fn commit(ds: &Dataset, pairs: &[&str], run: Option<&str>) -> (u64, Written) {
        let mut txn = ds.begin(CommitMeta::default()).unwrap();
        let written = txn
            .write_groups(
                TableKind::Alignments,
                run,
                ShardOptions::default(),
                |w| -> Result<()> {
                    for p in pairs {
                        w.group(p, &cells(p, "run-1", 3))?;
                    }
                    Ok(())
                },
            )
            .unwrap();
        (txn.commit().unwrap(), written)
    }

    #[test]
    fn a_run_writes_each_group_once() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::open_or_create(dir.path(), CommitMeta::default()).unwrap();
        let (v1, w1) = commit(&ds, &["a", "b"], Some("run-1"));
        assert_eq!((v1, w1.groups.len()), (1, 2));
        // The same run again: nothing written, nothing committed.
        let (v2, w2) = commit(&ds, &["a", "b"], Some("run-1"));
        assert_eq!(v2, 1);
        assert!(w2.groups.is_empty());
        assert_eq!(w2.skipped, ["a", "b"]);
        // A new pair of the run is added alone.
        let (v3, w3) = commit(&ds, &["a", "c"], Some("run-1"));
        assert_eq!(
            (v3, w3.groups.clone(), w3.skipped.clone()),
            (2, vec!["c".to_string()], vec!["a".to_string()])
        );
        let (_, rows) = read::alignment_run(&ds, v3, None, "").unwrap();
        assert_eq!(rows.len(), 9);
        assert!(read::duplicate_groups(&ds, v3).unwrap().is_empty());
    }

    #[test]
    fn duplicated_groups_are_reported_and_read_once() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::open_or_create(dir.path(), CommitMeta::default()).unwrap();
        commit(&ds, &["a", "b"], None);
        let (v, _) = commit(&ds, &["a"], None);
        let dups = read::duplicate_groups(&ds, v).unwrap();
        assert_eq!(dups.len(), 1);
        assert_eq!(
            (dups[0].table, dups[0].group.as_str(), dups[0].files.len()),
            (TableKind::Alignments, "a", 2)
        );
        assert!(
            dups[0]
                .to_string()
                .contains("pair_id a of run run-1 is written 2 times"),
            "{}",
            dups[0]
        );
        let (run, rows) = read::alignment_run(&ds, v, None, "").unwrap();
        assert_eq!((run.rows, rows.len()), (6, 6));
        let report = crate::ops::verify(&ds, v, |_| {}).unwrap();
        assert!(report.ok(), "{:?}", report.problems);
        assert_eq!(report.duplicates, dups);
    }

    #[test]
    fn rows_of_another_group_or_table_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::open_or_create(dir.path(), CommitMeta::default()).unwrap();
        let mut txn = ds.begin(CommitMeta::default()).unwrap();
        let err = txn
            .write_groups(
                TableKind::Alignments,
                None,
                ShardOptions::default(),
                |w| -> Result<()> {
                    w.group("a", &cells("b", "r", 1))?;
                    Ok(())
                },
            )
            .unwrap_err();
        assert!(err.to_string().contains("a row of group b"), "{err}");
        let err = txn
            .write_groups(
                TableKind::Alignments,
                None,
                ShardOptions::default(),
                |w| -> Result<()> {
                    w.group("e", &[ScoreRow::default()])?;
                    Ok(())
                },
            )
            .unwrap_err();
        assert!(
            err.to_string()
                .contains("scores rows handed to the writer of table alignments"),
            "{err}"
        );
        let err = txn
            .write_groups(
                TableKind::Alignments,
                None,
                ShardOptions::default(),
                |w| -> Result<()> {
                    w.begin("a")?;
                    Ok(())
                },
            )
            .unwrap_err();
        assert!(err.to_string().contains("never ended"), "{err}");
        // Nothing was added, and no file is left behind.
        assert!(txn.is_empty());
        let left = std::fs::read_dir(ds.table_root(TableKind::Alignments))
            .unwrap()
            .count();
        assert_eq!(left, 0);
    }
}
